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

// Index loops mirror the maths of the condensing; all ranges are const-bounded.
#![allow(clippy::needless_range_loop)]

use crate::bicycle::{self, BicycleGeometry};
use crate::obstacles::{obstacle_speed_cap, Parabola, Side};
use crate::plan::{Plan, HORIZON, PLAN_DT_S};
use crate::reference_path::{CurvatureWindow, ReferencePath};
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
/// Working-set capacity of the QP solver.
pub const WS: usize = 48;
/// QP iterations one activation may run, summed over its passes
/// ([`MpcSettings::qp_max_iter`] of [`MpcSettings::paper`], the ECU's settings):
/// the flow fact that bounds the plan task's worst case.
pub const QP_MAX_ITER: u32 = 90;
/// QP refactorizations one activation may make, summed over its passes (each
/// pass gets what is left as its [`qp::QpSettings::max_refactorizations`]):
/// with [`QP_MAX_ITER`], the flow fact that bounds the plan task's worst case. A
/// refactorization rebuilds the factor of up to [`WS`] rows (about `WS³/6`
/// multiply-adds); past the cap the pass ends as a numerical error.
pub const QP_MAX_REFACTORIZATIONS: u32 = 2;
/// A node's row `V ≥ 0` (the car does not reverse: the plant only brakes) is
/// added where the linearised speed is under this, m/s (only slow nodes need it,
/// and so the rows stay within [`NC`] beside the obstacles'). Without it a car standing across the road planned three-point
/// turns it could not drive, and stood.
pub const SPEED_ROW_BELOW_MPS: f32 = 1.0;
/// Soft weight of the `V ≥ 0` rows, per (m/s)² (as the obstacles' `2·q_obs`).
pub const SPEED_ROW_WEIGHT: f32 = 2.0e5;
/// Linearise–solve passes on a cold start ([`MpcSettings::cold_start_iterations`]
/// of [`MpcSettings::paper`]).
pub const COLD_START_PASSES: u8 = 3;

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
    /// Obstacle rows that did not fit in [`MAX_OBSTACLE_ROWS`] (farthest nodes dropped).
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
    /// Counters of the last step, whatever its outcome.
    last_report: MpcReport<T>,
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

    /// Forgets the previous solution: the next step starts cold.
    pub fn reset(&mut self) {
        self.have_prev = false;
        self.warm_len = 0;
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
            self.warm_len = 0;
            self.solver.clear_working_set();
        }
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

        let passes = if warm {
            1
        } else {
            settings.cold_start_iterations.max(1) as u32
        };
        let mut v_heur = [T::ZERO; HORIZON + 1];
        // `passes` is 1 (warm) or `cold_start_iterations.max(1)`; the ECU's settings
        // (MpcSettings::paper, via VehicleConfig::mpc_settings) set it to COLD_START_PASSES.
        // wcet-bound: COLD_START_PASSES
        for _ in 0..passes {
            // The iteration cap is the activation's: this pass gets what is left.
            let left = settings.qp_max_iter.saturating_sub(report.qp_iterations);
            if left == 0 {
                // Only after a pass (the cap is ≥ 1): its optimum stands.
                report.refinement_failed = true;
                break;
            }
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
            let status = self.solver.solve();
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
            xi = settings.geometry.step(&xi, &u, dt);
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

    /// Linearises around `ū` from `xi0` and writes the condensed QP into the solver
    /// (Method, steps 2 and 3): input bounds and regularisation, then node by node
    /// the linearisation, the tracking costs, and the validity, road and obstacle
    /// rows. Costs and rows of node `k + 1` depend only on the inputs before it, so
    /// every loop runs over the first `NU·(k + 1)` columns only.
    #[allow(clippy::too_many_arguments)]
    fn condense<const CAP: usize>(
        &mut self,
        st: &MpcSettings<T>,
        validity: &ValidityLimit<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        xi0: &[T; NX],
        v0: T,
        mu: T,
        v_heur: &mut [T; HORIZON + 1],
        report: &mut MpcReport<T>,
    ) {
        let dt = T::lit(PLAN_DT_S);
        let u_bar = self.u_bar;
        let qp = self.solver.problem_mut();
        let c = &mut self.condensing;
        let accel = input_bounds_and_regularisation(qp, st, mu);
        let ay_limit = validity.ay_limit_mps2();
        let buffer = st.obstacle_offset_buffer_m;
        let cap = |s: T| obstacle_speed_cap(&st.velocity, path, obstacles, s, v0, ay_limit, buffer);
        v_heur[0] = velocity_planner::v_heur(&st.velocity, path, xi0[IS], v0, mu).min(cap(xi0[IS]));
        c.start(st);
        let mut window = CurvatureWindow::new();
        let mut xbar = *xi0;
        // wcet-bound: HORIZON
        for k in 0..HORIZON {
            // tan δ̄ once, for the friction ellipse and the linearisation.
            let tan_delta = xbar[IDELTA].tan();
            accel.friction_ellipse(qp, st, &xbar, tan_delta, k);
            xbar = c.linearise(&st.geometry, &xbar, tan_delta, &u_bar[k], k, dt);
            let node = k + 1;
            let ncols = NU * node;
            let (fr, at) = NodeFrame::new(path, &xbar);
            let vh =
                velocity_planner::v_heur_at(&st.velocity, path, &mut window, &at, fr.s, v0, mu)
                    .min(cap(fr.s));
            v_heur[node] = vh;
            c.tracking_costs(qp, st, path, obstacles, &xbar, &fr, vh, &u_bar, ncols);
            c.node = node as u8;
            c.node_first[node] = qp.m as u8;
            c.road_row(qp, st, &fr);
            c.validity_rows(qp, st, validity, &xbar, &u_bar, ncols);
            c.obstacle_rows(qp, st, path, obstacles, &fr, &u_bar, ncols);
            c.speed_row(qp, &xbar, &u_bar, ncols);
        }
        c.node_first[HORIZON + 1] = qp.m as u8;
        report.rows = qp.m as u32;
        report.obstacle_rows = c.obstacle_rows as u32;
        report.obstacle_rows_dropped = c.dropped;
    }

    /// Keeps the solver's working set after a solve, rows by [`RowId`], for the
    /// next solve's warm start.
    fn keep_working_set(&mut self) {
        let mut n = 0;
        // The working set is at most WS entries (the solver's array of WS); the compiler
        // splits this loop, its parts found at the two annotated lines below: WS each.
        for e in self.solver.working_set() {
            let entry = match e.index {
                ConstraintIndex::Bound(j) => WarmEntry::Bound(j, e.side),
                // wcet-bound: WS
                ConstraintIndex::Row(i) => match self.condensing.row_id.get(i as usize) {
                    Some(&id) => WarmEntry::Row(id, e.side),
                    None => continue,
                },
            };
            // wcet-bound: WS
            if let Some(d) = self.warm_set.get_mut(n) {
                *d = entry;
                n += 1;
            }
        }
        self.warm_len = n;
    }

    /// Gives the solver the kept working set with each row's index in this pass's
    /// QP (Method, step 4: the warm start): a row is found by its [`RowId`] among
    /// its node's rows; one that does not exist in this pass (an obstacle no longer
    /// relevant at that node) is dropped. The solver drops the entries that this
    /// pass's bounds make inadmissible or that are dependent.
    fn renumber_working_set(&mut self) {
        let c = &self.condensing;
        self.solver.clear_working_set();
        // One pass over the kept entries, each looked up once: a plain loop (an
        // iterator chain handed to the solver compiles to nested loops whose
        // bounds multiply in the timing analysis).
        // wcet-bound: WS
        for &e in &self.warm_set[..self.warm_len.min(WS)] {
            let renumbered = match e {
                WarmEntry::Bound(j, side) => Some(ActiveConstraint {
                    index: ConstraintIndex::Bound(j),
                    side,
                }),
                WarmEntry::Row(id, side) => {
                    let node = id.node as usize;
                    match (c.node_first.get(node), c.node_first.get(node + 1)) {
                        (Some(&first), Some(&end)) => {
                            // A node's rows `node_first[node]..node_first[node + 1]`: row counts `qp.m` <= NC.
                            (first as usize..end as usize)
                                .find(|&i| c.row_id.get(i) == Some(&id)) // wcet-bound: NC
                                .map(|i| ActiveConstraint {
                                    index: ConstraintIndex::Row(i as u16),
                                    side,
                                })
                        }
                        _ => None,
                    }
                }
            };
            if let Some(a) = renumbered {
                if !self.solver.push_working_set(a) {
                    break;
                }
            }
        }
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

/// Kinematic steering that follows curvature `kappa` (1/m), signed, rad.
fn path_steering<T: Real>(geometry: &BicycleGeometry<T>, kappa: T) -> T {
    if kappa == T::ZERO {
        return T::ZERO;
    }
    let r = T::ONE / kappa.abs();
    let d = kinematic_steering_for_radius(geometry, r).unwrap_or(T::HALF * T::PI);
    if kappa > T::ZERO {
        d
    } else {
        -d
    }
}

/// Cost rows that one node adds to the Hessian (lateral, longitudinal, speed,
/// steering), appended to its factor as one block.
const COST_ROWS: usize = 4;

/// Kind of a QP row (for the slack diagnostics and the warm start).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RowKind {
    Validity,
    Road,
    Obstacle,
    Speed,
}

/// What a QP row constrains: its kind, its node (1..=HORIZON) and which of the
/// node's rows of that kind it is (validity: 0 for `+δ`, 1 for `−δ`; road: 0;
/// obstacle: the obstacle's id). Row indices move from one step to the next (an
/// obstacle row that appears at an early node shifts every later row); a
/// `RowId` names the same constraint in both.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RowId {
    kind: RowKind,
    node: u8,
    sub: u16,
}

