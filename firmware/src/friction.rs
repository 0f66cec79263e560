//! Online friction check: an upper bound on the road's friction `μ̂` from what the
//! tyres deliver against what they are asked, run by the `control` task at 100 Hz
//! (not in the paper, which assumes the planner knows `μ`).
//!
//! # Why
//!
//! The planner's acceleration bounds (`friction_usage·μ·g`, the traction share of
//! it on the driven axle) and its velocity planner (`V_heur`, `V_max`) take the
//! configured `μ` at its word. On a road with less grip than configured (a wet
//! road, a wrong setting: the `mu-high` fault), the lateral plan still fits in the
//! tyres (`0.5·μ_planner·g` is within `μ_road·g` for `μ_planner < 2·μ_road`), but
//! the longitudinal one does not: the driven wheels spin accelerating out of curves
//! (slip ratio 0.7–0.8 measured at `μ_planner = 1.5·μ_road`), the wheels lock under
//! braking, and with them the tyres' lateral force goes: the car runs straight off
//! the road. Without wheel speeds slip cannot be seen directly; its effect can
//! (with them, *Wheel speeds* below).
//!
//! # How
//!
//! Each period, with `V` the measured speed and `T` the total wheel torque applied
//! over the period that just ended (the last command), `a_cmd = (y_d + b̂·y_b −
//! r(V))/k̂` (`y = T/(r_eff·m₀)`, its drive part `y_d ≥ 0` and braking part
//! `y_b ≤ 0`) is what the torque asks of the tyres, m/s²: the acceleration of the
//! car as estimated by [`crate::longitudinal_estimator`] (its mass ratio `k̂`, its
//! resistances `r(V)` per configured mass `m₀`, its brakes' gain `b̂`), so that a
//! heavier car, more drag or weaker brakes are not read as slip. A speed observer integrates it and is
//! pulled to the measured speed with the time constant `τ_o`
//! ([`FrictionConfig::observer_time_s`]):
//!
//! ```text
//! V̂ ← V̂ + Δt·a_cmd − (Δt/τ_o)·(V̂ − V)
//! s = LP((V̂ − V)/τ_o)          shortfall a_cmd − a_meas, low-passed, m/s²
//! ```
//!
//! (`(V̂ − V)/τ_o` is the shortfall low-passed at `τ_o`, computed from the speed,
//! not from its derivative: the speed's noise enters divided by `τ_o`, not by the
//! 10 ms period; `LP` is a first-order filter of [`FrictionConfig::filter_time_s`],
//! the same on `a_cmd`.) A wheel that grips turns (almost) all of its torque into
//! force: `a_meas ≈ a_cmd` less drag and rolling resistance (on the 17 circuits at
//! μ = 1 and 0.5 without fault, the shortfall is at most 0.42 m/s² when
//! `|a_cmd| > 1 m/s²`, at any demand). A spinning or locked wheel does not: the
//! torque goes into the wheel's own rotation (0.9–2 m/s² spinning, 2–8 m/s²
//! locked, with `μ_planner = 1.5·μ_road`). **Slip** is declared when
//! `|a_cmd| ≥` [`FrictionConfig::min_demand_mps2`], the car moves (`|V| ≥`
//! [`FrictionConfig::standstill_mps`]: a brake holding a standing car is not
//! slip) and `sign(a_cmd)·s` exceeds
//!
//! ```text
//! limit = s₀ + u·|a_cmd| + |r₀|,   s₀ = shortfall_mps2_limit (× vigilance while μ̂ < μ_nominal)
//! ```
//!
//! for [`FrictionConfig::confirm_s`]: `u` is the mass ratio's uncertainty when
//! driving
//! ([`crate::longitudinal_estimator::LongitudinalEstimator::mass_uncertainty`],
//! 0.25 before anything is learned, a few % once it is), the brakes' gain's when
//! braking ([`crate::longitudinal_estimator::LongitudinalEstimator::brake_uncertainty`],
//! 0.3 before), so slip is the
//! shortfall that grows with the demand beyond what the estimated car explains;
//! once the road has shown slip ([`FrictionConfig::vigilance`], 0.6) a relapse is
//! caught earlier.
//!
//! The friction the tyres use is computed every period,
//!
//! ```text
//! μ_used·g = sqrt((a_t/s_d)² + (V·ψ̇)²),   a_t = a_meas + r(V)/k̂,   a_meas = LP(a_cmd) − s
//! ```
//!
//! (`a_t` the tyres' force per the car's mass: its acceleration plus the
//! resistances they overcome as estimated, drag, rolling and a grade: a 6 %
//! descent's pull, 0.59 m/s², is 12 % of `μ·g` at μ 0.5, which the brakes hold
//! back and the acceleration alone does not show), with `s_d` the driven axle's share of the weight when driving
//! (`driven_load_share − (h/L)·a_meas/g`: only those wheels push, and the load
//! moves off the front axle) and 1 when braking (all four brake), `V·ψ̇` the
//! lateral acceleration; its peak over the last [`FrictionConfig::peak_window_s`]
//! is kept: the force at the tyre's peak, just before it spun or locked (a wheel
//! far past its peak gives less, and a spinning wheel braked back to the road's
//! speed gives almost none). On a slip event
//!
//! ```text
//! μ̂ = min(μ̂_before, max(μ_used,peak, μ_shown, μ_min, max_drop·μ̂_before))
//! ```
//!
//! the best `μ_used,peak` of the event counting. An event ends once the evidence
//! of slip has been gone for [`FrictionConfig::event_gap_s`] (1 s): a shortfall
//! within it continues the event (wheels that spun, braked back to the road's
//! speed, take the brake torque first; read as a second event, 0.75 s after a
//! spin on Spielberg's wet patch, it took `μ̂` from 0.6 to the floor 0.4 of a
//! 0.5 road). Too low an estimate is no safer
//! than too high a one: the planner can then brake only at `0.8·μ̂·g`, and its
//! `V_max` falls to `0.8·μ̂·g·T_H`; hence the peak, and the floor
//! [`FrictionConfig::max_drop`] per event.
//!
//! **The grip shown**: `μ_shown` is the largest `μ_used` since the last slip
//! event began (that event's own peak included) when `μ̂` is below
//! `μ_nominal` (a relapse), 0 otherwise (the first event: what the tyres used
//! before it may be another road's). A relapse lowers `μ̂` no further than the
//! road has shown it holds since: the tyres used that much on it without
//! slipping. Why: a relapse is measured on wheels that locked or spun again,
//! and its last second can hold only their sliding friction, lower than the
//! road's (a wet patch of μ 0.5 on a μ 1 road: 0.18–0.39 measured at the
//! second event, the front wheels locked for up to 1 s before the shortfall
//! confirmed it), so the second event took `μ̂` from 0.6 to the floor 0.4 on 7
//! of 17 circuits, among them three where the tyres had used 0.43–0.56 g on
//! the patch since the first event began (`docs/tuning.md`).
//!
//! **Recovery** (grip that comes back): the hold counts the periods without
//! evidence of slip, that is with the demand under `min_demand_mps2` or the
//! shortfall under [`FrictionConfig::clear_fraction`] (0.5) of the threshold (the
//! hysteresis: a shortfall between the two holds `μ̂` where it is, neither
//! lowered nor raised). After [`FrictionConfig::hold_s`]·`p` of them, `μ̂` rises
//! at [`FrictionConfig::recovery_per_s`] up to
//! [`FrictionConfig::fast_ceiling`]·`μ_nominal`, then at
//! [`FrictionConfig::creep_per_s`] up to `μ_nominal`. `p` is the patience, 1 to
//! [`FrictionConfig::patience_max`]: a slip event after `μ̂` rose (a relapse:
//! the road is still slippery) doubles it; reaching `μ_nominal` resets it.
//! Constants ([`FrictionConfig::for_car`]): hold 2 s, 0.12·`μ_nominal` per s up
//! to 0.9·`μ_nominal` (from a drop to 0.4 of it, 0.9 again 4.2 s after the hold:
//! a wet patch costs the patch), then 0.002 per s (the last 10 % is where a road
//! uniformly slipperier than configured shows itself, and a planner friction
//! 1.5 × the road's at 0.9 of it asks 1.08 of the road's, under the tyres'
//! longitudinal peak of about 1.2); patience up to 32 (hold ≤ 20 s). The
//! patience lengthens the hold only: with the rate divided by it too, a wet
//! patch with two relapses on it took 17.7 s after its exit to give back 0.9 of
//! `μ_nominal` (the hold alone 8 s of it; MoscowRaceway), 8.1 s without. The
//! simulator runs that chose them: `docs/tuning.md`.
//!
//! **Standstill**: a car standing ([`FrictionConfig::standstill_mps`], 1 m/s) for
//! [`FrictionConfig::standstill_s`] (2 s) asks nothing of the road: `μ̂` returns
//! to `μ_nominal` so that the planner plans a start with the configured friction
//! (a road still slippery shows as slip again, at low speed), unless the car
//! stands within [`FrictionConfig::standstill_clear_m`] (50 m) of its last slip
//! event: it stands on the road that slipped, and plans its start, and a swerve
//! round what stopped it, with the friction that road showed (the recovery still
//! raises `μ̂` while it stands, on evidence of nothing).
//!
//! # Wheel speeds
//!
//! When the state estimate carries the four wheel speeds
//! ([`StateEstimate::wheel_speed_mps`], as an ABS system measures them), slip is
//! also read where it happens, per wheel ([`FrictionEstimator::read_sensors`]):
//! each wheel's speed `ω·r` against the ground's under it, `v_x ∓ ψ̇·t/2` (left,
//! right), the front wheels' times `1 + δ²/2` (rolling along their steered
//! heading). A driven (front) wheel faster than that by more than
//! `κ_w·|v_x| + d₀` spins; any wheel slower by as much locks (`κ_w` =
//! [`FrictionConfig::wheel_slip_ratio`], 0.15: the default tyre gives its peak
//! force at a slip ratio of about 0.1, and on the 17 circuits without fault
//! the largest measured is under 0.09; `d₀` =
//! [`FrictionConfig::wheel_slip_margin_mps`], 1 m/s: at noise level 4 a wheel's
//! difference from the ground's carries 0.12 m/s of the wheel's noise and
//! 0.2 m/s of the speed's, so 1 m/s is over 4 of their σ; the ground-speed
//! approximations err most at low speed). A driven wheel that spins, or two
//! wheels or more that lock, for [`FrictionConfig::wheel_confirm_s`] (30 ms;
//! the car moving) are slip whatever the demand: the event lowers `μ̂` to the
//! friction used at its peak, as below. One wheel locked alone is not: on a
//! dry road it is what the inside wheel, unloaded in a bend, does under
//! braking, and the anti-lock limit it triggers ends it (`docs/tuning.md`,
//! *Wheel speeds*). Their largest difference from the ground's `|ω·r − V|`
//! goes to the estimator of the car, whose samples count only under
//! `0.06·|V|` ([`crate::longitudinal_estimator`]: a wheel slipping too little
//! to flag is not learnt as mass; the default tyre gives 0.8 of its peak force
//! at 0.06 at μ 1, its linear range). A shortfall while every wheel has been
//! within that range for as long as the shortfall's filters remember
//! (`τ_o + τ_f`, 0.6 s) is not slip: a tyre gives the force its torque asks
//! until it leaves its linear range (a wheel whose tyre cannot turns the torque
//! into its own rotation, and leaves it within a period or two), so the
//! shortfall is the estimated car's error (a grade the resistance has not learnt
//! yet, the mass), which a climb read as slip (μ̂ from 0.5 to 0.3 on Sepang, a
//! 6 % grade, the car then off the road for a steering limit of 0.3). Wheels
//! out of the range within that time (a lock the anti-lock limit ended) leave
//! the shortfall its say. Without wheel speeds (not
//! finite), slip is read from the shortfall alone.
//!
//! The time the wheels spun or locked is kept between interventions and
//! forgotten at [`WHEEL_FORGET`] (a tenth of the rate it grows): the traction
//! control and the anti-lock limit below end a spin within a period or two,
//! and their repeating (three periods within about 0.3 s) is the event.
//!
//! The control task limits the torque by them too
//! ([`crate::tasks::ControlTask::car_model`]): while a driven wheel spins, half
//! the traction grip (a traction control); while a wheel locks, half the
//! braking grip (an anti-lock system), in the same period.
//!
//! # The accelerometer
//!
//! When the state estimate carries the accelerometer's specific force along
//! the car ([`StateEstimate::specific_force_x_mps2`] `f`, as an IMU measures
//! it: the acceleration plus `g·sin γ` on a grade `γ`), the observer integrates
//! `a_cmd − a_f` instead of comparing `V̂` with the speed:
//!
//! ```text
//! a_f = f + v_y·ψ̇                     (v̇_x + g·sin γ: the body frame turns)
//! V̂ − V ← (1 − Δt/τ_o)·(V̂ − V + Δt·(a_cmd − a_f))
//! ```
//!
//! (`f` alone falls short of `a_cmd` in a bend: the steered front's lateral
//! force has a component `F_yf·sin δ` against the car's `x` axis, about
//! `(l_r/L)·a_y·δ`, 0.4–0.5 m/s² in a hairpin at `a_y` 4 m/s², which read as
//! slip; `v_y·ψ̇`, with `v_y ≈ l_r·ψ̇` at the centre of gravity, gives it back,
//! as the speed does.)
//!
//! the same filter of the same shortfall, but of the force the tyres and the
//! air give per unit mass rather than of the acceleration: a grade is no
//! longer a shortfall (a 6 % climb is 0.59 m/s² of `g·sin γ` the speed alone
//! shows as missing acceleration), and the longitudinal estimator learns the
//! mass and the resistances on `f` too, so `r₀` holds the rolling resistance,
//! not the grade under the car. The speed's noise no longer enters the
//! shortfall; the accelerometer's (white, a few 0.01 m/s²) enters low-passed.
//! `a_meas` in the friction used is then `LP(a_f)`: the tyres' force with the
//! grade's share in it. A change between the two (the accelerometer lost or
//! found) restarts the observer, as a gap does.
//!
//! # Use
//!
//! The `plan` task plans with `min(μ_configured, μ̂)`
//! ([`crate::tasks::PlanTask::set_friction_limit`], given `μ̂` with the state
//! estimate at its release), so the acceleration bounds, the friction ellipse,
//! `V_heur` and `V_max` all shrink to the road measured.
//!
//! # Cost
//!
//! Per period about 60 floating-point operations and two divisions; the square
//! root only on a slip; the wheel speeds about 30 operations, no division; plus
//! the estimator of the mass, resistances and brakes (about 100 operations, two
//! divisions, one square root). Deterministic, no allocation, no loop, no branch
//! on data but the slip test and the estimator's gate. Its static bound with the
//! rest of the control job: `host-sim wcet` (`control_job`).

