//! Tests of the sideslip-lag estimate on synthetic cornering data.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::bicycle::BicycleGeometry;
use firmware::mpc::MpcSettings;
use firmware::sideslip::{SideslipConfig, SideslipLag};
use firmware::state_estimate::StateEstimate;
use firmware::tasks::PlanTask;
use proptest::prelude::*;

/// The car: `k = l_r/L = 0.55`.
const G: BicycleGeometry<f32> = BicycleGeometry {
    l_f_m: 1.215,
    l_r_m: 1.485,
};
const K: f32 = 1.485 / 2.7;

fn cfg() -> SideslipConfig<f32> {
    SideslipConfig::shipped()
}

/// A car at `v` (m/s) turning with lateral acceleration `ay` (m/s²) at steering
/// `delta` (rad), its sideslip `lag·a_y` behind the kinematic one, plus `noise` rad.
fn cornering(v: f32, ay: f32, delta: f32, lag: f32, noise: f32) -> StateEstimate<f32> {
    let beta = K * delta.tan() - lag * ay + noise;
    StateEstimate {
        vx_mps: v,
        vy_mps: v * beta,
        yaw_rate_radps: ay / v,
        delta_rad: delta,
        ..StateEstimate::zeroed()
    }
}

/// Deterministic pseudo-random numbers in [-1, 1] (a linear congruential
/// generator: the test needs no crate's stream to stay the same).
struct Lcg(u32);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 23) as f32 - 1.0
    }
}

#[test]
fn it_learns_a_known_lag_from_bends_both_ways() {
    let c = cfg();
    let mut e = SideslipLag::new();
    assert_eq!(e.lag(&c), 0.0);
    for i in 0..200 {
        let ay = if i % 20 < 10 { 4.0 } else { -3.0 };
        assert!(e.update(&c, &G, &cornering(22.0, ay, ay * 0.01, 0.012, 0.0), false));
    }
    assert!((e.lag(&c) - 0.012).abs() < 2e-4, "lag {}", e.lag(&c));
    assert_eq!(e.samples(), 200);
}

#[test]
fn it_follows_a_change_of_load_within_its_memory() {
    // The lag steps from 0.006 to 0.014 (a heavier load): 5 s of bends at 10 Hz
    // later the estimate is most of the way there.
    let c = cfg();
    let mut e = SideslipLag::new();
    for _ in 0..300 {
        e.update(&c, &G, &cornering(20.0, 3.5, 0.03, 0.006, 0.0), false);
    }
    assert!((e.lag(&c) - 0.006).abs() < 2e-4);
    for _ in 0..100 {
        e.update(&c, &G, &cornering(20.0, 3.5, 0.03, 0.014, 0.0), false);
    }
    assert!((e.lag(&c) - 0.014).abs() < 0.002, "lag {}", e.lag(&c));
}

#[test]
fn noise_averages_out() {
    // 0.02 rad of sideslip noise (a plain GNSS/INS's lateral speed at 20 m/s is
    // about 0.4 m/s): the estimate stays within 0.002 of the truth.
    let c = cfg();
    let mut e = SideslipLag::new();
    let mut r = Lcg(7);
    let mut worst: f32 = 0.0;
    for i in 0..600 {
        let ay = 2.0 + 2.5 * (1.0 + r.next());
        e.update(
            &c,
            &G,
            &cornering(20.0, ay, 0.02, 0.01, 0.02 * r.next()),
            false,
        );
        if i >= 100 {
            worst = worst.max((e.lag(&c) - 0.01).abs());
        }
    }
    assert!(worst < 0.002, "worst error {worst}");
}

