//! Implicit path enumeration (IPET): the worst-case cost of a task as a linear
//! program over its blocks' execution counts.
//!
//! Every block `b` reachable from the task's entry gets a count `x_b ≥ 0`, every
//! edge a count `e ≥ 0`, every function an entry count `n_f`. The program
//! maximises `Σ cost_b · x_b` subject to
//!
//! * flow conservation: `x_b = Σ in-edges (+ n_f at the entry) = Σ out-edges (+ exits)`;
//! * calls: `n_f = Σ` over the blocks that call `f` of their counts (one per call
//!   instruction; an indirect call counts towards each listed target: sound and
//!   pessimistic), plus the tail calls into `f`; the task's entry `n_root = 1`;
//! * loop bounds: `Σ back edges ≤ B · Σ entry edges` per loop ([`Per::Entry`]), or
//!   `Σ back edges ≤ B · n_root` for a flow fact over the whole activation
//!   ([`Per::Activation`]): caps that span loops are linear constraints, not
//!   products of worst cases. Such a cap also holds per entry: `Σ back edges ≤
//!   B · n_f` for the loop's function and `≤ B · Σ entry edges` for a natural
//!   loop (true of every execution, since a loop runs only once entered); without
//!   them the relaxation enters a function a fraction of the activation, or not at
//!   all round a loop's cycle, and still charges the whole cap;
//! * `Σ back edges ≤ B · n_f` for a bound per call of the loop's function
//!   ([`Per::Call`]: a triangular nest), and `Σ x_b ≤ B · n_root` over the blocks
//!   of a step capped per activation ([`BlockCap::activation_group`]);
//! * block copies and fills ([`CopySizes`]): the loops of `memcpy`, `memset`, ...
//!   take together `Σ k_l · back_l ≤ Σ bytes · x_site` over the call sites, where
//!   `k_l ≥ 1` is the fewest bytes loop `l` stores outside the stack on one trip
//!   ([`min_stored_bytes_per_trip`]: a word loop unrolled four times stores 16)
//!   and each destination byte is written once per call;
//! * paths that never return (a call of a panic handler, a trap) are not part of a
//!   completing activation: their blocks get count 0.
//!
//! In cycles, an edge that falls through to the next block costs less than the
//! two blocks' costs by [`super::cfg::Block::fall_through_saving`] (a conditional
//! branch not taken, a flash line already read): the objective takes it off that
//! edge's count. A loop whose lines stay in the instruction cache
//! ([`Persistence`]) is charged its lines once per entry, its blocks without their
//! fetch.
//!
//! The functions' entry counts are integers, the other counts continuous (a mixed
//! integer program, solved by branch and bound): a relaxation that enters a
//! function a fraction of the activation pays a fraction of its fixed work and
//! may still charge a cap per activation in full, so with continuous entries the
//! plan task's bound mixed half a window adoption with half a plan and exceeded
//! both. The continuous block and edge counts are a relaxation of the integer
//! program, whose optimum it cannot be below: the bound stays an upper bound.
//! Solved with `microlp` through `good_lp` (pure Rust).

use super::cache::Persistence;
use super::cfg::{Exit, Function, Program};
use super::loops::{depth, min_stored_bytes_per_trip, reverse_post_order, Loop};
use good_lp::{
    constraint, variable, Expression, ProblemVariables, Solution, SolverModel, Variable,
};
use std::collections::HashMap;

/// What a loop bound counts against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Per {
    /// Back edges per entry of the loop.
    Entry,
    /// Back edges per activation of the task (a cap that spans the loop's entries).
    Activation,
    /// Back edges per call of the function holding the loop (the function is
    /// not inlined: checked where the fact is made).
    Call,
    /// Back edges per activation, summed with the loops and calls of every other
    /// annotation of the same counter (the group's index, as
    /// [`BlockCap::activation_group`]) under one bound.
    Counted(usize),
    /// A retry loop that retries only when an exception came in between: all such
    /// loops share one cap, the task's retries per activation (the `retries`
    /// argument of [`task_bound`]); the fact's own bound is not used.
    Preemption,
    /// A retry loop that retries only when the monotonic's tick came in between:
    /// all such loops share one cap, the task's tick retries per activation
    /// ([`Retries::tick`]); the fact's own bound is not used.
    Tick,
}

/// The retries one activation of a task can make, by what causes them: the
/// caps of the loops that retry [`Per::Preemption`] and [`Per::Tick`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Retries {
    /// Retries any preemption can cause, summed over the activation's
    /// preemptions.
    pub preemption: u64,
    /// Retries a preemption by the monotonic's tick can cause, summed over the
    /// ticks that preempt the activation.
    pub tick: u64,
}

impl From<u64> for Retries {
    /// Retries any preemption causes, none for the tick alone.
    fn from(preemption: u64) -> Self {
        Self {
            preemption,
            tick: 0,
        }
    }
}

impl Retries {
    /// Each cap the larger of the two.
    pub fn max(self, other: Self) -> Self {
        Self {
            preemption: self.preemption.max(other.preemption),
            tick: self.tick.max(other.tick),
        }
    }
}

/// A bound on one loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoopFact {
    /// Function index in the program.
    pub function: usize,
    /// Loop index in that function's loops.
    pub loop_index: usize,
    /// Most back edges taken, per [`Self::per`].
    pub bound: u64,
    /// What the bound counts against.
    pub per: Per,
    /// Another loop of the same function (its index) whose bound this one shares:
    /// one source loop the compiler split into nested binary loops. Their back
    /// edges together are bounded, against the other loop's entries.
    pub group: Option<usize>,
    /// The bound counts the loop's iterations (a source annotation), not its back
    /// edges (a bound recognised from the binary). Where every run of the header
    /// starts an iteration ([`header_starts_iterations`]) the header then runs at
    /// most `bound` times, so the back edges are one fewer per entry.
    pub iterations: bool,
}

