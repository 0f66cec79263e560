//! The scenario options `run`, `pil` and `sweep` share, in one clap struct
//! ([`ScenarioArgs`]) each command flattens, so the three speak one language; their
//! checks (a path that does not exist is refused, with the forms accepted, before
//! any run starts); and the set-up of one run from one choice of them
//! ([`set_up`]), the same for `run`, `pil` and every run of a sweep, so `run` with a
//! sweep run's factors replays it.
//!
//! `sweep` takes lists (comma-separated; several tracks, folders and vehicles) and
//! runs every combination; `run` and `pil` take one value of each and refuse a list.
//! The old spellings `--tracks`, `--faults` and `--planner-mu` are hidden aliases.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{anyhow, bail, Result};
use clap::Args;

use crate::closed_loop::SimOptions;
use crate::model::vehicle::{check_mass_scale, VehicleParams};
use crate::world::disturbance::{
    check_delay_ms, run_seed, Disturbances, Dropout, DropoutKind, LateObstacle, NoiseLevel,
};
use crate::world::faults::{fault_help, Fault, FAULT_START_S};
use crate::world::obstacle_file::{load_obstacles_path, Obstacle};
use crate::world::obstacle_placement::{box_at, random_obstacles, RoadCheck};
use crate::world::road_friction::{MuPatch, RoadFriction};
use crate::world::scenario::{self, Scenario, ScenarioError};

/// What `--track` accepts.
pub const TRACK_FORMS: &str = "`paper` (the built-in track), a track CSV file (`# x_m,y_m,w_tr_right_m,w_tr_left_m`) or, for `sweep`, a folder of them (its `*.csv`)";

/// What `--obstacles` accepts.
pub const OBSTACLE_FORMS: &str = "`none`, `paper` (the built-in obstacles, on the `paper` track only), `random:N` (N boxes per km of road, placed from --seed) or an obstacle CSV file (`id,x_m,y_m`, one row per vertex)";

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

/// The obstacles of a run (`--obstacles`).
#[derive(Clone, Debug, PartialEq)]
pub enum ObstacleSpec {
    /// None.
    None,
    /// The built-in obstacles of the `paper` track.
    Paper,
    /// This many random boxes per km, from the run's seed.
    Random(f64),
    /// From an obstacle file.
    File(String),
}

impl FromStr for ObstacleSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => return Ok(ObstacleSpec::None),
            "paper" => return Ok(ObstacleSpec::Paper),
            _ => {}
        }
        if let Some(n) = s.strip_prefix("random:") {
            return match n.parse::<f64>() {
                Ok(x) if x.is_finite() && x >= 0.0 => Ok(ObstacleSpec::Random(x)),
                _ => Err(format!(
                    "--obstacles random:N wants N ≥ 0 obstacles per km, got {n:?}"
                )),
            };
        }
        if s.is_empty() {
            return Err(format!("--obstacles is empty: give {OBSTACLE_FORMS}"));
        }
        Ok(ObstacleSpec::File(s.to_string()))
    }
}

impl fmt::Display for ObstacleSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ObstacleSpec::None => write!(f, "none"),
            ObstacleSpec::Paper => write!(f, "paper"),
            ObstacleSpec::Random(n) => write!(f, "random:{n}"),
            ObstacleSpec::File(p) => write!(f, "{p}"),
        }
    }
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

/// Loads the vehicle file or the built-in vehicle.
pub fn load_vehicle(path: Option<&Path>) -> Result<VehicleParams> {
    match path {
        None => Ok(VehicleParams::default()),
        Some(p) => Ok(VehicleParams::from_toml_file(p)?),
    }
}

