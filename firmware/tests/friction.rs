//! Tests of the friction check (`firmware::friction`), beside the unit tests in
//! `firmware/src/friction.rs`: each setting's range, the settings for a car, and
//! the estimator's inputs (which torque a late estimate is paired with, non-finite
//! measurements) and its rules at their edges, each worked out from the module's
//! documentation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::friction::{FrictionConfig, FrictionEstimator, TORQUE_HISTORY};
use firmware::state_estimate::StateEstimate;
use firmware::timing::CONTROL_PERIOD_US;

const M: f64 = 1500.0;
const R: f64 = 0.3;
const MU: f64 = 0.75;

/// The default car (58.5 % of its weight on the driven front axle), planned at
/// μ = 0.75.
fn cfg() -> FrictionConfig<f64> {
    FrictionConfig::for_car(M, R, 0.585, 0.55 / 2.65, MU)
}

/// True when `cfg()` changed by `change` is valid.
fn valid_with(change: impl Fn(&mut FrictionConfig<f64>)) -> bool {
    let mut c = cfg();
    change(&mut c);
    c.is_valid()
}

#[test]
fn each_setting_out_of_its_range_is_refused_and_each_edge_accepted() {
    assert!(cfg().is_valid());
    // Each setting alone out of its range (the others as for the car).
    type Change = fn(&mut FrictionConfig<f64>);
    let refused: &[(&str, Change)] = &[
        ("driven share 0", |c| c.driven_load_share = 0.0),
        ("driven share 1.5", |c| c.driven_load_share = 1.5),
        ("driven share NaN", |c| c.driven_load_share = f64::NAN),
        ("front share 0", |c| c.front_load_share = 0.0),
        ("front share 1", |c| c.front_load_share = 1.0),
        ("h/L < 0", |c| c.cg_height_over_wheelbase = -0.1),
        ("h/L ∞", |c| c.cg_height_over_wheelbase = f64::INFINITY),
        ("h/t < 0", |c| c.cg_height_over_track = -0.1),
        ("wheelbase < 0", |c| c.wheelbase_m = -2.65),
        ("μ nominal 0", |c| c.mu_nominal = 0.0),
        ("μ nominal < 0", |c| c.mu_nominal = -0.75),
        ("μ nominal ∞", |c| c.mu_nominal = f64::INFINITY),
        ("observer 0", |c| c.observer_time_s = 0.0),
        ("filter 0", |c| c.filter_time_s = 0.0),
        ("min demand 0", |c| c.min_demand_mps2 = 0.0),
        ("shortfall limit 0", |c| c.shortfall_mps2_limit = 0.0),
        ("vigilance 0", |c| c.vigilance = 0.0),
        ("vigilance 1.5", |c| c.vigilance = 1.5),
        ("confirm < 0", |c| c.confirm_s = -0.01),
        ("peak window 0", |c| c.peak_window_s = 0.0),
        ("max drop 0", |c| c.max_drop = 0.0),
        ("max drop 1.2", |c| c.max_drop = 1.2),
        ("hold < 0", |c| c.hold_s = -1.0),
        ("hold max ∞", |c| c.hold_max_s = f64::INFINITY),
        ("hold max < hold", |c| c.hold_max_s = 1.0),
        ("recovery < 0", |c| c.recovery_per_s = -0.1),
        ("fast ceiling < 0", |c| c.fast_ceiling = -0.1),
        ("fast ceiling 1.1", |c| c.fast_ceiling = 1.1),
        ("creep < 0", |c| c.creep_per_s = -0.002),
        ("patience max ∞", |c| c.patience_max = f64::INFINITY),
        ("patience max 0.5", |c| c.patience_max = 0.5),
        ("clear fraction < 0", |c| c.clear_fraction = -0.1),
        ("clear fraction 1.1", |c| c.clear_fraction = 1.1),
        ("μ min 0", |c| c.mu_min = 0.0),
        ("max gap 0", |c| c.max_gap_s = 0.0),
        ("standstill speed < 0", |c| c.standstill_mps = -1.0),
        ("standstill time < 0", |c| c.standstill_s = -1.0),
        ("standstill distance < 0", |c| c.standstill_clear_m = -1.0),
        ("standstill distance NaN", |c| {
            c.standstill_clear_m = f64::NAN
        }),
        ("half track < 0", |c| c.half_track_m = -0.8),
        ("wheel slip ratio 0", |c| c.wheel_slip_ratio = 0.0),
        ("wheel slip ratio 1", |c| c.wheel_slip_ratio = 1.0),
        ("wheel slip ratio NaN", |c| c.wheel_slip_ratio = f64::NAN),
        ("wheel margin < 0", |c| c.wheel_slip_margin_mps = -0.1),
        ("wheel confirm < 0", |c| c.wheel_confirm_s = -0.01),
        ("wheel confirm NaN", |c| c.wheel_confirm_s = f64::NAN),
        ("estimator invalid", |c| c.longitudinal.memory_s = -1.0),
        ("estimator's mass", |c| c.longitudinal.mass_kg = 1600.0),
        ("estimator's wheel", |c| {
            c.longitudinal.wheel_radius_m = 0.31
        }),
        ("mass 0", |c| {
            c.mass_kg = 0.0;
            c.longitudinal.mass_kg = 0.0;
        }),
    ];
    for (what, change) in refused {
        assert!(!valid_with(change), "{what} accepted");
    }
    // The edges of the ranges.
    let accepted: &[(&str, Change)] = &[
        ("driven share 1", |c| c.driven_load_share = 1.0),
        ("h/L 0", |c| c.cg_height_over_wheelbase = 0.0),
        ("h/t 0.2", |c| c.cg_height_over_track = 0.2),
        ("wheelbase 2.65", |c| c.wheelbase_m = 2.65),
        ("vigilance 1", |c| c.vigilance = 1.0),
        ("confirm 0", |c| c.confirm_s = 0.0),
        ("max drop 1", |c| c.max_drop = 1.0),
        ("hold 0", |c| c.hold_s = 0.0),
        ("hold max = hold", |c| c.hold_max_s = c.hold_s),
        ("recovery 0", |c| c.recovery_per_s = 0.0),
        ("fast ceiling 0", |c| c.fast_ceiling = 0.0),
        ("fast ceiling 1", |c| c.fast_ceiling = 1.0),
        ("creep 0", |c| c.creep_per_s = 0.0),
        ("patience max 1", |c| c.patience_max = 1.0),
        ("clear fraction 0", |c| c.clear_fraction = 0.0),
        ("clear fraction 1", |c| c.clear_fraction = 1.0),
        ("standstill speed 0", |c| c.standstill_mps = 0.0),
        ("standstill time 0", |c| c.standstill_s = 0.0),
        ("half track 0.8", |c| c.half_track_m = 0.8),
        ("wheel slip ratio 0.99", |c| c.wheel_slip_ratio = 0.99),
        ("wheel margin 0", |c| c.wheel_slip_margin_mps = 0.0),
        ("wheel confirm 0", |c| c.wheel_confirm_s = 0.0),
    ];
    for (what, change) in accepted {
        assert!(valid_with(change), "{what} refused");
    }
}

