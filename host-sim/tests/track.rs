//! Track files, track geometry, obstacle files and polygon geometry.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::PathBuf;

use host_sim::world::obstacle_file::{
    distance, intersects, load_obstacles_reader, point_in_polygon, vehicle_footprint, ObstacleError,
};
use host_sim::world::track::{Track, TrackError, TrackPiece, DEFAULT_HALF_WIDTH_M};

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests")
        .join("data")
        .join(name)
}

fn load(text: &str, closed: bool) -> Result<Track, TrackError> {
    Track::from_csv_reader(text.as_bytes(), "test.csv", closed)
}

fn err(text: &str, closed: bool) -> String {
    load(text, closed)
        .expect_err("should be rejected")
        .to_string()
}

// ---------------------------------------------------------------- loading

#[test]
fn budapest_loads_closed_with_its_known_length() {
    let t = Track::from_csv_path(data("Budapest.csv"), true).unwrap();
    assert_eq!(t.name, "Budapest");
    assert!(t.closed);
    assert_eq!(t.points.len(), 876);
    assert_eq!(t.w_right.len(), 876);
    assert_eq!(t.w_left.len(), 876);
    let l = t.length();
    // 4376.86 m computed independently; the Hungaroring is 4.381 km.
    assert!((l - 4376.86).abs() < 0.05, "length {l}");
    assert!((t.points[0][0] + 2.447973).abs() < 1e-12);
    assert!((t.w_right[0] - 6.187).abs() < 1e-12);
    assert!((t.w_left[0] - 6.476).abs() < 1e-12);
    // The tightest radius is 12-14 m depending on smoothing (an earlier README's figure);
    // the raw three-point estimate gives 14.19 m (computed independently).
    let r = t.min_radius();
    assert!((r - 14.19).abs() < 0.01, "min radius {r}");
}

#[test]
fn open_track_has_no_closing_segment() {
    let text = "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n10,0,1,1\n10,10,1,1\n";
    let open = load(text, false).unwrap();
    let closed = load(text, true).unwrap();
    assert!((open.length() - 20.0).abs() < 1e-12);
    assert!((closed.length() - (20.0 + 200f64.sqrt())).abs() < 1e-12);
    assert_eq!(open.segment_count(), 2);
    assert_eq!(closed.segment_count(), 3);
}

#[test]
fn header_without_hash_and_no_header_are_accepted() {
    let a = load(
        "x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,2\n1,0,1,2\n1,1,1,2\n",
        true,
    )
    .unwrap();
    let b = load("0,0,1,2\n1,0,1,2\n1,1,1,2\n", true).unwrap();
    let c = load(
        "#x_m, y_m, w_tr_right_m, w_tr_left_m\n0,0,1,2\n1,0,1,2\n1,1,1,2\n",
        true,
    )
    .unwrap();
    assert_eq!(a.points, b.points);
    assert_eq!(a.rows(), c.rows());
    assert_eq!(a.rows()[2], [1.0, 1.0, 1.0, 2.0]);
}

#[test]
fn utf8_bom_and_crlf_are_accepted() {
    let a = load(
        "\u{feff}# x_m,y_m,w_tr_right_m,w_tr_left_m\r\n0,0,1,2\r\n1,0,1,2\r\n1,1,1,2\r\n",
        true,
    )
    .unwrap();
    let b = load("\u{feff}0,0,1,2\n1,0,1,2\n1,1,1,2\n", true).unwrap();
    assert_eq!(a, b);
    let o = obstacles("\u{feff}id,x_m,y_m\r\na,0,0\r\n").unwrap();
    assert_eq!(o[0].id, "a");
    let o = obstacles("\u{feff}a,0,0\n").unwrap();
    assert_eq!(o[0].id, "a");
}

#[test]
fn two_column_files_get_the_default_half_width() {
    let t = load("# x_m,y_m\n0,0\n5,0\n5,5\n", true).unwrap();
    assert_eq!(DEFAULT_HALF_WIDTH_M, 3.5);
    assert!(t.w_left.iter().chain(&t.w_right).all(|&w| w == 3.5));
    let t = load("0,0\n5,0\n5,5\n", true).unwrap();
    assert_eq!(t.rows()[1], [5.0, 0.0, 3.5, 3.5]);
}

