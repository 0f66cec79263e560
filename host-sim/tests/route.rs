//! The windows of the road sent to the ECU: always enough road ahead of the car
//! and behind it, on closed and open tracks, over several laps.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use host_sim::world::route::{RouteFeeder, Window, AHEAD_M, BEHIND_M, WINDOW_ROWS};
use host_sim::world::track::Track;

/// A track of `n` rows round an ellipse (closed) or along a sine (open), `spacing`
/// metres apart on average.
fn track(n: usize, spacing: f64, closed: bool) -> Track {
    let mut csv = String::new();
    for i in 0..n {
        let t = i as f64 / n as f64;
        let (x, y) = if closed {
            let a = n as f64 * spacing / std::f64::consts::TAU;
            let th = t * std::f64::consts::TAU;
            (1.2 * a * th.cos(), 0.8 * a * th.sin())
        } else {
            let x = i as f64 * spacing;
            (x, 20.0 * (x / 80.0).sin())
        };
        csv.push_str(&format!("{x},{y},4,4\n"));
    }
    Track::from_csv_reader(csv.as_bytes(), "test", closed).unwrap()
}

/// Length of the road a window covers, m.
fn span(w: &Window) -> f64 {
    w.rows
        .windows(2)
        .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
        .sum()
}

/// Drives `distance_m` along the road in 0.5 m steps; at every step the window
/// the ECU holds must reach `AHEAD_M` ahead of the car (or the end of an open
/// track) and keep the car inside it. Returns the windows sent.
fn drive(t: &Track, distance_m: f64) -> usize {
    let mut feeder = RouteFeeder::new(t).unwrap();
    let mut w = feeder.first();
    assert!(!w.closed);
    assert_eq!(w.rows.len(), WINDOW_ROWS);
    let length = t.length();
    let mut sent = 0;
    let mut p = 0.0;
    while p < distance_m {
        if let Some(next) = feeder.update(p) {
            assert!(next.origin_m > w.origin_m, "windows move forward");
            assert!(
                p - next.origin_m >= BEHIND_M - 10.0,
                "at {p:.1} m: a window starts {:.1} m behind the car",
                p - next.origin_m
            );
            w = next;
            sent += 1;
        }
        let end = w.origin_m + span(&w);
        let road_end = if t.closed { f64::INFINITY } else { length };
        assert!(p >= w.origin_m, "at {p:.1} m: the car is behind its window");
        assert!(
            end >= (p + AHEAD_M).min(road_end) - 1e-6,
            "at {p:.1} m: the window ends {:.1} m ahead, {AHEAD_M} needed",
            end - p
        );
        p += 0.5;
    }
    sent
}

#[test]
fn a_closed_circuit_always_has_its_road_ahead_over_two_laps() {
    let t = track(1500, 2.0, true);
    let sent = drive(&t, 2.0 * t.length());
    // About one window per 60 m driven.
    let expected = 2.0 * t.length() / host_sim::world::route::ADVANCE_M;
    assert!(
        (sent as f64 - expected).abs() < 0.1 * expected + 2.0,
        "{sent} windows, ~{expected:.0} expected"
    );
}

#[test]
fn an_open_road_has_its_road_ahead_up_to_its_end() {
    let t = track(1200, 1.5, false);
    drive(&t, t.length() - 1.0);
    let mut feeder = RouteFeeder::new(&t).unwrap();
    feeder.first();
    // Past the end nothing more is sent, and the last window ends at the road's end.
    let mut last = None;
    let mut p = 0.0;
    while p < t.length() + 100.0 {
        if let Some(w) = feeder.update(p) {
            last = Some(w);
        }
        p += 1.0;
    }
    let last = last.unwrap();
    assert_eq!(last.rows.last(), t.rows().last());
}

#[test]
fn a_short_circuit_is_sent_whole_once() {
    let t = track(WINDOW_ROWS, 3.0, true);
    let mut feeder = RouteFeeder::new(&t).unwrap();
    let w = feeder.first();
    assert!(w.closed);
    assert_eq!(w.rows, t.rows());
    for k in 0..2000 {
        assert!(feeder.update(k as f64).is_none());
    }
}

#[test]
fn a_track_too_dense_for_the_window_is_refused_with_what_to_change() {
    // 2,000 rows 0.1 m apart: a window of 320 rows covers 32 m.
    let t = track(2000, 0.1, false);
    let e = RouteFeeder::new(&t).unwrap_err().to_string();
    assert!(e.contains("resample"), "{e}");
    assert!(e.contains("test"), "names the track: {e}");
}

/// A track dense only in one place (a 30 m stretch of points 0.25 m apart on a
/// road sampled every 2 m, so the window's span is met): the ECU's projections
/// search a bounded number of segments, so it is refused, naming the place and
/// the spacing to resample to; a road sampled every 0.8 m passes.
#[test]
fn a_track_too_dense_for_the_projections_search_is_refused_where_it_is_dense() {
    let mut csv = String::new();
    let mut x = 0.0;
    while x < 600.0 {
        csv.push_str(&format!("{x},0,4,4\n"));
        x += if (200.0..230.0).contains(&x) {
            0.25
        } else {
            2.0
        };
    }
    let t = Track::from_csv_reader(csv.as_bytes(), "test", false).unwrap();
    let e = RouteFeeder::new(&t).unwrap_err().to_string();
    assert!(e.contains("too dense near (1"), "{e}");
    assert!(e.contains("resample the track to at least 0.64 m"), "{e}");
    let even = track(2000, 0.8, false);
    RouteFeeder::new(&even).unwrap();
}
