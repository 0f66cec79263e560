//! The static worst-case timing analysis of an ELF against its target
//! description, put together: control-flow graphs ([`super::cfg`]), natural
//! loops ([`super::loops`]), loop bounds recognised from the binary
//! ([`super::bounds`]), source locations from the DWARF line table, and the IPET
//! bound of each task ([`super::ipet`]) when every loop it reaches is bounded.
//! Written as `static.json` and `static.md` beside the timing report.
//!
//! What it refuses, it says: a loop without a bound, an irreducible cycle (two
//! entries, no header to bound), an indirect call no rule resolves, a recursion.
//! A task with any of these gets no bound, and the reasons are listed.

use super::cfg::Function;
use super::cfg::{self, FlashData, MemoryModel, Program};
pub use super::copies::copy_size_register;
use super::copies::copy_sizes;
use super::ipet::{self, Cost, LoopFact, Per};
use super::loops::{self, reverse_post_order, Loop};
use super::source_lines::SourceLines;
use super::target::Target;
use super::{annotations, bounds, demangle};
use crate::WcetError;

/// The analysis's results, or why there is none.
type Result<T> = std::result::Result<T, WcetError>;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How many of a task bound's largest functions the report lists.
const TOP_FUNCTIONS: usize = 25;

/// Whether a loop is a load-exclusive/store-exclusive retry (an atomic
/// read-modify-write): it retries only when the exclusive monitor was cleared,
/// which on a single Cortex-M core an exception entry or return does.
fn is_exclusive_retry(f: &Function, l: &Loop) -> bool {
    let has = |prefix: &str| {
        l.blocks.iter().any(|&b| {
            f.blocks.get(b).is_some_and(|blk| {
                f.instructions[blk.first..blk.end]
                    .iter()
                    .any(|i| i.base().starts_with(prefix))
            })
        })
    };
    // The back edge is taken on the store's failure: the latch holds the store.
    let latch_stores = l.back_edges.first().is_some_and(|&(t, _)| {
        f.blocks.get(t).is_some_and(|blk| {
            f.instructions[blk.first..blk.end]
                .iter()
                .any(|i| i.base().starts_with("strex"))
        })
    });
    !l.irreducible && l.back_edges.len() == 1 && has("ldrex") && latch_stores
}

/// A loop of the binary reachable from a task.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoopEntry {
    /// Tasks that reach it.
    pub tasks: Vec<String>,
    /// Function holding the loop (demangled).
    pub function: String,
    /// Address of the loop's header.
    pub header: String,
    /// Source file of its latch (the innermost frame of the firmware's own code
    /// when there is one).
    pub file: String,
    /// Source line.
    pub line: u32,
    /// Most back edges per entry, if known.
    pub bound: Option<u64>,
    /// Where the bound comes from: `binary` for a recognised counted loop, else
    /// the annotation (`file:line: expression`).
    pub source: Option<String>,
    /// Why the binary's shape was not recognised (for a loop without a bound).
    pub why_unbounded: Option<String>,
    /// An irreducible cycle (several entries), bounded by its edges into them.
    pub irreducible: bool,
    /// Largest back edges per entry seen in a QEMU trace (`null` until checked).
    pub observed_max: Option<u64>,
}

/// One kind of extra work of a task's heavier activations
/// ([`super::target::ExtraWork`]), as the response-time analysis charges it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LightExtra {
    /// What it is.
    pub what: String,
    /// The unit it comes in.
    pub unit: String,
    /// The bounds a unit's cost is the largest step of, cycles: without the
    /// work, with one unit and with an activation's whole, first with the other
    /// kinds left out, then with them whole (`[[b0, b1, bmax], [b0, b1, bmax]]`).
    pub bounds: [[u64; 3]; 2],
    /// The charge: cycles a unit, units per activation and per window.
    #[serde(flatten)]
    pub charge: super::rta::Extra,
}

/// One task's static figures (`Default`: a task of no function, nothing
/// bounded or observed).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TaskStatic {
    /// Task name.
    pub name: String,
    /// Its handler symbol.
    pub root: String,
    /// Functions reachable from it.
    pub functions: usize,
    /// Loops reachable from it.
    pub loops: usize,
    /// Of those, with a bound.
    pub bounded_loops: usize,
    /// Loops in functions that never return (the panic, fault and `exit` paths,
    /// which end the activation with the actuators safe): not part of a
    /// completing activation, not counted above.
    pub excluded_loops: usize,
    /// Irreducible cycles (function: blocks' addresses).
    pub irreducible: Vec<String>,
    /// The IPET bound in instructions, when the analysis could give one.
    pub static_bound_instructions: Option<u64>,
    /// The IPET bound in worst-case cycles of the memory model.
    pub static_bound_cycles: Option<u64>,
    /// How the cycle bound's program was solved: `integer` (the mixed-integer
    /// optimum) or `relaxation` (the branch and bound stopped at its node cap: the
    /// largest open relaxation, at or above the integer optimum: sound, possibly
    /// pessimistic); none without a bound.
    pub optimum: Option<String>,
    /// Why there is no bound.
    pub refused: Option<String>,
    /// The bound's top contributors (function, cycles).
    pub top_functions: Vec<(String, f64)>,
    /// The same functions' entries (calls) on that path.
    pub top_functions_entries: Vec<(String, f64)>,
    /// The bound's costliest blocks (in cycles), with their source lines.
    pub top_blocks: Vec<TopBlock>,
    /// Activations of the task seen in the traces.
    pub observed_activations: u64,
    /// Largest traced activation, instructions (its executed blocks' counts).
    pub observed_max_instructions: Option<u64>,
    /// Largest traced activation with the same block cycle costs as the bound.
    pub observed_max_cycles: Option<u64>,
    /// `static_bound_cycles / observed_max_cycles`.
    pub tightness: Option<f64>,
    /// The budget the ECU's deadline monitor holds the task's own work to, cycles.
    pub budget_cycles: Option<u64>,
    /// Response-time bound (`wcet::rta`): the static bound, blocking and the
    /// higher priorities' interference; `None` when a bound is missing or the
    /// iteration passed the deadline.
    pub response_time_bound_us: Option<f64>,
    /// When the response-time bound passes the deadline: the fixed point past it
    /// (how far it misses), µs; `None` otherwise.
    pub response_time_past_deadline_us: Option<f64>,
    /// Deadline (= period) of a task, µs; `None` for a section.
    pub deadline_us: Option<f64>,
    /// A task whose activations are not all alike
    /// ([`super::target::LightActivations`]): the bound of those without the
    /// extra work, cycles (`None`: every activation charged the static bound).
    pub light_bound_cycles: Option<u64>,
    /// The extra work those activations leave out, each kind as the
    /// response-time analysis charges it.
    pub light_extras: Vec<LightExtra>,
    /// The work within a window as long as its deadline (`wcet::rta`): its own,
    /// then each higher priority's; empty for a section or without a bound.
    pub demand_at_deadline: Vec<super::rta::Demand>,
}

/// The whole static analysis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StaticAnalysis {
    /// The ELF analysed.
    pub elf: String,
    /// Which build of the target it is (its tasks and schedule):
    /// [`Target::id`].
    pub build: &'static str,
    /// Its name in the reports ([`Target::name`]).
    #[serde(skip)]
    pub build_name: &'static str,
    /// The core clock, Hz ([`Target::clock_hz`]).
    #[serde(skip)]
    pub clock_hz: u32,
    /// The core clock as the binary sets it (frequency, source, the function).
    pub clock: super::target::ClockReport,
    /// The interrupts of the schedule (SysTick, the flashed build's link): what
    /// the response-time analysis charges every lower priority for them.
    pub interrupts: Vec<InterruptEntry>,
    /// The processor and memory model the cycles assume.
    pub assumptions: Vec<String>,
    /// Per task.
    pub tasks: Vec<TaskStatic>,
    /// Every loop reachable from a task.
    pub loops: Vec<LoopEntry>,
    /// Loops reachable from a task without a bound.
    pub unbounded_loops: usize,
    /// Indirect calls and jumps no rule resolves, and jumps to no function.
    pub unresolved_indirect_calls: Vec<String>,
    /// Cycles of the call graph reachable from a task.
    pub recursions: Vec<Vec<String>>,
    /// QEMU traces the loop bounds were checked against.
    pub traces: Vec<String>,
    /// Loop bounds a trace exceeded, and traced activations above their task's
    /// bound: each an error of the analysis (a wrong annotation or recogniser).
    pub violations: Vec<String>,
    /// The bounds over more than one loop entry (per activation, per call, the
    /// counters, the capped lines, the retries), each checked on the traces.
    pub flow_facts: Vec<super::flow_facts::FlowFact>,
    /// The loops the traces executed, and why each other one was not (`None`
    /// without traces).
    pub coverage: Option<super::coverage::Coverage>,
    /// The tasks' critical sections (interrupts disabled, RTIC locks) with their
    /// bounds: what blocks a higher priority in the response-time analysis.
    pub critical_sections: Vec<super::critical::CriticalSection>,
    /// The functions indirect calls and jumps may reach, read from the binary:
    /// each with where its address is.
    pub indirect_targets: Vec<super::indirect::Taken>,
    /// The indirect transfers the traces took (each checked against its site's
    /// targets): `(site, function, target, times)`.
    pub indirect_calls_traced: Vec<(String, String, String, u64)>,
}

/// An interrupt of the schedule, as the response-time analysis takes it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct InterruptEntry {
    /// Its name in the schedule (`systick`, `link`).
    pub name: String,
    /// Its handler, the vector table's symbol (`SysTick`, `USART1`).
    pub handler: String,
    /// RTIC logical priority (higher preempts).
    pub priority: u8,
    /// Static bound of one entry, model cycles (`null`: not bounded).
    pub static_bound_cycles: Option<u64>,
    /// Minimum inter-arrival time of its entries, µs: the timer's period, or
    /// for the link the line's spacing (two entries a byte's time).
    pub min_interarrival_us: f64,
    /// Entries that may come together besides those the inter-arrival time
    /// spaces.
    pub at_once: u64,
    /// At most this many entries per budget window (the link's budget renewed
    /// by the control task), `null` without such a cap.
    pub per_window: Option<u64>,
    /// That window, µs.
    pub window_us: Option<f64>,
    /// And at most this many more per second budget's window (the link's budget
    /// renewed by the plan task, and a plan event's bytes), `null` without one.
    pub per_slow_window: Option<u64>,
    /// That window, µs.
    pub slow_window_us: Option<f64>,
    /// Response-time bound of one entry, µs (`null`: none within its deadline).
    pub response_time_bound_us: Option<f64>,
    /// Its deadline, µs (the link's: a byte's time, after which the next byte
    /// overruns it).
    pub deadline_us: f64,
}

/// The interrupts of the target's schedule with the bounds `tasks` found for them.
pub fn interrupts_of(build: &Target, tasks: &[TaskStatic]) -> Vec<InterruptEntry> {
    build
        .schedule()
        .into_iter()
        .filter(|s| build.interrupts().contains(&s.name))
        .map(|s| {
            let task = tasks.iter().find(|t| t.name == s.name);
            let handler = build
                .tasks()
                .iter()
                .find(|(n, _)| *n == s.name)
                .map_or("", |(_, h)| *h);
            InterruptEntry {
                name: s.name.to_string(),
                handler: handler.to_string(),
                priority: s.priority,
                static_bound_cycles: task.and_then(|t| t.static_bound_cycles),
                min_interarrival_us: s.period_us,
                at_once: s.burst.map_or(0, |b| b.at_once),
                per_window: s.burst.map(|b| b.per_window),
                window_us: s.burst.map(|b| b.window_us),
                per_slow_window: s.burst.and_then(|b| b.slow).map(|w| w.per_window),
                slow_window_us: s.burst.and_then(|b| b.slow).map(|w| w.window_us),
                response_time_bound_us: task.and_then(|t| t.response_time_bound_us),
                deadline_us: s.deadline_us,
            }
        })
        .collect()
}

