//! One run of a sweep, set up from its factors and run on the modelled ECU behind
//! its disturbances, as a row of `sweep.csv` (an error is a row too); and many runs
//! in parallel.

use std::fs;
use std::path::PathBuf;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::closed_loop::disturbed_ecu::DisturbedEcu;
use crate::closed_loop::plan_activation::PlanActivation;
use crate::closed_loop::set_up::{set_up, RunSpec, Setting};
use crate::closed_loop::summary::classify;
use crate::closed_loop::timeline::{self, LogRow};
use crate::model::vehicle::vehicle_width_m;
use crate::model::vehicle::VehicleParams;
use crate::output::run_files::write_outputs;
use crate::sweep::table::{summary_header, summary_values, RESULT_COLUMNS};
use crate::world::faults::{Fault, Outcome, RunFacts, FAULT_START_S};
use crate::world::obstacle_file::obstacles_to_csv_string;
use crate::world::obstacle_placement::widths_at;
use crate::world::scenario::Scenario;

/// Which runs of a sweep keep their logs (`--logs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LogRuns {
    /// The runs whose outcome is not `ok`.
    Failed,
    /// Every run.
    All,
}

/// What one run produced: its factors and its `sweep.csv` cells after them.
#[derive(Clone, Debug)]
pub struct RunRow {
    /// The run.
    pub spec: RunSpec,
    /// Cells of [`RESULT_COLUMNS`] then of the summary's fields.
    pub cells: Vec<String>,
}

impl RunRow {
    /// The cell of column `name` of `sweep.csv` (a result column or a summary
    /// field), `None` for a factor column or a name that is no column.
    pub fn cell(&self, name: &str) -> Option<&str> {
        let i = RESULT_COLUMNS
            .iter()
            .map(|c| c.to_string())
            .chain(summary_header())
            .position(|c| c == name)?;
        self.cells.get(i).map(String::as_str)
    }
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
            .and_then(|_| fs::write(&p, obstacles_to_csv_string(setup.static_obstacles())))
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    let mut ecu = DisturbedEcu::<f32>::new(scn, &setup.nominal, opts, setup.disturbances.clone())?;
    let res = timeline::run_with(scn, &setup.plant_car, opts, &mut ecu, |_, _| {})?;
    let s = &res.summary;
    let edge = edge_excess(scn, &setup.plant_car, &res.log);
    let outcome = classify(s, edge.off_road_samples > 0);
    if let Some((dir, which)) = &common.log_dir {
        if *which == LogRuns::All || outcome != Outcome::Ok {
            write_outputs(&dir.join(spec.index.to_string()), scn, &res, false)?;
        }
    }
    let fault_event_s = match spec.fault {
        Fault::LateObstacle(_) | Fault::BlockedRoad(_) => {
            ecu.obstacle_appeared_at_us().map(|t| t as f64 * 1e-6)
        }
        Fault::DropoutNan(_) | Fault::DropoutHold(_) => Some(FAULT_START_S),
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
    for a in acts.iter().filter(|a| !a.published && !a.window) {
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
