//! Tests of the obstacle manager: minimal parabolas, side choice, errors.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use core::f64::consts::PI;
use firmware::obstacles::{
    build_parabola, constraint_value_and_gradient, minimal_apex, obstacle_speed_cap, Obstacle,
    ObstacleError, ObstacleManager, ObstacleSettings, Parabola, Side, MAX_OBSTACLES, MAX_VERTICES,
};
use firmware::reference_path::ReferencePath;
use firmware::velocity_planner::VelocityPlannerSettings;
use proptest::prelude::*;

/// Straight open path along X from −100 m to 200 m, half-widths 4 m each side.
fn straight() -> ReferencePath<f64, 64> {
    let pts: Vec<[f64; 2]> = (0..=30).map(|i| [-100.0 + 10.0 * i as f64, 0.0]).collect();
    let w = vec![[4.0, 4.0]; pts.len()];
    let mut p = ReferencePath::new();
    p.load(&pts, Some(&w), false).unwrap();
    p
}

/// A closed circle of radius `r` m about the origin, counter-clockwise, 200
/// points, default widths (3.5 m).
fn circle_path(r: f64) -> ReferencePath<f64, 256> {
    let pts: Vec<[f64; 2]> = (0..200)
        .map(|i| {
            let a = 2.0 * PI * i as f64 / 200.0;
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let mut p = ReferencePath::new();
    p.load(&pts, None, true).unwrap();
    p
}

fn boxed(x0: f64, x1: f64, y0: f64, y1: f64) -> Obstacle<f64> {
    Obstacle::from_vertices(7, &[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]).unwrap()
}

/// Global position of a point given in the parabola frame.
fn global(p: &Parabola<f64>, xi: f64, eta: f64) -> [f64; 2] {
    let t = p.tangent;
    [
        p.origin_m[0] + xi * t[0] - eta * t[1],
        p.origin_m[1] + xi * t[1] + eta * t[0],
    ]
}

/// Every inflated vertex is inside (g ≤ 0), one touches the boundary (minimal
/// height), and no other ξ0 gives a lower apex (minimal over ξ0).
fn check_minimal(par: &Parabola<f64>, o: &Obstacle<f64>, s: &ObstacleSettings<f64>) {
    let sigma = par.sigma();
    let mut pts = vec![];
    let mut gmax = f64::NEG_INFINITY;
    for v in &o.vertices {
        let (xi, eta) = par.to_local(*v);
        for dx in [-s.half_car_length_m, s.half_car_length_m] {
            let q = global(par, xi + dx, eta + sigma * s.lateral_margin_m());
            let (g, _) = constraint_value_and_gradient(par, q);
            assert!(g <= 1e-9, "inflated vertex outside: g = {g}");
            gmax = gmax.max(g);
            pts.push((xi + dx, sigma * eta + s.lateral_margin_m()));
        }
        // The raw vertex is deeper inside by at least the margin.
        let (g, _) = constraint_value_and_gradient(par, *v);
        assert!(g <= -s.lateral_margin_m() + 1e-9);
    }
    assert!(gmax > -1e-9, "apex not tight: {gmax}");
    let a = sigma * par.eta_apex_m;
    let f = |x0: f64| {
        pts.iter()
            .map(|(xi, e)| e + par.steepness_1pm * (xi - x0).powi(2))
            .fold(f64::NEG_INFINITY, f64::max)
    };
    for k in -4000..=4000 {
        let x0 = par.xi0_m + k as f64 * 0.005;
        assert!(
            f(x0) >= a - 1e-9,
            "lower apex at ξ0 = {x0}: {} < {a}",
            f(x0)
        );
    }
}

#[test]
fn obstacle_on_the_right_is_passed_on_its_left() {
    let path = straight();
    let s = ObstacleSettings::default();
    let o = boxed(48.0, 52.0, -3.0, -1.5);
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Left);
    // The path starts at X = −100 m: s = X + 100.
    assert!((par.xi0_m + par.s_m - 150.0).abs() < 1e-9);
    // Symmetric box: apex over its middle, above its top by the margin and by
    // c·(half length of the box + half car length)².
    let expected =
        -1.5 + s.lateral_margin_m() + s.steepness_1pm * (2.0 + s.half_car_length_m).powi(2);
    assert!((par.eta_apex_m - expected).abs() < 1e-9);
    check_minimal(&par, &o, &s);
    // η_a ≈ 0.07 m: the car passes 0.5 m left of the centre line, not on it.
    assert!(par.constraint_value_and_gradient([50.0, 0.5]).0 > 0.0);
    assert!(par.constraint_value_and_gradient([50.0, 0.0]).0 < 0.0);
}

#[test]
fn obstacle_on_the_left_is_passed_on_its_right() {
    let path = straight();
    let s = ObstacleSettings::default();
    let o = Obstacle::from_vertices(1, &[[30.0, 1.0], [33.0, 2.5], [29.0, 3.5]]).unwrap();
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Right);
    check_minimal(&par, &o, &s);
    // Set by the lowest vertex (30, 1) alone: apex over it.
    let expected = 1.0 - s.lateral_margin_m() - s.steepness_1pm * s.half_car_length_m.powi(2);
    assert!((par.eta_apex_m - expected).abs() < 1e-9);
    assert!((par.xi0_m + par.s_m - 130.0).abs() < 1e-9);
    // Forbidden region above: a point further left is inside.
    assert!(par.constraint_value_and_gradient([31.0, 3.9]).0 < 0.0);
    assert!(par.constraint_value_and_gradient([31.0, -1.0]).0 > 0.0);
}