/// The period of the control task, s.
const P: f64 = CONTROL_PERIOD_US as f64 * 1e-6;

/// An estimator started on [`cfg`] and its clock.
struct Rig {
    e: FrictionEstimator<f64>,
    c: FrictionConfig<f64>,
    now_us: u64,
}

impl Rig {
    fn new() -> Self {
        Self::with(cfg())
    }

    fn with(c: FrictionConfig<f64>) -> Self {
        let mut e = FrictionEstimator::new();
        e.start(&c);
        Self { e, c, now_us: 0 }
    }

    /// A rig whose car, of the configured mass, climbing a grade that costs it
    /// `grade_mps2` (m/s²), was driven gently (±1.5 m/s² and coasting, the
    /// grade's torque on top, no slip) for 120 s from 20 m/s: its mass,
    /// resistance and brakes are learned. Returns the speed.
    fn learned(grade_mps2: f64) -> (Self, f64) {
        let mut r = Self::new();
        let mut v = 20.0;
        // Driving, coasting, braking: the coasting tells the grade from the
        // mass (the brakes' gain is learnt from the braking alone).
        // The torque holds the grade too, so that the speed stays about 20 m/s.
        for k in 0..30 {
            let a = [1.5, 0.0, -1.5][k % 3];
            v = r.drive(v, a + grade_mps2, a, 4.0);
        }
        (r, v)
    }

    /// Drives the estimator for `secs` with fresh estimates from the speed `v`
    /// (m/s), the torque asking `a_cmd` (m/s²) of the configured car while the
    /// car achieves `a_meas` (m/s²), straight; returns the speed reached.
    fn drive(&mut self, v: f64, a_cmd: f64, a_meas: f64, secs: f64) -> f64 {
        self.drive_turning(v, a_cmd, a_meas, 0.0, secs)
    }

    /// [`Rig::drive`] with the accelerometer: the estimate carries the
    /// specific force `f` (m/s²; the acceleration plus the grade's `g·sin γ`),
    /// the wheel speeds not measured.
    fn drive_measured(&mut self, v: f64, a_cmd: f64, a_meas: f64, f: f64, secs: f64) -> f64 {
        let mut v = v;
        for _ in 0..(secs / P).round() as u32 {
            let t = self.now_us;
            let est = StateEstimate {
                stamp_us: t,
                vx_mps: v,
                specific_force_x_mps2: f,
                ..StateEstimate::zeroed()
            };
            self.e.read_sensors(&self.c, &est);
            self.e.update(&self.c, t, t, v, 0.0, a_cmd * M * R);
            self.now_us += CONTROL_PERIOD_US;
            v += a_meas * P;
        }
        v
    }

    /// [`Rig::drive`] at the lateral acceleration `ay` (m/s²).
    fn drive_turning(&mut self, v: f64, a_cmd: f64, a_meas: f64, ay: f64, secs: f64) -> f64 {
        let mut v = v;
        for _ in 0..(secs / P).round() as u32 {
            let t = self.now_us;
            let yaw_rate = if v > 0.0 { ay / v } else { 0.0 };
            self.e.update(&self.c, t, t, v, yaw_rate, a_cmd * M * R);
            self.now_us += CONTROL_PERIOD_US;
            v += a_meas * P;
        }
        v
    }
}

