//! Critical sections read off the binary: the code a task runs with every
//! interrupt masked (`cpsid i` up to the `msr primask` or `cpsie i` that ends it:
//! a `critical_section::with`, the release clock's slots) or with the
//! base priority raised to a resource's ceiling (`msr basepri_max` up to the
//! `msr basepri` that restores it: an RTIC lock). Each blocks the activities it
//! masks for its whole length, so the response-time analysis charges the longest
//! one of a lower priority as blocking ([`super::rta`]).
//!
//! A section's bound is the longest path through its blocks, each block at its
//! worst-case cycles times the iterations of the loops it sits in (loops wholly
//! inside the section, at their per-entry bounds), each call at its callee's own
//! bound: the section's blocks priced all at once, a sound over-approximation for
//! the short sections an application keeps. A section that leaves its function
//! before it ends, or that spans iterations of a loop it is inside, gets no bound
//! and says why.

use super::bounds::constant_before;
use super::cfg::{Exit, MemoryModel, Program};
use super::ipet::{back_edges_per_entry, LoopFact, Per};
use super::loops::Loop;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// Priority bits the NVIC implements (STM32F4: 4); `BASEPRI` holds the priority in
/// its top bits, `(2^bits − ceiling) << (8 − bits)` for an RTIC ceiling.
pub const NVIC_PRIO_BITS: u32 = 4;

/// The ceiling of an interrupts-disabled section: above every priority.
pub const ALL_MASKED: u8 = u8::MAX;

/// A critical section of a task's code.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CriticalSection {
    /// The task that runs it.
    pub task: String,
    /// Function holding it (demangled).
    pub function: String,
    /// Address of the instruction that starts it.
    pub start: u32,
    /// Its source location (`file:line`).
    pub source: String,
    /// The highest priority it masks: [`ALL_MASKED`] for interrupts disabled, an
    /// RTIC ceiling for a lock.
    pub ceiling: u8,
    /// Its bound, model cycles; `None` with `why` when it has none.
    pub bound_cycles: Option<u64>,
    /// Why there is no bound.
    pub why: Option<String>,
}

/// What starts a section at instruction `i` of block `b`: its ceiling, if any.
fn starts(f: &super::cfg::Function, preds: &[Vec<usize>], b: usize, i: usize) -> Option<u8> {
    let ins = &f.instructions[i];
    if is_cps(ins, "cpsid") {
        return Some(ALL_MASKED);
    }
    match ins.base() {
        "msr" if ins.first_operand() == "basepri_max" => {
            let reg = ins.operands.split(',').nth(1).unwrap_or("").trim();
            let v = constant_before(f, preds, b, i, reg, 4)?;
            let level = (v >> (8 - NVIC_PRIO_BITS)) as u32;
            // A lock raises BASEPRI to the ceiling's value; 0 would unmask all.
            (level > 0).then(|| (1u32 << NVIC_PRIO_BITS).saturating_sub(level) as u8)
        }
        _ => None,
    }
}

/// Whether `ins` is `cpsid i` / `cpsie i` (`which`): the disassembler prints the
/// interrupt flag with the mnemonic (`cpsid i`) or as its operand.
fn is_cps(ins: &super::cfg::Instruction, which: &str) -> bool {
    let text = format!("{} {}", ins.mnemonic, ins.operands);
    let mut words = text.split_whitespace();
    words.next() == Some(which) && words.next() == Some("i")
}

/// Whether instruction `i` ends a section of `ceiling`.
fn ends(f: &super::cfg::Function, i: usize, ceiling: u8) -> bool {
    let ins = &f.instructions[i];
    if ceiling == ALL_MASKED {
        is_cps(ins, "cpsie") || (ins.base() == "msr" && ins.first_operand() == "primask")
    } else {
        ins.base() == "msr" && ins.first_operand() == "basepri"
    }
}

/// Iterations per entry a loop fact allows (at most; a retry loop's one retry).
fn iterations(fact: &LoopFact, func: &super::cfg::Function, l: &Loop, shared: bool) -> u64 {
    match fact.per {
        Per::Entry => back_edges_per_entry(fact, func, l, shared) + 1,
        Per::Preemption | Per::Tick => 2,
        Per::Activation | Per::Counted(_) | Per::Call => fact.bound + 1,
    }
}

