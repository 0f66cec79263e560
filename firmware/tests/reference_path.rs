//! Tests of the reference path: arc length, heading, curvature, projection, errors.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use core::f64::consts::PI;
use firmware::reference_path::{
    CurvatureWindow, PathError, ReferencePath, MAX_CURVATURE_WINDOW_STEPS,
};
use proptest::prelude::*;

fn circle(r: f64, n: usize, ccw: bool) -> Vec<[f64; 2]> {
    (0..n)
        .map(|i| {
            let a = 2.0 * PI * i as f64 / n as f64;
            let a = if ccw { a } else { -a };
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn circle_length_heading_and_curvature() {
    let r = 50.0;
    let n = 100;
    let mut p: ReferencePath<f64, 256> = ReferencePath::new();
    p.load(&circle(r, n, true), None, true).unwrap();
    assert!(p.is_closed());
    let chord = 2.0 * r * (PI / n as f64).sin();
    assert!(close(p.length_m(), chord * n as f64, 1e-9));
    assert!(close(p.total_turning_rad(), 2.0 * PI, 1e-9));
    for k in 0..37 {
        let s = k as f64 * 9.3;
        assert!(
            close(p.curvature_at(s), 1.0 / r, 1e-9),
            "s={s}: {}",
            p.curvature_at(s)
        );
    }
    // Heading at vertex 0 is tangent (+Y), grows by 2π per lap and is continuous.
    assert!(close(p.heading_at(0.0), PI / 2.0, 1e-9));
    let l = p.length_m();
    assert!(close(
        p.heading_at(10.0 + l),
        p.heading_at(10.0) + 2.0 * PI,
        1e-9
    ));
    let mut prev = p.heading_at(-l);
    for k in 1..2000 {
        let s = -l + k as f64 * 3.0 * l / 2000.0;
        let h = p.heading_at(s);
        assert!(h > prev && h - prev < 0.05, "s={s}");
        prev = h;
    }
}

#[test]
fn clockwise_circle_has_negative_curvature() {
    let mut p: ReferencePath<f64, 256> = ReferencePath::new();
    p.load(&circle(20.0, 60, false), None, true).unwrap();
    assert!(close(p.curvature_at(5.0), -1.0 / 20.0, 1e-9));
    assert!(close(p.total_turning_rad(), -2.0 * PI, 1e-9));
}

#[test]
fn noisy_circle_curvature_is_filtered_by_the_window() {
    // Points every ~0.5 m with ±2 cm of deterministic noise.
    let r = 30.0;
    let n = 377;
    let pts: Vec<[f64; 2]> = circle(r, n, true)
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let e = 0.02 * ((i * 7919 % 13) as f64 / 6.0 - 1.0);
            [q[0] * (1.0 + e / r), q[1] * (1.0 + e / r)]
        })
        .collect();
    let mut p: ReferencePath<f64, 512> = ReferencePath::new();
    p.set_curvature_half_window_m(4.0);
    p.load(&pts, None, true).unwrap();
    for k in 0..50 {
        let kappa = p.curvature_at(k as f64 * 3.7);
        assert!((kappa * r - 1.0).abs() < 0.1, "{kappa}");
    }
    // A window shorter than the noise scale would be much worse.
    let mut q: ReferencePath<f64, 512> = ReferencePath::new();
    q.set_curvature_half_window_m(0.01);
    q.load(&pts, None, true).unwrap();
    assert!((q.max_abs_curvature_1pm() * r - 1.0).abs() > 0.2);
}

#[test]
fn closing_duplicate_is_dropped_and_s_wraps() {
    let mut pts = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
    pts.push(pts[0]);
    let mut p: ReferencePath<f64, 8> = ReferencePath::new();
    p.load(&pts, None, true).unwrap();
    assert_eq!(p.len(), 4);
    assert!(close(p.length_m(), 40.0, 1e-12));
    assert_eq!(p.position_at(45.0), [5.0, 0.0]);
    assert_eq!(p.position_at(-5.0), [0.0, 5.0]);
    assert_eq!(p.position_at(35.0), [0.0, 5.0]);
    assert!(close(p.wrap_s(-5.0), 35.0, 1e-12));
    assert!(close(p.unwrap_s(1.0, 79.0), 81.0, 1e-12));
    assert!(close(p.unwrap_s(39.0, 41.0), 39.0, 1e-12));
}

#[test]
fn open_path_extrapolates_positions_and_clamps_the_rest() {
    let pts = [[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [20.0, 10.0]];
    let w = [[1.0, 2.0], [1.0, 2.0], [3.0, 4.0], [3.0, 4.0]];
    let mut p: ReferencePath<f64, 8> = ReferencePath::new();
    p.load(&pts, Some(&w), false).unwrap();
    assert!(!p.is_closed());
    assert!(close(p.length_m(), 30.0, 1e-12));
    assert_eq!(p.position_at(-3.0), [-3.0, 0.0]);
    assert_eq!(p.position_at(35.0), [20.0, 15.0]);
    assert!(close(p.heading_at(-3.0), 0.0, 1e-12));
    assert!(close(p.heading_at(100.0), PI / 2.0, 1e-12));
    assert!(close(p.heading_at(20.0), PI / 4.0, 1e-12));
    let wd = p.widths_at(15.0).unwrap();
    assert!(close(wd.right_m, 2.0, 1e-12) && close(wd.left_m, 3.0, 1e-12));
    // Left turn at the corner.
    assert!(p.curvature_at(20.0) > 0.0);
    assert!(close(p.curvature_at(5.0), 0.0, 1e-12));
}

#[test]
fn max_abs_curvature_between_sees_the_curve_ahead() {
    // Straight of 100 m then a left arc of radius 10 m (closed by a generic return).
    let mut pts = vec![];
    for i in 0..=50 {
        pts.push([2.0 * i as f64, 0.0]);
    }
    for k in 1..=30 {
        let a = PI * k as f64 / 30.0;
        pts.push([100.0 + 10.0 * a.sin(), 10.0 - 10.0 * a.cos()]);
    }
    let mut p: ReferencePath<f64, 128> = ReferencePath::new();
    p.load(&pts, None, false).unwrap();
    assert!(p.max_abs_curvature_between(0.0, 80.0) < 1e-9);
    let k = p.max_abs_curvature_between(50.0, 120.0);
    assert!(close(k, 0.1, 0.01), "{k}");
    assert!(close(p.max_abs_curvature_between(120.0, 50.0), k, 0.0));
    // Range beyond the end is clamped.
    assert!(close(p.max_abs_curvature_between(125.0, 1e4), 0.1, 0.01));
}

#[test]
fn signed_curvature_tells_left_bends_from_right_ones() {
    // Straight of 100 m, a left arc of radius 10 m, then a right arc of radius 20 m.
    let mut pts = vec![];
    for i in 0..=50 {
        pts.push([2.0 * i as f64, 0.0]);
    }
    for k in 1..=30 {
        let a = 0.5 * PI * k as f64 / 30.0;
        pts.push([100.0 + 10.0 * a.sin(), 10.0 - 10.0 * a.cos()]);
    }
    // From (110, 10) heading +Y, turning right about (130, 10).
    for k in 1..=30 {
        let a = 0.5 * PI * k as f64 / 30.0;
        pts.push([130.0 - 20.0 * a.cos(), 10.0 + 20.0 * a.sin()]);
    }
    let mut p: ReferencePath<f64, 256> = ReferencePath::new();
    p.load(&pts, None, false).unwrap();
    let left_end = 100.0 + 0.5 * PI * 10.0;
    // Over the left arc: the sharpest left bend is 1/10, no right bend at all.
    let l = p.max_signed_curvature_between(105.0, left_end - 3.0, 1.0);
    let r = p.max_signed_curvature_between(105.0, left_end - 3.0, -1.0);
    assert!(close(l, 0.1, 0.01) && r < 0.0, "{l} {r}");
    // Over both arcs: left 1/10, right 1/20; the absolute maximum is the left one.
    let l = p.max_signed_curvature_between(105.0, left_end + 20.0, 1.0);
    let r = p.max_signed_curvature_between(left_end + 20.0, 105.0, -1.0);
    assert!(close(l, 0.1, 0.01) && close(r, 0.05, 0.01), "{l} {r}");
    assert!(close(
        p.max_abs_curvature_between(105.0, left_end + 20.0),
        l,
        0.0
    ));
    // On the straight: no bend either way.
    assert!(p.max_signed_curvature_between(10.0, 80.0, 1.0).abs() < 1e-9);
}

#[test]
fn projection_of_a_circle_point() {
    let r = 50.0;
    let mut p: ReferencePath<f64, 512> = ReferencePath::new();
    p.load(&circle(r, 400, true), None, true).unwrap();
    let a: f64 = 1.0;
    let q = [(r + 2.0) * a.cos(), (r + 2.0) * a.sin()];
    let pr = p.project(q, None).unwrap();
    assert!(close(pr.s_m, r * a, 0.01), "{}", pr.s_m);
    assert!(close(pr.lateral_m, -2.0, 0.01));
    assert!(close(pr.heading_rad, a + PI / 2.0, 1e-3));
    assert!(close(pr.curvature_1pm, 1.0 / r, 1e-9));
    // With a hint two laps on, s stays on that lap.
    let pr2 = p
        .project(q, Some(r * a + 2.0 * p.length_m() + 3.0))
        .unwrap();
    assert!(close(pr2.s_m, pr.s_m + 2.0 * p.length_m(), 1e-9));
    assert!(close(pr2.heading_rad, pr.heading_rad + 4.0 * PI, 1e-9));
}

#[test]
fn hint_keeps_the_projection_on_the_right_branch() {
    // A hairpin: out along y = 0, back along y = 4.
    let mut pts = vec![];
    for i in 0..=100 {
        pts.push([i as f64, 0.0]);
    }
    for k in 1..20 {
        let a = PI * k as f64 / 20.0;
        pts.push([100.0 + 2.0 * a.sin(), 2.0 - 2.0 * a.cos()]);
    }
    for i in 0..=100 {
        pts.push([(100 - i) as f64, 4.0]);
    }
    let mut p: ReferencePath<f64, 256> = ReferencePath::new();
    p.load(&pts, None, false).unwrap();
    let q = [50.0, 1.5];
    let g = p.project(q, None).unwrap();
    assert!(close(g.s_m, 50.0, 1e-9) && close(g.lateral_m, 1.5, 1e-9));
    let s_back = 100.0 + PI * 2.0 + 50.0;
    let h = p.project(q, Some(s_back + 5.0)).unwrap();
    assert!((h.s_m - s_back).abs() < 0.1, "{}", h.s_m);
    assert!(close(h.lateral_m, 2.5, 1e-9));
    assert!(close(h.heading_rad, PI, 1e-9));
}

#[test]
fn load_errors_name_the_bad_point() {
    let mut p: ReferencePath<f64, 4> = ReferencePath::new();
    assert_eq!(
        p.load(&[[0.0, 0.0], [1.0, 0.0]], None, false),
        Err(PathError::TooFewPoints { count: 2 })
    );
    assert_eq!(
        p.load(&[[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]], None, true),
        Err(PathError::TooFewPoints { count: 2 })
    );
    assert_eq!(
        p.load(
            &[[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 1.0]],
            None,
            false
        ),
        Err(PathError::RepeatedPoint { index: 2 })
    );
    assert_eq!(
        p.load(&[[0.0, 0.0], [1.0, 0.0], [2.0, f64::NAN]], None, false),
        Err(PathError::NonFinite { index: 2 })
    );
    assert_eq!(
        p.load(
            &[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]],
            None,
            false
        ),
        Err(PathError::TooManyPoints {
            count: 5,
            capacity: 4
        })
    );
    // Five points of which the last closes the loop fit in 4.
    assert!(p
        .load(
            &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]],
            None,
            true
        )
        .is_ok());
    assert_eq!(
        p.load(
            &[[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]],
            Some(&[[1.0, 1.0], [1.0, -0.1], [1.0, 1.0]]),
            false
        ),
        Err(PathError::NegativeWidth { index: 1 })
    );
    assert_eq!(
        p.load_track(
            &[
                [0.0, 0.0, 1.0, 1.0],
                [1.0, 0.0, f64::INFINITY, 1.0],
                [2.0, 1.0, 1.0, 1.0]
            ],
            false
        ),
        Err(PathError::NonFinite { index: 1 })
    );
    assert_eq!(
        p.load(
            &[[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]],
            Some(&[[1.0, 1.0]]),
            false
        ),
        Err(PathError::WidthCountMismatch {
            points: 3,
            widths: 1
        })
    );
    // After an error the path is empty and queries stay defined.
    assert!(p.is_empty());
    assert_eq!(p.position_at(3.0), [0.0, 0.0]);
    assert!(p.project([1.0, 1.0], None).is_none());
    assert_eq!(p.max_abs_curvature_between(0.0, 10.0), 0.0);
}

