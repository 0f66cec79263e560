//! The two tasks of the architecture, as library functions (RTIC v2 semantics).
//!
//! | task | period | priority | deadline | does |
//! |---|---|---|---|---|
//! | [`ControlTask::run`] | 10 ms (100 Hz) | high | 10 ms, budget a few thousand cycles | follows the current plan: speed PID → wheel torques (feed-forward for the car's estimated mass and resistances, torque within the grip `μ̂·g`), `δ = δ_ol + δ_cl`; the friction check ([`crate::friction`]) and its estimate of the car ([`crate::longitudinal_estimator`]) |
//! | [`PlanTask::run`] | 100 ms (10 Hz) | low | 100 ms | `V_heur` → obstacle parabolas → MPC, into its own buffer, with `min(μ, μ̂)` |
//!
//! They share two resources: the latest [`StateEstimate`] and the current [`Plan`]
//! (and one word: the friction estimate `μ̂` that `control` updates and `plan`
//! reads with the estimate at its release, [`PlanTask::set_friction_limit`]).
//! `control` preempts `plan`. The planner computes into a buffer of its own,
//! outside any lock, and publishes with [`PlanTask::publish`] — a swap of the two
//! buffers, the only work done inside the critical section on the shared plan — so
//! `control` is blocked at most by that swap. The RTIC application and the host
//! simulator call these same functions.
//!
//! Faults: a plan whose MPC status is not optimal is not published (the previous
//! one stays, and `control` keeps following it, shifted in time; when it runs out
//! the low-level controller brings the car to a controlled stop). A non-finite
//! state estimate is refused by both tasks and counted; `control` then applies the
//! safe actuation (no traction, moderate braking, steering held).
//!
//! Late plans ([`PlanTask::publish_at`]): an activation that finishes after its
//! deadline (the next release) but within [`MAX_PLAN_AGE_US`] of its release still
//! publishes its plan when it finishes: it is the newest plan, a trajectory
//! stamped at its release that `control` follows at the current time (shifted).
//! A plan older than that when it finishes is dropped (counted in
//! [`PlanTaskStats::stale`]): planned from a state that old it could lead the car
//! off the road. Until a plan is published `control` keeps following the previous
//! one shifted in time, and brings the car to a controlled stop when it runs out.
//! A release that falls while `plan` is still running is skipped, not queued
//! (RTIC cannot spawn a busy task), so the next activation plans from a fresh
//! state; each skipped release is a deadline miss.
//!
//! Worst-case work of one `plan` activation: at most
//! [`MpcSettings::cold_start_iterations`] linearise–condense passes and at most
//! [`MpcSettings::qp_max_iter`] QP iterations (see [`Mpc::step_observed`]).

use crate::friction::{FrictionConfig, FrictionEstimator};
use crate::longitudinal_estimator::V_REF_MPS;
use crate::low_level::{
    self, Actuation, CarModel, ControlFault, LowLevelConfig, LowLevelState, Mode,
};
use crate::mpc::{Mpc, MpcError, MpcReport, MpcSettings};
use crate::obstacles::{Obstacle, ObstacleError, ObstacleManager, ObstacleSettings, MAX_OBSTACLES};
use crate::plan::{Plan, HORIZON};
use crate::reference_path::{PathError, ReferencePath, MAX_SEARCH_SEGMENTS};
use crate::sideslip::SideslipLag;
use crate::state_estimate::StateEstimate;
use crate::Real;
use qp::real::{clamp_within, larger, smaller};

pub use crate::reference_path::ECU_PATH_ROWS;
pub use crate::timing::{CONTROL_PERIOD_US, PLAN_PERIOD_US};
/// Weight of the newest value in the plan task's low-pass filter of the yaw
/// loop's share of the measured steering, per activation (dimensionless; 0.2 at
/// 10 Hz is a time constant of about 0.5 s): [`PlanTask::initial_steering`].
pub const STEER_FEEDBACK_GAIN: f32 = 0.2;

/// The MPC's step [`crate::plan::PLAN_DT_S`] in µs (a test checks they agree).
const PLAN_DT_US: u64 = 200_000;

/// Fraction of the grip `μ̂·g` the low-level torque may ask of the tyres
/// ([`ControlTask::car_model`]), dimensionless: the planner asks at most 0.8 of
/// it; the speed PID's correction gets the rest, not more (under speed noise at
/// four times level 1 it locked the front wheels on a μ = 0.3 road without it).
pub const TORQUE_GRIP_FRACTION: f32 = 0.9;

/// The front tyres are saturated (past their peak: sliding sideways, or spinning or
/// locked, which takes their lateral force) when the lateral acceleration
/// measured, `V·ψ̇` in the steering's direction, is under this fraction of the
/// kinematic one the steering asks, `V²·tan δ/L` (dimensionless;
/// [`ControlTask::front_saturated`]).
pub const UNDERSTEER_RATIO: f32 = 0.5;

/// Smallest kinematic lateral acceleration `|V²·tan δ/L|` at which the front
/// tyres' grip is checked, m/s² ([`UNDERSTEER_RATIO`]).
pub const UNDERSTEER_MIN_MPS2: f32 = 2.0;

/// Time the understeer must last before the front tyres are declared saturated,
/// s ([`UNDERSTEER_RATIO`]).
pub const UNDERSTEER_CONFIRM_S: f32 = 0.05;

/// Control periods the tyres must have stayed within their linear range (no
/// saturated or sliding front, no slip event, no wheel spinning or locking)
/// before the plan task's sideslip lag counts a sample
/// ([`ControlTask::tyres_linear`]): a plan period's, so a sample never follows a
/// sliding moment the plan task did not see.
pub const TYRES_LINEAR_PERIODS: u8 = (PLAN_PERIOD_US / CONTROL_PERIOD_US) as u8;

/// Front slip angle from which saturated front tyres are held at their steering
/// angle, rad ([`ControlTask::steering_held`]). The shipped cars' tyres
/// (`host-sim/examples/tyre_peak.rs`) peak at 0.10–0.11 rad at μ 0.3, 0.15–0.16
/// at μ 0.5 and 0.27–0.29 at μ 1, and give at 0.1 rad 99 % of their peak at
/// μ 0.5 and 82–85 % at μ 1; on a dry road at the planner's lateral
/// acceleration the heavy car's front runs at about 0.05 rad.
pub const FRONT_SLIP_HOLD_RAD: f32 = 0.1;

