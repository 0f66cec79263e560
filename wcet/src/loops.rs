//! Natural loops of a function's control-flow graph.
//!
//! Dominators by the iterative algorithm of Cooper, Harvey and Kennedy ("A Simple,
//! Fast Dominance Algorithm", 2001) over the reverse post-order; a back edge is an
//! edge `t → h` whose head `h` dominates its tail; the natural loop of `h` is `h`
//! and every block that reaches one of its back edges' tails without passing
//! through `h`. A cycle that no back edge closes (an irreducible loop: two entries)
//! has no header to bound and is refused.

use super::cfg::Function;
use super::WcetError;
use std::collections::BTreeSet;

/// A natural loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Loop {
    /// Header block (the loop's only entry).
    pub header: usize,
    /// Blocks of the loop, header included, ascending.
    pub blocks: Vec<usize>,
    /// Back edges `(tail, header)`.
    pub back_edges: Vec<(usize, usize)>,
    /// Entry edges `(outside block, header)`; the function's entry counts as one
    /// when the header is block 0 (`usize::MAX` as its tail).
    pub entry_edges: Vec<(usize, usize)>,
    /// The innermost loop containing this one (index into the function's loops).
    pub parent: Option<usize>,
    /// An irreducible cycle (several entry blocks): `header` is its first entry
    /// block, `back_edges` every edge from inside the cycle to one of its entry
    /// blocks, `entry_edges` every edge from outside into it.
    pub irreducible: bool,
}

/// How many loops of `loops` enclose loop `k`.
pub fn depth(loops: &[Loop], mut k: usize) -> usize {
    let mut d = 0;
    while let Some(p) = loops.get(k).and_then(|l| l.parent) {
        d += 1;
        k = p;
    }
    d
}

/// Blocks reachable from the entry, in reverse post-order.
pub fn reverse_post_order(f: &Function) -> Vec<usize> {
    let n = f.blocks.len();
    let mut seen = vec![false; n];
    let mut post = Vec::with_capacity(n);
    if n == 0 {
        return post;
    }
    let mut stack: Vec<(usize, usize)> = vec![(0, 0)];
    seen[0] = true;
    while let Some((b, k)) = stack.pop() {
        if let Some(&s) = f.blocks[b].successors.get(k) {
            stack.push((b, k + 1));
            if !seen[s] {
                seen[s] = true;
                stack.push((s, 0));
            }
        } else {
            post.push(b);
        }
    }
    post.reverse();
    post
}

/// Immediate dominator of every block reachable from the entry (`None` for the
/// entry and for unreachable blocks).
pub fn immediate_dominators(f: &Function) -> Vec<Option<usize>> {
    let n = f.blocks.len();
    let rpo = reverse_post_order(f);
    let mut order = vec![usize::MAX; n];
    for (k, &b) in rpo.iter().enumerate() {
        order[b] = k;
    }
    let preds = f.predecessors();
    let mut idom: Vec<Option<usize>> = vec![None; n];
    if n == 0 {
        return idom;
    }
    idom[0] = Some(0);
    let intersect = |idom: &[Option<usize>], mut a: usize, mut b: usize| -> usize {
        while a != b {
            while order[a] > order[b] {
                a = idom[a].unwrap_or(0);
            }
            while order[b] > order[a] {
                b = idom[b].unwrap_or(0);
            }
        }
        a
    };
    let mut changed = true;
    while changed {
        changed = false;
        for &b in rpo.iter().skip(1) {
            let mut new: Option<usize> = None;
            for &p in &preds[b] {
                if idom[p].is_none() {
                    continue;
                }
                new = Some(match new {
                    None => p,
                    Some(x) => intersect(&idom, p, x),
                });
            }
            if new.is_some() && idom[b] != new {
                idom[b] = new;
                changed = true;
            }
        }
    }
    idom[0] = None;
    idom
}

/// Whether `a` dominates `b`.
fn dominates(idom: &[Option<usize>], a: usize, mut b: usize) -> bool {
    loop {
        if a == b {
            return true;
        }
        match idom[b] {
            Some(p) => b = p,
            None => return false,
        }
    }
}

