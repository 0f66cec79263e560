//! Our QP solver against OSQP and Clarabel on the MPC's QP corpus.
//!
//! The corpus is read from `$QP_CORPUS` (a directory written by `host-sim qp-corpus`) or,
//! if unset, recorded in-process from the built-in scenario (f64 run, 400 steps).
//!
//! Two parts:
//! 1. A per-QP timing pass (printed first): every QP is solved `$QP_BENCH_REPS` times
//!    (default 7) by each solver from the same state and the minimum time is kept; then
//!    p50/p99 per solver, the ratios to ours, and the accuracy of each solver against
//!    our f64 solution (max/median `|Δx|` on the 32 inputs, relative objective gap,
//!    largest constraint violation in the standard form).
//! 2. Criterion: each solver solves the whole corpus in order per iteration (throughput
//!    in QPs), for medians of the sequence time.
//!
//! Solvers:
//! - `ours-f64-warm`, `ours-f32-warm`: one solver, the sequence in order, warm-started
//!   from the previous working set, as in the MPC (timed: `solve()`, which includes the
//!   Cholesky factorisation of `H` and the row transformation; the problem copy into the
//!   solver is not timed, as the MPC condenses in place).
//! - `ours-f64-cold`, `ours-f32-cold`: empty working set at every QP.
//! - `osqp-warm`: OSQP 0.6 on the standard form (sparse), `eps_abs = eps_rel = 1e-6`,
//!   polish on; a new problem per QP (the matrices change at every MPC step; setup
//!   timed), warm-started with the previous QP's `x`/`y` when the sizes match.
//! - `osqp-cold`: the same without warm start.
//! - `clarabel`: Clarabel 0.11 on the standard form, default tolerances (1e-8 gap and
//!   feasibility), setup timed; it cannot warm start.
//! - `clarabel-1e-6`: Clarabel with gap and feasibility tolerances loosened to 1e-6.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput};
use firmware::mpc::{MpcQp, MpcQpProblem};
use firmware::Real;
use host_sim::closed_loop::Precision;
use host_sim::qp_corpus::entry::{status_name, CorpusEntry, N_DECISION};
use host_sim::qp_corpus::files::read_corpus;
use host_sim::qp_corpus::record::{builtin_obstacles, builtin_track_rows, record, DEFAULT_STEPS};
use host_sim::qp_corpus::replay::{median_max, native_problems};
use host_sim::qp_corpus::standard::StandardQp;

/// OSQP's infinity.
const OSQP_INF: f64 = 1e30;

fn load_corpus() -> Vec<CorpusEntry> {
    match std::env::var_os("QP_CORPUS") {
        Some(dir) => read_corpus(std::path::Path::new(&dir)).expect("reading $QP_CORPUS"),
        None => record(
            &builtin_track_rows(),
            true,
            &builtin_obstacles(),
            DEFAULT_STEPS,
            Precision::F64,
        )
        .expect("recording the built-in scenario"),
    }
}

/// A solver's answer to one QP: inputs (32), full standard-form point if it has one,
/// whether it reports success, time.
#[derive(Clone)]
struct Answer {
    x: Vec<f64>,
    z: Option<Vec<f64>>,
    ok: bool,
    time: Duration,
    /// The solver's iterations (ours: working-set changes; OSQP: ADMM; Clarabel: IPM).
    iters: u32,
}

// ---------- ours ----------

fn ours_sequence<T: Real>(
    probs: &[Box<MpcQpProblem<T>>],
    max_iter: u32,
    warm: bool,
    reps: usize,
) -> Vec<Answer> {
    let mut solver = Box::new(MpcQp::<T>::new());
    solver.settings.max_iter = max_iter;
    solver.settings.warm_start = warm;
    let mut out = Vec::with_capacity(probs.len());
    for p in probs {
        let mut best = Duration::MAX;
        let mut last = solver.clone();
        for _ in 0..reps.max(1) {
            let mut s = solver.clone();
            s.problem_mut().clone_from(p);
            let t0 = Instant::now();
            black_box(s.solve());
            best = best.min(t0.elapsed());
            last = s;
        }
        let sol = last.solution();
        out.push(Answer {
            x: sol.x.iter().map(|v| v.to_f64()).collect(),
            z: None,
            ok: status_name(sol.status) == "optimal",
            time: best,
            iters: sol.iterations,
        });
        solver = last;
    }
    out
}

fn ours_run<T: Real>(solver: &mut MpcQp<T>, probs: &[Box<MpcQpProblem<T>>]) {
    for p in probs {
        solver.problem_mut().clone_from(p);
        black_box(solver.solve());
    }
}

// ---------- OSQP ----------

