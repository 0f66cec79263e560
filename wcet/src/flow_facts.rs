//! Flow facts: the bounds the IPET takes over more than one loop entry (per
//! activation of a task, per call of a function, a counter shared by several
//! places, the calls of a line capped per activation, the retries an exception
//! can cause), each with what it counts in the binary, so that every QEMU trace
//! checks it as it checks a loop's bound per entry.
//!
//! A fact counts exactly what [`super::ipet`] constrains: a loop's back edges
//! (and its entries, where the bound is on iterations of a loop whose header
//! starts each of them, [`ipet::bounds_header_runs`]), the back edges of the
//! nested loops that share its bound, and the runs of the blocks whose calls a
//! `times per activation` line caps. A fact no trace exercised is reported as
//! such: its bound rests on the argument written beside it alone.

use super::annotations::Annotation;
use super::cfg::Program;
use super::ipet::{self, CopySizes, LoopFact, Per};
use super::loops::Loop;
use super::trace_check::{CounterScope, CounterSpec, TraceCheck};
use serde::Serialize;
use std::collections::BTreeMap;

/// One flow fact, what bounds it and what the traces saw of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlowFact {
    /// The counter's name (`counted in NAME`), else the fact's source line.
    pub name: String,
    /// What one count is per: `activation`, `call of FUNCTION`, `loop entry`.
    pub per: String,
    /// What is counted: loop iterations, calls of a line, retries.
    pub counts: String,
    /// The bound per scope (for retries, per task: `bound_by_task`).
    pub bound: u64,
    /// Per task, where the bound depends on the task (retries: its preemptions).
    pub bound_by_task: Vec<(String, u64)>,
    /// The annotations or rules that state it (`file:line: expression`).
    pub sources: Vec<String>,
    /// Loops and blocks it counts on.
    pub members: usize,
    /// Largest count in one scope over the traces; `None`: no trace exercised it.
    pub observed_max: Option<u64>,
    /// Scopes (activations, calls, entries) in which the traces saw it count.
    pub observed_scopes: u64,
    /// What the replay counts for it.
    #[serde(skip)]
    pub counter: CounterSpec,
}

impl FlowFact {
    /// A fact no trace has been checked against yet (no count observed), its
    /// bound the same for every task.
    fn unobserved(
        name: String,
        per: String,
        counts: String,
        bound: u64,
        sources: Vec<String>,
        members: usize,
        counter: CounterSpec,
    ) -> Self {
        Self {
            name,
            per,
            counts,
            bound,
            bound_by_task: Vec::new(),
            sources,
            members,
            observed_max: None,
            observed_scopes: 0,
            counter,
        }
    }

    /// Whether a trace exercised the fact.
    pub fn exercised(&self) -> bool {
        self.observed_max.is_some()
    }
}

/// A fact's name from the annotation that states it (`file:line: `expression``):
/// its `file:line`.
fn stated_name(stated: &str) -> String {
    stated.split(": `").next().unwrap_or(stated).to_string()
}

/// The counted edges of one loop fact: its back edges, and its entries where
/// the bound counts the header's runs.
fn loop_edges(
    program: &Program,
    loops: &[Vec<Loop>],
    fact: &LoopFact,
    shared: bool,
) -> Vec<(usize, usize, usize)> {
    let f = fact.function;
    let (Some(func), Some(l)) = (
        program.functions.get(f),
        loops.get(f).and_then(|ls| ls.get(fact.loop_index)),
    ) else {
        return Vec::new();
    };
    let mut edges: Vec<(usize, usize, usize)> =
        l.back_edges.iter().map(|&(a, b)| (f, a, b)).collect();
    if ipet::bounds_header_runs(fact, func, l, shared) {
        edges.extend(l.entry_edges.iter().map(|&(a, b)| (f, a, b)));
    }
    edges
}

