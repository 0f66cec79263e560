//! The transformed constraint rows `m̃ = R⁻ᵀ a` the working set is made of, and the
//! dot products between them.

use crate::{ActiveConstraint, ConstraintIndex, QpProblem, Real, Side};

/// A transformed constraint row `m̃` from column `start` on (zero before): its entry
/// at `start` and the entries after it.
#[derive(Clone, Copy)]
pub(crate) struct ConRow<'a, T> {
    pub(crate) start: usize,
    pub(crate) head: T,
    pub(crate) tail: &'a [T],
}

impl<T: Real> ConRow<'_, T> {
    /// `m̃ᵀx` (the tail in four partial sums).
    #[inline(always)]
    pub(crate) fn dot<const N: usize>(&self, x: &[T; N]) -> T {
        let xs = x.get(self.start + 1..).unwrap_or(&[]);
        let x0 = x.get(self.start).copied().unwrap_or(T::ZERO);
        self.head * x0 + dot4_unrolled(self.tail, xs, (N - 1) / 4)
    }

    /// `m̃₁ᵀm̃₂` of two rows of `N` columns. Inlined into its callers' loops, which
    /// then call nothing and keep their code in the flash interface's cache.
    #[inline(always)]
    pub(crate) fn dot_row<const N: usize>(&self, other: &Self) -> T {
        let (lo, hi) = if self.start <= other.start {
            (self, other)
        } else {
            (other, self)
        };
        // lo's entry at hi.start (its head, or its tail[off − 1]) times hi's head,
        // then the tails from there on: one copy of the unrolled product, so that
        // the loops that inline this keep their code in the flash cache.
        let (first, lo_tail) = if lo.start == hi.start {
            (lo.head * hi.head, lo.tail)
        } else {
            let off = hi.start - lo.start;
            let at = lo.tail.get(off - 1).copied().unwrap_or(T::ZERO);
            (at * hi.head, lo.tail.get(off..).unwrap_or(&[]))
        };
        first + dot4_unrolled(lo_tail, hi.tail, (N - 1) / 4)
    }
}

#[inline]
pub(crate) fn sign<T: Real>(side: Side) -> T {
    match side {
        Side::Lower => -T::ONE,
        Side::Upper => T::ONE,
    }
}

#[inline]
pub(crate) fn row_start(r: usize) -> usize {
    r * (r + 1) / 2
}

/// The transformed row of a constraint: a general row's `a_iᵀR⁻¹` in place of
/// `a_i`, a bound's `e_jᵀR⁻¹` from the lower triangle of `h` ([`store_inverse_row`](crate::cholesky::store_inverse_row)),
/// its first entry `1/R_jj` from `rinv` (`Workspace::rinv`).
#[inline]
pub(crate) fn con_row<'a, T: Real, const N: usize, const M: usize>(
    p: &'a QpProblem<T, N, M>,
    rinv: &[T; N],
    c: ConstraintIndex,
) -> ConRow<'a, T> {
    match c {
        ConstraintIndex::Bound(j) => {
            let j = (j as usize).min(N - 1);
            let dst = N - 1 - j;
            ConRow {
                start: j,
                head: rinv[j],
                tail: p.h[dst].get(..dst).unwrap_or(&[]),
            }
        }
        // A constraint of the working set is in range (`admissible`); out of
        // range, a zero row (no panic path).
        ConstraintIndex::Row(i) => match p.a.get(i as usize) {
            Some(a) => ConRow {
                start: 0,
                head: a.first().copied().unwrap_or(T::ZERO),
                tail: a.get(1..).unwrap_or(&[]),
            },
            None => ConRow {
                start: 0,
                head: T::ZERO,
                tail: &[],
            },
        },
    }
}

