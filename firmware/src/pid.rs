//! PID controller: coefficients ([`PidConfig`]) and state ([`PidState`]) kept apart.
//!
//! # Control law and sign convention
//!
//! The paper's convention (Polack et al., Section III D): the error is
//! **measurement minus setpoint**, and with positive gains
//!
//! ```text
//! e(t) = y(t) − r(t)
//! u(t) = −K_P·e(t) − K_I·∫e dτ − K_D·ẏ_f(t)
//! ```
//!
//! so a measurement above its setpoint drives the output negative. The derivative
//! acts on the **measurement** `y`, not on the error, so a step of the setpoint
//! causes no derivative kick; `ẏ_f` is the backward difference of `y` through a
//! first-order low-pass filter of time constant `T_f`
//! (`ẏ_f ← ẏ_f + α·((y_k − y_{k−1})/Δt − ẏ_f)`, `α = Δt/(T_f + Δt)`, the
//! backward-Euler discretisation of `T_f·ẏ_f' + ẏ_f = ẏ`; `T_f = 0` disables it).
//!
//! The integrator is stored as its contribution to the output, `I = −K_I·∫e dτ`
//! (output units), integrated with forward Euler: `I ← I − K_I·e·Δt`. This makes
//! presetting it bumpless ([`preset_output`]) and keeps it meaningful if `K_I` is
//! changed between updates.
//!
//! # Saturation and anti-windup
//!
//! `u = P + I + D` is clamped to `[output_min, output_max]` (optionally narrowed per
//! call by [`update_within`]); `I` is kept in `[integral_min, integral_max]`. While
//! the output saturates, the integrator is kept from winding up by the
//! [`AntiWindup`] mode of the configuration:
//!
//! * [`AntiWindup::Conditional`] (clamping): the integration step is skipped when
//!   the unclamped output is beyond a limit and the step would push it further out;
//! * [`AntiWindup::BackCalculation`]: the integrator is bled by
//!   `(u_sat − u_unsat)·Δt/T_t`;
//! * [`AntiWindup::None`]: plain integration, only bounded by the integrator limits
//!   (for comparison; not for use on a vehicle).
//!
//! # Cost
//!
//! One [`update`] is about 25 floating-point operations and one division (two
//! with back-calculation), no transcendental function: about 230 Thumb-2
//! instructions in `f32` (static count, many of them the checks), of the order of
//! 150 cycles on the Cortex-M4F.
//!
//! # Failures
//!
//! Non-finite inputs or a non-positive `Δt` return an error and leave the state
//! untouched; the caller keeps the last output ([`PidState::output`]) or goes to its
//! safe state.

use crate::Real;
use qp::real::{all_finite, at_least, at_most, clamp_within};

/// How the integrator is kept from winding up while the output saturates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AntiWindup<T> {
    /// No anti-windup: the integrator integrates the error whatever the output,
    /// bounded only by the integrator limits. For comparison and tests.
    None,
    /// Conditional integration (clamping): no integration step while the
    /// unclamped output is beyond a limit and the step would move it further out.
    Conditional,
    /// Back-calculation: the integrator is driven towards the saturated output with
    /// tracking time constant `tracking_time_s` (s, > 0; typically `√(T_i·T_d)` or
    /// about `T_i/2`).
    BackCalculation {
        /// Tracking time constant `T_t`, s.
        tracking_time_s: T,
    },
}

/// Coefficients and limits of one PID loop (never changed by [`update`]).
///
/// Units: write `[y]` for the unit of the setpoint and measurement and `[u]` for the
/// unit of the output; each field states its unit in those terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PidConfig<T> {
    /// Proportional gain `K_P`, `[u]/[y]`, ≥ 0.
    pub kp: T,
    /// Integral gain `K_I`, `[u]/([y]·s)`, ≥ 0 (0 disables the integrator's growth).
    pub ki: T,
    /// Derivative gain `K_D`, `[u]·s/[y]`, ≥ 0.
    pub kd: T,
    /// Time constant `T_f` of the first-order filter on the measurement's
    /// derivative, s, ≥ 0 (0: unfiltered backward difference).
    pub derivative_filter_s: T,
    /// Lower output limit, `[u]` (may be −∞).
    pub output_min: T,
    /// Upper output limit, `[u]` (may be +∞), ≥ `output_min`.
    pub output_max: T,
    /// Lower limit of the integrator's contribution `I`, `[u]` (may be −∞).
    pub integral_min: T,
    /// Upper limit of the integrator's contribution `I`, `[u]` (may be +∞),
    /// ≥ `integral_min`.
    pub integral_max: T,
    /// Anti-windup mode used while the output saturates.
    pub anti_windup: AntiWindup<T>,
    /// Nominal sample time, s, > 0 (the `Δt` of [`step`]).
    pub sample_time_s: T,
}