/// A rig configured with `c`, after one slip event: locked wheels at 20 m/s
/// (−6 m/s² asked, −1 m/s² delivered, for 0.5 s). Returns the rig, the speed
/// after the event (m/s) and `μ̂` then.
fn after_locked_wheels(c: FrictionConfig<f64>) -> (Rig, f64, f64) {
    let mut r = Rig::with(c);
    let v = r.drive(20.0, -6.0, -1.0, 0.5);
    assert_eq!(r.e.events(), 1);
    let low = r.e.mu();
    (r, v, low)
}

/// The default car planned at μ = 1: one slip event lowers μ̂ to 0.6 at most.
fn cfg_mu1() -> FrictionConfig<f64> {
    FrictionConfig::for_car(M, R, 0.585, 0.55 / 2.65, 1.0)
}

/// The friction the front-driven car uses accelerating at `a` (m/s²) on its
/// driven axle (module docs: its share of the weight, lowered by the transfer
/// `h/L·a/g`).
fn driving_mu(a: f64) -> f64 {
    let g = f64::from(firmware::G);
    a / (0.585 - 0.55 / 2.65 * a / g) / g
}

/// The shortfall's first filtered value after a torque that asks `a` (m/s²) of a
/// car at rest on the observer (module docs): the observer's error
/// `e = Δt·a`, the raw shortfall `e/τ_o`, through the first-order filter of gain
/// `Δt/τ_f`.
fn first_shortfall(c: &FrictionConfig<f64>, a: f64) -> f64 {
    (P / c.filter_time_s) * (P * a / c.observer_time_s)
}

/// Runs `n` periods of a car cruising at 10 m/s that takes no notice of the
/// torque, with estimates `delay_us` old, a torque pulse asking 100 m/s² at the
/// period `pulse` and none otherwise: the shortfall after each period.
fn pulse_response(delay_us: u64, pulse: usize, n: usize) -> Vec<f64> {
    let c = cfg();
    let mut e = FrictionEstimator::new();
    e.start(&c);
    let t0 = 1_000_000;
    (0..n)
        .map(|k| {
            let now = t0 + k as u64 * CONTROL_PERIOD_US;
            let torque = if k == pulse { 100.0 * M * R } else { 0.0 };
            e.update(&c, now, now - delay_us, 10.0, 0.0, torque);
            e.shortfall_mps2()
        })
        .collect()
}

#[test]
fn a_late_estimate_is_paired_with_the_torque_applied_before_its_stamp() {
    let c = cfg();
    let jump = first_shortfall(&c, 100.0);
    // The torque commanded at period j acts over (j, j + 1]: an estimate `d`
    // periods old shows it first at period j + d + 1 (and a stamp between two
    // periods at the one after the stamp passes j + 1). Pulses late enough that
    // the ring of torques has wrapped; under 1.2 s, before the estimator of the
    // car takes a sample (the car stays the configured one).
    for (delay_us, pulse, seen) in [
        (0, 20, 21),
        (3 * CONTROL_PERIOD_US, 20, 24),
        (25_000, 37, 40),
        (15 * CONTROL_PERIOD_US, 40, 56),
    ] {
        let s = pulse_response(delay_us, pulse, 70);
        for (k, &x) in s.iter().enumerate().take(seen) {
            assert_eq!(x, 0.0, "delay {delay_us} µs: shortfall {x} at {k}");
        }
        assert!(
            (s[seen] - jump).abs() < 1e-6 * jump,
            "delay {delay_us} µs: {} at {seen}, expected {jump}",
            s[seen]
        );
    }
    // An estimate older than the torques kept measures nothing.
    for delay_us in [
        TORQUE_HISTORY as u64 * CONTROL_PERIOD_US,
        40 * CONTROL_PERIOD_US,
    ] {
        let s = pulse_response(delay_us, 20, 70);
        assert!(s.iter().all(|&x| x == 0.0), "delay {delay_us} µs");
    }
}

#[test]
fn a_period_without_an_estimate_records_its_torque_and_restarts_the_observer() {
    let c = cfg();
    let jump = first_shortfall(&c, 100.0);
    let mut e = FrictionEstimator::new();
    e.start(&c);
    let delay = 2 * CONTROL_PERIOD_US;
    let mut shortfall = Vec::new();
    for k in 0..40u64 {
        let now = 1_000_000 + k * CONTROL_PERIOD_US;
        let torque = if k == 20 { 100.0 * M * R } else { 0.0 };
        if k == 20 {
            // No estimate this period: the pulse is applied all the same.
            e.forget(torque);
        } else {
            e.update(&c, now, now - delay, 10.0, 0.0, torque);
        }
        shortfall.push(e.shortfall_mps2());
    }
    // Period 21 restarts the observer; the pulse shows at 20 + 2 + 1.
    assert!(shortfall[..23].iter().all(|&x| x == 0.0), "{shortfall:?}");
    assert!((shortfall[23] - jump).abs() < 1e-6 * jump, "{shortfall:?}");
}

#[test]
fn an_older_stamp_than_the_last_adds_nothing() {
    let mut r = Rig::new();
    let v = r.drive(20.0, 3.5, 2.0, 0.3);
    let before = (r.e.mu(), r.e.shortfall_mps2(), r.e.events());
    assert!(before.1 > 0.0);
    // An estimate stamped before the last one used (out of order).
    let now = r.now_us;
    r.e.update(&r.c, now, now - 50_000, v, 0.0, 3.5 * M * R);
    assert_eq!((r.e.mu(), r.e.shortfall_mps2(), r.e.events()), before);
}

