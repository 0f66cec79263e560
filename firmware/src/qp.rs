//! Our dense dual active-set QP solver (the MPC's optimiser).
//!
//! # Problem solved
//!
//! ```text
//!   minimise    ½ xᵀ H x + fᵀ x + Σ_{i soft} ½ ρ_i s_i²          x ∈ ℝᴺ
//!   subject to  x_lo ≤ x ≤ x_hi                               (simple bounds)
//!               lo_i ≤ a_iᵀ x ≤ hi_i            i = 0..m, row i hard (ρ_i = 0)
//!               lo_i − s_i ≤ a_iᵀ x ≤ hi_i + s_i  i = 0..m, row i soft (ρ_i > 0)
//! ```
//!
//! `H` symmetric positive definite (only its upper triangle is read), bounds may be
//! `±∞`, `lo = hi` makes an equality. The slack `s_i ≥ 0` of a soft row is never a
//! variable: it is implicit in the dual (below).
//!
//! # Method: dual active set, after DAQP (Arnström, Bemporad, Axehill 2022)
//!
//! With the Cholesky factor `H = RᵀR` (`R` upper) and `u = R x`, the cost becomes
//! `½‖u + v‖² − ½‖v‖²` with `v = R⁻ᵀ f`, and a constraint row `a` becomes
//! `m̃ = R⁻ᵀ a` (row `a R⁻¹` of `M̃ = A R⁻¹`; a bound on `x_j` has the row `j` of `R⁻¹`).
//! For a working set `W` of constraints held at one of their sides, `b_k` the bound of
//! that side, the Lagrangian `½‖u+v‖² + Σ_k λ_k (m̃_kᵀu − b_k)` gives
//! `u = −v − M̃_Wᵀ λ`, and the multipliers solve
//!
//! ```text
//!   (M̃_W M̃_Wᵀ + D_W) λ = −d_W,    d_k = b_k + m̃_kᵀ v,
//! ```
//!
//! with the sign convention `λ_k ≥ 0` at an upper side, `λ_k ≤ 0` at a lower side,
//! free for an equality.
//!
//! **Soft rows.** Relaxing `m̃ᵀu ≤ hi` to `m̃ᵀu − s ≤ hi` with `½ρ s²` added to the
//! cost adds `λ(m̃ᵀu − s − hi) + ½ρs²` to the Lagrangian; stationarity in `s` gives
//! `ρ s = λ`, so `s = λ/ρ ≥ 0` (at a lower side, `s = −λ/ρ`). The active row then
//! reads `m̃ᵀu = b + λ/ρ` in both cases, and substituting `u` gives the system above
//! with `D_W = diag(1/ρ_k)` on the soft rows (0 on hard ones). So a soft row costs
//! nothing more than a hard one: its working-set matrix only gains `1/ρ` on the
//! diagonal, it stays positive definite however many soft rows are active (more than
//! `N` of them may be), and a problem whose rows are all soft is never infeasible.
//!
//! **Why dual.** `λ = 0` (the unconstrained optimum `u = −v`) is dual feasible, so no
//! phase 1 is needed; every iterate is dual feasible and the dual cost rises, so the
//! method ends at the first primal-feasible iterate; an infeasible problem shows as a
//! dual ray (a violated constraint that depends linearly on the working set and whose
//! multiplier can grow without any other reaching zero).
//!
//! **Iteration.** Solve for `λ*` on the working set. If some `λ*_k` has the wrong sign,
//! step `λ ← λ + α(λ* − λ)` to the first multiplier reaching zero and remove that
//! constraint. Otherwise take `λ = λ*`, form `u` and add the most violated inactive
//! constraint (violation above `primal_tol`); none: optimal, `x = R⁻¹u`. If the new
//! row makes the working-set matrix singular (tiny relative pivot: it depends linearly
//! on the hard rows of `W`), move `λ` along the null-space direction, which keeps `u`
//! and raises the dual cost, until a multiplier reaches zero, and swap that constraint
//! for the new one; if no multiplier can reach zero, the problem is infeasible (in
//! `f32`, if the pivot is small but above rounding level, the row is nearly but not
//! exactly dependent and is added after all). Before `Optimal` is returned, the working-set
//! constraints are checked to hold at the final point; if they do not (an inaccurate
//! factor of a nearly singular working set), the factor is recomputed once, and a
//! second failure gives `NumericalError` rather than a wrong optimum.
//!
//! **Factors.** `LDLᵀ` of the working-set matrix, packed by rows: a row is appended
//! when a constraint enters (`O(|W|·N + |W|²)`), and a constraint leaves by deleting its
//! row and column and a rank-one update of the trailing block (`O(|W|²)`, no new
//! factorisation). When a small pivot may come from accumulated rounding, or a solve
//! gives non-finite multipliers, the factor is recomputed from scratch (counted).
//!
//! **Cost.** Per solve: Cholesky of `H` (`N³/6` multiply-adds; none when the caller
//! gives the factor `R`, see [`QpProblem::h_factor`]); `R` is never inverted: `v`,
//! a row's transformation `a_iᵀR⁻¹` and a bound's row `e_jᵀR⁻¹` are triangular
//! solves with `Rᵀ` (`N²/2`, row `axpy`s), the last two only when the constraint
//! first enters the working set in the solve (an inactive row's value is checked as
//! `a_iᵀx`, `x = R⁻¹u` by back substitution, which equals `m̃_iᵀu`); dot products
//! in four partial sums, so that the host pipelines and vectorises them. Per iteration: `O(m·N)` for the constraint values, `O(|W|·N + |W|²)` for the multipliers and the factor update. The counters of
//! [`QpSolution`] (iterations, additions, removals, refactorisations) are
//! deterministic, so a time budget can be derived from them.
//!
//! **Storage.** The solver owns the problem; [`QpSolver::solve`] overwrites `H` with
//! its factor `R` (upper triangle) and the rows `e_jᵀR⁻¹` of the bounds that entered
//! the working set (lower triangle), and the rows `a_i` that entered with `a_i R⁻¹`, so
//! the caller refills them before every solve (the MPC rebuilds them anyway). Nothing is
//! allocated; there is no recursion; the sizes are const generics checked at compile
//! time.
//!
//! **Warm start.** With [`QpSettings::warm_start`], a solve starts from the working
//! set of the previous solve, or the one given with [`QpSolver::set_working_set`]
//! (e.g. shifted by one MPC step). Entries that are out of range, duplicated, at an
//! infinite bound or linearly dependent on earlier entries are dropped; entries whose
//! multipliers come out with the wrong sign leave through ordinary removal steps
//! (starting from `λ = 0`, which is dual feasible).

//!
//! # Use
//!
//! ```
//! use firmware::qp::{ldl_len, QpSolver, QpStatus};
//! // 2 variables, up to 4 rows, working set of up to 4.
//! let mut qp = QpSolver::<f64, 2, 4, 4, { ldl_len(4) }>::new();
//! let p = qp.problem_mut(); // fill in place (refill H and rows before every solve)
//! p.h = [[1.0, 0.0], [0.0, 1.0]];
//! p.f = [-2.0, -2.0]; // unconstrained optimum (2, 2)
//! p.x_hi = [1.5, f64::INFINITY]; // x0 ≤ 1.5
//! p.push_row(&[1.0, 1.0], f64::NEG_INFINITY, 2.0, 0.0); // hard: x0 + x1 ≤ 2
//! assert_eq!(qp.solve(), QpStatus::Optimal);
//! let s = qp.solution();
//! assert!((s.x[0] - 1.0).abs() < 1e-12 && (s.x[1] - 1.0).abs() < 1e-12);
//! assert!((s.lambda_rows[0] - 1.0).abs() < 1e-12); // H x + f + Aᵀλ = 0
//! // Next solve: refill, optionally shift `qp.working_set()` and `set_working_set` it.
//! ```

// Index loops mirror the maths of the factorisations; the ranges are bounded by the
// const sizes and the working-set count (≤ W).
#![allow(clippy::needless_range_loop)]
// `!(a > b)` is meant: it is also true when `a` is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::Real;

/// Length of the packed `LDLᵀ` storage for a working-set capacity `w`: `w(w+1)/2`.
///
/// Use it for the last const parameter of [`QpSolver`]: `QpSolver<f32, 32, 96, 48,
/// { ldl_len(48) }>`.
pub const fn ldl_len(w: usize) -> usize {
    w * (w + 1) / 2
}

/// Which side of a constraint is held active.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The lower bound (`x_j = x_lo_j`, or `a_iᵀx = lo_i`, minus the slack if soft);
    /// its multiplier is `≤ 0`.
    Lower,
    /// The upper bound (`x_j = x_hi_j`, or `a_iᵀx = hi_i`, plus the slack if soft);
    /// its multiplier is `≥ 0`.
    Upper,
}

