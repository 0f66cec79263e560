//! The plant a real car lives in, end to end: a lap of the paper track over a
//! climb and a descent (the grade under the car in the log, the accelerometer's
//! `g·sin γ`), a lap with lagging actuators, and the same run twice with all of it
//! and a biased, noisy estimate, bit for bit; a sweep row records the grades and
//! actuators.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::closed_loop::simulate::{simulate, simulate_with};
use host_sim::closed_loop::timeline::{LogRow, RunResult};
use host_sim::closed_loop::{Precision, SimOptions};
use host_sim::model::actuator::ActuatorSetting;
use host_sim::model::vehicle::{VehicleParams, G};
use host_sim::sweep::execute::{execute, Common};
use host_sim::world::disturbance::{run_seed, Disturbances};
use host_sim::world::faults::Fault;
use host_sim::world::road_grade::GradePatch;
use host_sim::world::scenario::{Scenario, PAPER_HALF_WIDTH_M};

/// +6 % from 100 m to 400 m, −6 % from 550 m to 850 m: twice per lap of the paper
/// track, back to where it started.
const HILL: [GradePatch; 2] = [
    GradePatch {
        start_m: 100.0,
        length_m: 300.0,
        percent: 6.0,
    },
    GradePatch {
        start_m: 550.0,
        length_m: 300.0,
        percent: -6.0,
    },
];

/// The grade the log should show at arc length `s` (m), or `None` within a car's
/// length of a patch's ends (where the axles straddle them).
fn expected_grade_pct(s: f64) -> Option<f64> {
    let margin = 3.0;
    for p in HILL {
        let (a, b) = (p.start_m, p.start_m + p.length_m);
        if (s - a).abs() < margin || (s - b).abs() < margin {
            return None;
        }
        if s > a && s < b {
            return Some(p.percent);
        }
    }
    Some(0.0)
}

/// Over the samples of `log` between the arc lengths `a` and `b` (m) where the car
/// goes straight (`|a_y| < 0.3 m/s²`: in a bend the speed's rate of change also
/// has the side-slip's share of the lateral acceleration): the mean of the specific
/// force less the speed's rate of change (m/s²), which is `g·sin γ` on a grade `γ`
/// and 0 on the level.
fn specific_force_less_acceleration(log: &[LogRow], a: f64, b: f64) -> f64 {
    let excess: Vec<f64> = log
        .windows(3)
        .filter(|w| w[1].progress_m >= a && w[1].progress_m <= b && w[1].ay_mps2.abs() < 0.3)
        .map(|w| w[1].specific_force_x_mps2 - (w[2].v_mps - w[0].v_mps) / (w[2].t_s - w[0].t_s))
        .collect();
    assert!(
        excess.len() > 200,
        "{} straight samples in {a}–{b} m",
        excess.len()
    );
    excess.iter().sum::<f64>() / excess.len() as f64
}

#[test]
fn a_lap_over_a_6_percent_climb_and_descent_completes_and_logs_the_grade_and_the_accelerometer() {
    let mut scenario = Scenario::paper(false);
    scenario.grade_patches = HILL.to_vec();
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
    assert!(
        s.max_abs_lateral_error_m < PAPER_HALF_WIDTH_M,
        "{} m off the centre line",
        s.max_abs_lateral_error_m
    );
    assert_eq!(s.grade_patches, "100:300:6;550:300:-6");
    assert_eq!(s.actuators, "");
    let (mut up, mut down) = (0, 0);
    for row in &r.log {
        if let Some(pct) = expected_grade_pct(row.progress_m) {
            assert!(
                (row.road_grade_pct - pct).abs() < 1e-9,
                "t = {} s, s = {} m: {} %",
                row.t_s,
                row.progress_m,
                row.road_grade_pct
            );
            up += usize::from(pct > 0.0);
            down += usize::from(pct < 0.0);
        }
    }
    assert!(up > 1000 && down > 1000, "{up} samples up, {down} down");
    // The accelerometer reads the speed's rate of change plus g·sin γ: over each
    // patch's middle, and nothing more on the level before the climb.
    let g_sin = G * 0.06_f64.atan().sin();
    for (a, b, want) in [
        (130.0, 370.0, g_sin),
        (580.0, 820.0, -g_sin),
        (20.0, 90.0, 0.0),
    ] {
        let got = specific_force_less_acceleration(&r.log, a, b);
        assert!(
            (got - want).abs() < 0.05 * g_sin,
            "{a}–{b} m: {got} m/s², want {want} m/s²"
        );
    }
}