use crate::longitudinal_estimator::{
    LongitudinalConfig, LongitudinalEstimator, LongitudinalSample,
};
use crate::state_estimate::StateEstimate;
use crate::timing::CONTROL_PERIOD_US;
use crate::Real;
use qp::real::{all_finite, larger, smaller};

/// Control periods of commanded torque the friction check keeps (160 ms at
/// 100 Hz): the oldest state estimate it can pair with the torque that moved the
/// car.
pub const TORQUE_HISTORY: usize = 16;

/// Rate at which the time the wheels spun or locked is forgotten, per s of
/// time without (module docs, *Wheel speeds*).
pub const WHEEL_FORGET: f32 = 0.1;

/// Settings of the friction check (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrictionConfig<T> {
    /// Vehicle mass `m`, kg, > 0.
    pub mass_kg: T,
    /// Effective wheel radius `r_eff`, m, > 0.
    pub wheel_radius_m: T,
    /// Static share of the weight on the driven wheels, in `(0, 1]` (front-wheel
    /// drive: `l_r/(l_f + l_r)`).
    pub driven_load_share: T,
    /// Static share of the weight on the front axle, in `(0, 1)` (the brakes'
    /// anti-lock limit, [`crate::tasks::ControlTask::car_model`];
    /// [`FrictionConfig::for_car`]: front-wheel drive, `driven_load_share`).
    pub front_load_share: T,
    /// Height of the centre of gravity over the track, `h/t`, ≥ 0: cornering at
    /// `a_y` takes about `2·(a_y/g)·(h/t)` of the driven axle's load off its inside
    /// wheel, which gets half the torque (the traction limit,
    /// [`crate::tasks::ControlTask::car_model`]; [`FrictionConfig::for_car`]: 0).
    pub cg_height_over_track: T,
    /// Wheelbase `L`, m, ≥ 0: the kinematic lateral acceleration the steering asks,
    /// `V²·tan δ/L`, against which the control task checks that the front tyres
    /// still grip ([`crate::tasks::ControlTask::front_saturated`]); 0: no such check
    /// ([`FrictionConfig::for_car`]: 0).
    pub wheelbase_m: T,
    /// Height of the centre of gravity over the wheelbase, `h/L`, ≥ 0: driving at
    /// `a` moves `h/L · a/g` of the weight off the front axle.
    pub cg_height_over_wheelbase: T,
    /// The friction the planner is configured with: the estimate's start and
    /// ceiling, dimensionless, > 0.
    pub mu_nominal: T,
    /// Time constant `τ_o` of the speed observer, s, > 0 (module docs).
    pub observer_time_s: T,
    /// Time constant of the low-pass filters on `a_cmd` and the shortfall, s, > 0.
    pub filter_time_s: T,
    /// Smallest `|a_cmd|` (filtered) at which slip is looked for, m/s², > 0.
    pub min_demand_mps2: T,
    /// Shortfall over which slip is declared, m/s², > 0 (plus `u·|a_cmd|`, module
    /// docs).
    pub shortfall_mps2_limit: T,
    /// Factor on `shortfall_mps2_limit` while `μ̂` is below `mu_nominal` (the
    /// road has shown slip: a relapse is caught earlier), in `(0, 1]`.
    pub vigilance: T,
    /// Time the shortfall must last before slip is declared, s, ≥ 0.
    pub confirm_s: T,
    /// Window over which the largest friction used is kept, s, > 0.
    pub peak_window_s: T,
    /// Smallest factor by which one slip event lowers `μ̂`, in `(0, 1]`.
    pub max_drop: T,
    /// Time without evidence of slip before `μ̂` starts to recover, s, ≥ 0 (at
    /// patience 1; module docs).
    pub hold_s: T,
    /// Largest hold, s, ≥ `hold_s`.
    pub hold_max_s: T,
    /// Recovery rate of `μ̂` up to `fast_ceiling·mu_nominal`, 1/s, ≥ 0.
    pub recovery_per_s: T,
    /// Fraction of `mu_nominal` up to which `μ̂` recovers at `recovery_per_s`,
    /// in `[0, 1]`; above it at `creep_per_s`.
    pub fast_ceiling: T,
    /// Recovery rate above `fast_ceiling·mu_nominal`, 1/s, ≥ 0.
    pub creep_per_s: T,
    /// Largest patience (module docs: each relapse doubles it), ≥ 1.
    pub patience_max: T,
    /// Time without evidence of slip that ends a slip event, s, ≥ 0: a slip
    /// within it continues the event (module docs).
    pub event_gap_s: T,
    /// Evidence of slip is gone when the shortfall is under this fraction of the
    /// slip threshold, in `[0, 1]` (the hysteresis).
    pub clear_fraction: T,
    /// Lowest estimate, dimensionless, > 0.
    pub mu_min: T,
    /// Largest time between two estimates the observer accepts, s, > 0 (a longer
    /// gap restarts it).
    pub max_gap_s: T,
    /// Speed under which the car stands, m/s, ≥ 0.
    pub standstill_mps: T,
    /// Time standing after which `μ̂` returns to `mu_nominal`, s, ≥ 0.
    pub standstill_s: T,
    /// Distance from the last slip event within which a standing car keeps its
    /// `μ̂` (it stands on the road that slipped), m, ≥ 0.
    pub standstill_clear_m: T,
    /// Half the track `t/2`, m, ≥ 0: a wheel's ground speed is `v_x ∓ ψ̇·t/2`
    /// (left, right; [`FrictionConfig::for_car`]: 0).
    pub half_track_m: T,
    /// Slip ratio past which a wheel spins (a driven one) or locks (any), in
    /// `(0, 1)`: past the tyre's peak (module docs, *Wheel speeds*).
    pub wheel_slip_ratio: T,
    /// Difference of a wheel's speed from its ground speed under which it
    /// neither spins nor locks, whatever the speed, m/s, ≥ 0 (the sensors' noise
    /// and the ground speed's approximations at low speed).
    pub wheel_slip_margin_mps: T,
    /// Time a wheel must spin or lock before it is a slip event, s, ≥ 0 (the
    /// traction control and anti-lock limit act at once; module docs, *Wheel
    /// speeds*).
    pub wheel_confirm_s: T,
    /// The estimator of the car's mass and resistances
    /// ([`crate::longitudinal_estimator`]).
    pub longitudinal: LongitudinalConfig<T>,
}

