//! `host-sim run`: a closed-loop drive of a scenario, with its log, summary and figures.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Result};
use clap::Args;

use crate::closed_loop::set_up::{set_up, ObstacleSpec, RunSpec, SetUp, Setting};
use crate::closed_loop::simulate::simulate_with;
use crate::closed_loop::summary::Summary;
use crate::closed_loop::{Precision, SimOptions};
use crate::commands::scenario_args::{
    check_mu, check_obstacles_arg, check_run_length, check_track_arg, check_vehicle_arg,
    ScenarioArgs,
};
use crate::model::actuator::ActuatorSetting;
use crate::model::vehicle::check_mass_scale;
use crate::output::run_files::write_outputs;
use crate::world::disturbance::{check_delay_ms, NoiseLevel};
use crate::world::faults::Fault;
use crate::world::road_friction::MuPatch;
use crate::world::road_grade::GradePatch;
use crate::world::scenario::Scenario;

/// `host-sim run`'s command line: the scenario options `run`, `pil` and `sweep`
/// share ([`ScenarioArgs`], one value each here), the firmware's arithmetic and
/// clock, and the outputs.
#[derive(Debug, Clone, Args)]
pub struct RunCommand {
    /// Track, obstacles, friction, car, conditions, fault, seed, laps.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// ECU clock, MHz (the tasks' response times, so their deadlines, depend on it;
    /// their cycle budgets do not).
    #[arg(long, default_value_t = f64::from(firmware::timing::ECU_CLOCK_HZ) / 1e6)]
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
}

impl RunCommand {
    /// The run's settings: one value of each scenario option, checked (`command`,
    /// `run` or `pil`, names the command in the errors).
    pub fn resolve(&self, command: &str) -> Result<RunArgs> {
        let sc = &self.scenario;
        let one = sc.one(command)?;
        Ok(RunArgs {
            track: one.track,
            open: sc.open,
            obstacles: sc.obstacles.to_string(),
            vehicle: one.vehicle,
            mu: one.mu,
            planner_mu: one.mu_planner,
            laps: sc.laps,
            duration: sc.duration,
            initial_speed: sc.initial_speed,
            precision: self.precision,
            ecu_mhz: self.ecu_mhz,
            no_plots: self.no_plots,
            out: self.out.clone(),
            conditions: ConditionArgs {
                mu_patches: sc.mu_patches.clone(),
                grade_patches: sc.grade_patches.clone(),
                actuators: sc.actuators.clone(),
                mass_scale: one.mass_scale,
                noise: one.noise,
                delay_ms: one.delay_ms,
                fault: one.fault,
                seed: one.seed,
            },
        })
    }
}

/// One run's settings: what the command lines of `run` and `pil` resolve to
/// ([`RunCommand::resolve`]), or what a program builds (the PIL laps of `wcet`).
#[derive(Debug, Clone)]
pub struct RunArgs {
    /// Track: `paper` (built in) or a track CSV file.
    pub track: String,
    /// The track file is an open path (default: closed loop).
    pub open: bool,
    /// Obstacles: `none`, `paper`, `random:N` or an obstacle CSV file
    /// ([`ObstacleSpec`]).
    pub obstacles: String,
    /// Vehicle TOML file (`None`: the built-in car).
    pub vehicle: Option<PathBuf>,
    /// Road friction coefficient μ, given to the plant and to the planner.
    pub mu: f64,
    /// Friction given to the planner if different from the road's (`--mu-planner`).
    pub planner_mu: Option<f64>,
    /// Laps to drive on a closed track.
    pub laps: u32,
    /// Simulated time limit, s.
    pub duration: f64,
    /// Initial speed, m/s.
    pub initial_speed: f64,
    /// Precision of the firmware maths.
    pub precision: Precision,
    /// ECU clock, MHz.
    pub ecu_mhz: f64,
    /// Skip the PNG figures.
    pub no_plots: bool,
    /// Output directory (created).
    pub out: PathBuf,
    /// Road patches and grades, actuators, load, noise, delay, fault and seed.
    pub conditions: ConditionArgs,
}

/// The conditions of a run beyond its track, obstacles, car and friction (the
/// default: none of them).
#[derive(Debug, Clone, PartialEq)]
pub struct ConditionArgs {
    /// Patches of road with their own friction (`--mu-patch`).
    pub mu_patches: Vec<MuPatch>,
    /// Stretches of road with a grade (`--grade`).
    pub grade_patches: Vec<GradePatch>,
    /// Actuator parameters of the plant's car over its vehicle file's (`--actuator`).
    pub actuators: Vec<ActuatorSetting>,
    /// Scale of the plant's mass and inertias (the firmware is told the nominal car).
    pub mass_scale: f64,
    /// Noise on the state estimate.
    pub noise: NoiseLevel,
    /// Delay of the state estimate, ms.
    pub delay_ms: f64,
    /// Fault scenario.
    pub fault: Fault,
    /// Seed number of the random draws (with the track's name, as a sweep's `seed`).
    pub seed: u32,
}

