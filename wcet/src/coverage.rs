//! What the traces covered: the loops reachable from the tasks that no trace
//! executed, each with the reason read off the traces themselves (the function
//! never ran, and which call the traces never made; or the branch they never took
//! towards the loop). A bound on an untraced loop rests on its annotation's
//! argument alone; this list says which ones do, and why.

use super::cfg::{Exit, Program};
use super::loops::{immediate_dominators, Loop};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// A loop no trace executed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UntracedLoop {
    /// Function holding it (demangled).
    pub function: String,
    /// Address of its header.
    pub header: String,
    /// Its source file and line.
    pub file: String,
    /// Source line.
    pub line: u32,
    /// Tasks that reach it.
    pub tasks: Vec<String>,
    /// Why no trace reached it, from the traces.
    pub reason: String,
}

/// The loops' coverage by the traces.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Coverage {
    /// Loops reachable from a task's completing activations.
    pub loops: usize,
    /// Of those, executed by a trace (entered at least once).
    pub traced: usize,
    /// `traced / loops`, percent.
    pub percent: f64,
    /// The others, with their reasons.
    pub untraced: Vec<UntracedLoop>,
}

/// One loop of the analysis: where it is and who reaches it.
pub struct LoopSite<'a> {
    /// Function index and loop index.
    pub key: (usize, usize),
    /// Its source file and line.
    pub file: &'a str,
    /// Source line.
    pub line: u32,
    /// Tasks that reach it.
    pub tasks: &'a [String],
    /// Whether a trace executed it.
    pub traced: bool,
}

/// The coverage of `sites` by the blocks the traces ran (`blocks_run`, sorted
/// `(function, block)` pairs); `locate` gives an address's source line.
pub fn coverage(
    program: &Program,
    loops: &[Vec<Loop>],
    sites: &[LoopSite<'_>],
    blocks_run: &BTreeSet<(usize, usize)>,
    locate: &dyn Fn(u32) -> (String, u32),
) -> Coverage {
    let ran_function: BTreeSet<usize> = blocks_run.iter().map(|&(f, _)| f).collect();
    // Who calls whom, from which block (calls, tail calls, resolved indirect ones).
    let mut callers: BTreeMap<usize, Vec<(usize, usize)>> = BTreeMap::new();
    for (g, func) in program.functions.iter().enumerate() {
        for (b, block) in func.blocks.iter().enumerate() {
            let mut targets: Vec<usize> = block.calls.clone();
            match &block.exit {
                Exit::TailCall(t) => targets.push(*t),
                Exit::IndirectTail(ts) => targets.extend(ts.iter().copied()),
                _ => {}
            }
            for t in targets {
                callers.entry(t).or_default().push((g, b));
            }
        }
    }
    let name = |f: usize| {
        program
            .functions
            .get(f)
            .map_or("?".to_string(), |x| x.demangled.clone())
    };
    let at = |f: usize, b: usize| -> String {
        let Some(block) = program.functions.get(f).and_then(|x| x.blocks.get(b)) else {
            return "?".into();
        };
        let last = program.functions[f]
            .instructions
            .get(block.end.saturating_sub(1))
            .map_or(block.start, |i| i.address);
        let (file, line) = locate(last);
        format!("{file}:{line} ({last:#x})")
    };
    // The branch the traces never took towards block `b` of a function that ran:
    // the nearest dominator of `b` that ran ends with it.
    let decision = |f: usize, b: usize| -> Option<String> {
        let func = program.functions.get(f)?;
        let idom = immediate_dominators(func);
        let mut d = idom.get(b).copied().flatten();
        while let Some(x) = d {
            if blocks_run.contains(&(f, x)) {
                return Some(at(f, x));
            }
            d = idom.get(x).copied().flatten();
        }
        None
    };
    // Why function `f` never ran: the calls into it the traces never made, up the
    // callers until one that ran (a few levels).
    let why_not_called = |f: usize| -> String {
        let mut chain = vec![name(f)];
        let mut frontier = vec![f];
        let mut seen = BTreeSet::from([f]);
        for _ in 0..4 {
            let mut next = Vec::new();
            let mut found = Vec::new();
            for &g in &frontier {
                for &(c, b) in callers.get(&g).into_iter().flatten() {
                    if ran_function.contains(&c) {
                        let branch = decision(c, b)
                            .map(|d| format!(", past the branch at {d}"))
                            .unwrap_or_default();
                        found.push(format!(
                            "`{}` calls it at {}{branch}: the traces never took that call",
                            name(c),
                            at(c, b)
                        ));
                    } else if seen.insert(c) {
                        next.push(c);
                    }
                }
            }
            if !found.is_empty() {
                found.truncate(3);
                return format!("{} never ran; {}", chain.join(" ← "), found.join("; "));
            }
            if next.is_empty() {
                break;
            }
            chain.push(
                next.iter()
                    .take(2)
                    .map(|&c| format!("`{}`", name(c)))
                    .collect::<Vec<_>>()
                    .join(" or "),
            );
            frontier = next;
        }
        format!(
            "{} never ran, nor any caller that a trace ran",
            chain.join(" ← ")
        )
    };
    let mut untraced = Vec::new();
    for s in sites.iter().filter(|s| !s.traced) {
        let (f, x) = s.key;
        let Some(l) = loops.get(f).and_then(|ls| ls.get(x)) else {
            continue;
        };
        let header = program
            .functions
            .get(f)
            .and_then(|func| func.blocks.get(l.header))
            .map_or(0, |b| b.start);
        let reason = if !ran_function.contains(&f) {
            why_not_called(f)
        } else {
            match decision(f, l.header) {
                Some(d) => format!(
                    "`{}` ran, the loop did not: the traces never took the branch at {d} towards it",
                    name(f)
                ),
                None => format!("`{}` ran, the loop did not", name(f)),
            }
        };
        untraced.push(UntracedLoop {
            function: name(f),
            header: format!("{header:#x}"),
            file: s.file.to_string(),
            line: s.line,
            tasks: s.tasks.to_vec(),
            reason,
        });
    }
    let traced = sites.iter().filter(|s| s.traced).count();
    Coverage {
        loops: sites.len(),
        traced,
        percent: if sites.is_empty() {
            100.0
        } else {
            100.0 * traced as f64 / sites.len() as f64
        },
        untraced,
    }
}
