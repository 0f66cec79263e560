//! How a solve ended and what it returns.

use crate::Real;

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
    /// refilled (see [`QpSolver::problem_mut`](crate::QpSolver::problem_mut)).
    InvalidInput,
    /// A constraint had to enter a working set already holding `W` constraints.
    WorkingSetFull,
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