#[test]
fn slow_straight_sliding_or_broken_samples_do_not_count() {
    let c = cfg();
    let mut e = SideslipLag::new();
    // Too slow, too little lateral acceleration, a slip flagged, NaN, a car at rest.
    assert!(!e.update(&c, &G, &cornering(8.0, 4.0, 0.05, 0.02, 0.0), false));
    assert!(!e.update(&c, &G, &cornering(25.0, 1.0, 0.01, 0.02, 0.0), false));
    assert!(!e.update(&c, &G, &cornering(25.0, 4.0, 0.02, 0.02, 0.0), true));
    let mut nan = cornering(25.0, 4.0, 0.02, 0.02, 0.0);
    nan.vy_mps = f32::NAN;
    assert!(!e.update(&c, &G, &nan, false));
    let mut inf = cornering(25.0, 4.0, 0.02, 0.02, 0.0);
    inf.delta_rad = f32::INFINITY;
    assert!(!e.update(&c, &G, &inf, false));
    assert!(!e.update(&c, &G, &StateEstimate::zeroed(), false));
    // Nor a sample of a car with no rear axle's distance (a geometry the MPC
    // refuses: `k` NaN).
    let nan_geometry = BicycleGeometry {
        l_f_m: 0.0,
        l_r_m: 0.0,
    };
    let sample = cornering(25.0, 4.0, 0.02, 0.02, 0.0);
    assert!(!e.update(&c, &nan_geometry, &sample, false));
    assert_eq!(e.samples(), 0);
    assert_eq!(e.lag(&c), 0.0);
    // One counted sample moves it from the prior by that sample's weight only.
    assert!(e.update(&c, &G, &cornering(25.0, 4.0, 0.02, 0.02, 0.0), false));
    let one = e.lag(&c);
    assert!(
        one > 0.0 && one < 0.02 * 16.0 / (16.0 + 0.98 * 40.0) + 1e-6,
        "lag {one}"
    );
}

#[test]
fn an_oversteering_or_sliding_car_is_held_inside_the_bounds() {
    let c = cfg();
    let mut e = SideslipLag::new();
    // The course ahead of the kinematic one (negative lag): the kinematic model.
    for _ in 0..100 {
        e.update(&c, &G, &cornering(20.0, 4.0, 0.03, -0.01, 0.0), false);
    }
    assert_eq!(e.lag(&c), 0.0);
    // A rear sliding far out: at most lag_max.
    for _ in 0..100 {
        e.update(&c, &G, &cornering(20.0, 4.0, 0.03, 0.2, 0.0), false);
    }
    assert_eq!(e.lag(&c), c.lag_max);
}

#[test]
fn shipped_settings_are_valid_and_bad_ones_are_not() {
    assert!(cfg().is_valid());
    let mut b = cfg();
    b.forgetting = 1.5;
    assert!(!b.is_valid());
    let mut b = cfg();
    b.lag_max = f32::NAN;
    assert!(!b.is_valid());
    let mut b = cfg();
    b.prior_weight = 0.0;
    assert!(!b.is_valid());
    // The bounds that exclude their end: no forgetting factor 0, no speed 0.
    let mut b = cfg();
    b.forgetting = 0.0;
    assert!(!b.is_valid());
    let mut b = cfg();
    b.min_speed_mps = 0.0;
    assert!(!b.is_valid());
    // And the ones that include it.
    let mut b = cfg();
    (b.forgetting, b.lag_max, b.min_lateral_mps2) = (1.0, 0.0, 0.0);
    assert!(b.is_valid());
}

proptest! {
    #[test]
    fn the_lag_is_always_finite_and_within_its_bounds(
        samples in proptest::collection::vec(
            (-5.0f32..60.0, -1.0f32..1.0, -3.0f32..3.0, -0.6f32..0.6, any::<bool>()), 1..80),
    ) {
        let c = cfg();
        let mut e = SideslipLag::new();
        for (vx, vy, r, d, slip) in samples {
            let est = StateEstimate {
                vx_mps: vx,
                vy_mps: vy * vx.abs(),
                yaw_rate_radps: r,
                delta_rad: d,
                ..StateEstimate::zeroed()
            };
            e.update(&c, &G, &est, slip);
            let l = e.lag(&c);
            prop_assert!(l.is_finite() && (0.0..=c.lag_max).contains(&l), "lag {l}");
        }
    }
}

