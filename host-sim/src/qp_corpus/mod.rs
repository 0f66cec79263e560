//! QP corpus: every QP the MPC solves over a closed-loop run, recorded as JSON, so other
//! solvers (OSQP, Clarabel) can be benchmarked on exactly the problems ours saw.
//!
//! # Recording
//!
//! [`record`] drives the firmware MPC ([`firmware::mpc::Mpc::step_observed`]) in a closed
//! loop with a kinematic-bicycle plant (the car follows `plan.inputs[0]` for 0.1 s with
//! the bicycle model's RK4 discretisation, as in `firmware/tests/mpc.rs`) along a track
//! given as rows `[x, y, w_right, w_left]` (m), around box or polygon obstacles, starting
//! at the first track point, aligned with the track, at [`START_SPEED_MPS`]. Each
//! condensed QP is copied *before* the solve (the solver overwrites `H` and the rows) and
//! paired with the solution the solver returned. A cold first step solves several QPs
//! (the Gauss–Newton passes of a cold start), each is recorded. If an MPC step fails,
//! recording stops after that step's QPs (their status says why).
//!
//! [`builtin_track_rows`] and [`builtin_obstacles`] give the default scenario: a
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
//! | `solve_us_cold`, `solve_us_warm` | only with `--time`: our f64 solver's time on this QP, µs, from an empty working set and warm-started as in the MPC ([`time_solves`] says what is timed) |
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
//! ([`replay`]), reproduces the MPC's solves bit for bit: the MPC warm-starts each QP
//! from the previous QP's working set with its rows renumbered for this QP (rows are
//! kept by what they constrain, and an obstacle row appearing at an early node moves
//! the later ones), and clears it on a cold step, which only the first step is.
//!
//! # Use
//!
//! `host-sim qp-corpus --out DIR [--steps N] [--precision f64|f32] [--track
//! builtin|paper|FILE [--open]] [--obstacles builtin|none|paper|FILE] [--time
//! [--time-reps K]]` (see [`run`]; `--time` adds our solver's times, [`time_solves`]); the
//! benchmark `cargo bench -p host-sim --bench qp_solvers` reads `QP_CORPUS=DIR` or
//! records the built-in scenario itself.

use std::cell::RefCell;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use firmware::mpc::{Mpc, MpcQp, MpcQpProblem, MpcQpSolution, NC, NV};
use firmware::obstacles::{Obstacle, ObstacleManager};

use crate::closed_loop;
use crate::model::vehicle::VehicleParams;
use firmware::plan::Plan;
use firmware::reference_path::ReferencePath;
use firmware::state_estimate::StateEstimate;
use firmware::Real;
use qp::{ActiveConstraint, ConstraintIndex, QpStatus, Side};
use serde::{Deserialize, Serialize};

/// Number of decision variables of the MPC's QP (the inputs over the horizon).
pub const N_DECISION: usize = NV;
/// Speed at the start of a recording, m/s.
pub const START_SPEED_MPS: f64 = 15.0;
/// Road friction coefficient used for the recording (dimensionless).
pub const MU: f64 = 1.0;
/// Default number of MPC steps (0.1 s each): a little more than a lap of the
/// built-in track.
pub const DEFAULT_STEPS: usize = 400;
/// Largest number of track rows [`record`] accepts (the reference path's capacity).
pub const PATH_CAPACITY: usize = 4096;
/// Planning period of the closed loop, s.
const STEP_S: f64 = 0.1;
/// Plant integration steps per planning period.
const PLANT_SUBSTEPS: usize = 10;

pub use crate::closed_loop::Precision;

/// The QP in our solver's own form (see the module doc): `min ½xᵀHx + fᵀx + Σ ½ρ_i s_i²`
/// s.t. `x_lo ≤ x ≤ x_hi`, `lo_i (− s_i) ≤ a_iᵀx ≤ hi_i (+ s_i)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NativeQp {
    /// Variables (32).
    pub n: usize,
    /// General rows in use.
    pub m: usize,
    /// `H`, `n×n` row-major; only the upper triangle is meaningful. When
    /// [`NativeQp::h_factor`], the upper-triangular factor `R` of `H = RᵀR` instead
    /// (what the MPC hands the solver; [`NativeQp::h_sym`] gives `H` either way).
    #[serde(rename = "H")]
    pub h: Vec<f64>,
    /// `H` holds the factor `R` (`QpProblem::h_factor`).
    #[serde(default, rename = "H_is_factor")]
    pub h_factor: bool,
    /// Linear cost, `n`.
    pub f: Vec<f64>,
    /// Rows, `m×n` row-major.
    #[serde(rename = "A")]
    pub a: Vec<f64>,
    /// Row lower bounds, `m` (`None`: −∞), in row units.
    pub lo: Vec<Option<f64>>,
    /// Row upper bounds, `m` (`None`: +∞).
    pub hi: Vec<Option<f64>>,
    /// Variable lower bounds, `n` (`None`: −∞); m/s² for accelerations, rad/s for rates.
    pub x_lo: Vec<Option<f64>>,
    /// Variable upper bounds, `n` (`None`: +∞).
    pub x_hi: Vec<Option<f64>>,
    /// Soft weights `ρ_i`, `m` (0: hard), cost per squared row unit.
    pub soft: Vec<f64>,
    /// Iteration cap the MPC gave the solver.
    pub max_iter: u32,
}

