//! KKT conditions of the QP solver on random and hand-made problems (f64), and every
//! failure status.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

mod qp_util;

use proptest::prelude::*;
use qp::{ldl_len, QpProblem, QpSolver, QpStatus};
use qp_util::{kkt_residual, max_abs_diff, random_problem, Mix, Rng};

const N: usize = 6;
const M: usize = 14;
const W: usize = 20;
type Small = QpSolver<f64, N, M, W, { ldl_len(W) }>;

const N2: usize = 12;
const M2: usize = 30;
const W2: usize = 40;
type Medium = QpSolver<f64, N2, M2, W2, { ldl_len(W2) }>;

/// KKT tolerance (scaled residuals) for f64.
const TOL: f64 = 1e-8;

fn solve_and_check<const N: usize, const M: usize, const W: usize, const WL: usize>(
    solver: &mut QpSolver<f64, N, M, W, WL>,
    p: &QpProblem<f64, N, M>,
) -> Result<(), String> {
    *solver.problem_mut() = p.clone();
    let st = solver.solve();
    if st != QpStatus::Optimal {
        return Err(format!("status {st:?}"));
    }
    let (r, what) = kkt_residual(p, solver.solution());
    if r > TOL {
        return Err(format!("KKT residual {r:e}: {what}"));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn kkt_random_small(seed in any::<u64>(), m in 0usize..=M, soft in 0.0..0.6f64,
                        deg in 0.0..0.4f64, eq in 0.0..0.3f64, fixed in 0.0..0.3f64, tight in any::<bool>()) {
        let mut rng = Rng::new(seed);
        let p = random_problem::<N, M>(&mut rng, Mix { m, p_soft: soft, p_degenerate: deg, p_eq: eq, p_fixed: fixed, tight });
        let mut s = Box::new(Small::new());
        s.settings.warm_start = false;
        if let Err(e) = solve_and_check(&mut s, &p) { prop_assert!(false, "{}", e); }
    }

    #[test]
    fn kkt_random_medium(seed in any::<u64>(), m in 0usize..=M2, soft in 0.0..0.6f64,
                         deg in 0.0..0.4f64, eq in 0.0..0.2f64, fixed in 0.0..0.2f64) {
        let mut rng = Rng::new(seed);
        let p = random_problem::<N2, M2>(&mut rng, Mix { m, p_soft: soft, p_degenerate: deg, p_eq: eq, p_fixed: fixed, tight: true });
        let mut s = Box::new(Medium::new());
        s.settings.warm_start = false;
        if let Err(e) = solve_and_check(&mut s, &p) { prop_assert!(false, "{}", e); }
    }

    /// Warm-started from whatever the previous random problem left: still optimal.
    #[test]
    fn kkt_random_warm_from_unrelated_set(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        let mut s = Box::new(Medium::new());
        for _ in 0..3 {
            let m = rng.below(M2 + 1);
            let p = random_problem::<N2, M2>(&mut rng, Mix::all(m));
            if let Err(e) = solve_and_check(&mut s, &p) { prop_assert!(false, "{}", e); }
        }
    }
}

/// Many fixed seeds of the fully mixed generator (not shrunk, just counted).
#[test]
fn kkt_fixed_seeds_all_features() {
    let mut s = Box::new(Medium::new());
    let mut worst_iters = 0;
    for seed in 0..500u64 {
        let mut rng = Rng::new(seed);
        let p = random_problem::<N2, M2>(&mut rng, Mix::all(M2));
        s.settings.warm_start = false;
        solve_and_check(&mut s, &p).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        worst_iters = worst_iters.max(s.solution().iterations);
    }
    println!("worst iterations over 500 problems (N=12, m=30): {worst_iters}");
}

fn problem_1d() -> QpProblem<f64, N, M> {
    // min ½ Σ x² − 3 x0 (optimum x0 = 3 unconstrained).
    let mut p = QpProblem::<f64, N, M>::new();
    for j in 0..N {
        p.h[j][j] = 1.0;
    }
    p.f[0] = -3.0;
    p
}

fn e0() -> [f64; N] {
    let mut a = [0.0; N];
    a[0] = 1.0;
    a
}

#[test]
fn infeasible_rows_hard() {
    // x0 ≥ 1 and x0 ≤ 0.
    let mut p = problem_1d();
    p.push_row(&e0(), 1.0, f64::INFINITY, 0.0);
    p.push_row(&e0(), f64::NEG_INFINITY, 0.0, 0.0);
    let mut s = Small::new();
    *s.problem_mut() = p.clone();
    assert_eq!(s.solve(), QpStatus::Infeasible);
    assert!(s.solution().x.iter().all(|v| v.is_finite()));
    // Same with the opposite sign of f (the other row enters first).
    p.f[0] = 3.0;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::Infeasible);
}

