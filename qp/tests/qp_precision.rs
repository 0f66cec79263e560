//! The same well-conditioned problems solved in f32 and f64: the f32 solution agrees
//! with the f64 one within `1e-3 · (1 + |x|∞)` in `x` and `1e-3 · (1 + |J|)` in cost.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

mod qp_util;

use qp::{ldl_len, QpSolver, QpStatus};
use qp_util::{max_abs_diff, random_problem, to_f32, Mix, Rng};

const N: usize = 10;
const M: usize = 24;
const W: usize = 30;

/// Stated f32-vs-f64 tolerance (relative to 1 + max |x|).
const TOL32: f64 = 1e-3;
/// The same for degenerate problems (dependent rows made nearly dependent by rounding).
const TOL32_DEGENERATE: f64 = 1e-2;

#[test]
fn f32_agrees_with_f64() {
    let mut s64 = Box::new(QpSolver::<f64, N, M, W, { ldl_len(W) }>::new());
    let mut s32 = Box::new(QpSolver::<f32, N, M, W, { ldl_len(W) }>::new());
    s64.settings.warm_start = false;
    s32.settings.warm_start = false;
    let mut worst = 0.0f64;
    for seed in 0..300u64 {
        let mut rng = Rng::new(50_000 + seed);
        // Well conditioned: no degenerate rows; soft rows and equalities allowed.
        let mix = Mix {
            m: M,
            p_soft: 0.3,
            p_degenerate: 0.0,
            p_eq: 0.1,
            p_fixed: 0.1,
            tight: true,
        };
        let mut p = random_problem::<N, M>(&mut rng, mix);
        for j in 0..N {
            p.h[j][j] += 1.0;
        }
        let q = to_f32(&p);
        *s64.problem_mut() = p;
        *s32.problem_mut() = q;
        assert_eq!(s64.solve(), QpStatus::Optimal, "seed {seed} f64");
        assert_eq!(s32.solve(), QpStatus::Optimal, "seed {seed} f32");
        let x64 = s64.solution().x;
        let x32 = s32.solution().x;
        let scale = 1.0 + x64.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let dx = max_abs_diff(&x64, &x32) / scale;
        let j64 = s64.solution().objective;
        let dj = (j64 - s32.solution().objective as f64).abs() / (1.0 + j64.abs());
        worst = worst.max(dx).max(dj);
        assert!(dx < TOL32, "seed {seed}: relative |Δx| = {dx:e}");
        assert!(dj < TOL32, "seed {seed}: relative |ΔJ| = {dj:e}");
    }
    println!("worst relative f32/f64 difference over 300 problems: {worst:e}");
}

/// At the firmware MPC's N = 32 and W = 48, with M = 96 rows (the MPC has 80): f32
/// and f64 agree and the work is reported.
#[test]
fn mpc_sized_problems_f32_vs_f64() {
    const N: usize = 32;
    const M: usize = 96;
    const W: usize = 48;
    let mut s64 = Box::new(QpSolver::<f64, N, M, W, { ldl_len(W) }>::new());
    let mut s32 = Box::new(QpSolver::<f32, N, M, W, { ldl_len(W) }>::new());
    s64.settings.warm_start = false;
    s32.settings.warm_start = false;
    let (mut it32, mut it64, mut worst_it) = (0u32, 0u32, 0u32);
    let mut worst = 0.0f64;
    for seed in 0..40u64 {
        let mut rng = Rng::new(90_000 + seed);
        let mix = Mix {
            m: 72,
            p_soft: 0.3,
            p_degenerate: 0.0,
            p_eq: 0.05,
            p_fixed: 0.0,
            tight: false,
        };
        let mut p = random_problem::<N, M>(&mut rng, mix);
        for j in 0..N {
            p.h[j][j] += 2.0;
        }
        let q = to_f32(&p);
        *s64.problem_mut() = p;
        *s32.problem_mut() = q;
        assert_eq!(s64.solve(), QpStatus::Optimal, "seed {seed} f64");
        assert_eq!(s32.solve(), QpStatus::Optimal, "seed {seed} f32");
        it64 += s64.solution().iterations;
        it32 += s32.solution().iterations;
        worst_it = worst_it.max(s32.solution().iterations);
        let x64 = s64.solution().x;
        let scale = 1.0 + x64.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let dx = max_abs_diff(&x64, &s32.solution().x) / scale;
        worst = worst.max(dx);
        assert!(dx < TOL32, "seed {seed}: relative |Δx| = {dx:e}");
    }
    println!("N=32, M=96 cold solves: f64 {it64} iterations, f32 {it32} (worst {worst_it}); worst relative |Δx| {worst:e}");
}