/// Speed from which the front slip angle is checked, m/s
/// ([`ControlTask::steering_held`]; slower, the estimate's lateral velocity
/// divided by the speed is mostly noise).
pub const FRONT_SLIP_MIN_SPEED_MPS: f32 = 3.0;

/// `tan x` as `x + x³/3`, rad → dimensionless: within 2 % for `|x| ≤ 0.6`
/// rad, no trigonometric call (the control task's budget).
#[inline(always)]
fn tan_cubic<T: Real>(x: T) -> T {
    x + x * x * x * T::lit(1.0 / 3.0)
}

/// Oldest a plan may be when it is published (time since its release), µs: two
/// periods. An older plan is dropped ([`PlanTask::publish_at`]).
pub const MAX_PLAN_AGE_US: u64 = 2 * PLAN_PERIOD_US;

/// Counters of the `plan` task (deterministic).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlanTaskStats {
    /// Activations.
    pub activations: u32,
    /// Plans published.
    pub published: u32,
    /// Activations whose plan was not published (any [`MpcError`]).
    pub failures: u32,
    /// Of those, refused non-finite state estimates.
    pub non_finite_estimates: u32,
    /// Plans dropped because they finished more than [`MAX_PLAN_AGE_US`] after
    /// their release.
    pub stale: u32,
    /// Path windows adopted ([`PlanTask::adopt_window`]).
    pub windows: u32,
    /// Obstacles in an adopted window that the obstacle manager refused (their
    /// parabola left out of that window's plans).
    pub obstacle_errors: u32,
    /// Rebuilds of the parabolas that found an obstacle blocking the road: the
    /// parabolas are kept and the plans stop the car before it.
    pub blocked_roads: u32,
}

/// The `plan` task's local resources: the reference path, the obstacle parabolas,
/// the MPC workspace and the plan being computed. `CAP` is the path's point capacity.
#[derive(Clone, Debug)]
pub struct PlanTask<T, const CAP: usize> {
    /// MPC settings.
    pub settings: MpcSettings<T>,
    /// Road friction coefficient `μ` the planner is configured with, dimensionless
    /// (it plans with `min(μ, friction limit)`: [`PlanTask::set_friction_limit`]).
    pub mu: T,
    /// The `control` task's friction estimate `μ̂` ([`crate::friction`]),
    /// dimensionless, `+∞` when there is none.
    friction_limit: T,
    /// The `control` task's [`ControlTask::tyres_linear`] at the release: the
    /// sideslip lag learns only then (true without a control task).
    tyres_linear: bool,
    /// The reference path (load it once before the first activation).
    pub path: ReferencePath<T, CAP>,
    /// Parabolas of the static obstacles (update after loading the path).
    pub obstacles: ObstacleManager<T>,
    /// Every static obstacle known, in the global frame; the parabolas of those in
    /// the current window are rebuilt when a window is adopted.
    obstacle_list: heapless::Vec<Obstacle<T>, MAX_OBSTACLES>,
    obstacle_settings: Option<ObstacleSettings<T>>,
    /// Distance along the road of the current window's first point, m.
    window_origin_m: T,
    mpc: Mpc<T>,
    working: Plan<T>,
    ready: bool,
    /// Steering of the last plan computed, rad, at its nodes (`None` before the
    /// first), and that plan's stamp, µs: see [`PlanTask::initial_steering`].
    last_steering: Option<(u64, [T; HORIZON + 1])>,
    /// The yaw loop's share of the measured steering, low-passed, rad: see
    /// [`PlanTask::initial_steering`].
    steer_feedback_rad: T,
    /// The sideslip lag's estimate ([`crate::sideslip`]), the MPC's model's.
    sideslip: SideslipLag<T>,
    /// Counters.
    pub stats: PlanTaskStats,
    /// Why the last activation published nothing (`None` after a success).
    pub last_error: Option<MpcError>,
}

impl<T: Real, const CAP: usize> PlanTask<T, CAP> {
    /// A planner with an empty path and no obstacles; `const` for a `static`.
    pub const fn new(settings: MpcSettings<T>, mu: T) -> Self {
        Self {
            settings,
            mu,
            friction_limit: T::INFINITY,
            tyres_linear: true,
            // Its projections near a hint (the car's, the obstacles' vertices')
            // scan a bounded number of segments, not the window.
            path: ReferencePath::with_search_segments(MAX_SEARCH_SEGMENTS),
            obstacles: ObstacleManager::new(),
            mpc: Mpc::new(),
            working: Plan::zeroed(),
            ready: false,
            last_steering: None,
            steer_feedback_rad: T::ZERO,
            sideslip: SideslipLag::new(),
            stats: PlanTaskStats {
                activations: 0,
                published: 0,
                failures: 0,
                non_finite_estimates: 0,
                stale: 0,
                windows: 0,
                obstacle_errors: 0,
                blocked_roads: 0,
            },
            obstacle_list: heapless::Vec::new(),
            obstacle_settings: None,
            window_origin_m: T::ZERO,
            last_error: None,
        }
    }

    /// The friction estimate `μ̂` of the `control` task ([`ControlTask::friction_mu`],
    /// dimensionless; `+∞`, NaN or a value not above 0: none), read with the state
    /// estimate at the release: the activations plan with
    /// [`PlanTask::planning_mu`], so a road found slipperier than configured
    /// lowers the acceleration bounds, `V_heur` and `V_max`.
    pub fn set_friction_limit(&mut self, mu: T) {
        self.friction_limit = if mu > T::ZERO { mu } else { T::INFINITY };
    }

    /// Whether the `control` task found the tyres within their linear range
    /// ([`ControlTask::tyres_linear`]), read with the state estimate at the
    /// release: the sideslip lag ([`crate::sideslip`]) counts the activation's
    /// sample only then, since a sliding car is not the linear tyre it models.
    pub fn set_tyres_linear(&mut self, linear: bool) {
        self.tyres_linear = linear;
    }

    /// The friction the activations plan with: `min(μ, μ̂)`, dimensionless.
    pub fn planning_mu(&self) -> T {
        self.mu.min(self.friction_limit)
    }

