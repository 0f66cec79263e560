//! `host-sim sweep` and `host-sim sweep-merge` ([`crate::sweep`] says what a sweep
//! runs and writes): the cross product of the scenario options' lists, `--list`,
//! `--only I/N` shards and their merge, and the exit status ([`verdict`]).

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;

use crate::closed_loop::set_up::{ObstacleSpec, RunSpec, Setting};
use crate::commands::scenario_args::{check_track_arg, ScenarioArgs};
use crate::sweep::aggregate::{aggregate, text_summary};
use crate::sweep::execute::{run_all, Common, LogRuns};
use crate::sweep::figures;
use crate::sweep::table::{header, parse_rows, write_csv, Row, FACTOR_COLUMNS};
use crate::world::road_friction::RoadFriction;
use crate::world::road_grade::RoadGrade;
use crate::world::scenario;

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

/// The cross product of `args` (the order of [`crate::sweep`]'s docs), in index order.
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

/// Checks that the friction and grade patches fit every track and road friction of
/// `specs` before any run starts (a patch past a lap's end is the command's
/// mistake, not a run's).
fn check_patches(specs: &[RunSpec], setting: &Setting) -> Result<()> {
    let patches = &setting.mu_patches;
    if patches.is_empty() && setting.grade_patches.is_empty() {
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
        RoadGrade::new(
            &setting.grade_patches,
            &track.name,
            track.length(),
            track.closed,
        )?;
    }
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
    use crate::sweep::table::header;
    use crate::world::disturbance::NoiseLevel;

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
}
