//! One recorded QP, one JSON file of the corpus ([`CorpusEntry`]; its keys are in
//! [`crate::qp_corpus`]'s docs): the problem in standard and native form, our
//! solution, status and counters, and the working set its solve started from.

use firmware::mpc::{MpcQpProblem, MpcQpSolution, NV};
use firmware::Real;
use qp::{ActiveConstraint, ConstraintIndex, QpStatus, Side};
use serde::{Deserialize, Serialize};

use crate::closed_loop::Precision;
use crate::qp_corpus::native::NativeQp;
use crate::qp_corpus::standard::StandardQp;

/// Number of decision variables of the MPC's QP (the inputs over the horizon).
pub const N_DECISION: usize = NV;

/// One recorded QP: one JSON file of the corpus (keys in [`crate::qp_corpus`]'s docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorpusEntry {
    /// The standard form (keys `n`, `m`, `H`, `f`, `A`, `lower`, `upper`).
    #[serde(flatten)]
    pub standard: StandardQp,
    /// Our solution in the standard form's variables (inputs, then slacks).
    pub x: Vec<f64>,
    /// Our solver's status ([`status_name`]).
    pub status: String,
    /// Our solver's iterations.
    pub iterations: u32,
    /// Number of leading variables that are MPC inputs (32).
    pub n_decision: usize,
    /// Our solver's own form of the problem.
    pub native: NativeQp,
    /// `"f64"` or `"f32"`: the precision of the MPC run.
    pub precision: String,
    /// MPC step (0.1 s of closed loop each) that solved this QP.
    pub step: usize,
    /// Pass within the step (a cold start runs several).
    pub pass: u32,
    /// Our objective `½xᵀHx + fᵀx + Σ ½ρ_i s_i²`, cost units.
    pub objective: f64,
    /// Constraints added to our working set.
    pub added: u32,
    /// Constraints removed from our working set.
    pub removed: u32,
    /// Our from-scratch refactorisations.
    pub refactorizations: u32,
    /// With `qp-corpus --time`: our f64 solver's time on this QP from an empty working
    /// set, µs (median of the repetitions; see [`time_solves`](crate::qp_corpus::replay::time_solves) for what is timed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solve_us_cold: Option<f64>,
    /// With `qp-corpus --time`: the same, warm-started from the working set the MPC's
    /// solve started from (`warm_start`), µs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solve_us_warm: Option<f64>,
    /// The working set our solve started from (the MPC's warm start), in order.
    #[serde(default)]
    pub warm_start: Vec<WarmStartEntry>,
}

/// One entry of the working set a corpus QP's solve started from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WarmStartIndex {
    /// The bound on variable `j`.
    Bound(u16),
    /// General row `i` of the native problem.
    Row(u16),
}

/// One entry of `warm_start`: the constraint and the side held (`"lower"`, `"upper"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WarmStartEntry {
    /// The constraint.
    #[serde(flatten)]
    pub index: WarmStartIndex,
    /// `"lower"` or `"upper"`.
    pub side: WarmStartSide,
}

/// The side of a working-set entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WarmStartSide {
    /// Held at its lower bound.
    Lower,
    /// Held at its upper bound.
    Upper,
}

impl WarmStartEntry {
    /// From the solver's working-set entry.
    pub fn from_active(e: &ActiveConstraint) -> Self {
        Self {
            index: match e.index {
                ConstraintIndex::Bound(j) => WarmStartIndex::Bound(j),
                ConstraintIndex::Row(i) => WarmStartIndex::Row(i),
            },
            side: match e.side {
                Side::Lower => WarmStartSide::Lower,
                Side::Upper => WarmStartSide::Upper,
            },
        }
    }

    /// The solver's working-set entry.
    pub fn to_active(self) -> ActiveConstraint {
        ActiveConstraint {
            index: match self.index {
                WarmStartIndex::Bound(j) => ConstraintIndex::Bound(j),
                WarmStartIndex::Row(i) => ConstraintIndex::Row(i),
            },
            side: match self.side {
                WarmStartSide::Lower => Side::Lower,
                WarmStartSide::Upper => Side::Upper,
            },
        }
    }
}

/// The corpus name of a solver status (`"optimal"`, `"iteration_limit"`, …).
pub fn status_name(s: QpStatus) -> &'static str {
    match s {
        QpStatus::NotSolved => "not_solved",
        QpStatus::Optimal => "optimal",
        QpStatus::IterationLimit => "iteration_limit",
        QpStatus::Infeasible => "infeasible",
        QpStatus::NotConvex => "not_convex",
        QpStatus::NumericalError => "numerical_error",
        QpStatus::NonFiniteInput => "non_finite_input",
        QpStatus::InvalidInput => "invalid_input",
        QpStatus::WorkingSetFull => "working_set_full",
    }
}

impl CorpusEntry {
    /// Builds an entry from the problem as given to the solver and the solution it
    /// returned.
    pub fn from_solve<T: Real>(
        problem: &MpcQpProblem<T>,
        solution: &MpcQpSolution<T>,
        max_iter: u32,
        precision: Precision,
        step: usize,
        pass: u32,
    ) -> Self {
        let mut native = NativeQp::from_problem(problem);
        native.max_iter = max_iter;
        let lambda: Vec<f64> = solution.lambda_rows.iter().map(|v| v.to_f64()).collect();
        let mut x: Vec<f64> = solution.x.iter().map(|v| v.to_f64()).collect();
        x.extend(native.slacks_from_multipliers(&lambda));
        Self {
            standard: native.to_standard(),
            x,
            status: status_name(solution.status).to_string(),
            iterations: solution.iterations,
            n_decision: NV,
            native,
            precision: precision.name().to_string(),
            step,
            pass,
            objective: solution.objective.to_f64(),
            added: solution.added,
            removed: solution.removed,
            refactorizations: solution.refactorizations,
            solve_us_cold: None,
            solve_us_warm: None,
            warm_start: Vec::new(),
        }
    }
}
