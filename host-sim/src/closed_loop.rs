//! The closed loop on a deterministic timeline: the 9-DoF plant against the
//! firmware's two tasks, with every task activation checked against its budget.
//!
//! # Timeline
//!
//! Simulated time advances in plant steps (1 ms by default). Every 10 ms the
//! `control` task (high priority) runs on the plant's state at that instant and its
//! actuation is held until the next activation. Every 100 ms the `plan` task is
//! released on the state at its release (after `control`, which has the higher
//! priority, ran at the same instant); the host computes the plan at once, but the
//! plan is published only at the instant the task would have finished on the ECU:
//!
//! ```text
//! finish = release + (plan cycles + cycles of the control activations that preempt it) / f_ECU
//! ```
//!
//! A plan whose MPC status is not optimal is never published. A plan activation
//! whose response time exceeds its period (100 ms), or a control activation whose
//! cost exceeds its budget, is a deadline miss: counted and reported. A plan still
//! running at the next release makes that release skip (RTIC cannot spawn a busy
//! task): counted as a deadline miss too.
//!
//! # Costs
//!
//! The cost of an activation in ECU cycles is a deterministic estimate from the
//! firmware's work counters through [`CostModel`] (calibrated against instruction
//! counts under QEMU, see the README); the host's wall time is recorded beside it,
//! for information only.

use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use firmware::low_level::{Actuation, Mode};
use firmware::mpc::MpcReport;
use firmware::obstacles::Obstacle as FwObstacle;
use firmware::plan::{Plan, HORIZON};
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{ControlTask, PlanTask, CONTROL_PERIOD_US, PLAN_PERIOD_US};
use firmware::vehicle_config::VehicleConfig;
use firmware::Real;
use serde::Serialize;

use crate::obstacle_file::{self, Obstacle};
use crate::plant::{Inputs, Plant, State};
use crate::scenario::Scenario;
use crate::vehicle::VehicleParams;

/// Scalar the firmware computes in (the simulator can run it in either).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Precision {
    /// Single precision (the ECU's).
    F32,
    /// Double precision.
    F64,
}

impl Precision {
    /// `"f32"` or `"f64"`, as written in the corpus.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

/// Point capacity of the reference path on the host (the ECU build picks its own).
pub const HOST_PATH_CAP: usize = 4096;

/// Deterministic cost model of the two tasks, in ECU cycles.
///
/// `plan = passes·(per_pass + per_row·rows) + per_iteration·QP iterations`;
/// `control` is a constant (no data-dependent loops).
///
/// Calibrated on the `mpc_step` ECU binary under QEMU (`-icount shift=3`, one
/// instruction per 8 ns of virtual time): a least-squares fit of its 150 steps
/// (`.ci/ecu-check` prints them) gives 542,657 instructions per pass, 8,537 per
/// row and pass, 13,416 per QP iteration, within 4.6 % of every step; the control
/// task took at most 771 instructions. Instructions become cycles at 1.34 cycles
/// per instruction (a 168 MHz Cortex-M4F with flash wait states), plus 5 % for the
/// fit's largest error, so the estimate does not undercount.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CostModel {
    /// Fixed cost of a plan activation, cycles.
    pub plan_base: f64,
    /// Per linearise–condense–factorise pass (16 RK4 steps with Jacobians, the
    /// condensed Hessian, its Cholesky factor), cycles.
    pub plan_per_pass: f64,
    /// Per general QP row and pass (forming it, transforming it by `R⁻¹`), cycles.
    pub plan_per_row: f64,
    /// Per QP iteration (multiplier solve, factor update, constraint scan), cycles.
    pub plan_per_iteration: f64,
    /// One control activation, cycles.
    pub control: f64,
}

impl Default for CostModel {
    /// The QEMU calibration above.
    fn default() -> Self {
        let cycles = 1.34 * 1.05;
        Self {
            plan_base: 0.0,
            plan_per_pass: 542_657.0 * cycles,
            plan_per_row: 8_537.0 * cycles,
            plan_per_iteration: 13_416.0 * cycles,
            control: 771.0 * cycles,
        }
    }
}

