//! The QP corpus: JSON round trip, standard form equivalent to the native one, Clarabel
//! agreement on recorded QPs, statuses and iteration counts, warm against cold.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

use std::sync::OnceLock;

use host_sim::closed_loop::Precision;
use host_sim::qp_corpus::entry::{CorpusEntry, N_DECISION};
use host_sim::qp_corpus::files::{read_corpus, write_corpus};
use host_sim::qp_corpus::record::{builtin_obstacles, builtin_track_rows, record, DEFAULT_STEPS};
use host_sim::qp_corpus::replay::{median_max, native_problems, replay, time_solves};
use host_sim::qp_corpus::standard::StandardQp;

/// The built-in scenario's corpus (f64), recorded once for all tests.
fn corpus() -> &'static [CorpusEntry] {
    static C: OnceLock<Vec<CorpusEntry>> = OnceLock::new();
    C.get_or_init(|| {
        record(
            &builtin_track_rows(),
            true,
            &builtin_obstacles(),
            DEFAULT_STEPS,
            Precision::F64,
        )
        .expect("recording the built-in scenario")
    })
}

#[test]
fn the_built_in_run_records_every_step_and_all_are_optimal() {
    let c = corpus();
    // A cold first step solves COLD_START_PASSES QPs (Gauss–Newton passes), every
    // later one 1.
    assert_eq!(
        c.len(),
        DEFAULT_STEPS + usize::from(firmware::mpc::COLD_START_PASSES) - 1,
        "one QP per step plus the cold passes"
    );
    assert_eq!(c.last().unwrap().step, DEFAULT_STEPS - 1);
    for (k, e) in c.iter().enumerate() {
        assert_eq!(e.status, "optimal", "QP {k} (step {})", e.step);
        assert_eq!(e.n_decision, N_DECISION);
        assert_eq!(e.native.n, N_DECISION);
        assert_eq!(e.standard.n, N_DECISION + e.native.soft_rows().len());
        assert_eq!(e.x.len(), e.standard.n);
    }
    // Obstacles matter in part of the run, not all of it.
    let with_obstacle_rows = c.iter().filter(|e| e.native.m > 48).count();
    println!(
        "{} QPs, {with_obstacle_rows} with obstacle rows; rows {}..{}",
        c.len(),
        c.iter().map(|e| e.native.m).min().unwrap(),
        c.iter().map(|e| e.native.m).max().unwrap()
    );
    assert!(with_obstacle_rows > 10 && with_obstacle_rows < c.len());
}

#[test]
fn iteration_counts_are_recorded_and_a_warm_replay_reproduces_them() {
    let c = corpus();
    assert!(c.iter().any(|e| e.iterations > 0));
    // Replaying the native problems in order, each from the working set the MPC's
    // solve started from, is exactly what the MPC did: same iterations, same bits.
    let probs = native_problems::<f64>(c).unwrap();
    let sets: Vec<_> = c.iter().map(|e| e.warm_start.clone()).collect();
    assert!(
        sets.iter().skip(3).any(|w| !w.is_empty()),
        "warm starts recorded"
    );
    let warm = replay(&probs, c[0].native.max_iter, Some(&sets));
    for (k, (e, r)) in c.iter().zip(&warm).enumerate() {
        assert_eq!(r.iterations, e.iterations, "QP {k}");
        assert_eq!(r.x[..], e.x[..N_DECISION], "QP {k}");
    }
}

#[test]
fn warm_start_takes_no_more_iterations_than_cold() {
    let c = corpus();
    let probs = native_problems::<f64>(c).unwrap();
    let max_iter = c[0].native.max_iter;
    let warm: Vec<u32> = c.iter().map(|e| e.iterations).collect();
    let cold_runs = replay(&probs, max_iter, None);
    assert!(cold_runs.iter().all(|r| r.status == "optimal"));
    let cold: Vec<u32> = cold_runs.iter().map(|r| r.iterations).collect();
    let (wm, wx) = median_max(&warm);
    let (cm, cx) = median_max(&cold);
    println!(
        "QP iterations over {} QPs: warm median {wm} max {wx}; cold median {cm} max {cx}",
        c.len()
    );
    // Same optimum either way.
    let dx = cold_runs
        .iter()
        .zip(c)
        .flat_map(|(r, e)| r.x.iter().zip(&e.x).map(|(a, b)| (a - b).abs()))
        .fold(0.0, f64::max);
    println!("max |x_cold − x_warm| = {dx:e}");
    assert!(dx < 1e-6);
    assert!(wm <= cm, "warm median {wm} > cold median {cm}");
}