/// The actuators of the robustness runs: steering 80 ms, torque 50 ms of lag.
fn lagging() -> Vec<ActuatorSetting> {
    [
        "steering_time_constant_s=0.08",
        "torque_time_constant_s=0.05",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect()
}

#[test]
fn a_lap_with_lagging_actuators_completes_and_its_steering_lags_the_command() {
    let car = VehicleParams::default();
    let plant_car = VehicleParams {
        actuators: car.actuators.with_settings(&lagging()),
        ..car
    };
    let opts = SimOptions {
        max_duration_s: 200.0,
        ..SimOptions::default()
    };
    let r = simulate_with(
        &Scenario::paper(false),
        &car,
        &plant_car,
        &opts,
        &Disturbances::default(),
        Precision::F32,
        false,
    )
    .unwrap();
    let s = &r.summary;
    assert!(s.completed, "{}", s.stop_reason);
    assert!(
        s.max_abs_lateral_error_m <= 0.4,
        "{} m off the centre line",
        s.max_abs_lateral_error_m
    );
    assert_eq!(
        s.actuators,
        "steering_time_constant_s=0.08;torque_time_constant_s=0.05"
    );
    // The applied angle trails the command: they differ at a good part of the
    // samples (with ideal actuators, only where the command changed within 10 ms).
    let apart = r
        .log
        .iter()
        .filter(|row| (row.delta_applied_rad - row.delta_rad).abs() > 1e-4)
        .count();
    assert!(
        apart > r.log.len() / 4,
        "{apart} of {} samples",
        r.log.len()
    );
}

/// A short run of the paper track over the hill with lagging actuators and a
/// noisy, biased estimate of seed `seed`.
fn everything(seed: u64) -> RunResult {
    let car = VehicleParams::default();
    let plant_car = VehicleParams {
        actuators: car.actuators.with_settings(&lagging()),
        ..car
    };
    let mut scenario = Scenario::paper(false);
    scenario.grade_patches = HILL.to_vec();
    let opts = SimOptions {
        max_duration_s: 15.0,
        ..SimOptions::default()
    };
    let d = Disturbances {
        noise_scale: 4.0,
        seed,
        ..Disturbances::default()
    };
    simulate_with(
        &scenario,
        &car,
        &plant_car,
        &opts,
        &d,
        Precision::F32,
        false,
    )
    .unwrap()
}

#[test]
fn the_same_run_with_grades_lagging_actuators_and_a_biased_estimate_is_the_same_bit_for_bit() {
    let seed = run_seed("paper", 0);
    let (a, b) = (everything(seed), everything(seed));
    // Debug formatting: NaN fields compare equal, every bit of the others does.
    assert_eq!(format!("{:?}", a.log), format!("{:?}", b.log));
    assert_eq!(a.log.len(), 1501);
    let other = everything(run_seed("paper", 1));
    assert_ne!(
        format!("{:?}", a.log),
        format!("{:?}", other.log),
        "another seed, other draws"
    );
}

#[test]
fn a_sweep_row_records_the_grades_and_the_actuators() {
    let spec = RunSpec {
        index: 0,
        track: "paper".into(),
        mu: 1.0,
        mu_planner: 1.0,
        vehicle: None,
        mass_scale: 1.0,
        noise: 1.0,
        delay_ms: 0.0,
        fault: Fault::None,
        seed: 0,
    };
    let common = Common {
        setting: Setting {
            duration_s: 5.0,
            grade_patches: HILL.to_vec(),
            actuators: lagging(),
            ..Setting::default()
        },
        obstacle_dir: None,
        log_dir: None,
    };
    let row = execute(&spec, &common);
    let cell = |name: &str| {
        row.cell(name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .to_string()
    };
    assert_eq!(cell("stop_reason"), "time limit reached");
    assert_eq!(cell("grade_patches"), "100:300:6;550:300:-6");
    assert_eq!(
        cell("actuators"),
        "steering_time_constant_s=0.08;torque_time_constant_s=0.05"
    );
}