/// One of the blocks that cost a task's bound the most.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopBlock {
    /// The block's function (demangled).
    pub function: String,
    /// Its first instruction's address.
    pub address: u32,
    /// Its source file (from the workspace on) and line: the innermost frame in
    /// the firmware's own sources.
    pub file: String,
    /// Line in `file`.
    pub line: u32,
    /// Its count on the worst path.
    pub count: f64,
    /// Model cycles per execution.
    pub cycles: u64,
}

/// Runs the analysis on `elf`, the program `build` describes, with the loop
/// annotations of `sources` (the target's source folders, under its
/// [`Target::source_labels`]).
///
/// The phases, in order: load the program, find its loops, read and index the
/// annotations, bound every loop, derive the flow facts, bound each task and
/// section (IPET), bound the critical sections and the response times, then
/// check every bound against the QEMU `traces` and measure their coverage.
pub fn analyse(
    elf: &Path,
    build: &Target,
    sources: &[annotations::SourceDir],
    traces: &[PathBuf],
) -> Result<StaticAnalysis> {
    let binary = Binary::load(elf, build)?;
    let (all_loops, irreducible) = find_loops(&binary.program);
    let (annotations, dependency_facts) = read_annotations(build, sources)?;
    let index = AnnotationIndex::new(&annotations, &dependency_facts)?;
    let copies = copy_sizes(
        build,
        &binary.program,
        &binary.ctx,
        &annotations,
        &index.counter_groups,
    );
    check_activation_caps(&annotations, &copies)?;
    let bounds = LoopBinder::new(&binary, &index, &copies, build).bind_all(&all_loops)?;
    let retries = retries_per_activation(build, &annotations);
    let mut flow_facts = super::flow_facts::flow_facts(
        &binary.program,
        &all_loops,
        &bounds.facts,
        &copies,
        &annotations,
        &bounds.origin,
        &retries,
    );
    let model = Model {
        program: &binary.program,
        memory: &binary.memory,
        ctx: &binary.ctx,
        all_loops: &all_loops,
        facts: &bounds.facts,
        copies: &copies,
        build,
    };
    let mut units = Units::default();
    units.bound_all(elf, &model, &irreducible, &bounds, &retries)?;
    bound_light_activations(
        &mut units,
        &binary,
        &all_loops,
        sources,
        build,
        &BTreeMap::new(),
    )?;
    let (critical_sections, task_reach) = bound_critical_sections(&model, &retries);
    bound_response_times(&model, &mut units.tasks, &critical_sections, &task_reach);
    // Once more with each retry loop's preemptions counted within the task's
    // response-time bound rather than its deadline: an activation that completes
    // within that bound is preempted only there, so the bounds computed with
    // these fewer retries hold, and so does the response time they give (it is
    // at most the first). A task without a bound within its deadline keeps its
    // deadline's count. The critical sections keep the first pass's bounds.
    let windows: BTreeMap<String, f64> = units
        .tasks
        .iter()
        .filter_map(|t| Some((t.name.clone(), t.response_time_bound_us?)))
        .collect();
    let refined = retries_within(build, &annotations, &windows);
    if refined != retries {
        let mut tighter = Units::default();
        tighter.bound_all(elf, &model, &irreducible, &bounds, &refined)?;
        bound_light_activations(&mut tighter, &binary, &all_loops, sources, build, &windows)?;
        bound_response_times(&model, &mut tighter.tasks, &critical_sections, &task_reach);
        units = tighter;
    }
    let mut observed = Observed::default();
    TraceReplay::new(elf, &model, &flow_facts)?.check_all(
        traces,
        &mut units,
        &mut flow_facts,
        &mut observed,
    )?;
    observed
        .violations
        .extend(check_tightness(&mut units.tasks));
    let coverage =
        (!traces.is_empty()).then(|| loop_coverage(&model, &units.loop_rows, &observed.blocks_run));
    let Units {
        loop_rows,
        tasks,
        unresolved,
        recursions,
    } = units;
    let loops: Vec<LoopEntry> = loop_rows.into_values().collect();
    Ok(StaticAnalysis {
        build: build.id,
        build_name: build.name,
        clock_hz: build.clock_hz,
        clock: build.clock.clone(),
        interrupts: interrupts_of(build, &tasks),
        traces: traces.iter().map(|t| t.display().to_string()).collect(),
        violations: observed.violations,
        flow_facts,
        coverage,
        critical_sections,
        indirect_targets: binary.taken.into_values().flatten().collect(),
        indirect_calls_traced: observed.indirect_calls_traced,
        elf: elf.display().to_string(),
        assumptions: binary.memory.assumptions(),
        unbounded_loops: loops.iter().filter(|l| l.bound.is_none()).count(),
        tasks,
        loops,
        unresolved_indirect_calls: unresolved,
        recursions,
    })
}