impl CostModel {
    /// Estimated cycles of one plan activation from its work counters (an activation
    /// that fails before any pass costs one pass).
    pub fn plan_cycles<T: Real>(&self, r: Option<&MpcReport<T>>) -> f64 {
        match r {
            None => self.plan_base + self.plan_per_pass,
            Some(r) => {
                let passes = r.passes as f64;
                self.plan_base
                    + passes * (self.plan_per_pass + self.plan_per_row * r.rows as f64)
                    + self.plan_per_iteration * r.qp_iterations as f64
            }
        }
    }
}

/// Options of a closed-loop run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimOptions {
    /// Plant integration step, s (1 ms; must divide 10 ms).
    pub plant_dt_s: f64,
    /// ECU clock, Hz (168 MHz).
    pub ecu_clock_hz: f64,
    /// Budget of one control activation, cycles.
    pub control_budget_cycles: f64,
    /// Budget of one plan activation, cycles (its deadline is its 100 ms period).
    pub plan_budget_cycles: f64,
    /// Cost model.
    pub cost_model: CostModel,
    /// Friction coefficient of the road (the plant), dimensionless.
    pub mu_road: f64,
    /// Friction coefficient given to the planner, dimensionless.
    pub mu_planner: f64,
    /// Laps to drive (closed tracks) before stopping.
    pub laps: u32,
    /// Simulated time limit, s.
    pub max_duration_s: f64,
    /// Initial speed, m/s.
    pub initial_speed_mps: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            plant_dt_s: 1e-3,
            ecu_clock_hz: 168e6,
            control_budget_cycles: 5_000.0,
            plan_budget_cycles: 8.4e6,
            cost_model: CostModel::default(),
            mu_road: 1.0,
            mu_planner: 1.0,
            laps: 1,
            max_duration_s: 600.0,
            initial_speed_mps: 15.0,
        }
    }
}

/// One row of the 10 ms log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LogRow {
    /// Simulated time, s.
    pub t_s: f64,
    /// Position X, m.
    pub x_m: f64,
    /// Position Y, m.
    pub y_m: f64,
    /// Yaw, rad.
    pub psi_rad: f64,
    /// Speed, m/s.
    pub v_mps: f64,
    /// Reference speed `V^r` (plan, interpolated), m/s.
    pub v_ref_mps: f64,
    /// `V_heur` of the plan being followed at its first node, m/s.
    pub v_heur_mps: f64,
    /// Steering command `δ`, rad.
    pub delta_rad: f64,
    /// Open-loop steering `δ_ol`, rad.
    pub delta_ol_rad: f64,
    /// Closed-loop steering `δ_cl`, rad.
    pub delta_cl_rad: f64,
    /// Wheel torque front left, N·m.
    pub torque_fl_nm: f64,
    /// Wheel torque front right, N·m.
    pub torque_fr_nm: f64,
    /// Wheel torque rear left, N·m.
    pub torque_rl_nm: f64,
    /// Wheel torque rear right, N·m.
    pub torque_rr_nm: f64,
    /// Lateral acceleration, m/s².
    pub ay_mps2: f64,
    /// Lateral offset from the track's centre line (left positive), m.
    pub lateral_error_m: f64,
    /// Arc length driven along the track, m.
    pub progress_m: f64,
    /// Slip ratio front left.
    pub kappa_fl: f64,
    /// Slip ratio front right.
    pub kappa_fr: f64,
    /// Slip ratio rear left.
    pub kappa_rl: f64,
    /// Slip ratio rear right.
    pub kappa_rr: f64,
    /// Slip angle front left, rad.
    pub alpha_fl_rad: f64,
    /// Slip angle front right, rad.
    pub alpha_fr_rad: f64,
    /// Slip angle rear left, rad.
    pub alpha_rl_rad: f64,
    /// Slip angle rear right, rad.
    pub alpha_rr_rad: f64,
    /// Distance from the active plan's position at this instant, m.
    pub plan_deviation_m: f64,
    /// Status of the last plan activation (`optimal`, or the failure).
    pub plan_status: &'static str,
    /// Low-level controller mode.
    pub control_mode: &'static str,
}

/// A published plan's positions (for the trajectory figure).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanTrace {
    /// Release time, s.
    pub t_release_s: f64,
    /// Publication time, s.
    pub t_publish_s: f64,
    /// Node positions `[X, Y]`, m.
    pub xy: Vec<[f64; 2]>,
}