/// The loops of a function, or the blocks of an irreducible cycle
/// ([`WcetError::Irreducible`]).
pub fn natural_loops(f: &Function) -> Result<Vec<Loop>, WcetError> {
    let idom = immediate_dominators(f);
    let rpo = reverse_post_order(f);
    let reachable: BTreeSet<usize> = rpo.iter().copied().collect();
    let preds = f.predecessors();
    let mut loops: Vec<Loop> = Vec::new();
    for &h in &rpo {
        let backs: Vec<(usize, usize)> = preds[h]
            .iter()
            .filter(|&&t| reachable.contains(&t) && dominates(&idom, h, t))
            .map(|&t| (t, h))
            .collect();
        if backs.is_empty() {
            continue;
        }
        let mut body = BTreeSet::from([h]);
        let mut stack: Vec<usize> = backs.iter().map(|&(t, _)| t).collect();
        while let Some(b) = stack.pop() {
            if body.insert(b) {
                stack.extend(preds[b].iter().copied().filter(|p| reachable.contains(p)));
            }
        }
        let mut entry_edges: Vec<(usize, usize)> = preds[h]
            .iter()
            .filter(|p| reachable.contains(p) && !body.contains(p))
            .map(|&p| (p, h))
            .collect();
        if h == 0 {
            entry_edges.push((usize::MAX, 0));
        }
        loops.push(Loop {
            header: h,
            blocks: body.into_iter().collect(),
            back_edges: backs,
            entry_edges,
            parent: None,
            irreducible: false,
        });
    }
    // Irreducible cycles: strongly connected parts left after removing every back
    // edge. Each becomes a loop whose "back edges" are the edges into its entry
    // blocks from inside; if cycles remain without them, the graph is refused.
    let mut back: BTreeSet<(usize, usize)> = loops
        .iter()
        .flat_map(|l| l.back_edges.iter().copied())
        .collect();
    for region in cyclic_regions(f, &reachable, &back) {
        let set: BTreeSet<usize> = region.iter().copied().collect();
        let mut entries: BTreeSet<usize> = BTreeSet::new();
        let mut entry_edges = Vec::new();
        for &b in &region {
            for &p in &preds[b] {
                if reachable.contains(&p) && !set.contains(&p) && !back.contains(&(p, b)) {
                    entries.insert(b);
                    entry_edges.push((p, b));
                }
            }
            if b == 0 {
                entries.insert(0);
                entry_edges.push((usize::MAX, 0));
            }
        }
        let mut pseudo: Vec<(usize, usize)> = Vec::new();
        for &b in &region {
            for &s in &f.blocks[b].successors {
                if entries.contains(&s) && !back.contains(&(b, s)) {
                    pseudo.push((b, s));
                }
            }
        }
        back.extend(pseudo.iter().copied());
        loops.push(Loop {
            header: entries.iter().next().copied().unwrap_or(region[0]),
            blocks: region,
            back_edges: pseudo,
            entry_edges,
            parent: None,
            irreducible: true,
        });
    }
    if let Some(cycle) = forward_cycle(f, &reachable, &back) {
        return Err(WcetError::Irreducible(cycle));
    }
    // Nesting: the smallest loop strictly containing each loop.
    let sets: Vec<BTreeSet<usize>> = loops
        .iter()
        .map(|l| l.blocks.iter().copied().collect())
        .collect();
    for i in 0..loops.len() {
        let mut best: Option<usize> = None;
        for j in 0..loops.len() {
            if i != j && sets[j].is_superset(&sets[i]) && sets[j].len() > sets[i].len() {
                best = match best {
                    Some(b) if sets[b].len() <= sets[j].len() => Some(b),
                    _ => Some(j),
                };
            }
        }
        loops[i].parent = best;
    }
    Ok(loops)
}