#[test]
fn f32_path_in_a_static_like_const() {
    static EMPTY: ReferencePath<f32, 64> = ReferencePath::new();
    assert!(EMPTY.is_empty());
    let mut p: ReferencePath<f32, 64> = ReferencePath::new();
    let pts: Vec<[f32; 2]> = circle(25.0, 48, true)
        .iter()
        .map(|q| [q[0] as f32, q[1] as f32])
        .collect();
    p.load(&pts, None, true).unwrap();
    assert!((p.curvature_at(7.0) - 0.04).abs() < 1e-4);
    let pr = p.project([0.0, -24.0], Some(100.0)).unwrap();
    assert!((pr.lateral_m - 1.0).abs() < 1e-2);
}

proptest! {
    #[test]
    fn project_inverts_position_plus_normal_offset(s in 0.0f64..300.0, lat in -3.0f64..3.0) {
        // Closed loop: two straights and two half-circles of radius 20 m.
        let mut pts = vec![];
        for i in 0..50 { pts.push([i as f64 * 2.0, -20.0]); }
        for k in 0..40 { let a = PI * k as f64 / 40.0 - PI / 2.0; pts.push([100.0 + 20.0 * a.cos(), 20.0 * a.sin()]); }
        for i in 0..50 { pts.push([100.0 - i as f64 * 2.0, 20.0]); }
        for k in 0..40 { let a = PI * k as f64 / 40.0 + PI / 2.0; pts.push([20.0 * a.cos(), 20.0 * a.sin()]); }
        let mut p: ReferencePath<f64, 256> = ReferencePath::new();
        p.load(&pts, None, true).unwrap();
        // Offset along the normal of the segment containing s.
        let seg = p.project(p.position_at(s), Some(s)).unwrap();
        let v = p.vertex(seg.segment).unwrap();
        let w = p.vertex((seg.segment + 1) % p.len()).unwrap();
        let l = ((w[0] - v[0]).powi(2) + (w[1] - v[1]).powi(2)).sqrt();
        let n = [-(w[1] - v[1]) / l, (w[0] - v[0]) / l];
        let base = p.position_at(s);
        let q = [base[0] + lat * n[0], base[1] + lat * n[1]];
        let pr = p.project(q, Some(s)).unwrap();
        // Exact unless the offset point lies nearer a neighbouring segment (inside of a bend).
        prop_assert!((pr.lateral_m.abs() - lat.abs()).abs() < 1e-6 || pr.lateral_m.abs() < lat.abs());
        prop_assert!((pr.s_m - s).abs() < 0.2 * lat.abs() + 1e-6);
        prop_assert!(pr.lateral_m * lat >= -1e-9);
    }
}