/// Whether every run of loop `l`'s header starts an iteration: the header cannot
/// leave the loop (no successor outside it, no return or tail call), so the test
/// that ends the loop is elsewhere (a rotated, bottom-tested loop) and a run of
/// the header is always followed by the body. A loop of `n` iterations then runs
/// its header `n` times per entry and takes its back edges `n − 1` times; a
/// top-tested loop runs its header once more, to leave.
pub fn header_starts_iterations(func: &Function, l: &Loop) -> bool {
    func.blocks.get(l.header).is_some_and(|h| {
        h.exit == Exit::Internal
            && !h.successors.is_empty()
            && h.successors
                .iter()
                .all(|s| l.blocks.binary_search(s).is_ok())
    })
}

/// Whether `fact` bounds the runs of its loop's header rather than its back
/// edges: a bound on iterations, of a natural loop whose header starts every
/// iteration, that no nested binary loop shares (`shared`). An irreducible
/// cycle's bound counts its back edges: it is entered at blocks other than its
/// header too, so its header's runs are not its iterations.
pub fn bounds_header_runs(fact: &LoopFact, func: &Function, l: &Loop, shared: bool) -> bool {
    fact.iterations && !shared && !l.irreducible && header_starts_iterations(func, l)
}

/// The most back edges per entry a fact allows: its bound, one fewer where it
/// bounds the header's runs ([`bounds_header_runs`]).
pub fn back_edges_per_entry(fact: &LoopFact, func: &Function, l: &Loop, shared: bool) -> u64 {
    if bounds_header_runs(fact, func, l, shared) {
        fact.bound.saturating_sub(1)
    } else {
        fact.bound
    }
}

/// Block copies and fills (`memcpy`, `memset`, ...): functions whose loops are
/// bounded by the bytes their callers pass, not per entry. Each of their loops
/// takes at most one back edge per byte, so over an activation each loop's back
/// edges are at most `Σ bytes × count` over the call sites.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CopySizes {
    /// The copy and fill functions (indices in the program).
    pub family: std::collections::BTreeSet<usize>,
    /// Every call from outside the family into it.
    pub sites: Vec<CopySite>,
    /// Caps on blocks per loop entry (`per loop entry` annotations).
    pub caps: Vec<BlockCap>,
    /// The counter group of each activation group that shares its bound with
    /// others (`counted in NAME`): their runs are summed under one bound, with
    /// the loops of [`Per::Counted`] of the same group.
    pub counters: std::collections::BTreeMap<usize, usize>,
}

/// A cap on blocks: they run at most `bound` times per entry of loop
/// `loop_index` of their function (per entry of the function when `None`), or,
/// with `activation_group` set, over one activation together with every other
/// cap of the same group (one source line inlined in several places).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockCap {
    /// Function index.
    pub function: usize,
    /// The blocks.
    pub blocks: Vec<usize>,
    /// The innermost loop around them.
    pub loop_index: Option<usize>,
    /// Most executions of the blocks together per entry (per activation for a
    /// group).
    pub bound: u64,
    /// The caps counted together per activation (an index shared by the caps of
    /// one annotation); `None` for a cap per loop entry.
    pub activation_group: Option<usize>,
    /// The annotation that makes the cap (its index in the scanned annotations),
    /// for the report; `None` for a cap made by hand.
    pub annotation: Option<usize>,
}

/// One call of a copy or fill function.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CopySite {
    /// The calling function.
    pub function: usize,
    /// The copy or fill function it calls.
    pub callee: usize,
    /// The calling block.
    pub block: usize,
    /// The most bytes it moves: a constant the binary sets before the call, or
    /// a `bytes` annotation at its line; `None` when neither.
    pub bytes: Option<u64>,
    /// Where (function, address, source line), for the messages.
    pub at: String,
}

/// Which cost a block contributes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cost {
    /// Instructions, as QEMU counts them.
    Instructions,
    /// Worst-case cycles of the memory model.
    Cycles,
}

/// How many of the costliest blocks [`IpetBound::by_block`] keeps.
pub const TOP_BLOCKS: usize = 40;

/// A task's bound and what it is made of.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct IpetBound {
    /// The bound (the linear program's optimum, rounded up).
    pub bound: u64,
    /// Per function: its blocks' cost on the worst path, most first.
    pub by_function: Vec<(String, f64)>,
    /// Per function: its entries (calls) on the worst path, in the order of
    /// `by_function`.
    pub entries_by_function: Vec<(String, f64)>,
    /// Per block, the most costly first: its function, its first instruction's
    /// address, its count on the worst path and its cost per execution (the
    /// persistent loops' one fetch per entry and the fall-through savings are
    /// in [`Self::by_function`], not here).
    pub by_block: Vec<BlockShare>,
    /// Variables and constraints of the linear program.
    pub variables: usize,
    /// Constraints of the linear program.
    pub constraints: usize,
    /// How the optimum was reached: `"integer"` (the functions' entry counts
    /// whole, the mixed-integer optimum), or `"relaxation"` (the branch and bound
    /// stopped at [`MAX_NODES`]; the bound is the largest relaxation left open,
    /// which is at or above the integer optimum: sound, possibly pessimistic).
    pub optimum: &'static str,
}

/// One block's share of a bound.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BlockShare {
    /// The block's function (demangled).
    pub function: String,
    /// Its first instruction's address.
    pub address: u32,
    /// Its count on the worst path.
    pub count: f64,
    /// Its cost per execution (instructions or cycles, as the bound).
    pub cost: u64,
}

pub use crate::error::IpetError;

