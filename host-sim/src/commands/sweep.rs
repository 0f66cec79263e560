//! `host-sim sweep`: the cross product of tracks, frictions, vehicles, loads,
//! noise levels, delays, faults and seeds, run in parallel, one row per run in
//! `sweep.csv`, the aggregate in `sweep.json`, figures and a text summary.
//!
//! # Runs
//!
//! The runs are the cross product in the order track, μ, μ_planner, vehicle, mass
//! scale, noise, delay, fault, seed; a run's `index` is its place in that order and
//! addresses it on its own (`--list` prints them, `--only I/N` runs those whose
//! index is `I` modulo `N`, so shards are balanced across tracks; `sweep-merge`
//! joins the shards' `sweep.csv` files). Every run is deterministic: the firmware
//! runs in `f32` on the modelled ECU, and every random draw (obstacles, noise)
//! comes from a seed made of the track's name and the run's `seed` column, so the
//! same command writes the same `sweep.csv` whatever the thread count or shard.
//!
//! # Factors
//!
//! The scenario options `run` and `pil` take too
//! ([`crate::commands::scenario_args::ScenarioArgs`]), lists here:
//!
//! - `--mass-scale k`: the plant's mass and inertias × k; the firmware is told the
//!   nominal car (an unknown load).
//! - `--noise`: a level name (`none` 0, `low` 1, `medium` 2, `high` 4) or a number,
//!   multiplying [`crate::world::disturbance::NOISE_UNIT`] (σ of 0.05 m on X and Y, 0.005
//!   rad on the heading, 0.05 m/s on the speed, 0.005 rad/s on the yaw rate).
//! - `--delay-ms`: the estimate the tasks see is that old (rounded to 10 ms).
//! - `--fault`: see [`crate::world::faults`] (`--help` lists them).
//! - `--obstacles random:N`: see [`crate::world::obstacle_placement`].
//! - `--seed` (a list) or `--seeds N` (0..N).
//! - `--mu-patch START_M:LENGTH_M:MU` (repeatable): patches of road with their own
//!   friction, the same in every run (not a factor), checked against every track's
//!   lap before the first run; see [`crate::world::road_friction`].
//!
//! # The friction check against the road
//!
//! Per run (summary fields, so columns of `sweep.csv`; definitions in
//! [`crate::world::road_friction`]): `friction_mu_min` (the lowest `μ̂`), `road_mu_min`,
//! `mu_false_drop` (at some 10 ms sample `μ̂ < 0.9·min` of the road μ under the car
//! over the last 10 s) and `mu_false_drop_s` (when first), `mu_recovery_s` (the
//! slowest return to `μ̂ ≥ 0.9·road μ` after leaving a patch of lower grip) and
//! `mu_unrecovered_exits`. The aggregate counts the false drops per track and μ
//! (`mu_false_drops`, a missed bound).
//!
//! # Outcome and off-road
//!
//! [`crate::world::faults::Outcome`], worst first. Off-road: at some 10 ms sample the
//! centre of gravity was farther from the centre line than the road's local
//! half-width on that side. `max_edge_excess_m` is how far the body's side went
//! past the edge (negative: the margin left).
//!
//! With obstacles, each run's are written to `obstacles/<index>.csv`. `host-sim run`
//! with a run's factors (`--track T --mu … --fault … --seed S`, its `--obstacles`)
//! sets the run up as the sweep did ([`crate::world::set_up::set_up`]) and
//! replays it.
//!
//! # Exit status
//!
//! [`verdict`]: non-zero when a run could not run (an error row: outcome `failed`,
//! an error, no summary), after every output is written; with `--strict` also when
//! a run did not show its expected behaviour. Laps that ran and ended badly are
//! measurements (`sweep.json`). A missing track, folder, obstacle or vehicle file is
//! refused before the first run.
//!
//! `sweep.csv` holds every field of `summary.json` except the host's wall-time
//! figures (`plan_host_us_p50`, `plan_host_us_max`, `sim_speed_x_realtime`), which
//! differ from one run of the same command to the next.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;

use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::summary::Summary;
use crate::closed_loop::timeline::{self, LogRow};
use crate::closed_loop::vehicle_width_m;
use crate::commands::scenario_args::{check_track_arg, ScenarioArgs};
use crate::model::vehicle::VehicleParams;
use crate::sweep::figures;
use crate::world::disturbance::DisturbedEcu;
pub use crate::world::disturbance::NoiseLevel;
use crate::world::faults::{classify, Fault, Outcome, RunFacts};
use crate::world::obstacle_placement::widths_at;
use crate::world::road_friction::RoadFriction;
use crate::world::scenario::{self, Scenario};
use crate::world::set_up::{set_up, ObstacleSpec, RunSpec, Setting};

