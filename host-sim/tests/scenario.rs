//! The built-in `paper` scenario, its exported files, and scenario resolution.
//!
//! `HOST_SIM_BLESS=1 cargo test -p host-sim --test scenario` rewrites
//! `host-sim/tracks/paper.csv` and `paper_obstacles.csv` from the code.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::f64::consts::PI;
use std::path::PathBuf;

use host_sim::world::obstacle_file::{
    distance, intersects, load_obstacles_path, vehicle_footprint, Obstacle,
};
use host_sim::world::scenario::{
    paper_obstacles, paper_obstacles_csv, paper_pieces, paper_pose_at, paper_track,
    paper_track_csv, resolve, Scenario, ScenarioError, CAR_WIDTH_M, PAPER_HALF_WIDTH_M,
    PAPER_MIN_FREE_WIDTH_M, PAPER_OBSTACLES,
};
use host_sim::world::track::{Track, TrackPiece};

fn manifest(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn circ_diff(a: f64, b: f64, total: f64) -> f64 {
    let d = (a - b).rem_euclid(total);
    d.min(total - d)
}

#[test]
fn paper_loop_closes_exactly() {
    let pieces = paper_pieces();
    let end = pieces
        .iter()
        .fold([0.0, 0.0, 0.0], |pose, p| p.end_pose(pose));
    let closure = end[0].hypot(end[1]);
    assert!(closure < 1e-9, "closure error {closure} m");
    assert!((end[2] - 2.0 * PI).abs() < 1e-12, "end heading {}", end[2]);
    let turn: f64 = pieces
        .iter()
        .map(|p| match *p {
            TrackPiece::Arc { angle_rad, .. } => angle_rad,
            TrackPiece::Straight { .. } => 0.0,
        })
        .sum();
    assert!((turn - 2.0 * PI).abs() < 1e-12);
}

#[test]
fn paper_pieces_are_in_the_papers_spirit() {
    let pieces = paper_pieces();
    let mut hairpin = false;
    for p in &pieces {
        match *p {
            TrackPiece::Straight { length_m } => {
                assert!(
                    (40.0..=150.0).contains(&length_m),
                    "straight of {length_m} m"
                )
            }
            TrackPiece::Arc {
                radius_m,
                angle_rad,
            } => {
                assert!((10.0..=30.0).contains(&radius_m), "radius {radius_m} m");
                if radius_m == 10.0 && (angle_rad.abs() - PI).abs() < 1e-12 {
                    hairpin = true;
                }
            }
        }
    }
    assert!(hairpin, "a 10 m, 180 degree hairpin");
    // An S-bend: two adjacent arcs turning opposite ways.
    let s_bend = pieces.windows(2).any(|w| match (w[0], w[1]) {
        (TrackPiece::Arc { angle_rad: a, .. }, TrackPiece::Arc { angle_rad: b, .. }) => a * b < 0.0,
        _ => false,
    });
    assert!(s_bend);
    let exact: f64 = pieces.iter().map(TrackPiece::length).sum();
    assert!((900.0..=1200.0).contains(&exact), "length {exact}");
}

#[test]
fn paper_track_is_sampled_smooth_and_sized() {
    let t = paper_track();
    assert_eq!(t.name, "paper");
    assert!(t.closed);
    let l = t.length();
    assert!((900.0..=1200.0).contains(&l), "length {l}");
    let n = t.points.len();
    // Points every <= 1 m (and not much closer).
    for i in 0..n {
        let (a, b) = (t.points[i], t.points[(i + 1) % n]);
        let d = (b[0] - a[0]).hypot(b[1] - a[1]);
        assert!(d <= 1.0 + 1e-9 && d > 0.5, "spacing {d} at {i}");
    }
    // Heading continuity: between consecutive chords the heading turns by at
    // most spacing / R_min (1 m / 10 m), including across the closure.
    for i in 0..n {
        let (a, b, c) = (t.points[i], t.points[(i + 1) % n], t.points[(i + 2) % n]);
        let h1 = (b[1] - a[1]).atan2(b[0] - a[0]);
        let h2 = (c[1] - b[1]).atan2(c[0] - b[0]);
        let dh = (h2 - h1 + PI).rem_euclid(2.0 * PI) - PI;
        assert!(dh.abs() <= 0.1 + 1e-9, "heading jump {dh} rad at point {i}");
    }
    let r = t.min_radius();
    assert!((r - 10.0).abs() < 0.05, "min radius {r}");
    assert!(t
        .w_left
        .iter()
        .chain(&t.w_right)
        .all(|&w| w == PAPER_HALF_WIDTH_M));
    // The S-bend shows in the sampled curvature: from right (< -1/30) to left
    // (> 1/30) within a few points.
    let k = t.curvature();
    let s_bend = (0..n).any(|i| k[i] < -1.0 / 30.0 && (1..4).any(|j| k[(i + j) % n] > 1.0 / 30.0));
    assert!(s_bend);
}

#[test]
fn paper_track_does_not_overlap_itself() {
    let t = paper_track();
    let cum = t.arc_lengths();
    let total = t.length();
    let n = t.points.len();
    let mut min_gap = f64::INFINITY;
    for i in 0..n {
        for j in (i + 1)..n {
            // Parts of the road more than 40 m apart along it.
            if circ_diff(cum[i], cum[j], total) > 40.0 {
                let (a, b) = (t.points[i], t.points[j]);
                min_gap = min_gap.min((a[0] - b[0]).hypot(a[1] - b[1]));
            }
        }
    }
    // Two road widths plus 2 m of verge.
    assert!(
        min_gap > 4.0 * PAPER_HALF_WIDTH_M + 2.0,
        "closest approach {min_gap} m"
    );
}

#[test]
fn projection_round_trip_on_the_paper_track() {
    let t = paper_track();
    let total = t.length();
    let exact_total: f64 = paper_pieces().iter().map(TrackPiece::length).sum();
    let mut s = 0.0;
    while s < exact_total {
        let [x, y, th] = paper_pose_at(s);
        for d in [-3.0, 0.0, 2.5] {
            let p = [x - d * th.sin(), y + d * th.cos()];
            let (ps, lat) = t.project(p, Some(s - 1.0));
            // The polyline's s differs from the exact arc's: chords are
            // shorter than arcs (drift < 5 cm here), and a point offset by d
            // from an arc projects onto a chord up to |d| * (half the angle a
            // 1 m chord subtends, 0.05 rad on R 10) away from its radial foot.
            let tol = 0.05 + d.abs() * 0.5 / 10.0;
            assert!(
                circ_diff(ps, s, total) < tol,
                "s {s} d {d}: projected to {ps}"
            );
            // Sagitta of a 1 m chord on R 10: 1.25 cm.
            assert!((lat - d).abs() < 0.02, "s {s} d {d}: lateral {lat}");
        }
        s += 3.7;
    }
}

fn lateral_extent(t: &Track, o: &Obstacle) -> (f64, f64) {
    o.vertices
        .iter()
        .fold((f64::INFINITY, -f64::INFINITY), |(lo, hi), v| {
            let (_, d) = t.project(*v, None);
            (lo.min(d), hi.max(d))
        })
}

#[test]
fn paper_obstacles_leave_room_to_pass() {
    const { assert!(PAPER_MIN_FREE_WIDTH_M >= CAR_WIDTH_M + 0.5) };
    let t = paper_track();
    let obs = paper_obstacles();
    assert!(obs.len() >= 5);
    assert_eq!(obs.len(), PAPER_OBSTACLES.len());
    let (mut left, mut right, mut across) = (0, 0, 0);
    for o in &obs {
        assert_eq!(o.vertices.len(), 4);
        let (lo, hi) = lateral_extent(&t, o);
        assert!(
            lo >= -PAPER_HALF_WIDTH_M && hi <= PAPER_HALF_WIDTH_M,
            "{}: off the road",
            o.id
        );
        let free_left = PAPER_HALF_WIDTH_M - hi;
        let free_right = lo + PAPER_HALF_WIDTH_M;
        assert!(
            free_left.max(free_right) >= PAPER_MIN_FREE_WIDTH_M,
            "{}: free left {free_left} m, right {free_right} m",
            o.id
        );
        if lo > 0.0 {
            left += 1;
        } else if hi < 0.0 {
            right += 1;
        } else {
            across += 1;
        }
    }
    assert!(
        left >= 1 && right >= 1 && across >= 1,
        "{left} {right} {across}"
    );
    for b in &PAPER_OBSTACLES {
        assert!((1.0..=2.5).contains(&b.width_m) && (1.0..=4.5).contains(&b.length_m));
    }
    // One stands within 10 m after the end of a curve.
    let pieces = paper_pieces();
    let at_exit = PAPER_OBSTACLES.iter().any(|b| {
        b.piece > 0
            && matches!(pieces[b.piece - 1], TrackPiece::Arc { .. })
            && b.offset_m - 0.5 * b.length_m < 10.0
    });
    assert!(at_exit);
    // Apart from each other and from the start.
    for (i, a) in obs.iter().enumerate() {
        for b in &obs[i + 1..] {
            assert!(
                distance(&a.vertices, &b.vertices) > 20.0,
                "{} {}",
                a.id,
                b.id
            );
        }
        let car = vehicle_footprint(0.0, 0.0, 0.0, 4.5, 1.8);
        assert!(!intersects(&car, &a.vertices));
        assert!(distance(&car, &a.vertices) > 30.0);
    }
}

#[test]
fn paper_scenario_starts_on_the_centre_line() {
    let sc = Scenario::paper(true);
    assert_eq!(sc.mu, 1.0);
    assert_eq!(sc.initial_speed_mps, 15.0);
    assert_eq!(sc.start_pose, [0.0, 0.0, 0.0]);
    assert_eq!(sc.obstacles.len(), PAPER_OBSTACLES.len());
    let (s, d) = sc.track.project([sc.start_pose[0], sc.start_pose[1]], None);
    assert!(s.abs() < 1e-12 && d.abs() < 1e-12);
    assert_eq!(sc.track.start_pose(), sc.start_pose);
    assert!(Scenario::paper(false).obstacles.is_empty());
}

#[test]
fn exported_files_match_the_code() {
    let track_path = manifest("tracks/paper.csv");
    let obs_path = manifest("tracks/paper_obstacles.csv");
    if std::env::var_os("HOST_SIM_BLESS").is_some() {
        std::fs::create_dir_all(manifest("tracks")).unwrap();
        std::fs::write(&track_path, paper_track_csv()).unwrap();
        std::fs::write(&obs_path, paper_obstacles_csv()).unwrap();
    }
    let hint = "regenerate with HOST_SIM_BLESS=1 cargo test -p host-sim --test scenario";
    let file = Track::from_csv_path(&track_path, true).expect(hint);
    let code = paper_track();
    assert_eq!(file.points.len(), code.points.len(), "{hint}");
    for (a, b) in file.rows().iter().zip(code.rows()) {
        for k in 0..4 {
            assert!((a[k] - b[k]).abs() <= 1e-6, "{hint}: {a:?} vs {b:?}");
        }
    }
    let file = load_obstacles_path(&obs_path).expect(hint);
    let code = paper_obstacles();
    assert_eq!(file.len(), code.len(), "{hint}");
    for (a, b) in file.iter().zip(&code) {
        assert_eq!(a.id, b.id, "{hint}");
        assert_eq!(a.vertices.len(), b.vertices.len(), "{hint}");
        for (p, q) in a.vertices.iter().zip(&b.vertices) {
            assert!(
                (p[0] - q[0]).abs() <= 1e-6 && (p[1] - q[1]).abs() <= 1e-6,
                "{hint}"
            );
        }
    }
}

#[test]
fn resolve_builds_what_the_command_line_asks_for() {
    let sc = resolve("paper", "paper", true).unwrap();
    assert_eq!(sc, Scenario::paper(true));
    let sc = resolve("paper", "none", true).unwrap();
    assert_eq!(sc, Scenario::paper(false));
    let file_obs = manifest("tracks/paper_obstacles.csv");
    let sc = resolve("paper", file_obs.to_str().unwrap(), true).unwrap();
    assert_eq!(sc.obstacles.len(), PAPER_OBSTACLES.len());

    let budapest = manifest("tests/data/Budapest.csv");
    let sc = resolve(budapest.to_str().unwrap(), "none", true).unwrap();
    assert_eq!(sc.name, "Budapest");
    assert_eq!(sc.mu, 1.0);
    assert_eq!(sc.initial_speed_mps, 15.0);
    assert_eq!([sc.start_pose[0], sc.start_pose[1]], sc.track.points[0]);
    let [x0, y0] = sc.track.points[0];
    let [x1, y1] = sc.track.points[1];
    assert!((sc.start_pose[2] - (y1 - y0).atan2(x1 - x0)).abs() < 1e-15);
    let open = resolve(budapest.to_str().unwrap(), "none", false).unwrap();
    assert!(!open.track.closed);

    assert!(matches!(
        resolve(budapest.to_str().unwrap(), "paper", true),
        Err(ScenarioError::PaperObstaclesNeedPaperTrack { .. })
    ));
    assert!(matches!(
        resolve("paper", "none", false),
        Err(ScenarioError::PaperTrackIsClosed)
    ));
    let e = resolve("no/such/track.csv", "none", true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no/such/track.csv"), "{e}");
    let e = resolve("paper", "no/such/obstacles.csv", true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no/such/obstacles.csv"), "{e}");
}
