//! The solver value: settings, problem, workspace and solution; the solve's entry,
//! its input checks and its exits.

use crate::cholesky::{factor_h_counted, prepare_factor, solve_transposed};
use crate::factor::{Workspace, ROW_FULL};
use crate::{
    ActiveConstraint, ConstraintIndex, QpProblem, QpSettings, QpSolution, QpStatus, Real, Side,
};

/// Length of the packed `LDLᵀ` storage for a working-set capacity `w`: `w(w+1)/2`.
///
/// Use it for the last const parameter of [`QpSolver`]: `QpSolver<f32, 32, 96, 48,
/// { ldl_len(48) }>`.
pub const fn ldl_len(w: usize) -> usize {
    w * (w + 1) / 2
}

/// The solver: settings, problem, workspace and solution in one value (for a
/// `static` on the ECU).
///
/// `N` variables, `M` general-row capacity, `W` working-set capacity, `WL` must be
/// [`ldl_len`]`(W)` (checked at compile time).
#[derive(Clone, Debug)]
pub struct QpSolver<T, const N: usize, const M: usize, const W: usize, const WL: usize> {
    /// Settings, read at each solve.
    pub settings: QpSettings<T>,
    pub(crate) problem: QpProblem<T, N, M>,
    pub(crate) work: Workspace<T, N, M, W, WL>,
    pub(crate) solution: QpSolution<T, N, M>,
    /// The problem's `H` and rows hold factor data from the last solve.
    pub(crate) consumed: bool,
}

