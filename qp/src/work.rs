//! Flow facts of the solver's work over a budget of iterations: how much of
//! `append`'s work (its loops over the rows already in the factor) a budget of
//! iterations can buy, for the timing analysis's annotations (`factor.rs`).
//!
//! # The fact
//!
//! An `append` at a working set of `n` rows runs its three loops over the rows
//! `n` times each and its forward solve's groups of four `q(n) = Σ_{l<n} ⌊l/4⌋`
//! times. A product of caps charges every append at `n = W`; but the appends
//! that find many rows are few: the rows come from earlier appends or from the
//! warm start, and a full working set needs a removal, an iteration of its own,
//! before each append. Per solve, with `s ≤ W` rows after its start, `T` counted
//! iterations and the `c`-th call of `add` (the main loop's append, one per
//! iteration that adds):
//!
//! * the `c`-th `add` appends at `n_c ≤ min(W − 1, s + c − 1)` rows: each `add`
//!   raises the rows by at most one (an append, or the pending row's commit after
//!   its null-space steps), nothing else raises them (a refactorization rebuilds
//!   what is there, dropping some), and at `n ≥ W` `append` returns `Full` before
//!   its loops;
//! * each `add` raises the rows by exactly one, or ends the solve (an error
//!   status): so `A` calls raise them `A − 1` times at least, and since the rows
//!   never exceed `W`, the solve removes or drops `D ≥ s + A − 1 − W` of them;
//!   each removal, null-space step and dropped row is an iteration of its own,
//!   distinct from the `A` that add, so `A + max(0, s + A − 1 − W) ≤ T`;
//! * a retry (an `append` again after a refactorization) adds at most `W − 1`
//!   rows' work, once per refactorization, at most `R` per activation.
//!
//! An activation runs at most `P` solves (the MPC's passes) whose iterations
//! add up to at most `K`. The bound is the largest sum over those constraints
//! (the worst `s` per solve, the worst split of `K` over the solves), computed
//! here at compile time from the caps; the traces check it like every other flow
//! fact.

/// `q(n) = Σ_{l<n} ⌊l/4⌋`: the trips of the forward solve's groups of four over
/// one append at `n` rows (row `l` of `L` against the `l` entries before it).
pub const fn forward_groups(n: u64) -> u64 {
    let (a, b) = (n / 4, n % 4);
    2 * a * a - 2 * a + a * b
}

/// One append's count at `n` rows: `n` (a loop over the rows) or, with `groups`,
/// [`forward_groups`]`(n)`.
const fn per_append(n: u64, groups: bool) -> u64 {
    if groups {
        forward_groups(n)
    } else {
        n
    }
}

/// The most a solve of `t` iterations can sum over its appends (module docs).
const fn per_solve(t: u64, w: u64, groups: bool) -> u64 {
    if w == 0 {
        return 0;
    }
    let mut best = 0;
    let mut s = 0;
    while s <= w {
        // The most `add` calls: all `t` while they stay below the capacity, else
        // half of what is left once the climb from `s` has filled it.
        let adds = if s + t <= w + 1 {
            t
        } else {
            (t + w + 1 - s) / 2
        };
        let mut sum = 0;
        let mut c = 0;
        while c < adds {
            let n = if s + c < w - 1 { s + c } else { w - 1 };
            sum += per_append(n, groups);
            c += 1;
        }
        if sum > best {
            best = sum;
        }
        s += 1;
    }
    best
}

/// The most iterations [`append_work_bound`] handles.
pub const MAX_BUDGET: u32 = 512;

