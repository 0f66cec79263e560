//! The run's figures of merit, `summary.json`: what the closed-loop driver
//! ([`super::timeline`]) measured over a run, written by `run` and `pil` and read
//! back through this same type.

use serde::{Deserialize, Serialize};

use crate::world::faults::Outcome;

/// The run's figures of merit (`summary.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
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
    /// Largest |a_y| of the car, m/s²: the plant's body lateral acceleration at the
    /// centre of gravity, `ΣF_y/M_T` in the vehicle frame (tyre forces, so it
    /// includes the body's side-slip dynamics), sampled every 10 ms.
    pub max_abs_ay_mps2: f64,
    /// Largest |a_y| the published plans asked for, m/s²: the kinematic bicycle's
    /// `V²·sin β(δ)/l_r` at every node but the first of every published plan (the
    /// quantity the validity limit keeps under `0.5·μ_planner·g`, slack aside; the
    /// first node is the measured state, its steering the low-level controller's
    /// `δ_ol + δ_cl`, which no plan chose). Null when the ECU reports its plans'
    /// positions only (processor in the loop): not measured.
    pub max_abs_plan_ay_mps2: Option<f64>,
    /// Simulated time with at least one wheel lifted off the road (load zero), s.
    pub wheel_lift_s: f64,
    /// Time at which a wheel first lifted off the road, s (null if none did).
    pub first_wheel_lift_s: Option<f64>,
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
    /// Largest estimated cost of a plan activation, instructions.
    pub plan_max_instructions: f64,
    /// Median estimated cost of a plan activation, instructions.
    pub plan_p50_instructions: f64,
    /// Plan releases whose response time exceeded the 100 ms period, skipped
    /// releases included.
    pub plan_deadline_misses: u64,
    /// Plan releases skipped because the task was still running (the activation
    /// before ran, with the route frames it received, past them).
    pub plan_skipped_releases: u64,
    /// Plan activations over their cycle budget (deadline met or not).
    pub plan_budget_overruns: u64,
    /// Largest estimated cost of a control activation, cycles.
    pub control_max_cost_cycles: f64,
    /// Largest estimated cost of a control activation, instructions.
    pub control_max_instructions: f64,
    /// Control activations whose answer was sent more than the 10 ms period after
    /// their release, skipped control releases included.
    pub control_deadline_misses: u64,
    /// Control releases the ECU skipped because the task was still running.
    pub control_skipped_releases: u64,
    /// Control activations over their cycle budget (deadline met or not).
    pub control_budget_overruns: u64,
    /// Control activations.
    pub control_activations: u64,
    /// Control activations that applied the safe actuation.
    pub control_safe_actuations: u64,
    /// Lowest friction estimate `μ̂` of the control task's friction check
    /// (`firmware::friction`: below the planner's `μ` when a slip showed the road
    /// slipperier), null when the ECU does not report it (processor in the loop).
    pub friction_mu_min: Option<f64>,
    /// The plan task's sideslip lag `λ` at the end of the run, rad per m/s²
    /// (`firmware::sideslip`: the plans' course lags the kinematic bicycle's by
    /// `λ·a_y`), null when the ECU does not report it (processor in the loop).
    pub sideslip_lag: Option<f64>,
    /// The largest sideslip lag `λ` over the run, rad per m/s² (its cap is
    /// `firmware::sideslip::SideslipConfig::lag_max`), null as `sideslip_lag`.
    pub sideslip_lag_max: Option<f64>,
    /// The control task's mass ratio `k = m/m₀` at the end of the run
    /// (`firmware::longitudinal_estimator`; this and the five after it null
    /// when the ECU does not report them: processor in the loop).
    pub est_mass_ratio: Option<f64>,
    /// Its uncertainty `u` at the end of the run, dimensionless.
    pub est_mass_uncertainty: Option<f64>,
    /// The estimated resistance at rest per configured mass `r₀`, m/s².
    pub est_resistance_r0_mps2: Option<f64>,
    /// The estimated drag per configured mass at 30 m/s `r₂`, m/s².
    pub est_resistance_r2_mps2: Option<f64>,
    /// The estimated brakes' gain `b` (brake torque given per N·m commanded).
    pub est_brake_gain: Option<f64>,
    /// Its uncertainty `u_b`, dimensionless.
    pub est_brake_uncertainty: Option<f64>,
    /// The patches of road with their own friction, `START:LENGTH:MU` joined by `;`
    /// (empty without any).
    pub mu_patches: String,
    /// The stretches of road with a grade, `START:LENGTH:PERCENT` joined by `;`
    /// (empty on a level road).
    pub grade_patches: String,
    /// The plant's actuators where they are not ideal, `field=value` joined by `;`
    /// as `--actuator` takes them (empty for ideal actuators).
    pub actuators: String,
    /// Lowest road friction under the car over the run ([`LogRow::road_mu`](super::timeline::LogRow::road_mu)).
    pub road_mu_min: f64,
    /// `μ̂` fell below 0.9 × the lowest road μ under the car over the last 10 s at
    /// some sample: a false alarm of the friction check
    /// ([`crate::world::road_friction::judge`]); null when the ECU does not report `μ̂`.
    pub mu_false_drop: Option<bool>,
    /// When `μ̂` first fell that low, s (null if it never did).
    pub mu_false_drop_s: Option<f64>,
    /// The slowest recovery after leaving a patch of lower grip: time from the exit
    /// until `μ̂ ≥ 0.9 × road μ`, s (null without an exit that recovered, or when
    /// the ECU does not report `μ̂`).
    pub mu_recovery_s: Option<f64>,
    /// Exits from a patch of lower grip after which `μ̂` did not reach 0.9 × the
    /// road's μ before the next exit or the end of the run (null when the ECU does
    /// not report `μ̂`).
    pub mu_unrecovered_exits: Option<u32>,
    /// Median host wall time of the ECU's work at a plan release (the plan
    /// activation and the control activation before it), µs (information only).
    pub plan_host_us_p50: f64,
    /// Largest host wall time of the same, µs (information only).
    pub plan_host_us_max: f64,
    /// Largest QP iterations in one plan activation.
    pub plan_max_qp_iterations: u32,
    /// QP refactorizations over the run's plan activations: factors rebuilt from
    /// scratch because rounding had spoiled them (at most
    /// `firmware::mpc::QP_MAX_REFACTORIZATIONS` per activation).
    pub plan_qp_refactorizations: u64,
    /// Simulated seconds per wall-clock second.
    pub sim_speed_x_realtime: f64,
    /// Largest distance between where the active plan put the car and where it was, m.
    pub consistency_max_m: f64,
    /// Largest validity slack in any published plan, rad; `None` where it is not
    /// measured (processor in the loop: the ECU does not send it).
    pub max_validity_slack_rad: Option<f64>,
    /// Budgets used, cycles.
    pub plan_budget_cycles: f64,
    /// Budget of one control activation, cycles.
    pub control_budget_cycles: f64,
    /// The ECU's own count of `plan` deadline misses (late completions and
    /// skipped releases, on its clock: `firmware::deadline`), null without an ECU
    /// that counts (the in-process run).
    pub ecu_plan_deadline_misses: Option<u64>,
    /// The ECU's own count of skipped `plan` releases, null without an ECU.
    pub ecu_skipped_releases: Option<u64>,
    /// The ECU's own count of `plan` budget overruns (its own clock ticks over
    /// the budget in cycles: at `-icount shift=4` a tick is 1/2.69 of an
    /// instruction, so this is at least the host's count), null without an ECU.
    pub ecu_plan_budget_overruns: Option<u64>,
    /// The ECU's own count of `control` deadline misses, null without an ECU.
    pub ecu_control_deadline_misses: Option<u64>,
    /// The ECU's own count of skipped `control` releases, null without an ECU.
    pub ecu_control_skipped_releases: Option<u64>,
    /// The ECU's own count of `control` budget overruns (its clock's ticks), null
    /// without an ECU.
    pub ecu_control_budget_overruns: Option<u64>,
    /// Times the ECU's watchdog saw no new plan for more than
    /// `firmware::deadline::PLAN_WATCHDOG_PERIODS` plan periods, null without an ECU.
    pub ecu_watchdog_trips: Option<u64>,
    /// Frames the ECU refused as forged (their tag did not verify), null without
    /// an ECU.
    pub ecu_frames_refused_auth: Option<u64>,
    /// Frames the ECU refused as replayed (authentic, not newer than the last
    /// accepted), null without an ECU.
    pub ecu_frames_refused_replay: Option<u64>,
    /// Frames the ECU refused as corrupt (not well-formed frames of this
    /// version: CRC, COBS, length, version), null without an ECU.
    pub ecu_frames_refused_corrupt: Option<u64>,
    /// The ECU's frames the host refused as forged, null without an ECU.
    pub host_frames_refused_auth: Option<u64>,
    /// The ECU's frames the host refused as replayed, null without an ECU.
    pub host_frames_refused_replay: Option<u64>,
    /// The ECU's frames the host refused as corrupt, null without an ECU.
    pub host_frames_refused_corrupt: Option<u64>,
    /// How the ECU was linked to the simulator: `semihosting` (the lock-step
    /// PIL), `usart` (the real-time HIL over the emulated USART); null for the
    /// in-process run.
    #[serde(default)]
    pub link: Option<String>,
    /// The real-time HIL's link and timing figures (`--link usart`), null
    /// otherwise.
    #[serde(default)]
    pub hil: Option<HilSummary>,
}

