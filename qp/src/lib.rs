//! Our dense dual active-set QP solver (the MPC's optimiser in `firmware`).
//!
//! `no_std`, no heap, no `alloc`, no recursion, no panics (every exit is a
//! [`QpStatus`]); sizes are const generics checked at compile time. Generic over
//! the scalar trait [`Real`] (`f32` on the ECU, `f64` on the host), defined here
//! and re-exported by `firmware`.
//!
//! # Problem solved
//!
//! ```text
//!   minimise    ½ xᵀ H x + fᵀ x + Σ_{i soft} ½ ρ_i s_i²          x ∈ ℝᴺ
//!   subject to  x_lo ≤ x ≤ x_hi                               (simple bounds)
//!               lo_i ≤ a_iᵀ x ≤ hi_i            i = 0..m, row i hard (ρ_i = 0)
//!               lo_i − s_i ≤ a_iᵀ x ≤ hi_i + s_i  i = 0..m, row i soft (ρ_i > 0)
//! ```
//!
//! `H` symmetric positive definite (only its upper triangle is read), bounds may be
//! `±∞`, `lo = hi` makes an equality. The slack `s_i ≥ 0` of a soft row is never a
//! variable: it is implicit in the dual (below).
//!
//! # Method: dual active set, after DAQP (Arnström, Bemporad, Axehill 2022)
//!
//! With the Cholesky factor `H = RᵀR` (`R` upper) and `u = R x`, the cost becomes
//! `½‖u + v‖² − ½‖v‖²` with `v = R⁻ᵀ f`, and a constraint row `a` becomes
//! `m̃ = R⁻ᵀ a` (row `a R⁻¹` of `M̃ = A R⁻¹`; a bound on `x_j` has the row `j` of `R⁻¹`).
//! For a working set `W` of constraints held at one of their sides, `b_k` the bound of
//! that side, the Lagrangian `½‖u+v‖² + Σ_k λ_k (m̃_kᵀu − b_k)` gives
//! `u = −v − M̃_Wᵀ λ`, and the multipliers solve
//!
//! ```text
//!   (M̃_W M̃_Wᵀ + D_W) λ = −d_W,    d_k = b_k + m̃_kᵀ v,
//! ```
//!
//! with the sign convention `λ_k ≥ 0` at an upper side, `λ_k ≤ 0` at a lower side,
//! free for an equality.
//!
//! **Soft rows.** Relaxing `m̃ᵀu ≤ hi` to `m̃ᵀu − s ≤ hi` with `½ρ s²` added to the
//! cost adds `λ(m̃ᵀu − s − hi) + ½ρs²` to the Lagrangian; stationarity in `s` gives
//! `ρ s = λ`, so `s = λ/ρ ≥ 0` (at a lower side, `s = −λ/ρ`). The active row then
//! reads `m̃ᵀu = b + λ/ρ` in both cases, and substituting `u` gives the system above
//! with `D_W = diag(1/ρ_k)` on the soft rows (0 on hard ones). So a soft row costs
//! nothing more than a hard one: its working-set matrix only gains `1/ρ` on the
//! diagonal, it stays positive definite however many soft rows are active (more than
//! `N` of them may be), and a problem whose rows are all soft is never infeasible.
//!
//! **Why dual.** `λ = 0` (the unconstrained optimum `u = −v`) is dual feasible, so no
//! phase 1 is needed; every iterate is dual feasible and the dual cost rises, so the
//! method ends at the first primal-feasible iterate; an infeasible problem shows as a
//! dual ray (a violated constraint that depends linearly on the working set and whose
//! multiplier can grow without any other reaching zero).
//!
//! **Iteration.** Solve for `λ*` on the working set. If some `λ*_k` has the wrong sign,
//! step `λ ← λ + α(λ* − λ)` to the first multiplier reaching zero and remove that
//! constraint. Otherwise take `λ = λ*`, form `u` and add the most violated inactive
//! constraint (violation above `primal_tol`); none: optimal, `x = R⁻¹u`. If the new
//! row makes the working-set matrix singular (tiny relative pivot: it depends linearly
//! on the hard rows of `W`), move `λ` along the null-space direction, which keeps `u`
//! and raises the dual cost, until a multiplier reaches zero, and swap that constraint
//! for the new one; if no multiplier can reach zero, the problem is infeasible (in
//! `f32`, if the pivot is small but above rounding level, the row is nearly but not
//! exactly dependent and is added after all). Before `Optimal` is returned, the working-set
//! constraints are checked to hold at the final point; if they do not (an inaccurate
//! factor of a nearly singular working set), the factor is recomputed once, and a
//! second failure gives `NumericalError` rather than a wrong optimum.
//!
//! **Factors.** `LDLᵀ` of the working-set matrix, packed by rows: a row is appended
//! when a constraint enters (`O(|W|·N + |W|²)`), and a constraint leaves by deleting its
//! row and column and a rank-one update of the trailing block (`O(|W|²)`, no new
//! factorisation). When a small pivot may come from accumulated rounding, or a solve
//! gives non-finite multipliers, the factor is recomputed from scratch (counted).
//!
//! **Cost.** Per solve: Cholesky of `H` (`N³/6` multiply-adds; none when the caller
//! gives the factor `R`, see [`QpProblem::h_factor`]); `R` is never inverted: `v`,
//! a row's transformation `a_iᵀR⁻¹` and a bound's row `e_jᵀR⁻¹` are triangular
//! solves with `Rᵀ` (`N²/2`, row `axpy`s), the last two only when the constraint
//! first enters the working set in the solve (an inactive row's value is checked as
//! `a_iᵀx`, `x = R⁻¹u` by back substitution, which equals `m̃_iᵀu`); dot products
//! in four partial sums, so that the host pipelines and vectorises them. Per iteration: `O(m·N)` for the constraint values, `O(|W|·N + |W|²)` for the multipliers and the factor update. The counters of
//! [`QpSolution`] (iterations, additions, removals, refactorisations) are
//! deterministic, so a time budget can be derived from them.
//!
//! **Storage.** The solver owns the problem; [`QpSolver::solve`] overwrites `H` with
//! its factor `R` (upper triangle) and the rows `e_jᵀR⁻¹` of the bounds that entered
//! the working set (lower triangle), and the rows `a_i` that entered with `a_i R⁻¹`, so
//! the caller refills them before every solve (the MPC rebuilds them anyway). Nothing is
//! allocated; there is no recursion; the sizes are const generics checked at compile
//! time.
//!
//! **Warm start.** With [`QpSettings::warm_start`], a solve starts from the working
//! set of the previous solve, or the one given with [`QpSolver::set_working_set`]
//! (e.g. shifted by one MPC step). Entries that are out of range, duplicated, at an
//! infinite bound or linearly dependent on earlier entries are dropped; entries whose
//! multipliers come out with the wrong sign leave through ordinary removal steps
//! (starting from `λ = 0`, which is dual feasible).