/// A constraint of the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConstraintIndex {
    /// The simple bound on variable `j` (`0 ≤ j < N`).
    Bound(u16),
    /// The general row `i` (`0 ≤ i < m`).
    Row(u16),
}

/// One entry of the working set: a constraint held at one side (6 bytes, `Copy`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ActiveConstraint {
    /// The constraint.
    pub index: ConstraintIndex,
    /// The side at which it is held (for an equality, the side it was violated at).
    pub side: Side,
}

/// How a solve ended. Every exit is one of these; the solver never panics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpStatus {
    /// No solve has run since the solver was created.
    NotSolved,
    /// KKT conditions hold within the tolerances.
    Optimal,
    /// `max_iter` iterations ran out. The returned point is the primal point of the
    /// current dual iterate: `x` minimises the Lagrangian at the returned multipliers,
    /// which have the right signs and are zero off the working set (stationarity
    /// `Hx + f + Aᵀλ + λ_bounds = 0` and dual feasibility hold). Constraints may be
    /// violated, including those of the working set when the last step was a partial
    /// one; the caller should check the violation it can accept.
    IterationLimit,
    /// The hard constraints cannot all hold (a dual ray was found). `x` is the last
    /// iterate, as for [`QpStatus::IterationLimit`].
    Infeasible,
    /// `H` is not (numerically) positive definite: its Cholesky factorisation failed.
    NotConvex,
    /// Factor trouble that refactoring could not fix (non-finite multipliers, or a
    /// dependent constraint still dependent after `W` null-space swaps).
    NumericalError,
    /// NaN or ±∞ in `H`, `f`, a used row of `A` or a soft weight, or NaN in a bound.
    NonFiniteInput,
    /// `m > M`, some `lo > hi`, a lower bound `+∞` or upper bound `−∞`, a negative
    /// soft weight, or the problem data were consumed by a previous solve and not
    /// refilled (see [`QpSolver::problem_mut`]).
    InvalidInput,
    /// A constraint had to enter a working set already holding `W` constraints.
    WorkingSetFull,
}

/// Refactorizations a solve may make unless its settings say otherwise
/// ([`QpSettings::max_refactorizations`]).
pub const DEFAULT_MAX_REFACTORIZATIONS: u32 = 2;

/// Solver settings (tolerances in the units of the constraint values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QpSettings<T> {
    /// Largest constraint violation accepted as feasible (absolute, in the units of
    /// `a_iᵀx` and `x_j`). `0` means the precision default `√ε` (1.5e-8 for `f64`,
    /// 3.5e-4 for `f32`).
    pub primal_tol: T,
    /// A multiplier counts as of the wrong sign below `−dual_tol`. `0` means the
    /// precision default `√ε`.
    pub dual_tol: T,
    /// Relative pivot threshold: a constraint entering the working set is treated as
    /// linearly dependent if its `LDLᵀ` pivot is below `pivot_tol` times its diagonal
    /// entry (then a null-space swap is tried; in `f32`, if no multiplier limits the
    /// ray and the pivot is above 6.4e-6, the row is taken as independent after all).
    /// `0` means the precision default (1e-9 `f64`, 1.2e-4 `f32`).
    pub pivot_tol: T,
    /// Iteration cap (one iteration adds or removes one constraint, or swaps one after
    /// a singular step). Bounds the worst-case time of a solve.
    pub max_iter: u32,
    /// Refactorization cap: how many times a solve may rebuild its factor from
    /// scratch after rounding spoiled it (the warm start's first build is not
    /// one). A rebuild costs about `W³/6` multiply-adds, tens of iterations' worth:
    /// past the cap the solve ends with [`QpStatus::NumericalError`]. Bounds the
    /// worst-case time of a solve with the iteration cap.
    pub max_refactorizations: u32,
    /// Start from the working set left by the previous solve (or set with
    /// [`QpSolver::set_working_set`]) instead of an empty one.
    pub warm_start: bool,
}

impl<T: Real> QpSettings<T> {
    /// Precision-default tolerances, `max_iter` iterations,
    /// [`DEFAULT_MAX_REFACTORIZATIONS`] refactorizations, warm start on.
    pub const fn new(max_iter: u32) -> Self {
        Self {
            primal_tol: T::ZERO,
            dual_tol: T::ZERO,
            pivot_tol: T::ZERO,
            max_iter,
            max_refactorizations: DEFAULT_MAX_REFACTORIZATIONS,
            warm_start: true,
        }
    }

    fn effective(&self) -> Tols<T> {
        let sqrt_eps = T::EPSILON.sqrt();
        let pick = |v: T, d: T| if v > T::ZERO { v } else { d };
        // Single precision (ε ≈ 1.2e-7) or double (ε ≈ 2.2e-16); the pivot levels were
        // tuned on degenerate random problems (tests/qp_precision.rs, tests/qp_kkt.rs).
        let single = T::EPSILON > T::lit(1e-10);
        let (pivot, rounding) = if single {
            (T::lit(1.2e-4), T::lit(6.4e-6))
        } else {
            // No forcing band in f64: it cost infeasibility detection on degenerate sets.
            (T::lit(1e-9), T::lit(1e-9))
        };
        Tols {
            primal: pick(self.primal_tol, sqrt_eps),
            dual: pick(self.dual_tol, sqrt_eps),
            pivot: pick(self.pivot_tol, pivot),
            rounding: rounding.min(pick(self.pivot_tol, pivot)),
            noise: sqrt_eps,
        }
    }
}

#[derive(Clone, Copy)]
struct Tols<T> {
    primal: T,
    dual: T,
    pivot: T,
    /// Relative pivot at rounding level (`ε^¾`): below it a row is exactly dependent.
    rounding: T,
    /// Relative size below which a null-space coefficient is rounding noise (`√ε`).
    noise: T,
}

/// The problem data, filled in place by the caller (see [`QpSolver::problem_mut`]).
///
/// `N` variables, capacity `M` general rows of which the first `m` are used.
#[derive(Clone, Debug)]
pub struct QpProblem<T, const N: usize, const M: usize> {
    /// Hessian `H` (`N×N`, symmetric positive definite; only the upper triangle
    /// `h[r][c]`, `c ≥ r`, is read). Overwritten during a solve by its factor `R` (upper
    /// triangle) and rows of `R⁻¹` (lower triangle).
    pub h: [[T; N]; N],
    /// Linear cost `f` (`N`).
    pub f: [T; N],
    /// General rows: `a[i]` is `a_iᵀ` (`M×N`, rows `0..m` used). A row that enters
    /// the working set during a solve is overwritten by `a_iᵀ R⁻¹`.
    pub a: [[T; N]; M],
    /// Row lower bounds `lo_i` (`M`; `−∞` for none).
    pub lo: [T; M],
    /// Row upper bounds `hi_i` (`M`; `+∞` for none; `lo_i = hi_i` for an equality).
    pub hi: [T; M],
    /// Variable lower bounds (`N`; `−∞` for none).
    pub x_lo: [T; N],
    /// Variable upper bounds (`N`; `+∞` for none; equal to `x_lo` fixes the variable).
    pub x_hi: [T; N],
    /// Soft weight `ρ_i` of each row (`M`): `0` hard, `> 0` soft with penalty
    /// `½ ρ_i s_i²` on its slack `s_i` (in cost units per squared row unit).
    pub soft: [T; M],
    /// Number of rows in use, `m ≤ M`.
    pub m: usize,
    /// When true, `h` holds not `H` but an upper-triangular factor `R` with
    /// `H = RᵀR` (lower triangle ignored; the sign of a row is free). A caller that
    /// builds its cost as a sum of squares (the MPC) can maintain `R` by orthogonal
    /// updates (Householder reflections in `mpc.rs`): `R`'s condition number is the square root
    /// of `H`'s, which keeps single precision accurate where forming `H` and
    /// factorising it would not.
    pub h_factor: bool,
}

impl<T: Real, const N: usize, const M: usize> QpProblem<T, N, M> {
    /// An empty problem: `H = 0`, `f = 0`, no rows, all bounds infinite, all rows hard.
    pub const fn new() -> Self {
        Self {
            h: [[T::ZERO; N]; N],
            f: [T::ZERO; N],
            a: [[T::ZERO; N]; M],
            lo: [T::ZERO; M],
            hi: [T::ZERO; M],
            x_lo: [T::ZERO; N],
            x_hi: [T::ZERO; N],
            soft: [T::ZERO; M],
            m: 0,
            h_factor: false,
        }
        .with_free_bounds()
    }

    const fn with_free_bounds(mut self) -> Self {
        let mut j = 0;
        while j < N {
            self.x_lo[j] = T::NEG_INFINITY;
            self.x_hi[j] = T::INFINITY;
            j += 1;
        }
        let mut i = 0;
        while i < M {
            self.lo[i] = T::NEG_INFINITY;
            self.hi[i] = T::INFINITY;
            i += 1;
        }
        self
    }