/// The light activations' bounds of the build's tasks ([`light_bound`]), with
/// the retries counted within `windows`, into `units`, and the cost of a unit of
/// each kind of extra work: the largest step of the task's bound as that work's
/// constants go from none to one unit, and from none to an activation's whole
/// (per unit), with the other kinds left out and with them whole. The bound is
/// an IPET's optimum, in which a loop's cap is a constant of the constraints:
/// as a maximum over a polytope, it is concave in that constant, so its first
/// step is the largest (the IPET's integer optimum taken to be its relaxation's,
/// as the flow graph's constraints make it); the average step covers a bound
/// that grows faster instead. Either way each unit costs at most the larger.
fn bound_light_activations(
    units: &mut Units,
    binary: &Binary,
    all_loops: &[Vec<Loop>],
    sources: &[annotations::SourceDir],
    build: &Target,
    windows: &BTreeMap<String, f64>,
) -> Result<()> {
    let full = build.constants.clone();
    for light in build.light_activations() {
        let Some(task_bound) = units
            .tasks
            .iter()
            .find(|t| t.name == light.task)
            .and_then(|t| t.static_bound_cycles)
        else {
            continue;
        };
        let mut memo: BTreeMap<Vec<(&'static str, u64)>, Option<u64>> = BTreeMap::new();
        let mut bound = |amounts: &[u64]| -> Result<Option<u64>> {
            let constants: Vec<(&'static str, u64)> = light
                .extras
                .iter()
                .zip(amounts)
                .flat_map(|(e, &u)| e.constants_at(u, &full))
                .collect();
            if let Some(&c) = memo.get(&constants) {
                return Ok(c);
            }
            let c = light_bound(
                binary, all_loops, sources, build, light.task, &constants, windows,
            )?;
            memo.insert(constants, c);
            Ok(c)
        };
        let none = vec![0; light.extras.len()];
        let Some(light_cycles) = bound(&none)? else {
            continue;
        };
        let mut extras = Vec::new();
        for (k, extra) in light.extras.iter().enumerate() {
            let mut steps = [[0u64; 3]; 2];
            let mut unit_cycles = 0.0_f64;
            for (others_whole, row) in [false, true].into_iter().zip(steps.iter_mut()) {
                let at = |u: u64| -> Vec<u64> {
                    light
                        .extras
                        .iter()
                        .enumerate()
                        .map(|(j, e)| {
                            if j == k {
                                u
                            } else if others_whole {
                                e.per_activation
                            } else {
                                0
                            }
                        })
                        .collect()
                };
                let (Some(b0), Some(b1), Some(bmax)) = (
                    bound(&at(0))?,
                    bound(&at(1))?,
                    bound(&at(extra.per_activation))?,
                ) else {
                    return Err(WcetError::Analysis(format!(
                        "`{}`: no bound with part of {} (its light bound is {light_cycles})",
                        light.task, extra.what
                    )));
                };
                *row = [b0, b1, bmax];
                let first = b1.saturating_sub(b0) as f64;
                let average = bmax.saturating_sub(b0) as f64 / extra.per_activation.max(1) as f64;
                unit_cycles = unit_cycles.max(first).max(average);
            }
            extras.push(LightExtra {
                what: extra.what.to_string(),
                unit: extra.unit.to_string(),
                bounds: steps,
                charge: extra.charge(unit_cycles),
            });
        }
        if let Some(t) = units.tasks.iter_mut().find(|t| t.name == light.task) {
            t.light_bound_cycles = Some(light_cycles.min(task_bound));
            t.light_extras = extras;
        }
    }
    Ok(())
}

/// The bound of `task` with the annotations evaluated under the tighter
/// `constants`: the loop bounds and the IPET again. `None` when the task has no
/// bound.
fn light_bound(
    binary: &Binary,
    all_loops: &[Vec<Loop>],
    sources: &[annotations::SourceDir],
    build: &Target,
    task: &str,
    constants: &[(&'static str, u64)],
    windows: &BTreeMap<String, f64>,
) -> Result<Option<u64>> {
    let mut values = build.constants.clone();
    for &(name, value) in constants {
        if values.insert(name, value).is_none() {
            return Err(WcetError::Analysis(format!(
                "the light activations of `{task}` bind `{name}`, which is not one of the target's constants"
            )));
        }
    }
    let annotations = annotations::scan_sources_with(sources, &values)
        .map_err(|e| WcetError::Annotation(format!("loop annotations: {e}")))?;
    let dependency_facts = (build.dependency_facts)(&values);
    let index = AnnotationIndex::new(&annotations, &dependency_facts)?;
    let copies = copy_sizes(
        build,
        &binary.program,
        &binary.ctx,
        &annotations,
        &index.counter_groups,
    );
    let bounds = LoopBinder::new(binary, &index, &copies, build).bind_all(all_loops)?;
    let retries = retries_within(build, &annotations, windows);
    let model = Model {
        program: &binary.program,
        memory: &binary.memory,
        ctx: &binary.ctx,
        all_loops,
        facts: &bounds.facts,
        copies: &copies,
        build,
    };
    let Some(&(_, symbol)) = build.tasks().iter().find(|(n, _)| *n == task) else {
        return Err(WcetError::Analysis(format!(
            "no task `{task}` in the {} build",
            build.name()
        )));
    };
    let Some(&root) = binary.program.find(symbol).first() else {
        return Err(WcetError::Analysis(format!(
            "no function `{symbol}` (task `{task}`)"
        )));
    };
    let preemptions = retries
        .iter()
        .find(|(t, _)| t == task)
        .map_or_else(ipet::Retries::default, |r| r.1);
    Ok(ipet_figures(&model, root, preemptions).cycles)
}

/// The ECU program as the analysis reads it from the ELF: its functions' graphs,
/// the memory model its cycles assume, the functions whose address it takes and
/// its DWARF line table.
struct Binary {
    /// The functions' control-flow graphs.
    program: Program,
    /// The target's memory model, with the flash data this binary reads.
    memory: MemoryModel,
    /// The functions indirect calls and jumps may reach, by function.
    taken: BTreeMap<usize, Vec<super::indirect::Taken>>,
    /// The DWARF line table, for the source lines of addresses.
    ctx: SourceLines,
}

impl Binary {
    /// Loads the program: disassembles `elf`, classifies its flash data, finds the
    /// targets of its indirect calls and builds the control-flow graphs.
    fn load(elf: &Path, target: &Target) -> Result<Self> {
        let text = super::stack::disassemble_with_bytes(elf)?;
        let raw = cfg::parse_disassembly(&text);
        let data = super::read_elf(elf)?;
        let file = super::parse_elf(elf, &data)?;
        let memory = MemoryModel {
            flash_data: FlashData::classify(&file, &raw, target.memory.flash, demangle),
            ..target.memory.clone()
        };
        // Indirect calls and jumps may reach every function whose address the binary
        // holds or builds (its data sections, literal pools, movw/movt pairs).
        let taken = super::indirect::address_taken(&raw, &super::indirect::data_sections(&file));
        let program: Program = cfg::build_program(
            &raw,
            &super::indirect::targets(&raw, &taken, demangle),
            &memory,
            demangle,
        )?;
        let ctx = SourceLines::new(elf, &target.source_labels)?;
        Ok(Self {
            program,
            memory,
            taken,
            ctx,
        })
    }
}

/// Finds every function's natural loops; a function with an irreducible cycle
/// gets none, and its cycle's blocks are returned by function instead (a cycle
/// with two entries has no header to bound).
fn find_loops(program: &Program) -> (Vec<Vec<Loop>>, BTreeMap<usize, Vec<usize>>) {
    let mut all_loops: Vec<Vec<Loop>> = Vec::with_capacity(program.functions.len());
    let mut irreducible: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (k, f) in program.functions.iter().enumerate() {
        match loops::natural_loops(f) {
            Ok(l) => all_loops.push(l),
            Err(e) => {
                if let WcetError::Irreducible(blocks) = e {
                    irreducible.insert(k, blocks);
                }
                all_loops.push(Vec::new());
            }
        }
    }
    (all_loops, irreducible)
}

/// Reads the loop annotations of the firmware's `sources`, and the facts stated
/// about the dependencies' code (which the firmware's sources cannot carry).
fn read_annotations(
    build: &Target,
    sources: &[annotations::SourceDir],
) -> Result<(Vec<annotations::Annotation>, Vec<annotations::Annotation>)> {
    let annotations = annotations::scan_sources_with(sources, &build.constants).map_err(|e| {
        let dirs: Vec<String> = sources
            .iter()
            .map(|s| s.dir.display().to_string())
            .collect();
        WcetError::Annotation(format!("loop annotations in {}: {e}", dirs.join(", ")))
    })?;
    Ok((annotations, (build.dependency_facts)(&build.constants)))
}

/// The loop annotations indexed by the source line they bound, the way the loop
/// bounding looks them up.
struct AnnotationIndex<'a> {
    /// The annotations of a line (the firmware's and the dependencies'), except
    /// those of one caller's copy and those that bound no loop (`bytes`, loop
    /// entries, runs).
    by_line: BTreeMap<(String, u32), &'a annotations::Annotation>,
    /// `// wcet-bound in NAME:`: for the copies of a line inlined into `NAME`.
    within_line: BTreeMap<(String, u32, String), &'a annotations::Annotation>,
    /// The counters of the `per activation` annotations, each with its group.
    counter_groups: BTreeMap<String, usize>,
}

impl<'a> AnnotationIndex<'a> {
    /// Indexes the firmware's `annotations` and the `dependency_facts`; refuses
    /// counters grouped inconsistently.
    fn new(
        annotations: &'a [annotations::Annotation],
        dependency_facts: &'a [annotations::Annotation],
    ) -> Result<Self> {
        // Bounds: recognised from the binary, else the source's annotation at the
        // loop's line (DWARF), never the one an enclosing loop took.
        let by_line = annotations
            .iter()
            .chain(dependency_facts.iter())
            .filter(|a| {
                !matches!(
                    a.scope,
                    annotations::Scope::Bytes
                        | annotations::Scope::LoopEntry
                        | annotations::Scope::Runs
                )
            })
            .filter(|a| a.within.is_none())
            .map(|a| ((a.file.clone(), a.line), a))
            .collect();
        let within_line = annotations
            .iter()
            .filter_map(|a| Some(((a.file.clone(), a.line, a.within.clone()?), a)))
            .collect();
        let counter_groups = annotations::counter_groups(annotations)
            .map_err(|e| WcetError::Annotation(format!("loop annotations: {e}")))?;
        Ok(Self {
            by_line,
            within_line,
            counter_groups,
        })
    }

    /// The annotation of a line for the function named `fname` (its last path
    /// segment): its own copy's, else the line's.
    fn annotation_of(
        &self,
        key: &(String, u32),
        fname: &str,
    ) -> Option<&'a annotations::Annotation> {
        self.within_line
            .get(&(key.0.clone(), key.1, fname.to_string()))
            .or_else(|| self.by_line.get(key))
            .copied()
    }
}

/// Refuses a cap per activation that matches no call: it is stale (the code
/// moved or was inlined away), and the bound it was meant to give would be
/// missing.
fn check_activation_caps(
    annotations: &[annotations::Annotation],
    copies: &ipet::CopySizes,
) -> Result<()> {
    for (k, a) in annotations.iter().enumerate() {
        if a.scope == annotations::Scope::Runs
            && !copies.caps.iter().any(|c| c.activation_group == Some(k))
        {
            return Err(WcetError::Analysis(format!(
                "{}:{}: `// wcet-bound: {} times per activation` matches no call the tasks make: \
                 put it on the line of the call it caps (a function that is not inlined)",
                a.file, a.line, a.expression
            )));
        }
    }
    Ok(())
}

/// Every loop's bound, where it comes from, or why it has none.
#[derive(Default)]
struct LoopBounds {
    /// The bounds found, for the IPET.
    facts: Vec<LoopFact>,
    /// Per `(function, loop)`, where its bound comes from.
    origin: BTreeMap<(usize, usize), String>,
    /// Per `(function, loop)` without a bound, why.
    notes: BTreeMap<(usize, usize), String>,
    /// Per `(function, loop)`, its source line (for the report).
    source_line: BTreeMap<(usize, usize), (String, u32)>,
}

/// Bounds the loops of the program, one function at a time: from the block
/// copies' call sites, the exclusive retries, the binary's counted loops, else
/// the annotations of the loops' source lines.
struct LoopBinder<'a> {
    program: &'a Program,
    ctx: &'a SourceLines,
    index: &'a AnnotationIndex<'a>,
    copies: &'a ipet::CopySizes,
    /// The build: its tasks' handlers are named by their tasks.
    build: &'a Target,
    /// The annotations of one caller's copy some loop took.
    within_used: std::collections::BTreeSet<(String, u32, String)>,
    /// What was found so far.
    out: LoopBounds,
}

/// The state of bounding one function's loops.
struct FunctionLoops<'a> {
    /// The function's index.
    k: usize,
    func: &'a Function,
    /// What `wcet-bound in NAME:` names it by: its task's name for a task's
    /// handler, else its name's last path segment.
    fname: String,
    /// Its loops.
    ls: &'a [Loop],
    /// Per loop, the annotated line it took.
    matched: Vec<Option<(String, u32)>>,
    /// Per loop, whether it is a dependency's code ([`is_library_loop`]).
    library_loops: Vec<bool>,
    /// The lines a firmware loop of the function took.
    firmware_taken: std::collections::BTreeSet<(String, u32)>,
}

impl<'a> LoopBinder<'a> {
    fn new(
        binary: &'a Binary,
        index: &'a AnnotationIndex<'a>,
        copies: &'a ipet::CopySizes,
        build: &'a Target,
    ) -> Self {
        Self {
            program: &binary.program,
            ctx: &binary.ctx,
            index,
            copies,
            build,
            within_used: Default::default(),
            out: LoopBounds::default(),
        }
    }

    /// Bounds every loop of `all_loops` (per function); refuses an annotation of
    /// one caller's copy that no loop took.
    fn bind_all(mut self, all_loops: &'a [Vec<Loop>]) -> Result<LoopBounds> {
        for (k, ls) in all_loops.iter().enumerate() {
            self.bind_function(k, ls);
        }
        // An annotation for one caller's copy that no loop took is stale: the function
        // was renamed, or the line is no longer inlined there.
        if let Some((file, line, w)) = self
            .index
            .within_line
            .keys()
            .find(|key| !self.within_used.contains(*key))
        {
            return Err(WcetError::Analysis(format!(
                "{file}:{line}: `{}{w}:` matches no loop of a function named `{w}` \
                 (or of the handler of the task `{w}`): the function was renamed or \
                 the line is no longer inlined into it",
                annotations::WITHIN_MARKER
            )));
        }
        Ok(self.out)
    }

    /// Bounds the loops `ls` of function `k`, outer loops first.
    fn bind_function(&mut self, k: usize, ls: &'a [Loop]) {
        let func = &self.program.functions[k];
        // A task's handler (the interrupt RTIC runs it in, which differs between
        // the builds) by its task's name; any other function by its last path
        // segment.
        let fname = self
            .build
            .tasks()
            .iter()
            .find(|(_, handler)| func.demangled == *handler || func.name == *handler)
            .map_or_else(
                || {
                    func.demangled
                        .rsplit("::")
                        .next()
                        .unwrap_or(&func.demangled)
                        .to_string()
                },
                |(task, _)| task.to_string(),
            );
        // Outer loops first: an inner loop does not take an annotation one of its
        // enclosing loops took (the compiler may put both back edges on one line);
        // it takes the next of its lines that has one, or none.
        // The firmware's loops before the dependencies' (a library loop inlined
        // into a firmware line takes the line's annotation only if no firmware loop
        // of the function took it: it is the line's own loop's otherwise; a library
        // loop nests no firmware loop, so every parent still comes first).
        let library_loops: Vec<bool> = ls
            .iter()
            .map(|l| is_library_loop(func, l, self.ctx))
            .collect();
        let mut fl = FunctionLoops {
            k,
            func,
            fname,
            ls,
            matched: vec![None; ls.len()],
            library_loops,
            firmware_taken: Default::default(),
        };
        let mut order: Vec<usize> = (0..ls.len()).collect();
        order.sort_by_key(|&x| (fl.library_loops[x], loops::depth(ls, x)));
        for x in order {
            self.bind_loop(&mut fl, x);
        }
    }

    /// Records loop `x` of function `k`'s bound and where it comes from.
    fn record(&mut self, k: usize, x: usize, fact: LoopFact, origin: String) {
        self.out.facts.push(fact);
        self.out.origin.insert((k, x), origin);
    }

