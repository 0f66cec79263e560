//! The problem data and the names of its constraints (bounds and rows, their sides).

use crate::Real;

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

/// The problem data, filled in place by the caller (see [`QpSolver::problem_mut`](crate::QpSolver::problem_mut)).
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
    /// updates (Householder reflections in the firmware's `mpc.rs`): `R`'s condition number is the square root
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
