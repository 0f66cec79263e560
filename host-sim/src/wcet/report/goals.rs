//! The project's goals for the ECU binary (timing, memory, completeness of the
//! analysis), each a value against the most it may be, and the `--require` check.

use super::{MemoryReport, RunEntry, StaticSummary, Tasks};
use serde::Serialize;

/// Goal: plan task, warm-started activations, observed instructions at most this
/// (a warm MPC step within 0.5 M instructions), plus the static bound of the route
/// frame the same activation may receive first (`route_job`, when the analysis
/// bounds it): the step and the frame each within their own figure.
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
/// Goal: the loops the tasks reach that no trace executed, at most this percent of
/// them (95 % traced).
pub const GOAL_LOOPS_UNTRACED_PERCENT: f64 = 5.0;
/// Goal: flash image at most this, in bytes (256 KiB).
pub const GOAL_FLASH_BYTES: f64 = 262_144.0;

/// The id of the stack-bound goal, in the report and for `--require` with
/// `--static-only`.
pub const STACK_BOUND_GOAL: &str = "stack-bound";

/// What `--require stack-bound` says of a stack bound of `total_bytes` (`sound`:
/// everything reachable analysed) when it misses the goal: unsound, or past
/// [`GOAL_STACK_BOUND_BYTES`]; `None` when it meets it.
pub fn missed_stack_bound(total_bytes: u32, sound: bool) -> Option<String> {
    if !sound {
        Some(format!(
            "{STACK_BOUND_GOAL}: {total_bytes} B is not sound (stack.json lists what it leaves out)"
        ))
    } else if f64::from(total_bytes) > GOAL_STACK_BOUND_BYTES {
        Some(format!(
            "{STACK_BOUND_GOAL}: {total_bytes} B, goal {GOAL_STACK_BOUND_BYTES} B"
        ))
    } else {
        None
    }
}

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

/// Every goal, from the report's figures: the tasks' timing, the analysis'
/// completeness, the footprint, then the PIL runs.
pub(super) fn goals(
    tasks: &Tasks,
    memory: &MemoryReport,
    runs: &[RunEntry],
    statics: &StaticSummary,
) -> Vec<Goal> {
    let mut out = timing_goals(tasks, statics);
    out.extend(analysis_goals(memory, statics));
    out.extend(footprint_goals(tasks, memory));
    out.extend(run_goals(runs));
    out
}