#[test]
fn obstacle_across_the_centre_line_goes_to_the_roomier_side() {
    let path = straight();
    let s = ObstacleSettings::default();
    // More room on the right (3.5 m) than on the left (2.5 m).
    let o = boxed(60.0, 62.0, -0.5, 1.5);
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Right);
    check_minimal(&par, &o, &s);
    // Mirror image: more room on the left.
    let o2 = boxed(60.0, 62.0, -1.5, 0.5);
    let par2 = build_parabola(&s, &path, 0, &o2).unwrap();
    assert_eq!(par2.side, Side::Left);
    check_minimal(&par2, &o2, &s);
    assert!((par2.eta_apex_m + par.eta_apex_m).abs() < 1e-9);
    assert!((par2.xi0_m - par.xi0_m).abs() < 1e-9);
}

#[test]
fn irregular_obstacle_apex_is_off_centre_and_minimal() {
    let path = straight();
    let s = ObstacleSettings::default();
    let o = Obstacle::from_vertices(
        3,
        &[
            [10.0, -3.5],
            [14.0, -1.0],
            [15.0, -2.0],
            [22.0, -2.6],
            [18.0, -3.9],
        ],
    )
    .unwrap();
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Left);
    check_minimal(&par, &o, &s);
}

#[test]
fn blocked_road_reports_the_obstacle_and_the_missing_room() {
    let path = straight();
    let s = ObstacleSettings::default();
    let o = boxed(80.0, 82.0, -3.0, 3.0);
    let e = build_parabola(&s, &path, 4, &o).unwrap_err();
    match e {
        ObstacleError::RoadBlocked {
            obstacle,
            missing_m,
        } => {
            assert_eq!(obstacle, 4);
            // 1 m free each side, 2.1 m needed.
            assert!((missing_m - (s.required_room_m() - 1.0)).abs() < 1e-9);
        }
        other => panic!("{other:?}"),
    }
    // The manager keeps a best-effort parabola and reports the error.
    let mut m = ObstacleManager::new();
    let r = m.update(&s, &path, &[boxed(48.0, 52.0, -3.0, -1.5), o]);
    assert!(matches!(
        r,
        Err(ObstacleError::RoadBlocked { obstacle: 1, .. })
    ));
    assert_eq!(m.parabolas().len(), 2);
    // Only the blocking one is marked, with its stop before the near face
    // (X = 80 m): half the car's length and the stop clearance before it.
    let [free, blocking] = [m.parabolas()[0], m.parabolas()[1]];
    assert!(!free.blocks_road);
    assert!(blocking.blocks_road);
    let stop_s = blocking.s_m + blocking.stop_xi_m;
    let want = 180.0 - s.half_car_length_m - s.stop_clearance_m;
    assert!((stop_s - want).abs() < 1e-9, "{stop_s} vs {want}");
}

#[test]
fn a_blocking_obstacle_caps_the_speed_to_a_stop_before_it() {
    // The box of X 80..82 m across the whole road: s 180..182 m on `straight()`.
    let path = straight();
    let v = VelocityPlannerSettings::<f64>::default();
    let s = ObstacleSettings::default();
    let mut m = ObstacleManager::new();
    let r = m.update(&s, &path, &[boxed(80.0, 82.0, -3.0, 3.0)]);
    assert!(matches!(r, Err(ObstacleError::RoadBlocked { .. })));
    let par = m.parabolas()[0];
    let stop = par.s_m + par.stop_xi_m;
    let (_, far) = par.s_range_m();
    let decel = 4.0;
    let cap = |s_node: f64| obstacle_speed_cap(&v, &path, &[par], s_node, 20.0, decel, 0.3);
    // The braking curve sqrt(2·a·gap) before the stop, 0 from it to the far end
    // of the parabola's range, nothing past it.
    for gap in [50.0, 12.5, 2.0, 0.5] {
        let want = (2.0 * decel * gap).sqrt();
        assert!((cap(stop - gap) - want).abs() < 1e-9, "{gap} m before");
    }
    assert_eq!(cap(stop), 0.0);
    assert_eq!(cap(181.0), 0.0);
    assert_eq!(cap(far - 0.01), 0.0);
    assert_eq!(cap(far + 0.01), f64::INFINITY);
    // A car too fast to stop is capped at every node all the same (never above
    // the curve), and the cap falls monotonically towards the stop.
    let mut last = f64::INFINITY;
    for k in 0..100 {
        let c = cap(stop - 100.0 + k as f64);
        assert!(c <= last, "not monotone at {k}");
        last = c;
    }
}

