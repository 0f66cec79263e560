//! The worst-case timing and memory report of the ECU binary (`wcet.json`, `wcet.md`).
//!
//! It puts together what the other analyses measured or bounded:
//!
//! * **timing**: per task, the instructions observed on the ECU in the
//!   processor-in-the-loop runs (`host-sim pil --out DIR`), beside what the static
//!   analysis of the binary derives ([`super::analysis`]: the IPET bound in
//!   instructions and cycles of the stated processor and memory model, the
//!   response-time bound against the deadline, the tightness against the traced
//!   activations). The cycles per instruction of a traced run ([`super::cpi`]) are
//!   reported as what they are, an average over the code that ran, not a bound;
//! * **memory**: section sizes of the ECU ELF (flash and static RAM), the static
//!   stack bound of [`super::stack`] over the RTIC application's priority levels, and
//!   the painted-stack high-water mark the PIL runs measured;
//! * **symbols**: whether a heap allocator or software double-precision routines
//!   were linked in;
//! * **goals**: each project goal with its value and whether it is met.
//!
//! | module | concept |
//! |---|---|
//! | this file | the report model ([`WcetReport`]) and its assembly ([`build_report`]) |
//! | [`pil_runs`] | reading processor-in-the-loop run folders |
//! | [`elf`] | the ELF's section sizes and linked symbols |
//! | [`goals`] | the project goals and `--require` |
//! | [`markdown`] | writing `wcet.json` and `wcet.md` |
//! | [`expected`] | the CI comparison with a committed `wcet.json` |
//! | [`clock`] | the core clock, its source and the function that sets it |

pub mod elf;
pub mod expected;
pub mod goals;
pub mod markdown;
pub mod pil_runs;

use super::cpi::CpiReport;
use super::ecu_app::{ecu_once, EcuBuild};
use super::stack::{PriorityLevel, StackReport, StackRoot};
use anyhow::{bail, ensure, Context, Result};
use elf::{elf_caps, elf_memory, elf_symbols, Caps, ElfMemory, ElfSymbols};
use goals::{goals, Goal};
use pil_runs::{load_pil_run, PilRun, PIL_COMMAND};
use serde::Serialize;
use std::path::PathBuf;

/// What [`build_report`] needs besides the files it reads.
#[derive(Debug, Clone)]
pub struct ReportInputs {
    /// Processor-in-the-loop run folders (`host-sim pil --out DIR`), at least one.
    pub run_dirs: Vec<PathBuf>,
    /// The ECU ELF (`target/thumbv7em-none-eabihf/release/ecu`).
    pub elf: PathBuf,
    /// Priority levels for the stack bound, thread mode first; usually
    /// [`EcuBuild::priority_levels`].
    pub stack_levels: Vec<PriorityLevel>,
    /// The cycles per instruction of a traced ECU run ([`super::cpi::analyse_log`]):
    /// an average over the code the trace ran, reported for information.
    pub cpi: CpiReport,
    /// What the static analysis of the ELF derived ([`StaticSummary::of`]).
    pub statics: StaticSummary,
    /// Plan task period, in cycles (16.8e6: 100 ms at 168 MHz): a plan activation
    /// (planning, or adopting a window of the road instead) must end within it,
    /// or the next release is lost.
    pub plan_period_cycles: f64,
    /// Plan task budget per activation, in cycles (15.96e6: 95 ms at 168 MHz).
    pub plan_budget_cycles: f64,
    /// Control task budget per activation, in cycles.
    pub control_budget_cycles: f64,
    /// Core clock, in Hz (168e6).
    pub clock_hz: u64,
}

/// What the static analysis derived for one task (`None`: no bound).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StaticTiming {
    /// IPET bound on one activation of the whole task (its interrupt handler: the
    /// link, the job and the publication, or the window's adoption), in
    /// instructions.
    pub static_bound_instructions: Option<u64>,
    /// The same in worst-case cycles of the processor and memory model.
    pub static_bound_cycles: Option<u64>,
    /// IPET bound on the task's own job (`ecu::plan_job`, `ecu_control_job`), the
    /// part the budget limits, in cycles.
    pub job_static_bound_cycles: Option<u64>,
    /// Response-time bound (static C, blocking, interference), in µs; `None` when
    /// there is none within the deadline.
    pub response_time_bound_us: Option<f64>,
    /// The task's deadline (its period), in µs.
    pub deadline_us: Option<f64>,
    /// Largest traced activation priced with the bound's block cycles, in cycles.
    pub traced_max_cycles: Option<u64>,
    /// `static_bound_cycles / traced_max_cycles` (dimensionless, ≥ 1 when sound).
    pub tightness: Option<f64>,
    /// Calls of the task's job seen in the traces.
    pub job_traced_activations: u64,
    /// Largest traced call of the job priced with the bound's block cycles, in
    /// cycles.
    pub job_traced_max_cycles: Option<u64>,
    /// `job_static_bound_cycles / job_traced_max_cycles` (dimensionless).
    pub job_tightness: Option<f64>,
}

/// What the static analysis of the ELF found, as the report uses it.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StaticSummary {
    /// The plan task (`USART1`, its job `ecu::plan_job`).
    pub plan: StaticTiming,
    /// The control task (`USART2`, its job `ecu_control_job`).
    pub control: StaticTiming,
    /// IPET bound on the plan task's adoption of a window of the road
    /// (`ecu::window_job`, in place of its job), in cycles.
    pub window_job_static_bound_cycles: Option<u64>,
    /// IPET bound on a route frame's reception in a plan activation
    /// (`ecu::route_job`, before the plan or the adoption), in instructions.
    pub route_job_static_bound_instructions: Option<u64>,
    /// The interrupts of the schedule (SysTick, the flashed build's link): each
    /// entry's bound, inter-arrival time and response time.
    pub interrupts: Vec<super::analysis::InterruptEntry>,
    /// The loops and what the analysis could not bound.
    #[serde(flatten)]
    pub coverage: Coverage,
}

/// The loops the tasks reach and what the static analysis could not bound (in
/// `wcet.json`, at the top level).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Coverage {
    /// Every loop the tasks reach (function, file, line, bound, observed_max).
    pub loops: Vec<super::analysis::LoopEntry>,
    /// Loops without a bound (an error of the analysis).
    pub unbounded_loops: usize,
    /// Indirect calls without listed targets (an error of the analysis).
    pub unresolved_indirect_calls: Vec<String>,
    /// Call cycles (an error of the analysis).
    pub recursions: Vec<String>,
    /// The bounds over more than one loop entry, each with its source and its
    /// largest traced count (`observed_max`, `null`: no trace exercised it).
    pub flow_facts: Vec<super::flow_facts::FlowFact>,
    /// Loops the traces executed, percent of the loops the tasks reach (`null`
    /// without traces).
    pub loops_traced_percent: Option<f64>,
    /// The loops no trace executed, each with the reason read off the traces.
    pub untraced_loops: Vec<super::coverage::UntracedLoop>,
    /// Budgeted jobs (sections with a budget) and their traced calls.
    pub jobs_traced: Vec<(String, u64)>,
}

