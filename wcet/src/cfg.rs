//! Control-flow graphs of a thumbv7em ELF, from its Thumb-2 disassembly.
//!
//! `llvm-objdump -d` (raw bytes shown) gives every function's instructions and the
//! data inside `.text` (literal pools, `tbb`/`tbh` tables, bracketed by the ELF's
//! mapping symbols). A function's basic blocks start at its entry, at every target
//! of a jump inside it (table entries included) and after every instruction that
//! ends a block: a jump, a conditional jump, a return, a tail call, a call of a
//! function that never returns. Calls (`bl`, resolved `blx`) do not end a block:
//! a block lists the functions it calls.
//!
//! An instruction inside an `IT` block is conditional: executed or not, its cost is
//! charged (the bound does not rely on the condition); a conditional jump or return
//! inside an `IT` block ends the block with two successors, as `b<cond>` does.
//!
//! Indirect calls and jumps (`blx rN`, `bx rN` other than `bx lr`, `ldr pc, ..` not
//! popping the stack) have no static target: they are resolved by a list of their
//! possible targets (see [`IndirectTargets`]), checked against the symbol table;
//! one the list does not cover is reported unresolved, which is an error of the
//! analysis.

use super::disassembly::{has_condition, it_length};
pub use super::disassembly::{
    parse_disassembly, strip_condition, DataRun, Instruction, RawFunction,
};
pub use super::flash_data::FlashData;
pub use super::memory_model::MemoryModel;
use super::WcetError;
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// How a block ends.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Exit {
    /// Falls through or jumps to its successors inside the function.
    Internal,
    /// Returns to the caller (possibly conditionally, with a fall-through successor).
    Return,
    /// Jumps to the entry of another function, which returns for this one.
    TailCall(usize),
    /// Calls a function that never returns (panics, the fault path): the activation
    /// does not complete through this block.
    NoReturn,
    /// An indirect jump (a tail call through a register) with the listed targets.
    IndirectTail(Vec<usize>),
}

/// A basic block.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Block {
    /// Address of its first instruction.
    pub start: u32,
    /// Index range of its instructions in the function's `instructions`.
    pub first: usize,
    /// One past its last instruction.
    pub end: usize,
    /// Successor blocks inside the function (indices).
    pub successors: Vec<usize>,
    /// Functions called from the block (indices into the program), once per call
    /// instruction.
    pub calls: Vec<usize>,
    /// How it ends.
    pub exit: Exit,
    /// What the analysis could not resolve in this block: an indirect call or jump
    /// no rule covers, a branch to an address that starts no function. An error
    /// when the block is reachable from a task.
    pub problems: Vec<String>,
    /// Instructions executed, counted as QEMU counts them (each instruction of the
    /// block once, conditional ones included).
    pub instructions: u64,
    /// Worst-case cycles (see [`MemoryModel`]).
    pub cycles: u64,
    /// Of `cycles`, the fetch of the flash lines the block's bytes touch (the
    /// lines of return addresses after calls not included); 0 outside flash.
    pub fetch_cycles: u64,
    /// The first and last flash line (address / line size) its bytes touch;
    /// `None` outside flash.
    pub lines: Option<(u64, u64)>,
    /// The successor control falls through to (the block starting where this one
    /// ends), when the block can fall through and that successor is not also the
    /// target of its jump.
    pub fall_through: Option<usize>,
    /// Cycles of `cycles` plus the fall-through successor's `cycles` that the
    /// fall-through edge does not spend ([`MemoryModel::fall_through_saving`]):
    /// `(refill, line)`, the branch not taken and the line already read.
    pub fall_through_saving: (u64, u64),
}

impl super::data_cache::BlockShape for Block {
    fn instructions(&self) -> std::ops::Range<usize> {
        self.first..self.end
    }

    fn successors(&self) -> &[usize] {
        &self.successors
    }
}

/// A function's control-flow graph.
#[derive(Debug, Clone)]
pub struct Function {
    /// Symbol (mangled).
    pub name: String,
    /// Demangled name without hash.
    pub demangled: String,
    /// Other symbols at its address.
    pub aliases: Vec<String>,
    /// Entry address.
    pub address: u32,
    /// Instructions.
    pub instructions: Vec<Instruction>,
    /// Blocks; block 0 is the entry.
    pub blocks: Vec<Block>,
    /// `false` when no path returns (panic handlers, `exit`).
    pub returns: bool,
    /// The flash lines it can read as data (`data_cache::lines_read`; `None`:
    /// a line not known statically).
    pub data_lines: Option<std::collections::BTreeSet<u64>>,
}

