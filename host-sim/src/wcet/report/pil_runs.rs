//! Processor-in-the-loop run folders as the report reads them: `summary.json`,
//! `pil.json` and `plan_activations.csv`, written by `host-sim pil --out DIR`, each
//! read through the type its writer uses, with errors that name the file, line and
//! column.

use anyhow::{ensure, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The command that writes a processor-in-the-loop run folder.
pub(crate) const PIL_COMMAND: &str = "host-sim pil --out DIR";

/// A PIL run's `summary.json`: the type `run` and `pil` write it with.
pub use crate::closed_loop::summary::Summary;
/// A PIL run's `pil.json`: the type `pil` writes it with.
pub use crate::pil::report::PilReport;

/// One row of `plan_activations.csv`: the type `run` and `pil` write it with.
pub use crate::closed_loop::plan_activation::PlanActivation;

/// A processor-in-the-loop run folder, read by [`load_pil_run`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PilRun {
    /// The folder.
    pub dir: PathBuf,
    /// Its `summary.json`.
    pub summary: Summary,
    /// Its `pil.json`.
    pub pil: PilReport,
    /// Its `plan_activations.csv`, one entry per activation.
    pub plan: Vec<PlanActivation>,
}

/// Columns `plan_activations.csv` must have (the report reads these).
const PLAN_COLUMNS: [&str; 5] = [
    "activation",
    "instructions",
    "status",
    "deadline_miss",
    "passes",
];

fn read_json<T: for<'de> Deserialize<'de>>(dir: &Path, name: &str) -> Result<T> {
    let path = dir.join(name);
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "cannot read {}: a PIL run folder holds {name}, written by `{PIL_COMMAND}`",
            path.display()
        )
    })?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not the {name} of `{PIL_COMMAND}` (a key is missing or has the wrong type)",
            path.display()
        )
    })
}

fn read_plan_csv(dir: &Path) -> Result<Vec<PlanActivation>> {
    let path = dir.join("plan_activations.csv");
    let mut reader = csv::Reader::from_path(&path).with_context(|| {
        format!(
            "cannot read {}: a PIL run folder holds plan_activations.csv, written by `{PIL_COMMAND}`",
            path.display()
        )
    })?;
    let headers = reader
        .headers()
        .with_context(|| format!("{}: cannot read the header line", path.display()))?
        .clone();
    for column in PLAN_COLUMNS {
        ensure!(
            headers.iter().any(|h| h == column),
            "{}: no `{column}` column (the header must name at least {})",
            path.display(),
            PLAN_COLUMNS.join(", ")
        );
    }
    let mut rows = Vec::new();
    for (k, row) in reader.deserialize::<PlanActivation>().enumerate() {
        // Line 1 is the header.
        let row = row.map_err(|e| {
            // Name the column the value was for.
            let column = match e.kind() {
                csv::ErrorKind::Deserialize { err, .. } => err
                    .field()
                    .and_then(|i| headers.get(i as usize))
                    .map(|h| format!(" in column `{h}`"))
                    .unwrap_or_default(),
                _ => String::new(),
            };
            anyhow::anyhow!(
                "{} line {}{column}: not a row of `{PIL_COMMAND}`'s plan_activations.csv \
                 (numbers, true/false, a known status): {e}",
                path.display(),
                k + 2
            )
        })?;
        ensure!(
            row.instructions.is_finite() && row.instructions >= 0.0,
            "{} line {}: instructions must be a finite number ≥ 0, got {}",
            path.display(),
            k + 2,
            row.instructions
        );
        rows.push(row);
    }
    Ok(rows)
}

/// Reads a processor-in-the-loop run folder: `summary.json`, `plan_activations.csv`
/// and `pil.json`, as written by `host-sim pil --out DIR`.
pub fn load_pil_run(dir: &Path) -> Result<PilRun> {
    ensure!(
        dir.is_dir(),
        "{} is not a folder: give the folder written by `{PIL_COMMAND}`",
        dir.display()
    );
    Ok(PilRun {
        dir: dir.to_path_buf(),
        summary: read_json(dir, "summary.json")?,
        pil: read_json(dir, "pil.json")?,
        plan: read_plan_csv(dir)?,
    })
}
