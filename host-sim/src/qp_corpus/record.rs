//! Recording a corpus: the MPC in closed loop with a kinematic-bicycle plant, every
//! QP copied before its solve ([`record`]); the built-in scenario.

use std::cell::RefCell;

use anyhow::{bail, ensure, Result};
use firmware::mpc::{Mpc, MpcQpProblem};
use firmware::obstacles::{Obstacle, ObstacleManager};
use firmware::plan::Plan;
use firmware::reference_path::ReferencePath;
use firmware::state_estimate::StateEstimate;
use firmware::Real;

use crate::closed_loop::Precision;
use crate::model::vehicle::VehicleParams;
use crate::qp_corpus::entry::{CorpusEntry, WarmStartEntry};

/// Speed at the start of a recording, m/s.
pub const START_SPEED_MPS: f64 = 15.0;
/// Road friction coefficient used for the recording (dimensionless).
pub const MU: f64 = 1.0;
/// Default number of MPC steps (0.1 s each): a little more than a lap of the
/// built-in track.
pub const DEFAULT_STEPS: usize = 400;
/// Largest number of track rows [`record`] accepts (the reference path's capacity).
pub const PATH_CAPACITY: usize = 4096;
/// Planning period of the closed loop, s.
const STEP_S: f64 = 0.1;
/// Plant integration steps per planning period.
const PLANT_SUBSTEPS: usize = 10;

/// A QP copied before its solve, with the working set the solve starts from.
type PendingQp<T> = (Box<MpcQpProblem<T>>, Vec<WarmStartEntry>);

/// The built-in closed track: a 120 m × 70 m loop (counter-clockwise, starting at
/// `(10, 0)` heading +X) of four straights joined by 90° curves of radii 30, 15, 20 and
/// 10 m, one point per metre, rows `[x, y, w_right, w_left]` with 4 m half-widths.
pub fn builtin_track_rows() -> Vec<[f64; 4]> {
    use std::f64::consts::FRAC_PI_2;
    let (w, h) = (120.0f64, 70.0f64);
    // Corner radii: bottom-right, top-right, top-left, bottom-left.
    let r = [30.0f64, 15.0, 20.0, 10.0];
    let centres = [
        [w - r[0], r[0]],
        [w - r[1], h - r[1]],
        [r[2], h - r[2]],
        [r[3], r[3]],
    ];
    // Straight starts: bottom, right, top, left (each ends where the next curve starts).
    let straights = [
        ([r[3], 0.0], [w - r[0], 0.0]),
        ([w, r[0]], [w, h - r[1]]),
        ([w - r[1], h], [r[2], h]),
        ([0.0, h - r[2]], [0.0, r[3]]),
    ];
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for k in 0..4 {
        let (p0, p1) = straights[k];
        let len = (p1[0] - p0[0]).hypot(p1[1] - p0[1]);
        let n = len.round().max(1.0) as usize;
        for i in 0..n {
            let t = i as f64 / n as f64;
            pts.push([p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])]);
        }
        // Curve k turns from heading k·90° to (k+1)·90°, counter-clockwise.
        let a0 = -FRAC_PI_2 + k as f64 * FRAC_PI_2;
        let n = (r[k] * FRAC_PI_2).round().max(2.0) as usize;
        for i in 0..n {
            let a = a0 + FRAC_PI_2 * i as f64 / n as f64;
            pts.push([
                centres[k][0] + r[k] * a.cos(),
                centres[k][1] + r[k] * a.sin(),
            ]);
        }
    }
    pts.into_iter().map(|p| [p[0], p[1], 4.0, 4.0]).collect()
}

/// The built-in obstacles: three 4 m × 2 m boxes (vertices, m) on the built-in track,
/// each on the outer side of a straight (bottom, right, top), so the car passes them
/// on the inside.
///
/// Why the outside: the firmware's `Parabola::is_relevant` only checks the position
/// along the obstacle's tangent (`ξ`), so an obstacle's row also appears where the
/// loop passes through the same `ξ` strip on the far side of the track; for a box on
/// the inside of the loop, passed on the outside, that far-side row cannot be met
/// (a box at `(118.5, 42)` makes step 217 end `WorkingSetFull` with a 130 m slack).
pub fn builtin_obstacles() -> Vec<Vec<[f64; 2]>> {
    let boxed = |cx: f64, cy: f64, hx: f64, hy: f64| {
        vec![
            [cx - hx, cy - hy],
            [cx + hx, cy - hy],
            [cx + hx, cy + hy],
            [cx - hx, cy + hy],
        ]
    };
    vec![
        // Bottom straight (heading +X): right is −Y.
        boxed(55.0, -1.5, 2.0, 1.0),
        // Right straight (heading +Y): right is +X.
        boxed(121.5, 42.0, 1.0, 2.0),
        // Top straight (heading −X): right is +Y.
        boxed(60.0, 71.5, 2.0, 1.0),
    ]
}

