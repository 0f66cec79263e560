//! Replays a QEMU execution trace against the control-flow graphs: observed loop
//! iterations and activation costs, to check the static analysis against a run.
//!
//! The log is QEMU's `-d in_asm,exec,nochain` output (see [`super::cpi`]): every
//! translation block (TB) is listed once (`IN:`), every execution is a `Trace` line.
//! The executed instruction stream is rebuilt TB by TB, with the icount corrections
//! of [`super::cpi`] (an execution `Stopped` before it ran is dropped, one rewound
//! by `cpu_io_recompile` counts up to the rewound instruction), and walked
//! instruction by instruction: a TB may span several basic blocks and a basic block
//! several TBs, so a block is entered when its first instruction executes.
//!
//! **Contexts.** Thread mode and every exception handler activation is an execution
//! context with its own call stack. An exception is entered between two TBs: a TB
//! starting at a handler's entry that is not the target of the current context's
//! last branch pushes a new context; a return (`bx lr`, `pop {.., pc}`) executed in
//! the handler's own frame (call depth 0; tail calls keep the depth) is the exception
//! return and pops it, the preempted context resuming where it stopped (tail-chained
//! handlers work the same way). A conditional return at depth 0 is resolved at the
//! context's next instruction: if an exception enters between a not-taken
//! conditional return and the next instruction, the entry is seen as a preemption
//! (costs are still attributed right; only the nesting differs).
//!
//! **Loops.** Within one frame, entering block `B` of the function from block `A` is
//! an edge. If `B` is a loop's header, the edge is either one of the loop's back
//! edges (one more iteration of the current entry) or an entry (from outside the
//! loop, or the frame's first block: the function was called or tail-called). The
//! result is, per loop, the entries seen and the largest number of back-edge
//! traversals in one entry: the quantity a loop bound bounds.
//!
//! **Activations.** Per root (a task's handler), each activation from exception
//! entry to exception return adds, for every block entered in its own context, the
//! block's `instructions` and static worst-case `cycles` (the numbers the static
//! analysis uses); instructions of nested exceptions are theirs, not the
//! preempted activation's.
//!
//! This file holds what the check reports and its entry points; `tb_stream`
//! reads the log into executed translations, `replay` walks them through the
//! contexts, frames and loops.

mod observations;
mod replay;
mod tb_stream;

use super::cfg::Program;
use super::loops::Loop;
use super::WcetError;
pub use observations::{
    CounterObservation, CounterScope, CounterSpec, IndirectObservation, LoopObservation,
    RootObservation, SectionObservation, TraceCheck, LARGEST_KEPT,
};
use replay::Replay;
use std::io::BufRead;
use tb_stream::{Event, Resolved, TbStream};

/// Names of the Cortex-M fault and system handlers recognised as exception entries
/// by [`check_trace`] in addition to the roots.
pub const SYSTEM_HANDLERS: [&str; 11] = [
    "HardFault",
    "HardFault_",
    "DefaultHandler",
    "DefaultHandler_",
    "NonMaskableInt",
    "MemoryManagement",
    "BusFault",
    "UsageFault",
    "SVCall",
    "PendSV",
    "DebugMonitor",
];

pub use super::vector_table::vector_table_handlers;

/// Replays `log` against `program`. `loops[f]` are the natural loops of function
/// `f` (an empty list for a function without loops or not analysed); `roots` are
/// the tasks' `(name, handler function)`. Exception entries are recognised at the
/// roots and at the functions named in [`SYSTEM_HANDLERS`].
pub fn check_trace<R: BufRead>(
    log: R,
    program: &Program,
    loops: &[Vec<Loop>],
    roots: &[(String, usize)],
) -> Result<TraceCheck, WcetError> {
    let handlers: Vec<usize> = SYSTEM_HANDLERS
        .iter()
        .flat_map(|n| program.find(n))
        .filter(|&f| {
            let func = &program.functions[f];
            SYSTEM_HANDLERS
                .iter()
                .any(|n| func.demangled == *n || func.name == *n)
        })
        .collect();
    check_trace_with_handlers(log, program, loops, roots, &handlers)
}

