//! The files of a closed-loop run, as `run`, `pil` and a sweep's `--logs` write
//! them: `log.csv` (one row every 10 ms), `plan_activations.csv` (one row per plan
//! activation), `summary.json` and, optionally, the figures.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};

use crate::closed_loop::timeline::RunResult;
use crate::output::figures;
use crate::world::scenario::Scenario;

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