impl RowId {
    const NONE: Self = Self {
        kind: RowKind::Validity,
        node: 0,
        sub: 0,
    };
}

/// One entry of the working set kept for the next step's warm start: a variable
/// bound, or a row by its [`RowId`]; and the side held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum WarmEntry {
    /// The bound on QP variable `j`.
    Bound(u16, QpSide),
    /// A general row.
    Row(RowId, QpSide),
}

/// Scratch of one linearise–condense pass, kept in the workspace [`Mpc`] rather
/// than on the stack. Only the first `NU·(k + 1)` columns of a node's rows are
/// ever written or read (the inputs from node `k + 1` on do not reach it).
#[derive(Clone, Debug)]
struct Condensing<T> {
    /// Sensitivities `S_k = ∂ξ_k/∂u` of the current node, alternating between the
    /// two buffers (`2 × NX × NV`; unit of `ξ_i` per unit of `u_j`).
    sens: [[[T; NV]; NX]; 2],
    /// Which buffer of `sens` holds `S_k`.
    cur: usize,
    /// The current node's cost rows, each scaled by `√w`, column-major
    /// (`NV × COST_ROWS`): the block appended to the Hessian factor.
    cost: [[T; COST_ROWS]; NV],
    /// Weight `w` and `√w` of each cost row (lateral, longitudinal, speed,
    /// steering), set by [`Condensing::start`].
    cost_weights: [(T, T); COST_ROWS],
    /// The QP row being built (`NV`).
    row: [T; NV],
    /// The current node's lateral-deviation row (`NV`) and its constant (m), kept
    /// from the tracking costs for the road row.
    lateral: ([T; NV], T),
    /// What each QP row pushed in this pass constrains (`NC`).
    row_id: [RowId; NC],
    /// Node whose rows are being pushed (1..=HORIZON).
    node: u8,
    /// First QP row of each node `1..=HORIZON`; entry `HORIZON + 1` is the row count
    /// (rows of node `n` are `node_first[n]..node_first[n + 1]`).
    node_first: [u8; HORIZON + 2],
    /// Obstacle rows pushed in this pass.
    obstacle_rows: usize,
    /// Obstacle rows that found no room.
    dropped: u32,
}

