//! The replay of executed instructions against the control-flow graphs: execution
//! contexts (thread mode, exception activations) with their call stacks, loop
//! entries and back edges per frame, and per-root activation costs (the rules are
//! in [`super`]'s documentation).

use super::observations::{
    CounterObservation, CounterScope, CounterSpec, IndirectObservation, LoopObservation,
    RootObservation, SectionObservation, TraceCheck, LARGEST_KEPT, MAX_EXAMPLES,
};
use super::tb_stream::Resolved;
use crate::cache::Persistence;
use crate::cfg::{Instruction, Program};
use crate::loops::Loop;
use std::collections::{BTreeMap, HashMap};

/// What an instruction does to the call stack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Straight,
    /// A direct or indirect jump (`b`, `cbz`, `tbb`, `bx rN`, `mov pc, ..`).
    Jump,
    /// `bl`, `blx`.
    Call,
    /// `bx lr`, `pop {.., pc}` and the like.
    Return,
}

/// `bne` → (`b`, true); only a condition suffix that leaves a flow mnemonic counts.
fn strip_condition(base: &str) -> (&str, bool) {
    const CONDITIONS: [&str; 16] = [
        "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt",
        "le",
    ];
    if base.len() > 2 {
        let (head, tail) = base.split_at(base.len() - 2);
        if CONDITIONS.contains(&tail)
            && matches!(
                head,
                "b" | "bx"
                    | "pop"
                    | "ldm"
                    | "ldmia"
                    | "ldmfd"
                    | "ldr"
                    | "bl"
                    | "blx"
                    | "mov"
                    | "add"
            )
        {
            return (head, true);
        }
    }
    (base, false)
}

/// Kind of an instruction and whether it is conditional.
fn kind(i: &Instruction) -> (Kind, bool) {
    let (plain, conditional) = strip_condition(i.base());
    let k = match plain {
        "bl" | "blx" => Kind::Call,
        "bx" if i.first_operand() == "lr" => Kind::Return,
        _ if i.pops_pc() => Kind::Return,
        "b" | "cbz" | "cbnz" | "bx" | "tbb" | "tbh" => Kind::Jump,
        "mov" | "ldr" | "add" if i.first_operand() == "pc" => Kind::Jump,
        _ => Kind::Straight,
    };
    (k, conditional)
}

/// The last instruction a context executed.
#[derive(Debug, Clone, Copy)]
struct Last {
    function: usize,
    index: usize,
}

/// One function activation on a context's call stack.
#[derive(Debug, Clone)]
struct Frame {
    function: usize,
    /// The block last entered in this frame.
    block: Option<usize>,
    /// Where the call returns to (`None` for a context's first frame).
    return_to: Option<u32>,
    /// Loops of the function entered and not left: (loop index, back edges so far).
    active: Vec<(usize, u64)>,
    /// Counters per call of this frame's function: (counter, count so far).
    per_call: Vec<(usize, u64)>,
    /// Counters per entry of a loop of this frame: (loop, counter, count so far).
    per_loop_entry: Vec<(usize, usize, u64)>,
    /// A section (a job bounded apart) this frame is a call of: (section index,
    /// the context's instructions and cycles when it was called).
    section: Option<(usize, u64, u64)>,
}

impl Frame {
    fn new(function: usize, return_to: Option<u32>) -> Self {
        Frame {
            function,
            block: None,
            return_to,
            active: Vec::new(),
            per_call: Vec::new(),
            per_loop_entry: Vec::new(),
            section: None,
        }
    }
}

/// Who an execution context is, for the loop statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
enum Owner {
    Thread,
    Root(usize),
    Handler(usize),
}

/// An execution context: thread mode or one exception activation.
#[derive(Debug, Clone)]
struct Context {
    owner: Owner,
    frames: Vec<Frame>,
    last: Option<Last>,
    instructions: u64,
    cycles: u64,
    executed: u64,
    preempted: bool,
    /// Counters per activation: (counter, count so far).
    per_activation: Vec<(usize, u64)>,
}