#[test]
fn first_equal_to_last_is_dropped_on_a_closed_track_only() {
    let text = "0,0,1,1\n10,0,1,1\n10,10,1,1\n0,0,1,1\n";
    let closed = load(text, true).unwrap();
    assert_eq!(closed.points.len(), 3);
    let open = load(text, false).unwrap();
    assert_eq!(open.points.len(), 4);
}

#[test]
fn comment_lines_after_the_header_are_skipped() {
    let t = load(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n# a note\n10,0,1,1\n10,10,1,1\n",
        true,
    )
    .unwrap();
    assert_eq!(t.points.len(), 3);
}

#[test]
fn too_few_points_is_an_error() {
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1,1\n",
        true,
    );
    assert!(
        e.contains("test.csv") && e.contains("2 distinct point") && e.contains("at least 3"),
        "{e}"
    );
    // Closing duplicate does not count as a point.
    let e = err("0,0,1,1\n1,0,1,1\n0,0,1,1\n", true);
    assert!(e.contains("2 distinct point"), "{e}");
    let e = err("", true);
    assert!(e.contains("0 distinct point"), "{e}");
}

#[test]
fn repeated_point_names_both_lines() {
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1,1\n1,0,1,1\n2,2,1,1\n",
        true,
    );
    assert!(
        e.contains("lines 3 and 4") && e.contains("remove one"),
        "{e}"
    );
    assert!(matches!(
        load("0,0,1,1\n1,0,1,1\n1,0,1,1\n2,2,1,1\n", true),
        Err(TrackError::RepeatedPoint {
            first_line: 2,
            second_line: 3,
            ..
        })
    ));
}

#[test]
fn nan_and_garbage_name_line_and_column() {
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,NaN,1,1\n2,2,1,1\n",
        true,
    );
    assert!(
        e.contains("line 3") && e.contains("y_m") && e.contains("finite"),
        "{e}"
    );
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1,inf\n2,2,1,1\n",
        true,
    );
    assert!(e.contains("line 3") && e.contains("w_tr_left_m"), "{e}");
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1,1\n2,abc,1,1\n",
        true,
    );
    assert!(
        e.contains("line 4") && e.contains("`abc`") && e.contains("not a number"),
        "{e}"
    );
}

#[test]
fn bad_header_is_an_error() {
    let e = err("# x,y,left,right\n0,0,1,1\n1,0,1,1\n2,2,1,1\n", true);
    assert!(
        e.contains("line 1") && e.contains("unexpected header") && e.contains("x_m,y_m"),
        "{e}"
    );
    // Widths in the wrong order are a bad header, not silently swapped.
    let e = err(
        "# x_m,y_m,w_tr_left_m,w_tr_right_m\n0,0,1,1\n1,0,1,1\n2,2,1,1\n",
        true,
    );
    assert!(e.contains("unexpected header"), "{e}");
}

#[test]
fn wrong_column_count_is_an_error() {
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1\n2,2,1,1\n",
        true,
    );
    assert!(
        e.contains("line 3") && e.contains("3 columns") && e.contains("expected 4"),
        "{e}"
    );
    let e = err("0,0\n1,0,1,1\n2,2\n", true);
    assert!(e.contains("line 2") && e.contains("expected 2"), "{e}");
}

#[test]
fn negative_width_is_an_error() {
    let e = err(
        "# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,-0.5,1\n2,2,1,1\n",
        true,
    );
    assert!(
        e.contains("line 3") && e.contains("w_tr_right_m") && e.contains(">= 0"),
        "{e}"
    );
}

#[test]
fn missing_file_names_the_file() {
    let e = Track::from_csv_path(data("no_such_track.csv"), true).unwrap_err();
    assert!(e.to_string().contains("no_such_track.csv"), "{e}");
}

// ---------------------------------------------------------------- geometry