#[test]
fn bad_vertices_are_errors() {
    let path = straight();
    let s = ObstacleSettings::default();
    let o = Obstacle::from_vertices(2, &[[1.0, 1.0], [2.0, f64::NAN]]).unwrap();
    assert_eq!(
        build_parabola(&s, &path, 5, &o),
        Err(ObstacleError::NonFiniteVertex {
            obstacle: 5,
            vertex: 1
        })
    );
    let empty = Obstacle::from_vertices(2, &[]).unwrap();
    assert_eq!(
        build_parabola(&s, &path, 0, &empty),
        Err(ObstacleError::NoVertices { obstacle: 0 })
    );
    assert!(matches!(
        Obstacle::from_vertices(2, &[[0.0, 0.0]; 9]),
        Err(ObstacleError::TooManyVertices { count: 9, .. })
    ));
    let bad = ObstacleSettings {
        steepness_1pm: 0.0,
        ..s
    };
    assert_eq!(
        build_parabola(&bad, &path, 0, &boxed(0.0, 1.0, -3.0, -2.0)),
        Err(ObstacleError::InvalidSettings)
    );
    // A negative or infinite length is refused too, not only a flat parabola.
    for bad in [
        ObstacleSettings {
            half_car_width_m: -0.5,
            ..s
        },
        ObstacleSettings {
            lateral_buffer_m: f64::INFINITY,
            ..s
        },
        ObstacleSettings {
            stop_clearance_m: f64::NAN,
            ..s
        },
    ] {
        assert_eq!(
            build_parabola(&bad, &path, 0, &boxed(0.0, 1.0, -3.0, -2.0)),
            Err(ObstacleError::InvalidSettings)
        );
    }
    let empty_path: ReferencePath<f64, 8> = ReferencePath::new();
    assert_eq!(
        build_parabola(&s, &empty_path, 0, &boxed(0.0, 1.0, -3.0, -2.0)),
        Err(ObstacleError::PathEmpty)
    );
    let many = vec![boxed(0.0, 1.0, -3.0, -2.0); MAX_OBSTACLES + 1];
    let mut m = ObstacleManager::new();
    assert!(matches!(
        m.update(&s, &path, &many),
        Err(ObstacleError::TooManyObstacles { count: 17, .. })
    ));
    assert_eq!(m.parabolas().len(), MAX_OBSTACLES);
}

#[test]
fn gradient_matches_finite_differences() {
    let path = straight();
    let s = ObstacleSettings::default();
    for o in [boxed(48.0, 52.0, -3.0, -1.5), boxed(30.0, 31.0, 1.0, 2.0)] {
        let par = build_parabola(&s, &path, 0, &o).unwrap();
        for p in [[40.0, 0.5], [55.0, -2.0], [50.0, 3.0]] {
            let (_, grad) = par.constraint_value_and_gradient(p);
            let h = 1e-6;
            let gx = (par.constraint_value_and_gradient([p[0] + h, p[1]]).0
                - par.constraint_value_and_gradient([p[0] - h, p[1]]).0)
                / (2.0 * h);
            let gy = (par.constraint_value_and_gradient([p[0], p[1] + h]).0
                - par.constraint_value_and_gradient([p[0], p[1] - h]).0)
                / (2.0 * h);
            assert!((gx - grad[0]).abs() < 1e-6 && (gy - grad[1]).abs() < 1e-6);
        }
    }
}

#[test]
fn relevance_window_covers_where_the_region_reaches_the_road() {
    let path = straight();
    let s = ObstacleSettings::default();
    let par = build_parabola(&s, &path, 0, &boxed(48.0, 52.0, -3.0, -1.5)).unwrap();
    assert!(par.reaches_road);
    let (a, b) = par.s_range_m();
    // The boundary meets the right road edge (η = −4) at the ends of the range.
    let r = ((par.eta_apex_m + 4.0) / s.steepness_1pm).sqrt();
    assert!((b - a - 2.0 * r).abs() < 1e-9);
    // s = X + 100 on this path.
    assert!(par.is_relevant([50.0, 0.0]) && par.is_relevant_at_s(&path, 150.0));
    assert!(!par.is_relevant([50.0 + r + 1.0, 0.0]));
    assert!(!par.is_relevant_at_s(&path, 150.0 - r - 1.0));
    assert!(par.overlaps_s_window(&path, 100.0, 140.0));
    assert!(!par.overlaps_s_window(&path, 180.0, 220.0));
    // An obstacle off the road never matters.
    let off = build_parabola(&s, &path, 0, &boxed(48.0, 52.0, -12.0, -10.0)).unwrap();
    assert!(!off.reaches_road && !off.is_relevant([50.0, -6.0]));
}