/// `sample_at` gives exactly what the four single lookups give, on open and closed
/// paths, with and without widths, inside and outside `[0, L]`.
#[test]
fn sample_at_matches_the_single_lookups() {
    let pts = circle(30.0, 40, true);
    let half: Vec<[f64; 2]> = pts[..20].to_vec();
    let widths: Vec<[f64; 2]> = (0..20).map(|i| [2.0 + 0.1 * i as f64, 3.0]).collect();
    let mut closed: ReferencePath<f64, 64> = ReferencePath::new();
    closed.load(&pts, None, true).unwrap();
    let mut open: ReferencePath<f64, 64> = ReferencePath::new();
    open.load(&half, Some(&widths), false).unwrap();
    let empty: ReferencePath<f64, 64> = ReferencePath::new();
    for p in [&closed, &open, &empty] {
        for k in -30..300 {
            let s = k as f64 * 1.37;
            let a = p.sample_at(s);
            assert_eq!(a.position, p.position_at(s), "s={s}");
            assert_eq!(a.heading_rad.to_bits(), p.heading_at(s).to_bits(), "s={s}");
            assert_eq!(a.curvature_1pm.to_bits(), p.curvature_at(s).to_bits());
            assert_eq!(a.widths, p.widths_at(s), "s={s}");
        }
    }
}

