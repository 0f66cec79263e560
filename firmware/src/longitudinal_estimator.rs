//! Online estimate of the car's longitudinal dynamics: its effective mass, its
//! driving resistances and its brakes' effectiveness, from the wheel torque and
//! the measured speed while the tyres are far from their limit (not in the paper,
//! which knows its car).
//!
//! # Why
//!
//! The friction check ([`crate::friction`]) reads slip as the shortfall of the
//! measured acceleration on the one the wheel torque asks. A car heavier than
//! configured (passengers, luggage, a trailer), or with more drag, shows such a
//! shortfall too, at every demand. Estimated here, the mass and the resistances
//! leave slip as what remains: a shortfall that grows with the force demanded
//! beyond what the tyres far from their limit showed.
//!
//! # Model
//!
//! With `T` the total wheel torque commanded over a period (N·m; positive drives
//! the front wheels, negative brakes the four), `r` the wheel radius, `m₀` the
//! configured mass and `V` the speed, the longitudinal dynamics off the tyres'
//! limit, normalised by `m₀`:
//!
//! ```text
//! y = T/(r·m₀) = y_d + y_b,  y_d = max(y, 0),  y_b = min(y, 0)      m/s²
//! y_d + b·y_b = k·V̇ + r₀ + r₂·(V/V_ref)²
//! θ = [k, r₀, r₂]:  k = m/m₀ (effective mass ratio: wheel inertias included),
//!                   r₀ = F₀/m₀ (rolling resistance, grade; m/s²),
//!                   r₂ = c₂·V_ref²/m₀ (aerodynamic drag at V_ref = 30 m/s; m/s²)
//! b:                the brakes' gain, brake torque given per N·m commanded
//! ```
//!
//! A drive torque is what the motor gives (known from its current); a brake's
//! is its pads' friction times the force asked, which heat, wear and water
//! change by ±20 % or more. One ratio for both read a weak brake as a light car
//! and flagged the next acceleration as slip, or read a strong one as a heavy
//! car and flagged the next braking (a brake gain of 0.7 or 1.3 in the
//! simulator's plant: `μ̂` from 1 to 0.6 and 0.4 on a dry oval).
//!
//! **What tells them apart**: braking alone measures only `b/k` (the two are
//! proportional there); driving and coasting measure `k` and the resistances with
//! the brakes off. So `θ` is learnt from the samples whose filter memory holds no
//! braking (`|H·y_b|` at most [`LongitudinalConfig::brake_idle_mps2`]), `b` from
//! those with braking (`H·y_b` at least [`LongitudinalConfig::brake_excitation_mps2`]
//! in magnitude) given `θ`, once `θ` has learnt from a sample: the braking's
//! own evidence, the shortfall of the deceleration the brakes give on what the
//! learnt car needs (before any such sample, a grade braked onto would be read
//! as the brakes: a 6 % climb as brakes 28 % stronger). The grade is in `r₀`,
//! learnt only without braking: a grade that changes under the brakes (a
//! descent held by braking) is still read as the brakes' gain. Slip is kept out
//! of both by the gate below (no slip flagged, the demand within a fraction of
//! the grip, the wheels' slip ratio small when they are measured).
//!
//! The speed is not differentiated: `y`, `V` and `(V/V_ref)²` go through the same
//! second-order low-pass filter `H = 1/(τs + 1)²` (two cascaded first-order
//! filters, forward Euler), and `V̇` is replaced by the derivative of the filtered
//! speed, `(v₁ − v₂)/τ`, which equals `H·V̇` exactly in the discrete recursion. So
//! the regression `H·y = k·H·V̇ + r₀ + r₂·H·(V/V_ref)²` holds without lag between
//! its sides, and the speed's white noise reaches `H·V̇` attenuated to about
//! `0.13·σ_V/τ` (0.09 m/s² at σ_V = 0.2 m/s, τ = 0.3 s) instead of `σ_V/Δt`.
//!
//! # The accelerometer
//!
//! With the accelerometer's specific force along the car `f` (the acceleration
//! plus `g·sin γ` on a grade `γ`; [`LongitudinalSample::specific_force_mps2`]
//! gives `f + v_y·ψ̇`, `v̇_x + g·sin γ`: `crate::friction`, *The accelerometer*),
//! the model reads `y_d + b·y_b = k·f + r₀ + r₂·(V/V_ref)²`: the force the
//! tyres give against the mass times the non-gravitational force per unit mass.
//! The grade is then in `f`, not in `r₀`, which holds the rolling resistance
//! alone, and a climb taken while accelerating cannot be learnt as mass. `H·f`
//! (`f` through the same two stages) replaces `H·V̇`; everything else is as
//! below. Without it (`f` not finite) the grade is a resistance that changes
//! under the car, which the forgetting follows with lag: the mass ratio takes
//! what `r₀` has not yet followed (`docs/sweeps.md`, the grade row).
//!
//! # Estimator
//!
//! Recursive least squares with exponential forgetting (memory
//! [`LongitudinalConfig::memory_s`], `λ = 1 − Δt/memory`), `φ = [H·V̇, 1, H·q]`,
//! on the samples without braking:
//!
//! ```text
//! g = P·φ / (λ + φᵀ·P·φ),   θ ← clamp(θ + g·(H·y_d − θᵀφ)),   P ← (P − g·φᵀ·P)/λ
//! ```
//!
//! and a scalar one for `b` on the braking samples, `φ_b = H·y_b`,
//! `z = k·H·V̇ + r₀ + r₂·H·q − H·y_d` (what the brakes gave, per `m₀`):
//!
//! ```text
//! g_b = P_b·φ_b / (λ + P_b·φ_b²),   b ← clamp(b + g_b·(z − b·φ_b)),   P_b ← (1 − g_b·φ_b)·P_b/λ
//! ```
//!
//! * **Gate** (the tyres far from their limit, the model valid): a sample counts
//!   only when, for the whole of the last [`LongitudinalConfig::settle_s`] (the
//!   filters' memory), the speed was at least [`LongitudinalConfig::min_speed_mps`],
//!   no slip was flagged, the wheels' measured slip ratio was at most
//!   [`LongitudinalConfig::max_slip_ratio`] (a driven wheel spinning up past its
//!   peak loses little force at first: its shortfall, too small to flag, would
//!   read as mass), the demand `|y_d + b̂·y_b − r̂|/k̂` was at most
//!   [`LongitudinalConfig::demand_fraction`] of `μ̂·g` (of the driven axle's share
//!   when driving; [`LongitudinalConfig::measured_demand_fraction`] when the
//!   wheel speeds are measured: their slip ratio then shows a tyre past its
//!   linear range directly), and the lateral acceleration `|V·ψ̇|` at most
//!   [`LongitudinalConfig::lateral_fraction`] of `μ̂·g` (cornering drag is not in
//!   the model).
//! * **Excitation**: a sample whose filtered demand `|H·y − r₀ − r₂·H·q|/k̂` (the
//!   torque's, free of the speed's noise) is under
//!   [`LongitudinalConfig::excitation_mps2`] (steady cruise) informs the
//!   resistances only (`φ = [0, 1, H·q]` against `H·y − k̂·H·V̇`) and without
//!   forgetting (`λ = 1`): no information on the mass means none is forgotten, so
//!   `P` cannot wind up, and the speed's noise in `H·V̇` cannot drag `k` to 0.
//!   A braking sample whose `|H·y_b|` is under
//!   [`LongitudinalConfig::brake_excitation_mps2`] but over the idle level informs
//!   nothing.
//! * **Bounds**: `θ` is clamped to `[k_min, k_max] × [−r₀,max, r₀,max] ×
//!   [0, r₂,max]`, `b` to [`LongitudinalConfig::brake_gain_bounds`]; the trace of
//!   `P` is held at most its prior's (scaled by `2 − x` when above it by the
//!   ratio `x`: no division, at most `(Δt/memory)²` under it), `P_b` at most its
//!   prior; a non-finite or non-positive diagonal resets `P` (`P_b`) to its prior.
//! * **Uncertainty** of the mass ratio, used by the friction check as a tolerance
//!   on the relative shortfall when driving: `u = u_max·sqrt(P₀₀/P₀₀,prior)` (at
//!   most [`LongitudinalConfig::mass_uncertainty_max`]: before any sample a
//!   shortfall the heaviest car allowed would show is not slip); of the brakes'
//!   gain, the tolerance when braking, `u_b = u_b,max·sqrt(P_b/P_b,prior)` (at most
//!   [`LongitudinalConfig::brake_uncertainty_max`]: braking measures `b/k`, which
//!   `b` is learnt as, so `u_b` alone is that ratio's).
//!
//! Non-finite inputs are refused (the filters restart, `θ` and `P` are kept).
//!
//! # Cost
//!
//! Per period about 100 floating-point operations, two divisions (the RLS gain,
//! and the inverse of the parameter updated: mass ratio or brake gain; the
//! braking and the driving updates exclusive) and one square root (on the FPU,
//! the updated parameter's uncertainty: kept, so that reading it costs none);
//! the settings' inverses are taken once, at [`LongitudinalEstimator::start`];
//! no loop, no branch on data but the gate and the choice of update; 124 bytes
//! of state in `f32`.

