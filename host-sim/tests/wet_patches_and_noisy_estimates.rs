//! Grip that changes and sensors that lie, end to end on real circuits
//! (`tests/data`): a wet patch entered in a curve (Shanghai: a car standing at its
//! steering lock must turn its wheels back; Oschersleben: front tyres at their
//! limit must keep their lateral grip under braking; BrandsHatch and
//! MoscowRaceway: front tyres sliding at a large angle must not be steered to the
//! lock; on each the friction estimate back at 0.9 of the configured friction
//! within 10 s of the patch's exit) and a noisy, late estimate on
//! a wet road (Budapest at μ 0.3: the car must not stand still on a clear road).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::sweep::execute::{execute, Common};
use host_sim::world::faults::Fault;
use host_sim::world::road_friction::MuPatch;

/// One lap of `track` (a file of `tests/data`) as the sweep runs it; returns the
/// cells `outcome`, `stop_reason`, `collisions` and `mu_recovery_s`.
fn lap(track: &str, mu: f64, noise: f64, delay_ms: f64, patches: Vec<MuPatch>) -> [String; 4] {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(track);
    let spec = RunSpec {
        index: 0,
        track: path.to_str().unwrap().into(),
        mu,
        mu_planner: mu,
        vehicle: None,
        mass_scale: 1.0,
        noise,
        delay_ms,
        fault: Fault::None,
        seed: 0,
    };
    let common = Common {
        setting: Setting {
            mu_patches: patches,
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
    assert_eq!(cell("error"), "", "{track}");
    [
        cell("outcome"),
        cell("stop_reason"),
        cell("collisions"),
        cell("mu_recovery_s"),
    ]
}

#[test]
fn a_wet_patch_entered_in_a_curve_costs_no_lap() {
    let patch = MuPatch {
        start_m: 500.0,
        length_m: 200.0,
        mu: 0.5,
    };
    for track in [
        "Shanghai.csv",
        "Oschersleben.csv",
        "BrandsHatch.csv",
        "MoscowRaceway.csv",
    ] {
        let [outcome, stop, collisions, recovery] = lap(track, 1.0, 0.0, 0.0, vec![patch]);
        assert_eq!(outcome, "ok", "{track}: {stop}");
        assert_eq!(collisions, "0", "{track}");
        // Empty when μ̂ never dropped on the patch.
        let recovery: f64 = if recovery.is_empty() {
            0.0
        } else {
            recovery.parse().unwrap()
        };
        assert!(
            recovery <= 10.0,
            "{track}: μ̂ back at 0.9 after {recovery} s"
        );
    }
}

#[test]
fn a_noisy_late_estimate_on_a_wet_road_drives_on() {
    let [outcome, stop, collisions, _] = lap("Budapest.csv", 0.3, 4.0, 100.0, Vec::new());
    assert_eq!(outcome, "ok", "{stop}");
    assert_eq!(collisions, "0");
}