/// The run's figures of merit (`summary.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// The requested laps were driven (or the end of an open track reached).
    pub completed: bool,
    /// Why the run stopped.
    pub stop_reason: String,
    /// Time of the first completed lap, s (null if none).
    pub lap_time_s: Option<f64>,
    /// Distance driven along the track, m.
    pub distance_m: f64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Largest |lateral offset| from the centre line, m.
    pub max_abs_lateral_error_m: f64,
    /// RMS lateral offset, m.
    pub rms_lateral_error_m: f64,
    /// Largest |a_y|, m/s².
    pub max_abs_ay_mps2: f64,
    /// Road friction of the plant.
    pub mu: f64,
    /// Friction given to the planner.
    pub mu_planner: f64,
    /// Largest |slip angle| over the four tyres, rad.
    pub max_abs_slip_angle_rad: f64,
    /// Largest |slip ratio| over the four tyres.
    pub max_abs_slip_ratio: f64,
    /// Log samples at which the vehicle footprint overlapped an obstacle.
    pub collisions: u64,
    /// Smallest distance from the vehicle footprint to an obstacle polygon, m (null without obstacles).
    pub min_obstacle_clearance_m: Option<f64>,
    /// Largest speed, m/s.
    pub max_speed_mps: f64,
    /// Plan activations.
    pub plan_activations: u64,
    /// Plan activations that published nothing (MPC not optimal or refused).
    pub plan_failures: u64,
    /// Largest estimated cost of a plan activation, cycles.
    pub plan_max_cost_cycles: f64,
    /// Plan activations whose response time exceeded the period or cost the budget.
    pub plan_deadline_misses: u64,
    /// Largest estimated cost of a control activation, cycles.
    pub control_max_cost_cycles: f64,
    /// Control activations over budget.
    pub control_deadline_misses: u64,
    /// Control activations.
    pub control_activations: u64,
    /// Control activations that applied the safe actuation.
    pub control_safe_actuations: u64,
    /// Median host wall time of a plan activation, µs (information only).
    pub plan_host_us_p50: f64,
    /// Largest host wall time of a plan activation, µs (information only).
    pub plan_host_us_max: f64,
    /// Largest QP iterations in one plan activation.
    pub plan_max_qp_iterations: u32,
    /// Simulated seconds per wall-clock second.
    pub sim_speed_x_realtime: f64,
    /// Largest distance between where the active plan put the car and where it was, m.
    pub consistency_max_m: f64,
    /// Largest validity slack in any published plan, rad.
    pub max_validity_slack_rad: f64,
    /// Budgets used, cycles.
    pub plan_budget_cycles: f64,
    /// Budget of one control activation, cycles.
    pub control_budget_cycles: f64,
}

/// Everything a run produces.
#[derive(Clone, Debug, Default)]
pub struct RunResult {
    /// The 10 ms log.
    pub log: Vec<LogRow>,
    /// Published plans.
    pub plans: Vec<PlanTrace>,
    /// Estimated cost of each plan activation, cycles.
    pub plan_costs: Vec<f64>,
    /// Estimated cost of each control activation, cycles.
    pub control_costs: Vec<f64>,
    /// Figures of merit.
    pub summary: Summary,
}

/// What the firmware is told about the car of a vehicle file (the same numbers
/// the ECU receives in its configuration frame).
pub fn vehicle_config<T: Real>(v: &VehicleParams) -> VehicleConfig<T> {
    VehicleConfig {
        l_f_m: T::from_f64(v.lf_m),
        l_r_m: T::from_f64(v.lr_m),
        cg_height_m: T::from_f64(v.h_m),
        width_m: T::from_f64(vehicle_width_m(v)),
        length_m: T::from_f64(vehicle_length_m(v)),
        mass_kg: T::from_f64(v.mass_kg),
        wheel_radius_m: T::from_f64(v.r_eff_m),
        max_steer_rad: T::from_f64(v.max_steer_rad),
    }
}

/// Body width used for clearances: track plus a tyre width, m.
pub fn vehicle_width_m(v: &VehicleParams) -> f64 {
    2.0 * v.lw_m + 0.25
}