    /// Resets to [`QpProblem::new`]'s empty problem, in place.
    pub fn clear(&mut self) {
        for r in self.h.iter_mut() {
            r.fill(T::ZERO);
        }
        self.f.fill(T::ZERO);
        for r in self.a.iter_mut() {
            r.fill(T::ZERO);
        }
        self.lo.fill(-T::INFINITY);
        self.hi.fill(T::INFINITY);
        self.x_lo.fill(-T::INFINITY);
        self.x_hi.fill(T::INFINITY);
        self.soft.fill(T::ZERO);
        self.m = 0;
        self.h_factor = false;
    }

    /// Appends a row `lo ≤ aᵀx ≤ hi` with soft weight `soft` (`0` = hard) at index `m`
    /// and returns that index, or `None` if `M` rows are already in use.
    pub fn push_row(&mut self, a: &[T; N], lo: T, hi: T, soft: T) -> Option<usize> {
        let i = self.m;
        let row = self.a.get_mut(i)?;
        *row = *a;
        if let (Some(l), Some(h), Some(s)) =
            (self.lo.get_mut(i), self.hi.get_mut(i), self.soft.get_mut(i))
        {
            *l = lo;
            *h = hi;
            *s = soft;
        }
        self.m = i + 1;
        Some(i)
    }
}

impl<T: Real, const N: usize, const M: usize> Default for QpProblem<T, N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// The result of a solve.
#[derive(Clone, Debug)]
pub struct QpSolution<T, const N: usize, const M: usize> {
    /// Primal point `x` (`N`); see [`QpStatus`] for what it satisfies on each exit.
    pub x: [T; N],
    /// Row multipliers `λ_i` (`M`, first `m` meaningful): `≥ 0` at an active upper
    /// side, `≤ 0` at an active lower side, `0` if inactive. With the bound
    /// multipliers, `H x + f + Aᵀ λ + λ_bounds = 0`. A soft row's slack is
    /// `|λ_i| / ρ_i`.
    pub lambda_rows: [T; M],
    /// Bound multipliers (`N`), same sign convention.
    pub lambda_bounds: [T; N],
    /// Cost `½xᵀHx + fᵀx + Σ ½ρ_i s_i²` at `x`.
    pub objective: T,
    /// How the solve ended.
    pub status: QpStatus,
    /// Iterations (each adds, removes or swaps one constraint).
    pub iterations: u32,
    /// Constraints added to the working set (warm-start re-activations not counted).
    pub added: u32,
    /// Constraints removed from the working set.
    pub removed: u32,
    /// `LDLᵀ` factorisations recomputed from scratch (warm-start build not counted).
    pub refactorizations: u32,
    /// Pivots of `H`'s Cholesky factor floored at `√ε·H_jj` (0 normally; > 0 when
    /// `H` was singular to working precision and a small proximal term was added).
    pub floored_pivots: u32,
    /// Working-set size at exit.
    pub working_set_len: u16,
}

impl<T: Real, const N: usize, const M: usize> QpSolution<T, N, M> {
    /// A zero solution with status [`QpStatus::NotSolved`].
    pub const fn new() -> Self {
        Self {
            x: [T::ZERO; N],
            lambda_rows: [T::ZERO; M],
            lambda_bounds: [T::ZERO; N],
            objective: T::ZERO,
            status: QpStatus::NotSolved,
            iterations: 0,
            added: 0,
            removed: 0,
            refactorizations: 0,
            floored_pivots: 0,
            working_set_len: 0,
        }
    }
}

impl<T: Real, const N: usize, const M: usize> Default for QpSolution<T, N, M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Solver workspace: the working set, its factor and per-constraint flags.
#[derive(Clone, Debug)]
struct Workspace<T, const N: usize, const M: usize, const W: usize, const WL: usize> {
    /// Working set entries `0..n`.
    ws: [ActiveConstraint; W],
    /// Entries in use, `≤ W` (`commit` refuses at `W`, `set_working_set_from` keeps at
    /// most `W`, `rebuild` starts from 0): it bounds every loop over the working set.
    n: usize,
    /// Current (dual-feasible) multipliers of the working set (`W`).
    lam: [T; W],
    /// Scratch (`W`): right-hand side then `λ*` of the working-set system, rank-one
    /// vectors, null-space direction.
    tmp: [T; W],
    /// Packed `LDLᵀ` of the working-set matrix: row `r` at `r(r+1)/2`, holding
    /// `L[r][0..r]` then `D[r]`.
    ldl: [T; WL],
    /// `v = R⁻ᵀ f` (`N`).
    v: [T; N],
    /// `u = R x` (`N`).
    u: [T; N],
    /// Whether bound `j`'s row `e_jᵀ R⁻¹` is stored in this solve (`N`): `R` itself
    /// is kept, not inverted, and a bound's row is computed when it enters the working
    /// set, into the lower triangle of `h` (see [`store_inverse_row`]).
    bound_ready: [bool; N],
    /// Side at which each row is active (`M`).
    row_state: [Option<Side>; M],
    /// Side at which each bound is active (`N`).
    bound_state: [Option<Side>; N],
    /// Appends since the last from-scratch factorisation.
    updates: u32,
    /// Pivot of the last `append` relative to its diagonal entry.
    last_rel_pivot: T,
    /// Per row (`M`, one byte to keep the solver small): [`ROW_TRANSFORMED`] once
    /// the row holds `a_i R⁻¹` in this solve (rows are transformed only when they
    /// enter the working set); otherwise the length of its prefix that can be
    /// nonzero, in groups of four entries (its last nonzero entry rounded up to the
    /// four-sum groups of [`dot_from`], so that a dot product over the prefix gives
    /// the same result as over all `N` entries), or [`ROW_FULL`].
    row_code: [u8; M],
}

/// [`Workspace::row_code`] of a row that holds `a_i R⁻¹`.
const ROW_TRANSFORMED: u8 = 0xFF;
/// [`Workspace::row_code`] of an untransformed row used over all `N` entries.
const ROW_FULL: u8 = 0xFE;