#[test]
fn a_non_finite_yaw_rate_is_refused_and_restarts_the_observer() {
    let mut r = Rig::new();
    let mut v = 20.0;
    for yaw_rate in [f64::NAN, f64::INFINITY] {
        v = r.drive(v, 3.5, 2.0, 0.3);
        assert!(r.e.shortfall_mps2() > 0.0);
        let mu = r.e.mu();
        let now = r.now_us;
        r.e.update(&r.c, now, now, v, yaw_rate, 3.5 * M * R);
        assert_eq!(r.e.mu(), mu);
        r.now_us += CONTROL_PERIOD_US;
        // The next estimate starts the observer afresh: no shortfall yet.
        v = r.drive(v, 3.5, 2.0, P);
        assert_eq!(r.e.shortfall_mps2(), 0.0);
    }
}

#[test]
fn estimates_at_half_the_control_rate_still_teach_the_car() {
    // A 50 Hz estimator: every other control period holds the last estimate.
    // The car is 20 % heavier than configured and delivers what the torque asks
    // of it (±1.5 m/s² of the configured car, alternating every 4 s).
    let c = cfg();
    let mut e = FrictionEstimator::new();
    e.start(&c);
    let mut v = 20.0;
    for k in 0..4000u64 {
        let now = k * CONTROL_PERIOD_US;
        let stamp = now - now % (2 * CONTROL_PERIOD_US);
        let a = if (k / 400) % 2 == 0 { 1.5 } else { -1.5 };
        e.update(&c, now, stamp, v, 0.0, a * M * R);
        v += a / 1.2 * P;
    }
    let l = e.longitudinal();
    assert!(l.updates() > 1000, "updates {}", l.updates());
    assert!(
        (l.mass_ratio() - 1.2).abs() < 0.05,
        "k = {}",
        l.mass_ratio()
    );
    assert_eq!(e.events(), 0);
}

#[test]
fn slipping_is_reported_while_the_event_lasts() {
    let mut r = Rig::new();
    let v = r.drive(20.0, 0.0, 0.0, 0.5);
    assert!(!r.e.slipping());
    // Braking wheels that lock: 1 m/s² of the 6 asked.
    let v = r.drive(v, -6.0, -1.0, 0.5);
    assert!(r.e.slipping());
    assert_eq!(r.e.events(), 1);
    // Released: the shortfall falls back and the event ends.
    r.drive(v, 0.0, 0.0, 2.0);
    assert!(!r.e.slipping());
    assert_eq!(r.e.events(), 1);
}

#[test]
fn driving_slip_measures_the_driven_axle_with_its_load_transfer() {
    // Asked 6 m/s², the front wheels give 3.5 (and spin): μ̂ is what the driven
    // axle used, above the drop's floor (0.6).
    let mut r = Rig::with(cfg_mu1());
    r.drive(10.0, 6.0, 3.5, 3.0);
    assert_eq!(r.e.events(), 1);
    let expected = driving_mu(3.5);
    assert!(expected > 0.65);
    assert!(
        (r.e.mu() - expected).abs() < 2e-3,
        "μ̂ = {}, expected {expected}",
        r.e.mu()
    );
}

#[test]
fn braking_slip_in_a_curve_counts_the_lateral_acceleration() {
    // All four wheels brake at 5 m/s² (of 9 asked) while the car turns at
    // 5 m/s²: the tyres use sqrt(5² + 5²).
    let mut r = Rig::with(cfg_mu1());
    r.drive_turning(25.0, -9.0, -5.0, 5.0, 3.0);
    assert_eq!(r.e.events(), 1);
    let expected = (50.0f64).sqrt() / f64::from(firmware::G);
    assert!(
        (r.e.mu() - expected).abs() < 2e-3,
        "μ̂ = {}, expected {expected}",
        r.e.mu()
    );
}

#[test]
fn the_tyres_peak_counts_within_its_window_and_not_after() {
    // The front wheels give 4 m/s² of 5.5 asked (a shortfall under the
    // threshold: no slip), then spin (0.5 m/s²). Confirmed after 0.5 s, the
    // event still counts the 4 m/s² of 0.5 s before.
    let mut c = cfg_mu1();
    c.confirm_s = 0.5;
    let mut r = Rig::with(c);
    let v = r.drive(10.0, 5.5, 4.0, 3.0);
    assert_eq!(r.e.events(), 0);
    r.drive(v, 5.5, 0.5, 1.0);
    assert_eq!(r.e.events(), 1);
    let expected = driving_mu(4.0);
    assert!(
        (r.e.mu() - expected).abs() < 2e-3,
        "μ̂ = {}, expected {expected}",
        r.e.mu()
    );
    // The same 4 m/s², then 2 s of cruise before the wheels lock braking
    // (1 m/s² of 6): the peak is older than its window (1 s); what the tyres
    // gave since is under the drop's floor.
    let mut r = Rig::with(cfg_mu1());
    let v = r.drive(10.0, 5.5, 4.0, 3.0);
    let v = r.drive(v, 0.0, 0.0, 2.0);
    r.drive(v, -6.0, -1.0, 1.0);
    assert_eq!(r.e.events(), 1);
    assert!((r.e.mu() - 0.6).abs() < 1e-6, "μ̂ = {}", r.e.mu());
}

