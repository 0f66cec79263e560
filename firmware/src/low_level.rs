//! Low-level control (the paper's Section III D): from the current [`Plan`] and
//! [`StateEstimate`] to the four wheel torques and the front steering angle, at
//! 100 Hz.
//!
//! Let `t = now − plan.stamp` (s) be the time into the plan, `Δt_u = plan.dt_s` the
//! MPC step (0.2 s) and `T_H = HORIZON·Δt_u` its horizon.
//!
//! # Longitudinal
//!
//! `V^r(t)` is the plan's node speed linearly interpolated at `t`; `V` the measured
//! speed `±√(v_x² + v_y²)` (sign of `v_x`). With the paper's error `e = V − V^r`,
//! the speed PID ([`crate::pid`], derivative on the measurement) gives
//!
//! ```text
//! T = −K_P·e − K_D·V̇_f − K_I·∫e dτ  (+ T_ff)        total wheel torque, N·m
//! T_ff = (m·a_plan + F₀ + c₂·V²)·r_eff               (our addition, switchable)
//!        (divided by the brakes' gain b when negative: braking is commanded)
//! ```
//!
//! `T_ff` is **not in the paper** (a pure PID there): it feeds the plan's
//! acceleration `u1` of the current interval forward through the vehicle's mass and
//! wheel radius, and the driving resistances `F₀ + c₂·V²` (N), so that the PID only
//! corrects model error. [`control`] uses the configured mass and no resistance
//! (the PID's integral holds drag and grade); [`control_with_model`] the mass and
//! resistances the `control` task estimates ([`crate::longitudinal_estimator`]), and
//! its brakes' gain `b` (the torque a brake gives per N·m commanded: a braking
//! feed-forward and the braking limit are commanded as `1/b` of the torque the
//! car needs, [`CarModel::inverse_brake_gain`]). It is
//! on by default; [`LowLevelConfig::accel_feedforward`] switches it off to get the
//! paper's controller. `T` is limited to
//! `[−max_braking_torque_nm, max_traction_torque_nm]`, the speed PID's anti-windup
//! acting on that total. Dispatch (front-wheel drive): `T > 0` goes half to each
//! front wheel, the rear ones get 0; `T < 0` (braking) goes to the four wheels, a
//! share [`LowLevelConfig::brake_front_share`] to the front axle and the rest to the
//! rear, each axle's split between left and right by [`CarModel::brake_left_share`]
//! (equally for the configured car). The paper dispatches braking equally
//! on the four wheels (share 0.5, [`LowLevelConfig::default`]); a real car's brake
//! balance puts more on the front, which carries more load when braking, so that
//! the rear wheels do not lock first and spin the car (the simulator sets the share
//! from the vehicle's geometry), and its brake force distribution puts more on the
//! outside wheels of a bend, which the lateral load transfer loads, so that the
//! inside ones do not lock first (the `control` task sets the left share from the
//! measured lateral acceleration, [`crate::tasks::ControlTask::car_model`]). The
//! four torques always add up to `T`.
//!
//! # Lateral
//!
//! `δ = δ_ol + δ_cl`, saturated at the mechanical limit (and at the optional
//! steering-rate limit).
//!
//! * `δ_ol(t) = δ_k + u2_k·(t − k·Δt_u)` for `t ∈ [k·Δt_u, (k+1)·Δt_u]`: in the
//!   first interval it is the plan's initial steering plus the integral of its
//!   first steering rate, as in the paper; when no new plan arrives it goes on
//!   integrating the following rates from the plan's own nodes. Since `δ̇ = u2` is
//!   piecewise constant in the kinematic model, this is the plan's `δ` linearly
//!   interpolated. Each new plan (a new [`Plan::stamp_us`]) restarts it from its
//!   node 0.
//! * `δ_cl` is a PID on the yaw error **projected one MPC step ahead**, read here
//!   as: predict the car's yaw `Δt_u` ahead at its present yaw rate and compare it
//!   with the plan's yaw (linearly interpolated) at that same future time,
//!
//!   ```text
//!   e_ψ = wrap((ψ + ψ̇·Δt_u) − ψ^r(t + Δt_u)) ∈ (−π, π]
//!   δ_cl = −K_P·e_ψ − K_D·(d/dt)(ψ + ψ̇·Δt_u)_f − K_I·∫e_ψ dτ
//!   ```
//!
//!   (the PID's measurement is the projected yaw, its setpoint the unwrapped
//!   reference nearest to it, so the derivative is on the measurement). A car
//!   yawed to the right of the plan (`e_ψ < 0`) steers left (`δ_cl > 0`). The
//!   projection makes the proportional term act on `ψ̇` too (a built-in damping of
//!   `K_P·Δt_u`). `δ_cl`'s output window is what the limits leave once `δ_ol` is
//!   applied, so its integrator stops winding up when the total `δ` saturates.
//!   Below [`LowLevelConfig::lateral_min_speed_mps`] the yaw cannot be steered: the
//!   yaw PID is paused, and its `δ_cl` and integrator are released towards 0 with
//!   the time constant [`PAUSED_YAW_RELEASE_S`], so that the steering is the plan's
//!   (held, a `δ_cl` of −0.05 rad cancelled every 100 ms the 0.05 rad the plan
//!   turned the wheels in that time: a car standing at its steering lock never
//!   turned them back, and its plans waited for it, forever).
//!
//! # Past the end of the plan (plans stopped arriving)
//!
//! [`Mode::Following`] while `t + Δt_u ≤ T_H`; [`Mode::Extrapolating`] while
//! `t ≤ T_H` but the projected yaw reference lies past the last node;
//! [`Mode::Stopping`] once `t > T_H`. Past `T_H` the references continue as a
//! controlled stop: `V^r = max(0, V_N − a_stop·(t − T_H))` from the last planned
//! speed at [`LowLevelConfig::stop_decel_mps2`], the planned acceleration (for the
//! feed-forward) is `−a_stop` until `V^r` reaches 0, `δ_ol` holds the last planned
//! `δ_N`, and the yaw reference continues on the last planned arc at the ramped
//! speed (`ψ^r = ψ_N + ψ̇_N·∫V^r/V_N`, `ψ̇_N` the last interval's yaw rate), so the
//! yaw loop keeps the car on that arc while it stops.
//!
//! # Faults
//!
//! A non-finite state estimate, a non-finite value of the plan read in this
//! period (`dt_s`, the nodes and input the references are sampled from), or a
//! plan whose `dt_s` is not positive returns a [`ControlFault`] and leaves the
//! state untouched; the caller then applies
//! [`safe_actuation`] (zero traction, [`LowLevelConfig::safe_brake_torque_nm`] of
//! braking spread on the four wheels, steering held at its last command). The
//! rest of the plan is not read, so not checked here: a plan published by
//! [`crate::tasks::PlanTask`] is finite throughout ([`Plan::is_finite`], checked
//! once where it is computed rather than by every period that reads it). A clock
//! behind the plan's stamp (`now < stamp`) is treated as `t = 0` and shows as a
//! negative [`Actuation::plan_age_s`].
//!
//! # Cost
//!
//! No trigonometric function: one `sqrt` (the speed, `VSQRT` on the M4F), one
//! `floor` (the yaw wrap, [`qp::real::f32_math::floor`]), a few divisions and two
//! calls to [`pid::update_within`]; no loop, no call to `f64` or integer-division
//! routines. Its static bound on the ECU, with the rest of the control task's job,
//! is in `host-sim wcet`'s report (`control_job`).