/// Body length used for clearances: wheelbase plus overhangs, m.
pub fn vehicle_length_m(v: &VehicleParams) -> f64 {
    v.lf_m + v.lr_m + 1.8
}

/// Distance from the centre of gravity to the body's front, m.
fn front_overhang_from_cg_m(v: &VehicleParams) -> f64 {
    v.lf_m + 0.9
}

fn estimate<T: Real>(s: &State, delta_rad: f64, t_us: u64) -> StateEstimate<T> {
    StateEstimate {
        stamp_us: t_us,
        x_m: T::from_f64(s.x_m),
        y_m: T::from_f64(s.y_m),
        psi_rad: T::from_f64(s.psi_rad),
        vx_mps: T::from_f64(s.vx_mps),
        vy_mps: T::from_f64(s.vy_mps),
        yaw_rate_radps: T::from_f64(s.yaw_rate_radps),
        delta_rad: T::from_f64(delta_rad),
    }
}

fn plan_position_at<T: Real>(plan: &Plan<T>, t_us: u64) -> Option<[f64; 2]> {
    let dt = plan.dt_s.to_f64();
    if dt <= 0.0 || t_us < plan.stamp_us {
        return None;
    }
    let tau = (t_us - plan.stamp_us) as f64 * 1e-6 / dt;
    if tau > HORIZON as f64 {
        return None;
    }
    let i = (tau.floor() as usize).min(HORIZON - 1);
    let f = tau - i as f64;
    let (a, b) = (plan.nodes[i], plan.nodes[i + 1]);
    Some([
        a.x_m.to_f64() + f * (b.x_m.to_f64() - a.x_m.to_f64()),
        a.y_m.to_f64() + f * (b.y_m.to_f64() - a.y_m.to_f64()),
    ])
}

fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Following => "following",
        Mode::Extrapolating => "extrapolating",
        Mode::Stopping => "stopping",
        Mode::Safe => "safe",
    }
}