/// Adds `runs` to activation group `g`'s sum, whose bound is the smallest any of
/// its members gives (`bound` for this one).
fn add_to_group(
    groups: &mut std::collections::BTreeMap<usize, (u64, Expression)>,
    g: usize,
    bound: u64,
    runs: Expression,
) {
    let entry = groups
        .entry(g)
        .or_insert_with(|| (bound, Expression::from(0.0)));
    entry.0 = entry.0.min(bound);
    entry.1 += runs;
}

/// The worst-case cost of one activation of the task entered at `root`.
///
/// The phases: refuse a recursion or a loop or copy without a bound, build the
/// linear program function by function (flow, block caps, loop bounds), add the
/// constraints over the whole activation (copies, caps per activation, retries,
/// calls), then solve it and rank the functions and blocks by their share.
pub fn task_bound(
    program: &Program,
    loops: &[Vec<Loop>],
    root: usize,
    facts: &[LoopFact],
    retries: impl Into<Retries>,
    copies: &CopySizes,
    cost: Cost,
) -> Result<IpetBound, crate::WcetError> {
    let retries = retries.into();
    if let Some(r) = program.recursions(&[root]).into_iter().next() {
        return Err(IpetError::Recursion(r).into());
    }
    let reach = program.completing_reachable(&[root]);
    let mut lp = Ipet::new(program, loops, root, facts, copies, cost, &reach);
    let sites = lp.check_bounded(&reach)?;
    for &f in &reach {
        lp.add_function(f);
    }
    lp.add_copy_budgets(&sites);
    lp.add_activation_caps(retries);
    lp.add_call_counts(&reach);
    Ok(lp.solve(&reach)?)
}

/// The integer linear program of one task's activation, built one function at a
/// time: its variables, constraints and objective, and what the report ranks.
struct Ipet<'a> {
    program: &'a Program,
    loops: &'a [Vec<Loop>],
    root: usize,
    copies: &'a CopySizes,
    cost: Cost,
    /// Per reachable function, which of its blocks can complete the activation.
    completing: HashMap<usize, Vec<bool>>,
    /// The loop bounds by `(function, loop)`.
    fact_of: HashMap<(usize, usize), &'a LoopFact>,
    /// The loops that keep their lines cached.
    persistence: Persistence,
    vars: ProblemVariables,
    /// Every variable is `≥ 0`: the relaxation rebuilds them from their count.
    relaxed: usize,
    constraints: Vec<good_lp::Constraint>,
    objective: Expression,
    /// Each reachable function's entry count.
    n_entry: HashMap<usize, Variable>,
    /// Incoming calls per function.
    calls_into: HashMap<usize, Expression>,
    /// Each function's own cost.
    per_function: Vec<(usize, Expression)>,
    /// (function, block, count, cost per execution) of every costly block.
    per_block: Vec<(usize, usize, Variable, u64)>,
    /// Retries per preemption: one constraint over all such loops.
    retry_edges: Expression,
    any_retry: bool,
    tick_edges: Expression,
    any_tick: bool,
    /// Every block's count, for the copy sites.
    x_all: HashMap<(usize, usize), Variable>,
    /// Per copy function: its loops' back edges weighted by the bytes a trip
    /// stores.
    copy_loops: std::collections::BTreeMap<usize, Expression>,
    /// The calls between the copy functions.
    family: FamilyCalls,
    /// Per activation group: its bound and the runs of its blocks.
    group_runs: std::collections::BTreeMap<usize, (u64, Expression)>,
}

/// The calls a copy function gets from the family's other functions: bytes
/// known only for the hand-over of a word copy's remainder to `memcpy`
/// ([`REMAINDER_BYTES`]) or a forwarder's call, else unknown.
#[derive(Default)]
struct FamilyCalls {
    /// Per function, the bytes handed over to it.
    handoffs: HashMap<usize, Expression>,
    /// The functions called with bytes unknown.
    unknown_handoff: std::collections::HashSet<usize>,
    /// (to, from): `from` forwards its calls to `to` unchanged.
    forwards: Vec<(usize, usize)>,
}

impl FamilyCalls {
    /// Notes a call (`count` times) from `from` to `to`, if both copy.
    fn note(
        &mut self,
        program: &Program,
        copies: &CopySizes,
        from: usize,
        to: usize,
        count: Expression,
    ) {
        if !copies.family.contains(&from) || !copies.family.contains(&to) {
            return;
        }
        let (caller, callee) = (
            base_name(&program.functions[from].demangled),
            base_name(&program.functions[to].demangled),
        );
        if is_word_copy(caller) && callee == "memcpy" {
            *self
                .handoffs
                .entry(to)
                .or_insert_with(|| Expression::from(0.0)) += REMAINDER_BYTES as f64 * count;
        } else if is_forwarder(caller, callee) {
            self.forwards.push((to, from));
        } else {
            self.unknown_handoff.insert(to);
        }
    }
}

/// One function's block and edge counts in the program.
struct FunctionFlow {
    f: usize,
    /// Per live block, its count.
    x: HashMap<usize, Variable>,
    /// Per edge, its count.
    edges: HashMap<(usize, usize), Variable>,
    /// The function's own cost.
    fcost: Expression,
}

impl FunctionFlow {
    /// A loop's entries: its entry edges (the function's entry for a loop
    /// headed at block 0).
    fn entries_of(&self, l: &Loop, n_entry: &HashMap<usize, Variable>) -> Expression {
        let mut entries = Expression::from(0.0);
        for &(p, h) in &l.entry_edges {
            if p == usize::MAX {
                entries += n_entry[&self.f];
            } else if let Some(&e) = self.edges.get(&(p, h)) {
                entries += e;
            }
        }
        entries
    }
}