impl Coverage {
    /// Unbounded loops, unresolved indirect calls and recursions, together.
    pub fn gaps(&self) -> usize {
        self.unbounded_loops + self.unresolved_indirect_calls.len() + self.recursions.len()
    }
}

impl StaticSummary {
    /// The figures of `analysis` for the plan and control tasks (task `plan` and
    /// section `plan_job`, task `control` and section `control_job`).
    pub fn of(analysis: &super::analysis::StaticAnalysis) -> Self {
        let bound_cycles = |name: &str| {
            analysis
                .tasks
                .iter()
                .find(|t| t.name == name)
                .and_then(|t| t.static_bound_cycles)
        };
        let task = |name: &str, job: &str| {
            let t = analysis.tasks.iter().find(|t| t.name == name);
            let j = analysis.tasks.iter().find(|t| t.name == job);
            StaticTiming {
                job_traced_activations: j.map_or(0, |j| j.observed_activations),
                job_traced_max_cycles: j.and_then(|j| j.observed_max_cycles),
                job_tightness: j.and_then(|j| j.tightness),
                static_bound_instructions: t.and_then(|t| t.static_bound_instructions),
                static_bound_cycles: t.and_then(|t| t.static_bound_cycles),
                job_static_bound_cycles: bound_cycles(job),
                response_time_bound_us: t.and_then(|t| t.response_time_bound_us),
                deadline_us: t.and_then(|t| t.deadline_us),
                traced_max_cycles: t.and_then(|t| t.observed_max_cycles),
                tightness: t.and_then(|t| t.tightness),
            }
        };
        Self {
            plan: task("plan", "plan_job"),
            control: task("control", "control_job"),
            window_job_static_bound_cycles: bound_cycles("window_job"),
            route_job_static_bound_instructions: analysis
                .tasks
                .iter()
                .find(|t| t.name == "route_job")
                .and_then(|t| t.static_bound_instructions),
            interrupts: analysis.interrupts.clone(),
            coverage: Coverage {
                loops: analysis.loops.clone(),
                unbounded_loops: analysis.unbounded_loops,
                unresolved_indirect_calls: analysis.unresolved_indirect_calls.clone(),
                recursions: analysis
                    .recursions
                    .iter()
                    .map(|r| format!("{r:?}"))
                    .collect(),
                flow_facts: analysis.flow_facts.clone(),
                loops_traced_percent: analysis.coverage.as_ref().map(|c| c.percent),
                untraced_loops: analysis
                    .coverage
                    .as_ref()
                    .map(|c| c.untraced.clone())
                    .unwrap_or_default(),
                jobs_traced: analysis
                    .tasks
                    .iter()
                    .filter(|t| t.budget_cycles.is_some())
                    .map(|t| (t.name.clone(), t.observed_activations))
                    .collect(),
            },
        }
    }
}

/// Observed and bounded timing of one task.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskTiming {
    /// Most instructions of one activation over all PIL runs, in instructions.
    pub observed_max_instructions: f64,
    /// Median instructions of an activation, in instructions (plan: over all
    /// activations of all runs; control: the largest of the runs' medians).
    pub observed_p50_instructions: f64,
    /// Plan only: most instructions of an activation that planned from the
    /// previous plan (warm), in instructions; `null` if there was none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observed_warm_max_instructions: Option<f64>,
    /// Plan only: most instructions of an activation that planned from zero
    /// inputs (a cold start), in instructions; `null` if there was none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observed_cold_max_instructions: Option<f64>,
    /// What the static analysis derived.
    #[serde(flatten)]
    pub statics: StaticTiming,
    /// Budget of one activation's job, in cycles.
    pub budget_cycles: f64,
    /// `budget_cycles` at the clock, in µs.
    pub budget_us: f64,
}

/// Both tasks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Tasks {
    /// The plan task (priority 1, every 100 ms), up to its publication.
    pub plan: TaskTiming,
    /// The control task (priority 2, every 10 ms).
    pub control: TaskTiming,
    /// The plan task's adoption of a new window of the road, instead of planning.
    pub plan_window: WindowTiming,
}

/// An activation of the plan task that adopts a new window of the road instead of
/// planning.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowTiming {
    /// Most instructions of one adoption over all PIL runs, in instructions (the
    /// adoption is part of the plan task's static bound).
    pub observed_max_instructions: f64,
    /// IPET bound on the adoption (`ecu::window_job`), in cycles.
    pub static_bound_cycles: Option<u64>,
    /// Its budget, the plan task's, in cycles.
    pub budget_cycles: f64,
    /// The plan period, in cycles.
    pub period_cycles: f64,
}

/// Flash, RAM and stack of the ECU binary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MemoryReport {
    /// The ELF's section sizes (their keys written inline in `wcet.json`).
    #[serde(flatten)]
    pub sections: ElfMemory,
    /// `.data` + `.bss` + `.uninit`, in bytes.
    pub static_ram_bytes: u64,
    /// `.vector_table` + `.text` + `.rodata` + `.data`, in bytes.
    pub flash_bytes: u64,
    /// Static worst-case stack bound over the priority levels, in bytes.
    pub stack_bound_bytes: u64,
    /// How the stack bound was computed and what it does not cover.
    pub stack_method: String,
    /// `true` if nothing reachable escaped the stack analysis.
    pub stack_sound: bool,
    /// What the stack bound misses: indirect calls, unresolved calls, unknown
    /// frames, recursion, vector-table handlers it could not place (one line each).
    pub stack_misses: Vec<String>,
    /// Every root of the stack bound: thread mode, each priority level's handlers,
    /// every other handler of the vector table, the functions counted once; with
    /// how each is counted and its depth.
    pub stack_roots: Vec<StackRoot>,
    /// Deepest painted-stack use over the PIL runs, in bytes.
    pub stack_high_water_bytes: u64,
    /// Size of the stack region (RAM below the statics, flip-link), in bytes.
    pub stack_size_bytes: u64,
}

/// One PIL run as the report names it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunEntry {
    /// The run folder.
    pub dir: String,
    /// Whether the run reached the end of its scenario.
    pub completed: bool,
    /// Plan activations.
    pub plan_activations: u64,
    /// Plan deadline misses (the larger of `summary.json` and the CSV's count).
    pub plan_deadline_misses: u64,
    /// Control deadline misses.
    pub control_deadline_misses: u64,
    /// Plan activations whose status was not `optimal`.
    pub plan_failures: u64,
    /// Painted-stack high-water mark of the run, in bytes.
    pub stack_high_water_bytes: u64,
    /// The ELF the run used (from `pil.json`).
    pub elf: String,
}

