//! Strongly connected components (Tarjan, "Depth-first search and linear graph
//! algorithms", 1972), iterative: the cycles of the call graph (recursion) and of
//! a control-flow graph without its back edges (irreducible loops).

/// The strongly connected components of the graph over `0..n` reachable from
/// `starts` through `successors` that contain a cycle (several nodes, or one node
/// with an edge to itself), each sorted.
pub fn cyclic_components(
    n: usize,
    starts: impl IntoIterator<Item = usize>,
    successors: impl Fn(usize) -> Vec<usize>,
) -> Vec<Vec<usize>> {
    let mut index = vec![usize::MAX; n];
    let mut low = vec![0usize; n];
    let mut on = vec![false; n];
    let mut stack: Vec<usize> = Vec::new();
    let mut next = 0;
    let mut out = Vec::new();
    for r in starts {
        if index[r] != usize::MAX {
            continue;
        }
        index[r] = next;
        low[r] = next;
        next += 1;
        stack.push(r);
        on[r] = true;
        let mut work: Vec<(usize, Vec<usize>)> = vec![(r, successors(r))];
        while let Some((v, mut rest)) = work.pop() {
            if let Some(w) = rest.pop() {
                work.push((v, rest));
                if index[w] == usize::MAX {
                    index[w] = next;
                    low[w] = next;
                    next += 1;
                    stack.push(w);
                    on[w] = true;
                    work.push((w, successors(w)));
                } else if on[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            if let Some(p) = work.last().map(|w| w.0) {
                low[p] = low[p].min(low[v]);
            }
            if low[v] == index[v] {
                let mut component = Vec::new();
                while let Some(w) = stack.pop() {
                    on[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 || successors(v).contains(&v) {
                    component.sort_unstable();
                    out.push(component);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cycles_and_self_loops() {
        // 0 → 1 → 2 → 1, 2 → 3 → 3, 4 unreachable with a self loop.
        let succ = |v: usize| match v {
            0 => vec![1],
            1 => vec![2],
            2 => vec![1, 3],
            3 => vec![3],
            4 => vec![4],
            _ => vec![],
        };
        let mut c = cyclic_components(5, [0], succ);
        c.sort();
        assert_eq!(c, vec![vec![1, 2], vec![3]]);
        assert!(cyclic_components(3, [0], |v| if v < 2 { vec![v + 1] } else { vec![] }).is_empty());
    }
}