/// Runs the MPC in closed loop with a kinematic-bicycle plant for `steps` planning
/// periods of 0.1 s along the track `rows` (`[x, y, w_right, w_left]`, m; `closed` for
/// a loop) around `obstacles` (polygons, vertices in m), in `precision`, and returns
/// every QP it solved, in order.
///
/// The car starts at the first track point heading to the second at
/// [`START_SPEED_MPS`], on a road of friction [`MU`]. If an MPC step fails, the run
/// stops and the QPs recorded so far, including the failed one, are returned.
pub fn record(
    rows: &[[f64; 4]],
    closed: bool,
    obstacles: &[Vec<[f64; 2]>],
    steps: usize,
    precision: Precision,
) -> Result<Vec<CorpusEntry>> {
    match precision {
        Precision::F64 => record_in::<f64>(rows, closed, obstacles, steps, precision),
        Precision::F32 => record_in::<f32>(rows, closed, obstacles, steps, precision),
    }
}

fn record_in<T: Real>(
    rows: &[[f64; 4]],
    closed: bool,
    obstacles: &[Vec<[f64; 2]>],
    steps: usize,
    precision: Precision,
) -> Result<Vec<CorpusEntry>> {
    ensure!(
        rows.len() >= 2,
        "the track needs at least 2 rows [x, y, w_right, w_left], got {}",
        rows.len()
    );
    ensure!(
        rows.len() <= PATH_CAPACITY,
        "the track has {} rows, at most {PATH_CAPACITY} fit: resample it more coarsely",
        rows.len()
    );
    let rows_t: Vec<[T; 4]> = rows.iter().map(|r| r.map(T::from_f64)).collect::<Vec<_>>();
    let mut path = Box::new(ReferencePath::<T, PATH_CAPACITY>::new());
    path.load_track(&rows_t, closed)
        .map_err(|e| anyhow::anyhow!("the track cannot be loaded: {e:?}"))?;
    let mut obs_t = Vec::with_capacity(obstacles.len());
    for (k, verts) in obstacles.iter().enumerate() {
        let v: Vec<[T; 2]> = verts.iter().map(|p| p.map(T::from_f64)).collect();
        let o = Obstacle::from_vertices(k as u32, &v)
            .map_err(|e| anyhow::anyhow!("obstacle {k} is invalid: {e:?}"))?;
        obs_t.push(o);
    }
    // The simulator's settings for the built-in vehicle.
    let vehicle = VehicleParams::default();
    let car = crate::model::vehicle::vehicle_config::<T>(&vehicle);
    let settings = car.mpc_settings();
    let obstacle_settings = car.obstacle_settings(T::from_f64(MU));
    let mut manager = ObstacleManager::<T>::new();
    manager
        .update(&obstacle_settings, &*path, &obs_t)
        .map_err(|e| {
            anyhow::anyhow!(
                "the obstacles cannot be placed on the track: {e:?} (move them or widen the road)"
            )
        })?;

    let max_iter = settings.qp_max_iter;
    let (p0, p1) = match (rows.first(), rows.get(1)) {
        (Some(a), Some(b)) => (*a, *b),
        _ => bail!("the track needs at least 2 rows"),
    };
    let psi0 = (p1[1] - p0[1]).atan2(p1[0] - p0[0]);
    let mut est = StateEstimate::<T> {
        stamp_us: 0,
        x_m: T::from_f64(p0[0]),
        y_m: T::from_f64(p0[1]),
        psi_rad: T::from_f64(psi0),
        vx_mps: T::from_f64(START_SPEED_MPS),
        ..StateEstimate::zeroed()
    };
    let mut mpc = Box::new(Mpc::<T>::new());
    let mut plan = Box::new(Plan::<T>::zeroed());
    let mut out = Vec::new();
    let mu = T::from_f64(MU);
    let dt = T::from_f64(STEP_S / PLANT_SUBSTEPS as f64);
    for step in 0..steps {
        // Written by `before`, taken by `after`: both closures need it.
        let pending: RefCell<Option<PendingQp<T>>> = RefCell::new(None);
        let mut pass = 0u32;
        let res = mpc.step_observed(
            &settings,
            &*path,
            manager.parabolas(),
            &est,
            mu,
            &mut plan,
            |q| {
                let ws = q
                    .working_set()
                    .iter()
                    .map(WarmStartEntry::from_active)
                    .collect();
                *pending.borrow_mut() = Some((Box::new(q.problem().clone()), ws));
            },
            |s| {
                if let Some((p, ws)) = pending.borrow_mut().take() {
                    let mut e = CorpusEntry::from_solve(&p, s, max_iter, precision, step, pass);
                    e.warm_start = ws;
                    out.push(e);
                }
                pass += 1;
            },
        );
        if res.is_err() {
            break;
        }
        let mut xi = [
            T::ZERO,
            est.x_m,
            est.y_m,
            est.speed_mps(),
            est.psi_rad,
            est.delta_rad,
        ];
        for _ in 0..PLANT_SUBSTEPS {
            xi = settings
                .geometry
                .discretize(&xi, &plan.inputs[0], dt)
                .x_next;
        }
        est = StateEstimate {
            stamp_us: est.stamp_us + (STEP_S * 1e6) as u64,
            x_m: xi[1],
            y_m: xi[2],
            psi_rad: xi[4],
            vx_mps: xi[3],
            vy_mps: T::ZERO,
            yaw_rate_radps: T::ZERO,
            delta_rad: xi[5],
            ..StateEstimate::zeroed()
        };
    }
    Ok(out)
}