#[test]
fn a_deceleration_without_torque_is_not_the_driven_axles() {
    // Coasting, no torque, the car slows at 4 m/s² (all four wheels: 0.41 g),
    // then its wheels lock braking (1 m/s² of 6): the grip of the window is at
    // most 0.41 g, under the drop's floor (0.6·0.75 = 0.45), not up to 4 m/s²
    // over the driven axle's share (0.70 g). 1.1 s of it: before the estimator
    // of the car takes its first sample (1.2 s), which would read the
    // deceleration as a resistance, and a torque of 0 as a demand.
    let mut r = Rig::new();
    let v = r.drive(25.0, 0.0, -4.0, 1.1);
    assert_eq!(r.e.events(), 0);
    r.drive(v, -6.0, -1.0, 1.0);
    assert_eq!(r.e.events(), 1);
    assert!((r.e.mu() - 0.45).abs() < 1e-6, "μ̂ = {}", r.e.mu());
}

#[test]
fn with_the_accelerometer_a_sudden_climb_is_neither_slip_nor_resistance() {
    // Learnt on the level with the accelerometer (driving, coasting, braking),
    // then a 15 % climb (1.46 m/s² of `g·sin γ`) under a torque asking 3 m/s²:
    // the tyres give all of it (the specific force is 3), the car gains 1.54.
    let grade = 9.81 * 0.15;
    let run = |accel: bool| {
        let mut r = Rig::new();
        let mut v = 20.0;
        for k in 0..30 {
            let a = [1.5, 0.0, -1.5][k % 3];
            v = if accel {
                r.drive_measured(v, a, a, a, 4.0)
            } else {
                r.drive(v, a, a, 4.0)
            };
        }
        assert_eq!(r.e.events(), 0);
        let _ = if accel {
            r.drive_measured(v, 3.0, 3.0 - grade, 3.0, 3.0)
        } else {
            r.drive(v, 3.0, 3.0 - grade, 3.0)
        };
        let [r0, _] = r.e.longitudinal().resistance_terms_mps2();
        (r.e.events(), r.e.mu(), r0)
    };
    let (events, mu, r0) = run(true);
    assert_eq!((events, mu), (0, MU));
    assert!(r0.abs() < 0.1, "r0 = {r0}");
    // From the speed alone, the same climb is a shortfall the estimate does
    // not explain: slip.
    let (events, mu, _) = run(false);
    assert!(events == 1 && mu < MU, "{events} events, mu {mu}");
}

#[test]
fn losing_the_accelerometer_restarts_the_observer_and_keeps_the_estimate() {
    // The accelerometer for 10 s, then not (NaN) for 5 s, then again: each change
    // starts the observer afresh (no shortfall carried across), the car learnt
    // is kept, and a grip that holds stays no slip.
    let mut r = Rig::new();
    let mut v = r.drive_measured(20.0, 1.5, 1.5, 1.5, 10.0);
    v = r.drive_measured(v, 1.0, 1.0, f64::NAN, 5.0);
    r.drive_measured(v, -1.0, -1.0, -1.0, 5.0);
    assert_eq!(r.e.events(), 0);
    let k = r.e.longitudinal().mass_ratio();
    assert!((k - 1.0).abs() < 0.02, "k = {k}");
    assert!(
        r.e.shortfall_mps2().abs() < 0.05,
        "{}",
        r.e.shortfall_mps2()
    );
}

#[test]
fn a_learned_grade_is_not_slip() {
    // Climbing a grade that costs 0.8 m/s² (under the threshold at 1 m/s² of
    // demand before it is learned): once learned, a torque asking 3 m/s² of the
    // car gets 3 less the grade, and that is no shortfall.
    let (mut r, v) = Rig::learned(0.8);
    let [r0, _] = r.e.longitudinal().resistance_terms_mps2();
    assert!((r0 - 0.8).abs() < 0.1, "r0 = {r0}");
    assert_eq!(r.e.events(), 0);
    let v = r.drive(v, 3.0 + 0.8, 3.0, 2.0);
    r.drive(v, -3.0 + 0.8, -3.0, 2.0);
    assert_eq!(r.e.events(), 0);
    assert_eq!(r.e.mu(), MU);
    assert!(r.e.shortfall_mps2().abs() < 0.2, "{}", r.e.shortfall_mps2());
}

#[test]
fn the_vigilant_threshold_applies_only_below_the_configured_friction() {
    // The car's mass learned (u small): a shortfall of 0.5 m/s² at 2 m/s² of
    // demand is under the threshold 0.6 + 2·u, over the vigilant 0.36 + 2·u.
    let (mut r, v) = Rig::learned(0.0);
    let u = r.e.longitudinal().mass_uncertainty(&r.c.longitudinal);
    assert!(u < 0.03, "u = {u}");
    r.drive(v, 2.0, 1.5, 1.5);
    assert_eq!(r.e.events(), 0);
    assert_eq!(r.e.mu(), MU);
}