/// A car whose course lags the kinematic one by `lag·a_y`, driven by the plan
/// task's plans (their first input held for each 0.1 s) round a 120 m circle
/// from 16 m/s; returns the largest distance from the circle over the last 20 s
/// (m) and the lag the plan task learnt. `learn`: the shipped settings, else
/// `lag_max = 0` (the kinematic model always).
fn lap_of_a_lagging_car(lag: f64, learn: bool) -> (f64, f64) {
    const R: f64 = 120.0;
    let geometry = firmware::vehicle_config::VehicleConfig::reference().geometry();
    let mut settings = MpcSettings::paper(geometry, 0.6, 1.8);
    if !learn {
        settings.sideslip.lag_max = 0.0;
    }
    let mut planner = Box::new(PlanTask::<f64, 1024>::new(settings, 1.0));
    let n = (2.0 * std::f64::consts::PI * R).round() as usize;
    let rows: Vec<[f64; 4]> = (0..n)
        .map(|i| {
            let a = -std::f64::consts::FRAC_PI_2 + 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            [R * a.cos(), R + R * a.sin(), 4.0, 4.0]
        })
        .collect();
    planner.path.load_track(&rows, true).unwrap();
    let k = geometry.l_r_m / geometry.wheelbase_m();
    let mut xi = [
        0.0,
        0.0,
        0.0,
        16.0,
        0.0,
        (geometry.wheelbase_m() / R).atan(),
    ];
    let mut worst: f64 = 0.0;
    let (mut u, mut failures) = ([0.0; 2], 0);
    for step in 0..600u64 {
        // What the car measures: its course, `β + ε`, from the heading.
        let beta = (k * xi[5].tan()).atan();
        let yaw_rate = xi[3] * beta.sin() / geometry.l_r_m;
        let course = beta - lag * xi[3] * yaw_rate;
        let est = StateEstimate {
            stamp_us: step * 100_000,
            x_m: xi[1],
            y_m: xi[2],
            psi_rad: xi[4],
            vx_mps: xi[3] * course.cos(),
            vy_mps: xi[3] * course.sin(),
            yaw_rate_radps: yaw_rate,
            delta_rad: xi[5],
            ..StateEstimate::zeroed()
        };
        // A failed activation (a QP at its iteration cap, 2–6 of the 600 here)
        // keeps the input, as the control task keeps the last plan.
        if planner.run(&est).is_ok() {
            u = planner.pending().unwrap().inputs[0];
        } else {
            failures += 1;
        }
        for _ in 0..10 {
            xi = geometry.step_lagged(&xi, &u, 0.01, lag);
        }
        if step >= 400 {
            worst = worst.max((xi[1].hypot(xi[2] - R) - R).abs());
        }
    }
    assert!(failures <= 10, "{failures} failed activations");
    (worst, planner.sideslip_lag())
}

#[test]
fn the_plan_task_learns_the_lag_and_its_plans_hold_the_line() {
    let (kinematic_car, lag0) = lap_of_a_lagging_car(0.0, true);
    let (unlearnt, _) = lap_of_a_lagging_car(0.015, false);
    let (learnt, lag) = lap_of_a_lagging_car(0.015, true);
    // The kinematic car teaches nothing; the lagging one its lag.
    assert!(lag0.abs() < 1e-3, "lag {lag0}");
    assert!((lag - 0.015).abs() < 0.0015, "lag {lag}");
    // Unlearnt, the lagging car runs wide (1.0 m when written); learnt, as close
    // as the kinematic car (both about 1 mm).
    assert!(unlearnt > 0.5, "unlearnt {unlearnt} m");
    assert!(
        learnt < 0.1 * unlearnt,
        "learnt {learnt} m, unlearnt {unlearnt} m"
    );
    assert!(
        learnt < kinematic_car + 0.02,
        "learnt {learnt} m, kinematic {kinematic_car} m"
    );
}
