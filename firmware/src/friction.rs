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
//! the road. The state estimate carries no wheel speeds, so slip cannot be seen
//! directly; its effect can.
//!
//! # How
//!
//! Each period, with `V` the measured speed and `T` the total wheel torque applied
//! over the period that just ended (the last command), `a_cmd = T/(m·r_eff)` is
//! what the torque asks of the tyres, m/s². A speed observer integrates it and is
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
//! `|a_cmd| ≥` [`FrictionConfig::min_demand_mps2`] and `sign(a_cmd)·s` exceeds
//! [`FrictionConfig::shortfall_mps2_limit`] for [`FrictionConfig::confirm_s`].
//!
//! The friction the tyres use is computed every period,
//!
//! ```text
//! μ_used·g = sqrt((a_meas/s_d)² + (V·ψ̇)²),   a_meas = LP(a_cmd) − s
//! ```
//!
//! with `s_d` the driven axle's share of the weight when driving
//! (`driven_load_share − (h/L)·a_meas/g`: only those wheels push, and the load
//! moves off the front axle) and 1 when braking (all four brake), `V·ψ̇` the
//! lateral acceleration; its peak over the last [`FrictionConfig::peak_window_s`]
//! is kept: the force at the tyre's peak, just before it spun or locked (a wheel
//! far past its peak gives less, and a spinning wheel braked back to the road's
//! speed gives almost none). On a slip event
//!
//! ```text
//! μ̂ = clamp(min(μ̂_before, μ_used,peak), max(μ_min, max_drop·μ̂_before), ·)
//! ```
//!
//! the best `μ_used,peak` of the event counting. Too low an estimate is no safer
//! than too high a one: the planner can then brake only at `0.8·μ̂·g`, and its
//! `V_max` falls to `0.8·μ̂·g·T_H`; hence the peak, and the floor
//! [`FrictionConfig::max_drop`] per event.
//!
//! **Recovery**: [`FrictionConfig::hold_s`] after the last slip, `μ̂` rises at
//! [`FrictionConfig::recovery_per_s`] back towards [`FrictionConfig::mu_nominal`]
//! (grip that came back, or a false alarm, is not a permanent slow-down); a road
//! still slippery shows again as a (milder) slip: the driven wheels spin before
//! the brakes lock, since traction asks for `0.8·μ̂·g` of the driven axle's share
//! only.
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
//! Per period about 40 floating-point operations and two divisions; the square
//! root only on a slip. Deterministic, no allocation, no branch on data but the
//! slip test.

use crate::tasks::CONTROL_PERIOD_US;
use crate::Real;

