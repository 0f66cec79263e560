//! Shared helpers of the QP tests: a deterministic problem generator, a KKT checker
//! and a clarabel reference solve.
#![allow(
    dead_code,
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

use qp::{QpProblem, QpSolution};

/// xorshift64* — deterministic, no dependency.
pub struct Rng(pub u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn unif(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.unif()
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// What kinds of rows the generator makes.
#[derive(Clone, Copy, Debug)]
pub struct Mix {
    /// Rows to generate (≤ M).
    pub m: usize,
    /// Probability of a soft row.
    pub p_soft: f64,
    /// Probability of a degenerate row (duplicate or linear combination of earlier rows).
    pub p_degenerate: f64,
    /// Probability of an equality row (hard ones limited to n/3).
    pub p_eq: f64,
    /// Probability of a fixed variable (x_lo = x_hi).
    pub p_fixed: f64,
    /// Bounds are placed around a point `x0`; if `tight`, the unconstrained optimum is far
    /// from `x0` so many constraints are active.
    pub tight: bool,
}

impl Mix {
    pub fn plain(m: usize) -> Self {
        Mix {
            m,
            p_soft: 0.0,
            p_degenerate: 0.0,
            p_eq: 0.0,
            p_fixed: 0.0,
            tight: true,
        }
    }
    pub fn all(m: usize) -> Self {
        Mix {
            m,
            p_soft: 0.25,
            p_degenerate: 0.2,
            p_eq: 0.1,
            p_fixed: 0.1,
            tight: true,
        }
    }
}

/// A random strictly convex QP whose hard constraints are feasible (they all hold at a
/// random point x0).
pub fn random_problem<const N: usize, const M: usize>(
    rng: &mut Rng,
    mix: Mix,
) -> QpProblem<f64, N, M> {
    let mut p = QpProblem::<f64, N, M>::new();
    let x0: Vec<f64> = (0..N).map(|_| rng.range(-1.0, 1.0)).collect();
    // H = GᵀG + μI.
    let g: Vec<Vec<f64>> = (0..N)
        .map(|_| (0..N).map(|_| rng.range(-1.0, 1.0)).collect())
        .collect();
    let mu = rng.range(0.05, 1.0);
    for r in 0..N {
        for c in 0..N {
            let mut s = if r == c { mu } else { 0.0 };
            for k in 0..N {
                s += g[k][r] * g[k][c];
            }
            p.h[r][c] = s;
        }
    }
    let fscale = if mix.tight { 6.0 } else { 1.0 };
    for j in 0..N {
        p.f[j] = rng.range(-fscale, fscale) * N as f64 / 2.0;
    }
    let mut hard_eq = 0usize;
    for j in 0..N {
        let kind = rng.unif();
        if kind < mix.p_fixed && hard_eq < N / 3 {
            p.x_lo[j] = x0[j];
            p.x_hi[j] = x0[j];
            hard_eq += 1;
        } else if kind < 0.5 {
            p.x_lo[j] = x0[j] - rng.range(0.0, 1.0);
            p.x_hi[j] = x0[j] + rng.range(0.0, 1.0);
        } else if kind < 0.65 {
            p.x_lo[j] = x0[j] - rng.range(0.0, 1.0);
        } else if kind < 0.8 {
            p.x_hi[j] = x0[j] + rng.range(0.0, 1.0);
        }
    }
    let m = mix.m.min(M);
    for i in 0..m {
        let soft = rng.unif() < mix.p_soft;
        let degenerate = i >= 2 && rng.unif() < mix.p_degenerate;
        let mut a = [0.0; N];
        if degenerate {
            let p1 = rng.below(i);
            let p2 = rng.below(i);
            let (c1, c2) = if rng.unif() < 0.5 {
                (1.0, 0.0)
            } else {
                (rng.range(-2.0, 2.0), rng.range(-2.0, 2.0))
            };
            for j in 0..N {
                a[j] = c1 * p.a[p1][j] + c2 * p.a[p2][j];
            }
        } else {
            for v in a.iter_mut() {
                *v = rng.range(-1.0, 1.0);
            }
        }
        let ax0: f64 = a.iter().zip(&x0).map(|(x, y)| x * y).sum();
        let kind = rng.unif();
        let (lo, hi) = if kind < mix.p_eq && (soft || hard_eq < N / 3) {
            if !soft {
                hard_eq += 1;
            }
            (ax0, ax0)
        } else if kind < 0.45 {
            (ax0 - rng.range(0.0, 0.5), ax0 + rng.range(0.0, 0.5))
        } else if kind < 0.7 {
            (ax0 - rng.range(0.0, 0.5), f64::INFINITY)
        } else {
            (f64::NEG_INFINITY, ax0 + rng.range(0.0, 0.5))
        };
        // Soft rows may be shifted away from x0 (they need not be satisfiable).
        let shift = if soft { rng.range(-1.0, 1.0) } else { 0.0 };
        p.push_row(
            &a,
            lo + shift,
            hi + shift,
            if soft { rng.range(0.5, 50.0) } else { 0.0 },
        );
    }
    p
}

/// Checks the KKT conditions of `s` for the original problem `p`; returns the largest
/// scaled residual and a description of the worst one.
pub fn kkt_residual<const N: usize, const M: usize>(
    p: &QpProblem<f64, N, M>,
    s: &QpSolution<f64, N, M>,
) -> (f64, String) {
    let mut worst = 0.0f64;
    let mut what = String::new();
    let mut note = |r: f64, w: String| {
        if r > worst || r.is_nan() {
            worst = if r.is_nan() { f64::INFINITY } else { r };
            what = w;
        }
    };
    let x = &s.x;
    // Stationarity.
    for j in 0..N {
        let mut r = p.f[j] + s.lambda_bounds[j];
        let mut scale = p.f[j].abs() + s.lambda_bounds[j].abs();
        for k in 0..N {
            let hk = if k >= j { p.h[j][k] } else { p.h[k][j] };
            r += hk * x[k];
            scale += (hk * x[k]).abs();
        }
        for i in 0..p.m {
            r += p.a[i][j] * s.lambda_rows[i];
            scale += (p.a[i][j] * s.lambda_rows[i]).abs();
        }
        note(
            r.abs() / (1.0 + scale),
            format!("stationarity j={j}: {r:e}"),
        );
    }
    let act = |val: f64,
               lo: f64,
               hi: f64,
               lam: f64,
               rho: f64,
               name: String,
               note: &mut dyn FnMut(f64, String)| {
        let slack = if rho > 0.0 { lam.abs() / rho } else { 0.0 };
        let sc = 1.0 + val.abs();
        // Primal feasibility (with the slack).
        note(
            (lo - slack - val).max(0.0) / sc,
            format!("{name}: below lo {val} < {lo} - {slack}"),
        );
        note(
            (val - hi - slack).max(0.0) / sc,
            format!("{name}: above hi {val} > {hi} + {slack}"),
        );
        // Dual sign + complementarity: λ > 0 only at hi (+λ/ρ), λ < 0 only at lo (+λ/ρ).
        let shift = if rho > 0.0 { lam / rho } else { 0.0 };
        if lam > 0.0 {
            note(
                (val - hi - shift).abs() * lam.abs().min(1.0) / sc,
                format!("{name}: λ={lam} > 0 but val {val} ≠ hi {hi} + {shift}"),
            );
            if !hi.is_finite() {
                note(lam, format!("{name}: λ={lam} > 0 at infinite hi"));
            }
        } else if lam < 0.0 {
            note(
                (val - lo - shift).abs() * lam.abs().min(1.0) / sc,
                format!("{name}: λ={lam} < 0 but val {val} ≠ lo {lo} + {shift}"),
            );
            if !lo.is_finite() {
                note(-lam, format!("{name}: λ={lam} < 0 at infinite lo"));
            }
        }
    };
    for j in 0..N {
        act(
            x[j],
            p.x_lo[j],
            p.x_hi[j],
            s.lambda_bounds[j],
            0.0,
            format!("bound {j}"),
            &mut note,
        );
    }
    for i in 0..p.m {
        let val: f64 = (0..N).map(|j| p.a[i][j] * x[j]).sum();
        act(
            val,
            p.lo[i],
            p.hi[i],
            s.lambda_rows[i],
            p.soft[i],
            format!("row {i}"),
            &mut note,
        );
    }
    // Objective as reported.
    let obj = objective(p, s);
    note(
        (obj - s.objective).abs() / (1.0 + obj.abs()),
        format!("objective {obj} vs reported {}", s.objective),
    );
    (worst, what)
}

/// ½xᵀHx + fᵀx + Σ ½ρ s² with s = |λ|/ρ.
pub fn objective<const N: usize, const M: usize>(
    p: &QpProblem<f64, N, M>,
    s: &QpSolution<f64, N, M>,
) -> f64 {
    let x = &s.x;
    let mut c = 0.0;
    for r in 0..N {
        c += p.f[r] * x[r];
        for k in 0..N {
            let hk = if k >= r { p.h[r][k] } else { p.h[k][r] };
            c += 0.5 * x[r] * hk * x[k];
        }
    }
    for i in 0..p.m {
        if p.soft[i] > 0.0 {
            let sl = s.lambda_rows[i].abs() / p.soft[i];
            c += 0.5 * p.soft[i] * sl * sl;
        }
    }
    c
}

/// Reference solve with clarabel: returns (status solved?, x, objective).
pub fn clarabel_solve<const N: usize, const M: usize>(
    p: &QpProblem<f64, N, M>,
) -> (bool, Vec<f64>, f64) {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{
        DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    };
    let soft: Vec<usize> = (0..p.m).filter(|&i| p.soft[i] > 0.0).collect();
    let nv = N + soft.len();
    // P (upper triangle), q.
    let mut pi = vec![];
    let mut pj = vec![];
    let mut pv = vec![];
    for r in 0..N {
        for c in r..N {
            let v = p.h[r][c];
            if v != 0.0 {
                pi.push(r);
                pj.push(c);
                pv.push(v);
            }
        }
    }
    for (k, &i) in soft.iter().enumerate() {
        pi.push(N + k);
        pj.push(N + k);
        pv.push(p.soft[i]);
    }
    let mut q = vec![0.0; nv];
    q[..N].copy_from_slice(&p.f);
    // Rows: equalities first (zero cone), then inequalities `row·z ≤ b`.
    let mut eq: Vec<(Vec<f64>, f64)> = vec![];
    let mut ineq: Vec<(Vec<f64>, f64)> = vec![];
    for j in 0..N {
        let mut e = vec![0.0; nv];
        e[j] = 1.0;
        if p.x_lo[j] == p.x_hi[j] {
            eq.push((e, p.x_lo[j]));
        } else {
            if p.x_hi[j].is_finite() {
                ineq.push((e.clone(), p.x_hi[j]));
            }
            if p.x_lo[j].is_finite() {
                ineq.push((e.iter().map(|v| -v).collect(), -p.x_lo[j]));
            }
        }
    }
    for i in 0..p.m {
        let mut a = vec![0.0; nv];
        a[..N].copy_from_slice(&p.a[i]);
        let sk = soft.iter().position(|&s| s == i);
        if let Some(k) = sk {
            if p.hi[i].is_finite() {
                let mut r = a.clone();
                r[N + k] = -1.0;
                ineq.push((r, p.hi[i]));
            }
            if p.lo[i].is_finite() {
                let mut r: Vec<f64> = a.iter().map(|v| -v).collect();
                r[N + k] = -1.0;
                ineq.push((r, -p.lo[i]));
            }
            let mut r = vec![0.0; nv];
            r[N + k] = -1.0;
            ineq.push((r, 0.0));
        } else if p.lo[i] == p.hi[i] {
            eq.push((a, p.lo[i]));
        } else {
            if p.hi[i].is_finite() {
                ineq.push((a.clone(), p.hi[i]));
            }
            if p.lo[i].is_finite() {
                ineq.push((a.iter().map(|v| -v).collect(), -p.lo[i]));
            }
        }
    }
    let neq = eq.len();
    let nin = ineq.len();
    let (mut ai, mut aj, mut av, mut b) = (vec![], vec![], vec![], vec![]);
    for (r, (row, bv)) in eq.iter().chain(ineq.iter()).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            if v != 0.0 {
                ai.push(r);
                aj.push(c);
                av.push(v);
            }
        }
        b.push(*bv);
    }
    let pm = CscMatrix::new_from_triplets(nv, nv, pi, pj, pv);
    let am = CscMatrix::new_from_triplets(neq + nin, nv, ai, aj, av);
    let mut cones = vec![];
    if neq > 0 {
        cones.push(SupportedConeT::ZeroConeT(neq));
    }
    if nin > 0 {
        cones.push(SupportedConeT::NonnegativeConeT(nin));
    }
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .tol_gap_abs(1e-11)
        .tol_gap_rel(1e-11)
        .tol_feas(1e-11)
        .tol_ktratio(1e-9)
        .max_iter(400)
        .build()
        .unwrap();
    let mut solver = DefaultSolver::new(&pm, &q, &am, &b, &cones, settings).unwrap();
    solver.solve();
    let ok = matches!(solver.solution.status, SolverStatus::Solved);
    (ok, solver.solution.x[..N].to_vec(), solver.solution.obj_val)
}