    /// The work counters of the last activation, whatever its outcome (a failed
    /// activation's counters say how much work it did; see [`Mpc::last_report`]).
    pub fn last_report(&self) -> &MpcReport<T> {
        self.mpc.last_report()
    }

    /// The sideslip lag `λ` the plans use, rad per m/s² ([`crate::sideslip`]): 0
    /// until the car has cornered.
    pub fn sideslip_lag(&self) -> T {
        self.sideslip.lag(&self.settings.sideslip)
    }

    /// Forgets the MPC's previous solution: the next activation starts cold (the
    /// sideslip lag, a property of the car, is kept).
    pub fn reset(&mut self) {
        self.mpc.reset();
        self.last_steering = None;
        self.steer_feedback_rad = T::ZERO;
    }

    /// The steering the MPC starts from, rad: the open-loop steering `δ_ol` of the
    /// last plan computed at the estimate's stamp (its nodes' steering linearly
    /// interpolated, which is exact: `δ̇` is constant between nodes) plus the yaw
    /// loop's share of the measured steering (`est.delta_rad − δ_ol`) low-passed
    /// over the activations (weight [`STEER_FEEDBACK_GAIN`] for the new value, a
    /// time constant of about 0.5 s at 10 Hz); the measured steering
    /// `est.delta_rad` when there is no such plan, the stamp is outside it, or the
    /// measurement is not finite (the MPC then refuses it).
    ///
    /// Why not the measured steering: the steering applied is `δ_ol + δ_cl`, and
    /// `δ_cl` is the yaw loop's feedback on the measured yaw and yaw rate, high
    /// frequency under sensor noise (±0.03 rad every 10 ms at twice the level-1
    /// noise, against `δ_max(V) ≈ 0.02 rad` at 25 m/s). Started from it, the
    /// kinematic model predicts yaw rates the car does not have, the plans steer
    /// back hard at their bounds, and the QPs need several times the iterations
    /// of a noise-free lap, up to the cap ([`MpcSettings::qp_max_iter`]; the
    /// sweep reports the largest per run, `plan_max_qp_iterations`). The slow
    /// part of `δ_cl` (its integral holds the understeer in curves) is kept, so
    /// the plan starts from the steering the car holds.
    pub fn initial_steering(&self, est: &StateEstimate<T>) -> T {
        self.initial_steering_and_feedback(est).0
    }

    /// [`PlanTask::initial_steering`] and the filtered yaw-loop share it used, rad.
    fn initial_steering_and_feedback(&self, est: &StateEstimate<T>) -> (T, T) {
        let measured = (est.delta_rad, T::ZERO);
        let Some((stamp, nodes)) = &self.last_steering else {
            return measured;
        };
        if !est.delta_rad.is_finite() || est.stamp_us < *stamp {
            return measured;
        }
        let us = est.stamp_us - stamp;
        let i = us / PLAN_DT_US;
        if i >= HORIZON as u64 {
            return measured;
        }
        // Integers first: no f64 on the ECU.
        let i = i as usize;
        let f = T::lit((us % PLAN_DT_US) as f32) / T::lit(PLAN_DT_US as f32);
        let open_loop = nodes[i] + f * (nodes[i + 1] - nodes[i]);
        let fb = self.steer_feedback_rad;
        let fb = fb + T::lit(STEER_FEEDBACK_GAIN) * ((est.delta_rad - open_loop) - fb);
        (open_loop + fb, fb)
    }

    /// The plan computed by the last successful activation, not yet published.
    pub fn pending(&self) -> Option<&Plan<T>> {
        if self.ready {
            Some(&self.working)
        } else {
            None
        }
    }

    /// One activation, released on `est` (read from the shared estimate under a
    /// short lock by the caller). Computes outside any lock; on success the plan
    /// waits in the task's buffer for [`PlanTask::publish`]. A plan that is not
    /// finite throughout ([`Plan::is_finite`]) is a failure
    /// ([`MpcError::NonFinitePlan`]), never published.
    pub fn run(&mut self, est: &StateEstimate<T>) -> Result<MpcReport<T>, MpcError> {
        self.run_observed(est, |_| {}, |_| {})
    }

    /// [`PlanTask::run`] with the MPC's QP observers (see [`Mpc::step_observed`]).
    pub fn run_observed(
        &mut self,
        est: &StateEstimate<T>,
        before: impl FnMut(&crate::mpc::MpcQp<T>),
        after: impl FnMut(&crate::mpc::MpcQpSolution<T>),
    ) -> Result<MpcReport<T>, MpcError> {
        self.stats.activations = self.stats.activations.wrapping_add(1);
        self.ready = false;
        let (delta0, feedback) = self.initial_steering_and_feedback(est);
        self.steer_feedback_rad = feedback;
        // The car does not reverse: a speed estimate below 0 is noise around a
        // standstill (the MPC linearised at a negative speed plans backwards and
        // the car, which only brakes, stands).
        let est = &StateEstimate {
            delta_rad: delta0,
            // (not `max`: a NaN must stay NaN and be refused)
            vx_mps: if est.vx_mps < T::ZERO {
                T::ZERO
            } else {
                est.vx_mps
            },
            ..*est
        };
        let mu = self.planning_mu();
        // The sideslip lag learns while the road grips as configured (a road found
        // slipperier, `μ̂ < μ`, makes a sliding car, not the linear tyre it models)
        // and the control task found the tyres within their linear range; from the
        // steering the MPC starts from (the yaw loop's fast share left out).
        let cfg = &self.settings.sideslip;
        self.sideslip.update(
            cfg,
            &self.settings.geometry,
            est,
            self.friction_limit < self.mu || !self.tyres_linear,
        );
        self.mpc.set_sideslip_lag(self.sideslip.lag(cfg));
        let computed = self.mpc.step_observed(
            &self.settings,
            &self.path,
            self.obstacles.parabolas(),
            est,
            mu,
            &mut self.working,
            before,
            after,
        );
        // Checked once here, where it is computed, not by every control period
        // that reads it: the control task then checks only the values it reads.
        let result = match computed {
            Ok(_) if !self.working.is_finite() => Err(MpcError::NonFinitePlan),
            r => r,
        };
        self.last_error = result.err();
        match result {
            Ok(_) => {
                self.ready = true;
                let mut d = [T::ZERO; HORIZON + 1];
                for (d, n) in d.iter_mut().zip(self.working.nodes.iter()) {
                    *d = n.delta_rad;
                }
                self.last_steering = Some((self.working.stamp_us, d));
            }
            Err(e) => {
                self.stats.failures = self.stats.failures.wrapping_add(1);
                if e == MpcError::NonFiniteState {
                    self.stats.non_finite_estimates =
                        self.stats.non_finite_estimates.wrapping_add(1);
                }
            }
        }
        result
    }

