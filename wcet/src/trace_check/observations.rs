//! What a replayed trace observed: per loop its entries and back edges, per
//! root its activations' costs, the flow facts' counters, the sections and the
//! indirect transfers ([`TraceCheck`]).

use serde::Serialize;

/// How many of the largest activation costs [`RootObservation::largest_instructions`]
/// keeps.
pub const LARGEST_KEPT: usize = 10;

/// How many diagnostic examples [`TraceCheck::examples`] keeps.
pub(super) const MAX_EXAMPLES: usize = 20;

/// What one loop did in the trace.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LoopObservation {
    /// Function index in the [`crate::cfg::Program`].
    pub function: usize,
    /// Demangled function name.
    pub function_name: String,
    /// Loop index in the function's loops (as given to [`check_trace`]).
    pub loop_index: usize,
    /// Address of the loop header's first instruction.
    pub header: u32,
    /// Entries seen (the header reached from outside the loop).
    pub entries: u64,
    /// Back-edge traversals seen, all entries together.
    pub back_edges: u64,
    /// Largest number of back-edge traversals in one entry.
    pub max_back_edges: u64,
    /// Back edges taken in an entry the trace did not show (the loop was running
    /// when the trace began, or the context was lost): they are in `back_edges`,
    /// and in `max_back_edges` as an entry of their own.
    pub back_edges_without_entry: u64,
    /// Per execution context that ran the loop (a root's task name, `thread`, or a
    /// handler's name): `(context, entries, max_back_edges)`.
    pub by_context: Vec<(String, u64, u64)>,
}

/// What the activations of one root did in the trace.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RootObservation {
    /// Task name, as given.
    pub name: String,
    /// The root's function index.
    pub function: usize,
    /// Complete activations seen (exception entry to exception return).
    pub activations: u64,
    /// Largest activation cost, instructions (sum of the entered blocks'
    /// `instructions`, nested exceptions excluded).
    pub max_instructions: u64,
    /// Largest activation cost, static worst-case cycles (sum of the entered
    /// blocks' `cycles`, nested exceptions excluded).
    pub max_cycles: u64,
    /// Largest number of instructions actually executed in one activation (nested
    /// exceptions excluded); equal to `max_instructions` unless a block was left
    /// before its end.
    pub max_executed: u64,
    /// The largest activation costs, instructions (up to [`LARGEST_KEPT`],
    /// descending).
    pub largest_instructions: Vec<u64>,
    /// Sum of the activations' instructions (block costs).
    pub total_instructions: u64,
    /// Sum of the activations' static cycles.
    pub total_cycles: u64,
    /// Activations preempted at least once by another exception.
    pub preempted_activations: u64,
    /// Activations still running at the end of the trace (not counted above).
    pub incomplete: u64,
}

/// What a flow-fact counter's count is per: the quantity a fact caps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum CounterScope {
    /// One activation of a root (a task), nested exceptions excluded.
    Activation,
    /// One call of the function (its index), tail calls from it ending it.
    Call(usize),
    /// One entry of a loop `(function, loop index)`.
    LoopEntry(usize, usize),
}

/// A counter the replay keeps for a flow fact: every entry of one of `blocks`
/// and every traversal of one of `edges` adds one, per `scope`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CounterSpec {
    /// What the count is per.
    pub scope: CounterScope,
    /// Blocks `(function, block)` whose entries count.
    pub blocks: Vec<(usize, usize)>,
    /// Edges `(function, from block, to block)` whose traversals count; `from` =
    /// `usize::MAX` is the function's entry (a call or tail call into block 0).
    pub edges: Vec<(usize, usize, usize)>,
}

/// What a counter counted.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct CounterObservation {
    /// Scopes that ended with a count (activations, calls or loop entries); an
    /// activation counts only if the counter moved in it.
    pub scopes: u64,
    /// Largest count in one scope.
    pub max: u64,
    /// Sum over the scopes.
    pub total: u64,
    /// Per task (counters per activation): `(task, largest count)`.
    pub by_root: Vec<(String, u64)>,
}