/// Control periods of commanded torque the friction check keeps (160 ms at
/// 100 Hz): the oldest state estimate it can pair with the torque that moved the
/// car.
pub const TORQUE_HISTORY: usize = 16;

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
    /// Shortfall over which slip is declared, m/s², > 0.
    pub shortfall_mps2_limit: T,
    /// Time the shortfall must last before slip is declared, s, ≥ 0.
    pub confirm_s: T,
    /// Window over which the largest friction used is kept, s, > 0.
    pub peak_window_s: T,
    /// Smallest factor by which one slip event lowers `μ̂`, in `(0, 1]`.
    pub max_drop: T,
    /// Time after the last slip before `μ̂` starts to recover, s, ≥ 0.
    pub hold_s: T,
    /// Recovery rate of `μ̂` towards `mu_nominal`, 1/s, ≥ 0.
    pub recovery_per_s: T,
    /// Lowest estimate, dimensionless, > 0.
    pub mu_min: T,
    /// Largest time between two estimates the observer accepts, s, > 0 (a longer
    /// gap restarts it).
    pub max_gap_s: T,
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
    ///   one event lowers `μ̂` by at most 40 %;
    /// * recovery after 10 s without slip at 0.002 per s (0.1 of `μ` in 50 s),
    ///   up to `mu_nominal`; `μ̂ ≥ 0.4·mu_nominal` (the configured friction is
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
            cg_height_over_wheelbase,
            mu_nominal,
            observer_time_s: T::lit(0.4),
            filter_time_s: T::lit(0.2),
            min_demand_mps2: T::ONE,
            shortfall_mps2_limit: T::lit(0.6),
            confirm_s: T::lit(0.05),
            peak_window_s: T::ONE,
            max_drop: T::lit(0.6),
            hold_s: T::lit(10.0),
            recovery_per_s: T::lit(0.002),
            mu_min: T::lit(0.4) * mu_nominal,
            max_gap_s: T::lit(0.1),
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
            && nonneg(self.cg_height_over_wheelbase)
            && pos(self.mu_nominal)
            && pos(self.observer_time_s)
            && pos(self.filter_time_s)
            && pos(self.min_demand_mps2)
            && pos(self.shortfall_mps2_limit)
            && nonneg(self.confirm_s)
            && pos(self.peak_window_s)
            && pos(self.max_drop)
            && self.max_drop <= T::ONE
            && nonneg(self.hold_s)
            && nonneg(self.recovery_per_s)
            && pos(self.mu_min)
            && pos(self.max_gap_s)
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
    /// The observer's speed `V̂`, m/s.
    v_hat_mps: T,
    /// `a_cmd` low-passed at `τ_o` (as the observer low-passes the shortfall),
    /// then at `τ_f`, m/s².
    accel_cmd_mps2: [T; 2],
    /// Filtered shortfall `a_cmd − a_meas`, m/s².
    shortfall_mps2: T,
    /// Time the shortfall has been over its threshold, s.
    shortfall_s: T,
    /// Largest `(μ_obs·g)²` of the last `peak_window_s`, m²/s⁴, and its age, s.
    peak: (T, T),
    /// True while a slip event is under way.
    slipping: bool,
    /// `μ̂` before the slip event under way.
    mu_before: T,
    /// Time since the last slip, s.
    since_slip_s: T,
    /// The estimate `μ̂`.
    mu: T,
    /// Slip events (wrapping).
    events: u32,
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
            accel_cmd_mps2: [T::ZERO; 2],
            shortfall_mps2: T::ZERO,
            shortfall_s: T::ZERO,
            peak: (T::ZERO, T::ZERO),
            slipping: false,
            mu_before: T::INFINITY,
            since_slip_s: T::ZERO,
            mu: T::INFINITY,
            events: 0,
            inverses: [T::ZERO; 3],
        }
    }

    /// Forgets everything and starts at `μ̂ = cfg.mu_nominal` (`cfg` valid:
    /// [`FrictionConfig::is_valid`]; [`FrictionEstimator::update`] must be given
    /// the same settings).
    pub fn start(&mut self, cfg: &FrictionConfig<T>) {
        *self = Self::new();
        self.mu = cfg.mu_nominal;
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

    /// One period, after a successful low-level step at `now_us` (µs): the
    /// estimate's stamp `stamp_us` (µs, at most `now_us`), the measured speed
    /// `v_mps` (m/s) and yaw rate `yaw_rate_radps` (rad/s), then `torque_nm`
    /// (N·m), the total wheel torque commanded now and applied for the next
    /// period. The speed measured at the stamp is compared with the torque applied
    /// over the period before the stamp (an estimate `d` old answers the torque
    /// commanded `d` + one period ago: kept for [`TORQUE_HISTORY`] periods; an
    /// older estimate is not used). A stamp that does not advance (a held estimate)
    /// adds nothing; a gap over `max_gap_s` restarts the observer. Returns `μ̂`.
    #[inline(never)]
    pub fn update(
        &mut self,
        cfg: &FrictionConfig<T>,
        now_us: u64,
        stamp_us: u64,
        v_mps: T,
        yaw_rate_radps: T,
        torque_nm: T,
    ) -> T {
        if !(v_mps.is_finite() && yaw_rate_radps.is_finite()) {
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
                if dt <= cfg.max_gap_s && back <= TORQUE_HISTORY {
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
        self.v_hat_mps = v;
        self.accel_cmd_mps2 = [T::ZERO; 2];
        self.shortfall_mps2 = T::ZERO;
        self.shortfall_s = T::ZERO;
        self.peak = (T::ZERO, T::ZERO);
    }

    /// The observer, the slip test and the estimate over one step of `dt` s.
    fn step(&mut self, cfg: &FrictionConfig<T>, v: T, yaw_rate: T, torque_nm: T, dt: T) {
        let [inv_mr, inv_tau_o, inv_tau_f] = self.inverses;
        let a_cmd = torque_nm * inv_mr;
        // V̂ integrates the commanded acceleration and is pulled to the measured
        // speed in `observer_time_s`: (V̂ − V)/τ_o is the shortfall low-passed at
        // τ_o, from the speed itself, not its noisy derivative. Forward Euler
        // (gains at most 1).
        // Predicted to now with the torque applied since the last estimate, then
        // corrected: e_j = (1 − k_o)·e_{j−1} + Δt·(a_cmd − a_meas) exactly, the
        // recursion of the first filter on a_cmd below.
        let k_o = (dt * inv_tau_o).min(T::ONE);
        let e = self.v_hat_mps + dt * a_cmd - v;
        self.v_hat_mps = v + (T::ONE - k_o) * e;
        let s_raw = e * inv_tau_o;
        // a_cmd through the same two filters as the shortfall, so that
        // a_cmd − shortfall is the measured acceleration without a lag between them.
        let [c1, c2] = self.accel_cmd_mps2;
        let c1 = c1 + k_o * (a_cmd - c1);
        let k = (dt * inv_tau_f).min(T::ONE);
        let cmd = c2 + k * (c1 - c2);
        self.accel_cmd_mps2 = [c1, cmd];
        self.shortfall_mps2 += k * (s_raw - self.shortfall_mps2);
        let demand = cmd.abs();
        let shortfall = self.shortfall_mps2 * cmd.signum0();
        // What the tyres deliver, (μ_obs·g)², kept at its peak over the window.
        let a_meas = cmd - self.shortfall_mps2;
        let a_tyre = if cmd > T::ZERO {
            // Driving: the driven axle alone, its load lowered by the transfer.
            let share = cfg.driven_load_share
                - cfg.cg_height_over_wheelbase * a_meas.max(T::ZERO) * T::lit(1.0 / crate::G);
            a_meas / share.max(T::lit(0.1))
        } else {
            a_meas
        };
        let ay = v * yaw_rate;
        let used = a_tyre * a_tyre + ay * ay;
        self.peak.1 += dt;
        if used >= self.peak.0 || self.peak.1 > cfg.peak_window_s {
            self.peak = (used, T::ZERO);
        }
        let short = demand >= cfg.min_demand_mps2 && shortfall > cfg.shortfall_mps2_limit;
        self.shortfall_s = if short {
            self.shortfall_s + dt
        } else {
            T::ZERO
        };
        if short && self.shortfall_s >= cfg.confirm_s {
            let new_event = !self.slipping;
            if new_event {
                self.slipping = true;
                self.mu_before = self.mu;
                self.events = self.events.wrapping_add(1);
            }
            // Within one event, the best the tyres gave counts: the square root
            // only when the peak is new to the event.
            let g = T::lit(crate::G);
            let mu_g = self.mu * g;
            if new_event || self.peak.0 > mu_g * mu_g {
                let obs = self.peak.0.sqrt() / g;
                let floor = (self.mu_before * cfg.max_drop).max(cfg.mu_min);
                let mu = self.mu_before.min(obs).max(floor);
                self.mu = if new_event { mu } else { self.mu.max(mu) };
            }
            self.since_slip_s = T::ZERO;
        } else {
            self.slipping = false;
            self.since_slip_s += dt;
            if self.since_slip_s > cfg.hold_s && self.mu < cfg.mu_nominal {
                self.mu = (self.mu + cfg.recovery_per_s * dt).min(cfg.mu_nominal);
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

        /// Drives the estimator for `secs` from the speed `v` (m/s) with the torque
        /// asking `a_cmd` (m/s²) while the car achieves `a_meas` (m/s²) at lateral
        /// acceleration `ay` (m/s²); returns the speed reached.
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
    fn spinning_driven_wheels_lower_the_estimate_to_the_friction_they_gave() {
        let mut r = Rig::new();
        // The torque asks 3.5 m/s²; the road (μ = 0.5) gives 2.4 m/s² on the
        // front axle, then 2.0 once the wheels spin far past their peak.
        let v = r.drive(15.0, 3.5, 2.4, 0.0, 0.3);
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

    #[test]
    fn locked_wheels_lower_the_estimate_and_it_recovers_slowly_after_the_hold() {
        let mut r = Rig::new();
        // The brakes ask 5.9 m/s², the road gives 4.9 (μ = 0.5, all four wheels):
        // within the event the estimate follows the filtered deceleration up to it.
        let v = r.drive(25.0, -5.9, -4.9, 0.0, 2.0);
        assert_eq!(r.e.events(), 1);
        // Cruising: no slip; held for 10 s, then +0.002 per second.
        let v = r.drive(v, 0.0, 0.0, 0.0, 0.5);
        let low = r.e.mu();
        assert!((low - 0.5).abs() < 0.03, "μ̂ = {low}");
        let v = r.drive(v, 0.0, 0.0, 0.0, 9.0);
        assert_eq!(r.e.mu(), low);
        let v = r.drive(v, 0.0, 0.0, 0.0, 10.5);
        let mu = r.e.mu();
        assert!((mu - (low + 0.002 * 10.0)).abs() < 0.002, "μ̂ = {mu}");
        // Never above the nominal friction.
        r.drive(v, 0.0, 0.0, 0.0, 200.0);
        assert_eq!(r.e.mu(), 0.75);
    }

    #[test]
    fn one_event_lowers_the_estimate_by_at_most_its_drop() {
        let mut r = Rig::new();
        // A spinning wheel braked back (almost no deceleration for the brake torque).
        r.drive(20.0, -3.0, -0.1, 0.0, 0.5);
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
    }
}