#[test]
fn infeasible_bound_and_row() {
    let mut p = problem_1d();
    p.x_hi[0] = 0.0;
    p.push_row(&[0.5, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 2.0, 0.0);
    let mut s = Small::new();
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::Infeasible);
}

#[test]
fn infeasible_combination_of_three_rows() {
    // x0 + x1 ≥ 2, x0 ≤ 0.5, x1 ≤ 0.5 (rows), f pulls elsewhere.
    let mut p = problem_1d();
    p.f[0] = 1.0;
    p.f[1] = 1.0;
    p.push_row(&[1.0, 1.0, 0.0, 0.0, 0.0, 0.0], 2.0, f64::INFINITY, 0.0);
    p.push_row(&e0(), f64::NEG_INFINITY, 0.5, 0.0);
    p.push_row(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], f64::NEG_INFINITY, 0.5, 0.0);
    let mut s = Small::new();
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::Infeasible);
}

#[test]
fn conflicting_soft_rows_are_never_infeasible_and_can_exceed_n() {
    // 12 soft rows x0 ∈ [k, k] for k = 0..12 and 2 hard ones; N = 6 but 12+ active.
    let mut p = problem_1d();
    for k in 0..12 {
        p.push_row(&e0(), k as f64, k as f64, 1.0 + k as f64);
    }
    p.push_row(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], 1.0, f64::INFINITY, 0.0);
    let mut s = Small::new();
    s.settings.warm_start = false;
    solve_and_check(&mut s, &p).unwrap();
    assert!(
        s.working_set().len() > N,
        "{} active",
        s.working_set().len()
    );
    // Weighted mean: x0 = (3 + Σ ρ_k k) / (1 + Σ ρ_k).
    let num: f64 = 3.0 + (0..12).map(|k| (1.0 + k as f64) * k as f64).sum::<f64>();
    let den: f64 = 1.0 + (0..12).map(|k| 1.0 + k as f64).sum::<f64>();
    assert!((s.solution().x[0] - num / den).abs() < 1e-10);
    assert!((s.solution().x[1] - 1.0).abs() < 1e-12);
    // Slack of row 0 (x0 ≤ 0 soft) is x0 − 0.
    assert!((s.slack(0) - num / den).abs() < 1e-10);
}

#[test]
fn soft_version_of_infeasible_pair() {
    let mut p = problem_1d();
    p.push_row(&e0(), 1.0, f64::INFINITY, 10.0);
    p.push_row(&e0(), f64::NEG_INFINITY, 0.0, 0.0);
    let mut s = Small::new();
    solve_and_check(&mut s, &p).unwrap();
    // min ½x² − 3x + 5 (1 − x)² s.t. x ≤ 0 → x = 0.
    assert!(s.solution().x[0].abs() < 1e-12);
    assert!((s.slack(0) - 1.0).abs() < 1e-12);
}

#[test]
fn duplicated_and_dependent_active_rows() {
    // The same active row three times, once scaled, plus a combination.
    let mut p = problem_1d();
    let a = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    p.push_row(&a, f64::NEG_INFINITY, 1.0, 0.0);
    p.push_row(&a, f64::NEG_INFINITY, 1.0, 0.0);
    p.push_row(&[2.0, 2.0, 0.0, 0.0, 0.0, 0.0], f64::NEG_INFINITY, 2.0, 0.0);
    p.push_row(&e0(), f64::NEG_INFINITY, 0.75, 0.0);
    p.push_row(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], 0.25, f64::INFINITY, 0.0);
    p.push_row(
        &[1.0, 2.0, 0.0, 0.0, 0.0, 0.0],
        f64::NEG_INFINITY,
        1.25,
        0.0,
    );
    p.x_hi[0] = 0.75;
    let mut s = Small::new();
    solve_and_check(&mut s, &p).unwrap();
    assert!((s.solution().x[0] - 0.75).abs() < 1e-12);
    assert!((s.solution().x[1] - 0.25).abs() < 1e-12);
}

