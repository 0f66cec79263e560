//! Wheel speeds in the state estimate, end to end: a planner told 1.5 times the
//! road's friction (`mu-high`) asks more than the tyres give. With the wheel
//! speeds the traction control and anti-lock limit keep the wheels' slip near
//! the tyres' peak (without them, on Oschersleben: slip ratio 0.82); when the
//! wheel speeds are noisy and late like the rest of the estimate, the brakes'
//! left/right distribution keeps the inside wheels of braked bends from
//! locking; and on a dry road the noisy, late wheels lower μ̂ nowhere.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::closed_loop::set_up::{RunSpec, Setting};
use host_sim::sweep::execute::{execute, Common};
use host_sim::world::faults::Fault;

/// One lap of `track` (a file of `tests/data`) at μ 1 under `fault`, at the
/// noise level `noise` with the estimate `delay_ms` late (ms), as the sweep
/// runs it (seed 0); the cells of `names`.
fn lap<const N: usize>(
    track: &str,
    fault: Fault,
    (noise, delay_ms): (f64, f64),
    names: [&str; N],
) -> [String; N] {
    lap_seeded(track, fault, (noise, delay_ms), 0, names)
}

/// [`lap`] with the noise drawn from `seed`.
fn lap_seeded<const N: usize>(
    track: &str,
    fault: Fault,
    (noise, delay_ms): (f64, f64),
    seed: u32,
    names: [&str; N],
) -> [String; N] {
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
        noise,
        delay_ms,
        fault,
        seed,
    };
    let common = Common {
        setting: Setting::default(),
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
    names.map(cell)
}

#[test]
fn a_planner_asking_too_much_spins_no_wheel_far_past_its_peak() {
    let [outcome, slip, mu_min] = lap(
        "Oschersleben.csv",
        Fault::MuHigh(1.5),
        (0.0, 0.0),
        ["outcome", "max_abs_slip_ratio", "friction_mu_min"],
    );
    assert_eq!(outcome, "ok");
    let (slip, mu_min): (f64, f64) = (slip.parse().unwrap(), mu_min.parse().unwrap());
    // The default tyre's peak is at a slip ratio of about 0.1; the wheel is
    // caught past 0.15 (plus 1 m/s) and its torque halved.
    assert!(slip < 0.25, "slip ratio {slip}");
    // The traction control keeps the spins short: no slip event, μ̂ at the
    // planner's, never under the road's.
    assert!(mu_min >= 0.9, "μ̂ min {mu_min}");
}

/// The same with the estimate at noise level 4 (`--noise high`: each wheel's
/// speed 0.12 m/s of noise) and 100 ms late, wheel speeds included, on five
/// circuits and two seeds. The limits act on what the wheels did 100 ms before:
/// a wheel is seen locking only 100 ms after it passed `0.15·V + 1 m/s`, so
/// its slip goes further past the peak than with the wheels seen at once. What
/// keeps it short of locking is the brakes' left/right distribution by the
/// lateral load transfer: with the torque split equally, the inside wheel of a
/// braked bend locked first, the laps' peak slip ratios' median 0.76 (0.50 to
/// 0.98); with it 0.45 (0.33 to 0.75). A peak near locking is left to chance
/// under this noise: on 40 other seeds of these circuits (`host-sim sweep`
/// `--fault mu-high:1.5 --noise high --delay-ms 100 --seed 2,...,9`) 3 to 5 of
/// the 40 laps passed 0.9 (the median 0.55 to 0.56 before the accelerometer,
/// 0.49 with it), none since the limits wait for the late estimate's age
/// (`firmware::tasks`' wheel limits; median 0.50; these ten laps' median 0.583,
/// their eighth 0.80), so the test asks the median under 0.6 and no more than
/// two of its ten laps at 0.9 or past it.
#[test]
fn noisy_late_wheel_speeds_still_hold_the_slip_of_a_planner_asking_too_much() {
    let mut peaks = Vec::new();
    for track in [
        "Oschersleben.csv",
        "Budapest.csv",
        "BrandsHatch.csv",
        "MoscowRaceway.csv",
        "Shanghai.csv",
    ] {
        for seed in 0..2 {
            let [outcome, slip] = lap_seeded(
                track,
                Fault::MuHigh(1.5),
                (4.0, 100.0),
                seed,
                ["outcome", "max_abs_slip_ratio"],
            );
            assert_eq!(outcome, "ok", "{track} seed {seed}");
            peaks.push(slip.parse::<f64>().unwrap());
        }
    }
    peaks.sort_by(f64::total_cmp);
    let median = 0.5 * (peaks[4] + peaks[5]);
    assert!(median < 0.6, "median peak slip ratio {median}: {peaks:?}");
    assert!(peaks[7] < 0.9, "peak slip ratios {peaks:?}");
}

/// On a dry road with the planner's friction, a noisy estimate 100 ms late:
/// the inside wheel unloaded in a braked bend, or the noise, is no slip event
/// (before one wheel locked alone counted, it lowered μ̂ to 0.8 or less).
#[test]
fn noisy_late_wheel_speeds_lower_mu_hat_nowhere_on_a_dry_road() {
    let [outcome, drop, mu_min] = lap(
        "Oschersleben.csv",
        Fault::None,
        (4.0, 100.0),
        ["outcome", "mu_false_drop", "friction_mu_min"],
    );
    assert_eq!(outcome, "ok");
    assert_eq!(drop, "false", "μ̂ min {mu_min}");
    let mu_min: f64 = mu_min.parse().unwrap();
    assert!(mu_min >= 0.99, "μ̂ min {mu_min}");
}
