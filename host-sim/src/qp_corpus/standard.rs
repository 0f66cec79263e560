//! The QP in standard form ([`StandardQp`], what other solvers take) and in the
//! conic form of interior-point solvers ([`ConicQp`]).

use serde::{Deserialize, Serialize};

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