/// One run: its factors (a `sweep` run, or the one run of `run` and `pil`).
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// Place in the sweep's cross product (0 for `run`).
    pub index: usize,
    /// Track: `paper` or a file path.
    pub track: String,
    /// Road friction.
    pub mu: f64,
    /// Planner friction (before a `mu-high` fault).
    pub mu_planner: f64,
    /// Vehicle file (`None`: the built-in car).
    pub vehicle: Option<PathBuf>,
    /// Plant mass scale.
    pub mass_scale: f64,
    /// Noise level.
    pub noise: f64,
    /// Estimate delay, ms.
    pub delay_ms: f64,
    /// Fault scenario.
    pub fault: Fault,
    /// Seed column (`--seed`).
    pub seed: u32,
}

impl RunSpec {
    /// The track's name (file stem).
    pub fn track_name(&self) -> String {
        Path::new(&self.track)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.track.clone())
    }

    /// The vehicle's name (file stem, or `default`).
    pub fn vehicle_name(&self) -> String {
        self.vehicle
            .as_deref()
            .and_then(|p| p.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "default".into())
    }

    /// The seed of the run's random draws: the track's name and the seed column
    /// (the same obstacles and noise across frictions, vehicles and faults).
    pub fn rng_seed(&self) -> u64 {
        run_seed(&self.track_name(), self.seed)
    }
}

/// What every run of a command shares.
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// Obstacles.
    pub obstacles: ObstacleSpec,
    /// Track files are open paths.
    pub open: bool,
    /// Laps.
    pub laps: u32,
    /// Simulated time limit, s.
    pub duration_s: f64,
    /// Initial speed, m/s.
    pub initial_speed_mps: f64,
    /// Patches of road with their own friction.
    pub mu_patches: Vec<MuPatch>,
}

impl Default for Setting {
    fn default() -> Self {
        Self {
            obstacles: ObstacleSpec::None,
            open: false,
            laps: 1,
            duration_s: 900.0,
            initial_speed_mps: SimOptions::default().initial_speed_mps,
            mu_patches: Vec::new(),
        }
    }
}

/// A run ready to drive: the scenario, the cars, the options and the disturbances.
#[derive(Clone, Debug)]
pub struct SetUp {
    /// Track, obstacles (the late obstacle of a `late-obstacle` fault last) and
    /// friction patches.
    pub scenario: Scenario,
    /// Obstacles placed from the start (before the late one, if any).
    pub placed_obstacles: usize,
    /// The car the firmware is told of.
    pub nominal: VehicleParams,
    /// The plant's car (`--mass-scale`).
    pub plant_car: VehicleParams,
    /// Friction, laps, time limit, initial speed, ECU clock.
    pub opts: SimOptions,
    /// Noise, delay, and the fault's dropout, steering limit or late obstacle.
    pub disturbances: Disturbances,
}

impl SetUp {
    /// The obstacles placed from the start (written to `obstacles/<index>.csv` by
    /// a sweep: `run --obstacles` replays them).
    pub fn static_obstacles(&self) -> &[Obstacle] {
        &self.scenario.obstacles[..self.placed_obstacles]
    }
}

/// The late-obstacle fault's box: 2 m × 2 m at half the lap, its centre 0.8 m off
/// the centre line on the side the firmware finds room beside it.
fn late_obstacle_box(scn: &Scenario, check: &RoadCheck) -> Result<Obstacle> {
    let s = 0.5 * scn.track.length();
    [-0.8, 0.8, -1.5, 1.5, 0.0]
        .into_iter()
        .map(|lat| box_at(&scn.track, "late_obstacle", s, lat, (2.0, 2.0)))
        .find(|o| check.leaves_room(o))
        .ok_or_else(|| anyhow!("no room for the late obstacle at half the lap"))
}