/// A cycle of the graph without the back edges, if any (its blocks).
fn forward_cycle(
    f: &Function,
    reachable: &BTreeSet<usize>,
    back: &BTreeSet<(usize, usize)>,
) -> Option<Vec<usize>> {
    let n = f.blocks.len();
    // Kahn's algorithm: what cannot be ordered lies on or behind a cycle.
    let mut indegree = vec![0usize; n];
    for &b in reachable {
        for &s in &f.blocks[b].successors {
            if !back.contains(&(b, s)) && reachable.contains(&s) {
                indegree[s] += 1;
            }
        }
    }
    let mut ready: Vec<usize> = reachable
        .iter()
        .copied()
        .filter(|&b| indegree[b] == 0)
        .collect();
    let mut done = 0;
    while let Some(b) = ready.pop() {
        done += 1;
        for &s in &f.blocks[b].successors {
            if !back.contains(&(b, s)) && reachable.contains(&s) {
                indegree[s] -= 1;
                if indegree[s] == 0 {
                    ready.push(s);
                }
            }
        }
    }
    (done < reachable.len()).then(|| {
        reachable
            .iter()
            .copied()
            .filter(|&b| indegree[b] > 0)
            .collect()
    })
}

/// Strongly connected regions with a cycle, of the graph without the `back`
/// edges.
fn cyclic_regions(
    f: &Function,
    reachable: &BTreeSet<usize>,
    back: &BTreeSet<(usize, usize)>,
) -> Vec<Vec<usize>> {
    super::graph::cyclic_components(f.blocks.len(), reachable.iter().copied(), |b| {
        f.blocks[b]
            .successors
            .iter()
            .copied()
            .filter(|&s| reachable.contains(&s) && !back.contains(&(b, s)))
            .collect()
    })
}

/// Bytes the stores of `insn` surely write to memory that is not the stack: 0 for
/// a conditional store (inside an `IT` block it may not execute), a store
/// relative to sp or the frame pointer r7, and anything that is no store.
pub fn stored_bytes(insn: &super::cfg::Instruction) -> u64 {
    let ops = insn.operands.as_str();
    if ops.contains("[sp") || ops.contains("[r7") {
        return 0;
    }
    let registers = || {
        ops.split_once('{')
            .and_then(|(_, r)| r.split_once('}'))
            .map_or(0, |(list, _)| list.split(',').count() as u64)
    };
    match insn.base() {
        "str" => 4,
        "strh" => 2,
        "strb" => 1,
        "strd" => 8,
        "stm" | "stmia" | "stmdb" => 4 * registers(),
        "vstr" => {
            if ops.trim_start().starts_with('d') {
                8
            } else {
                4
            }
        }
        _ => 0,
    }
}

/// The fewest bytes the loop's stores write (outside the stack) on one trip from
/// its header around to one of its back edges: the shortest path through its
/// blocks, each block weighted by [`stored_bytes`] of its instructions, no back
/// edge of any loop taken on the way (going around an inner loop only adds
/// stores).
pub fn min_stored_bytes_per_trip(f: &Function, loops: &[Loop], l: &Loop) -> u64 {
    let weight: Vec<u64> = f
        .blocks
        .iter()
        .map(|b| {
            f.instructions
                .get(b.first..b.end)
                .unwrap_or(&[])
                .iter()
                .map(stored_bytes)
                .sum()
        })
        .collect();
    let back: BTreeSet<(usize, usize)> = loops
        .iter()
        .flat_map(|x| x.back_edges.iter().copied())
        .collect();
    let inside: BTreeSet<usize> = l.blocks.iter().copied().collect();
    // The loop's blocks in reverse post-order: with back edges removed, an order
    // in which every edge goes forward.
    let order: Vec<usize> = reverse_post_order(f)
        .into_iter()
        .filter(|b| inside.contains(b))
        .collect();
    let mut best: Vec<Option<u64>> = vec![None; f.blocks.len()];
    best[l.header] = Some(weight[l.header]);
    let mut trip: Option<u64> = None;
    for &b in &order {
        let Some(here) = best[b] else { continue };
        for &s in &f.blocks[b].successors {
            if l.back_edges.contains(&(b, s)) {
                trip = Some(trip.map_or(here, |t| t.min(here)));
            } else if inside.contains(&s) && !back.contains(&(b, s)) {
                let via = here + weight[s];
                best[s] = Some(best[s].map_or(via, |v| v.min(via)));
            }
        }
    }
    trip.unwrap_or(0)
}
