//! The plan: what the 10 Hz `plan` task publishes and the 100 Hz `control` task follows.
//!
//! A plan is the MPC's predicted trajectory of the kinematic bicycle model at
//! `HORIZON + 1` nodes spaced by [`Plan::dt_s`], starting at the state estimate the
//! planner was released on (node 0, time stamp [`Plan::stamp_us`]), and the piecewise
//! constant inputs between nodes.

use crate::Real;
use qp::real::finite_probe;

/// Number of control intervals of the MPC horizon (the paper's `N_u = T_H/Δt_u + 1 = 16`).
pub const HORIZON: usize = 16;

/// Duration of one MPC control interval `Δt_u`, s (the paper's 0.2 s).
pub const PLAN_DT_S: f32 = 0.2;

/// One node of a planned trajectory (the state `ξ = [s, X, Y, V, ψ, δ]` of the paper).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanNode<T> {
    /// Curvilinear abscissa along the reference path, m.
    pub s_m: T,
    /// Global X position of the centre of gravity, m.
    pub x_m: T,
    /// Global Y position of the centre of gravity, m.
    pub y_m: T,
    /// Speed, m/s.
    pub v_mps: T,
    /// Yaw angle, rad (counter-clockwise from the global X axis, not wrapped).
    pub psi_rad: T,
    /// Front steering angle, rad (positive to the left).
    pub delta_rad: T,
}

/// A complete plan: the trajectory and the inputs that produce it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plan<T> {
    /// Time of node 0 (the planner's release), µs since start.
    pub stamp_us: u64,
    /// Spacing of the nodes, s.
    pub dt_s: T,
    /// Predicted states at `stamp_us + k·dt_s`, `k = 0..=HORIZON`.
    pub nodes: [PlanNode<T>; HORIZON + 1],
    /// Inputs on interval `k`: `[u1 = acceleration m/s², u2 = steering rate rad/s]`.
    pub inputs: [[T; 2]; HORIZON],
    /// The local velocity planner's `V_heur` at each node, m/s (for logs).
    pub v_heur_mps: [T; HORIZON + 1],
}

impl<T: Real> Plan<T> {
    /// An empty plan (all zero), stamped at 0; a valid `const` initialiser.
    pub const fn zeroed() -> Self {
        let node = PlanNode {
            s_m: T::ZERO,
            x_m: T::ZERO,
            y_m: T::ZERO,
            v_mps: T::ZERO,
            psi_rad: T::ZERO,
            delta_rad: T::ZERO,
        };
        Self {
            stamp_us: 0,
            dt_s: T::ZERO,
            nodes: [node; HORIZON + 1],
            inputs: [[T::ZERO; 2]; HORIZON],
            v_heur_mps: [T::ZERO; HORIZON + 1],
        }
    }

    /// Duration covered by the plan, s.
    pub fn duration_s(&self) -> T {
        self.dt_s * T::from_usize(HORIZON)
    }

    /// True when every number the low-level control may read is finite: `dt_s`,
    /// the nodes and the inputs ([`finite_probe`]: one pass, no branch per value).
    /// [`crate::tasks::PlanTask`] publishes no plan that fails it, so the control
    /// task checks only the values it reads.
    pub fn is_finite(&self) -> bool {
        let mut acc = finite_probe([self.dt_s]);
        for n in &self.nodes {
            acc += finite_probe([n.s_m, n.x_m, n.y_m, n.v_mps, n.psi_rad, n.delta_rad]);
        }
        for u in &self.inputs {
            acc += finite_probe(*u);
        }
        acc == T::ZERO
    }
}
