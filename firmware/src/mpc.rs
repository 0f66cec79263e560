//! The local MPC planner (the paper's Section III C).
//!
//! # Problem
//!
//! Over `N = HORIZON = 16` intervals of `Δt_u = 0.2 s`, with the kinematic bicycle
//! state `ξ = [s, X, Y, V, ψ, δ]` and inputs `u = [u1 = a, u2 = δ̇]`:
//!
//! ```text
//! min  Σ_{k=1..N} q_v (V_k − V_heur,k)² + q_Δ (δ_k − δ_ref,k)² + q_x e_x,k² + q_y e_y,k²
//!    + Σ_{k=0..N−1} q_δ̇ u2,k² + q_a u1,k²
//!    + Σ soft-constraint penalties  q_δtol δ_tol² + q_obs obs_tol² + q_road road_tol²
//! s.t. ξ_{k+1} = F(ξ_k, u_k)  (RK4 discretisation of the kinematic bicycle, ṡ = V)
//!      ξ_0 = the state estimate (s from its projection on the path)
//!      u1 ∈ [−8, 6] m/s²,  u2 ∈ [−0.5, 0.5] rad/s                 (hard)
//!      |δ_k| ≤ δ_max(V_k) + δ_tol,k                                (soft, validity)
//!      −(w_right − b) − road_tol ≤ e_y,k ≤ (w_left − b) + road_tol  (soft, road limits)
//!      g_o(X_k, Y_k) ≥ −obs_tol   for each obstacle parabola o     (soft)
//!      V_k ≥ 0 where the linearised V̄_k < 1 m/s                    (soft, no reversing)
//! ```
//!
//! `e_x`, `e_y` are the longitudinal and lateral deviations of `(X_k, Y_k)` from the
//! path point at `s_k`. The paper writes them as slack variables `x_tol`, `y_tol`
//! bounded by a tolerance margin; with a zero margin those slacks equal `|e_x|`,
//! `|e_y|` at the optimum, so we keep them in the objective exactly, as quadratic
//! costs, and encode the road limits as separate soft rows. `δ_ref` is 0 as in the
//! paper ([`SteeringReference::Zero`]) or, by default, the kinematic steering of the
//! path curvature at `s_k` ([`SteeringReference::PathCurvature`]), which removes the
//! steady bias of penalising a steering angle that a curve needs.
//!
//! # Method: real-time iteration, condensed, on our QP solver
//!
//! 1. Shift: the previous optimal inputs are re-sampled at the new release time
//!    (averaged over each new interval), giving `ū`; a cold start uses `ū = 0` and
//!    [`MpcSettings::cold_start_iterations`] Gauss–Newton passes.
//! 2. Linearise: simulate `ξ̄` from `ξ_0` under `ū`; the Jacobians of the discrete map
//!    give the sensitivities `S_k = ∂ξ_k/∂u` (6 × 32) recursively,
//!    `S_{k+1} = A_k S_k + B_k E_k`, so `ξ_k ≈ ξ̄_k + S_k (u − ū)`.
//!    `ξ_k` depends only on the inputs before node `k`, so `S_k`'s columns from
//!    `NU·k` on are zero: every product, cost row and constraint row of node `k`
//!    runs over its first `NU·k` columns only.
//! 3. Condense: every cost term and constraint is an affine function of `u` through a
//!    row of `S_k`; constraints become rows of `A`; costs add rank-one terms to `H`,
//!    which is kept as its factor `R` (`H = RᵀR`, single precision could not hold
//!    `H` itself): each node's four cost rows join `R` as one block of Householder
//!    reflections. The QP has the 32 inputs as variables and no state or slack
//!    variables: soft constraints are handled inside the solver (a `1/ρ` on its
//!    dual diagonal). In code, [`Mpc`]'s `condense` calls the steps by name:
//!    input bounds and regularisation, friction ellipse, linearise, tracking
//!    costs, road row, validity rows, obstacle rows.
//! 4. Solve, warm-started from the previous working set (input bounds by
//!    variable, rows by what they constrain: kind, node and obstacle, since an
//!    obstacle row appearing at an early node renumbers the later rows), and
//!    re-simulate the nonlinear model under the optimal inputs (no Jacobians
//!    needed there:
//!    [`BicycleGeometry::step`]): that trajectory is the plan.
//!
//! All sizes are constants; the workspace [`Mpc`] (solver, warm start and the
//! pass's scratch: sensitivities, cost block, row) is `const`-constructible for a
//! `static` on the ECU, which keeps the step's stack frames small.
//!
//! This file holds the settings, the workspace and the step; the submodule
//! `condensing` the linearise–condense pass (steps 2 and 3), `warm_start` the
//! shift of the previous inputs and the working set carried over by row identity
//! (steps 1 and 4).

// Index loops mirror the maths of the condensing; all ranges are const-bounded.
#![allow(clippy::needless_range_loop)]

mod condensing;
mod warm_start;

use condensing::Condensing;
use warm_start::{interpolate_nodes, shift_inputs, RowKind, WarmEntry};