/// The flow facts of an analysis: `facts` (the loops' bounds), `copies.caps` (the
/// capped lines), `annotations` (for names and sources), `origin` (each loop
/// fact's stated source) and `retries` (per task, the retries an activation can
/// make: its preemptions, [`crate::target::Target::preemptions_of`], × the
/// retries per preemption, and its ticks × the retries per tick).
///
/// The loops' facts first (in `facts`' order), then the capped lines', then the
/// shared counters (by group) and the retries.
pub fn flow_facts(
    program: &Program,
    loops: &[Vec<Loop>],
    facts: &[LoopFact],
    copies: &CopySizes,
    annotations: &[Annotation],
    origin: &BTreeMap<(usize, usize), String>,
    retries: &[(String, ipet::Retries)],
) -> Vec<FlowFact> {
    let mut b = FactBuilder {
        program,
        annotations,
        out: Vec::new(),
        groups: BTreeMap::new(),
        retry: retry_fact(retries),
        tick: tick_fact(retries),
    };
    for fact in facts.iter().filter(|f| f.group.is_none()) {
        b.add_loop_fact(loops, facts, origin, fact);
    }
    for cap in &copies.caps {
        b.add_cap(copies, cap);
    }
    b.finish()
}

/// The flow facts found so far.
struct FactBuilder<'a> {
    program: &'a Program,
    annotations: &'a [Annotation],
    /// The facts of one loop or line each.
    out: Vec<FlowFact>,
    /// Counters shared by annotations (`counted in NAME`, and the caps per
    /// activation of a line), by their group's annotation index.
    groups: BTreeMap<usize, FlowFact>,
    /// The retries an exception can cause, over every retry loop.
    retry: FlowFact,
    /// The retries the monotonic's tick can cause, over every `per tick` loop.
    tick: FlowFact,
}

/// The fact over the retry loops (load/store-exclusive, `per preemption`), before
/// any member: its bound is each task's `retries` per activation.
fn retry_fact(retries: &[(String, ipet::Retries)]) -> FlowFact {
    let by_task: Vec<(String, u64)> = retries
        .iter()
        .map(|(t, r)| (t.clone(), r.preemption))
        .collect();
    FlowFact {
        bound_by_task: by_task.clone(),
        ..FlowFact::unobserved(
            "exception retries".into(),
            "activation".into(),
            "back edges of the retry loops (load/store-exclusive, `per preemption`)".into(),
            by_task.iter().map(|r| r.1).max().unwrap_or(0),
            vec![
                "one retry per preemption of the activation (an exception clears the exclusive monitor; `wcet-bound: N per preemption`)"
                    .into(),
            ],
            0,
            activation_counter(),
        )
    }
}

/// The fact over the loops that retry when the monotonic ticks (`per tick`),
/// before any member: its bound is each task's tick retries per activation.
fn tick_fact(retries: &[(String, ipet::Retries)]) -> FlowFact {
    let by_task: Vec<(String, u64)> = retries.iter().map(|(t, r)| (t.clone(), r.tick)).collect();
    FlowFact {
        bound_by_task: by_task.clone(),
        ..FlowFact::unobserved(
            "tick retries".into(),
            "activation".into(),
            "back edges of the loops that retry when the tick count changes (`per tick`)".into(),
            by_task.iter().map(|r| r.1).max().unwrap_or(0),
            vec![
                "retries per SysTick that preempts the activation (the tick count read twice; `wcet-bound: N per tick`)"
                    .into(),
            ],
            0,
            activation_counter(),
        )
    }
}

/// An empty counter per activation (its members added as they are found).
fn activation_counter() -> CounterSpec {
    CounterSpec {
        scope: CounterScope::Activation,
        blocks: Vec::new(),
        edges: Vec::new(),
    }
}

/// Annotation `k` as a source (`file:line: `expression``).
fn source(annotations: &[Annotation], k: usize) -> String {
    annotations.get(k).map_or("?".to_string(), |a| {
        format!("{}:{}: `{}`", a.file, a.line, a.expression)
    })
}