/// Why a [`PidConfig`] was refused by [`PidConfig::validate`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PidConfigError {
    /// A gain is NaN, infinite or negative.
    InvalidGain,
    /// The derivative filter time constant is NaN, infinite or negative.
    InvalidFilterTime,
    /// An output limit is NaN, or `output_min > output_max`.
    InvalidOutputLimits,
    /// An integrator limit is NaN, or `integral_min > integral_max`.
    InvalidIntegralLimits,
    /// The back-calculation tracking time is NaN, infinite or not positive.
    InvalidTrackingTime,
    /// The sample time is NaN, infinite or not positive.
    InvalidSampleTime,
}

/// Why one [`update`] was refused (the state is left untouched).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PidError {
    /// The setpoint or the measurement is NaN or infinite.
    NonFiniteInput,
    /// `Δt` is NaN, infinite, zero or negative.
    InvalidTimeStep,
    /// The per-call output window of [`update_within`] is NaN or empty.
    InvalidLimits,
    /// The computed output was not finite (overflow); nothing was stored.
    NonFiniteOutput,
}

impl<T: Real> PidConfig<T> {
    /// A configuration with the given gains, no derivative filter, no limits,
    /// conditional anti-windup and the given sample time (s).
    pub fn new(kp: T, ki: T, kd: T, sample_time_s: T) -> Self {
        Self {
            kp,
            ki,
            kd,
            derivative_filter_s: T::ZERO,
            output_min: -T::INFINITY,
            output_max: T::INFINITY,
            integral_min: -T::INFINITY,
            integral_max: T::INFINITY,
            anti_windup: AntiWindup::Conditional,
            sample_time_s,
        }
    }

    /// Checks every coefficient and limit; call once when the configuration is made.
    ///
    /// [`update`] does not re-check the configuration: with an unvalidated one it
    /// does not panic, but its output is meaningless.
    pub fn validate(&self) -> Result<(), PidConfigError> {
        let gain_ok = |g: T| g.is_finite() && g >= T::ZERO;
        if !(gain_ok(self.kp) && gain_ok(self.ki) && gain_ok(self.kd)) {
            return Err(PidConfigError::InvalidGain);
        }
        if !gain_ok(self.derivative_filter_s) {
            return Err(PidConfigError::InvalidFilterTime);
        }
        if !ordered(self.output_min, self.output_max) {
            return Err(PidConfigError::InvalidOutputLimits);
        }
        if !ordered(self.integral_min, self.integral_max) {
            return Err(PidConfigError::InvalidIntegralLimits);
        }
        if let AntiWindup::BackCalculation { tracking_time_s } = self.anti_windup {
            if !(tracking_time_s.is_finite() && tracking_time_s > T::ZERO) {
                return Err(PidConfigError::InvalidTrackingTime);
            }
        }
        if !(self.sample_time_s.is_finite() && self.sample_time_s > T::ZERO) {
            return Err(PidConfigError::InvalidSampleTime);
        }
        Ok(())
    }
}

/// The memory of one PID loop (changed only by a successful [`update`], by
/// [`preset_output`] and by the methods below).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PidState<T> {
    /// The integrator's contribution to the output, `I = −K_I·∫e dτ`, `[u]`.
    pub integral: T,
    /// Filtered derivative of the measurement `ẏ_f`, `[y]/s`.
    pub derivative: T,
    /// Measurement at the last update, `[y]` (meaningful when `initialised`).
    pub prev_measurement: T,
    /// Last output returned by [`update`], `[u]` (0 after a reset).
    pub last_output: T,
    /// False until the first update (or after [`PidState::forget_derivative`]): the
    /// next update then takes its measurement as the previous one, so the
    /// derivative starts at 0 without a kick.
    pub initialised: bool,
}

impl<T: Real> Default for PidState<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> PidState<T> {
    /// A fresh state: empty integrator, no derivative history, output 0.
    pub const fn new() -> Self {
        Self {
            integral: T::ZERO,
            derivative: T::ZERO,
            prev_measurement: T::ZERO,
            last_output: T::ZERO,
            initialised: false,
        }
    }