use crate::pid::{self, PidConfig, PidConfigError, PidState};
use crate::plan::{Plan, HORIZON};
use crate::state_estimate::StateEstimate;
use crate::Real;
use qp::real::{all_finite, at_least, at_most, clamp_within, larger, smaller};

/// Time constant with which a paused yaw loop's output `δ_cl` and its integrator
/// are released towards 0, s (below [`LowLevelConfig::lateral_min_speed_mps`]:
/// module docs, *Lateral*).
pub const PAUSED_YAW_RELEASE_S: f32 = 0.3;

/// Coefficients and limits of the low-level controllers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LowLevelConfig<T> {
    /// Speed loop: input m/s, output **total** wheel torque N·m (sum over the four
    /// wheels, positive driving forward). Its output limits apply on top of
    /// `max_traction_torque_nm` / `max_braking_torque_nm`. Its `sample_time_s` is
    /// not used by [`control`] (see `period_s`).
    pub speed_pid: PidConfig<T>,
    /// Yaw loop: input rad (projected yaw), output `δ_cl` rad (positive left). Its
    /// `sample_time_s` is not used by [`control`] (see `period_s`).
    pub yaw_pid: PidConfig<T>,
    /// Adds the feed-forward torque `m·a_plan·r_eff` (not in the paper).
    pub accel_feedforward: bool,
    /// Vehicle mass `m` for the feed-forward, kg, > 0.
    pub mass_kg: T,
    /// Effective wheel radius `r_eff` for the feed-forward, m, > 0.
    pub wheel_radius_m: T,
    /// Largest total traction torque (sum of the two front wheels), N·m, > 0.
    pub max_traction_torque_nm: T,
    /// Largest total braking torque (magnitude, sum of the four wheels), N·m, > 0.
    pub max_braking_torque_nm: T,
    /// Mechanical limit of the front steering angle `|δ|`, rad, > 0.
    pub steer_limit_rad: T,
    /// Largest steering rate of the command `|δ̇|`, rad/s, > 0 (+∞: none).
    pub steer_rate_limit_radps: T,
    /// Deceleration of the controlled stop past the end of a plan, m/s², > 0.
    pub stop_decel_mps2: T,
    /// Total braking torque of [`safe_actuation`] (magnitude), N·m, ≥ 0.
    pub safe_brake_torque_nm: T,
    /// Fraction of a braking torque applied to the front axle, in `[0, 1]` (0.5:
    /// equal on the four wheels, as the paper).
    pub brake_front_share: T,
    /// Below this speed the yaw loop is paused, m/s, ≥ 0.
    pub lateral_min_speed_mps: T,
    /// Nominal period of [`control`], s, > 0. Used as the PIDs' time step when the
    /// measured time since the last call is not in `(0, 10·period_s]`.
    pub period_s: T,
}