    /// The obstacles (global frame) and the obstacle manager's settings used when a
    /// window is adopted. At most [`MAX_OBSTACLES`]; returns false if there were more.
    pub fn set_obstacles(&mut self, settings: ObstacleSettings<T>, list: &[Obstacle<T>]) -> bool {
        self.obstacle_settings = Some(settings);
        self.obstacle_list.clear();
        list.iter()
            .all(|o| self.obstacle_list.push(o.clone()).is_ok())
    }

    /// Adopts the window of the reference path whose `count` rows were written with
    /// `path.stage_row` (the ECU receives a window of the road, not the whole
    /// circuit, so its RAM does not grow with the track): loads it (`closed` only
    /// when it is the whole of a closed circuit), moves the MPC's warm start to the
    /// new origin (`origin_m`, the distance along the road of the window's first
    /// row, m) and rebuilds the parabolas of the obstacles that lie inside it
    /// (those more than 5 m from its ends and within 20 m of its centre line).
    /// An obstacle the manager refuses is left out and counted; a path refused is an
    /// error (the planner then has no path: its steps fail with `NoPath`).
    pub fn adopt_window(
        &mut self,
        count: usize,
        origin_m: T,
        closed: bool,
    ) -> Result<(), PathError> {
        let r = self.path.load_staged(count, closed);
        self.stats.windows = self.stats.windows.wrapping_add(1);
        self.mpc.shift_s(origin_m - self.window_origin_m);
        self.window_origin_m = origin_m;
        // A refused path leaves the planner without one: no parabola either.
        self.rebuild_obstacles();
        r
    }

    /// Rebuilds the parabolas of the known obstacles ([`PlanTask::set_obstacles`])
    /// that lie inside the current window of the road: more than 5 m from its ends
    /// (anywhere on a closed path) and within 20 m of its centre line. Returns false,
    /// counting it in `stats.obstacle_errors` and leaving no parabola, when the
    /// obstacle manager refuses one (invalid, too many); true otherwise. An
    /// obstacle that blocks the road keeps its parabola, on the roomier side, and
    /// the plans stop the car before it (counted in `stats.blocked_roads`).
    pub fn rebuild_obstacles(&mut self) -> bool {
        self.obstacles.clear();
        let Some(settings) = self.obstacle_settings else {
            return true;
        };
        if self.path.is_empty() {
            return true;
        }
        // The obstacles inside the window are moved to the front of the list (in
        // place: no copy on the stack), their projection kept as the hint.
        let (margin, reach) = (T::lit(5.0), T::lit(20.0));
        let length = self.path.length_m();
        let closed = self.path.is_closed();
        let mut inside = 0;
        // wcet-bound: MAX_OBSTACLES
        for i in 0..self.obstacle_list.len() {
            // One path back to the loop's head (no `continue`): a second one made
            // the compiler split the loop into two nested ones over the same
            // indices, each bounded by MAX_OBSTACLES, MAX_OBSTACLES² projections.
            let o = &self.obstacle_list[i];
            let n = T::from_usize(o.vertices.len().max(1));
            let c = o
                .vertices
                .iter()
                // wcet-bound: MAX_VERTICES
                .fold([T::ZERO; 2], |a, v| [a[0] + v[0], a[1] + v[1]]);
            // On the polyline: an open window's end segments, extended, can pass
            // near a far part of the road and claim the obstacle for it.
            let hit = self
                .path
                .project_on_polyline([c[0] / n, c[1] / n], None)
                .filter(|p| {
                    let within = closed || (p.s_m > margin && p.s_m < length - margin);
                    within && p.lateral_m.abs() < reach
                });
            if let Some(p) = hit {
                self.obstacle_list[i].s_hint_m = Some(p.s_m);
                // Two disjoint references (inside <= i): `slice::swap` copies
                // through `memmove`, whose unaligned and backward paths would be
                // loops of the binary that no activation takes.
                let (kept, rest) = self.obstacle_list.split_at_mut(i);
                if let Some(slot) = kept.get_mut(inside) {
                    core::mem::swap(slot, &mut rest[0]);
                }
                inside += 1;
            }
        }
        match self
            .obstacles
            .update(&settings, &self.path, &self.obstacle_list[..inside])
        {
            Ok(()) => true,
            // Every obstacle has its parabola and one leaves no room: the plans
            // stop the car before it (`obstacle_speed_cap`).
            Err(ObstacleError::RoadBlocked { .. })
                if self.obstacles.parabolas().len() == inside =>
            {
                self.stats.blocked_roads = self.stats.blocked_roads.wrapping_add(1);
                true
            }
            Err(_) => {
                self.obstacles.clear();
                self.stats.obstacle_errors = self.stats.obstacle_errors.wrapping_add(1);
                false
            }
        }
    }

    /// [`PlanTask::adopt_window`] from rows `[x_m, y_m, w_right_m, w_left_m]` (the
    /// simulator's way: it holds the rows itself).
    pub fn load_window(
        &mut self,
        rows: &[[T; 4]],
        origin_m: T,
        closed: bool,
    ) -> Result<(), PathError> {
        for (i, r) in rows.iter().enumerate() {
            if !self.path.stage_row(i, *r) {
                return Err(PathError::TooManyPoints {
                    count: rows.len(),
                    capacity: CAP,
                });
            }
        }
        self.adopt_window(rows.len(), origin_m, closed)
    }

    /// Publishes the pending plan into the shared one by swapping buffers (call
    /// inside the critical section on the shared plan). Returns false, leaving the
    /// shared plan untouched, when there is nothing to publish.
    pub fn publish(&mut self, shared: &mut Plan<T>) -> bool {
        if !self.ready {
            return false;
        }
        // The swap's loop moves a word or more per iteration: a Plan<f32> is 154 words (stamp 2,
        // dt 1, HORIZON + 1 nodes of 6 and as many V_heur, HORIZON inputs of NU).
        core::mem::swap(&mut self.working, shared); // wcet-bound: 3 + (HORIZON + 1) * 7 + HORIZON * NU
        self.ready = false;
        self.stats.published = self.stats.published.wrapping_add(1);
        true
    }