    /// Bounds loop `x` of `fl`'s function, or notes why it cannot.
    fn bind_loop(&mut self, fl: &mut FunctionLoops<'a>, x: usize) {
        let (k, func, ls) = (fl.k, fl.func, fl.ls);
        let l = &ls[x];
        // The loop's telling instructions, and their lines (innermost frame in
        // the firmware's sources): for the annotation and for the report.
        let candidates = candidate_addresses(func, l);
        let keys: Vec<(String, u32)> = candidates
            .iter()
            .map(|&a| {
                let (file, line) = self.ctx.location(a);
                (self.ctx.short_path(&file), line)
            })
            .collect();
        if let Some(key) = keys.iter().find(|(_, line)| *line > 0) {
            self.out.source_line.insert((k, x), key.clone());
        }
        let mut taken: Vec<(String, u32)> = Vec::new();
        let mut p = l.parent;
        while let Some(q) = p {
            taken.extend(fl.matched[q].iter().cloned());
            p = ls[q].parent;
        }
        if self.copies.family.contains(&k) {
            self.bind_copy_loop(k, x);
            return;
        }
        if is_exclusive_retry(func, l) {
            self.record(
                k,
                x,
                LoopFact {
                    function: k,
                    loop_index: x,
                    bound: 1,
                    per: Per::Preemption,
                    group: None,
                    iterations: false,
                },
                "load/store-exclusive retry: 1 per preemption (an exception clears the monitor)"
                    .into(),
            );
            return;
        }
        if !l.irreducible {
            if let Some(b) = bounds::constant_bound(func, l) {
                self.record(
                    k,
                    x,
                    LoopFact {
                        function: k,
                        loop_index: x,
                        bound: b,
                        per: Per::Entry,
                        group: None,
                        iterations: false,
                    },
                    "binary".into(),
                );
                return;
            }
        }
        let hit = self.annotated_line(fl, x, &keys, &candidates, &taken);
        let same_loop = hit
            .as_ref()
            .and_then(|key| self.index.annotation_of(key, &fl.fname))
            .is_some_and(|a| a.scope == annotations::Scope::SameLoop);
        let Some(key) = hit.clone().filter(|_| !same_loop) else {
            if same_loop {
                self.share_enclosing_bound(fl, x, hit);
            } else {
                self.note_unbounded(fl, x, &keys, &candidates, &taken);
            }
            return;
        };
        fl.matched[x] = Some(key.clone());
        let Some(a) = self.index.annotation_of(&key, &fl.fname) else {
            return;
        };
        self.bind_annotated(fl, x, &key, &candidates, a);
    }

    /// A block copy or fill: one back edge per byte, the bytes at its call sites
    /// (the IPET's copy constraint); per entry, the largest.
    fn bind_copy_loop(&mut self, k: usize, x: usize) {
        let sizes: Vec<Option<u64>> = self.copies.sites.iter().map(|c| c.bytes).collect();
        match sizes.iter().copied().collect::<Option<Vec<u64>>>() {
            Some(v) => {
                let most = v.into_iter().max().unwrap_or(0);
                let origin = format!(
                    "block copy: one back edge per byte, Σ bytes over its {} call sites (the largest {most})",
                    self.copies.sites.len()
                );
                self.record(
                    k,
                    x,
                    LoopFact {
                        function: k,
                        loop_index: x,
                        bound: most,
                        per: Per::Entry,
                        group: None,
                        iterations: false,
                    },
                    origin,
                );
            }
            None => {
                let unknown: Vec<&str> = self
                    .copies
                    .sites
                    .iter()
                    .filter(|c| c.bytes.is_none())
                    .map(|c| c.at.as_str())
                    .collect();
                self.out.notes.insert(
                    (k, x),
                    format!(
                        "block copy: sizes unknown at {} (annotate `// wcet-bound: EXPR bytes`)",
                        unknown.join(", ")
                    ),
                );
            }
        }
    }

    /// The annotated line loop `x` takes, if any: the first of its `keys` with an
    /// annotation no enclosing loop `taken`, else a dependency's fact at any
    /// frame of its candidates' inlining chains. A dependency's loop takes no
    /// line a firmware loop of the function took; a firmware loop marks its line
    /// taken.
    fn annotated_line(
        &self,
        fl: &mut FunctionLoops<'a>,
        x: usize,
        keys: &[(String, u32)],
        candidates: &[u32],
        taken: &[(String, u32)],
    ) -> Option<(String, u32)> {
        let library = fl.library_loops[x];
        let annotated = |key: &(String, u32)| self.index.annotation_of(key, &fl.fname).is_some();
        // Read off the line table only if no key of its own is free.
        let chain = candidates
            .iter()
            .flat_map(|&a| self.ctx.frames(a))
            .map(|(file, line)| (self.ctx.short_path(&file), line));
        let (key, own_line) =
            choose_line(library, keys, chain, &fl.firmware_taken, taken, annotated)?;
        if own_line && !library {
            fl.firmware_taken.insert(key.clone());
        }
        Some(key)
    }

    /// Notes why loop `x`, neither recognised nor annotated, has no bound.
    fn note_unbounded(
        &mut self,
        fl: &FunctionLoops<'a>,
        x: usize,
        keys: &[(String, u32)],
        candidates: &[u32],
        taken: &[(String, u32)],
    ) {
        let library = fl.library_loops[x];
        let shares = keys.iter().any(|key| taken.contains(key));
        let own: Vec<String> = keys
            .iter()
            .filter(|k| k.1 > 0 && !taken.contains(*k))
            .map(|(f, l)| format!("{f}:{l}"))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let note = if library {
            let inner = candidates
                .first()
                .and_then(|&a| self.ctx.frames(a).into_iter().next())
                .map(|(f, l)| format!("{}:{l}", self.ctx.short_path(&f)))
                .unwrap_or_default();
            format!(
                "a loop of a dependency's code ({inner}) inlined into a firmware line whose \
                 annotation bounds a loop of the firmware's: state its bound as a dependency \
                 fact about its own line (the target's dependency facts, Target::dependency_facts), or \
                 annotate a line of its own"
            )
        } else if shares {
            format!(
                "its only annotated line is its enclosing loop's: if the compiler split that \
                 source loop into these nested binary loops, write `// wcet-bound: same loop` \
                 on one of its own lines ({}), else annotate it there",
                own.join(", ")
            )
        } else {
            bounds::why_not(fl.func, &fl.ls[x])
        };
        self.out.notes.insert((fl.k, x), note);
    }

    /// `same loop` (annotated at `hit`): one source loop the compiler split into
    /// nested binary loops (a `continue` path). It shares the bound of the
    /// nearest enclosing loop that has one: their back edges together, against
    /// that loop's entries.
    fn share_enclosing_bound(
        &mut self,
        fl: &mut FunctionLoops<'a>,
        x: usize,
        hit: Option<(String, u32)>,
    ) {
        let (k, func, ls) = (fl.k, fl.func, fl.ls);
        let facts = &self.out.facts;
        let mut q = ls[x].parent;
        while let Some(p) = q {
            if facts.iter().any(|f| f.function == k && f.loop_index == p) {
                break;
            }
            q = ls[p].parent;
        }
        let host = q.and_then(|p| {
            facts
                .iter()
                .find(|f| f.function == k && f.loop_index == p)
                .cloned()
                .map(|f| (p, f))
        });
        let Some((p, hf)) = host else {
            self.out.notes.insert(
                (k, x),
                "`same loop`, but no enclosing binary loop has a bound to share: \
                 the loop is not nested in the one it was split from"
                    .into(),
            );
            return;
        };
        let rep = hf.group.unwrap_or(p);
        let origin = format!(
            "{}:{}: `same loop`: shares the bound of the loop at {:#x}: {}",
            hit.as_ref().map_or("?", |h| h.0.as_str()),
            hit.as_ref().map_or(0, |h| h.1),
            func.blocks.get(ls[rep].header).map_or(0, |b| b.start),
            self.out.origin.get(&(k, rep)).cloned().unwrap_or_default()
        );
        fl.matched[x] = hit;
        self.record(
            k,
            x,
            LoopFact {
                function: k,
                loop_index: x,
                group: Some(rep),
                ..hf
            },
            origin,
        );
    }

    /// Bounds loop `x` by the annotation `a` of its line `key`, unless it is a
    /// bound `per call` in code inlined into a caller (then it notes why not).
    fn bind_annotated(
        &mut self,
        fl: &FunctionLoops<'a>,
        x: usize,
        key: &(String, u32),
        candidates: &[u32],
        a: &annotations::Annotation,
    ) {
        let k = fl.k;
        if let Some(w) = &a.within {
            self.within_used.insert((a.file.clone(), a.line, w.clone()));
        }
        // Per call of the function that holds the loop: for an annotation of
        // one caller's copy, that function is the caller named (this one).
        if a.scope == annotations::Scope::Call && a.within.is_none() {
            // Per call of the function that holds the loop: sound only if the
            // binary function is that function, not a caller it was inlined into.
            let inlined = candidates.iter().any(|&addr| {
                let fr = self.ctx.frames(addr);
                fr.iter()
                    .position(|(file, line)| (self.ctx.short_path(file), *line) == *key)
                    .is_some_and(|at| at + 1 < fr.len())
            });
            if inlined {
                self.out.notes.insert(
                    (k, x),
                    format!(
                        "{}:{}: a bound `per call` in code inlined into `{}`: mark its function #[inline(never)]",
                        a.file, a.line, fl.func.demangled
                    ),
                );
                return;
            }
        }
        let fact = annotation_fact(a, &self.index.counter_groups, k, x);
        self.record(k, x, fact, annotation_origin(a));
    }
}

/// The loop fact annotation `a` states for loop `x` of function `k`.
fn annotation_fact(
    a: &annotations::Annotation,
    counter_groups: &BTreeMap<String, usize>,
    k: usize,
    x: usize,
) -> LoopFact {
    LoopFact {
        function: k,
        loop_index: x,
        bound: a.bound,
        per: match a.scope {
            // (`bytes` annotations are not in `by_line`.)
            annotations::Scope::Entry
            | annotations::Scope::Bytes
            | annotations::Scope::LoopEntry
            | annotations::Scope::Runs
            | annotations::Scope::SameLoop => Per::Entry,
            annotations::Scope::Call => Per::Call,
            annotations::Scope::Activation => {
                match a.counter.as_deref().and_then(|c| counter_groups.get(c)) {
                    Some(&g) => Per::Counted(g),
                    None => Per::Activation,
                }
            }
            annotations::Scope::Preemption => Per::Preemption,
            annotations::Scope::Tick => Per::Tick,
        },
        group: None,
        iterations: matches!(
            a.scope,
            annotations::Scope::Entry | annotations::Scope::Call | annotations::Scope::Activation
        ),
    }
}

/// Where a bound from annotation `a` comes from, for the report.
fn annotation_origin(a: &annotations::Annotation) -> String {
    format!(
        "{}:{}: `{}`{}{}{}",
        a.file,
        a.line,
        a.expression,
        a.within
            .as_ref()
            .map(|w| format!(" (its copy in `{w}`)"))
            .unwrap_or_default(),
        match a.scope {
            annotations::Scope::Activation => " per activation",
            annotations::Scope::Preemption => " per preemption",
            annotations::Scope::Tick => " per tick",
            annotations::Scope::Call => " per call",
            annotations::Scope::Entry
            | annotations::Scope::Bytes
            | annotations::Scope::LoopEntry
            | annotations::Scope::Runs
            | annotations::Scope::SameLoop => "",
        },
        a.counter
            .as_ref()
            .map(|c| format!(", counted in {c}"))
            .unwrap_or_default()
    )
}

/// Retries per activation: each preemption can make the exclusive retry loop
/// it interrupts retry once and each `per preemption` annotation's loop retry
/// its bound's times; each preemption by the monotonic's tick can in addition
/// make each `per tick` annotation's loop retry its bound's times (one exception
/// can do all). Returns, per task, the retries per activation: the caps the
/// retry loops' back edges share, by cause.
fn retries_per_activation(
    build: &Target,
    annotations: &[annotations::Annotation],
) -> Vec<(String, ipet::Retries)> {
    retries_within(build, annotations, &BTreeMap::new())
}

