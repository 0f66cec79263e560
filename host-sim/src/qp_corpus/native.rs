//! The QP in our solver's own form ([`NativeQp`]): what the MPC handed the solver,
//! its checks, its conversion back to a problem, its slacks and objective, and its
//! standard form.

use anyhow::{ensure, Result};
use firmware::mpc::{MpcQpProblem, NC, NV};
use firmware::Real;
use serde::{Deserialize, Serialize};

use crate::qp_corpus::standard::StandardQp;

/// The QP in our solver's own form (see [`crate::qp_corpus`]'s docs): `min ½xᵀHx + fᵀx + Σ ½ρ_i s_i²`
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

    /// The equivalent standard form (see [`crate::qp_corpus`]'s docs): variables `[x; s]`, bounds as
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