impl<'a> Ipet<'a> {
    /// An empty program over the functions of `reach`, with their entry counts.
    fn new(
        program: &'a Program,
        loops: &'a [Vec<Loop>],
        root: usize,
        facts: &'a [LoopFact],
        copies: &'a CopySizes,
        cost: Cost,
        reach: &[usize],
    ) -> Self {
        let completing: HashMap<usize, Vec<bool>> = reach
            .iter()
            .map(|&f| (f, program.functions[f].completing()))
            .collect();
        let fact_of: HashMap<(usize, usize), &LoopFact> = facts
            .iter()
            .map(|f| ((f.function, f.loop_index), f))
            .collect();
        let mut lp = Self {
            program,
            loops,
            root,
            copies,
            cost,
            completing,
            fact_of,
            persistence: Persistence::new(program, loops),
            vars: ProblemVariables::new(),
            relaxed: 0,
            constraints: Vec::new(),
            objective: Expression::from(0.0),
            n_entry: HashMap::new(),
            calls_into: HashMap::new(),
            per_function: Vec::new(),
            per_block: Vec::new(),
            retry_edges: Expression::from(0.0),
            any_retry: false,
            tick_edges: Expression::from(0.0),
            any_tick: false,
            x_all: HashMap::new(),
            copy_loops: Default::default(),
            family: FamilyCalls::default(),
            group_runs: Default::default(),
        };
        for &f in reach {
            // Integer: see the module's documentation. `relaxed` counts the same
            // variables, for the branch and bound if the solver's own fails.
            lp.n_entry
                .insert(f, lp.vars.add(variable().integer().min(0.0)));
            lp.relaxed += 1;
        }
        lp
    }