use crate::Real;
use qp::real::{at_most, clamp_within, larger, smaller};

/// The filter's two first-order stages `[stage 1, stage 2]` advanced by the
/// input `x` with the gain `k` (forward Euler): stage 1 towards `x`, stage 2
/// towards the new stage 1.
#[inline(always)]
fn two_stages<T: Real>(stages: [T; 2], x: T, k: T) -> [T; 2] {
    let s1 = stages[0] + k * (x - stages[0]);
    [s1, stages[1] + k * (s1 - stages[1])]
}

/// `x` within `[lo, hi]` (not NaN, `lo <= hi`), a NaN `x` passed through, for
/// the caller to refuse (`Real::clamp` gives `lo`); one comparison per bound.
#[inline(always)]
fn clamp_nan<T: Real>(x: T, lo: T, hi: T) -> T {
    smaller(larger(x, lo), hi)
}

/// Reference speed of the drag term `r₂·(V/V_ref)²`, m/s.
pub const V_REF_MPS: f32 = 30.0;

/// Settings of the estimator (module docs). Valid when
/// [`LongitudinalConfig::validate`] says so.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LongitudinalConfig<T> {
    /// Configured mass `m₀`, kg, > 0.
    pub mass_kg: T,
    /// Effective wheel radius `r`, m, > 0.
    pub wheel_radius_m: T,
    /// Time constant `τ` of each of the two low-pass stages, s, > 0.
    pub filter_time_s: T,
    /// Memory of the forgetting, s, > 0 (`λ = 1 − Δt/memory`).
    pub memory_s: T,
    /// Time the gate must have held before a sample counts, s, ≥ 0.
    pub settle_s: T,
    /// Smallest speed of a sample, m/s, ≥ 0.
    pub min_speed_mps: T,
    /// Largest demand of a sample as a fraction of `μ̂·g` (of the driven axle's
    /// share when driving), in `(0, 1]`.
    pub demand_fraction: T,
    /// The same when the wheel speeds are measured, in `(0, 1]`: the slip
    /// ratio then shows a tyre past its linear range directly (module docs).
    pub measured_demand_fraction: T,
    /// Largest lateral acceleration of a sample as a fraction of `μ̂·g`, in `(0, 1]`.
    pub lateral_fraction: T,
    /// Filtered demand under which a sample informs the resistances only and
    /// forgets nothing, m/s², ≥ 0.
    pub excitation_mps2: T,
    /// Bounds of the mass ratio `k = m/m₀`: `[min, max]`, `0 < min ≤ 1 ≤ max`.
    pub mass_ratio_bounds: [T; 2],
    /// Bound of `|r₀|`, m/s², ≥ 0.
    pub r0_max_mps2: T,
    /// Bound of `r₂` (drag at [`V_REF_MPS`]), m/s², ≥ 0.
    pub r2_max_mps2: T,
    /// Prior variances (the diagonal of `P` at the start) of `k`, `r₀`, `r₂`:
    /// `[1, (m/s²)², (m/s²)²]` per `(m/s²)²` of residual, each > 0.
    pub prior_variance: [T; 3],
    /// Uncertainty of the mass ratio at the prior, `u_max`, in `[0, 1)`.
    pub mass_uncertainty_max: T,
    /// Largest wheel slip ratio `|κ|` of a sample, dimensionless, > 0 (module
    /// docs; compared as `|ω·r − V| ≤ κ·|V|`; a sample without measured wheel
    /// speeds gives 0).
    pub max_slip_ratio: T,
    /// Filtered braking `|H·y_b|` up to which a sample counts as one without
    /// braking (for `θ`), m/s², ≥ 0.
    pub brake_idle_mps2: T,
    /// Filtered braking `|H·y_b|` from which a sample informs the brakes' gain,
    /// m/s², > `brake_idle_mps2`.
    pub brake_excitation_mps2: T,
    /// Bounds of the brakes' gain `b`: `[min, max]`, `0 < min ≤ 1 ≤ max`.
    pub brake_gain_bounds: [T; 2],
    /// Prior variance of `b`, per `(m/s²)²` of residual, > 0.
    pub brake_prior_variance: T,
    /// Uncertainty of the brakes' gain at the prior, `u_b,max`, in `[0, 1)`.
    pub brake_uncertainty_max: T,
}

/// Why a [`LongitudinalConfig`] was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LongitudinalConfigError {
    /// Mass or wheel radius not finite and positive.
    InvalidVehicle,
    /// A time constant, the memory or the settling time out of range.
    InvalidTiming,
    /// A gate's fraction, speed or excitation out of range.
    InvalidGate,
    /// A parameter's bound or prior out of range.
    InvalidBounds,
}