use crate::bicycle::{self, BicycleGeometry};
use crate::obstacles::{obstacle_speed_cap, Parabola, Side};
use crate::plan::{Plan, HORIZON, PLAN_DT_S};
use crate::reference_path::{CurvatureWindow, ReferencePath};
use crate::sideslip::SideslipConfig;
use crate::state_estimate::StateEstimate;
use crate::validity::{kinematic_steering_for_radius, ValidityLimit};
use crate::velocity_planner::{self, VelocityPlannerSettings};
use crate::Real;
use qp::{
    ldl_len, ActiveConstraint, ConstraintIndex, QpProblem, QpSolution, QpSolver, QpStatus,
    Side as QpSide,
};

pub use crate::bicycle::{NU, NX};
/// Number of QP variables: the inputs over the horizon.
pub const NV: usize = NU * HORIZON;
/// Constraint rows each node always has: validity (2) and road limits (1).
pub const ROWS_PER_NODE: usize = 3;
/// Capacity for obstacle rows over the whole horizon (one per obstacle and node
/// where its parabola matters, nearest nodes first).
pub const MAX_OBSTACLE_ROWS: usize = 32;
/// Capacity of general QP rows.
pub const NC: usize = ROWS_PER_NODE * HORIZON + MAX_OBSTACLE_ROWS;
/// Working-set capacity of the QP solver, rows: more than the [`NV`] variables,
/// since soft rows (obstacles, `V ≥ 0`) may all be active (a car standing by an
/// obstacle: 37–40 active rows, `docs/tuning.md`). With [`QP_MAX_ITER`] it sizes
/// the plan task's static bound (its factor's work grows as `WS²` per iteration).
pub const WS: usize = 48;
/// QP iterations one activation may run, summed over its passes
/// ([`MpcSettings::qp_max_iter`] of [`MpcSettings::paper`], the ECU's settings):
/// the flow fact that bounds the plan task's worst case. With [`WS`] 48, one
/// cold pass and no refactorization, the largest cap whose static bound of the
/// plan job stays within 75 % of its budget (`host-sim wcet --static-only`;
/// docs/timing.md, *How the plan task fits its budget*). A step stopped at the
/// cap gives no plan (the control task follows the last one) and the next goes
/// on from its working set.
pub const QP_MAX_ITER: u32 = 79;
/// QP refactorizations one activation may make, summed over its passes (each
/// pass gets what is left as its [`qp::QpSettings::max_refactorizations`]):
/// with [`QP_MAX_ITER`], the flow fact that bounds the plan task's worst case. A
/// refactorization rebuilds the factor of up to [`WS`] rows (about `WS³/6`
/// multiply-adds and the `WS²/2` products of its rows), which the static bound
/// charges as about ten iterations. None: the stress sweep fails fewer plan
/// steps with the iterations they buy (docs/tuning.md, *Iterations instead of a
/// refactorization*). Without one, a dependent row is added by null-space steps
/// as always, and a solve whose factor has lost the working set's optimality
/// ends as a numerical error (no plan, as at the cap).
pub const QP_MAX_REFACTORIZATIONS: u32 = 0;
/// A node's row `V ≥ 0` (the car does not reverse: the plant only brakes) is
/// added where the linearised speed is under this, m/s (only slow nodes need it,
/// and so the rows stay within [`NC`] beside the obstacles'). Without it a car standing across the road planned three-point
/// turns it could not drive, and stood.
pub const SPEED_ROW_BELOW_MPS: f32 = 1.0;
/// Soft weight of the `V ≥ 0` rows, per (m/s)² (as the obstacles' `2·q_obs`).
pub const SPEED_ROW_WEIGHT: f32 = 2.0e5;
/// Linearise–solve passes on a cold start ([`MpcSettings::cold_start_iterations`]
/// of [`MpcSettings::paper`]). One: the next activation, warm, linearises about
/// this one's plan (a real-time iteration: one Gauss–Newton step per sampling
/// instant), and every further pass would add its worst case (a linearisation, a
/// factor rebuilt from scratch) to the activation's.
pub const COLD_START_PASSES: u8 = 1;

/// `append`'s trips over the rows already in the QP's factor, summed over one
/// activation (each of its loops over the rows; `qp::work`): the rows a budget of
/// [`QP_MAX_ITER`] iterations, [`QP_MAX_REFACTORIZATIONS`] retries and
/// [`COLD_START_PASSES`] solves can find, each append at most [`WS`]` − 1` and a
/// full working set a removal, an iteration, before each append. The timing
/// analysis's flow fact (`qp/src/factor.rs`), checked on the traces.
pub const QP_APPEND_ROWS: u64 = qp::work::append_work_bound(
    QP_MAX_ITER,
    QP_MAX_REFACTORIZATIONS,
    COLD_START_PASSES as u32,
    WS,
    false,
);
/// The trips of `append`'s forward solve (groups of four entries) summed over one
/// activation, as [`QP_APPEND_ROWS`] (`qp::work`).
pub const QP_APPEND_GROUPS: u64 = qp::work::append_work_bound(
    QP_MAX_ITER,
    QP_MAX_REFACTORIZATIONS,
    COLD_START_PASSES as u32,
    WS,
    true,
);
const _: () = assert!(QP_MAX_ITER <= qp::work::MAX_BUDGET);