#[test]
fn curved_closed_path_frame_and_wrap() {
    // Circle of radius 50 m, counter-clockwise, default widths (3.5 m).
    let path = circle_path(50.0);
    let s = ObstacleSettings::default();
    // Obstacle outside the circle (to the right of a left turn) at angle 1 rad.
    let a: f64 = 1.0;
    let o = Obstacle::from_vertices(
        9,
        &[
            [52.0 * a.cos(), 52.0 * a.sin()],
            [53.0 * (a + 0.02).cos(), 53.0 * (a + 0.02).sin()],
            [53.0 * a.cos(), 53.0 * a.sin()],
        ],
    )
    .unwrap();
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Left);
    check_minimal(&par, &o, &s);
    assert!((par.s_m - 50.0 * a).abs() < 0.5);
    let l = path.length_m();
    assert!(par.is_relevant_at_s(&path, par.s_m + 3.0 * l));
    assert!(par.overlaps_s_window(&path, par.s_m + 2.0 * l - 10.0, par.s_m + 2.0 * l + 5.0));
}

#[test]
fn f32_parabolas_are_deterministic() {
    let pts: Vec<[f32; 2]> = (0..=30).map(|i| [-100.0 + 10.0 * i as f32, 0.0]).collect();
    let mut path: ReferencePath<f32, 64> = ReferencePath::new();
    path.load(&pts, None, false).unwrap();
    let s = ObstacleSettings::<f32>::default();
    let o = Obstacle::from_vertices(1, &[[48.0f32, -3.0], [52.0, -3.0], [50.0, -1.5]]).unwrap();
    let a = build_parabola(&s, &path, 0, &o).unwrap();
    let b = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    assert!((a.eta_apex_m - (-1.5 + 1.2 + 0.02 * 2.3 * 2.3)).abs() < 1e-5);
}

proptest! {
    #[test]
    fn minimal_apex_is_the_global_minimum(
        pts in proptest::collection::vec((-20.0f64..20.0, -5.0f64..5.0), 1..16),
        c in 0.005f64..0.5,
    ) {
        let (x0, a) = minimal_apex(&pts, c).unwrap();
        let f = |x: f64| pts.iter().map(|(xi, e)| e + c * (xi - x).powi(2)).fold(f64::NEG_INFINITY, f64::max);
        prop_assert!((f(x0) - a).abs() < 1e-12);
        for k in -2000..=2000 {
            let x = k as f64 * 0.02;
            prop_assert!(f(x) >= a - 1e-9);
        }
    }
}

#[test]
fn linearised_half_plane_is_tangent_and_conservative_outside() {
    let path = straight();
    let s = ObstacleSettings::default();
    let par = build_parabola(&s, &path, 0, &boxed(48.0, 52.0, -3.0, -1.5)).unwrap();
    let p_bar = [44.0, 0.5];
    let (n, r) = par.linearized_half_plane(p_bar);
    let (g, _) = par.constraint_value_and_gradient(p_bar);
    assert!((n[0] * p_bar[0] + n[1] * p_bar[1] - r - g).abs() < 1e-12);
    // g is convex in p, so its linearisation under-estimates it: any point the
    // half-plane allows is outside the parabola.
    for k in 0..200 {
        let q = [30.0 + 0.2 * k as f64, -4.0 + 0.04 * k as f64];
        if n[0] * q[0] + n[1] * q[1] >= r {
            assert!(!par.contains(q), "{q:?}");
        }
    }
}

/// The speed cap near obstacles binds where the car must swerve towards the inside
/// of a bend (the obstacle on its outside), at `sqrt(a_y,lim/(κ + 2c))`; an obstacle
/// on the inside, one on a straight, and one beside the centre line that needs no
/// swerve leave the car above its top speed.
#[test]
fn speed_cap_binds_only_for_an_obstacle_on_the_outside_of_a_bend() {
    let r = 50.0;
    let bend = circle_path(r);
    let v_max = 25.0;
    let s = ObstacleSettings::for_vehicle(1.8, 4.45, 1.0, v_max);
    let vel = VelocityPlannerSettings::default();
    let ay_lim = 0.5 * 9.81;
    let box_at = |path: &ReferencePath<f64, 256>, s_m: f64, lateral: f64| {
        let p = path.position_at(s_m);
        let h = path.heading_at(s_m);
        let n = [-h.sin(), h.cos()];
        let c = [p[0] + lateral * n[0], p[1] + lateral * n[1]];
        let v: Vec<[f64; 2]> = [[-1.0, -0.5], [1.0, -0.5], [1.0, 0.5], [-1.0, 0.5]]
            .iter()
            .map(|d| {
                [
                    c[0] + d[0] * h.cos() - d[1] * h.sin(),
                    c[1] + d[0] * h.sin() + d[1] * h.cos(),
                ]
            })
            .collect();
        Obstacle::from_vertices(1, &v).unwrap()
    };
    let cap = |path: &ReferencePath<f64, 256>, o: &Obstacle<f64>| {
        let par = build_parabola(&s, path, 0, o).unwrap();
        (
            par,
            obstacle_speed_cap(&vel, path, &[par], 40.0, 20.0, ay_lim, 0.2),
        )
    };
    // 1 m right of the centre line of a left bend: the car passes on its left, the
    // inside; its swerve adds to the bend.
    let (par, outside) = cap(&bend, &box_at(&bend, 60.0, -1.0));
    assert_eq!(par.side, Side::Left);
    let expected = (ay_lim / (1.0 / r + 2.0 * s.steepness_1pm)).sqrt();
    assert!(
        (outside - expected).abs() < 0.05 * expected,
        "{outside} vs {expected}"
    );
    assert!(outside < v_max);
    // 1 m left of it (the inside): the car passes on the outside, no cap below
    // `V_max·√2` (the boundary's own curvature alone).
    let (par, inside) = cap(&bend, &box_at(&bend, 60.0, 1.0));
    assert_eq!(par.side, Side::Right);
    assert!(inside > v_max, "{inside}");
    // Far beside the centre line (the centre line stays free): no swerve, no cap.
    let (_, aside) = cap(&bend, &box_at(&bend, 60.0, -3.0));
    assert!(aside.is_infinite(), "{aside}");
    // Out of the preview window: no cap.
    assert!(obstacle_speed_cap(&vel, &bend, &[par], 200.0, 20.0, ay_lim, 0.2).is_infinite());
}