#[test]
fn fixed_variables_and_equality_rows() {
    let mut p = problem_1d();
    p.x_lo[2] = 0.5;
    p.x_hi[2] = 0.5;
    p.push_row(&[1.0, 0.0, 1.0, 0.0, 0.0, 0.0], 1.0, 1.0, 0.0);
    p.push_row(&[0.0, 0.0, 0.0, 1.0, -1.0, 0.0], 2.0, 2.0, 0.0);
    let mut s = Small::new();
    solve_and_check(&mut s, &p).unwrap();
    let x = s.solution().x;
    assert!((x[2] - 0.5).abs() < 1e-12 && (x[0] - 0.5).abs() < 1e-12);
    assert!((x[3] - 1.0).abs() < 1e-12 && (x[4] + 1.0).abs() < 1e-12);
}

#[test]
fn non_finite_input() {
    let mut s = Small::new();
    for case in 0..5 {
        let mut p = problem_1d();
        p.push_row(&e0(), 0.0, 1.0, 0.0);
        match case {
            0 => p.h[1][2] = f64::NAN,
            1 => p.f[3] = f64::NAN,
            2 => p.a[0][4] = f64::NAN,
            3 => p.a[0][1] = f64::INFINITY,
            _ => p.lo[0] = f64::NAN,
        }
        *s.problem_mut() = p;
        assert_eq!(s.solve(), QpStatus::NonFiniteInput, "case {case}");
        assert_eq!(s.solution().status, QpStatus::NonFiniteInput);
    }
    // NaN in an unused row is ignored; infinite bounds are fine.
    let mut p = problem_1d();
    p.a[5][0] = f64::NAN;
    p.x_lo[0] = f64::NEG_INFINITY;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::Optimal);
}

#[test]
fn not_convex() {
    let mut s = Small::new();
    let mut p = problem_1d();
    p.h[3][3] = -1.0;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::NotConvex);
    let mut p = problem_1d();
    p.h[0][1] = 2.0; // [[1,2],[2,1]] block: indefinite
    p.h[1][0] = 2.0;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::NotConvex);
    // Singular but positive semidefinite ([[1,1],[1,1]]): solved with a floored
    // pivot (a small proximal term), and said so.
    let mut p = problem_1d();
    p.h[0][1] = 1.0;
    p.h[1][0] = 1.0;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::Optimal);
    assert_eq!(s.solution().floored_pivots, 1);
}

#[test]
fn invalid_input() {
    let mut s = Small::new();
    let mut p = problem_1d();
    p.m = M + 1;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::InvalidInput);
    let mut p = problem_1d();
    p.push_row(&e0(), 1.0, 0.0, 0.0);
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::InvalidInput);
    let mut p = problem_1d();
    p.x_lo[1] = 2.0;
    p.x_hi[1] = 1.0;
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::InvalidInput);
    let mut p = problem_1d();
    p.push_row(&e0(), 0.0, 1.0, -1.0);
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::InvalidInput);
    // Solving again without refilling the consumed data.
    *s.problem_mut() = problem_1d();
    assert_eq!(s.solve(), QpStatus::Optimal);
    assert_eq!(s.solve(), QpStatus::InvalidInput);
}

#[test]
fn iteration_limit_gives_finite_dual_feasible_point() {
    let mut rng = Rng::new(7);
    let p = random_problem::<N2, M2>(&mut rng, Mix::plain(M2));
    let mut s = Box::new(Medium::new());
    s.settings.warm_start = false;
    solve_and_check(&mut s, &p).unwrap();
    let full = s.solution().iterations;
    assert!(full >= 3, "{full}");
    s.settings.max_iter = 2;
    *s.problem_mut() = p.clone();
    assert_eq!(s.solve(), QpStatus::IterationLimit);
    let sol = s.solution();
    assert_eq!(sol.iterations, 2);
    assert!(sol.x.iter().all(|v| v.is_finite()));
    // Stationarity and dual feasibility hold at the iterate.
    for j in 0..N2 {
        let mut r = p.f[j] + sol.lambda_bounds[j];
        for k in 0..N2 {
            r += p.h[j][k] * sol.x[k];
        }
        for i in 0..p.m {
            r += p.a[i][j] * sol.lambda_rows[i];
        }
        assert!(r.abs() < 1e-9, "stationarity {r}");
    }
    // Signs: λ > 0 only at a finite upper side, λ < 0 only at a finite lower side.
    for i in 0..p.m {
        let l = sol.lambda_rows[i];
        assert!(l <= 0.0 || p.hi[i].is_finite(), "row {i}: λ = {l}");
        assert!(l >= 0.0 || p.lo[i].is_finite(), "row {i}: λ = {l}");
    }
    for j in 0..N2 {
        let l = sol.lambda_bounds[j];
        assert!(l <= 0.0 || p.x_hi[j].is_finite(), "bound {j}: λ = {l}");
        assert!(l >= 0.0 || p.x_lo[j].is_finite(), "bound {j}: λ = {l}");
    }
    let nonzero = sol
        .lambda_rows
        .iter()
        .chain(sol.lambda_bounds.iter())
        .filter(|l| **l != 0.0)
        .count();
    assert!(nonzero <= s.working_set().len());
}