impl<T: Real> FrictionConfig<T> {
    /// The settings for a car of mass `mass_kg` (kg), wheel radius
    /// `wheel_radius_m` (m), driven-axle load share `driven_load_share`, centre of
    /// gravity height over wheelbase `cg_height_over_wheelbase`, planned with the
    /// friction `mu_nominal`:
    ///
    /// * observer 0.4 s, filters 0.2 s: the shortfall's noise is the speed's
    ///   over 0.4 s, not its derivative's over 10 ms (at four times the level-1
    ///   noise, σ = 0.2 m/s, about 0.06 m/s² against the 0.6 m/s² threshold);
    /// * slip looked for above 1 m/s² of demand, declared at a shortfall of
    ///   0.6 m/s² (1.4× the largest measured without slip: 0.42 m/s², the 17
    ///   circuits at μ = 1 and 0.5) held for 0.05 s;
    /// * the friction used kept over 1 s (the tyre's peak before it spun or locked);
    ///   one event lowers `μ̂` by at most 40 %, and ends after 1 s without
    ///   evidence of slip;
    /// * the recovery, the vigilance and the standstill rule of the module docs
    ///   (their constants stated and justified there); `μ̂ ≥ 0.4·mu_nominal`
    ///   (the configured friction is
    ///   trusted within a factor 2.5: a road with less grip than that is not one
    ///   this car was set up for, and a planner that cannot brake is no safer).
    pub fn for_car(
        mass_kg: T,
        wheel_radius_m: T,
        driven_load_share: T,
        cg_height_over_wheelbase: T,
        mu_nominal: T,
    ) -> Self {
        Self {
            mass_kg,
            wheel_radius_m,
            driven_load_share,
            front_load_share: driven_load_share,
            cg_height_over_track: T::ZERO,
            wheelbase_m: T::ZERO,
            cg_height_over_wheelbase,
            mu_nominal,
            observer_time_s: T::lit(0.4),
            filter_time_s: T::lit(0.2),
            min_demand_mps2: T::ONE,
            shortfall_mps2_limit: T::lit(0.6),
            vigilance: T::lit(0.6),
            confirm_s: T::lit(0.05),
            peak_window_s: T::ONE,
            max_drop: T::lit(0.6),
            hold_s: T::lit(2.0),
            hold_max_s: T::lit(20.0),
            recovery_per_s: T::lit(0.12) * mu_nominal,
            fast_ceiling: T::lit(0.9),
            creep_per_s: T::lit(0.002),
            patience_max: T::lit(32.0),
            event_gap_s: T::ONE,
            clear_fraction: T::HALF,
            mu_min: T::lit(0.4) * mu_nominal,
            max_gap_s: T::lit(0.1),
            standstill_mps: T::ONE,
            standstill_s: T::TWO,
            standstill_clear_m: T::lit(50.0),
            half_track_m: T::ZERO,
            wheel_slip_ratio: T::lit(0.15),
            wheel_slip_margin_mps: T::ONE,
            wheel_confirm_s: T::lit(0.03),
            longitudinal: LongitudinalConfig::for_car(mass_kg, wheel_radius_m),
        }
    }