#[test]
fn json_round_trips() {
    let c = corpus();
    let picks = [0, 1, 2, c.len() / 2, c.len() - 1];
    for &k in &picks {
        let text = serde_json::to_string(&c[k]).unwrap();
        let back: CorpusEntry = serde_json::from_str(&text).unwrap();
        assert_eq!(back, c[k], "QP {k}");
        // The keys of the format are there, infinities as null.
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        for key in [
            "n",
            "m",
            "H",
            "f",
            "A",
            "lower",
            "upper",
            "x",
            "status",
            "iterations",
            "native",
            "n_decision",
        ] {
            assert!(v.get(key).is_some(), "key {key} missing");
        }
        let n = v["n"].as_u64().unwrap() as usize;
        let m = v["m"].as_u64().unwrap() as usize;
        assert_eq!(v["H"].as_array().unwrap().len(), n * n);
        assert_eq!(v["A"].as_array().unwrap().len(), m * n);
        assert!(v["upper"].as_array().unwrap().iter().any(|u| u.is_null()));
        assert!(v["lower"].as_array().unwrap().iter().any(|u| u.is_null()));
        for key in ["n", "m", "H", "f", "A", "lo", "hi", "x_lo", "x_hi", "soft"] {
            assert!(v["native"].get(key).is_some(), "native key {key} missing");
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let some: Vec<CorpusEntry> = picks.iter().map(|&k| c[k].clone()).collect();
    write_corpus(dir.path(), &some).unwrap();
    assert!(dir.path().join("qp_0004.json").exists());
    assert_eq!(read_corpus(dir.path()).unwrap(), some);
    // A directory without a corpus is an error that says what to do.
    let empty = tempfile::tempdir().unwrap();
    let err = read_corpus(empty.path()).unwrap_err().to_string();
    assert!(err.contains("qp-corpus"), "{err}");
}

#[test]
fn the_standard_form_is_equivalent_to_the_native_one() {
    let c = corpus();
    let (mut worst_viol, mut worst_obj, mut worst_slack) = (0.0f64, 0.0f64, 0.0f64);
    let mut active_slacks = 0usize;
    for (k, e) in c.iter().enumerate() {
        let s = &e.standard;
        // H symmetric.
        for r in 0..s.n {
            for col in 0..r {
                assert_eq!(s.h[r * s.n + col], s.h[col * s.n + r], "QP {k}");
            }
        }
        // Our x is feasible in the standard form.
        let viol = s.max_violation(&e.x);
        worst_viol = worst_viol.max(viol);
        assert!(viol <= 1e-6, "QP {k}: violation {viol:e}");
        // Its objective is the native objective plus slack penalties, and our solver's.
        let (x, slacks) = e.x.split_at(N_DECISION);
        let native = e.native.objective(x, slacks);
        let std_obj = s.objective(&e.x);
        let gap = (std_obj - native).abs() / (1.0 + native.abs());
        let gap2 = (std_obj - e.objective).abs() / (1.0 + e.objective.abs());
        worst_obj = worst_obj.max(gap).max(gap2);
        assert!(
            gap < 1e-12 && gap2 < 1e-9,
            "QP {k}: {std_obj} vs {native} vs {}",
            e.objective
        );
        // The slacks from the multipliers are the smallest that make x feasible.
        for (a, b) in slacks.iter().zip(e.native.slacks_at(x)) {
            worst_slack = worst_slack.max((a - b).abs());
            if b > 1e-6 {
                active_slacks += 1;
            }
        }
    }
    println!(
        "max violation {worst_viol:e}, objective gap {worst_obj:e}, slack mismatch {worst_slack:e}, {active_slacks} positive slacks"
    );
    assert!(worst_slack < 1e-6);
    assert!(
        active_slacks > 0,
        "the corpus should exercise the soft rows"
    );
}

/// Clarabel on a standard-form QP: (solved, z, objective).
fn clarabel_solve(q: &StandardQp) -> (bool, Vec<f64>, f64) {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{
        DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    };
    let c = q.conic();
    let pm = CscMatrix::new_from_triplets(c.n, c.n, c.p.0, c.p.1, c.p.2);
    let am = CscMatrix::new_from_triplets(c.b.len(), c.n, c.a.0, c.a.1, c.a.2);
    let b = c.b;
    let mut cones = vec![];
    if c.n_eq > 0 {
        cones.push(SupportedConeT::ZeroConeT(c.n_eq));
    }
    if c.n_ineq > 0 {
        cones.push(SupportedConeT::NonnegativeConeT(c.n_ineq));
    }
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .tol_gap_abs(1e-10)
        .tol_gap_rel(1e-10)
        .tol_feas(1e-10)
        .tol_ktratio(1e-8)
        .max_iter(200)
        .build()
        .unwrap();
    let mut solver = DefaultSolver::new(&pm, &q.f, &am, &b, &cones, settings).unwrap();
    solver.solve();
    let ok = matches!(solver.solution.status, SolverStatus::Solved);
    (ok, solver.solution.x.clone(), solver.solution.obj_val)
}

#[test]
fn clarabel_on_the_standard_form_agrees_with_our_solution() {
    let c = corpus();
    // A spread of QPs, including the cold passes and some with obstacle rows.
    let mut picks: Vec<usize> = (0..8).map(|i| i * (c.len() - 1) / 7).collect();
    picks.extend(
        c.iter()
            .enumerate()
            .filter(|(_, e)| e.native.m > 48)
            .map(|(k, _)| k)
            .step_by(25)
            .take(4),
    );
    for &k in &picks {
        let e = &c[k];
        let (ok, z, obj) = clarabel_solve(&e.standard);
        assert!(ok, "QP {k}: Clarabel did not solve");
        let dx = z
            .iter()
            .zip(&e.x)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let ours = e.standard.objective(&e.x);
        println!(
            "QP {k} (m = {}): |z − z_clarabel|∞ = {dx:.2e}, objective {ours:.9} vs {obj:.9}",
            e.native.m
        );
        // Where the cost is flat the two may differ more, as long as ours is no
        // worse than Clarabel's (its interior point stops short of the optimum).
        let no_worse = ours <= obj + 1e-12 * obj.abs();
        assert!(
            dx < 1e-5 || (no_worse && dx < 1e-4),
            "QP {k}: |z − z_clarabel|∞ = {dx:e}"
        );
        assert!(
            (ours - obj).abs() <= 1e-6 * (1.0 + obj.abs()),
            "QP {k}: {ours} vs {obj}"
        );
    }
}

#[test]
fn an_f32_run_records_too() {
    let c = record(
        &builtin_track_rows(),
        true,
        &builtin_obstacles(),
        DEFAULT_STEPS,
        Precision::F32,
    )
    .unwrap();
    let optimal = c.iter().filter(|e| e.status == "optimal").count();
    let (wm, wx) = median_max(&c.iter().map(|e| e.iterations).collect::<Vec<_>>());
    println!(
        "f32 run: {} QPs, {optimal} optimal, iterations median {wm} max {wx}",
        c.len()
    );
    assert!(c.iter().all(|e| e.precision == "f32"));
    assert_eq!(
        c.len(),
        DEFAULT_STEPS + usize::from(firmware::mpc::COLD_START_PASSES) - 1
    );
    assert_eq!(optimal, c.len());
    // f32 data are stored exactly: converting back gives the same f32 problem.
    let p = c[5].native.to_problem::<f32>().unwrap();
    assert_eq!(p.f[0] as f64, c[5].native.f[0]);
}

#[test]
fn solve_times_are_medians_of_real_solves_and_survive_the_json() {
    let c = corpus();
    let some: Vec<CorpusEntry> = c.iter().take(12).cloned().collect();
    assert!(
        time_solves(&some, 4).is_err(),
        "fewer than 5 repetitions refused"
    );
    let times = time_solves(&some, 5).unwrap();
    assert_eq!(times.len(), some.len());
    for (k, &(cold, warm)) in times.iter().enumerate() {
        // A solve of 32 variables and 48+ rows takes more than 0.1 µs and less than 1 s.
        assert!(cold > 0.1 && cold < 1e6, "QP {k}: cold {cold} µs");
        assert!(warm > 0.1 && warm < 1e6, "QP {k}: warm {warm} µs");
    }
    let mut e = some[0].clone();
    let text = serde_json::to_string(&e).unwrap();
    assert!(!text.contains("solve_us"), "no times unless asked for");
    e.solve_us_cold = Some(times[0].0);
    e.solve_us_warm = Some(times[0].1);
    let text = serde_json::to_string(&e).unwrap();
    let back: CorpusEntry = serde_json::from_str(&text).unwrap();
    assert_eq!(back, e);
}