/// The acceleration bounds of one pass, m/s² (`a_hi` before the friction ellipse),
/// and the grip `friction_usage·μ·g`, m/s².
struct AccelBounds<T> {
    a_hi: T,
    grip: T,
}

/// Input bounds (the acceleration's capped by the road's friction) and the input
/// regularisation `q_a u1² + q_δ̇ u2²`, which starts the Hessian factor `R`
/// (`H = RᵀR`) as a diagonal. Clears the QP.
fn input_bounds_and_regularisation<T: Real>(
    qp: &mut MpcQpProblem<T>,
    st: &MpcSettings<T>,
    mu: T,
) -> AccelBounds<T> {
    let w = &st.weights;
    qp.m = 0;
    qp.f = [T::ZERO; NV];
    for r in qp.h.iter_mut() {
        *r = [T::ZERO; NV];
    }
    let grip = st.friction_usage * mu * T::lit(crate::G);
    let a_lo = st.accel_min_mps2.max(-grip).min(T::ZERO);
    let a_hi = st
        .accel_max_mps2
        .min(grip * st.driven_load_share)
        .max(T::ZERO);
    // The Hessian is kept as its factor R (H = RᵀR), updated by Householder
    // reflections per block of squared cost terms: in f32, H itself would span
    // more than 1/ε.
    qp.h_factor = true;
    for k in 0..HORIZON {
        let (ia, ir) = (NU * k, NU * k + 1);
        qp.x_lo[ia] = a_lo;
        qp.x_hi[ia] = a_hi;
        qp.x_lo[ir] = -st.steer_rate_max_radps;
        qp.x_hi[ir] = st.steer_rate_max_radps;
        qp.h[ia][ia] = (T::TWO * w.q_accel).sqrt();
        qp.h[ir][ir] = (T::TWO * w.q_delta_rate).sqrt();
    }
    AccelBounds { a_hi, grip }
}

impl<T: Real> AccelBounds<T> {
    /// Friction ellipse on the plan's traction: the upper acceleration bound of
    /// interval `k` shrinks with the lateral acceleration the nominal trajectory
    /// needs at its start (`xbar`), so that the plan does not ask the driven tyres
    /// for more than `friction_usage·μ·g` in all. Braking keeps its bound: slowing
    /// down is what restores the validity domain.
    fn friction_ellipse(
        &self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        xbar: &[T; NX],
        tan_delta: T,
        k: usize,
    ) {
        // kinematic_lateral_acceleration(geometry, V̄, δ̄) from tan δ̄ (same value).
        let g = &st.geometry;
        let v = xbar[IV];
        let ay = v * v * g.beta_from_tan_rad(tan_delta).sin() / g.l_r_m;
        let r = (ay / self.grip).abs().min(T::ONE);
        qp.x_hi[NU * k] = self.a_hi * (T::ONE - r * r).sqrt();
    }
}