/// The QP solver sized for the MPC.
pub type MpcQp<T> = QpSolver<T, NV, NC, WS, { ldl_len(WS) }>;
/// The condensed QP, as handed to the solver.
pub type MpcQpProblem<T> = QpProblem<T, NV, NC>;
/// The QP's solution.
pub type MpcQpSolution<T> = QpSolution<T, NV, NC>;

use crate::bicycle::{DELTA as IDELTA, S as IS, V as IV, X as IX, Y as IY};

/// Cost weights (the paper's `q_*`; each multiplies a squared quantity in SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MpcWeights<T> {
    /// On the speed error `V − V_heur`, per (m/s)² (paper: 4).
    pub q_v: T,
    /// On the steering `δ − δ_ref`, per rad² (paper: 10).
    pub q_delta: T,
    /// On the steering rate `δ̇`, per (rad/s)² (paper: 0.2).
    pub q_delta_rate: T,
    /// On the longitudinal path deviation `e_x`, per m² (paper: 5).
    pub q_x: T,
    /// On the lateral path deviation `e_y`, per m² (paper: 5).
    pub q_y: T,
    /// On the obstacle slack, per m² (paper: 100).
    pub q_obs: T,
    /// On the validity slack `δ_tol`, per rad² where `δ_max(V)` is the mechanical
    /// limit `δ_mech` (low speed), and `q_δtol·(δ_mech/δ_max(V))²` per rad² at speed
    /// `V` (the ratio capped at 100): a given *fraction* of `δ_max` over the limit
    /// costs the same at every speed (paper: 100 per rad², at every speed).
    pub q_delta_tol: T,
    /// On the road-limit slack, per m² (not in the paper: its road limits are the
    /// `y_tol` margins).
    pub q_road: T,
    /// On the acceleration `u1`, per (m/s²)² (not in the paper; a small
    /// regularisation that keeps the speed profile smooth).
    pub q_accel: T,
}

impl<T: Real> Default for MpcWeights<T> {
    /// The paper's weights except `q_y = 100` (paper: 5), `q_δtol = 10⁴` (paper:
    /// 100; scaled by `(δ_mech/δ_max(V))²`), `q_obs = 10⁵` (paper: 100) and
    /// `q_δ̇ = 10` (paper: 0.2).
    ///
    /// * `q_y`: on the 9-DoF plant the car understeers against the kinematic plan
    ///   at the validity limit; a small weight lets the planner accept that drift
    ///   rather than steer to `δ_max` or slow down. The lateral reference is
    ///   shifted round obstacles ([`obstacle_offset`]), so this weight does not
    ///   fight obstacle avoidance.
    /// * `q_δtol`: the validity slack is in radians and small (at 15 m/s `δ_max` is
    ///   0.055 rad); at 10⁴ a 10 % excess costs as much as 0.25 m of lateral
    ///   deviation, so the limit binds as the paper intends. Scaled by
    ///   `(δ_mech/δ_max(V))²` (10⁴ per rad² at low speed, ~9·10⁶ at 25 m/s) so that a
    ///   given fraction of `δ_max` over the limit costs the same at every speed.
    /// * `q_obs` above `q_δtol`: the planner must not buy validity with clearance.
    /// * `q_δ̇`: a small weight lets the plan steer back and forth round the kinks
    ///   of a measured centre line; at low speed the lateral acceleration then
    ///   carries the term `V·β̇` of the steering rate, which the kinematic
    ///   `V²·sin β/l_r` does not.
    ///
    /// The runs that chose them: `docs/tuning.md`, "MPC weights".
    fn default() -> Self {
        Self {
            q_delta_rate: T::lit(10.0),
            q_y: T::lit(100.0),
            q_delta_tol: T::lit(1.0e4),
            q_obs: T::lit(1.0e5),
            ..Self::paper()
        }
    }
}

impl<T: Real> MpcWeights<T> {
    /// The paper's weights exactly, plus the two small additions documented on the
    /// fields (`q_road`, `q_accel`).
    pub fn paper() -> Self {
        Self {
            q_v: T::lit(4.0),
            q_delta: T::lit(10.0),
            q_delta_rate: T::lit(0.2),
            q_x: T::lit(5.0),
            q_y: T::lit(5.0),
            q_obs: T::lit(100.0),
            q_delta_tol: T::lit(100.0),
            q_road: T::lit(100.0),
            q_accel: T::lit(0.05),
        }
    }
}

/// What the steering cost `q_Δ (δ − δ_ref)²` pulls the steering towards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SteeringReference {
    /// `δ_ref = 0`, as in the paper.
    Zero,
    /// `δ_ref` = the kinematic steering that follows the path's curvature at the
    /// predicted abscissa (0 on straights, so equal to the paper there).
    PathCurvature,
}