/// The solver: settings, problem, workspace and solution in one value (for a
/// `static` on the ECU).
///
/// `N` variables, `M` general-row capacity, `W` working-set capacity, `WL` must be
/// [`ldl_len`]`(W)` (checked at compile time).
#[derive(Clone, Debug)]
pub struct QpSolver<T, const N: usize, const M: usize, const W: usize, const WL: usize> {
    /// Settings, read at each solve.
    pub settings: QpSettings<T>,
    problem: QpProblem<T, N, M>,
    work: Workspace<T, N, M, W, WL>,
    solution: QpSolution<T, N, M>,
    /// The problem's `H` and rows hold factor data from the last solve.
    consumed: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum AppendError {
    Singular,
    Full,
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
                tmp: [T::ZERO; W],
                ldl: [T::ZERO; WL],
                v: [T::ZERO; N],
                u: [T::ZERO; N],
                bound_ready: [false; N],
                row_state: [None; M],
                bound_state: [None; N],
                updates: 0,
                last_rel_pivot: T::ZERO,
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
        // At most W entries (the zip with `ws`); the ECU's `set` (mpc.rs
        // `renumber_working_set`) filters at most WS warm entries in all.
        // wcet-bound: WS
        for (d, s) in self.work.ws.iter_mut().zip(set) {
            *d = s;
            k += 1;
        }
        self.work.n = k;
        k
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
                    let floored = if self.problem.h_factor {
                        prepare_factor(&mut self.problem.h)
                    } else {
                        factor_h_counted(&mut self.problem.h)
                    };
                    self.solution.floored_pivots = floored.unwrap_or(0);
                    if floored.is_none() {
                        QpStatus::NotConvex
                    } else {
                        let p = &mut self.problem;
                        self.work.v = p.f;
                        solve_transposed(&p.h, &mut self.work.v, 0);
                        let tols = self.settings.effective();
                        self.work.start(p, &self.settings, tols);
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

/// `h` holds an upper-triangular factor `R` (`H = RᵀR`): makes its diagonal
/// positive (a row's sign is free) and floors a pivot below `√ε·‖R_·j‖` as
/// [`factor_h_counted`] does. `None` for a zero or non-finite column.
fn prepare_factor<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> Option<u32> {
    let mut floored = 0u32;
    // wcet-bound: NV
    for j in 0..N {
        if h[j][j] < T::ZERO {
            // wcet-bound: NV
            for v in h[j].iter_mut().skip(j) {
                *v = -*v;
            }
        }
        let mut col = T::ZERO;
        // wcet-bound: NV
        for i in 0..=j {
            col += h[i][j] * h[i][j];
        }
        let norm = col.sqrt();
        if !(norm > T::ZERO) || !norm.is_finite() {
            return None;
        }
        let floor = T::EPSILON.sqrt() * norm;
        if !(h[j][j] > floor) {
            h[j][j] = floor;
            floored += 1;
        }
    }
    Some(floored)
}

/// Cholesky `H = RᵀR` in the upper triangle (the lower triangle keeps `H`'s, never
/// read). False if a pivot is not clearly positive.
#[cfg(test)]
fn factor_h<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> bool {
    factor_h_counted(h).is_some()
}

/// [`factor_h`], returning how many pivots were floored (see below), `None` when
/// `H` is not positive definite.
///
/// A pivot that comes out below `√ε·H_jj` but above `−0.1·H_jj` is taken for
/// rounding on a nearly singular (positive semidefinite in exact arithmetic)
/// Hessian, as a condensed MPC Hessian in single precision can be (its eigenvalues
/// span more than `1/ε_f32`): it is floored to `√ε·H_jj`, which factors `H + E`
/// with a small diagonal `E` (a proximal term of relative size `√ε`, 3·10⁻⁴ in
/// `f32`) in the direction that rounding left undetermined. A pivot below
/// `−0.1·H_jj` is a Hessian that is not convex: `None`.
#[inline(never)]
fn factor_h_counted<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> Option<u32> {
    let tiny = T::EPSILON * T::from_usize(N);
    let mut floored = 0u32;
    // wcet-bound: NV
    for j in 0..N {
        // Column j of R: R[k][j] for k ≤ j, from H[k][j] (upper triangle).
        let mut d = h[j][j];
        let scale = d.abs();
        // Σ j over j < N per call (not inlined).
        // wcet-bound: NV * (NV - 1) / 2 per call
        for k in 0..j {
            d -= h[k][j] * h[k][j];
        }
        if !d.is_finite() || !(scale > T::ZERO) {
            return None;
        }
        if !(d > tiny * scale) {
            let floor = T::EPSILON.sqrt() * scale;
            if d < -T::lit(0.1) * scale {
                return None;
            }
            d = floor;
            floored += 1;
        }
        let rjj = d.sqrt();
        h[j][j] = rjj;
        // Σ (N − 1 − j) over j < N per call.
        // wcet-bound: NV * (NV - 1) / 2 per call
        for i in (j + 1)..N {
            let mut s = h[j][i];
            // Σ j·(N − 1 − j) over j < N ≤ N³/6 per call.
            // wcet-bound: NV * NV * NV / 6 per call
            for k in 0..j {
                s -= h[k][j] * h[k][i];
            }
            h[j][i] = s / rjj;
        }
    }
    Some(floored)
}

/// `x ← x R⁻¹` in place for the upper-triangular `R` (upper triangle of `r`, positive
/// diagonal): solves `Rᵀ y = x` forwards, `y_j = (x_j − Σ_{k<j} y_k R_kj) / R_jj`.
/// The entries of `x` before `start` must be zero (they stay zero). Row `axpy`s:
/// once `y_j` is final, its share leaves the later entries (contiguous, like the
/// rows of `R`); zero entries skipped.
fn solve_transposed<T: Real, const N: usize>(r: &[[T; N]; N], x: &mut [T; N], start: usize) {
    // wcet-bound: NV
    for j in start..N {
        // Σ_{start≤k<j} y_k R_kj in four partial sums, as `dot4` groups them.
        let mut acc = [T::ZERO; 4];
        let mut k = start;
        // k steps by 4 from `start` to at most j < N: at most N/4 passes, then j − k ≤ 3.
        // wcet-bound: NV / 4
        while k + 4 <= j {
            for (q, a) in acc.iter_mut().enumerate() {
                *a += x[k + q] * r[k + q][j];
            }
            k += 4;
        }
        let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
        // wcet-bound: 3
        while k < j {
            s += x[k] * r[k][j];
            k += 1;
        }
        x[j] = (x[j] - s) / r[j][j];
    }
}

/// `x = R⁻¹ u` for the upper-triangular `R` (upper triangle of `r`, positive
/// diagonal), by back substitution `x_j = (u_j − Σ_{k>j} R_jk x_k) / R_jj` (each sum
/// a contiguous dot product over row `j` of `R`).
fn solve_upper<T: Real, const N: usize>(r: &[[T; N]; N], u: &[T; N], x: &mut [T; N]) {
    // wcet-bound: NV
    for j in (0..N).rev() {
        let s = dot_from(&r[j], x, j + 1);
        x[j] = (u[j] - s) / r[j][j];
    }
}

/// Row `j` of `R⁻¹` (`e_jᵀ R⁻¹`, zero before column `j`) into `out`.
fn inverse_row<T: Real, const N: usize>(r: &[[T; N]; N], j: usize, out: &mut [T; N]) {
    out.fill(T::ZERO);
    if let Some(o) = out.get_mut(j) {
        *o = T::ONE;
        solve_transposed(r, out, j);
    }
}

/// `a_i ← a_iᵀ R⁻¹` for the used rows, `v = R⁻ᵀ f`, and every bound's row of
/// `R⁻¹` (the solver itself transforms a row or a bound only when it enters the
/// working set).
#[cfg(test)]
fn transform<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize>(
    p: &mut QpProblem<T, N, M>,
    w: &mut Workspace<T, N, M, W, WL>,
) {
    for row in p.a.iter_mut().take(p.m) {
        solve_transposed(&p.h, row, 0);
    }
    w.v = p.f;
    solve_transposed(&p.h, &mut w.v, 0);
    for j in 0..N {
        store_inverse_row(&mut p.h, j);
        w.bound_ready[j] = true;
    }
}

/// Stores row `j` of `R⁻¹` (`e_jᵀ R⁻¹`: zero before column `j`, `1/R_jj` at `j`)
/// in the lower triangle of `h`, which holds `R` in its upper triangle: the `N−1−j`
/// entries after the diagonal go to `h[N−1−j][0..N−1−j]`, the lower part of row
/// `N−1−j`, exactly its length (so the rows of all `N` bounds fit at once). The
/// solve reads the upper triangle only.
fn store_inverse_row<T: Real, const N: usize>(h: &mut [[T; N]; N], j: usize) {
    if j >= N {
        return;
    }
    let mut row = [T::ZERO; N];
    inverse_row(h, j, &mut row);
    let dst = N - 1 - j;
    if let (Some(d), Some(src)) = (
        h.get_mut(dst).and_then(|r| r.get_mut(..dst)),
        row.get(j + 1..),
    ) {
        // WCET: fewer than N entries; on the ECU the QP is the MPC's, N = NV f32.
        // wcet-bound: NV * 4 bytes
        d.copy_from_slice(src);
    }
}

/// A transformed constraint row `m̃` from column `start` on (zero before): its entry
/// at `start` and the entries after it.
#[derive(Clone, Copy)]
struct ConRow<'a, T> {
    start: usize,
    head: T,
    tail: &'a [T],
}

impl<T: Real> ConRow<'_, T> {
    /// `m̃ᵀx` (the tail in four partial sums).
    #[inline]
    fn dot<const N: usize>(&self, x: &[T; N]) -> T {
        let xs = x.get(self.start + 1..).unwrap_or(&[]);
        let x0 = x.get(self.start).copied().unwrap_or(T::ZERO);
        self.head * x0 + dot4(self.tail, xs)
    }

    /// `m̃₁ᵀm̃₂`.
    #[inline]
    fn dot_row(&self, other: &Self) -> T {
        let (lo, hi) = if self.start <= other.start {
            (self, other)
        } else {
            (other, self)
        };
        if lo.start == hi.start {
            return lo.head * hi.head + dot4(lo.tail, hi.tail);
        }
        // lo's entry at hi.start is its tail[off − 1].
        let off = hi.start - lo.start;
        let at = lo.tail.get(off - 1).copied().unwrap_or(T::ZERO);
        at * hi.head + dot4(lo.tail.get(off..).unwrap_or(&[]), hi.tail)
    }
}

#[inline]
fn sign<T: Real>(side: Side) -> T {
    match side {
        Side::Lower => -T::ONE,
        Side::Upper => T::ONE,
    }
}

#[inline]
fn row_start(r: usize) -> usize {
    r * (r + 1) / 2
}

/// The transformed row of a constraint: a general row's `a_iᵀR⁻¹` in place of
/// `a_i`, a bound's `e_jᵀR⁻¹` from the lower triangle of `h` ([`store_inverse_row`]).
#[inline]
fn con_row<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    c: ConstraintIndex,
) -> ConRow<'_, T> {
    match c {
        ConstraintIndex::Bound(j) => {
            let j = (j as usize).min(N - 1);
            let dst = N - 1 - j;
            ConRow {
                start: j,
                head: T::ONE / p.h[j][j],
                tail: p.h[dst].get(..dst).unwrap_or(&[]),
            }
        }
        ConstraintIndex::Row(i) => {
            let a = &p.a[i as usize];
            ConRow {
                start: 0,
                head: a[0],
                tail: a.get(1..).unwrap_or(&[]),
            }
        }
    }
}