/// Sets up the run `spec` (module docs): the track and its patches, the cars, the
/// options, the fault, the obstacles.
pub fn set_up(spec: &RunSpec, setting: &Setting) -> Result<SetUp> {
    let mut scn = scenario::resolve(&spec.track, "none", !setting.open)?;
    RoadFriction::new(
        spec.mu,
        &setting.mu_patches,
        &scn.track.name,
        scn.track.length(),
        scn.track.closed,
    )?;
    scn.mu_patches = setting.mu_patches.clone();
    let nominal = load_vehicle(spec.vehicle.as_deref())?;
    let plant_car = nominal.with_mass_scale(spec.mass_scale);
    let mut opts = SimOptions {
        mu_road: spec.mu,
        mu_planner: spec.mu_planner,
        laps: setting.laps,
        max_duration_s: setting.duration_s,
        initial_speed_mps: setting.initial_speed_mps,
        ..SimOptions::default()
    };
    let mut d = Disturbances {
        noise_scale: spec.noise,
        delay_ms: spec.delay_ms,
        seed: spec.rng_seed(),
        ..Disturbances::default()
    };
    let start_us = (FAULT_START_S * 1e6) as u64;
    match spec.fault {
        Fault::None | Fault::LateObstacle(_) => {}
        Fault::DropoutNan(n) | Fault::DropoutHold(n) => {
            let kind = if matches!(spec.fault, Fault::DropoutNan(_)) {
                DropoutKind::Nan
            } else {
                DropoutKind::Hold
            };
            d.dropout = Some(Dropout {
                start_us,
                periods: n,
                kind,
            });
        }
        Fault::Overrun(mhz) => opts.ecu_clock_hz = mhz * 1e6,
        Fault::MuHigh(k) => opts.mu_planner = (spec.mu_planner * k).min(2.0),
        Fault::SteerRate(r) => d.steer_rate_limit_radps = Some(r),
    }
    // The firmware's own check that an obstacle leaves room, for the ones placed here.
    let needs_check = matches!(setting.obstacles, ObstacleSpec::Random(_))
        || matches!(spec.fault, Fault::LateObstacle(_));
    let check = if needs_check {
        Some(RoadCheck::new(&scn.track, &nominal, opts.mu_planner)?)
    } else {
        None
    };
    let road_check = || {
        check
            .as_ref()
            .ok_or_else(|| anyhow!("the road check was not set up"))
    };
    scn.obstacles = match &setting.obstacles {
        ObstacleSpec::None => Vec::new(),
        ObstacleSpec::Paper if spec.track == "paper" => scenario::paper_obstacles(),
        ObstacleSpec::Paper => {
            return Err(ScenarioError::PaperObstaclesNeedPaperTrack {
                track: spec.track.clone(),
            }
            .into())
        }
        ObstacleSpec::Random(n) => random_obstacles(&scn.track, *n, spec.rng_seed(), road_check()?),
        ObstacleSpec::File(f) => load_obstacles_path(f)?,
    };
    let placed_obstacles = scn.obstacles.len();
    if let Fault::LateObstacle(dist) = spec.fault {
        scn.obstacles.push(late_obstacle_box(&scn, road_check()?)?);
        d.late_obstacle = Some(LateObstacle {
            index: scn.obstacles.len() - 1,
            appear_m: dist,
        });
    }
    Ok(SetUp {
        scenario: scn,
        placed_obstacles,
        nominal,
        plant_car,
        opts,
        disturbances: d,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obstacle_specs_parse_and_print_back() {
        for (s, o) in [
            ("none", ObstacleSpec::None),
            ("paper", ObstacleSpec::Paper),
            ("random:3", ObstacleSpec::Random(3.0)),
            ("random:0.5", ObstacleSpec::Random(0.5)),
            ("a/b.csv", ObstacleSpec::File("a/b.csv".into())),
        ] {
            assert_eq!(s.parse::<ObstacleSpec>(), Ok(o.clone()));
            assert_eq!(o.to_string(), s);
        }
        assert!("random:x".parse::<ObstacleSpec>().is_err());
        assert!("random:-1".parse::<ObstacleSpec>().is_err());
        assert!("".parse::<ObstacleSpec>().is_err());
    }
}
