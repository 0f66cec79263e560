//! Fuzzing the firmware boundary: the public entry points (the reference path
//! builder, the obstacle manager, the MPC step, the two tasks) driven with arbitrary
//! finite and non-finite states, tracks, obstacles and plans, in `f32` (the ECU's
//! precision). Every entry point must return (never panic), report a status, and
//! whatever it returns for the actuators must be finite and within their limits.
//!
//! `cargo test -p firmware --test fuzz` runs [`CASES`] cases per property; the long
//! run, `cargo test --release -p firmware --test fuzz -- --ignored`, runs
//! [`LONG_CASES`] per property (the cases come from the fixed seed in
//! `.cargo/config.toml`; change `PROPTEST_RNG_SEED` to explore others).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::low_level::{Actuation, LowLevelConfig};
use firmware::mpc::{Mpc, MpcSettings};
use firmware::obstacles::{Obstacle, ObstacleManager};
use firmware::plan::{Plan, PlanNode, HORIZON};
use firmware::reference_path::ReferencePath;
use firmware::state_estimate::StateEstimate;
use firmware::tasks::{ControlTask, PlanTask, CONTROL_PERIOD_US, PLAN_PERIOD_US};
use firmware::vehicle_config::VehicleConfig;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::sync::atomic::{AtomicU32, Ordering};

/// How many cases reached the interesting paths (a fuzzer that never gets past the
/// input checks tests nothing): paths loaded, MPC steps solved, plans published.
static PATHS_LOADED: AtomicU32 = AtomicU32::new(0);
static MPC_SOLVED: AtomicU32 = AtomicU32::new(0);
static PLANS_PUBLISHED: AtomicU32 = AtomicU32::new(0);
/// Plan nodes whose steering is past the mechanical limit (see [`check_plan`]).
static PLAN_STEER_PAST_LIMIT: AtomicU32 = AtomicU32::new(0);

/// Cases per property in `cargo test`.
const CASES: u32 = 128;
/// Cases per property in the long run (`-- --ignored`).
const LONG_CASES: u32 = 20_000;
/// Path capacity (as small as the ECU's window, so overflow is exercised too).
const CAP: usize = 256;

/// The built-in car as the firmware is told of it.
fn car() -> VehicleConfig<f32> {
    VehicleConfig::reference()
}

/// Any `f32`: mostly ordinary magnitudes, often a special value.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -200.0f32..200.0,
        1 => -1e30f32..1e30,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::MAX),
        1 => Just(0.0f32),
        1 => Just(-0.0f32),
        1 => Just(f32::MIN_POSITIVE),
    ]
}

/// A plausible value (near the track, a speed) or, sometimes, anything.
fn near(lo: f32, hi: f32) -> impl Strategy<Value = f32> {
    prop_oneof![8 => lo..hi, 1 => any_f32()]
}

fn estimate() -> impl Strategy<Value = StateEstimate<f32>> {
    (
        0u64..10_000_000,
        near(-60.0, 60.0),
        near(-60.0, 60.0),
        near(-7.0, 7.0),
        near(-1.0, 40.0),
        near(-3.0, 3.0),
        near(-2.0, 2.0),
        near(-0.7, 0.7),
    )
        .prop_map(estimate_of)
}

/// The estimate of `(stamp_us, x_m, y_m, psi_rad, vx_mps, vy_mps, yaw_rate_radps,
/// delta_rad)`.
fn estimate_of(
    (t, x, y, psi, vx, vy, r, d): (u64, f32, f32, f32, f32, f32, f32, f32),
) -> StateEstimate<f32> {
    StateEstimate {
        stamp_us: t,
        x_m: x,
        y_m: y,
        psi_rad: psi,
        vx_mps: vx,
        vy_mps: vy,
        yaw_rate_radps: r,
        delta_rad: d,
        ..StateEstimate::zeroed()
    }
}

/// A small deviation from a pose on the track (added by [`on_track`]): position
/// and heading errors, speeds, steering; sometimes anything.
fn deviation() -> impl Strategy<Value = StateEstimate<f32>> {
    (
        0u64..10_000_000,
        near(-1.5, 1.5),
        near(-1.5, 1.5),
        near(-0.3, 0.3),
        near(0.0, 20.0),
        near(-1.0, 1.0),
        near(-0.5, 0.5),
        near(-0.3, 0.3),
    )
        .prop_map(estimate_of)
}

/// The estimate `d` relative to the track's point `k` (heading along the track).
fn on_track(rows: &[[f32; 4]], k: usize, d: &StateEstimate<f32>) -> StateEstimate<f32> {
    let n = rows.len().max(1);
    let a = rows.get(k % n).copied().unwrap_or([0.0; 4]);
    let b = rows
        .get((k + 1) % n)
        .copied()
        .unwrap_or([1.0, 0.0, 0.0, 0.0]);
    StateEstimate {
        x_m: a[0] + d.x_m,
        y_m: a[1] + d.y_m,
        psi_rad: (b[1] - a[1]).atan2(b[0] - a[0]) + d.psi_rad,
        ..*d
    }
}