/// A QP in standard form `min ½zᵀHz + fᵀz` s.t. `lower ≤ Az ≤ upper` (dense, row-major).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StandardQp {
    /// Variables.
    pub n: usize,
    /// Rows of `A`.
    pub m: usize,
    /// `H`, `n×n`, full symmetric, row-major.
    #[serde(rename = "H")]
    pub h: Vec<f64>,
    /// Linear cost, `n`.
    pub f: Vec<f64>,
    /// Constraint matrix, `m×n` row-major.
    #[serde(rename = "A")]
    pub a: Vec<f64>,
    /// Row lower bounds, `m` (`None`: −∞).
    pub lower: Vec<Option<f64>>,
    /// Row upper bounds, `m` (`None`: +∞).
    pub upper: Vec<Option<f64>>,
}

/// One recorded QP: one JSON file of the corpus (keys in the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorpusEntry {
    /// The standard form (keys `n`, `m`, `H`, `f`, `A`, `lower`, `upper`).
    #[serde(flatten)]
    pub standard: StandardQp,
    /// Our solution in the standard form's variables (inputs, then slacks).
    pub x: Vec<f64>,
    /// Our solver's status ([`status_name`]).
    pub status: String,
    /// Our solver's iterations.
    pub iterations: u32,
    /// Number of leading variables that are MPC inputs (32).
    pub n_decision: usize,
    /// Our solver's own form of the problem.
    pub native: NativeQp,
    /// `"f64"` or `"f32"`: the precision of the MPC run.
    pub precision: String,
    /// MPC step (0.1 s of closed loop each) that solved this QP.
    pub step: usize,
    /// Pass within the step (a cold start runs several).
    pub pass: u32,
    /// Our objective `½xᵀHx + fᵀx + Σ ½ρ_i s_i²`, cost units.
    pub objective: f64,
    /// Constraints added to our working set.
    pub added: u32,
    /// Constraints removed from our working set.
    pub removed: u32,
    /// Our from-scratch refactorisations.
    pub refactorizations: u32,
    /// With `qp-corpus --time`: our f64 solver's time on this QP from an empty working
    /// set, µs (median of the repetitions; see [`time_solves`] for what is timed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solve_us_cold: Option<f64>,
    /// With `qp-corpus --time`: the same, warm-started from the working set the MPC's
    /// solve started from (`warm_start`), µs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solve_us_warm: Option<f64>,
    /// The working set our solve started from (the MPC's warm start), in order.
    #[serde(default)]
    pub warm_start: Vec<WarmStartEntry>,
}

/// One entry of the working set a corpus QP's solve started from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WarmStartIndex {
    /// The bound on variable `j`.
    Bound(u16),
    /// General row `i` of the native problem.
    Row(u16),
}

/// One entry of `warm_start`: the constraint and the side held (`"lower"`, `"upper"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WarmStartEntry {
    /// The constraint.
    #[serde(flatten)]
    pub index: WarmStartIndex,
    /// `"lower"` or `"upper"`.
    pub side: WarmStartSide,
}

/// The side of a working-set entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WarmStartSide {
    /// Held at its lower bound.
    Lower,
    /// Held at its upper bound.
    Upper,
}

impl WarmStartEntry {
    /// From the solver's working-set entry.
    pub fn from_active(e: &ActiveConstraint) -> Self {
        Self {
            index: match e.index {
                ConstraintIndex::Bound(j) => WarmStartIndex::Bound(j),
                ConstraintIndex::Row(i) => WarmStartIndex::Row(i),
            },
            side: match e.side {
                Side::Lower => WarmStartSide::Lower,
                Side::Upper => WarmStartSide::Upper,
            },
        }
    }

    /// The solver's working-set entry.
    pub fn to_active(self) -> ActiveConstraint {
        ActiveConstraint {
            index: match self.index {
                WarmStartIndex::Bound(j) => ConstraintIndex::Bound(j),
                WarmStartIndex::Row(i) => ConstraintIndex::Row(i),
            },
            side: match self.side {
                WarmStartSide::Lower => Side::Lower,
                WarmStartSide::Upper => Side::Upper,
            },
        }
    }
}

/// The corpus name of a solver status (`"optimal"`, `"iteration_limit"`, …).
pub fn status_name(s: QpStatus) -> &'static str {
    match s {
        QpStatus::NotSolved => "not_solved",
        QpStatus::Optimal => "optimal",
        QpStatus::IterationLimit => "iteration_limit",
        QpStatus::Infeasible => "infeasible",
        QpStatus::NotConvex => "not_convex",
        QpStatus::NumericalError => "numerical_error",
        QpStatus::NonFiniteInput => "non_finite_input",
        QpStatus::InvalidInput => "invalid_input",
        QpStatus::WorkingSetFull => "working_set_full",
    }
}

fn finite_or_none(v: f64) -> Option<f64> {
    if v.is_finite() {
        Some(v)
    } else {
        None
    }
}