/// `Σ a_k b_k` over two slices of equal length, in four interleaved partial sums
/// (independent additions pipeline; one chain would wait on each addition's
/// latency), then the remainder in order.
#[inline]
fn dot4<T: Real>(a: &[T], b: &[T]) -> T {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    let mut acc = [T::ZERO; 4];
    // Every caller passes slices of `[T; N]` rows (at most N entries): N/4 chunks.
    // wcet-bound: NV / 4
    for (x, y) in ca.zip(cb) {
        for ((s, &p), &q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (&p, &q) in ra.iter().zip(rb) {
        s += p * q;
    }
    s
}

/// `Σ_{k ≥ start} a_k b_k` ([`dot4`]).
#[inline]
fn dot_from<T: Real, const N: usize>(a: &[T; N], b: &[T; N], start: usize) -> T {
    dot4(a.get(start..).unwrap_or(&[]), b.get(start..).unwrap_or(&[]))
}

/// [`dot4`] from 0 over the first `len` entries only: the same result as over
/// all `N` when the rest of `a` is zero and `len` is a multiple of 4 (or `N`), since
/// the four partial sums then group the entries alike.
#[inline]
fn dot_prefix<T: Real, const N: usize>(a: &[T; N], b: &[T; N], len: usize) -> T {
    dot4(a.get(..len).unwrap_or(a), b.get(..len).unwrap_or(b))
}

/// Entry of the working-set matrix `m̃_c1ᵀ m̃_c2`.
#[inline]
fn mdot<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    c1: ConstraintIndex,
    c2: ConstraintIndex,
) -> T {
    con_row(p, c1).dot_row(&con_row(p, c2))
}

/// `1/ρ` for a soft row, else 0.
#[inline]
fn delta<T: Real, const N: usize, const M: usize>(p: &QpProblem<T, N, M>, c: ConstraintIndex) -> T {
    match c {
        ConstraintIndex::Row(i) => {
            let rho = p.soft[i as usize];
            if rho > T::ZERO {
                T::ONE / rho
            } else {
                T::ZERO
            }
        }
        ConstraintIndex::Bound(_) => T::ZERO,
    }
}

/// `(lo, hi)` of a constraint.
#[inline]
fn bounds_of<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    c: ConstraintIndex,
) -> (T, T) {
    match c {
        ConstraintIndex::Bound(j) => (p.x_lo[j as usize], p.x_hi[j as usize]),
        ConstraintIndex::Row(i) => (p.lo[i as usize], p.hi[i as usize]),
    }
}

/// The bound `b` at which working-set entry `e` is held: the lower or upper bound of
/// its constraint, by its side.
fn held_bound<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    e: ActiveConstraint,
) -> T {
    let (lo, hi) = bounds_of(p, e.index);
    match e.side {
        Side::Lower => lo,
        Side::Upper => hi,
    }
}