/// The tasks' timing goals: the plan's warm observed instructions, the jobs'
/// static bounds within their budgets, the plan's tightness, the response times
/// within the deadlines.
fn timing_goals(tasks: &Tasks, statics: &StaticSummary) -> Vec<Goal> {
    vec![
        goal(
            "plan-warm-observed",
            "plan warm-start observed max",
            tasks.plan.observed_warm_max_instructions,
            GOAL_PLAN_WARM_MAX_INSTRUCTIONS
                + statics.route_job_static_bound_instructions.unwrap_or(0) as f64,
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
    ]
}

/// The analysis' completeness: no gap, no flow fact above its traced maximum,
/// the loops and budgeted jobs traced, the stack bound covering everything.
fn analysis_goals(memory: &MemoryReport, statics: &StaticSummary) -> Vec<Goal> {
    vec![
        goal(
            "analysis-complete",
            "unbounded loops, unresolved calls, recursions",
            Some(statics.coverage.gaps() as f64),
            0.0,
            "",
        ),
        goal(
            "flow-facts",
            "flow facts below their traced maximum",
            Some(
                statics
                    .coverage
                    .flow_facts
                    .iter()
                    .filter(|f| f.observed_max.is_some_and(|m| m > f.bound))
                    .count() as f64,
            ),
            0.0,
            "facts",
        ),
        goal(
            "loops-traced",
            "loops the tasks reach that no trace executed",
            statics.coverage.loops_traced_percent.map(|p| 100.0 - p),
            GOAL_LOOPS_UNTRACED_PERCENT,
            "% of the loops",
        ),
        goal(
            "jobs-traced",
            "budgeted jobs no trace called",
            Some(
                statics
                    .coverage
                    .jobs_traced
                    .iter()
                    .filter(|(_, n)| *n == 0)
                    .count() as f64,
            ),
            0.0,
            "jobs",
        ),
        goal(
            "stack-covered",
            "stack bound: what it does not cover",
            Some(memory.stack_misses.len() as f64),
            0.0,
            "items",
        ),
    ]
}

/// The footprint: the control task's observed instructions, static RAM, the
/// stack bound and flash.
fn footprint_goals(tasks: &Tasks, memory: &MemoryReport) -> Vec<Goal> {
    vec![
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
            STACK_BOUND_GOAL,
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
    ]
}

/// The PIL runs' goals: no deadline miss (claimed only over completed runs),
/// every run completed.
fn run_goals(runs: &[RunEntry]) -> Vec<Goal> {
    let misses: u64 = runs
        .iter()
        .map(|r| r.plan_deadline_misses + r.control_deadline_misses)
        .sum();
    let not_completed = runs.iter().filter(|r| !r.completed).count();
    // A miss counts wherever it happened; "no miss" is claimed only over runs that
    // reached the end of their scenario (a lap), not over a run cut short.
    let (misses_name, misses_value) = if misses == 0 && not_completed > 0 {
        (
            "deadline misses over the runs (none counted, but a run did not complete: \
             zero is claimed only over completed runs)",
            None,
        )
    } else {
        ("deadline misses over the runs", Some(misses as f64))
    };
    vec![
        goal("deadline-misses", misses_name, misses_value, 0.0, "misses"),
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
    use super::super::{
        Coverage, ElfMemory, MemoryReport, RunEntry, StaticSummary, StaticTiming, TaskTiming,
        Tasks, WindowTiming,
    };
    use super::*;

    #[test]
    fn the_static_stack_goal_fails_past_8_kib_or_unsound() {
        assert_eq!(missed_stack_bound(8_192, true), None);
        let over = missed_stack_bound(8_193, true).unwrap_or_default();
        assert!(over.contains("8193 B") && over.contains("8192"), "{over}");
        let unsound = missed_stack_bound(4_000, false).unwrap_or_default();
        assert!(unsound.contains("not sound"), "{unsound}");
    }

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

    /// What [`goals`] reads, every goal met by a small margin (figures of the
    /// kind the ECU's report has).
    struct Fixture {
        tasks: Tasks,
        memory: MemoryReport,
        runs: Vec<RunEntry>,
        statics: StaticSummary,
    }

    fn timing(statics: StaticTiming, observed: f64, budget: f64) -> TaskTiming {
        TaskTiming {
            observed_max_instructions: observed,
            observed_p50_instructions: observed / 2.0,
            observed_warm_max_instructions: None,
            observed_cold_max_instructions: None,
            statics,
            budget_cycles: budget,
            budget_us: budget / 168.0,
        }
    }

    fn run(dir: &str) -> RunEntry {
        RunEntry {
            dir: dir.into(),
            completed: true,
            plan_activations: 880,
            plan_deadline_misses: 0,
            control_deadline_misses: 0,
            plan_failures: 0,
            stack_high_water_bytes: 5_000,
            elf: "ecu".into(),
        }
    }

    impl Fixture {
        fn all_met() -> Self {
            let plan = StaticTiming {
                static_bound_instructions: Some(7_800_000),
                static_bound_cycles: Some(14_700_000),
                job_static_bound_cycles: Some(14_600_000),
                response_time_bound_us: Some(96_800.0),
                deadline_us: Some(100_000.0),
                traced_max_cycles: Some(5_400_000),
                tightness: Some(2.7),
                ..StaticTiming::default()
            };
            let control = StaticTiming {
                static_bound_instructions: Some(60_000),
                static_bound_cycles: Some(130_000),
                job_static_bound_cycles: Some(4_995),
                response_time_bound_us: Some(903.0),
                deadline_us: Some(10_000.0),
                traced_max_cycles: Some(44_000),
                tightness: Some(2.9),
                ..StaticTiming::default()
            };
            let mut plan_timing = timing(plan.clone(), 720_000.0, 15.96e6);
            plan_timing.observed_warm_max_instructions = Some(480_000.0);
            Self {
                tasks: Tasks {
                    plan: plan_timing,
                    control: timing(control.clone(), 1_500.0, 5_000.0),
                    plan_window: WindowTiming {
                        observed_max_instructions: 720_000.0,
                        static_bound_cycles: Some(13_000_000),
                        budget_cycles: 15.96e6,
                        period_cycles: 16.8e6,
                    },
                },
                memory: MemoryReport {
                    sections: ElfMemory::default(),
                    static_ram_bytes: 48_700,
                    flash_bytes: 155_000,
                    stack_bound_bytes: 8_144,
                    stack_method: "fixture".into(),
                    stack_sound: true,
                    stack_misses: Vec::new(),
                    stack_roots: Vec::new(),
                    stack_high_water_bytes: 5_232,
                    stack_size_bytes: 82_000,
                },
                runs: vec![run("lap-a"), run("lap-b")],
                statics: StaticSummary {
                    plan,
                    control,
                    window_job_static_bound_cycles: Some(13_000_000),
                    route_job_static_bound_instructions: None,
                    interrupts: Vec::new(),
                    coverage: Coverage {
                        loops_traced_percent: Some(100.0),
                        jobs_traced: vec![("control_job".into(), 10), ("plan_job".into(), 2)],
                        ..Coverage::default()
                    },
                },
            }
        }

        fn goals(&self) -> Vec<Goal> {
            goals(&self.tasks, &self.memory, &self.runs, &self.statics)
        }
    }

    /// Checks that exactly the goals `ids` are missed, and that `--require` with
    /// every goal names each of them.
    fn only_missed(f: &Fixture, ids: &[&str]) -> Result<(), String> {
        let goals = f.goals();
        let mut missed: Vec<&str> = goals.iter().filter(|g| !g.met).map(|g| g.id).collect();
        let mut want = ids.to_vec();
        missed.sort_unstable();
        want.sort_unstable();
        assert_eq!(missed, want, "{goals:#?}");
        let every: Vec<String> = goals.iter().map(|g| g.id.to_string()).collect();
        let lines = missed_required(&goals, &every)?;
        for id in ids {
            assert!(
                lines.iter().any(|l| l.starts_with(&format!("{id} ("))),
                "--require {id} did not fail: {lines:?}"
            );
        }
        Ok(())
    }

    #[test]
    fn a_warm_activation_with_a_route_frame_is_held_to_the_step_and_the_frames_bound() {
        let mut f = Fixture::all_met();
        f.statics.route_job_static_bound_instructions = Some(90_000);
        f.tasks.plan.observed_warm_max_instructions = Some(590_000.0);
        assert!(f.goals().iter().all(|g| g.met), "{:#?}", f.goals());
    }

    /// One test per goal (`name: "goal-id" + "also-missed"... => breach;`): the
    /// breach applied to [`Fixture::all_met`] misses that goal and no other but
    /// those listed after it.
    macro_rules! breaches {
        ($($test:ident: $id:literal $(+ $also:literal)* => $breach:expr;)*) => {
            $(
                #[test]
                fn $test() -> Result<(), String> {
                    let mut f = Fixture::all_met();
                    let breach: fn(&mut Fixture) = $breach;
                    breach(&mut f);
                    only_missed(&f, &[$id $(, $also)*])
                }
            )*
            /// The goals the breach tests make fail.
            const BREACHED: &[&str] = &[$($id),*];
        };
    }

    breaches! {
        plan_warm_observed_fails_over_half_a_million_instructions: "plan-warm-observed" =>
            |f| f.tasks.plan.observed_warm_max_instructions = Some(500_001.0);
        plan_warm_observed_fails_past_the_step_and_the_route_frames_bound: "plan-warm-observed" =>
            |f| {
                f.statics.route_job_static_bound_instructions = Some(90_000);
                f.tasks.plan.observed_warm_max_instructions = Some(590_001.0);
            };
        plan_job_budget_fails_when_the_bound_exceeds_the_budget: "plan-job-budget" =>
            |f| f.tasks.plan.statics.job_static_bound_cycles = Some(15_960_001);
        plan_job_budget_fails_without_a_bound: "plan-job-budget" =>
            |f| f.tasks.plan.statics.job_static_bound_cycles = None;
        window_job_budget_fails_when_the_adoption_exceeds_the_budget: "window-job-budget" =>
            |f| f.tasks.plan_window.static_bound_cycles = Some(15_960_001);
        plan_tightness_fails_over_three: "plan-tightness" =>
            |f| f.tasks.plan.statics.tightness = Some(3.01);
        flow_facts_fails_on_a_fact_below_its_traced_count: "flow-facts" =>
            |f| f.statics.coverage.flow_facts.push(crate::wcet::flow_facts::FlowFact {
                name: "qp_iterations".into(),
                per: "activation".into(),
                counts: "loop iterations".into(),
                bound: 56,
                bound_by_task: Vec::new(),
                sources: vec!["qp/src/active_set.rs:143".into()],
                members: 2,
                observed_max: Some(57),
                observed_scopes: 1,
                counter: crate::wcet::trace_check::CounterSpec {
                    scope: crate::wcet::trace_check::CounterScope::Activation,
                    blocks: Vec::new(),
                    edges: Vec::new(),
                },
            });
        loops_traced_fails_under_ninety_five_percent: "loops-traced" =>
            |f| f.statics.coverage.loops_traced_percent = Some(94.9);
        loops_traced_fails_without_traces: "loops-traced" =>
            |f| f.statics.coverage.loops_traced_percent = None;
        jobs_traced_fails_on_a_job_never_called: "jobs-traced" =>
            |f| f.statics.coverage.jobs_traced.push(("window_job".into(), 0));
        control_job_budget_fails_one_cycle_over: "control-job-budget" =>
            |f| f.tasks.control.statics.job_static_bound_cycles = Some(5_001);
        plan_response_time_fails_past_the_period: "plan-response-time" =>
            |f| f.tasks.plan.statics.response_time_bound_us = Some(100_000.1);
        control_response_time_fails_without_a_bound_within_the_deadline: "control-response-time" =>
            |f| f.tasks.control.statics.response_time_bound_us = None;
        analysis_complete_fails_on_an_unbounded_loop: "analysis-complete" =>
            |f| f.statics.coverage.unbounded_loops = 1;
        analysis_complete_fails_on_a_recursion: "analysis-complete" =>
            |f| f.statics.coverage.recursions = vec!["[a, b]".into()];
        stack_covered_fails_on_an_unresolved_indirect_call: "stack-covered" =>
            |f| f.memory.stack_misses = vec!["indirect call in f: blx r2".into()];
        control_observed_fails_over_two_thousand_instructions: "control-observed" =>
            |f| f.tasks.control.observed_max_instructions = 2_001.0;
        static_ram_fails_over_48_kib: "static-ram" =>
            |f| f.memory.static_ram_bytes = 49_153;
        stack_bound_fails_over_8_kib: "stack-bound" =>
            |f| f.memory.stack_bound_bytes = 8_193;
        flash_fails_over_256_kib: "flash" =>
            |f| f.memory.flash_bytes = 262_145;
        deadline_misses_fails_on_a_plan_overrun: "deadline-misses" =>
            |f| f.runs[0].plan_deadline_misses = 1;
        deadline_misses_fails_on_a_control_overrun: "deadline-misses" =>
            |f| f.runs[1].control_deadline_misses = 1;
        runs_completed_fails_on_a_run_cut_short_and_no_miss_is_claimed_over_it:
            "runs-completed" + "deadline-misses" =>
            |f| f.runs[1].completed = false;
    }

    #[test]
    fn the_fixture_meets_every_goal() -> Result<(), String> {
        only_missed(&Fixture::all_met(), &[])
    }

    #[test]
    fn every_goal_has_a_breach_test() {
        let mut ids: Vec<&str> = Fixture::all_met().goals().iter().map(|g| g.id).collect();
        let mut breached = BREACHED.to_vec();
        ids.sort_unstable();
        breached.sort_unstable();
        breached.dedup();
        assert_eq!(breached, ids, "add a case to breaches! for each new goal");
    }

    #[test]
    fn a_miss_in_a_run_cut_short_still_counts() -> Result<(), String> {
        let mut f = Fixture::all_met();
        f.runs[1].completed = false;
        f.runs[1].plan_deadline_misses = 3;
        let goals = f.goals();
        let misses = goals
            .iter()
            .find(|g| g.id == "deadline-misses")
            .ok_or("no deadline-misses goal")?;
        assert_eq!(
            (misses.value, misses.met, misses.name.as_str()),
            (Some(3.0), false, "deadline misses over the runs")
        );
        Ok(())
    }

    /// The real ECU ELF (`cargo ecu-lockstep`); fails when it has not been built.
    fn real_elf() -> std::path::PathBuf {
        let path =
            crate::pil::built_ecu_elf(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
        assert!(
            path.is_file(),
            "the ECU binary {} is missing: build it first (cargo ecu-lockstep)",
            path.display()
        );
        path
    }

    /// The real ECU in QEMU, each instruction 256 ns instead of 16 (`-icount
    /// shift=8`, as if the core ran at a sixteenth of its speed): every plan
    /// activation overruns its 100 ms period. The ECU's own deadline monitor
    /// counts the misses, the report carries them, and `--require
    /// deadline-misses` fails. On its own clock, over the same 2 s, no miss is
    /// counted, but the run does not complete its lap, so no pass is claimed.
    #[test]
    #[ignore = "needs the ECU binary (cargo ecu-lockstep) and qemu-system-arm"]
    fn real_ecu_elf_deadline_gate_fails_on_an_injected_overrun() -> anyhow::Result<()> {
        let elf = real_elf();
        let tmp = tempfile::tempdir()?;
        let report = |shift: u32| -> anyhow::Result<(Goal, crate::closed_loop::summary::Summary)> {
            let dir = tmp.path().join(format!("shift-{shift}"));
            let mut args = crate::commands::wcet::pil_args(dir.clone(), "paper", 1.0, 2.0, &elf);
            args.icount_shift = shift;
            crate::commands::pil::run(&args)?;
            let inputs = super::super::ReportInputs {
                run_dirs: vec![dir.clone()],
                elf: elf.clone(),
                stack_levels: crate::wcet::ecu_app::EcuBuild::LockStep.priority_levels(),
                cpi: crate::commands::wcet::given_cpi(2.6),
                statics: StaticSummary::default(),
                plan_period_cycles: 16.8e6,
                plan_budget_cycles: 15.96e6,
                control_budget_cycles: 5_000.0,
                clock_hz: 168_000_000,
            };
            let r = super::super::build_report(&inputs)?;
            let summary: crate::closed_loop::summary::Summary =
                serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json"))?)?;
            let g = r
                .goals
                .iter()
                .find(|g| g.id == "deadline-misses")
                .cloned()
                .ok_or_else(|| anyhow::anyhow!("no deadline-misses goal"))?;
            Ok((g, summary))
        };
        let (slow, s) = report(8)?;
        let ecu_count =
            s.ecu_plan_deadline_misses.unwrap_or(0) + s.ecu_control_deadline_misses.unwrap_or(0);
        assert!(
            ecu_count > 0,
            "no miss counted by the ECU at 256 ns per instruction: {s:?}"
        );
        assert_eq!(slow.value, Some(ecu_count as f64), "{slow:?}");
        assert!(!slow.met);
        let required = ["deadline-misses".to_string()];
        let lines = missed_required(std::slice::from_ref(&slow), &required)
            .map_err(|e| anyhow::anyhow!(e))?;
        assert!(
            lines.len() == 1 && lines[0].starts_with("deadline-misses ("),
            "{lines:?}"
        );
        let (own_clock, s) = report(4)?;
        assert_eq!(
            (
                s.plan_deadline_misses,
                s.control_deadline_misses,
                s.completed
            ),
            (0, 0, false)
        );
        assert_eq!(
            (own_clock.value, own_clock.met),
            (None, false),
            "{own_clock:?}"
        );
        Ok(())
    }
}