    /// Refuses the task when a loop of a function that can complete has no
    /// bound or a block copy it can make has no size; else returns the copy
    /// sites on its completing paths.
    fn check_bounded(&self, reach: &[usize]) -> Result<Vec<&'a CopySite>, IpetError> {
        let (program, loops) = (self.program, self.loops);
        let completing = &self.completing;
        let fact_ref = &self.fact_of;
        let mut missing: Vec<String> = reach
            .iter()
            .flat_map(|&f| {
                let func = &program.functions[f];
                // A function that never returns is entered only from paths the
                // program excludes (count 0): its loops need no bound.
                let needed = if func.returns { loops.get(f) } else { None };
                let live = &completing[&f];
                needed
                    .map(|ls| ls.as_slice())
                    .unwrap_or(&[])
                    .iter()
                    .enumerate()
                    .filter(move |(_, l)| live.get(l.header).copied().unwrap_or(false))
                    .filter(move |(k, _)| !fact_ref.contains_key(&(f, *k)))
                    .map(move |(_, l)| {
                        format!(
                            "{} loop at {:#x}",
                            func.demangled,
                            func.blocks.get(l.header).map_or(0, |b| b.start)
                        )
                    })
            })
            .collect();
        let in_reach: std::collections::HashSet<usize> = reach.iter().copied().collect();
        let sites: Vec<&CopySite> = self
            .copies
            .sites
            .iter()
            .filter(|c| in_reach.contains(&c.function))
            .filter(|c| {
                completing[&c.function]
                    .get(c.block)
                    .copied()
                    .unwrap_or(false)
            })
            .collect();
        missing.extend(
            sites
                .iter()
                .filter(|c| c.bytes.is_none())
                .map(|c| format!("block copy of unknown size at {}", c.at)),
        );
        if !missing.is_empty() {
            return Err(IpetError::Unbounded(missing));
        }
        Ok(sites)
    }

    /// Adds function `f`: its flow, its loops' cached lines, its block caps and
    /// its loop bounds.
    fn add_function(&mut self, f: usize) {
        let mut flow = self.add_flow(f);
        self.add_persistent_lines(&mut flow);
        self.add_block_caps(&flow);
        self.add_loop_bounds(&flow);
        self.per_function.push((f, flow.fcost));
    }

    /// Adds a variable `≥ 0`.
    fn add_var(&mut self) -> Variable {
        self.relaxed += 1;
        self.vars.add(variable().min(0.0))
    }

    /// Adds `count` calls into `to` from `from` (also a family call, if both copy).
    fn add_call(&mut self, from: usize, to: usize, count: Expression) {
        *self
            .calls_into
            .entry(to)
            .or_insert_with(|| Expression::from(0.0)) += count.clone();
        self.family.note(self.program, self.copies, from, to, count);
    }

    /// Adds function `f`'s block and edge counts, flow conservation, its exits
    /// and calls, and its blocks' costs.
    fn add_flow(&mut self, f: usize) -> FunctionFlow {
        let (program, cost) = (self.program, self.cost);
        let func = &program.functions[f];
        let live = reverse_post_order(func);
        let mut x: HashMap<usize, Variable> = HashMap::new();
        for &b in &live {
            let v = self.add_var();
            x.insert(b, v);
        }
        let mut edges: HashMap<(usize, usize), Variable> = HashMap::new();
        let mut inflow: HashMap<usize, Expression> = HashMap::new();
        let mut fcost = Expression::from(0.0);
        for &b in &live {
            let block = &func.blocks[b];
            let xb = x[&b];
            let mut out = Expression::from(0.0);
            for &s in &block.successors {
                let e = self.add_var();
                if cost == Cost::Cycles {
                    let saving = self.persistence.edge_saving(program, f, b, s) as f64;
                    if saving > 0.0 {
                        self.objective -= saving * e;
                        fcost -= saving * e;
                    }
                }
                edges.insert((b, s), e);
                out += e;
                *inflow.entry(s).or_insert_with(|| Expression::from(0.0)) += e;
            }
            let exits = block.successors.is_empty() || block.exit != Exit::Internal;
            let can_complete = self.completing[&f].get(b).copied().unwrap_or(false);
            if !can_complete {
                self.constraints.push(constraint!(xb == 0.0));
            }
            match &block.exit {
                Exit::NoReturn => self.constraints.push(constraint!(xb == 0.0)),
                _ if exits => {
                    let r = self.add_var();
                    out += r;
                    match &block.exit {
                        Exit::TailCall(t) => self.add_call(f, *t, r.into()),
                        Exit::IndirectTail(ts) => {
                            for t in ts {
                                self.add_call(f, *t, r.into());
                            }
                        }
                        _ => {}
                    }
                }
                _ => {}
            }
            self.constraints.push(constraint!(xb == out));
            for &c in block.calls.iter().filter(|_| can_complete) {
                self.add_call(f, c, xb.into());
            }
            let c = match cost {
                Cost::Instructions => block.instructions,
                Cost::Cycles => self.persistence.block_cycles(program, f, b),
            } as f64;
            self.objective += c * xb;
            fcost += c * xb;
            if c > 0.0 {
                self.per_block.push((f, b, xb, c as u64));
            }
        }
        for (&b, &v) in &x {
            self.x_all.insert((f, b), v);
        }
        for &b in &live {
            let mut inn = inflow.remove(&b).unwrap_or_else(|| Expression::from(0.0));
            if b == 0 {
                inn += self.n_entry[&f];
            }
            self.constraints.push(constraint!(x[&b] == inn));
        }
        FunctionFlow { f, x, edges, fcost }
    }

    /// In cycles: the lines of a loop that keeps them cached, once per entry.
    fn add_persistent_lines(&mut self, flow: &mut FunctionFlow) {
        if self.cost != Cost::Cycles {
            return;
        }
        let f = flow.f;
        for r in self
            .persistence
            .regions()
            .iter()
            .filter(|r| r.function == f)
        {
            if let Some(l) = self.loops.get(f).and_then(|ls| ls.get(r.loop_index)) {
                let c = self.persistence.entry_cycles(r) as f64;
                let entries = flow.entries_of(l, &self.n_entry);
                self.objective += c * entries.clone();
                flow.fcost += c * entries;
            }
        }
    }

    /// Caps on blocks per loop entry, and the runs of the caps per activation.
    fn add_block_caps(&mut self, flow: &FunctionFlow) {
        let f = flow.f;
        for cap in self.copies.caps.iter().filter(|c| c.function == f) {
            let runs = cap
                .blocks
                .iter()
                .filter_map(|b| flow.x.get(b))
                .fold(Expression::from(0.0), |a, &v| a + v);
            if let Some(g) = cap.activation_group {
                // Runs only in a call of `f`: at most the cap per entry of `f`
                // (see the loops' caps per activation below).
                let bound = cap.bound as f64;
                let n_f = self.n_entry[&f];
                self.constraints
                    .push(constraint!(runs.clone() <= bound * n_f));
                let g = self.copies.counters.get(&g).copied().unwrap_or(g);
                add_to_group(&mut self.group_runs, g, cap.bound, runs);
                continue;
            }
            let per = match cap.loop_index.and_then(|k| self.loops.get(f)?.get(k)) {
                Some(l) => flow.entries_of(l, &self.n_entry),
                None => Expression::from(self.n_entry[&f]),
            };
            let bound = cap.bound as f64;
            self.constraints.push(constraint!(runs <= bound * per));
        }
    }

    /// Loop bounds. The members of a shared bound first (they are nested in
    /// the loop they share it with, which comes first in `loops`), so walk
    /// the loops inner to outer.
    fn add_loop_bounds(&mut self, flow: &FunctionFlow) {
        let (f, loops) = (flow.f, self.loops);
        let func = &self.program.functions[f];
        let mut shared: HashMap<(usize, usize), Expression> = HashMap::new();
        let mut order: Vec<(usize, &Loop)> = loops
            .get(f)
            .map(|v| v.as_slice())
            .unwrap_or(&[])
            .iter()
            .enumerate()
            .collect();
        order.sort_by_key(|(k, _)| {
            std::cmp::Reverse(depth(loops.get(f).map_or(&[][..], |v| v), *k))
        });
        for (k, l) in order {
            let back: Expression = l
                .back_edges
                .iter()
                .filter_map(|e| flow.edges.get(e))
                .fold(Expression::from(0.0), |a, &v| a + v);
            if self.copies.family.contains(&f) {
                let all = loops.get(f).map_or(&[][..], |v| v.as_slice());
                let per_trip = min_stored_bytes_per_trip(func, all, l).max(1) as f64;
                *self
                    .copy_loops
                    .entry(f)
                    .or_insert_with(|| Expression::from(0.0)) += per_trip * back.clone();
            }
            let Some(&fact) = self.fact_of.get(&(f, k)) else {
                continue;
            };
            if let Some(g) = fact.group {
                // Counted with the loop it shares its bound with, below.
                *shared
                    .entry((f, g))
                    .or_insert_with(|| Expression::from(0.0)) += back;
                continue;
            }
            let members = shared.remove(&(f, k));
            self.add_loop_bound(flow, fact, l, back, members);
        }
    }

    /// The bound `fact` of loop `l` on its back edges `back` (with those of the
    /// loops that share it, `members`).
    fn add_loop_bound(
        &mut self,
        flow: &FunctionFlow,
        fact: &LoopFact,
        l: &Loop,
        back: Expression,
        members: Option<Expression>,
    ) {
        let f = flow.f;
        let func = &self.program.functions[f];
        // A bound on iterations of a loop whose header starts each of them
        // bounds the header's runs (entries + back edges), not the back edges.
        let runs_header = bounds_header_runs(fact, func, l, members.is_some());
        let back = back + members.unwrap_or_else(|| Expression::from(0.0));
        let back = if runs_header {
            back + flow.entries_of(l, &self.n_entry)
        } else {
            back
        };
        let bound = fact.bound as f64;
        let n_f = self.n_entry[&f];
        // A cap per activation also caps each entry's share. A loop runs only
        // in a call of its function, and its back edges are taken only after
        // one of its entry edges (an irreducible cycle's too: its entry edges
        // are every edge into it from outside): in any execution that takes
        // them, `back ≤ B ≤ B · n_f` and `≤ B · entries`. The relaxation, whose
        // counts are fractions, needs both. Without them it enters the
        // function a small fraction of the activation and still charges the
        // whole cap (the plan task's QP iterations on the path that adopts a
        // window), or carries flow round the cycle with no entry at all (a
        // circulation: the async tasks' cycle ran a job that way, without the
        // entry path of a real poll).
        if matches!(fact.per, Per::Activation | Per::Counted(_)) {
            self.constraints
                .push(constraint!(back.clone() <= bound * n_f));
            self.constraints.push(constraint!(
                back.clone() <= bound * flow.entries_of(l, &self.n_entry)
            ));
        }
        match fact.per {
            Per::Entry => {
                self.constraints.push(constraint!(
                    back <= bound * flow.entries_of(l, &self.n_entry)
                ));
            }
            Per::Activation => {
                let n_root = self.n_entry[&self.root];
                self.constraints.push(constraint!(back <= bound * n_root));
            }
            Per::Counted(g) => add_to_group(&mut self.group_runs, g, fact.bound, back),
            Per::Call => {
                self.constraints.push(constraint!(back <= bound * n_f));
            }
            Per::Preemption => {
                self.retry_edges += back;
                self.any_retry = true;
            }
            Per::Tick => {
                self.tick_edges += back;
                self.any_tick = true;
            }
        }
    }

    /// The block copies' budgets (`sites`: the copy calls the task can make).
    fn add_copy_budgets(&mut self, sites: &[&CopySite]) {
        if self.copy_loops.is_empty() {
            return;
        }
        let x_all = &self.x_all;
        let mut bytes = Expression::from(0.0);
        for c in sites {
            if let (Some(n), Some(&v)) = (c.bytes, x_all.get(&(c.function, c.block))) {
                bytes += n as f64 * v;
            }
        }
        // Every trip around a copy loop stores at least the bytes of its
        // shortest path (at least one byte; stores to the stack and conditional
        // ones not counted), and a call writes each byte of its destination once
        // (head, words and tail are disjoint; a `__aeabi_memcpy4` that hands its
        // remainder to `memcpy` hands over only the bytes it did not move): all
        // the family's trips, weighted by those bytes, take at most the bytes of
        // all the calls.
        let all = self
            .copy_loops
            .values()
            .fold(Expression::from(0.0), |a, b| a + b.clone());
        self.constraints.push(constraint!(all <= bytes));
        // And each function's own share: its loops store at most the bytes of
        // the calls made to it, from outside the family (their sizes) and from
        // its other functions (a word copy's remainder); a function that another
        // copy function calls with bytes unknown has only the shared budget.
        let sites_into = |g: usize| {
            let mut e = Expression::from(0.0);
            for c in sites.iter().filter(|c| c.callee == g) {
                if let (Some(n), Some(&v)) = (c.bytes, x_all.get(&(c.function, c.block))) {
                    e += n as f64 * v;
                }
            }
            e
        };
        let family = &mut self.family;
        for (g, own) in std::mem::take(&mut self.copy_loops) {
            // A forwarder's own callers must all be outside the family; each
            // forwarder counts once, however many of its blocks call `g`.
            let forwarded: std::collections::BTreeSet<usize> = family
                .forwards
                .iter()
                .filter(|f| f.0 == g)
                .map(|f| f.1)
                .collect();
            if family.unknown_handoff.contains(&g)
                || forwarded
                    .iter()
                    .any(|h| family.unknown_handoff.contains(h) || family.handoffs.contains_key(h))
            {
                continue;
            }
            let mut given = family
                .handoffs
                .remove(&g)
                .unwrap_or_else(|| Expression::from(0.0));
            given += sites_into(g);
            for h in forwarded {
                given += sites_into(h);
            }
            self.constraints.push(constraint!(own <= given));
        }
    }

    /// The caps over the whole activation: each activation group's, and the
    /// retries' (`retries` per activation).
    fn add_activation_caps(&mut self, retries: Retries) {
        let n_root = self.n_entry[&self.root];
        for (_, (bound, runs)) in std::mem::take(&mut self.group_runs) {
            let bound = bound as f64;
            self.constraints.push(constraint!(runs <= bound * n_root));
        }
        if self.any_retry {
            let cap = retries.preemption as f64;
            let retry_edges = std::mem::replace(&mut self.retry_edges, Expression::from(0.0));
            self.constraints
                .push(constraint!(retry_edges <= cap * n_root));
        }
        if self.any_tick {
            let cap = retries.tick as f64;
            let tick_edges = std::mem::replace(&mut self.tick_edges, Expression::from(0.0));
            self.constraints
                .push(constraint!(tick_edges <= cap * n_root));
        }
    }

    /// The entry counts: one for the root, the calls into it for every other
    /// function.
    fn add_call_counts(&mut self, reach: &[usize]) {
        for &f in reach {
            let n = self.n_entry[&f];
            if f == self.root {
                self.constraints.push(constraint!(n == 1.0));
            } else {
                let inn = self
                    .calls_into
                    .remove(&f)
                    .unwrap_or_else(|| Expression::from(0.0));
                self.constraints.push(constraint!(n == inn));
            }
        }
    }

    /// Solves the program; the bound, with the functions (cost and entries)
    /// and blocks of the worst path that cost the most.
    fn solve(self, reach: &[usize]) -> Result<IpetBound, IpetError> {
        let program = self.program;
        let variables = self.vars.len();
        let n_constraints = self.constraints.len();
        let integers: Vec<Variable> = reach.iter().map(|f| self.n_entry[f]).collect();
        let (solution, optimum) = solve_mixed_integer(
            self.vars,
            self.relaxed,
            &self.objective,
            &self.constraints,
            &integers,
        )?;
        let value = solution.eval(&self.objective);
        // Cost and entries per function, kept by index (two instances of a generic
        // function can demangle alike).
        let mut ranked: Vec<(usize, f64)> = self
            .per_function
            .iter()
            .map(|(f, e)| (*f, solution.eval(e)))
            .filter(|(_, v)| *v > 0.5)
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        let name = |f: usize| program.functions[f].demangled.clone();
        let by_function = ranked.iter().map(|&(f, v)| (name(f), v)).collect();
        let entries_by_function = ranked
            .iter()
            .map(|&(f, _)| (name(f), solution.value(self.n_entry[&f])))
            .collect();
        let mut by_block: Vec<BlockShare> = self
            .per_block
            .iter()
            .map(|&(f, b, x, c)| BlockShare {
                function: name(f),
                address: program.functions[f].blocks[b].start,
                count: solution.value(x),
                cost: c,
            })
            .filter(|s| s.count > 0.5)
            .collect();
        by_block.sort_by(|a, b| (b.count * b.cost as f64).total_cmp(&(a.count * a.cost as f64)));
        by_block.truncate(TOP_BLOCKS);
        Ok(IpetBound {
            bound: round_up(value),
            by_function,
            entries_by_function,
            by_block,
            variables,
            constraints: n_constraints,
            optimum,
        })
    }
}

