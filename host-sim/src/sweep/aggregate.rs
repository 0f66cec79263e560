//! `sweep.json` and `summary.txt`: the aggregate of a sweep's rows (outcomes per
//! factor level, figures per track and friction against their bounds, expected
//! behaviour per fault, errors) and its one-screen text summary.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::sweep::table::{Row, FACTOR_COLUMNS};
use crate::world::faults::{Fault, Outcome};

/// The bounds the benchmark checks: lateral error, lateral acceleration over μg and
/// plan–trajectory consistency (the sweep goals, docs/sweeps.md).
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
    /// Plan activations that published nothing over every run, by why (the
    /// runs' `plan_failure_kinds` summed: the QP's iteration cap, a full working
    /// set, ...).
    pub plan_failures: BTreeMap<String, u64>,
}

/// The runs' `plan_failure_kinds` (`kind:count;...`) summed by kind; a cell that
/// does not parse counts as one failure of its own text.
fn sum_plan_failures<'a>(rows: impl Iterator<Item = &'a Row>) -> BTreeMap<String, u64> {
    let mut m = BTreeMap::new();
    for r in rows {
        for part in r.plan_failure_kinds.split(';').filter(|p| !p.is_empty()) {
            let (kind, n) = match part.rsplit_once(':') {
                Some((k, n)) => match n.parse::<u64>() {
                    Ok(n) => (k, n),
                    Err(_) => (part, 1),
                },
                None => (part, 1),
            };
            *m.entry(kind.to_string()).or_insert(0) += n;
        }
    }
    m
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
        plan_failures: sum_plan_failures(rows.iter()),
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
    let failed: u64 = a.plan_failures.values().sum();
    let kinds: Vec<String> = a
        .plan_failures
        .iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect();
    let _ = writeln!(
        t,
        "plan activations that published nothing: {failed}{}",
        if kinds.is_empty() {
            String::new()
        } else {
            format!(" ({})", kinds.join(", "))
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::table::{header, parse_rows};

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
    fn failed_plan_steps_are_summed_by_kind() {
        let h = header();
        let record = |kinds: &str| -> Vec<String> {
            h.iter()
                .map(|c| match c.as_str() {
                    "track" => "a".into(),
                    "mu" => "1".into(),
                    "outcome" => "ok".into(),
                    "completed" => "true".into(),
                    "plan_failure_kinds" => kinds.into(),
                    _ => String::new(),
                })
                .collect()
        };
        let rows = parse_rows(&[
            record("qp_iteration_limit:20;qp_working_set_full:4"),
            record(""),
            record("qp_iteration_limit:3"),
            record("odd"),
        ]);
        let agg = aggregate(&rows, None);
        let want: BTreeMap<String, u64> = [
            ("odd".to_string(), 1),
            ("qp_iteration_limit".to_string(), 23),
            ("qp_working_set_full".to_string(), 4),
        ]
        .into();
        assert_eq!(agg.plan_failures, want);
        assert!(
            text_summary(&agg).contains(
                "plan activations that published nothing: 28 (odd 1, qp_iteration_limit 23, qp_working_set_full 4)"
            ),
            "{}",
            text_summary(&agg)
        );
    }
}