impl Default for ConditionArgs {
    fn default() -> Self {
        Self {
            mu_patches: Vec::new(),
            grade_patches: Vec::new(),
            actuators: Vec::new(),
            mass_scale: 1.0,
            noise: NoiseLevel(0.0),
            delay_ms: 0.0,
            fault: Fault::None,
            seed: 0,
        }
    }
}

impl ConditionArgs {
    /// Checks the load and the delay (the patches and grades are checked against
    /// the track, the actuators against the car, by [`prepare`]).
    pub fn check(&self) -> Result<()> {
        check_mass_scale(self.mass_scale).map_err(|e| anyhow!(e))?;
        check_delay_ms(self.delay_ms).map_err(|e| anyhow!(e))?;
        Ok(())
    }
}

/// Checks a run's settings (every path before anything runs) and sets it up as a
/// sweep's run with the same factors ([`set_up`]): the scenario (its obstacles,
/// `random:N` ones included, and `--mu-patch` patches, checked against the track),
/// the nominal car (the firmware is told of it) and the plant's, the options and
/// the disturbances (noise, delay, the fault's). Shared by `run` and `pil`.
pub fn prepare(args: &RunArgs) -> Result<SetUp> {
    check_mu("--mu", args.mu)?;
    let planner_mu = args.planner_mu.unwrap_or(args.mu);
    check_mu("--mu-planner", planner_mu)?;
    check_run_length(args.laps, args.duration, args.initial_speed)?;
    if !(args.ecu_mhz.is_finite() && args.ecu_mhz > 0.0) {
        bail!(
            "--ecu-mhz must be a positive clock frequency in MHz (e.g. 168), got {}",
            args.ecu_mhz
        );
    }
    let c = &args.conditions;
    c.check()?;
    check_track_arg(&args.track, false)?;
    let obstacles: ObstacleSpec = args.obstacles.parse().map_err(|e: String| anyhow!(e))?;
    check_obstacles_arg(&obstacles, std::slice::from_ref(&args.track))?;
    if let Some(v) = &args.vehicle {
        check_vehicle_arg(v)?;
    }
    let default_clock_hz = SimOptions::default().ecu_clock_hz;
    let overrun = matches!(c.fault, Fault::Overrun(_));
    if overrun && (args.ecu_mhz * 1e6 - default_clock_hz).abs() > 1.0 {
        bail!(
            "--fault {} sets the ECU clock itself: leave --ecu-mhz out",
            c.fault
        );
    }
    let spec = RunSpec {
        index: 0,
        track: args.track.clone(),
        mu: args.mu,
        mu_planner: planner_mu,
        vehicle: args.vehicle.clone(),
        mass_scale: c.mass_scale,
        noise: c.noise.0,
        delay_ms: c.delay_ms,
        fault: c.fault,
        seed: c.seed,
    };
    let setting = Setting {
        obstacles,
        open: args.open,
        laps: args.laps,
        duration_s: args.duration,
        initial_speed_mps: args.initial_speed,
        mu_patches: c.mu_patches.clone(),
        grade_patches: c.grade_patches.clone(),
        actuators: c.actuators.clone(),
    };
    let mut s = set_up(&spec, &setting)?;
    if !overrun {
        s.opts.ecu_clock_hz = args.ecu_mhz * 1e6;
    }
    Ok(s)
}

/// The one-line summary `run` and `pil` print.
pub fn summary_line(scenario: &Scenario, s: &Summary) -> String {
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

/// The line `run` and `pil` print on the road's friction, the firmware's `μ̂` and
/// the plans' sideslip lag `λ`.
pub fn friction_line(s: &Summary) -> String {
    let opt = |x: Option<f64>, unit: &str| x.map_or("-".to_string(), |v| format!("{v:.3}{unit}"));
    format!(
        "friction: road μ min {:.2}{} | μ̂ min {} | false drop {} | slowest recovery after a patch {}{} | sideslip lag {}",
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
        opt(s.sideslip_lag.map(|l| l * 1e3), " mrad per m/s²"),
    )
}

/// The line `run` and `pil` print on the plant's road grades and actuators, when
/// the run has either.
pub fn plant_line(s: &Summary) -> Option<String> {
    let or_none = |x: &str, none: &str| {
        if x.is_empty() {
            none.to_string()
        } else {
            x.to_string()
        }
    };
    (!(s.grade_patches.is_empty() && s.actuators.is_empty())).then(|| {
        format!(
            "plant: grades {} | actuators {}",
            or_none(&s.grade_patches, "none (level)"),
            or_none(&s.actuators, "ideal")
        )
    })
}

/// `host-sim run` from its command line.
pub fn command(cmd: &RunCommand) -> Result<()> {
    run(&cmd.resolve("run")?)
}

/// `host-sim run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let s = prepare(args)?;
    let result = simulate_with(
        &s.scenario,
        &s.nominal,
        &s.plant_car,
        &s.opts,
        &s.disturbances,
        args.precision,
        true,
    )?;
    write_outputs(&args.out, &s.scenario, &result, !args.no_plots)?;
    let sum = &result.summary;
    println!("{}", summary_line(&s.scenario, sum));
    println!("{}", friction_line(sum));
    if let Some(line) = plant_line(sum) {
        println!("{line}");
    }
    if !sum.completed {
        println!("stopped: {}", sum.stop_reason);
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
