//! The project's goals for the ECU binary (timing, memory, completeness of the
//! analysis), each a value against the most it may be, and the `--require` check.

use super::{MemoryReport, RunEntry, StaticSummary, Tasks};
use serde::Serialize;

/// Goal: plan task, warm-started activations, observed instructions at most this
/// (a warm MPC step within 0.5 M instructions).
pub const GOAL_PLAN_WARM_MAX_INSTRUCTIONS: f64 = 5.0e5;
/// Goal: the plan task's static bound at most this many times its largest traced
/// activation (in cycles of the same model).
pub const GOAL_PLAN_TIGHTNESS: f64 = 3.0;
/// Goal: control task, observed instructions at most this.
pub const GOAL_CONTROL_MAX_INSTRUCTIONS: f64 = 2000.0;
/// Goal: static RAM (`.data`, `.rodata_ram`, `.bss`, `.uninit`) at most this, in bytes (48 KiB).
pub const GOAL_STATIC_RAM_BYTES: f64 = 49_152.0;
/// Goal: static stack bound at most this, in bytes (8 KiB).
pub const GOAL_STACK_BOUND_BYTES: f64 = 8_192.0;
/// Goal: flash image at most this, in bytes (256 KiB).
pub const GOAL_FLASH_BYTES: f64 = 262_144.0;

/// One project goal: met when `value ≤ goal`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Goal {
    /// Short name, for `host-sim wcet --require ID`.
    pub id: &'static str,
    /// What is measured.
    pub name: String,
    /// Its value (unit in `unit`); `null` when there was nothing to measure.
    pub value: Option<f64>,
    /// The most it may be (same unit).
    pub goal: f64,
    /// Unit of `value` and `goal`.
    pub unit: String,
    /// `value ≤ goal`.
    pub met: bool,
}

impl Goal {
    /// `value (goal ≤ goal unit)`, the value rounded, `n/a` when not measured.
    pub fn figures(&self) -> String {
        format!(
            "{} (goal ≤ {} {})",
            self.value.map_or("n/a".into(), |v| format!("{v:.0}")),
            self.goal,
            self.unit
        )
    }
}

/// The goals among `required` (ids) that are missed, one line each; an error
/// naming the ids that are no goal, with the list of goals.
pub fn missed_required(goals: &[Goal], required: &[String]) -> Result<Vec<String>, String> {
    let unknown: Vec<&str> = required
        .iter()
        .map(String::as_str)
        .filter(|id| !goals.iter().any(|g| g.id == *id))
        .collect();
    if !unknown.is_empty() {
        let ids: Vec<&str> = goals.iter().map(|g| g.id).collect();
        return Err(format!(
            "--require: no goal {} (the goals: {})",
            unknown.join(", "),
            ids.join(", ")
        ));
    }
    Ok(goals
        .iter()
        .filter(|g| !g.met && required.iter().any(|id| id == g.id))
        .map(|g| format!("{} ({}): {}", g.id, g.name, g.figures()))
        .collect())
}

fn goal(id: &'static str, name: &str, value: Option<f64>, goal: f64, unit: &str) -> Goal {
    Goal {
        id,
        name: name.to_string(),
        value,
        goal,
        unit: unit.to_string(),
        met: value.is_some_and(|v| v <= goal),
    }
}

/// Every goal, from the report's figures.
pub(super) fn goals(
    tasks: &Tasks,
    memory: &MemoryReport,
    runs: &[RunEntry],
    statics: &StaticSummary,
) -> Vec<Goal> {
    let misses: u64 = runs
        .iter()
        .map(|r| r.plan_deadline_misses + r.control_deadline_misses)
        .sum();
    let not_completed = runs.iter().filter(|r| !r.completed).count();
    vec![
        goal(
            "plan-warm-observed",
            "plan warm-start observed max",
            tasks.plan.observed_warm_max_instructions,
            GOAL_PLAN_WARM_MAX_INSTRUCTIONS,
            "instructions",
        ),
        goal(
            "plan-job-budget",
            "plan job static bound within budget",
            tasks.plan.statics.job_static_bound_cycles.map(|c| c as f64),
            tasks.plan.budget_cycles,
            "cycles",
        ),
        goal(
            "window-job-budget",
            "window adoption static bound within the plan budget",
            tasks.plan_window.static_bound_cycles.map(|c| c as f64),
            tasks.plan_window.budget_cycles,
            "cycles",
        ),
        goal(
            "plan-tightness",
            "plan static bound over the traced maximum",
            tasks.plan.statics.tightness,
            GOAL_PLAN_TIGHTNESS,
            "×",
        ),
        goal(
            "control-job-budget",
            "control job static bound within budget",
            tasks
                .control
                .statics
                .job_static_bound_cycles
                .map(|c| c as f64),
            tasks.control.budget_cycles,
            "cycles",
        ),
        goal(
            "plan-response-time",
            "plan response time bound within the deadline",
            tasks.plan.statics.response_time_bound_us,
            tasks.plan.statics.deadline_us.unwrap_or(0.0),
            "µs",
        ),
        goal(
            "control-response-time",
            "control response time bound within the deadline",
            tasks.control.statics.response_time_bound_us,
            tasks.control.statics.deadline_us.unwrap_or(0.0),
            "µs",
        ),
        goal(
            "analysis-complete",
            "unbounded loops, unresolved calls, recursions",
            Some(statics.coverage.gaps() as f64),
            0.0,
            "",
        ),
        goal(
            "stack-covered",
            "stack bound: what it does not cover",
            Some(memory.stack_misses.len() as f64),
            0.0,
            "items",
        ),
        goal(
            "control-observed",
            "control observed max",
            Some(tasks.control.observed_max_instructions),
            GOAL_CONTROL_MAX_INSTRUCTIONS,
            "instructions",
        ),
        goal(
            "static-ram",
            "static RAM",
            Some(memory.static_ram_bytes as f64),
            GOAL_STATIC_RAM_BYTES,
            "bytes",
        ),
        goal(
            "stack-bound",
            "stack bound",
            Some(memory.stack_bound_bytes as f64),
            GOAL_STACK_BOUND_BYTES,
            "bytes",
        ),
        goal(
            "flash",
            "flash",
            Some(memory.flash_bytes as f64),
            GOAL_FLASH_BYTES,
            "bytes",
        ),
        goal(
            "deadline-misses",
            "deadline misses over the runs",
            Some(misses as f64),
            0.0,
            "misses",
        ),
        goal(
            "runs-completed",
            "PIL runs not completed",
            Some(not_completed as f64),
            0.0,
            "runs",
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn required_goals_fail_only_when_missed_and_unknown_ids_are_errors(
    ) -> std::result::Result<(), String> {
        let goals = vec![
            goal("a", "a goal", Some(1.0), 2.0, "x"),
            goal("b", "b goal", Some(3.0), 2.0, "x"),
            goal("c", "c goal", None, 2.0, "x"),
        ];
        let req = |ids: &[&str]| ids.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(missed_required(&goals, &req(&["a"]))?.is_empty());
        let missed = missed_required(&goals, &req(&["a", "b", "c"]))?;
        assert_eq!(missed.len(), 2, "{missed:?}");
        assert!(missed[0].starts_with("b (b goal): 3"), "{missed:?}");
        assert!(missed[1].contains("n/a"), "{missed:?}");
        let err = missed_required(&goals, &req(&["a", "z"]))
            .err()
            .unwrap_or_default();
        assert!(
            err.contains("no goal z") && err.contains("a, b, c"),
            "{err}"
        );
        Ok(())
    }
}