proptest! {
    /// The sliding window's maximum equals the full scan's for every window of a
    /// sequence whose ends never move back (the MPC's nodes), on random wiggly
    /// closed and open paths, including windows that wrap past the start of a
    /// closed path, run off the end of an open one, or span more than a lap; a
    /// window whose ends move back starts afresh and still agrees.
    #[test]
    fn sliding_curvature_window_matches_the_full_scan(
        seed in 0u64..1_000,
        closed in any::<bool>(),
        start in -50.0f64..400.0,
        steps in proptest::collection::vec((0.0f64..6.0, 0.0f64..60.0), 1..20),
    ) {
        let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut rnd = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // A circle of radius 40 m with radial wiggles: curvature of both signs.
        let n = 60;
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let a = 2.0 * PI * i as f64 / n as f64;
                let r = 40.0 + 4.0 * (rnd() - 0.5);
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        let mut p: ReferencePath<f64, 128> = ReferencePath::new();
        p.load(&pts, None, closed).unwrap();
        let mut win = CurvatureWindow::new();
        let mut s0 = start;
        for (i, &(ds, len)) in steps.iter().enumerate() {
            // Every fifth window moves back: the window must start afresh.
            s0 = if i % 5 == 4 { s0 - ds } else { s0 + ds };
            let s1 = s0 + len;
            let at = p.sample_at(s0);
            let full = p.max_abs_curvature_from(&at, s0, s1);
            let slid = p.max_abs_curvature_window(&mut win, &at, s0, s1);
            prop_assert!(
                (slid - full).abs() <= 1e-12 * (1.0 + full.abs()),
                "window {i} [{s0}, {s1}]: sliding {slid} vs full {full}"
            );
        }
    }
}