impl<T: Real> LongitudinalConfig<T> {
    /// The settings for a car of configured mass `mass_kg` (kg) on wheels of
    /// radius `wheel_radius_m` (m):
    ///
    /// * filters `τ = 0.3 s` (two stages), a sample counts after 1.2 s of gate
    ///   (`4τ`: the filters have forgotten all but 2 % of what came before);
    /// * memory 10 s of excited samples (the mass is learnt from the driving
    ///   alone, about a quarter of a lap's time: a load changed at a stop is
    ///   followed within about two laps' accelerations);
    /// * gate: above 3 m/s, demand at most 0.5 of `μ̂·g` (0.9 with the wheel
    ///   speeds measured: their slip ratio gates the tyre's range; a tyre at half its
    ///   friction gives its force at a few % of slip), lateral at most 0.3;
    /// * excitation 0.2 m/s² of filtered demand;
    /// * `k ∈ [0.6, 1.8]` (a car 40 % lighter to 80 % heavier than configured),
    ///   `|r₀| ≤ 1 m/s²` (a 10 % grade), `r₂ ∈ [0, 1] m/s²` at 30 m/s (four times
    ///   the default car's drag);
    /// * prior variances `[0.5, 0.1, 0.1]` (`u` halves after about 3 s of
    ///   excited samples at 1 m/s²), uncertainty 0.25 at the prior
    ///   (a car 1.33 times heavier gives a relative shortfall of 0.25; more
    ///   would hide the front wheels spinning at a planner friction 1.5 times
    ///   the road's: a shortfall of 0.49 of 3.5 m/s² asked);
    /// * wheel slip ratio at most 0.06 (the default tyre gives half its peak
    ///   force at 0.031 of slip, 0.8 of it at 0.061, its peak at 0.145 at μ 1:
    ///   its linear range, where the torque turns into force; spinning or
    ///   locking, 0.15 and more);
    /// * brakes idle under 0.05 m/s² of filtered braking (a gain wrong by 0.5
    ///   then errs by 0.025 m/s² on `θ`'s samples), excited from 0.3 m/s²;
    /// * `b ∈ [0.5, 1.5]`, prior variance 0.1 (`u_b` halves after about 1 s of
    ///   braking at 1.5 m/s²), uncertainty 0.3 at the prior (a brake 30 % weaker
    ///   than commanded is not slip before anything is learnt; locked wheels
    ///   lose 2–8 m/s² of 5–8 asked, more than that).
    pub fn for_car(mass_kg: T, wheel_radius_m: T) -> Self {
        Self {
            mass_kg,
            wheel_radius_m,
            filter_time_s: T::lit(0.3),
            memory_s: T::lit(10.0),
            settle_s: T::lit(1.2),
            min_speed_mps: T::lit(3.0),
            demand_fraction: T::HALF,
            measured_demand_fraction: T::lit(0.9),
            lateral_fraction: T::lit(0.3),
            excitation_mps2: T::lit(0.2),
            mass_ratio_bounds: [T::lit(0.6), T::lit(1.8)],
            r0_max_mps2: T::ONE,
            r2_max_mps2: T::ONE,
            prior_variance: [T::HALF, T::lit(0.1), T::lit(0.1)],
            mass_uncertainty_max: T::lit(0.25),
            max_slip_ratio: T::lit(0.06),
            brake_idle_mps2: T::lit(0.05),
            brake_excitation_mps2: T::lit(0.3),
            brake_gain_bounds: [T::HALF, T::lit(1.5)],
            brake_prior_variance: T::lit(0.1),
            brake_uncertainty_max: T::lit(0.3),
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), LongitudinalConfigError> {
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        let nonneg = |x: T| x.is_finite() && x >= T::ZERO;
        let fraction = |x: T| pos(x) && x <= T::ONE;
        if !(pos(self.mass_kg) && pos(self.wheel_radius_m)) {
            return Err(LongitudinalConfigError::InvalidVehicle);
        }
        if !(pos(self.filter_time_s) && pos(self.memory_s) && nonneg(self.settle_s)) {
            return Err(LongitudinalConfigError::InvalidTiming);
        }
        if !(nonneg(self.min_speed_mps)
            && fraction(self.demand_fraction)
            && fraction(self.measured_demand_fraction)
            && fraction(self.lateral_fraction)
            && nonneg(self.excitation_mps2)
            && pos(self.max_slip_ratio)
            && nonneg(self.brake_idle_mps2)
            && self.brake_excitation_mps2.is_finite()
            && self.brake_excitation_mps2 > self.brake_idle_mps2)
        {
            return Err(LongitudinalConfigError::InvalidGate);
        }
        let [lo, hi] = self.mass_ratio_bounds;
        let [p0, p1, p2] = self.prior_variance;
        if !(pos(lo)
            && lo <= T::ONE
            && hi.is_finite()
            && hi >= T::ONE
            && nonneg(self.r0_max_mps2)
            && nonneg(self.r2_max_mps2)
            && pos(p0)
            && pos(p1)
            && pos(p2)
            && nonneg(self.mass_uncertainty_max)
            && self.mass_uncertainty_max < T::ONE
            && pos(self.brake_gain_bounds[0])
            && self.brake_gain_bounds[0] <= T::ONE
            && self.brake_gain_bounds[1].is_finite()
            && self.brake_gain_bounds[1] >= T::ONE
            && pos(self.brake_prior_variance)
            && nonneg(self.brake_uncertainty_max)
            && self.brake_uncertainty_max < T::ONE)
        {
            return Err(LongitudinalConfigError::InvalidBounds);
        }
        Ok(())
    }
}

/// One period's measurements for [`LongitudinalEstimator::update`] (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LongitudinalSample<T> {
    /// Time since the previous sample, s, > 0.
    pub dt_s: T,
    /// Measured speed `V`, m/s.
    pub v_mps: T,
    /// Total wheel torque commanded over the period that ended at the
    /// measurement, N·m (negative: braking, before the brakes' gain).
    pub torque_nm: T,
    /// Lateral acceleration `V·ψ̇`, m/s².
    pub lateral_mps2: T,
    /// The grip the tyres have at most, `μ̂·g`, m/s².
    pub grip_mps2: T,
    /// The driven axle's share of the weight when driving, in `(0, 1]`.
    pub driven_share: T,
    /// True when slip is flagged (the friction check): no sample counts.
    pub slipping: bool,
    /// Largest difference `|ω·r − V|` of a wheel's speed from the ground's under
    /// it, m/s (0 when the wheel speeds are not measured): its slip ratio times
    /// the speed.
    pub slip_mps: T,
    /// True when the wheel speeds were measured (`slip_mps` read from them):
    /// the demand gate is then [`LongitudinalConfig::measured_demand_fraction`].
    pub wheels_measured: bool,
    /// The accelerometer's specific force along the car plus `v_y·ψ̇`
    /// (`v̇_x + g·sin γ`), m/s² (module docs, *The accelerometer*); not finite:
    /// not measured, the acceleration is read
    /// from the speed. The caller restarts the estimator
    /// ([`LongitudinalEstimator::restart`]) when it goes from one to the other.
    pub specific_force_mps2: T,
}

/// The estimator's state (module docs): filters, parameters, covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LongitudinalEstimator<T> {
    /// `θ = [k, r₀, r₂]`: mass ratio, m/s², m/s².
    theta: [T; 3],
    /// `1/k`.
    inv_k: T,
    /// The brakes' gain `b` (dimensionless), `1/b`, and its variance `P_b`.
    brake: [T; 3],
    /// The uncertainties `[u, u_b]` of `P` and `P_b` as they stand (computed
    /// when they change: one square root per update, none per read).
    u: [T; 2],
    /// `P` (symmetric), its upper triangle `[p00, p01, p02, p11, p12, p22]`.
    p: [T; 6],
    /// The filters' stages: speed (m/s), `y` (m/s²), `(V/V_ref)²`, `y_b` (m/s²):
    /// `[stage 1, stage 2]`.
    v_f: [T; 2],
    /// The specific force's stages, m/s² (NaN while not measured).
    f_f: [T; 2],
    y_f: [T; 2],
    q_f: [T; 2],
    yb_f: [T; 2],
    /// Time the gate has held, s (`< 0`: the filters restart at the next sample).
    clean_s: T,
    /// Samples that counted (wrapping).
    updates: u32,
    /// True once `θ` has learnt from a sample (the brakes' gain learns only
    /// then).
    theta_learnt: bool,
    /// `[1/τ, 1/memory, 1/P₀₀,prior, 1/P_b,prior, 1/tr(P_prior)]` of the settings
    /// given to [`LongitudinalEstimator::start`] (zero before: nothing moves), so
    /// that a period divides only where the data does.
    inverses: [T; 5],
}