/// The most `append`'s work over one activation (module docs) of at most
/// `solves` solves sharing `max_iter` iterations and `max_refactorizations`
/// refactorizations, with a working set of at most `w`: with `groups` false the
/// trips of each of its loops over the rows (`Σ n`), with `groups` true those of
/// its forward solve's groups of four (`Σ q(n)`). The first attempts and the
/// retries (`add`'s calls of `append`); not the rebuilds' appends (their own
/// copy, bounded per call). `max_iter` at most [`MAX_BUDGET`] (a larger one is
/// taken as `MAX_BUDGET`: then the bound is not one, and the caller's
/// compile-time check must refuse it).
pub const fn append_work_bound(
    max_iter: u32,
    max_refactorizations: u32,
    solves: u32,
    w: usize,
    groups: bool,
) -> u64 {
    let k = if max_iter > MAX_BUDGET {
        MAX_BUDGET
    } else {
        max_iter
    } as usize;
    let w = w as u64;
    // f[t]: one solve of t iterations.
    let mut f = [0u64; MAX_BUDGET as usize + 1];
    let mut t = 0;
    while t <= k {
        f[t] = per_solve(t as u64, w, groups);
        t += 1;
    }
    // best[t]: up to `p` solves sharing t iterations (f is nondecreasing, so a
    // split that leaves iterations over is no better than one that does not).
    let mut best = f;
    let mut p = 1;
    while p < solves {
        let mut next = [0u64; MAX_BUDGET as usize + 1];
        let mut t = 0;
        while t <= k {
            let mut m = 0;
            let mut u = 0;
            while u <= t {
                let v = f[u] + best[t - u];
                if v > m {
                    m = v;
                }
                u += 1;
            }
            next[t] = m;
            t += 1;
        }
        best = next;
        p += 1;
    }
    let retry = if w == 0 { 0 } else { per_append(w - 1, groups) };
    best[k] + max_refactorizations as u64 * retry
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{ldl_len, ActiveConstraint, ConstraintIndex, QpSolver, Side};
    use std::cell::Cell;

    std::thread_local! {
        /// The rows `append` found, summed over its calls (this thread's).
        pub(crate) static APPEND_ROWS: Cell<u64> = const { Cell::new(0) };
    }

    /// The solver itself, on random problems with more rows than variables
    /// (soft and hard), warm-started from random working sets of every size,
    /// at every cap: the rows its appends find stay within the bound.
    #[test]
    fn the_solver_appends_within_the_bound() {
        const W: usize = 8;
        let mut st = 7u64;
        let mut rnd = move || {
            st = st
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((st >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut worst = 0;
        for case in 0..600 {
            let mut s = QpSolver::<f64, 4, 14, W, { ldl_len(W) }>::new();
            let p = s.problem_mut();
            for r in 0..4 {
                p.h[r][r] = 1.0 + rnd().abs();
                p.f[r] = 3.0 * rnd();
                p.x_lo[r] = -0.5 - rnd().abs();
                p.x_hi[r] = 0.5 + rnd().abs();
            }
            for i in 0..14 {
                let a = [rnd(), rnd(), rnd(), rnd()];
                let soft = if i % 2 == 0 { 1.0 + rnd().abs() } else { 0.0 };
                p.push_row(&a, -0.2 - 0.3 * rnd().abs(), 0.1 * rnd().abs(), soft);
            }
            let warm = case % (W + 2);
            let set: std::vec::Vec<ActiveConstraint> = (0..warm)
                .map(|k| ActiveConstraint {
                    index: if k % 3 == 0 {
                        ConstraintIndex::Bound((k % 4) as u16)
                    } else {
                        ConstraintIndex::Row(((k * 5 + case) % 14) as u16)
                    },
                    side: if (k + case) % 2 == 0 {
                        Side::Lower
                    } else {
                        Side::Upper
                    },
                })
                .collect();
            s.set_working_set(&set);
            let max_iter = 1 + (case % 23) as u32;
            s.settings.max_iter = max_iter;
            s.settings.max_refactorizations = (case % 3) as u32;
            APPEND_ROWS.with(|c| c.set(0));
            s.solve();
            let rows = APPEND_ROWS.with(|c| c.get());
            let bound = append_work_bound(max_iter, (case % 3) as u32, 1, W, false);
            assert!(rows <= bound, "case {case}: {rows} rows > {bound}");
            worst = worst.max(rows * 100 / bound.max(1));
        }
        // The random problems reach the bound's neighbourhood (the test tests).
        assert!(worst >= 50, "largest share of the bound {worst} %");
    }

    #[test]
    fn forward_groups_counts_the_groups_of_four() {
        for n in 0..100u64 {
            let direct: u64 = (0..n).map(|l| l / 4).sum();
            assert_eq!(forward_groups(n), direct, "n = {n}");
        }
    }

    /// Every sequence of one solve's moves (add, remove) from every start, by
    /// exhaustive search on small sizes: the largest sum the rules allow is the
    /// bound's.
    #[test]
    fn per_solve_is_the_largest_sum_of_the_moves() {
        fn search(level: u64, left: u64, w: u64, groups: bool) -> u64 {
            if left == 0 {
                return 0;
            }
            let mut best = 0;
            // An add at `level` rows (its work only below the capacity), then one
            // more row (or the end of the solve, which a further move cannot beat).
            if level < w {
                best = per_append(level, groups) + search(level + 1, left - 1, w, groups);
            }
            // A removal.
            if level > 0 {
                best = best.max(search(level - 1, left - 1, w, groups));
            }
            best
        }
        for w in 1..7u64 {
            for t in 0..12u64 {
                for groups in [false, true] {
                    let exhaustive = (0..=w).map(|s| search(s, t, w, groups)).max().unwrap_or(0);
                    assert!(
                        per_solve(t, w, groups) >= exhaustive,
                        "w {w} t {t} groups {groups}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_bound_is_below_the_product_of_the_caps() {
        // The MPC's caps: at most the appends of the `balance` count at W rows each.
        let (k, r, p, w) = (56u32, 1u32, 1u32, 48usize);
        let rows = append_work_bound(k, r, p, w, false);
        let appends = (k + 3 * r + p * w as u32).div_ceil(2) as u64;
        assert!(rows < appends * w as u64, "{rows}");
        assert!(append_work_bound(k, r, p, w, true) < appends * forward_groups(w as u64));
        // More solves, more work; more iterations, more work.
        assert!(append_work_bound(k, r, 2, w, false) > rows);
        assert!(append_work_bound(k + 10, r, p, w, false) > rows);
    }
}