/// The nominal state at a node seen from the path point at its abscissa.
struct NodeFrame<T> {
    /// Predicted abscissa `s̄`, m.
    s: T,
    /// Path tangent `t` (unit, `[x, y]`).
    t: [T; 2],
    /// Path normal `n` (unit, to the left, `[x, y]`).
    n: [T; 2],
    /// Path curvature `κ`, 1/m.
    kappa: T,
    /// Longitudinal deviation `ē_x = tᵀ(P̄ − p(s̄))`, m.
    ex: T,
    /// Lateral deviation `ē_y = nᵀ(P̄ − p(s̄))`, m.
    ey: T,
    /// Track half-widths at `s̄`, m (`None` for a path without widths).
    widths: Option<crate::reference_path::Widths<T>>,
}

impl<T: Real> NodeFrame<T> {
    /// The frame and the path sample it was built from.
    fn new<const CAP: usize>(
        path: &ReferencePath<T, CAP>,
        xbar: &[T; NX],
    ) -> (Self, crate::reference_path::PathSample<T>) {
        let s = xbar[IS];
        let at = path.sample_at(s);
        let p = at.position;
        let (sin_h, cos_h) = at.heading_rad.sin_cos();
        let kappa = at.curvature_1pm;
        let (t, n) = ([cos_h, sin_h], [-sin_h, cos_h]);
        let (dx, dy) = (xbar[IX] - p[0], xbar[IY] - p[1]);
        let fr = Self {
            s,
            t,
            n,
            kappa,
            ex: t[0] * dx + t[1] * dy,
            ey: n[0] * dx + n[1] * dy,
            widths: at.widths,
        };
        (fr, at)
    }
}

impl<T: Real> Condensing<T> {
    const fn new() -> Self {
        Self {
            sens: [[[T::ZERO; NV]; NX]; 2],
            cur: 0,
            cost: [[T::ZERO; COST_ROWS]; NV],
            cost_weights: [(T::ZERO, T::ZERO); COST_ROWS],
            row: [T::ZERO; NV],
            lateral: ([T::ZERO; NV], T::ZERO),
            row_id: [RowId::NONE; NC],
            node: 0,
            node_first: [0; HORIZON + 2],
            obstacle_rows: 0,
            dropped: 0,
        }
    }

    /// Starts a pass: `S_0 = 0` (`ξ_0` is given), no rows.
    fn start(&mut self, st: &MpcSettings<T>) {
        let w = &st.weights;
        for (r, q) in [w.q_y, w.q_x, w.q_v, w.q_delta].into_iter().enumerate() {
            let wr = T::TWO * q;
            let sw = if wr > T::ZERO { wr.sqrt() } else { T::ZERO };
            self.cost_weights[r] = (wr, sw);
        }
        self.cur = 0;
        self.obstacle_rows = 0;
        self.dropped = 0;
    }

