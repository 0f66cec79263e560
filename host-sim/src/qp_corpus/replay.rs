//! The corpus re-solved with our solver: bit for bit from the recorded working sets
//! ([`replay`]), and timed ([`time_solves`]).

use std::hint::black_box;
use std::time::Instant;

use anyhow::{ensure, Context, Result};
use firmware::mpc::{MpcQp, MpcQpProblem};
use firmware::Real;

use crate::qp_corpus::entry::{status_name, CorpusEntry, WarmStartEntry};

/// The result of re-solving one corpus QP with our solver.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    /// Solution inputs (32).
    pub x: Vec<f64>,
    /// Status name ([`status_name`]).
    pub status: &'static str,
    /// Iterations.
    pub iterations: u32,
    /// Objective with slack penalties, cost units.
    pub objective: f64,
}

/// The corpus' native problems converted for our solver in precision `T` (boxed; copy
/// one into [`MpcQp::problem_mut`] before each solve).
pub fn native_problems<T: Real>(entries: &[CorpusEntry]) -> Result<Vec<Box<MpcQpProblem<T>>>> {
    entries
        .iter()
        .enumerate()
        .map(|(k, e)| {
            e.native
                .to_problem::<T>()
                .with_context(|| format!("corpus QP {k}"))
        })
        .collect()
}

/// Solves `problems` in order with one solver of precision `T`: each from the
/// working set the MPC's solve started from (`warm_starts`, one per problem: the
/// corpus's `warm_start`), which reproduces the MPC's solves bit for bit, or, with
/// `None`, from an empty one (cold).
pub fn replay<T: Real>(
    problems: &[Box<MpcQpProblem<T>>],
    max_iter: u32,
    warm_starts: Option<&[Vec<WarmStartEntry>]>,
) -> Vec<Replay> {
    let mut solver = Box::new(MpcQp::<T>::new());
    solver.settings.max_iter = max_iter;
    solver.settings.warm_start = warm_starts.is_some();
    problems
        .iter()
        .enumerate()
        .map(|(k, p)| {
            *solver.problem_mut() = (**p).clone();
            match warm_starts.and_then(|w| w.get(k)) {
                Some(ws) => {
                    solver.set_working_set_from(ws.iter().map(|e| e.to_active()));
                }
                None => solver.clear_working_set(),
            }
            let st = solver.solve();
            let s = solver.solution();
            Replay {
                x: s.x.iter().map(|v| v.to_f64()).collect(),
                status: status_name(st),
                iterations: s.iterations,
                objective: s.objective.to_f64(),
            }
        })
        .collect()
}

/// Fewest repetitions [`time_solves`] accepts (the median of fewer is too noisy).
pub const MIN_TIME_REPS: usize = 5;

/// Our f64 solver's time on each QP of `entries`, `(cold, warm)` in µs, the median of
/// `reps` (≥ [`MIN_TIME_REPS`]) repetitions each.
///
/// What is timed is [`MpcQp::solve`] alone, in this process, by [`Instant`]: the input
/// checks, the inversion of the factor `R` the MPC hands in (or the Cholesky
/// factorisation of `H`), the transformation of the rows (`A R⁻¹`, `R⁻ᵀ f`), the
/// warm-start factor of the working set, the iterations and the output (`x`,
/// multipliers, objective). Not timed: copying the problem into the solver (the MPC
/// condenses in place) and the solver's state copy made before each repetition, so that
/// every repetition starts from the same state.
///
/// *Cold*: an empty working set. *Warm*: the working set the MPC's solve started from
/// (the entry's `warm_start`), as [`replay`] gives it. Each QP gets its `max_iter`.
pub fn time_solves(entries: &[CorpusEntry], reps: usize) -> Result<Vec<(f64, f64)>> {
    ensure!(
        reps >= MIN_TIME_REPS,
        "at least {MIN_TIME_REPS} repetitions per QP are needed for a median, got {reps}"
    );
    let problems = native_problems::<f64>(entries)?;
    let mut warm = Box::new(MpcQp::<f64>::new());
    warm.settings.warm_start = true;
    let mut cold = Box::new(MpcQp::<f64>::new());
    cold.settings.warm_start = false;
    let mut run = Box::new(MpcQp::<f64>::new());
    let mut samples = vec![0.0; reps];
    let mut out = Vec::with_capacity(problems.len());
    for (p, e) in problems.iter().zip(entries) {
        let max_iter = if e.native.max_iter > 0 {
            e.native.max_iter
        } else {
            warm.settings.max_iter
        };
        warm.settings.max_iter = max_iter;
        cold.settings.max_iter = max_iter;
        let mut time_from = |start: &MpcQp<f64>, run: &mut MpcQp<f64>| {
            for t in samples.iter_mut() {
                run.clone_from(start);
                run.problem_mut().clone_from(p);
                let t0 = Instant::now();
                black_box(run.solve());
                *t = t0.elapsed().as_secs_f64() * 1e6;
            }
            crate::stats::median(&samples).unwrap_or(0.0)
        };
        let cold_us = time_from(&cold, &mut run);
        warm.set_working_set_from(e.warm_start.iter().map(|w| w.to_active()));
        let warm_us = time_from(&warm, &mut run);
        out.push((cold_us, warm_us));
    }
    Ok(out)
}

/// Median and maximum of a list of counts (0, 0 for an empty list).
pub fn median_max(v: &[u32]) -> (u32, u32) {
    let mut s = v.to_vec();
    s.sort_unstable();
    let med = s.get(s.len() / 2).copied().unwrap_or(0);
    (med, s.last().copied().unwrap_or(0))
}