#[test]
fn settings_for_a_vehicle_by_hand() {
    // c = a_y / (2·V²).
    assert_eq!(ObstacleSettings::<f64>::steepness_for(2.0, 10.0), 0.01);
    // A car 2 m wide and 5 m long (not the defaults' 1.8 × 4.6), at 20 m/s on
    // μ = 0.5: a quarter of μ·g.
    let s = ObstacleSettings::<f64>::for_vehicle(2.0, 5.0, 0.5, 20.0);
    assert_eq!(s.half_car_width_m, 1.0);
    assert_eq!(s.half_car_length_m, 2.5);
    let ay = 0.25 * 0.5 * f64::from(firmware::G);
    assert!((s.steepness_1pm - ay / (2.0 * 20.0 * 20.0)).abs() < 1e-15);
    // Below 5 m/s the parabola is shaped for 5 m/s.
    let slow = ObstacleSettings::<f64>::for_vehicle(2.0, 5.0, 0.5, 1.0);
    assert!((slow.steepness_1pm - ay / (2.0 * 5.0 * 5.0)).abs() < 1e-15);
    // The room the car needs beside an obstacle: its margin (half width and
    // buffer) and its half width again.
    assert_eq!(s.required_room_m(), (1.0 + s.lateral_buffer_m) + 1.0);
    // The other fields are the defaults.
    let d = ObstacleSettings::<f64>::default();
    assert_eq!(s.lateral_buffer_m, d.lateral_buffer_m);
    assert_eq!(s.default_half_width_m, d.default_half_width_m);
}

#[test]
fn an_obstacle_with_the_most_vertices_is_inside_its_parabola() {
    // A regular polygon of MAX_VERTICES vertices, radius 1 m, 2.5 m right of the
    // centre line, listed from its far side: the vertices that shape the parabola
    // (nearest the centre line) come last, so each of the inflated points (two per
    // vertex) must be kept.
    let path = straight();
    let s = ObstacleSettings::default();
    let v: Vec<[f64; 2]> = (0..MAX_VERTICES)
        .map(|k| {
            let a = PI + 0.3 + 2.0 * PI * k as f64 / MAX_VERTICES as f64;
            [50.0 + a.cos(), -2.5 + a.sin()]
        })
        .collect();
    let o = Obstacle::from_vertices(3, &v).unwrap();
    let par = build_parabola(&s, &path, 0, &o).unwrap();
    assert_eq!(par.side, Side::Left);
    check_minimal(&par, &o, &s);
}

/// A parabola in a frame turned by `angle` rad, on `side`, with round numbers.
fn turned(angle: f64, side: Side) -> Parabola<f64> {
    Parabola {
        obstacle: 0,
        id: 1,
        s_m: 0.0,
        origin_m: [10.0, -20.0],
        tangent: [angle.cos(), angle.sin()],
        side,
        xi0_m: 3.0,
        eta_apex_m: 1.0,
        steepness_1pm: 0.5,
        xi_min_m: -10.0,
        xi_max_m: 10.0,
        reaches_road: true,
        outside_kappa_1pm: 0.0,
        blocks_road: false,
        stop_xi_m: 0.0,
    }
}

#[test]
fn gradient_matches_finite_differences_in_a_turned_frame() {
    // The straight path's frame is the global one (t = [1, 0]), where a wrong
    // sign or product on a tangent component cannot show.
    for side in [Side::Left, Side::Right] {
        let par = turned(0.7, side);
        for p in [[12.0, -18.0], [15.0, -25.0], [5.0, -19.0]] {
            let (_, grad) = par.constraint_value_and_gradient(p);
            let h = 1e-6;
            let g = |q: [f64; 2]| par.constraint_value_and_gradient(q).0;
            let gx = (g([p[0] + h, p[1]]) - g([p[0] - h, p[1]])) / (2.0 * h);
            let gy = (g([p[0], p[1] + h]) - g([p[0], p[1] - h])) / (2.0 * h);
            assert!(
                (gx - grad[0]).abs() < 1e-6 && (gy - grad[1]).abs() < 1e-6,
                "{side:?} at {p:?}: {grad:?} vs ({gx}, {gy})"
            );
        }
    }
}

