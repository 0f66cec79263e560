//! `host-sim run`: a closed-loop drive of a scenario, with its log, summary and figures.

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::closed_loop::{self, RunResult, SimOptions};
use crate::disturbance::{check_delay_ms, run_seed, Disturbances, DisturbedEcu, NoiseLevel};
use crate::figures;
use crate::road_friction::{MuPatch, RoadFriction};
use crate::scenario::{self, Scenario};
use crate::vehicle::{check_mass_scale, VehicleParams};

pub use crate::closed_loop::Precision;

/// Arguments of `host-sim run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Track: `paper` (built in) or a CSV file `# x_m,y_m,w_tr_right_m,w_tr_left_m`.
    #[arg(long, default_value = "paper")]
    pub track: String,
    /// The track file is an open path (default: closed loop).
    #[arg(long)]
    pub open: bool,
    /// Obstacles: `none`, `paper` (built in, on the paper track) or a CSV file `id,x_m,y_m`.
    #[arg(long, default_value = "none")]
    pub obstacles: String,
    /// Vehicle TOML file (default: the built-in car, `host-sim/vehicles/default.toml`).
    #[arg(long)]
    pub vehicle: Option<PathBuf>,
    /// Road friction coefficient μ, given to the plant and to the planner.
    #[arg(long, default_value_t = 1.0)]
    pub mu: f64,
    /// Friction given to the planner if different from the road's (default: --mu).
    #[arg(long)]
    pub planner_mu: Option<f64>,
    /// Laps to drive on a closed track.
    #[arg(long, default_value_t = 1)]
    pub laps: u32,
    /// Simulated time limit, s.
    #[arg(long, default_value_t = 600.0)]
    pub duration: f64,
    /// Initial speed, m/s (the paper: 15).
    #[arg(long, default_value_t = 15.0)]
    pub initial_speed: f64,
    /// ECU clock, MHz (the tasks' response times, so their deadlines, depend on it;
    /// their cycle budgets do not).
    #[arg(long, default_value_t = 168.0)]
    pub ecu_mhz: f64,
    /// Precision of the firmware maths.
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    /// Skip the PNG figures.
    #[arg(long)]
    pub no_plots: bool,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Road patches, load, noise and delay.
    #[command(flatten)]
    pub conditions: ConditionArgs,
}

/// The drive's conditions `run` and `pil` share with `sweep` (one value each here,
/// parsed and checked as the sweep does).
#[derive(Debug, Clone, PartialEq, Args)]
pub struct ConditionArgs {
    /// A patch of road with its own friction, `START_M:LENGTH_M:MU`: from START_M
    /// metres along the lap (the centre line's arc length from its first point),
    /// LENGTH_M metres long, friction MU (the rest of the road has --mu). Repeatable;
    /// wraps over laps.
    #[arg(long = "mu-patch", value_name = "START_M:LENGTH_M:MU")]
    pub mu_patches: Vec<MuPatch>,
    /// Scale of the plant's mass and inertias, in (0.2, 5) (the firmware is told the
    /// nominal car: an unknown load).
    #[arg(long, default_value_t = 1.0)]
    pub mass_scale: f64,
    /// Noise on the state estimate: none, low, medium, high or a multiple of the
    /// level-1 σ (`run` only; the seed is the sweep's seed 0 for the track).
    #[arg(long, default_value = "none")]
    pub noise: NoiseLevel,
    /// Delay of the state estimate, ms, rounded to 10 ms (`run` only).
    #[arg(long, default_value_t = 0.0)]
    pub delay_ms: f64,
}

impl Default for ConditionArgs {
    fn default() -> Self {
        Self {
            mu_patches: Vec::new(),
            mass_scale: 1.0,
            noise: NoiseLevel(0.0),
            delay_ms: 0.0,
        }
    }
}

impl ConditionArgs {
    /// Checks the load, the noise level and the delay (the patches are checked
    /// against the track by [`prepare`]).
    pub fn check(&self) -> Result<()> {
        check_mass_scale(self.mass_scale).map_err(|e| anyhow!(e))?;
        check_delay_ms(self.delay_ms).map_err(|e| anyhow!(e))?;
        Ok(())
    }