/// Settings of the MPC (kept apart from its workspace [`Mpc`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MpcSettings<T> {
    /// Cost weights.
    pub weights: MpcWeights<T>,
    /// Bicycle geometry (`l_f`, `l_r`), m.
    pub geometry: BicycleGeometry<T>,
    /// Lower bound of the acceleration input `u1`, m/s² (paper: −8).
    pub accel_min_mps2: T,
    /// Upper bound of the acceleration input `u1`, m/s² (paper: 6).
    pub accel_max_mps2: T,
    /// Bound of the steering-rate input `|u2|`, rad/s (paper: 0.5).
    pub steer_rate_max_radps: T,
    /// Fraction of the vehicle's weight on the driven wheels (0.6 for a front-wheel
    /// drive car with 60 % of its weight on the front axle; 1 for four-wheel drive).
    /// With [`MpcSettings::friction_usage`] it caps the planned acceleration at what
    /// the tyres can transmit on the road of friction `μ` (not in the paper, whose
    /// bounds `[−8, 6] m/s²` assume a dry road and enough grip).
    pub driven_load_share: T,
    /// Fraction `f` of the friction `μ·g` the plan may use: the acceleration bounds
    /// are `max(accel_min, −f·μ·g)` and `min(accel_max, f·μ·g·driven_load_share)`,
    /// the upper one scaled by `√(1 − (a_y/(f·μ·g))²)` where the nominal trajectory
    /// turns with lateral acceleration `a_y` (a friction ellipse on the plan's
    /// traction; not in the paper, whose car accelerating out of a curve at
    /// 0.5·μ·g lateral would spin its front tyres).
    pub friction_usage: T,
    /// Mechanical steering limit `|δ|`, rad.
    pub delta_mech_max_rad: T,
    /// Fraction of `μ·g` allowed as lateral acceleration (paper: 0.5).
    pub ay_fraction: T,
    /// Half of the vehicle's width, m (keeps the body inside the road limits).
    pub half_width_m: T,
    /// Extra distance kept from the road edge, m.
    pub road_margin_m: T,
    /// Extra lateral distance beyond an obstacle parabola's boundary that the
    /// lateral cost's reference keeps, m (see [`obstacle_offset`]).
    pub obstacle_offset_buffer_m: T,
    /// Local velocity planner settings.
    pub velocity: VelocityPlannerSettings<T>,
    /// Steering reference of the steering cost.
    pub steering_reference: SteeringReference,
    /// The sideslip lag's estimate ([`crate::sideslip`]): the plan task learns it,
    /// the model uses at most its `lag_max` ([`Mpc::set_sideslip_lag`]).
    pub sideslip: SideslipConfig<T>,
    /// Linearise–solve passes on a cold start (no previous solution), ≥ 1.
    pub cold_start_iterations: u8,
    /// QP iterations allowed in one activation, summed over its passes, ≥ 1 (with
    /// [`MpcSettings::cold_start_iterations`] it bounds the step's worst-case time:
    /// see [`Mpc::step_observed`]).
    pub qp_max_iter: u32,
}

impl<T: Real> MpcSettings<T> {
    /// The paper's settings (bounds, horizon, `0.5·μ·g`; weights from
    /// [`MpcWeights::default`]) for a vehicle of the given geometry, mechanical
    /// steering limit (rad) and width (m).
    pub fn paper(geometry: BicycleGeometry<T>, delta_mech_max_rad: T, width_m: T) -> Self {
        Self {
            weights: MpcWeights::default(),
            geometry,
            accel_min_mps2: T::lit(-8.0),
            accel_max_mps2: T::lit(6.0),
            steer_rate_max_radps: T::lit(0.5),
            driven_load_share: T::ONE,
            friction_usage: T::lit(0.8),
            delta_mech_max_rad,
            ay_fraction: T::HALF,
            half_width_m: T::HALF * width_m,
            road_margin_m: T::lit(0.2),
            obstacle_offset_buffer_m: T::lit(0.2),
            velocity: VelocityPlannerSettings {
                // 80 % of the validity limit, with a curvature reserve: at exactly
                // `0.5·μ·g` the plan sits on `δ_max` through every curve and has no
                // steering left to correct a lateral error. At 21–25 m/s the car
                // turns less than the kinematic model says for the same steering
                // (the validity experiment), so the reserve must be largest there:
                // a fixed curvature reserve is a fixed steering reserve
                // ([`VelocityPlannerSettings::curve_speed_mps`]). The runs that chose
                // 0.4 and 0.002 1/m: `docs/tuning.md`, "Velocity planner".
                ay_fraction: T::lit(0.4),
                curvature_reserve_1pm: T::lit(0.002),
                // `V_heur` is evaluated at every node, so each node already looks
                // ahead; 2 s of preview from there (instead of the whole horizon)
                // lets the car reach `V_max` on the paper track's longest straight.
                preview_time_s: T::lit(2.0),
                ..VelocityPlannerSettings::default()
            },
            steering_reference: SteeringReference::PathCurvature,
            sideslip: SideslipConfig::shipped(),
            cold_start_iterations: COLD_START_PASSES,
            // The flow fact of the plan task's static bound (`host-sim wcet`); how
            // many the laps and the harshest tests need: `docs/tuning.md`, "QP
            // iteration cap".
            qp_max_iter: QP_MAX_ITER,
        }
    }