impl NativeQp {
    /// Copies the used part of a problem held by our solver (before it is solved).
    pub fn from_problem<T: Real>(p: &MpcQpProblem<T>) -> Self {
        let m = p.m.min(NC);
        let rows = p.a.get(..m).unwrap_or(&[]);
        let conv = |v: &[T]| v.iter().map(|x| x.to_f64()).collect::<Vec<_>>();
        let conv_opt = |v: &[T]| {
            v.iter()
                .map(|x| finite_or_none(x.to_f64()))
                .collect::<Vec<_>>()
        };
        Self {
            n: NV,
            m,
            h: p.h.iter().flat_map(|r| conv(r)).collect(),
            h_factor: p.h_factor,
            f: conv(&p.f),
            a: rows.iter().flat_map(|r| conv(r)).collect(),
            lo: conv_opt(p.lo.get(..m).unwrap_or(&[])),
            hi: conv_opt(p.hi.get(..m).unwrap_or(&[])),
            x_lo: conv_opt(&p.x_lo),
            x_hi: conv_opt(&p.x_hi),
            soft: conv(p.soft.get(..m).unwrap_or(&[])),
            max_iter: 0,
        }
    }

    /// Checks that the sizes fit our MPC solver (`n = 32`, `m ≤ 80`) and are consistent.
    pub fn check(&self) -> Result<()> {
        ensure!(
            self.n == NV,
            "native QP has n = {}, our MPC solver has {NV} variables",
            self.n
        );
        ensure!(
            self.m <= NC,
            "native QP has m = {} rows, our MPC solver holds at most {NC}",
            self.m
        );
        let (n, m) = (self.n, self.m);
        ensure!(
            self.h.len() == n * n
                && self.f.len() == n
                && self.a.len() == m * n
                && self.lo.len() == m
                && self.hi.len() == m
                && self.x_lo.len() == n
                && self.x_hi.len() == n
                && self.soft.len() == m,
            "native QP arrays do not match n = {n}, m = {m} (H n×n, f n, A m×n, lo/hi/soft m, x_lo/x_hi n)"
        );
        Ok(())
    }