impl Function {
    /// The block holding the instruction at `address`.
    pub fn block_at(&self, address: u32) -> Option<usize> {
        let i = self.blocks.partition_point(|b| b.start <= address);
        let b = i.checked_sub(1)?;
        let block = self.blocks.get(b)?;
        let last = self.instructions.get(block.end.checked_sub(1)?)?;
        (address <= last.address).then_some(b)
    }

    /// Predecessors of each block.
    pub fn predecessors(&self) -> Vec<Vec<usize>> {
        let mut preds = vec![Vec::new(); self.blocks.len()];
        for (b, block) in self.blocks.iter().enumerate() {
            for &s in &block.successors {
                if let Some(p) = preds.get_mut(s) {
                    p.push(b);
                }
            }
        }
        preds
    }

    /// Which blocks can complete: some path from them returns (or tail-calls)
    /// without a call that never returns. The others end the activation (a panic,
    /// the fault path, the end of the run): the analysis excludes them, their loops
    /// and their calls.
    pub fn completing(&self) -> Vec<bool> {
        let preds = self.predecessors();
        let mut done = vec![false; self.blocks.len()];
        let mut stack: Vec<usize> = self
            .blocks
            .iter()
            .enumerate()
            .filter(|(_, b)| {
                matches!(
                    b.exit,
                    Exit::Return | Exit::TailCall(_) | Exit::IndirectTail(_)
                )
            })
            .map(|(k, _)| k)
            .collect();
        while let Some(b) = stack.pop() {
            if std::mem::replace(&mut done[b], true) {
                continue;
            }
            for &p in &preds[b] {
                if !done[p] && self.blocks[p].exit != Exit::NoReturn {
                    stack.push(p);
                }
            }
        }
        done
    }
}

/// Targets of the indirect calls and jumps, by the function they are in: a caller
/// (demangled prefix) to its possible callees (demangled prefixes), each of which
/// must match at least one symbol.
#[derive(Debug, Clone, Default)]
pub struct IndirectTargets {
    /// `(caller prefix, callee prefixes)`.
    pub rules: Vec<(String, Vec<String>)>,
}

impl IndirectTargets {
    /// The callees listed for `caller` (demangled) by every rule whose prefix it
    /// starts with; `None` when no rule covers it.
    pub fn callees_of(&self, caller: &str) -> Option<Vec<&str>> {
        let mut covered = false;
        let mut out = Vec::new();
        for (prefix, callees) in &self.rules {
            if caller.starts_with(prefix.as_str()) {
                covered = true;
                out.extend(callees.iter().map(String::as_str));
            }
        }
        covered.then_some(out)
    }

    /// Whether a function, by its demangled name and its symbols, is the listed
    /// callee `callee` (a demangled prefix or an exact symbol).
    pub fn lists<'a>(
        callee: &str,
        demangled: &str,
        mut symbols: impl Iterator<Item = &'a str>,
    ) -> bool {
        demangled.starts_with(callee) || symbols.any(|s| s == callee)
    }
}

/// The whole program's graphs.
#[derive(Debug, Clone)]
pub struct Program {
    /// Functions in address order.
    pub functions: Vec<Function>,
    /// Cycles of one flash line fetch ([`MemoryModel::line_fetch_cycles`]).
    pub line_fetch_cycles: u64,
    by_address: HashMap<u32, usize>,
}

impl Program {
    /// The function starting at `address`.
    pub fn at(&self, address: u32) -> Option<usize> {
        self.by_address.get(&(address & !1)).copied()
    }

    /// The function containing `address`.
    pub fn containing(&self, address: u32) -> Option<usize> {
        let i = self.functions.partition_point(|f| f.address <= address);
        let f = i.checked_sub(1)?;
        let func = self.functions.get(f)?;
        let last = func.instructions.last()?;
        (address < last.address + last.bytes).then_some(f)
    }

    /// Functions whose symbol, alias or demangled name (without hash) equals `name`,
    /// or else whose demangled name starts with it.
    pub fn find(&self, name: &str) -> Vec<usize> {
        let exact: Vec<usize> = (0..self.functions.len())
            .filter(|&i| {
                let f = &self.functions[i];
                f.name == name || f.demangled == name || f.aliases.iter().any(|a| a == name)
            })
            .collect();
        if !exact.is_empty() {
            return exact;
        }
        (0..self.functions.len())
            .filter(|&i| self.functions[i].demangled.starts_with(name))
            .collect()
    }

