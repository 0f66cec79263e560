//! Agreement of the QP solver with clarabel (f64 interior point) on random problems with
//! fixed seeds and on hand-made ones: `x` and the objective to 1e-6.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

mod qp_util;

use qp::{ldl_len, QpProblem, QpSolver, QpStatus};
use qp_util::{clarabel_solve, kkt_residual, max_abs_diff, objective, random_problem, Mix, Rng};

const N: usize = 8;
const M: usize = 24;
const W: usize = 32;
type Solver = QpSolver<f64, N, M, W, { ldl_len(W) }>;

const TOL: f64 = 1e-6;

fn compare(p: &QpProblem<f64, N, M>, s: &mut Solver, label: &str) {
    *s.problem_mut() = p.clone();
    let st = s.solve();
    assert_eq!(st, QpStatus::Optimal, "{label}");
    let (r, what) = kkt_residual(p, s.solution());
    assert!(r < 1e-8, "{label}: KKT {r:e} {what}");
    let (ok, xr, objr) = clarabel_solve(p);
    assert!(ok, "{label}: clarabel did not solve");
    let ours = objective(p, s.solution());
    let dx = max_abs_diff(&s.solution().x, &xr);
    let xscale = 1.0 + xr.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(dx <= TOL * xscale, "{label}: |x − x_clarabel|∞ = {dx:e}");
    assert!(
        (ours - objr).abs() <= TOL * (1.0 + objr.abs()),
        "{label}: objective {ours} vs clarabel {objr}"
    );
}

#[test]
fn agrees_with_clarabel_on_random_problems() {
    let mut s = Box::new(Solver::new());
    s.settings.warm_start = false;
    let mut active = 0usize;
    for seed in 0..300u64 {
        let mut rng = Rng::new(1000 + seed);
        let mix = match seed % 3 {
            0 => Mix::plain(M),
            1 => Mix::all(M),
            _ => Mix {
                m: (seed as usize) % (M + 1),
                p_soft: 0.5,
                p_degenerate: 0.3,
                p_eq: 0.2,
                p_fixed: 0.2,
                tight: seed % 2 == 0,
            },
        };
        let p = random_problem::<N, M>(&mut rng, mix);
        compare(&p, &mut s, &format!("seed {seed}"));
        active += s.working_set().len();
    }
    println!(
        "mean working-set size at the optimum: {:.1}",
        active as f64 / 300.0
    );
    assert!(
        active > 300 * 3,
        "the random problems should have active constraints"
    );
}

#[test]
fn agrees_with_clarabel_on_hand_made_problems() {
    let mut s = Box::new(Solver::new());
    s.settings.warm_start = false;
    // 1. Box-constrained least squares towards (3, −3, ...) with a coupling row.
    let mut p = QpProblem::<f64, N, M>::new();
    for j in 0..N {
        p.h[j][j] = 2.0;
        if j + 1 < N {
            p.h[j][j + 1] = -0.5;
            p.h[j + 1][j] = -0.5;
        }
        p.f[j] = if j % 2 == 0 { -6.0 } else { 6.0 };
        p.x_lo[j] = -1.0;
        p.x_hi[j] = 1.0;
    }
    let mut a = [0.0; N];
    a[0] = 1.0;
    a[1] = 1.0;
    p.push_row(&a, 0.5, 0.5, 0.0);
    compare(&p, &mut s, "box + equality");
    // 2. Same with a soft two-sided row that conflicts with the equality.
    let mut b = [0.0; N];
    b[0] = 1.0;
    b[1] = 1.0;
    b[2] = 1.0;
    p.push_row(&b, 2.5, 3.0, 4.0);
    compare(&p, &mut s, "soft two-sided");
    // 3. A soft equality and a one-sided hard row that is a combination of two others.
    let mut c = [0.0; N];
    c[3] = 1.0;
    c[4] = -1.0;
    p.push_row(&c, 0.25, 0.25, 0.5);
    let mut d = [0.0; N];
    for j in 0..N {
        d[j] = a[j] + 2.0 * c[j];
    }
    p.push_row(&d, f64::NEG_INFINITY, 0.5, 0.0);
    compare(&p, &mut s, "soft equality + combination");
    // 4. A fixed variable and an MPC-like rate chain u_{k+1} − u_k ∈ [−0.1, 0.1].
    p.x_lo[7] = 0.3;
    p.x_hi[7] = 0.3;
    for k in 4..7 {
        let mut r = [0.0; N];
        r[k + 1] = 1.0;
        r[k] = -1.0;
        p.push_row(&r, -0.1, 0.1, 0.0);
    }
    compare(&p, &mut s, "fixed + rate chain");
}