/// Why a [`LowLevelConfig`] was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LowLevelConfigError {
    /// The speed PID's configuration is invalid.
    SpeedPid(PidConfigError),
    /// The yaw PID's configuration is invalid.
    YawPid(PidConfigError),
    /// Mass or wheel radius not finite and positive.
    InvalidVehicle,
    /// A torque limit is not finite and positive (safe braking: not ≥ 0).
    InvalidTorqueLimit,
    /// Steering limit not finite and positive, or rate limit not positive.
    InvalidSteeringLimit,
    /// Stop deceleration not finite and positive.
    InvalidStopDecel,
    /// Minimum lateral speed or period invalid.
    InvalidTiming,
}

impl<T: Real> Default for LowLevelConfig<T> {
    /// Defaults for the host simulator's car (1500 kg, `r_eff` 0.3 m, wheelbase
    /// 2.65 m, mechanical steering limit 0.6 rad); the gains are justified in the
    /// doc of [`LowLevelConfig::default_speed_pid`] and
    /// [`LowLevelConfig::default_yaw_pid`].
    fn default() -> Self {
        let mass_kg = T::from_f64(1500.0);
        let wheel_radius_m = T::from_f64(0.3);
        let max_traction_torque_nm = T::from_f64(3000.0);
        let max_braking_torque_nm = T::from_f64(4500.0);
        Self {
            speed_pid: Self::default_speed_pid(),
            yaw_pid: Self::default_yaw_pid(),
            accel_feedforward: true,
            mass_kg,
            wheel_radius_m,
            max_traction_torque_nm,
            max_braking_torque_nm,
            steer_limit_rad: T::from_f64(0.6),
            steer_rate_limit_radps: T::INFINITY,
            stop_decel_mps2: T::from_f64(3.0),
            // 3 m/s² on 1500 kg through 0.3 m.
            safe_brake_torque_nm: T::from_f64(1350.0),
            brake_front_share: T::HALF,
            lateral_min_speed_mps: T::from_f64(0.5),
            period_s: T::from_f64(0.01),
        }
    }
}

impl<T: Real> LowLevelConfig<T> {
    /// Default speed loop for a 1500 kg car on 0.3 m wheels (`m·r_eff = 450 kg·m`):
    ///
    /// * `K_P = 900 N·m/(m/s)`: with `m·r_eff·V̇ = T` the proportional loop has a time
    ///   constant `m·r_eff/K_P = 0.5 s`, fast against the 0.2 s-step plan's speed
    ///   changes yet smooth for the tyres;
    /// * `K_I = 450 N·m/m` (integral time 2 s, zero at 0.5 rad/s, under the loop's
    ///   2 rad/s bandwidth): removes the offset from drag and rolling resistance;
    /// * `K_D = 45 N·m·s/m` on the speed, filtered at 0.05 s: a 10 % virtual inertia,
    ///   a light damping that does not amplify the speed estimate's noise;
    /// * integrator within ±3000 N·m, conditional anti-windup; output limited by the
    ///   torque limits of [`LowLevelConfig`].
    pub fn default_speed_pid() -> PidConfig<T> {
        let mut c = PidConfig::new(
            T::from_f64(900.0),
            T::from_f64(450.0),
            T::from_f64(45.0),
            T::from_f64(0.01),
        );
        c.derivative_filter_s = T::from_f64(0.05);
        c.integral_min = T::from_f64(-3000.0);
        c.integral_max = T::from_f64(3000.0);
        c
    }

    /// Default yaw loop:
    ///
    /// * `K_P = 1 rad/rad`: with the kinematic yaw rate `ψ̇ ≈ V·δ/L` and the
    ///   one-step projection, the closed loop's time constant is
    ///   `L/(V·K_P) + Δt_u` ≈ 0.38 s at 15 m/s and 0.73 s at 5 m/s (`L` = 2.65 m);
    /// * `K_I = 0.5 rad/(rad·s)`: removes the steady yaw error in curves where the
    ///   real car understeers against the kinematic plan;
    /// * `K_D = 0.02 rad·s/rad`, filtered at 0.05 s: the projection already adds
    ///   `K_P·Δt_u = 0.2 s` of rate feedback, so little more is needed;
    /// * `δ_cl` within ±0.3 rad, its integrator within ±0.15 rad.
    pub fn default_yaw_pid() -> PidConfig<T> {
        let mut c = PidConfig::new(
            T::from_f64(1.0),
            T::from_f64(0.5),
            T::from_f64(0.02),
            T::from_f64(0.01),
        );
        c.derivative_filter_s = T::from_f64(0.05);
        c.output_min = T::from_f64(-0.3);
        c.output_max = T::from_f64(0.3);
        c.integral_min = T::from_f64(-0.15);
        c.integral_max = T::from_f64(0.15);
        c
    }