impl<T: Real> Default for LongitudinalEstimator<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> LongitudinalEstimator<T> {
    /// The configured car (`k = 1`, no resistance) and a zero covariance: a valid
    /// `const` initialiser; [`LongitudinalEstimator::start`] sets the prior.
    pub const fn new() -> Self {
        Self {
            theta: [T::ONE, T::ZERO, T::ZERO],
            inv_k: T::ONE,
            brake: [T::ONE, T::ONE, T::ZERO],
            u: [T::ZERO; 2],
            p: [T::ZERO; 6],
            v_f: [T::ZERO; 2],
            f_f: [T::ZERO; 2],
            y_f: [T::ZERO; 2],
            q_f: [T::ZERO; 2],
            yb_f: [T::ZERO; 2],
            clean_s: T::NEG_INFINITY,
            updates: 0,
            theta_learnt: false,
            inverses: [T::ZERO; 5],
        }
    }

    /// Forgets everything: the configured car, no resistance, brakes as
    /// commanded, the prior covariances of `cfg` (valid:
    /// [`LongitudinalConfig::validate`]; [`LongitudinalEstimator::update`] must
    /// be given the same settings).
    pub fn start(&mut self, cfg: &LongitudinalConfig<T>) {
        *self = Self::new();
        self.reset_covariance(cfg);
        self.brake[2] = cfg.brake_prior_variance;
        self.u = [cfg.mass_uncertainty_max, cfg.brake_uncertainty_max];
        let [v0, v1, v2] = cfg.prior_variance;
        self.inverses = [
            T::ONE / cfg.filter_time_s,
            T::ONE / cfg.memory_s,
            T::ONE / v0,
            T::ONE / cfg.brake_prior_variance,
            T::ONE / (v0 + v1 + v2),
        ];
    }

    fn reset_covariance(&mut self, cfg: &LongitudinalConfig<T>) {
        let [a, b, c] = cfg.prior_variance;
        self.p = [a, T::ZERO, T::ZERO, b, T::ZERO, c];
    }

    /// The mass ratio `k = m/m₀`, dimensionless, within its bounds.
    pub fn mass_ratio(&self) -> T {
        self.theta[0]
    }

    /// `1/k`, dimensionless.
    pub fn inverse_mass_ratio(&self) -> T {
        self.inv_k
    }

    /// The estimated effective mass `k·m₀`, kg.
    pub fn mass_kg(&self, cfg: &LongitudinalConfig<T>) -> T {
        self.theta[0] * cfg.mass_kg
    }

    /// `[r₀, r₂]`: the resistance per configured mass at rest and the drag at
    /// [`V_REF_MPS`], m/s² each.
    pub fn resistance_terms_mps2(&self) -> [T; 2] {
        [self.theta[1], self.theta[2]]
    }

    /// The driving resistance per configured mass at the speed `v_mps` (m/s),
    /// `r₀ + r₂·(V/V_ref)²`, m/s² (times `m₀`: the force, N).
    pub fn resistance_mps2(&self, v_mps: T) -> T {
        let q = v_mps * T::lit(1.0 / V_REF_MPS);
        self.theta[1] + self.theta[2] * q * q
    }

    /// The acceleration the torque `torque_nm` (N·m, commanded) gives the
    /// estimated car at the speed `v_mps` (m/s) when its tyres grip, m/s²:
    /// `(y_d + b·y_b − r(V))/k`.
    pub fn expected_accel_mps2(&self, cfg: &LongitudinalConfig<T>, torque_nm: T, v_mps: T) -> T {
        let y = self.applied_mps2(T::ONE / (cfg.mass_kg * cfg.wheel_radius_m), torque_nm);
        (y - self.resistance_mps2(v_mps)) * self.inv_k
    }

    /// The uncertainty `u` of the mass ratio (module docs), dimensionless, in
    /// `[0, mass_uncertainty_max]`: a relative shortfall under `u` may be mass.
    /// Kept from the last update of `P` (`cfg` is the one it was computed with).
    pub fn mass_uncertainty(&self, _cfg: &LongitudinalConfig<T>) -> T {
        self.u[0]
    }

    /// The brakes' gain `b`, brake torque given per N·m commanded,
    /// dimensionless, within its bounds.
    pub fn brake_gain(&self) -> T {
        self.brake[0]
    }

    /// `1/b`, dimensionless.
    pub fn inverse_brake_gain(&self) -> T {
        self.brake[1]
    }

    /// The uncertainty `u_b` of the brakes' gain (module docs), dimensionless,
    /// in `[0, brake_uncertainty_max]`: a relative shortfall under `u_b` when
    /// braking may be the brakes.
    /// Kept from the last update of `P_b`.
    pub fn brake_uncertainty(&self, _cfg: &LongitudinalConfig<T>) -> T {
        self.u[1]
    }

    /// The tolerance on the relative shortfall for a demand of sign `braking`:
    /// [`Self::brake_uncertainty`] when braking, [`Self::mass_uncertainty`]
    /// otherwise, dimensionless (one square root).
    pub fn uncertainty(&self, _cfg: &LongitudinalConfig<T>, braking: bool) -> T {
        if braking {
            self.u[1]
        } else {
            self.u[0]
        }
    }

    /// `u_max·sqrt(p/prior)`, `p/prior` within `[0, 1]` (module docs), from
    /// `inv_prior = 1/prior`.
    fn uncertainty_of(p: T, inv_prior: T, max: T) -> T {
        max * clamp_within(p * inv_prior, T::ZERO, T::ONE).sqrt()
    }

    /// The force per configured mass the torque `torque_nm` (N·m) gives through
    /// the wheels, m/s²: `y_d + b·y_b` of `y = torque·inv_mr` (`inv_mr` is
    /// `1/(m₀·r)`, 1/(kg·m)).
    pub fn applied_mps2(&self, inv_mr: T, torque_nm: T) -> T {
        let y = torque_nm * inv_mr;
        if y < T::ZERO {
            y * self.brake[0]
        } else {
            y
        }
    }

    /// Samples that counted so far (wrapping).
    pub fn updates(&self) -> u32 {
        self.updates
    }

    /// The filters restart at the next sample (a gap, a fault); `θ` and `P` kept.
    pub fn restart(&mut self) {
        self.clean_s = T::NEG_INFINITY;
    }

