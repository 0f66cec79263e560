//! The set-up of one run from one value of each of its factors ([`set_up`]): the
//! scenario (the track, its friction and grade patches, its obstacles, `random:N`
//! ones included), the car the firmware is told of and the plant's (its load and
//! actuators), the closed loop's options and the disturbances of the run's fault. The same for `run`, `pil` and
//! every run of a sweep, so `run` with a sweep run's factors replays it.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{anyhow, Result};

use crate::closed_loop::SimOptions;
use crate::model::actuator::ActuatorSetting;
use crate::model::vehicle::VehicleParams;
use crate::world::disturbance::{run_seed, Disturbances, Dropout, DropoutKind, LateObstacle};
use crate::world::faults::{Fault, FAULT_START_S};
use crate::world::obstacle_file::{load_obstacles_path, Obstacle};
use crate::world::obstacle_placement::{box_at, pose_at, random_obstacles, RoadCheck};
use crate::world::road_friction::{MuPatch, RoadFriction};
use crate::world::road_grade::{GradePatch, RoadGrade};
use crate::world::scenario::{self, Scenario, ScenarioError};

/// What `--obstacles` accepts.
pub const OBSTACLE_FORMS: &str = "`none`, `paper` (the built-in obstacles, on the `paper` track only), `random:N` (N boxes per km of road, placed from --seed) or an obstacle CSV file (`id,x_m,y_m`, one row per vertex)";

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
    /// Stretches of road with a grade.
    pub grade_patches: Vec<GradePatch>,
    /// Actuator parameters of the plant's car over its vehicle file's.
    pub actuators: Vec<ActuatorSetting>,
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
            grade_patches: Vec::new(),
            actuators: Vec::new(),
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
    /// The plant's car (`--mass-scale`, `--actuator`).
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

/// The blocked-road fault's box: 2 m along the road at half the lap, across its
/// whole width and 0.5 m past each edge, so that no car finds room beside it.
fn blocking_box(scn: &Scenario) -> Obstacle {
    let s = 0.5 * scn.track.length();
    let (_, _, [w_right, w_left]) = pose_at(&scn.track, s);
    let centre = 0.5 * (w_left - w_right);
    box_at(
        &scn.track,
        "blocked_road",
        s,
        centre,
        (2.0, w_left + w_right + 1.0),
    )
}

/// Sets up the run `spec` (module docs): the track and its patches, the cars, the
/// options, the fault, the obstacles.
///
/// An actuator setting the plant's car refuses is an error naming `--actuator`.
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
    RoadGrade::new(
        &setting.grade_patches,
        &scn.track.name,
        scn.track.length(),
        scn.track.closed,
    )?;
    scn.grade_patches = setting.grade_patches.clone();
    let nominal = load_vehicle(spec.vehicle.as_deref())?;
    let mut plant_car = nominal.with_mass_scale(spec.mass_scale);
    plant_car.actuators = plant_car.actuators.with_settings(&setting.actuators);
    plant_car.validate().map_err(|e| {
        anyhow!(
            "--actuator {}: the plant's car refuses them: {e}",
            setting
                .actuators
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" ")
        )
    })?;
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
        Fault::None | Fault::LateObstacle(_) | Fault::BlockedRoad(_) => {}
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
                withholds_route: false,
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
    let late = match spec.fault {
        Fault::LateObstacle(dist) => Some((late_obstacle_box(&scn, road_check()?)?, dist)),
        Fault::BlockedRoad(dist) => Some((blocking_box(&scn), dist)),
        _ => None,
    };
    if let Some((o, dist)) = late {
        scn.obstacles.push(o);
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