    /// Checks every field; call once when the configuration is made.
    pub fn validate(&self) -> Result<(), LowLevelConfigError> {
        self.speed_pid
            .validate()
            .map_err(LowLevelConfigError::SpeedPid)?;
        self.yaw_pid
            .validate()
            .map_err(LowLevelConfigError::YawPid)?;
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        if !(pos(self.mass_kg) && pos(self.wheel_radius_m)) {
            return Err(LowLevelConfigError::InvalidVehicle);
        }
        if !(pos(self.max_traction_torque_nm)
            && pos(self.max_braking_torque_nm)
            && self.safe_brake_torque_nm.is_finite()
            && self.safe_brake_torque_nm >= T::ZERO
            && self.brake_front_share >= T::ZERO
            && self.brake_front_share <= T::ONE)
        {
            return Err(LowLevelConfigError::InvalidTorqueLimit);
        }
        // The rate limit may be +∞ (no limit); `> 0` is false for NaN.
        if !(pos(self.steer_limit_rad) && self.steer_rate_limit_radps > T::ZERO) {
            return Err(LowLevelConfigError::InvalidSteeringLimit);
        }
        if !pos(self.stop_decel_mps2) {
            return Err(LowLevelConfigError::InvalidStopDecel);
        }
        if !(pos(self.period_s)
            && self.lateral_min_speed_mps.is_finite()
            && self.lateral_min_speed_mps >= T::ZERO)
        {
            return Err(LowLevelConfigError::InvalidTiming);
        }
        Ok(())
    }
}

/// Which part of the plan the controller is following.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Inside the plan: `t + Δt_u ≤ T_H`.
    Following,
    /// `t ≤ T_H` but the projected yaw reference `t + Δt_u` is past the last node:
    /// the plan is about to run out (no new plan for `T_H − Δt_u`).
    Extrapolating,
    /// Past the last node: controlled stop (see the module doc).
    Stopping,
    /// Not computed by [`control`]: the safe actuation after a fault.
    Safe,
}

/// Why [`control`] refused to compute (the caller applies [`safe_actuation`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlFault {
    /// The state estimate contains NaN or ±∞.
    NonFiniteEstimate,
    /// A value of the plan read this period is NaN or ±∞: `dt_s`, or the nodes
    /// and input the references are sampled from. (A plan published by
    /// [`crate::tasks::PlanTask`] is finite throughout, [`Plan::is_finite`]: it is
    /// checked once, where it is computed, not by every period that reads it.)
    NonFinitePlan,
    /// The plan's `dt_s` is not positive (e.g. [`Plan::zeroed`] before the first plan).
    InvalidPlan,
    /// A PID refused its inputs or overflowed (not expected after the checks above).
    Numerical,
}

/// The actuator commands and what they were computed from (for logs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Actuation<T> {
    /// Wheel torques `[fl, fr, rl, rr]`, N·m, positive driving forward.
    pub wheel_torque_nm: [T; 4],
    /// Front steering angle command `δ = δ_ol + δ_cl` after saturation, rad.
    pub delta_rad: T,
    /// Open-loop part `δ_ol` (the plan's steering at `t`), rad.
    pub delta_ol_rad: T,
    /// Closed-loop part as applied, `δ − δ_ol`, rad.
    pub delta_cl_rad: T,
    /// Reference speed `V^r(t)`, m/s.
    pub v_ref_mps: T,
    /// Measured speed `V`, m/s.
    pub v_mps: T,
    /// Yaw reference one MPC step ahead, `ψ^r(t + Δt_u)`, rad (unwrapped as in the plan).
    pub psi_ref_rad: T,
    /// Projected yaw error `e_ψ` in `(−π, π]`, rad.
    pub yaw_error_rad: T,
    /// Total wheel torque `T` (sum of the four), N·m.
    pub torque_total_nm: T,
    /// Feed-forward part of `T`, N·m (0 when switched off).
    pub torque_ff_nm: T,
    /// Time into the plan `now − stamp`, s (negative if the clock is behind the stamp).
    pub plan_age_s: T,
    /// Which part of the plan was followed.
    pub mode: Mode,
    /// True on the first call with this plan (a new stamp).
    pub new_plan: bool,
}

impl<T: Real> Actuation<T> {
    /// The safe actuation: no traction, `brake_torque_nm` (total magnitude, N·m) of
    /// braking spread equally on the four wheels, steering held at
    /// `delta_hold_rad` (rad). Other fields are 0, the mode [`Mode::Safe`].
    pub fn safe(delta_hold_rad: T, brake_torque_nm: T) -> Self {
        let b = -brake_torque_nm.abs() * T::lit(0.25);
        Self {
            wheel_torque_nm: [b; 4],
            delta_rad: delta_hold_rad,
            delta_ol_rad: delta_hold_rad,
            delta_cl_rad: T::ZERO,
            v_ref_mps: T::ZERO,
            v_mps: T::ZERO,
            psi_ref_rad: T::ZERO,
            yaw_error_rad: T::ZERO,
            torque_total_nm: b * T::lit(4.0),
            torque_ff_nm: T::ZERO,
            plan_age_s: T::ZERO,
            mode: Mode::Safe,
            new_plan: false,
        }
    }
}