impl Context {
    pub(super) fn new(owner: Owner) -> Self {
        Context {
            owner,
            frames: Vec::new(),
            last: None,
            instructions: 0,
            cycles: 0,
            executed: 0,
            preempted: false,
            per_activation: Vec::new(),
        }
    }
}

/// Adds one to `counter` in a list of (counter, count).
fn bump(list: &mut Vec<(usize, u64)>, counter: usize) {
    match list.iter_mut().find(|(c, _)| *c == counter) {
        Some((_, n)) => *n += 1,
        None => list.push((counter, 1)),
    }
}

#[derive(Debug, Clone, Default)]
struct LoopStats {
    entries: u64,
    back_edges: u64,
    max: u64,
    orphan: u64,
    /// Per owner: (entries, max back edges).
    by_owner: BTreeMap<Owner, (u64, u64)>,
}

/// The replay's state.
pub(super) struct Replay<'a> {
    program: &'a Program,
    loops: &'a [Vec<Loop>],
    roots: &'a [(String, usize)],
    /// Instruction address → (function, instruction index).
    index: HashMap<u32, (usize, usize)>,
    /// (function, header block) → loop indices.
    headers: HashMap<(usize, usize), Vec<usize>>,
    /// The loops whose lines stay cached, as the static bound counts them.
    persistence: Persistence,
    /// Handler entry address → owner of its contexts.
    handlers: HashMap<u32, Owner>,
    kinds: HashMap<(usize, usize), (Kind, bool)>,
    stack: Vec<Context>,
    loop_stats: BTreeMap<(usize, usize), LoopStats>,
    root_stats: Vec<RootObservation>,
    /// The counters' specifications, and what each counts on: block entries and
    /// edge traversals `(function, from, to)` (`from` = `usize::MAX`: the
    /// function's entry), each to the counters it adds to.
    counters: &'a [CounterSpec],
    counter_blocks: HashMap<(usize, usize), Vec<usize>>,
    counter_edges: HashMap<(usize, usize, usize), Vec<usize>>,
    counter_obs: Vec<CounterObservation>,
    /// Section entry address → section index.
    section_at: HashMap<u32, usize>,
    section_stats: Vec<SectionObservation>,
    indirect: BTreeMap<(u32, usize), u64>,
    /// Blocks entered at least once, in any context.
    blocks_run: std::collections::BTreeSet<(usize, usize)>,
    other: BTreeMap<usize, u64>,
    tb_executions: u64,
    instructions: u64,
    block_entries: u64,
    exception_entries: u64,
    outside: u64,
    unexpected: u64,
    examples: Vec<String>,
}