#[test]
fn without_a_confirmation_time_slip_is_declared_at_once_and_only_then() {
    let mut c = cfg();
    c.confirm_s = 0.0;
    let mut r = Rig::with(c);
    // Tyres that deliver: nothing.
    let v = r.drive(20.0, 3.0, 3.0, 2.0);
    let v = r.drive(v, 0.0, 0.0, 1.0);
    assert_eq!(r.e.events(), 0);
    assert!(!r.e.slipping());
    // Wheels that lock: slip.
    r.drive(v, -6.0, -1.0, 0.5);
    assert_eq!(r.e.events(), 1);
}

#[test]
fn at_a_low_friction_the_estimate_follows_the_grip_up_within_an_event() {
    // Planned at μ = 0.3: the floor of one event is 0.6·0.3 = 0.18. The brakes
    // ask 5 m/s², the locked wheels give 1.85 (0.189 g): declared while the
    // filtered deceleration is still rising, the event then follows it up.
    let mut r = Rig::with(FrictionConfig::for_car(M, R, 0.585, 0.55 / 2.65, 0.3));
    r.drive(20.0, -5.0, -1.85, 3.0);
    assert_eq!(r.e.events(), 1);
    let expected = 1.85 / f64::from(firmware::G);
    assert!(expected > 0.18 + 5e-3);
    assert!(
        (r.e.mu() - expected).abs() < 1e-3,
        "μ̂ = {}, expected {expected}",
        r.e.mu()
    );
}

#[test]
fn periods_without_demand_count_for_the_recovery_whatever_the_shortfall() {
    // Hold 0.3 s. After a slip event (locked wheels) the car rolls downhill
    // without torque, gaining 0.5 m/s²: the shortfall (0.5 m/s² against the
    // braking demand, as it fades) stays over the clear level, but once the
    // demand is under 1 m/s² (about 1 s) there is no evidence of slip: the hold
    // runs and μ̂ rises at 0.12·0.75 per s, before the estimator of the car
    // takes a sample (1.2 s after the event) that would explain the gain.
    let mut c = cfg();
    c.hold_s = 0.3;
    let (mut r, v, low) = after_locked_wheels(c);
    r.drive(v, 0.0, 0.5, 2.0);
    let mu = r.e.mu();
    assert!(mu > low + 0.02, "μ̂ {low} → {mu}");
    assert_eq!(r.e.events(), 1);
    assert_eq!(r.e.longitudinal().updates(), 0);
}

#[test]
fn a_first_event_after_standing_at_the_configured_friction_is_no_relapse() {
    // Standing at the configured friction does not raise μ̂ (it is there): the
    // first slip event after it keeps the recovery's patience at 1.
    let mut r = Rig::new();
    let v = r.drive(0.0, 0.0, 0.0, 3.0);
    assert_eq!(r.e.mu(), MU);
    let v = r.drive(v, 3.0, 3.0, 7.0);
    r.drive(v, -6.0, -1.0, 0.5);
    assert_eq!(r.e.events(), 1);
    assert_eq!(r.e.patience(), 1.0);
}

#[test]
fn a_car_rolling_at_the_standstill_speed_is_not_standing() {
    // (Standing anywhere restores μ̂ here: no distance from the slip.)
    let mut c = cfg();
    c.standstill_clear_m = 0.0;
    let (mut r, _, low) = after_locked_wheels(c);
    assert!(low < 0.5, "μ̂ = {low}");
    // 3 s at exactly 1 m/s (the standstill speed): not standing; μ̂ recovers at
    // its rate after the hold, far from the configured friction.
    r.drive(1.0, 0.0, 0.0, 3.0);
    assert!(r.e.mu() < 0.6, "μ̂ = {}", r.e.mu());
    // Under it, the car stands: after 2 s, the configured friction again.
    r.drive(0.99, 0.0, 0.0, 2.5);
    assert_eq!(r.e.mu(), MU);
}

#[test]
fn the_car_is_learned_only_within_half_its_grip_and_without_slip() {
    // Driving at 2.5 m/s² asks more than half the grip of the driven axle
    // (0.5·0.75·g·0.585 = 2.15 m/s²): the estimator of the car takes no sample;
    // at 2 m/s² it does.
    let mut r = Rig::new();
    r.drive(5.0, 2.5, 2.5, 5.0);
    assert_eq!(r.e.longitudinal().updates(), 0);
    let mut r = Rig::new();
    r.drive(5.0, 2.0, 2.0, 5.0);
    assert!(r.e.longitudinal().updates() > 0);
    // A shortfall over the threshold not yet confirmed as slip (confirmation
    // 5 s) is slip for the estimator of the car: no sample either.
    let mut c = cfg();
    c.confirm_s = 5.0;
    let mut r = Rig::with(c);
    r.drive(5.0, 2.0, 0.5, 4.0);
    assert_eq!(r.e.events(), 0);
    assert_eq!(r.e.longitudinal().updates(), 0);
}

#[test]
fn without_a_hold_near_slip_still_holds_the_estimate() {
    // Hold 0: μ̂ recovers from the first period without evidence of slip, and
    // not before. The locked wheels of the event (1 m/s² of 6) then give 2.2
    // m/s² of 3: a shortfall of 0.8 m/s², between the clear level and the
    // (vigilant) threshold, 0.5·(0.36 + 0.25·3) and 0.36 + 0.25·3, all the way
    // down from the event's: evidence still.
    let mut c = cfg();
    c.hold_s = 0.0;
    let mut r = Rig::with(c);
    let v = r.drive(25.0, -6.0, -1.0, 0.5);
    assert_eq!(r.e.events(), 1);
    let v = r.drive(v, -3.0, -2.2, 1.5);
    let low = r.e.mu();
    assert!(low < MU);
    assert!(!r.e.slipping());
    let v = r.drive(v, -3.0, -2.2, 3.0);
    assert_eq!(r.e.mu(), low);
    assert_eq!(r.e.events(), 1);
    // Tyres that deliver: μ̂ rises at once.
    r.drive(v, -3.0, -3.0, 1.0);
    assert!(r.e.mu() > low);
}