/// The memory of the low-level controllers (changed only by a successful [`control`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LowLevelState<T> {
    /// Speed PID state (output: total torque, N·m).
    pub speed_pid: PidState<T>,
    /// Yaw PID state (output: `δ_cl`, rad).
    pub yaw_pid: PidState<T>,
    /// Stamp of the plan followed at the last call, µs (`None` before the first).
    pub plan_stamp_us: Option<u64>,
    /// Number of distinct plans followed so far (wrapping).
    pub plans_seen: u32,
    /// Time of the last call, µs (`None` before the first).
    pub last_now_us: Option<u64>,
    /// Steering angle commanded at the last call, rad (`None` before the first).
    pub last_delta_rad: Option<T>,
}

impl<T: Real> Default for LowLevelState<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> LowLevelState<T> {
    /// A fresh state (a valid `const` initialiser).
    pub const fn new() -> Self {
        Self {
            speed_pid: PidState::new(),
            yaw_pid: PidState::new(),
            plan_stamp_us: None,
            plans_seen: 0,
            last_now_us: None,
            last_delta_rad: None,
        }
    }

    /// Back to [`LowLevelState::new`].
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}

/// The safe actuation for this configuration and state: [`Actuation::safe`] with
/// [`LowLevelConfig::safe_brake_torque_nm`] and the last commanded steering angle
/// (0 before the first command), limited to the mechanical limit.
pub fn safe_actuation<T: Real>(cfg: &LowLevelConfig<T>, state: &LowLevelState<T>) -> Actuation<T> {
    let hold = state
        .last_delta_rad
        .unwrap_or(T::ZERO)
        .clamp(-cfg.steer_limit_rad, cfg.steer_limit_rad);
    Actuation::safe(hold, cfg.safe_brake_torque_nm)
}

/// The references read from a plan at one time.
#[derive(Clone, Copy, Debug)]
struct Sample<T> {
    v_mps: T,
    psi_rad: T,
    delta_rad: T,
    accel_mps2: T,
}

/// The plan's references at `tau_s` ≥ 0 s after its stamp (module doc: linear
/// interpolation inside the plan, controlled stop past it); `None` when a value
/// it reads is NaN or ±∞. Requires a finite `dt_s > 0`; `inv_dt` is
/// `1/plan.dt_s` (one division for the period's two samples).
// Two calls per period, inlined: each is a few interpolations.
#[inline(always)]
fn sample<T: Real>(plan: &Plan<T>, inv_dt: T, tau_s: T, stop_decel_mps2: T) -> Option<Sample<T>> {
    let n = T::from_usize(HORIZON);
    let x = tau_s * inv_dt;
    let last = &plan.nodes[HORIZON];
    if x <= n {
        // `as usize` saturates (NaN → 0); `k ≤ HORIZON − 1` keeps `k + 1` in range.
        let k = (x.to_f32() as usize).min(HORIZON - 1);
        let f = x - T::from_usize(k);
        let a = &plan.nodes[k];
        let b = &plan.nodes[k + 1];
        let [u1, u2] = plan.inputs[k];
        // The values read, at once.
        let read = [a.v_mps, b.v_mps, a.psi_rad, b.psi_rad, a.delta_rad, u1, u2];
        all_finite(read).then(|| Sample {
            v_mps: a.v_mps + (b.v_mps - a.v_mps) * f,
            psi_rad: a.psi_rad + (b.psi_rad - a.psi_rad) * f,
            delta_rad: a.delta_rad + u2 * f * plan.dt_s,
            accel_mps2: u1,
        })
    } else {
        let s = tau_s - n * plan.dt_s;
        let v_n = at_least(last.v_mps, T::ZERO);
        let a = stop_decel_mps2;
        let v = v_n - a * s;
        let prev = &plan.nodes[HORIZON - 1];
        if !all_finite([last.v_mps, last.psi_rad, prev.psi_rad, last.delta_rad]) {
            return None;
        }
        let yaw_rate = (last.psi_rad - prev.psi_rad) * inv_dt;
        // ∫V^r/V_N over the stop: the time the last yaw rate acts for.
        let t_eff = if v > T::ZERO {
            s - a * s * s / (T::TWO * v_n)
        } else {
            v_n / (T::TWO * a)
        };
        Some(Sample {
            v_mps: at_least(v, T::ZERO),
            psi_rad: last.psi_rad + yaw_rate * t_eff,
            delta_rad: last.delta_rad,
            accel_mps2: if v > T::ZERO { -a } else { T::ZERO },
        })
    }
}

/// Angle wrapped to `(−π, π]`, rad.
pub fn wrap_pi<T: Real>(x: T) -> T {
    let two_pi = T::TWO * T::PI;
    // `1/2π` folded by the compiler: a product, not a division.
    let r = x - two_pi * ((x + T::PI) * (T::ONE / two_pi)).floor();
    if r <= -T::PI {
        r + two_pi
    } else if r > T::PI {
        r - two_pi
    } else {
        r
    }
}

/// A duration of `d_us` µs in seconds (saturates beyond 71 min).
fn seconds<T: Real>(d_us: u64) -> T {
    T::from_usize(d_us.min(u64::from(u32::MAX)) as usize) * (T::ONE / T::lit(1.0e6))
}