/// Arguments of `host-sim sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The scenario options `run` and `pil` take too, lists here: every
    /// combination runs.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Seeds 0..N per combination (instead of --seed's list).
    #[arg(long = "seeds", value_name = "N", conflicts_with = "seed")]
    pub seed_count: Option<u32>,
    /// Print the runs (index and factors) and exit.
    #[arg(long)]
    pub list: bool,
    /// Run only the I-th shard of N (`I/N`, I in 0..N): the runs whose index is I mod N.
    #[arg(long)]
    pub only: Option<Shard>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Skip the PNG figures.
    #[arg(long)]
    pub no_plots: bool,
    /// Also write each run's `log.csv`, `plan_activations.csv` and
    /// `summary.json` (what `host-sim run` writes, without figures) into
    /// `OUT/runs/<index>/`: `failed` for the runs whose outcome is not `ok`,
    /// `all` for every run.
    #[arg(long, value_enum)]
    pub logs: Option<LogRuns>,
    /// Also exit non-zero when a run did not show its expected behaviour
    /// (`fault_check` fail: with no fault, any outcome but `ok`). Without it only
    /// the runs that could not run (an error row) make the exit status non-zero.
    #[arg(long)]
    pub strict: bool,
    /// Output directory (created).
    #[arg(long, required_unless_present = "list")]
    pub out: Option<PathBuf>,
}

/// Which runs of a sweep keep their logs (`--logs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogRuns {
    /// The runs whose outcome is not `ok`.
    Failed,
    /// Every run.
    All,
}

/// Arguments of `host-sim sweep-merge`.
#[derive(Debug, Clone, Args)]
pub struct MergeArgs {
    /// Shard output folders (each with a `sweep.csv`).
    #[arg(required = true, num_args = 1..)]
    pub dirs: Vec<PathBuf>,
    /// Skip the PNG figures.
    #[arg(long)]
    pub no_plots: bool,
    /// Also exit non-zero when a run did not show its expected behaviour (as for
    /// `sweep --strict`).
    #[arg(long)]
    pub strict: bool,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
}

/// `I/N`: the I-th of N shards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("--only wants I/N with 0 ≤ I < N, got {s:?}");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl RunSpec {
    fn columns(&self) -> Vec<String> {
        vec![
            self.index.to_string(),
            self.track_name(),
            self.mu.to_string(),
            self.mu_planner.to_string(),
            self.vehicle_name(),
            self.mass_scale.to_string(),
            self.noise.to_string(),
            self.delay_ms.to_string(),
            self.fault.to_string(),
            self.seed.to_string(),
        ]
    }
}

/// Leading columns of `sweep.csv`: the run's factors.
pub const FACTOR_COLUMNS: [&str; 10] = [
    "index",
    "track",
    "mu",
    "mu_planner",
    "vehicle",
    "mass_scale",
    "noise",
    "delay_ms",
    "fault",
    "seed",
];

/// Columns after the factors: the outcome and what the sweep measures itself.
pub const RESULT_COLUMNS: [&str; 10] = [
    "outcome",
    "fault_check",
    "error",
    "plan_failure_kinds",
    "obstacle_count",
    "fault_event_s",
    "off_road_samples",
    "max_edge_excess_m",
    "ay_over_mu_g",
    "plan_ay_over_mu_g",
];

/// `summary.json` fields left out of `sweep.csv` (host wall time: not reproducible).
pub const WALL_TIME_FIELDS: [&str; 3] = [
    "plan_host_us_p50",
    "plan_host_us_max",
    "sim_speed_x_realtime",
];

/// Expands folders into their `*.csv` files (sorted); other arguments as given
/// (checked first: [`check_track_arg`]). A folder without a `*.csv` is an error.
pub fn expand_tracks(args: &[String]) -> Result<Vec<String>> {
    let mut out = Vec::new();
    for a in args {
        check_track_arg(a, true)?;
        let p = Path::new(a);
        if p.is_dir() {
            let mut files: Vec<String> = fs::read_dir(p)
                .with_context(|| format!("--track {a}: cannot read the folder"))?
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|f| f.extension().is_some_and(|x| x == "csv"))
                .map(|f| f.display().to_string())
                .collect();
            if files.is_empty() {
                bail!("--track {a}: no *.csv track file in this folder");
            }
            files.sort();
            out.extend(files);
        } else {
            out.push(a.clone());
        }
    }
    Ok(out)
}

/// The seeds of every combination: `--seeds N` (0..N) or `--seed`'s list.
fn seeds(args: &SweepArgs) -> Vec<u32> {
    match args.seed_count {
        Some(n) => (0..n).collect(),
        None => args.scenario.seed.clone(),
    }
}