/// Arbitrary track rows `[x, y, w_right, w_left]`, 0 to 300 of them (past `CAP`).
fn any_rows() -> impl Strategy<Value = Vec<[f32; 4]>> {
    prop::collection::vec(
        (any_f32(), any_f32(), any_f32(), any_f32()).prop_map(|(a, b, c, d)| [a, b, c, d]),
        0..300,
    )
}

/// A roughly circular closed track of radius 40–200 m (40 to 199 points), its points jittered, a
/// few of its values sometimes replaced by anything.
fn circuit_rows() -> impl Strategy<Value = Vec<[f32; 4]>> {
    (
        40.0f32..200.0,
        40usize..200,
        prop::collection::vec((-0.4f32..0.4, -0.4f32..0.4), 200),
        2.0f32..8.0,
        prop::collection::vec((0usize..200, 0usize..4, any_f32()), 0..3),
    )
        .prop_map(|(r, n, jitter, w, corrupt)| {
            let mut rows: Vec<[f32; 4]> = (0..n)
                .map(|i| {
                    let a = i as f32 / n as f32 * core::f32::consts::TAU;
                    [r * a.cos() + jitter[i].0, r * a.sin() + jitter[i].1, w, w]
                })
                .collect();
            for (i, k, v) in corrupt {
                if let Some(row) = rows.get_mut(i) {
                    row[k] = v;
                }
            }
            rows
        })
}

fn obstacles() -> impl Strategy<Value = Vec<Vec<[f32; 2]>>> {
    prop::collection::vec(
        prop::collection::vec((near(-60.0, 60.0), near(-60.0, 60.0)), 0..10)
            .prop_map(|v| v.into_iter().map(|(x, y)| [x, y]).collect()),
        0..20,
    )
}

fn any_plan() -> impl Strategy<Value = Plan<f32>> {
    (
        0u64..10_000_000,
        prop_oneof![4 => Just(0.2f32), 1 => any_f32()],
        prop::collection::vec(
            (
                near(-60.0, 60.0),
                near(-60.0, 60.0),
                near(0.0, 40.0),
                near(-7.0, 7.0),
                near(-0.6, 0.6),
            ),
            HORIZON + 1,
        ),
        prop::collection::vec((near(-8.0, 6.0), near(-0.5, 0.5)), HORIZON),
    )
        .prop_map(|(stamp, dt, nodes, inputs)| {
            let mut p = Plan::zeroed();
            p.stamp_us = stamp;
            p.dt_s = dt;
            for (k, (x, y, v, psi, d)) in nodes.into_iter().enumerate() {
                p.nodes[k] = PlanNode {
                    s_m: k as f32,
                    x_m: x,
                    y_m: y,
                    v_mps: v,
                    psi_rad: psi,
                    delta_rad: d,
                };
            }
            for (k, (a, r)) in inputs.into_iter().enumerate() {
                p.inputs[k] = [a, r];
            }
            p
        })
}

/// The actuator limits: finite, steering within its mechanical limit, each wheel's
/// torque within the traction and braking limits.
fn check_actuation(a: &Actuation<f32>, cfg: &LowLevelConfig<f32>) -> Result<(), TestCaseError> {
    prop_assert!(a.delta_rad.is_finite(), "steering {:?}", a);
    prop_assert!(
        a.delta_rad.abs() <= cfg.steer_limit_rad * (1.0 + 1e-6),
        "steering {} past the limit {}",
        a.delta_rad,
        cfg.steer_limit_rad
    );
    for t in a.wheel_torque_nm {
        prop_assert!(t.is_finite(), "torque {:?}", a);
        prop_assert!(
            t <= cfg.max_traction_torque_nm * (1.0 + 1e-5)
                && -t <= cfg.max_braking_torque_nm * (1.0 + 1e-5),
            "wheel torque {} outside [-{}, {}]",
            t,
            cfg.max_braking_torque_nm,
            cfg.max_traction_torque_nm
        );
    }
    let total: f32 = a.wheel_torque_nm.iter().sum();
    prop_assert!(total <= cfg.max_traction_torque_nm * (1.0 + 1e-5));
    prop_assert!(-total <= cfg.max_braking_torque_nm * (1.0 + 1e-5));
    Ok(())
}