/// Signed time `a − b` in seconds from two µs stamps (saturates beyond ±71 min).
fn signed_seconds<T: Real>(a_us: u64, b_us: u64) -> T {
    // The sign given to the count of µs before the one product by a positive
    // constant, 1e-6 as the compiler folds `1/1e6` in `T` (a sign chosen after
    // it, the compiler takes ±1e6 from a constant island in flash, which the
    // timing analysis must then charge as flash reads for every load of the
    // control job).
    let magnitude = T::from_usize(a_us.abs_diff(b_us).min(u64::from(u32::MAX)) as usize);
    let us = if a_us < b_us { -magnitude } else { magnitude };
    us * (T::ONE / T::lit(1.0e6))
}

/// The car the feed-forward torque is computed for:
/// `T_ff = (m·a_plan + F₀ + c₂·V²)·r_eff` (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarModel<T> {
    /// Effective mass `m`, kg, > 0.
    pub mass_kg: T,
    /// Resistance at rest `F₀` (rolling resistance, grade), N.
    pub resistance_n: T,
    /// Drag coefficient `c₂`, N/(m/s)², ≥ 0.
    pub drag_n_per_mps2: T,
    /// Acceleration the driven wheels may be asked for at most (the grip they
    /// have), m/s², > 0 (+∞: none): the traction torque is limited to
    /// `(m·a + F₀ + c₂·V²)·r_eff` (a traction control).
    pub traction_grip_mps2: T,
    /// Deceleration the brakes may be asked for at most, m/s², > 0 (+∞: none):
    /// the braking torque is limited to `m·a·r_eff/b` (an anti-lock limit).
    pub braking_grip_mps2: T,
    /// `1/b`, the inverse of the brakes' gain `b` (brake torque given per N·m
    /// commanded; [`crate::longitudinal_estimator`]), dimensionless, > 0: a
    /// braking feed-forward and the anti-lock limit are commanded as `1/b` of
    /// the torque the car needs (1: the brakes give what is asked).
    pub inverse_brake_gain: T,
    /// Share of each axle's braking torque given to its left wheel,
    /// dimensionless, in `[0.1, 0.9]` (0.5: left and right alike): the wheels'
    /// loads under the lateral load transfer, so that the inside wheel of a
    /// braked bend, unloaded, is not the first to lock (a brake force
    /// distribution). The driving torque is always split equally (an open
    /// differential).
    pub brake_left_share: T,
    /// True when the steering may turn no further from straight ahead than the
    /// last command (it may turn back): the front tyres slide at a large angle
    /// ([`crate::tasks::ControlTask::steering_held`]).
    pub hold_steering: bool,
}

impl<T: Real> CarModel<T> {
    /// The configured car: [`LowLevelConfig::mass_kg`], no resistance (the speed
    /// PID's integral holds it).
    pub fn configured(cfg: &LowLevelConfig<T>) -> Self {
        Self {
            mass_kg: cfg.mass_kg,
            resistance_n: T::ZERO,
            drag_n_per_mps2: T::ZERO,
            traction_grip_mps2: T::INFINITY,
            braking_grip_mps2: T::INFINITY,
            inverse_brake_gain: T::ONE,
            brake_left_share: T::HALF,
            hold_steering: false,
        }
    }
}

/// One 100 Hz step of the low-level controllers (module doc): the plan `plan`
/// followed at time `now_us` (µs, the clock of [`Plan::stamp_us`]) from the state
/// estimate `est`, the feed-forward for the configured car
/// ([`control_with_model`] for an estimated one).
///
/// On `Err` the state is left untouched and the caller applies
/// [`safe_actuation`]. The configuration must have passed
/// [`LowLevelConfig::validate`].
pub fn control<T: Real>(
    cfg: &LowLevelConfig<T>,
    state: &mut LowLevelState<T>,
    plan: &Plan<T>,
    est: &StateEstimate<T>,
    now_us: u64,
) -> Result<Actuation<T>, ControlFault> {
    control_with_model(cfg, state, plan, est, now_us, &CarModel::configured(cfg))
}

/// Longest age of a state estimate its heading is projected over, s (an older one
/// is projected over this much).
pub const MAX_PROJECTED_AGE_S: f32 = 0.3;

/// Speed under which the car stands, m/s: the brake hold's
/// ([`control_with_model`]) and [`crate::tasks::ControlTask::stop_reason`]'s.
pub const STANDSTILL_MPS: f32 = 0.5;

/// True when the plan's speed now and one plan step ahead (m/s) and the
/// measured speed `v_mps` (m/s, signed) are all under [`STANDSTILL_MPS`]: the car
/// stands and is to stand, and its brakes hold it with
/// [`LowLevelConfig::safe_brake_torque_nm`].
fn standing<T: Real>(v_ref_now_mps: T, v_ref_ahead_mps: T, v_mps: T) -> bool {
    let still = T::lit(STANDSTILL_MPS);
    v_ref_now_mps < still && v_ref_ahead_mps < still && v_mps.abs() < still
}