    /// All-zero settings that every step refuses ([`MpcError::InvalidSettings`]):
    /// a `const` placeholder for a planner in a `static`, replaced once the car is
    /// known (the ECU receives it in its configuration frame).
    pub const fn unset() -> Self {
        let z = T::ZERO;
        Self {
            weights: MpcWeights {
                q_v: z,
                q_delta: z,
                q_delta_rate: z,
                q_x: z,
                q_y: z,
                q_obs: z,
                q_delta_tol: z,
                q_road: z,
                q_accel: z,
            },
            geometry: BicycleGeometry { l_f_m: z, l_r_m: z },
            accel_min_mps2: z,
            accel_max_mps2: z,
            steer_rate_max_radps: z,
            driven_load_share: z,
            friction_usage: z,
            delta_mech_max_rad: z,
            ay_fraction: z,
            half_width_m: z,
            road_margin_m: z,
            obstacle_offset_buffer_m: z,
            velocity: VelocityPlannerSettings {
                delta_v_mps: z,
                preview_time_s: z,
                preview_speed_floor_mps: z,
                ay_fraction: z,
                curvature_reserve_1pm: z,
                v_cap_mps: z,
                brake_decel_mps2: z,
                horizon_s: z,
            },
            steering_reference: SteeringReference::PathCurvature,
            sideslip: SideslipConfig {
                forgetting: z,
                prior_weight: z,
                min_speed_mps: z,
                min_lateral_mps2: z,
                lag_max: z,
            },
            cold_start_iterations: 0,
            qp_max_iter: 0,
        }
    }

    fn validate(&self) -> Result<(), MpcError> {
        let w = &self.weights;
        let finite_nonneg = |x: T| x.is_finite() && x >= T::ZERO;
        let ok = [
            w.q_v,
            w.q_delta,
            w.q_delta_rate,
            w.q_x,
            w.q_y,
            w.q_obs,
            w.q_delta_tol,
            w.q_road,
            w.q_accel,
            self.half_width_m,
            self.road_margin_m,
            self.obstacle_offset_buffer_m,
        ]
        .iter()
        .all(|&x| finite_nonneg(x))
            && w.q_obs > T::ZERO
            && w.q_delta_tol > T::ZERO
            && w.q_road > T::ZERO
            && (w.q_accel > T::ZERO || w.q_v > T::ZERO)
            && (w.q_delta_rate > T::ZERO || w.q_delta > T::ZERO)
            && self.accel_min_mps2.is_finite()
            && self.accel_max_mps2.is_finite()
            && self.accel_min_mps2 < self.accel_max_mps2
            && self.steer_rate_max_radps.is_finite()
            && self.steer_rate_max_radps > T::ZERO
            && self.driven_load_share > T::ZERO
            && self.driven_load_share <= T::ONE
            && self.friction_usage > T::ZERO
            && self.friction_usage.is_finite()
            && self.delta_mech_max_rad.is_finite()
            && self.delta_mech_max_rad > T::ZERO
            && self.ay_fraction.is_finite()
            && self.ay_fraction > T::ZERO
            && self.geometry.l_f_m.is_finite()
            && self.geometry.l_f_m > T::ZERO
            && self.geometry.l_r_m.is_finite()
            && self.geometry.l_r_m > T::ZERO
            && self.sideslip.is_valid()
            && self.cold_start_iterations >= 1
            && self.qp_max_iter >= 1;
        if ok {
            Ok(())
        } else {
            Err(MpcError::InvalidSettings)
        }
    }
}

/// Why an MPC step produced no plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpcError {
    /// The state estimate holds NaN or ±∞.
    NonFiniteState,
    /// `μ` is not a positive finite number.
    InvalidFriction,
    /// A setting is out of range (negative or non-finite weight, empty bounds…).
    InvalidSettings,
    /// The path is empty or the vehicle position could not be projected on it.
    NoPath,
    /// The QP solver did not reach an optimum (its status says why).
    Qp(QpStatus),
    /// The plan computed holds NaN or ±∞ ([`crate::plan::Plan::is_finite`]): not
    /// published ([`crate::tasks::PlanTask::run`]).
    NonFinitePlan,
}

/// What an MPC step did: work counters (deterministic, for the timing budget) and
/// diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MpcReport<T> {
    /// Linearise–solve passes run (1 when warm).
    pub passes: u32,
    /// QP iterations, summed over the passes.
    pub qp_iterations: u32,
    /// Constraints added to the working set, summed.
    pub qp_added: u32,
    /// Constraints removed from the working set, summed.
    pub qp_removed: u32,
    /// Factorisations from scratch, summed.
    pub qp_refactorizations: u32,
    /// General QP rows of the last pass.
    pub rows: u32,
    /// Obstacle rows of the last pass.
    pub obstacle_rows: u32,
    /// Obstacle rows that did not fit in [`MAX_OBSTACLE_ROWS`] or in the QP (farthest
    /// nodes dropped).
    pub obstacle_rows_dropped: u32,
    /// Working-set size at the optimum.
    pub active_constraints: u32,
    /// Whether the solve started from the previous solution.
    pub warm: bool,
    /// On a cold start, a refinement pass after the first failed (or the
    /// activation's QP iteration cap left it no iteration) and the previous pass's
    /// solution was kept (the slack diagnostics below are then 0).
    pub refinement_failed: bool,
    /// Largest validity slack `δ_tol` in the solution, rad (0: the limit holds).
    pub max_validity_slack_rad: T,
    /// Largest obstacle slack in the solution, m (0: all parabolas respected).
    pub max_obstacle_slack_m: T,
    /// Largest road-limit slack in the solution, m.
    pub max_road_slack_m: T,
}