/// [`check_trace`] with the exception handlers (besides the roots) given, e.g. by
/// [`vector_table_handlers`].
pub fn check_trace_with_handlers<R: BufRead>(
    log: R,
    program: &Program,
    loops: &[Vec<Loop>],
    roots: &[(String, usize)],
    handlers: &[usize],
) -> Result<TraceCheck, WcetError> {
    replay_trace(log, program, loops, roots, handlers, &[], &[])
}

/// [`check_trace_with_handlers`] that also keeps the flow-fact `counters` and
/// measures the calls of the `sections` `(name, function)`.
pub fn replay_trace<R: BufRead>(
    log: R,
    program: &Program,
    loops: &[Vec<Loop>],
    roots: &[(String, usize)],
    handlers: &[usize],
    counters: &[CounterSpec],
    sections: &[(String, usize)],
) -> Result<TraceCheck, WcetError> {
    let mut replay = Replay::new(program, loops, roots, handlers, counters, sections);
    let mut stream = TbStream::new(log);
    while let Some(event) = stream.next_event(|a| replay.resolve(a))? {
        match event {
            Event::Executed { tb, count } => {
                let insns: Vec<Resolved> = stream
                    .translations
                    .get(tb)
                    .map(|t| t.iter().take(count).copied().collect())
                    .unwrap_or_default();
                replay.tb(&insns);
            }
            Event::Untraced => replay.break_stream(),
        }
    }
    let mut check = replay.finish();
    check.untraced_executions = stream.untraced;
    check.abandoned_executions = stream.abandoned;
    Ok(check)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfg::{build_program, parse_disassembly, IndirectTargets, MemoryModel};
    use crate::loops::natural_loops;
    use std::collections::HashMap;

    /// `USART1` (the `plan` root): a loop tested at its header (`cmp; beq` out,
    /// body `adds; bl helper; b` back), so a trip count of n is n back edges.
    /// `USART2` (`control`): a loop tested at its bottom (`bne` back), n trips are
    /// n - 1 back edges. `main`: the idle loop. `SysTick` tail-calls `helper`.
    const DISASSEMBLY: &str = "
/tmp/ecu:\tfile format elf32-littlearm

Disassembly of section .text:

08000100 <USART1>:
 8000100: b580         \tpush\t{r7, lr}
 8000102: 2000         \tmovs\tr0, #0x0
 8000104: 4288         \tcmp\tr0, r1
 8000106: d003         \tbeq\t0x8000110 <USART1+0x10> @ imm = #0x6
 8000108: 3001         \tadds\tr0, #0x1
 800010a: f000 f809    \tbl\t0x8000120 <helper>    @ imm = #0x12
 800010e: e7f9         \tb\t0x8000104 <USART1+0x4> @ imm = #-0xe
 8000110: bd80         \tpop\t{r7, pc}

08000120 <helper>:
 8000120: 4770         \tbx\tlr

08000200 <USART2>:
 8000200: 2000         \tmovs\tr0, #0x0
 8000202: 3001         \tadds\tr0, #0x1
 8000204: 4290         \tcmp\tr0, r2
 8000206: d1fc         \tbne\t0x8000202 <USART2+0x2> @ imm = #-0x8
 8000208: 4770         \tbx\tlr

08000300 <main>:
 8000300: bf30         \twfi
 8000302: e7fd         \tb\t0x8000300 <main>     @ imm = #-0x6

08000400 <SysTick>:
 8000400: 2000         \tmovs\tr0, #0x0
 8000402: e68d         \tb\t0x8000120 <helper>   @ imm = #-0x2e6
";

    /// Writes a QEMU log: each translation listed before its first execution.
    /// Addresses are offsets from the start of flash.
    #[derive(Default)]
    struct Log {
        text: String,
        hosts: HashMap<Vec<u32>, u64>,
    }

    const FLASH: u32 = 0x0800_0000;

    impl Log {
        fn host(&self, offsets: &[u32]) -> u64 {
            self.hosts.get(offsets).copied().unwrap_or(0)
        }

        fn tb(&mut self, offsets: &[u32]) {
            let next = 0x7f00_0000_0000 + 0x100 * (self.hosts.len() as u64 + 1);
            let host = match self.hosts.get(offsets) {
                Some(&h) => h,
                None => {
                    self.text.push_str("----------------\nIN: f\n");
                    for o in offsets {
                        let a = FLASH + o;
                        self.text.push_str(&format!("0x{a:08x}:  bf00       nop\n"));
                    }
                    self.text.push('\n');
                    self.hosts.insert(offsets.to_vec(), next);
                    next
                }
            };
            let pc = FLASH + offsets.first().copied().unwrap_or(0);
            self.text.push_str(&format!(
                "Trace 0: 0x{host:x} [00800408/{pc:08x}/00000110/ff020200] f\n"
            ));
        }

        fn line(&mut self, text: &str) {
            self.text.push_str(text);
            self.text.push('\n');
        }

        /// One activation of USART2 with `trips` trips of its loop.
        fn control(&mut self, trips: u32) {
            self.control_ticked(trips, None);
        }

        /// One activation of USART2 with `trips` trips of its loop, preempted by
        /// SysTick after trip `tick`.
        fn control_ticked(&mut self, trips: u32, tick: Option<u32>) {
            self.tb(&[0x200, 0x202, 0x204, 0x206]);
            for trip in 1..trips {
                if tick == Some(trip) {
                    self.tb(&[0x400, 0x402]);
                    self.tb(&[0x120]);
                }
                self.tb(&[0x202, 0x204, 0x206]);
            }
            self.tb(&[0x208]);
        }
    }

    struct Fixture {
        program: Program,
        loops: Vec<Vec<Loop>>,
        roots: Vec<(String, usize)>,
    }

    fn fixture() -> Result<Fixture, Box<dyn std::error::Error>> {
        let raw = parse_disassembly(DISASSEMBLY);
        let program = build_program(
            &raw,
            &IndirectTargets::default(),
            &MemoryModel::TEST,
            |s: &str| s.to_string(),
        )?;
        let loops = program
            .functions
            .iter()
            .map(natural_loops)
            .collect::<Result<Vec<_>, _>>()?;
        let plan = program.at(0x0800_0100).ok_or("no USART1")?;
        let control = program.at(0x0800_0200).ok_or("no USART2")?;
        let systick = program.at(0x0800_0400).ok_or("no SysTick")?;
        Ok(Fixture {
            program,
            loops,
            roots: vec![
                ("plan".into(), plan),
                ("control".into(), control),
                ("systick".into(), systick),
            ],
        })
    }

    /// The trace of the synthetic program: idle, then plan with trip counts 4, 7, 5;
    /// the second preempted three times by control (after a `bl`, in the middle of
    /// a block split over two TBs, at a TB boundary that is a block boundary); the
    /// first with a rewound TB and a stopped one.
    fn synthetic_log() -> String {
        let mut log = Log::default();
        log.tb(&[0x300, 0x302]);
        log.tb(&[0x300, 0x302]);
        for (activation, trips) in [4u32, 7, 5].into_iter().enumerate() {
            log.tb(&[0x100, 0x102, 0x104, 0x106]);
            for trip in 0..trips {
                match (activation, trip) {
                    (1, 2) => {
                        // Preempted after the bl, before the callee's first TB.
                        log.tb(&[0x108, 0x10a]);
                        log.control(3);
                        log.tb(&[0x120]);
                    }
                    (1, 4) => {
                        // The block split over two TBs, preempted in between.
                        log.tb(&[0x108]);
                        log.control(2);
                        log.tb(&[0x10a]);
                        log.tb(&[0x120]);
                    }
                    (0, 1) => {
                        // icount: the TB rewound at the bl, which runs alone.
                        log.tb(&[0x108, 0x10a]);
                        log.line("cpu_io_recompile: rewound execution of TB to 0800010a");
                        log.tb(&[0x10a]);
                        log.tb(&[0x120]);
                    }
                    _ => {
                        log.tb(&[0x108, 0x10a]);
                        log.tb(&[0x120]);
                    }
                }
                log.tb(&[0x10e]);
                if (activation, trip) == (1, 5) {
                    // Preempted between two TBs at a block boundary, and control
                    // preempted by SysTick (which ends in a tail call).
                    log.control_ticked(4, Some(2));
                }
                if (activation, trip) == (0, 2) {
                    // Started, stopped before it ran, started again.
                    log.tb(&[0x104, 0x106]);
                    let host = log.host(&[0x104, 0x106]);
                    log.line(&format!(
                        "Stopped execution of TB chain before 0x{host:x} [08000104] f"
                    ));
                }
                log.tb(&[0x104, 0x106]);
            }
            log.tb(&[0x110]);
            log.tb(&[0x300, 0x302]);
        }
        // A control activation from idle.
        log.control(6);
        log.tb(&[0x300, 0x302]);
        log.text
    }

    fn loop_of(check: &TraceCheck, function: usize) -> Result<&LoopObservation, String> {
        check
            .loops
            .iter()
            .find(|l| l.function == function)
            .ok_or_else(|| format!("no loop seen in function {function}"))
    }
    #[test]
    fn loops_and_activations_of_a_synthetic_trace() -> Result<(), Box<dyn std::error::Error>> {
        let fx = fixture()?;
        let log = synthetic_log();
        let check = check_trace(log.as_bytes(), &fx.program, &fx.loops, &fx.roots)?;
        assert_eq!(check.unexpected_transfers, 0, "{:?}", check.examples);
        assert_eq!(check.outside_functions, 0);
        assert_eq!(check.untraced_executions, 0);
        assert_eq!(check.abandoned_executions, 2);
        let (plan, control) = (fx.roots[0].1, fx.roots[1].1);
        // Top-tested loop: n trips are n back edges.
        let l = loop_of(&check, plan)?;
        assert_eq!(l.entries, 3);
        assert_eq!(l.max_back_edges, 7);
        assert_eq!(l.back_edges, 4 + 7 + 5);
        assert_eq!(l.back_edges_without_entry, 0);
        assert_eq!(l.header, 0x0800_0104);
        assert_eq!(l.by_context, vec![("plan".to_string(), 3, 7)]);
        // Bottom-tested loop: n trips are n - 1 back edges; activations 3, 2, 4, 6.
        let l = loop_of(&check, control)?;
        assert_eq!(l.entries, 4);
        assert_eq!(l.max_back_edges, 5);
        assert_eq!(l.back_edges, 2 + 1 + 3 + 5);
        // The idle loop: entered once, iterated at every return to thread mode.
        let main = fx.program.at(0x0800_0300).ok_or("no main")?;
        let l = loop_of(&check, main)?;
        assert_eq!((l.entries, l.back_edges), (1, 5));
        assert_eq!(check.loops_of("thread").len(), 1);

        // Activation costs: the executed blocks' static costs.
        let blocks = |f: usize| &fx.program.functions[f].blocks;
        let cost = |f: usize, counts: &[u64]| -> (u64, u64) {
            blocks(f)
                .iter()
                .zip(counts)
                .fold((0, 0), |(i, c), (b, &n)| {
                    (i + n * b.instructions, c + n * b.cycles)
                })
        };
        let helper = fx.program.at(0x0800_0120).ok_or("no helper")?;
        assert_eq!(blocks(plan).len(), 4);
        // Less what the fall-throughs save: into the loop (one line already
        // read), out of it into the call (the `beq` not taken, the same line);
        // and the back edge's target, in the line of its `b` (in the cache).
        let plan_cost = |n: u64| {
            let (i, c) = cost(plan, &[1, n + 1, n, 1]);
            let (hi, hc) = cost(helper, &[n]);
            (i + hi, c + hc - 6 - 9 * n - 6 * n)
        };
        assert_eq!(blocks(plan)[0].fall_through_saving, (0, 6));
        assert_eq!(blocks(plan)[1].fall_through_saving, (3, 6));
        // control's loop calls nothing and fits a line: the line is fetched once
        // per entry (6), its block's own fetch not per trip; the fall-through in
        // (-6) and out (`bne` not taken, same line: -9).
        let control_cost = |n: u64| {
            let (i, c) = cost(control, &[1, n, 1]);
            (i, c - n * blocks(control)[1].fetch_cycles + 6 - 6 - 9)
        };
        assert_eq!(blocks(control)[1].fetch_cycles, 6);
        let p = &check.roots[0];
        assert_eq!(p.activations, 3);
        assert_eq!((p.max_instructions, p.max_cycles), plan_cost(7));
        assert_eq!(p.max_instructions, 5 + 6 * 7);
        assert_eq!(p.max_executed, p.max_instructions);
        assert_eq!(
            p.total_instructions,
            plan_cost(4).0 + plan_cost(7).0 + plan_cost(5).0
        );
        assert_eq!(
            p.total_cycles,
            plan_cost(4).1 + plan_cost(7).1 + plan_cost(5).1
        );
        assert_eq!(p.preempted_activations, 1);
        assert_eq!(p.incomplete, 0);
        let c = &check.roots[1];
        assert_eq!(c.activations, 4);
        assert_eq!((c.max_instructions, c.max_cycles), control_cost(6));
        assert_eq!(
            c.total_instructions,
            [3, 2, 4, 6].iter().map(|&n| control_cost(n).0).sum::<u64>()
        );
        let t = &check.roots[2];
        assert_eq!((t.activations, t.max_instructions), (1, 2 + 1));
        assert_eq!(c.preempted_activations, 1);
        assert_eq!(check.exception_entries, 3 + 4 + 1);
        // Every replayed instruction was in a block counted once.
        let all: u64 = check.roots.iter().map(|r| r.total_instructions).sum();
        assert_eq!(check.instructions, all + 6 * 2);
        Ok(())
    }

    #[test]
    fn counters_per_activation_call_and_loop_entry_and_sections(
    ) -> Result<(), Box<dyn std::error::Error>> {
        let fx = fixture()?;
        let log = synthetic_log();
        let (plan, systick) = (fx.roots[0].1, fx.roots[2].1);
        let helper = fx.program.at(0x0800_0120).ok_or("no helper")?;
        let counters = vec![
            // The plan loop's back edge (block 2 → header 1), per activation.
            CounterSpec {
                scope: CounterScope::Activation,
                blocks: vec![],
                edges: vec![(plan, 2, 1)],
            },
            // The same per call of USART1 (its activation's frame).
            CounterSpec {
                scope: CounterScope::Call(plan),
                blocks: vec![],
                edges: vec![(plan, 2, 1)],
            },
            // The loop body's block per entry of the loop.
            CounterSpec {
                scope: CounterScope::LoopEntry(plan, 0),
                blocks: vec![(plan, 2)],
                edges: vec![],
            },
            // helper's entry per activation, whoever runs it: called by plan,
            // tail-called by SysTick.
            CounterSpec {
                scope: CounterScope::Activation,
                blocks: vec![],
                edges: vec![(helper, usize::MAX, 0)],
            },
        ];
        let sections = vec![("helper".to_string(), helper)];
        let handlers: Vec<usize> = Vec::new();
        let check = replay_trace(
            log.as_bytes(),
            &fx.program,
            &fx.loops,
            &fx.roots,
            &handlers,
            &counters,
            &sections,
        )?;
        let c = &check.counters;
        assert_eq!((c[0].scopes, c[0].max, c[0].total), (3, 7, 4 + 7 + 5));
        assert_eq!(c[0].by_root, vec![("plan".to_string(), 7)]);
        assert_eq!((c[1].scopes, c[1].max), (3, 7));
        // Top-tested: the body runs once per trip, 4, 7 and 5 per entry.
        assert_eq!((c[2].scopes, c[2].max, c[2].total), (3, 7, 16));
        assert_eq!(
            c[3].by_root,
            vec![("plan".to_string(), 7), ("systick".to_string(), 1)]
        );
        let s = &check.sections[0];
        // Called 16 times (SysTick's tail call is no call); one `bx lr` each.
        assert_eq!((s.calls, s.max_instructions), (16, 1));
        assert_eq!(s.max_cycles, fx.program.functions[helper].blocks[0].cycles);
        let _ = systick;
        // No indirect call in the synthetic program.
        assert!(check.indirect_calls.is_empty());
        Ok(())
    }

    #[test]
    fn bounds_below_the_observation_are_violations() -> Result<(), Box<dyn std::error::Error>> {
        let fx = fixture()?;
        let log = synthetic_log();
        let check = check_trace(log.as_bytes(), &fx.program, &fx.loops, &fx.roots)?;
        let plan = fx.roots[0].1;
        assert!(check.violations(&[(plan, 0, 7)]).is_empty());
        let v = check.violations(&[(plan, 0, 6)]);
        assert_eq!(v.len(), 1);
        assert!(
            v[0].contains("USART1") && v[0].contains("0x08000104"),
            "{v:?}"
        );
        assert!(
            v[0].contains("bound 6") && v[0].contains("observed 7"),
            "{v:?}"
        );
        // A loop never seen is no violation.
        assert!(check.violations(&[(plan, 5, 0)]).is_empty());
        Ok(())
    }

    #[test]
    fn a_trace_line_without_pc_is_named() -> Result<(), Box<dyn std::error::Error>> {
        let fx = fixture()?;
        let err = check_trace(
            "Trace 0: garbage\n".as_bytes(),
            &fx.program,
            &fx.loops,
            &fx.roots,
        );
        assert!(matches!(err, Err(WcetError::LogFormat { line: 1, .. })));
        Ok(())
    }

    /// Tool, not a check: `TRACE_CHECK_LOG=qemu.log TRACE_CHECK_ELF=ecu cargo test
    /// --release -p wcet --lib trace_check::tests::check_the_trace_in_trace_check_log
    /// -- --ignored --nocapture` replays a saved PIL trace against the ELF's graphs
    /// (roots `USART1` plan, `USART2` control, `SysTick` systick) and prints the
    /// result.
    #[test]
    #[ignore = "needs a QEMU log in TRACE_CHECK_LOG and its ELF in TRACE_CHECK_ELF"]
    fn check_the_trace_in_trace_check_log() -> Result<(), Box<dyn std::error::Error>> {
        let log = std::env::var("TRACE_CHECK_LOG")?;
        let elf = std::path::PathBuf::from(std::env::var("TRACE_CHECK_ELF")?);
        let objdump = crate::stack::llvm_objdump_path()?;
        let out = std::process::Command::new(objdump)
            .arg("-d")
            .arg(&elf)
            .output()?;
        let text = String::from_utf8_lossy(&out.stdout);
        let raw = parse_disassembly(&text);
        let program = build_program(
            &raw,
            &IndirectTargets::default(),
            &MemoryModel::TEST,
            crate::demangle,
        )?;
        let loops: Vec<Vec<Loop>> = program
            .functions
            .iter()
            .map(|f| natural_loops(f).unwrap_or_default())
            .collect();
        let mut roots = Vec::new();
        for (task, symbol) in [
            ("plan", "USART1"),
            ("control", "USART2"),
            ("systick", "SysTick"),
        ] {
            let f = *program.find(symbol).first().ok_or(symbol)?;
            roots.push((task.to_string(), f));
        }
        let handlers = vector_table_handlers(&elf, &program)?;
        let file = std::fs::File::open(&log)?;
        let check = check_trace_with_handlers(
            std::io::BufReader::with_capacity(1 << 20, file),
            &program,
            &loops,
            &roots,
            &handlers,
        )?;
        let mut summary = check.clone();
        summary.loops.clear();
        eprintln!("{}", serde_json::to_string_pretty(&summary)?);
        let mut seen = check.loops.clone();
        seen.sort_by_key(|l| std::cmp::Reverse(l.max_back_edges));
        for l in &seen {
            eprintln!(
                "max {:>6} entries {:>6} back edges {:>8} without entry {} {:#010x} {} #{} {:?}",
                l.max_back_edges,
                l.entries,
                l.back_edges,
                l.back_edges_without_entry,
                l.header,
                l.function_name,
                l.loop_index,
                l.by_context
            );
        }
        Ok(())
    }
}