/// `p` rounded to single precision, written into `q` in place (a boxed solver's problem
/// need not pass through the stack).
pub fn to_f32_into<const N: usize, const M: usize>(
    p: &QpProblem<f64, N, M>,
    q: &mut QpProblem<f32, N, M>,
) {
    let f = |v: &[f64], d: &mut [f32]| {
        for (d, s) in d.iter_mut().zip(v) {
            *d = *s as f32;
        }
    };
    for (d, s) in q.h.iter_mut().zip(&p.h) {
        f(s, d);
    }
    for (d, s) in q.a.iter_mut().zip(&p.a) {
        f(s, d);
    }
    f(&p.f, &mut q.f);
    f(&p.x_lo, &mut q.x_lo);
    f(&p.x_hi, &mut q.x_hi);
    f(&p.lo, &mut q.lo);
    f(&p.hi, &mut q.hi);
    f(&p.soft, &mut q.soft);
    q.m = p.m;
    q.h_factor = p.h_factor;
}

/// `p` rounded to single precision.
pub fn to_f32<const N: usize, const M: usize>(p: &QpProblem<f64, N, M>) -> QpProblem<f32, N, M> {
    let mut q = QpProblem::new();
    to_f32_into(p, &mut q);
    q
}

/// `max |a_i − b_i|` (0 for empty slices): how far two solutions lie apart, the
/// second in `f64` or `f32`.
pub fn max_abs_diff<B: Copy + Into<f64>>(a: &[f64], b: &[B]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - (*y).into()).abs())
        .fold(0.0, f64::max)
}