struct OsqpData {
    p: osqp::CscMatrix<'static>,
    q: Vec<f64>,
    a: osqp::CscMatrix<'static>,
    l: Vec<f64>,
    u: Vec<f64>,
}

fn osqp_data(s: &StandardQp) -> OsqpData {
    let p = osqp::CscMatrix::from_column_iter(s.n, s.n, s.h.iter().copied()).into_upper_tri();
    let a = osqp::CscMatrix::from_row_iter(s.m, s.n, s.a.iter().copied());
    OsqpData {
        p,
        q: s.f.clone(),
        a,
        l: s.lower.iter().map(|v| v.unwrap_or(-OSQP_INF)).collect(),
        u: s.upper.iter().map(|v| v.unwrap_or(OSQP_INF)).collect(),
    }
}

fn osqp_settings(warm: bool) -> osqp::Settings {
    osqp::Settings::default()
        .verbose(false)
        .eps_abs(1e-6)
        .eps_rel(1e-6)
        .polish(true)
        .max_iter(20_000)
        .warm_start(warm)
}

/// Solves one QP; returns (z, y, ok, iterations).
fn osqp_solve(
    d: &OsqpData,
    settings: &osqp::Settings,
    start: Option<&(Vec<f64>, Vec<f64>)>,
) -> (Vec<f64>, Vec<f64>, bool, u32) {
    let mut prob = osqp::Problem::new(&d.p, &d.q, &d.a, &d.l, &d.u, settings).expect("OSQP setup");
    if let Some((x, y)) = start {
        if x.len() == d.q.len() && y.len() == d.l.len() {
            prob.warm_start(x, y);
        } else if x.len() == d.q.len() {
            prob.warm_start_x(x);
        }
    }
    let st = prob.solve();
    let it = st.iter();
    match st {
        osqp::Status::Solved(s) => (s.x().to_vec(), s.y().to_vec(), true, it),
        osqp::Status::SolvedInaccurate(s) | osqp::Status::MaxIterationsReached(s) => {
            (s.x().to_vec(), s.y().to_vec(), false, it)
        }
        _ => (vec![0.0; d.q.len()], vec![0.0; d.l.len()], false, it),
    }
}

fn osqp_sequence(data: &[OsqpData], warm: bool, reps: usize) -> Vec<Answer> {
    let settings = osqp_settings(warm);
    let mut prev: Option<(Vec<f64>, Vec<f64>)> = None;
    let mut out = Vec::with_capacity(data.len());
    for d in data {
        let mut best = Duration::MAX;
        let mut res = None;
        for _ in 0..reps.max(1) {
            let start = if warm { prev.as_ref() } else { None };
            let t0 = Instant::now();
            let r = osqp_solve(d, &settings, start);
            best = best.min(t0.elapsed());
            res = Some(r);
        }
        let (z, y, ok, iters) = res.expect("at least one repetition");
        out.push(Answer {
            x: z[..N_DECISION].to_vec(),
            z: Some(z.clone()),
            ok,
            time: best,
            iters,
        });
        prev = Some((z, y));
    }
    out
}

fn osqp_run(data: &[OsqpData], warm: bool) {
    let settings = osqp_settings(warm);
    let mut prev: Option<(Vec<f64>, Vec<f64>)> = None;
    for d in data {
        let (z, y, _, _) = osqp_solve(d, &settings, if warm { prev.as_ref() } else { None });
        prev = Some((black_box(z), y));
    }
}

// ---------- Clarabel ----------

struct ClarabelData {
    p: clarabel::algebra::CscMatrix<f64>,
    q: Vec<f64>,
    a: clarabel::algebra::CscMatrix<f64>,
    b: Vec<f64>,
    cones: Vec<clarabel::solver::SupportedConeT<f64>>,
}

fn clarabel_data(s: &StandardQp) -> ClarabelData {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::SupportedConeT;
    let c = s.conic();
    let mut cones = vec![];
    if c.n_eq > 0 {
        cones.push(SupportedConeT::ZeroConeT(c.n_eq));
    }
    if c.n_ineq > 0 {
        cones.push(SupportedConeT::NonnegativeConeT(c.n_ineq));
    }
    ClarabelData {
        p: CscMatrix::new_from_triplets(c.n, c.n, c.p.0, c.p.1, c.p.2),
        q: s.f.clone(),
        a: CscMatrix::new_from_triplets(c.b.len(), c.n, c.a.0, c.a.1, c.a.2),
        b: c.b,
        cones,
    }
}

