//! The Hessian's factor `R` (`H = RᵀR`): Cholesky factorisation, the triangular
//! solves with `R` and `Rᵀ`, and the rows of `R⁻¹` the bounds use.

use crate::Real;
#[cfg(test)]
use crate::{factor::Workspace, QpProblem};

/// `h` holds an upper-triangular factor `R` (`H = RᵀR`): makes its diagonal
/// positive (a row's sign is free) and floors a pivot below `√ε·‖R_·j‖` as
/// [`factor_h_counted`] does. `None` for a zero or non-finite column.
pub(crate) fn prepare_factor<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> Option<u32> {
    let mut floored = 0u32;
    // wcet-bound: NV
    for j in 0..N {
        if h[j][j] < T::ZERO {
            // wcet-bound: NV
            for v in h[j].iter_mut().skip(j) {
                *v = -*v;
            }
        }
        let mut col = T::ZERO;
        // wcet-bound: NV
        for i in 0..=j {
            col += h[i][j] * h[i][j];
        }
        let norm = col.sqrt();
        if !(norm > T::ZERO) || !norm.is_finite() {
            return None;
        }
        let floor = T::EPSILON.sqrt() * norm;
        if !(h[j][j] > floor) {
            h[j][j] = floor;
            floored += 1;
        }
    }
    Some(floored)
}

/// Cholesky `H = RᵀR` in the upper triangle (the lower triangle keeps `H`'s, never
/// read). False if a pivot is not clearly positive.
#[cfg(test)]
pub(crate) fn factor_h<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> bool {
    factor_h_counted(h).is_some()
}

/// Cholesky `H = RᵀR` in the upper triangle, returning how many pivots were floored
/// (see below), `None` when `H` is not positive definite.
///
/// A pivot that comes out below `√ε·H_jj` but above `−0.1·H_jj` is taken for
/// rounding on a nearly singular (positive semidefinite in exact arithmetic)
/// Hessian, as a condensed MPC Hessian in single precision can be (its eigenvalues
/// span more than `1/ε_f32`): it is floored to `√ε·H_jj`, which factors `H + E`
/// with a small diagonal `E` (a proximal term of relative size `√ε`, 3·10⁻⁴ in
/// `f32`) in the direction that rounding left undetermined. A pivot below
/// `−0.1·H_jj` is a Hessian that is not convex: `None`.
#[inline(never)]
pub(crate) fn factor_h_counted<T: Real, const N: usize>(h: &mut [[T; N]; N]) -> Option<u32> {
    let tiny = T::EPSILON * T::from_usize(N);
    let mut floored = 0u32;
    // wcet-bound: NV
    for j in 0..N {
        // Column j of R: R[k][j] for k ≤ j, from H[k][j] (upper triangle).
        let mut d = h[j][j];
        let scale = d.abs();
        // Σ j over j < N per call (not inlined).
        // wcet-bound: NV * (NV - 1) / 2 per call
        for k in 0..j {
            d -= h[k][j] * h[k][j];
        }
        if !d.is_finite() || !(scale > T::ZERO) {
            return None;
        }
        if !(d > tiny * scale) {
            let floor = T::EPSILON.sqrt() * scale;
            if d < -T::lit(0.1) * scale {
                return None;
            }
            d = floor;
            floored += 1;
        }
        let rjj = d.sqrt();
        h[j][j] = rjj;
        // Σ (N − 1 − j) over j < N per call.
        // wcet-bound: NV * (NV - 1) / 2 per call
        for i in (j + 1)..N {
            let mut s = h[j][i];
            // Σ j·(N − 1 − j) over j < N ≤ N³/6 per call.
            // wcet-bound: NV * NV * NV / 6 per call
            for k in 0..j {
                s -= h[k][j] * h[k][i];
            }
            h[j][i] = s / rjj;
        }
    }
    Some(floored)
}

/// `x ← x R⁻¹` in place for the upper-triangular `R` (upper triangle of `r`, positive
/// diagonal): solves `Rᵀ y = x` forwards, `y_j = (x_j − Σ_{k<j} y_k R_kj) / R_jj`.
/// The entries of `x` before `start` must be zero (they stay zero). Row `axpy`s:
/// once `y_j` is final, its share leaves the later entries (contiguous, like the
/// rows of `R`); zero entries skipped. Not inlined: its inner loop is bounded per
/// call (a triangle).
#[inline(never)]
pub(crate) fn solve_transposed<T: Real, const N: usize>(
    r: &[[T; N]; N],
    x: &mut [T; N],
    start: usize,
) {
    // wcet-bound: NV
    for j in start..N {
        // Σ_{start≤k<j} y_k R_kj in four partial sums, as `dot4` groups them.
        let mut acc = [T::ZERO; 4];
        let mut k = start;
        // k steps by 4 from `start` to at most j < N: ⌊(j − start)/4⌋ passes, then
        // j − k ≤ 3; over the call Σ_{j<N} j/4 = N(N − 1)/8 at most.
        // wcet-bound: NV * (NV - 1) / 8 per call
        while k + 4 <= j {
            for (q, a) in acc.iter_mut().enumerate() {
                *a += x[k + q] * r[k + q][j];
            }
            k += 4;
        }
        let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
        // wcet-bound: 3
        while k < j {
            s += x[k] * r[k][j];
            k += 1;
        }
        x[j] = (x[j] - s) / r[j][j];
    }
}