/// The shared counter of group `g` (an annotation index), without members.
fn group_fact(annotations: &[Annotation], g: usize) -> FlowFact {
    let a = annotations.get(g);
    let counter = a.and_then(|a| a.counter.clone());
    let sources: Vec<String> = match &counter {
        Some(c) => annotations
            .iter()
            .enumerate()
            .filter(|(_, b)| b.counter.as_deref() == Some(c.as_str()))
            .map(|(k, _)| source(annotations, k))
            .collect(),
        None => vec![source(annotations, g)],
    };
    FlowFact::unobserved(
        counter.unwrap_or_else(|| a.map_or("?".to_string(), |a| format!("{}:{}", a.file, a.line))),
        "activation".into(),
        String::new(),
        a.map_or(0, |a| a.bound),
        sources,
        0,
        activation_counter(),
    )
}

impl FactBuilder<'_> {
    /// Function `f`'s demangled name.
    fn name_of(&self, f: usize) -> String {
        self.program
            .functions
            .get(f)
            .map_or("?".to_string(), |x| x.demangled.clone())
    }

    /// The shared counter of group `g`, made on its first member.
    fn group(&mut self, g: usize) -> &mut FlowFact {
        let annotations = self.annotations;
        self.groups
            .entry(g)
            .or_insert_with(|| group_fact(annotations, g))
    }

    /// The flow fact of one loop's bound `fact` (with the loops that share it),
    /// unless it is a bound per entry alone; `origin` gives its stated source.
    fn add_loop_fact(
        &mut self,
        loops: &[Vec<Loop>],
        facts: &[LoopFact],
        origin: &BTreeMap<(usize, usize), String>,
        fact: &LoopFact,
    ) {
        let program = self.program;
        let (f, x) = (fact.function, fact.loop_index);
        // Loops whose bound another loop of the same function shares.
        let shared: Vec<&LoopFact> = facts
            .iter()
            .filter(|g| g.function == f && g.group == Some(x))
            .collect();
        let mut edges = loop_edges(program, loops, fact, !shared.is_empty());
        for m in &shared {
            edges.extend(loop_edges(program, loops, m, true));
        }
        let n = 1 + shared.len();
        let stated = origin.get(&(f, x)).cloned().unwrap_or_default();
        match fact.per {
            // A bound per entry alone is checked as a loop bound; shared with the
            // nested loops split from it (`same loop`), their back edges together
            // are a flow fact per entry of this loop.
            Per::Entry if shared.is_empty() => {}
            Per::Entry => self.out.push(FlowFact::unobserved(
                stated_name(&stated),
                format!("entry of a loop of `{}`", self.name_of(f)),
                format!("iterations of one source loop split into {n} binary loops (`same loop`)"),
                fact.bound,
                vec![stated],
                n,
                CounterSpec {
                    scope: CounterScope::LoopEntry(f, x),
                    blocks: Vec::new(),
                    edges,
                },
            )),
            Per::Preemption => {
                self.retry.counter.edges.extend(edges);
                self.retry.members += n;
            }
            Per::Tick => {
                self.tick.counter.edges.extend(edges);
                self.tick.members += n;
            }
            Per::Counted(g) => {
                let e = self.group(g);
                e.counter.edges.extend(edges);
                e.members += n;
            }
            Per::Activation | Per::Call => {
                let (per, scope) = match fact.per {
                    Per::Call => (
                        format!("call of `{}`", self.name_of(f)),
                        CounterScope::Call(f),
                    ),
                    _ => ("activation".to_string(), CounterScope::Activation),
                };
                self.out.push(FlowFact::unobserved(
                    stated_name(&stated),
                    per,
                    format!("iterations of a loop of `{}`", self.name_of(f)),
                    fact.bound,
                    vec![stated],
                    n,
                    CounterSpec {
                        scope,
                        blocks: Vec::new(),
                        edges,
                    },
                ));
            }
        }
    }

    /// The flow fact of one capped line `cap`: its own, or a member of its
    /// activation group's counter.
    fn add_cap(&mut self, copies: &CopySizes, cap: &ipet::BlockCap) {
        let blocks = cap.blocks.iter().map(|&b| (cap.function, b));
        match cap.activation_group {
            Some(g) => {
                let g = copies.counters.get(&g).copied().unwrap_or(g);
                let e = self.group(g);
                e.counter.blocks.extend(blocks);
                e.members += cap.blocks.len();
            }
            None => {
                let scope = match cap.loop_index {
                    Some(l) => CounterScope::LoopEntry(cap.function, l),
                    None => CounterScope::Call(cap.function),
                };
                let stated = cap
                    .annotation
                    .map_or_else(String::new, |k| source(self.annotations, k));
                let per = match cap.loop_index {
                    Some(_) => format!("loop entry in `{}`", self.name_of(cap.function)),
                    None => format!("call of `{}`", self.name_of(cap.function)),
                };
                self.out.push(FlowFact::unobserved(
                    stated_name(&stated),
                    per,
                    "runs of the line's calls".into(),
                    cap.bound,
                    vec![stated],
                    cap.blocks.len(),
                    CounterSpec {
                        scope,
                        blocks: blocks.collect(),
                        edges: Vec::new(),
                    },
                ));
            }
        }
    }

    /// The facts: each loop's and line's, then the shared counters (named for
    /// what they count) and the retries if any loop retries; each counter's
    /// edges and blocks sorted, once each.
    fn finish(self) -> Vec<FlowFact> {
        let mut out = self.out;
        for mut g in self.groups.into_values() {
            g.counts = match (g.counter.edges.is_empty(), g.counter.blocks.is_empty()) {
                (false, false) => "loop iterations and runs of capped calls, summed".into(),
                (false, true) => "loop iterations, summed over the loops".into(),
                _ => "runs of the line's calls, every inlined copy".into(),
            };
            out.push(g);
        }
        if self.retry.members > 0 {
            out.push(self.retry);
        }
        if self.tick.members > 0 {
            out.push(self.tick);
        }
        for f in &mut out {
            f.counter.edges.sort_unstable();
            f.counter.edges.dedup();
            f.counter.blocks.sort_unstable();
            f.counter.blocks.dedup();
        }
        out
    }
}