fn clarabel_settings(tol: Option<f64>) -> clarabel::solver::DefaultSettings<f64> {
    let mut b = clarabel::solver::DefaultSettingsBuilder::default();
    b.verbose(false);
    if let Some(t) = tol {
        b.tol_gap_abs(t).tol_gap_rel(t).tol_feas(t);
    }
    b.build().unwrap()
}

fn clarabel_solve(
    d: &ClarabelData,
    settings: clarabel::solver::DefaultSettings<f64>,
) -> (Vec<f64>, bool, u32) {
    use clarabel::solver::{DefaultSolver, IPSolver, SolverStatus};
    let mut s =
        DefaultSolver::new(&d.p, &d.q, &d.a, &d.b, &d.cones, settings).expect("Clarabel setup");
    s.solve();
    let ok = matches!(s.solution.status, SolverStatus::Solved);
    (s.solution.x.clone(), ok, s.solution.iterations)
}

fn clarabel_sequence(data: &[ClarabelData], tol: Option<f64>, reps: usize) -> Vec<Answer> {
    let settings = clarabel_settings(tol);
    data.iter()
        .map(|d| {
            let mut best = Duration::MAX;
            let mut res = None;
            for _ in 0..reps.max(1) {
                let st = settings.clone();
                let t0 = Instant::now();
                let r = clarabel_solve(d, st);
                best = best.min(t0.elapsed());
                res = Some(r);
            }
            let (z, ok, iters) = res.expect("at least one repetition");
            Answer {
                x: z[..N_DECISION].to_vec(),
                z: Some(z),
                ok,
                time: best,
                iters,
            }
        })
        .collect()
}

// ---------- report ----------

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

struct Row {
    name: &'static str,
    p50_us: f64,
    p99_us: f64,
    mean_us: f64,
    failures: usize,
    it_med: u32,
    it_max: u32,
    dx_max: f64,
    dx_med: f64,
    gap_max: f64,
    viol_max: f64,
}

fn summarise(name: &'static str, answers: &[Answer], corpus: &[CorpusEntry]) -> Row {
    let mut t: Vec<f64> = answers.iter().map(|a| a.time.as_secs_f64() * 1e6).collect();
    let mean_us = t.iter().sum::<f64>() / t.len().max(1) as f64;
    t.sort_by(|a, b| a.total_cmp(b));
    let mut dxs = vec![];
    let (mut gap_max, mut viol_max) = (0.0f64, 0.0f64);
    for (a, e) in answers.iter().zip(corpus) {
        let dx =
            a.x.iter()
                .zip(&e.x)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max);
        dxs.push(dx);
        // Objective of the solver's point in the standard form (our slacks if it has
        // none: the smallest feasible ones), against ours.
        let z = a.z.clone().unwrap_or_else(|| {
            let mut z = a.x.clone();
            z.extend(e.native.slacks_at(&a.x));
            z
        });
        let obj = e.standard.objective(&z);
        let ours = e.standard.objective(&e.x);
        gap_max = gap_max.max((obj - ours).abs() / (1.0 + ours.abs()));
        viol_max = viol_max.max(e.standard.max_violation(&z));
    }
    dxs.sort_by(|a, b| a.total_cmp(b));
    let its: Vec<u32> = answers.iter().map(|a| a.iters).collect();
    Row {
        name,
        p50_us: percentile(&t, 0.5),
        p99_us: percentile(&t, 0.99),
        mean_us,
        failures: answers.iter().filter(|a| !a.ok).count(),
        it_med: median_max(&its).0,
        it_max: median_max(&its).1,
        dx_max: dxs.last().copied().unwrap_or(0.0),
        dx_med: percentile(&dxs, 0.5),
        gap_max,
        viol_max,
    }
}