/// The MPC's workspace: the QP solver, the previous solution for the warm start,
/// and the scratch of a linearise–condense pass (so that it is not on the stack).
/// Build it with [`Mpc::new`] (`const`), keep it across steps.
#[derive(Clone, Debug)]
pub struct Mpc<T> {
    solver: MpcQp<T>,
    /// Optimal inputs of the last successful step.
    u_prev: [[T; NU]; HORIZON],
    /// Release time of the last successful step, µs.
    prev_stamp_us: u64,
    /// Predicted abscissa at each node of the last plan (projection hints), m.
    s_prev: [T; HORIZON + 1],
    have_prev: bool,
    /// Nominal inputs of the current pass.
    u_bar: [[T; NU]; HORIZON],
    /// Scratch of the linearise–condense pass (sensitivities, cost block, rows).
    condensing: Condensing<T>,
    /// The last solve's working set at its optimum, rows by [`RowId`], for the
    /// next warm start (the next step's rows are numbered afresh).
    warm_set: [WarmEntry; WS],
    /// Entries of `warm_set` in use.
    warm_len: usize,
    /// The last step started cold and its QP stopped at the iteration cap: the
    /// working set it reached is kept for the next cold step to resume from.
    resume_cold: bool,
    /// Counters of the last step, whatever its outcome.
    last_report: MpcReport<T>,
    /// The sideslip lag of the model, rad per m/s² ([`Mpc::set_sideslip_lag`]).
    sideslip_lag: T,
}

impl<T: Real> Default for Mpc<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> Mpc<T> {
    /// An empty workspace (cold). `const`, so it can initialise a `static`.
    pub const fn new() -> Self {
        Self {
            solver: QpSolver::new(),
            u_prev: [[T::ZERO; NU]; HORIZON],
            prev_stamp_us: 0,
            s_prev: [T::ZERO; HORIZON + 1],
            have_prev: false,
            u_bar: [[T::ZERO; NU]; HORIZON],
            condensing: Condensing::new(),
            warm_set: [WarmEntry::Bound(0, QpSide::Lower); WS],
            warm_len: 0,
            resume_cold: false,
            last_report: MpcReport {
                passes: 0,
                qp_iterations: 0,
                qp_added: 0,
                qp_removed: 0,
                qp_refactorizations: 0,
                rows: 0,
                obstacle_rows: 0,
                obstacle_rows_dropped: 0,
                active_constraints: 0,
                warm: false,
                refinement_failed: false,
                max_validity_slack_rad: T::ZERO,
                max_obstacle_slack_m: T::ZERO,
                max_road_slack_m: T::ZERO,
            },
            sideslip_lag: T::ZERO,
        }
    }

    /// Moves the previous solution's path abscissae by `−delta_m`, m: the path was
    /// replaced by a window of the same road whose origin lies `delta_m` further
    /// along it (the warm start's projection hints stay on the same points).
    pub fn shift_s(&mut self, delta_m: T) {
        for s in self.s_prev.iter_mut() {
            *s -= delta_m;
        }
    }

    /// The sideslip lag `λ` of the model the next steps plan with, rad per m/s²
    /// ([`crate::sideslip`]; [`crate::tasks::PlanTask`] sets its estimate before
    /// each step): the course lags the kinematic bicycle's by `λ·a_y`. At most
    /// [`MpcSettings::sideslip`]'s `lag_max` is used; 0, a negative value or NaN
    /// is the paper's kinematic model (the default).
    pub fn set_sideslip_lag(&mut self, lag_rad_per_mps2: T) {
        self.sideslip_lag = if lag_rad_per_mps2 > T::ZERO {
            lag_rad_per_mps2
        } else {
            T::ZERO
        };
    }

    /// Forgets the previous solution: the next step starts cold.
    pub fn reset(&mut self) {
        self.have_prev = false;
        self.warm_len = 0;
        self.resume_cold = false;
        self.solver.clear_working_set();
    }

    /// The QP solver (its last problem data are consumed by the solve; its solution
    /// and working set are readable).
    pub fn solver(&self) -> &MpcQp<T> {
        &self.solver
    }

    /// One MPC step: plans from `est` (released at `est.stamp_us`) along `path`,
    /// around `obstacles`, on a road of friction `mu`; writes the plan into `plan`.
    pub fn step<const CAP: usize>(
        &mut self,
        settings: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        est: &StateEstimate<T>,
        mu: T,
        plan: &mut Plan<T>,
    ) -> Result<MpcReport<T>, MpcError> {
        self.step_observed(settings, path, obstacles, est, mu, plan, |_| {}, |_| {})
    }

    /// The work counters and diagnostics of the last step, whatever its outcome
    /// (reset at the start of every step): a failed step's counters say how much
    /// work it did before it failed, which its cost on the ECU depends on.
    pub fn last_report(&self) -> &MpcReport<T> {
        &self.last_report
    }