fn mpc_error_name(e: &firmware::mpc::MpcError) -> &'static str {
    use firmware::mpc::MpcError as E;
    use firmware::qp::QpStatus as Q;
    match e {
        E::NonFiniteState => "non_finite_state",
        E::InvalidFriction => "invalid_friction",
        E::InvalidSettings => "invalid_settings",
        E::NoPath => "no_path",
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

/// Runs the closed loop of `scenario` with the firmware in precision `T`.
///
/// `progress` is called every simulated second with `(t_s, distance_m)`.
pub fn run<T: Real>(
    scenario: &Scenario,
    vehicle: &VehicleParams,
    opts: &SimOptions,
    mut progress: impl FnMut(f64, f64),
) -> Result<RunResult> {
    let wall = Instant::now();
    let steps_per_control = (CONTROL_PERIOD_US as f64 * 1e-6 / opts.plant_dt_s).round() as u64;
    if steps_per_control == 0 || ((steps_per_control as f64) * opts.plant_dt_s - 0.01).abs() > 1e-12
    {
        return Err(anyhow!(
            "plant step {} s does not divide the 10 ms control period: use e.g. 0.001 or 0.0005",
            opts.plant_dt_s
        ));
    }
    let step_us = CONTROL_PERIOD_US / steps_per_control;
    let track = &scenario.track;

    // The planner: path, obstacles, MPC (boxed: the path is large on the host).
    let car = vehicle_config::<T>(vehicle);
    let mu_planner = T::from_f64(opts.mu_planner);
    let mut planner: Box<PlanTask<T, HOST_PATH_CAP>> =
        Box::new(PlanTask::new(car.mpc_settings(), mu_planner));
    let rows: Vec<[T; 4]> = track
        .rows()
        .iter()
        .map(|r| {
            [
                T::from_f64(r[0]),
                T::from_f64(r[1]),
                T::from_f64(r[2]),
                T::from_f64(r[3]),
            ]
        })
        .collect();
    planner
        .path
        .load_track(&rows, track.closed)
        .map_err(|e| anyhow!("track {}: the planner refused it: {e:?}", track.name))?;
    let fw_obstacles = scenario
        .obstacles
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let v: Vec<[T; 2]> = o
                .vertices
                .iter()
                .map(|p| [T::from_f64(p[0]), T::from_f64(p[1])])
                .collect();
            FwObstacle::from_vertices(k as u32, &v)
                .map_err(|e| anyhow!("obstacle {:?}: {e:?}", o.id))
        })
        .collect::<Result<Vec<_>>>()?;
    planner
        .obstacles
        .update(
            &car.obstacle_settings(mu_planner),
            &planner.path,
            &fw_obstacles,
        )
        .map_err(|e| obstacle_error_message(e, &scenario.obstacles))?;

    let mut control = ControlTask::new(car.low_level_config())
        .map_err(|e| anyhow!("low-level controller configuration: {e:?}"))?;

    // The plant, on the centre line at the start, heading along the track.
    let start = scenario.start_pose;
    let mut init = State::at_speed(opts.initial_speed_mps, vehicle);
    init.x_m = start[0];
    init.y_m = start[1];
    init.psi_rad = start[2];
    let mut plant = Plant::with_step(*vehicle, init, opts.plant_dt_s).context("plant")?;

    let mut shared_plan: Plan<T> = Plan::zeroed();
    let mut pending_publish_us: Option<u64> = None;
    let mut plan_busy_until_us: u64 = 0;
    let mut inputs = Inputs::default();
    let mut last_status: &'static str = "none";

    let mut res = RunResult::default();
    let mut sum = Summary {
        mu: opts.mu_road,
        mu_planner: opts.mu_planner,
        plan_budget_cycles: opts.plan_budget_cycles,
        control_budget_cycles: opts.control_budget_cycles,
        ..Summary::default()
    };
    let mut host_us: Vec<f64> = Vec::new();
    let (mut sum_sq_lat, mut n_lat) = (0.0f64, 0u64);
    let mut s_hint: Option<f64> = None;
    let mut progress_m = 0.0f64;
    let mut s_prev = 0.0f64;
    let projector = track.projector();
    let lap_length = track.length();
    let target_m = if track.closed {
        lap_length * opts.laps.max(1) as f64
    } else {
        lap_length
    };
    let half_len = 0.5 * vehicle_length_m(vehicle);
    let cg_offset = front_overhang_from_cg_m(vehicle) - half_len;
    let width = vehicle_width_m(vehicle);
    let max_half_width = track
        .w_left
        .iter()
        .chain(track.w_right.iter())
        .fold(0.0f64, |a, &b| a.max(b));
    let mut stopped_for_s = 0.0f64;

    let max_steps = (opts.max_duration_s / opts.plant_dt_s).ceil() as u64;
    let mut t_us: u64 = 0;
    let mut step: u64 = 0;
    let mut stop_reason = String::from("time limit reached");
    while step <= max_steps {
        if t_us % CONTROL_PERIOD_US == 0 {
            // A plan that has finished on the ECU by now is published first.
            if let Some(ft) = pending_publish_us {
                if ft <= t_us {
                    planner.publish(&mut shared_plan);
                    if let Some(tr) = trace_of(&shared_plan, ft) {
                        res.plans.push(tr);
                    }
                    pending_publish_us = None;
                }
            }
            let st = *plant.state();
            let out = plant.outputs();
            let est = estimate::<T>(&st, out.delta_rad, t_us);
            let act = control.run(&est, &shared_plan, t_us);
            let c_cost = opts.cost_model.control;
            res.control_costs.push(c_cost);
            sum.control_activations += 1;
            if c_cost > opts.control_budget_cycles {
                sum.control_deadline_misses += 1;
            }
            sum.control_max_cost_cycles = sum.control_max_cost_cycles.max(c_cost);
            inputs = Inputs {
                torque_nm: act.wheel_torque_nm.map(|x| x.to_f64()),
                delta_rad: act.delta_rad.to_f64(),
            };

            if t_us % PLAN_PERIOD_US == 0 {
                sum.plan_activations += 1;
                if plan_busy_until_us > t_us {
                    // Still running: this release is lost.
                    sum.plan_deadline_misses += 1;
                } else {
                    let h0 = Instant::now();
                    let outcome = planner.run(&est);
                    host_us.push(h0.elapsed().as_secs_f64() * 1e6);
                    let cycles = opts.cost_model.plan_cycles(outcome.as_ref().ok());
                    res.plan_costs.push(cycles);
                    sum.plan_max_cost_cycles = sum.plan_max_cost_cycles.max(cycles);
                    // Response time: the plan's cycles plus the control activations
                    // that preempt it meanwhile.
                    let mut resp_s = cycles / opts.ecu_clock_hz;
                    for _ in 0..64 {
                        let preempting = (resp_s * 1e6 / CONTROL_PERIOD_US as f64).floor();
                        let next =
                            (cycles + preempting * opts.cost_model.control) / opts.ecu_clock_hz;
                        if (next - resp_s).abs() < 1e-12 {
                            break;
                        }
                        resp_s = next;
                    }
                    let finish_us = t_us + (resp_s * 1e6).ceil() as u64;
                    plan_busy_until_us = finish_us;
                    if cycles > opts.plan_budget_cycles || finish_us > t_us + PLAN_PERIOD_US {
                        sum.plan_deadline_misses += 1;
                    }
                    match outcome {
                        Ok(r) => {
                            pending_publish_us = Some(finish_us);
                            sum.plan_max_qp_iterations =
                                sum.plan_max_qp_iterations.max(r.qp_iterations);
                            sum.max_validity_slack_rad = sum
                                .max_validity_slack_rad
                                .max(r.max_validity_slack_rad.to_f64());
                            last_status = "optimal";
                        }
                        Err(e) => {
                            sum.plan_failures += 1;
                            last_status = mpc_error_name(&e);
                        }
                    }
                }
            }

            // Measurements of this instant.
            let (s, lat) = projector.project([st.x_m, st.y_m], s_hint);
            if s_hint.is_some() {
                // Arc length driven since the last sample (across the lap line too).
                let mut ds = s - s_prev;
                if track.closed {
                    if ds > 0.5 * lap_length {
                        ds -= lap_length;
                    } else if ds < -0.5 * lap_length {
                        ds += lap_length;
                    }
                }
                progress_m += ds;
            }
            s_prev = s;
            s_hint = Some(s);
            sum_sq_lat += lat * lat;
            n_lat += 1;
            sum.max_abs_lateral_error_m = sum.max_abs_lateral_error_m.max(lat.abs());
            sum.max_abs_ay_mps2 = sum.max_abs_ay_mps2.max(out.ay_mps2.abs());
            sum.max_speed_mps = sum.max_speed_mps.max(st.speed_mps());
            for i in 0..4 {
                sum.max_abs_slip_angle_rad = sum.max_abs_slip_angle_rad.max(out.alpha_rad[i].abs());
                sum.max_abs_slip_ratio = sum.max_abs_slip_ratio.max(out.kappa[i].abs());
            }
            let dev = plan_position_at(&shared_plan, t_us)
                .map(|p| (p[0] - st.x_m).hypot(p[1] - st.y_m))
                .unwrap_or(0.0);
            if shared_plan.dt_s > T::ZERO {
                sum.consistency_max_m = sum.consistency_max_m.max(dev);
            }
            if !scenario.obstacles.is_empty() {
                let fp = obstacle_file::vehicle_footprint(
                    st.x_m + cg_offset * st.psi_rad.cos(),
                    st.y_m + cg_offset * st.psi_rad.sin(),
                    st.psi_rad,
                    vehicle_length_m(vehicle),
                    width,
                );
                for o in &scenario.obstacles {
                    let d = obstacle_file::distance(&fp, &o.vertices);
                    if obstacle_file::intersects(&fp, &o.vertices) {
                        sum.collisions += 1;
                    }
                    sum.min_obstacle_clearance_m =
                        Some(sum.min_obstacle_clearance_m.map_or(d, |m: f64| m.min(d)));
                }
            }
            let g = |f: fn(&Actuation<T>) -> T| f(&act).to_f64();
            res.log.push(LogRow {
                t_s: t_us as f64 * 1e-6,
                x_m: st.x_m,
                y_m: st.y_m,
                psi_rad: st.psi_rad,
                v_mps: st.speed_mps(),
                v_ref_mps: g(|x| x.v_ref_mps),
                v_heur_mps: shared_plan.v_heur_mps[0].to_f64(),
                delta_rad: g(|x| x.delta_rad),
                delta_ol_rad: g(|x| x.delta_ol_rad),
                delta_cl_rad: g(|x| x.delta_cl_rad),
                torque_fl_nm: inputs.torque_nm[0],
                torque_fr_nm: inputs.torque_nm[1],
                torque_rl_nm: inputs.torque_nm[2],
                torque_rr_nm: inputs.torque_nm[3],
                ay_mps2: out.ay_mps2,
                lateral_error_m: lat,
                progress_m,
                kappa_fl: out.kappa[0],
                kappa_fr: out.kappa[1],
                kappa_rl: out.kappa[2],
                kappa_rr: out.kappa[3],
                alpha_fl_rad: out.alpha_rad[0],
                alpha_fr_rad: out.alpha_rad[1],
                alpha_rl_rad: out.alpha_rad[2],
                alpha_rr_rad: out.alpha_rad[3],
                plan_deviation_m: dev,
                plan_status: last_status,
                control_mode: mode_name(act.mode),
            });

            // Stop conditions.
            if sum.lap_time_s.is_none() && progress_m >= lap_length {
                sum.lap_time_s = Some(t_us as f64 * 1e-6);
            }
            if progress_m >= target_m {
                sum.completed = true;
                stop_reason = "completed".into();
                break;
            }
            if lat.abs() > max_half_width + 3.0 {
                stop_reason = format!(
                    "left the road at t = {:.2} s ({lat:.2} m off the centre line)",
                    t_us as f64 * 1e-6
                );
                break;
            }
            if st.speed_mps() < 0.05 {
                stopped_for_s += CONTROL_PERIOD_US as f64 * 1e-6;
                if stopped_for_s > 5.0 {
                    stop_reason = format!("stood still for 5 s at t = {:.2} s", t_us as f64 * 1e-6);
                    break;
                }
            } else {
                stopped_for_s = 0.0;
            }
            if t_us % 1_000_000 == 0 {
                progress(t_us as f64 * 1e-6, progress_m);
            }
        }
        plant
            .step(&inputs, opts.mu_road)
            .with_context(|| format!("plant step at t = {:.3} s", t_us as f64 * 1e-6))?;
        t_us += step_us;
        step += 1;
    }

    sum.stop_reason = stop_reason;
    sum.distance_m = progress_m;
    sum.duration_s = t_us as f64 * 1e-6;
    sum.rms_lateral_error_m = if n_lat > 0 {
        (sum_sq_lat / n_lat as f64).sqrt()
    } else {
        0.0
    };
    sum.control_safe_actuations = control.stats.safe_actuations as u64;
    host_us.sort_by(|a, b| a.total_cmp(b));
    sum.plan_host_us_p50 = host_us.get(host_us.len() / 2).copied().unwrap_or(0.0);
    sum.plan_host_us_max = host_us.last().copied().unwrap_or(0.0);
    let wall_s = wall.elapsed().as_secs_f64();
    sum.sim_speed_x_realtime = if wall_s > 0.0 {
        sum.duration_s / wall_s
    } else {
        0.0
    };
    res.summary = sum;
    Ok(res)
}

fn trace_of<T: Real>(plan: &Plan<T>, publish_us: u64) -> Option<PlanTrace> {
    if plan.dt_s <= T::ZERO {
        return None;
    }
    Some(PlanTrace {
        t_release_s: plan.stamp_us as f64 * 1e-6,
        t_publish_s: publish_us as f64 * 1e-6,
        xy: plan
            .nodes
            .iter()
            .map(|n| [n.x_m.to_f64(), n.y_m.to_f64()])
            .collect(),
    })
}

fn obstacle_error_message<T: Real>(
    e: firmware::obstacles::ObstacleError<T>,
    obstacles: &[Obstacle],
) -> anyhow::Error {
    use firmware::obstacles::ObstacleError as E;
    match e {
        E::RoadBlocked {
            obstacle,
            missing_m,
        } => {
            let id = obstacles
                .get(obstacle)
                .map(|o| o.id.as_str())
                .unwrap_or("?");
            anyhow!(
                "obstacle {id:?} blocks the road: the car needs {:.2} m more free width beside it on either side; move it, make it narrower, or widen the track there",
                missing_m.to_f64()
            )
        }
        other => anyhow!("obstacles: {other:?}"),
    }
}
