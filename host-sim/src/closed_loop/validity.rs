//! The validity experiment of the paper's Figure 3 (what `host-sim validity` runs).
//!
//! For each circle radius `R` and for speeds from walking pace up to the speed at
//! which the car can no longer hold the circle, the 9-DoF plant is driven round a
//! left-hand circle of radius `R` until it is in steady state, and the steering angle
//! it needs, `δ_a`, is compared with the kinematic bicycle's `δ_th` (the paper's
//! Equation 2, constant in speed).
//!
//! # How `δ_a` is found
//!
//! One run per radius, by continuation in speed: the car starts on the circle at the
//! first speed and every next speed starts from the previous steady state.
//!
//! * Steering: `δ = δ_bias + L·(3p·ė_y + 3p²·e_y)/V²`, with `δ_bias` integrating
//!   `L·p³·e_y/V²`. `e_y` is the distance outside the circle and `ė_y = −V·sin e_χ`
//!   with `e_χ` the course (velocity direction) error to the circle's tangent. With the
//!   kinematic relation `ë_y = −V²·(curvature − 1/R)` this places the three poles of
//!   the path error at `−p` (`p` = 1.2 rad/s); the integral removes any steady error,
//!   so at steady state `δ = δ_bias` is the steering the plant needs.
//! * Speed: a PI on the speed error, plus the drag as feed-forward, gives a driving
//!   force shared equally as torque on the two front wheels. The reference ramps to
//!   each new speed at 1 m/s².
//! * Steady state: checked every second (at least 3 s after the ramp): speed within
//!   1 % (+0.02 m/s) of the target, distance to the circle under `0.02 + 0.002·R` m,
//!   and the mean steering of the last second within `1e-4 + 1e-3·|δ|` rad of the
//!   second before. `δ_a`, `a_y` and the speed are the means over that last second.
//! * The car can no longer hold the circle when it slides out of it (more than
//!   `max(1.5 m, 0.1·R)` outside: [`StopCause::Sliding`]), spins (side-slip over
//!   0.35 rad: [`StopCause::Spin`]), lifts a wheel off the road
//!   ([`StopCause::WheelLift`]), needs the steering's mechanical limit
//!   ([`StopCause::SteeringLimit`]), cannot hold the speed ([`StopCause::Speed`]),
//!   needs more than 5× `δ_th` or does not settle within 30 s
//!   ([`StopCause::NotSteady`]); the sweep for that radius stops there, and reports
//!   its highest steady lateral acceleration and why the next speed failed.
//!
//! Radii are run in parallel (rayon); each is independent and deterministic, so the
//! results do not depend on the number of threads.

use firmware::bicycle::BicycleGeometry;
use firmware::validity::kinematic_steering_for_radius;
use indicatif::ProgressBar;
use rayon::prelude::*;

use crate::model::plant::{Inputs, Plant, PlantError, State};
use crate::model::vehicle::{VehicleParams, G};

/// Relative deviations `|δ_a − δ_th|/δ_th` reported by the command.
pub const THRESHOLDS: [f64; 3] = [0.05, 0.10, 0.20];

/// Settings of the experiment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidityConfig {
    /// Road friction coefficient μ.
    pub mu: f64,
    /// Integration step, s.
    pub dt_s: f64,
    /// First speed of every sweep, m/s.
    pub v_start_mps: f64,
    /// Number of speed steps between `v_start_mps` and `sqrt(μ·g·R)`.
    pub steps_to_friction_limit: usize,
}

impl Default for ValidityConfig {
    fn default() -> Self {
        Self {
            mu: 1.0,
            dt_s: crate::model::plant::DEFAULT_DT_S,
            v_start_mps: 2.0,
            steps_to_friction_limit: 30,
        }
    }
}

/// One steady state on a circle.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ValidityPoint {
    /// Circle radius `R`, m.
    pub radius_m: f64,
    /// Steady speed of the centre of gravity, m/s.
    pub speed_mps: f64,
    /// Steady lateral acceleration at the centre of gravity, m/s².
    pub ay_mps2: f64,
    /// Steering angle the 9-DoF plant needs, rad.
    pub delta_a_rad: f64,
    /// Steering angle of the kinematic bicycle (paper's Equation 2), rad.
    pub delta_th_rad: f64,
}

impl ValidityPoint {
    /// `|δ_a − δ_th|/δ_th`, dimensionless.
    pub fn relative_error(&self) -> f64 {
        ((self.delta_a_rad - self.delta_th_rad) / self.delta_th_rad).abs()
    }
}

