//! Unit tests of the solver's internals: the factors, the bound rows, the
//! working-set factor updates.

#![allow(clippy::unwrap_used, clippy::panic)]
use crate::cholesky::{factor_h, inverse_row, solve_upper, transform};
use crate::factor::AppendError;
use crate::rows::{con_row, row_start};
use crate::{ldl_len, ActiveConstraint, ConstraintIndex, QpSettings, QpSolver, Side};

type S = QpSolver<f64, 5, 8, 8, { ldl_len(8) }>;

/// Deterministic pseudo-random numbers in [-1, 1).
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

fn filled(seed: u64) -> S {
    let mut s = S::new();
    let mut st = seed;
    let p = s.problem_mut();
    let mut g = [[0.0; 5]; 5];
    for r in g.iter_mut() {
        for v in r.iter_mut() {
            *v = lcg(&mut st);
        }
    }
    for r in 0..5 {
        for c in 0..5 {
            p.h[r][c] =
                (0..5).map(|k| g[k][r] * g[k][c]).sum::<f64>() + if r == c { 0.3 } else { 0.0 };
        }
        p.f[r] = lcg(&mut st);
        p.x_lo[r] = -1.0;
        p.x_hi[r] = 1.0;
    }
    for i in 0..8 {
        let mut a = [0.0; 5];
        for v in a.iter_mut() {
            *v = lcg(&mut st);
        }
        let soft = if i % 3 == 0 { 2.0 + lcg(&mut st) } else { 0.0 };
        p.push_row(&a, -1.0, 1.0, soft);
    }
    s
}

#[test]
fn cholesky_and_triangular_solves_invert_h() {
    let mut s = filled(3);
    let h = s.problem.h;
    assert!(factor_h(&mut s.problem.h));
    let r = &s.problem.h;
    // The rows of R⁻¹ from the forward solve: H · R⁻¹ R⁻ᵀ = I.
    let mut ri = [[0.0; 5]; 5];
    for (j, row) in ri.iter_mut().enumerate() {
        inverse_row(r, j, row);
    }
    // Back substitution: R⁻¹ e_j is column j of R⁻¹.
    for j in 0..5 {
        let mut e = [0.0; 5];
        e[j] = 1.0;
        let mut col = [0.0; 5];
        solve_upper(r, &e, &mut col);
        for k in 0..5 {
            assert!((col[k] - ri[k][j]).abs() < 1e-12, "R⁻¹[{k}][{j}]");
        }
    }
    for r in 0..5 {
        for c in 0..5 {
            let mut v = 0.0;
            for k in 0..5 {
                let hk = if k >= r { h[r][k] } else { h[k][r] };
                let mut inv = 0.0;
                for q in 0..5 {
                    inv += ri[k][q] * ri[c][q];
                }
                v += hk * inv;
            }
            let want = if r == c { 1.0 } else { 0.0 };
            assert!((v - want).abs() < 1e-10, "({r},{c}) = {v}");
        }
    }
}

/// Every bound's row of `R⁻¹`, stored in the lower triangle of `h` next to `R`,
/// reads back as `e_jᵀ R⁻¹` (checked against `R⁻¹ e_k` by back substitution),
/// and the rows' products are those of `R⁻¹`'s rows.
#[test]
fn bound_rows_in_the_lower_triangle_are_rows_of_the_inverse() {
    let mut s = filled(5);
    assert!(factor_h(&mut s.problem.h));
    let r = s.problem.h;
    // Columns of R⁻¹ from the upper triangle alone, before any row is stored.
    let mut inv = [[0.0; 5]; 5];
    for k in 0..5 {
        let mut e = [0.0; 5];
        e[k] = 1.0;
        let mut col = [0.0; 5];
        solve_upper(&r, &e, &mut col);
        for j in 0..5 {
            inv[j][k] = col[j];
        }
    }
    transform(&mut s.problem, &mut s.work);
    // R itself is untouched.
    for j in 0..5 {
        for k in j..5 {
            assert_eq!(s.problem.h[j][k], r[j][k]);
        }
    }
    for j in 0..5u16 {
        let row = con_row(&s.problem, &s.work.rinv, ConstraintIndex::Bound(j));
        assert_eq!(row.start, j as usize);
        let mut full = [0.0; 5];
        full[row.start] = row.head;
        full[row.start + 1..].copy_from_slice(row.tail);
        for k in 0..5 {
            assert!(
                (full[k] - inv[j as usize][k]).abs() < 1e-12,
                "R⁻¹[{j}][{k}]"
            );
        }
        for i in 0..5u16 {
            let want: f64 = (0..5)
                .map(|k| inv[i as usize][k] * inv[j as usize][k])
                .sum();
            let got = con_row(&s.problem, &s.work.rinv, ConstraintIndex::Bound(i)).dot_row::<5>(
                &con_row(&s.problem, &s.work.rinv, ConstraintIndex::Bound(j)),
            );
            assert!((got - want).abs() < 1e-12, "({i}, {j})");
        }
    }
}