    /// Functions `f` calls, tail-calls or may reach through a resolved indirect
    /// call or jump.
    pub fn callees(&self, f: usize) -> BTreeSet<usize> {
        self.callees_from(f, |_| true)
    }

    /// The functions `f` calls or tail-calls from its blocks that can complete
    /// ([`Function::completing`]): the calls on paths that end the activation
    /// (the stop and fault paths) left out.
    pub fn completing_callees(&self, f: usize) -> BTreeSet<usize> {
        let live = self.functions[f].completing();
        self.callees_from(f, |b| live[b])
    }

    /// The functions `f` calls or tail-calls from the blocks `take` accepts.
    fn callees_from(&self, f: usize, take: impl Fn(usize) -> bool) -> BTreeSet<usize> {
        let mut s = BTreeSet::new();
        for (b, block) in self.functions[f].blocks.iter().enumerate() {
            if !take(b) {
                continue;
            }
            s.extend(block.calls.iter().copied());
            match &block.exit {
                Exit::TailCall(t) => {
                    s.insert(*t);
                }
                Exit::IndirectTail(ts) => s.extend(ts.iter().copied()),
                _ => {}
            }
        }
        s
    }

    /// Functions an activation that completes can run, from `roots` through
    /// [`Self::completing_callees`] (roots included), in discovery order.
    pub fn completing_reachable(&self, roots: &[usize]) -> Vec<usize> {
        self.reach_through(roots, |f| self.completing_callees(f))
    }

    /// Functions reachable from `roots` through [`Self::callees`] (roots
    /// included), in discovery order.
    pub fn reachable(&self, roots: &[usize]) -> Vec<usize> {
        self.reach_through(roots, |f| self.callees(f))
    }

    /// Functions reachable from `roots` through `next`, in discovery order.
    fn reach_through(
        &self,
        roots: &[usize],
        next: impl Fn(usize) -> BTreeSet<usize>,
    ) -> Vec<usize> {
        let mut seen = vec![false; self.functions.len()];
        let mut order = Vec::new();
        let mut stack: Vec<usize> = roots.to_vec();
        while let Some(f) = stack.pop() {
            if std::mem::replace(&mut seen[f], true) {
                continue;
            }
            order.push(f);
            stack.extend(next(f));
        }
        order
    }

    /// Cycles in the call graph reachable from `roots` (each as its function names):
    /// recursion, which the analysis refuses.
    pub fn recursions(&self, roots: &[usize]) -> Vec<Vec<String>> {
        super::graph::cyclic_components(self.functions.len(), self.reachable(roots), |f| {
            self.callees(f).into_iter().collect()
        })
        .into_iter()
        .map(|c| {
            c.iter()
                .map(|&f| self.functions[f].demangled.clone())
                .collect()
        })
        .collect()
    }
}

/// What one instruction does to control flow.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Flow {
    Straight,
    Call(u32),
    IndirectCall,
    Jump { target: u32, conditional: bool },
    Return { conditional: bool },
    IndirectJump { conditional: bool },
    Table,
    Trap,
}

fn flow(i: &Instruction, in_it: bool) -> Flow {
    let base = i.base();
    let plain = strip_condition(base);
    let conditional = has_condition(base) || in_it;
    match plain {
        "bl" => i.target.map_or(Flow::IndirectCall, Flow::Call),
        "blx" => match i.target {
            Some(t) => Flow::Call(t),
            None => Flow::IndirectCall,
        },
        "b" | "cbz" | "cbnz" => match i.target {
            Some(target) => Flow::Jump {
                target,
                conditional: conditional || plain != "b",
            },
            None => Flow::IndirectJump { conditional },
        },
        "bx" if i.first_operand() == "lr" => Flow::Return { conditional },
        "bx" => Flow::IndirectJump { conditional },
        "tbb" | "tbh" => Flow::Table,
        "udf" => Flow::Trap,
        _ if i.pops_pc() => Flow::Return { conditional },
        "mov" | "ldr" | "add" if i.first_operand() == "pc" => Flow::IndirectJump { conditional },
        _ => Flow::Straight,
    }
}