fn square(side: f64) -> Track {
    let text = format!("0,0\n{side},0\n{side},{side}\n0,{side}\n");
    load(&text, true).unwrap()
}

#[test]
fn rows_match_the_fields() {
    let t = load("0,0,1,2\n1,0,3,4\n1,1,5,6\n", false).unwrap();
    assert_eq!(
        t.rows(),
        vec![
            [0.0, 0.0, 1.0, 2.0],
            [1.0, 0.0, 3.0, 4.0],
            [1.0, 1.0, 5.0, 6.0]
        ]
    );
}

#[test]
fn resampling_caps_the_spacing_and_keeps_the_shape() {
    let t = square(10.0);
    let r = t.resampled(2.0);
    assert_eq!(r.points.len(), 20); // 4 sides x 5 parts
    assert!((r.length() - 40.0).abs() < 1e-9);
    let n = r.points.len();
    for i in 0..n {
        let (a, b) = (r.points[i], r.points[(i + 1) % n]);
        assert!((a[0] - b[0]).hypot(a[1] - b[1]) <= 2.0 + 1e-12);
    }
    // Widths are interpolated.
    let t = load("0,0,1,1\n4,0,3,1\n4,4,3,1\n", false).unwrap();
    let r = t.resampled(2.0);
    assert_eq!(r.points.len(), 5);
    assert_eq!(r.points[1], [2.0, 0.0]);
    assert!((r.w_right[1] - 2.0).abs() < 1e-12);
    // Budapest (~5 m spacing) gets points every <= 2 m, same length.
    let b = Track::from_csv_path(data("Budapest.csv"), true).unwrap();
    let rb = b.resampled(2.0);
    assert!(rb.points.len() > 2 * b.points.len());
    assert!((rb.length() - b.length()).abs() < 1e-6);
}

#[test]
fn curvature_of_a_sampled_circle() {
    let r = 25.0;
    let n = 200;
    let text: String = (0..n)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            format!("{},{}\n", r * a.cos(), r * a.sin())
        })
        .collect();
    let t = load(&text, true).unwrap();
    for k in t.curvature() {
        assert!((k - 1.0 / r).abs() < 1e-9, "{k}"); // anticlockwise: left, positive
    }
    assert!((t.min_radius() - r).abs() < 1e-6);
    let reversed: String = text.lines().rev().map(|l| format!("{l}\n")).collect();
    let t = load(&reversed, true).unwrap();
    assert!(t.curvature().iter().all(|&k| (k + 1.0 / r).abs() < 1e-9));
    // A straight line has infinite radius.
    let t = load("0,0\n1,0\n2,0\n", false).unwrap();
    assert!(t.min_radius().is_infinite());
}

#[test]
fn projection_round_trip_on_a_square() {
    let t = square(100.0);
    // Travel is anticlockwise: on the bottom side (y = 0) left is +y.
    let (s, d) = t.project([30.0, 2.5], None);
    assert!(
        (s - 30.0).abs() < 1e-12 && (d - 2.5).abs() < 1e-12,
        "{s} {d}"
    );
    let (s, d) = t.project([30.0, -1.5], None);
    assert!(
        (s - 30.0).abs() < 1e-12 && (d + 1.5).abs() < 1e-12,
        "{s} {d}"
    );
    // Last (closing) side: from (0,100) down to (0,0); s in [300, 400).
    let (s, d) = t.project([1.0, 40.0], Some(350.0));
    assert!(
        (s - 360.0).abs() < 1e-12 && (d - 1.0).abs() < 1e-12,
        "{s} {d}"
    );
}

