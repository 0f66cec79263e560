//! Solver settings: tolerances and the iteration and refactorization caps.

use crate::Real;

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
    /// past the cap the solve ends with [`QpStatus::NumericalError`](crate::QpStatus::NumericalError). Bounds the
    /// worst-case time of a solve with the iteration cap.
    pub max_refactorizations: u32,
    /// Start from the working set left by the previous solve (or set with
    /// [`QpSolver::set_working_set`](crate::QpSolver::set_working_set)) instead of an empty one.
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

    pub(crate) fn effective(&self) -> Tols<T> {
        let sqrt_eps = T::EPSILON.sqrt();
        let pick = |v: T, d: T| if v > T::ZERO { v } else { d };
        // Single precision (ε ≈ 1.2e-7) or double (ε ≈ 2.2e-16); the pivot levels were
        // tuned on degenerate random problems (qp/tests/qp_precision.rs, qp/tests/qp_kkt.rs).
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

/// The tolerances a solve uses ([`QpSettings`] with its zeros replaced by the
/// precision defaults).
#[derive(Clone, Copy)]
pub(crate) struct Tols<T> {
    pub(crate) primal: T,
    pub(crate) dual: T,
    pub(crate) pivot: T,
    /// Relative pivot at rounding level (`ε^¾`): below it a row is exactly dependent.
    pub(crate) rounding: T,
    /// Relative size below which a null-space coefficient is rounding noise (`√ε`).
    pub(crate) noise: T,
}
