//! The ART accelerator's data cache, for the cycle bounds: which literal-pool
//! loads hit on every path, and so do not pay the flash's wait states.
//!
//! RM0090 §3.5.2 (STM32F405): literal pools are read from flash through the
//! DCode bus; with `DCEN` set in `FLASH_ACR` (the ECU's clock set-up sets it,
//! `firmware::clock_tree`) every 128-bit line read so is copied into a data
//! cache of [`DATA_CACHE_LINES`] lines, replaced least recently used once full.
//! A read of a line the cache holds costs no wait state.
//!
//! The classification is the LRU *must* analysis (Ferdinand and Wilhelm, 1999)
//! over each function's control-flow graph: the abstract state maps each line
//! surely cached to an upper bound of its age (0 for the most recently used).
//! An access to a known line makes it the youngest and ages the lines younger
//! than it was; an access to an unknown line (a table branch's entry, a load
//! through a register in a function that may read flash) ages every line; a
//! line aged to [`DATA_CACHE_LINES`] is no longer sure. At a join, a line stays
//! sure only if it is on every incoming path, with the older of its ages. A call
//! forgets everything (the callee may read any line), and so does the
//! function's entry. A load whose lines are all sure before it executes hits on
//! every path to it: its block is charged no wait states for it
//! ([`must_hits`]).
//!
//! A preemption may evict the lines: the response-time analysis charges each
//! preemption the reload of the lines the preempting activation can read
//! ([`evicting_lines`], at most the whole data cache) besides the instruction
//! cache's refill ([`super::cache::PREEMPTION_REFILL_CYCLES`]).

use super::disassembly::{parse_imm, strip_condition, Instruction};
use super::memory_model::{flash_read, FlashRead};
use std::collections::{BTreeMap, BTreeSet};

/// Lines of the ART's data cache (RM0090 §3.5.2: 8 lines of 128 bits).
pub const DATA_CACHE_LINES: u32 = 8;

/// The must-cache state: line → upper bound of its age, every age below
/// [`DATA_CACHE_LINES`].
type State = BTreeMap<u64, u32>;

/// What an instruction does to the data cache.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    /// Nothing (no flash data read, or not through the cache).
    None,
    /// A pc-relative load of these lines (first, last).
    Lines(u64, u64),
    /// A flash read of a line not known statically.
    Unknown,
    /// A call: the callee may read anything.
    Call,
}

/// The flash lines (address / `line_bytes`) a pc-relative load reads: `ldr`,
/// `ldrh`, `ldrb`, `ldrsh`, `ldrsb`, `ldrd` and `vldr` with `[pc, #imm]`, whose
/// address is the instruction's, plus 4, rounded down to a word, plus `imm`.
pub fn literal_lines(i: &Instruction, line_bytes: u32) -> Option<(u64, u64)> {
    let base = strip_condition(i.base());
    let size: i64 = match base {
        "ldr" => 4,
        "ldrh" | "ldrsh" => 2,
        "ldrb" | "ldrsb" => 1,
        "ldrd" => 8,
        "vldr" => {
            if i.first_operand().starts_with('d') {
                8
            } else {
                4
            }
        }
        _ => return None,
    };
    let inside = i.operands.split_once("[pc")?.1;
    let inside = inside.split(']').next()?;
    let imm: i64 = match inside.split_once('#') {
        None if inside.trim().is_empty() => 0,
        None => return None,
        Some((_, v)) => {
            let v = v.trim();
            match v.strip_prefix('-') {
                Some(neg) => -i64::from(parse_imm(neg)?),
                None => i64::from(parse_imm(v)?),
            }
        }
    };
    let address = i64::from((i.address + 4) & !3) + imm;
    let line = i64::from(line_bytes.max(1));
    (address >= 0).then(|| {
        (
            (address / line) as u64,
            ((address + size - 1) / line) as u64,
        )
    })
}

/// What instruction `i` does to the data cache; `through_registers`: its
/// function's loads not relative to sp or pc may read flash.
fn access(i: &Instruction, line_bytes: u32, through_registers: bool) -> Access {
    if matches!(strip_condition(i.base()), "bl" | "blx") {
        return Access::Call;
    }
    // The reads the memory model charges wait states for, and only those.
    match flash_read(i, through_registers) {
        FlashRead::No => Access::None,
        FlashRead::LiteralPool => {
            literal_lines(i, line_bytes).map_or(Access::Unknown, |(lo, hi)| Access::Lines(lo, hi))
        }
        FlashRead::Table | FlashRead::ThroughRegister => Access::Unknown,
    }
}

