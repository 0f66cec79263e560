//! Friction that changes along the road (`--mu-patch`): the plant's wheels on their
//! own μ, a closed-loop lap across a wet patch, and the sweep's `mu_false_drop`
//! column against the definition applied to the run's own trace.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::closed_loop::simulate::simulate;
use host_sim::closed_loop::timeline::LogRow;
use host_sim::closed_loop::{Precision, SimOptions};
use host_sim::model::plant::{Inputs, Plant, State};
use host_sim::model::vehicle::VehicleParams;
use host_sim::sweep::execute::{execute, Common, LogRuns};
use host_sim::world::faults::Fault;
use host_sim::world::road_friction::MuPatch;
use host_sim::world::scenario::{Scenario, PAPER_HALF_WIDTH_M};

/// Speed after braking hard from 20 m/s for 1 s with the four wheels on `mu`.
fn speed_after_braking(mu: [f64; 4]) -> f64 {
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(20.0, &p)).unwrap();
    let brake = Inputs {
        torque_nm: [-1500.0; 4],
        delta_rad: 0.0,
    };
    for _ in 0..1000 {
        plant.step_on(&brake, mu).unwrap();
    }
    plant.state().vx_mps
}

#[test]
fn each_wheel_brakes_on_its_own_road() {
    let dry = speed_after_braking([1.0; 4]);
    let rear_on_ice = speed_after_braking([1.0, 1.0, 0.05, 0.05]);
    let all_on_ice = speed_after_braking([0.05; 4]);
    // The same numbers as `step` on a uniform road.
    let p = VehicleParams::default();
    let mut plant = Plant::new(p, State::at_speed(20.0, &p)).unwrap();
    for _ in 0..1000 {
        let brake = Inputs {
            torque_nm: [-1500.0; 4],
            delta_rad: 0.0,
        };
        plant.step(&brake, 1.0).unwrap();
    }
    assert_eq!(plant.state().vx_mps, dry);
    // Locked rear wheels on ice lose their share of the braking, not all of it.
    assert!(
        dry < rear_on_ice && rear_on_ice < all_on_ice,
        "{dry} {rear_on_ice} {all_on_ice}"
    );
    assert!(20.0 - rear_on_ice > 0.4 * (20.0 - dry), "{rear_on_ice}");
    assert!(all_on_ice > 19.0, "{all_on_ice}");
}

const PATCH: MuPatch = MuPatch {
    start_m: 300.0,
    length_m: 200.0,
    mu: 0.5,
};

/// The μ the log should show at arc length `s` (m) of the paper track, or `None`
/// within a car's length of the patch's ends (where the wheels straddle them).
fn expected_road_mu(s: f64) -> Option<f64> {
    let (a, b) = (PATCH.start_m, PATCH.start_m + PATCH.length_m);
    let margin = 2.0;
    if (s - a).abs() < margin || (s - b).abs() < margin {
        None
    } else if s > a && s < b {
        Some(PATCH.mu)
    } else {
        Some(1.0)
    }
}

#[test]
fn a_lap_across_a_wet_patch_stays_on_the_road_and_logs_the_road_under_the_car() {
    let mut scenario = Scenario::paper(false);
    scenario.mu_patches = vec![PATCH];
    let opts = SimOptions {
        max_duration_s: 200.0,
        ..SimOptions::default()
    };
    let r = simulate(
        &scenario,
        &VehicleParams::default(),
        &opts,
        Precision::F32,
        false,
    )
    .unwrap();
    let s = &r.summary;
    assert!(s.completed, "{}", s.stop_reason);
    assert_eq!(s.collisions, 0);
    // No off-road: the centre of gravity within the road's half-width everywhere.
    assert!(
        s.max_abs_lateral_error_m < PAPER_HALF_WIDTH_M,
        "{} m off the centre line",
        s.max_abs_lateral_error_m
    );
    assert_eq!(s.road_mu_min, 0.5);
    assert_eq!(s.mu_patches, "300:200:0.5");
    let mut on_patch = 0;
    for row in &r.log {
        if let Some(mu) = expected_road_mu(row.progress_m) {
            assert_eq!(
                row.road_mu, mu,
                "t = {} s, s = {} m",
                row.t_s, row.progress_m
            );
            on_patch += usize::from(mu == 0.5);
        }
    }
    // Crossing 196 m of the patch takes more than 5 s.
    assert!(on_patch > 500, "{on_patch} samples on the patch");
    // The judge ran: the ECU reports μ̂ in process.
    assert!(s.mu_false_drop.is_some());
    assert!(s.mu_unrecovered_exits.is_some());
}

/// The definition of a false drop applied by brute force to a log: the first time
/// at which μ̂ < 0.9 × the lowest road μ of the samples within the last 10 s.
fn first_false_drop(log: &[LogRow]) -> Option<f64> {
    log.iter().enumerate().find_map(|(k, row)| {
        let low = log[..=k]
            .iter()
            .rev()
            .take_while(|r| r.t_s >= row.t_s - 10.0)
            .map(|r| r.road_mu)
            .fold(f64::INFINITY, f64::min);
        (row.friction_mu < 0.9 * low).then_some(row.t_s)
    })
}

fn read_log(path: &std::path::Path) -> Vec<LogRow> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap();
    let (t, road, hat) = (col("t_s"), col("road_mu"), col("friction_mu"));
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            let f = |i: usize| rec[i].parse::<f64>().unwrap();
            LogRow {
                t_s: f(t),
                road_mu: f(road),
                friction_mu: f(hat),
                ..LogRow::default()
            }
        })
        .collect()
}

#[test]
fn the_sweeps_false_drop_column_follows_its_definition_on_the_runs_trace() {
    let dir = tempfile::tempdir().unwrap();
    // An icy patch (μ 0.3) on a road of μ 1: the friction check lowers μ̂ there,
    // so there is something to judge (a false drop or not, depending on how fast
    // μ̂ recovers). On the wet patch of μ 0.5 the traction control and the
    // anti-lock limit keep the wheels' slip small enough that μ̂ stays at 1.
    let spec = RunSpec {
        index: 0,
        track: "paper".into(),
        mu: 1.0,
        mu_planner: 1.0,
        vehicle: None,
        mass_scale: 1.0,
        noise: 0.0,
        delay_ms: 0.0,
        fault: Fault::None,
        seed: 0,
    };
    let common = Common {
        setting: Setting {
            duration_s: 200.0,
            mu_patches: vec![MuPatch { mu: 0.3, ..PATCH }],
            ..Setting::default()
        },
        obstacle_dir: None,
        log_dir: Some((dir.path().to_path_buf(), LogRuns::All)),
    };
    let row = execute(&spec, &common);
    let cell = |name: &str| {
        row.cell(name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .to_string()
    };
    assert_eq!(cell("error"), "");
    let log = read_log(&dir.path().join("0").join("log.csv"));
    assert!(log.iter().any(|r| r.road_mu == 0.3));
    assert!(log.iter().any(|r| r.friction_mu < 1.0), "μ̂ never moved");
    let want = first_false_drop(&log);
    assert_eq!(cell("mu_false_drop"), want.is_some().to_string());
    match want {
        Some(t) => {
            let got: f64 = cell("mu_false_drop_s").parse().unwrap();
            assert!((got - t).abs() < 1e-9, "{got} vs {t}");
        }
        None => assert_eq!(cell("mu_false_drop_s"), ""),
    }
    assert_eq!(cell("mu_patches"), "300:200:0.3");
    let low: f64 = cell("friction_mu_min").parse().unwrap();
    let lowest = log
        .iter()
        .map(|r| r.friction_mu)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(low, lowest);
}