/// The bound of the section starting at instruction `at` of block `b0` of
/// function `f` with `ceiling`, or why there is none. `callee(g, preemptible)`
/// gives a called function's own bound in cycles: with the retries a preemption
/// can cause when the section does not mask every interrupt.
///
/// The phases: find the section's blocks, repeat those of the loops wholly
/// inside it, cost each block (its calls' bounds included), then take the
/// longest path.
#[allow(clippy::too_many_arguments)]
fn section_bound(
    program: &Program,
    memory: &MemoryModel,
    loops: &[Loop],
    facts: &[LoopFact],
    f: usize,
    b0: usize,
    at: usize,
    ceiling: u8,
    callee: &dyn Fn(usize, bool) -> Option<u64>,
) -> Result<u64, String> {
    let section = Section::find(&program.functions[f], b0, at, ceiling)?;
    let (times, cut) = section.repetitions(loops, facts, f)?;
    let mut cost: BTreeMap<usize, u64> = BTreeMap::new();
    for &b in &section.inside {
        let c = section.block_cost(program, memory, callee, b)?;
        cost.insert(b, c.saturating_mul(times[&b]));
    }
    section.longest_path(&cost, &cut)
}

/// A critical section's blocks in its function.
struct Section<'a> {
    func: &'a super::cfg::Function,
    /// The block it starts in.
    b0: usize,
    /// The instruction that starts it.
    at: usize,
    /// The priority it masks up to.
    ceiling: u8,
    /// Its blocks.
    inside: BTreeSet<usize>,
    /// The blocks it ends in, whose successors are not in it.
    ending: BTreeSet<usize>,
}

impl<'a> Section<'a> {
    /// The section's blocks: from `at` on, up to the instructions that end it;
    /// refused if it leaves the function or reaches its own start again.
    fn find(
        func: &'a super::cfg::Function,
        b0: usize,
        at: usize,
        ceiling: u8,
    ) -> Result<Self, String> {
        let mut inside: BTreeSet<usize> = BTreeSet::from([b0]);
        let mut ending: BTreeSet<usize> = BTreeSet::new();
        let mut stack = vec![b0];
        while let Some(b) = stack.pop() {
            let block = &func.blocks[b];
            let from = if b == b0 { at + 1 } else { block.first };
            if (from..block.end).any(|i| ends(func, i, ceiling)) {
                ending.insert(b);
                continue;
            }
            match &block.exit {
                Exit::NoReturn => continue,
                Exit::Return | Exit::TailCall(_) | Exit::IndirectTail(_) => {
                    return Err(format!(
                        "it leaves `{}` at {:#x} before it ends",
                        func.demangled, block.start
                    ))
                }
                Exit::Internal => {}
            }
            for &s in &block.successors {
                if s == b0 {
                    return Err(format!(
                        "it reaches its own start again at {:#x}: it spans a loop's iterations",
                        block.start
                    ));
                }
                if inside.insert(s) {
                    stack.push(s);
                }
            }
        }
        Ok(Self {
            func,
            b0,
            at,
            ceiling,
            inside,
            ending,
        })
    }

    /// Loops wholly inside repeat their blocks; a back edge of another loop inside
    /// the section means it spans that loop's iterations. Returns each block's
    /// repetitions and the back edges of the loops inside (`loops` and `facts`:
    /// function `f`'s loops and every loop bound).
    #[allow(clippy::type_complexity)]
    fn repetitions(
        &self,
        loops: &[Loop],
        facts: &[LoopFact],
        f: usize,
    ) -> Result<(BTreeMap<usize, u64>, BTreeSet<(usize, usize)>), String> {
        let (func, inside, ending) = (self.func, &self.inside, &self.ending);
        let mut times: BTreeMap<usize, u64> = inside.iter().map(|&b| (b, 1)).collect();
        let mut cut: BTreeSet<(usize, usize)> = BTreeSet::new();
        for (x, l) in loops.iter().enumerate() {
            let inner = l
                .blocks
                .iter()
                .all(|b| inside.contains(b) && !ending.contains(b));
            let crossing = l
                .back_edges
                .iter()
                .any(|(t, h)| inside.contains(t) && !ending.contains(t) && inside.contains(h));
            if !inner {
                if crossing {
                    return Err(format!(
                        "it spans iterations of the loop at {:#x} of `{}`",
                        func.blocks[l.header].start, func.demangled
                    ));
                }
                continue;
            }
            let shared = facts.iter().any(|g| g.function == f && g.group == Some(x));
            let Some(fact) = facts.iter().find(|q| q.function == f && q.loop_index == x) else {
                return Err(format!(
                    "the loop at {:#x} inside it has no bound",
                    func.blocks[l.header].start
                ));
            };
            let n = iterations(fact, func, l, shared);
            for b in &l.blocks {
                if let Some(t) = times.get_mut(b) {
                    *t = t.saturating_mul(n);
                }
            }
            cut.extend(l.back_edges.iter().copied());
        }
        Ok((times, cut))
    }

