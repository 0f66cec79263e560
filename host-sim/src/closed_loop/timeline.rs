//! The closed loop on a deterministic timeline: the 9-DoF plant against the
//! firmware, with every task activation checked against its budget and deadline.
//!
//! The driver ([`run_with`]) owns the plant, the measurements, the log, the
//! summary and the stop conditions; what runs the firmware is an [`Ecu`]: the
//! firmware's tasks in this process on a modelled timeline ([`SimulatedEcu`],
//! what [`run`] uses), or the firmware on an emulated ECU. The driver assumes
//! nothing of it beyond the trait.
//!
//! # Timeline
//!
//! Simulated time advances in plant steps (1 ms by default). Every 10 ms the
//! driver calls [`Ecu::control`] on the plant's state at that instant. The
//! actuation it returns acts from the instant the ECU sent it
//! ([`ControlOutput::sent_us`]), as on a car: the plant steps at 1 kHz with its
//! inputs held over a step, so the actuation takes effect at the first plant step
//! at or after its send instant rounded down to the step grid, i.e. from the step
//! during which it was sent, `⌊sent / step⌋·step` (never before the release it
//! answers), and is held until the next one takes effect. An answer sent within
//! the first plant step after its release (every answer of the ECU at 168 MHz in
//! PIL, the first included: its first release is a tick of its monotonic, as
//! every later one) acts at the release, so on-time answers give the same
//! trajectory as the modelled ECU's; a late answer acts late. The instant and
//! step of each are in [`RunResult::actuations`]. Every 100 ms the
//! `plan` task is released on the state at its release (after `control`, which
//! has the higher priority, ran at the same instant). How long it runs and when
//! its plan is published is the ECU's to say ([`SimulatedEcu`]: see
//! [`crate::closed_loop::ecu`]).
//!
//! # The road's friction and grade
//!
//! The plant steps on `SimOptions::mu_road`, or, with patches
//! ([`Scenario::mu_patches`]), each wheel on the μ at its own arc length: the car's,
//! projected at each 10 ms sample and advanced by its speed over the plant steps
//! between samples, plus `l_f` ahead for the front wheels and `l_r` behind for the
//! rear ones ([`crate::world::road_friction`]). The log's `road_mu` is the lowest of the
//! four at the sample; the summary judges the ECU's `μ̂` against it.
//!
//! With grade patches ([`Scenario::grade_patches`]) the plant steps on the grade
//! under the car at the same arc length, the chord between its axles
//! ([`crate::world::road_grade`]); the log's `road_grade_pct` is that grade at the
//! sample, `specific_force_x_mps2` what an accelerometer on the car reads. The
//! estimate the ECU receives carries no acceleration: the firmware sees a grade
//! only through the speed it measures.
//!
//! # Deadlines and budgets
//!
//! Budgets are in ECU cycles (control 6,000, plan 15.96 M); deadlines are times: a
//! plan activation whose response time exceeds its 100 ms period, and a control
//! activation that completes more than its 10 ms period after its release
//! ([`ControlOutput::completion`]: when its answer has left it, which may follow
//! the instant the answer carries, [`ControlOutput::sent_us`]), are deadline
//! misses, and so is every skipped
//! release of either task (counted apart too: `plan_skipped_releases`,
//! `control_skipped_releases`). An activation over its cycle budget is a budget overrun, counted apart
//! (it may or may not miss its deadline, depending on the clock). All are counted
//! and reported, never absorbed.
//!
//! # Late plans
//!
//! A plan activation that finishes after its deadline still publishes its plan when
//! it finishes: it is the newest plan, a trajectory stamped at its release, which
//! `control` follows at the current time (shifted). Until then `control` keeps
//! following the previous plan shifted in time, and brings the car to a controlled
//! stop when it runs out. A release that falls while the `plan` task is still
//! running is skipped, not queued (RTIC cannot spawn a busy task), so the next
//! activation plans from a fresh state; each skipped release is a deadline miss.
//! A plan whose MPC status is not optimal is never published.
//!
//! # Costs
//!
//! The cost of an activation is a deterministic estimate in ECU instructions from
//! the firmware's work counters through [`CostModel`](crate::closed_loop::cost_model::CostModel) (failed activations from
//! their own counters too); cycles are instructions ×
//! [`SimOptions::cycles_per_instruction`]. The host's wall time is recorded
//! beside it, for information only.