/// The spread of a measured time over a run, µs (all 0 without samples).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    /// Samples.
    pub samples: u64,
    /// Smallest, µs.
    pub min: f64,
    /// Median, µs.
    pub median: f64,
    /// 99th percentile (nearest rank), µs.
    pub p99: f64,
    /// Largest, µs.
    pub max: f64,
}

impl Spread {
    /// The spread of `values`.
    pub fn of(values: &[f64]) -> Self {
        use crate::stats::{median, percentile};
        Self {
            samples: values.len() as u64,
            min: if values.is_empty() {
                0.0
            } else {
                values.iter().copied().fold(f64::INFINITY, f64::min)
            },
            median: median(values).unwrap_or(0.0),
            p99: percentile(values, 0.99),
            max: percentile(values, 1.0),
        }
    }
}

/// What the real-time HIL over the emulated USART adds to the summary
/// (`crate::pil::usart`): its frames and the spread of its timing. The ECU's
/// own deadline counts and refused frames are the summary's `ecu_*` fields.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HilSummary {
    /// QEMU's clock options.
    pub qemu_clock: String,
    /// How far ahead of an ECU release the run's periods were placed to start,
    /// µs (the sensor frames' lead while the two clocks agree).
    pub lead_us: u64,
    /// Periods of dropout answers read before the run to find the ECU's phase.
    pub warmup_periods: u64,
    /// Of those, the answers saying no sensor frame had arrived.
    pub warmup_missing: u64,
    /// Sensor frames sent (one per 10 ms period).
    pub sensor_frames_sent: u64,
    /// Frames of the road sent on the route channel.
    pub route_frames_sent: u64,
    /// Actuation frames received during the run.
    pub actuation_frames_received: u64,
    /// Of those, answers to a sensor frame the ECU accepted.
    pub answers: u64,
    /// Answers saying no whole sensor frame had arrived at the release
    /// (`SENSOR_MISSING`): the ECU ran the period as a dropout.
    pub sensor_missing_at_ecu: u64,
    /// Answers saying the ECU refused the sensor frame (forged, replayed,
    /// corrupt, unexpected).
    pub sensor_refused_at_ecu: u64,
    /// Answers to a sensor frame received after the end of its period (acted
    /// on from the next period).
    pub late_answers: u64,
    /// Periods in which no actuation frame arrived (the last one held).
    pub periods_without_frame: u64,
    /// Periods in which no sensor frame was sent: no ECU release fell in them
    /// (the ECU's clock had fallen a period behind the host's).
    pub periods_not_fed: u64,
    /// Plan events received.
    pub plan_events: u64,
    /// The ECU's control response times (release → its frame written), µs.
    pub control_response_us: Spread,
    /// The ECU's plan response times (release → plan published), µs.
    pub plan_response_us: Spread,
    /// The host's round trip, sensor frame written → its answer read, µs.
    pub round_trip_us: Spread,
    /// The ECU's release less the instant its sensor frame was sent, µs (through
    /// the estimated clock offset).
    pub lead_at_release_us: Spread,
    /// How much the estimated offset between the ECU's clock and the host's
    /// moved over the run, µs (positive: the ECU's clock fell behind).
    pub clock_offset_drift_us: Option<f64>,
    /// Wall time of the run, s.
    pub wall_s: f64,
}