/// Linear programs the branch and bound solves at most for one bound (each a
/// fresh simplex over the whole program: seconds on a task as large as `plan`).
pub const MAX_NODES: usize = 24;

/// The linear program `max objective` under `constraints`, over `count`
/// continuous variables `≥ 0` (the IPET's, in the order they were made), those at
/// the positions in `bounds` `(position, low, high)` within their bounds, by
/// `microlp`. The branching bounds are variable bounds (no extra row): a fresh
/// set of `count` variables has the IPET's handles, so `objective` and
/// `constraints` apply to it as they are.
fn solve_relaxation(
    count: usize,
    objective: &Expression,
    constraints: &[good_lp::Constraint],
    bounds: &[(usize, f64, f64)],
) -> Result<good_lp::solvers::microlp::MicroLpSolution, good_lp::ResolutionError> {
    let mut lo = vec![0.0f64; count];
    let mut hi = vec![f64::INFINITY; count];
    for &(k, l, h) in bounds {
        if let (Some(lo), Some(hi)) = (lo.get_mut(k), hi.get_mut(k)) {
            *lo = lo.max(l);
            *hi = hi.min(h);
        }
    }
    let bounded = || {
        let mut vars = ProblemVariables::new();
        for (&l, &h) in lo.iter().zip(&hi) {
            let d = variable().min(l);
            let _ = vars.add(if h.is_finite() { d.max(h) } else { d });
        }
        vars
    };
    solve_in_row_orders(bounded, objective, constraints, &ROW_ORDERS)
}