    /// Linearise (Method, step 2): `ξ̄_{k+1} = F(ξ̄_k, ū_k)` (returned) and
    /// `S_{k+1} = A_k S_k + B_k E_k`, where `S_k`'s columns from `NU·k` on are
    /// zero and `A_k`'s structural zeros are skipped.
    fn linearise(
        &mut self,
        geometry: &BicycleGeometry<T>,
        xbar: &[T; NX],
        tan_delta: T,
        u: &[T; NU],
        k: usize,
        dt: T,
    ) -> [T; NX] {
        let lin = geometry.discretize_with_tan(xbar, u, dt, tan_delta);
        let used = NU * k;
        let (a, b) = self.sens.split_at_mut(1);
        let (old, new) = if self.cur == 0 {
            (&a[0], &mut b[0])
        } else {
            (&b[0], &mut a[0])
        };
        // wcet-bound: NX
        for i in 0..NX {
            let out = &mut new[i];
            // Row i of A has at most four nonzeros (the kinematic bicycle's
            // structure); they are summed in column order in one pass per entry,
            // the same sums as adding one column after the other to a zero row.
            let mut terms: [(&[T; NV], T); 4] = [(&old[0], T::ZERO); 4];
            let mut cnt = 0;
            let mut extra = false;
            // Over the NX entries of row i; the compiler splits this loop (runs of zeros
            // skipped), each part at the two annotated lines below advancing `l`: NX each.
            for (l, &ail) in lin.a[i].iter().enumerate() {
                // wcet-bound: NX
                if ail == T::ZERO {
                    continue;
                }
                // wcet-bound: NX
                match terms.get_mut(cnt) {
                    Some(t) => {
                        *t = (&old[l], ail);
                        cnt += 1;
                    }
                    None => extra = true,
                }
            }
            let [(s0, a0), (s1, a1), (s2, a2), (s3, a3)] = terms;
            // `o` is `out[..NU·k]` with k < HORIZON: fewer than NV entries.
            let o = &mut out[..used];
            match cnt {
                // WCET: fewer than NV f32.
                // wcet-bound: NV * 4 bytes
                0 => o.fill(T::ZERO),
                1 => {
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = a0 * s0[j];
                    }
                }
                2 => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = a0 * s0[j] + a1 * s1[j];
                    }
                }
                3 => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = (a0 * s0[j] + a1 * s1[j]) + a2 * s2[j];
                    }
                }
                4 if !extra => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = ((a0 * s0[j] + a1 * s1[j]) + a2 * s2[j]) + a3 * s3[j];
                    }
                }
                _ => {
                    // wcet-bound: NV * 4 bytes
                    o.fill(T::ZERO);
                    for l in 0..NX {
                        let ail = lin.a[i][l];
                        if ail == T::ZERO {
                            continue;
                        }
                        // wcet-bound: NV
                        for (d, s) in o.iter_mut().zip(old[l][..used].iter()) {
                            *d += ail * *s;
                        }
                    }
                }
            }
            out[used] = lin.b[i][0];
            out[used + 1] = lin.b[i][1];
        }
        self.cur ^= 1;
        lin.x_next
    }

    /// `row = Σ coef · S_k[state]` over the first `ncols` columns (the rest zero);
    /// returns the row's constant `nominal − row·ū`.
    fn lin_row(
        &mut self,
        terms: &[(usize, T)],
        nominal: T,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) -> T {
        lin_row_into(
            &self.sens[self.cur],
            &mut self.row,
            terms,
            nominal,
            u_bar,
            ncols,
        )
    }

    /// Puts `½·w·(rowᵀu + d)²` into block column `r`: `f += w·d·row` now, the
    /// Hessian term `w·row·rowᵀ` when the block is appended ([`add_square_root_rows`]).
    /// The weight is `w` of row `r` and its root `√w` (0 unless `w > 0`), both
    /// from [`Condensing::start`].
    fn cost_row(&mut self, qp: &mut MpcQpProblem<T>, r: usize, ncols: usize, d: T) {
        let wr = self.cost_weights[r];
        cost_row_of(qp, &mut self.cost, wr, &self.row, r, ncols, d);
    }

    /// Cost terms (Method, step 3) of the node: lateral deviation about the
    /// obstacle-clearing offset, longitudinal deviation, speed towards `V_heur`
    /// (`vh`, m/s), steering towards its reference; their squares join the
    /// Hessian factor as one block.
    #[allow(clippy::too_many_arguments)]
    fn tracking_costs<const CAP: usize>(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        xbar: &[T; NX],
        fr: &NodeFrame<T>,
        vh: T,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        // Lateral deviation: e_y ≈ ē_y + nᵀδP − κ ē_x δs, about the reference
        // offset that clears the obstacles' parabolas (0 away from them).
        // Built in the kept lateral row itself (no copy).
        let terms = [(IX, fr.n[0]), (IY, fr.n[1]), (IS, -fr.kappa * fr.ex)];
        let sens = &self.sens[self.cur];
        let d = lin_row_into(sens, &mut self.lateral.0, &terms, fr.ey, u_bar, ncols);
        self.lateral.1 = d;
        let ey_ref = obstacle_offset(path, obstacles, fr.s, st.obstacle_offset_buffer_m);
        let wr = self.cost_weights[0];
        cost_row_of(
            qp,
            &mut self.cost,
            wr,
            &self.lateral.0,
            0,
            ncols,
            d - ey_ref,
        );
        // Longitudinal deviation: e_x ≈ ē_x + tᵀδP + (κ ē_y − 1) δs.
        let terms = [
            (IX, fr.t[0]),
            (IY, fr.t[1]),
            (IS, fr.kappa * fr.ey - T::ONE),
        ];
        let d = self.lin_row(&terms, fr.ex, u_bar, ncols);
        self.cost_row(qp, 1, ncols, d);
        // Speed towards V_heur.
        let d = self.lin_row(&[(IV, T::ONE)], xbar[IV], u_bar, ncols) - vh;
        self.cost_row(qp, 2, ncols, d);
        // Steering towards its reference.
        let delta_ref = match st.steering_reference {
            SteeringReference::Zero => T::ZERO,
            SteeringReference::PathCurvature => path_steering(&st.geometry, fr.kappa)
                .clamp(-st.delta_mech_max_rad, st.delta_mech_max_rad),
        };
        let d = self.lin_row(&[(IDELTA, T::ONE)], xbar[IDELTA], u_bar, ncols) - delta_ref;
        self.cost_row(qp, 3, ncols, d);
        add_square_root_rows(&mut qp.h, &mut self.cost, ncols);
    }

    /// Row `sub` of kind `kind` at the current node.
    fn id_here(&self, kind: RowKind, sub: u16) -> RowId {
        RowId {
            kind,
            node: self.node,
            sub,
        }
    }

    /// Appends `row` with bounds `lo ≤ rowᵀu ≤ hi` and soft weight `rho`, as row
    /// `sub` of its kind at the current node.
    fn push(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        kind: RowKind,
        sub: u16,
        lo: T,
        hi: T,
        rho: T,
    ) -> bool {
        let id = self.id_here(kind, sub);
        push_row_of(qp, &mut self.row_id, &self.row, id, lo, hi, rho)
    }

    /// Road limits (soft): `−(w_right − b) ≤ e_y ≤ w_left − b`, `b` the half-width
    /// plus the margin, on the lateral deviation's row (kept by
    /// [`Condensing::tracking_costs`] of the same node).
    fn road_row(&mut self, qp: &mut MpcQpProblem<T>, st: &MpcSettings<T>, fr: &NodeFrame<T>) {
        let Some(wd) = fr.widths else {
            return;
        };
        let keep = st.half_width_m + st.road_margin_m;
        let hi = wd.left_m - keep;
        let lo = -(wd.right_m - keep);
        let (lo, hi) = if lo <= hi {
            (lo, hi)
        } else {
            let mid = T::HALF * (lo + hi);
            (mid, mid)
        };
        let (row, d) = (&self.lateral.0, self.lateral.1);
        let rho = T::TWO * st.weights.q_road;
        let id = self.id_here(RowKind::Road, 0);
        push_row_of(qp, &mut self.row_id, row, id, lo - d, hi - d, rho);
    }

    /// The car does not reverse (soft, weight [`SPEED_ROW_WEIGHT`]): `V ≥ 0` at a
    /// node whose linearised speed `V̄` is under [`SPEED_ROW_BELOW_MPS`] (`V` is
    /// exactly linear in the accelerations, so the row is exact). After the obstacle
    /// rows of the node: when the rows are full, an obstacle keeps its row.
    fn speed_row(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        xbar: &[T; NX],
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        if !xbar[IV].is_finite() || xbar[IV] >= T::lit(SPEED_ROW_BELOW_MPS) {
            return;
        }
        let d = self.lin_row(&[(IV, T::ONE)], xbar[IV], u_bar, ncols);
        let rho = T::lit(SPEED_ROW_WEIGHT);
        self.push(qp, RowKind::Speed, 0, -d, T::INFINITY, rho);
    }

    /// Validity (soft): `±δ ≤ δ_max(V̄) + δ_max'(V̄)(V − V̄) + δ_tol`.
    fn validity_rows(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        validity: &ValidityLimit<T>,
        xbar: &[T; NX],
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        let (dmax, slope) = validity.delta_max_and_slope(xbar[IV]);
        // The rows `±S_δ − δ_max'·S_V` in one pass over the sensitivities, each
        // entry accumulated as [`Condensing::lin_row`] does (same values).
        let sens = &self.sens[self.cur];
        let (sd, sv) = (&sens[IDELTA], &sens[IV]);
        let mut minus = [T::ZERO; NV];
        let plus = &mut self.row;
        plus.fill(T::ZERO);
        let neg_slope = -slope;
        // ncols = NU·(k + 1) <= NU·HORIZON = NV (condense, the only caller).
        if neg_slope == T::ZERO {
            // wcet-bound: NV
            for j in 0..ncols {
                plus[j] += sd[j];
                minus[j] += -sd[j];
            }
        } else {
            // wcet-bound: NV
            for j in 0..ncols {
                let t = neg_slope * sv[j];
                plus[j] = (plus[j] + sd[j]) + t;
                minus[j] = (minus[j] + -sd[j]) + t;
            }
        }
        // The slack's weight grows as `δ_max(V̄)` shrinks ([`MpcWeights::q_delta_tol`]):
        // `q_δtol·(δ_mech/δ_max)²`, the ratio capped at 100 (`δ_max(V)` → 0 as V → ∞).
        let mech = validity.delta_mech_max_rad;
        let ratio = mech / dmax.max(mech * T::lit(0.01));
        let rho = T::TWO * st.weights.q_delta_tol * ratio * ratio;
        let sv_bar = slope * xbar[IV];
        let d = (xbar[IDELTA] - sv_bar) - dot(&self.row, u_bar, ncols);
        let hi = dmax - sv_bar - d;
        self.push(qp, RowKind::Validity, 0, -T::INFINITY, hi, rho);
        let d = (-xbar[IDELTA] - sv_bar) - dot(&minus, u_bar, ncols);
        let hi = dmax - sv_bar - d;
        let id = self.id_here(RowKind::Validity, 1);
        push_row_of(qp, &mut self.row_id, &minus, id, -T::INFINITY, hi, rho);
    }

    /// Obstacles (soft), in the path frame: the parabola's directrix is parallel
    /// to the path, so with ξ ≈ s − s_o and η ≈ e_y near the obstacle,
    /// g = σ·(e_y − η_a) + c·(s − s_o − ξ0)² ≥ 0, linearised at the nominal
    /// (s̄, ē_y). Curvilinear coordinates keep it right on a curved road, where the
    /// obstacle's own Cartesian frame would not be.
    #[allow(clippy::too_many_arguments)]
    fn obstacle_rows<const CAP: usize>(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        fr: &NodeFrame<T>,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        // `obstacles`: the plan task's parabolas, a heapless::Vec of MAX_OBSTACLES.
        // wcet-bound: MAX_OBSTACLES
        for o in obstacles {
            let Some(s) = o.relevant_s_at(path, fr.s) else {
                continue;
            };
            if self.obstacle_rows >= MAX_OBSTACLE_ROWS {
                self.dropped += 1;
                continue;
            }
            let sigma = o.sigma();
            let dxi = s - o.s_m - o.xi0_m;
            let g = sigma * (fr.ey - o.eta_apex_m) + o.steepness_1pm * dxi * dxi;
            let dg_ds = T::TWO * o.steepness_1pm * dxi;
            // ∂g/∂(X, Y, s) through e_y's and s's rows.
            let terms = [
                (IX, sigma * fr.n[0]),
                (IY, sigma * fr.n[1]),
                (IS, dg_ds - sigma * fr.kappa * fr.ex),
            ];
            // Past the check above: at most MAX_OBSTACLE_ROWS per pass.
            // wcet-bound: MAX_OBSTACLE_ROWS * COLD_START_PASSES times per activation
            let d = self.lin_row(&terms, g, u_bar, ncols);
            if self.push(
                qp,
                RowKind::Obstacle,
                o.id as u16,
                -d,
                T::INFINITY,
                T::TWO * st.weights.q_obs,
            ) {
                self.obstacle_rows += 1;
            }
        }
    }
}