    /// Back to [`PidState::new`].
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Forgets the derivative history (filtered derivative set to 0, next update
    /// re-initialises the previous measurement) but keeps the integrator. Use after
    /// the loop was paused or the measurement jumped (e.g. an angle re-wrapped).
    pub fn forget_derivative(&mut self) {
        self.derivative = T::ZERO;
        self.initialised = false;
    }

    /// The last output returned by [`update`], `[u]`.
    pub fn output(&self) -> T {
        self.last_output
    }
}

/// One PID step with the configuration's sample time ([`PidConfig::sample_time_s`]).
pub fn step<T: Real>(
    cfg: &PidConfig<T>,
    state: &mut PidState<T>,
    setpoint: T,
    measurement: T,
) -> Result<T, PidError> {
    update(cfg, state, setpoint, measurement, cfg.sample_time_s)
}

/// One PID step: returns `u = clamp(−K_P·e + I − K_D·ẏ_f)`, `[u]`, with
/// `e = measurement − setpoint` (see the module doc), over a time step `dt_s` (s, > 0).
///
/// On error the state is left untouched.
pub fn update<T: Real>(
    cfg: &PidConfig<T>,
    state: &mut PidState<T>,
    setpoint: T,
    measurement: T,
    dt_s: T,
) -> Result<T, PidError> {
    update_within(
        cfg,
        state,
        setpoint,
        measurement,
        dt_s,
        -T::INFINITY,
        T::INFINITY,
    )
}

/// Like [`update`], but the output is further limited to `[out_lo, out_hi]`
/// (`[u]`, intersected with the configuration's limits), and anti-windup acts on
/// that window. For a loop whose authority changes from call to call (e.g. the
/// part of a steering angle left by an open-loop term). If the two ranges do not
/// overlap, the output is the bound of `[out_lo, out_hi]` nearest to the
/// configuration's range.
#[allow(clippy::too_many_arguments)]
// Inlined into the control task's two PID updates: a call fetches these flash lines
// again and saves registers; inlined, the callers' constants fold into it.
#[inline(always)]
pub fn update_within<T: Real>(
    cfg: &PidConfig<T>,
    state: &mut PidState<T>,
    setpoint: T,
    measurement: T,
    dt_s: T,
    out_lo: T,
    out_hi: T,
) -> Result<T, PidError> {
    // Finiteness without a branch per value.
    if !all_finite([setpoint, measurement]) {
        return Err(PidError::NonFiniteInput);
    }
    if !(all_finite([dt_s]) && dt_s > T::ZERO) {
        return Err(PidError::InvalidTimeStep);
    }
    if !ordered(out_lo, out_hi) {
        return Err(PidError::InvalidLimits);
    }
    // `out_lo`, `out_hi` not NaN (ordered): one comparison per bound.
    let lo = at_most(at_least(cfg.output_min, out_lo), out_hi);
    let hi = at_least(at_most(cfg.output_max, out_hi), out_lo);

    let e = measurement - setpoint;

    // Derivative of the measurement, filtered: `α·((y − y₋₁)/Δt − ẏ_f)` with
    // `α = Δt/(T_f + Δt)` is `(y − y₋₁ − ẏ_f·Δt)/(T_f + Δt)`, one division.
    let derivative = if state.initialised {
        let change = measurement - state.prev_measurement;
        state.derivative + (change - state.derivative * dt_s) / (cfg.derivative_filter_s + dt_s)
    } else {
        T::ZERO
    };

    let p = -cfg.kp * e;
    let d = -cfg.kd * derivative;
    let di = -cfg.ki * e * dt_s;
    let i_old = state.integral;

    let integral = match cfg.anti_windup {
        AntiWindup::None => i_old + di,
        AntiWindup::Conditional => {
            let candidate = i_old + di;
            let u_unsat = p + candidate + d;
            if (u_unsat > hi && di > T::ZERO) || (u_unsat < lo && di < T::ZERO) {
                i_old
            } else {
                candidate
            }
        }
        AntiWindup::BackCalculation { tracking_time_s } => {
            let u_unsat = p + i_old + d;
            let u_sat = clamp_within(u_unsat, lo, hi);
            i_old + di + (u_sat - u_unsat) * dt_s / tracking_time_s
        }
    };
    let integral = clamp_within(integral, cfg.integral_min, cfg.integral_max);

    let u = clamp_within(p + integral + d, lo, hi);
    if !all_finite([u, integral, derivative]) {
        return Err(PidError::NonFiniteOutput);
    }

    state.integral = integral;
    state.derivative = derivative;
    state.prev_measurement = measurement;
    state.last_output = u;
    state.initialised = true;
    Ok(u)
}

/// Bumpless transfer: presets the integrator so that, with the current setpoint,
/// measurement and filtered derivative, the controller's output is `output` (`[u]`)
/// — e.g. the command that was applied while the loop was off. The integrator is
/// kept within its limits, so the output is matched only as far as they allow.
/// Also takes `measurement` as the previous one (no derivative kick next update).
/// Returns the output the preset state corresponds to, `[u]`.
pub fn preset_output<T: Real>(
    cfg: &PidConfig<T>,
    state: &mut PidState<T>,
    setpoint: T,
    measurement: T,
    output: T,
) -> Result<T, PidError> {
    if !(setpoint.is_finite() && measurement.is_finite() && output.is_finite()) {
        return Err(PidError::NonFiniteInput);
    }
    let p = -cfg.kp * (measurement - setpoint);
    let d = -cfg.kd * state.derivative;
    let integral = (output - p - d).clamp(cfg.integral_min, cfg.integral_max);
    let u = (p + integral + d).clamp(cfg.output_min, cfg.output_max);
    if !(u.is_finite() && integral.is_finite()) {
        return Err(PidError::NonFiniteOutput);
    }
    state.integral = integral;
    state.prev_measurement = measurement;
    state.last_output = u;
    state.initialised = true;
    Ok(u)
}

/// `lo <= hi`, false when either is NaN.
#[inline]
fn ordered<T: Real>(lo: T, hi: T) -> bool {
    lo <= hi
}