    /// Writes this problem into a solver's problem (all of it: call before every solve).
    pub fn fill<T: Real>(&self, p: &mut MpcQpProblem<T>) -> Result<()> {
        self.check()?;
        let n = self.n;
        p.clear();
        p.h_factor = self.h_factor;
        for (r, row) in p.h.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = T::from_f64(self.h.get(r * n + c).copied().unwrap_or(0.0));
            }
        }
        for (d, s) in p.f.iter_mut().zip(&self.f) {
            *d = T::from_f64(*s);
        }
        for (r, row) in p.a.iter_mut().take(self.m).enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = T::from_f64(self.a.get(r * n + c).copied().unwrap_or(0.0));
            }
        }
        let lo = |v: &Option<f64>| v.map_or(T::NEG_INFINITY, T::from_f64);
        let hi = |v: &Option<f64>| v.map_or(T::INFINITY, T::from_f64);
        for i in 0..self.m {
            if let (Some(l), Some(h), Some(s)) =
                (p.lo.get_mut(i), p.hi.get_mut(i), p.soft.get_mut(i))
            {
                *l = self.lo.get(i).map_or(T::NEG_INFINITY, lo);
                *h = self.hi.get(i).map_or(T::INFINITY, hi);
                *s = T::from_f64(self.soft.get(i).copied().unwrap_or(0.0));
            }
        }
        for (d, s) in p.x_lo.iter_mut().zip(&self.x_lo) {
            *d = lo(s);
        }
        for (d, s) in p.x_hi.iter_mut().zip(&self.x_hi) {
            *d = hi(s);
        }
        p.m = self.m;
        Ok(())
    }

    /// A boxed solver problem holding this QP.
    pub fn to_problem<T: Real>(&self) -> Result<Box<MpcQpProblem<T>>> {
        let mut p = Box::new(MpcQpProblem::<T>::new());
        self.fill(&mut p)?;
        Ok(p)
    }

    /// Indices of the soft rows (`ρ_i > 0`), in row order: slack `k` of the standard
    /// form belongs to row `soft_rows()[k]`.
    pub fn soft_rows(&self) -> Vec<usize> {
        (0..self.m)
            .filter(|&i| self.soft.get(i).is_some_and(|&r| r > 0.0))
            .collect()
    }

    /// `H[r][c]` of the symmetric Hessian, read from the upper triangle (or
    /// `(RᵀR)[r][c]` from the factor).
    pub fn h_sym(&self, r: usize, c: usize) -> f64 {
        let (i, j) = if r <= c { (r, c) } else { (c, r) };
        if self.h_factor {
            (0..=i)
                .map(|k| {
                    self.h.get(k * self.n + i).copied().unwrap_or(0.0)
                        * self.h.get(k * self.n + j).copied().unwrap_or(0.0)
                })
                .sum()
        } else {
            self.h.get(i * self.n + j).copied().unwrap_or(0.0)
        }
    }

    /// `a_iᵀ x` for row `i`.
    pub fn row_value(&self, i: usize, x: &[f64]) -> f64 {
        let row = self.a.get(i * self.n..(i + 1) * self.n).unwrap_or(&[]);
        row.iter().zip(x).map(|(a, b)| a * b).sum()
    }

    /// The slacks of the soft rows from the row multipliers: `s_i = |λ_i| / ρ_i`, one per
    /// soft row (row units).
    pub fn slacks_from_multipliers(&self, lambda_rows: &[f64]) -> Vec<f64> {
        self.soft_rows()
            .into_iter()
            .map(|i| {
                let rho = self.soft.get(i).copied().unwrap_or(1.0);
                lambda_rows.get(i).map_or(0.0, |l| l.abs() / rho)
            })
            .collect()
    }

    /// The slacks of the soft rows at `x`: `s_i = max(lo_i − a_iᵀx, a_iᵀx − hi_i, 0)`.
    pub fn slacks_at(&self, x: &[f64]) -> Vec<f64> {
        self.soft_rows()
            .into_iter()
            .map(|i| {
                let v = self.row_value(i, x);
                let below = self.lo.get(i).copied().flatten().map_or(0.0, |l| l - v);
                let above = self.hi.get(i).copied().flatten().map_or(0.0, |h| v - h);
                below.max(above).max(0.0)
            })
            .collect()
    }

    /// The native objective `½xᵀHx + fᵀx + Σ ½ρ_i s_i²` at inputs `x` (32) and slacks `s`
    /// (one per soft row), cost units.
    pub fn objective(&self, x: &[f64], slacks: &[f64]) -> f64 {
        let n = self.n.min(x.len());
        let mut q = 0.0;
        for (r, &xr) in x.iter().take(n).enumerate() {
            let hx: f64 = x
                .iter()
                .take(n)
                .enumerate()
                .map(|(c, &xc)| self.h_sym(r, c) * xc)
                .sum();
            q += xr * (0.5 * hx + self.f.get(r).copied().unwrap_or(0.0));
        }
        let pen: f64 = self
            .soft_rows()
            .iter()
            .zip(slacks)
            .map(|(&i, s)| 0.5 * self.soft.get(i).copied().unwrap_or(0.0) * s * s)
            .sum();
        q + pen
    }

    /// The equivalent standard form (see the module doc): variables `[x; s]`, bounds as
    /// rows, two rows per two-sided soft row plus `s ≥ 0`.
    pub fn to_standard(&self) -> StandardQp {
        let soft = self.soft_rows();
        let nd = self.n;
        let n = nd + soft.len();
        let mut h = vec![0.0; n * n];
        for r in 0..nd {
            for c in 0..nd {
                h[r * n + c] = self.h_sym(r, c);
            }
        }
        for (k, &i) in soft.iter().enumerate() {
            h[(nd + k) * n + nd + k] = self.soft.get(i).copied().unwrap_or(0.0);
        }
        let mut f = vec![0.0; n];
        f[..nd].copy_from_slice(self.f.get(..nd).unwrap_or(&[]));
        let mut a: Vec<f64> = Vec::new();
        let mut lower = Vec::new();
        let mut upper = Vec::new();
        let mut push = |coefs: &[(usize, f64)], base: Option<&[f64]>, l, u| {
            let start = a.len();
            a.resize(start + n, 0.0);
            if let Some(b) = base {
                a[start..start + nd].copy_from_slice(b);
            }
            for &(j, v) in coefs {
                a[start + j] = v;
            }
            lower.push(l);
            upper.push(u);
        };
        for j in 0..nd {
            let (l, u) = (
                self.x_lo.get(j).copied().flatten(),
                self.x_hi.get(j).copied().flatten(),
            );
            if l.is_some() || u.is_some() {
                push(&[(j, 1.0)], None, l, u);
            }
        }
        for i in 0..self.m {
            let row = self.a.get(i * nd..(i + 1) * nd);
            let (l, u) = (
                self.lo.get(i).copied().flatten(),
                self.hi.get(i).copied().flatten(),
            );
            match soft.iter().position(|&s| s == i) {
                None => {
                    if l.is_some() || u.is_some() {
                        push(&[], row, l, u);
                    }
                }
                Some(k) => {
                    if l.is_some() {
                        push(&[(nd + k, 1.0)], row, l, None);
                    }
                    if u.is_some() {
                        push(&[(nd + k, -1.0)], row, None, u);
                    }
                }
            }
        }
        for k in 0..soft.len() {
            push(&[(nd + k, 1.0)], None, Some(0.0), None);
        }
        StandardQp {
            n,
            m: lower.len(),
            h,
            f,
            a,
            lower,
            upper,
        }
    }
}

/// A [`StandardQp`] in the conic form of interior-point solvers such as Clarabel:
/// `min ½zᵀPz + fᵀz` s.t. `A z + s = b`, `s` in `{0}^n_eq × ℝ₊^n_ineq`, as
/// triplets (row, column, value) for a sparse matrix.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConicQp {
    /// Variables.
    pub n: usize,
    /// Upper triangle of `P = H`, triplets.
    pub p: (Vec<usize>, Vec<usize>, Vec<f64>),
    /// `A`, triplets: the equality rows first, then one row per finite side.
    pub a: (Vec<usize>, Vec<usize>, Vec<f64>),
    /// Right-hand side, one per row of `A`.
    pub b: Vec<f64>,
    /// Equality rows (the zero cone), first in `A`.
    pub n_eq: usize,
    /// Inequality rows (the non-negative cone), after them.
    pub n_ineq: usize,
}