    /// True when every field is in its range.
    pub fn is_valid(&self) -> bool {
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        let nonneg = |x: T| x.is_finite() && x >= T::ZERO;
        pos(self.mass_kg)
            && pos(self.wheel_radius_m)
            && pos(self.driven_load_share)
            && self.driven_load_share <= T::ONE
            && pos(self.front_load_share)
            && self.front_load_share < T::ONE
            && nonneg(self.cg_height_over_wheelbase)
            && nonneg(self.cg_height_over_track)
            && nonneg(self.wheelbase_m)
            && pos(self.mu_nominal)
            && pos(self.observer_time_s)
            && pos(self.filter_time_s)
            && pos(self.min_demand_mps2)
            && pos(self.shortfall_mps2_limit)
            && pos(self.vigilance)
            && self.vigilance <= T::ONE
            && nonneg(self.confirm_s)
            && pos(self.peak_window_s)
            && pos(self.max_drop)
            && self.max_drop <= T::ONE
            && nonneg(self.hold_s)
            && self.hold_max_s.is_finite()
            && self.hold_max_s >= self.hold_s
            && nonneg(self.recovery_per_s)
            && nonneg(self.fast_ceiling)
            && self.fast_ceiling <= T::ONE
            && nonneg(self.creep_per_s)
            && self.patience_max.is_finite()
            && self.patience_max >= T::ONE
            && nonneg(self.event_gap_s)
            && nonneg(self.clear_fraction)
            && self.clear_fraction <= T::ONE
            && pos(self.mu_min)
            && pos(self.max_gap_s)
            && nonneg(self.standstill_mps)
            && nonneg(self.standstill_s)
            && nonneg(self.standstill_clear_m)
            && nonneg(self.half_track_m)
            && pos(self.wheel_slip_ratio)
            && self.wheel_slip_ratio < T::ONE
            && nonneg(self.wheel_slip_margin_mps)
            && nonneg(self.wheel_confirm_s)
            && self.longitudinal.validate().is_ok()
            && self.longitudinal.mass_kg == self.mass_kg
            && self.longitudinal.wheel_radius_m == self.wheel_radius_m
    }
}

/// The friction check's memory and its estimate (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrictionEstimator<T> {
    /// Stamp of the last estimate used, µs (`None`: differentiation restarts).
    prev_stamp_us: Option<u64>,
    /// The total wheel torques commanded at the last [`TORQUE_HISTORY`] control
    /// periods, N·m (a ring; `head` is the next to write).
    torques: [T; TORQUE_HISTORY],
    /// Next slot of `torques` to write.
    head: usize,
    /// The observer's speed `V̂`, m/s; `V̂ − V` while it reads the
    /// accelerometer (`accel_mode`).
    v_hat_mps: T,
    /// The observer integrates the specific force (module docs, *The
    /// accelerometer*) rather than comparing with the speed.
    accel_mode: bool,
    /// The last estimate's specific force along `x` plus `v_y·ψ̇`, m/s² (NaN:
    /// not measured; module docs, *The accelerometer*).
    specific_force_mps2: T,
    /// `a_cmd` low-passed at `τ_o` (as the observer low-passes the shortfall),
    /// then at `τ_f`, m/s².
    accel_cmd_mps2: [T; 2],
    /// Filtered shortfall `a_cmd − a_meas`, m/s².
    shortfall_mps2: T,
    /// Time the shortfall has been over its threshold, s.
    shortfall_s: T,
    /// Largest `(μ_obs·g)²` of the last `peak_window_s`, m²/s⁴, and its age, s.
    peak: (T, T),
    /// Largest `(μ_obs·g)²` since the last slip event began (its own peak
    /// included), m²/s⁴: the grip the road has shown since (module docs).
    shown: T,
    /// True while a slip event is under way.
    slipping: bool,
    /// `μ̂` before the slip event under way.
    mu_before: T,
    /// Time without evidence of slip since the last slip, s (+∞ before the
    /// first).
    since_slip_s: T,
    /// The estimate `μ̂`.
    mu: T,
    /// Slip events (wrapping).
    events: u32,
    /// Patience: the hold is `hold_s·patience` (module docs), in
    /// `[1, patience_max]`.
    patience: T,
    /// True when `μ̂` has risen since the last slip event.
    rose: bool,
    /// Time the car has stood, s.
    standing_s: T,
    /// Distance travelled since the last slip event, m (`+∞` before the first;
    /// it stops counting at [`FrictionConfig::standstill_clear_m`]).
    since_slip_m: T,
    /// The car's mass and resistances.
    longitudinal: LongitudinalEstimator<T>,
    /// The wheels at the last estimate (module docs, *Wheel speeds*): a driven
    /// wheel spins, a wheel locks, and the largest `|ω·r − V|`, m/s (0 when not
    /// measured).
    wheel_spin: bool,
    wheel_lock: bool,
    /// Two wheels or more lock (a slip event; one alone may be a wheel
    /// unloaded by the load transfer in a bend).
    wheels_lock: bool,
    wheel_slip_mps: T,
    /// The last estimate carried the four wheel speeds (all finite).
    wheels_measured: bool,
    /// Time a wheel has spun or locked, s.
    wheel_s: T,
    /// Time every wheel has been measured within its tyre's linear range, s.
    grip_s: T,
    /// `1/(m·r_eff)` (1/(kg·m)), `1/τ_o` and `1/τ_f` (1/s), set by
    /// [`FrictionEstimator::start`].
    inverses: [T; 3],
}

impl<T: Real> Default for FrictionEstimator<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> FrictionEstimator<T> {
    /// No evidence yet: `μ̂ = +∞` (a valid `const` initialiser; the control task
    /// starts it at [`FrictionConfig::mu_nominal`] with [`FrictionEstimator::start`]).
    pub const fn new() -> Self {
        Self {
            prev_stamp_us: None,
            torques: [T::ZERO; TORQUE_HISTORY],
            head: 0,
            v_hat_mps: T::ZERO,
            accel_mode: false,
            specific_force_mps2: T::NAN,
            accel_cmd_mps2: [T::ZERO; 2],
            shortfall_mps2: T::ZERO,
            shortfall_s: T::ZERO,
            peak: (T::ZERO, T::ZERO),
            shown: T::ZERO,
            slipping: false,
            mu_before: T::INFINITY,
            since_slip_s: T::INFINITY,
            mu: T::INFINITY,
            events: 0,
            patience: T::ONE,
            rose: false,
            standing_s: T::ZERO,
            since_slip_m: T::INFINITY,
            longitudinal: LongitudinalEstimator::new(),
            wheel_spin: false,
            wheel_lock: false,
            wheels_lock: false,
            wheel_slip_mps: T::ZERO,
            wheels_measured: false,
            wheel_s: T::ZERO,
            grip_s: T::ZERO,
            inverses: [T::ZERO; 3],
        }
    }

    /// Forgets everything and starts at `μ̂ = cfg.mu_nominal` (`cfg` valid:
    /// [`FrictionConfig::is_valid`]; [`FrictionEstimator::update`] must be given
    /// the same settings).
    pub fn start(&mut self, cfg: &FrictionConfig<T>) {
        *self = Self::new();
        self.mu = cfg.mu_nominal;
        self.longitudinal.start(&cfg.longitudinal);
        self.inverses = [
            T::ONE / (cfg.mass_kg * cfg.wheel_radius_m),
            T::ONE / cfg.observer_time_s,
            T::ONE / cfg.filter_time_s,
        ];
    }

    /// The estimate `μ̂`, dimensionless: an upper bound on the road's friction
    /// from the slips seen (`+∞` when there is none).
    pub fn mu(&self) -> T {
        self.mu
    }

    /// Slip events seen so far (wrapping).
    pub fn events(&self) -> u32 {
        self.events
    }

    /// True while a slip event is under way.
    pub fn slipping(&self) -> bool {
        self.slipping
    }

    /// The filtered shortfall of the measured acceleration on the commanded one,
    /// `a_cmd − a_meas`, m/s² (module docs).
    pub fn shortfall_mps2(&self) -> T {
        self.shortfall_mps2
    }

    /// The estimate of the car's mass and resistances
    /// ([`crate::longitudinal_estimator`]).
    pub fn longitudinal(&self) -> &LongitudinalEstimator<T> {
        &self.longitudinal
    }

    /// True when a driven (front) wheel spun at the last estimate (module docs,
    /// *Wheel speeds*).
    pub fn wheel_spinning(&self) -> bool {
        self.wheel_spin
    }

    /// True when a wheel locked at the last estimate (module docs, *Wheel
    /// speeds*): the anti-lock limit (a slip event needs two).
    pub fn wheel_locking(&self) -> bool {
        self.wheel_lock
    }