#[test]
fn contains_is_strictly_inside() {
    // In the global frame (angle 0), g = σ·(η − 1) + 0.5·(ξ − 3)² with the
    // origin at (10, −20): the apex is (13, −19), where g = 0 exactly.
    let par = turned(0.0, Side::Left);
    assert_eq!(par.constraint_value_and_gradient([13.0, -19.0]).0, 0.0);
    assert!(!par.contains([13.0, -19.0]), "the boundary is not inside");
    assert!(par.contains([13.0, -19.5]), "below the apex is inside");
    assert!(!par.contains([13.0, -18.0]), "above the apex is outside");
    // On the other side the forbidden region is above the apex.
    let right = turned(0.0, Side::Right);
    assert!(right.contains([13.0, -18.5]));
    assert!(!right.contains([13.0, -19.5]));
}

/// A parabola across the straight path at s = 150 m (X = 50 m), reaching the
/// road from ξ = −10 to +10 m, on `side` with apex `eta_m`: a swerve when the
/// apex, moved by the planner's offset buffer, is on the far side of the centre
/// line.
fn across(side: Side, eta_m: f64) -> Parabola<f64> {
    Parabola {
        s_m: 150.0,
        origin_m: [50.0, 0.0],
        tangent: [1.0, 0.0],
        side,
        xi0_m: 0.0,
        eta_apex_m: eta_m,
        steepness_1pm: 0.02,
        xi_min_m: -10.0,
        xi_max_m: 10.0,
        outside_kappa_1pm: 0.01,
        ..turned(0.0, side)
    }
}

#[test]
fn speed_cap_by_hand() {
    let path = straight();
    let v = VelocityPlannerSettings::<f64>::default();
    // a_y 5 m/s² over κ = 0.01 + 2·0.02 = 0.05 1/m: 10 m/s.
    let cap = |p: Parabola<f64>, s_node: f64, buffer: f64| {
        obstacle_speed_cap(&v, &path, &[p], s_node, 10.0, 5.0, buffer)
    };
    let d = v.preview_distance_m(10.0);
    assert!(d > 0.0 && d < 100.0);
    let near = 150.0 - d / 2.0;
    // Passed on the left: a swerve when η_a + buffer > 0.
    assert_eq!(cap(across(Side::Left, 0.2), near, 0.0), 10.0);
    assert_eq!(cap(across(Side::Left, -0.3), near, 0.5), 10.0);
    assert_eq!(cap(across(Side::Left, -0.5), near, 0.5), f64::INFINITY);
    assert_eq!(cap(across(Side::Left, -0.8), near, 0.5), f64::INFINITY);
    // Passed on the right: a swerve when η_a − buffer < 0.
    assert_eq!(cap(across(Side::Right, 0.3), near, 0.5), 10.0);
    assert_eq!(cap(across(Side::Right, 0.5), near, 0.5), f64::INFINITY);
    assert_eq!(cap(across(Side::Right, 0.8), near, 0.5), f64::INFINITY);
    // Only where the preview [s, s + d] meets the parabola's [140, 160] m.
    assert_eq!(cap(across(Side::Left, 0.2), 161.0, 0.0), f64::INFINITY);
    assert_eq!(
        cap(across(Side::Left, 0.2), 140.0 - d - 1.0, 0.0),
        f64::INFINITY
    );
    assert_eq!(cap(across(Side::Left, 0.2), 140.0 - d + 1.0, 0.0), 10.0);
}

/// A failure of a test step, as text (the tests below return `Result`).
fn text<E: core::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

/// Settings with binary-exact lengths (`m_y` = 1 m, room needed 1.75 m,
/// `c` = 0.25 1/m, half length 2 m) so that ties are exact.
fn exact_settings() -> ObstacleSettings<f64> {
    ObstacleSettings {
        steepness_1pm: 0.25,
        half_car_width_m: 0.75,
        lateral_buffer_m: 0.25,
        half_car_length_m: 2.0,
        default_half_width_m: 3.5,
        stop_clearance_m: 2.0,
    }
}

#[test]
fn the_frame_starts_at_the_vertex_nearest_the_path_when_all_are_on_one_side() -> Result<(), String>
{
    // On `straight()` s = X + 100. The centroid of each triangle is at
    // X = 46.67 m (s = 146.67 m).
    let path = straight();
    let s = ObstacleSettings::default();
    let frame_s = |v: &[[f64; 2]]| -> Result<f64, String> {
        let o = Obstacle::from_vertices(1, v).map_err(text)?;
        Ok(build_parabola(&s, &path, 0, &o).map_err(text)?.s_m)
    };
    let centroid = 100.0 + 140.0 / 3.0;
    for (v, want, what) in [
        // All left (right): the nearest vertex, the first of two at 1 m.
        ([[40.0, 1.0], [50.0, 1.0], [50.0, 3.0]], 140.0, "all left"),
        (
            [[40.0, -1.0], [50.0, -1.0], [50.0, -3.0]],
            140.0,
            "all right",
        ),
        // Across the centre line: the centroid's foot point.
        ([[40.0, 1.0], [50.0, -0.5], [50.0, 3.0]], centroid, "across"),
        (
            [[40.0, -1.0], [50.0, 0.5], [50.0, -3.0]],
            centroid,
            "across",
        ),
        // A vertex on the centre line is on neither side.
        (
            [[40.0, 0.0], [50.0, 1.0], [50.0, 3.0]],
            centroid,
            "touching, left",
        ),
        (
            [[40.0, 0.0], [50.0, -1.0], [50.0, -3.0]],
            centroid,
            "touching, right",
        ),
    ] {
        let got = frame_s(&v)?;
        if (got - want).abs() > 1e-9 {
            return Err(format!("{what}: frame at s = {got}, want {want}"));
        }
    }
    Ok(())
}