impl StandardQp {
    /// The conic form: `lo = hi` rows become equalities, a finite upper side
    /// `aᵀz ≤ hi` the row `aᵀz + s = hi`, a finite lower side `−aᵀz + s = −lo`.
    pub fn conic(&self) -> ConicQp {
        let n = self.n;
        let mut c = ConicQp {
            n,
            ..ConicQp::default()
        };
        for r in 0..n {
            for col in r..n {
                let v = self.h.get(r * n + col).copied().unwrap_or(0.0);
                if v != 0.0 {
                    c.p.0.push(r);
                    c.p.1.push(col);
                    c.p.2.push(v);
                }
            }
        }
        let (mut eq, mut ineq) = (Vec::new(), Vec::new()); // (row, sign, b)
        for i in 0..self.m {
            match (
                self.lower.get(i).copied().flatten(),
                self.upper.get(i).copied().flatten(),
            ) {
                (Some(l), Some(u)) if l == u => eq.push((i, 1.0, u)),
                (l, u) => {
                    if let Some(u) = u {
                        ineq.push((i, 1.0, u));
                    }
                    if let Some(l) = l {
                        ineq.push((i, -1.0, -l));
                    }
                }
            }
        }
        c.n_eq = eq.len();
        c.n_ineq = ineq.len();
        for (r, &(i, sign, bv)) in eq.iter().chain(ineq.iter()).enumerate() {
            for col in 0..n {
                let v = self.a.get(i * n + col).copied().unwrap_or(0.0);
                if v != 0.0 {
                    c.a.0.push(r);
                    c.a.1.push(col);
                    c.a.2.push(sign * v);
                }
            }
            c.b.push(bv);
        }
        c
    }

    /// `½zᵀHz + fᵀz`, cost units.
    pub fn objective(&self, z: &[f64]) -> f64 {
        let n = self.n.min(z.len());
        let mut q = 0.0;
        for r in 0..n {
            let row = self.h.get(r * self.n..r * self.n + n).unwrap_or(&[]);
            let hz: f64 = row.iter().zip(z).map(|(a, b)| a * b).sum();
            q += z[r] * (0.5 * hz + self.f.get(r).copied().unwrap_or(0.0));
        }
        q
    }

    /// `A z` (`m`).
    pub fn rows_at(&self, z: &[f64]) -> Vec<f64> {
        (0..self.m)
            .map(|i| {
                let row = self.a.get(i * self.n..(i + 1) * self.n).unwrap_or(&[]);
                row.iter().zip(z).map(|(a, b)| a * b).sum()
            })
            .collect()
    }

    /// Largest violation of `lower ≤ Az ≤ upper` at `z` (0 if feasible), row units.
    pub fn max_violation(&self, z: &[f64]) -> f64 {
        self.rows_at(z)
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let below = self.lower.get(i).copied().flatten().map_or(0.0, |l| l - v);
                let above = self.upper.get(i).copied().flatten().map_or(0.0, |u| v - u);
                below.max(above).max(0.0)
            })
            .fold(0.0, f64::max)
    }
}

impl CorpusEntry {
    /// Builds an entry from the problem as given to the solver and the solution it
    /// returned.
    pub fn from_solve<T: Real>(
        problem: &MpcQpProblem<T>,
        solution: &MpcQpSolution<T>,
        max_iter: u32,
        precision: Precision,
        step: usize,
        pass: u32,
    ) -> Self {
        let mut native = NativeQp::from_problem(problem);
        native.max_iter = max_iter;
        let lambda: Vec<f64> = solution.lambda_rows.iter().map(|v| v.to_f64()).collect();
        let mut x: Vec<f64> = solution.x.iter().map(|v| v.to_f64()).collect();
        x.extend(native.slacks_from_multipliers(&lambda));
        Self {
            standard: native.to_standard(),
            x,
            status: status_name(solution.status).to_string(),
            iterations: solution.iterations,
            n_decision: NV,
            native,
            precision: precision.name().to_string(),
            step,
            pass,
            objective: solution.objective.to_f64(),
            added: solution.added,
            removed: solution.removed,
            refactorizations: solution.refactorizations,
            solve_us_cold: None,
            solve_us_warm: None,
            warm_start: Vec::new(),
        }
    }
}