#[test]
fn working_set_full() {
    type Tiny = QpSolver<f64, N, M, 1, { ldl_len(1) }>;
    let mut p = problem_1d();
    p.f[1] = -3.0;
    p.push_row(&e0(), f64::NEG_INFINITY, 1.0, 0.0);
    p.push_row(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], f64::NEG_INFINITY, 1.0, 0.0);
    let mut s = Tiny::new();
    *s.problem_mut() = p;
    assert_eq!(s.solve(), QpStatus::WorkingSetFull);
    assert!(s.solution().x.iter().all(|v| v.is_finite()));
}

/// Contradictions injected into a random feasible problem, in three forms.
fn inject_contradiction(p: &mut QpProblem<f64, N2, M2>, rng: &mut Rng, kind: usize) {
    let mut c = [0.0; N2];
    for v in c.iter_mut() {
        *v = rng.range(-1.0, 1.0);
    }
    let t = rng.range(-2.0, 2.0);
    match kind {
        0 => {
            // c·x ≥ t + 0.1 and (k c)·x ≤ k t.
            let k = rng.range(0.2, 5.0);
            p.push_row(&c, t + 0.1, f64::INFINITY, 0.0);
            let kc = c.map(|v| k * v);
            p.push_row(&kc, f64::NEG_INFINITY, k * t, 0.0);
        }
        1 => {
            // r1 ≥ 1, r2 ≥ 1, r1 + r2 ≤ 1.5 (a hidden combination).
            let mut d = [0.0; N2];
            for v in d.iter_mut() {
                *v = rng.range(-1.0, 1.0);
            }
            let s: [f64; N2] = core::array::from_fn(|j| c[j] + d[j]);
            p.push_row(&c, 1.0, f64::INFINITY, 0.0);
            p.push_row(&s, f64::NEG_INFINITY, 1.5, 0.0);
            p.push_row(&d, 1.0, 2.0, 0.0);
        }
        _ => {
            // x_j ≥ 1 by its bound and 2 x_j ≤ 1 by a row.
            let j = rng.below(N2);
            p.x_lo[j] = 1.0;
            p.x_hi[j] = p.x_hi[j].max(2.0);
            let mut e = [0.0; N2];
            e[j] = 2.0;
            p.push_row(&e, f64::NEG_INFINITY, 1.0, 0.0);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Hard contradictions give `Infeasible` (never a panic, a finite point); the same
    /// rows made soft give an optimum satisfying the KKT conditions.
    #[test]
    fn infeasible_sets_are_detected(seed in any::<u64>(), m in 0usize..=(M2 - 3), kind in 0usize..3) {
        let mut rng = Rng::new(seed);
        let mut p = random_problem::<N2, M2>(&mut rng, Mix { m, ..Mix::all(m) });
        let m0 = p.m;
        inject_contradiction(&mut p, &mut rng, kind);
        let mut s = Box::new(Medium::new());
        s.settings.warm_start = false;
        *s.problem_mut() = p.clone();
        prop_assert_eq!(s.solve(), QpStatus::Infeasible);
        prop_assert!(s.solution().x.iter().all(|v| v.is_finite()));
        // Soften the injected rows: now solvable (unless kind 2's bound conflicts remain).
        if kind < 2 {
            for i in m0..p.m {
                p.soft[i] = 10.0;
            }
            if let Err(e) = solve_and_check(&mut s, &p) { prop_assert!(false, "softened: {}", e); }
        }
    }
}

/// Found by 3000-case runs of `infeasible_sets_are_detected`: a dependent row accepted
/// with a rounding-level pivot (1e-12) made the working set nearly singular, and the
/// solver reported `Optimal` at a point violating an active row (first seed), or cycled
/// to `IterationLimit` (second). Now both `Infeasible`.
#[test]
fn near_degenerate_infeasible_regression() {
    for (seed, m, kind) in [
        (1088713243839321581u64, 19usize, 0usize),
        (2239510376892575553, 27, 0),
    ] {
        let mut rng = Rng::new(seed);
        let mut p = random_problem::<N2, M2>(&mut rng, Mix { m, ..Mix::all(m) });
        inject_contradiction(&mut p, &mut rng, kind);
        let mut s = Box::new(Medium::new());
        s.settings.warm_start = false;
        *s.problem_mut() = p;
        assert_eq!(s.solve(), QpStatus::Infeasible, "seed {seed}");
    }
}

/// Deterministic count over fixed seeds (the proptest above explores new ones each
/// run): every injected contradiction, of each kind, ends `Infeasible`.
#[test]
fn infeasible_over_fixed_seeds() {
    let mut counts = std::collections::BTreeMap::new();
    for seed in 0..3000u64 {
        let mut rng = Rng::new(seed * 7919 + 13);
        let m = rng.below(M2 - 2);
        let kind = (seed % 3) as usize;
        let mut p = random_problem::<N2, M2>(&mut rng, Mix { m, ..Mix::all(m) });
        inject_contradiction(&mut p, &mut rng, kind);
        let mut s = Box::new(Medium::new());
        s.settings.warm_start = false;
        *s.problem_mut() = p;
        let st = s.solve();
        assert!(s.solution().x.iter().all(|v| v.is_finite()));
        *counts.entry(format!("{st:?}")).or_insert(0) += 1;
    }
    println!("3000 infeasible problems: {counts:?}");
    assert_eq!(counts.get("Infeasible"), Some(&3000), "{counts:?}");
}

/// A case the property test above once found (f64): a contradiction whose
/// infeasibility certificate was lost to rounding gave `NumericalError`.
#[test]
fn infeasible_regression_seed_11089739763387800491() {
    let mut rng = Rng::new(11089739763387800491);
    let m = 10;
    let mut p = random_problem::<N2, M2>(&mut rng, Mix { m, ..Mix::all(m) });
    inject_contradiction(&mut p, &mut rng, 1);
    let mut s = Box::new(Medium::new());
    s.settings.warm_start = false;
    *s.problem_mut() = p.clone();
    let st = s.solve();
    println!("status {st:?} iterations {}", s.solution().iterations);
    assert!(st == QpStatus::Infeasible, "{st:?}");
}

/// The upper Cholesky factor `R` of `h` (`H = RᵀR`), in a full matrix.
fn upper_cholesky<const N: usize>(h: &[[f64; N]; N]) -> [[f64; N]; N] {
    let mut r = [[0.0; N]; N];
    for j in 0..N {
        let d = h[j][j] - (0..j).map(|k| r[k][j] * r[k][j]).sum::<f64>();
        r[j][j] = d.sqrt();
        for c in j + 1..N {
            let s = h[j][c] - (0..j).map(|k| r[k][j] * r[k][c]).sum::<f64>();
            r[j][c] = s / r[j][j];
        }
    }
    r
}

/// `solve_factored` on `R` finds the optimum `solve` finds on `H`, and refuses a
/// problem that holds `H` with `InvalidInput` and a cleared solution.
#[test]
fn solve_factored_takes_the_factor_and_refuses_the_hessian() {
    for seed in 0..20u64 {
        let mut rng = Rng::new(4100 + seed);
        let mix = Mix {
            m: M2,
            p_soft: 0.3,
            p_degenerate: 0.1,
            p_eq: 0.05,
            p_fixed: 0.05,
            tight: true,
        };
        let p = random_problem::<N2, M2>(&mut rng, mix);
        let mut on_h = Box::new(Medium::new());
        *on_h.problem_mut() = p.clone();
        let st = on_h.solve();
        let mut on_r = Box::new(Medium::new());
        let mut pr = p.clone();
        pr.h = upper_cholesky(&p.h);
        pr.h_factor = true;
        *on_r.problem_mut() = pr;
        assert_eq!(on_r.solve_factored(), st, "seed {seed}");
        if st == QpStatus::Optimal {
            let dx = max_abs_diff(&on_h.solution().x, &on_r.solution().x);
            assert!(dx < 1e-7, "seed {seed}: |Δx| {dx:e}");
        }
        let mut refused = Box::new(Medium::new());
        *refused.problem_mut() = p;
        assert_eq!(
            refused.solve_factored(),
            QpStatus::InvalidInput,
            "seed {seed}"
        );
        assert!(refused.solution().x.iter().all(|&v| v == 0.0));
    }
}