/// [`control`] with the feed-forward computed for `car` (e.g. the mass and
/// resistances estimated by [`crate::longitudinal_estimator`]; a non-finite or
/// non-positive mass falls back to the configured car's).
pub fn control_with_model<T: Real>(
    cfg: &LowLevelConfig<T>,
    state: &mut LowLevelState<T>,
    plan: &Plan<T>,
    est: &StateEstimate<T>,
    now_us: u64,
    car: &CarModel<T>,
) -> Result<Actuation<T>, ControlFault> {
    if !est.is_finite() {
        return Err(ControlFault::NonFiniteEstimate);
    }
    if !plan.dt_s.is_finite() {
        return Err(ControlFault::NonFinitePlan);
    }
    if plan.dt_s <= T::ZERO {
        return Err(ControlFault::InvalidPlan);
    }

    // Time step of the PIDs.
    let dt = match state.last_now_us {
        Some(prev) if now_us > prev => {
            let d = seconds::<T>(now_us - prev);
            if d <= T::lit(10.0) * cfg.period_s {
                d
            } else {
                cfg.period_s
            }
        }
        _ => cfg.period_s,
    };

    let plan_age_s = signed_seconds::<T>(now_us, plan.stamp_us);
    let t = at_least(plan_age_s, T::ZERO);
    let horizon_s = plan.dt_s * T::from_usize(HORIZON);
    let mode = if t > horizon_s {
        Mode::Stopping
    } else if t + plan.dt_s > horizon_s {
        Mode::Extrapolating
    } else {
        Mode::Following
    };
    let new_plan = state.plan_stamp_us != Some(plan.stamp_us);

    let inv_dt = T::ONE / plan.dt_s;
    let (Some(now_ref), Some(ahead_ref)) = (
        sample(plan, inv_dt, t, cfg.stop_decel_mps2),
        sample(plan, inv_dt, t + plan.dt_s, cfg.stop_decel_mps2),
    ) else {
        return Err(ControlFault::NonFinitePlan);
    };

    // Longitudinal.
    let v = {
        let s = (est.vx_mps * est.vx_mps + est.vy_mps * est.vy_mps).sqrt();
        if est.vx_mps < T::ZERO {
            -s
        } else {
            s
        }
    };
    let mut speed_pid = state.speed_pid;
    let (torque, torque_ff, wheel_torque_nm) =
        longitudinal(cfg, car, &mut speed_pid, &now_ref, &ahead_ref, v, dt)?;
    let mut yaw_pid = state.yaw_pid;
    // The estimate's age at `now_us` (its stamp is when it was measured): the
    // heading is projected over it too.
    let est_age_s = smaller(
        at_least(signed_seconds::<T>(now_us, est.stamp_us), T::ZERO),
        T::lit(MAX_PROJECTED_AGE_S),
    );
    let (delta_ol, delta, yaw_error) = lateral(
        cfg,
        car,
        state.last_delta_rad,
        &mut yaw_pid,
        plan.dt_s + est_age_s,
        est,
        &now_ref,
        &ahead_ref,
        v,
        dt,
    )?;

    state.speed_pid = speed_pid;
    state.yaw_pid = yaw_pid;
    if new_plan {
        state.plan_stamp_us = Some(plan.stamp_us);
        state.plans_seen = state.plans_seen.wrapping_add(1);
    }
    state.last_now_us = Some(now_us);
    state.last_delta_rad = Some(delta);

    Ok(Actuation {
        wheel_torque_nm,
        delta_rad: delta,
        delta_ol_rad: delta_ol,
        delta_cl_rad: delta - delta_ol,
        v_ref_mps: now_ref.v_mps,
        v_mps: v,
        psi_ref_rad: ahead_ref.psi_rad,
        yaw_error_rad: yaw_error,
        torque_total_nm: torque,
        torque_ff_nm: torque_ff,
        plan_age_s,
        mode,
        new_plan,
    })
}