/// The built-in closed track: a 120 m × 70 m loop (counter-clockwise, starting at
/// `(10, 0)` heading +X) of four straights joined by 90° curves of radii 30, 15, 20 and
/// 10 m, one point per metre, rows `[x, y, w_right, w_left]` with 4 m half-widths.
pub fn builtin_track_rows() -> Vec<[f64; 4]> {
    use std::f64::consts::FRAC_PI_2;
    let (w, h) = (120.0f64, 70.0f64);
    // Corner radii: bottom-right, top-right, top-left, bottom-left.
    let r = [30.0f64, 15.0, 20.0, 10.0];
    let centres = [
        [w - r[0], r[0]],
        [w - r[1], h - r[1]],
        [r[2], h - r[2]],
        [r[3], r[3]],
    ];
    // Straight starts: bottom, right, top, left (each ends where the next curve starts).
    let straights = [
        ([r[3], 0.0], [w - r[0], 0.0]),
        ([w, r[0]], [w, h - r[1]]),
        ([w - r[1], h], [r[2], h]),
        ([0.0, h - r[2]], [0.0, r[3]]),
    ];
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for k in 0..4 {
        let (p0, p1) = straights[k];
        let len = (p1[0] - p0[0]).hypot(p1[1] - p0[1]);
        let n = len.round().max(1.0) as usize;
        for i in 0..n {
            let t = i as f64 / n as f64;
            pts.push([p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])]);
        }
        // Curve k turns from heading k·90° to (k+1)·90°, counter-clockwise.
        let a0 = -FRAC_PI_2 + k as f64 * FRAC_PI_2;
        let n = (r[k] * FRAC_PI_2).round().max(2.0) as usize;
        for i in 0..n {
            let a = a0 + FRAC_PI_2 * i as f64 / n as f64;
            pts.push([
                centres[k][0] + r[k] * a.cos(),
                centres[k][1] + r[k] * a.sin(),
            ]);
        }
    }
    pts.into_iter().map(|p| [p[0], p[1], 4.0, 4.0]).collect()
}

/// The built-in obstacles: three 4 m × 2 m boxes (vertices, m) on the built-in track,
/// each on the outer side of a straight (bottom, right, top), so the car passes them
/// on the inside.
///
/// Why the outside: the firmware's `Parabola::is_relevant` only checks the position
/// along the obstacle's tangent (`ξ`), so an obstacle's row also appears where the
/// loop passes through the same `ξ` strip on the far side of the track; for a box on
/// the inside of the loop, passed on the outside, that far-side row cannot be met
/// (a box at `(118.5, 42)` makes step 217 end `WorkingSetFull` with a 130 m slack).
pub fn builtin_obstacles() -> Vec<Vec<[f64; 2]>> {
    let boxed = |cx: f64, cy: f64, hx: f64, hy: f64| {
        vec![
            [cx - hx, cy - hy],
            [cx + hx, cy - hy],
            [cx + hx, cy + hy],
            [cx - hx, cy + hy],
        ]
    };
    vec![
        // Bottom straight (heading +X): right is −Y.
        boxed(55.0, -1.5, 2.0, 1.0),
        // Right straight (heading +Y): right is +X.
        boxed(121.5, 42.0, 1.0, 2.0),
        // Top straight (heading −X): right is +Y.
        boxed(60.0, 71.5, 2.0, 1.0),
    ]
}

/// Runs the MPC in closed loop with a kinematic-bicycle plant for `steps` planning
/// periods of 0.1 s along the track `rows` (`[x, y, w_right, w_left]`, m; `closed` for
/// a loop) around `obstacles` (polygons, vertices in m), in `precision`, and returns
/// every QP it solved, in order.
///
/// The car starts at the first track point heading to the second at
/// [`START_SPEED_MPS`], on a road of friction [`MU`]. If an MPC step fails, the run
/// stops and the QPs recorded so far, including the failed one, are returned.
pub fn record(
    rows: &[[f64; 4]],
    closed: bool,
    obstacles: &[Vec<[f64; 2]>],
    steps: usize,
    precision: Precision,
) -> Result<Vec<CorpusEntry>> {
    match precision {
        Precision::F64 => record_in::<f64>(rows, closed, obstacles, steps, precision),
        Precision::F32 => record_in::<f32>(rows, closed, obstacles, steps, precision),
    }
}