    /// [`PlanTask::publish`] at `now_us` (µs, the clock of the plan's stamp) under
    /// the late-plan policy (module docs): a plan more than [`MAX_PLAN_AGE_US`] old
    /// is dropped instead (counted in [`PlanTaskStats::stale`]). Returns whether it
    /// was published.
    pub fn publish_at(&mut self, shared: &mut Plan<T>, now_us: u64) -> bool {
        if self.ready && now_us.saturating_sub(self.working.stamp_us) > MAX_PLAN_AGE_US {
            self.ready = false;
            self.stats.stale = self.stats.stale.wrapping_add(1);
            return false;
        }
        self.publish(shared)
    }
}

/// Counters of the `control` task (deterministic).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ControlTaskStats {
    /// Activations.
    pub activations: u32,
    /// Activations that applied the safe actuation.
    pub safe_actuations: u32,
    /// Of those, refused non-finite state estimates.
    pub non_finite_estimates: u32,
    /// Of those, no valid plan yet / a non-finite plan.
    pub invalid_plans: u32,
}

pub use crate::low_level::STANDSTILL_MPS;

/// Why the car stands ([`ControlTask::stop_reason`]): every controlled stop has one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The safe actuation after a fault (its reason: [`ControlTask::last_fault`]).
    Fault(ControlFault),
    /// No new plan came: the last one ran out and the controller stopped the car
    /// ([`crate::low_level::Mode::Stopping`]).
    PlanRanOut,
    /// The plan being followed asks to stand (its speed at the current time is
    /// under [`STANDSTILL_MPS`]): the planner's own choice (an obstacle, the end
    /// of an open road, or a car it could not steer back to the road moving).
    Planned,
    /// The plan asks to move and the car does not yet (starting).
    Starting,
}

/// The `control` task's local resources: configuration and controller state.
#[derive(Clone, Debug)]
pub struct ControlTask<T> {
    /// Low-level controller configuration (validated by [`ControlTask::new`]).
    pub config: LowLevelConfig<T>,
    state: LowLevelState<T>,
    /// Settings of the friction check ([`crate::friction`]).
    friction_config: FrictionConfig<T>,
    friction: FrictionEstimator<T>,
    /// Counters.
    pub stats: ControlTaskStats,
    /// The last fault, if the last activation applied the safe actuation.
    pub last_fault: Option<ControlFault>,
    /// Why the car stood at the last activation (`None`: it moved).
    stop_reason: Option<StopReason>,
    /// Time the front tyres have shown understeer ([`UNDERSTEER_RATIO`]), s.
    understeer_s: T,
    /// Control periods the tyres have stayed within their linear range, up to
    /// [`TYRES_LINEAR_PERIODS`] ([`ControlTask::tyres_linear`]).
    linear_periods: u8,
    /// `1/L` of the friction settings' wheelbase, 1/m (0 without one).
    inv_wheelbase: T,
    /// True when the front tyres' slip angle, in the steering's direction, is
    /// over [`FRONT_SLIP_HOLD_RAD`].
    front_sliding: bool,
    /// Distance from the centre of gravity to the front axle `l_f`, m (0: none).
    front_axle_m: T,
    /// `1/max(s, 0.01)` of the brake balance's front share `s` and of its rear
    /// share `1 − s` ([`LowLevelConfig::brake_front_share`]): the anti-lock
    /// limit's axle loads per brake share without a division per period.
    inv_brake_shares: [T; 2],
    /// The traction limit held for a driven wheel that spun ([`WheelLimit`]).
    spin_limit: WheelLimit,
    /// The braking limit held for a wheel that locked.
    lock_limit: WheelLimit,
}

/// A torque limit lowered while a wheel slips, for as long as the estimates
/// cannot yet show what the lowering did ([`ControlTask::car_model`]): it
/// starts at the release whose estimate shows the wheel slipping, and ends at
/// the first estimate measured at or after that release that shows it rolling. An estimate `d` old shows
/// the wheel `d` ago: without the wait, each of the `d` of estimates measured
/// before the halving took effect would lift it again while the wheel was still
/// slipping, and a wheel that slips under the full torque would slip again.
/// With fresh estimates (measured at their release) it ends at the next one
/// that shows the wheel rolling.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct WheelLimit {
    /// The release (µs) whose estimate first showed the wheel slipping; `None`
    /// when the limit is whole.
    since_us: Option<u64>,
}

/// Share of the braking limit while a wheel's lock awaits an estimate measured
/// after the braking was halved ([`WheelLimit`]): the estimates in between show
/// the wheel rolling, but from before the halving took effect.
pub const LOCK_WAIT_BRAKING_SHARE: f32 = 0.75;

impl WheelLimit {
    /// True while the limit is held (since a slip was seen, until an estimate
    /// measured after that shows the wheel rolling).
    fn held(self) -> bool {
        self.since_us.is_some()
    }

    /// The estimate measured at `stamp_us` (µs) shows the wheel slipping
    /// (`slipping`) at the release `now_us` (µs); true while the limit is halved.
    fn update(&mut self, slipping: bool, stamp_us: u64, now_us: u64) -> bool {
        self.since_us = match self.since_us {
            _ if slipping => Some(self.since_us.unwrap_or(now_us)),
            Some(since) if stamp_us < since => Some(since),
            _ => None,
        };
        self.since_us.is_some()
    }
}

impl<T: Real> ControlTask<T> {
    /// A controller with a validated configuration; its friction check assumes
    /// every wheel driven, no load transfer, the brake balance matched to the
    /// axles' loads and a nominal `μ = 1` ([`ControlTask::with_friction`] to say
    /// otherwise).
    pub fn new(config: LowLevelConfig<T>) -> Result<Self, low_level::LowLevelConfigError> {
        let mut friction = FrictionConfig::for_car(
            config.mass_kg,
            config.wheel_radius_m,
            T::ONE,
            T::ZERO,
            T::ONE,
        );
        friction.front_load_share = config.brake_front_share;
        Self::with_friction(config, friction)
    }