#[test]
fn projection_round_trip_on_budapest() {
    let t = Track::from_csv_path(data("Budapest.csv"), true).unwrap();
    let cum = t.arc_lengths();
    let n = t.points.len();
    let mut checked = 0;
    for i in (0..n).step_by(7) {
        let (a, b) = (t.points[i], t.points[(i + 1) % n]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let (ux, uy) = ((b[0] - a[0]) / len, (b[1] - a[1]) / len);
        // Mid-segment, offset to the left by d; d small against the radius.
        for d in [-1.5, 0.0, 1.0] {
            let p = [
                a[0] + 0.5 * len * ux - d * uy,
                a[1] + 0.5 * len * uy + d * ux,
            ];
            let (s, lat) = t.project(p, Some(cum[i]));
            let expect = cum[i] + 0.5 * len;
            // A neighbouring segment may be marginally closer on a curve.
            if (s - expect).abs() < 0.5 {
                assert!((lat - d).abs() < 0.05, "i {i} d {d} lat {lat}");
                checked += 1;
            } else {
                panic!("point {i}: s {s} instead of {expect}");
            }
        }
    }
    assert!(checked > 300);
}

#[test]
fn projection_uses_the_hint_where_the_track_comes_back_near_itself() {
    // A hairpin: out along y = 0, back along y = 6 (open track).
    let pieces = [
        TrackPiece::Straight { length_m: 100.0 },
        TrackPiece::Arc {
            radius_m: 3.0,
            angle_rad: std::f64::consts::PI,
        },
        TrackPiece::Straight { length_m: 100.0 },
    ];
    let t = Track::from_pieces("hairpin", [0.0, 0.0, 0.0], &pieces, 1.0, 2.0, false);
    let p = [50.0, 2.8]; // nearer the outbound leg (2.8 m) than the return (3.2 m)
    let (s_out, d_out) = t.project(p, Some(48.0));
    assert!(
        (s_out - 50.0).abs() < 1e-9 && (d_out - 2.8).abs() < 1e-9,
        "{s_out} {d_out}"
    );
    // With a hint on the return leg, it stays there.
    // The arc is 10 chords of 2 R sin(pi / 20) on the polyline.
    let back_s = 100.0 + 60.0 * (std::f64::consts::PI / 20.0).sin() + 50.0;
    let (s_back, d_back) = t.project(p, Some(back_s + 2.0));
    assert!((s_back - back_s).abs() < 1e-6, "{s_back}");
    assert!((d_back - 3.2).abs() < 1e-6, "{d_back}"); // left of the return leg (heading -x)
                                                      // Without a hint: the globally closest.
    let (s, _) = t.project(p, None);
    assert!((s - 50.0).abs() < 1e-9);
    // A hint far from the point: it left the window, global search.
    let (s, _) = t.project(p, Some(0.0));
    assert!((s - 50.0).abs() < 1e-9, "{s}");
}

#[test]
fn projection_wraps_on_a_closed_loop() {
    let t = square(100.0);
    // Just before the start, on the closing side, with a hint just after s = 0.
    let (s, d) = t.project([0.5, 2.0], Some(1.0));
    assert!(
        (s - 398.0).abs() < 1e-9 && (d - 0.5).abs() < 1e-12,
        "{s} {d}"
    );
}

// ---------------------------------------------------------------- obstacles

fn obstacles(text: &str) -> Result<Vec<host_sim::world::obstacle_file::Obstacle>, ObstacleError> {
    load_obstacles_reader(text.as_bytes(), "obs.csv")
}

#[test]
fn obstacle_file_groups_vertices_by_id() {
    let o = obstacles(
        "id,x_m,y_m\ncar,0,0\ncar,4,0\ncar,4,2\ncar,0,2\ncone,10,1\nwall,20,0\nwall,20,5\n",
    )
    .unwrap();
    assert_eq!(o.len(), 3);
    assert_eq!(o[0].id, "car");
    assert_eq!(o[0].vertices.len(), 4);
    assert_eq!(o[1].vertices, vec![[10.0, 1.0]]);
    assert_eq!(o[2].vertices.len(), 2);
    // Header optional, '#' header accepted.
    assert_eq!(
        obstacles("car,0,0\ncar,1,0\ncar,1,1\n").unwrap()[0]
            .vertices
            .len(),
        3
    );
    assert_eq!(obstacles("# id,x_m,y_m\nc,0,0\n").unwrap().len(), 1);
    assert!(obstacles("").unwrap().is_empty());
}

#[test]
fn obstacle_file_errors_name_the_line() {
    let e = obstacles("id,x_m,y_m\na,0,0\na,1,NaN\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("obs.csv") && e.contains("line 3") && e.contains("y_m"),
        "{e}"
    );
    let e = obstacles("id,x_m,y_m\na,0,0\nb,5,5\na,1,0\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 4") && e.contains("line 2") && e.contains("`a`") && e.contains("together"),
        "{e}"
    );
    let e = obstacles("id,x_m,y_m\na,0,0,7\n").unwrap_err().to_string();
    assert!(e.contains("line 2") && e.contains("4 columns"), "{e}");
    let e = obstacles("name,x,y\na,0,0\n").unwrap_err().to_string();
    assert!(
        e.contains("line 1") && e.contains("unexpected header"),
        "{e}"
    );
    let e = obstacles("id,x_m,y_m\n,0,0\n").unwrap_err().to_string();
    assert!(e.contains("line 2") && e.contains("empty id"), "{e}");
    let e = obstacles("id,x_m,y_m\na,0,zero\n").unwrap_err().to_string();
    assert!(e.contains("line 2") && e.contains("`zero`"), "{e}");
    // A bow-tie.
    let e = obstacles("id,x_m,y_m\nbow,0,0\nbow,2,2\nbow,2,0\nbow,0,2\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("self-intersecting") && e.contains("lines 2-5"),
        "{e}"
    );
}