    /// [`Mpc::step`], calling `before(solver)` on the solver holding each condensed
    /// QP and the working set its solve starts from (the warm start) before it is
    /// solved, and `after(solution)` after (to record the QPs; no cost otherwise).
    ///
    /// # Work bound
    ///
    /// One step runs at most [`MpcSettings::cold_start_iterations`]
    /// linearise–condense passes (1 when warm) and at most
    /// [`MpcSettings::qp_max_iter`] QP iterations in total: the cap is the
    /// activation's, each pass gets the iterations the previous passes left. A
    /// first pass that reaches the cap fails the step
    /// ([`QpStatus::IterationLimit`]); a refinement pass (the second or later of a
    /// cold start) that reaches it, or that finds none left, ends the refinement and
    /// the previous pass's optimum stands ([`MpcReport::refinement_failed`]).
    #[allow(clippy::too_many_arguments)]
    pub fn step_observed<const CAP: usize>(
        &mut self,
        settings: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        est: &StateEstimate<T>,
        mu: T,
        plan: &mut Plan<T>,
        before: impl FnMut(&MpcQp<T>),
        after: impl FnMut(&MpcQpSolution<T>),
    ) -> Result<MpcReport<T>, MpcError> {
        let mut report = MpcReport::default();
        let result = self.step_inner(
            settings,
            path,
            obstacles,
            est,
            mu,
            plan,
            before,
            after,
            &mut report,
        );
        self.last_report = report;
        result.map(|()| report)
    }

    /// The step itself; `report` accumulates its counters whatever the outcome.
    #[allow(clippy::too_many_arguments)]
    fn step_inner<const CAP: usize>(
        &mut self,
        settings: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        est: &StateEstimate<T>,
        mu: T,
        plan: &mut Plan<T>,
        mut before: impl FnMut(&MpcQp<T>),
        mut after: impl FnMut(&MpcQpSolution<T>),
        report: &mut MpcReport<T>,
    ) -> Result<(), MpcError> {
        settings.validate()?;
        if !est.is_finite() {
            return Err(MpcError::NonFiniteState);
        }
        if !(mu.is_finite() && mu > T::ZERO) {
            return Err(MpcError::InvalidFriction);
        }
        let dt = T::lit(PLAN_DT_S);
        let validity = ValidityLimit {
            geometry: settings.geometry,
            mu,
            ay_fraction: settings.ay_fraction,
            delta_mech_max_rad: settings.delta_mech_max_rad,
        };

        // 1. Shift the previous solution to the new release time.
        // Elapsed since the previous plan, s (integer µs first: no f64 on the ECU).
        let elapsed_s = if self.have_prev && est.stamp_us >= self.prev_stamp_us {
            let us = (est.stamp_us - self.prev_stamp_us).min(u32::MAX as u64) as u32;
            T::lit(us as f32) * T::lit(1e-6)
        } else {
            -T::ONE
        };
        let warm = elapsed_s >= T::ZERO && elapsed_s < dt * T::from_usize(HORIZON);
        let s_hint = if warm {
            Some(interpolate_nodes(&self.s_prev, elapsed_s / dt))
        } else {
            None
        };
        if warm {
            shift_inputs(&self.u_prev, elapsed_s / dt, &mut self.u_bar);
        } else {
            self.u_bar = [[T::ZERO; NU]; HORIZON];
            // A cold QP that stopped at its cap (e.g. started next to an obstacle
            // across the path) has added the right rows, but not all of them: the
            // next cold step, linearised about the same zero inputs, goes on from
            // its working set instead of from nothing (else every cold step would
            // stop at the same cap).
            if !self.resume_cold {
                self.warm_len = 0;
                self.solver.clear_working_set();
            }
        }
        self.resume_cold = false;
        report.warm = warm;

        // Initial state.
        let proj = path
            .project([est.x_m, est.y_m], s_hint)
            .ok_or(MpcError::NoPath)?;
        let v0 = est.speed_mps();
        let xi0: [T; NX] = [
            proj.s_m,
            est.x_m,
            est.y_m,
            v0,
            est.psi_rad,
            est.delta_rad
                .clamp(-settings.delta_mech_max_rad, settings.delta_mech_max_rad),
        ];

        // The model's sideslip lag, within the settings' bound.
        self.condensing.lag = qp::real::smaller(self.sideslip_lag, settings.sideslip.lag_max);
        let passes = if warm {
            1
        } else {
            settings.cold_start_iterations.max(1) as u32
        };
        let mut v_heur = [T::ZERO; HORIZON + 1];
        // `passes` is 1 (warm) or `cold_start_iterations.max(1)`; the ECU's settings
        // (MpcSettings::paper, via VehicleConfig::mpc_settings) set it to COLD_START_PASSES.
        // A pass, then the test for the next one (`passes ≥ 1`): every run of the
        // loop's header is a pass, so the analysis counts COLD_START_PASSES of them
        // (the bound is on the last test, where the compiler puts the back edge).
        let mut pass = 0;
        loop {
            // The iteration cap is the activation's: this pass gets what is left
            // (at least 1: the cap is ≥ 1, and a later pass starts only below it).
            let left = settings.qp_max_iter.saturating_sub(report.qp_iterations);
            self.condense(
                settings,
                &validity,
                path,
                obstacles,
                &xi0,
                v0,
                mu,
                &mut v_heur,
                report,
            );
            self.renumber_working_set();
            self.solver.settings.max_iter = left;
            self.solver.settings.max_refactorizations =
                QP_MAX_REFACTORIZATIONS.saturating_sub(report.qp_refactorizations);
            self.solver.settings.warm_start = true;
            before(&self.solver);
            let status = self.solver.solve_factored();
            self.keep_working_set();
            let sol = self.solver.solution();
            after(sol);
            report.passes += 1;
            report.qp_iterations += sol.iterations;
            report.qp_added += sol.added;
            report.qp_removed += sol.removed;
            report.qp_refactorizations += sol.refactorizations;
            report.active_constraints = sol.working_set_len as u32;
            if status != QpStatus::Optimal {
                if report.passes == 1 {
                    self.resume_cold = !warm && status == QpStatus::IterationLimit;
                    return Err(MpcError::Qp(status));
                }
                // A cold start's refinement pass failed: the previous pass's optimum
                // (of the QP linearised one pass earlier) stands. The solver's
                // working set is that of the failed pass: start the next step afresh.
                report.refinement_failed = true;
                self.warm_len = 0;
                self.solver.clear_working_set();
                break;
            }
            for k in 0..HORIZON {
                self.u_bar[k] = [sol.x[2 * k], sol.x[2 * k + 1]];
            }
            pass += 1;
            if pass >= passes {
                break;
            }
            // No iteration left for the next pass: this pass's optimum stands.
            // wcet-bound: COLD_START_PASSES
            if report.qp_iterations >= settings.qp_max_iter {
                report.refinement_failed = true;
                break;
            }
        }
        if !report.refinement_failed {
            self.slack_diagnostics(report);
        }

        // 4. The plan: the nonlinear model under the optimal inputs.
        plan.stamp_us = est.stamp_us;
        plan.dt_s = dt;
        plan.v_heur_mps = v_heur;
        let mut xi = xi0;
        plan.nodes[0] = bicycle::node_from_state(&xi);
        // wcet-bound: HORIZON
        for k in 0..HORIZON {
            let u = self.u_bar[k];
            xi = settings
                .geometry
                .step_lagged(&xi, &u, dt, self.condensing.lag);
            plan.nodes[k + 1] = bicycle::node_from_state(&xi);
            plan.inputs[k] = u;
        }
        // wcet-bound: HORIZON + 1
        for k in 0..=HORIZON {
            self.s_prev[k] = plan.nodes[k].s_m;
        }
        self.u_prev = self.u_bar;
        self.prev_stamp_us = est.stamp_us;
        self.have_prev = true;
        Ok(())
    }