#[test]
fn at_the_fast_ceiling_the_estimate_creeps() {
    // The fast ceiling where the floor is (0.4 of the configured friction, the
    // lowest estimate): two events in a row take μ̂ down to it, and the
    // recovery from there is the creep (0.002 per s) from its first step.
    let mut c = cfg();
    c.fast_ceiling = f64::from(0.4f32);
    let mut r = Rig::with(c);
    // (2 s apart: the second after the 1 s gap that ends the first.)
    let v = r.drive(25.0, -6.0, -1.0, 0.5);
    let v = r.drive(v, 0.0, 0.0, 2.0);
    let v = r.drive(v, -6.0, -1.0, 0.5);
    assert_eq!(r.e.events(), 2);
    let floor = r.c.mu_min;
    assert_eq!(r.e.mu(), floor);
    assert_eq!(floor, r.c.fast_ceiling * r.c.mu_nominal);
    let mut v = v;
    let mut first_rise = None;
    for _ in 0..600 {
        let before = r.e.mu();
        v = r.drive(v, 0.0, 0.0, P);
        if r.e.mu() > before {
            first_rise = Some(r.e.mu() - before);
            break;
        }
    }
    let rise = first_rise.expect("no recovery in 6 s");
    let creep = 0.002 * P;
    assert!((rise - creep).abs() < 1e-3 * creep, "first step {rise}");
    assert!(v > 0.0);
}

/// The wheels against the ground: rolling (straight, cornering, steered at
/// low speed) is neither spin nor lock; a driven wheel past the slip ratio
/// spins, any wheel below it locks; not measured (NaN), neither.
#[test]
fn wheel_speeds_tell_a_rolling_wheel_from_a_spinning_or_locked_one() {
    let mut c = cfg();
    c.half_track_m = 0.65;
    let mut e = FrictionEstimator::new();
    e.start(&c);
    let est = |vx: f64, yaw: f64, delta: f64, w: [f64; 4]| StateEstimate {
        vx_mps: vx,
        yaw_rate_radps: yaw,
        delta_rad: delta,
        wheel_speed_mps: w,
        ..StateEstimate::zeroed()
    };
    let mut read = |s: StateEstimate<f64>| {
        e.read_sensors(&c, &s);
        (e.wheel_spinning(), e.wheel_locking(), e.wheel_slip_mps())
    };
    // Straight at 20 m/s, rolling.
    assert_eq!(read(est(20.0, 0.0, 0.0, [20.0; 4])), (false, false, 0.0));
    // Turning left at 0.5 rad/s: the left wheels 0.325 m/s slower, the right
    // ones faster.
    let (l, r) = (20.0 - 0.325, 20.0 + 0.325);
    let (spin, lock, most) = read(est(
        20.0,
        0.5,
        0.05,
        [l / (0.05f64).cos(), r / (0.05f64).cos(), l, r],
    ));
    assert!(!spin && !lock && most < 0.01, "{most}");
    // A hairpin at 5 m/s steered 0.5 rad: the front wheels roll 1/cos δ as
    // fast as the car (0.69 m/s more): the second-order factor leaves 0.07 m/s
    // (its fourth-order term), under the margin.
    let f = 5.0 / (0.5f64).cos();
    let (spin, lock, most) = read(est(5.0, 0.0, 0.5, [f, f, 5.0, 5.0]));
    assert!(!spin && !lock && most < 0.08, "{most}");
    // A front wheel at slip ratio 0.25 at 20 m/s spins (0.15·20 + 1 = 4 m/s
    // is the limit); at 0.15 it does not.
    assert!(read(est(20.0, 0.0, 0.0, [25.0, 20.0, 20.0, 20.0])).0);
    assert!(!read(est(20.0, 0.0, 0.0, [23.0, 20.0, 20.0, 20.0])).0);
    // A rear wheel faster is not a driven wheel spinning.
    let (spin, lock, most) = read(est(20.0, 0.0, 0.0, [20.0, 20.0, 24.0, 20.0]));
    assert!(!spin && !lock && (most - 4.0).abs() < 1e-12);
    // Any wheel at slip ratio −0.25 locks.
    assert!(read(est(20.0, 0.0, 0.0, [20.0, 20.0, 20.0, 15.0])).1);
    assert!(read(est(20.0, 0.0, 0.0, [15.0, 20.0, 20.0, 20.0])).1);
    // Under the margin at walking pace: a wheel 0.4 m/s off at 1 m/s is noise.
    assert_eq!(
        read(est(1.0, 0.0, 0.0, [1.4, 1.0, 0.6, 1.0])),
        (false, false, 0.4)
    );
    // Not measured.
    assert_eq!(
        read(est(20.0, 0.0, 0.0, [f64::NAN; 4])),
        (false, false, 0.0)
    );
}