/// `Σ a_k b_k` over two slices of equal length, in four interleaved partial sums
/// (independent additions pipeline; one chain would wait on each addition's
/// latency), then the remainder in order: the sums the solver's dot products
/// make ([`dot4_unrolled`], [`dot_groups`], `solve_upper`'s rows), as a plain
/// loop, the tests' reference.
#[cfg(test)]
pub(crate) fn dot4<T: Real>(a: &[T], b: &[T]) -> T {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    let mut acc = [T::ZERO; 4];
    for (x, y) in ca.zip(cb) {
        for ((s, &p), &q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (&p, &q) in ra.iter().zip(rb) {
        s += p * q;
    }
    s
}

/// [`dot4`] of two slices of equal length, at most `4·max_groups + 3` entries (a
/// constant of the caller's, so that the loop unrolls: `(N − 1)/4` for a row's
/// tail), unrolled: each
/// group of four behind a test of the length, the rest (at most three) likewise,
/// no loop, so the bound charges the groups the slices have (the same sums in the
/// same order). The slices' addresses go through `black_box`: as offsets from a
/// struct's base each load's address would be formed anew (past a load's
/// immediate range), as pointers there is one each.
#[inline(always)]
pub(crate) fn dot4_unrolled<T: Real>(a: &[T], b: &[T], max_groups: usize) -> T {
    let (a, b) = (core::hint::black_box(a), core::hint::black_box(b));
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    let groups = ca.len().min(cb.len());
    let mut acc = [T::ZERO; 4];
    for (c, (x, y)) in ca.zip(cb).enumerate().take(max_groups) {
        if c >= groups {
            break;
        }
        for ((s, &p), &q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    let mut rest = ra.iter().zip(rb);
    if let Some((&p, &q)) = rest.next() {
        s += p * q;
        if let Some((&p, &q)) = rest.next() {
            s += p * q;
            if let Some((&p, &q)) = rest.next() {
                s += p * q;
            }
        }
    }
    s
}

/// `y_k −= s·x_k` over two slices of equal length, four entries a trip (each
/// entry's own operation: the same result as one at a time).
#[inline(always)]
pub(crate) fn sub_scaled<T: Real>(y: &mut [T], s: T, x: &[T]) {
    // The whole groups and the rest apart: one counter for the groups' loop, and
    // the rest (at most three entries) without a loop.
    let k = y.len().min(x.len());
    let whole = k - k % 4;
    let (y4, yr) = y.split_at_mut(whole);
    let (x4, xr) = x.split_at(whole.min(x.len()));
    // `primal`: a transformed row's tail (at most N entries); `ldl_solve_tmp` and
    // `null_space_step`: the first r entries of `tmp`, Σ r/4 over 1 ≤ r < n ≤ W per
    // call.
    // wcet-bound: NV / 4
    // wcet-bound in ldl_solve_tmp: WS * (WS - 1) / 8 per call
    // wcet-bound in solve_lam_star_tmp: WS * (WS - 1) / 8 per call
    // wcet-bound in null_space_step: WS * (WS - 1) / 8 per call
    for (y4, x4) in y4.chunks_exact_mut(4).zip(x4.chunks_exact(4)) {
        for (y, &x) in y4.iter_mut().zip(x4) {
            *y -= s * x;
        }
    }
    let mut rest = yr.iter_mut().zip(xr);
    if let Some((y, &x)) = rest.next() {
        *y -= s * x;
        if let Some((y, &x)) = rest.next() {
            *y -= s * x;
            if let Some((y, &x)) = rest.next() {
                *y -= s * x;
            }
        }
    }
}

/// `acc − Σ_k a_k b_k` over two slices of equal length, each product subtracted
/// in order (the same operations as a loop of `acc -= a_k·b_k`, so the same
/// result), four a trip: the trips of a forward substitution's row.
#[inline(always)]
pub(crate) fn sub_products<T: Real>(mut acc: T, a: &[T], b: &[T]) -> T {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    // A row of the factor against the entries before it: fewer than W entries
    // (`commit`'s row of `y`); Σ r/4 over the rows r < n ≤ W of one `append` or
    // one `ldl_solve_tmp`; over one `rebuild`'s appends Σ n(n − 1)/8 and its
    // commits' rows Σ n/4; over an activation's appends at most what its
    // iterations can buy (`qp::work`, QP_APPEND_GROUPS).
    // wcet-bound: WS / 4
    // wcet-bound in append: QP_APPEND_GROUPS per activation
    // wcet-bound in ldl_solve_tmp: WS * (WS - 1) / 8 per call
    // wcet-bound in rebuild: WS * (WS - 1) * (WS - 2) / 24 + WS * (WS - 1) / 8 per call
    for (x, y) in ca.zip(cb) {
        acc -= x[0] * y[0];
        acc -= x[1] * y[1];
        acc -= x[2] * y[2];
        acc -= x[3] * y[3];
    }
    // wcet-bound: 3
    for (&p, &q) in ra.iter().zip(rb) {
        acc -= p * q;
    }
    acc
}

/// [`dot4`] over the first `4·groups` entries (`groups ≤ N/4`), and with `rest`
/// the `N mod 4` entries after the last whole group: [`dot4`] over all `N` entries
/// when `groups = N/4` and `rest`, over a prefix of `4·groups` entries otherwise
/// (the same sums in the same order: the four partial sums, then the rest).
/// Unrolled, each group behind a test of `groups`: no loop, so the bound charges
/// the groups a row has, not a trip more.
#[inline(always)]
pub(crate) fn dot_groups<T: Real, const N: usize>(
    a: &[T; N],
    b: &[T; N],
    groups: usize,
    rest: bool,
) -> T {
    let mut acc = [T::ZERO; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (c, (x, y)) in ca.zip(cb).enumerate() {
        if c >= groups {
            break;
        }
        for ((s, &p), &q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    if rest {
        for (&p, &q) in ra.iter().zip(rb) {
            s += p * q;
        }
    }
    s
}

/// `1/ρ` for a soft row, else 0.
#[inline]
pub(crate) fn delta<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    c: ConstraintIndex,
) -> T {
    match c {
        ConstraintIndex::Row(i) => {
            // A constraint of the working set is in range (`admissible`); out of
            // range, a hard row (no panic path).
            let rho = p.soft.get(i as usize).copied().unwrap_or(T::ZERO);
            if rho > T::ZERO {
                T::ONE / rho
            } else {
                T::ZERO
            }
        }
        ConstraintIndex::Bound(_) => T::ZERO,
    }
}

/// `(lo, hi)` of a constraint.
#[inline]
pub(crate) fn bounds_of<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    c: ConstraintIndex,
) -> (T, T) {
    // A constraint of the working set or a candidate is in range; out of range,
    // one without bounds (no panic path).
    let at = |lo: &[T], hi: &[T], k: u16| {
        let k = k as usize;
        (
            lo.get(k).copied().unwrap_or(T::NEG_INFINITY),
            hi.get(k).copied().unwrap_or(T::INFINITY),
        )
    };
    match c {
        ConstraintIndex::Bound(j) => at(&p.x_lo, &p.x_hi, j),
        ConstraintIndex::Row(i) => at(&p.lo, &p.hi, i),
    }
}

/// The bound `b` at which working-set entry `e` is held: the lower or upper bound of
/// its constraint, by its side.
pub(crate) fn held_bound<T: Real, const N: usize, const M: usize>(
    p: &QpProblem<T, N, M>,
    e: ActiveConstraint,
) -> T {
    let (lo, hi) = bounds_of(p, e.index);
    match e.side {
        Side::Lower => lo,
        Side::Upper => hi,
    }
}