/// Targets of a `tbb`/`tbh` at index `at`: the table follows the instruction, its
/// entries are halfword offsets from the instruction's address + 4.
fn table_targets(f: &RawFunction, at: usize) -> Vec<u32> {
    let Some(i) = f.instructions.get(at) else {
        return Vec::new();
    };
    let base = i.address + 4;
    let Some(data) = f.data.iter().find(|d| d.address == base) else {
        return Vec::new();
    };
    let halfword = strip_condition(i.base()) == "tbh";
    let entries: Vec<u32> = if halfword {
        data.bytes
            .chunks_exact(2)
            .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]])))
            .collect()
    } else {
        data.bytes.iter().map(|&b| u32::from(b)).collect()
    };
    let starts: BTreeSet<u32> = f.instructions.iter().map(|i| i.address).collect();
    entries
        .into_iter()
        .map(|e| base + 2 * e)
        // A padding byte at the table's end points into the table itself.
        .filter(|t| starts.contains(t))
        .collect()
}

/// Builds every function's graph. `indirect` lists the targets of indirect calls;
/// `demangle` gives the demangled name without hash.
///
/// Two passes: each function's block boundaries and control flow, then (once
/// it is known which functions return) its blocks, a call of a function that
/// never returns ending its block.
pub fn build_program(
    raw: &[RawFunction],
    indirect: &IndirectTargets,
    memory: &MemoryModel,
    demangle: impl Fn(&str) -> String,
) -> Result<Program, WcetError> {
    let mut by_address = HashMap::new();
    for (k, f) in raw.iter().enumerate() {
        by_address.insert(f.address, k);
    }
    let demangled: Vec<String> = raw.iter().map(|f| demangle(&f.name)).collect();
    // First pass: per function, block boundaries and raw edges.
    let pending: Vec<Pending> = raw.iter().map(find_leaders).collect();
    let returns = which_return(raw, &pending, &by_address);
    // Second pass: blocks, with calls to non-returning functions ending blocks.
    let linker = Linker {
        raw,
        indirect,
        memory,
        demangled,
        by_address,
        returns,
    };
    let functions = raw
        .iter()
        .zip(&pending)
        .enumerate()
        .map(|(k, (f, p))| linker.build_function(k, f, p))
        .collect();
    Ok(Program {
        functions,
        line_fetch_cycles: memory.line_fetch_cycles(),
        by_address: linker.by_address,
    })
}

/// One function's first pass: where its blocks start and how each instruction
/// transfers control.
struct Pending {
    leaders: BTreeSet<usize>,
    /// Per instruction index: (flow, table targets).
    flows: Vec<Flow>,
    tables: BTreeMap<usize, Vec<u32>>,
}

/// Finds function `f`'s block leaders (the targets of its jumps and tables, the
/// instructions after each transfer) and its instructions' flow.
fn find_leaders(f: &RawFunction) -> Pending {
    let mut leaders = BTreeSet::from([0usize]);
    let index: HashMap<u32, usize> = f
        .instructions
        .iter()
        .enumerate()
        .map(|(k, i)| (i.address, k))
        .collect();
    let mut flows = Vec::with_capacity(f.instructions.len());
    let mut tables = BTreeMap::new();
    let mut it_left = 0usize;
    for (k, i) in f.instructions.iter().enumerate() {
        let in_it = it_left > 0;
        it_left = it_left.saturating_sub(1);
        if let Some(n) = it_length(i.base()) {
            it_left = n;
        }
        let fl = flow(i, in_it);
        match &fl {
            Flow::Jump { target, .. } => {
                if let Some(&t) = index.get(target) {
                    leaders.insert(t);
                }
                leaders.insert(k + 1);
            }
            Flow::Return { .. } | Flow::IndirectJump { .. } | Flow::Trap => {
                leaders.insert(k + 1);
            }
            Flow::Table => {
                let ts = table_targets(f, k);
                for t in &ts {
                    if let Some(&x) = index.get(t) {
                        leaders.insert(x);
                    }
                }
                tables.insert(k, ts);
                leaders.insert(k + 1);
            }
            Flow::Straight | Flow::Call(_) | Flow::IndirectCall => {}
        }
        flows.push(fl);
    }
    leaders.retain(|&l| l < f.instructions.len());
    Pending {
        leaders,
        flows,
        tables,
    }
}