/// The speed loop of [`control_with_model`] at the measured speed `v` (m/s,
/// signed) over `dt` (s): the total torque (N·m, positive driving), its
/// feed-forward (N·m) and the four wheels' torques (N·m, FL FR RL RR), the
/// speed PID's state updated in `speed_pid`.
fn longitudinal<T: Real>(
    cfg: &LowLevelConfig<T>,
    car: &CarModel<T>,
    speed_pid: &mut PidState<T>,
    now_ref: &Sample<T>,
    ahead_ref: &Sample<T>,
    v: T,
    dt: T,
) -> Result<(T, T, [T; 4]), ControlFault> {
    // The car's model, or the configured car where it is not usable.
    let resistance = car.resistance_n + car.drag_n_per_mps2 * v * v;
    // The brakes give `b` of the torque commanded: a braking torque is
    // commanded as `1/b` of the one the car needs (one finiteness test for the
    // three; a gain not in (0, ∞) with the rest: the configured car, 1).
    let (mass, resistance, inv_b) = if (car.mass_kg + resistance + car.inverse_brake_gain)
        .is_finite()
        && car.mass_kg > T::ZERO
        && car.inverse_brake_gain > T::ZERO
    {
        (car.mass_kg, resistance, car.inverse_brake_gain)
    } else {
        (cfg.mass_kg, T::ZERO, T::ONE)
    };
    let r = cfg.wheel_radius_m;
    // Within the grip (`min` keeps the configured limit for +∞ or NaN grip).
    // (`at_least(x, 0)` is 0 for a NaN `x`, as `Real::max`; the limits below are
    // not NaN, so one comparison per bound.)
    let t_grip = at_least(
        (mass * car.traction_grip_mps2 + at_least(resistance, T::ZERO)) * r,
        T::ZERO,
    );
    let t_max = at_most(cfg.max_traction_torque_nm, t_grip);
    let b_max = at_most(
        cfg.max_braking_torque_nm,
        at_least(mass * car.braking_grip_mps2 * r * inv_b, T::ZERO),
    );
    let torque_ff = if cfg.accel_feedforward {
        let needed = (mass * now_ref.accel_mps2 + resistance) * r;
        let commanded = if needed < T::ZERO {
            needed * inv_b
        } else {
            needed
        };
        clamp_within(commanded, -b_max, t_max)
    } else {
        T::ZERO
    };
    let torque_fb = pid::update_within(
        &cfg.speed_pid,
        speed_pid,
        now_ref.v_mps,
        v,
        dt,
        -b_max - torque_ff,
        t_max - torque_ff,
    )
    .map_err(|_| ControlFault::Numerical)?;
    let torque = if standing(now_ref.v_mps, ahead_ref.v_mps, v) {
        // The plan stands and so does the car: the brakes hold it, as a driver's
        // foot does (the speed loop would chase the estimate's noise round 0 with
        // torques of either sign, and creep), and the speed loop starts afresh
        // when the plan moves off.
        speed_pid.reset();
        -cfg.safe_brake_torque_nm
    } else {
        clamp_within(torque_fb + torque_ff, -b_max, t_max)
    };
    let wheel_torque_nm = if torque > T::ZERO {
        let h = torque * T::HALF;
        [h, h, T::ZERO, T::ZERO]
    } else {
        // Each axle's share by the brake balance, then left and right by their
        // loads (`car.brake_left_share`).
        let front = torque * cfg.brake_front_share;
        let rear = torque - front;
        let l = car.brake_left_share;
        let (fl, rl) = (front * l, rear * l);
        [fl, front - fl, rl, rear - rl]
    };
    Ok((torque, torque_ff, wheel_torque_nm))
}

/// The steering of [`control_with_model`]: the plan's open-loop steering `δ_ol`
/// plus the yaw loop's `δ_cl` within the mechanical limit, the rate limit from
/// `last_delta_rad` (the last command, rad) and the steering hold; returns
/// `(δ_ol, δ, yaw error)` (rad), the yaw PID's state updated in `yaw_pid`.
/// `plan_dt_s` (s) is the plan's node spacing, `v` (m/s) the measured speed,
/// `dt` (s) the PIDs' step.
#[allow(clippy::too_many_arguments)]
fn lateral<T: Real>(
    cfg: &LowLevelConfig<T>,
    car: &CarModel<T>,
    last_delta_rad: Option<T>,
    yaw_pid: &mut PidState<T>,
    plan_dt_s: T,
    est: &StateEstimate<T>,
    now_ref: &Sample<T>,
    ahead_ref: &Sample<T>,
    v: T,
    dt: T,
) -> Result<(T, T, T), ControlFault> {
    let lim = cfg.steer_limit_rad;
    let (mut lo, mut hi) = (-lim, lim);
    if let Some(prev) = last_delta_rad {
        let step = cfg.steer_rate_limit_radps * dt;
        let prev = clamp_within(prev, -lim, lim);
        // All finite (a validated configuration, a clamped command): plain
        // comparisons.
        lo = larger(lo, prev - step);
        hi = smaller(hi, prev + step);
        if car.hold_steering {
            // No further from straight ahead than the last command.
            let m = prev.abs();
            lo = larger(lo, -m);
            hi = smaller(hi, m);
        }
    }
    let delta_ol = now_ref.delta_rad;
    let psi_proj = est.psi_rad + est.yaw_rate_radps * plan_dt_s;
    let yaw_error = wrap_pi(psi_proj - ahead_ref.psi_rad);
    let delta_cl = if v.abs() >= cfg.lateral_min_speed_mps {
        // A jump of the yaw by more than π (an estimator that wrapped) would be a
        // derivative spike: restart the derivative instead.
        if yaw_pid.initialised && (psi_proj - yaw_pid.prev_measurement).abs() > T::PI {
            yaw_pid.forget_derivative();
        }
        pid::update_within(
            &cfg.yaw_pid,
            yaw_pid,
            psi_proj - yaw_error,
            psi_proj,
            dt,
            lo - delta_ol,
            hi - delta_ol,
        )
        .map_err(|_| ControlFault::Numerical)?
    } else {
        // Paused: the yaw cannot be steered, and a held `δ_cl` would cancel the
        // plan's steering (a car standing at the lock could not turn its wheels
        // back). `δ_cl` and its integrator are released towards 0.
        yaw_pid.forget_derivative();
        // 1/(1 + Δt/τ): in (0, 1] for any step (the implicit Euler step of the decay).
        let keep = T::ONE / (T::ONE + dt * T::lit(1.0 / PAUSED_YAW_RELEASE_S));
        yaw_pid.integral *= keep;
        yaw_pid.last_output *= keep;
        yaw_pid.last_output
    };
    let delta = clamp_within(delta_ol + delta_cl, lo, hi);
    Ok((delta_ol, delta, yaw_error))
}
