//! `sweep.csv`: its columns (the run's factors, what the sweep measures, every field
//! of `summary.json` but the host's wall time), writing it, and reading its rows
//! back for the aggregate.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, Context, Result};

use crate::closed_loop::set_up::RunSpec;
use crate::closed_loop::summary::Summary;
use crate::world::faults::Outcome;

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

impl RunSpec {
    /// The run's cells under [`FACTOR_COLUMNS`] in `sweep.csv`.
    pub fn columns(&self) -> Vec<String> {
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

/// The summary's cells in `sweep.csv`, under [`summary_header`]'s columns.
pub fn summary_values(s: &Summary) -> Result<Vec<String>> {
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
    /// Plan activations that published nothing, by why (`plan_failure_kinds`:
    /// `kind:count` pairs joined by `;`).
    pub plan_failure_kinds: String,
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
            plan_failure_kinds: get(r, "plan_failure_kinds"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