impl<'a> Replay<'a> {
    pub(super) fn new(
        program: &'a Program,
        loops: &'a [Vec<Loop>],
        roots: &'a [(String, usize)],
        handlers: &[usize],
        counters: &'a [CounterSpec],
        sections: &[(String, usize)],
    ) -> Self {
        let mut counter_blocks: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        let mut counter_edges: HashMap<(usize, usize, usize), Vec<usize>> = HashMap::new();
        for (k, c) in counters.iter().enumerate() {
            for &b in &c.blocks {
                counter_blocks.entry(b).or_default().push(k);
            }
            for &e in &c.edges {
                counter_edges.entry(e).or_default().push(k);
            }
        }
        let counter_obs = counters
            .iter()
            .map(|_| CounterObservation::default())
            .collect();
        let section_at: HashMap<u32, usize> = sections
            .iter()
            .enumerate()
            .filter_map(|(k, (_, f))| Some((program.functions.get(*f)?.address, k)))
            .collect();
        let section_stats = sections
            .iter()
            .map(|(name, f)| SectionObservation {
                name: name.clone(),
                function: *f,
                ..SectionObservation::default()
            })
            .collect();
        let mut index = HashMap::new();
        for (f, func) in program.functions.iter().enumerate() {
            for (k, i) in func.instructions.iter().enumerate() {
                index.insert(i.address, (f, k));
            }
        }
        let mut headers: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (f, ls) in loops.iter().enumerate() {
            for (l, lp) in ls.iter().enumerate() {
                headers.entry((f, lp.header)).or_default().push(l);
            }
        }
        let mut handler_map = HashMap::new();
        for &h in handlers {
            if let Some(func) = program.functions.get(h) {
                handler_map.insert(func.address, Owner::Handler(h));
            }
        }
        for (r, (_, f)) in roots.iter().enumerate() {
            if let Some(func) = program.functions.get(*f) {
                handler_map.insert(func.address, Owner::Root(r));
            }
        }
        let root_stats = roots
            .iter()
            .map(|(name, f)| RootObservation {
                name: name.clone(),
                function: *f,
                activations: 0,
                max_instructions: 0,
                max_cycles: 0,
                max_executed: 0,
                largest_instructions: Vec::new(),
                total_instructions: 0,
                total_cycles: 0,
                preempted_activations: 0,
                incomplete: 0,
            })
            .collect();
        Replay {
            program,
            loops,
            roots,
            index,
            headers,
            persistence: Persistence::new(program, loops),
            handlers: handler_map,
            kinds: HashMap::new(),
            stack: vec![Context::new(Owner::Thread)],
            loop_stats: BTreeMap::new(),
            root_stats,
            counters,
            counter_blocks,
            counter_edges,
            counter_obs,
            section_at,
            section_stats,
            indirect: BTreeMap::new(),
            blocks_run: Default::default(),
            other: BTreeMap::new(),
            tb_executions: 0,
            instructions: 0,
            block_entries: 0,
            exception_entries: 0,
            outside: 0,
            unexpected: 0,
            examples: Vec::new(),
        }
    }

    pub(super) fn resolve(&self, address: u32) -> Resolved {
        let at = self.index.get(&address).map(|&(f, k)| {
            let func = &self.program.functions[f];
            let block = func
                .block_at(address)
                .filter(|&b| func.blocks[b].start == address);
            (f, k, block)
        });
        Resolved { address, at }
    }

