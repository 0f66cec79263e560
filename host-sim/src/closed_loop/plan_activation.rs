//! One activation of the plan task, as the ECU (modelled or measured) ran it:
//! [`PlanActivation`], a row of `plan_activations.csv`, and the names of its
//! statuses ([`plan_status_name`], [`mpc_error_name`]).

use serde::Serialize;

/// A plan status's name, one of [`plan_status_name`]'s (an alias, so that serde's
/// derive does not take it for a string borrowed from the input).
pub type StatusName = &'static str;

/// One activation of the plan task, as the ECU (modelled or measured) ran it: a
/// row of `plan_activations.csv`, written by `run` and `pil` and read back by the
/// timing report and the cost model's fit through this same type.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct PlanActivation {
    /// 1-based count of the task's releases (skipped releases included).
    pub activation: u32,
    /// Release time, µs.
    pub release_us: u64,
    /// When it finished (response time = finish − release), µs.
    pub finish_us: u64,
    /// Instructions of the task's own execution (modelled: from the cost model;
    /// processor in the loop: measured): its planning, or its adoption of a
    /// window of the road (`window`).
    pub instructions: f64,
    /// `instructions` × cycles per instruction (see [`CostModel`](super::cost_model::CostModel)), ECU cycles.
    pub cycles: f64,
    /// `"optimal"`, `"window"` ([`WINDOW_STATUS`]: the activation adopted a
    /// window instead of planning) or the failure's name ([`plan_status_name`]).
    #[serde(deserialize_with = "known_plan_status")]
    pub status: StatusName,
    /// The plan was published (at `finish_us`).
    pub published: bool,
    /// The response time exceeded the period (100 ms).
    pub deadline_miss: bool,
    /// Linearise–condense passes.
    pub passes: u32,
    /// Whether the MPC started from the previous plan (false on a cold start,
    /// and on an activation that adopted a window instead of planning; false in
    /// a file written before the column existed).
    #[serde(default)]
    pub warm: bool,
    /// QP iterations, all passes.
    pub qp_iterations: u32,
    /// Constraints added to the QP's working set, all passes.
    pub qp_added: u32,
    /// Constraints removed from the QP's working set, all passes.
    pub qp_removed: u32,
    /// Factorisations of the working set from scratch, all passes.
    pub qp_refactorizations: u32,
    /// General QP rows of the last pass.
    pub rows: u32,
    /// Working-set size at the end of the last pass.
    pub active_constraints: u32,
    /// The activation adopted a new window of the road instead of planning.
    #[serde(default)]
    pub window: bool,
    /// Instructions of that adoption (then equal to `instructions`), 0 without a
    /// window.
    #[serde(default)]
    pub window_instructions: f64,
    /// Frames of the road the activation received before planning or adopting
    /// (0 or 1), frames.
    #[serde(default)]
    pub route_frames: u32,
    /// Largest validity slack of the plan, rad (0 if none or not optimal); `None`
    /// (an empty cell) where it is not measured (the ECU does not send it).
    #[serde(default)]
    pub max_validity_slack_rad: Option<f64>,
}

impl PlanActivation {
    /// Whether the activation planned (ran the MPC) from the previous plan.
    pub fn plans_warm(&self) -> bool {
        self.passes >= 1 && self.warm
    }

    /// Whether the activation planned (ran the MPC) from zero inputs: a cold start.
    pub fn plans_cold(&self) -> bool {
        self.passes >= 1 && !self.warm
    }
}

/// The status of an activation that adopted a new window of the road instead of
/// planning (`firmware::link::PLAN_WINDOW`): it publishes nothing, and is not a
/// failure.
pub const WINDOW_STATUS: &str = "window";

/// The name of a plan activation's status code (`firmware::link`'s
/// [`PlanEventFrame::status`](firmware::link::PlanEventFrame)): `"optimal"`, the
/// error's name ([`mpc_error_name`]), or `"unknown"`.
pub fn plan_status_name(code: u8) -> &'static str {
    match firmware::link::mpc_error_from_code(code) {
        None if code == firmware::link::MPC_OK => "optimal",
        None if code == firmware::link::PLAN_WINDOW => WINDOW_STATUS,
        None => "unknown",
        Some(e) => mpc_error_name(&e),
    }
}

/// Reads a status name back as the name [`plan_status_name`] gives (refusing a
/// name no code has).
fn known_plan_status<'de, D: serde::Deserializer<'de>>(d: D) -> Result<&'static str, D::Error> {
    let name = <std::borrow::Cow<'de, str> as serde::Deserialize>::deserialize(d)?;
    (0..=u8::MAX)
        .map(plan_status_name)
        .find(|n| *n == name)
        .ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown plan status `{name}` (expected `optimal`, `window` or an MPC error's name)"
            ))
        })
}

/// The name of an MPC failure, as written in the log and the activations.
pub fn mpc_error_name(e: &firmware::mpc::MpcError) -> &'static str {
    use firmware::mpc::MpcError as E;
    use qp::QpStatus as Q;
    match e {
        E::NonFiniteState => "non_finite_state",
        E::InvalidFriction => "invalid_friction",
        E::InvalidSettings => "invalid_settings",
        E::NoPath => "no_path",
        E::NonFinitePlan => "non_finite_plan",
        E::Qp(Q::IterationLimit) => "qp_iteration_limit",
        E::Qp(Q::Infeasible) => "qp_infeasible",
        E::Qp(Q::NumericalError) => "qp_numerical_error",
        E::Qp(Q::NotConvex) => "qp_not_convex",
        E::Qp(Q::NonFiniteInput) => "qp_non_finite_input",
        E::Qp(Q::InvalidInput) => "qp_invalid_input",
        E::Qp(Q::WorkingSetFull) => "qp_working_set_full",
        E::Qp(Q::NotSolved) => "qp_not_solved",
        E::Qp(Q::Optimal) => "optimal",
    }
}
