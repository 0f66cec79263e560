//! Warm start: on sequences of slowly changing problems a warm start takes fewer
//! iterations in total than a cold start, and any given working set (shifted, stale,
//! inconsistent) still leads to the optimum.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

mod qp_util;

use proptest::prelude::*;
use qp::{ldl_len, ActiveConstraint, ConstraintIndex, QpProblem, QpSolver, QpStatus, Side};
use qp_util::{kkt_residual, max_abs_diff, random_problem, Mix, Rng};

const N: usize = 16;
const M: usize = 40;
const W: usize = 48;
type Solver = QpSolver<f64, N, M, W, { ldl_len(W) }>;

fn solve_checked(s: &mut Solver, p: &QpProblem<f64, N, M>, label: &str) -> u32 {
    *s.problem_mut() = p.clone();
    assert_eq!(s.solve(), QpStatus::Optimal, "{label}");
    let (r, what) = kkt_residual(p, s.solution());
    assert!(r < 1e-8, "{label}: KKT {r:e} {what}");
    s.solution().iterations
}

/// f and the feasible region drift slowly (the region follows a moving point x0, so the
/// hard constraints stay feasible), as between two MPC solves.
#[test]
fn warm_start_takes_fewer_iterations_on_drifting_problems() {
    let mut total_cold = 0u32;
    let mut total_warm = 0u32;
    for seed in 0..10u64 {
        let mut rng = Rng::new(777 + seed);
        let mix = Mix {
            m: M,
            p_soft: 0.3,
            p_degenerate: 0.0,
            p_eq: 0.05,
            p_fixed: 0.05,
            tight: true,
        };
        let base = random_problem::<N, M>(&mut rng, mix);
        let df: Vec<f64> = (0..N).map(|_| rng.range(-0.05, 0.05)).collect();
        let dx0: Vec<f64> = (0..N).map(|_| rng.range(-0.01, 0.01)).collect();
        let mut cold = Box::new(Solver::new());
        cold.settings.warm_start = false;
        let mut warm = Box::new(Solver::new());
        warm.settings.warm_start = true;
        for k in 0..40 {
            let t = k as f64;
            let mut p = base.clone();
            for j in 0..N {
                p.f[j] += t * df[j] * (1.0 + 0.3 * (0.2 * t).sin());
                p.x_lo[j] += t * dx0[j];
                p.x_hi[j] += t * dx0[j];
            }
            for i in 0..p.m {
                let shift: f64 = (0..N).map(|j| p.a[i][j] * t * dx0[j]).sum();
                p.lo[i] += shift;
                p.hi[i] += shift;
            }
            total_cold += solve_checked(&mut cold, &p, &format!("cold seed {seed} k {k}"));
            total_warm += solve_checked(&mut warm, &p, &format!("warm seed {seed} k {k}"));
            // Same optimum either way.
            let dx = max_abs_diff(&cold.solution().x, &warm.solution().x);
            assert!(dx < 1e-8, "seed {seed} k {k}: cold/warm differ by {dx:e}");
        }
    }
    println!("drifting problems, 10 × 40 solves: cold {total_cold} iterations, warm {total_warm}");
    assert!(
        total_warm < total_cold,
        "warm {total_warm} ≥ cold {total_cold}"
    );
    assert!(
        2 * total_warm < total_cold,
        "warm start should at least halve the work here"
    );
}