/// The cross product of `args` (module docs), in index order.
pub fn runs(args: &SweepArgs) -> Result<Vec<RunSpec>> {
    let sc = &args.scenario;
    let tracks = expand_tracks(&sc.tracks)?;
    let vehicles: Vec<Option<PathBuf>> = if sc.vehicle.is_empty() {
        vec![None]
    } else {
        sc.vehicle.iter().cloned().map(Some).collect()
    };
    let seeds = seeds(args);
    let mut out = Vec::new();
    for track in &tracks {
        for &mu in &sc.mu {
            let planners = if sc.mu_planner.is_empty() {
                vec![mu]
            } else {
                sc.mu_planner.clone()
            };
            for &mu_planner in &planners {
                for vehicle in &vehicles {
                    for &mass_scale in &sc.mass_scale {
                        for noise in &sc.noise {
                            for &delay_ms in &sc.delay_ms {
                                for &fault in &sc.faults {
                                    for &seed in &seeds {
                                        out.push(RunSpec {
                                            index: out.len(),
                                            track: track.clone(),
                                            mu,
                                            mu_planner,
                                            vehicle: vehicle.clone(),
                                            mass_scale,
                                            noise: noise.0,
                                            delay_ms,
                                            fault,
                                            seed,
                                        });
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Checks the arguments (every value and path) before any run starts.
fn check_args(args: &SweepArgs) -> Result<()> {
    args.scenario.check(true)?;
    if seeds(args).is_empty() {
        bail!("--seeds must be at least 1");
    }
    Ok(())
}

/// Checks that the patches fit every track and road friction of `specs` before any
/// run starts (a patch past a lap's end is the command's mistake, not a run's).
fn check_patches(specs: &[RunSpec], setting: &Setting) -> Result<()> {
    let patches = &setting.mu_patches;
    if patches.is_empty() {
        return Ok(());
    }
    let mut seen: Vec<&str> = Vec::new();
    for spec in specs {
        if seen.contains(&spec.track.as_str()) {
            continue;
        }
        seen.push(&spec.track);
        let track = scenario::resolve(&spec.track, "none", !setting.open)?.track;
        RoadFriction::new(spec.mu, patches, &track.name, track.length(), track.closed)?;
    }
    Ok(())
}

/// What one run produced: its factors and its `sweep.csv` cells after them.
#[derive(Clone, Debug)]
pub struct RunRow {
    /// The run.
    pub spec: RunSpec,
    /// Cells of [`RESULT_COLUMNS`] then of the summary's fields.
    pub cells: Vec<String>,
}

/// Settings shared by every run of a sweep.
#[derive(Clone, Debug)]
pub struct Common {
    /// Obstacles, laps, time limit, initial speed, patches.
    pub setting: Setting,
    /// Where to write each run's obstacles as `<index>.csv` (random ones included,
    /// so `host-sim run --obstacles` can replay a run); `None`: not written.
    pub obstacle_dir: Option<PathBuf>,
    /// Where and for which runs to write the run's outputs (`<dir>/<index>/`).
    pub log_dir: Option<(PathBuf, LogRuns)>,
}

/// Runs one run and returns its row (an error is a row too).
pub fn execute(spec: &RunSpec, common: &Common) -> RunRow {
    let cells = match try_execute(spec, common) {
        Ok(c) => c,
        Err(e) => {
            let mut c = vec![String::new(); RESULT_COLUMNS.len()];
            c[0] = Outcome::Failed.name().into();
            c[1] = check_cell(spec.fault, None);
            c[2] = format!("{e:#}");
            c.extend(std::iter::repeat_n(String::new(), summary_header().len()));
            c
        }
    };
    RunRow {
        spec: spec.clone(),
        cells,
    }
}

fn check_cell(fault: Fault, facts: Option<&RunFacts>) -> String {
    match facts {
        Some(f) if fault.check(f) => "pass".into(),
        _ => "fail".into(),
    }
}

fn try_execute(spec: &RunSpec, common: &Common) -> Result<Vec<String>> {
    let setup = set_up(spec, &common.setting)?;
    let (scn, opts) = (&setup.scenario, &setup.opts);
    if let (Some(dir), false) = (&common.obstacle_dir, setup.static_obstacles().is_empty()) {
        let p = dir.join(format!("{}.csv", spec.index));
        fs::create_dir_all(dir)
            .and_then(|_| {
                fs::write(
                    &p,
                    crate::world::obstacle_file::obstacles_to_csv_string(setup.static_obstacles()),
                )
            })
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    let mut ecu = DisturbedEcu::<f32>::new(scn, &setup.nominal, opts, setup.disturbances.clone())?;
    let res = timeline::run_with(scn, &setup.plant_car, opts, &mut ecu, |_, _| {})?;
    let s = &res.summary;
    let edge = edge_excess(scn, &setup.plant_car, &res.log);
    let outcome = classify(s, edge.off_road_samples > 0);
    if let Some((dir, which)) = &common.log_dir {
        if *which == LogRuns::All || outcome != Outcome::Ok {
            crate::output::run_files::write_outputs(
                &dir.join(spec.index.to_string()),
                scn,
                &res,
                false,
            )?;
        }
    }
    let fault_event_s = match spec.fault {
        Fault::LateObstacle(_) => ecu.obstacle_appeared_at_us().map(|t| t as f64 * 1e-6),
        Fault::DropoutNan(_) | Fault::DropoutHold(_) => Some(crate::world::faults::FAULT_START_S),
        _ => None,
    };
    let facts = RunFacts {
        outcome,
        completed: s.completed,
        safe_actuations: s.control_safe_actuations,
        fault_event_s,
    };
    let g = f64::from(firmware::G);
    let mut cells = vec![
        outcome.name().to_string(),
        check_cell(spec.fault, Some(&facts)),
        if outcome == Outcome::Failed {
            s.stop_reason.clone()
        } else {
            String::new()
        },
        failure_kinds(&res.plan_activations),
        scn.obstacles.len().to_string(),
        fault_event_s.map(|t| format!("{t:.2}")).unwrap_or_default(),
        edge.off_road_samples.to_string(),
        format!("{:.4}", edge.max_excess_m),
        format!("{:.4}", s.max_abs_ay_mps2 / (spec.mu * g)),
        s.max_abs_plan_ay_mps2
            .map(|ay| format!("{:.4}", ay / (opts.mu_planner * g)))
            .unwrap_or_default(),
    ];
    cells.extend(summary_values(s)?);
    Ok(cells)
}

/// The statuses of the plan activations that published nothing, with their
/// counts (`qp_iteration_limit:3;stale:1`), in order of first appearance.
fn failure_kinds(acts: &[PlanActivation]) -> String {
    let mut kinds: Vec<(String, usize)> = Vec::new();
    for a in acts.iter().filter(|a| !a.published) {
        let name = if a.status == "optimal" {
            "stale".to_string()
        } else {
            a.status.to_string()
        };
        match kinds.iter_mut().find(|(k, _)| *k == name) {
            Some((_, n)) => *n += 1,
            None => kinds.push((name, 1)),
        }
    }
    kinds
        .iter()
        .map(|(k, n)| format!("{k}:{n}"))
        .collect::<Vec<_>>()
        .join(";")
}

/// Off-road samples and the largest excess of the body's side past the road edge.
struct Edge {
    off_road_samples: u64,
    max_excess_m: f64,
}

fn edge_excess(scn: &Scenario, car: &VehicleParams, log: &[LogRow]) -> Edge {
    let arcs = scn.track.arc_lengths();
    let total = scn.track.length();
    let half_car = 0.5 * vehicle_width_m(car);
    let mut e = Edge {
        off_road_samples: 0,
        max_excess_m: f64::NEG_INFINITY,
    };
    for row in log {
        let s = if scn.track.closed {
            row.progress_m.rem_euclid(total)
        } else {
            row.progress_m
        };
        let [wr, wl] = widths_at(&scn.track, &arcs, s);
        let lat = row.lateral_error_m;
        let w = if lat >= 0.0 { wl } else { wr };
        if lat.abs() > w {
            e.off_road_samples += 1;
        }
        e.max_excess_m = e.max_excess_m.max(lat.abs() + half_car - w);
    }
    e
}

fn summary_csv(s: &Summary) -> Result<(Vec<String>, Vec<String>)> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.serialize(s)?;
    let bytes = w.into_inner().map_err(|e| anyhow!("{e}"))?;
    let mut r = csv::Reader::from_reader(bytes.as_slice());
    let header: Vec<String> = r.headers()?.iter().map(String::from).collect();
    let rec = r
        .records()
        .next()
        .ok_or_else(|| anyhow!("empty summary record"))??;
    let keep: Vec<(String, String)> = header
        .into_iter()
        .zip(rec.iter().map(String::from))
        .filter(|(h, _)| !WALL_TIME_FIELDS.contains(&h.as_str()))
        .collect();
    Ok(keep.into_iter().unzip())
}

/// The summary's columns in `sweep.csv` (every field but [`WALL_TIME_FIELDS`]).
pub fn summary_header() -> Vec<String> {
    summary_csv(&Summary::default())
        .map(|(h, _)| h)
        .unwrap_or_default()
}

fn summary_values(s: &Summary) -> Result<Vec<String>> {
    Ok(summary_csv(s)?.1)
}

/// The full header of `sweep.csv`.
pub fn header() -> Vec<String> {
    FACTOR_COLUMNS
        .iter()
        .chain(RESULT_COLUMNS.iter())
        .map(|s| s.to_string())
        .chain(summary_header())
        .collect()
}

/// Writes `sweep.csv` (rows sorted by index).
pub fn write_csv(path: &Path, rows: &[Vec<String>]) -> Result<()> {
    let mut w =
        csv::Writer::from_path(path).with_context(|| format!("cannot write {}", path.display()))?;
    w.write_record(header())?;
    for r in rows {
        w.write_record(r)?;
    }
    w.flush()?;
    Ok(())
}

/// The exit status of a sweep from its rows: an error when a run could not run
/// (its row has outcome `failed`, an error and no summary), so that a script or a
/// batch engine notices; with `strict`, also when a run that ran did not show its
/// expected behaviour (`fault_check` fail). Laps that ran and ended badly
/// (collision, off-road, a miss, a standstill, the time limit) are the sweep's
/// measurements, counted in `sweep.json`; they fail the command only with `strict`.
pub fn verdict(rows: &[Row], strict: bool) -> Result<()> {
    let broken: Vec<&Row> = rows.iter().filter(|r| !r.ran).collect();
    if let Some(first) = broken.first() {
        bail!(
            "{} of {} runs could not run (outcome `failed`, column `error` of sweep.csv); the first, run {}: {}",
            broken.len(),
            rows.len(),
            first.factors["index"],
            first.error
        );
    }
    let unexpected = rows.iter().filter(|r| !r.fault_pass).count();
    if strict && unexpected > 0 {
        bail!(
            "--strict: {unexpected} of {} runs did not show their expected behaviour (column `fault_check` of sweep.csv)",
            rows.len()
        );
    }
    Ok(())
}

/// `host-sim sweep`.
pub fn run(args: &SweepArgs) -> Result<()> {
    check_args(args)?;
    let all = runs(args)?;
    if args.list {
        println!("{}", FACTOR_COLUMNS.join("\t"));
        for r in &all {
            println!("{}", r.columns().join("\t"));
        }
        println!("# {} runs", all.len());
        return Ok(());
    }
    let out = args
        .out
        .as_ref()
        .ok_or_else(|| anyhow!("--out is required"))?;
    let mine: Vec<RunSpec> = match args.only {
        None => all.clone(),
        Some(sh) => all
            .iter()
            .filter(|r| r.index % sh.count == sh.index)
            .cloned()
            .collect(),
    };
    let setting = args.scenario.setting();
    check_patches(&mine, &setting)?;
    let common = Common {
        obstacle_dir: (setting.obstacles != ObstacleSpec::None).then(|| out.join("obstacles")),
        setting,
        log_dir: args.logs.map(|w| (out.join("runs"), w)),
    };
    fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let wall = Instant::now();
    let rows = run_all(&mine, &common, args.jobs, true)?;
    let wall_s = wall.elapsed().as_secs_f64();
    let records: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            r.spec
                .columns()
                .into_iter()
                .chain(r.cells.clone())
                .collect()
        })
        .collect();
    write_csv(&out.join("sweep.csv"), &records)?;
    let text = finish(out, &records, Some(wall_s), !args.no_plots)?;
    println!("{text}");
    println!("wrote {}", out.display());
    verdict(&parse_rows(&records), args.strict)
}

/// Runs `specs` in parallel (on `jobs` threads, default all cores), with a
/// progress bar if `progress`; rows in the order of `specs`.
pub fn run_all(
    specs: &[RunSpec],
    common: &Common,
    jobs: Option<usize>,
    progress: bool,
) -> Result<Vec<RunRow>> {
    let bar = if progress {
        let b = ProgressBar::new(specs.len() as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{bar:40} {pos}/{len} runs  {elapsed_precise} elapsed, ETA {eta_precise}  {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let mut builder = rayon::ThreadPoolBuilder::new().stack_size(16 << 20);
    if let Some(j) = jobs {
        builder = builder.num_threads(j.max(1));
    }
    let pool = builder.build().context("thread pool")?;
    let rows = pool.install(|| {
        specs
            .par_iter()
            .map(|s| {
                let r = execute(s, common);
                bar.set_message(format!("{} μ={}", s.track_name(), s.mu));
                bar.inc(1);
                r
            })
            .collect::<Vec<_>>()
    });
    bar.finish_and_clear();
    Ok(rows)
}

/// `host-sim sweep-merge`.
pub fn merge(args: &MergeArgs) -> Result<()> {
    let head = header();
    let mut by_index: BTreeMap<usize, Vec<String>> = BTreeMap::new();
    for d in &args.dirs {
        let p = d.join("sweep.csv");
        let mut r =
            csv::Reader::from_path(&p).with_context(|| format!("cannot read {}", p.display()))?;
        let h: Vec<String> = r.headers()?.iter().map(String::from).collect();
        if h != head {
            bail!(
                "{}: its columns differ from this host-sim's sweep.csv",
                p.display()
            );
        }
        for rec in r.records() {
            let rec: Vec<String> = rec?.iter().map(String::from).collect();
            let i: usize = rec[0]
                .parse()
                .with_context(|| format!("{}: bad index {:?}", p.display(), rec[0]))?;
            if let Some(prev) = by_index.insert(i, rec.clone()) {
                if prev != rec {
                    bail!("run {i} appears twice with different results");
                }
            }
        }
    }
    let records: Vec<Vec<String>> = by_index.into_values().collect();
    fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    write_csv(&args.out.join("sweep.csv"), &records)?;
    let text = finish(&args.out, &records, None, !args.no_plots)?;
    println!("{text}");
    println!("wrote {}", args.out.display());
    verdict(&parse_rows(&records), args.strict)
}

/// One row of `sweep.csv` as the aggregate reads it.
#[derive(Clone, Debug)]
pub struct Row {
    /// The factors, by column name.
    pub factors: BTreeMap<&'static str, String>,
    /// Outcome.
    pub outcome: Outcome,
    /// Fault name.
    pub fault: String,
    /// The fault's expected behaviour was seen.
    pub fault_pass: bool,
    /// Error, if any.
    pub error: String,
    /// The run ran (its summary's cells are filled); false for a run that could
    /// not run (a track or vehicle that cannot be loaded, a planner that refuses
    /// the track, an error on the way): a row with outcome `failed` and its error.
    pub ran: bool,
    /// Completed.
    pub completed: bool,
    /// Largest |lateral error|, m.
    pub lat_max_m: f64,
    /// Largest |a_y| over μg.
    pub ay_over_mu_g: f64,
    /// The plan's largest kinematic |a_y| over μ_planner·g.
    pub plan_ay_over_mu_g: f64,
    /// Largest plan-vs-executed distance, m.
    pub consistency_m: f64,
    /// Plan and control deadline misses.
    pub misses: u64,
    /// The friction check's `μ̂` fell below 0.9 × the road's recent lowest μ
    /// (`mu_false_drop`; false when not judged).
    pub mu_false_drop: bool,
}

/// Parses `sweep.csv` records (with [`header`]'s columns).
pub fn parse_rows(records: &[Vec<String>]) -> Vec<Row> {
    let head = header();
    let col = |name: &str| head.iter().position(|h| h == name);
    let get = |r: &[String], name: &str| -> String {
        col(name)
            .and_then(|i| r.get(i))
            .cloned()
            .unwrap_or_default()
    };
    let num = |r: &[String], name: &str| get(r, name).parse::<f64>().unwrap_or(f64::NAN);
    records
        .iter()
        .map(|r| Row {
            factors: FACTOR_COLUMNS.iter().map(|&c| (c, get(r, c))).collect(),
            outcome: Outcome::from_name(&get(r, "outcome")).unwrap_or(Outcome::Failed),
            fault: get(r, "fault"),
            fault_pass: get(r, "fault_check") == "pass",
            error: get(r, "error"),
            ran: !get(r, "completed").is_empty(),
            completed: get(r, "completed") == "true",
            lat_max_m: num(r, "max_abs_lateral_error_m"),
            ay_over_mu_g: num(r, "ay_over_mu_g"),
            plan_ay_over_mu_g: num(r, "plan_ay_over_mu_g"),
            consistency_m: num(r, "consistency_max_m"),
            misses: (num(r, "plan_deadline_misses") + num(r, "control_deadline_misses")).max(0.0)
                as u64,
            mu_false_drop: get(r, "mu_false_drop") == "true",
        })
        .collect()
}

/// The bounds the benchmark checks (issue 9).
pub const BOUNDS: Bounds = Bounds {
    lateral_error_m: 0.4,
    ay_over_mu_g: 0.55,
    consistency_m: 0.2,
};

/// Bounds on a run's figures.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Bounds {
    /// Largest |lateral error|, m.
    pub lateral_error_m: f64,
    /// Largest |a_y| over μg.
    pub ay_over_mu_g: f64,
    /// Largest plan-vs-executed distance, m.
    pub consistency_m: f64,
}

/// One track and friction in `sweep.json`.
#[derive(Clone, Debug, Serialize)]
pub struct TrackMu {
    /// Track name.
    pub track: String,
    /// Road friction.
    pub mu: String,
    /// Runs.
    pub runs: usize,
    /// Runs that completed.
    pub completed: usize,
    /// Largest |lateral error| over the runs, m.
    pub lat_max_m: f64,
    /// Largest |a_y|/μg.
    pub ay_over_mu_g: f64,
    /// Largest kinematic |a_y| of the plans / μ_planner·g.
    pub plan_ay_over_mu_g: f64,
    /// Largest consistency distance, m.
    pub consistency_m: f64,
    /// Deadline misses.
    pub misses: u64,
    /// Runs whose `μ̂` dropped falsely (`mu_false_drop`).
    pub mu_false_drops: usize,
    /// Bounds missed (names).
    pub missed: Vec<&'static str>,
}

/// One fault in `sweep.json`.
#[derive(Clone, Debug, Serialize)]
pub struct FaultRate {
    /// Fault name.
    pub fault: String,
    /// Expected behaviour.
    pub expected: String,
    /// Runs.
    pub runs: usize,
    /// Runs that showed it.
    pub pass: usize,
    /// Outcomes of its runs.
    pub outcomes: BTreeMap<&'static str, usize>,
}

/// `sweep.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Aggregate {
    /// Runs.
    pub runs: usize,
    /// Host wall time of the sweep, s (only when run at once, not merged; not reproducible).
    pub wall_s: Option<f64>,
    /// Outcome counts.
    pub outcomes: BTreeMap<&'static str, usize>,
    /// Outcome counts per level of each factor.
    pub by_factor: BTreeMap<&'static str, BTreeMap<String, BTreeMap<&'static str, usize>>>,
    /// Figures per track and friction.
    pub per_track_mu: Vec<TrackMu>,
    /// Expected behaviour per fault.
    pub faults: Vec<FaultRate>,
    /// The bounds checked.
    pub bounds: Bounds,
    /// The errors, by run index.
    pub errors: BTreeMap<String, String>,
}

fn count_outcomes<'a>(rows: impl Iterator<Item = &'a Row>) -> BTreeMap<&'static str, usize> {
    let mut m = BTreeMap::new();
    for r in rows {
        *m.entry(r.outcome.name()).or_insert(0) += 1;
    }
    m
}

/// `x` is within `bound` (false for NaN: an unmeasured figure misses its bound).
fn meets(x: f64, bound: f64) -> bool {
    x <= bound
}

fn fmax(it: impl Iterator<Item = f64>) -> f64 {
    it.filter(|x| x.is_finite()).fold(f64::NAN, f64::max)
}

/// The aggregate of `rows`.
pub fn aggregate(rows: &[Row], wall_s: Option<f64>) -> Aggregate {
    let mut by_factor = BTreeMap::new();
    for f in FACTOR_COLUMNS.iter().skip(1) {
        let mut levels: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
        for r in rows {
            levels.entry(r.factors[f].clone()).or_default().push(r);
        }
        by_factor.insert(
            *f,
            levels
                .into_iter()
                .map(|(k, v)| (k, count_outcomes(v.into_iter())))
                .collect(),
        );
    }
    let mut groups: Vec<((String, String), Vec<&Row>)> = Vec::new();
    for r in rows {
        let key = (r.factors["track"].clone(), r.factors["mu"].clone());
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) => v.push(r),
            None => groups.push((key, vec![r])),
        }
    }
    let per_track_mu = groups
        .into_iter()
        .map(|((track, mu), v)| {
            let t = TrackMu {
                track,
                mu,
                runs: v.len(),
                completed: v.iter().filter(|r| r.completed).count(),
                lat_max_m: fmax(v.iter().map(|r| r.lat_max_m)),
                ay_over_mu_g: fmax(v.iter().map(|r| r.ay_over_mu_g)),
                plan_ay_over_mu_g: fmax(v.iter().map(|r| r.plan_ay_over_mu_g)),
                consistency_m: fmax(v.iter().map(|r| r.consistency_m)),
                misses: v.iter().map(|r| r.misses).sum(),
                mu_false_drops: v.iter().filter(|r| r.mu_false_drop).count(),
                missed: Vec::new(),
            };
            let mut missed = Vec::new();
            if t.completed < t.runs {
                missed.push("completed");
            }
            if !meets(t.lat_max_m, BOUNDS.lateral_error_m) {
                missed.push("lateral_error");
            }
            if !meets(t.ay_over_mu_g, BOUNDS.ay_over_mu_g) {
                missed.push("ay");
            }
            if !meets(t.consistency_m, BOUNDS.consistency_m) {
                missed.push("consistency");
            }
            if t.misses > 0 {
                missed.push("misses");
            }
            if t.mu_false_drops > 0 {
                missed.push("mu_false_drop");
            }
            TrackMu { missed, ..t }
        })
        .collect();
    let mut fault_names: Vec<String> = Vec::new();
    for r in rows {
        if !fault_names.contains(&r.fault) {
            fault_names.push(r.fault.clone());
        }
    }
    let faults = fault_names
        .into_iter()
        .map(|f| {
            let v: Vec<&Row> = rows.iter().filter(|r| r.fault == f).collect();
            FaultRate {
                expected: f
                    .parse::<Fault>()
                    .map(|x| x.expected().to_string())
                    .unwrap_or_default(),
                runs: v.len(),
                pass: v.iter().filter(|r| r.fault_pass).count(),
                outcomes: count_outcomes(v.iter().copied()),
                fault: f,
            }
        })
        .collect();
    Aggregate {
        runs: rows.len(),
        wall_s,
        outcomes: count_outcomes(rows.iter()),
        by_factor,
        per_track_mu,
        faults,
        bounds: BOUNDS,
        errors: rows
            .iter()
            .filter(|r| !r.error.is_empty())
            .map(|r| (r.factors["index"].clone(), r.error.clone()))
            .collect(),
    }
}

/// The one-screen text summary.
pub fn text_summary(a: &Aggregate) -> String {
    let mut t = String::new();
    let _ = write!(t, "{} runs", a.runs);
    if let Some(w) = a.wall_s {
        let _ = write!(t, " in {:.0} s wall", w);
    }
    let _ = writeln!(t, ":  {}", fmt_counts(&a.outcomes));
    if a.per_track_mu.len() <= 40 {
        let _ = writeln!(
            t,
            "{:<16} {:>5} {:>6} {:>8} {:>8} {:>8} {:>8} {:>6} {:>6}  missed",
            "track", "μ", "done", "lat max", "ay/μg", "plan", "consist", "misses", "μ̂ fd"
        );
        for r in &a.per_track_mu {
            let _ = writeln!(
                t,
                "{:<16} {:>5} {:>3}/{:<2} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>6} {:>6}  {}",
                r.track,
                r.mu,
                r.completed,
                r.runs,
                r.lat_max_m,
                r.ay_over_mu_g,
                r.plan_ay_over_mu_g,
                r.consistency_m,
                r.misses,
                r.mu_false_drops,
                r.missed.join(",")
            );
        }
    } else {
        let bad = a
            .per_track_mu
            .iter()
            .filter(|r| !r.missed.is_empty())
            .count();
        let _ = writeln!(
            t,
            "{} track×μ groups, {} miss a bound (see sweep.json)",
            a.per_track_mu.len(),
            bad
        );
    }
    let _ = writeln!(
        t,
        "bounds: lateral error ≤ {} m, |a_y| ≤ {} μg, consistency ≤ {} m, no misses, no false drop of μ̂ (μ̂ fd: runs where μ̂ < 0.9 × the lowest road μ of the last 10 s)",
        a.bounds.lateral_error_m, a.bounds.ay_over_mu_g, a.bounds.consistency_m
    );
    for f in &a.faults {
        let _ = writeln!(
            t,
            "fault {:<20} {:>3}/{:<3} as expected ({})  [{}]",
            f.fault,
            f.pass,
            f.runs,
            f.expected,
            fmt_counts(&f.outcomes)
        );
    }
    for (i, e) in a.errors.iter().take(5) {
        let _ = writeln!(t, "run {i}: {e}");
    }
    if a.errors.len() > 5 {
        let _ = writeln!(t, "... {} more errors in sweep.json", a.errors.len() - 5);
    }
    t
}

fn fmt_counts(m: &BTreeMap<&'static str, usize>) -> String {
    Outcome::ALL
        .iter()
        .rev()
        .filter_map(|o| m.get(o.name()).map(|n| format!("{} {n}", o.name())))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Writes `sweep.json`, the figures and `summary.txt` from `sweep.csv`'s records;
/// returns the text summary.
pub fn finish(
    out: &Path,
    records: &[Vec<String>],
    wall_s: Option<f64>,
    plots: bool,
) -> Result<String> {
    let rows = parse_rows(records);
    let agg = aggregate(&rows, wall_s);
    let p = out.join("sweep.json");
    fs::write(&p, serde_json::to_string_pretty(&agg)?)
        .with_context(|| format!("cannot write {}", p.display()))?;
    if plots {
        figures::draw_all(out, &rows, &agg)?;
    }
    let text = text_summary(&agg);
    fs::write(out.join("summary.txt"), &text)?;
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_refuse_nonsense() {
        assert_eq!("1/4".parse::<Shard>(), Ok(Shard { index: 1, count: 4 }));
        assert!("4/4".parse::<Shard>().is_err());
        assert!("1/0".parse::<Shard>().is_err());
        assert!("x".parse::<Shard>().is_err());
    }

    #[test]
    fn noise_levels_and_obstacle_specs_parse() {
        assert_eq!("high".parse::<NoiseLevel>(), Ok(NoiseLevel(4.0)));
        assert_eq!("0.5".parse::<NoiseLevel>(), Ok(NoiseLevel(0.5)));
        assert!("-1".parse::<NoiseLevel>().is_err());
        assert_eq!(
            "random:3".parse::<ObstacleSpec>(),
            Ok(ObstacleSpec::Random(3.0))
        );
        assert!("random:x".parse::<ObstacleSpec>().is_err());
    }

    #[test]
    fn false_drops_of_the_friction_estimate_are_counted_and_miss_a_bound() {
        let h = header();
        let record = |track: &str, drop: &str| -> Vec<String> {
            h.iter()
                .map(|c| match c.as_str() {
                    "track" => track.to_string(),
                    "mu" => "1".into(),
                    "outcome" => "ok".into(),
                    "completed" => "true".into(),
                    "mu_false_drop" => drop.into(),
                    "max_abs_lateral_error_m"
                    | "ay_over_mu_g"
                    | "plan_ay_over_mu_g"
                    | "consistency_max_m"
                    | "plan_deadline_misses"
                    | "control_deadline_misses" => "0".into(),
                    _ => String::new(),
                })
                .collect()
        };
        let rows = parse_rows(&[
            record("a", "true"),
            record("a", "false"),
            record("b", "false"),
            record("b", ""),
        ]);
        let agg = aggregate(&rows, None);
        let a = &agg.per_track_mu[0];
        let b = &agg.per_track_mu[1];
        assert_eq!((a.track.as_str(), a.mu_false_drops), ("a", 1));
        assert_eq!(a.missed, vec!["mu_false_drop"]);
        assert_eq!((b.track.as_str(), b.mu_false_drops), ("b", 0));
        assert!(b.missed.is_empty(), "{:?}", b.missed);
        assert!(text_summary(&agg).contains("μ̂ fd"));
    }

    #[test]
    fn a_run_that_could_not_run_fails_the_sweep_and_a_bad_outcome_only_when_strict() {
        let h = header();
        let record = |index: &str, completed: &str, check: &str| -> Vec<String> {
            h.iter()
                .map(|c| match c.as_str() {
                    "index" => index.to_string(),
                    "track" => "a".into(),
                    "outcome" => if completed == "true" { "ok" } else { "failed" }.into(),
                    "fault_check" => check.into(),
                    "error" if completed.is_empty() => "a.csv: line 3: bad".into(),
                    "completed" => completed.into(),
                    _ => String::new(),
                })
                .collect()
        };
        let good = [record("0", "true", "pass"), record("1", "false", "fail")];
        // A lap that ran and failed is a measurement; only --strict fails on it.
        assert!(verdict(&parse_rows(&good), false).is_ok());
        let strict = verdict(&parse_rows(&good), true)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(strict.contains("1 of 2 runs did not show"), "{strict}");
        // A run that could not run (no summary) fails the sweep, strict or not.
        let broken = [record("0", "true", "pass"), record("1", "", "fail")];
        for strict in [false, true] {
            let e = verdict(&parse_rows(&broken), strict)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(e.contains("1 of 2 runs could not run"), "{e}");
            assert!(e.contains("run 1: a.csv: line 3: bad"), "{e}");
        }
    }

    #[test]
    fn the_header_has_every_summary_field_but_wall_time() {
        let h = header();
        assert!(h.iter().any(|c| c == "max_abs_plan_ay_mps2"));
        assert!(h.iter().any(|c| c == "consistency_max_m"));
        for w in WALL_TIME_FIELDS {
            assert!(!h.iter().any(|c| c == w));
        }
    }
}