/// Why a sweep stopped: how the car failed to hold the next speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum StopCause {
    /// The tyres saturated and the car slid out of the circle (understeer).
    Sliding,
    /// The car spun: side-slip over 0.35 rad (oversteer).
    Spin,
    /// A wheel's load reached zero: it lifted off the road.
    WheelLift,
    /// The steering needed its mechanical limit.
    SteeringLimit,
    /// The speed could not be held (the driven wheels spin, or too little grip).
    Speed,
    /// The steering diverged (over 5× `δ_th`) or did not settle within 30 s.
    NotSteady,
    /// The sweep went far above `sqrt(μ·g·R)` without failing.
    AboveLimit,
    /// The plant stopped (a non-finite state).
    Plant,
}

impl StopCause {
    /// A short name for the summary line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sliding => "sliding",
            Self::Spin => "spin",
            Self::WheelLift => "wheel lift",
            Self::SteeringLimit => "steering limit",
            Self::Speed => "speed not held",
            Self::NotSteady => "not steady",
            Self::AboveLimit => "above the friction limit",
            Self::Plant => "plant error",
        }
    }
}

/// The sweep over speeds for one radius.
#[derive(Debug, Clone, PartialEq)]
pub struct RadiusSweep {
    /// Circle radius, m.
    pub radius_m: f64,
    /// Kinematic steering `δ_th`, rad.
    pub delta_th_rad: f64,
    /// Steady states, by increasing speed.
    pub points: Vec<ValidityPoint>,
    /// Why the sweep stopped (the first speed the car could not hold, and how).
    pub stop_reason: String,
    /// The kind of failure that stopped the sweep.
    pub stop_cause: StopCause,
    /// Wheel lifts the plant saw over the sweep (see [`crate::model::plant::WheelLift`]).
    pub wheel_lifts: u64,
}

impl RadiusSweep {
    /// Lateral acceleration (m/s²) at which `|δ_a − δ_th|/δ_th` first exceeds
    /// `fraction`, interpolated linearly between the two points around the crossing;
    /// `None` if it never does before the sweep stopped.
    pub fn ay_at_deviation(&self, fraction: f64) -> Option<f64> {
        let first = self
            .points
            .iter()
            .position(|p| p.relative_error() > fraction)?;
        let b = &self.points[first];
        if first == 0 {
            return Some(b.ay_mps2);
        }
        let a = &self.points[first - 1];
        let (ea, eb) = (a.relative_error(), b.relative_error());
        let w = if eb > ea {
            (fraction - ea) / (eb - ea)
        } else {
            1.0
        };
        Some(a.ay_mps2 + w * (b.ay_mps2 - a.ay_mps2))
    }
}

