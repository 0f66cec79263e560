//! `host-sim qp-corpus`: records the QPs of a scenario ([`crate::qp_corpus`]) and
//! writes the corpus.

use std::path::PathBuf;

use anyhow::{bail, ensure, Result};

use crate::closed_loop::Precision;
use crate::qp_corpus::files::write_corpus;
use crate::qp_corpus::record::{builtin_obstacles, builtin_track_rows, record, DEFAULT_STEPS};
use crate::qp_corpus::replay::{median_max, time_solves};

/// Arguments of `host-sim qp-corpus`.
#[derive(Clone, Debug, clap::Args)]
pub struct QpCorpusArgs {
    /// Directory to write `qp_0000.json`, … into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// MPC steps of 0.1 s to run (a cold first step solves 3 QPs, the others 1).
    #[arg(long, default_value_t = DEFAULT_STEPS)]
    pub steps: usize,
    /// Precision of the MPC run to record.
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Track: `builtin` (this module's 120 m × 70 m loop), `paper` or a CSV file
    /// `# x_m,y_m,w_tr_right_m,w_tr_left_m`.
    #[arg(long, default_value = "builtin")]
    pub track: String,
    /// The track file is an open path (default: closed loop).
    #[arg(long)]
    pub open: bool,
    /// Obstacles: `builtin` (with `--track builtin`), `none`, `paper` (with `--track
    /// paper`) or a CSV file `id,x_m,y_m`.
    #[arg(long, default_value = "builtin")]
    pub obstacles: String,
    /// Also time our f64 solver on every QP, cold and warm (keys `solve_us_cold`,
    /// `solve_us_warm`, µs; see `time_solves`), and print the percentiles.
    #[arg(long)]
    pub time: bool,
    /// Repetitions per QP and mode with `--time` (their median is kept; at least 5).
    #[arg(long, default_value_t = 21)]
    pub time_reps: usize,
}

/// Track rows, closed flag and obstacle polygons (m) of `args`' scenario.
type ScenarioData = (Vec<[f64; 4]>, bool, Vec<Vec<[f64; 2]>>);

fn scenario_data(args: &QpCorpusArgs) -> Result<ScenarioData> {
    let file_obstacles = |path: &str| -> Result<Vec<Vec<[f64; 2]>>> {
        Ok(crate::world::obstacle_file::load_obstacles_path(path)?
            .into_iter()
            .map(|o| o.vertices)
            .collect())
    };
    if args.track == "builtin" {
        ensure!(
            !args.open,
            "the built-in track is a closed loop; --open only applies to track files"
        );
        let obstacles = match args.obstacles.as_str() {
            "builtin" => builtin_obstacles(),
            "none" => Vec::new(),
            "paper" => bail!(
                "the `paper` obstacles are placed on the `paper` track; with `--track builtin` use `--obstacles builtin`, `none` or an obstacle file"
            ),
            path => file_obstacles(path)?,
        };
        return Ok((builtin_track_rows(), true, obstacles));
    }
    ensure!(
        args.obstacles != "builtin",
        "`--obstacles builtin` goes with `--track builtin`; with `--track {}` use `none`, `paper` (paper track) or an obstacle file",
        args.track
    );
    let sc = crate::world::scenario::resolve(&args.track, &args.obstacles, !args.open)?;
    Ok((
        sc.track.rows(),
        sc.track.closed,
        sc.obstacles.into_iter().map(|o| o.vertices).collect(),
    ))
}

/// `host-sim qp-corpus`: records the scenario of `--track`/`--obstacles` and writes the
/// corpus; prints a summary (QPs, statuses, iterations).
pub fn run(args: &QpCorpusArgs) -> Result<()> {
    ensure!(args.steps > 0, "--steps must be at least 1");
    let (rows, closed, obstacles) = scenario_data(args)?;
    let mut entries = record(&rows, closed, &obstacles, args.steps, args.precision)?;
    if args.time {
        let times = time_solves(&entries, args.time_reps)?;
        for (e, &(cold, warm)) in entries.iter_mut().zip(&times) {
            e.solve_us_cold = Some(cold);
            e.solve_us_warm = Some(warm);
        }
        let (cold, warm): (Vec<f64>, Vec<f64>) = times.into_iter().unzip();
        let pct = crate::stats::percentile;
        println!(
            "our f64 solve() (median of {} repetitions per QP): cold p50 {:.1} µs, p99 {:.1} µs; warm p50 {:.1} µs, p99 {:.1} µs",
            args.time_reps,
            pct(&cold, 0.5),
            pct(&cold, 0.99),
            pct(&warm, 0.5),
            pct(&warm, 0.99)
        );
    }
    write_corpus(&args.out, &entries)?;
    let optimal = entries.iter().filter(|e| e.status == "optimal").count();
    let warm: Vec<u32> = entries.iter().map(|e| e.iterations).collect();
    let (wmed, wmax) = median_max(&warm);
    println!(
        "wrote {} QPs ({} precision) to {}: {optimal} optimal; iterations (warm, as in the MPC) median {wmed}, max {wmax}",
        entries.len(),
        args.precision.name(),
        args.out.display()
    );
    if let Some(last) = entries.last() {
        let steps_done = last.step + 1;
        if last.status != "optimal" {
            println!(
                "warning: the MPC failed at step {} ({}); the run stopped there",
                last.step, last.status
            );
        } else if steps_done < args.steps {
            println!("warning: only {steps_done} of {} steps ran", args.steps);
        }
    }
    Ok(())
}