/// [`retries_per_activation`] with the preemptions counted within a window of
/// each task's release: its response-time bound where `windows` has one, else
/// its deadline.
fn retries_within(
    build: &Target,
    annotations: &[annotations::Annotation],
    windows: &BTreeMap<String, f64>,
) -> Vec<(String, ipet::Retries)> {
    let sum = |scope| {
        annotations
            .iter()
            .filter(|a| a.scope == scope)
            .map(|a| a.bound)
            .sum::<u64>()
    };
    let per_preemption = 1 + sum(annotations::Scope::Preemption);
    let per_tick = sum(annotations::Scope::Tick);
    build
        .tasks()
        .iter()
        .map(|(n, _)| {
            let window = windows.get(*n).copied();
            (
                n.to_string(),
                ipet::Retries {
                    preemption: build.preemptions_within(n, window) * per_preemption,
                    tick: build.ticks_within(n, window) * per_tick,
                },
            )
        })
        .collect()
}

/// The bounded program the later phases read.
struct Model<'a> {
    program: &'a Program,
    memory: &'a MemoryModel,
    ctx: &'a SourceLines,
    all_loops: &'a [Vec<Loop>],
    facts: &'a [LoopFact],
    copies: &'a ipet::CopySizes,
    /// Which build of the application the ELF is: its tasks and schedule.
    build: &'a Target,
}

/// The tasks' and sections' static figures, and what the loops and calls they
/// reach show.
#[derive(Default)]
struct Units {
    /// Every loop a task or section reaches, by `(function, loop)`.
    loop_rows: BTreeMap<(usize, usize), LoopEntry>,
    /// Per task and section.
    tasks: Vec<TaskStatic>,
    /// Indirect calls and jumps no rule resolves.
    unresolved: Vec<String>,
    /// Cycles of the call graph.
    recursions: Vec<Vec<String>>,
}

/// What a task's reachable functions hold: its loops, counted.
struct LoopCount {
    loops: usize,
    bounded: usize,
    excluded: usize,
    /// Irreducible cycles (function: blocks' addresses).
    irreducible: Vec<String>,
}

/// A task's IPET bounds (instructions, then cycles with the costliest
/// functions and blocks), or why there is none.
#[derive(Default)]
struct IpetFigures {
    instructions: Option<u64>,
    cycles: Option<u64>,
    optimum: Option<String>,
    top: Vec<(String, f64)>,
    top_entries: Vec<(String, f64)>,
    top_blocks: Vec<TopBlock>,
    refused: Vec<String>,
}

impl Units {
    /// Bounds every task and section of the target (each its root's
    /// completing activation); refuses a root the ELF lacks.
    fn bound_all(
        &mut self,
        elf: &Path,
        model: &Model<'_>,
        irreducible: &BTreeMap<usize, Vec<usize>>,
        bounds: &LoopBounds,
        retries: &[(String, ipet::Retries)],
    ) -> Result<()> {
        let build = model.build;
        let units: Vec<(&str, &str, &str, Option<u64>)> = build
            .tasks()
            .iter()
            .map(|&(n, sym)| (n, sym, n, None))
            .chain(build.sections().iter().copied())
            .collect();
        for (name, symbol, owner, budget) in units {
            let roots = model.program.find(symbol);
            let Some(&root) = roots.first() else {
                return Err(WcetError::Analysis(format!(
                    "no function `{symbol}` (task `{name}`) in {}: is it the program the target describes?",
                    elf.display()
                )));
            };
            // What a completing activation can run: the stop and fault paths excluded.
            let reach = model.program.completing_reachable(&[root]);
            let count = self.survey(model, irreducible, bounds, name, &reach);
            let recs = model.program.recursions(&[root]);
            for r in &recs {
                if !self.recursions.contains(r) {
                    self.recursions.push(r.clone());
                }
            }
            let mut refused: Vec<String> = Vec::new();
            if !count.irreducible.is_empty() {
                refused.push(format!("{} irreducible cycle(s)", count.irreducible.len()));
            }
            let preemptions = retries
                .iter()
                .find(|(t, _)| t == owner)
                .map_or_else(ipet::Retries::default, |r| r.1);
            let figures = if count.irreducible.is_empty() {
                ipet_figures(model, root, preemptions)
            } else {
                IpetFigures::default()
            };
            refused.extend(figures.refused);
            self.tasks.push(TaskStatic {
                name: name.to_string(),
                root: symbol.to_string(),
                functions: reach.len(),
                loops: count.loops,
                bounded_loops: count.bounded,
                excluded_loops: count.excluded,
                irreducible: count.irreducible,
                static_bound_instructions: figures.instructions,
                static_bound_cycles: figures.cycles,
                optimum: figures.optimum,
                refused: (!refused.is_empty()).then(|| refused.join("; ")),
                top_functions: figures.top,
                top_functions_entries: figures.top_entries,
                top_blocks: figures.top_blocks,
                observed_activations: 0,
                observed_max_instructions: None,
                observed_max_cycles: None,
                tightness: None,
                budget_cycles: budget,
                response_time_bound_us: None,
                response_time_past_deadline_us: None,
                deadline_us: build
                    .schedule()
                    .iter()
                    .find(|t| t.name == name)
                    .map(|t| t.deadline_us),
                light_bound_cycles: None,
                light_extras: Vec::new(),
                demand_at_deadline: Vec::new(),
            });
        }
        Ok(())
    }

    /// Surveys the functions task `name` reaches (`reach`): collects their
    /// unresolved indirect transfers and irreducible cycles, counts their loops
    /// (those on paths that end the activation excluded) and adds each counted
    /// loop to the loop rows.
    fn survey(
        &mut self,
        model: &Model<'_>,
        irreducible: &BTreeMap<usize, Vec<usize>>,
        bounds: &LoopBounds,
        name: &str,
        reach: &[usize],
    ) -> LoopCount {
        let mut n_loops = 0;
        let mut n_bounded = 0;
        let mut n_excluded = 0;
        let mut irr = Vec::new();
        for &f in reach {
            let func = &model.program.functions[f];
            let live = reverse_post_order(func);
            for &b in &live {
                for p in &func.blocks[b].problems {
                    if !self.unresolved.contains(p) {
                        self.unresolved.push(p.clone());
                    }
                }
            }
            if let Some(blocks) = irreducible.get(&f) {
                irr.push(format!(
                    "{}: {} blocks from {:#x}",
                    func.demangled,
                    blocks.len(),
                    blocks
                        .first()
                        .and_then(|&b| func.blocks.get(b))
                        .map_or(0, |b| b.start)
                ));
            }
            if !func.returns {
                // Panic, fault and exit paths end the activation: excluded.
                n_excluded += model.all_loops[f].len();
                continue;
            }
            let live = func.completing();
            for (x, l) in model.all_loops[f].iter().enumerate() {
                if !live.get(l.header).copied().unwrap_or(false) {
                    // On a path that ends the activation: excluded.
                    n_excluded += 1;
                    continue;
                }
                n_loops += 1;
                let fact = model
                    .facts
                    .iter()
                    .find(|q| q.function == f && q.loop_index == x);
                if fact.is_some() {
                    n_bounded += 1;
                }
                let row = self.loop_rows.entry((f, x)).or_insert_with(|| {
                    let (file, line) = bounds
                        .source_line
                        .get(&(f, x))
                        .cloned()
                        .unwrap_or_else(|| ("?".into(), 0));
                    LoopEntry {
                        tasks: Vec::new(),
                        function: func.demangled.clone(),
                        header: format!("{:#x}", func.blocks.get(l.header).map_or(0, |b| b.start)),
                        file,
                        line,
                        bound: fact.map(|q| q.bound),
                        source: bounds.origin.get(&(f, x)).cloned(),
                        why_unbounded: bounds.notes.get(&(f, x)).cloned(),
                        irreducible: l.irreducible,
                        observed_max: None,
                    }
                });
                row.tasks.push(name.to_string());
            }
        }
        LoopCount {
            loops: n_loops,
            bounded: n_bounded,
            excluded: n_excluded,
            irreducible: irr,
        }
    }
}

/// The IPET bounds of the activation entered at `root` with `preemptions`
/// retries: in instructions, then (when that one exists) in cycles with the
/// costliest functions and blocks.
fn ipet_figures(model: &Model<'_>, root: usize, retries: ipet::Retries) -> IpetFigures {
    let mut out = IpetFigures::default();
    let bound = |cost| {
        ipet::task_bound(
            model.program,
            model.all_loops,
            root,
            model.facts,
            retries,
            model.copies,
            cost,
        )
    };
    match bound(Cost::Instructions) {
        Ok(b) => out.instructions = Some(b.bound),
        Err(e) => out.refused.push(match e {
            WcetError::Ipet(ipet::IpetError::Unbounded(l)) => {
                format!("{} loop(s) without a bound", l.len())
            }
            other => other.to_string(),
        }),
    }
    if out.instructions.is_none() {
        return out;
    }
    match bound(Cost::Cycles) {
        Ok(b) => {
            out.cycles = Some(b.bound);
            out.optimum = Some(b.optimum.to_string());
            out.top = b.by_function.into_iter().take(TOP_FUNCTIONS).collect();
            out.top_entries = b
                .entries_by_function
                .into_iter()
                .take(TOP_FUNCTIONS)
                .collect();
            out.top_blocks = b
                .by_block
                .into_iter()
                .map(|x| {
                    let (file, line) = model.ctx.location(x.address);
                    TopBlock {
                        function: x.function,
                        address: x.address,
                        file: model.ctx.short_path(&file),
                        line,
                        count: x.count,
                        cycles: x.cost,
                    }
                })
                .collect();
        }
        Err(e) => out.refused.push(e.to_string()),
    }
    out
}

/// The tasks' critical sections (interrupts disabled, RTIC locks), each with
/// its bound: the blocking of the response-time analysis. Returned with each
/// task's completing reach.
fn bound_critical_sections(
    model: &Model<'_>,
    retries: &[(String, ipet::Retries)],
) -> (
    Vec<super::critical::CriticalSection>,
    Vec<(String, Vec<usize>)>,
) {
    let program = model.program;
    // A call inside a section that masks every interrupt retries nothing; inside a
    // lock, the higher priorities can preempt it: the retries of the task's
    // activation (the most preemptions of any task, a bound for every section).
    let most_retries = retries
        .iter()
        .map(|r| r.1)
        .fold(ipet::Retries::default(), ipet::Retries::max);
    let callee_bounds: std::cell::RefCell<BTreeMap<(usize, bool), Option<u64>>> =
        Default::default();
    let callee = |g: usize, preemptible: bool| -> Option<u64> {
        if let Some(&b) = callee_bounds.borrow().get(&(g, preemptible)) {
            return b;
        }
        let r = if preemptible {
            most_retries
        } else {
            ipet::Retries::default()
        };
        let b = ipet::task_bound(
            program,
            model.all_loops,
            g,
            model.facts,
            r,
            model.copies,
            Cost::Cycles,
        )
        .ok()
        .map(|b| b.bound);
        callee_bounds.borrow_mut().insert((g, preemptible), b);
        b
    };
    let task_reach: Vec<(String, Vec<usize>)> = model
        .build
        .tasks()
        .iter()
        .filter_map(|&(n, sym)| {
            let root = *program.find(sym).first()?;
            Some((n.to_string(), program.completing_reachable(&[root])))
        })
        .collect();
    let locate = |a: u32| {
        let (file, line) = model.ctx.location(a);
        format!("{}:{line}", model.ctx.short_path(&file))
    };
    let critical_sections = super::critical::critical_sections(
        program,
        model.memory,
        model.all_loops,
        model.facts,
        &task_reach,
        &callee,
        &locate,
    );
    (critical_sections, task_reach)
}