/// Removing an entry by downdate gives the same factor as factorising the
/// remaining working set from scratch, and the kept `y = L⁻¹(−d_W)` and
/// `ℓ = D⁻¹y` (updated as the last row of the bordered factor) are those of a
/// forward substitution on it, to rounding.
#[test]
fn remove_matches_refactor() {
    use crate::rows::held_bound;
    for seed in 0..20u64 {
        let mut s = filled(seed);
        assert!(factor_h(&mut s.problem.h));
        transform(&mut s.problem, &mut s.work);
        let tols = QpSettings::<f64>::new(10).effective();
        let set = [
            ConstraintIndex::Row(0),
            ConstraintIndex::Bound(1),
            ConstraintIndex::Row(3),
            ConstraintIndex::Row(4),
            ConstraintIndex::Bound(3),
            ConstraintIndex::Row(6),
            ConstraintIndex::Row(2),
        ];
        for &c in &set {
            let e = ActiveConstraint {
                index: c,
                side: Side::Upper,
            };
            s.work.append(&s.problem, e, tols).unwrap();
        }
        for pos in [2usize, 0, 4] {
            s.work.remove(pos);
            let n = s.work.n;
            let down = s.work.ldl;
            let (y_down, l_down) = (s.work.y, s.work.ly);
            // A forward substitution from scratch on the downdated factor.
            let mut y = [0.0; 8];
            for r in 0..n {
                let e = s.work.ws[r];
                let d = held_bound(&s.problem, e)
                    + con_row(&s.problem, &s.work.rinv, e.index).dot(&s.work.v);
                let mut acc = -d;
                for l in 0..r {
                    acc -= down[row_start(r) + l] * y[l];
                }
                y[r] = acc;
            }
            for r in 0..n {
                let tol = 1e-12 * (1.0 + y[r].abs());
                assert!(
                    (y_down[r] - y[r]).abs() < tol,
                    "seed {seed} pos {pos} r {r}"
                );
                let dr = down[row_start(r) + r];
                assert!(
                    (l_down[r] - y[r] / dr).abs() < 1e-12 * (1.0 + (y[r] / dr).abs()),
                    "seed {seed} pos {pos} r {r}"
                );
            }
            let dropped = s.work.rebuild(&s.problem, tols, n);
            assert_eq!(dropped, 0);
            assert_eq!(s.work.n, n);
            for k in 0..ldl_len(n) {
                assert!(
                    (down[k] - s.work.ldl[k]).abs() < 1e-10,
                    "seed {seed} pos {pos} k {k}"
                );
            }
            for r in 0..n {
                assert!(
                    (y_down[r] - s.work.y[r]).abs() < 1e-9 * (1.0 + y[r].abs()),
                    "seed {seed} pos {pos} r {r}"
                );
            }
        }
    }
}

#[test]
fn dependent_rows_are_refused_by_append() {
    let mut s = filled(1);
    let a0 = s.problem.a[0];
    s.problem.a[1] = a0;
    s.problem.soft[0] = 0.0;
    s.problem.soft[1] = 0.0;
    assert!(factor_h(&mut s.problem.h));
    transform(&mut s.problem, &mut s.work);
    let tols = QpSettings::<f64>::new(10).effective();
    let e = |i| ActiveConstraint {
        index: ConstraintIndex::Row(i),
        side: Side::Upper,
    };
    assert_eq!(s.work.append(&s.problem, e(0), tols), Ok(()));
    assert_eq!(
        s.work.append(&s.problem, e(1), tols),
        Err(AppendError::Singular)
    );
    // A soft copy is not dependent: its pivot is at least 1/ρ.
    s.problem.soft[1] = 4.0;
    assert_eq!(s.work.append(&s.problem, e(1), tols), Ok(()));
    assert!((s.work.ldl[row_start(1) + 1] - 0.25).abs() < 1e-12);
}