/// Appends the rows of `x` (`NV × COST_ROWS`, column-major, entries from column
/// `ncols` on zero) to the upper-triangular factor `r` (`H = RᵀR`): after the call
/// `RᵀR` gains `Σ_rows x xᵀ`. One Householder reflection per column over the
/// `COST_ROWS + 1` entries `[R_jj; x_·j]` (positive diagonal kept), `O(ncols²)`;
/// `x` is zeroed.
#[inline(never)]
fn add_square_root_rows<T: Real>(
    r: &mut [[T; NV]; NV],
    x: &mut [[T; COST_ROWS]; NV],
    ncols: usize,
) {
    let n = ncols.min(NV);
    // wcet-bound: NV
    for k in 0..n {
        let v = x[k];
        x[k] = [T::ZERO; COST_ROWS];
        let mut sigma = T::ZERO;
        for vi in v {
            sigma += vi * vi;
        }
        if sigma == T::ZERO {
            continue;
        }
        let rkk = r[k][k];
        let mu = (rkk * rkk + sigma).sqrt();
        // w = [R_kk − μ; v], computed without cancellation when R_kk ≥ 0.
        let w0 = if rkk > T::ZERO {
            -sigma / (rkk + mu)
        } else {
            rkk - mu
        };
        let beta = T::TWO / (w0 * w0 + sigma);
        r[k][k] = mu;
        let (rk, xs) = (&mut r[k], &mut x[k + 1..n]);
        // The four rows as scalars (registers), summed in the order of the rows.
        let [v0, v1, v2, v3] = v;
        // Σ (n − 1 − k) over k < n ≤ NV per call (not inlined).
        // wcet-bound: NV * (NV - 1) / 2 per call
        for (rkj, xj) in rk[k + 1..n].iter_mut().zip(xs.iter_mut()) {
            let [x0, x1, x2, x3] = *xj;
            let mut d = w0 * *rkj;
            d += v0 * x0;
            d += v1 * x1;
            d += v2 * x2;
            d += v3 * x3;
            let t = beta * d;
            *rkj -= t * w0;
            *xj = [x0 - t * v0, x1 - t * v1, x2 - t * v2, x3 - t * v3];
        }
    }
}