/// A position of the `k`-th row added among `n`.
type RowOrder = fn(usize, usize) -> usize;

/// The orders the rows of a program are given to `microlp` in, in turn: as made,
/// reversed, rotated by half. Its pivoting follows the rows' order, and a
/// singular basis met on one order is often not met on another (the same
/// program, the same optimum).
const ROW_ORDERS: [RowOrder; 3] = [|k, _| k, |k, n| n - 1 - k, |k, n| (k + n / 2) % n];

/// `max objective` under `constraints` over the variables `vars` makes, by
/// `microlp`, with the rows in each of `orders` in turn until one does not fail
/// numerically (an infeasible or unbounded program is that answer on any order);
/// the last numerical failure when every order fails.
fn solve_in_row_orders(
    vars: impl Fn() -> ProblemVariables,
    objective: &Expression,
    constraints: &[good_lp::Constraint],
    orders: &[RowOrder],
) -> Result<good_lp::solvers::microlp::MicroLpSolution, good_lp::ResolutionError> {
    let mut last = None;
    for order in orders {
        let mut problem = vars().maximise(objective.clone()).using(good_lp::microlp);
        let n = constraints.len();
        for k in 0..n {
            problem = problem.with(constraints[order(k, n)].clone());
        }
        match problem.solve() {
            Err(e @ (good_lp::ResolutionError::Other(_) | good_lp::ResolutionError::Str(_))) => {
                last = Some(e)
            }
            result => return result,
        }
    }
    Err(last.unwrap_or(good_lp::ResolutionError::Other("no row order solved")))
}

/// The mixed-integer optimum: `microlp`'s own branch and bound on `vars`, whose
/// `integers` are declared integer, and should it fail numerically (a singular
/// basis in one of its nodes) on the rows as made and reversed,
/// [`branch_and_bound`] over the `relaxed` variables of the same program,
/// continuous.
fn solve_mixed_integer(
    vars: ProblemVariables,
    relaxed: usize,
    objective: &Expression,
    constraints: &[good_lp::Constraint],
    integers: &[Variable],
) -> Result<(good_lp::solvers::microlp::MicroLpSolution, &'static str), IpetError> {
    // The rows as made, then reversed ([`ROW_ORDERS`]); past those, the branch
    // and bound.
    match solve_in_row_orders(|| vars.clone(), objective, constraints, &ROW_ORDERS[..2]) {
        Ok(s) => Ok((s, "integer")),
        Err(good_lp::ResolutionError::Infeasible | good_lp::ResolutionError::Unbounded) => Err(
            IpetError::Solver("the IPET program is infeasible or unbounded".into()),
        ),
        Err(_) => branch_and_bound(relaxed, objective, constraints, integers),
    }
}