    /// The largest difference of a wheel's speed from its ground speed at the
    /// last estimate, m/s (0 when the wheel speeds are not measured).
    pub fn wheel_slip_mps(&self) -> T {
        self.wheel_slip_mps
    }

    /// Reads the accelerometer of `est` (module docs, *The accelerometer*) and
    /// its wheel speeds (module docs, *Wheel speeds*): each
    /// wheel's speed against its ground speed, `v_x ∓ ψ̇·t/2` (left, right),
    /// the front ones' times `1 + δ²/2` (they roll along their steered heading,
    /// `1/cos δ` of the car's speed to second order). A driven front wheel
    /// spins, or a wheel locks, when it differs from its ground speed by more
    /// than `wheel_slip_ratio·|v_x| + wheel_slip_margin_mps`. Non-finite wheel
    /// speeds (not measured): neither, and no difference. No division, no loop.
    // Inlined into the control task's one call.
    #[inline(always)]
    pub fn read_sensors(&mut self, cfg: &FrictionConfig<T>, est: &StateEstimate<T>) {
        // The body frame turns: `v̇_x = f + v_y·ψ̇` on the level (module docs).
        self.specific_force_mps2 = est.specific_force_x_mps2 + est.vy_mps * est.yaw_rate_radps;
        let [fl, fr, rl, rr] = est.wheel_speed_mps;
        let vx = est.vx_mps;
        let side = est.yaw_rate_radps * cfg.half_track_m;
        let d = est.delta_rad;
        let (left, right) = (vx - side, vx + side);
        let steer = T::ONE + T::HALF * d * d;
        let diff = [fl - left * steer, fr - right * steer, rl - left, rr - right];
        let ok = all_finite(diff);
        let limit = cfg.wheel_slip_ratio * vx.abs() + cfg.wheel_slip_margin_mps;
        let lock = -limit;
        // One comparison per wheel and bound: a driven wheel over the limit
        // spins; the count of wheels under it, one or more, lock.
        let spin = u8::from(diff[0] > limit) | u8::from(diff[1] > limit);
        let locked = u8::from(diff[0] < lock)
            + u8::from(diff[1] < lock)
            + u8::from(diff[2] < lock)
            + u8::from(diff[3] < lock);
        self.wheel_spin = ok && spin != 0;
        self.wheel_lock = ok && locked >= 1;
        self.wheels_lock = ok && locked >= 2;
        let high = larger(
            larger(diff[0].abs(), diff[1].abs()),
            larger(diff[2].abs(), diff[3].abs()),
        );
        self.wheel_slip_mps = if ok { high } else { T::ZERO };
        self.wheels_measured = ok;
    }

    /// The patience of the recovery (module docs), in `[1, patience_max]`.
    pub fn patience(&self) -> T {
        self.patience
    }