/// [`Condensing::lin_row`] into `row`, from the sensitivities `sens`.
fn lin_row_into<T: Real>(
    sens: &[[T; NV]; NX],
    row: &mut [T; NV],
    terms: &[(usize, T)],
    nominal: T,
    u_bar: &[[T; NU]; HORIZON],
    ncols: usize,
) -> T {
    let n = ncols.min(NV);
    // The terms with a nonzero coefficient (at most three are used), summed in their
    // order in one pass per entry, with the dot product `row·ū` in the same pass
    // (the same sums as adding one term after the other to a zero row).
    let mut used: [(&[T; NV], T); 3] = [(&sens[0], T::ZERO); 3];
    let mut cnt = 0;
    let mut extra = false;
    // `terms` has 1 or 3 entries (the arrays of tracking_costs and obstacle_rows);
    // the compiler splits this loop, its parts at the two annotated lines below: 3 each.
    for &(state, coef) in terms {
        if coef == T::ZERO {
            continue;
        }
        // wcet-bound: 3
        if let Some(srow) = sens.get(state) {
            // wcet-bound: 3
            match used.get_mut(cnt) {
                Some(t) => {
                    *t = (srow, coef);
                    cnt += 1;
                }
                None => extra = true,
            }
        }
    }
    if let Some(tail) = row.get_mut(n..) {
        // WCET: `row` holds NV f32.
        // wcet-bound: NV * 4 bytes
        tail.fill(T::ZERO);
    }
    let u = u_bar.as_flattened();
    let mut acc = T::ZERO;
    let [(s0, c0), (s1, c1), (s2, c2)] = used;
    match cnt {
        1 if !extra => {
            // wcet-bound: NV
            for j in 0..n {
                let r = c0 * s0[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
        2 if !extra => {
            // wcet-bound: NV
            for j in 0..n {
                let r = c0 * s0[j] + c1 * s1[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
        3 if !extra => {
            // wcet-bound: NV
            for j in 0..n {
                let r = (c0 * s0[j] + c1 * s1[j]) + c2 * s2[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
        _ => {
            row.fill(T::ZERO);
            for &(state, coef) in terms {
                if coef == T::ZERO {
                    continue;
                }
                if let Some(srow) = sens.get(state) {
                    // wcet-bound: NV
                    for j in 0..n {
                        row[j] += coef * srow[j];
                    }
                }
            }
            acc = dot(row, u_bar, n);
        }
    }
    nominal - acc
}

/// [`Condensing::cost_row`] of `row` with `(w, √w)`.
fn cost_row_of<T: Real>(
    qp: &mut MpcQpProblem<T>,
    cost: &mut [[T; COST_ROWS]; NV],
    (w, sw): (T, T),
    row: &[T; NV],
    r: usize,
    ncols: usize,
    d: T,
) {
    // ncols = NU·(k + 1) <= NU·HORIZON = NV (tracking_costs, from condense).
    // wcet-bound: NV
    for j in 0..ncols {
        qp.f[j] += w * row[j] * d;
        cost[j][r] = sw * row[j];
    }
}

/// [`Condensing::push`] of `row`.
fn push_row_of<T: Real>(
    qp: &mut MpcQpProblem<T>,
    row_id: &mut [RowId; NC],
    row: &[T; NV],
    id: RowId,
    lo: T,
    hi: T,
    rho: T,
) -> bool {
    match qp.push_row(row, lo, hi, rho) {
        Some(i) => {
            if let Some(k) = row_id.get_mut(i) {
                *k = id;
            }
            true
        }
        None => false,
    }
}

fn dot<T: Real>(row: &[T; NV], u: &[[T; NU]; HORIZON], ncols: usize) -> T {
    let mut acc = T::ZERO;
    // ncols <= NV: NU·(k + 1) from condense, or `ncols.min(NV)` in lin_row_into.
    // wcet-bound: NV
    for j in 0..ncols {
        acc += row[j] * u[j / 2][j % 2];
    }
    acc
}

/// Linear interpolation of node values at a fractional node index `t` (clamped).
fn interpolate_nodes<T: Real>(values: &[T; HORIZON + 1], t: T) -> T {
    let t = t.clamp(T::ZERO, T::from_usize(HORIZON));
    let i = (t.floor().to_f32() as usize).min(HORIZON - 1);
    let f = t - T::from_usize(i);
    values[i] + (values[i + 1] - values[i]) * f
}

/// Re-samples piecewise-constant inputs shifted by `shift` intervals: each new
/// interval gets the average of the old inputs over it; past the end, the last.
fn shift_inputs<T: Real>(old: &[[T; NU]; HORIZON], shift: T, new: &mut [[T; NU]; HORIZON]) {
    // wcet-bound: HORIZON
    for k in 0..HORIZON {
        let a = shift + T::from_usize(k);
        let b = a + T::ONE;
        let mut acc = [T::ZERO; NU];
        let j0 = a.floor();
        let mut j = (j0.to_f32() as usize).min(HORIZON);
        let mut t = a;
        // `j` (>= 0) grows by one each iteration and the loop stops past HORIZON.
        // wcet-bound: HORIZON + 1
        while t < b && j <= HORIZON {
            let end = (T::from_usize(j) + T::ONE).min(b);
            let src = old[j.min(HORIZON - 1)];
            let wgt = end - t;
            acc[0] += wgt * src[0];
            acc[1] += wgt * src[1];
            t = end;
            j += 1;
        }
        if t < b {
            let src = old[HORIZON - 1];
            acc[0] += (b - t) * src[0];
            acc[1] += (b - t) * src[1];
        }
        new[k] = acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifting_by_half_an_interval_averages_neighbours() {
        let mut old = [[0.0f64; NU]; HORIZON];
        for k in 0..HORIZON {
            old[k] = [k as f64, -(k as f64)];
        }
        let mut new = [[0.0; NU]; HORIZON];
        shift_inputs(&old, 0.5, &mut new);
        assert!((new[0][0] - 0.5).abs() < 1e-12);
        assert!((new[3][1] + 3.5).abs() < 1e-12);
        // The last interval extends the last input.
        assert!((new[HORIZON - 1][0] - 15.0).abs() < 1e-12);
        shift_inputs(&old, 0.0, &mut new);
        assert_eq!(new, old);
    }

    #[test]
    fn interpolation_between_nodes() {
        let mut v = [0.0f32; HORIZON + 1];
        for (k, x) in v.iter_mut().enumerate() {
            *x = 2.0 * k as f32;
        }
        assert_eq!(interpolate_nodes(&v, 0.5), 1.0);
        assert_eq!(interpolate_nodes(&v, 16.0), 32.0);
        assert_eq!(interpolate_nodes(&v, 99.0), 32.0);
    }
}