/// The worst-case timing and memory report (`wcet.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WcetReport {
    /// Core clock, in Hz.
    pub clock_hz: u64,
    /// The core clock as the binary sets it: frequency, source, the function.
    pub clock: super::clock::ClockReport,
    /// Cycles per instruction of the traced ECU code (dimensionless): the
    /// worst-case cycles of the blocks that ran over their instructions, an
    /// average over that trace, not a bound for other code.
    pub traced_cycles_per_instruction: f64,
    /// How those cycles were counted.
    pub traced_cpi_method: String,
    /// Timing of both tasks.
    pub tasks: Tasks,
    /// The interrupts of the schedule: each entry's static bound, minimum
    /// inter-arrival time and response time.
    pub interrupts: Vec<super::analysis::InterruptEntry>,
    /// The loops and what the analysis could not bound.
    #[serde(flatten)]
    pub coverage: Coverage,
    /// Flash, RAM, stack.
    pub memory: MemoryReport,
    /// Allocator and software-double symbols.
    pub symbols: ElfSymbols,
    /// The plan task's caps, read from the binary (`null`: an ELF without them).
    pub caps: Option<Caps>,
    /// The PIL runs the observations come from.
    pub runs: Vec<RunEntry>,
    /// Deepest painted-stack use over the runs, in bytes.
    pub stack_high_water_bytes: u64,
    /// The project goals.
    pub goals: Vec<Goal>,
    /// The ECU ELF analysed.
    pub elf: String,
    /// The full static stack analysis (levels, worst paths, what it misses).
    pub stack: StackReport,
}

/// Reads the run folders and the ELF, bounds the stack with `llvm-objdump`, and
/// assembles the report.
pub fn build_report(inputs: &ReportInputs) -> Result<WcetReport> {
    let runs = inputs
        .run_dirs
        .iter()
        .map(|d| load_pil_run(d))
        .collect::<Result<Vec<_>>>()?;
    let memory = elf_memory(&inputs.elf)?;
    let symbols = elf_symbols(&inputs.elf)?;
    let stack = super::stack::analyse_elf_once(
        &inputs.elf,
        &inputs.stack_levels,
        &ecu_once(),
        &EcuBuild::of_elf(&inputs.elf)?.masked(),
        &super::indirect::targets_of_elf(&inputs.elf)?,
    )
    .with_context(|| format!("stack bound of {}", inputs.elf.display()))?;
    let mut report = assemble_report(inputs, &runs, memory, symbols, stack)?;
    report.clock = super::clock::of_elf(&inputs.elf)?;
    report.caps = elf_caps(&inputs.elf)?;
    Ok(report)
}

fn check_inputs(inputs: &ReportInputs, cpi: f64) -> Result<()> {
    let positive = [
        ("plan_budget_cycles", inputs.plan_budget_cycles),
        ("control_budget_cycles", inputs.control_budget_cycles),
        ("the CPI report's total.cpi_bound", cpi),
    ];
    for (name, value) in positive {
        ensure!(
            value.is_finite() && value > 0.0,
            "{name} must be a finite number > 0, got {value}"
        );
    }
    ensure!(
        inputs.clock_hz > 0,
        "clock_hz must be > 0 (168e6 for the ECU)"
    );
    Ok(())
}

/// Assembles the report from what [`build_report`] read (exposed so that the
/// report can be built from fixtures).
pub fn assemble_report(
    inputs: &ReportInputs,
    runs: &[PilRun],
    memory: ElfMemory,
    symbols: ElfSymbols,
    stack: StackReport,
) -> Result<WcetReport> {
    let cpi = inputs.cpi.total.cpi_bound;
    check_inputs(inputs, cpi)?;
    if runs.is_empty() {
        bail!("no PIL run given: make one with `{PIL_COMMAND}` and pass its folder");
    }
    let clock = inputs.clock_hz as f64;
    let (plan_obs, control_obs) = (plan_observed(runs)?, control_observed(runs));
    let plan = TaskTiming {
        observed_max_instructions: plan_obs.max,
        observed_p50_instructions: plan_obs.p50,
        observed_warm_max_instructions: plan_obs.warm_max,
        observed_cold_max_instructions: plan_obs.cold_max,
        statics: inputs.statics.plan.clone(),
        budget_cycles: inputs.plan_budget_cycles,
        budget_us: inputs.plan_budget_cycles / clock * 1e6,
    };
    let control = TaskTiming {
        observed_max_instructions: control_obs.max,
        observed_p50_instructions: control_obs.p50,
        observed_warm_max_instructions: None,
        observed_cold_max_instructions: None,
        statics: inputs.statics.control.clone(),
        budget_cycles: inputs.control_budget_cycles,
        budget_us: inputs.control_budget_cycles / clock * 1e6,
    };
    let run_entries: Vec<RunEntry> = runs.iter().map(run_entry).collect();
    let high_water = runs
        .iter()
        .map(|r| u64::from(r.pil.stack_high_water_bytes))
        .max()
        .unwrap_or(0);
    let stack_size = runs
        .iter()
        .map(|r| u64::from(r.pil.stack_size_bytes))
        .max()
        .unwrap_or(0);
    let memory = memory_report(&memory, &stack, high_water, stack_size);
    let plan_window = WindowTiming {
        observed_max_instructions: max_of(
            runs.iter()
                .flat_map(|r| r.plan.iter())
                .map(|a| a.window_instructions),
        )
        .unwrap_or(0.0),
        static_bound_cycles: inputs.statics.window_job_static_bound_cycles,
        budget_cycles: inputs.plan_budget_cycles,
        period_cycles: inputs.plan_period_cycles,
    };
    let tasks = Tasks {
        plan,
        control,
        plan_window,
    };
    let goals = goals(&tasks, &memory, &run_entries, &inputs.statics);
    Ok(WcetReport {
        clock_hz: inputs.clock_hz,
        // The function that sets it is read from the ELF by `build_report`.
        clock: super::clock::of_firmware(None),
        traced_cycles_per_instruction: cpi,
        traced_cpi_method: inputs.cpi.justification.clone(),
        tasks,
        interrupts: inputs.statics.interrupts.clone(),
        coverage: inputs.statics.coverage.clone(),
        memory,
        symbols,
        // Read from the ELF by `build_report`.
        caps: None,
        runs: run_entries,
        stack_high_water_bytes: high_water,
        goals,
        elf: inputs.elf.display().to_string(),
        stack,
    })
}

/// Observed instructions of a task over the runs.
struct Observed {
    max: f64,
    p50: f64,
    warm_max: Option<f64>,
    cold_max: Option<f64>,
}

fn max_of(values: impl Iterator<Item = f64>) -> Option<f64> {
    values.fold(None, |m, v| Some(m.map_or(v, |m: f64| m.max(v))))
}