    /// Block `b`'s cost once: the cycles of its instructions inside the section
    /// (from the start, up to the end) and its calls' bounds there.
    fn block_cost(
        &self,
        program: &Program,
        memory: &MemoryModel,
        callee: &dyn Fn(usize, bool) -> Option<u64>,
        b: usize,
    ) -> Result<u64, String> {
        let (func, at, ceiling) = (self.func, self.at, self.ceiling);
        let block = &func.blocks[b];
        let (lo, from) = if b == self.b0 {
            (at, at + 1)
        } else {
            (block.first, block.first)
        };
        let hi = if self.ending.contains(&b) {
            (from..block.end)
                .find(|&i| ends(func, i, ceiling))
                .map_or(block.end, |e| e + 1)
        } else {
            block.end
        };
        let insns = &func.instructions[lo..hi];
        let mut c = memory.block_cycles(func.address, insns);
        // An indirect call may go to any of the block's resolved targets that no
        // direct call of the block names: the costliest is charged.
        let mut indirect: Vec<usize> = block.calls.clone();
        for i in &func.instructions[block.first..block.end] {
            if let Some(g) = i.target.and_then(|t| program.at(t)) {
                if let Some(k) = indirect.iter().position(|&x| x == g) {
                    indirect.remove(k);
                }
            }
        }
        let preemptible = ceiling != ALL_MASKED;
        let bound_of = |g: usize| {
            callee(g, preemptible).ok_or_else(|| {
                format!(
                    "its call of `{}` has no bound",
                    program.functions[g].demangled
                )
            })
        };
        for i in insns.iter().filter(|i| matches!(i.base(), "bl" | "blx")) {
            let cost = match i.target.and_then(|t| program.at(t)) {
                Some(g) => bound_of(g)?,
                None if indirect.is_empty() => {
                    return Err(format!(
                        "an indirect call at {:#x} inside it has no resolved target",
                        i.address
                    ))
                }
                None => indirect
                    .iter()
                    .map(|&g| bound_of(g))
                    .collect::<Result<Vec<u64>, String>>()?
                    .into_iter()
                    .max()
                    .unwrap_or(0),
            };
            c = c.saturating_add(cost);
        }
        Ok(c)
    }

    /// Longest path from the first block over the section's edges (each block
    /// at its `cost`), the back edges of the loops inside (`cut`) cut: a DAG, any
    /// other cycle was refused.
    fn longest_path(
        &self,
        cost: &BTreeMap<usize, u64>,
        cut: &BTreeSet<(usize, usize)>,
    ) -> Result<u64, String> {
        let (func, b0) = (self.func, self.b0);
        let next = |b: usize| -> Vec<usize> {
            if self.ending.contains(&b) {
                return Vec::new();
            }
            func.blocks[b]
                .successors
                .iter()
                .copied()
                .filter(|s| self.inside.contains(s) && !cut.contains(&(b, *s)))
                .collect()
        };
        let order = topological(func, &next, b0)?;
        let mut memo: BTreeMap<usize, u64> = BTreeMap::new();
        for &b in order.iter().rev() {
            let best = next(b)
                .iter()
                .filter_map(|s| memo.get(s).copied())
                .max()
                .unwrap_or(0);
            memo.insert(b, cost[&b].saturating_add(best));
        }
        memo.get(&b0)
            .copied()
            .ok_or_else(|| "no path through it".to_string())
    }
}

/// The section's blocks in an order where each comes before its successors
/// (`next`), from `start`; a cycle left is an error.
fn topological(
    func: &super::cfg::Function,
    next: &dyn Fn(usize) -> Vec<usize>,
    start: usize,
) -> Result<Vec<usize>, String> {
    // Depth-first post-order, then reversed.
    let mut state: BTreeMap<usize, u8> = BTreeMap::new();
    let mut post = Vec::new();
    let mut stack: Vec<(usize, usize)> = vec![(start, 0)];
    state.insert(start, 1);
    while let Some((b, k)) = stack.pop() {
        let succ = next(b);
        if let Some(&s) = succ.get(k) {
            stack.push((b, k + 1));
            match state.get(&s).copied().unwrap_or(0) {
                0 => {
                    state.insert(s, 1);
                    stack.push((s, 0));
                }
                1 => {
                    return Err(format!(
                        "a cycle through {:#x} inside it",
                        func.blocks[s].start
                    ))
                }
                _ => {}
            }
        } else {
            state.insert(b, 2);
            post.push(b);
        }
    }
    post.reverse();
    Ok(post)
}

