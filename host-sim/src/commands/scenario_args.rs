//! The scenario options `run`, `pil` and `sweep` share, in one clap struct
//! ([`ScenarioArgs`]) each command flattens, so the three speak one language, and
//! their checks (a path that does not exist is refused, with the forms accepted,
//! before any run starts). One choice of them sets a run up through
//! [`set_up`](crate::closed_loop::set_up::set_up), the same for `run`, `pil` and every run
//! of a sweep, so `run` with a sweep run's factors replays it.
//!
//! `sweep` takes lists (comma-separated; several tracks, folders and vehicles) and
//! runs every combination; `run` and `pil` take one value of each and refuse a list.
//! The old spellings `--tracks`, `--faults` and `--planner-mu` are hidden aliases.

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::Args;

use crate::closed_loop::set_up::{ObstacleSpec, Setting, OBSTACLE_FORMS};
use crate::model::actuator::{actuator_help, ActuatorSetting};
use crate::model::vehicle::check_mass_scale;
use crate::world::disturbance::{check_delay_ms, NoiseLevel};
use crate::world::faults::{fault_help, Fault};
use crate::world::road_friction::MuPatch;
use crate::world::road_grade::GradePatch;
use crate::world::scenario::ScenarioError;

/// What `--track` accepts.
pub const TRACK_FORMS: &str = "`paper` (the built-in track), a track CSV file (`# x_m,y_m,w_tr_right_m,w_tr_left_m`) or, for `sweep`, a folder of them (its `*.csv`)";

/// What `--vehicle` accepts.
pub const VEHICLE_FORMS: &str = "a vehicle TOML file (copy host-sim/vehicles/default.toml), or no --vehicle for the built-in car";

const TRACK_HELP: &str = "Track: `paper` (built in), a track CSV file `# x_m,y_m,w_tr_right_m,w_tr_left_m`, or (sweep) folders of them; `sweep` takes several";

const OBSTACLES_HELP: &str = "Obstacles: `none`, `paper` (built in, on the paper track), `random:N` (N boxes per km, placed from --seed) or an obstacle CSV file `id,x_m,y_m`";

/// The scenario options of `run`, `pil` and `sweep` (module docs).
#[derive(Debug, Clone, PartialEq, Args)]
pub struct ScenarioArgs {
    #[arg(long = "track", alias = "tracks", num_args = 1.., default_value = "paper", value_name = "TRACK", help = TRACK_HELP)]
    /// Tracks (`run` and `pil`: exactly one).
    pub tracks: Vec<String>,
    /// Track files are open paths (default: closed loops; the `paper` track is one).
    #[arg(long)]
    pub open: bool,
    #[arg(long, default_value = "none", value_name = "OBSTACLES", help = OBSTACLES_HELP)]
    /// The obstacles of every run.
    pub obstacles: ObstacleSpec,
    /// Seed of the random draws (random obstacles, noise), with the track's name
    /// (`sweep`: a comma-separated list, or --seeds N for 0..N).
    #[arg(long, value_delimiter = ',', default_value = "0")]
    pub seed: Vec<u32>,
    /// Road friction μ in (0, 2], the plant's and, unless --mu-planner, the
    /// planner's (`sweep`: a comma-separated list).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub mu: Vec<f64>,
    /// Friction given to the planner, in (0, 2] (default: the road's --mu; `sweep`: a
    /// comma-separated list).
    #[arg(long = "mu-planner", alias = "planner-mu", value_delimiter = ',')]
    pub mu_planner: Vec<f64>,
    /// Vehicle TOML file (default: the built-in car, host-sim/vehicles/default.toml;
    /// `sweep` takes several).
    #[arg(long, num_args = 1..)]
    pub vehicle: Vec<PathBuf>,
    /// Scale of the plant's mass and inertias, in (0.2, 5); the firmware is told the
    /// nominal car, an unknown load (`sweep`: a comma-separated list).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub mass_scale: Vec<f64>,
    /// Noise on the state estimate: none, low, medium, high (0, 1, 2, 4) or a
    /// multiple of the level-1 σ (`sweep`: a comma-separated list).
    #[arg(long, value_delimiter = ',', default_value = "none")]
    pub noise: Vec<NoiseLevel>,
    /// Delay of the state estimate, ms in [0, 1000], rounded to 10 ms (`sweep`: a
    /// comma-separated list).
    #[arg(long, value_delimiter = ',', default_value = "0")]
    pub delay_ms: Vec<f64>,
    /// Fault scenario (`--help` lists them; `sweep`: a comma-separated list).
    #[arg(long = "fault", alias = "faults", value_delimiter = ',', default_value = "none", value_name = "FAULT", long_help = fault_help())]
    pub faults: Vec<Fault>,
    /// A patch of road with its own friction, `START_M:LENGTH_M:MU`: from START_M
    /// metres along the lap (the centre line's arc length from its first point),
    /// LENGTH_M metres long, friction MU (the rest of the road has --mu).
    /// Repeatable; wraps over laps; the same in every run of a sweep.
    #[arg(long = "mu-patch", value_name = "START_M:LENGTH_M:MU")]
    pub mu_patches: Vec<MuPatch>,
    /// A stretch of road with a grade, `START_M:LENGTH_M:PERCENT`: from START_M
    /// metres along the lap, LENGTH_M metres long, rising PERCENT % (100 × rise
    /// over run, negative downhill, within ±30) in the direction of travel (the
    /// rest of the road is level). Repeatable; wraps over laps; the same in every
    /// run of a sweep.
    #[arg(
        long = "grade",
        value_name = "START_M:LENGTH_M:PERCENT",
        allow_hyphen_values = true
    )]
    pub grade_patches: Vec<GradePatch>,
    /// An actuator parameter of the plant's car, KEY=VALUE (`--help` lists them).
    #[arg(long = "actuator", value_name = "KEY=VALUE", long_help = actuator_help())]
    pub actuators: Vec<ActuatorSetting>,
    /// Laps to drive on a closed track (per run).
    #[arg(long, default_value_t = 1)]
    pub laps: u32,
    /// Simulated time limit per run, s.
    #[arg(long, default_value_t = 900.0)]
    pub duration: f64,
    /// Initial speed, m/s, in [0, 60) (the paper: 15).
    #[arg(long, default_value_t = 15.0)]
    pub initial_speed: f64,
}

