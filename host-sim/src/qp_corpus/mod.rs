//! QP corpus: every QP the MPC solves over a closed-loop run, recorded as JSON, so other
//! solvers (OSQP, Clarabel) can be benchmarked on exactly the problems ours saw.
//!
//! # Recording
//!
//! [`record`](record::record) drives the firmware MPC ([`firmware::mpc::Mpc::step_observed`]) in a closed
//! loop with a kinematic-bicycle plant (the car follows `plan.inputs[0]` for 0.1 s with
//! the bicycle model's RK4 discretisation, as in `firmware/tests/mpc.rs`) along a track
//! given as rows `[x, y, w_right, w_left]` (m), around box or polygon obstacles, starting
//! at the first track point, aligned with the track, at [`START_SPEED_MPS`](record::START_SPEED_MPS). Each
//! condensed QP is copied *before* the solve (the solver overwrites `H` and the rows) and
//! paired with the solution the solver returned. A cold first step solves several QPs
//! (the Gauss–Newton passes of a cold start), each is recorded. If an MPC step fails,
//! recording stops after that step's QPs (their status says why).
//!
//! [`builtin_track_rows`](record::builtin_track_rows) and [`builtin_obstacles`](record::builtin_obstacles) give the default scenario: a
//! 120 m × 70 m closed loop of four straights and four 90° curves of radii 30, 15, 20
//! and 10 m, half-widths 4 m, and three 4 m × 2 m boxes.
//!
//! # File format
//!
//! One JSON object per QP, `DIR/qp_0000.json`, `DIR/qp_0001.json`, … in solve order. All
//! matrices are dense and row-major; all numbers are `f64` (an `f32` run's data are
//! converted exactly). The top level is the **standard form**
//!
//! ```text
//!   minimise ½ zᵀ H z + fᵀ z   subject to   lower ≤ A z ≤ upper
//! ```
//!
//! | key | meaning |
//! |---|---|
//! | `n` | variables: the `n_decision` = 32 MPC inputs, then one slack per soft row |
//! | `m` | rows of `A` |
//! | `H` | `n×n`, full symmetric |
//! | `f` | `n` |
//! | `A` | `m×n`: first one row per bounded input (`e_jᵀ`, the variable bounds), then the general rows, then the slacks' `s ≥ 0` rows |
//! | `lower`, `upper` | `m` each; `null` for −∞ / +∞ |
//! | `x` | our solution `z` (inputs, then the slacks `s_i = |λ_i|/ρ_i`); from an `f32` run, feasible to the f32 solver's tolerance (3.5e-4) only |
//! | `status` | our solver's status: `"optimal"`, `"iteration_limit"`, `"infeasible"`, … |
//! | `iterations` | our solver's iterations on this QP, warm-started as in the MPC |
//! | `n_decision` | 32: the first 32 variables are the MPC inputs `[a_0, δ̇_0, a_1, …]` |
//! | `native` | the problem in our solver's own form, see below |
//! | `precision`, `step`, `pass`, `objective`, `added`, `removed`, `refactorizations` | run information: `"f64"`/`"f32"`, MPC step (0.1 s each), pass within the step, our objective (with slack penalties), our working-set counters |
//! | `solve_us_cold`, `solve_us_warm` | only with `--time`: our f64 solver's time on this QP, µs, from an empty working set and warm-started as in the MPC ([`time_solves`](replay::time_solves) says what is timed) |
//! | `warm_start` | the working set our solve started from, in order: `{"bound": j}` (variable `j`) or `{"row": i}` (general row `i` of `native`), each with `"side": "lower"\|"upper"`; empty on a cold start |
//!
//! A hard row `lo ≤ aᵀx ≤ hi` is written as it is. A soft row (weight `ρ > 0`, meaning
//! `lo − s ≤ aᵀx ≤ hi + s` with cost `½ρs²`, `s ≥ 0`) gets a slack variable `s` with `ρ`
//! on the diagonal of `H`, and one row per finite side: `aᵀx + s ≥ lo` and
//! `aᵀx − s ≤ hi`, plus `s ≥ 0`. At the optimum `s = max(lo − aᵀx, aᵀx − hi, 0)`, so
//! the standard form has the same optimal inputs and objective as the native one.
//!
//! `native` holds exactly what our solver was given ([`qp::QpProblem`]):
//! `n` (32), `m` (general rows), `H` (`n×n` row-major; only the upper triangle is read,
//! the lower one is as the MPC left it), `f`, `A` (`m×n`), `lo`, `hi` (`null` for ∓∞),
//! `x_lo`, `x_hi` (`n`, `null` for ∓∞), `soft` (`m` weights `ρ_i`, 0 for hard rows) and
//! `max_iter`. Feeding these to one solver in file order, each with its `warm_start` set
//! ([`replay`](replay::replay)), reproduces the MPC's solves bit for bit: the MPC warm-starts each QP
//! from the previous QP's working set with its rows renumbered for this QP (rows are
//! kept by what they constrain, and an obstacle row appearing at an early node moves
//! the later ones), and clears it on a cold step, which only the first step is.
//!
//! # Use
//!
//! `host-sim qp-corpus --out DIR [--steps N] [--precision f64|f32] [--track
//! builtin|paper|FILE [--open]] [--obstacles builtin|none|paper|FILE] [--time
//! [--time-reps K]]` (see [`run`](crate::commands::qp_corpus::run); `--time` adds our solver's times, [`time_solves`](replay::time_solves)); the
//! benchmark `cargo bench -p host-sim --bench qp_solvers` reads `QP_CORPUS=DIR` or
//! records the built-in scenario itself.
//!
//! | module | concept |
//! |---|---|
//! | [`entry`] | one recorded QP, one JSON file ([`CorpusEntry`](entry::CorpusEntry)) |
//! | [`native`] | the QP in our solver's own form |
//! | [`standard`] | the QP in standard and conic form, for other solvers |
//! | [`record`] | recording: the MPC in closed loop with a kinematic bicycle; the built-in scenario |
//! | [`replay`] | re-solving and timing the corpus with our solver |
//! | [`files`] | writing and reading the corpus' files |
//!
//! The `qp-corpus` command is [`crate::commands::qp_corpus`].

pub mod entry;
pub mod files;
pub mod native;
pub mod record;
pub mod replay;
pub mod standard;