/// Every critical section in the functions each task's completing activation
/// runs (`tasks`: name and reachable functions), with its bound.
pub fn critical_sections(
    program: &Program,
    memory: &MemoryModel,
    all_loops: &[Vec<Loop>],
    facts: &[LoopFact],
    tasks: &[(String, Vec<usize>)],
    callee: &dyn Fn(usize, bool) -> Option<u64>,
    locate: &dyn Fn(u32) -> String,
) -> Vec<CriticalSection> {
    let mut out = Vec::new();
    for (task, reach) in tasks {
        for &f in reach {
            let func = &program.functions[f];
            if !func.returns {
                continue;
            }
            let live = func.completing();
            let preds = func.predecessors();
            for (b, block) in func.blocks.iter().enumerate() {
                if !live.get(b).copied().unwrap_or(false) {
                    continue;
                }
                for i in block.first..block.end {
                    let Some(ceiling) = starts(func, &preds, b, i) else {
                        continue;
                    };
                    let loops = all_loops.get(f).map_or(&[][..], |v| v.as_slice());
                    let bound =
                        section_bound(program, memory, loops, facts, f, b, i, ceiling, callee);
                    let start = func.instructions[i].address;
                    out.push(CriticalSection {
                        task: task.clone(),
                        function: func.demangled.clone(),
                        start,
                        source: locate(start),
                        ceiling,
                        bound_cycles: bound.as_ref().ok().copied(),
                        why: bound.err(),
                    });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfg::{build_program, parse_disassembly, IndirectTargets};

    /// `task`: a section with interrupts disabled around two instructions, then a
    /// call outside it; a lock at ceiling 2 (`BASEPRI` 0xe0) around a call of
    /// `helper`.
    const TASK: &str = "
/tmp/ecu:\tfile format elf32-littlearm

Disassembly of section .text:

08000100 <task>:
 8000100: b580         \tpush\t{r7, lr}
 8000102: f3ef 8010    \tmrs\tr0, primask
 8000106: b672         \tcpsid i
 8000108: 2101         \tmovs\tr1, #0x1
 800010a: 3101         \tadds\tr1, #0x1
 800010c: f380 8810    \tmsr\tprimask, r0
 8000110: f000 f810    \tbl\t0x8000134 <helper>
 8000114: 21e0         \tmovs\tr1, #0xe0
 8000116: f3ef 8211    \tmrs\tr2, basepri
 800011a: f381 8812    \tmsr\tbasepri_max, r1
 800011e: f000 f809    \tbl\t0x8000134 <helper>
 8000122: f382 8811    \tmsr\tbasepri, r2
 8000126: bd80         \tpop\t{r7, pc}

08000134 <helper>:
 8000134: 3001         \tadds\tr0, #0x1
 8000136: 3001         \tadds\tr0, #0x1
 8000138: 4770         \tbx\tlr
";

    #[test]
    fn sections_are_priced_from_their_start_to_their_end_calls_included() -> Result<(), String> {
        let memory = MemoryModel::TEST;
        let program = build_program(
            &parse_disassembly(TASK),
            &IndirectTargets::default(),
            &memory,
            |s: &str| s.to_string(),
        )
        .map_err(|e| e.to_string())?;
        let task = program.at(0x0800_0100).ok_or("no task")?;
        let helper = program.at(0x0800_0134).ok_or("no helper")?;
        let loops: Vec<Vec<Loop>> = vec![Vec::new(); program.functions.len()];
        let helper_cycles = 100;
        let callee = |g: usize, _: bool| (g == helper).then_some(helper_cycles);
        let sections = critical_sections(
            &program,
            &memory,
            &loops,
            &[],
            &[("plan".to_string(), vec![task, helper])],
            &callee,
            &|a: u32| format!("{a:#x}"),
        );
        assert_eq!(sections.len(), 2, "{sections:?}");
        let f = &program.functions[task];
        let cycles = |from: u32, to: u32| {
            let insns: Vec<_> = f
                .instructions
                .iter()
                .filter(|i| i.address >= from && i.address <= to)
                .cloned()
                .collect();
            memory.block_cycles(f.address, &insns)
        };
        // Interrupts disabled: `cpsid i` to `msr primask`, not the call after it.
        let masked = &sections[0];
        assert_eq!((masked.start, masked.ceiling), (0x0800_0106, ALL_MASKED));
        assert_eq!(masked.bound_cycles, Some(cycles(0x0800_0106, 0x0800_010c)));
        // The lock: ceiling 2 from BASEPRI 0xe0, the call inside it charged.
        let lock = &sections[1];
        assert_eq!((lock.start, lock.ceiling), (0x0800_011a, 2));
        assert_eq!(
            lock.bound_cycles,
            Some(cycles(0x0800_011a, 0x0800_0122) + helper_cycles)
        );
        // A callee without a bound leaves the lock without one, saying why.
        let unbounded = critical_sections(
            &program,
            &memory,
            &loops,
            &[],
            &[("plan".to_string(), vec![task])],
            &|_, _| None,
            &|a: u32| format!("{a:#x}"),
        );
        assert_eq!(unbounded[1].bound_cycles, None);
        assert!(unbounded[1]
            .why
            .as_deref()
            .unwrap_or("")
            .contains("`helper` has no bound"));
        Ok(())
    }
}