/// Ages every line younger than `than` by one, dropping those that reach the
/// cache's size.
fn age(state: &mut State, than: u32) {
    state.retain(|_, a| {
        if *a < than {
            *a += 1;
        }
        *a < DATA_CACHE_LINES
    });
}

/// Applies one access; true when it is a pc-relative load whose lines were all
/// sure before it.
fn apply(state: &mut State, access: &Access) -> bool {
    match *access {
        Access::None => false,
        Access::Call => {
            state.clear();
            false
        }
        Access::Unknown => {
            age(state, DATA_CACHE_LINES);
            false
        }
        Access::Lines(lo, hi) => {
            let hit = (lo..=hi).all(|l| state.contains_key(&l));
            for l in lo..=hi {
                let was = state.get(&l).copied().unwrap_or(DATA_CACHE_LINES);
                age(state, was);
                state.insert(l, 0);
            }
            hit
        }
    }
}

/// Applies one instruction's access, which may not happen when `conditional`
/// (in an IT block): then the state is the join of both outcomes. True when it
/// is a pc-relative load whose lines were all sure before it.
fn step(state: &mut State, (access, conditional): &(Access, bool)) -> bool {
    if *conditional {
        let before = state.clone();
        let hit = apply(state, access);
        *state = join(&before, state);
        hit
    } else {
        apply(state, access)
    }
}

/// The flash lines a function's instructions can read as data, `None` when
/// some read's line is not known statically (a table branch, a load through a
/// register in a function that may read flash).
pub fn lines_read(
    instructions: &[Instruction],
    line_bytes: u32,
    through_registers: bool,
) -> Option<BTreeSet<u64>> {
    let mut lines = BTreeSet::new();
    for i in instructions {
        match access(i, line_bytes, through_registers) {
            Access::Lines(lo, hi) => lines.extend(lo..=hi),
            Access::Unknown => return None,
            Access::None | Access::Call => {}
        }
    }
    Some(lines)
}

/// Per instruction, whether an IT instruction before it makes it conditional
/// (`it` covers one, `itt`/`ite` two, up to four).
fn in_it_blocks(instructions: &[Instruction]) -> Vec<bool> {
    let mut out = vec![false; instructions.len()];
    let mut left = 0usize;
    for (x, i) in instructions.iter().enumerate() {
        if left > 0 {
            out[x] = true;
            left -= 1;
            continue;
        }
        let m = i.base();
        if m.len() <= 5 && m.starts_with("it") && m[2..].chars().all(|c| c == 't' || c == 'e') {
            left = m.len() - 1;
        }
    }
    out
}

/// The join of two must states: the lines in both, each with its older age.
fn join(a: &State, b: &State) -> State {
    a.iter()
        .filter_map(|(l, &x)| b.get(l).map(|&y| (*l, x.max(y))))
        .collect()
}

/// A block of a function's graph as the must analysis walks it.
pub trait BlockShape {
    /// The indices of its instructions in the function's.
    fn instructions(&self) -> std::ops::Range<usize>;
    /// The blocks control may pass to after it.
    fn successors(&self) -> &[usize];
}