/// Which functions return: iterate to a fixed point (a function returns if some
/// block returns, or tail-calls a function that returns).
fn which_return(
    raw: &[RawFunction],
    pending: &[Pending],
    by_address: &HashMap<u32, usize>,
) -> Vec<bool> {
    let mut returns = vec![false; raw.len()];
    loop {
        let mut changed = false;
        for (k, f) in raw.iter().enumerate() {
            if returns[k] {
                continue;
            }
            let p = &pending[k];
            let r = p.flows.iter().any(|fl| match fl {
                Flow::Return { .. } => true,
                Flow::Jump { target, .. } => {
                    let inside = f.instructions.iter().any(|i| i.address == *target);
                    !inside && by_address.get(target).is_some_and(|&t| returns[t])
                }
                Flow::IndirectJump { .. } => true,
                _ => false,
            });
            if r {
                returns[k] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    returns
}

/// What the second pass links against: every function's address, demangled
/// name and whether it returns, the indirect targets and the memory model.
struct Linker<'a> {
    raw: &'a [RawFunction],
    indirect: &'a IndirectTargets,
    memory: &'a MemoryModel,
    demangled: Vec<String>,
    by_address: HashMap<u32, usize>,
    returns: Vec<bool>,
}

/// How one block's instructions transfer control.
struct Transfers {
    calls: Vec<usize>,
    successors: Vec<usize>,
    exit: Exit,
    falls: bool,
    /// The last transfer is conditional and, not taken, falls through.
    conditional_transfer: bool,
    jump_targets: Vec<usize>,
    unresolved: Vec<String>,
}

/// One function's block structure in the second pass.
struct Blocks<'p> {
    /// Each block's first instruction.
    starts: Vec<usize>,
    /// Instruction index by address.
    index: HashMap<u32, usize>,
    /// The first pass.
    pending: &'p Pending,
}

impl Blocks<'_> {
    /// The block holding instruction `x`.
    fn block_of_insn(&self, x: usize) -> usize {
        self.starts.partition_point(|&s| s <= x) - 1
    }
}