//!
//! # Use
//!
//! ```
//! use qp::{ldl_len, QpSolver, QpStatus};
//! // 2 variables, up to 4 rows, working set of up to 4.
//! let mut qp = QpSolver::<f64, 2, 4, 4, { ldl_len(4) }>::new();
//! let p = qp.problem_mut(); // fill in place (refill H and rows before every solve)
//! p.h = [[1.0, 0.0], [0.0, 1.0]];
//! p.f = [-2.0, -2.0]; // unconstrained optimum (2, 2)
//! p.x_hi = [1.5, f64::INFINITY]; // x0 ≤ 1.5
//! p.push_row(&[1.0, 1.0], f64::NEG_INFINITY, 2.0, 0.0); // hard: x0 + x1 ≤ 2
//! assert_eq!(qp.solve(), QpStatus::Optimal);
//! let s = qp.solution();
//! assert!((s.x[0] - 1.0).abs() < 1e-12 && (s.x[1] - 1.0).abs() < 1e-12);
//! assert!((s.lambda_rows[0] - 1.0).abs() < 1e-12); // H x + f + Aᵀλ = 0
//! // Next solve: refill, optionally shift `qp.working_set()` and `set_working_set` it.
//! ```
//!
//! # Modules
//!
//! | file | concept |
//! |---|---|
//! | `problem.rs` | [`QpProblem`]: the data; [`ConstraintIndex`], [`Side`], [`ActiveConstraint`] |
//! | `settings.rs` | [`QpSettings`]: tolerances, iteration and refactorization caps |
//! | `solution.rs` | [`QpSolution`], [`QpStatus`] |
//! | `solver.rs` | [`QpSolver`]: the solve's entry, input checks, exits |
//! | `cholesky.rs` | the factor `R` of `H`, triangular solves, rows of `R⁻¹` |
//! | `rows.rs` | transformed constraint rows and their dot products |
//! | `factor.rs` | the working set's `LDLᵀ` factor: append, remove, rebuild, solve |
//! | `active_set.rs` | the dual active-set iteration |
//! | `real.rs` | the scalar trait [`Real`]; `f32` trigonometry in `f32` only |
//! | `work.rs` | flow facts: the most work of `append` a budget of iterations buys |
//!
//! # Timing annotations
//!
//! The `wcet-bound` comments bound loops for the ECU's static timing analysis
//! (`host-sim wcet`, which scans this crate's sources with the firmware's). They
//! name the firmware's constants: on the ECU the solver is the MPC's, `N = NV`,
//! `M = NC`, `W = WS`, its caps `QP_MAX_ITER` and `QP_MAX_REFACTORIZATIONS` per
//! plan activation. The `#[inline(never)]` on the factor updates keeps their
//! per-call bounds (`... per call`) attached to one function each. Where the
//! work of a loop depends on the working set's size, a bound per activation
//! that follows from the algorithm replaces the product of the caps: `append`'s
//! loops over the rows ([`work`], `QP_APPEND_ROWS`), the bounds' rows of `R⁻¹`
//! and the rows' transformations (once per solve).
//!
//! # Features
//!
//! `std` (off by default): builds with the standard library (host tools); the
//! solver itself is the same.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]
// Index loops mirror the maths of the factorisations; the ranges are bounded by the
// const sizes and the working-set count (≤ W).
#![allow(clippy::needless_range_loop)]
// `!(a > b)` is meant: it is also true when `a` is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod real;

mod active_set;
mod cholesky;
mod factor;
mod problem;
mod rows;
mod settings;
mod solution;
mod solver;
#[cfg(test)]
mod tests;
pub mod work;

pub use problem::{ActiveConstraint, ConstraintIndex, QpProblem, Side};
pub use real::Real;
pub use settings::{QpSettings, DEFAULT_MAX_REFACTORIZATIONS};
pub use solution::{QpSolution, QpStatus};
pub use solver::{ldl_len, QpSolver};
