//! The plan task on a window of the road (what the ECU holds) against the same
//! task on the whole road: same plans, the warm start carried across a new window,
//! and the obstacles of each window rebuilt.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::mpc::MpcSettings;
use firmware::obstacles::{Obstacle, ObstacleSettings};
use firmware::plan::Plan;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::PlanTask;

/// A window's rows, as on the ECU.
const WINDOW: usize = firmware::tasks::ECU_PATH_ROWS;
/// The whole road.
const WHOLE: usize = 1024;

/// A winding road, one row per metre: `y = 12 sin(x / 40)`, 4 m each side.
fn road() -> Vec<[f64; 4]> {
    (0..1000)
        .map(|i| {
            let x = i as f64;
            [x, 12.0 * (x / 40.0).sin(), 4.0, 4.0]
        })
        .collect()
}

/// Arc length of the polyline at each row, m.
fn arc_lengths(rows: &[[f64; 4]]) -> Vec<f64> {
    let mut s = vec![0.0];
    for w in rows.windows(2) {
        let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        s.push(s.last().unwrap() + d);
    }
    s
}

fn settings() -> MpcSettings<f64> {
    let geometry = firmware::vehicle_config::VehicleConfig::reference().geometry();
    MpcSettings::paper(geometry, 0.6, 1.8)
}

fn obstacle_settings() -> ObstacleSettings<f64> {
    ObstacleSettings::for_vehicle(1.8, 4.5, 1.0, 30.0)
}

/// A 1 m square obstacle 2 m left of the centre line at row `i`.
fn obstacle_at(rows: &[[f64; 4]], id: u32, i: usize) -> Obstacle<f64> {
    let (x, y) = (rows[i][0], rows[i][1] + 2.0);
    Obstacle::from_vertices(
        id,
        &[[x, y], [x + 1.0, y], [x + 1.0, y + 1.0], [x, y + 1.0]],
    )
    .unwrap()
}

/// The car on the centre line at row `i`, along the road at 15 m/s.
fn estimate_at(rows: &[[f64; 4]], i: usize, stamp_us: u64) -> StateEstimate<f64> {
    let (a, b) = (rows[i], rows[i + 1]);
    StateEstimate {
        stamp_us,
        x_m: a[0],
        y_m: a[1],
        psi_rad: (b[1] - a[1]).atan2(b[0] - a[0]),
        vx_mps: 15.0,
        vy_mps: 0.0,
        yaw_rate_radps: 0.0,
        delta_rad: 0.0,
        ..StateEstimate::zeroed()
    }
}

/// The plan's state `dt_s` after its start (the car follows it exactly).
fn estimate_along(plan: &Plan<f64>, stamp_us: u64) -> StateEstimate<f64> {
    let n = &plan.nodes[1];
    let v = n.v_mps;
    StateEstimate {
        stamp_us,
        x_m: n.x_m,
        y_m: n.y_m,
        psi_rad: n.psi_rad,
        vx_mps: v,
        vy_mps: 0.0,
        yaw_rate_radps: 0.0,
        delta_rad: n.delta_rad,
        ..StateEstimate::zeroed()
    }
}

/// Largest difference between two plans' positions, speeds and steering; their
/// abscissae compared after moving `offset_m` (the window's origin).
fn plan_difference(whole: &Plan<f64>, window: &Plan<f64>, offset_m: f64) -> f64 {
    whole
        .nodes
        .iter()
        .zip(window.nodes.iter())
        .map(|(a, b)| {
            [
                a.x_m - b.x_m,
                a.y_m - b.y_m,
                a.v_mps - b.v_mps,
                a.delta_rad - b.delta_rad,
                a.s_m - offset_m - b.s_m,
            ]
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()))
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_window_plans_as_the_whole_road_and_keeps_its_warm_start_across_windows() {
    let rows = road();
    let s = arc_lengths(&rows);
    let obstacles = [obstacle_at(&rows, 1, 330), obstacle_at(&rows, 2, 900)];

    let mut whole = Box::new(PlanTask::<f64, WHOLE>::new(settings(), 1.0));
    whole.path.load_track(&rows, false).unwrap();
    assert!(whole.set_obstacles(obstacle_settings(), &obstacles));
    whole.adopt_window(0, 0.0, false).unwrap_err(); // no rows staged: refused
    whole.load_window(&rows, 0.0, false).unwrap();
    assert_eq!(whole.obstacles.parabolas().len(), 2);

    let mut windowed = Box::new(PlanTask::<f64, WINDOW>::new(settings(), 1.0));
    assert!(windowed.set_obstacles(obstacle_settings(), &obstacles));
    // First window: rows 200..520 (the obstacle at row 900 is not in it).
    windowed
        .load_window(&rows[200..200 + WINDOW], s[200], false)
        .unwrap();
    assert_eq!(windowed.obstacles.parabolas().len(), 1);
    assert_eq!(windowed.stats.windows, 1);

    // Three activations in the first window, then a new window (rows 260..580),
    // three more: the plans stay those of the whole road, warm start included.
    let mut est = estimate_at(&rows, 260, 0);
    for k in 0..6u64 {
        if k == 3 {
            windowed
                .load_window(&rows[260..260 + WINDOW], s[260], false)
                .unwrap();
            assert_eq!(windowed.obstacles.parabolas().len(), 1);
        }
        let rw = whole.run(&est).unwrap();
        let rv = windowed.run(&est).unwrap();
        let (pw, pv) = (*whole.pending().unwrap(), *windowed.pending().unwrap());
        let origin = if k < 3 { s[200] } else { s[260] };
        let d = plan_difference(&pw, &pv, origin);
        assert!(d < 1e-6, "activation {k}: plans differ by {d:e}");
        assert_eq!(
            rw.qp_iterations, rv.qp_iterations,
            "activation {k}: the warm start differs"
        );
        assert_eq!(rw.passes, rv.passes);
        est = estimate_along(&pw, (k + 1) * 100_000);
    }
    // The car moved ~90 m; a window far ahead holds the other obstacle only.
    windowed
        .load_window(&rows[680..680 + WINDOW], s[680], false)
        .unwrap();
    assert_eq!(windowed.obstacles.parabolas().len(), 1);
    assert_eq!(windowed.stats.windows, 3);
    assert_eq!(windowed.stats.obstacle_errors, 0);
}

#[test]
fn a_window_too_large_for_the_path_is_refused_and_the_planner_says_no_path() {
    let rows = road();
    let mut windowed = Box::new(PlanTask::<f64, WINDOW>::new(settings(), 1.0));
    let e = windowed
        .load_window(&rows[..WINDOW + 1], 0.0, false)
        .unwrap_err();
    assert!(format!("{e:?}").contains("TooManyPoints"), "{e:?}");
    let est = estimate_at(&rows, 10, 0);
    assert!(windowed.run(&est).is_err());
}
