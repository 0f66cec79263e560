//! Tests of the local velocity planner `V_heur`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use core::f64::consts::PI;
use firmware::reference_path::ReferencePath;
use firmware::velocity_planner::{v_heur, VelocityPlannerSettings};

/// 200 m straight, then a left hairpin of radius 10 m, then 200 m back (open).
fn track() -> ReferencePath<f64, 512> {
    let mut pts = vec![];
    for i in 0..=100 {
        pts.push([2.0 * i as f64, 0.0]);
    }
    for k in 1..40 {
        let a = PI * k as f64 / 40.0;
        pts.push([200.0 + 10.0 * a.sin(), 10.0 - 10.0 * a.cos()]);
    }
    for i in 0..=100 {
        pts.push([200.0 - 2.0 * i as f64, 20.0]);
    }
    let mut p = ReferencePath::new();
    p.load(&pts, None, false).unwrap();
    p
}

#[test]
fn defaults_follow_the_horizon_and_braking_bound() {
    let s: VelocityPlannerSettings<f64> = VelocityPlannerSettings::default();
    assert!((s.horizon_s - 3.2).abs() < 1e-6);
    assert!((s.v_max_mps(1.0) - 8.0 * s.horizon_s).abs() < 1e-9);
    // On ice the car cannot brake at 8 m/s²: μ·g limits it.
    assert!((s.v_max_mps(0.3) - 0.3 * 9.81 * s.horizon_s).abs() < 1e-4);
    assert_eq!(s.v_max_mps(f64::NAN), 0.0);
}

#[test]
fn straight_gives_v_plus_delta_v_or_v_max() {
    let p = track();
    let s = VelocityPlannerSettings::default();
    assert!((v_heur(&s, &p, 0.0, 10.0, 1.0) - 13.0).abs() < 1e-9);
    let v = v_heur(&s, &p, 0.0, 24.0, 1.0);
    assert!((v - s.v_max_mps(1.0)).abs() < 1e-9, "{v}");
    assert!((v_heur(&s, &p, 0.0, -3.0, 1.0) - 3.0).abs() < 1e-9);
}

#[test]
fn tight_curve_ahead_limits_to_the_lateral_bound() {
    let p = track();
    let s = VelocityPlannerSettings::default();
    // At 20 m/s the preview is 64 m: from s = 150 the hairpin (s = 200) is seen.
    let v = v_heur(&s, &p, 150.0, 20.0, 1.0);
    let expected = (0.5 * 9.81 * 10.0f64).sqrt();
    assert!((v - expected).abs() < 0.05 * expected, "{v} vs {expected}");
    // From s = 100 it is not yet in view.
    assert!((v_heur(&s, &p, 100.0, 20.0, 1.0) - 23.0).abs() < 1e-9);
    // μ enters as an input.
    let v_wet = v_heur(&s, &p, 150.0, 20.0, 0.5);
    assert!((v_wet - expected * 0.5f64.sqrt()).abs() < 0.05 * expected);
    // The lateral fraction is configurable.
    let s2 = VelocityPlannerSettings {
        ay_fraction: 0.3,
        ..s
    };
    assert!(v_heur(&s2, &p, 150.0, 20.0, 1.0) < v);
}

#[test]
fn closed_path_wraps_and_f32_works() {
    let mut pts = vec![];
    for k in 0..64 {
        let a = 2.0 * PI * k as f64 / 64.0;
        pts.push([(40.0 * a.cos()) as f32, (40.0 * a.sin()) as f32]);
    }
    let mut p: ReferencePath<f32, 64> = ReferencePath::new();
    p.load(&pts, None, true).unwrap();
    let s = VelocityPlannerSettings::<f32>::default();
    let a = v_heur(&s, &p, 10.0, 20.0, 1.0);
    let b = v_heur(&s, &p, 10.0 + 3.0 * p.length_m(), 20.0, 1.0);
    assert!((a - (0.5f32 * 9.81 * 40.0).sqrt()).abs() < 0.1, "{a}");
    assert!((a - b).abs() < 1e-3);
}

#[test]
fn empty_path_is_a_straight() {
    let p: ReferencePath<f64, 8> = ReferencePath::new();
    let s = VelocityPlannerSettings::default();
    assert!((v_heur(&s, &p, 0.0, 5.0, 1.0) - 8.0).abs() < 1e-12);
}

#[test]
fn curvature_reserve_slows_fast_curves_most() {
    let none: VelocityPlannerSettings<f64> = VelocityPlannerSettings::default();
    assert_eq!(none.curvature_reserve_1pm, 0.0);
    let res = VelocityPlannerSettings {
        curvature_reserve_1pm: 0.002,
        ..none
    };
    let ay = none.ay_fraction * 9.81;
    for kappa in [0.1, 0.02, 0.005, -0.005] {
        // Without a reserve: the paper's sqrt(a_y/|κ|); with it, sqrt(a_y/(|κ| + κ_res)).
        let v0 = none.curve_speed_mps(kappa, 1.0);
        assert!((v0 / (ay / f64::abs(kappa)).sqrt() - 1.0).abs() < 1e-6);
        let v1 = res.curve_speed_mps(kappa, 1.0);
        assert!((v1 / (ay / (f64::abs(kappa) + 0.002)).sqrt() - 1.0).abs() < 1e-6);
        assert!(v1 < v0);
    }
    // A 10 m hairpin loses 1 %, a 200 m curve 15 %: the steering reserve is a
    // larger share of δ_max(V) at speed.
    let loss = |k: f64| 1.0 - res.curve_speed_mps(k, 1.0) / none.curve_speed_mps(k, 1.0);
    assert!(
        loss(0.1) < 0.011 && loss(0.005) > 0.15,
        "{} {}",
        loss(0.1),
        loss(0.005)
    );
    // On a straight the reserve alone bounds the speed (far above V_max here).
    assert!(res.curve_speed_mps(0.0, 1.0) > 40.0);
    assert_eq!(none.curve_speed_mps(0.0, 1.0), f64::INFINITY);
    // A negative reserve counts as none.
    let neg = VelocityPlannerSettings {
        curvature_reserve_1pm: -1.0,
        ..none
    };
    assert_eq!(
        neg.curve_speed_mps(0.01, 1.0),
        none.curve_speed_mps(0.01, 1.0)
    );
}

/// The sliding preview of the horizon's nodes (`v_heur_at`) gives what the
/// direct look-up (`v_heur`) gives, node after node into and out of the hairpin.
#[test]
fn sliding_preview_matches_the_direct_look_up() {
    use firmware::reference_path::CurvatureWindow;
    use firmware::velocity_planner::v_heur_at;
    let p = track();
    let s = VelocityPlannerSettings::default();
    let mut window = CurvatureWindow::new();
    let mut limited = 0;
    for k in 0..40 {
        let s_node = 120.0 + 4.0 * k as f64;
        let at = p.sample_at(s_node);
        let direct = v_heur(&s, &p, s_node, 20.0, 1.0);
        let sliding = v_heur_at(&s, &p, &mut window, &at, s_node, 20.0, 1.0);
        assert!(
            (sliding - direct).abs() < 1e-6 * direct,
            "s {s_node}: {sliding} vs {direct}"
        );
        if direct < 22.0 {
            limited += 1;
        }
    }
    // The hairpin is in view for part of the way (the test sees the curve).
    assert!(limited > 5 && limited < 40, "{limited}");
}