/// A published plan is finite, its inputs inside the MPC's bounds and its
/// steering inside the mechanical limit.
fn check_plan(p: &Plan<f32>, s: &MpcSettings<f32>) -> Result<(), TestCaseError> {
    prop_assert!(p.dt_s.is_finite() && p.dt_s > 0.0);
    for n in &p.nodes {
        for v in [n.s_m, n.x_m, n.y_m, n.v_mps, n.psi_rad, n.delta_rad] {
            prop_assert!(v.is_finite(), "plan node {:?}", n);
        }
        // Known, reported to the MPC's owner: an optimal plan may steer past the
        // mechanical limit (the MPC keeps δ within it only through the soft validity
        // constraint); counted, not failed. The control task clamps the command.
        if n.delta_rad.abs() > s.delta_mech_max_rad * 1.001 + 1e-4 {
            PLAN_STEER_PAST_LIMIT.fetch_add(1, Ordering::Relaxed);
        }
    }
    // The QP (f32) meets its bounds to its tolerance: within 1 % of the bound.
    let tol = |b: f32| 0.01 * b.abs() + 1e-3;
    for [a, r] in &p.inputs {
        prop_assert!(a.is_finite() && r.is_finite());
        prop_assert!(
            *a >= s.accel_min_mps2 - tol(s.accel_min_mps2)
                && *a <= s.accel_max_mps2 + tol(s.accel_max_mps2),
            "acceleration {} outside [{}, {}]",
            a,
            s.accel_min_mps2,
            s.accel_max_mps2
        );
        prop_assert!(
            r.abs() <= s.steer_rate_max_radps + tol(s.steer_rate_max_radps),
            "steering rate {} past {}: {:?}",
            r,
            s.steer_rate_max_radps,
            p.inputs.map(|u| u[1])
        );
    }
    Ok(())
}

fn path_of(rows: &[[f32; 4]]) -> Option<Box<ReferencePath<f32, CAP>>> {
    let mut p: Box<ReferencePath<f32, CAP>> = Box::new(ReferencePath::new());
    p.load_track(rows, true).ok()?;
    PATHS_LOADED.fetch_add(1, Ordering::Relaxed);
    Some(p)
}

fn fw_obstacles(polys: &[Vec<[f32; 2]>]) -> Vec<Obstacle<f32>> {
    polys
        .iter()
        .enumerate()
        .filter_map(|(k, v)| Obstacle::from_vertices(k as u32, v).ok())
        .collect()
}

fn path_builder(rows: Vec<[f32; 4]>, closed: bool, q: [f32; 2]) -> Result<(), TestCaseError> {
    let mut p: Box<ReferencePath<f32, CAP>> = Box::new(ReferencePath::new());
    if p.load_track(&rows, closed).is_ok() {
        prop_assert!(p.length_m().is_finite() && p.length_m() > 0.0);
        if let Some(pr) = p.project(q, None) {
            if q[0].is_finite() && q[1].is_finite() && q[0].abs() < 1e6 && q[1].abs() < 1e6 {
                prop_assert!(pr.s_m.is_finite() && pr.lateral_m.is_finite());
            }
        }
        let _ = p.curvature_at(q[0]);
        let _ = p.widths_at(q[1]);
        let _ = p.max_abs_curvature_between(q[0], q[1]);
    }
    Ok(())
}

fn obstacle_manager(rows: Vec<[f32; 4]>, polys: Vec<Vec<[f32; 2]>>) -> Result<(), TestCaseError> {
    let Some(path) = path_of(&rows) else {
        return Ok(());
    };
    let mut m = ObstacleManager::new();
    let _ = m.update(&car().obstacle_settings(1.0), &*path, &fw_obstacles(&polys));
    for par in m.parabolas() {
        let _ = par.constraint_value_and_gradient([0.0, 0.0]);
    }
    Ok(())
}

fn mpc_step(
    rows: Vec<[f32; 4]>,
    polys: Vec<Vec<[f32; 2]>>,
    (k, d): (usize, StateEstimate<f32>),
    mu: f32,
) -> Result<(), TestCaseError> {
    let Some(path) = path_of(&rows) else {
        return Ok(());
    };
    let est = on_track(&rows, k, &d);
    let settings = car().mpc_settings();
    let mut m = ObstacleManager::new();
    let _ = m.update(&car().obstacle_settings(1.0), &*path, &fw_obstacles(&polys));
    let mut mpc: Box<Mpc<f32>> = Box::new(Mpc::new());
    let mut plan = Plan::zeroed();
    // Twice: a cold start, then a warm one from its solution.
    for k in 0..2u64 {
        let mut e = est;
        e.stamp_us = est.stamp_us + k * PLAN_PERIOD_US;
        if mpc
            .step(&settings, &*path, m.parabolas(), &e, mu, &mut plan)
            .is_ok()
        {
            MPC_SOLVED.fetch_add(1, Ordering::Relaxed);
            check_plan(&plan, &settings)?;
        }
    }
    Ok(())
}