/// The control task's estimate of the car's longitudinal dynamics
/// (`firmware::longitudinal_estimator`), in the units of its docs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CarEstimate {
    /// Mass ratio `k = m/m₀` (effective mass over the configured one).
    pub mass_ratio: f64,
    /// Its uncertainty `u` (the friction check's tolerance on a relative
    /// shortfall when driving), dimensionless.
    pub mass_uncertainty: f64,
    /// Resistance at rest per configured mass `r₀` (rolling resistance, grade),
    /// m/s².
    pub resistance_r0_mps2: f64,
    /// Aerodynamic drag per configured mass at 30 m/s, `r₂`, m/s².
    pub resistance_r2_mps2: f64,
    /// The brakes' gain `b`: brake torque given per N·m commanded.
    pub brake_gain: f64,
    /// Its uncertainty `u_b` (the tolerance when braking), dimensionless.
    pub brake_uncertainty: f64,
}

impl Summary {
    /// The estimate of the car at the end of the run.
    pub fn set_car_estimate(&mut self, e: &CarEstimate) {
        self.est_mass_ratio = Some(e.mass_ratio);
        self.est_mass_uncertainty = Some(e.mass_uncertainty);
        self.est_resistance_r0_mps2 = Some(e.resistance_r0_mps2);
        self.est_resistance_r2_mps2 = Some(e.resistance_r2_mps2);
        self.est_brake_gain = Some(e.brake_gain);
        self.est_brake_uncertainty = Some(e.brake_uncertainty);
    }
}