/// Plan: the CSV rows of every run, and each summary's maximum (the larger wins).
fn plan_observed(runs: &[PilRun]) -> Result<Observed> {
    let rows = || runs.iter().flat_map(|r| r.plan.iter());
    let summary_max = max_of(runs.iter().map(|r| r.summary.plan_max_instructions));
    let csv_max = max_of(rows().map(|a| a.instructions));
    let Some(max) = max_of(summary_max.into_iter().chain(csv_max)) else {
        bail!("no PIL run given: make one with `{PIL_COMMAND}` and pass its folder");
    };
    let instructions: Vec<f64> = rows().map(|a| a.instructions).collect();
    let p50 = match crate::stats::median(&instructions) {
        Some(p) => p,
        None => max_of(runs.iter().map(|r| r.summary.plan_p50_instructions)).unwrap_or(0.0),
    };
    Ok(Observed {
        max,
        p50,
        warm_max: max_of(rows().filter(|a| a.plans_warm()).map(|a| a.instructions)),
        cold_max: max_of(rows().filter(|a| a.plans_cold()).map(|a| a.instructions)),
    })
}

/// Control: the larger of `summary.json` and `pil.json` of every run.
fn control_observed(runs: &[PilRun]) -> Observed {
    let max = max_of(runs.iter().flat_map(|r| {
        [
            r.summary.control_max_instructions,
            r.pil.control_max_instructions,
        ]
    }));
    Observed {
        max: max.unwrap_or(0.0),
        p50: max_of(runs.iter().map(|r| r.pil.control_p50_instructions)).unwrap_or(0.0),
        warm_max: None,
        cold_max: None,
    }
}

fn run_entry(run: &PilRun) -> RunEntry {
    let csv_misses = run.plan.iter().filter(|a| a.deadline_miss).count() as u64;
    RunEntry {
        dir: run.dir.display().to_string(),
        completed: run.summary.completed,
        plan_activations: run.summary.plan_activations.max(run.plan.len() as u64),
        plan_deadline_misses: run.summary.plan_deadline_misses.max(csv_misses),
        control_deadline_misses: run.summary.control_deadline_misses,
        plan_failures: run
            .plan
            .iter()
            .filter(|a| a.status != "optimal" && !a.window)
            .count() as u64,
        stack_high_water_bytes: u64::from(run.pil.stack_high_water_bytes),
        elf: run.pil.elf.clone(),
    }
}

/// One line per thing the stack analysis could not follow.
fn stack_misses(stack: &StackReport) -> Vec<String> {
    let mut misses = Vec::new();
    for call in &stack.indirect_calls {
        misses.push(format!(
            "indirect call in {}: {}",
            call.function, call.instruction
        ));
    }
    for call in &stack.unresolved_calls {
        misses.push(format!("call to a symbol not disassembled: {call}"));
    }
    for frame in &stack.unknown_frames {
        misses.push(format!(
            "frame not understood in {}: {}",
            frame.function, frame.reason
        ));
    }
    for cycle in &stack.cycles {
        misses.push(format!("recursion: {}", cycle.join(" -> ")));
    }
    for handler in &stack.unplaced_handlers {
        misses.push(format!("vector-table handler not placed: {handler}"));
    }
    if !stack.vector_table {
        misses.push(
            "no vector table read: handlers other than the given roots (HardFault, NMI) \
             are not in the bound"
                .to_string(),
        );
    }
    misses
}

fn memory_report(
    memory: &ElfMemory,
    stack: &StackReport,
    high_water: u64,
    stack_size: u64,
) -> MemoryReport {
    MemoryReport {
        sections: *memory,
        static_ram_bytes: memory.static_ram_bytes(),
        flash_bytes: memory.flash_bytes(),
        stack_bound_bytes: u64::from(stack.total_bytes),
        stack_method: format!("{} Bound: {}.", stack.method, stack.formula()),
        stack_sound: stack.sound,
        stack_misses: stack_misses(stack),
        stack_roots: stack.roots(),
        stack_high_water_bytes: high_water,
        stack_size_bytes: stack_size,
    }
}

#[cfg(test)]
mod tests {
    use super::elf::{elf_memory, elf_symbols};
    use super::expected::{bless, check_against_expected};
    use super::markdown::write_report;
    use super::pil_runs::{PilReport, Summary};
    use super::*;
    use crate::wcet::cpi::Figures;
    use crate::wcet::stack::{parse_objdump, stack_bound, Counted, PriorityLevel};

    use std::path::Path;

    fn levels(roots: &[&str]) -> Vec<PriorityLevel> {
        PriorityLevel::numbered(roots)
    }

    const HEADER: &str = "activation,release_us,finish_us,instructions,cycles,status,published,\
deadline_miss,passes,warm,qp_iterations,qp_added,qp_removed,qp_refactorizations,rows,\
active_constraints,max_validity_slack_rad";