    /// A controller with a validated configuration and the friction check's
    /// settings (refused as an invalid vehicle when they are out of range).
    pub fn with_friction(
        config: LowLevelConfig<T>,
        friction_config: FrictionConfig<T>,
    ) -> Result<Self, low_level::LowLevelConfigError> {
        config.validate()?;
        if !friction_config.is_valid() {
            return Err(low_level::LowLevelConfigError::InvalidVehicle);
        }
        let mut friction = FrictionEstimator::new();
        friction.start(&friction_config);
        Ok(Self {
            state: LowLevelState::new(),
            friction_config,
            friction,
            stats: ControlTaskStats::default(),
            last_fault: None,
            stop_reason: None,
            understeer_s: T::ZERO,
            linear_periods: 0,
            inv_wheelbase: if friction_config.wheelbase_m > T::ZERO {
                T::ONE / friction_config.wheelbase_m
            } else {
                T::ZERO
            },
            front_sliding: false,
            spin_limit: WheelLimit::default(),
            lock_limit: WheelLimit::default(),
            front_axle_m: friction_config.wheelbase_m * (T::ONE - friction_config.front_load_share),
            inv_brake_shares: [
                T::ONE / larger(config.brake_front_share, T::lit(0.01)),
                T::ONE / larger(T::ONE - config.brake_front_share, T::lit(0.01)),
            ],
            config,
        })
    }

    /// The controller's state (PID states, plan being followed).
    pub fn state(&self) -> &LowLevelState<T> {
        &self.state
    }

    /// Why the car stood at the last activation (its measured speed under
    /// [`STANDSTILL_MPS`]; a fault's safe actuation whatever the speed), `None`
    /// when it moved: a controlled stop always has a stated reason.
    pub fn stop_reason(&self) -> Option<StopReason> {
        self.stop_reason
    }

    /// True when the front tyres were saturated at the last activation: for
    /// [`UNDERSTEER_CONFIRM_S`] the lateral acceleration measured in the steering's
    /// direction was under [`UNDERSTEER_RATIO`] of the kinematic `V²·tan δ/L`
    /// (itself at least [`UNDERSTEER_MIN_MPS2`]). The torque then keeps the
    /// friction the steering asks for ([`ControlTask::run`]).
    pub fn front_saturated(&self) -> bool {
        self.understeer_s >= T::lit(UNDERSTEER_CONFIRM_S)
    }

    /// True when the tyres have stayed within their linear range for
    /// [`TYRES_LINEAR_PERIODS`] control periods up to the last activation: no
    /// saturated front ([`ControlTask::front_saturated`]), no front slip angle
    /// past [`FRONT_SLIP_HOLD_RAD`], no slip event, no wheel spinning or locking
    /// ([`crate::friction`]), no fault. Give it to the `plan` task
    /// ([`PlanTask::set_tyres_linear`]) with the state estimate: its sideslip lag
    /// learns only then (a sliding car is not the linear tyre the lag models, and
    /// what it learns stays for the forgetting's memory, about 5 s).
    pub fn tyres_linear(&self) -> bool {
        self.linear_periods >= TYRES_LINEAR_PERIODS
    }

    /// True when the steering was held at the last activation: the front tyres
    /// saturated ([`ControlTask::front_saturated`]) at a slip angle, in the
    /// steering's direction, of at least [`FRONT_SLIP_HOLD_RAD`], from
    /// [`FRONT_SLIP_MIN_SPEED_MPS`]. The steering then turns no further from
    /// straight ahead ([`crate::low_level::CarModel::hold_steering`]): tyres past
    /// their peak give no more lateral force for more angle, and a wheel sliding
    /// at a large angle locks under the least braking torque, which takes the
    /// lateral force it had (a wet patch taken at dry speed: the steering went to
    /// its lock, the front wheels locked under braking, the car left the road).
    /// Front wheels that lose their lateral force by spinning or locking at a
    /// small slip angle are not held: they need their torque cut, and the
    /// steering they ask.
    pub fn steering_held(&self) -> bool {
        self.front_saturated() && self.front_sliding
    }

    /// The lateral acceleration the torque limits leave room for, m/s², on `est`
    /// (updating the understeer timer): the measured `V·ψ̇`; while the front tyres
    /// are saturated, the larger of it and the kinematic `V²·tan δ/L` the steering
    /// asks (the tyres' lateral force is what steers the car: a wheel braked or
    /// driven past its peak on a slippery road gives it up, and a measured `a_y`
    /// that fell because of it would free more torque still).
    fn lateral_demand(&mut self, est: &StateEstimate<T>) -> T {
        let v = est.vx_mps;
        let measured = v * est.yaw_rate_radps;
        // tan δ to within 2 % for |δ| ≤ 0.6 rad (no trigonometric call); 0 without
        // a wheelbase (no check).
        let d = est.delta_rad;
        let kinematic = v * v * tan_cubic(d) * self.inv_wheelbase;
        // `measured` in the steering's direction under the ratio of `|kinematic|`,
        // both sides times `|kinematic|` (no branch on the sign).
        let k2 = kinematic * kinematic;
        let under = k2 >= T::lit(UNDERSTEER_MIN_MPS2 * UNDERSTEER_MIN_MPS2)
            && measured * kinematic < T::lit(UNDERSTEER_RATIO) * k2;
        // The front axle's slip angle in the steering's direction,
        // |δ| − sign(δ)·atan((v_y + l_f·ψ̇)/v_x), at least α_h: as
        // δ·(v_y + l_f·ψ̇) ≤ v_x·|δ|·tan(|δ| − α_h) (atan increasing, v_x > 0; both
        // sides times |δ|), tan as `tan_cubic` (within 0.005 for |x| ≤ 0.5): no
        // division, no branch on the sign.
        let n = est.vy_mps + self.front_axle_m * est.yaw_rate_radps;
        let x = d.abs() - T::lit(FRONT_SLIP_HOLD_RAD);
        self.front_sliding =
            v >= T::lit(FRONT_SLIP_MIN_SPEED_MPS) && n * d <= v * d.abs() * tan_cubic(x);
        self.understeer_s = if under {
            self.understeer_s + T::lit(CONTROL_PERIOD_US as f32 * 1e-6)
        } else {
            T::ZERO
        };
        if self.front_saturated() {
            larger(measured.abs(), kinematic.abs())
        } else {
            measured
        }
    }