    fn slack_diagnostics(&self, report: &mut MpcReport<T>) {
        let m = self.solver.problem().m.min(NC);
        let (mut v, mut o, mut r) = (T::ZERO, T::ZERO, T::ZERO);
        // wcet-bound: NC
        for i in 0..m {
            let s = self.solver.slack(i);
            match self.condensing.row_id[i].kind {
                RowKind::Validity => v = v.max(s),
                RowKind::Obstacle => o = o.max(s),
                RowKind::Road => r = r.max(s),
                RowKind::Speed => {}
            }
        }
        report.max_validity_slack_rad = v;
        report.max_obstacle_slack_m = o;
        report.max_road_slack_m = r;
    }
}

/// The lateral offset from the path (m, positive left) at path abscissa `s_m` (m)
/// that clears every obstacle parabola by `buffer_m` (m): the reference of the
/// lateral-deviation cost. 0 where no parabola reaches the path.
///
/// A parabola passed on its left forbids `η < η_a − c·(ξ − ξ0)²` (ξ, η in the path
/// frame at the obstacle, `ξ ≈ s − s_o` near it), so the offset there is
/// `η_a − c·(ξ − ξ0)² + buffer` when positive; mirrored for the right. Without this
/// shift, the lateral cost `q_y·e_y²` would fight the obstacle constraint, and a
/// planner weighted for accurate tracking would rather stop than go round.
pub fn obstacle_offset<T: Real, const CAP: usize>(
    path: &ReferencePath<T, CAP>,
    obstacles: &[Parabola<T>],
    s_m: T,
    buffer_m: T,
) -> T {
    let (mut left, mut right) = (T::ZERO, T::ZERO);
    // `obstacles`: the plan task's parabolas, a heapless::Vec of MAX_OBSTACLES.
    // wcet-bound: MAX_OBSTACLES
    for o in obstacles {
        let Some(s) = o.relevant_s_at(path, s_m) else {
            continue;
        };
        let dxi = s - o.s_m - o.xi0_m;
        let bend = o.steepness_1pm * dxi * dxi;
        match o.side {
            Side::Left => left = left.max(o.eta_apex_m - bend + buffer_m),
            Side::Right => right = right.min(o.eta_apex_m + bend - buffer_m),
        }
    }
    if left > T::ZERO && right < T::ZERO {
        // Obstacles on both sides at the same abscissa: aim between them.
        T::HALF * (left + right)
    } else {
        left + right
    }
}