    /// One period (module docs). `inv_mr` is `1/(m₀·r)` (1/(kg·m)), precomputed by
    /// the caller; `cfg` the settings given to [`LongitudinalEstimator::start`].
    /// Returns true when the sample counted.
    pub fn update(
        &mut self,
        cfg: &LongitudinalConfig<T>,
        inv_mr: T,
        s: &LongitudinalSample<T>,
    ) -> bool {
        let y = s.torque_nm * inv_mr;
        let yb = smaller(y, T::ZERO);
        let q = s.v_mps * T::lit(1.0 / V_REF_MPS);
        let q = q * q;
        let finite = (y + q + s.dt_s + s.lateral_mps2 + s.grip_mps2 + s.driven_share + s.slip_mps)
            .is_finite();
        if !(finite && s.dt_s > T::ZERO) {
            self.restart();
            return false;
        }
        if self.clean_s < T::ZERO {
            // Filters at rest on the first sample.
            self.v_f = [s.v_mps; 2];
            self.f_f = [s.specific_force_mps2; 2];
            self.y_f = [y; 2];
            self.q_f = [q; 2];
            self.yb_f = [yb; 2];
            self.clean_s = T::ZERO;
            return false;
        }
        // Two first-order stages; H·V̇ = (v₁ − v₂)/τ after stage 1, before stage 2.
        let [inv_tau, inv_memory, ..] = self.inverses;
        let kf = at_most(s.dt_s * inv_tau, T::ONE);
        let v_f = two_stages(self.v_f, s.v_mps, kf);
        let mut accel = (v_f[0] - self.v_f[1]) * inv_tau;
        self.v_f = v_f;
        // With the accelerometer, `H·f` in place of `H·V̇` (module docs).
        self.f_f = two_stages(self.f_f, s.specific_force_mps2, kf);
        if self.f_f[1].is_finite() {
            accel = self.f_f[1];
        }
        self.y_f = two_stages(self.y_f, y, kf);
        self.q_f = two_stages(self.q_f, q, kf);
        self.yb_f = two_stages(self.yb_f, yb, kf);
        let [_, y2] = self.y_f;
        let [_, q2] = self.q_f;
        let [b1, b2] = self.yb_f;

        // The gate, over the filters' memory.
        let applied = y + (self.brake[0] - T::ONE) * yb;
        // r(V) from `q` as computed above (`resistance_mps2`, without its square).
        let demand = (applied - self.theta[1] - self.theta[2] * q) * self.inv_k;
        let share = if demand > T::ZERO {
            s.driven_share
        } else {
            T::ONE
        };
        let fraction = if s.wheels_measured {
            cfg.measured_demand_fraction
        } else {
            cfg.demand_fraction
        };
        let open = !s.slipping
            && s.slip_mps.abs() <= cfg.max_slip_ratio * s.v_mps.abs()
            && s.v_mps >= cfg.min_speed_mps
            && demand.abs() <= fraction * s.grip_mps2 * share
            && s.lateral_mps2.abs() <= cfg.lateral_fraction * s.grip_mps2;
        self.clean_s = if open { self.clean_s + s.dt_s } else { T::ZERO };
        if self.clean_s < cfg.settle_s {
            return false;
        }
        // H·y_d: the drive's share of the filtered torque.
        let yd2 = y2 - b2;
        if b2 <= -cfg.brake_excitation_mps2 {
            // Braking: what the brakes gave, z = k·H·V̇ + r(·) − H·y_d, against
            // the filtered braking commanded; only once `θ` has learnt from a
            // sample without braking: before, `z` holds whatever resistance
            // the road has (a climb braked onto before any such sample read as
            // brakes 28 % stronger than they were, and their next braking as
            // slip).
            if !self.theta_learnt {
                return false;
            }
            let [k, r0, r2] = self.theta;
            let z = k * accel + r0 + r2 * q2 - yd2;
            self.brake_rls(cfg, b2, z, s.dt_s * inv_memory);
            return true;
        }
        if b1 < -cfg.brake_idle_mps2 || b2 < -cfg.brake_idle_mps2 {
            // Braking in the filters' memory, too little to tell `b`: nothing.
            return false;
        }
        // The brakes idle: the drive's torque (the little braking left, at the
        // gain learnt) against the mass and the resistances.
        let y2 = yd2 + self.brake[0] * b2;
        // Excitation: the filtered demand (the torque's, free of the speed's noise).
        let excited =
            ((y2 - self.theta[1] - self.theta[2] * q2) * self.inv_k).abs() >= cfg.excitation_mps2;
        if excited {
            self.rls(cfg, [accel, T::ONE, q2], y2, s.dt_s * inv_memory);
        } else {
            // Steady: the resistances only (the acceleration's share, from the
            // mass ratio as it stands, taken out), nothing forgotten.
            let y = y2 - self.theta[0] * accel;
            self.rls(cfg, [T::ZERO, T::ONE, q2], y, T::ZERO);
        }
        true
    }

    /// One scalar recursive-least-squares step of the brakes' gain on
    /// `φ_b = H·y_b` (m/s², < 0) and `z` (m/s²), forgetting the fraction `forget`
    /// (module docs).
    // One caller, once per control period: inlined, no call to bound.
    #[inline(always)]
    fn brake_rls(&mut self, cfg: &LongitudinalConfig<T>, phi: T, z: T, forget: T) {
        let [b, _, p] = self.brake;
        let (lambda, inv_lambda) = (T::ONE - forget, T::ONE + forget);
        let pf = p * phi;
        let g = pf / (lambda + pf * phi);
        let [lo, hi] = cfg.brake_gain_bounds;
        // A NaN passes the bounds (`clamp_nan`) and is refused below.
        let b = clamp_nan(b + g * (z - b * phi), lo, hi);
        let p = smaller((p - g * pf) * inv_lambda, cfg.brake_prior_variance);
        if b.is_finite() {
            self.brake[0] = b;
            self.brake[1] = T::ONE / b;
        }
        self.brake[2] = if p.is_finite() && p > T::ZERO {
            p
        } else {
            cfg.brake_prior_variance
        };
        self.u[1] =
            Self::uncertainty_of(self.brake[2], self.inverses[3], cfg.brake_uncertainty_max);
        self.updates = self.updates.wrapping_add(1);
    }