fn record_in<T: Real>(
    rows: &[[f64; 4]],
    closed: bool,
    obstacles: &[Vec<[f64; 2]>],
    steps: usize,
    precision: Precision,
) -> Result<Vec<CorpusEntry>> {
    ensure!(
        rows.len() >= 2,
        "the track needs at least 2 rows [x, y, w_right, w_left], got {}",
        rows.len()
    );
    ensure!(
        rows.len() <= PATH_CAPACITY,
        "the track has {} rows, at most {PATH_CAPACITY} fit: resample it more coarsely",
        rows.len()
    );
    let rows_t: Vec<[T; 4]> = rows.iter().map(|r| r.map(T::from_f64)).collect::<Vec<_>>();
    let mut path = Box::new(ReferencePath::<T, PATH_CAPACITY>::new());
    path.load_track(&rows_t, closed)
        .map_err(|e| anyhow::anyhow!("the track cannot be loaded: {e:?}"))?;
    let mut obs_t = Vec::with_capacity(obstacles.len());
    for (k, verts) in obstacles.iter().enumerate() {
        let v: Vec<[T; 2]> = verts.iter().map(|p| p.map(T::from_f64)).collect();
        let o = Obstacle::from_vertices(k as u32, &v)
            .map_err(|e| anyhow::anyhow!("obstacle {k} is invalid: {e:?}"))?;
        obs_t.push(o);
    }
    // The simulator's settings for the built-in vehicle.
    let vehicle = VehicleParams::default();
    let car = closed_loop::vehicle_config::<T>(&vehicle);
    let settings = car.mpc_settings();
    let obstacle_settings = car.obstacle_settings(T::from_f64(MU));
    let mut manager = ObstacleManager::<T>::new();
    manager
        .update(&obstacle_settings, &*path, &obs_t)
        .map_err(|e| {
            anyhow::anyhow!(
                "the obstacles cannot be placed on the track: {e:?} (move them or widen the road)"
            )
        })?;

    let max_iter = settings.qp_max_iter;
    let (p0, p1) = match (rows.first(), rows.get(1)) {
        (Some(a), Some(b)) => (*a, *b),
        _ => bail!("the track needs at least 2 rows"),
    };
    let psi0 = (p1[1] - p0[1]).atan2(p1[0] - p0[0]);
    let mut est = StateEstimate::<T> {
        stamp_us: 0,
        x_m: T::from_f64(p0[0]),
        y_m: T::from_f64(p0[1]),
        psi_rad: T::from_f64(psi0),
        vx_mps: T::from_f64(START_SPEED_MPS),
        ..StateEstimate::zeroed()
    };
    let mut mpc = Box::new(Mpc::<T>::new());
    let mut plan = Box::new(Plan::<T>::zeroed());
    let mut out = Vec::new();
    let mu = T::from_f64(MU);
    let dt = T::from_f64(STEP_S / PLANT_SUBSTEPS as f64);
    for step in 0..steps {
        // Written by `before`, taken by `after`: both closures need it.
        let pending: RefCell<Option<PendingQp<T>>> = RefCell::new(None);
        let mut pass = 0u32;
        let res = mpc.step_observed(
            &settings,
            &*path,
            manager.parabolas(),
            &est,
            mu,
            &mut plan,
            |q| {
                let ws = q
                    .working_set()
                    .iter()
                    .map(WarmStartEntry::from_active)
                    .collect();
                *pending.borrow_mut() = Some((Box::new(q.problem().clone()), ws));
            },
            |s| {
                if let Some((p, ws)) = pending.borrow_mut().take() {
                    let mut e = CorpusEntry::from_solve(&p, s, max_iter, precision, step, pass);
                    e.warm_start = ws;
                    out.push(e);
                }
                pass += 1;
            },
        );
        if res.is_err() {
            break;
        }
        let mut xi = [
            T::ZERO,
            est.x_m,
            est.y_m,
            est.speed_mps(),
            est.psi_rad,
            est.delta_rad,
        ];
        for _ in 0..PLANT_SUBSTEPS {
            xi = settings
                .geometry
                .discretize(&xi, &plan.inputs[0], dt)
                .x_next;
        }
        est = StateEstimate {
            stamp_us: est.stamp_us + (STEP_S * 1e6) as u64,
            x_m: xi[1],
            y_m: xi[2],
            psi_rad: xi[4],
            vx_mps: xi[3],
            vy_mps: T::ZERO,
            yaw_rate_radps: T::ZERO,
            delta_rad: xi[5],
        };
    }
    Ok(out)
}

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

/// A QP copied before its solve, with the working set the solve starts from.
type PendingQp<T> = (Box<MpcQpProblem<T>>, Vec<WarmStartEntry>);

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
            median(&samples)
        };
        let cold_us = time_from(&cold, &mut run);
        warm.set_working_set_from(e.warm_start.iter().map(|w| w.to_active()));
        let warm_us = time_from(&warm, &mut run);
        out.push((cold_us, warm_us));
    }
    Ok(out)
}

/// Median of a non-empty list (the mean of the middle two for an even length); 0 for
/// an empty one.
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    match (s.get((n.max(1) - 1) / 2), s.get(n / 2)) {
        (Some(a), Some(b)) => 0.5 * (a + b),
        _ => 0.0,
    }
}

/// Writes the corpus as `dir/qp_0000.json`, … (creating `dir`).
pub fn write_corpus(dir: &Path, entries: &[CorpusEntry]) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output directory {}", dir.display()))?;
    for (k, e) in entries.iter().enumerate() {
        let path = dir.join(format!("qp_{k:04}.json"));
        let file = std::fs::File::create(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        serde_json::to_writer(&mut w, e)
            .with_context(|| format!("cannot write {}", path.display()))?;
        std::io::Write::flush(&mut w)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// Reads every `qp_*.json` of `dir`, in file-name order.
pub fn read_corpus(dir: &Path) -> Result<Vec<CorpusEntry>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read the corpus directory {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("qp_") && n.ends_with(".json"))
        })
        .collect();
    files.sort();
    ensure!(
        !files.is_empty(),
        "no qp_*.json in {} (write a corpus with `host-sim qp-corpus --out DIR`)",
        dir.display()
    );
    files
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read {}", p.display()))?;
            let e: CorpusEntry = serde_json::from_str(&text)
                .with_context(|| format!("{} is not a corpus QP", p.display()))?;
            e.native
                .check()
                .with_context(|| format!("in {}", p.display()))?;
            Ok(e)
        })
        .collect()
}

/// Median and maximum of a list of counts (0, 0 for an empty list).
pub fn median_max(v: &[u32]) -> (u32, u32) {
    let mut s = v.to_vec();
    s.sort_unstable();
    let med = s.get(s.len() / 2).copied().unwrap_or(0);
    (med, s.last().copied().unwrap_or(0))
}