use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use firmware::low_level::{Actuation, Mode};
use firmware::plan::{Plan, HORIZON};
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{CONTROL_PERIOD_US, PLAN_PERIOD_US};
use firmware::Real;
use serde::Serialize;

use crate::closed_loop::ecu::{ControlOutput, Ecu, SimulatedEcu};
use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::summary::{CarEstimate, Summary};
use crate::closed_loop::SimOptions;
use crate::model::plant::{Inputs, Outputs, Plant, RoadUnder, State};
use crate::model::vehicle::VehicleParams;
use crate::model::vehicle::{vehicle_length_m, vehicle_width_m};
use crate::world::lap_patches;
use crate::world::obstacle_file;
use crate::world::road_friction::{judge, MuSample, RoadFriction};
use crate::world::road_grade::RoadGrade;
use crate::world::scenario::Scenario;

/// The stop reason of a run that reached its `--duration` (its `max_duration_s`).
pub const TIME_LIMIT_REASON: &str = "time limit reached";

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
    /// Steering angle the actuator applied over the last plant step, rad (the
    /// command itself with ideal actuators; the estimate's measured angle).
    pub delta_applied_rad: f64,
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
    /// Longitudinal specific force at the centre of gravity, m/s²: what an
    /// accelerometer on the car reads along its `x` axis, the acceleration plus
    /// `g·sin γ` on a grade ([`crate::model::plant::Outputs::specific_force_x_mps2`]).
    pub specific_force_x_mps2: f64,
    /// The road's grade under the car (the chord between its axles:
    /// [`crate::world::road_grade`]), %.
    pub road_grade_pct: f64,
    /// Lateral offset from the track's centre line (left positive), m.
    pub lateral_error_m: f64,
    /// Arc length driven along the track, m.
    pub progress_m: f64,
    /// Wheel speed `ω·r_eff` front left (the plant's, before the estimate's
    /// noise and delay), m/s.
    pub wheel_speed_fl_mps: f64,
    /// Wheel speed front right, m/s.
    pub wheel_speed_fr_mps: f64,
    /// Wheel speed rear left, m/s.
    pub wheel_speed_rl_mps: f64,
    /// Wheel speed rear right, m/s.
    pub wheel_speed_rr_mps: f64,
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
    /// Status of the last plan activation that finished (`optimal`, the failure, or
    /// `none` before the first finishes).
    pub plan_status: &'static str,
    /// Low-level controller mode.
    pub control_mode: &'static str,
    /// The control task's friction estimate `μ̂` (`firmware::friction`): `inf`
    /// before any slip, NaN when the ECU does not report it (processor in the loop).
    pub friction_mu: f64,
    /// The road's friction under the car: the lowest of the four wheels' (they
    /// differ on the edge of a `--mu-patch`; see [`crate::world::road_friction`]).
    pub road_mu: f64,
    /// The plan task's sideslip lag `λ` (`firmware::sideslip`), rad per m/s²: the
    /// plans' course lags the kinematic bicycle's by `λ·a_y`; NaN when the ECU does
    /// not report it (processor in the loop).
    pub sideslip_lag_rad_per_mps2: f64,
    /// The control task's mass ratio `k = m/m₀` (`firmware::longitudinal_estimator`;
    /// this and the five columns after it NaN when the ECU does not report them).
    pub est_mass_ratio: f64,
    /// Its uncertainty `u`, dimensionless.
    pub est_mass_uncertainty: f64,
    /// The estimated resistance at rest per configured mass `r₀`, m/s².
    pub est_resistance_r0_mps2: f64,
    /// The estimated drag per configured mass at 30 m/s `r₂`, m/s².
    pub est_resistance_r2_mps2: f64,
    /// The estimated brakes' gain `b` (brake torque given per N·m commanded).
    pub est_brake_gain: f64,
    /// Its uncertainty `u_b`, dimensionless.
    pub est_brake_uncertainty: f64,
}

impl LogRow {
    /// The wheel-speed columns, `[fl, fr, rl, rr]`, m/s.
    pub fn set_wheel_speeds(&mut self, w: [f64; 4]) {
        [
            self.wheel_speed_fl_mps,
            self.wheel_speed_fr_mps,
            self.wheel_speed_rl_mps,
            self.wheel_speed_rr_mps,
        ] = w;
    }