    /// One recursive-least-squares step on `φ`, `y` (module docs), forgetting the
    /// fraction `forget` (`1 − λ`, dimensionless).
    // One caller, once per control period: inlined, no call to bound.
    #[inline(always)]
    fn rls(&mut self, cfg: &LongitudinalConfig<T>, phi: [T; 3], y: T, forget: T) {
        let [p00, p01, p02, p11, p12, p22] = self.p;
        let [a, b, c] = phi;
        let pf = [
            p00 * a + p01 * b + p02 * c,
            p01 * a + p11 * b + p12 * c,
            p02 * a + p12 * b + p22 * c,
        ];
        // 1/λ to first order: (Δt/memory)² ≤ 1e-6 at 100 Hz.
        let (lambda, inv_lambda) = (T::ONE - forget, T::ONE + forget);
        let inv_s = T::ONE / (lambda + a * pf[0] + b * pf[1] + c * pf[2]);
        let g = [pf[0] * inv_s, pf[1] * inv_s, pf[2] * inv_s];
        let [k, r0, r2] = self.theta;
        let e = y - (k * a + r0 * b + r2 * c);
        let [lo, hi] = cfg.mass_ratio_bounds;
        let k = clamp_nan(k + g[0] * e, lo, hi);
        let r0 = clamp_nan(r0 + g[1] * e, -cfg.r0_max_mps2, cfg.r0_max_mps2);
        let r2 = clamp_nan(r2 + g[2] * e, T::ZERO, cfg.r2_max_mps2);
        // A NaN from a degenerate P keeps the last parameters (`clamp_nan` passes
        // it; `Real::clamp` would give the lower bound).
        if (k + r0 + r2).is_finite() {
            self.theta = [k, r0, r2];
            self.inv_k = T::ONE / k;
        }
        let mut p = [
            (p00 - g[0] * pf[0]) * inv_lambda,
            (p01 - g[0] * pf[1]) * inv_lambda,
            (p02 - g[0] * pf[2]) * inv_lambda,
            (p11 - g[1] * pf[1]) * inv_lambda,
            (p12 - g[1] * pf[2]) * inv_lambda,
            (p22 - g[2] * pf[2]) * inv_lambda,
        ];
        // The trace held at most the prior's: over it (by at most the forgetting,
        // from a trace within it), `P` is scaled by `2 − x`, `x` = trace / the
        // prior's, which leaves `1 − (x − 1)²` of the prior's trace (within
        // `(Δt/memory)²` of it, no division); a scale not positive (`x ≥ 2`: no
        // such step) is refused with the rest below.
        let x = (p[0] + p[3] + p[5]) * self.inverses[4];
        if x > T::ONE {
            let f = T::TWO - x;
            p = [p[0] * f, p[1] * f, p[2] * f, p[3] * f, p[4] * f, p[5] * f];
        }
        if !(x.is_finite() && p[0] > T::ZERO && p[3] > T::ZERO && p[5] > T::ZERO) {
            self.reset_covariance(cfg);
        } else {
            self.p = p;
        }
        self.u[0] = Self::uncertainty_of(self.p[0], self.inverses[2], cfg.mass_uncertainty_max);
        self.updates = self.updates.wrapping_add(1);
        self.theta_learnt = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const M: f64 = 1500.0;
    const R: f64 = 0.3;
    const DT: f64 = 0.01;

    fn cfg() -> LongitudinalConfig<f64> {
        cfg_of()
    }

    /// The settings in the precision `T`.
    fn cfg_of<T: Real>() -> LongitudinalConfig<T> {
        LongitudinalConfig::for_car(T::from_f64(M), T::from_f64(R))
    }

    /// A deterministic pseudo-random normal sample (SplitMix64 + Box–Muller).
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform().max(1e-12), self.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// A car of mass `m` (kg) with resistance `f0 + c2·V²` (N) driven on a
    /// repeating pattern of moderate accelerations and brakings; the speed is
    /// measured with white noise `sigma` (m/s). `slip(t, a_cmd)` (m/s²) takes
    /// away acceleration the torque asked (a wheel that spins), unflagged.
    struct Car {
        m: f64,
        f0: f64,
        c2: f64,
        /// The brakes' gain: brake torque given per N·m commanded.
        brake: f64,
        /// The wheels' slip ratio reported with each sample.
        slip_ratio: f64,
        /// `sin γ` of the road's grade at time `t` (uphill positive).
        grade: fn(f64) -> f64,
        /// The accelerometer's white noise, m/s² (`None`: not measured).
        accel_sigma: Option<f64>,
        v: f64,
        t: f64,
        sigma: f64,
        rng: Rng,
    }

    impl Car {
        fn new(m: f64, f0: f64, c2: f64, sigma: f64) -> Self {
            Self {
                m,
                f0,
                c2,
                brake: 1.0,
                slip_ratio: 0.0,
                grade: |_| 0.0,
                accel_sigma: None,
                v: 20.0,
                t: 0.0,
                sigma,
                rng: Rng(7),
            }
        }

        /// Runs `secs`, feeding the estimator; `accel_cmd(t)` is the acceleration
        /// asked of the configured car (m/s²) before resistance.
        /// Runs `secs`, feeding the estimator (in the precision `T`);
        /// `accel_cmd(t)` is the acceleration asked of the configured car (m/s²)
        /// before resistance.
        fn run<T: Real>(
            &mut self,
            e: &mut LongitudinalEstimator<T>,
            secs: f64,
            accel_cmd: impl Fn(f64) -> f64,
            slip: impl Fn(f64, f64) -> f64,
        ) {
            let c = cfg_of::<T>();
            let inv_mr = T::from_f64(1.0 / (M * R));
            for _ in 0..(secs / DT).round() as usize {
                let a_cmd = accel_cmd(self.t);
                // The torque a controller would apply: the configured car's
                // feed-forward plus the true resistance (a PID's integral).
                let torque = (M * a_cmd + self.f0 + self.c2 * self.v * self.v) * R;
                let given = if torque < 0.0 {
                    torque * self.brake
                } else {
                    torque
                };
                let force = given / R - self.f0 - self.c2 * self.v * self.v;
                let lost = slip(self.t, a_cmd);
                let specific = force / self.m - lost;
                self.v += (specific - 9.81 * (self.grade)(self.t)) * DT;
                self.t += DT;
                let meas = self.v + self.sigma * self.rng.normal();
                let f = self
                    .accel_sigma
                    .map_or(f64::NAN, |s| specific + s * self.rng.normal());
                e.update(
                    &c,
                    inv_mr,
                    &LongitudinalSample {
                        dt_s: T::from_f64(DT),
                        v_mps: T::from_f64(meas),
                        torque_nm: T::from_f64(torque),
                        lateral_mps2: T::ZERO,
                        grip_mps2: T::from_f64(9.81),
                        driven_share: T::from_f64(0.585),
                        // Not flagged: the gate alone keeps slip out.
                        slipping: false,
                        slip_mps: T::from_f64(if lost > 0.0 {
                            self.slip_ratio * self.v
                        } else {
                            0.0
                        }),
                        wheels_measured: self.slip_ratio > 0.0,
                        specific_force_mps2: T::from_f64(f),
                    },
                );
            }
        }
    }

    /// Gentle driving: ±1.5 m/s² in 4 s cycles with cruise in between.
    fn pattern(t: f64) -> f64 {
        match (t % 12.0) as u32 {
            0..=3 => 1.5,
            4..=5 => 0.0,
            6..=9 => -1.5,
            _ => 0.0,
        }
    }

    fn started() -> LongitudinalEstimator<f64> {
        let mut e = LongitudinalEstimator::new();
        e.start(&cfg());
        e
    }

    #[test]
    fn default_settings_are_valid_and_bad_ones_refused() {
        assert_eq!(cfg().validate(), Ok(()));
        let mut c = cfg();
        c.mass_kg = f64::NAN;
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidVehicle));
        let mut c = cfg();
        c.filter_time_s = 0.0;
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidTiming));
        let mut c = cfg();
        c.demand_fraction = 1.5;
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidGate));
        let mut c = cfg();
        c.mass_ratio_bounds = [1.2, 2.0];
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidBounds));
        let mut c = cfg();
        c.mass_uncertainty_max = 1.0;
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidBounds));
    }

    #[test]
    fn a_car_as_configured_is_found_as_configured() {
        let mut e = started();
        let mut car = Car::new(M, 0.0, 0.0, 0.0);
        car.run(&mut e, 60.0, pattern, |_, _| 0.0);
        assert!(e.updates() > 1000, "updates {}", e.updates());
        assert!(
            (e.mass_ratio() - 1.0).abs() < 0.02,
            "k = {}",
            e.mass_ratio()
        );
        assert!(e.resistance_mps2(20.0).abs() < 0.05);
        // The uncertainty fell from its prior's.
        assert!(e.mass_uncertainty(&cfg()) < 0.15);
    }

    #[test]
    fn a_known_resistance_is_found() {
        // 200 N of rolling resistance and the default car's drag, 0.418 N/(m/s)².
        let mut e = started();
        let mut car = Car::new(M, 200.0, 0.418, 0.0);
        car.run(&mut e, 120.0, pattern, |_, _| 0.0);
        let expected = |v: f64| (200.0 + 0.418 * v * v) / M;
        for v in [15.0, 20.0, 25.0] {
            let r = e.resistance_mps2(v);
            assert!(
                (r - expected(v)).abs() < 0.03,
                "r({v}) = {r}, expected {}",
                expected(v)
            );
        }
        assert!(
            (e.mass_ratio() - 1.0).abs() < 0.03,
            "k = {}",
            e.mass_ratio()
        );
    }

    #[test]
    fn a_mass_step_is_followed_within_its_memory() {
        let mut e = started();
        let mut car = Car::new(M, 100.0, 0.418, 0.0);
        car.run(&mut e, 40.0, pattern, |_, _| 0.0);
        assert!((e.mass_ratio() - 1.0).abs() < 0.03);
        // 30 % heavier from now on (a trailer hitched).
        // 90 s of the pattern: 25 s of excited driving samples, 2.5 memories
        // (the brakings inform the brakes' gain, not the mass).
        car.m = 1.3 * M;
        car.run(&mut e, 90.0, pattern, |_, _| 0.0);
        let k = e.mass_ratio();
        assert!((k - 1.3).abs() < 0.04, "k = {k}");
        // The acceleration expected of 3 m/s² asked is the heavier car's.
        let a = e.expected_accel_mps2(&cfg(), 3.0 * M * R, 0.0);
        assert!((a - 3.0 / 1.3).abs() < 0.1, "a = {a}");
    }

    /// A 6 % climb and a 6 % descent of 20 s each, then 20 s level, in turn:
    /// the grade changes while the car accelerates and brakes.
    fn hills(t: f64) -> f64 {
        match (t % 60.0) as u32 {
            0..=19 => 0.06,
            20..=39 => -0.06,
            _ => 0.0,
        }
    }

    /// A heavier car on hills, 1.3 × the configured mass with rolling
    /// resistance and drag, speed noise of level 4: what it learns by the end
    /// of 240 s, `(k, r₀)`, with the accelerometer of noise `accel_sigma`
    /// (m/s²) or without one (`None`).
    fn on_hills(accel_sigma: Option<f64>) -> (f64, f64) {
        let mut e = started();
        let mut car = Car::new(1.3 * M, 200.0, 0.418, 0.2);
        car.grade = hills;
        car.accel_sigma = accel_sigma;
        car.run(&mut e, 240.0, pattern, |_, _| 0.0);
        (e.mass_ratio(), e.resistance_terms_mps2()[0])
    }

    #[test]
    fn with_the_accelerometer_a_grade_is_neither_mass_nor_resistance() {
        // The specific force carries `g·sin γ`: the mass and the rolling
        // resistance (200 N on 1,500 kg configured: 0.133 m/s²) are learnt as
        // on the level, whatever the grade under the car.
        let (k, r0) = on_hills(Some(0.05));
        assert!((k - 1.3).abs() < 0.039, "k = {k}");
        assert!((r0 - 200.0 / M).abs() < 0.05, "r0 = {r0}");
        // From the speed alone the grade is a resistance that changes: `r₀`
        // holds the grade under the car, and the mass ratio takes what `r₀`
        // has not yet followed.
        let (k, r0) = on_hills(None);
        assert!(
            (k - 1.3).abs() > 0.039 || (r0 - 200.0 / M).abs() > 0.05,
            "k = {k}, r0 = {r0}"
        );
    }

    #[test]
    fn speed_noise_at_four_times_level_one_leaves_the_mass_within_five_percent() {
        let mut e = started();
        let mut car = Car::new(1.3 * M, 100.0, 0.418, 0.2);
        car.run(&mut e, 120.0, pattern, |_, _| 0.0);
        let k = e.mass_ratio();
        assert!((k - 1.3).abs() < 0.065, "k = {k}");
    }

    #[test]
    fn slip_at_high_demand_during_a_mass_change_is_not_taken_for_mass() {
        let mut e = started();
        let mut car = Car::new(M, 100.0, 0.418, 0.05);
        car.run(&mut e, 30.0, pattern, |_, _| 0.0);
        // Heavier, and every 12 s a hard acceleration (4.5 m/s² asked, beyond
        // half the driven axle's grip) that spins the wheels: 2 m/s² lost.
        car.m = 1.3 * M;
        let hard = |t: f64| if t % 12.0 < 2.0 { 4.5 } else { pattern(t) };
        // 150 s: the pattern's driving left between the spins (2 s in 12, less
        // the gate's settling) holds 2.5 memories of excited samples.
        car.run(
            &mut e,
            150.0,
            hard,
            |t, _| if t % 12.0 < 2.0 { 2.0 } else { 0.0 },
        );
        let k = e.mass_ratio();
        // The spins would read as k ≈ 1.3·4.5/(4.5 − 2.6) ≫ 1.3.
        assert!((k - 1.3).abs() < 0.05, "k = {k}");
    }

    #[test]
    fn steady_cruise_does_not_wind_the_covariance_up() {
        let mut e = started();
        let mut car = Car::new(M, 100.0, 0.418, 0.2);
        car.run(&mut e, 40.0, pattern, |_, _| 0.0);
        let u = e.mass_uncertainty(&cfg());
        // Ten minutes at a steady speed: the resistance's torque only.
        car.run(&mut e, 600.0, |_| 0.0, |_, _| 0.0);
        assert!(e.mass_uncertainty(&cfg()) <= u * 1.01);
        assert!(
            (e.mass_ratio() - 1.0).abs() < 0.05,
            "k = {}",
            e.mass_ratio()
        );
    }

    #[test]
    fn non_finite_samples_are_refused() {
        let mut e = started();
        let mut car = Car::new(M, 0.0, 0.0, 0.0);
        car.run(&mut e, 30.0, pattern, |_, _| 0.0);
        let before = e;
        let inv = 1.0 / (M * R);
        for bad in [f64::NAN, f64::INFINITY] {
            let s = LongitudinalSample {
                dt_s: DT,
                v_mps: bad,
                torque_nm: 100.0,
                lateral_mps2: 0.0,
                grip_mps2: 9.81,
                driven_share: 0.6,
                slipping: false,
                slip_mps: 0.0,
                wheels_measured: false,
                specific_force_mps2: f64::NAN,
            };
            assert!(!e.update(&cfg(), inv, &s));
            assert_eq!(e.mass_ratio(), before.mass_ratio());
            assert_eq!(e.resistance_terms_mps2(), before.resistance_terms_mps2());
        }
    }

    /// The pattern of [`pattern`] with the brakes' gain `brake` and the mass
    /// `m/M = k`, in f32 as on the ECU: both are found, each within 3 %, and
    /// their uncertainties fall.
    fn learns_brakes_apart_from_mass(k: f64, brake: f64) {
        let c = cfg_of::<f32>();
        let mut e = LongitudinalEstimator::<f32>::new();
        e.start(&c);
        let mut car = Car::new(k * M, 150.0, 0.418, 0.02);
        car.brake = brake;
        car.run(&mut e, 120.0, pattern, |_, _| 0.0);
        let (k_hat, b_hat) = (e.mass_ratio(), e.brake_gain());
        assert!(
            ((k_hat as f64) - k).abs() < 0.03 * k,
            "k = {k_hat}, true {k}"
        );
        assert!(
            ((b_hat as f64) - brake).abs() < 0.03 * brake,
            "b = {b_hat}, true {brake}"
        );
        assert!(
            e.mass_uncertainty(&c) < 0.05,
            "u = {}",
            e.mass_uncertainty(&c)
        );
        assert!(
            e.brake_uncertainty(&c) < 0.05,
            "u_b = {}",
            e.brake_uncertainty(&c)
        );
        // The braking expected of the torque is the brakes' and the car's.
        let torque = -3.0 * M * R;
        let a = e.expected_accel_mps2(&c, torque as f32, 0.0) as f64;
        let r0 = e.resistance_terms_mps2()[0] as f64;
        let expected = (-3.0 * brake - r0) / k;
        assert!((a - expected).abs() < 0.1, "a = {a}, expected {expected}");
    }

    #[test]
    fn weak_brakes_are_learnt_as_brakes_not_as_a_light_car() {
        learns_brakes_apart_from_mass(1.0, 0.7);
    }

    #[test]
    fn strong_brakes_on_a_heavy_car_are_learnt_apart() {
        learns_brakes_apart_from_mass(1.3, 1.3);
        learns_brakes_apart_from_mass(0.8, 0.85);
    }

    #[test]
    fn braking_alone_leaves_the_mass_and_its_uncertainty_alone() {
        // Braking and coasting only: b/k is all there is to learn, as b.
        let c = cfg_of::<f32>();
        let mut e = LongitudinalEstimator::<f32>::new();
        e.start(&c);
        let mut car = Car::new(1.2 * M, 0.0, 0.0, 0.0);
        let brake_only = |t: f64| if t % 8.0 < 3.0 { -1.5 } else { 0.0 };
        // From 30 m/s to 7.5 m/s in six brakings.
        car.v = 30.0;
        car.run(&mut e, 48.0, brake_only, |_, _| 0.0);
        assert_eq!(e.mass_ratio(), 1.0);
        assert_eq!(e.mass_uncertainty(&c), c.mass_uncertainty_max);
        // The brakes seem 1/1.2 as strong to the configured car.
        let b = e.brake_gain();
        assert!((b - 1.0 / 1.2).abs() < 0.03, "b = {b}");
    }

    #[test]
    fn slip_below_the_demand_gate_is_not_learnt_as_mass() {
        // The road gives less than the tyres were thought to: at 2 m/s² asked
        // (under the gate's half of 0.585·g, 2.87 m/s²), the driven wheels
        // spin up and 0.6 m/s² of it is lost, a shortfall under the friction
        // check's threshold (0.6 + u·2): unflagged. Read as mass it would be
        // k = 2/1.4 = 1.43.
        let spin = |t: f64| if t % 12.0 < 4.0 { 2.0 } else { pattern(t) };
        let lost = |t: f64, _: f64| if t % 12.0 < 4.0 { 0.6 } else { 0.0 };
        // The wheel speeds measured: slip ratio 0.08 while spinning. The gate
        // refuses those samples.
        let c = cfg_of::<f32>();
        let mut e = LongitudinalEstimator::<f32>::new();
        e.start(&c);
        let mut car = Car::new(M, 100.0, 0.418, 0.02);
        car.slip_ratio = 0.08;
        car.run(&mut e, 120.0, spin, lost);
        let k = e.mass_ratio();
        assert!((k - 1.0).abs() < 0.03, "k = {k}");
        // Without wheel speeds (slip ratio 0: not measured) the same slip is
        // learnt as mass: the demand gate alone does not separate them.
        let mut e = LongitudinalEstimator::<f32>::new();
        e.start(&c);
        let mut car = Car::new(M, 100.0, 0.418, 0.02);
        car.run(&mut e, 120.0, spin, lost);
        assert!(e.mass_ratio() > 1.1, "k = {}", e.mass_ratio());
    }

    #[test]
    fn the_brakes_gain_is_bounded_and_settings_checked() {
        let mut c = cfg();
        c.brake_gain_bounds = [1.1, 1.5];
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidBounds));
        let mut c = cfg();
        c.brake_excitation_mps2 = c.brake_idle_mps2;
        assert_eq!(c.validate(), Err(LongitudinalConfigError::InvalidGate));
        // Brakes giving nothing (a failed circuit): b stops at its bound.
        let mut e = started();
        let mut car = Car::new(M, 0.0, 0.0, 0.0);
        car.brake = 0.2;
        car.run(&mut e, 60.0, pattern, |_, _| 0.0);
        assert_eq!(e.brake_gain(), 0.5);
    }

    mod props {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            /// Whatever finite (and wild) samples come, the parameters stay within
            /// their bounds, the covariance's diagonal positive and bounded, and
            /// everything finite.
            #[test]
            fn estimates_stay_within_their_bounds(
                samples in proptest::collection::vec(
                    (1e-4f64..0.1, -50.0f64..80.0, -3e4f64..3e4, -20.0f64..20.0,
                     0.0f64..20.0, 0.05f64..1.0, any::<bool>(), 0.0f64..3.0),
                    1..400),
                seed_k in 0.0f64..1.0,
            ) {
                let c = cfg();
                let mut e = started();
                // Start anywhere in the bounds.
                e.theta[0] = 0.6 + 1.2 * seed_k;
                e.inv_k = 1.0 / e.theta[0];
                let inv = 1.0 / (M * R);
                for (dt, v, t, lat, grip, share, slip, kappa) in samples {
                    let s = LongitudinalSample {
                        dt_s: dt, v_mps: v, torque_nm: t, lateral_mps2: lat,
                        grip_mps2: grip, driven_share: share, slipping: slip,
                        slip_mps: kappa, wheels_measured: kappa > 0.0,
                        specific_force_mps2: if kappa > 0.05 { t / 400.0 } else { f64::NAN },
                    };
                    e.update(&c, inv, &s);
                    let [k, r0, r2] = e.theta;
                    prop_assert!((0.6..=1.8).contains(&k), "k = {}", k);
                    prop_assert!((-1.0..=1.0).contains(&r0), "r0 = {}", r0);
                    prop_assert!((0.0..=1.0).contains(&r2), "r2 = {}", r2);
                    prop_assert!((e.inverse_mass_ratio() * k - 1.0).abs() < 1e-9);
                    let [p00, _, _, p11, _, p22] = e.p;
                    prop_assert!(p00 > 0.0 && p11 > 0.0 && p22 > 0.0);
                    let [v0, v1, v2] = c.prior_variance;
                    prop_assert!(p00 + p11 + p22 <= (v0 + v1 + v2) * (1.0 + 1e-9));
                    prop_assert!(e.p.iter().all(|x| x.is_finite()));
                    let u = e.mass_uncertainty(&c);
                    prop_assert!((0.0..=0.25).contains(&u));
                    prop_assert!(e.expected_accel_mps2(&c, t, v).is_finite());
                    let b = e.brake_gain();
                    prop_assert!((0.5..=1.5).contains(&b), "b = {}", b);
                    prop_assert!((e.inverse_brake_gain() * b - 1.0).abs() < 1e-9);
                    prop_assert!(e.brake[2] > 0.0 && e.brake[2] <= c.brake_prior_variance);
                    let ub = e.brake_uncertainty(&c);
                    prop_assert!((0.0..=c.brake_uncertainty_max).contains(&ub));
                }
            }
        }
    }
}