/// The calls of a section (a job bounded apart, a function called from a task).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct SectionObservation {
    /// Section name, as given.
    pub name: String,
    /// Its function index.
    pub function: usize,
    /// Complete calls seen (call to return).
    pub calls: u64,
    /// Largest call, instructions (its blocks' and its callees', nested
    /// exceptions excluded).
    pub max_instructions: u64,
    /// Largest call, static worst-case cycles of the same blocks.
    pub max_cycles: u64,
}

/// An indirect call or jump seen in the trace.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IndirectObservation {
    /// Address of the `blx rN` / `bx rN` (or other register branch).
    pub site: u32,
    /// The function holding it (index; `usize::MAX` if none).
    pub from: usize,
    /// The function it went to (index).
    pub target: usize,
    /// Its demangled name.
    pub target_name: String,
    /// Times taken.
    pub count: u64,
}

/// The replay of a trace.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TraceCheck {
    /// Every loop executed at least once (entered or iterated), by function then
    /// loop index.
    pub loops: Vec<LoopObservation>,
    /// The flow-fact counters given to the replay, in their order.
    pub counters: Vec<CounterObservation>,
    /// The sections given to the replay, in their order.
    pub sections: Vec<SectionObservation>,
    /// Indirect calls and jumps taken, by site then target.
    pub indirect_calls: Vec<IndirectObservation>,
    /// Blocks `(function, block)` entered at least once, in any context, sorted.
    #[serde(skip)]
    pub blocks_run: Vec<(usize, usize)>,
    /// Per root, in the order given.
    pub roots: Vec<RootObservation>,
    /// Activations of exception handlers that are not roots (faults), by name.
    pub other_handlers: Vec<(String, u64)>,
    /// Translation block executions replayed.
    pub tb_executions: u64,
    /// Instructions replayed.
    pub instructions: u64,
    /// Block entries (each block execution counted once).
    pub block_entries: u64,
    /// Exception entries recognised.
    pub exception_entries: u64,
    /// Executed instructions at an address that is no instruction of any function
    /// of the disassembly.
    pub outside_functions: u64,
    /// `Trace` lines whose translation is not in the log (skipped; the stream is
    /// broken there).
    pub untraced_executions: u64,
    /// Executions QEMU stopped before they ran or rewound (dropped, or replayed up
    /// to where execution resumed).
    pub abandoned_executions: u64,
    /// Control transfers the graphs do not have: an edge between blocks that is no
    /// successor edge, a return elsewhere than after its call, a jump into the
    /// middle of another function, a fall-through that did not fall through.
    pub unexpected_transfers: u64,
    /// The first few unexpected transfers and other oddities, described.
    pub examples: Vec<String>,
}

impl TraceCheck {
    /// The loops observed in a context (a root's task name, `thread`, or a handler's
    /// name).
    pub fn loops_of(&self, context: &str) -> Vec<&LoopObservation> {
        self.loops
            .iter()
            .filter(|l| l.by_context.iter().any(|(c, _, _)| c == context))
            .collect()
    }

    /// Checks the observed loops against static bounds `(function, loop, max back
    /// edges per entry)`: one message per loop whose observed maximum exceeds its
    /// bound (the bound is then wrong, or the graph is).
    pub fn violations(&self, bounds: &[(usize, usize, u64)]) -> Vec<String> {
        let mut out = Vec::new();
        for &(function, loop_index, bound) in bounds {
            let Some(seen) = self
                .loops
                .iter()
                .find(|l| l.function == function && l.loop_index == loop_index)
            else {
                continue;
            };
            if seen.max_back_edges > bound {
                out.push(format!(
                    "{}: loop {} at {:#010x}: bound {} back edges per entry, observed {} (in {} entries)",
                    seen.function_name,
                    loop_index,
                    seen.header,
                    bound,
                    seen.max_back_edges,
                    seen.entries
                ));
            }
        }
        out
    }
}
