//! One closed-loop run on the modelled ECU ([`SimulatedEcu`]), or on the modelled
//! ECU behind the disturbances of a run ([`DisturbedEcu`]: noise, delay, a fault),
//! in either precision, with a progress bar if asked: what `run` drives and what
//! tests call.

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};

use crate::closed_loop::disturbed_ecu::DisturbedEcu;
use crate::closed_loop::ecu::SimulatedEcu;
use crate::closed_loop::timeline::{self, RunResult};
use crate::closed_loop::{Precision, SimOptions};
use crate::model::vehicle::VehicleParams;
use crate::world::disturbance::Disturbances;
use crate::world::scenario::Scenario;

/// Runs one closed-loop scenario and returns its result (no files written).
pub fn simulate(
    scenario: &Scenario,
    vehicle: &VehicleParams,
    opts: &SimOptions,
    precision: Precision,
    show_progress: bool,
) -> Result<RunResult> {
    let plain = Disturbances::default();
    simulate_with(
        scenario,
        vehicle,
        vehicle,
        opts,
        &plain,
        precision,
        show_progress,
    )
}

/// As [`simulate`], the plant's car `plant_car` (the firmware is told of
/// `vehicle`) and the estimate behind `d` (noise, delay).
pub fn simulate_with(
    scenario: &Scenario,
    vehicle: &VehicleParams,
    plant_car: &VehicleParams,
    opts: &SimOptions,
    d: &Disturbances,
    precision: Precision,
    show_progress: bool,
) -> Result<RunResult> {
    let bar = if show_progress {
        let b = ProgressBar::new(opts.max_duration_s.ceil() as u64);
        b.set_style(
            ProgressStyle::with_template("{spinner} simulated {pos} s  {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        Some(b)
    } else {
        None
    };
    let progress = |t: f64, d: f64| {
        if let Some(b) = &bar {
            b.set_position(t as u64);
            b.set_message(format!("{d:.0} m driven"));
        }
    };
    let result = if *d == Disturbances::default() {
        match precision {
            Precision::F32 => {
                let mut ecu = SimulatedEcu::<f32>::new(scenario, vehicle, opts)?;
                timeline::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
            Precision::F64 => {
                let mut ecu = SimulatedEcu::<f64>::new(scenario, vehicle, opts)?;
                timeline::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
        }
    } else {
        match precision {
            Precision::F32 => {
                let mut ecu = DisturbedEcu::<f32>::new(scenario, vehicle, opts, d.clone())?;
                timeline::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
            Precision::F64 => {
                let mut ecu = DisturbedEcu::<f64>::new(scenario, vehicle, opts, d.clone())?;
                timeline::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
        }
    };
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    result
}
