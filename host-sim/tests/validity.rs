//! The validity experiment: at walking pace the plant needs the kinematic steering.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::validity::{run_experiment, ValidityConfig};
use host_sim::model::vehicle::VehicleParams;
use indicatif::ProgressBar;

#[test]
fn a_slow_steady_circle_needs_the_kinematic_steering() {
    let p = VehicleParams::default();
    let cfg = ValidityConfig {
        // Three speed steps from 2 m/s to sqrt(mu g R) ~ 14 m/s; only the first is checked.
        steps_to_friction_limit: 3,
        ..ValidityConfig::default()
    };
    let sweeps = run_experiment(&p, &[20.0, 40.0], &cfg, &ProgressBar::hidden()).unwrap();
    for s in &sweeps {
        let first = s.points.first().expect("at least the slowest point");
        assert!((first.speed_mps - 2.0).abs() < 0.05);
        assert!(
            first.relative_error() < 0.05,
            "R={}: delta_a={} delta_th={}",
            s.radius_m,
            first.delta_a_rad,
            first.delta_th_rad
        );
        // a_y = V²/R at steady state.
        let ay = first.speed_mps.powi(2) / s.radius_m;
        assert!((first.ay_mps2 - ay).abs() < 0.05 * ay + 0.01);
    }
}

#[test]
fn the_experiment_is_deterministic_and_stops_when_the_circle_is_lost() {
    let p = VehicleParams::default();
    let cfg = ValidityConfig {
        steps_to_friction_limit: 8,
        ..ValidityConfig::default()
    };
    let a = run_experiment(&p, &[10.0], &cfg, &ProgressBar::hidden()).unwrap();
    let b = run_experiment(&p, &[10.0], &cfg, &ProgressBar::hidden()).unwrap();
    assert_eq!(a, b);
    let s = &a[0];
    assert!(
        s.stop_reason.contains("could not hold"),
        "{}",
        s.stop_reason
    );
    let last = s.points.last().unwrap();
    // It cannot exceed the friction limit of the tyres (lateral peak mu about 1.05).
    assert!(last.ay_mps2 < 1.25 * 9.81, "{}", last.ay_mps2);
    assert!(last.ay_mps2 > 0.5 * 9.81, "{}", last.ay_mps2);
}

#[test]
fn bad_settings_are_errors() {
    let p = VehicleParams::default();
    let cfg = ValidityConfig::default();
    let e = run_experiment(&p, &[1.0], &cfg, &ProgressBar::hidden()).unwrap_err();
    assert!(e.to_string().contains("radius 1"), "{e}");
    let bad_mu = ValidityConfig {
        mu: f64::NAN,
        ..cfg
    };
    assert!(run_experiment(&p, &[20.0], &bad_mu, &ProgressBar::hidden()).is_err());
}