/// f32 on the fully mixed generator (duplicated and dependent rows, equalities, soft
/// rows; rounding to f32 makes dependent rows only nearly dependent). Every `Optimal`
/// f32 answer is within `TOL32_DEGENERATE` of the f64 one; a failure status
/// (`NumericalError`, `Infeasible`) on these adversarial problems is allowed in at most
/// 1 of 1000 solves (observed: none in these 2000 warm-started solves; 2 in 20 000
/// cold-started ones during development).
/// The degenerate problem of `seed` (duplicate and combined rows, soft rows), its
/// Hessian's diagonal raised by 1: the corpus of the degenerate f32 tests.
fn degenerate_problem(seed: u64) -> qp::QpProblem<f64, N, M> {
    let mut rng = Rng::new(70_000 + seed);
    let mut p = random_problem::<N, M>(&mut rng, Mix::all(M));
    for j in 0..N {
        p.h[j][j] += 1.0;
    }
    p
}

#[test]
fn f32_on_degenerate_problems() {
    let mut s64 = Box::new(QpSolver::<f64, N, M, W, { ldl_len(W) }>::new());
    let mut s32 = Box::new(QpSolver::<f32, N, M, W, { ldl_len(W) }>::new());
    let mut worst = 0.0f64;
    let mut failures = 0;
    for seed in 0..2000u64 {
        let p = degenerate_problem(seed);
        let q = to_f32(&p);
        *s64.problem_mut() = p;
        *s32.problem_mut() = q;
        assert_eq!(s64.solve(), QpStatus::Optimal, "seed {seed} f64");
        let st = s32.solve();
        if st != QpStatus::Optimal {
            assert!(
                matches!(st, QpStatus::NumericalError | QpStatus::Infeasible),
                "seed {seed}: {st:?}"
            );
            println!("seed {seed}: f32 {st:?}");
            failures += 1;
            continue;
        }
        let x64 = s64.solution().x;
        let scale = 1.0 + x64.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let dx = max_abs_diff(&x64, &s32.solution().x) / scale;
        worst = worst.max(dx);
        assert!(dx < TOL32_DEGENERATE, "seed {seed}: relative |Δx| = {dx:e}");
    }
    println!("degenerate problems: {failures} f32 failures in 2000, worst relative f32/f64 |Δx| {worst:e}");
    assert!(failures <= 2, "{failures} f32 failures");
}

/// The refactorization cap: on degenerate f32 problems (where rounding spoils the
/// factor), no solve makes more refactorizations than its settings allow, and a
/// solve denied them ends `Optimal` at the same point (the null-space step) or as
/// a `NumericalError`, never otherwise.
#[test]
fn refactorizations_stay_within_their_cap() {
    let mut s = Box::new(QpSolver::<f32, N, M, W, { ldl_len(W) }>::new());
    let mut refactoring = 0;
    let mut denied_but_optimal = 0;
    for seed in 0..2000u64 {
        let p = degenerate_problem(seed);
        let q = to_f32(&p);
        s.settings.warm_start = false;
        s.settings.max_refactorizations = qp::DEFAULT_MAX_REFACTORIZATIONS;
        *s.problem_mut() = q.clone();
        let free = s.solve();
        let used = s.solution().refactorizations;
        assert!(
            used <= qp::DEFAULT_MAX_REFACTORIZATIONS,
            "seed {seed}: {used}"
        );
        if used == 0 {
            continue;
        }
        refactoring += 1;
        let x = s.solution().x;
        s.settings.max_refactorizations = 0;
        *s.problem_mut() = q;
        let st = s.solve();
        assert_eq!(s.solution().refactorizations, 0, "seed {seed}");
        assert!(
            matches!(st, QpStatus::Optimal | QpStatus::NumericalError) || st == free,
            "seed {seed}: {st:?} (with refactorizations: {free:?})"
        );
        if st == QpStatus::Optimal && free == QpStatus::Optimal {
            let scale = 1.0 + x.iter().map(|v| v.abs()).fold(0.0, f32::max);
            let dx = x
                .iter()
                .zip(s.solution().x.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(dx / scale < TOL32_DEGENERATE as f32, "seed {seed}: {dx}");
            denied_but_optimal += 1;
        }
    }
    println!("{refactoring} of 2000 solves refactored; {denied_but_optimal} optimal without");
    // The corpus exercises the cap: some solves need a refactorization.
    assert!(refactoring > 0);
}