/// A driven wheel that spins is slip though the torque asks little (under the
/// demand at which the shortfall is looked for) and the car accelerates as
/// asked: the event lowers the estimate.
#[test]
fn a_spinning_wheel_is_slip_whatever_the_shortfall() {
    let c = cfg();
    let mut e = FrictionEstimator::new();
    e.start(&c);
    let (mut v, mut t) = (15.0, 0u64);
    for k in 0..300 {
        // 0.5 m/s² asked and given; from 2 s on the front wheels at slip 0.3.
        let w = if k >= 200 { 1.3 * v } else { v };
        let s = StateEstimate {
            stamp_us: t,
            vx_mps: v,
            wheel_speed_mps: [w, w, v, v],
            ..StateEstimate::zeroed()
        };
        e.read_sensors(&c, &s);
        e.update(&c, t, t, v, 0.0, 0.5 * M * R);
        v += 0.5 * 0.01;
        t += CONTROL_PERIOD_US;
    }
    assert_eq!(e.events(), 1);
    assert!(e.mu() < MU, "μ̂ = {}", e.mu());
}

/// One wheel locked alone (the inside wheel unloaded in a bend) halves the
/// braking but is no slip event; two locked are, after the wheels'
/// confirmation.
#[test]
fn one_locked_wheel_is_no_slip_event_two_are() {
    let c = cfg();
    let run = |wheels: fn(f64) -> [f64; 4]| {
        let mut e = FrictionEstimator::new();
        e.start(&c);
        let (mut v, mut t) = (20.0, 0u64);
        for k in 0..300 {
            // 0.5 m/s² of braking asked and given; from 2 s on the wheels of
            // `wheels`.
            let w = if k >= 200 { wheels(v) } else { [v; 4] };
            let s = StateEstimate {
                stamp_us: t,
                vx_mps: v,
                wheel_speed_mps: w,
                ..StateEstimate::zeroed()
            };
            e.read_sensors(&c, &s);
            e.update(&c, t, t, v, 0.0, -0.5 * M * R);
            v -= 0.5 * 0.01;
            t += CONTROL_PERIOD_US;
        }
        (e.events(), e.wheel_locking())
    };
    assert_eq!(run(|v| [v, v, v, 0.5 * v]), (0, true));
    assert_eq!(run(|v| [v, v, 0.5 * v, 0.5 * v]), (1, true));
}

/// A wheel's spin is an event only once it lasts `wheel_confirm_s` (30 ms):
/// a spin of two periods (a bump, a noisy sample) is not; of four it is, and
/// the traction-control flag is up from its first period either way.
#[test]
fn a_spin_shorter_than_the_wheels_confirmation_is_no_event() {
    let c = cfg();
    let run = |periods: usize| {
        let mut e = FrictionEstimator::new();
        e.start(&c);
        let (mut v, mut t) = (15.0, 0u64);
        let mut flagged = false;
        for k in 0..300 {
            // 0.5 m/s² asked and given; from 2 s on the front wheels at slip
            // 0.3 for `periods` periods.
            let spin = (200..200 + periods).contains(&k);
            let w = if spin { 1.3 * v } else { v };
            let s = StateEstimate {
                stamp_us: t,
                vx_mps: v,
                wheel_speed_mps: [w, w, v, v],
                ..StateEstimate::zeroed()
            };
            e.read_sensors(&c, &s);
            flagged |= k == 200 && e.wheel_spinning();
            e.update(&c, t, t, v, 0.0, 0.5 * M * R);
            v += 0.5 * 0.01;
            t += CONTROL_PERIOD_US;
        }
        (e.events(), flagged, e.mu())
    };
    assert_eq!(run(2), (0, true, MU));
    let (events, flagged, mu) = run(4);
    assert_eq!((events, flagged), (1, true));
    assert!(mu < MU, "μ̂ = {mu}");
}

#[test]
fn a_car_standing_where_the_road_slipped_keeps_its_estimate() {
    // Locked wheels at 20 m/s, then a braking the tyres deliver (6 m/s², 32 m)
    // to a stand, 3 s (past the 2 s that restore μ̂ elsewhere): μ̂ stays where
    // the road showed it. (A recovery hold of 10 s keeps the recovery out of
    // the picture.)
    let stop = |r: &mut Rig, v: f64| {
        let v = r.drive(v, -6.0, -6.0, (v - 0.5) / 6.0);
        assert!((v - 0.5).abs() < 0.05, "{v} m/s");
        r.drive(v, 0.0, 0.0, 3.0)
    };
    let mut c = cfg();
    c.hold_s = 10.0;
    let (mut r, v, low) = after_locked_wheels(c);
    assert!(low < MU - 0.1, "μ̂ {low}");
    stop(&mut r, v);
    assert_eq!(r.e.events(), 1);
    assert_eq!(r.e.mu(), low);
    // The same event, then 60 m of road that did not slip (20 m/s, 3 s) before
    // the braking: the configured friction again.
    let (mut r, v, _) = after_locked_wheels(c);
    let v = r.drive(v, 0.0, 0.0, 3.0);
    assert!(r.e.mu() < MU - 0.1, "μ̂ {}", r.e.mu());
    stop(&mut r, v);
    assert_eq!(r.e.events(), 1);
    assert_eq!(r.e.mu(), MU);
}