proptest! {
    /// `project_each` gives, bit for bit, what one `project` per point gives with
    /// the same hint, on the hairpin (open: the end segments extended) and on a
    /// circle (closed: `s` unwrapped to the hint's lap), in f32 as on the ECU; a
    /// point not finite gives `None` and leaves the others; a hint not finite
    /// gives `None` for every point (it requires one).
    #[test]
    fn project_each_equals_one_projection_per_point(
        pts in proptest::collection::vec((-20.0f32..130.0, -30.0f32..30.0), 1..8),
        hint in -50.0f32..700.0,
        nan_at in 0usize..10,
        closed in any::<bool>(),
    ) {
        let path_pts: Vec<[f32; 2]> = if closed {
            circle(60.0, 90, true).iter().map(|p| [p[0] as f32 + 50.0, p[1] as f32]).collect()
        } else {
            let mut v: Vec<[f32; 2]> = (0..=100).map(|i| [i as f32, 0.0]).collect();
            v.extend((1..20).map(|k| {
                let a = core::f32::consts::PI * k as f32 / 20.0;
                [100.0 + 2.0 * a.sin(), 2.0 - 2.0 * a.cos()]
            }));
            v.extend((0..=100).map(|i| [(100 - i) as f32, 4.0]));
            v
        };
        let mut p: ReferencePath<f32, 256> = ReferencePath::new();
        p.load(&path_pts, None, closed).unwrap();
        let mut q: Vec<[f32; 2]> = pts.iter().map(|&(x, y)| [x, y]).collect();
        if nan_at < q.len() {
            q[nan_at][1] = f32::NAN;
        }
        let each: [Option<(f32, f32)>; 8] = p.project_each(&q, hint);
        for (k, v) in q.iter().enumerate() {
            let one = p.project(*v, Some(hint)).map(|r| (r.s_m.to_bits(), r.lateral_m.to_bits()));
            prop_assert_eq!(each[k].map(|(s, l)| (s.to_bits(), l.to_bits())), one, "point {}", k);
        }
        prop_assert!(each[q.len()..].iter().all(Option::is_none));
        // Points beyond K are not projected.
        let two: [Option<(f32, f32)>; 1] = p.project_each(&q, hint);
        prop_assert_eq!(two[0].map(|(s, _)| s.to_bits()), each[0].map(|(s, _)| s.to_bits()));
        let none: [Option<(f32, f32)>; 8] = p.project_each(&q, f32::NAN);
        prop_assert!(none.iter().all(Option::is_none));
    }
}