/// Response times: each task's and interrupt's static bound at its place in the
/// build's schedule ([`Target::schedule`]), the critical sections of lower
/// priorities as blocking. Written into `tasks` only when every task and section
/// has a bound.
fn bound_response_times(
    model: &Model<'_>,
    tasks: &mut [TaskStatic],
    critical_sections: &[super::critical::CriticalSection],
    task_reach: &[(String, Vec<usize>)],
) {
    let program = model.program;
    let cycles_of = |n: &str| {
        tasks
            .iter()
            .find(|t: &&TaskStatic| t.name == n)
            .and_then(|t| t.static_bound_cycles)
    };
    // A preemption by a task refills at most the lines of the instruction cache
    // and of the data cache (the literal loads the preempted code counted on as
    // hits, `data_cache`) its code can evict.
    let refill_of = |n: &str| {
        let lines = task_reach.iter().find(|(t, _)| t == n).map_or(
            super::cache::CACHE_LINES + u64::from(super::data_cache::DATA_CACHE_LINES),
            |(_, reach)| {
                super::cache::evicting_lines(program, reach)
                    + super::cache::evicting_data_lines(program, reach)
            },
        );
        (lines * program.line_fetch_cycles) as f64
    };
    // A task whose light activations have a bound of their own.
    let light_of = |n: &str| {
        let task = tasks.iter().find(|t: &&TaskStatic| t.name == n)?;
        Some(super::rta::Heavy {
            light_cycles: task.light_bound_cycles? as f64,
            extras: task.light_extras.iter().map(|e| e.charge).collect(),
        })
    };
    let mut activities = Vec::new();
    let mut complete = true;
    for scheduled in model.build.schedule() {
        let n = scheduled.name;
        let Some(c) = cycles_of(n) else {
            complete = false;
            break;
        };
        let mut sections = Vec::new();
        for s in critical_sections.iter().filter(|s| s.task == n) {
            match s.bound_cycles {
                Some(b) => sections.push((s.ceiling, b as f64)),
                None => complete = false,
            }
        }
        activities.push(super::rta::Activity {
            name: n.to_string(),
            priority: scheduled.priority,
            period_us: scheduled.period_us,
            deadline_us: scheduled.deadline_us,
            wcet_cycles: c as f64,
            refill_cycles: refill_of(n),
            burst: scheduled.burst,
            critical_sections: sections,
            heavy: light_of(n),
        });
    }
    if complete {
        for r in super::rta::response_times(&activities, f64::from(model.build.clock_hz)) {
            if let Some(t) = tasks.iter_mut().find(|t| t.name == r.name) {
                t.response_time_bound_us = r.response_time_bound_us;
                t.response_time_past_deadline_us = r.past_deadline_us;
                t.demand_at_deadline = r.demand_at_deadline;
            }
        }
    }
}

/// What the traces showed, beyond the tasks' and loops' own figures.
#[derive(Default)]
struct Observed {
    /// Bounds a trace exceeded, unexpected indirect targets.
    violations: Vec<String>,
    /// The `(function, block)` pairs the traces ran.
    blocks_run: std::collections::BTreeSet<(usize, usize)>,
    /// The indirect transfers taken: `(site, function, target, times)`.
    indirect_calls_traced: Vec<(String, String, String, u64)>,
}

/// Replays QEMU traces against the bounded program: every bound checked against
/// execution, per loop the largest back-edge count per entry seen, per task the
/// largest activation with the same block costs.
struct TraceReplay<'a> {
    model: &'a Model<'a>,
    /// The vector table's handlers.
    handlers: Vec<usize>,
    /// The tasks' roots.
    roots: Vec<(String, usize)>,
    /// The flow facts' counters.
    counters: Vec<super::trace_check::CounterSpec>,
    /// The sections' functions.
    sections: Vec<(String, usize)>,
}

impl<'a> TraceReplay<'a> {
    /// Finds what a replay follows: the handlers, the tasks' and sections'
    /// functions and the flow facts' counters.
    fn new(
        elf: &Path,
        model: &'a Model<'a>,
        flow_facts: &[super::flow_facts::FlowFact],
    ) -> Result<Self> {
        let program = model.program;
        let handlers = super::trace_check::vector_table_handlers(elf, program)?;
        let roots: Vec<(String, usize)> = model
            .build
            .tasks()
            .iter()
            .filter_map(|(n, sym)| program.find(sym).first().map(|&r| (n.to_string(), r)))
            .collect();
        let counters: Vec<super::trace_check::CounterSpec> =
            flow_facts.iter().map(|f| f.counter.clone()).collect();
        let sections: Vec<(String, usize)> = model
            .build
            .sections()
            .iter()
            .filter_map(|(n, sym, _, _)| program.find(sym).first().map(|&f| (n.to_string(), f)))
            .collect();
        Ok(Self {
            model,
            handlers,
            roots,
            counters,
            sections,
        })
    }

    /// Checks every trace of `traces` in turn.
    fn check_all(
        &self,
        traces: &[PathBuf],
        units: &mut Units,
        flow_facts: &mut [super::flow_facts::FlowFact],
        observed: &mut Observed,
    ) -> Result<()> {
        for trace in traces {
            self.check(trace, units, flow_facts, observed)?;
        }
        Ok(())
    }

    /// Replays one trace: records the blocks it ran, its indirect transfers, its
    /// activations and loops' counts, and every bound it exceeded.
    fn check(
        &self,
        trace: &Path,
        units: &mut Units,
        flow_facts: &mut [super::flow_facts::FlowFact],
        observed: &mut Observed,
    ) -> Result<()> {
        let program = self.model.program;
        let file = std::fs::File::open(trace).map_err(|source| WcetError::Io {
            path: trace.to_path_buf(),
            source,
        })?;
        let check = super::trace_check::replay_trace(
            std::io::BufReader::with_capacity(1 << 20, file),
            program,
            self.model.all_loops,
            &self.roots,
            &self.handlers,
            &self.counters,
            &self.sections,
        )?;
        observed.blocks_run.extend(check.blocks_run.iter().copied());
        record_indirect_calls(program, &check, &mut observed.indirect_calls_traced);
        observed.violations.extend(
            super::indirect::unexpected_targets(program, &check)
                .into_iter()
                .map(|v| format!("{}: {v}", trace.display())),
        );
        observed.violations.extend(super::flow_facts::observe(
            flow_facts,
            &check,
            &trace.display().to_string(),
        ));
        for sec in &check.sections {
            if let Some(t) = units.tasks.iter_mut().find(|t| t.name == sec.name) {
                t.observed_activations += sec.calls;
                if sec.calls > 0 {
                    t.observed_max_instructions = Some(
                        t.observed_max_instructions
                            .unwrap_or(0)
                            .max(sec.max_instructions),
                    );
                    t.observed_max_cycles =
                        Some(t.observed_max_cycles.unwrap_or(0).max(sec.max_cycles));
                }
            }
        }
        for o in &check.loops {
            if let Some(row) = units.loop_rows.get_mut(&(o.function, o.loop_index)) {
                row.observed_max = Some(row.observed_max.unwrap_or(0).max(o.max_back_edges));
            }
        }
        observed.violations.extend(
            check
                .violations(&entry_bounds(self.model))
                .into_iter()
                .map(|v| format!("{}: {v}", trace.display())),
        );
        for r in &check.roots {
            if let Some(t) = units.tasks.iter_mut().find(|t| t.name == r.name) {
                t.observed_activations += r.activations;
                t.observed_max_instructions = Some(
                    t.observed_max_instructions
                        .unwrap_or(0)
                        .max(r.max_instructions),
                );
                t.observed_max_cycles = Some(t.observed_max_cycles.unwrap_or(0).max(r.max_cycles));
            }
        }
        Ok(())
    }
}

/// Adds the indirect transfers of one trace's `check` to `traced`
/// (`(site, function, target, times)`, one row per site, function and target).
fn record_indirect_calls(
    program: &Program,
    check: &super::trace_check::TraceCheck,
    traced: &mut Vec<(String, String, String, u64)>,
) {
    for o in &check.indirect_calls {
        let from = program
            .functions
            .get(o.from)
            .map_or("?".to_string(), |f| f.demangled.clone());
        let key = (format!("{:#x}", o.site), from, o.target_name.clone());
        match traced
            .iter_mut()
            .find(|(s, f, t, _)| (s, f, t) == (&key.0, &key.1, &key.2))
        {
            Some(row) => row.3 += o.count,
            None => traced.push((key.0, key.1, key.2, o.count)),
        }
    }
}

/// Each loop fact's most back edges per entry, `(function, loop, bound)`, what a
/// trace's counts are checked against. A cap per activation is also a cap per
/// entry (an entry is within one activation): both are checked against the
/// largest count per entry.
fn entry_bounds(model: &Model<'_>) -> Vec<(usize, usize, u64)> {
    let most_preemptions = model
        .build
        .tasks()
        .iter()
        .map(|(n, _)| model.build.preemptions_of(n))
        .max()
        .unwrap_or(0);
    let most_ticks = model
        .build
        .tasks()
        .iter()
        .map(|(n, _)| model.build.ticks_of(n))
        .max()
        .unwrap_or(0);
    let facts = model.facts;
    facts
        .iter()
        .map(|f| {
            let shared = facts
                .iter()
                .any(|g| g.function == f.function && g.group == Some(f.loop_index));
            let b = match f.per {
                Per::Preemption => f.bound.max(1) * most_preemptions * 2,
                Per::Tick => f.bound.max(1) * most_ticks * 2,
                _ => match (
                    model.program.functions.get(f.function),
                    model
                        .all_loops
                        .get(f.function)
                        .and_then(|ls| ls.get(f.loop_index)),
                ) {
                    (Some(func), Some(l)) => ipet::back_edges_per_entry(f, func, l, shared),
                    _ => f.bound,
                },
            };
            (f.function, f.loop_index, b)
        })
        .collect()
}

/// Each task's tightness (its static bound over its largest traced activation),
/// and a violation for each task a traced activation exceeded.
fn check_tightness(tasks: &mut [TaskStatic]) -> Vec<String> {
    let mut violations = Vec::new();
    for t in tasks {
        if let (Some(b), Some(o)) = (t.static_bound_cycles, t.observed_max_cycles) {
            t.tightness = (o > 0).then(|| b as f64 / o as f64);
            if b < o {
                violations.push(format!(
                    "task {}: a traced activation costs {o} cycles, above the static bound {b}",
                    t.name
                ));
            }
        }
    }
    violations
}

/// The loops the traces executed (`blocks_run`), and why each other one of
/// `loop_rows` was not.
fn loop_coverage(
    model: &Model<'_>,
    loop_rows: &BTreeMap<(usize, usize), LoopEntry>,
    blocks_run: &std::collections::BTreeSet<(usize, usize)>,
) -> super::coverage::Coverage {
    let sites: Vec<super::coverage::LoopSite<'_>> = loop_rows
        .iter()
        .map(|(&key, row)| super::coverage::LoopSite {
            key,
            file: &row.file,
            line: row.line,
            tasks: &row.tasks,
            traced: row.observed_max.is_some(),
        })
        .collect();
    let locate = |a: u32| {
        let (file, line) = model.ctx.location(a);
        (model.ctx.short_path(&file), line)
    };
    super::coverage::coverage(model.program, model.all_loops, &sites, blocks_run, &locate)
}