/// Per block of a function, how many of its pc-relative loads hit the data
/// cache on every path (the must analysis of the module docs). `instructions`
/// and `blocks` are the function's; `through_registers`: its loads through a
/// register may read flash.
pub fn must_hits<B: BlockShape>(
    instructions: &[Instruction],
    blocks: &[B],
    line_bytes: u32,
    through_registers: bool,
) -> Vec<u64> {
    let n = blocks.len();
    let conditional = in_it_blocks(instructions);
    let accesses: Vec<Vec<(Access, bool)>> = blocks
        .iter()
        .map(|b| {
            b.instructions()
                .map(|x| {
                    let a = access(&instructions[x], line_bytes, through_registers);
                    (a, conditional[x])
                })
                .collect()
        })
        .collect();
    // In-states; `None`: not reached yet. The entry starts cold, and so does a
    // block nothing reaches (never executed; cold is safe).
    let mut input: Vec<Option<State>> = vec![None; n];
    if n > 0 {
        input[0] = Some(State::new());
    }
    let mut work: Vec<usize> = (0..n).rev().collect();
    let mut queued = vec![true; n];
    while let Some(b) = work.pop() {
        queued[b] = false;
        let mut state = input[b].clone().unwrap_or_default();
        for a in &accesses[b] {
            step(&mut state, a);
        }
        for &s in blocks[b].successors() {
            let next = match &input[s] {
                None => state.clone(),
                Some(old) => join(old, &state),
            };
            // The entry stays cold whatever jumps back to it.
            let next = if s == 0 { State::new() } else { next };
            if input[s].as_ref() != Some(&next) {
                input[s] = Some(next);
                if !queued[s] {
                    queued[s] = true;
                    work.push(s);
                }
            }
        }
    }
    (0..n)
        .map(|b| {
            let mut state = input[b].clone().unwrap_or_default();
            accesses[b].iter().filter(|a| step(&mut state, a)).count() as u64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn insn(address: u32, mnemonic: &str, operands: &str) -> Instruction {
        Instruction {
            address,
            bytes: 4,
            mnemonic: mnemonic.to_string(),
            operands: operands.to_string(),
            target: None,
        }
    }

    struct Shape(usize, usize, Vec<usize>);

    impl BlockShape for Shape {
        fn instructions(&self) -> std::ops::Range<usize> {
            self.0..self.1
        }
        fn successors(&self) -> &[usize] {
            &self.2
        }
    }

    fn block(first: usize, end: usize, successors: Vec<usize>) -> Shape {
        Shape(first, end, successors)
    }

    #[test]
    fn a_literal_address_is_the_word_aligned_pc_plus_the_offset() {
        // 0x8000480 + 4 = 0x8000484, + 420 = 0x8000628 (llvm-objdump's comment).
        let i = insn(0x0800_0480, "vldr", "s18, [pc, #420]");
        assert_eq!(
            literal_lines(&i, 16),
            Some((0x0800_0628 / 16, 0x0800_0628 / 16))
        );
        // A halfword-aligned instruction: pc rounded down to a word.
        let i = insn(0x0800_0482, "ldr.w", "r0, [pc, #0x10]");
        assert_eq!(
            literal_lines(&i, 16),
            Some((0x0800_0494 / 16, 0x0800_0494 / 16))
        );
        let i = insn(0x0800_0480, "ldr", "r0, [pc, #-8]");
        assert_eq!(
            literal_lines(&i, 16),
            Some((0x0800_047c / 16, 0x0800_047c / 16))
        );
        // A double across two lines.
        let i = insn(0x0800_0400, "vldr", "d0, [pc, #8]");
        assert_eq!(
            literal_lines(&i, 16),
            Some((0x0800_040c / 16, 0x0800_0413 / 16))
        );
        assert_eq!(literal_lines(&insn(0, "ldr", "r0, [r1, #4]"), 16), None);
    }

    #[test]
    fn a_second_load_of_a_line_hits_and_a_call_or_a_cold_entry_misses() {
        let code = vec![
            insn(0x100, "vldr", "s0, [pc, #12]"), // line of 0x110
            insn(0x104, "vldr", "s1, [pc, #8]"),  // the same line: hit
            insn(0x108, "bl", "0x200"),
            insn(0x10c, "vldr", "s2, [pc, #0]"), // 0x110 again, after a call: miss
        ];
        let hits = must_hits(&code, &[block(0, 4, vec![])], 16, false);
        assert_eq!(hits, vec![1]);
    }

    #[test]
    fn the_lines_a_function_reads_are_known_unless_it_reads_through_a_table_or_a_register() {
        let mut code = vec![
            insn(0x100, "vldr", "s0, [pc, #12]"), // 0x110
            insn(0x104, "ldr", "r0, [pc, #40]"),  // 0x130
            insn(0x108, "ldr", "r1, [r0, #4]"),
        ];
        assert_eq!(
            lines_read(&code, 16, false),
            Some(BTreeSet::from([0x11, 0x13]))
        );
        assert_eq!(lines_read(&code, 16, true), None);
        code.push(insn(0x10c, "tbb", "[pc, r1]"));
        assert_eq!(lines_read(&code, 16, false), None);
    }

    #[test]
    fn a_load_in_an_it_block_may_not_have_happened() {
        let code = vec![
            insn(0x100, "it", "ne"),
            insn(0x104, "ldrne", "r0, [pc, #8]"), // 0x110, maybe
            insn(0x108, "ldr", "r1, [pc, #4]"),   // 0x110: not sure
            insn(0x10c, "ldr", "r1, [pc, #0]"),   // 0x110: sure now
        ];
        assert_eq!(must_hits(&code, &[block(0, 4, vec![])], 16, false), vec![1]);
    }

    #[test]
    fn a_line_is_sure_after_a_join_only_if_every_path_loaded_it() {
        // 0: branch to 1 or 2; 1 loads line A; 2 loads line B; 3 loads A.
        let code = vec![
            insn(0x100, "cmp", "r0, #0"),
            insn(0x104, "vldr", "s0, [pc, #24]"), // 0x120
            insn(0x108, "vldr", "s0, [pc, #36]"), // 0x130
            insn(0x10c, "vldr", "s1, [pc, #16]"), // 0x120
        ];
        let blocks = vec![
            block(0, 1, vec![1, 2]),
            block(1, 2, vec![3]),
            block(2, 3, vec![3]),
            block(3, 4, vec![]),
        ];
        assert_eq!(must_hits(&code, &blocks, 16, false), vec![0, 0, 0, 0]);
        // Both paths load A: the load after the join hits.
        let code = vec![
            insn(0x100, "cmp", "r0, #0"),
            insn(0x104, "vldr", "s0, [pc, #24]"), // 0x120
            insn(0x108, "vldr", "s0, [pc, #20]"), // 0x120
            insn(0x10c, "vldr", "s1, [pc, #16]"), // 0x120
        ];
        assert_eq!(must_hits(&code, &blocks, 16, false), vec![0, 0, 0, 1]);
    }

    #[test]
    fn a_loop_hits_from_its_second_trip_only_on_lines_loaded_before_it() {
        // 0: loads A; 1 (loop header, back edge from itself): loads A and B.
        let code = vec![
            insn(0x100, "vldr", "s0, [pc, #28]"), // 0x120
            insn(0x104, "vldr", "s1, [pc, #24]"), // 0x120
            insn(0x108, "vldr", "s2, [pc, #36]"), // 0x130
            insn(0x10c, "bne", "0x104"),
        ];
        let blocks = vec![
            block(0, 1, vec![1]),
            block(1, 4, vec![1, 2]),
            block(4, 4, vec![]),
        ];
        // A is sure at the header from both edges; B only from the back edge.
        assert_eq!(must_hits(&code, &blocks, 16, false)[..2], [0, 1]);
    }

    #[test]
    fn nine_lines_evict_the_oldest_and_an_unknown_read_ages_all() {
        // Lines 0x200.. 0x280 (nine), then the first again: evicted.
        let mut code: Vec<Instruction> = (0..9u32)
            .map(|k| {
                insn(
                    0x100 + 4 * k,
                    "ldr",
                    &format!("r0, [pc, #{}]", 0x100 + 16 * k - 4 - 4 * k),
                )
            })
            .collect();
        code.push(insn(0x124, "ldr", &format!("r0, [pc, #{}]", 0x200 - 0x128)));
        assert_eq!(
            must_hits(&code, &[block(0, 10, vec![])], 16, false),
            vec![0]
        );
        // Eight lines, then the first again: still there.
        let mut code: Vec<Instruction> = code[..8].to_vec();
        code.push(insn(0x120, "ldr", &format!("r0, [pc, #{}]", 0x200 - 0x124)));
        assert_eq!(must_hits(&code, &[block(0, 9, vec![])], 16, false), vec![1]);
        // ... unless a load through a register in a function that may read flash
        // came in between (it may have been a ninth line).
        code.insert(8, insn(0x11e, "ldr", "r0, [r1, #0]"));
        assert_eq!(must_hits(&code, &[block(0, 10, vec![])], 16, true), vec![0]);
        // In a function whose register loads read only SRAM, it ages nothing.
        assert_eq!(
            must_hits(&code, &[block(0, 10, vec![])], 16, false),
            vec![1]
        );
    }
}