/// On a path whose points are closer than `h / MAX_CURVATURE_WINDOW_STEPS`, the
/// curvature window ends after that many segments: on the crest of a wiggle of
/// 2 m wavelength sampled every 2 cm, the circle is the one through the vertices
/// 32 segments away, not those 3 m of arc away (the default half-window).
#[test]
fn a_dense_path_ends_the_curvature_window_after_max_steps() {
    let d = 0.02;
    let pts: Vec<[f64; 2]> = (0..400)
        .map(|i| {
            let x = i as f64 * d;
            [x, 0.3 * (PI * x).sin()]
        })
        .collect();
    let mut p: ReferencePath<f64, 512> = ReferencePath::new();
    p.load(&pts, None, false).unwrap();
    let kappa = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        let (u, v, w) = (
            [b[0] - a[0], b[1] - a[1]],
            [c[0] - b[0], c[1] - b[1]],
            [c[0] - a[0], c[1] - a[1]],
        );
        let norm = |x: [f64; 2]| x[0].hypot(x[1]);
        2.0 * (u[0] * v[1] - u[1] * v[0]) / (norm(u) * norm(v) * norm(w))
    };
    let seg = |k: usize| {
        let (a, b) = (pts[k], pts[k + 1]);
        (b[0] - a[0]).hypot(b[1] - a[1])
    };
    // The crest at x = 4.5 m; the vertices 3 m of arc away each way.
    let i = 225;
    let (mut ia, mut back) = (i, 0.0);
    while back < 3.0 {
        ia -= 1;
        back += seg(ia);
    }
    let (mut ic, mut ahead) = (i, 0.0);
    while ahead < 3.0 {
        ahead += seg(ic);
        ic += 1;
    }
    let steps = MAX_CURVATURE_WINDOW_STEPS;
    assert!(i - ia > steps && ic - i > steps, "{ia} {ic}: the cap binds");
    let capped = kappa(pts[i - steps], pts[i], pts[i + steps]);
    let whole = kappa(pts[ia], pts[i], pts[ic]);
    assert!((capped - whole).abs() > 0.1, "{capped} {whole}");
    let s_i: f64 = (0..i).map(seg).sum();
    let got = p.curvature_at(s_i + 1e-9);
    assert!(
        (got - capped).abs() < 1e-6,
        "{got} vs capped {capped}, whole {whole}"
    );
}

/// A path limited to `MAX_SEARCH_SEGMENTS` segments per search near a hint (the
/// plan task's) loads a road as dense as the limit allows and refuses one point
/// more within the search's 60 m, naming where; a path without a limit loads
/// both; on the path both load, every projection near a hint is the same bit for
/// bit with and without the limit (the limit never cuts a search short).
#[test]
fn a_path_with_a_search_limit_refuses_a_road_denser_than_it_and_projects_the_same() {
    use firmware::reference_path::MAX_SEARCH_SEGMENTS;
    // Points `d` m apart on a gentle curve, 300 of them.
    let road = |d: f32| -> Vec<[f32; 2]> {
        (0..300)
            .map(|i| {
                let x = i as f32 * d;
                [x, 10.0 * (x / 50.0).sin()]
            })
            .collect()
    };
    // 60 m of search span: at 0.7 m about 86 points in it, within 96; at 0.55 m
    // about 110, past it.
    let (fits, dense) = (road(0.7), road(0.55));
    let mut limited: ReferencePath<f32, 512> =
        ReferencePath::with_search_segments(MAX_SEARCH_SEGMENTS);
    let mut free: ReferencePath<f32, 512> = ReferencePath::new();
    limited.load(&fits, None, false).unwrap();
    free.load(&fits, None, false).unwrap();
    for k in 0..200 {
        let s = k as f32;
        let q = [s * 0.7, 10.0 * (s * 0.7 / 50.0).sin() + 1.5];
        for hint in [s * 0.7, s * 0.7 - 15.0, s * 0.7 + 30.0] {
            let a = limited.project(q, Some(hint)).unwrap();
            let b = free.project(q, Some(hint)).unwrap();
            assert_eq!(
                (a.s_m.to_bits(), a.lateral_m.to_bits(), a.segment),
                (b.s_m.to_bits(), b.lateral_m.to_bits(), b.segment)
            );
        }
    }
    let e = limited.load(&dense, None, false).unwrap_err();
    assert!(matches!(e, PathError::TooDense { index: 0 }), "{e:?}");
    assert!(limited.is_empty());
    free.load(&dense, None, false).unwrap();
    // The same rule on a closed path, across its start.
    let ring = |n: usize, r: f32| -> Vec<[f32; 2]> {
        (0..n)
            .map(|i| {
                let a = core::f32::consts::TAU * i as f32 / n as f32;
                [r * a.cos(), r * a.sin()]
            })
            .collect()
    };
    // r = 100 m: 628 m round; 600 points 1.05 m apart fit, 1,200 (0.52 m) do not.
    let mut limited: ReferencePath<f32, 1280> =
        ReferencePath::with_search_segments(MAX_SEARCH_SEGMENTS);
    limited.load(&ring(600, 100.0), None, true).unwrap();
    assert!(matches!(
        limited.load(&ring(1200, 100.0), None, true),
        Err(PathError::TooDense { .. })
    ));
}