/// Why the experiment could not run.
#[derive(Debug, thiserror::Error)]
pub enum ValidityError {
    /// A radius the kinematic model cannot drive (smaller than `l_r`) or not finite.
    #[error("radius {radius_m} m: must be a finite number at least l_r = {lr_m} m")]
    Radius {
        /// The radius given, m.
        radius_m: f64,
        /// The vehicle's `l_r`, m.
        lr_m: f64,
    },
    /// Friction not usable.
    #[error("mu = {0}: must be a finite number greater than 0")]
    Mu(f64),
    /// The plant refused the vehicle or the step.
    #[error(transparent)]
    Plant(#[from] PlantError),
}

/// Runs the sweep for every radius (in parallel; results in the order given).
pub fn run_experiment(
    params: &VehicleParams,
    radii_m: &[f64],
    cfg: &ValidityConfig,
    progress: &ProgressBar,
) -> Result<Vec<RadiusSweep>, ValidityError> {
    if !(cfg.mu > 0.0 && cfg.mu.is_finite()) {
        return Err(ValidityError::Mu(cfg.mu));
    }
    radii_m
        .par_iter()
        .map(|&r| sweep_radius(params, r, cfg, progress))
        .collect()
}

/// The sweep over speeds on a circle of radius `radius_m` (m).
pub fn sweep_radius(
    params: &VehicleParams,
    radius_m: f64,
    cfg: &ValidityConfig,
    progress: &ProgressBar,
) -> Result<RadiusSweep, ValidityError> {
    let geometry = BicycleGeometry {
        l_f_m: params.lf_m,
        l_r_m: params.lr_m,
    };
    let delta_th = kinematic_steering_for_radius(&geometry, radius_m)
        .filter(|_| radius_m > 0.0)
        .ok_or(ValidityError::Radius {
            radius_m,
            lr_m: params.lr_m,
        })?;
    let v0 = cfg.v_start_mps;
    let v_limit = (cfg.mu * G * radius_m).sqrt();
    let dv = ((v_limit - v0) / cfg.steps_to_friction_limit.max(1) as f64).max(0.1);
    let mut initial = State::at_speed(v0, params);
    initial.yaw_rate_radps = v0 / radius_m;
    let plant = Plant::with_step(*params, initial, cfg.dt_s)?;
    let mut run = CircleRun {
        plant,
        radius_m,
        mu: cfg.mu,
        wheelbase_m: params.lf_m + params.lr_m,
        delta_bias: delta_th,
        speed_int: 0.0,
        v_ref: v0,
        delta_th,
    };
    let mut points = Vec::new();
    let mut k = 0usize;
    let (stop_cause, stop_reason) = loop {
        let target = v0 + k as f64 * dv;
        if target > 1.5 * v_limit + 2.0 {
            break (
                StopCause::AboveLimit,
                format!("stopped at {target:.2} m/s, far above sqrt(mu*g*R)"),
            );
        }
        match run.settle_at(target) {
            Ok(p) => points.push(p),
            Err((cause, why)) => {
                break (
                    cause,
                    format!("could not hold the circle at {target:.2} m/s: {why}"),
                )
            }
        }
        progress.inc(1);
        k += 1;
    };
    Ok(RadiusSweep {
        radius_m,
        delta_th_rad: delta_th,
        points,
        stop_reason,
        stop_cause,
        wheel_lifts: run.plant.wheel_lift().count,
    })
}

/// The car, its controllers and the circle.
struct CircleRun {
    plant: Plant,
    radius_m: f64,
    mu: f64,
    wheelbase_m: f64,
    delta_bias: f64,
    speed_int: f64,
    v_ref: f64,
    delta_th: f64,
}

/// Pole of the path-error dynamics, rad/s.
const POLE: f64 = 1.2;

/// Per-step errors: distance outside the circle (m) and side-slip (rad).
struct StepInfo {
    e_y: f64,
    beta: f64,
    delta: f64,
    saturated: bool,
}

impl CircleRun {
    fn step(&mut self, target: f64) -> Result<StepInfo, PlantError> {
        let dt = self.plant.dt_s();
        let p = self.plant.params();
        let (m, r_eff, max_steer) = (p.mass_kg, p.r_eff_m, p.max_steer_rad);
        let aero = 0.5 * p.rho_air_kg_per_m3 * p.cx * p.frontal_area_m2;
        let s = *self.plant.state();
        // Circle centred at (0, R), driven counter-clockwise.
        let (px, py) = (s.x_m, s.y_m - self.radius_m);
        let e_y = px.hypot(py) - self.radius_m;
        let tangent = py.atan2(px) + core::f64::consts::FRAC_PI_2;
        let beta = s.vy_mps.atan2(s.vx_mps);
        let e_chi = firmware::low_level::wrap_pi(s.psi_rad + beta - tangent);
        let v = s.speed_mps().max(0.5);
        let ey_dot = -v * e_chi.sin();
        let l = self.wheelbase_m;
        self.delta_bias += l * POLE.powi(3) * e_y / (v * v) * dt;
        let delta_cmd =
            self.delta_bias + l * (3.0 * POLE * ey_dot + 3.0 * POLE * POLE * e_y) / (v * v);
        let delta = delta_cmd.clamp(-max_steer, max_steer);
        // Speed: ramp the reference, PI on the speed error.
        let ramp = 1.0 * dt;
        self.v_ref += (target - self.v_ref).clamp(-ramp, ramp);
        let e_v = self.v_ref - s.speed_mps();
        self.speed_int += e_v * dt;
        let force = m * (1.5 * e_v + 0.5 * self.speed_int) + aero * s.vx_mps * s.vx_mps.abs();
        let t = force * r_eff / 2.0;
        let inputs = Inputs {
            torque_nm: [t, t, 0.0, 0.0],
            delta_rad: delta,
        };
        self.plant.step(&inputs, self.mu)?;
        Ok(StepInfo {
            e_y,
            beta,
            delta,
            saturated: delta_cmd.abs() >= max_steer,
        })
    }