fn control_task(
    plan: Plan<f32>,
    ests: Vec<StateEstimate<f32>>,
    now0: u64,
) -> Result<(), TestCaseError> {
    let cfg = car().low_level_config();
    let mut c = ControlTask::new(cfg).map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
    for (k, e) in ests.iter().enumerate() {
        let a = c.run(e, &plan, now0 + k as u64 * CONTROL_PERIOD_US);
        check_actuation(&a, &cfg)?;
    }
    Ok(())
}

fn both_tasks(
    rows: Vec<[f32; 4]>,
    polys: Vec<Vec<[f32; 2]>>,
    (k, ests): (usize, Vec<StateEstimate<f32>>),
) -> Result<(), TestCaseError> {
    let mut planner: Box<PlanTask<f32, CAP>> = Box::new(PlanTask::new(car().mpc_settings(), 1.0));
    if planner.path.load_track(&rows, true).is_err() {
        return Ok(());
    }
    let pt = &mut *planner;
    let _ = pt.obstacles.update(
        &car().obstacle_settings(1.0),
        &pt.path,
        &fw_obstacles(&polys),
    );
    let cfg = car().low_level_config();
    let mut control = ControlTask::new(cfg).map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
    let mut shared = Plan::zeroed();
    for (i, e) in ests.iter().enumerate() {
        let now = i as u64 * CONTROL_PERIOD_US;
        let mut e = on_track(&rows, k + i / 10, e);
        e.stamp_us = now;
        let a = control.run(&e, &shared, now);
        check_actuation(&a, &cfg)?;
        if now.is_multiple_of(PLAN_PERIOD_US) {
            let ok = planner.run(&e).is_ok();
            prop_assert_eq!(ok, planner.last_error.is_none());
            if planner.publish_at(&mut shared, now) {
                PLANS_PUBLISHED.fetch_add(1, Ordering::Relaxed);
                check_plan(&shared, &planner.settings)?;
            }
        }
    }
    Ok(())
}

/// A fresh runner per property (a runner counts its successes across `run` calls).
fn runner(cases: u32) -> TestRunner {
    TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    })
}

fn all_properties(cases: u32) {
    runner(cases)
        .run(
            &(any_rows(), any::<bool>(), (any_f32(), any_f32())),
            |(rows, c, q)| path_builder(rows, c, [q.0, q.1]),
        )
        .unwrap();
    runner(cases)
        .run(
            &(
                circuit_rows(),
                any::<bool>(),
                (near(-250.0, 250.0), near(-250.0, 250.0)),
            ),
            |(rows, c, q)| path_builder(rows, c, [q.0, q.1]),
        )
        .unwrap();
    runner(cases)
        .run(&(circuit_rows(), obstacles()), |(rows, o)| {
            obstacle_manager(rows, o)
        })
        .unwrap();
    runner(cases)
        .run(
            &(
                circuit_rows(),
                obstacles(),
                (0usize..200, deviation()),
                near(0.05, 1.5),
            ),
            |(rows, o, e, mu)| mpc_step(rows, o, e, mu),
        )
        .unwrap();
    runner(cases)
        .run(
            &(
                any_plan(),
                prop::collection::vec(estimate(), 1..60),
                0u64..10_000_000,
            ),
            |(p, e, t)| control_task(p, e, t),
        )
        .unwrap();
    runner(cases)
        .run(
            &(
                circuit_rows(),
                obstacles(),
                (0usize..200, prop::collection::vec(deviation(), 1..40)),
            ),
            |(rows, o, e)| both_tasks(rows, o, e),
        )
        .unwrap();
    let (paths, solved, published) = (
        PATHS_LOADED.load(Ordering::Relaxed),
        MPC_SOLVED.load(Ordering::Relaxed),
        PLANS_PUBLISHED.load(Ordering::Relaxed),
    );
    eprintln!(
        "fuzz: {paths} paths loaded, {solved} MPC steps solved, {published} plans published, \
         {} plan nodes steering past the mechanical limit",
        PLAN_STEER_PAST_LIMIT.load(Ordering::Relaxed)
    );
    assert!(paths >= cases, "too few paths loaded: {paths}");
    assert!(solved >= cases / 8, "too few MPC steps solved: {solved}");
    assert!(
        published >= cases / 8,
        "too few plans published: {published}"
    );
}

#[test]
fn firmware_boundary_never_panics_and_stays_in_limits() {
    all_properties(CASES);
}

#[test]
#[ignore = "long fuzz run: cargo test --release -p firmware --test fuzz -- --ignored"]
fn firmware_boundary_long_run() {
    all_properties(LONG_CASES);
}