impl Linker<'_> {
    /// Indirect targets of an indirect call or jump of `caller` (described by
    /// `what`); an unlisted caller or target is noted in `unresolved`.
    fn targets_of(&self, caller: usize, unresolved: &mut Vec<String>, what: String) -> Vec<usize> {
        let (raw, demangled) = (self.raw, &self.demangled);
        let mut out = Vec::new();
        let Some(callees) = self.indirect.callees_of(&demangled[caller]) else {
            unresolved.push(what);
            return out;
        };
        for c in callees {
            let hits: Vec<usize> = (0..raw.len())
                .filter(|&k| {
                    let symbols = std::iter::once(raw[k].name.as_str())
                        .chain(raw[k].aliases.iter().map(String::as_str));
                    IndirectTargets::lists(c, &demangled[k], symbols)
                })
                .collect();
            if hits.is_empty() {
                unresolved.push(format!(
                    "{what}: listed target `{c}` is no symbol of the binary"
                ));
            }
            out.extend(hits);
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Function `k`'s graph (`f` its instructions, `p` its first pass).
    fn build_function(&self, k: usize, f: &RawFunction, p: &Pending) -> Function {
        let mut leaders = p.leaders.clone();
        for (x, fl) in p.flows.iter().enumerate() {
            if let Flow::Call(t) = fl {
                if self.by_address.get(t).is_some_and(|&c| !self.returns[c]) {
                    leaders.insert(x + 1);
                }
            }
        }
        leaders.retain(|&l| l < f.instructions.len());
        let shape = Blocks {
            starts: leaders.iter().copied().collect(),
            index: f
                .instructions
                .iter()
                .enumerate()
                .map(|(x, i)| (i.address, x))
                .collect(),
            pending: p,
        };
        let mut blocks: Vec<Block> = (0..shape.starts.len())
            .map(|b| self.build_block(k, f, &shape, b))
            .collect();
        // Literal-pool loads that hit the ART's data cache on every path pay no
        // wait states (`data_cache`).
        let memory = self.memory;
        let through_registers = memory.flash_data.may_read_flash(f.address);
        let hits = super::data_cache::must_hits(
            &f.instructions,
            &blocks,
            memory.flash_line_bytes,
            through_registers,
        );
        for (block, h) in blocks.iter_mut().zip(hits) {
            let saved = h * u64::from(memory.flash_wait_states);
            block.cycles -= saved.min(block.cycles);
        }
        Function {
            name: f.name.clone(),
            demangled: self.demangled[k].clone(),
            aliases: f.aliases.clone(),
            address: f.address,
            instructions: f.instructions.clone(),
            blocks,
            returns: self.returns[k],
            data_lines: super::data_cache::lines_read(
                &f.instructions,
                memory.flash_line_bytes,
                through_registers,
            ),
        }
    }

    /// Block `b` of function `k`: its edges, calls and exit, and its costs in
    /// the memory model.
    fn build_block(&self, k: usize, f: &RawFunction, shape: &Blocks<'_>, b: usize) -> Block {
        let memory = self.memory;
        let first = shape.starts[b];
        let end = shape
            .starts
            .get(b + 1)
            .copied()
            .unwrap_or(f.instructions.len());
        let Transfers {
            calls,
            mut successors,
            exit,
            falls,
            conditional_transfer,
            jump_targets,
            unresolved,
        } = self.transfers(k, f, shape, first, end);
        let fall_through = (falls && end < f.instructions.len()).then_some(b + 1);
        if let Some(s) = fall_through {
            successors.push(s);
        }
        successors.sort_unstable();
        successors.dedup();
        let insns = &f.instructions[first..end];
        // A jump to the next block is the same edge taken or not: no saving.
        let fall_through = fall_through.filter(|s| !jump_targets.contains(s));
        let fall_through_saving = fall_through.map_or((0, 0), |_| {
            let next = f.instructions.get(end);
            memory.fall_through_saving(insns.last(), next, conditional_transfer)
        });
        let lines = memory.block_lines(insns);
        Block {
            start: insns.first().map_or(0, |i| i.address),
            first,
            end,
            successors,
            calls,
            exit,
            problems: unresolved,
            instructions: insns.len() as u64,
            cycles: memory.block_cycles(f.address, insns),
            fetch_cycles: lines.map_or(0, |(lo, hi)| (hi - lo + 1) * memory.line_fetch_cycles()),
            lines,
            fall_through,
            fall_through_saving,
        }
    }

    /// How instructions `first..end` of function `k` (one block) transfer
    /// control: calls, successors within the function, exit, whether the block
    /// falls through, and the transfers nothing resolves.
    fn transfers(
        &self,
        k: usize,
        f: &RawFunction,
        shape: &Blocks<'_>,
        first: usize,
        end: usize,
    ) -> Transfers {
        let (by_address, returns) = (&self.by_address, &self.returns);
        let mut t = Transfers {
            calls: Vec::new(),
            successors: Vec::new(),
            exit: Exit::Internal,
            falls: true,
            conditional_transfer: false,
            jump_targets: Vec::new(),
            unresolved: Vec::new(),
        };
        for x in first..end {
            let i = &f.instructions[x];
            let here = || {
                format!(
                    "{}: {:#x} {} {}",
                    self.demangled[k], i.address, i.mnemonic, i.operands
                )
            };
            match &shape.pending.flows[x] {
                Flow::Call(target) => match by_address.get(target) {
                    Some(&c) => {
                        t.calls.push(c);
                        if !returns[c] {
                            t.exit = Exit::NoReturn;
                            t.falls = false;
                        }
                    }
                    None => t.unresolved.push(format!("{}: calls no function", here())),
                },
                Flow::IndirectCall => {
                    let ts = self.targets_of(k, &mut t.unresolved, here());
                    t.calls.extend(ts);
                }
                Flow::Jump {
                    target,
                    conditional,
                } => {
                    if let Some(&y) = shape.index.get(target) {
                        t.successors.push(shape.block_of_insn(y));
                        t.jump_targets.push(shape.block_of_insn(y));
                    } else if let Some(&c) = by_address.get(target) {
                        // A tail call of a function that never returns ends the
                        // activation as a call of it does.
                        t.exit = if returns[c] {
                            Exit::TailCall(c)
                        } else {
                            t.calls.push(c);
                            Exit::NoReturn
                        };
                    } else {
                        t.unresolved
                            .push(format!("{}: jumps to no function", here()));
                    }
                    t.falls = *conditional;
                    t.conditional_transfer = *conditional;
                }
                Flow::Return { conditional } => {
                    t.exit = Exit::Return;
                    t.falls = *conditional;
                    t.conditional_transfer = *conditional;
                }
                Flow::IndirectJump { conditional } => {
                    t.exit = Exit::IndirectTail(self.targets_of(k, &mut t.unresolved, here()));
                    t.falls = *conditional;
                    t.conditional_transfer = *conditional;
                }
                Flow::Table => {
                    let ts = shape.pending.tables.get(&x).cloned().unwrap_or_default();
                    if ts.is_empty() {
                        t.unresolved
                            .push(format!("{} (jump table not found)", here()));
                    }
                    for target in ts {
                        if let Some(&y) = shape.index.get(&target) {
                            t.successors.push(shape.block_of_insn(y));
                        }
                    }
                    t.falls = false;
                }
                Flow::Trap => {
                    t.exit = Exit::NoReturn;
                    t.falls = false;
                }
                Flow::Straight => {}
            }
        }
        t
    }
}