/// The response times `required` names (`TASK-response-time`, a task of the
/// build: `control-response-time`, `link-response-time`, ...) that `tasks` do
/// not bound within their deadlines, one line each; an id of another form, or
/// naming no task with a deadline, is an error that says which ids exist.
pub fn missed_response_times(tasks: &[TaskStatic], required: &[String]) -> Result<Vec<String>> {
    let known: Vec<String> = tasks
        .iter()
        .filter(|t| t.deadline_us.is_some())
        .map(|t| format!("{}-response-time", t.name))
        .collect();
    let mut missed = Vec::new();
    for id in required {
        let task = id
            .strip_suffix("-response-time")
            .and_then(|n| tasks.iter().find(|t| t.name == n && t.deadline_us.is_some()))
            .ok_or_else(|| {
                WcetError::Analysis(format!(
                    "`{id}` is no goal of the static analysis: with --static-only, --require takes {}",
                    known.join(", ")
                ))
            })?;
        let deadline = task.deadline_us.unwrap_or(0.0);
        match task.response_time_bound_us {
            Some(r) if r <= deadline => {}
            Some(r) => missed.push(format!("{id}: {r:.2} µs, deadline {deadline:.2} µs")),
            None => missed.push(format!(
                "{id}: no bound within its deadline of {deadline:.2} µs{}",
                task.response_time_past_deadline_us
                    .map(|p| format!(" (fixed point {p:.2} µs)"))
                    .unwrap_or_default()
            )),
        }
    }
    Ok(missed)
}

impl StaticAnalysis {
    /// True when every reachable loop is bounded, every indirect call resolved and
    /// no function recursive: the analysis gave what it could.
    pub fn is_complete(&self) -> bool {
        self.unbounded_loops == 0
            && self.unresolved_indirect_calls.is_empty()
            && self.recursions.is_empty()
    }

    /// What the analysis could not bound, counted: `N unbounded loop(s), N
    /// unresolved indirect call(s), N recursion(s)`.
    pub fn gaps(&self) -> String {
        format!(
            "{} unbounded loop(s), {} unresolved indirect call(s), {} recursion(s)",
            self.unbounded_loops,
            self.unresolved_indirect_calls.len(),
            self.recursions.len()
        )
    }

    /// The Markdown report: the tasks' bounds and the gaps, what the bounds are
    /// made of, the flow facts, the coverage, the critical sections, the model
    /// and the loops.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        self.write_summary(&mut s);
        self.write_contributors(&mut s);
        self.write_flow_facts(&mut s);
        self.write_coverage(&mut s);
        self.write_critical_sections(&mut s);
        self.write_model_and_loops(&mut s);
        s
    }

    /// The report's head: the table of the tasks' and sections' bounds, then the
    /// gaps (unbounded loops, unresolved calls, recursions, irreducible cycles) and
    /// the violations the traces showed.
    fn write_summary(&self, s: &mut String) {
        let _ = writeln!(s, "# Static worst-case timing analysis of `{}`\n", self.elf);
        let _ = writeln!(s, "Build: {}.\n", self.build_name);
        let _ = writeln!(
            s,
            "Control-flow graphs from the Thumb-2 disassembly, natural loops, loop bounds \
             recognised from the binary, IPET with `good_lp`/`microlp`. A task gets a bound \
             only when every loop it reaches is bounded, no cycle is irreducible, every \
             indirect call is resolved and there is no recursion.\n"
        );
        let _ = writeln!(s, "| task or section | root | functions | loops (bounded) | bound, instructions | bound, cycles | budget, cycles | response time bound / deadline, µs | traced activations | observed max, instructions / cycles | tightness | refused because |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
        for t in &self.tasks {
            let opt = |v: Option<u64>| v.map_or("–".to_string(), |x| x.to_string());
            let within = match (t.static_bound_cycles, t.budget_cycles) {
                (Some(c), Some(b)) if c > b => " **over**",
                _ => "",
            };
            let rt = match (t.deadline_us, t.response_time_bound_us) {
                // A deadline under 100 µs (the link interrupt's byte time) with
                // its decimals.
                (Some(d), Some(r)) if d < 100.0 => format!("{r:.2} / {d:.2}"),
                (Some(d), Some(r)) => format!("{r:.0} / {d:.0}"),
                (Some(d), None) => match t.response_time_past_deadline_us {
                    Some(p) if d < 100.0 => format!("**none within** ({p:.2}) / {d:.2}"),
                    Some(p) => format!("**none within** ({p:.0}) / {d:.0}"),
                    None => format!("**none within** / {d:.0}"),
                },
                _ => "–".to_string(),
            };
            let _ = writeln!(
                s,
                "| {} | `{}` | {} | {} ({}) | {} | {} | {}{} | {} | {} | {} / {} | {} | {} |",
                t.name,
                t.root,
                t.functions,
                t.loops,
                t.bounded_loops,
                opt(t.static_bound_instructions),
                opt(t.static_bound_cycles),
                opt(t.budget_cycles),
                within,
                rt,
                t.observed_activations,
                opt(t.observed_max_instructions),
                opt(t.observed_max_cycles),
                t.tightness.map_or("–".to_string(), |x| format!("{x:.2}")),
                t.refused.as_deref().unwrap_or("")
            );
        }
        self.write_past_deadline(s);
        self.write_light_extras(s);
        self.write_interrupts(s);
        self.write_gaps(s);
    }

    /// Each task whose response time has no bound within its deadline: the work
    /// within a window of its deadline against what the window holds.
    fn write_past_deadline(&self, s: &mut String) {
        for t in self
            .tasks
            .iter()
            .filter(|t| t.response_time_past_deadline_us.is_some())
        {
            let Some(deadline) = t.deadline_us else {
                continue;
            };
            let total: f64 = t.demand_at_deadline.iter().map(|d| d.cycles).sum();
            let available = deadline * f64::from(self.clock_hz) / 1e6;
            let parts: Vec<String> = t
                .demand_at_deadline
                .iter()
                .map(|d| {
                    if d.name == t.name {
                        format!("its own {:.0}", d.cycles)
                    } else {
                        format!("`{}` {:.0} ({:.0} arrivals)", d.name, d.cycles, d.arrivals)
                    }
                })
                .collect();
            let _ = writeln!(
                s,
                "\n`{}`'s work within a window of its deadline ({deadline:.0} µs), cycles: {}; \
                 {total:.0} against the {available:.0} the window holds, {:.0} ({:.2} ms) too many.",
                t.name,
                parts.join(", "),
                total - available,
                (total - available) / f64::from(self.clock_hz) * 1e3
            );
        }
    }

    /// Each task's bound without its extra work, and each kind of extra work's
    /// charge.
    fn write_light_extras(&self, s: &mut String) {
        for t in &self.tasks {
            let Some(light) = t.light_bound_cycles else {
                continue;
            };
            let without: Vec<String> = t.light_extras.iter().map(|e| e.what.clone()).collect();
            let _ = writeln!(
                s,
                "\n`{}`'s activations without {}: {light} cycles ({} with all of it). The \
                 response-time analysis charges each of its preemptions that, and each kind of \
                 extra work at its cost a unit as often as its units can come \
                 (`wcet::rta::Heavy`); a unit's cost is the largest step of the bound from none \
                 to one unit and, per unit, to an activation's whole, with the other kinds left \
                 out or whole.\n\n\
                 | extra work | unit | cycles a unit | per activation | per window / window, µs | \
                 bound with 0, 1, all units, the rest left out | the rest whole |\n\
                 |---|---|---:|---:|---|---|---|",
                t.name,
                without.join(" or "),
                t.static_bound_cycles
                    .map_or("no bound".to_string(), |c| c.to_string()),
            );
            for e in &t.light_extras {
                let row = |b: [u64; 3]| format!("{} / {} / {}", b[0], b[1], b[2]);
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.0} | {} | {} / {:.0} (+{}) | {} | {} |",
                    e.what,
                    e.unit,
                    e.charge.unit_cycles,
                    e.charge.per_activation,
                    e.charge.per_window,
                    e.charge.window_us,
                    e.charge.extra_windows,
                    row(e.bounds[0]),
                    row(e.bounds[1]),
                );
            }
        }
    }

    /// The clock and the interrupts' bounds and response times.
    fn write_interrupts(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\nClock: {} Hz, {} (set by `{}`).\n",
            self.clock.sysclk_hz,
            self.clock.source,
            self.clock
                .configured_in
                .as_deref()
                .unwrap_or("no clock set-up in the ELF")
        );
        let _ = writeln!(s, "| interrupt | handler | priority | bound, cycles | min inter-arrival, µs | at once | per window / window, µs | response time bound / deadline, µs |");
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---|---|");
        for i in &self.interrupts {
            let _ = writeln!(
                s,
                "| {} | `{}` | {} | {} | {:.3} | {} | {} | {} / {:.2} |",
                i.name,
                i.handler,
                i.priority,
                i.static_bound_cycles
                    .map_or("–".to_string(), |c| c.to_string()),
                i.min_interarrival_us,
                i.at_once,
                match (
                    i.per_window,
                    i.window_us,
                    i.per_slow_window,
                    i.slow_window_us
                ) {
                    (Some(n), Some(w), Some(m), Some(v)) => format!("{n} / {w:.0} + {m} / {v:.0}"),
                    (Some(n), Some(w), _, _) => format!("{n} / {w:.0}"),
                    _ => "–".to_string(),
                },
                i.response_time_bound_us
                    .map_or("**none within**".to_string(), |r| format!("{r:.2}")),
                i.deadline_us
            );
        }
    }

    /// What the analysis could not bound, and the traces' violations.
    fn write_gaps(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n**Unbounded loops:** {}. **Unresolved indirect calls:** {}. **Recursions:** {}.\n",
            self.unbounded_loops,
            self.unresolved_indirect_calls.len(),
            self.recursions.len()
        );
        if !self.traces.is_empty() {
            let _ = writeln!(
                s,
                "Checked against {} QEMU trace(s): {} violation(s).\n",
                self.traces.len(),
                self.violations.len()
            );
        }
        for v in &self.violations {
            let _ = writeln!(s, "- **violation**: {v}");
        }
        for r in &self.recursions {
            let _ = writeln!(s, "- recursion: {}", r.join(" → "));
        }
        for u in &self.unresolved_indirect_calls {
            let _ = writeln!(s, "- unresolved: `{u}`");
        }
        for t in &self.tasks {
            for i in &t.irreducible {
                let _ = writeln!(s, "- irreducible ({}): {i}", t.name);
            }
        }
    }

    /// What the bounds are made of: per task or section, its costliest functions
    /// and blocks on the worst path.
    fn write_contributors(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n## What the bounds are made of\n\nPer task or section, the functions whose \
             blocks cost the most on the worst path the IPET found (their own blocks, \
             callees apart), in model cycles, with how often that path enters them.\n"
        );
        for t in self.tasks.iter().filter(|t| !t.top_functions.is_empty()) {
            let total = t.static_bound_cycles.unwrap_or(0).max(1) as f64;
            let _ = writeln!(s, "### {}\n", t.name);
            let _ = writeln!(s, "| function | cycles | share of the bound | entries |");
            let _ = writeln!(s, "|---|---:|---:|---:|");
            for (k, (f, c)) in t.top_functions.iter().enumerate() {
                let entries = t
                    .top_functions_entries
                    .get(k)
                    .filter(|(g, _)| g == f)
                    .map_or("–".to_string(), |(_, n)| format!("{n:.0}"));
                let _ = writeln!(
                    s,
                    "| `{f}` | {c:.0} | {:.1} % | {entries} |",
                    100.0 * c / total
                );
            }
            let _ = writeln!(s);
            if !t.top_blocks.is_empty() {
                let _ = writeln!(
                    s,
                    "Its costliest blocks (count on that path × model cycles per \
                     execution; a cached loop's one fetch per entry is not in them):\n"
                );
                let _ = writeln!(s, "| block | source | count | cycles each | total |");
                let _ = writeln!(s, "|---|---|---:|---:|---:|");
                for b in &t.top_blocks {
                    let _ = writeln!(
                        s,
                        "| {:#x} `{}` | {}:{} | {:.0} | {} | {:.0} |",
                        b.address,
                        b.function,
                        b.file,
                        b.line,
                        b.count,
                        b.cycles,
                        b.count * b.cycles as f64
                    );
                }
                let _ = writeln!(s);
            }
        }
    }

    /// The flow facts, with their traced maxima.
    fn write_flow_facts(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n## Flow facts\n\nThe bounds over more than one loop entry, each counted in the \
             traces as the IPET counts it (block entries and edges per activation, call or loop \
             entry); `–`: no trace exercised it, its bound rests on its source's argument alone.\n"
        );
        let _ = writeln!(
            s,
            "| fact | per | counts | bound | traced max | traced scopes | source |"
        );
        let _ = writeln!(s, "|---|---|---|---:|---:|---:|---|");
        for f in &self.flow_facts {
            let bound = if f.bound_by_task.is_empty() {
                f.bound.to_string()
            } else {
                f.bound_by_task
                    .iter()
                    .map(|(t, b)| format!("{t} {b}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let _ = writeln!(
                s,
                "| `{}` | {} | {} | {} | {} | {} | {} |",
                f.name,
                f.per,
                f.counts,
                bound,
                f.observed_max.map_or("–".to_string(), |m| m.to_string()),
                f.observed_scopes,
                f.sources.join("; ")
            );
        }
    }

    /// The loops no trace ran, and why (with traces only).
    fn write_coverage(&self, s: &mut String) {
        if let Some(c) = &self.coverage {
            let _ = writeln!(
                s,
                "\n## Coverage\n\n{} of the {} loops the tasks reach were executed by a trace \
                 ({:.1} %). The others, with the reason read off the traces:\n",
                c.traced, c.loops, c.percent
            );
            let _ = writeln!(
                s,
                "| function | header | source | tasks | why no trace ran it |"
            );
            let _ = writeln!(s, "|---|---|---|---|---|");
            for u in &c.untraced {
                let _ = writeln!(
                    s,
                    "| `{}` | {} | {}:{} | {} | {} |",
                    u.function,
                    u.header,
                    u.file,
                    u.line,
                    u.tasks.join(", "),
                    u.reason
                );
            }
        }
    }

    /// The critical sections, with what they mask and their bounds.
    fn write_critical_sections(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "\n## Critical sections\n\nThe code the tasks run with interrupts disabled or a \
             lock's ceiling raised: each blocks the priorities it masks for its length (the \
             response-time analysis charges the longest of a lower priority).\n"
        );
        let _ = writeln!(
            s,
            "| task | function | start | source | masks | bound, cycles |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---:|");
        for c in &self.critical_sections {
            let masks = if c.ceiling == super::critical::ALL_MASKED {
                "every interrupt".to_string()
            } else {
                format!("priorities up to {}", c.ceiling)
            };
            let _ = writeln!(
                s,
                "| {} | `{}` | {:#x} | {} | {masks} | {} |",
                c.task,
                c.function,
                c.start,
                c.source,
                c.bound_cycles.map_or_else(
                    || format!("**none**: {}", c.why.as_deref().unwrap_or("")),
                    |b| b.to_string()
                )
            );
        }
    }

    /// The processor and memory model's assumptions, and every loop with its bound.
    fn write_model_and_loops(&self, s: &mut String) {
        let _ = writeln!(s, "\n## Processor and memory model\n");
        for a in &self.assumptions {
            let _ = writeln!(s, "- {a}");
        }
        let _ = writeln!(s, "\n## Loops\n\n| tasks | function | header | source | bound | observed max (back edges per entry) | from |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for l in &self.loops {
            let _ = writeln!(
                s,
                "| {} | `{}` | {} | {}:{} | {} | {} | {} |",
                l.tasks.join(", "),
                l.function,
                l.header,
                l.file,
                l.line,
                l.bound.map_or("**none**".to_string(), |b| b.to_string()),
                l.observed_max.map_or("–".to_string(), |b| b.to_string()),
                l.source
                    .as_deref()
                    .or(l.why_unbounded.as_deref())
                    .unwrap_or("")
            );
        }
    }

    /// Writes `static.json` and `static.md` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let written = |path: PathBuf| move |source| WcetError::Write { path, source };
        std::fs::create_dir_all(dir).map_err(written(dir.to_path_buf()))?;
        let json = serde_json::to_string_pretty(self)?;
        let path = dir.join("static.json");
        std::fs::write(&path, json).map_err(written(path.clone()))?;
        let path = dir.join("static.md");
        std::fs::write(&path, self.markdown()).map_err(written(path.clone()))?;
        Ok(())
    }
}