    /// The columns of the control task's estimate of the car.
    pub fn set_car_estimate(&mut self, e: &CarEstimate) {
        self.est_mass_ratio = e.mass_ratio;
        self.est_mass_uncertainty = e.mass_uncertainty;
        self.est_resistance_r0_mps2 = e.resistance_r0_mps2;
        self.est_resistance_r2_mps2 = e.resistance_r2_mps2;
        self.est_brake_gain = e.brake_gain;
        self.est_brake_uncertainty = e.brake_uncertainty;
    }
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

/// When a control activation's answer was sent and from when the plant applied it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ActuationTiming {
    /// The control release it answered, µs.
    pub release_us: u64,
    /// When the ECU sent it, µs ([`ControlOutput::sent_us`]).
    pub sent_us: u64,
    /// The instant of the plant step from which it acts, µs: the step containing
    /// `sent_us`, never before the release (module docs).
    pub applied_us: u64,
}

/// Everything a run produces.
#[derive(Clone, Debug, Default)]
pub struct RunResult {
    /// The 10 ms log.
    pub log: Vec<LogRow>,
    /// Published plans.
    pub plans: Vec<PlanTrace>,
    /// Every plan activation that finished, in order.
    pub plan_activations: Vec<PlanActivation>,
    /// Estimated cost of each finished plan activation, cycles.
    pub plan_costs: Vec<f64>,
    /// Estimated cost of each control activation, cycles.
    pub control_costs: Vec<f64>,
    /// Estimated cost of each control activation, instructions.
    pub control_instructions: Vec<f64>,
    /// When each control activation's answer was sent and applied, one per log row.
    pub actuations: Vec<ActuationTiming>,
    /// Figures of merit.
    pub summary: Summary,
}

/// Distance from the centre of gravity to the body's front, m.
fn front_overhang_from_cg_m(v: &VehicleParams) -> f64 {
    v.lf_m + 0.9
}