/// A row `append` refuses stays pending below the working set; each removal
/// updates it as the factor's own rows, so that its entries and pivot are those
/// of appending it afresh to what is left (to rounding), and it stays singular
/// while what it depends on is still there.
#[test]
fn removals_update_a_pending_row_as_a_fresh_append() {
    for seed in 0..20u64 {
        let mut s = filled(seed);
        // Row 5 = 0.7·row 0 − 1.3·row 3, all three hard.
        let (a0, a3) = (s.problem.a[0], s.problem.a[3]);
        for j in 0..5 {
            s.problem.a[5][j] = 0.7 * a0[j] - 1.3 * a3[j];
        }
        for i in [0, 3, 5] {
            s.problem.soft[i] = 0.0;
        }
        assert!(factor_h(&mut s.problem.h));
        transform(&mut s.problem, &mut s.work);
        let tols = QpSettings::<f64>::new(10).effective();
        let e = |c| ActiveConstraint {
            index: c,
            side: Side::Upper,
        };
        let mut fresh = s.clone();
        let set = [
            ConstraintIndex::Row(0),
            ConstraintIndex::Bound(1),
            ConstraintIndex::Row(3),
            ConstraintIndex::Row(4),
        ];
        for &c in &set {
            s.work.append(&s.problem, e(c), tols).unwrap();
        }
        let new = e(ConstraintIndex::Row(5));
        assert_eq!(
            s.work.append(&s.problem, new, tols),
            Err(AppendError::Singular)
        );
        assert!(s.work.pending);
        // Removing the bound, which the row does not depend on: still singular.
        s.work.remove(1);
        assert!(s.work.pending);
        let n = s.work.n;
        assert!(s.work.ldl[row_start(n) + n].abs() < 1e-9 * s.work.pending_diag);
        // Removing row 3: the pending row's entries and pivot are a fresh append's.
        s.work.remove(1);
        let n = s.work.n;
        for &c in &[ConstraintIndex::Row(0), ConstraintIndex::Row(4)] {
            fresh.work.append(&fresh.problem, e(c), tols).unwrap();
        }
        assert_eq!(fresh.work.append(&fresh.problem, new, tols), Ok(()));
        let r = row_start(n);
        for k in r..=r + n {
            assert!(
                (s.work.ldl[k] - fresh.work.ldl[k]).abs() < 1e-10 * (1.0 + fresh.work.ldl[k].abs()),
                "seed {seed} k {k}: {} against {}",
                s.work.ldl[k],
                fresh.work.ldl[k]
            );
        }
        assert!(s.work.ldl[r + n] > tols.pivot * s.work.pending_diag);
        assert!((s.work.last_rel_pivot - fresh.work.last_rel_pivot).abs() < 1e-10);
        // Committed, it is the working set's last row with its forward entry.
        s.work.commit(&s.problem, new);
        assert!(!s.work.pending);
        assert_eq!(s.work.n, n + 1);
        assert!((s.work.y[n] - fresh.work.y[n]).abs() < 1e-9 * (1.0 + fresh.work.y[n].abs()));
    }
}

/// The unrolled kernels give their loops' results bit for bit: `dot_groups` is
/// `dot4` over all entries, or over a prefix of whole groups of a row that is zero
/// after it; `dot4_unrolled` is `dot4`; `sub_products` is a loop of `acc -= a·b`.
#[test]
fn unrolled_kernels_are_their_loops_bit_for_bit() {
    use crate::rows::{dot4, dot4_unrolled, dot_groups, sub_products};
    let mut st = 7u64;
    for _ in 0..200 {
        let mut a = [0.0f32; 11];
        let mut b = [0.0f32; 11];
        for (x, y) in a.iter_mut().zip(b.iter_mut()) {
            *x = lcg(&mut st) as f32 * 1e3;
            *y = lcg(&mut st) as f32;
        }
        // All entries, the remainder of 11 included.
        assert_eq!(
            dot_groups(&a, &b, 2, true).to_bits(),
            dot4(&a, &b).to_bits()
        );
        // A row zero after its first g groups.
        for g in 0..=2 {
            let mut z = a;
            z[4 * g..].fill(0.0);
            assert_eq!(
                dot_groups(&z, &b, g, false).to_bits(),
                dot4(&z, &b).to_bits()
            );
        }
        // Every length up to 4·2 + 3 (two groups and a remainder of three).
        for len in 0..=11 {
            assert_eq!(
                dot4_unrolled(&a[..len], &b[..len], 2).to_bits(),
                dot4(&a[..len], &b[..len]).to_bits()
            );
        }
        for len in 0..=11 {
            let acc0 = lcg(&mut st) as f32;
            let mut acc = acc0;
            for k in 0..len {
                acc -= a[k] * b[k];
            }
            assert_eq!(
                sub_products(acc0, &a[..len], &b[..len]).to_bits(),
                acc.to_bits()
            );
        }
    }
}

/// `store_inverse_row` writes row `j` of `R⁻¹` into the lower triangle bit for bit
/// as `inverse_row` computes it, for every `j` of an 11 × 11 `R` (groups of four
/// and remainders), and leaves the upper triangle (`R`) as it was.
#[test]
fn store_inverse_row_is_inverse_row() {
    const N: usize = 11;
    let mut st = 11u64;
    for _ in 0..50 {
        let mut r = [[0.0f32; N]; N];
        for (i, row) in r.iter_mut().enumerate() {
            for (k, x) in row.iter_mut().enumerate().skip(i) {
                *x = if k == i {
                    0.5 + lcg(&mut st).abs() as f32
                } else {
                    lcg(&mut st) as f32
                };
            }
        }
        let mut h = r;
        for j in 0..N {
            crate::cholesky::store_inverse_row(&mut h, j);
        }
        for j in 0..N {
            let mut want = [0.0f32; N];
            inverse_row(&r, j, &mut want);
            for l in j + 1..N {
                assert_eq!(h[N - 1 - j][l - j - 1].to_bits(), want[l].to_bits());
            }
        }
        for i in 0..N {
            for k in i..N {
                assert_eq!(h[i][k].to_bits(), r[i][k].to_bits());
            }
        }
    }
}