/// Checks a friction coefficient given on the command line.
pub fn check_mu(name: &str, mu: f64) -> Result<()> {
    if !(mu.is_finite() && mu > 0.0 && mu <= 2.0) {
        bail!("{name} must be a friction coefficient in (0, 2], got {mu}");
    }
    Ok(())
}

/// Checks the laps, time limit and initial speed of a run.
pub fn check_run_length(laps: u32, duration_s: f64, initial_speed_mps: f64) -> Result<()> {
    if laps == 0 {
        bail!("--laps must be at least 1");
    }
    if !(duration_s.is_finite() && duration_s > 0.0) {
        bail!("--duration must be a positive number of seconds, got {duration_s}");
    }
    if !(initial_speed_mps.is_finite() && (0.0..60.0).contains(&initial_speed_mps)) {
        bail!("--initial-speed must be in [0, 60) m/s, got {initial_speed_mps}");
    }
    Ok(())
}

/// Checks a `--track` argument before any run: `paper`, an existing file, or (when
/// `folders`) an existing folder.
pub fn check_track_arg(track: &str, folders: bool) -> Result<()> {
    if track == "paper" {
        return Ok(());
    }
    let p = Path::new(track);
    if p.is_dir() {
        if folders {
            return Ok(());
        }
        bail!("--track {track}: is a folder; `run` and `pil` drive one track file (`sweep --track FOLDER` runs each of its *.csv)");
    }
    if !p.exists() {
        bail!("--track {track}: no such file or folder; give {TRACK_FORMS}");
    }
    Ok(())
}

/// Why `path`, given to `option`, is not a file to read (`None`: it is one), with
/// the forms the option takes.
fn not_a_file(option: &str, path: &Path, forms: &str) -> Option<String> {
    let what = if path.is_dir() {
        "is a folder"
    } else if !path.exists() {
        "no such file"
    } else {
        return None;
    };
    Some(format!("{option} {}: {what}; give {forms}", path.display()))
}

/// Checks `--obstacles` against the tracks before any run: an obstacle file must
/// exist, the `paper` obstacles need the `paper` track.
pub fn check_obstacles_arg(obstacles: &ObstacleSpec, tracks: &[String]) -> Result<()> {
    match obstacles {
        ObstacleSpec::File(f) => match not_a_file("--obstacles", Path::new(f), OBSTACLE_FORMS) {
            Some(e) => bail!(e),
            None => Ok(()),
        },
        ObstacleSpec::Paper => {
            if let Some(t) = tracks.iter().find(|t| t.as_str() != "paper") {
                return Err(
                    ScenarioError::PaperObstaclesNeedPaperTrack { track: t.clone() }.into(),
                );
            }
            Ok(())
        }
        ObstacleSpec::None | ObstacleSpec::Random(_) => Ok(()),
    }
}