    /// Drives to a steady state at `target` (m/s); the point, or why not.
    fn settle_at(&mut self, target: f64) -> Result<ValidityPoint, (StopCause, String)> {
        let n_win = (1.0 / self.plant.dt_s()).round().max(1.0) as usize;
        let ramp_s = ((target - self.v_ref).abs() / 1.0).ceil() as usize;
        let lost = 1.5_f64.max(0.1 * self.radius_m);
        let ey_tol = 0.02 + 0.002 * self.radius_m;
        let mut prev_delta: Option<f64> = None;
        for second in 0..(ramp_s + 30) {
            let (mut sum_delta, mut sum_ay, mut sum_v, mut n_ay) = (0.0, 0.0, 0.0, 0usize);
            let mut max_ey = 0.0_f64;
            let mut saturated = 0usize;
            for k in 0..n_win {
                let info = self
                    .step(target)
                    .map_err(|e| (StopCause::Plant, e.to_string()))?;
                let lifted = self.plant.wheel_lift().last_step;
                if let Some(w) = lifted.iter().position(|&l| l) {
                    let name = ["front-left", "front-right", "rear-left", "rear-right"][w];
                    return Err((
                        StopCause::WheelLift,
                        format!(
                            "wheel lift (the {name} wheel's load reached zero at t = {:.3} s)",
                            self.plant.time_s()
                        ),
                    ));
                }
                if info.e_y.abs() > lost {
                    return Err((
                        StopCause::Sliding,
                        format!("sliding: left the circle ({:.2} m outside)", info.e_y),
                    ));
                }
                if info.beta.abs() > 0.35 {
                    return Err((
                        StopCause::Spin,
                        format!("spin (side-slip {:.2} rad)", info.beta),
                    ));
                }
                if info.saturated {
                    saturated += 1;
                }
                sum_delta += info.delta;
                max_ey = max_ey.max(info.e_y.abs());
                if k % 10 == 0 {
                    let o = self.plant.outputs();
                    sum_ay += o.ay_mps2;
                    sum_v += o.speed_mps;
                    n_ay += 1;
                }
            }
            if saturated * 2 > n_win {
                return Err((
                    StopCause::SteeringLimit,
                    "the steering is at its mechanical limit".to_string(),
                ));
            }
            let delta = sum_delta / n_win as f64;
            let ay = sum_ay / n_ay.max(1) as f64;
            let v = sum_v / n_ay.max(1) as f64;
            if delta.abs() > 5.0 * self.delta_th {
                return Err((
                    StopCause::NotSteady,
                    format!("delta_a diverging ({delta:.3} rad, over 5x delta_th)"),
                ));
            }
            let after_ramp = second >= ramp_s + 3;
            if after_ramp && (v - target).abs() > 0.5_f64.max(0.1 * target) {
                return Err((StopCause::Speed, format!("speed not held ({v:.2} m/s)")));
            }
            let steady = after_ramp
                && (v - target).abs() < 0.01 * target + 0.02
                && max_ey < ey_tol
                && prev_delta.is_some_and(|d| (d - delta).abs() < 1e-4 + 1e-3 * delta.abs());
            if steady {
                return Ok(ValidityPoint {
                    radius_m: self.radius_m,
                    speed_mps: v,
                    ay_mps2: ay,
                    delta_a_rad: delta,
                    delta_th_rad: self.delta_th,
                });
            }
            prev_delta = Some(delta);
        }
        Err((
            StopCause::NotSteady,
            "did not settle within 30 s".to_string(),
        ))
    }
}

/// One line of the summary per radius: the lateral accelerations at which the
/// deviation first exceeds each of [`THRESHOLDS`].
pub fn summary_line(s: &RadiusSweep, mu: f64) -> String {
    let parts: Vec<String> = THRESHOLDS
        .iter()
        .map(|&f| match s.ay_at_deviation(f) {
            Some(ay) => format!(
                ">{:.0}% at a_y = {:.2} m/s2 ({:.2} mu g)",
                f * 100.0,
                ay,
                ay / (mu * G)
            ),
            None => format!(">{:.0}%: not reached", f * 100.0),
        })
        .collect();
    let top = s
        .points
        .last()
        .map(|p| format!("{:.2} m/s, a_y = {:.2} m/s2", p.speed_mps, p.ay_mps2))
        .unwrap_or_else(|| "none".to_string());
    format!(
        "R = {:>5.1} m  delta_th = {:.4} rad  {}  (highest steady: {}; next speed failed: {}: {}; wheel lifts {})",
        s.radius_m,
        s.delta_th_rad,
        parts.join(", "),
        top,
        s.stop_cause.name(),
        s.stop_reason,
        s.wheel_lifts
    )
}