impl<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize>
    QpSolver<T, N, M, W, WL>
{
    const SIZES_OK: () = {
        assert!(WL == W * (W + 1) / 2, "WL must be ldl_len(W)");
        assert!(N >= 1 && W >= 1);
        assert!(N <= u16::MAX as usize && M <= u16::MAX as usize);
    };

    /// A solver with an empty problem, default settings (`max_iter = 4(N+M)`, warm
    /// start on) and an empty working set. `const`, so it can initialise a `static`.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::SIZES_OK;
        Self {
            settings: QpSettings::new((4 * (N + M)) as u32),
            problem: QpProblem::new(),
            work: Workspace {
                ws: [ActiveConstraint {
                    index: ConstraintIndex::Bound(0),
                    side: Side::Lower,
                }; W],
                n: 0,
                lam: [T::ZERO; W],
                ly: [T::ZERO; W],
                y: [T::ZERO; W],
                beta: [T::ZERO; W],
                tmp: [T::ZERO; W],
                ldl: [T::ZERO; WL],
                v: [T::ZERO; N],
                u: [T::ZERO; N],
                rinv: [T::ZERO; N],
                row_state: [None; M],
                bound_state: [None; N],
                updates: 0,
                last_rel_pivot: T::ZERO,
                pending: false,
                pending_diag: T::ZERO,
                row_code: [ROW_FULL; M],
            },
            solution: QpSolution::new(),
            consumed: false,
        }
    }

    /// The problem, to fill in place before a solve. A solve overwrites `h` and the
    /// used rows of `a`: write both (and anything else that changed) before every
    /// solve. Calling this marks the data as refilled.
    pub fn problem_mut(&mut self) -> &mut QpProblem<T, N, M> {
        self.consumed = false;
        &mut self.problem
    }

    /// The problem (after a solve, `h` holds `R` (`H = RᵀR`), and each row that entered the
    /// working set holds `a_iᵀ R⁻¹`, the others `a_iᵀ`).
    pub fn problem(&self) -> &QpProblem<T, N, M> {
        &self.problem
    }

    /// The result of the last solve.
    pub fn solution(&self) -> &QpSolution<T, N, M> {
        &self.solution
    }

    /// The working set left by the last solve (or set by
    /// [`QpSolver::set_working_set`]), in order of entry.
    pub fn working_set(&self) -> &[ActiveConstraint] {
        self.work.ws.get(..self.work.n).unwrap_or(&[])
    }

    /// Sets the working set the next (warm-started) solve starts from; keeps at most
    /// `W` entries and returns how many were kept. Entries are validated at the solve.
    pub fn set_working_set(&mut self, set: &[ActiveConstraint]) -> usize {
        self.set_working_set_from(set.iter().copied())
    }

    /// [`QpSolver::set_working_set`] from an iterator (no buffer needed); keeps at
    /// most `W` entries and returns how many were kept.
    pub fn set_working_set_from(
        &mut self,
        set: impl IntoIterator<Item = ActiveConstraint>,
    ) -> usize {
        let mut k = 0;
        // At most W entries (the zip with `ws`); the ECU's `set` (firmware's mpc.rs
        // `renumber_working_set`) filters at most WS warm entries in all.
        // wcet-bound: WS
        for (d, s) in self.work.ws.iter_mut().zip(set) {
            *d = s;
            k += 1;
        }
        self.work.n = k;
        k
    }

    /// Appends `e` to the working set the next (warm-started) solve starts from;
    /// false, and nothing kept, once it holds `W` entries. With
    /// [`QpSolver::clear_working_set`], the same as [`QpSolver::set_working_set`]
    /// one entry at a time (a caller that filters its entries needs no buffer).
    pub fn push_working_set(&mut self, e: ActiveConstraint) -> bool {
        match self.work.ws.get_mut(self.work.n) {
            Some(d) => {
                *d = e;
                self.work.n += 1;
                true
            }
            None => false,
        }
    }

    /// Empties the working set.
    pub fn clear_working_set(&mut self) {
        self.work.n = 0;
    }

    /// The slack `s_i = |λ_i|/ρ_i` of soft row `i` in the last solution (0 for a hard
    /// or unused row).
    pub fn slack(&self, i: usize) -> T {
        match (self.problem.soft.get(i), self.solution.lambda_rows.get(i)) {
            (Some(&rho), Some(&l)) if rho > T::ZERO && i < self.problem.m => l.abs() / rho,
            _ => T::ZERO,
        }
    }

    /// Solves the problem held in the solver; returns the status (also in
    /// [`QpSolver::solution`]). Consumes `H` and the rows (see
    /// [`QpSolver::problem_mut`]).
    pub fn solve(&mut self) -> QpStatus {
        self.solve_with(|h, is_factor| {
            if is_factor {
                prepare_factor(h)
            } else {
                factor_h_counted(h)
            }
        })
    }

    /// [`QpSolver::solve`] for a problem that holds the Hessian as its factor `R`
    /// ([`QpProblem::h_factor`]); `InvalidInput` if it holds `H`. A caller that
    /// always builds `R` (the MPC) links no Cholesky factorisation, whose loops
    /// would otherwise be code of the binary that no activation runs.
    pub fn solve_factored(&mut self) -> QpStatus {
        if !self.problem.h_factor {
            // As a consumed problem: `InvalidInput`, the solution cleared.
            self.consumed = true;
        }
        self.solve_with(|h, _| prepare_factor(h))
    }

    /// The solve, with `factor` making `R` in place from the problem's `h` (given
    /// whether `h` holds `R` already): the floored pivots, or `None` when `h` is
    /// not usable.
    fn solve_with(
        &mut self,
        factor: impl FnOnce(&mut [[T; N]; N], bool) -> Option<u32>,
    ) -> QpStatus {
        let s = &mut self.solution;
        s.iterations = 0;
        s.added = 0;
        s.removed = 0;
        s.refactorizations = 0;
        let status = if self.consumed {
            QpStatus::InvalidInput
        } else {
            self.consumed = true;
            match validate(&self.problem, &mut self.work.row_code) {
                Some(st) => st,
                None => {
                    let floored = factor(&mut self.problem.h, self.problem.h_factor);
                    self.solution.floored_pivots = floored.unwrap_or(0);
                    if floored.is_none() {
                        QpStatus::NotConvex
                    } else {
                        let p = &mut self.problem;
                        self.work.v = p.f;
                        solve_transposed(&p.h, &mut self.work.v, 0);
                        let tols = self.settings.effective();
                        let dropped = self.work.start(p, &self.settings, tols);
                        self.solution.iterations = dropped;
                        self.work
                            .iterate(p, &self.settings, tols, &mut self.solution)
                    }
                }
            }
        };
        self.solution.status = status;
        match status {
            QpStatus::Optimal
            | QpStatus::IterationLimit
            | QpStatus::Infeasible
            | QpStatus::WorkingSetFull
            | QpStatus::NumericalError => {
                // At `Optimal`, `u` and `x` are those of the final multipliers already.
                let fresh = status == QpStatus::Optimal;
                self.work.output(&self.problem, &mut self.solution, fresh);
            }
            _ => {
                self.work.n = 0;
                self.solution.x.fill(T::ZERO);
                self.solution.lambda_rows.fill(T::ZERO);
                self.solution.lambda_bounds.fill(T::ZERO);
                self.solution.objective = T::ZERO;
                self.solution.working_set_len = 0;
            }
        }
        status
    }
}