/// Arguments of `host-sim qp-corpus`.
#[derive(Clone, Debug, clap::Args)]
pub struct QpCorpusArgs {
    /// Directory to write `qp_0000.json`, … into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// MPC steps of 0.1 s to run (a cold first step solves 3 QPs, the others 1).
    #[arg(long, default_value_t = DEFAULT_STEPS)]
    pub steps: usize,
    /// Precision of the MPC run to record.
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Track: `builtin` (this module's 120 m × 70 m loop), `paper` or a CSV file
    /// `# x_m,y_m,w_tr_right_m,w_tr_left_m`.
    #[arg(long, default_value = "builtin")]
    pub track: String,
    /// The track file is an open path (default: closed loop).
    #[arg(long)]
    pub open: bool,
    /// Obstacles: `builtin` (with `--track builtin`), `none`, `paper` (with `--track
    /// paper`) or a CSV file `id,x_m,y_m`.
    #[arg(long, default_value = "builtin")]
    pub obstacles: String,
    /// Also time our f64 solver on every QP, cold and warm (keys `solve_us_cold`,
    /// `solve_us_warm`, µs; see `time_solves`), and print the percentiles.
    #[arg(long)]
    pub time: bool,
    /// Repetitions per QP and mode with `--time` (their median is kept; at least 5).
    #[arg(long, default_value_t = 21)]
    pub time_reps: usize,
}

/// Track rows, closed flag and obstacle polygons (m) of `args`' scenario.
type ScenarioData = (Vec<[f64; 4]>, bool, Vec<Vec<[f64; 2]>>);

fn scenario_data(args: &QpCorpusArgs) -> Result<ScenarioData> {
    let file_obstacles = |path: &str| -> Result<Vec<Vec<[f64; 2]>>> {
        Ok(crate::world::obstacle_file::load_obstacles_path(path)?
            .into_iter()
            .map(|o| o.vertices)
            .collect())
    };
    if args.track == "builtin" {
        ensure!(
            !args.open,
            "the built-in track is a closed loop; --open only applies to track files"
        );
        let obstacles = match args.obstacles.as_str() {
            "builtin" => builtin_obstacles(),
            "none" => Vec::new(),
            "paper" => bail!(
                "the `paper` obstacles are placed on the `paper` track; with `--track builtin` use `--obstacles builtin`, `none` or an obstacle file"
            ),
            path => file_obstacles(path)?,
        };
        return Ok((builtin_track_rows(), true, obstacles));
    }
    ensure!(
        args.obstacles != "builtin",
        "`--obstacles builtin` goes with `--track builtin`; with `--track {}` use `none`, `paper` (paper track) or an obstacle file",
        args.track
    );
    let sc = crate::world::scenario::resolve(&args.track, &args.obstacles, !args.open)?;
    Ok((
        sc.track.rows(),
        sc.track.closed,
        sc.obstacles.into_iter().map(|o| o.vertices).collect(),
    ))
}

/// `host-sim qp-corpus`: records the scenario of `--track`/`--obstacles` and writes the
/// corpus; prints a summary (QPs, statuses, iterations).
pub fn run(args: &QpCorpusArgs) -> Result<()> {
    ensure!(args.steps > 0, "--steps must be at least 1");
    let (rows, closed, obstacles) = scenario_data(args)?;
    let mut entries = record(&rows, closed, &obstacles, args.steps, args.precision)?;
    if args.time {
        let times = time_solves(&entries, args.time_reps)?;
        for (e, &(cold, warm)) in entries.iter_mut().zip(&times) {
            e.solve_us_cold = Some(cold);
            e.solve_us_warm = Some(warm);
        }
        let (cold, warm): (Vec<f64>, Vec<f64>) = times.into_iter().unzip();
        let pct = crate::closed_loop::cost_model::percentile;
        println!(
            "our f64 solve() (median of {} repetitions per QP): cold p50 {:.1} µs, p99 {:.1} µs; warm p50 {:.1} µs, p99 {:.1} µs",
            args.time_reps,
            pct(&cold, 0.5),
            pct(&cold, 0.99),
            pct(&warm, 0.5),
            pct(&warm, 0.99)
        );
    }
    write_corpus(&args.out, &entries)?;
    let optimal = entries.iter().filter(|e| e.status == "optimal").count();
    let warm: Vec<u32> = entries.iter().map(|e| e.iterations).collect();
    let (wmed, wmax) = median_max(&warm);
    println!(
        "wrote {} QPs ({} precision) to {}: {optimal} optimal; iterations (warm, as in the MPC) median {wmed}, max {wmax}",
        entries.len(),
        args.precision.name(),
        args.out.display()
    );
    if let Some(last) = entries.last() {
        let steps_done = last.step + 1;
        if last.status != "optimal" {
            println!(
                "warning: the MPC failed at step {} ({}); the run stopped there",
                last.step, last.status
            );
        } else if steps_done < args.steps {
            println!("warning: only {steps_done} of {} steps ran", args.steps);
        }
    }
    Ok(())
}