impl<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize>
    Workspace<T, N, M, W, WL>
{
    fn state_mut(&mut self, c: ConstraintIndex) -> Option<&mut Option<Side>> {
        match c {
            ConstraintIndex::Bound(j) => self.bound_state.get_mut(j as usize),
            ConstraintIndex::Row(i) => self.row_state.get_mut(i as usize),
        }
    }

    /// Whether entry `e` may be in the working set of problem `p` (in range, bound of
    /// its side finite, not already active).
    fn admissible(&self, p: &QpProblem<T, N, M>, e: ActiveConstraint) -> bool {
        let (in_range, active) = match e.index {
            ConstraintIndex::Bound(j) => {
                let j = j as usize;
                (j < N, self.bound_state.get(j).is_some_and(|s| s.is_some()))
            }
            ConstraintIndex::Row(i) => {
                let i = i as usize;
                (
                    i < p.m && i < M,
                    self.row_state.get(i).is_some_and(|s| s.is_some()),
                )
            }
        };
        if !in_range || active {
            return false;
        }
        let (lo, hi) = bounds_of(p, e.index);
        match e.side {
            Side::Lower => lo.is_finite(),
            Side::Upper => hi.is_finite(),
        }
    }

    /// Starts a solve: clears the flags and (warm start) re-activates the given
    /// working set with `λ = 0`, dropping inadmissible or dependent entries.
    fn start(&mut self, p: &mut QpProblem<T, N, M>, settings: &QpSettings<T>, tols: Tols<T>) {
        let count = if settings.warm_start { self.n } else { 0 };
        self.bound_ready.fill(false);
        // wcet-bound: WS
        for r in 0..count.min(W) {
            self.prepare(p, self.ws[r].index);
        }
        self.rebuild(p, tols, count);
        self.lam.fill(T::ZERO);
    }

    /// Transforms row constraint `c` to `a_iᵀ R⁻¹` in place, or computes bound `c`'s
    /// row `e_jᵀ R⁻¹` into the lower triangle of `h` ([`store_inverse_row`]), unless
    /// already done in this
    /// solve. Only constraints that enter the working set are ever transformed: the
    /// others are checked as `a_iᵀ x` or `x_j`.
    fn prepare(&mut self, p: &mut QpProblem<T, N, M>, c: ConstraintIndex) {
        let i = match c {
            ConstraintIndex::Row(i) => i as usize,
            ConstraintIndex::Bound(j) => {
                let j = j as usize;
                if let Some(ready) = self.bound_ready.get_mut(j) {
                    if !*ready {
                        store_inverse_row(&mut p.h, j);
                        *ready = true;
                    }
                }
                return;
            }
        };
        if i >= p.m {
            return;
        }
        let (Some(code), Some(row)) = (self.row_code.get_mut(i), p.a.get_mut(i)) else {
            return;
        };
        if *code != ROW_TRANSFORMED {
            solve_transposed(&p.h, row, 0);
            *code = ROW_TRANSFORMED;
        }
    }

    /// Rebuilds the factor from entries `ws[0..count]` (and their `lam`), dropping
    /// inadmissible and linearly dependent entries. Returns how many were dropped.
    #[inline(never)]
    fn rebuild(&mut self, p: &QpProblem<T, N, M>, tols: Tols<T>, count: usize) -> usize {
        self.row_state.fill(None);
        self.bound_state.fill(None);
        self.n = 0;
        self.updates = 0;
        let mut dropped = 0;
        // wcet-bound: WS
        for r in 0..count.min(W) {
            let e = self.ws[r];
            let l = self.lam[r];
            if !self.admissible(p, e) {
                dropped += 1;
                continue;
            }
            let k = self.n;
            match self.append(p, e, tols) {
                Ok(()) => self.lam[k] = l,
                Err(_) => dropped += 1,
            }
        }
        self.updates = 0;
        dropped
    }

    /// Appends constraint `e` as row `n` of the factor. On `Singular`, the row `n` of
    /// the packed storage holds `L_new = D⁻¹L⁻¹ M_{W,e}` but `n` is unchanged.
    #[inline(never)]
    fn append(
        &mut self,
        p: &QpProblem<T, N, M>,
        e: ActiveConstraint,
        tols: Tols<T>,
    ) -> Result<(), AppendError> {
        let n = self.n;
        if n >= W {
            return Err(AppendError::Full);
        }
        let s = row_start(n);
        // b_l = M_{l,e}
        // wcet-bound: WS
        for l in 0..n {
            self.ldl[s + l] = mdot(p, self.ws[l].index, e.index);
        }
        // Forward solve with the unit lower L: y = L⁻¹ b.
        // wcet-bound: WS
        for l in 0..n {
            let sl = row_start(l);
            let mut acc = self.ldl[s + l];
            // Σ l over l < n ≤ W (not inlined: one call, one append).
            // wcet-bound: WS * (WS - 1) / 2 per call
            for k in 0..l {
                acc -= self.ldl[sl + k] * self.ldl[s + k];
            }
            self.ldl[s + l] = acc;
        }
        let diag = mdot(p, e.index, e.index) + delta(p, e.index);
        let mut dn = diag;
        // wcet-bound: WS
        for l in 0..n {
            let dl = self.ldl[row_start(l) + l];
            let y = self.ldl[s + l];
            let lv = y / dl;
            self.ldl[s + l] = lv;
            dn -= y * lv;
        }
        self.ldl[s + n] = dn;
        self.last_rel_pivot = dn / diag;
        if !(dn > tols.pivot * diag) || !dn.is_finite() {
            return Err(AppendError::Singular);
        }
        self.commit(e);
        Ok(())
    }

    /// Makes the row `n` written by `append` part of the factor.
    fn commit(&mut self, e: ActiveConstraint) {
        let n = self.n;
        if n >= W {
            return;
        }
        self.ws[n] = e;
        if let Some(st) = self.state_mut(e.index) {
            *st = Some(e.side);
        }
        self.n = n + 1;
        self.updates += 1;
    }

    /// Removes working-set entry `p` (and its multiplier): deletes its row and column
    /// of `LDLᵀ` and updates the trailing block by a rank-one update.
    #[inline(never)]
    fn remove(&mut self, pos: usize) {
        let n = self.n;
        if pos >= n {
            return;
        }
        let e = self.ws[pos];
        if let Some(st) = self.state_mut(e.index) {
            *st = None;
        }
        let mut alpha = self.ldl[row_start(pos) + pos];
        // z (new indices pos..n-1) = old column pos of L below the diagonal.
        // `n ≤ W` (see `Workspace::n`) bounds this and every loop over the working set.
        // wcet-bound: WS
        for r in (pos + 1)..n {
            self.tmp[r - 1] = self.ldl[row_start(r) + pos];
        }
        // Shift rows pos+1..n up by one, dropping column pos (destinations precede
        // sources, so a forward copy is safe).
        // wcet-bound: WS
        for r in (pos + 1)..n {
            let src = row_start(r);
            let dst = row_start(r - 1);
            let mut k = 0;
            for c in 0..=r {
                // Bounds the `for c in 0..=r` loop above (its back edge is here):
                // Σ (r + 1) over r < n ≤ W per call.
                // wcet-bound: WS * (WS + 1) / 2 per call
                if c == pos {
                    continue;
                }
                self.ldl[dst + k] = self.ldl[src + c];
                k += 1;
            }
        }
        for r in pos..(n - 1) {
            self.ws[r] = self.ws[r + 1];
            // Bounds the `for r in pos..(n - 1)` loop (its back edge is on this line).
            self.lam[r] = self.lam[r + 1]; // wcet-bound: WS
        }
        let nn = n - 1;
        self.n = nn;
        // Rank-one update of the trailing block (rows/cols pos..nn) by alpha z zᵀ.
        for j in pos..nn {
            let pj = self.tmp[j];
            // Bounds the `for j in pos..nn` loop (the `continue` is its back edge, and
            // the compiler's loop that skips zero entries): j < nn < W per call.
            // wcet-bound: WS per call
            if pj == T::ZERO {
                continue;
            }
            let dj_idx = row_start(j) + j;
            let dj = self.ldl[dj_idx];
            let dnew = dj + alpha * pj * pj;
            let beta = pj * alpha / dnew;
            alpha = dj * alpha / dnew;
            // The j loop's back edge past an empty inner loop is here.
            // wcet-bound: WS per call
            self.ldl[dj_idx] = dnew;
            // Σ (nn − j − 1) over j < nn < W per call.
            // wcet-bound: WS * (WS - 1) / 2 per call
            for r in (j + 1)..nn {
                let idx = row_start(r) + j;
                self.tmp[r] -= pj * self.ldl[idx];
                self.ldl[idx] += beta * self.tmp[r];
            }
        }
    }

    /// Solves `(M_WW + D) x = tmp` in place in `tmp[0..n]`.
    #[inline(never)]
    fn ldl_solve_tmp(&mut self) {
        let n = self.n;
        // wcet-bound: WS
        for r in 0..n {
            let s = row_start(r);
            let mut acc = self.tmp[r];
            for k in 0..r {
                // Bounds the `for k in 0..r` loop: Σ r over r < n ≤ W per call.
                acc -= self.ldl[s + k] * self.tmp[k]; // wcet-bound: WS * (WS - 1) / 2 per call
            }
            self.tmp[r] = acc;
        }
        for r in 0..n {
            self.tmp[r] /= self.ldl[row_start(r) + r];
        }
        // Lᵀ x = y by columns of Lᵀ (rows of the packed L, contiguous): once x_r is
        // final, its share leaves the entries above it.
        // wcet-bound: WS
        for r in (1..n).rev() {
            let xr = self.tmp[r];
            if xr == T::ZERO {
                continue;
            }
            let s = row_start(r);
            let (t, l) = (
                self.tmp.get_mut(..r).unwrap_or(&mut []),
                self.ldl.get(s..s + r).unwrap_or(&[]),
            );
            // Σ r over 1 ≤ r < n ≤ W per call.
            // wcet-bound: WS * (WS - 1) / 2 per call
            for (t, &l) in t.iter_mut().zip(l) {
                *t -= l * xr;
            }
        }
    }

    /// `λ*` for the current working set, into `tmp`; false if not finite.
    fn solve_lam_star(&mut self, p: &QpProblem<T, N, M>) -> bool {
        // wcet-bound: WS
        for k in 0..self.n {
            let e = self.ws[k];
            let b = held_bound(p, e);
            self.tmp[k] = -(b + con_row(p, e.index).dot(&self.v));
        }
        self.ldl_solve_tmp();
        self.tmp.iter().take(self.n).all(|v| v.is_finite())
    }

    fn is_equality(p: &QpProblem<T, N, M>, c: ConstraintIndex) -> bool {
        let (lo, hi) = bounds_of(p, c);
        lo == hi
    }

    /// `u = −v − M̃_Wᵀ λ`, and `x = R⁻¹ u` into `x`.
    fn primal(&mut self, p: &QpProblem<T, N, M>, x: &mut [T; N]) {
        for (u, v) in self.u.iter_mut().zip(self.v.iter()) {
            *u = -*v;
        }
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k];
            if l == T::ZERO {
                continue;
            }
            let row = con_row(p, self.ws[k].index);
            if let Some(u0) = self.u.get_mut(row.start) {
                *u0 -= l * row.head;
            }
            let u = self.u.get_mut(row.start + 1..).unwrap_or(&mut []);
            // wcet-bound: NV
            for (u, r) in u.iter_mut().zip(row.tail) {
                *u -= l * *r;
            }
        }
        solve_upper(&p.h, &self.u, x);
    }

    /// Most violated inactive constraint (beyond `tol`), given `u` and `x`. `skip` is
    /// chosen only if no other constraint is violated (anti-cycling).
    fn most_violated(
        &self,
        p: &QpProblem<T, N, M>,
        x: &[T; N],
        tol: T,
        skip: Option<ConstraintIndex>,
    ) -> Option<ActiveConstraint> {
        let mut best = tol;
        let mut cand = None;
        let mut fallback = None;
        let mut consider = |val: T, lo: T, hi: T, index: ConstraintIndex| {
            let (viol, side) = if lo - val > val - hi {
                (lo - val, Side::Lower)
            } else {
                (val - hi, Side::Upper)
            };
            if Some(index) == skip {
                if viol > tol {
                    fallback = Some(ActiveConstraint { index, side });
                }
            } else if viol > best {
                best = viol;
                cand = Some(ActiveConstraint { index, side });
            }
        };
        // wcet-bound: NV
        for j in 0..N {
            if self.bound_state[j].is_none() {
                consider(x[j], p.x_lo[j], p.x_hi[j], ConstraintIndex::Bound(j as u16));
            }
        }
        // wcet-bound: NC
        for i in 0..p.m.min(M) {
            if self.row_state[i].is_none() {
                // m̃_iᵀu once the row is transformed, else a_iᵀx (the same value).
                let val = match self.row_code[i] {
                    ROW_TRANSFORMED => dot_from(&p.a[i], &self.u, 0),
                    ROW_FULL => dot_from(&p.a[i], x, 0),
                    groups => dot_prefix(&p.a[i], x, 4 * groups as usize),
                };
                consider(val, p.lo[i], p.hi[i], ConstraintIndex::Row(i as u16));
            }
        }
        cand.or(fallback)
    }

    /// Refactors from scratch (dropping dependent entries) and counts it; false,
    /// and nothing done, once `max` refactorizations were made in this solve.
    fn refactor(
        &mut self,
        p: &QpProblem<T, N, M>,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
        max: u32,
    ) -> bool {
        if sol.refactorizations >= max {
            return false;
        }
        let n = self.n;
        // The MPC gives each pass what is left of the activation's
        // QP_MAX_REFACTORIZATIONS (mpc.rs `step_inner`).
        // wcet-bound: QP_MAX_REFACTORIZATIONS times per activation
        let dropped = self.rebuild(p, tols, n);
        sol.refactorizations += 1;
        sol.removed += dropped as u32;
        true
    }

    /// The main loop; returns the exit status (the solution is written by `output`).
    fn iterate(
        &mut self,
        p: &mut QpProblem<T, N, M>,
        settings: &QpSettings<T>,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
    ) -> QpStatus {
        // Anti-cycling: a constraint that left by a zero-length step (degenerate dual)
        // is re-added only if no other constraint is violated, until the next addition.
        let mut blocked: Option<ConstraintIndex> = None;
        let mut checked_refactor = false;
        loop {
            // One back edge per iteration, counted in `sol.iterations` ≤ `settings.max_iter`,
            // which the MPC (mpc.rs `step_inner`) sets to what is left of the activation's
            // `qp_max_iter` (QP_MAX_ITER on the ECU) after its earlier passes.
            // wcet-bound: QP_MAX_ITER per activation
            if sol.iterations >= settings.max_iter {
                return QpStatus::IterationLimit;
            }
            sol.iterations += 1;
            if !self.solve_lam_star(p) {
                if !self.refactor(p, tols, sol, settings.max_refactorizations) {
                    return QpStatus::NumericalError;
                }
                if !self.solve_lam_star(p) {
                    return QpStatus::NumericalError;
                }
            }
            // Blocking multiplier on the way from λ to λ*.
            let mut block: Option<(usize, T)> = None;
            for k in 0..self.n {
                let e = self.ws[k];
                // Bounds the `for k in 0..self.n` loop (n ≤ W; back edges at the `continue`s).
                // wcet-bound: WS
                if Self::is_equality(p, e.index) {
                    continue;
                }
                let sg = sign::<T>(e.side);
                let ls = sg * self.tmp[k];
                // wcet-bound: WS
                if ls < -tols.dual {
                    let l = (sg * self.lam[k]).max(T::ZERO);
                    let ratio = l / (l - ls);
                    if block.is_none_or(|(_, r)| ratio < r) {
                        block = Some((k, ratio));
                    }
                }
            }
            if let Some((pos, alpha)) = block {
                // wcet-bound: WS
                for k in 0..self.n {
                    let mut l = self.lam[k] + alpha * (self.tmp[k] - self.lam[k]);
                    let e = self.ws[k];
                    if !Self::is_equality(p, e.index) && sign::<T>(e.side) * l < T::ZERO {
                        l = T::ZERO;
                    }
                    self.lam[k] = l;
                }
                blocked = if alpha > T::ZERO {
                    None
                } else {
                    Some(self.ws[pos].index)
                };
                self.remove(pos);
                sol.removed += 1;
                continue;
            }
            for k in 0..self.n {
                self.lam[k] = self.tmp[k];
            }
            self.primal(p, &mut sol.x);
            let Some(e) = self.most_violated(p, &sol.x, tols.primal, blocked) else {
                // Optimal if the working set itself holds; if it does not, the factor is
                // inaccurate: refactor (which also drops dependent entries) once and go on.
                // The check allows 10× the primal tolerance: with 40+ active
                // constraints in f32 the factor's own rounding reaches ~10⁻³
                // relative, which is a converged optimum, not a wrong one.
                if self.working_set_holds(p, tols.primal * T::lit(10.0)) {
                    self.refine(p, &mut sol.x);
                    return QpStatus::Optimal;
                }
                if checked_refactor {
                    return QpStatus::NumericalError;
                }
                checked_refactor = true;
                if !self.refactor(p, tols, sol, settings.max_refactorizations) {
                    return QpStatus::NumericalError;
                }
                continue;
            };
            blocked = None;
            if let Err(st) = self.add(p, e, tols, sol, settings) {
                return st;
            }
        }
    }

    /// Adds the violated constraint `e`. If it depends linearly on the working set,
    /// moves `λ` along the dual null-space direction (which keeps `u` and raises the
    /// dual cost) until a multiplier reaches zero, removes that constraint and tries
    /// again (at most `W` times, each removal an iteration against `max_iter`: past
    /// it, `IterationLimit`); no multiplier reaching zero means infeasible.
    fn add(
        &mut self,
        p: &mut QpProblem<T, N, M>,
        e: ActiveConstraint,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
        settings: &QpSettings<T>,
    ) -> Result<(), QpStatus> {
        let max_iter = settings.max_iter;
        self.prepare(p, e.index);
        let p = &*p;
        let sigma = sign::<T>(e.side);
        // Multiplier the new constraint has accumulated over null-space steps.
        let mut lam_e = T::ZERO;
        let mut refactored = false;
        // `0..=W`: W + 1 attempts. Each attempt after a removal counts as an
        // iteration against `max_iter` (what is left of the activation's cap), the
        // refactor-and-retry happens once per `add`: with the main loop's QP_MAX_ITER
        // iterations, each at most one `add`, at most 2 · QP_MAX_ITER retries.
        // wcet-bound: 2 * QP_MAX_ITER per activation
        for _ in 0..=W {
            match self.append(p, e, tols) {
                Ok(()) => {
                    self.lam[self.n - 1] = lam_e;
                    sol.added += 1;
                    return Ok(());
                }
                Err(AppendError::Full) => return Err(QpStatus::WorkingSetFull),
                Err(AppendError::Singular) => {}
            }
            if !refactored && self.updates > 0 {
                // The small pivot may be accumulated rounding: refactor and retry
                // (once per `add`, within the solve's refactorization cap).
                refactored = true;
                if self.refactor(p, tols, sol, settings.max_refactorizations) {
                    continue;
                }
            }
            // Null-space direction: λ_e grows by t·σ, λ_W by t·σ·c with
            // c = −(M_WW + D)⁻¹ M_{W,e} = −L⁻ᵀ L_new.
            let n = self.n;
            let s = row_start(n);
            let mut cmax = T::ZERO;
            // wcet-bound: WS
            for r in (0..n).rev() {
                let mut acc = -self.ldl[s + r];
                for k in (r + 1)..n {
                    // Bounds the `for k in (r + 1)..n` loop: n ≤ W.
                    acc -= self.ldl[row_start(k) + r] * self.tmp[k]; // wcet-bound: WS
                }
                self.tmp[r] = acc;
                cmax = cmax.max(acc.abs());
            }
            // Rates below this are rounding noise of a zero coefficient.
            let noise = tols.noise * (T::ONE + cmax);
            let mut block: Option<(usize, T)> = None;
            for k in 0..n {
                let ek = self.ws[k];
                // Bounds the `for k in 0..n` loop (n ≤ W; back edges at the `continue`s).
                // wcet-bound: WS
                if Self::is_equality(p, ek.index) {
                    continue;
                }
                let sg = sign::<T>(ek.side);
                let rate = sg * sigma * self.tmp[k];
                // wcet-bound: WS
                if rate < -noise {
                    let t = (sg * self.lam[k]).max(T::ZERO) / -rate;
                    if block.is_none_or(|(_, r)| t < r) {
                        block = Some((k, t));
                    }
                }
            }
            let Some((pos, t)) = block else {
                // No multiplier limits the ray. With an exactly dependent row the dual
                // is unbounded: infeasible. With a small but real pivot (nearly
                // dependent, not at rounding level) the dual is bounded along the ray:
                // the row is taken as independent after all, with its small pivot.
                let rel = self.last_rel_pivot;
                if rel.is_finite() && rel > tols.rounding {
                    self.commit(e);
                    self.lam[self.n - 1] = lam_e;
                    sol.added += 1;
                    return Ok(());
                }
                return Err(QpStatus::Infeasible);
            };
            // wcet-bound: WS
            for k in 0..n {
                let mut l = self.lam[k] + t * sigma * self.tmp[k];
                let ek = self.ws[k];
                if !Self::is_equality(p, ek.index) && sign::<T>(ek.side) * l < T::ZERO {
                    l = T::ZERO;
                }
                self.lam[k] = l;
            }
            lam_e += t * sigma;
            if sol.iterations >= max_iter {
                return Err(QpStatus::IterationLimit);
            }
            sol.iterations += 1;
            self.remove(pos);
            sol.removed += 1;
        }
        Err(QpStatus::NumericalError)
    }

    /// One step of iterative refinement of the multipliers at the optimum: the
    /// residuals `r_k = m̃_kᵀu − b_k − λ_k/ρ_k` of the working-set equations give
    /// `Δλ = (M̃_W M̃_Wᵀ + D_W)⁻¹ r` with the same factor; kept (and `u`, `x`
    /// recomputed) only if every multiplier keeps its sign.
    fn refine(&mut self, p: &QpProblem<T, N, M>, x: &mut [T; N]) {
        // wcet-bound: WS
        for k in 0..self.n {
            let e = self.ws[k];
            let b = held_bound(p, e);
            self.tmp[k] = con_row(p, e.index).dot(&self.u) - b - self.lam[k] * delta(p, e.index);
        }
        self.ldl_solve_tmp();
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k] + self.tmp[k];
            let e = self.ws[k];
            if !l.is_finite() || (!Self::is_equality(p, e.index) && sign::<T>(e.side) * l < T::ZERO)
            {
                return;
            }
        }
        for k in 0..self.n {
            self.lam[k] += self.tmp[k];
        }
        self.primal(p, x);
    }

    /// Whether every working-set constraint holds at `u`: `m̃_kᵀu = b_k + λ_k/ρ_k`
    /// within `tol` relative to `1 + |b_k + λ_k/ρ_k|`.
    fn working_set_holds(&self, p: &QpProblem<T, N, M>, tol: T) -> bool {
        // `n ≤ W` entries checked.
        // wcet-bound: WS
        (0..self.n).all(|k| {
            let e = self.ws[k];
            let b = held_bound(p, e);
            let val = con_row(p, e.index).dot(&self.u);
            let target = b + self.lam[k] * delta(p, e.index);
            // Relative to the magnitudes involved: rows are formed in the working
            // precision, so their rounding scales with them.
            (val - target).abs() <= tol * (T::ONE + target.abs().max(val.abs()))
        })
    }

    /// Writes `x` (unless `fresh`), multipliers and cost for the current iterate.
    /// `fresh`: `u` and `sol.x` already belong to the current multipliers (the
    /// optimal exit), so the primal point is not recomputed.
    fn output(&mut self, p: &QpProblem<T, N, M>, sol: &mut QpSolution<T, N, M>, fresh: bool) {
        if !fresh {
            self.primal(p, &mut sol.x);
        }
        sol.lambda_rows.fill(T::ZERO);
        sol.lambda_bounds.fill(T::ZERO);
        let mut soft_cost = T::ZERO;
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k];
            match self.ws[k].index {
                ConstraintIndex::Bound(j) => {
                    if let Some(d) = sol.lambda_bounds.get_mut(j as usize) {
                        *d = l;
                    }
                }
                ConstraintIndex::Row(i) => {
                    if let Some(d) = sol.lambda_rows.get_mut(i as usize) {
                        *d = l;
                    }
                    soft_cost += T::HALF * l * l * delta(p, self.ws[k].index);
                }
            }
        }
        let mut c = T::ZERO;
        for (u, v) in self.u.iter().zip(self.v.iter()) {
            c += *u * (T::HALF * *u + *v);
        }
        sol.objective = c + soft_cost;
        sol.working_set_len = self.n as u16;
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]
    use super::*;

    type S = QpSolver<f64, 5, 8, 8, { ldl_len(8) }>;

    /// Deterministic pseudo-random numbers in [-1, 1).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn filled(seed: u64) -> S {
        let mut s = S::new();
        let mut st = seed;
        let p = s.problem_mut();
        let mut g = [[0.0; 5]; 5];
        for r in g.iter_mut() {
            for v in r.iter_mut() {
                *v = lcg(&mut st);
            }
        }
        for r in 0..5 {
            for c in 0..5 {
                p.h[r][c] =
                    (0..5).map(|k| g[k][r] * g[k][c]).sum::<f64>() + if r == c { 0.3 } else { 0.0 };
            }
            p.f[r] = lcg(&mut st);
            p.x_lo[r] = -1.0;
            p.x_hi[r] = 1.0;
        }
        for i in 0..8 {
            let mut a = [0.0; 5];
            for v in a.iter_mut() {
                *v = lcg(&mut st);
            }
            let soft = if i % 3 == 0 { 2.0 + lcg(&mut st) } else { 0.0 };
            p.push_row(&a, -1.0, 1.0, soft);
        }
        s
    }

    #[test]
    fn cholesky_and_triangular_solves_invert_h() {
        let mut s = filled(3);
        let h = s.problem.h;
        assert!(factor_h(&mut s.problem.h));
        let r = &s.problem.h;
        // The rows of R⁻¹ from the forward solve: H · R⁻¹ R⁻ᵀ = I.
        let mut ri = [[0.0; 5]; 5];
        for (j, row) in ri.iter_mut().enumerate() {
            inverse_row(r, j, row);
        }
        // Back substitution: R⁻¹ e_j is column j of R⁻¹.
        for j in 0..5 {
            let mut e = [0.0; 5];
            e[j] = 1.0;
            let mut col = [0.0; 5];
            solve_upper(r, &e, &mut col);
            for k in 0..5 {
                assert!((col[k] - ri[k][j]).abs() < 1e-12, "R⁻¹[{k}][{j}]");
            }
        }
        for r in 0..5 {
            for c in 0..5 {
                let mut v = 0.0;
                for k in 0..5 {
                    let hk = if k >= r { h[r][k] } else { h[k][r] };
                    let mut inv = 0.0;
                    for q in 0..5 {
                        inv += ri[k][q] * ri[c][q];
                    }
                    v += hk * inv;
                }
                let want = if r == c { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-10, "({r},{c}) = {v}");
            }
        }
    }

    /// Every bound's row of `R⁻¹`, stored in the lower triangle of `h` next to `R`,
    /// reads back as `e_jᵀ R⁻¹` (checked against `R⁻¹ e_k` by back substitution),
    /// and the rows' products are those of `R⁻¹`'s rows.
    #[test]
    fn bound_rows_in_the_lower_triangle_are_rows_of_the_inverse() {
        let mut s = filled(5);
        assert!(factor_h(&mut s.problem.h));
        let r = s.problem.h;
        // Columns of R⁻¹ from the upper triangle alone, before any row is stored.
        let mut inv = [[0.0; 5]; 5];
        for k in 0..5 {
            let mut e = [0.0; 5];
            e[k] = 1.0;
            let mut col = [0.0; 5];
            solve_upper(&r, &e, &mut col);
            for j in 0..5 {
                inv[j][k] = col[j];
            }
        }
        transform(&mut s.problem, &mut s.work);
        // R itself is untouched.
        for j in 0..5 {
            for k in j..5 {
                assert_eq!(s.problem.h[j][k], r[j][k]);
            }
        }
        for j in 0..5u16 {
            let row = con_row(&s.problem, ConstraintIndex::Bound(j));
            assert_eq!(row.start, j as usize);
            let mut full = [0.0; 5];
            full[row.start] = row.head;
            full[row.start + 1..].copy_from_slice(row.tail);
            for k in 0..5 {
                assert!(
                    (full[k] - inv[j as usize][k]).abs() < 1e-12,
                    "R⁻¹[{j}][{k}]"
                );
            }
            for i in 0..5u16 {
                let want: f64 = (0..5)
                    .map(|k| inv[i as usize][k] * inv[j as usize][k])
                    .sum();
                let got = mdot(
                    &s.problem,
                    ConstraintIndex::Bound(i),
                    ConstraintIndex::Bound(j),
                );
                assert!((got - want).abs() < 1e-12, "({i}, {j})");
            }
        }
    }

    /// Removing an entry by downdate gives the same factor as factorising the
    /// remaining working set from scratch.
    #[test]
    fn remove_matches_refactor() {
        for seed in 0..20u64 {
            let mut s = filled(seed);
            assert!(factor_h(&mut s.problem.h));
            transform(&mut s.problem, &mut s.work);
            let tols = QpSettings::<f64>::new(10).effective();
            let set = [
                ConstraintIndex::Row(0),
                ConstraintIndex::Bound(1),
                ConstraintIndex::Row(3),
                ConstraintIndex::Row(4),
                ConstraintIndex::Bound(3),
                ConstraintIndex::Row(6),
                ConstraintIndex::Row(2),
            ];
            for &c in &set {
                let e = ActiveConstraint {
                    index: c,
                    side: Side::Upper,
                };
                s.work.append(&s.problem, e, tols).unwrap();
            }
            for pos in [2usize, 0, 4] {
                s.work.remove(pos);
                let n = s.work.n;
                let down = s.work.ldl;
                let dropped = s.work.rebuild(&s.problem, tols, n);
                assert_eq!(dropped, 0);
                assert_eq!(s.work.n, n);
                for k in 0..ldl_len(n) {
                    assert!(
                        (down[k] - s.work.ldl[k]).abs() < 1e-10,
                        "seed {seed} pos {pos} k {k}"
                    );
                }
            }
        }
    }

    #[test]
    fn dependent_rows_are_refused_by_append() {
        let mut s = filled(1);
        let a0 = s.problem.a[0];
        s.problem.a[1] = a0;
        s.problem.soft[0] = 0.0;
        s.problem.soft[1] = 0.0;
        assert!(factor_h(&mut s.problem.h));
        transform(&mut s.problem, &mut s.work);
        let tols = QpSettings::<f64>::new(10).effective();
        let e = |i| ActiveConstraint {
            index: ConstraintIndex::Row(i),
            side: Side::Upper,
        };
        assert_eq!(s.work.append(&s.problem, e(0), tols), Ok(()));
        assert_eq!(
            s.work.append(&s.problem, e(1), tols),
            Err(AppendError::Singular)
        );
        // A soft copy is not dependent: its pivot is at least 1/ρ.
        s.problem.soft[1] = 4.0;
        assert_eq!(s.work.append(&s.problem, e(1), tols), Ok(()));
        assert!((s.work.ldl[row_start(1) + 1] - 0.25).abs() < 1e-12);
    }
}