    /// The estimate of the car's mass, resistances and brakes' gain
    /// ([`crate::longitudinal_estimator`]; its settings are
    /// `friction_config().longitudinal`).
    pub fn longitudinal(&self) -> &crate::longitudinal_estimator::LongitudinalEstimator<T> {
        self.friction.longitudinal()
    }

    /// The friction check's settings.
    pub fn friction_config(&self) -> &FrictionConfig<T> {
        &self.friction_config
    }

    /// The friction estimate `μ̂`, dimensionless (the configured `μ` until a slip
    /// is seen): give it to
    /// the `plan` task ([`PlanTask::set_friction_limit`]) with the state estimate.
    pub fn friction_mu(&self) -> T {
        self.friction.mu()
    }

    /// The car as the friction check estimates it
    /// ([`crate::longitudinal_estimator`]): the feed-forward's model (mass,
    /// resistances, the brakes' gain), and the
    /// torque limits of the grip `μ̂·g` it found at the lateral acceleration
    /// `lateral_mps2` (m/s²; the friction ellipse `sqrt(1 − (a_y/grip)²)`, at least
    /// 0.3; half of it while slip is flagged; half the traction's while a driven
    /// wheel spins, half the braking's while a wheel locks, by the wheel speeds
    /// of the last estimate, and after it as long as the estimates were measured
    /// before the halving took effect: the traction's halved, the braking's at
    /// [`LOCK_WAIT_BRAKING_SHARE`]) ([`TORQUE_GRIP_FRACTION`] of it:
    /// of the driven axle's share for traction, as much as its inside wheel
    /// carries under the lateral load transfer and less the load the car's own
    /// acceleration moves off the driven front axle, for the lightest mass the
    /// estimate allows (`1 − u` of it); for braking, as much as the brake
    /// balance lets each axle carry of it); and each axle's braking torque
    /// shared between left and right by the load the lateral acceleration
    /// `transfer_mps2` (m/s², signed, to the left; [`ControlTask::run`] gives
    /// the measured `V·ψ̇`) puts on them ([`CarModel::brake_left_share`]). Both finite (a NaN gives
    /// NaN limits: [`ControlTask::run`] uses the model only on a finite
    /// estimate).
    pub fn car_model(&self, lateral_mps2: T, transfer_mps2: T) -> CarModel<T> {
        let lon = self.friction.longitudinal();
        let m0 = self.friction_config.longitudinal.mass_kg;
        let [r0, r2] = lon.resistance_terms_mps2();
        let fc = &self.friction_config;
        let mu = smaller(self.friction.mu(), fc.mu_nominal);
        let grip = mu * T::lit(crate::G * TORQUE_GRIP_FRACTION);
        // While slip is flagged the wheels are past their peak (spinning or
        // locked): half the grip, so that they roll again (what an anti-lock
        // system or a traction control does). With wheel speeds, a driven wheel
        // that spins halves the traction's, a wheel that locks the braking's
        // (`crate::friction`, *Wheel speeds*).
        let slipping = self.friction.slipping();
        let grip = if slipping { grip * T::HALF } else { grip };
        let half = |on: bool| if on && !slipping { T::HALF } else { T::ONE };
        // A late estimate (`WheelLimit`): the traction stays halved until an
        // estimate measured after the halving shows the wheels rolling; the
        // braking, halved while the estimate shows a wheel locking, is held at
        // LOCK_WAIT_BRAKING_SHARE of its limit meanwhile (halved through the
        // wait, the stopping distance grew by metres: docs/tuning.md).
        let traction_half = half(self.spin_limit.held());
        let braking_half = if self.friction.wheel_locking() {
            half(true)
        } else if self.lock_limit.held() && !slipping {
            T::lit(LOCK_WAIT_BRAKING_SHARE)
        } else {
            T::ONE
        };
        // The friction ellipse: what the lateral acceleration leaves, at least 0.3
        // of it (a car sliding sideways still brakes): `grip·sqrt(1 − (a_y/grip)²)`
        // as `sqrt(grip² − a_y²)`, no division (`grip > 0`).
        let grip2 = grip * grip;
        let grip = larger(grip2 - lateral_mps2 * lateral_mps2, T::lit(0.09) * grip2).sqrt();
        // Braking at that grip, the front axle carries `l_r/L + (h/L)·a/g` of the
        // weight and gets `brake_front_share` of the torque: neither axle may be
        // asked more than its share of the grip (an anti-lock limit).
        let front_load =
            fc.front_load_share + fc.cg_height_over_wheelbase * mu * T::lit(TORQUE_GRIP_FRACTION);
        let [inv_front_brake, inv_rear_brake] = self.inv_brake_shares;
        let axle = smaller(
            smaller(
                front_load * inv_front_brake,
                (T::ONE - front_load) * inv_rear_brake,
            ),
            T::ONE,
        );
        // The inside driven wheel's grip: `inside` of the axle's, the lateral load
        // transfer taken off.
        let inside = grip
            * larger(
                T::ONE
                    - T::TWO
                        * lateral_mps2.abs()
                        * T::lit(1.0 / crate::G)
                        * fc.cg_height_over_track,
                T::lit(0.2),
            );
        // Driving at `a` moves `(h/L)·a/g` of the weight off the driven front axle:
        // `a = inside·(share − (h/L)·a/g)` gives `a = inside·share/(1 + y)`,
        // `y = inside·(h/L)/g`. `1/(1 + y)` by its series to `y³` (no division):
        // always below it, by `y⁴` of it (0.3 % at `y = 0.23`: `μ̂ = 1` and the
        // heavy car's `h/L = 0.25`; 6 % at `y = 0.5`: `μ̂ = 2`, `h/L = 0.28`).
        let y = inside * fc.cg_height_over_wheelbase * T::lit(1.0 / crate::G);
        let transfer = T::ONE - y * (T::ONE - y * (T::ONE - y));
        let traction = inside
            * (T::ONE - lon.mass_uncertainty(&fc.longitudinal))
            * fc.driven_load_share
            * transfer;
        CarModel {
            mass_kg: lon.mass_ratio() * m0,
            resistance_n: r0 * m0,
            drag_n_per_mps2: r2 * m0 * T::lit(1.0 / (V_REF_MPS * V_REF_MPS)),
            // Each driven wheel gets half the torque: the inside one, unloaded
            // by the lateral load transfer, spins first. For the lightest car the
            // estimate allows, `m̂·(1 − u)`: a car lighter than configured has
            // less load on its driven wheels (the heavy car at 0.8 of its mass
            // spun them at the start, unseen, its lightness hiding the shortfall).
            traction_grip_mps2: traction * traction_half,
            braking_grip_mps2: grip * larger(axle, T::ZERO) * braking_half,
            inverse_brake_gain: lon.inverse_brake_gain(),
            // The left wheels carry `1/2 − (h/t)·a_y/g` of the car's weight
            // (`a_y` to the left): each axle's braking torque is shared by it,
            // within [0.1, 0.9] (a noisy or extreme `a_y` never leaves a wheel
            // all or nothing).
            brake_left_share: clamp_within(
                T::HALF - fc.cg_height_over_track * T::lit(1.0 / crate::G) * transfer_mps2,
                T::lit(0.1),
                T::lit(0.9),
            ),
            hold_steering: self.steering_held(),
        }
    }

