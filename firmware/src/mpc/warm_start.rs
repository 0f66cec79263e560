//! The warm start of a step (the Method's steps 1 and 4): the previous optimal
//! inputs shifted to the new release time, and the previous working set carried
//! over to the next QP by row identity ([`RowId`]: kind, node, obstacle), since row
//! indices move from one step to the next.

use super::*;

/// Kind of a QP row (for the slack diagnostics and the warm start).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum RowKind {
    Validity,
    Road,
    Obstacle,
    Speed,
}

/// What a QP row constrains: its kind, its node (1..=HORIZON) and which of the
/// node's rows of that kind it is (validity: 0 for `+δ`, 1 for `−δ`; road: 0;
/// obstacle: the obstacle's id). Row indices move from one step to the next (an
/// obstacle row that appears at an early node shifts every later row); a
/// `RowId` names the same constraint in both.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct RowId {
    /// What the row constrains.
    pub(super) kind: RowKind,
    /// Its node (1..=HORIZON).
    pub(super) node: u8,
    /// Which of the node's rows of that kind.
    pub(super) sub: u16,
}

impl RowId {
    /// A placeholder for rows not yet pushed.
    pub(super) const NONE: Self = Self {
        kind: RowKind::Validity,
        node: 0,
        sub: 0,
    };
}

/// One entry of the working set kept for the next step's warm start: a variable
/// bound, or a row by its [`RowId`]; and the side held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum WarmEntry {
    /// The bound on QP variable `j`.
    Bound(u16, QpSide),
    /// A general row.
    Row(RowId, QpSide),
}

impl<T: Real> Mpc<T> {
    /// Keeps the solver's working set after a solve, rows by [`RowId`], for the
    /// next solve's warm start.
    pub(super) fn keep_working_set(&mut self) {
        let mut n = 0;
        // The working set is at most WS entries (the solver's array of WS). No
        // `continue`: one path back to the loop's head keeps it one loop (a second
        // one made the compiler split it into two nested ones).
        // wcet-bound: WS
        for e in self.solver.working_set() {
            let entry = match e.index {
                ConstraintIndex::Bound(j) => Some(WarmEntry::Bound(j, e.side)),
                ConstraintIndex::Row(i) => self
                    .condensing
                    .row_id
                    .get(i as usize)
                    .map(|&id| WarmEntry::Row(id, e.side)),
            };
            if let (Some(entry), Some(d)) = (entry, self.warm_set.get_mut(n)) {
                *d = entry;
                n += 1;
            }
        }
        self.warm_len = n;
    }

    /// Gives the solver the kept working set with each row's index in this pass's
    /// QP (Method, step 4: the warm start): a row is found by its [`RowId`] among
    /// its node's rows; one that does not exist in this pass (an obstacle no longer
    /// relevant at that node) is dropped. The solver drops the entries that this
    /// pass's bounds make inadmissible or that are dependent.
    pub(super) fn renumber_working_set(&mut self) {
        let c = &self.condensing;
        self.solver.clear_working_set();
        // One pass over the kept entries, each looked up once: a plain loop (an
        // iterator chain handed to the solver compiles to nested loops whose
        // bounds multiply in the timing analysis).
        // wcet-bound: WS
        for &e in &self.warm_set[..self.warm_len.min(WS)] {
            let renumbered = match e {
                WarmEntry::Bound(j, side) => Some(ActiveConstraint {
                    index: ConstraintIndex::Bound(j),
                    side,
                }),
                WarmEntry::Row(id, side) => {
                    let node = id.node as usize;
                    match (c.node_first.get(node), c.node_first.get(node + 1)) {
                        (Some(&first), Some(&end)) => {
                            // A node's rows `node_first[node]..node_first[node + 1]`: its
                            // road and validity rows (ROWS_PER_NODE), a row per
                            // obstacle relevant there and a `V ≥ 0` row
                            // (`Mpc::condense`).
                            (first as usize..end as usize)
                                .find(|&i| c.row_id.get(i) == Some(&id)) // wcet-bound: ROWS_PER_NODE + MAX_OBSTACLES + 1
                                .map(|i| ActiveConstraint {
                                    index: ConstraintIndex::Row(i as u16),
                                    side,
                                })
                        }
                        _ => None,
                    }
                }
            };
            if let Some(a) = renumbered {
                if !self.solver.push_working_set(a) {
                    break;
                }
            }
        }
    }
}

/// Linear interpolation of node values at a fractional node index `t` (clamped).
pub(super) fn interpolate_nodes<T: Real>(values: &[T; HORIZON + 1], t: T) -> T {
    let t = t.clamp(T::ZERO, T::from_usize(HORIZON));
    let i = (t.floor().to_f32() as usize).min(HORIZON - 1);
    let f = t - T::from_usize(i);
    values[i] + (values[i + 1] - values[i]) * f
}

/// Re-samples piecewise-constant inputs shifted by `shift` intervals: each new
/// interval gets the average of the old inputs over it; past the end, the last.
pub(super) fn shift_inputs<T: Real>(
    old: &[[T; NU]; HORIZON],
    shift: T,
    new: &mut [[T; NU]; HORIZON],
) {
    // wcet-bound: HORIZON
    for k in 0..HORIZON {
        let a = shift + T::from_usize(k);
        let b = a + T::ONE;
        let mut acc = [T::ZERO; NU];
        let j0 = a.floor();
        let mut j = (j0.to_f32() as usize).min(HORIZON);
        let mut t = a;
        // `j` (>= 0) grows by one each iteration and the loop stops past HORIZON.
        // wcet-bound: HORIZON + 1
        while t < b && j <= HORIZON {
            let end = (T::from_usize(j) + T::ONE).min(b);
            let src = old[j.min(HORIZON - 1)];
            let wgt = end - t;
            acc[0] += wgt * src[0];
            acc[1] += wgt * src[1];
            t = end;
            j += 1;
        }
        if t < b {
            let src = old[HORIZON - 1];
            acc[0] += (b - t) * src[0];
            acc[1] += (b - t) * src[1];
        }
        new[k] = acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifting_by_half_an_interval_averages_neighbours() {
        let mut old = [[0.0f64; NU]; HORIZON];
        for k in 0..HORIZON {
            old[k] = [k as f64, -(k as f64)];
        }
        let mut new = [[0.0; NU]; HORIZON];
        shift_inputs(&old, 0.5, &mut new);
        assert!((new[0][0] - 0.5).abs() < 1e-12);
        assert!((new[3][1] + 3.5).abs() < 1e-12);
        // The last interval extends the last input.
        assert!((new[HORIZON - 1][0] - 15.0).abs() < 1e-12);
        shift_inputs(&old, 0.0, &mut new);
        assert_eq!(new, old);
    }

    #[test]
    fn interpolation_between_nodes() {
        let mut v = [0.0f32; HORIZON + 1];
        for (k, x) in v.iter_mut().enumerate() {
            *x = 2.0 * k as f32;
        }
        assert_eq!(interpolate_nodes(&v, 0.5), 1.0);
        assert_eq!(interpolate_nodes(&v, 16.0), 32.0);
        assert_eq!(interpolate_nodes(&v, 99.0), 32.0);
    }
}