#[test]
fn exactly_the_room_needed_is_not_blocked() -> Result<(), String> {
    let path = straight();
    let s = exact_settings();
    assert_eq!(s.required_room_m(), 1.75);
    // 4 − 2.25 = 1.75 m free on each side.
    let fits = build_parabola(&s, &path, 0, &boxed(60.0, 62.0, -2.25, 2.25));
    assert!(fits.is_ok(), "{fits:?}");
    // 1/64 m less on the roomier side is blocked by that much.
    let tight = build_parabola(&s, &path, 3, &boxed(60.0, 62.0, -2.265625, 2.265625));
    assert_eq!(
        tight.map(|p| p.side),
        Err(ObstacleError::RoadBlocked {
            obstacle: 3,
            missing_m: 0.015625
        })
    );
    Ok(())
}

#[test]
fn a_region_that_only_touches_the_road_edge_does_not_reach_the_road() -> Result<(), String> {
    // One vertex 6 m right of the centre line, passed on the left (σ = 1):
    // points (±2, −6 + 1), apex −5 + c·2² = −4: exactly the right edge.
    let path = straight();
    let s = exact_settings();
    let touching = Obstacle::from_vertices(1, &[[50.0, -6.0]]).map_err(text)?;
    let p = build_parabola(&s, &path, 0, &touching).map_err(text)?;
    assert_eq!((p.side, p.eta_apex_m), (Side::Left, -4.0));
    assert!(!p.reaches_road);
    assert!(!p.is_relevant_at_s(&path, 150.0));
    assert_eq!(p.relevant_s_at(&path, 150.0), None);
    // Half a metre closer: it reaches 2·sqrt(0.5/c) = 2.83 m of road.
    let reaching = Obstacle::from_vertices(1, &[[50.0, -5.5]]).map_err(text)?;
    let p = build_parabola(&s, &path, 0, &reaching).map_err(text)?;
    assert!(p.reaches_road);
    assert!((p.xi_max_m - p.xi_min_m - 2.0 * 2.0f64.sqrt()).abs() < 1e-12);
    Ok(())
}

#[test]
fn the_manager_takes_as_many_obstacles_as_it_holds_and_clears() -> Result<(), String> {
    let path = straight();
    let s = ObstacleSettings::default();
    let full: Vec<Obstacle<f64>> = (0..MAX_OBSTACLES)
        .map(|k| boxed(10.0 * k as f64, 10.0 * k as f64 + 1.0, -3.0, -2.0))
        .collect();
    let mut m = ObstacleManager::new();
    assert_eq!(m.update(&s, &path, &full), Ok(()));
    assert_eq!(m.parabolas().len(), MAX_OBSTACLES);
    m.clear();
    assert!(m.parabolas().is_empty());
    Ok(())
}

#[test]
fn at_a_tie_the_apex_is_the_first_candidate() {
    // At 1e20 m, c·d² ≤ 1 is below the rounding: every candidate (the two
    // points, their crossing at 0.5) gives the same height; the first (the
    // first point's abscissa) is kept.
    assert_eq!(
        minimal_apex(&[(0.0, 1e20), (1.0, 1e20)], 1.0),
        Some((0.0, 1e20))
    );
}

/// `relevant_s_at` against `is_relevant_at_s` and `unwrap_s` over ±1 km of node
/// abscissae round the parabola: (nodes where it is relevant, where it is not).
fn relevant_s_at_agrees<const CAP: usize>(
    p: &Parabola<f64>,
    path: &ReferencePath<f64, CAP>,
) -> Result<(usize, usize), String> {
    let (mut some, mut none) = (0, 0);
    for k in -2000..=2000 {
        let sn = p.s_m + 0.5 * k as f64;
        let want = if p.is_relevant_at_s(path, sn) {
            some += 1;
            Some(path.unwrap_s(sn, p.s_m))
        } else {
            none += 1;
            None
        };
        let got = p.relevant_s_at(path, sn);
        if got != want {
            return Err(format!("at s = {sn}: {got:?}, want {want:?}"));
        }
    }
    Ok((some, none))
}