    /// One 10 ms activation at `now_us` on `est` following `plan` (both read under
    /// short locks by the caller), its feed-forward for the car as estimated
    /// ([`ControlTask::car_model`]). Never fails: on a fault (non-finite estimate,
    /// no valid plan) it returns the safe actuation and counts it.
    pub fn run(&mut self, est: &StateEstimate<T>, plan: &Plan<T>, now_us: u64) -> Actuation<T> {
        self.stats.activations = self.stats.activations.wrapping_add(1);
        self.friction.read_sensors(&self.friction_config, est);
        let spinning = self.friction.wheel_spinning();
        let locking = self.friction.wheel_locking();
        // Whether each limit is held is read back by `car_model`.
        let _ = self.spin_limit.update(spinning, est.stamp_us, now_us);
        let _ = self.lock_limit.update(locking, est.stamp_us, now_us);
        let lateral = self.lateral_demand(est);
        // The brakes' left/right shares follow the measured `V·ψ̇`.
        let car = self.car_model(lateral, est.vx_mps * est.yaw_rate_radps);
        let act = match low_level::control_with_model(
            &self.config,
            &mut self.state,
            plan,
            est,
            now_us,
            &car,
        ) {
            Ok(a) => {
                self.last_fault = None;
                let still = T::lit(STANDSTILL_MPS);
                self.stop_reason = if a.v_mps.abs() >= still {
                    None
                } else if a.mode == Mode::Stopping {
                    Some(StopReason::PlanRanOut)
                } else if a.v_ref_mps < still {
                    Some(StopReason::Planned)
                } else {
                    Some(StopReason::Starting)
                };
                self.friction.update(
                    &self.friction_config,
                    now_us,
                    est.stamp_us,
                    a.v_mps,
                    est.yaw_rate_radps,
                    a.torque_total_nm,
                );
                a
            }
            Err(fault) => {
                let safe = low_level::safe_actuation(&self.config, &self.state);
                self.friction.forget(safe.torque_total_nm);
                self.stats.safe_actuations = self.stats.safe_actuations.wrapping_add(1);
                match fault {
                    ControlFault::NonFiniteEstimate => {
                        self.stats.non_finite_estimates =
                            self.stats.non_finite_estimates.wrapping_add(1)
                    }
                    ControlFault::NonFinitePlan | ControlFault::InvalidPlan => {
                        self.stats.invalid_plans = self.stats.invalid_plans.wrapping_add(1)
                    }
                    ControlFault::Numerical => {}
                }
                self.last_fault = Some(fault);
                self.stop_reason = Some(StopReason::Fault(fault));
                safe
            }
        };
        let beyond = self.last_fault.is_some()
            || self.front_saturated()
            || self.front_sliding
            || self.friction.slipping()
            || self.friction.wheel_spinning()
            || self.friction.wheel_locking();
        self.linear_periods = if beyond {
            0
        } else {
            self.linear_periods
                .saturating_add(1)
                .min(TYRES_LINEAR_PERIODS)
        };
        act
    }
}

#[cfg(test)]
mod tests {
    use super::{WheelLimit, PLAN_DT_US};
    use crate::plan::PLAN_DT_S;

    #[test]
    fn plan_step_in_microseconds_matches_the_plan_step() {
        assert_eq!(PLAN_DT_US, (f64::from(PLAN_DT_S) * 1e6).round() as u64);
    }

    /// Releases every 10 ms from `t0` (µs), estimates `delay_us` old, the wheel
    /// slipping in those measured in `slipping_at` (µs, a half-open range): the
    /// releases at which the limit is halved.
    fn halved(delay_us: u64, slipping_at: core::ops::Range<u64>) -> Vec<u64> {
        let mut limit = WheelLimit::default();
        (0..40u64)
            .map(|k| 1_000_000 + 10_000 * k)
            .filter(|&now| {
                let stamp = now - delay_us;
                limit.update(slipping_at.contains(&stamp), stamp, now)
            })
            .collect()
    }

    #[test]
    fn fresh_estimates_halve_the_limit_while_they_show_the_wheel_slipping() {
        // Measured at their release: halved exactly at the releases that see it.
        assert_eq!(
            halved(0, 1_100_000..1_130_000),
            [1_100_000, 1_110_000, 1_120_000]
        );
    }

    #[test]
    fn late_estimates_keep_the_limit_halved_until_one_measured_after_it_shows_the_wheel_rolling() {
        // 100 ms late: the slip measured over 30 ms is seen from 1.2 s on; the
        // estimates measured before 1.2 s (seen until 1.29 s) cannot show what
        // the halving did, so it lasts until the one measured at 1.2 s, seen at
        // 1.3 s, shows the wheel rolling.
        let h = halved(100_000, 1_100_000..1_130_000);
        assert_eq!(h.first(), Some(&1_200_000));
        assert_eq!(h.last(), Some(&1_290_000));
        assert_eq!(h.len(), 10);
        // Still slipping when measured after the halving: halved until an
        // estimate measured after its start shows it rolling again.
        let h = halved(100_000, 1_100_000..1_250_000);
        assert_eq!((h.first(), h.last()), (Some(&1_200_000), Some(&1_340_000)));
    }
}
