//! Wheel speeds in the state estimate, end to end: a planner told 1.5 times the
//! road's friction (`mu-high`) asks more than the tyres give. With the wheel
//! speeds the friction check sees the driven wheels spin and lowers μ̂, and the
//! traction control and anti-lock limit keep the wheels' slip near the tyres'
//! peak (without them, on Oschersleben: slip ratio 0.82 and μ̂ left at 1.5).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::sweep::execute::{execute, Common};
use host_sim::sweep::table::header;
use host_sim::world::faults::Fault;

/// One lap of `track` (a file of `tests/data`) at μ 1 under `fault`, as the
/// sweep runs it; the cells of `names`.
fn lap<const N: usize>(track: &str, fault: Fault, names: [&str; N]) -> [String; N] {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(track);
    let spec = RunSpec {
        index: 0,
        track: path.to_str().unwrap().into(),
        mu: 1.0,
        mu_planner: 1.0,
        vehicle: None,
        mass_scale: 1.0,
        noise: 0.0,
        delay_ms: 0.0,
        fault,
        seed: 0,
    };
    let common = Common {
        setting: Setting::default(),
        obstacle_dir: None,
        log_dir: None,
    };
    let row = execute(&spec, &common);
    let cells: Vec<(String, String)> = header().into_iter().skip(10).zip(row.cells).collect();
    let cell = |name: &str| {
        cells
            .iter()
            .find(|(h, _)| h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .1
            .clone()
    };
    assert_eq!(cell("error"), "", "{track}");
    names.map(cell)
}

#[test]
fn a_planner_asking_too_much_spins_no_wheel_far_past_its_peak_and_lowers_mu_hat() {
    let [outcome, slip, mu_min] = lap(
        "Oschersleben.csv",
        Fault::MuHigh(1.5),
        ["outcome", "max_abs_slip_ratio", "friction_mu_min"],
    );
    assert_eq!(outcome, "ok");
    let (slip, mu_min): (f64, f64) = (slip.parse().unwrap(), mu_min.parse().unwrap());
    // The default tyre's peak is at a slip ratio of about 0.1; the wheel is
    // caught past 0.15 (plus 1 m/s) and its torque halved.
    assert!(slip < 0.25, "slip ratio {slip}");
    // μ̂ below the planner's 1.5, not below the one-event floor 0.6 × 1.5.
    assert!((0.89..1.5).contains(&mu_min), "μ̂ min {mu_min}");
}