/// The plant's true state as an estimate at `t_us` (µs): with the outputs of its
/// last step `out`, the measured steering angle and the accelerometer's specific
/// force; the wheel speeds `ω·r_eff` (`r_eff_m`, m).
fn estimate<T: Real>(s: &State, out: &Outputs, t_us: u64, r_eff_m: f64) -> StateEstimate<T> {
    StateEstimate {
        stamp_us: t_us,
        x_m: T::from_f64(s.x_m),
        y_m: T::from_f64(s.y_m),
        psi_rad: T::from_f64(s.psi_rad),
        vx_mps: T::from_f64(s.vx_mps),
        vy_mps: T::from_f64(s.vy_mps),
        yaw_rate_radps: T::from_f64(s.yaw_rate_radps),
        delta_rad: T::from_f64(out.delta_rad),
        wheel_speed_mps: s.omega_radps.map(|w| T::from_f64(w * r_eff_m)),
        specific_force_x_mps2: T::from_f64(out.specific_force_x_mps2),
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

/// Runs the closed loop of `scenario` with the firmware in precision `T` on the
/// modelled ECU ([`SimulatedEcu`]).
///
/// `progress` is called every simulated second with `(t_s, distance_m)`.
pub fn run<T: Real>(
    scenario: &Scenario,
    vehicle: &VehicleParams,
    opts: &SimOptions,
    progress: impl FnMut(f64, f64),
) -> Result<RunResult> {
    let mut ecu = SimulatedEcu::<T>::new(scenario, vehicle, opts)?;
    run_with(scenario, vehicle, opts, &mut ecu, progress)
}

/// Runs the closed loop of `scenario` against `ecu` (which runs the firmware in
/// precision `T`): the plant, the measurements, the log, the summary and the stop
/// conditions.
///
/// `progress` is called every simulated second with `(t_s, distance_m)`.
pub fn run_with<T: Real, E: Ecu<T>>(
    scenario: &Scenario,
    vehicle: &VehicleParams,
    opts: &SimOptions,
    ecu: &mut E,
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

    // The plant, on the centre line at the start, heading along the track.
    let start = scenario.start_pose;
    let mut init = State::at_speed(opts.initial_speed_mps, vehicle);
    init.x_m = start[0];
    init.y_m = start[1];
    init.psi_rad = start[2];
    let mut plant = Plant::with_step(*vehicle, init, opts.plant_dt_s).context("plant")?;

    let mut inputs = Inputs::default();
    // Actuations waiting for the plant step they take effect at, in order.
    let mut pending: std::collections::VecDeque<(u64, Inputs)> = Default::default();
    let mut res = RunResult::default();
    let mut meter = Meter::new(scenario, vehicle, opts);
    if ecu.reports_plan_states() {
        meter.sum.max_abs_plan_ay_mps2 = Some(0.0);
    }
    let mut host_us: Vec<f64> = Vec::new();
    let mut last_status: &'static str = "none";

    // The road the ECU holds: a window, the next one sent as the car moves on.
    let mut feeder = crate::world::route::RouteFeeder::new(&scenario.track)?;
    // The road's friction and grade along the track, and where the car was at the
    // last sample: arc length (m), speed (m/s), time (µs), to place the wheels
    // between samples.
    let road = RoadFriction::new(
        opts.mu_road,
        &scenario.mu_patches,
        &scenario.track.name,
        scenario.track.length(),
        scenario.track.closed,
    )?;
    let grade = RoadGrade::new(
        &scenario.grade_patches,
        &scenario.track.name,
        scenario.track.length(),
        scenario.track.closed,
    )?;
    let mut at_sample = (0.0, 0.0, 0u64);
    feeder.first();
    let s_start = scenario
        .track
        .projector()
        .project([scenario.start_pose[0], scenario.start_pose[1]], None)
        .0;

    let max_steps = (opts.max_duration_s / opts.plant_dt_s).ceil() as u64;
    let mut t_us: u64 = 0;
    let mut step: u64 = 0;
    let mut stop_reason = String::from(TIME_LIMIT_REASON);
    while step <= max_steps {
        if t_us.is_multiple_of(CONTROL_PERIOD_US) {
            let st = *plant.state();
            let out = plant.outputs();
            let est = estimate::<T>(&st, &out, t_us, vehicle.r_eff_m);
            if let Some(w) = feeder.update(s_start + meter.progress_m) {
                ecu.set_window(&w).with_context(|| {
                    format!("window of the road at t = {:.3} s", t_us as f64 * 1e-6)
                })?;
            }
            let h0 = Instant::now();
            let c = ecu
                .control(t_us, &est)
                .with_context(|| format!("ECU at t = {:.3} s", t_us as f64 * 1e-6))?;
            if t_us.is_multiple_of(PLAN_PERIOD_US) {
                // A release (the ECU's contract): counted here, run or skipped.
                meter.sum.plan_activations += 1;
                if c.skipped_releases == 0 {
                    host_us.push(h0.elapsed().as_secs_f64() * 1e6);
                }
            }
            meter.account(opts, &c, &mut res);
            if let Some(p) = c.plans.last() {
                last_status = p.status;
            }
            if let Some(p) = c.plans.iter().rev().find(|p| p.published) {
                if let Some(tr) = trace_of(ecu.active_plan(), p.finish_us) {
                    res.plans.push(tr);
                }
                if let Some(max) = meter.sum.max_abs_plan_ay_mps2.as_mut() {
                    *max = max.max(plan_max_kinematic_ay(ecu.active_plan(), vehicle));
                }
            }
            let act = c.actuation;
            // From the plant step containing the send instant (module docs).
            let apply_us = (c.sent_us / step_us * step_us).max(t_us);
            res.actuations.push(ActuationTiming {
                release_us: c.release_us,
                sent_us: c.sent_us,
                applied_us: apply_us,
            });
            pending.push_back((
                apply_us,
                Inputs {
                    torque_nm: act.wheel_torque_nm.map(|x| x.to_f64()),
                    delta_rad: act.delta_rad.to_f64(),
                },
            ));
            let mut row = meter.measure(t_us, &st, &out, &act, ecu.active_plan(), last_status);
            at_sample = (meter.s_prev, st.vx_mps, t_us);
            meter.road_and_estimates(&mut row, &st, &c, (&road, &grade));
            res.log.push(row);
            if let Some(reason) = meter.stop_reason(t_us, &st, &row) {
                stop_reason = reason;
                break;
            }
            if t_us.is_multiple_of(1_000_000) {
                progress(t_us as f64 * 1e-6, meter.progress_m);
            }
        }
        while let Some(&(at, next)) = pending.front() {
            if at > t_us {
                break;
            }
            inputs = next;
            pending.pop_front();
        }
        let (s, v, t0) = at_sample;
        let s_now = s + v * (t_us - t0) as f64 * 1e-6;
        let under = RoadUnder {
            mu: if road.is_uniform() {
                [opts.mu_road; 4]
            } else {
                road.wheels_mu(s_now, vehicle.lf_m, vehicle.lr_m)
            },
            grade_rad: grade.under_car_rad(s_now, vehicle.lf_m, vehicle.lr_m),
        };
        plant
            .step_on_road(&inputs, &under)
            .with_context(|| format!("plant step at t = {:.3} s", t_us as f64 * 1e-6))?;
        t_us += step_us;
        step += 1;
    }

    res.summary = finish_summary(meter, t_us, stop_reason, &res, &plant, host_us, wall);
    Ok(res)
}

/// The run's summary at its end (`t_us`, µs): the driver's, with the road's
/// patches, the actuators, the friction estimate's verdict, the wheels' lift and
/// the host's plan times (`host_us`, µs) and speed since `wall`.
fn finish_summary(
    meter: Meter<'_>,
    t_us: u64,
    stop_reason: String,
    res: &RunResult,
    plant: &Plant,
    mut host_us: Vec<f64>,
    wall: Instant,
) -> Summary {
    let (scenario, vehicle) = (meter.scenario, meter.vehicle);
    let mut sum = meter.finish(t_us, stop_reason, res);
    sum.mu_patches = lap_patches::join(&scenario.mu_patches);
    sum.grade_patches = lap_patches::join(&scenario.grade_patches);
    sum.actuators = vehicle.actuators.to_settings_string();
    let samples: Vec<MuSample> = res
        .log
        .iter()
        .map(|r| MuSample {
            t_s: r.t_s,
            road_mu: r.road_mu,
            mu_hat: r.friction_mu,
        })
        .collect();
    if let Some(v) = judge(&samples) {
        sum.mu_false_drop = Some(v.false_drop);
        sum.mu_false_drop_s = v.first_false_drop_s;
        sum.mu_recovery_s = v.recovery_s;
        sum.mu_unrecovered_exits = Some(v.unrecovered_exits);
    }
    let lift = plant.wheel_lift();
    sum.wheel_lift_s = lift.lifted_s;
    sum.first_wheel_lift_s = lift.first_lift_s;
    host_us.sort_by(|a, b| a.total_cmp(b));
    sum.plan_host_us_p50 = host_us.get(host_us.len() / 2).copied().unwrap_or(0.0);
    sum.plan_host_us_max = host_us.last().copied().unwrap_or(0.0);
    let wall_s = wall.elapsed().as_secs_f64();
    sum.sim_speed_x_realtime = if wall_s > 0.0 {
        sum.duration_s / wall_s
    } else {
        0.0
    };
    sum
}

/// The driver's measurements: the summary being accumulated and what it needs.
struct Meter<'a> {
    scenario: &'a Scenario,
    vehicle: &'a VehicleParams,
    sum: Summary,
    sum_sq_lat: f64,
    n_lat: u64,
    s_hint: Option<f64>,
    s_prev: f64,
    progress_m: f64,
    projector: crate::world::track::Projector<'a>,
    lap_length: f64,
    target_m: f64,
    cg_offset: f64,
    max_half_width: f64,
    stopped_for_s: f64,
}

impl<'a> Meter<'a> {
    fn new(scenario: &'a Scenario, vehicle: &'a VehicleParams, opts: &SimOptions) -> Self {
        let track = &scenario.track;
        let lap_length = track.length();
        let half_len = 0.5 * vehicle_length_m(vehicle);
        Self {
            scenario,
            vehicle,
            sum: Summary {
                mu: opts.mu_road,
                mu_planner: opts.mu_planner,
                road_mu_min: f64::INFINITY,
                plan_budget_cycles: opts.plan_budget_cycles,
                control_budget_cycles: opts.control_budget_cycles,
                ..Summary::default()
            },
            sum_sq_lat: 0.0,
            n_lat: 0,
            s_hint: None,
            s_prev: 0.0,
            progress_m: 0.0,
            projector: track.projector(),
            lap_length,
            target_m: if track.closed {
                lap_length * opts.laps.max(1) as f64
            } else {
                lap_length
            },
            cg_offset: front_overhang_from_cg_m(vehicle) - half_len,
            max_half_width: track
                .w_left
                .iter()
                .chain(track.w_right.iter())
                .fold(0.0f64, |a, &b| a.max(b)),
            stopped_for_s: 0.0,
        }
    }

    /// Counts one control activation and the plan activations it reports against
    /// their budgets and deadlines.
    fn account<T: Real>(&mut self, opts: &SimOptions, c: &ControlOutput<T>, res: &mut RunResult) {
        let sum = &mut self.sum;
        sum.control_activations += 1;
        if c.actuation.mode == Mode::Safe {
            sum.control_safe_actuations += 1;
        }
        res.control_costs.push(c.cycles);
        res.control_instructions.push(c.instructions);
        if c.completion
            .is_some_and(|d| d.response_us() > CONTROL_PERIOD_US)
        {
            sum.control_deadline_misses += 1;
        }
        sum.control_deadline_misses += u64::from(c.control_skipped_releases);
        sum.control_skipped_releases += u64::from(c.control_skipped_releases);
        sum.plan_skipped_releases += u64::from(c.skipped_releases);
        if let Some(e) = &c.ecu_counts {
            sum.ecu_plan_deadline_misses = Some(e.plan.deadline_misses);
            sum.ecu_skipped_releases = Some(e.plan.skipped_releases);
            sum.ecu_plan_budget_overruns = Some(e.plan.budget_overruns);
            sum.ecu_control_deadline_misses = Some(e.control.deadline_misses);
            sum.ecu_control_skipped_releases = Some(e.control.skipped_releases);
            sum.ecu_control_budget_overruns = Some(e.control.budget_overruns);
            sum.ecu_watchdog_trips = Some(e.watchdog_trips);
            sum.ecu_frames_refused_auth = Some(e.frames_refused.auth.into());
            sum.ecu_frames_refused_replay = Some(e.frames_refused.replay.into());
            sum.ecu_frames_refused_corrupt = Some(e.frames_refused.corrupt.into());
        }
        if c.cycles > opts.control_budget_cycles {
            sum.control_budget_overruns += 1;
        }
        sum.control_max_cost_cycles = sum.control_max_cost_cycles.max(c.cycles);
        sum.control_max_instructions = sum.control_max_instructions.max(c.instructions);
        sum.plan_deadline_misses += u64::from(c.skipped_releases);
        for p in &c.plans {
            res.plan_costs.push(p.cycles);
            sum.plan_max_cost_cycles = sum.plan_max_cost_cycles.max(p.cycles);
            sum.plan_max_instructions = sum.plan_max_instructions.max(p.instructions);
            if p.deadline_miss {
                sum.plan_deadline_misses += 1;
            }
            if p.cycles > opts.plan_budget_cycles {
                sum.plan_budget_overruns += 1;
            }
            sum.plan_qp_refactorizations += u64::from(p.qp_refactorizations);
            if p.published {
                sum.plan_max_qp_iterations = sum.plan_max_qp_iterations.max(p.qp_iterations);
                if let Some(slack) = p.max_validity_slack_rad {
                    sum.max_validity_slack_rad =
                        Some(sum.max_validity_slack_rad.unwrap_or(0.0).max(slack));
                }
            } else if !p.window {
                // An activation that adopted a window planned nothing: no failure.
                sum.plan_failures += 1;
            }
            res.plan_activations.push(p.clone());
        }
    }

    /// The road under the car (grade, friction) and the ECU's estimates (μ̂, the
    /// sideslip lag, the car's) into `row` and the summary; the wheel speeds of
    /// the plant's state `st`.
    fn road_and_estimates<T: Real>(
        &mut self,
        row: &mut LogRow,
        st: &State,
        c: &ControlOutput<T>,
        (road, grade): (&RoadFriction, &RoadGrade),
    ) {
        let vehicle = self.vehicle;
        row.road_grade_pct = 100.0
            * grade
                .under_car_rad(self.s_prev, vehicle.lf_m, vehicle.lr_m)
                .tan();
        row.set_wheel_speeds(st.omega_radps.map(|w| w * vehicle.r_eff_m));
        row.road_mu = road
            .wheels_mu(self.s_prev, vehicle.lf_m, vehicle.lr_m)
            .into_iter()
            .fold(f64::INFINITY, f64::min);
        self.sum.road_mu_min = self.sum.road_mu_min.min(row.road_mu);
        if let Some(mu) = c.friction_mu {
            row.friction_mu = mu;
            if mu.is_finite() {
                let low = self.sum.friction_mu_min.map_or(mu, |m: f64| m.min(mu));
                self.sum.friction_mu_min = Some(low);
            }
        }
        if let Some(lag) = c.sideslip_lag {
            row.sideslip_lag_rad_per_mps2 = lag;
            self.sum.sideslip_lag = Some(lag);
            self.sum.sideslip_lag_max = Some(self.sum.sideslip_lag_max.map_or(lag, |m| m.max(lag)));
        }
        if let Some(e) = c.car_estimate {
            row.set_car_estimate(&e);
            self.sum.set_car_estimate(&e);
        }
    }

    /// The measurements of the instant `t_us`, as a log row.
    fn measure<T: Real>(
        &mut self,
        t_us: u64,
        st: &State,
        out: &crate::model::plant::Outputs,
        act: &Actuation<T>,
        plan: &Plan<T>,
        plan_status: &'static str,
    ) -> LogRow {
        let track = &self.scenario.track;
        let sum = &mut self.sum;
        let (s, lat) = self.projector.project([st.x_m, st.y_m], self.s_hint);
        if self.s_hint.is_some() {
            // Arc length driven since the last sample (across the lap line too).
            let mut ds = s - self.s_prev;
            if track.closed {
                if ds > 0.5 * self.lap_length {
                    ds -= self.lap_length;
                } else if ds < -0.5 * self.lap_length {
                    ds += self.lap_length;
                }
            }
            self.progress_m += ds;
        }
        self.s_prev = s;
        self.s_hint = Some(s);
        self.sum_sq_lat += lat * lat;
        self.n_lat += 1;
        sum.max_abs_lateral_error_m = sum.max_abs_lateral_error_m.max(lat.abs());
        sum.max_abs_ay_mps2 = sum.max_abs_ay_mps2.max(out.ay_mps2.abs());
        sum.max_speed_mps = sum.max_speed_mps.max(st.speed_mps());
        for i in 0..4 {
            sum.max_abs_slip_angle_rad = sum.max_abs_slip_angle_rad.max(out.alpha_rad[i].abs());
            sum.max_abs_slip_ratio = sum.max_abs_slip_ratio.max(out.kappa[i].abs());
        }
        let dev = plan_position_at(plan, t_us)
            .map(|p| (p[0] - st.x_m).hypot(p[1] - st.y_m))
            .unwrap_or(0.0);
        if plan.dt_s > T::ZERO {
            sum.consistency_max_m = sum.consistency_max_m.max(dev);
        }
        self.check_obstacles(st);
        let g = |f: fn(&Actuation<T>) -> T| f(act).to_f64();
        LogRow {
            t_s: t_us as f64 * 1e-6,
            x_m: st.x_m,
            y_m: st.y_m,
            psi_rad: st.psi_rad,
            v_mps: st.speed_mps(),
            v_ref_mps: g(|x| x.v_ref_mps),
            v_heur_mps: plan.v_heur_mps[0].to_f64(),
            delta_rad: g(|x| x.delta_rad),
            delta_applied_rad: out.delta_rad,
            delta_ol_rad: g(|x| x.delta_ol_rad),
            delta_cl_rad: g(|x| x.delta_cl_rad),
            torque_fl_nm: act.wheel_torque_nm[0].to_f64(),
            torque_fr_nm: act.wheel_torque_nm[1].to_f64(),
            torque_rl_nm: act.wheel_torque_nm[2].to_f64(),
            torque_rr_nm: act.wheel_torque_nm[3].to_f64(),
            ay_mps2: out.ay_mps2,
            specific_force_x_mps2: out.specific_force_x_mps2,
            road_grade_pct: 0.0,
            lateral_error_m: lat,
            progress_m: self.progress_m,
            wheel_speed_fl_mps: f64::NAN,
            wheel_speed_fr_mps: f64::NAN,
            wheel_speed_rl_mps: f64::NAN,
            wheel_speed_rr_mps: f64::NAN,
            kappa_fl: out.kappa[0],
            kappa_fr: out.kappa[1],
            kappa_rl: out.kappa[2],
            kappa_rr: out.kappa[3],
            alpha_fl_rad: out.alpha_rad[0],
            alpha_fr_rad: out.alpha_rad[1],
            alpha_rl_rad: out.alpha_rad[2],
            alpha_rr_rad: out.alpha_rad[3],
            plan_deviation_m: dev,
            plan_status,
            control_mode: mode_name(act.mode),
            friction_mu: f64::NAN,
            road_mu: f64::NAN,
            sideslip_lag_rad_per_mps2: f64::NAN,
            est_mass_ratio: f64::NAN,
            est_mass_uncertainty: f64::NAN,
            est_resistance_r0_mps2: f64::NAN,
            est_resistance_r2_mps2: f64::NAN,
            est_brake_gain: f64::NAN,
            est_brake_uncertainty: f64::NAN,
        }
    }

    /// Counts collisions and the smallest clearance to the obstacles.
    fn check_obstacles(&mut self, st: &State) {
        if self.scenario.obstacles.is_empty() {
            return;
        }
        let fp = obstacle_file::vehicle_footprint(
            st.x_m + self.cg_offset * st.psi_rad.cos(),
            st.y_m + self.cg_offset * st.psi_rad.sin(),
            st.psi_rad,
            vehicle_length_m(self.vehicle),
            vehicle_width_m(self.vehicle),
        );
        for o in &self.scenario.obstacles {
            let d = obstacle_file::distance(&fp, &o.vertices);
            if obstacle_file::intersects(&fp, &o.vertices) {
                self.sum.collisions += 1;
            }
            self.sum.min_obstacle_clearance_m = Some(
                self.sum
                    .min_obstacle_clearance_m
                    .map_or(d, |m: f64| m.min(d)),
            );
        }
    }

    /// Why the run stops at `t_us`, if it does.
    fn stop_reason(&mut self, t_us: u64, st: &State, row: &LogRow) -> Option<String> {
        let t_s = t_us as f64 * 1e-6;
        let lat = row.lateral_error_m;
        if self.sum.lap_time_s.is_none() && self.progress_m >= self.lap_length {
            self.sum.lap_time_s = Some(t_s);
        }
        if self.progress_m >= self.target_m {
            self.sum.completed = true;
            return Some("completed".into());
        }
        if lat.abs() > self.max_half_width + 3.0 {
            return Some(format!(
                "left the road at t = {t_s:.2} s ({lat:.2} m off the centre line)"
            ));
        }
        if st.speed_mps() < 0.05 {
            self.stopped_for_s += CONTROL_PERIOD_US as f64 * 1e-6;
            if self.stopped_for_s > 5.0 {
                return Some(format!("stood still for 5 s at t = {t_s:.2} s"));
            }
        } else {
            self.stopped_for_s = 0.0;
        }
        None
    }

    /// The summary at the end of the run at `t_us`.
    fn finish(self, t_us: u64, stop_reason: String, res: &RunResult) -> Summary {
        let mut sum = self.sum;
        sum.stop_reason = stop_reason;
        sum.distance_m = self.progress_m;
        sum.duration_s = t_us as f64 * 1e-6;
        sum.rms_lateral_error_m = if self.n_lat > 0 {
            (self.sum_sq_lat / self.n_lat as f64).sqrt()
        } else {
            0.0
        };
        let mut plan_instr: Vec<f64> = res
            .plan_activations
            .iter()
            .map(|p| p.instructions)
            .collect();
        plan_instr.sort_by(|a, b| a.total_cmp(b));
        sum.plan_p50_instructions = plan_instr.get(plan_instr.len() / 2).copied().unwrap_or(0.0);
        sum
    }
}

/// Largest |a_y| of the kinematic bicycle over a plan's nodes, m/s² (0 for an
/// empty plan).
fn plan_max_kinematic_ay<T: Real>(plan: &Plan<T>, vehicle: &VehicleParams) -> f64 {
    if plan.dt_s <= T::ZERO {
        return 0.0;
    }
    let geometry = firmware::bicycle::BicycleGeometry {
        l_f_m: vehicle.lf_m,
        l_r_m: vehicle.lr_m,
    };
    plan.nodes
        .iter()
        .skip(1)
        .map(|n| {
            firmware::validity::kinematic_lateral_acceleration(
                &geometry,
                n.v_mps.to_f64(),
                n.delta_rad.to_f64(),
            )
            .abs()
        })
        .fold(0.0, f64::max)
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
