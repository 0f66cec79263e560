//! Brakes that give more or less than commanded (`--actuator brake_gain=…`), end to
//! end: on an oval (`tests/data/oval.csv`: a straight at top speed, then braking
//! into a bend) the friction check must not read a weak brake as slip, nor a
//! strong one as a light car that slips when it drives (one mass ratio for the
//! drive and the brakes took μ̂ from 1 to 0.6 at a gain of 0.7 and to 0.4 at
//! 1.3), and the estimator must find the gain (`sweep.csv`'s `est_brake_gain`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::model::actuator::ActuatorSetting;
use host_sim::sweep::execute::{execute, Common};
use host_sim::world::faults::Fault;

/// Two laps of the oval at μ 1 with the brakes' gain `gain`, as the sweep runs
/// them; returns the cell called `name` of each of `names`.
fn oval<const N: usize>(gain: f64, names: [&str; N]) -> [String; N] {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/oval.csv");
    let spec = RunSpec {
        index: 0,
        track: path.to_str().unwrap().into(),
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
            laps: 2,
            actuators: vec![ActuatorSetting {
                field: "brake_gain",
                value: gain,
            }],
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
    assert_eq!(cell("error"), "");
    names.map(cell)
}

#[test]
fn brakes_weaker_or_stronger_than_commanded_are_not_slip() {
    for gain in [0.7, 1.0, 1.3] {
        let [outcome, drop, mu_min, b, u_b] = oval(
            gain,
            [
                "outcome",
                "mu_false_drop",
                "friction_mu_min",
                "est_brake_gain",
                "est_brake_uncertainty",
            ],
        );
        assert_eq!(outcome, "ok", "gain {gain}");
        assert_eq!(drop, "false", "gain {gain}: μ̂ min {mu_min}");
        let mu_min: f64 = mu_min.parse().unwrap();
        assert!(mu_min >= 0.99, "gain {gain}: μ̂ min {mu_min}");
        // The gain found within 10 % (the estimator's goal) by the end of the second
        // lap, and known to be.
        let (b, u_b): (f64, f64) = (b.parse().unwrap(), u_b.parse().unwrap());
        assert!((b - gain).abs() <= 0.1 * gain, "gain {gain}: b = {b}");
        assert!(u_b < 0.1, "gain {gain}: u_b = {u_b}");
    }
}