    /// One period, after a successful low-level step at `now_us` (µs): the
    /// estimate's stamp `stamp_us` (µs, at most `now_us`), the measured speed
    /// `v_mps` (m/s) and yaw rate `yaw_rate_radps` (rad/s), then `torque_nm`
    /// (N·m), the total wheel torque commanded now and applied for the next
    /// period. The speed measured at the stamp is compared with the torque applied
    /// over the period before the stamp (an estimate `d` old answers the torque
    /// commanded `d` + one period ago: kept for [`TORQUE_HISTORY`] periods; an
    /// older estimate is not used). A stamp that does not advance (a held estimate)
    /// adds nothing; a gap over `max_gap_s` restarts the observer. Returns `μ̂`.
    // Inlined into the control task's one call: its bound is smaller without the
    // call's register saves and second fetch of the caller's lines.
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &FrictionConfig<T>,
        now_us: u64,
        stamp_us: u64,
        v_mps: T,
        yaw_rate_radps: T,
        torque_nm: T,
    ) -> T {
        if !all_finite([v_mps, yaw_rate_radps]) {
            self.forget(torque_nm);
            return self.mu;
        }
        // Periods between the stamp and now (u32 division: one instruction).
        let age = (now_us.saturating_sub(stamp_us)).min(u64::from(u32::MAX)) as u32;
        let back = (age / CONTROL_PERIOD_US as u32) as usize + 1;
        match self.prev_stamp_us {
            Some(stamp) if stamp_us > stamp => {
                // u32 → f32 is one instruction on the ECU (u64 → f32 a call).
                let us = (stamp_us - stamp).min(u64::from(u32::MAX)) as u32;
                let dt = T::lit(us as f32) * T::lit(1.0e-6);
                // The accelerometer lost or found: the observer restarts.
                let accel = self.specific_force_mps2.is_finite();
                if dt <= cfg.max_gap_s && back <= TORQUE_HISTORY && accel == self.accel_mode {
                    let i = (self.head + TORQUE_HISTORY - back) % TORQUE_HISTORY;
                    let applied = self.torques[i];
                    self.step(cfg, v_mps, yaw_rate_radps, applied, dt);
                } else {
                    self.restart(v_mps);
                }
                self.prev_stamp_us = Some(stamp_us);
            }
            Some(_) => {}
            None => {
                self.restart(v_mps);
                self.prev_stamp_us = Some(stamp_us);
            }
        }
        self.record(torque_nm);
        self.mu
    }

    /// A period without a valid estimate (the safe actuation, of total torque
    /// `torque_nm`, N·m): the torque is recorded, and the next
    /// [`FrictionEstimator::update`] starts the observer afresh. The estimate is
    /// kept.
    pub fn forget(&mut self, torque_nm: T) {
        self.prev_stamp_us = None;
        self.record(torque_nm);
    }

    /// Records the torque commanded this period (non-finite: 0).
    fn record(&mut self, torque_nm: T) {
        self.torques[self.head] = if torque_nm.is_finite() {
            torque_nm
        } else {
            T::ZERO
        };
        self.head = (self.head + 1) % TORQUE_HISTORY;
    }

    /// The observer and the filters restart from the speed `v` (not the estimate).
    fn restart(&mut self, v: T) {
        self.accel_mode = self.specific_force_mps2.is_finite();
        self.v_hat_mps = if self.accel_mode { T::ZERO } else { v };
        self.accel_cmd_mps2 = [T::ZERO; 2];
        self.shortfall_mps2 = T::ZERO;
        self.shortfall_s = T::ZERO;
        self.peak = (T::ZERO, T::ZERO);
        self.grip_s = T::ZERO;
        self.longitudinal.restart();
    }

    /// The observer, the slip test and the estimate over one step of `dt` s.
    fn step(&mut self, cfg: &FrictionConfig<T>, v: T, yaw_rate: T, torque_nm: T, dt: T) {
        let [inv_mr, inv_tau_o, inv_tau_f] = self.inverses;
        // What the torque gives the car as estimated (its mass and resistances),
        // tyres gripping.
        let lon = &self.longitudinal;
        // The resistances at `v` per configured mass, m/s²: in the demand, and
        // in the force the tyres deliver below.
        let resistance = lon.resistance_mps2(v);
        let a_cmd = (lon.applied_mps2(inv_mr, torque_nm) - resistance) * lon.inverse_mass_ratio();
        // V̂ integrates the commanded acceleration and is pulled to the measured
        // speed in `observer_time_s`: (V̂ − V)/τ_o is the shortfall low-passed at
        // τ_o, from the speed itself, not its noisy derivative. Forward Euler
        // (gains at most 1).
        // Predicted to now with the torque applied since the last estimate, then
        // corrected: e_j = (1 − k_o)·e_{j−1} + Δt·(a_cmd − a_meas) exactly, the
        // recursion of the first filter on a_cmd below.
        let k_o = smaller(dt * inv_tau_o, T::ONE);
        // With the accelerometer (module docs), `v_hat_mps` holds `V̂ − V`, and
        // its measured change is `Δt·f`.
        let f = self.specific_force_mps2;
        let (e, anchor) = if self.accel_mode {
            (self.v_hat_mps + dt * (a_cmd - f), T::ZERO)
        } else {
            (self.v_hat_mps + dt * a_cmd - v, v)
        };
        self.v_hat_mps = anchor + (T::ONE - k_o) * e;
        let s_raw = e * inv_tau_o;
        // a_cmd through the same two filters as the shortfall, so that
        // a_cmd − shortfall is the measured acceleration without a lag between them.
        let [c1, c2] = self.accel_cmd_mps2;
        let c1 = c1 + k_o * (a_cmd - c1);
        let k = smaller(dt * inv_tau_f, T::ONE);
        let cmd = c2 + k * (c1 - c2);
        self.accel_cmd_mps2 = [c1, cmd];
        self.shortfall_mps2 += k * (s_raw - self.shortfall_mps2);
        let demand = cmd.abs();
        let shortfall = self.shortfall_mps2 * cmd.signum0();
        // What the tyres deliver, (μ_obs·g)², kept at its peak over the window:
        // the car's acceleration plus the resistances the tyres overcome as
        // estimated (drag and rolling resistance; a climb, or a descent's pull
        // the brakes hold back), per the car's mass.
        let a_meas = cmd - self.shortfall_mps2;
        let a_force = a_meas + resistance * lon.inverse_mass_ratio();
        let a_tyre = if cmd > T::ZERO {
            // Driving: the driven axle alone, its load lowered by the transfer.
            let share = cfg.driven_load_share
                - cfg.cg_height_over_wheelbase * larger(a_meas, T::ZERO) * T::lit(1.0 / crate::G);
            a_force / larger(share, T::lit(0.1))
        } else {
            a_force
        };
        let ay = v * yaw_rate;
        let used = a_tyre * a_tyre + ay * ay;
        self.peak.1 += dt;
        if used >= self.peak.0 || self.peak.1 > cfg.peak_window_s {
            self.peak = (used, T::ZERO);
        }
        if used > self.shown {
            self.shown = used;
        }
        // The threshold grows with the demand by the mass ratio's uncertainty
        // (driving) or the brakes' gain's (braking): a shortfall a car as heavy,
        // or brakes as weak, as the estimate allows would show is not slip.
        let base = if self.mu < cfg.mu_nominal {
            cfg.shortfall_mps2_limit * cfg.vigilance
        } else {
            cfg.shortfall_mps2_limit
        };
        let u = self
            .longitudinal
            .uncertainty(&cfg.longitudinal, cmd < T::ZERO);
        let limit = base + u * demand + self.longitudinal.resistance_terms_mps2()[0].abs();
        // Standing, a brake holds the car without decelerating it: no slip. A
        // driven wheel that spins, or two wheels that lock, is slip whatever the
        // shortfall.
        let moving = v.abs() >= cfg.standstill_mps;
        let wheel = (self.wheel_spin || self.wheels_lock) && moving;
        // Every wheel measured within its tyre's linear range for as long as the
        // shortfall's filters remember (`τ_o + τ_f`): the tyres gave the force
        // the torque asked (a wheel that cannot turns its torque into its own
        // rotation and leaves that range within a period or two), so the
        // shortfall is the estimated car's error (a grade, its mass), not slip
        // (module docs, *Wheel speeds*). A wheel out of the range in that time
        // (a lock the anti-lock limit ended) leaves the shortfall its say.
        let in_range = self.wheels_measured
            && self.wheel_slip_mps <= cfg.longitudinal.max_slip_ratio * v.abs();
        self.grip_s = if in_range { self.grip_s + dt } else { T::ZERO };
        let gripping = self.grip_s >= cfg.observer_time_s + cfg.filter_time_s;
        // The wheels' time is kept between interventions, forgotten at a tenth
        // of the rate it grows: the traction control and the anti-lock limit
        // end a spin or a lock within a period or two, and their repeating is
        // the evidence (module docs, *Wheel speeds*).
        self.wheel_s = if wheel {
            self.wheel_s + dt
        } else {
            larger(self.wheel_s - dt * T::lit(WHEEL_FORGET), T::ZERO)
        };
        let short =
            wheel || (demand >= cfg.min_demand_mps2 && shortfall > limit && moving && !gripping);
        self.shortfall_s = if short {
            self.shortfall_s + dt
        } else {
            T::ZERO
        };
        // A driven wheel that spins or two wheels that lock are measured, not
        // inferred: a shorter confirmation than the shortfall's.
        if (wheel && self.wheel_s >= cfg.wheel_confirm_s)
            || (short && self.shortfall_s >= cfg.confirm_s)
        {
            self.slip(cfg);
        } else {
            self.slipping = false;
            // Evidence is gone when the demand is under the one slip is looked for
            // at, or the shortfall under the clear level.
            let clear =
                !wheel && (demand < cfg.min_demand_mps2 || shortfall <= cfg.clear_fraction * limit);
            self.recover(cfg, clear, dt);
        }
        self.standstill(cfg, v, dt);
        let sample = LongitudinalSample {
            dt_s: dt,
            v_mps: v,
            torque_nm,
            lateral_mps2: ay,
            grip_mps2: self.mu * T::lit(crate::G),
            driven_share: cfg.driven_load_share,
            slipping: self.slipping || short,
            slip_mps: self.wheel_slip_mps,
            wheels_measured: self.wheels_measured,
            specific_force_mps2: if self.accel_mode { f } else { T::NAN },
        };
        self.longitudinal.update(&cfg.longitudinal, inv_mr, &sample);
    }

    /// Slip confirmed this period: a new event (or the continuation of the
    /// last one, module docs) lowers `μ̂` to the grip the tyres showed.
    fn slip(&mut self, cfg: &FrictionConfig<T>) {
        // A shortfall that returns within `event_gap_s` of the last one
        // continues its event (the spun wheels braked back to the road's
        // speed take the brake torque first: not a second slip).
        let new_event = !self.slipping && self.since_slip_s >= cfg.event_gap_s;
        // The grip shown since the last event (not counted before the first,
        // and once the estimate is back at the configured friction): a
        // relapse lowers μ̂ no further than the road has shown it holds.
        let shown = if self.mu < cfg.mu_nominal {
            self.shown
        } else {
            T::ZERO
        };
        self.slipping = true;
        if new_event {
            self.mu_before = self.mu;
            self.shown = self.peak.0;
            self.events = self.events.wrapping_add(1);
            // A relapse (slip again after μ̂ rose): the road is still
            // slippery; recover more patiently.
            if self.rose {
                self.patience = smaller(self.patience * T::TWO, cfg.patience_max);
            }
            self.rose = false;
        }
        // Within one event, the best the tyres gave counts: the square root
        // only when the peak is new to the event.
        let g = T::lit(crate::G);
        let mu_g = self.mu * g;
        if new_event || self.peak.0 > mu_g * mu_g {
            let best = if shown > self.peak.0 {
                shown
            } else {
                self.peak.0
            };
            let obs = best.sqrt() * (T::ONE / g);
            let floor = larger(self.mu_before * cfg.max_drop, cfg.mu_min);
            let mu = smaller(self.mu_before, larger(obs, floor));
            self.mu = if new_event { mu } else { larger(self.mu, mu) };
        }
        self.since_slip_s = T::ZERO;
        self.since_slip_m = T::ZERO;
    }

    /// The standstill rule (module docs, *Standstill*) at the measured speed `v`
    /// (m/s) over `dt` (s).
    fn standstill(&mut self, cfg: &FrictionConfig<T>, v: T, dt: T) {
        // Standing, the tyres ask nothing of the road: the configured friction
        // again, so that the planner plans a start (a road still slippery shows
        // as slip again, at low speed), unless the car stands where the road
        // slipped: it starts there, and swerves round what stopped it, with
        // the friction that road showed (the recovery still raises it).
        self.standing_s = if v.abs() < cfg.standstill_mps {
            self.standing_s + dt
        } else {
            T::ZERO
        };
        if self.since_slip_m < cfg.standstill_clear_m {
            self.since_slip_m += v.abs() * dt;
        }
        if self.standing_s >= cfg.standstill_s
            && self.mu < cfg.mu_nominal
            && self.since_slip_m >= cfg.standstill_clear_m
        {
            self.mu = cfg.mu_nominal;
            self.rose = true;
        }
    }

    /// No slip this period: `clear` when the evidence of slip is gone (module
    /// docs: the hold counts only such periods; then `μ̂` rises).
    fn recover(&mut self, cfg: &FrictionConfig<T>, clear: bool, dt: T) {
        if clear {
            self.since_slip_s += dt;
        }
        let hold = smaller(cfg.hold_s * self.patience, cfg.hold_max_s);
        if self.since_slip_s > hold && self.mu < cfg.mu_nominal {
            let rate = if self.mu < cfg.fast_ceiling * cfg.mu_nominal {
                cfg.recovery_per_s
            } else {
                cfg.creep_per_s
            };
            self.mu += rate * dt;
            self.rose = true;
            if self.mu >= cfg.mu_nominal {
                // Fully recovered: the road gave its grip back.
                self.mu = cfg.mu_nominal;
                self.patience = T::ONE;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const M: f64 = 1500.0;
    const R: f64 = 0.3;

    fn cfg() -> FrictionConfig<f64> {
        // The default car: 58.5 % of its weight on the driven front axle.
        FrictionConfig::for_car(M, R, 0.585, 0.55 / 2.65, 0.75)
    }

    /// An estimator started on [`cfg`] and its clock.
    struct Rig {
        e: FrictionEstimator<f64>,
        c: FrictionConfig<f64>,
        t_us: u64,
    }

    impl Rig {
        fn new() -> Self {
            let c = cfg();
            let mut e = FrictionEstimator::new();
            e.start(&c);
            Self { e, c, t_us: 0 }
        }

        /// A rig whose car of true mass `mass_ratio·M` was driven gently (±1.5 m/s²
        /// asked of it and coasting, no slip) for 120 s: its mass and brakes are
        /// learned. Returns the speed.
        fn learned(mass_ratio: f64) -> (Self, f64) {
            let mut r = Self::new();
            let mut v = 20.0;
            // Driving, coasting, braking: the mass from the first two, the
            // brakes' gain from the third.
            for k in 0..30 {
                let a = [1.5, 0.0, -1.5][k % 3];
                v = r.drive(v, a, a / mass_ratio, 0.0, 4.0);
            }
            (r, v)
        }

        /// Drives the estimator for `secs` from the speed `v` (m/s) with the torque
        /// asking `a_cmd` (m/s²) of the configured car while the car achieves
        /// `a_meas` (m/s²) at lateral acceleration `ay` (m/s²); returns the speed
        /// reached.
        fn drive(&mut self, v: f64, a_cmd: f64, a_meas: f64, ay: f64, secs: f64) -> f64 {
            let mut v = v;
            for _ in 0..(secs * 100.0).round() as u32 {
                let yaw_rate = if v > 0.0 { ay / v } else { 0.0 };
                let t = self.t_us;
                self.e.update(&self.c, t, t, v, yaw_rate, a_cmd * M * R);
                self.t_us += 10_000;
                v += a_meas * 0.01;
            }
            v
        }
    }

    #[test]
    fn tyres_that_deliver_what_is_asked_leave_the_estimate_alone() {
        assert!(cfg().is_valid());
        let mut r = Rig::new();
        // Accelerating and braking hard, in a curve, less 0.4 m/s² of drag.
        let v = r.drive(10.0, 4.0, 3.6, 3.0, 3.0);
        r.drive(v, -7.0, -7.4, 3.0, 2.0);
        assert_eq!(r.e.mu(), 0.75);
        assert_eq!(r.e.events(), 0);
        assert!(!r.e.slipping());
    }

    #[test]
    fn a_heavier_car_is_not_slip_before_or_after_its_mass_is_learned() {
        // 30 % heavier than configured, hard at once (nothing learned yet) ...
        let mut r = Rig::new();
        let v = r.drive(10.0, 4.0, 4.0 / 1.3, 0.0, 3.0);
        r.drive(v, -6.0, -6.0 / 1.3, 0.0, 2.0);
        assert_eq!(r.e.events(), 0);
        // ... and after: the check judges against the heavier car.
        let (mut r, v) = Rig::learned(1.3);
        let k = r.e.longitudinal().mass_ratio();
        assert!((k - 1.3).abs() < 0.05, "k = {k}");
        let v = r.drive(v, 4.5, 4.5 / 1.3, 0.0, 3.0);
        r.drive(v, -7.0, -7.0 / 1.3, 0.0, 2.0);
        assert_eq!(r.e.events(), 0);
        assert_eq!(r.e.mu(), 0.75);
    }

    #[test]
    fn spinning_driven_wheels_lower_the_estimate_to_the_friction_they_gave() {
        let (mut r, v) = Rig::learned(1.0);
        // The torque asks 3.5 m/s²; the road (μ = 0.5) gives 2.4 m/s² on the
        // front axle, then 2.0 once the wheels spin far past their peak.
        let v = r.drive(v, 3.5, 2.4, 0.0, 0.3);
        r.drive(v, 3.5, 2.0, 0.0, 1.0);
        let e = r.e;
        assert_eq!(e.events(), 1);
        // 2.4 m/s² over the front axle's share less the transfer: μ ≈ 0.45.
        let expected = 2.4 / (0.585 - 0.55 / 2.65 * 2.4 / 9.81) / 9.81;
        assert!(
            (e.mu() - expected).abs() < 0.03,
            "μ̂ = {}, expected ≈ {expected}",
            e.mu()
        );
        assert!(e.mu() >= 0.6 * 0.75);
    }

    /// 1 s of a 3.5 m/s² demand met, then 1 s of it met by 2.0 m/s² (a climb's
    /// shortfall, or slip), the driven wheels `before` then `during` m/s faster
    /// than the ground (NaN: not measured): the slip events.
    fn events_of_a_shortfall_with_wheels(before: f64, during: f64) -> u32 {
        let (mut r, mut v) = Rig::learned(1.0);
        for k in 0..200 {
            let (wheels, a_meas) = if k < 100 {
                (before, 3.5)
            } else {
                (during, 2.0)
            };
            let mut est = StateEstimate::<f64>::zeroed();
            est.vx_mps = v;
            est.wheel_speed_mps = [v + wheels, v + wheels, v, v];
            r.e.read_sensors(&r.c, &est);
            v = r.drive(v, 3.5, a_meas, 0.0, 0.01);
        }
        r.e.events()
    }

    #[test]
    fn a_shortfall_with_every_wheel_gripping_is_not_slip() {
        // Wheels at the ground's speed throughout: the shortfall is the car's.
        assert_eq!(events_of_a_shortfall_with_wheels(0.0, 0.0), 0);
        // Not measured: the shortfall alone is slip, as before.
        assert_eq!(events_of_a_shortfall_with_wheels(f64::NAN, f64::NAN), 1);
        // Driven wheels 8 % fast at about 20 m/s during the shortfall: past the
        // linear range (0.06), under the spin threshold: slip.
        assert_eq!(events_of_a_shortfall_with_wheels(0.0, 1.6), 1);
        // In range, but only since the shortfall began (a lock that ended): the
        // filters still hold what the wheels did before, and the shortfall is
        // slip.
        assert_eq!(events_of_a_shortfall_with_wheels(1.6, 0.0), 1);
    }

    #[test]
    fn a_heavier_car_that_slips_still_shows_slip() {
        // The learned heavier car asks 4.5/1.3 m/s² of its tyres and gets 2.0.
        let (mut r, v) = Rig::learned(1.3);
        r.drive(v, 4.5, 2.0, 0.0, 1.0);
        assert_eq!(r.e.events(), 1);
        assert!(r.e.mu() < 0.75);
    }

    #[test]
    fn locked_wheels_lower_the_estimate_and_grip_comes_back_after_the_hold() {
        let (mut r, v) = Rig::learned(1.0);
        // The brakes ask 5.9 m/s², the road (μ = 0.5) gives 4.9 (all four
        // wheels): within the event the estimate follows the filtered
        // deceleration up to it.
        let v = r.drive(v.max(25.0), -5.9, -4.9, 0.0, 2.0);
        assert_eq!(r.e.events(), 1);
        // Cruising: no slip; held for 2 s, then +0.12·0.75 per second.
        let v = r.drive(v, 0.0, 0.0, 0.0, 0.5);
        let low = r.e.mu();
        assert!((low - 0.5).abs() < 0.03, "μ̂ = {low}");
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.4);
        assert_eq!(r.e.mu(), low);
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.5);
        let before = r.e.mu();
        assert!(before > low);
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.0);
        let mu = r.e.mu();
        assert!((mu - (before + 0.09)).abs() < 0.002, "μ̂ = {mu}");
        // Back to 0.9 of the nominal friction within 10 s of the slip, then
        // creeping at 0.002 per s to it, never above.
        let v = r.drive(v, 0.0, 0.0, 0.0, 5.0);
        let mu = r.e.mu();
        assert!((0.9 * 0.75..0.9 * 0.75 + 0.01).contains(&mu), "μ̂ = {mu}");
        assert_eq!(r.e.patience(), 1.0);
        r.drive(v, 0.0, 0.0, 0.0, 40.0);
        assert_eq!(r.e.mu(), 0.75);
    }

    #[test]
    fn a_relapse_makes_the_recovery_patient_and_near_slip_holds_it() {
        let (mut r, v) = Rig::learned(1.0);
        let v = r.drive(v.max(25.0), -5.9, -4.9, 0.0, 1.0);
        let v = r.drive(v, 0.0, 0.0, 0.0, 6.0);
        assert!(r.e.mu() > 0.6, "μ̂ = {}", r.e.mu());
        // Slip again after the estimate rose: patience 2 (hold 4 s).
        let v = r.drive(v, -5.9, -4.9, 0.0, 1.0);
        assert_eq!(r.e.events(), 2);
        assert_eq!(r.e.patience(), 2.0);
        // The event ends once the filtered shortfall falls under the threshold.
        let v = r.drive(v, 0.0, 0.0, 0.0, 0.5);
        let low = r.e.mu();
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.5);
        assert_eq!(r.e.mu(), low);
        // A shortfall between the clear level and the slip threshold (0.3 m/s²
        // at 3 m/s² of demand; the threshold there 0.6·0.6 + 3·u while μ̂ is
        // below the nominal, the clear level half of it) is evidence still: the
        // hold does not count.
        let u = r.e.longitudinal().mass_uncertainty(&r.c.longitudinal);
        assert!(u < 0.02, "u = {u}");
        let v = r.drive(v, 3.0, 2.7, 0.0, 5.0);
        assert_eq!(r.e.mu(), low);
        assert_eq!(r.e.events(), 2);
        let v = r.drive(v, 0.0, 0.0, 0.0, 4.5);
        // The rest of the 4 s hold, then at the full rate (0.09 per s: the
        // patience lengthens the hold, not the rise).
        let mu = r.e.mu();
        assert!(mu > low, "μ̂ = {mu}");
        r.drive(v, 0.0, 0.0, 0.0, 0.5);
        let rate = (r.e.mu() - mu) / 0.5;
        assert!((rate - 0.09).abs() < 2e-3, "rate {rate}");
    }

    #[test]
    fn a_slip_within_the_event_gap_continues_the_event() {
        let (mut r, v) = Rig::learned(1.0);
        // Braking at 5.9 m/s² that gives 4.9: one event, μ̂ down by at most 40 %.
        let v = r.drive(v.max(25.0), -5.9, -4.9, 0.0, 0.5);
        assert_eq!(r.e.events(), 1);
        let first = r.e.mu();
        assert!((first - 0.45).abs() < 1e-6, "μ̂ = {first}");
        // The shortfall gone (the event's flag down, the evidence gone for less
        // than the 1 s gap), then back: the same event, μ̂ not lowered a second
        // time.
        let mut v = v;
        while r.e.slipping() {
            v = r.drive(v, 0.0, 0.0, 0.0, 0.01);
        }
        let v = r.drive(v, 0.0, 0.0, 0.0, 0.1);
        assert!(r.e.since_slip_s < r.c.event_gap_s, "{}", r.e.since_slip_s);
        let v = r.drive(v, -5.9, -4.9, 0.0, 0.5);
        assert!(r.e.slipping());
        assert_eq!(r.e.events(), 1);
        assert_eq!(r.e.mu(), first);
        // Gone for longer than the gap (under the 2 s hold: μ̂ has not risen): a
        // new event, which lowers it again.
        let mut v = v;
        while r.e.since_slip_s < r.c.event_gap_s {
            v = r.drive(v, 0.0, 0.0, 0.0, 0.01);
        }
        assert_eq!(r.e.mu(), first);
        r.drive(v, -5.9, -4.9, 0.0, 0.5);
        assert_eq!(r.e.events(), 2);
        assert!(r.e.mu() < first, "μ̂ = {}", r.e.mu());
    }

    #[test]
    fn a_relapse_lowers_the_estimate_no_further_than_the_grip_shown_since() {
        let (mut r, v) = Rig::learned(1.0);
        // Hard braking on a good road (0.61 g, no slip) shows nothing about the
        // wet road of the first event: it lowers μ̂ to its drop (0.6·0.75).
        let v = r.drive(v, -6.0, -6.0, 0.0, 1.0);
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.0);
        assert_eq!(r.e.events(), 0);
        let v = r.drive(v, -3.0, -0.1, 0.0, 0.5);
        assert_eq!(r.e.events(), 1);
        assert!((r.e.mu() - 0.45).abs() < 1e-6, "μ̂ = {}", r.e.mu());
        // The car then brakes at 3.9 m/s² on that road without slip (0.40 g),
        // cruises, and its wheels lock again, the tyres giving 1 m/s² of the 3.5
        // asked: without the grip shown since the first event the relapse would
        // take μ̂ to its floor (0.6 of it, at least 0.3, the lowest estimate);
        // the road held 0.40, and so does μ̂.
        let v = r.drive(v, -3.9, -3.9, 0.0, 2.0);
        let v = r.drive(v, 0.0, 0.0, 0.0, 1.2);
        let before = r.e.mu();
        assert!((0.45..0.46).contains(&before), "μ̂ = {before}");
        r.drive(v, -3.5, -1.0, 0.0, 0.5);
        assert_eq!(r.e.events(), 2);
        let mu = r.e.mu();
        let shown = 3.9 / 9.81;
        assert!((mu - shown).abs() < 0.01, "μ̂ = {mu}, shown {shown}");
    }

    #[test]
    fn a_car_standing_gets_the_configured_friction_back() {
        let (mut r, v) = Rig::learned(1.0);
        let v = r.drive(v.max(25.0), -5.9, -4.9, 0.0, 1.0);
        assert!(r.e.mu() < 0.6);
        // Brake to a stop (within the grip), then stand.
        let v = r.drive(v, -3.0, -3.0, 0.0, (v - 0.3) / 3.0);
        assert!(v.abs() < 0.5, "v = {v}");
        r.drive(v, 0.0, 0.0, 0.0, 2.1);
        assert_eq!(r.e.mu(), 0.75);
    }

    #[test]
    fn one_event_lowers_the_estimate_by_at_most_its_drop() {
        let (mut r, v) = Rig::learned(1.0);
        // A spinning wheel braked back (almost no deceleration for the brake torque).
        r.drive(v, -3.0, -0.1, 0.0, 0.5);
        assert_eq!(r.e.events(), 1);
        assert!((r.e.mu() - 0.6 * 0.75).abs() < 1e-6, "μ̂ = {}", r.e.mu());
    }

    #[test]
    fn held_estimates_add_nothing_and_gaps_restart_the_observer() {
        let c = cfg();
        let mut e = FrictionEstimator::new();
        e.start(&c);
        // The same stamp again and again (a held estimate) with a torque the car
        // does not follow: nothing is measured.
        for _ in 0..100 {
            e.update(&c, 1_000, 1_000, 10.0, 0.0, 4.0 * M * R);
        }
        assert_eq!(e.events(), 0);
        // Estimates 1 s apart: each gap restarts the observer.
        for k in 0..50u64 {
            let t = 2_000_000 + k * 1_000_000;
            e.update(&c, t, t, 10.0, 0.0, 4.0 * M * R);
        }
        assert_eq!(e.events(), 0);
        assert_eq!(e.shortfall_mps2(), 0.0);
        assert_eq!(e.longitudinal().updates(), 0);
        // A non-finite speed is refused and forgotten.
        e.update(&c, 60_000_000, 60_000_000, f64::NAN, 0.0, 0.0);
        assert_eq!(e.mu(), 0.75);
    }

    #[test]
    fn invalid_settings_are_refused() {
        let mut c = cfg();
        c.driven_load_share = 1.5;
        assert!(!c.is_valid());
        let mut c = cfg();
        c.mu_nominal = f64::NAN;
        assert!(!c.is_valid());
        let mut c = cfg();
        c.max_drop = 0.0;
        assert!(!c.is_valid());
        let mut c = cfg();
        c.patience_max = 0.5;
        assert!(!c.is_valid());
        let mut c = cfg();
        c.longitudinal.memory_s = -1.0;
        assert!(!c.is_valid());
    }
}