/// The outcome of a finished run ([`Outcome`]'s docs: worst first).
pub fn classify(s: &Summary, off_road: bool) -> Outcome {
    if s.collisions > 0 {
        Outcome::Collision
    } else if off_road || s.stop_reason.starts_with("left the road") {
        Outcome::OffRoad
    } else if s.plan_deadline_misses + s.control_deadline_misses > 0 {
        Outcome::DeadlineMiss
    } else if s.completed {
        Outcome::Ok
    } else if s.stop_reason.starts_with("stood still") {
        Outcome::StoppedSafely
    } else {
        Outcome::Failed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_json_reads_back_as_written() -> anyhow::Result<()> {
        let summary = Summary {
            completed: true,
            stop_reason: "completed".into(),
            lap_time_s: Some(88.25),
            max_abs_plan_ay_mps2: None,
            mu_patches: "100:50:0.5".into(),
            mu_false_drop: Some(false),
            mu_unrecovered_exits: Some(0),
            ecu_watchdog_trips: Some(3),
            ecu_frames_refused_auth: Some(20),
            host_frames_refused_corrupt: Some(0),
            ..Summary::default()
        };
        let back: Summary = serde_json::from_str(&serde_json::to_string_pretty(&summary)?)?;
        assert_eq!(back, summary);
        Ok(())
    }
}