/// `x = R⁻¹ u` for the upper-triangular `R` (upper triangle of `r`, positive
/// diagonal), by back substitution `x_j = (u_j − Σ_{k>j} R_jk x_k) / R_jj` (each sum
/// a contiguous dot product over row `j` of `R`).
pub(crate) fn solve_upper<T: Real, const N: usize>(r: &[[T; N]; N], u: &[T; N], x: &mut [T; N]) {
    // wcet-bound: NV
    for j in (0..N).rev() {
        // `dot_from(&r[j], x, j + 1)`: the same sums, in a loop that stays rolled
        // (its slices through `black_box`), so that its bound is the triangle's,
        // not `N/4` groups for every row.
        let (a, b) = (
            core::hint::black_box(r[j].get(j + 1..).unwrap_or(&[])),
            core::hint::black_box(x.get(j + 1..).unwrap_or(&[])),
        );
        let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
        let (ra, rb) = (ca.remainder(), cb.remainder());
        let mut acc = [T::ZERO; 4];
        // Σ (N − 1 − j)/4 over the rows j < N: N(N − 1)/8 per call of `primal`,
        // which inlines this and calls it once.
        // wcet-bound: NV / 4
        // wcet-bound in primal: NV * (NV - 1) / 8 per call
        for (x4, y4) in ca.zip(cb) {
            for ((s, &p), &q) in acc.iter_mut().zip(x4).zip(y4) {
                *s += p * q;
            }
        }
        let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
        let mut rest = ra.iter().zip(rb);
        if let Some((&p, &q)) = rest.next() {
            s += p * q;
            if let Some((&p, &q)) = rest.next() {
                s += p * q;
                if let Some((&p, &q)) = rest.next() {
                    s += p * q;
                }
            }
        }
        x[j] = (u[j] - s) / r[j][j];
    }
}

/// Row `j` of `R⁻¹` (`e_jᵀ R⁻¹`, zero before column `j`) into `out`: the tests'
/// reference for [`store_inverse_row`].
#[cfg(test)]
pub(crate) fn inverse_row<T: Real, const N: usize>(r: &[[T; N]; N], j: usize, out: &mut [T; N]) {
    out.fill(T::ZERO);
    if let Some(o) = out.get_mut(j) {
        *o = T::ONE;
        solve_transposed(r, out, j);
    }
}

/// `a_i ← a_iᵀ R⁻¹` for the used rows, `v = R⁻ᵀ f`, and every bound's row of
/// `R⁻¹` (the solver itself transforms a row or a bound only when it enters the
/// working set).
#[cfg(test)]
pub(crate) fn transform<
    T: Real,
    const N: usize,
    const M: usize,
    const W: usize,
    const WL: usize,
>(
    p: &mut QpProblem<T, N, M>,
    w: &mut Workspace<T, N, M, W, WL>,
) {
    for row in p.a.iter_mut().take(p.m) {
        solve_transposed(&p.h, row, 0);
    }
    w.v = p.f;
    solve_transposed(&p.h, &mut w.v, 0);
    for j in 0..N {
        store_inverse_row(&mut p.h, j);
        w.rinv[j] = T::ONE / p.h[j][j];
    }
}

/// Stores row `j` of `R⁻¹` (`e_jᵀ R⁻¹`: zero before column `j`, `1/R_jj` at `j`)
/// in the lower triangle of `h`, which holds `R` in its upper triangle: the `N−1−j`
/// entries after the diagonal go to `h[N−1−j][0..N−1−j]`, the lower part of row
/// `N−1−j`, exactly its length (so the rows of all `N` bounds fit at once). The
/// solve reads the upper triangle only. Not inlined: its loops' bounds are per
/// call.
#[inline(never)]
pub(crate) fn store_inverse_row<T: Real, const N: usize>(h: &mut [[T; N]; N], j: usize) {
    if j >= N {
        return;
    }
    // `solve_transposed` of `e_j` from `j`, written where the row is kept rather
    // than into a row of its own and copied (a frame of `N` entries and a `memcpy`
    // less on the plan task's deepest stack path): `x_j = 1/R_jj`, and `x_k` for
    // `k > j` at `h[dst][k − j − 1]`, the same sums in the same order, so bit for
    // bit `inverse_row`'s (the test `store_inverse_row_is_inverse_row`).
    let dst = N - 1 - j;
    let xj = (T::ONE - T::ZERO) / h[j][j];
    // A bound's row is stored once per solve (`Workspace::prepare`: only while its
    // `rinv` is 0, which `start` sets and the row's `1/R_jj` ends), so over the
    // MPC's solves of one activation the rows of all `N` bounds at most, each
    // `N − 1 − j` entries after its diagonal: `N(N − 1)/2` per solve.
    // wcet-bound: COLD_START_PASSES * NV * (NV - 1) / 2 per activation
    for l in j + 1..N {
        let mut acc = [T::ZERO; 4];
        let mut k = j;
        // The first group apart (it holds `x_j`), so that the others read `x` from
        // the kept row without a test.
        if k + 4 <= l {
            acc[0] += xj * h[j][l];
            for q in 1..4 {
                acc[q] += h[dst][q - 1] * h[j + q][l];
            }
            k += 4;
        }
        // As `solve_transposed`'s: Σ_{l<N} (l − j)/4 ≤ N(N − 1)/8 over the call;
        // over the rows of all N bounds, once each per solve (above),
        // Σ_j Σ_{l>j} (l − j)/4 = N(N² − 1)/24.
        // wcet-bound: COLD_START_PASSES * NV * (NV * NV - 1) / 24 per activation
        while k + 4 <= l {
            for (q, a) in acc.iter_mut().enumerate() {
                *a += h[dst][k + q - j - 1] * h[k + q][l];
            }
            k += 4;
        }
        let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
        // wcet-bound: 3
        while k < l {
            let x = if k == j { xj } else { h[dst][k - j - 1] };
            s += x * h[k][l];
            k += 1;
        }
        h[dst][l - j - 1] = (T::ZERO - s) / h[l][l];
    }
}