/// The mixed-integer optimum, `integers` whole, by branch and bound over the
/// linear relaxations, best first (the open node with the largest relaxation is
/// split next, so the first whole solution reached is optimal): each node a
/// fresh simplex, so no numerical state carries from one to the next. Past
/// [`MAX_NODES`] it returns the open node with the largest relaxation: every
/// whole solution lies in some open node, so that value bounds them all.
fn branch_and_bound(
    count: usize,
    objective: &Expression,
    constraints: &[good_lp::Constraint],
    integers: &[Variable],
) -> Result<(good_lp::solvers::microlp::MicroLpSolution, &'static str), IpetError> {
    // A count within this of a whole number is that number.
    const WHOLE: f64 = 1e-6;
    type Bounds = Vec<(usize, f64, f64)>;
    // Each integer variable's position among the `count` (handles compare by
    // position: a fresh set made the same way has the same handles).
    let positions: Vec<(Variable, usize)> = {
        let mut fresh = ProblemVariables::new();
        let made: Vec<Variable> = (0..count).map(|_| fresh.add(variable())).collect();
        integers
            .iter()
            .filter_map(|&x| made.iter().position(|&m| m == x).map(|k| (x, k)))
            .collect()
    };
    // Open nodes: their relaxation's value, solution and bounds.
    let mut open: Vec<(f64, good_lp::solvers::microlp::MicroLpSolution, Bounds)> = Vec::new();
    let root = solve_relaxation(count, objective, constraints, &[])
        .map_err(|e| IpetError::Solver(e.to_string()))?;
    open.push((root.eval(objective), root, Vec::new()));
    let mut nodes = 1;
    loop {
        let Some(k) = (0..open.len()).max_by(|&a, &b| open[a].0.total_cmp(&open[b].0)) else {
            return Err(IpetError::Solver(
                "no whole solution: the functions' entry counts admit none".into(),
            ));
        };
        let (_, s, bounds) = open.swap_remove(k);
        let fractional = positions.iter().copied().find(|&(x, _)| {
            let y = s.value(x);
            (y - y.round()).abs() > WHOLE
        });
        let Some((x, position)) = fractional else {
            return Ok((s, "integer"));
        };
        if nodes + 2 > MAX_NODES {
            return Ok((s, "relaxation"));
        }
        let y = s.value(x);
        let mut down = bounds.clone();
        down.push((position, 0.0, y.floor()));
        let mut up = bounds;
        up.push((position, y.ceil(), f64::INFINITY));
        for b in [down, up] {
            nodes += 1;
            match solve_relaxation(count, objective, constraints, &b) {
                Ok(s) => open.push((s.eval(objective), s, b)),
                Err(good_lp::ResolutionError::Infeasible) => {}
                Err(e) => return Err(IpetError::Solver(e.to_string())),
            }
        }
    }
}

/// The optimum as an integer: a value within the simplex's tolerance (1e-7
/// relative) of an integer is that integer; anything else is rounded up.
fn round_up(value: f64) -> u64 {
    let nearest = value.round();
    if (value - nearest).abs() <= 1e-7 * value.abs().max(1.0) {
        nearest.max(0.0) as u64
    } else {
        value.ceil().max(0.0) as u64
    }
}

/// Most bytes `__aeabi_memcpy4` (and `__aeabi_memcpy8`, which is it) hands to
/// `memcpy`: compiler_builtins' `arm.rs` copies whole words while `n ≥ 4` and
/// passes the rest, `n < 4`, to `memcpy` (the toolchain is pinned in
/// `rust-toolchain.toml`, so the binary's helpers are this code). Without it the
/// family's one byte budget lets the worst path move every byte of a word copy
/// through `memcpy`'s costliest (misaligned) loop.
pub const REMAINDER_BYTES: u64 = 3;

/// The last path segment of a demangled name.
fn base_name(demangled: &str) -> &str {
    demangled.rsplit("::").next().unwrap_or(demangled)
}

/// Whether the function is one of the AEABI word copies that hand their
/// remainder to `memcpy`.
fn is_word_copy(demangled: &str) -> bool {
    matches!(base_name(demangled), "__aeabi_memcpy4" | "__aeabi_memcpy8")
}

/// Whether `caller` passes its arguments to `callee` unchanged:
/// compiler_builtins' `__aeabi_memmove`, `…4` and `…8` are `memmove(dest, src,
/// n)` (the alignment they promise is not used), so `memmove` moves the bytes of
/// their calls.
fn is_forwarder(caller: &str, callee: &str) -> bool {
    callee == "memmove"
        && matches!(
            caller,
            "__aeabi_memmove" | "__aeabi_memmove4" | "__aeabi_memmove8"
        )
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// `max x + y` with `2x + 2y ≤ 3`: the relaxation's optimum is 1.5, the
    /// integer one 1.
    fn half_program() -> (
        ProblemVariables,
        Vec<Variable>,
        Expression,
        Vec<good_lp::Constraint>,
    ) {
        let mut vars = ProblemVariables::new();
        let x = vars.add(variable().integer().min(0));
        let y = vars.add(variable().integer().min(0));
        let objective: Expression = x + y;
        let rows = vec![constraint!(2 * x + 2 * y <= 3)];
        (vars, vec![x, y], objective, rows)
    }

    #[test]
    fn the_branch_and_bound_reaches_the_integer_optimum_below_the_relaxation() {
        let (_, ints, objective, rows) = half_program();
        let root = solve_relaxation(2, &objective, &rows, &[]).unwrap();
        assert!((root.eval(&objective) - 1.5).abs() < 1e-9);
        let (s, how) = branch_and_bound(2, &objective, &rows, &ints).unwrap();
        assert_eq!(how, "integer");
        assert!((s.eval(&objective) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_mixed_integer_solve_gives_the_integer_optimum() {
        let (vars, ints, objective, rows) = half_program();
        let (s, how) = solve_mixed_integer(vars, 2, &objective, &rows, &ints).unwrap();
        assert_eq!(how, "integer");
        assert!((s.eval(&objective) - 1.0).abs() < 1e-9);
    }
}