    fn note(&mut self, message: impl FnOnce() -> String) {
        self.unexpected += 1;
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(message());
        }
    }

    fn name(&self, f: usize) -> &str {
        self.program
            .functions
            .get(f)
            .map_or("?", |x| x.demangled.as_str())
    }

    fn owner_name(&self, owner: Owner) -> String {
        match owner {
            Owner::Thread => "thread".to_string(),
            Owner::Root(r) => self
                .roots
                .get(r)
                .map_or_else(|| format!("root {r}"), |x| x.0.clone()),
            Owner::Handler(f) => self.name(f).to_string(),
        }
    }

    fn instruction(&self, l: Last) -> Option<&'a Instruction> {
        let program: &'a Program = self.program;
        program.functions.get(l.function)?.instructions.get(l.index)
    }

    fn kind_of(&mut self, l: Last) -> (Kind, bool) {
        if let Some(&k) = self.kinds.get(&(l.function, l.index)) {
            return k;
        }
        let k = self.instruction(l).map_or((Kind::Straight, false), kind);
        self.kinds.insert((l.function, l.index), k);
        k
    }

    /// The trace lost an execution: no context knows where it is.
    pub(super) fn break_stream(&mut self) {
        for c in &mut self.stack {
            c.last = None;
        }
    }

    pub(super) fn tb(&mut self, insns: &[Resolved]) {
        if insns.is_empty() {
            return;
        }
        self.tb_executions += 1;
        for (n, r) in insns.iter().enumerate() {
            self.step(n == 0, *r);
        }
    }

    /// Records one scope's count of `counter` (an activation, a call, a loop
    /// entry; `root`: the task whose activation it was).
    fn fold(&mut self, counter: usize, count: u64, root: Option<usize>) {
        let name = root.and_then(|r| self.roots.get(r)).map(|r| r.0.clone());
        let Some(o) = self.counter_obs.get_mut(counter) else {
            return;
        };
        o.scopes += 1;
        o.total += count;
        o.max = o.max.max(count);
        if let Some(name) = name {
            match o.by_root.iter_mut().find(|(n, _)| *n == name) {
                Some((_, m)) => *m = (*m).max(count),
                None => o.by_root.push((name, count)),
            }
        }
    }

    /// A frame's scopes end (its function returned, was replaced by a tail call,
    /// or the context was lost): its counters per call and per loop entry are
    /// recorded, and its section's call when `ends_section`.
    fn end_frame_scopes(&mut self, mut frame: Frame, ends_section: bool) -> Frame {
        for (counter, n) in std::mem::take(&mut frame.per_call) {
            self.fold(counter, n, None);
        }
        for (_, counter, n) in std::mem::take(&mut frame.per_loop_entry) {
            self.fold(counter, n, None);
        }
        if ends_section {
            if let Some((k, i0, c0)) = frame.section.take() {
                let (i1, c1) = self
                    .stack
                    .last()
                    .map_or((i0, c0), |c| (c.instructions, c.cycles));
                if let Some(s) = self.section_stats.get_mut(k) {
                    s.calls += 1;
                    s.max_instructions = s.max_instructions.max(i1.saturating_sub(i0));
                    s.max_cycles = s.max_cycles.max(c1.saturating_sub(c0));
                }
            }
        }
        frame
    }

    /// Pops the top context (an exception return) and records its activation.
    fn pop_context(&mut self) {
        if self.stack.len() <= 1 {
            return;
        }
        let Some(mut c) = self.stack.pop() else {
            return;
        };
        // Frames left open (an exception return from a nested call cannot happen:
        // the handler's own frame returns) end their scopes with the activation.
        let open = std::mem::take(&mut c.frames);
        let activation = std::mem::take(&mut c.per_activation);
        self.stack.push(c);
        for fr in open.into_iter().rev() {
            self.end_frame_scopes(fr, true);
        }
        let Some(c) = self.stack.pop() else {
            return;
        };
        let root = match c.owner {
            Owner::Root(r) => Some(r),
            _ => None,
        };
        if root.is_some() {
            for (counter, n) in activation {
                self.fold(counter, n, root);
            }
        }
        match c.owner {
            Owner::Root(r) => {
                if let Some(s) = self.root_stats.get_mut(r) {
                    s.activations += 1;
                    s.max_instructions = s.max_instructions.max(c.instructions);
                    s.max_cycles = s.max_cycles.max(c.cycles);
                    s.max_executed = s.max_executed.max(c.executed);
                    let at = s
                        .largest_instructions
                        .partition_point(|&x| x >= c.instructions);
                    s.largest_instructions.insert(at, c.instructions);
                    s.largest_instructions.truncate(LARGEST_KEPT);
                    s.total_instructions += c.instructions;
                    s.total_cycles += c.cycles;
                    s.preempted_activations += u64::from(c.preempted);
                }
            }
            Owner::Handler(f) => *self.other.entry(f).or_insert(0) += 1,
            Owner::Thread => {}
        }
    }

    fn step(&mut self, tb_start: bool, r: Resolved) {
        self.instructions += 1;
        let Some((f, k, block)) = r.at else {
            self.outside += 1;
            if let Some(c) = self.stack.last_mut() {
                c.last = None;
                c.executed += 1;
            }
            return;
        };
        // Exception entry: a TB at a handler's entry that the context did not jump to.
        if tb_start {
            if let Some(&owner) = self.handlers.get(&r.address) {
                let jumped_here = self
                    .stack
                    .last()
                    .and_then(|c| c.last)
                    .and_then(|l| self.instruction(l))
                    .is_some_and(|i| i.target == Some(r.address));
                if !jumped_here {
                    if let Some(c) = self.stack.last_mut() {
                        c.preempted = true;
                    }
                    self.exception_entries += 1;
                    self.stack.push(Context::new(owner));
                }
            }
        }
        // Where this instruction is relative to the context's last one.
        loop {
            let depth = self.stack.len();
            let Some(last) = self.stack.last().and_then(|c| c.last) else {
                self.restart_frame(f);
                break;
            };
            let (kind, _) = self.kind_of(last);
            let last_address = self.instruction(last).map_or(0, |i| i.address);
            let fall = self
                .instruction(last)
                .map_or(0, |i| i.address.wrapping_add(i.bytes));
            let top_function = self
                .stack
                .last()
                .and_then(|c| c.frames.last())
                .map(|fr| fr.function);
            if kind == Kind::Call && r.address != fall {
                if self.program.at(r.address) != Some(f) {
                    let from = self.name(last.function).to_string();
                    let address = r.address;
                    self.note(|| format!("call from {from} to {address:#010x}, no function entry"));
                }
                let section = self.section_at.get(&r.address).copied();
                if let Some(c) = self.stack.last_mut() {
                    let mut frame = Frame::new(f, Some(fall));
                    frame.section = section.map(|k| (k, c.instructions, c.cycles));
                    c.frames.push(frame);
                }
                if self.instruction(last).is_some_and(|i| i.target.is_none()) {
                    *self.indirect.entry((last_address, f)).or_insert(0) += 1;
                }
                break;
            }
            if kind == Kind::Return && r.address != fall {
                let frames = self.stack.last().map_or(0, |c| c.frames.len());
                if frames <= 1 {
                    if depth > 1 {
                        // Exception return (a conditional one, resolved now).
                        self.pop_context();
                        continue;
                    }
                    let from = self.name(last.function).to_string();
                    let address = r.address;
                    self.note(|| format!("return from {from} with no caller, to {address:#010x}"));
                    self.restart_frame(f);
                    break;
                }
                let popped = self.stack.last_mut().and_then(|c| c.frames.pop());
                let popped = popped.map(|p| self.end_frame_scopes(p, true));
                let back_in = self
                    .stack
                    .last()
                    .and_then(|c| c.frames.last())
                    .map(|fr| fr.function);
                let expected = popped.and_then(|p| p.return_to);
                if expected != Some(r.address) || back_in != Some(f) {
                    let from = self.name(last.function).to_string();
                    let address = r.address;
                    let expected =
                        expected.map_or("no caller".to_string(), |e| format!("{e:#010x}"));
                    self.note(|| {
                        format!("return from {from} to {address:#010x}, expected {expected}")
                    });
                    self.restart_frame(f);
                }
                break;
            }
            if top_function == Some(f) {
                if kind == Kind::Straight && r.address != fall {
                    let from = self.instruction(last).map_or(0, |i| i.address);
                    let address = r.address;
                    self.note(|| format!("{from:#010x} fell through to {address:#010x}"));
                }
                break;
            }
            if self.program.at(r.address) == Some(f) {
                // Tail call: the callee takes the frame's place (a section's call
                // goes on in it).
                if self.instruction(last).is_some_and(|i| i.target.is_none()) {
                    *self.indirect.entry((last_address, f)).or_insert(0) += 1;
                }
                self.replace_top_frame(f);
                break;
            }
            let from = self.instruction(last).map_or(0, |i| i.address);
            let address = r.address;
            self.note(|| format!("{from:#010x} went to {address:#010x}, inside another function"));
            self.restart_frame(f);
            break;
        }
        if let Some(b) = block {
            self.enter_block(f, b);
        }
        let depth = self.stack.len();
        let Some(c) = self.stack.last_mut() else {
            return;
        };
        c.last = Some(Last {
            function: f,
            index: k,
        });
        c.executed += 1;
        let frames = c.frames.len();
        let (kind, conditional) = self.kind_of(Last {
            function: f,
            index: k,
        });
        if kind == Kind::Return && !conditional && frames <= 1 && depth > 1 {
            self.pop_context();
        }
    }

    /// The top context's innermost frame, its scopes ended, goes on in function
    /// `f` (a tail call, or a transfer the graphs do not explain).
    fn replace_top_frame(&mut self, f: usize) {
        if let Some(fr) = self.stack.last_mut().and_then(|c| c.frames.pop()) {
            let mut fr = self.end_frame_scopes(fr, false);
            fr.function = f;
            fr.block = None;
            fr.active.clear();
            if let Some(c) = self.stack.last_mut() {
                c.frames.push(fr);
            }
        }
    }

    /// Starts the top context's innermost frame over in function `f` (the first
    /// instruction of a context, or after a transfer the graphs do not explain).
    fn restart_frame(&mut self, f: usize) {
        let Some(c) = self.stack.last_mut() else {
            return;
        };
        match c.frames.last() {
            Some(fr) if fr.function == f => {}
            Some(_) => self.replace_top_frame(f),
            None => c.frames.push(Frame::new(f, None)),
        }
    }

    fn enter_block(&mut self, f: usize, b: usize) {
        self.block_entries += 1;
        self.blocks_run.insert((f, b));
        let program = self.program;
        let loops = self.loops;
        let Some(block) = program.functions.get(f).and_then(|x| x.blocks.get(b)) else {
            return;
        };
        let Some(c) = self.stack.last_mut() else {
            return;
        };
        // The block's cycles as the static bound counts them: the fall-through
        // edge's saving, a persistent loop's lines once per entry.
        let before = c.frames.last().and_then(|fr| fr.block);
        let saving = before.map_or(0, |a| self.persistence.edge_saving(program, f, a, b));
        let entry = self
            .persistence
            .entered(f, before, b)
            .map_or(0, |r| self.persistence.entry_cycles(r));
        c.instructions += block.instructions;
        c.cycles = (c.cycles + self.persistence.block_cycles(program, f, b) + entry)
            .saturating_sub(saving);
        let owner = c.owner;
        let Some(frame) = c.frames.last_mut() else {
            return;
        };
        let prev = frame.block.replace(b);
        let mut odd_edge = None;
        if let Some(a) = prev {
            let from = program.functions.get(f).and_then(|x| x.blocks.get(a));
            if from.is_some_and(|x| !x.successors.contains(&b)) {
                odd_edge = from.map(|x| (x.start, block.start));
            }
        }
        if let Some(ls) = self.headers.get(&(f, b)) {
            for &l in ls {
                let Some(lp) = loops.get(f).and_then(|x| x.get(l)) else {
                    continue;
                };
                let stats = self.loop_stats.entry((f, l)).or_default();
                let back = prev.is_some_and(|a| lp.back_edges.contains(&(a, b)));
                if back {
                    stats.back_edges += 1;
                    let count = match frame.active.iter_mut().find(|(x, _)| *x == l) {
                        Some((_, n)) => {
                            *n += 1;
                            *n
                        }
                        None => {
                            stats.orphan += 1;
                            frame.active.push((l, 1));
                            1
                        }
                    };
                    stats.max = stats.max.max(count);
                    let o = stats.by_owner.entry(owner).or_insert((0, 0));
                    o.1 = o.1.max(count);
                } else {
                    stats.entries += 1;
                    stats.by_owner.entry(owner).or_insert((0, 0)).0 += 1;
                    match frame.active.iter_mut().find(|(x, _)| *x == l) {
                        Some((_, n)) => *n = 0,
                        None => frame.active.push((l, 0)),
                    }
                }
            }
        }
        // Flow-fact counters: this block's entry and the edge into it. A loop
        // entered anew first ends its last entry's counts.
        let entered: Vec<usize> = self
            .headers
            .get(&(f, b))
            .into_iter()
            .flatten()
            .copied()
            .filter(|&l| {
                loops
                    .get(f)
                    .and_then(|x| x.get(l))
                    .is_some_and(|lp| !prev.is_some_and(|a| lp.back_edges.contains(&(a, b))))
            })
            .collect();
        if !entered.is_empty() {
            let mut ended = Vec::new();
            if let Some(frame) = self.stack.last_mut().and_then(|c| c.frames.last_mut()) {
                frame.per_loop_entry.retain(|&(l, counter, n)| {
                    let end = entered.contains(&l);
                    if end {
                        ended.push((counter, n));
                    }
                    !end
                });
            }
            for (counter, n) in ended {
                self.fold(counter, n, None);
            }
        }
        let edge = (f, prev.unwrap_or(usize::MAX), b);
        let hits: Vec<usize> = self
            .counter_blocks
            .get(&(f, b))
            .into_iter()
            .flatten()
            .chain(self.counter_edges.get(&edge).into_iter().flatten())
            .copied()
            .collect();
        let counters = self.counters;
        for k in hits {
            let Some(spec) = counters.get(k) else {
                continue;
            };
            let Some(c) = self.stack.last_mut() else {
                break;
            };
            match spec.scope {
                CounterScope::Activation => bump(&mut c.per_activation, k),
                CounterScope::Call(_) => {
                    if let Some(fr) = c.frames.last_mut() {
                        bump(&mut fr.per_call, k);
                    }
                }
                CounterScope::LoopEntry(_, l) => {
                    if let Some(fr) = c.frames.last_mut() {
                        match fr
                            .per_loop_entry
                            .iter_mut()
                            .find(|(x, counter, _)| *x == l && *counter == k)
                        {
                            Some((_, _, n)) => *n += 1,
                            None => fr.per_loop_entry.push((l, k, 1)),
                        }
                    }
                }
            }
        }
        if let Some((from, to)) = odd_edge {
            let name = self.name(f).to_string();
            self.note(|| format!("{name}: edge {from:#010x} -> {to:#010x} is not in the graph"));
        }
    }

    pub(super) fn finish(mut self) -> TraceCheck {
        while self.stack.len() > 1 {
            if let Some(c) = self.stack.pop() {
                if let Owner::Root(r) = c.owner {
                    if let Some(s) = self.root_stats.get_mut(r) {
                        s.incomplete += 1;
                    }
                }
            }
        }
        let loops = self
            .loop_stats
            .iter()
            .map(|(&(f, l), s)| {
                let function = self.program.functions.get(f);
                let header = self
                    .loops
                    .get(f)
                    .and_then(|x| x.get(l))
                    .and_then(|lp| function?.blocks.get(lp.header))
                    .map_or(0, |b| b.start);
                LoopObservation {
                    function: f,
                    function_name: self.name(f).to_string(),
                    loop_index: l,
                    header,
                    entries: s.entries,
                    back_edges: s.back_edges,
                    max_back_edges: s.max,
                    back_edges_without_entry: s.orphan,
                    by_context: s
                        .by_owner
                        .iter()
                        .map(|(&o, &(e, m))| (self.owner_name(o), e, m))
                        .collect(),
                }
            })
            .collect();
        let other_handlers = self
            .other
            .iter()
            .map(|(&f, &n)| (self.name(f).to_string(), n))
            .collect();
        let indirect_calls = self
            .indirect
            .iter()
            .map(|(&(site, target), &count)| IndirectObservation {
                site,
                from: self.program.containing(site).unwrap_or(usize::MAX),
                target,
                target_name: self.name(target).to_string(),
                count,
            })
            .collect();
        TraceCheck {
            loops,
            counters: self.counter_obs,
            sections: self.section_stats,
            indirect_calls,
            blocks_run: self.blocks_run.into_iter().collect(),
            roots: self.root_stats,
            other_handlers,
            tb_executions: self.tb_executions,
            instructions: self.instructions,
            block_entries: self.block_entries,
            exception_entries: self.exception_entries,
            outside_functions: self.outside,
            untraced_executions: 0,
            abandoned_executions: 0,
            unexpected_transfers: self.unexpected,
            examples: self.examples,
        }
    }
}