    /// The noise and delay on the estimate of a run on `track_name` (seed 0 of
    /// the sweep's seeds for that track).
    pub fn disturbances(&self, track_name: &str) -> Disturbances {
        Disturbances {
            noise_scale: self.noise.0,
            delay_ms: self.delay_ms,
            seed: run_seed(track_name, 0),
            ..Disturbances::default()
        }
    }
}

/// Loads the vehicle file or the built-in vehicle.
pub fn load_vehicle(path: Option<&Path>) -> Result<VehicleParams> {
    match path {
        None => Ok(VehicleParams::default()),
        Some(p) => Ok(VehicleParams::from_toml_file(p)?),
    }
}

/// Checks a friction coefficient given on the command line.
pub fn check_mu(name: &str, mu: f64) -> Result<()> {
    if !(mu.is_finite() && mu > 0.0 && mu <= 2.0) {
        bail!("{name} must be a friction coefficient in (0, 2], got {mu}");
    }
    Ok(())
}

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
                let mut ecu = closed_loop::SimulatedEcu::<f32>::new(scenario, vehicle, opts)?;
                closed_loop::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
            Precision::F64 => {
                let mut ecu = closed_loop::SimulatedEcu::<f64>::new(scenario, vehicle, opts)?;
                closed_loop::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
        }
    } else {
        match precision {
            Precision::F32 => {
                let mut ecu = DisturbedEcu::<f32>::new(scenario, vehicle, opts, d.clone())?;
                closed_loop::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
            Precision::F64 => {
                let mut ecu = DisturbedEcu::<f64>::new(scenario, vehicle, opts, d.clone())?;
                closed_loop::run_with(scenario, plant_car, opts, &mut ecu, progress)
            }
        }
    };
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    result
}

/// Checks `run`'s arguments and resolves the vehicle (the nominal car, the one the
/// firmware is told of), the scenario (with its `--mu-patch` patches, checked
/// against the track) and the options (shared by `run` and `pil`).
pub fn prepare(args: &RunArgs) -> Result<(VehicleParams, Scenario, SimOptions)> {
    check_mu("--mu", args.mu)?;
    let planner_mu = args.planner_mu.unwrap_or(args.mu);
    check_mu("--planner-mu", planner_mu)?;
    if args.laps == 0 {
        bail!("--laps must be at least 1");
    }
    if !(args.duration.is_finite() && args.duration > 0.0) {
        bail!(
            "--duration must be a positive number of seconds, got {}",
            args.duration
        );
    }
    if !(args.initial_speed.is_finite() && args.initial_speed >= 0.0 && args.initial_speed < 60.0) {
        bail!(
            "--initial-speed must be in [0, 60) m/s, got {}",
            args.initial_speed
        );
    }
    if !(args.ecu_mhz.is_finite() && args.ecu_mhz > 0.0) {
        bail!(
            "--ecu-mhz must be a positive clock frequency in MHz (e.g. 168), got {}",
            args.ecu_mhz
        );
    }
    args.conditions.check()?;
    let vehicle = load_vehicle(args.vehicle.as_deref())?;
    let mut scenario = scenario::resolve(&args.track, &args.obstacles, !args.open)?;
    RoadFriction::new(
        args.mu,
        &args.conditions.mu_patches,
        &scenario.track.name,
        scenario.track.length(),
        scenario.track.closed,
    )?;
    scenario.mu_patches = args.conditions.mu_patches.clone();
    let opts = SimOptions {
        mu_road: args.mu,
        mu_planner: planner_mu,
        laps: args.laps,
        max_duration_s: args.duration,
        initial_speed_mps: args.initial_speed,
        ecu_clock_hz: args.ecu_mhz * 1e6,
        ..SimOptions::default()
    };
    Ok((vehicle, scenario, opts))
}