/// Folds one trace's counts into `facts` (whose counters were given to the
/// replay in this order); returns one message per fact the trace saw above its
/// bound.
pub fn observe(facts: &mut [FlowFact], check: &TraceCheck, trace: &str) -> Vec<String> {
    let mut violations = Vec::new();
    for (fact, seen) in facts.iter_mut().zip(&check.counters) {
        if seen.scopes == 0 {
            continue;
        }
        fact.observed_scopes += seen.scopes;
        fact.observed_max = Some(fact.observed_max.unwrap_or(0).max(seen.max));
        let over: Vec<String> = if fact.bound_by_task.is_empty() {
            (seen.max > fact.bound)
                .then(|| format!("observed {}", seen.max))
                .into_iter()
                .collect()
        } else {
            seen.by_root
                .iter()
                .filter_map(|(task, n)| {
                    let b = fact
                        .bound_by_task
                        .iter()
                        .find(|(t, _)| t == task)
                        .map_or(0, |x| x.1);
                    (*n > b).then(|| format!("task {task}: bound {b}, observed {n}"))
                })
                .collect()
        };
        if !over.is_empty() {
            violations.push(format!(
                "{trace}: flow fact `{}` ({} per {}, bound {}; {}): {}",
                fact.name,
                fact.counts,
                fact.per,
                fact.bound,
                fact.sources.join("; "),
                over.join(", ")
            ));
        }
    }
    violations
}