/// The annotated line a loop takes, and whether it is one of its own `keys`
/// (else a line of its inlining `chain`, read only then): the first of its `keys` with an
/// annotation (`annotated`) that no enclosing loop `taken`, else the first such
/// line of the `chain` (every frame of its candidate addresses, innermost
/// first: a dependency's fact about its own code). A loop of a dependency's code
/// (`library`) inlined into a firmware line takes no line a firmware loop of
/// the function took (`firmware_taken`): those annotations bound the line's own
/// loop.
fn choose_line(
    library: bool,
    keys: &[(String, u32)],
    chain: impl IntoIterator<Item = (String, u32)>,
    firmware_taken: &std::collections::BTreeSet<(String, u32)>,
    taken: &[(String, u32)],
    annotated: impl Fn(&(String, u32)) -> bool,
) -> Option<((String, u32), bool)> {
    let free = |key: &&(String, u32)| {
        !(library && firmware_taken.contains(*key)) && annotated(key) && !taken.contains(*key)
    };
    if let Some(key) = keys.iter().find(free) {
        return Some((key.clone(), true));
    }
    chain
        .into_iter()
        .find(|key| free(&key))
        .map(|key| (key, false))
}

/// Whether every instruction of loop `l` is a dependency's code (the innermost
/// frame of its inlining chain outside the firmware's crates): a library loop,
/// inlined or not, whose bound is a fact about the library's own line.
fn is_library_loop(f: &Function, l: &Loop, ctx: &SourceLines) -> bool {
    l.blocks.iter().all(|&b| {
        f.blocks.get(b).is_none_or(|blk| {
            f.instructions[blk.first..blk.end].iter().all(|i| {
                ctx.frames(i.address)
                    .first()
                    .is_none_or(|(file, _)| ctx.source_path(file).is_none())
            })
        })
    })
}

/// Addresses whose source line may carry a loop's annotation, most telling first:
/// each back edge's branch, the header's first instruction, then the other
/// instructions of the latches and the header.
fn candidate_addresses(f: &Function, l: &Loop) -> Vec<u32> {
    let mut out = Vec::new();
    let block_insns = |b: usize| {
        f.blocks
            .get(b)
            .map(|blk| &f.instructions[blk.first..blk.end])
            .unwrap_or(&[])
    };
    for &(t, _) in &l.back_edges {
        if let Some(i) = block_insns(t).last() {
            out.push(i.address);
        }
    }
    if let Some(i) = block_insns(l.header).first() {
        out.push(i.address);
    }
    for &(t, _) in &l.back_edges {
        out.extend(block_insns(t).iter().rev().map(|i| i.address));
    }
    out.extend(block_insns(l.header).iter().map(|i| i.address));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A firmware line with an annotation bounds the firmware's loop on it; a
    /// dependency's loop inlined into that line takes the fact about its own line
    /// in the dependency, or no bound at all, never the firmware line's.
    #[test]
    fn an_inlined_library_loop_takes_no_bound_of_the_line_it_is_inlined_on() {
        let line = |f: &str, l: u32| (f.to_string(), l);
        let task_line = line("firmware/src/bin/ecu.rs", 1426);
        let walk = line("rtic-time-2.0.1/src/linked_list.rs", 78);
        let keys = [task_line.clone()];
        let chain = [walk.clone(), task_line.clone()];
        let with_fact = |k: &(String, u32)| *k == task_line || *k == walk;
        let no_fact = |k: &(String, u32)| *k == task_line;
        let mut firmware_taken = std::collections::BTreeSet::new();
        // The firmware's loop (bound first) takes its line.
        let own = choose_line(false, &keys, chain.clone(), &firmware_taken, &[], with_fact);
        assert_eq!(own, Some((task_line.clone(), true)));
        firmware_taken.insert(task_line.clone());
        // The library loop on the same line: its own line's fact, else nothing.
        let lib = choose_line(true, &keys, chain.clone(), &firmware_taken, &[], with_fact);
        assert_eq!(lib, Some((walk.clone(), false)));
        let lib = choose_line(true, &keys, chain.clone(), &firmware_taken, &[], no_fact);
        assert_eq!(lib, None);
        // No firmware loop took the line: the library loop alone is the line's
        // loop (a checksum's loop on its call's line), and takes it.
        let none_taken = std::collections::BTreeSet::new();
        let alone = choose_line(true, &keys, chain.clone(), &none_taken, &[], no_fact);
        assert_eq!(alone, Some((task_line.clone(), true)));
        // A line an enclosing loop took is not taken twice.
        let nested = choose_line(false, &keys, chain.clone(), &none_taken, &keys, no_fact);
        assert_eq!(nested, None);
    }

    fn task(
        name: &str,
        deadline: Option<f64>,
        bound: Option<f64>,
        past: Option<f64>,
    ) -> TaskStatic {
        TaskStatic {
            name: name.into(),
            response_time_bound_us: bound,
            response_time_past_deadline_us: past,
            deadline_us: deadline,
            ..TaskStatic::default()
        }
    }

    #[test]
    fn a_required_response_time_fails_only_when_missed_and_a_wrong_id_says_which_exist() {
        let tasks = [
            task("control", Some(10_000.0), Some(7_343.0), None),
            task("plan", Some(100_000.0), None, Some(159_560.0)),
            task("link", Some(10.85), Some(4.1), None),
            task("plan_job", None, None, None),
        ];
        let req = |ids: &[&str]| ids.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            missed_response_times(
                &tasks,
                &req(&["control-response-time", "link-response-time"])
            )
            .ok(),
            Some(Vec::new())
        );
        let missed =
            missed_response_times(&tasks, &req(&["plan-response-time"])).unwrap_or_default();
        assert_eq!(missed.len(), 1);
        assert!(missed[0].contains("159560.00"), "{missed:?}");
        // A section has no deadline; an unknown id is an error naming the known ones.
        for bad in [
            "plan_job-response-time",
            "stack-bound",
            "brake-response-time",
        ] {
            let e = missed_response_times(&tasks, &req(&[bad]))
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(
                e.contains("control-response-time, plan-response-time, link-response-time"),
                "{e}"
            );
        }
    }
}