impl<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize> Default
    for QpSolver<T, N, M, W, WL>
{
    fn default() -> Self {
        Self::new()
    }
}

#[inline]
fn is_nan<T: Real>(v: T) -> bool {
    v.partial_cmp(&v).is_none()
}

/// ±0 if every entry of `v` is finite, NaN otherwise: `x·0` is ±0 for a finite `x`
/// and NaN for ±∞ and NaN (one multiplication and one addition per entry, no branch).
#[inline]
fn nonfinite_probe<T: Real>(v: &[T]) -> T {
    let mut acc = [T::ZERO; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    // `v` has at most N entries (validate: `f`, a suffix of a row of `H`, a row's
    // prefix), so at most N/4 chunks and 3 left over.
    // wcet-bound: NV / 4
    for c in chunks {
        for (a, &x) in acc.iter_mut().zip(c) {
            *a += x * T::ZERO;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    // wcet-bound: 3
    for &x in rest {
        s += x * T::ZERO;
    }
    s
}

/// Input checks; `None` if the problem is acceptable.
/// Also writes `row_code` (see [`Workspace::row_code`]) for the used rows.
fn validate<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    row_code: &mut [u8; M],
) -> Option<QpStatus> {
    if p.m > M {
        return Some(QpStatus::InvalidInput);
    }
    let rows = p.a.get(..p.m).unwrap_or(&[]);
    let mut probe = nonfinite_probe(&p.f);
    // Only the upper triangle of `H` (or of its factor) is ever read.
    // wcet-bound: NV
    for (j, r) in p.h.iter().enumerate() {
        probe += nonfinite_probe(r.get(j..).unwrap_or(&[]));
    }
    let full = N - N % 4;
    // wcet-bound: NC
    for (r, code) in rows.iter().zip(row_code.iter_mut()) {
        // A NaN or ±∞ is nonzero: it lies in the prefix up to the last group of four
        // with a nonzero entry (the rest are zeros), so only that prefix needs the
        // finiteness probe. A group is zero when the sum of its magnitudes is (a NaN
        // or ±∞ makes it nonzero).
        let groups = r
            .chunks(4)
            .rposition(|c| c.iter().fold(T::ZERO, |acc, &v| acc + v.abs()) != T::ZERO)
            .map_or(0, |g| g + 1);
        probe += nonfinite_probe(r.get(..4 * groups).unwrap_or(r));
        *code = if 4 * groups > full || groups >= ROW_FULL as usize {
            ROW_FULL
        } else {
            groups as u8
        };
    }
    let mut bad_bound = false;
    let mut nan = false;
    for (&l, &h) in p.x_lo.iter().zip(p.x_hi.iter()) {
        nan |= is_nan(l) || is_nan(h);
        bad_bound |= l > h || l == T::INFINITY || h == -T::INFINITY;
    }
    // wcet-bound: NC
    for ((&l, &h), &s) in p.lo.iter().zip(p.hi.iter()).zip(p.soft.iter()).take(p.m) {
        nan |= is_nan(l) || is_nan(h) || !s.is_finite();
        bad_bound |= l > h || l == T::INFINITY || h == -T::INFINITY || s < T::ZERO;
    }
    // NaN != 0: the probe is 0 exactly when every entry is finite.
    if probe != T::ZERO || nan {
        Some(QpStatus::NonFiniteInput)
    } else if bad_bound {
        Some(QpStatus::InvalidInput)
    } else {
        None
    }
}