#[test]
fn relevant_s_at_is_the_unwrapped_abscissa_where_the_parabola_is_relevant() -> Result<(), String> {
    // Circle of radius 50 m (closed, L = 314 m) and the straight open path.
    let circle = circle_path(50.0);
    let s = ObstacleSettings::default();
    let o = Obstacle::from_vertices(9, &[[52.0, 0.5], [53.0, 1.5], [53.0, -0.5]]).map_err(text)?;
    let on_circle = build_parabola(&s, &circle, 0, &o).map_err(text)?;
    let (some, none) = relevant_s_at_agrees(&on_circle, &circle)?;
    // Relevant on each of the 7 laps the nodes cover, not everywhere.
    assert!(some > 7 && none > some, "{some} / {none}");
    let line = straight();
    let on_line = build_parabola(&s, &line, 0, &boxed(48.0, 52.0, -3.0, -1.5)).map_err(text)?;
    let (some, none) = relevant_s_at_agrees(&on_line, &line)?;
    assert!(some > 0 && none > some, "{some} / {none}");
    // Off the road: relevant nowhere.
    let off = build_parabola(&s, &line, 0, &boxed(48.0, 52.0, -12.0, -10.0)).map_err(text)?;
    assert_eq!(relevant_s_at_agrees(&off, &line)?.0, 0);
    Ok(())
}

#[test]
fn a_parabola_longer_than_half_a_lap_overlaps_a_window_half_a_lap_behind_it() -> Result<(), String>
{
    // Circle of radius 20 m (L = 125.7 m), a flat parabola (c = 0.0015 1/m)
    // whose apex is ahead of its frame's origin (the obstacle's vertex nearest
    // the centre line is ahead of its centroid): its range reaches more than
    // half a lap ahead, past the point half a lap behind its origin.
    let circle = circle_path(20.0);
    let polar = |r: f64, a: f64| [r * a.cos(), r * a.sin()];
    let o = Obstacle::from_vertices(
        4,
        &[
            polar(19.5, 0.0),
            polar(22.0, -0.3),
            polar(23.0, -0.3),
            polar(22.5, -0.25),
        ],
    )
    .map_err(text)?;
    let s = ObstacleSettings {
        steepness_1pm: 0.0015,
        ..ObstacleSettings::default()
    };
    let p = build_parabola(&s, &circle, 0, &o).map_err(text)?;
    let l = circle.length_m();
    let (a, b) = p.s_range_m();
    let behind = p.s_m - 0.5 * l;
    // The window [behind + 0.25, behind + 0.5]: one lap on it is in the range,
    // on this lap it ends before the range begins.
    if !(p.reaches_road && b - l > behind + 0.5 && a > behind + 0.5 && b - a < l - 0.4) {
        return Err(format!("s = {}, range [{a}, {b}], L = {l}", p.s_m));
    }
    assert!(p.overlaps_s_window(&circle, behind + 0.25, behind + 0.5));
    // Between the range's end and its start one lap on it does not.
    assert!(!p.overlaps_s_window(&circle, b + 0.1, b + 0.2));
    Ok(())
}

#[test]
fn the_outside_curvature_is_the_road_s_within_the_parabola_s_range() -> Result<(), String> {
    // Open road: a sharp left bend (κ = 0.05 1/m) on [0, 40) m, straight, a
    // gentle left bend (0.02) on [180, 200), straight, a sharp one on
    // [300, 330), straight to 340 m. An obstacle on the right in the gentle
    // bend, at s = 190 m: its parabola's range (±14 m) holds that bend alone.
    let kappa = |s: f64| match s {
        s if s < 40.0 => 0.05,
        s if (180.0..200.0).contains(&s) => 0.02,
        s if (300.0..330.0).contains(&s) => 0.05,
        _ => 0.0,
    };
    // Every 0.5 m: position and heading.
    let mut fine = vec![([0.0f64, 0.0f64], 0.0f64)];
    for k in 0..680 {
        let (p, th) = fine[k];
        let mid = th + 0.5 * kappa(0.5 * k as f64 + 0.25) * 0.5;
        let next = th + kappa(0.5 * k as f64 + 0.25) * 0.5;
        fine.push(([p[0] + 0.5 * mid.cos(), p[1] + 0.5 * mid.sin()], next));
    }
    let pts: Vec<[f64; 2]> = fine.iter().step_by(4).map(|(p, _)| *p).collect();
    let mut road: ReferencePath<f64, 256> = ReferencePath::new();
    road.load(&pts, None, false).map_err(text)?;
    let at = |s: f64, lat: f64| {
        let (p, th) = fine[(2.0 * s) as usize];
        [p[0] - lat * th.sin(), p[1] + lat * th.cos()]
    };
    let mut o = Obstacle::from_vertices(
        2,
        &[
            at(188.0, -1.5),
            at(192.0, -1.5),
            at(192.0, -3.0),
            at(188.0, -3.0),
        ],
    )
    .map_err(text)?;
    o.s_hint_m = Some(190.0);
    let p = build_parabola(&ObstacleSettings::default(), &road, 0, &o).map_err(text)?;
    let (a, b) = p.s_range_m();
    if !(p.side == Side::Left && 41.0 < a && a < 179.0 && 201.0 < b && b < 299.0) {
        return Err(format!("{:?}, range [{a}, {b}]", p.side));
    }
    assert!(
        (p.outside_kappa_1pm - 0.02).abs() < 0.003,
        "{}",
        p.outside_kappa_1pm
    );
    Ok(())
}