fn timing_pass(
    corpus: &[CorpusEntry],
    p64: &[Box<MpcQpProblem<f64>>],
    p32: &[Box<MpcQpProblem<f32>>],
    osqp: &[OsqpData],
    clar: &[ClarabelData],
) {
    let reps: usize = std::env::var("QP_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(7);
    let max_iter = corpus[0].native.max_iter;
    let rows = vec![
        summarise(
            "ours-f64-warm",
            &ours_sequence(p64, max_iter, true, reps),
            corpus,
        ),
        summarise(
            "ours-f64-cold",
            &ours_sequence(p64, max_iter, false, reps),
            corpus,
        ),
        summarise(
            "ours-f32-warm",
            &ours_sequence(p32, max_iter, true, reps),
            corpus,
        ),
        summarise(
            "ours-f32-cold",
            &ours_sequence(p32, max_iter, false, reps),
            corpus,
        ),
        summarise("osqp-warm", &osqp_sequence(osqp, true, reps), corpus),
        summarise("osqp-cold", &osqp_sequence(osqp, false, reps), corpus),
        summarise("clarabel", &clarabel_sequence(clar, None, reps), corpus),
        summarise(
            "clarabel-1e-6",
            &clarabel_sequence(clar, Some(1e-6), reps),
            corpus,
        ),
    ];
    let ns: Vec<usize> = corpus.iter().map(|e| e.standard.n).collect();
    let ms: Vec<usize> = corpus.iter().map(|e| e.standard.m).collect();
    println!(
        "\nQP corpus: {} QPs; ours: n = {N_DECISION}, m = {}..{} rows (+ 32 bounds, soft rows implicit); standard form: n = {}..{}, m = {}..{}; min of {reps} runs per QP",
        corpus.len(),
        corpus.iter().map(|e| e.native.m).min().unwrap_or(0),
        corpus.iter().map(|e| e.native.m).max().unwrap_or(0),
        ns.iter().min().unwrap_or(&0),
        ns.iter().max().unwrap_or(&0),
        ms.iter().min().unwrap_or(&0),
        ms.iter().max().unwrap_or(&0),
    );
    println!(
        "{:<15} {:>9} {:>9} {:>9} {:>5} {:>11} | {:>10} {:>10} {:>10} {:>10}",
        "solver",
        "p50 µs",
        "p99 µs",
        "mean µs",
        "fail",
        "it med/max",
        "max|Δx|",
        "med|Δx|",
        "max obj gap",
        "max viol"
    );
    for r in &rows {
        println!(
            "{:<15} {:>9.1} {:>9.1} {:>9.1} {:>5} {:>11} | {:>10.2e} {:>10.2e} {:>10.2e} {:>10.2e}",
            r.name,
            r.p50_us,
            r.p99_us,
            r.mean_us,
            r.failures,
            format!("{}/{}", r.it_med, r.it_max),
            r.dx_max,
            r.dx_med,
            r.gap_max,
            r.viol_max
        );
    }
    println!("(fail: not 'solved'/'optimal' (OSQP: polish or accuracy failures count); it: ours working-set changes, OSQP ADMM iterations, Clarabel IPM iterations; |Δx|: inputs vs our f64 solution as recorded; obj gap relative, 1 + |obj| scale; viol in the standard form)");
    let find = |n: &str| rows.iter().find(|r| r.name == n).expect("row");
    for ours in ["ours-f64-warm", "ours-f32-warm", "ours-f64-cold"] {
        let o = find(ours);
        for other in ["osqp-warm", "osqp-cold", "clarabel", "clarabel-1e-6"] {
            let t = find(other);
            println!(
                "{other:>13} / {ours:<13}: p50 {:>6.1}×   p99 {:>6.1}×",
                t.p50_us / o.p50_us,
                t.p99_us / o.p99_us
            );
        }
    }
    println!();
}

fn main() {
    let corpus = load_corpus();
    let p64 = native_problems::<f64>(&corpus).expect("native problems");
    let p32 = native_problems::<f32>(&corpus).expect("native problems");
    let osqp: Vec<OsqpData> = corpus.iter().map(|e| osqp_data(&e.standard)).collect();
    let clar: Vec<ClarabelData> = corpus.iter().map(|e| clarabel_data(&e.standard)).collect();
    let max_iter = corpus[0].native.max_iter;

    if std::env::var_os("QP_BENCH_SKIP_TABLE").is_none() {
        timing_pass(&corpus, &p64, &p32, &osqp, &clar);
    }

    let mut c = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4))
        .configure_from_args();
    let mut g = c.benchmark_group("qp_corpus_sequence");
    g.throughput(Throughput::Elements(corpus.len() as u64));
    for warm in [true, false] {
        let tag = if warm { "warm" } else { "cold" };
        g.bench_function(format!("ours-f64-{tag}"), |b| {
            b.iter(|| {
                let mut s = Box::new(MpcQp::<f64>::new());
                s.settings.max_iter = max_iter;
                s.settings.warm_start = warm;
                ours_run(&mut s, &p64);
            })
        });
        g.bench_function(format!("ours-f32-{tag}"), |b| {
            b.iter(|| {
                let mut s = Box::new(MpcQp::<f32>::new());
                s.settings.max_iter = max_iter;
                s.settings.warm_start = warm;
                ours_run(&mut s, &p32);
            })
        });
        g.bench_function(format!("osqp-{tag}"), |b| b.iter(|| osqp_run(&osqp, warm)));
    }
    let settings = clarabel_settings(None);
    g.bench_function("clarabel", |b| {
        b.iter(|| {
            for d in &clar {
                black_box(clarabel_solve(d, settings.clone()));
            }
        })
    });
    g.finish();
    c.final_summary();
}