/// An MPC-like tracking problem over a receding horizon: x_j is the input at step j,
/// |x_j| ≤ 1, |x_{j+1} − x_j| ≤ 0.15, soft |x_j − r| ≤ 0.3 rows; the reference r(t + j)
/// moves one step per solve. The working set is shifted by one step between solves.
#[test]
fn shifted_working_set_on_a_receding_horizon() {
    fn problem(t: usize) -> QpProblem<f64, N, M> {
        let mut p = QpProblem::<f64, N, M>::new();
        let r = |k: usize| 1.6 * (0.25 * k as f64).sin();
        for j in 0..N {
            p.h[j][j] = 1.0 + 0.01 * j as f64;
            p.f[j] = -r(t + j);
            p.x_lo[j] = -1.0;
            p.x_hi[j] = 1.0;
        }
        for j in 0..N - 1 {
            let mut a = [0.0; N];
            a[j + 1] = 1.0;
            a[j] = -1.0;
            p.push_row(&a, -0.15, 0.15, 0.0);
        }
        for j in 0..N {
            let mut a = [0.0; N];
            a[j] = 1.0;
            p.push_row(&a, 0.8 * r(t + j) - 0.3, 0.8 * r(t + j) + 0.3, 20.0);
        }
        p
    }
    fn shift(set: &[ActiveConstraint]) -> Vec<ActiveConstraint> {
        set.iter()
            .filter_map(|e| {
                let index = match e.index {
                    ConstraintIndex::Bound(0) => return None,
                    ConstraintIndex::Bound(j) => ConstraintIndex::Bound(j - 1),
                    // Rate rows 0..N−1, then soft rows N−1..2N−1: shift within each block.
                    ConstraintIndex::Row(0) => return None,
                    ConstraintIndex::Row(i) if i as usize == N - 1 => return None,
                    ConstraintIndex::Row(i) => ConstraintIndex::Row(i - 1),
                };
                Some(ActiveConstraint {
                    index,
                    side: e.side,
                })
            })
            .collect()
    }
    let mut cold = Box::new(Solver::new());
    cold.settings.warm_start = false;
    let mut warm = Box::new(Solver::new());
    let mut shifted = Box::new(Solver::new());
    let (mut ic, mut iw, mut is) = (0, 0, 0);
    for t in 0..60 {
        let p = problem(t);
        if t > 0 {
            let s = shift(shifted.working_set());
            shifted.set_working_set(&s);
        }
        ic += solve_checked(&mut cold, &p, &format!("cold t {t}"));
        iw += solve_checked(&mut warm, &p, &format!("warm t {t}"));
        is += solve_checked(&mut shifted, &p, &format!("shifted t {t}"));
    }
    println!("receding horizon, 60 solves: cold {ic}, warm (unshifted) {iw}, warm (shifted) {is} iterations");
    assert!(is < ic, "shifted warm {is} ≥ cold {ic}");
    assert!(is <= iw, "shifted warm {is} > unshifted warm {iw}");
}

/// A warm entry the start drops (out of range, a duplicate, at an infinite bound)
/// counts as an iteration against the cap, as a removal does: the bound on the
/// appends of a solve rests on it (`qp`'s module `active_set`, *Counts*).
#[test]
fn the_warm_starts_drops_count_as_iterations() {
    let mut p = QpProblem::<f64, N, M>::new();
    for j in 0..N {
        p.h[j][j] = 1.0;
        p.f[j] = 0.1 * j as f64;
        p.x_lo[j] = -10.0;
        p.x_hi[j] = if j == 1 { f64::INFINITY } else { 10.0 };
    }
    let e = |index, side| ActiveConstraint { index, side };
    let stale = [
        e(ConstraintIndex::Row(M as u16 + 3), Side::Upper),
        e(ConstraintIndex::Bound(0), Side::Lower),
        e(ConstraintIndex::Bound(0), Side::Lower),
        e(ConstraintIndex::Bound(1), Side::Upper),
    ];
    // Cold: the unconstrained optimum, one iteration.
    let mut s = Box::new(Solver::new());
    *s.problem_mut() = p.clone();
    assert_eq!(s.solve(), QpStatus::Optimal);
    assert_eq!(s.solution().iterations, 1);
    // Warm from the stale set: three entries dropped (out of range, duplicate,
    // infinite bound), Bound(0) kept and removed by a blocking step, then the
    // optimum: 3 + 2 iterations.
    for (cap, status) in [(3, QpStatus::IterationLimit), (5, QpStatus::Optimal)] {
        let mut s = Box::new(Solver::new());
        s.settings.max_iter = cap;
        s.set_working_set(&stale);
        *s.problem_mut() = p.clone();
        assert_eq!(s.solve(), status, "cap {cap}");
        assert_eq!(s.solution().iterations, cap, "cap {cap}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Arbitrary working sets (out of range, duplicated, at infinite bounds, dependent,
    /// wrong multiplier signs) never prevent the optimum.
    #[test]
    fn any_given_working_set_still_reaches_the_optimum(seed in any::<u64>(), entries in proptest::collection::vec((any::<bool>(), 0u16..(M as u16 + 4), any::<bool>()), 0..60)) {
        let mut rng = Rng::new(seed);
        let m = rng.below(M + 1);
        let p = random_problem::<N, M>(&mut rng, Mix::all(m));
        let set: Vec<ActiveConstraint> = entries.iter().map(|&(b, i, up)| ActiveConstraint {
            index: if b { ConstraintIndex::Bound(i % (N as u16 + 2)) } else { ConstraintIndex::Row(i) },
            side: if up { Side::Upper } else { Side::Lower },
        }).collect();
        let mut s = Box::new(Solver::new());
        let kept = s.set_working_set(&set);
        prop_assert_eq!(kept, set.len().min(W));
        *s.problem_mut() = p.clone();
        prop_assert_eq!(s.solve(), QpStatus::Optimal);
        let (r, what) = kkt_residual(&p, s.solution());
        prop_assert!(r < 1e-8, "KKT {:e} {}", r, what);
    }
}