/// Checks a `--vehicle` argument before any run.
pub fn check_vehicle_arg(path: &Path) -> Result<()> {
    match not_a_file("--vehicle", path, VEHICLE_FORMS) {
        Some(e) => bail!(e),
        None => Ok(()),
    }
}

impl ScenarioArgs {
    /// Checks every value and path before any run starts (`folders`: a track may
    /// be a folder, as for `sweep`).
    pub fn check(&self, folders: bool) -> Result<()> {
        for &mu in &self.mu {
            check_mu("--mu", mu)?;
        }
        for &mu in &self.mu_planner {
            check_mu("--mu-planner", mu)?;
        }
        for &k in &self.mass_scale {
            check_mass_scale(k).map_err(|e| anyhow!(e))?;
        }
        for &d in &self.delay_ms {
            check_delay_ms(d).map_err(|e| anyhow!(e))?;
        }
        check_run_length(self.laps, self.duration, self.initial_speed)?;
        for t in &self.tracks {
            check_track_arg(t, folders)?;
        }
        check_obstacles_arg(&self.obstacles, &self.tracks)?;
        for v in &self.vehicle {
            check_vehicle_arg(v)?;
        }
        Ok(())
    }

    /// The settings every run of these options shares.
    pub fn setting(&self) -> Setting {
        Setting {
            obstacles: self.obstacles.clone(),
            open: self.open,
            laps: self.laps,
            duration_s: self.duration,
            initial_speed_mps: self.initial_speed,
            mu_patches: self.mu_patches.clone(),
            grade_patches: self.grade_patches.clone(),
            actuators: self.actuators.clone(),
        }
    }

    /// The one choice of a single-run command (`command`: `run` or `pil`): each
    /// option must have one value (checked with [`Self::check`] first).
    pub fn one(&self, command: &str) -> Result<OneScenario> {
        self.check(false)?;
        fn single<T: Clone + fmt::Display>(command: &str, name: &str, v: &[T]) -> Result<T> {
            match v {
                [x] => Ok(x.clone()),
                _ => {
                    let list: Vec<String> = v.iter().map(ToString::to_string).collect();
                    bail!(
                        "{name} {}: `{command}` drives one scenario, give one value (`sweep` runs every combination of lists)",
                        list.join(",")
                    )
                }
            }
        }
        let shown =
            |v: &[PathBuf]| -> Vec<String> { v.iter().map(|p| p.display().to_string()).collect() };
        let noise: Vec<f64> = self.noise.iter().map(|n| n.0).collect();
        Ok(OneScenario {
            track: single(command, "--track", &self.tracks)?,
            mu: single(command, "--mu", &self.mu)?,
            mu_planner: match self.mu_planner.as_slice() {
                [] => None,
                v => Some(single(command, "--mu-planner", v)?),
            },
            vehicle: match self.vehicle.as_slice() {
                [] => None,
                [v] => Some(v.clone()),
                v => {
                    single(command, "--vehicle", &shown(v))?;
                    None
                }
            },
            mass_scale: single(command, "--mass-scale", &self.mass_scale)?,
            noise: NoiseLevel(single(command, "--noise", &noise)?),
            delay_ms: single(command, "--delay-ms", &self.delay_ms)?,
            fault: single(command, "--fault", &self.faults)?,
            seed: single(command, "--seed", &self.seed)?,
        })
    }
}

/// One value of each factor, as `run` and `pil` take them.
#[derive(Clone, Debug, PartialEq)]
pub struct OneScenario {
    /// Track: `paper` or a file.
    pub track: String,
    /// Road friction.
    pub mu: f64,
    /// Planner friction (`None`: the road's).
    pub mu_planner: Option<f64>,
    /// Vehicle file (`None`: the built-in car).
    pub vehicle: Option<PathBuf>,
    /// Plant mass scale.
    pub mass_scale: f64,
    /// Noise level.
    pub noise: NoiseLevel,
    /// Estimate delay, ms.
    pub delay_ms: f64,
    /// Fault scenario.
    pub fault: Fault,
    /// Seed number.
    pub seed: u32,
}