/// The one-line summary `run` and `pil` print.
pub fn summary_line(scenario: &Scenario, s: &crate::closed_loop::Summary) -> String {
    format!(
        "{}: {} in {:.1} s over {:.0} m | lateral error max {:.3} m rms {:.3} m | |a_y| max {:.2} m/s² ({:.2}·μg) | collisions {} | plan failures {}/{} | deadline misses plan {} control {} | {:.0}× real time",
        scenario.track.name,
        if s.completed { "completed" } else { "NOT completed" },
        s.lap_time_s.unwrap_or(s.duration_s),
        s.distance_m,
        s.max_abs_lateral_error_m,
        s.rms_lateral_error_m,
        s.max_abs_ay_mps2,
        s.max_abs_ay_mps2 / (s.mu * f64::from(firmware::G)),
        s.collisions,
        s.plan_failures,
        s.plan_activations,
        s.plan_deadline_misses,
        s.control_deadline_misses,
        s.sim_speed_x_realtime,
    )
}

/// The line `run` and `pil` print on the road's friction and the firmware's `μ̂`.
pub fn friction_line(s: &crate::closed_loop::Summary) -> String {
    let opt = |x: Option<f64>, unit: &str| x.map_or("-".to_string(), |v| format!("{v:.3}{unit}"));
    format!(
        "friction: road μ min {:.2}{} | μ̂ min {} | false drop {} | slowest recovery after a patch {}{}",
        s.road_mu_min,
        if s.mu_patches.is_empty() {
            String::new()
        } else {
            format!(" (patches {})", s.mu_patches)
        },
        opt(s.friction_mu_min, ""),
        match (s.mu_false_drop, s.mu_false_drop_s) {
            (Some(true), Some(t)) => format!("yes, first at {t:.2} s"),
            (Some(_), _) => "no".into(),
            (None, _) => "-".into(),
        },
        opt(s.mu_recovery_s, " s"),
        match s.mu_unrecovered_exits {
            Some(n) if n > 0 => format!(" ({n} exits not recovered)"),
            _ => String::new(),
        },
    )
}

/// `host-sim run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let (vehicle, scenario, opts) = prepare(args)?;
    let plant_car = vehicle.with_mass_scale(args.conditions.mass_scale);
    let d = args.conditions.disturbances(&scenario.track.name);
    let result = simulate_with(
        &scenario,
        &vehicle,
        &plant_car,
        &opts,
        &d,
        args.precision,
        true,
    )?;
    write_outputs(&args.out, &scenario, &result, !args.no_plots)?;
    let s = &result.summary;
    println!("{}", summary_line(&scenario, s));
    println!("{}", friction_line(s));
    if !s.completed {
        println!("stopped: {}", s.stop_reason);
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

/// Writes `log.csv`, `plan_activations.csv` (one row per plan activation: when it
/// ran, its cost, its work counters), `summary.json` and (optionally) the figures
/// into `dir`.
pub fn write_outputs(
    dir: &Path,
    scenario: &Scenario,
    result: &RunResult,
    plots: bool,
) -> Result<()> {
    fs::create_dir_all(dir)
        .with_context(|| format!("cannot create output directory {}", dir.display()))?;
    let log_path = dir.join("log.csv");
    let mut w = csv::Writer::from_path(&log_path)
        .with_context(|| format!("cannot write {}", log_path.display()))?;
    for row in &result.log {
        w.serialize(row)?;
    }
    w.flush()?;
    let act_path = dir.join("plan_activations.csv");
    let mut w = csv::Writer::from_path(&act_path)
        .with_context(|| format!("cannot write {}", act_path.display()))?;
    for a in &result.plan_activations {
        w.serialize(a)?;
    }
    w.flush()?;
    let summary_path = dir.join("summary.json");
    fs::write(
        &summary_path,
        serde_json::to_string_pretty(&result.summary)?,
    )
    .with_context(|| format!("cannot write {}", summary_path.display()))?;
    if plots {
        figures::draw_all(dir, scenario, result)?;
    }
    Ok(())
}