#[test]
fn polygon_distance_and_intersection() {
    let unit = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let shifted = |dx: f64, dy: f64| unit.map(|p| [p[0] + dx, p[1] + dy]);
    // Side by side, 2 m gap.
    assert!((distance(&unit, &shifted(3.0, 0.0)) - 2.0).abs() < 1e-12);
    assert!(!intersects(&unit, &shifted(3.0, 0.0)));
    // Corner to corner: sqrt(2) * 1.
    assert!((distance(&unit, &shifted(2.0, 2.0)) - 2f64.sqrt()).abs() < 1e-12);
    // Overlap.
    assert_eq!(distance(&unit, &shifted(0.5, 0.5)), 0.0);
    assert!(intersects(&unit, &shifted(0.5, 0.5)));
    // Touching edges.
    assert!(intersects(&unit, &shifted(1.0, 0.0)));
    // One inside the other, no edge crossing.
    let big = [[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]];
    assert!(intersects(&big, &unit) && intersects(&unit, &big));
    assert_eq!(distance(&unit, &big), 0.0);
    // Points and segments.
    assert!((distance(&unit, &[[4.0, 0.5]]) - 3.0).abs() < 1e-12);
    assert!(intersects(&unit, &[[0.5, 0.5]]));
    assert!((distance(&[[0.0, 3.0], [10.0, 3.0]], &unit) - 2.0).abs() < 1e-12);
    assert!((distance(&[[0.0, 0.0]], &[[3.0, 4.0]]) - 5.0).abs() < 1e-12);
    assert!(point_in_polygon([0.5, 0.5], &unit) && !point_in_polygon([1.5, 0.5], &unit));
}

#[test]
fn vehicle_footprint_corners() {
    let f = vehicle_footprint(10.0, 5.0, 0.0, 4.0, 2.0);
    assert_eq!(f, [[12.0, 4.0], [12.0, 6.0], [8.0, 6.0], [8.0, 4.0]]);
    let g = vehicle_footprint(0.0, 0.0, std::f64::consts::FRAC_PI_2, 4.0, 2.0);
    // Heading +y: front-right corner at (+1, +2).
    assert!((g[0][0] - 1.0).abs() < 1e-12 && (g[0][1] - 2.0).abs() < 1e-12);
    // Two cars side by side 0.5 m apart.
    let a = vehicle_footprint(0.0, 0.0, 0.0, 4.5, 1.8);
    let b = vehicle_footprint(0.0, 2.3, 0.0, 4.5, 1.8);
    assert!((distance(&a, &b) - 0.5).abs() < 1e-12);
}