    /// One plan activation of a fixture: instructions, passes, deadline miss, status.
    type Row = (f64, u32, bool, &'static str);

    /// Writes a PIL run folder `name` under `root` with these plan activations and
    /// control maximum; returns its path.
    fn write_run(
        root: &Path,
        name: &str,
        rows: &[Row],
        control_max: f64,
        high_water: u64,
    ) -> Result<PathBuf> {
        let dir = root.join(name);
        let mut csv = format!("{HEADER}\n");
        for (k, (instructions, passes, miss, status)) in rows.iter().enumerate() {
            csv += &format!(
                // One pass: a warm step; more: a cold start.
                "{k},{},{},{instructions},{},{status},true,{miss},{passes},{},12,3,1,0,40,5,0.01\n",
                k * 100_000,
                k * 100_000 + 5_000,
                instructions * 1.2,
                *passes == 1
            );
        }
        let misses = rows.iter().filter(|r| r.2).count();
        let max = rows.iter().map(|r| r.0).fold(0.0, f64::max);
        let summary = Summary {
            completed: true,
            plan_activations: rows.len() as u64,
            plan_deadline_misses: misses as u64,
            control_deadline_misses: 0,
            plan_max_instructions: max,
            plan_p50_instructions: 1.0,
            control_max_instructions: control_max - 10.0,
            ..Summary::default()
        };
        let pil = PilReport {
            icount_shift: 4,
            ns_per_instruction: 16.0,
            elf: "target/ecu".into(),
            stack_high_water_bytes: u32::try_from(high_water)?,
            stack_size_bytes: 43512,
            control_max_instructions: control_max,
            control_p50_instructions: control_max / 2.0,
            ..PilReport::default()
        };
        let (summary, pil) = (
            serde_json::to_string(&summary)?,
            serde_json::to_string(&pil)?,
        );
        let write = |file: &str, text: String| std::fs::write(dir.join(file), text);
        std::fs::create_dir_all(&dir)
            .and_then(|()| write("plan_activations.csv", csv))
            .and_then(|()| write("summary.json", summary))
            .and_then(|()| write("pil.json", pil))
            .with_context(|| format!("cannot write the fixture {}", dir.display()))?;
        Ok(dir)
    }

    fn cpi(bound: f64) -> CpiReport {
        CpiReport {
            total: Figures {
                instructions: 1000,
                worst_case_cycles: (1000.0 * bound) as u64,
                cpi_bound: bound,
                classes: Vec::new(),
            },
            idle: Figures {
                instructions: 0,
                worst_case_cycles: 0,
                cpi_bound: 0.0,
                classes: Vec::new(),
            },
            tb_executions: 10,
            translations: 2,
            untraced_executions: 0,
            abandoned_executions: 0,
            top_mnemonics: Vec::new(),
            unknown_mnemonics: Vec::new(),
            regions: Vec::new(),
            justification: "fixture CPI".into(),
        }
    }

    /// A stack report: `main` 16 B, handler 8 B + an indirect call.
    fn stack() -> Result<StackReport> {
        let text = "
08000000 <main>:
 8000000:      \tpush\t{r4, r5, r6, lr}
 8000002:      \tbx\tlr
08000010 <USART1>:
 8000010:      \tpush\t{r7, lr}
 8000012:      \tblx\tr2
";
        let levels = levels(&["main", "USART1"]);
        Ok(stack_bound(&parse_objdump(text), &levels)?)
    }

    fn memory() -> ElfMemory {
        ElfMemory {
            vector_table_bytes: 424,
            text_bytes: 100_000,
            rodata_bytes: 2_000,
            data_bytes: 40_000,
            bss_bytes: 2_000,
            uninit_bytes: 1_700,
        }
    }

    fn inputs(run_dirs: Vec<PathBuf>) -> ReportInputs {
        ReportInputs {
            run_dirs,
            elf: PathBuf::from("target/ecu"),
            stack_levels: EcuBuild::LockStep.priority_levels(),
            cpi: cpi(1.5),
            statics: StaticSummary {
                plan: StaticTiming {
                    static_bound_instructions: Some(4_000_000),
                    static_bound_cycles: Some(12_000_000),
                    job_static_bound_cycles: Some(6_000_000),
                    response_time_bound_us: Some(80_000.0),
                    deadline_us: Some(100_000.0),
                    traced_max_cycles: Some(3_000_000),
                    tightness: Some(4.0),
                    ..Default::default()
                },
                control: StaticTiming {
                    static_bound_instructions: Some(3000),
                    static_bound_cycles: Some(9000),
                    job_static_bound_cycles: Some(4500),
                    response_time_bound_us: None,
                    deadline_us: Some(10_000.0),
                    traced_max_cycles: None,
                    tightness: None,
                    ..Default::default()
                },
                ..Default::default()
            },
            plan_period_cycles: 16.8e6,
            plan_budget_cycles: 8.4e6,
            control_budget_cycles: 5000.0,
            clock_hz: 168_000_000,
        }
    }

    /// Two runs: warm activations up to 1.2e6, a cold one of 2.0e6 with a deadline
    /// miss; control maxima 1500 and 1800.
    fn fixture_report(root: &Path) -> Result<WcetReport> {
        fixture_report_with(root, stack()?)
    }

    /// [`fixture_report`] with this stack report.
    fn fixture_report_with(root: &Path, stack: StackReport) -> Result<WcetReport> {
        let a = write_run(
            root,
            "run-a",
            &[(1.0e6, 1, false, "optimal"), (1.2e6, 1, false, "optimal")],
            1500.0,
            9000,
        )?;
        let b = write_run(
            root,
            "run-b",
            &[
                (0.8e6, 1, false, "optimal"),
                (2.0e6, 3, true, "qp_iteration_limit"),
            ],
            1800.0,
            11620,
        )?;
        let inputs = inputs(vec![a.clone(), b.clone()]);
        let runs = [load_pil_run(&a)?, load_pil_run(&b)?];
        assemble_report(&inputs, &runs, memory(), ElfSymbols::default(), stack)
    }

    fn goal_of<'a>(r: &'a WcetReport, name: &str) -> Result<&'a Goal> {
        r.goals
            .iter()
            .find(|g| g.name == name)
            .with_context(|| format!("no goal `{name}` in {:?}", r.goals))
    }

    #[test]
    fn load_pil_run_reads_the_three_files() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let dir = write_run(
            tmp.path(),
            "run",
            &[(5.0, 1, false, "optimal"), (7.0, 2, true, "qp_infeasible")],
            99.0,
            1234,
        )?;
        let run = load_pil_run(&dir)?;
        assert_eq!(run.plan.len(), 2);
        assert_eq!(run.plan[1].instructions, 7.0);
        assert_eq!(run.plan[1].passes, 2);
        assert!(run.plan[1].deadline_miss);
        assert_eq!(run.plan[1].status, "qp_infeasible");
        assert_eq!(run.summary.plan_deadline_misses, 1);
        assert_eq!(run.pil.stack_high_water_bytes, 1234);
        assert_eq!(run.pil.control_max_instructions, 99.0);
        Ok(())
    }

    #[test]
    fn missing_file_names_it_and_the_command() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        for file in ["summary.json", "pil.json", "plan_activations.csv"] {
            let dir = write_run(tmp.path(), file, &[(5.0, 1, false, "optimal")], 9.0, 1)?;
            std::fs::remove_file(dir.join(file))?;
            let message = format!(
                "{:#}",
                load_pil_run(&dir)
                    .err()
                    .unwrap_or_else(|| anyhow::anyhow!(""))
            );
            assert!(message.contains(file), "{message}");
            assert!(message.contains("host-sim pil --out DIR"), "{message}");
        }
        Ok(())
    }

    #[test]
    fn bad_csv_row_and_missing_key_are_located() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let dir = write_run(
            tmp.path(),
            "run",
            &[(5.0, 1, false, "optimal"), (6.0, 1, false, "optimal")],
            9.0,
            1,
        )?;
        let path = dir.join("plan_activations.csv");
        let text = std::fs::read_to_string(&path)?;
        std::fs::write(
            &path,
            text.replace(",false,1,true,12,", ",maybe,1,true,12,"),
        )?;
        let message = format!(
            "{:#}",
            load_pil_run(&dir)
                .err()
                .unwrap_or_else(|| anyhow::anyhow!(""))
        );
        assert!(
            message.contains("line 2") && message.contains("deadline_miss"),
            "{message}"
        );

        std::fs::write(dir.join("summary.json"), r#"{"completed": true}"#)?;
        let message = format!(
            "{:#}",
            load_pil_run(&dir)
                .err()
                .unwrap_or_else(|| anyhow::anyhow!(""))
        );
        assert!(
            message.contains("summary.json") && message.contains("missing field"),
            "{message}"
        );
        Ok(())
    }

    #[test]
    fn report_from_fixtures_pins_the_numbers() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let r = fixture_report(tmp.path())?;
        let plan = &r.tasks.plan;
        assert_eq!(plan.observed_max_instructions, 2.0e6);
        assert_eq!(plan.observed_warm_max_instructions, Some(1.2e6));
        assert_eq!(plan.observed_cold_max_instructions, Some(2.0e6));
        // Median of 0.8, 1.0, 1.2, 2.0 (×1e6).
        assert_eq!(plan.observed_p50_instructions, 1.1e6);
        assert_eq!(plan.statics.job_static_bound_cycles, Some(6_000_000));
        assert!((plan.budget_us - 50_000.0).abs() < 1e-6);
        let control = &r.tasks.control;
        assert_eq!(control.observed_max_instructions, 1800.0);
        assert_eq!(control.statics.job_static_bound_cycles, Some(4500));
        assert!(control.observed_warm_max_instructions.is_none());
        assert_eq!(r.stack_high_water_bytes, 11620);
        assert_eq!(r.memory.static_ram_bytes, 42_000);
        assert_eq!(r.memory.flash_bytes, 142_424);
        // main 16 B; USART1 8 B + 108 B of exception entry; its blx is reported.
        assert_eq!(r.memory.stack_bound_bytes, 16 + 8 + 108);
        assert!(!r.memory.stack_sound);
        assert!(
            r.memory.stack_misses.iter().any(|m| m.contains("blx")),
            "{:?}",
            r.memory.stack_misses
        );
        assert_eq!(r.runs.len(), 2);
        assert_eq!(
            (r.runs[1].plan_deadline_misses, r.runs[1].plan_failures),
            (1, 1)
        );
        // The fixture's warm maximum, 1.2 M instructions, is over the 0.5 M goal.
        assert!(!goal_of(&r, "plan warm-start observed max")?.met);
        // The job's static bound (6 M) within the budget (8.4 M); 4 × the traced
        // maximum, over the 3 × goal; the control task's response time unbounded.
        assert!(goal_of(&r, "plan job static bound within budget")?.met);
        assert!(!goal_of(&r, "plan static bound over the traced maximum")?.met);
        assert!(goal_of(&r, "control job static bound within budget")?.met);
        assert!(goal_of(&r, "plan response time bound within the deadline")?.met);
        let control_r = goal_of(&r, "control response time bound within the deadline")?;
        assert_eq!((control_r.value, control_r.met), (None, false));
        assert!(goal_of(&r, "unbounded loops, unresolved calls, recursions")?.met);
        assert!(!goal_of(&r, "stack bound: what it does not cover")?.met);
        assert!(goal_of(&r, "control observed max")?.met);
        assert!(goal_of(&r, "static RAM")?.met);
        assert!(goal_of(&r, "stack bound")?.met);
        assert!(goal_of(&r, "flash")?.met);
        let misses = goal_of(&r, "deadline misses over the runs")?;
        assert_eq!((misses.value, misses.met), (Some(1.0), false));
        Ok(())
    }

    #[test]
    fn a_vector_table_handler_not_placed_is_a_stack_covered_gap() -> Result<()> {
        use crate::wcet::stack::stack_bound_vectors;
        use crate::wcet::vector_table::VectorEntry;
        // `main` 16 B, `USART1` 8 B, nothing indirect; Reset is `main`.
        let text = "
08000000 <main>:
 8000000:      \tpush\t{r4, r5, r6, lr}
 8000002:      \tbx\tlr
08000010 <USART1>:
 8000010:      \tpush\t{r7, lr}
 8000012:      \tbx\tlr
";
        let entry = |exception, address| VectorEntry { exception, address };
        let mut vectors = vec![entry(1, 0x0800_0000), entry(16, 0x0800_0010)];
        let p = parse_objdump(text);
        let covered = stack_bound_vectors(&p, &levels(&["main", "USART1"]), &[], &[], &vectors)?;
        // An entry into the middle of `USART1`: no function starts there.
        vectors.push(entry(21, 0x0800_0012));
        let gap = stack_bound_vectors(&p, &levels(&["main", "USART1"]), &[], &[], &vectors)?;
        let tmp = tempfile::tempdir()?;
        let r = fixture_report_with(tmp.path(), covered)?;
        let goal = goal_of(&r, "stack bound: what it does not cover")?;
        assert_eq!((goal.value, goal.met), (Some(0.0), true), "{:?}", r.memory);
        assert!(r.memory.stack_sound);
        let roots: Vec<(&str, &[String])> = r
            .memory
            .stack_roots
            .iter()
            .map(|root| (root.name.as_str(), root.exceptions.as_slice()))
            .collect();
        assert_eq!(
            roots,
            vec![
                ("main", &["Reset".to_string()][..]),
                ("USART1", &["IRQ 0".to_string()][..])
            ]
        );
        let r = fixture_report_with(tmp.path(), gap)?;
        let goal = goal_of(&r, "stack bound: what it does not cover")?;
        assert_eq!((goal.value, goal.met), (Some(1.0), false));
        assert!(!r.memory.stack_sound);
        assert!(
            r.memory.stack_misses[0].contains("IRQ 5"),
            "{:?}",
            r.memory.stack_misses
        );
        Ok(())
    }

    #[test]
    fn invalid_inputs_are_refused_with_the_field_name() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let dir = write_run(tmp.path(), "run", &[(5.0, 1, false, "optimal")], 9.0, 1)?;
        let runs = [load_pil_run(&dir)?];
        let mut bad = inputs(vec![dir]);
        bad.cpi = cpi(0.0);
        let err = assemble_report(&bad, &runs, memory(), ElfSymbols::default(), stack()?);
        let message = format!("{:#}", err.err().unwrap_or_else(|| anyhow::anyhow!("")));
        assert!(message.contains("cpi_bound"), "{message}");
        let mut budget = inputs(Vec::new());
        budget.plan_budget_cycles = f64::NAN;
        let err = assemble_report(&budget, &runs, memory(), ElfSymbols::default(), stack()?);
        let message = format!("{:#}", err.err().unwrap_or_else(|| anyhow::anyhow!("")));
        assert!(message.contains("plan_budget_cycles"), "{message}");
        let none = assemble_report(
            &inputs(Vec::new()),
            &[],
            memory(),
            ElfSymbols::default(),
            stack()?,
        );
        assert!(none.is_err());
        Ok(())
    }

    #[test]
    fn written_json_has_the_agreed_shape_and_markdown_the_verdicts() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let r = fixture_report(tmp.path())?;
        let out = tmp.path().join("out");
        write_report(&out, &r)?;
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("wcet.json"))?)?;
        assert_eq!(v["clock_hz"].as_u64(), Some(168_000_000));
        assert_eq!(v["clock"]["sysclk_hz"].as_u64(), Some(168_000_000));
        assert_eq!(
            v["clock"]["source"].as_str(),
            Some("HSE 25 MHz → PLL (M 25, N 336, P 2, Q 7)")
        );
        assert!(v["clock"]["configured_in"].is_null(), "no ELF read");
        assert_eq!(v["traced_cycles_per_instruction"].as_f64(), Some(1.5));
        assert_eq!(v["traced_cpi_method"].as_str(), Some("fixture CPI"));
        for task in ["plan", "control"] {
            for key in ["observed_max_instructions", "budget_cycles", "deadline_us"] {
                assert!(v["tasks"][task][key].is_f64(), "tasks.{task}.{key}");
            }
            for key in [
                "static_bound_instructions",
                "static_bound_cycles",
                "job_static_bound_cycles",
            ] {
                assert!(v["tasks"][task][key].is_u64(), "tasks.{task}.{key}");
            }
            for key in ["response_time_bound_us", "tightness"] {
                assert!(
                    v["tasks"][task].get(key).is_some(),
                    "tasks.{task}.{key} (a number or null)"
                );
            }
        }
        assert!(v["tasks"]["plan"]["tightness"].is_f64());
        assert!(v["tasks"]["control"]["response_time_bound_us"].is_null());
        for key in [
            "loops",
            "unresolved_indirect_calls",
            "recursions",
            "flow_facts",
            "untraced_loops",
            "jobs_traced",
        ] {
            assert!(v[key].is_array(), "{key}");
        }
        assert_eq!(v["unbounded_loops"].as_u64(), Some(0));
        assert!(v["memory"]["stack_sound"].is_boolean());
        for key in [
            "text_bytes",
            "rodata_bytes",
            "data_bytes",
            "bss_bytes",
            "static_ram_bytes",
            "stack_bound_bytes",
            "flash_bytes",
        ] {
            assert!(v["memory"][key].is_u64(), "memory.{key}");
        }
        assert!(v["memory"]["stack_method"].is_string());
        let roots = v["memory"]["stack_roots"].as_array().map(Vec::as_slice);
        let first = roots.and_then(<[_]>::first);
        assert_eq!(
            first.map(|r| (&r["name"], &r["counted"], &r["depth_bytes"])),
            Some((
                &serde_json::json!("main"),
                &serde_json::json!("priority_level"),
                &serde_json::json!(16)
            )),
            "{roots:?}"
        );
        assert_eq!(v["symbols"]["allocator"].as_bool(), Some(false));
        assert_eq!(v["symbols"]["soft_double"].as_bool(), Some(false));
        assert_eq!(v["runs"].as_array().map(Vec::len), Some(2));
        assert_eq!(v["goals"].as_array().map(Vec::len), Some(18));
        assert!(v["goals"][0]["met"].is_boolean());
        let md = std::fs::read_to_string(out.join("wcet.md"))?;
        assert!(
            md.contains(
                "| deadline misses over the runs | 1 | 0 misses | **MISSED** by 1 misses |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| flash | 142424 | 262144 bytes | met, 119720 bytes to spare (-45.7 %) |"),
            "{md}"
        );
        assert!(md.contains("run-b") && md.contains("fixture CPI") && md.contains("blx"));
        Ok(())
    }

    #[test]
    fn the_expected_values_read_the_reports_own_fields() -> Result<()> {
        let tmp = tempfile::tempdir()?;
        let mut r = fixture_report(tmp.path())?;
        // The fixture's static analysis bounds no window adoption.
        r.tasks.plan_window.static_bound_cycles = Some(7_000_000);
        let blessed = bless(&r, None, 0.05, None).map_err(anyhow::Error::msg)?;
        let file: serde_json::Value = serde_json::from_str(&blessed)?;
        let value = |key: &str| {
            file["quantities"]
                .as_array()
                .and_then(|q| q.iter().find(|e| e["key"] == key))
                .and_then(|e| e["value"].as_i64())
        };
        assert_eq!(value("memory.text_bytes"), Some(100_000));
        assert_eq!(value("memory.flash_bytes"), Some(142_424));
        assert_eq!(value("memory.stack_bound_bytes"), Some(132));
        assert_eq!(
            value("tasks.plan.observed_warm_max_instructions"),
            Some(1_200_000)
        );
        assert_eq!(
            value("tasks.control.observed_max_instructions"),
            Some(1_800)
        );
        assert_eq!(value("tasks.plan.job_static_bound_cycles"), Some(6_000_000));
        assert_eq!(
            value("tasks.plan_window.static_bound_cycles"),
            Some(7_000_000)
        );
        assert_eq!(value("symbols.soft_double"), Some(0));
        let check = |r: &WcetReport| check_against_expected(r, &blessed, 0.05);
        assert!(check(&r).map_err(anyhow::Error::msg)?.is_empty());
        // A byte more of stack: the file no longer describes the report.
        r.memory.stack_bound_bytes += 1;
        let m = check(&r).map_err(anyhow::Error::msg)?;
        assert!(
            m.regressions.is_empty() && m.stale.len() == 1 && m.stale[0].contains("stack bound"),
            "{m:?}"
        );
        Ok(())
    }

    /// The real ECU ELF (`cargo ecu-lockstep`); fails when it has not been built. The
    /// `real_ecu_elf_*` tests that read it are ignored by `cargo test`; `.ci/run`
    /// runs them after `cargo ecu-lockstep` (`cargo test -p host-sim --lib -- --ignored
    /// real_ecu_elf`).
    fn real_elf() -> PathBuf {
        let path = crate::pil::built_ecu_elf(&Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
        assert!(
            path.is_file(),
            "the ECU binary {} is missing: build it first (cargo ecu-lockstep)",
            path.display()
        );
        path
    }

    #[test]
    #[ignore = "needs the ECU binary: cargo ecu-lockstep"]
    fn real_ecu_elf_memory_and_symbols() -> Result<()> {
        let elf = real_elf();
        let m = elf_memory(&elf)?;
        eprintln!(
            "{m:?} static RAM {} flash {}",
            m.static_ram_bytes(),
            m.flash_bytes()
        );
        assert!(m.vector_table_bytes > 0 && m.text_bytes > 0);
        // memory.x copies the read-only data to SRAM with .data: none stays in flash.
        assert_eq!(m.rodata_bytes, 0, "{m:?}");
        assert!(m.data_bytes > 0 && m.bss_bytes > m.uninit_bytes);
        assert_eq!(
            m.flash_bytes(),
            m.vector_table_bytes + m.text_bytes + m.rodata_bytes + m.data_bytes
        );
        let s = elf_symbols(&elf)?;
        assert!(!s.allocator, "allocator linked: {:?}", s.allocator_symbols);
        assert!(
            !s.soft_double,
            "soft double linked: {:?}",
            s.soft_double_symbols
        );
        // The caps the binary says it was built with are the firmware's.
        let caps = super::elf::elf_caps(&elf)?
            .ok_or_else(|| anyhow::anyhow!("the ECU binary has no .ecu_caps section"))?;
        assert_eq!(
            caps,
            super::elf::Caps {
                qp_max_iterations: firmware::mpc::QP_MAX_ITER,
                cold_start_passes: u32::from(firmware::mpc::COLD_START_PASSES),
                qp_max_refactorizations: firmware::mpc::QP_MAX_REFACTORIZATIONS,
                working_set: firmware::mpc::WS as u32,
            }
        );
        Ok(())
    }

    #[test]
    fn caps_are_four_little_endian_words_and_any_other_length_is_refused() -> Result<()> {
        let mut bytes = Vec::new();
        for w in [67u32, 1, 1, 48] {
            bytes.extend_from_slice(&w.to_le_bytes());
        }
        let c = super::elf::caps_of(&bytes)?;
        assert_eq!(
            (
                c.qp_max_iterations,
                c.cold_start_passes,
                c.qp_max_refactorizations,
                c.working_set
            ),
            (67, 1, 1, 48)
        );
        let short = super::elf::caps_of(&bytes[..12]);
        assert!(
            short
                .as_ref()
                .is_err_and(|e| e.to_string().contains("12 bytes")),
            "{short:?}"
        );
        Ok(())
    }

    #[test]
    #[ignore = "needs the ECU binary: cargo ecu-lockstep"]
    fn real_ecu_elf_stack_bound_covers_every_vector_table_handler() -> Result<()> {
        use crate::wcet::stack::{disassemble, parse_objdump, Counted, EXCEPTION_ENTRY_BYTES};
        let elf = real_elf();
        let stack = crate::wcet::stack::analyse_elf_once(
            &elf,
            &EcuBuild::LockStep.priority_levels(),
            &ecu_once(),
            &EcuBuild::LockStep.masked(),
            &crate::wcet::indirect::targets_of_elf(&elf)?,
        )?;
        for level in &stack.levels {
            let root = level.roots.iter().max_by_key(|r| r.depth_bytes);
            eprintln!(
                "{} ({}): {} B = {:?}",
                level.name,
                level.counted.label(),
                level.contribution_bytes,
                root.map(|r| r
                    .worst_path
                    .iter()
                    .map(|e| format!("{} {}", e.function, e.frame_bytes))
                    .collect::<Vec<_>>())
            );
        }
        eprintln!(
            "{}; sound {}, misses {:#?}",
            stack.formula(),
            stack.sound,
            stack_misses(&stack)
        );
        // Every entry of the vector table is one root's, once.
        let roots = stack.roots();
        let mut listed: Vec<&str> = roots
            .iter()
            .flat_map(|r| r.exceptions.iter().map(String::as_str))
            .collect();
        listed.sort_unstable();
        let mut entries: Vec<String> = crate::wcet::vector_table::read_vector_table(&elf)?
            .iter()
            .map(|e| e.name())
            .collect();
        entries.sort_unstable();
        assert_eq!(listed, entries);
        assert!(stack.vector_table && stack.unplaced_handlers.is_empty());
        // The tasks' interrupts are their levels' roots, not the default handler:
        // the dispatchers USART1 (IRQ 37) and USART2 (IRQ 38), and SysTick.
        for (level, entry) in [(1, "IRQ 37"), (2, "IRQ 38"), (3, "SysTick")] {
            let root = &stack.levels[level].roots[0];
            assert_eq!(root.exceptions, [entry], "{}", stack.levels[level].name);
            assert_ne!(root.function, crate::wcet::stack::DEFAULT_HANDLER);
        }
        // HardFault and NMI on top, with their exception frames, each through the
        // application's handler (the vector's target itself) to the safe stop's
        // guard; the guard's work is counted once.
        let fault = |name: &str| {
            stack
                .levels
                .iter()
                .find(|l| l.counted == Counted::FaultOnTop && l.roots[0].root == name)
                .with_context(|| format!("no {name} level: {:?}", stack.levels))
        };
        let path = |level: &crate::wcet::stack::LevelReport| -> Vec<String> {
            level.roots[0]
                .worst_path
                .iter()
                .map(|e| e.function.clone())
                .collect()
        };
        let hard_fault = fault("HardFault")?;
        assert_eq!(path(hard_fault), ["HardFault", "ecu::safe_stop"]);
        assert_eq!(
            hard_fault.contribution_bytes,
            hard_fault.roots[0].depth_bytes + EXCEPTION_ENTRY_BYTES
        );
        let nmi = fault("NMI")?;
        assert_eq!(path(nmi), ["NonMaskableInt", "ecu::safe_stop"]);
        let sum = |counted: Counted| -> u32 {
            stack
                .levels
                .iter()
                .filter(|l| l.counted == counted)
                .map(|l| l.contribution_bytes)
                .sum()
        };
        assert!(
            stack.total_bytes
                >= sum(Counted::PriorityLevel)
                    + sum(Counted::Once)
                    + hard_fault.contribution_bytes
                    + nmi.contribution_bytes
        );
        // Counting the work once holds only if nothing but the guard calls it.
        let program = parse_objdump(&disassemble(&elf)?);
        let once = ecu_once();
        let callers: Vec<String> = program
            .functions
            .iter()
            .filter(|f| {
                f.calls
                    .iter()
                    .any(|c| once.contains(&crate::wcet::demangle(&c.target)))
            })
            .map(|f| crate::wcet::demangle(&f.name))
            .collect();
        assert_eq!(callers, ["ecu::safe_stop"], "callers of {once:?}");
        Ok(())
    }

    #[test]
    #[ignore = "needs the ECU binary: cargo ecu-lockstep"]
    fn real_ecu_elf_full_report_through_build_report() -> Result<()> {
        let elf = real_elf();
        let tmp = tempfile::tempdir()?;
        let run = write_run(
            tmp.path(),
            "run",
            &[(1.0e6, 1, false, "optimal"), (1.6e6, 2, false, "optimal")],
            1500.0,
            9000,
        )?;
        let mut inputs = inputs(vec![run]);
        inputs.elf = elf.clone();
        let r = build_report(&inputs)?;
        assert_eq!(r.memory.sections.text_bytes, elf_memory(&elf)?.text_bytes);
        assert_eq!(
            r.clock.configured_in.as_deref(),
            Some("firmware::clock_tree::configure")
        );
        // Four priority levels, the unbound interrupts, the safe stop's work
        // counted once, HardFault and NMI.
        let levels: Vec<(Counted, &str)> = r
            .stack
            .levels
            .iter()
            .map(|l| (l.counted, l.roots[0].root.as_str()))
            .collect();
        let level = Counted::PriorityLevel;
        assert_eq!(
            levels,
            [
                (level, "main"),
                (level, "USART1"),
                (level, "USART2"),
                (level, "SysTick"),
                (Counted::UnboundOnTop, "DefaultHandler"),
                (Counted::Once, "ecu::safe_stop_work"),
                (Counted::FaultOnTop, "HardFault"),
                (Counted::FaultOnTop, "NMI"),
            ]
        );
        assert_eq!(r.memory.stack_bound_bytes, u64::from(r.stack.total_bytes));
        assert_eq!(r.memory.stack_roots, r.stack.roots());
        assert!(r.memory.stack_method.contains("SysTick"));
        assert!(r
            .memory
            .stack_method
            .contains("HardFault (on top of everything)"));
        write_report(tmp.path(), &r)?;
        let md = std::fs::read_to_string(tmp.path().join("wcet.md"))?;
        assert!(md.contains("firmware::mpc::Mpc<T>::"), "{md}");
        eprintln!("{md}");
        Ok(())
    }
}
