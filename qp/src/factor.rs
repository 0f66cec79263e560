//! The working set and the `LDLᵀ` factor of its matrix `M̃_W M̃_Wᵀ + D_W`: a
//! constraint is appended (a new row of the factor) or removed (a row and column
//! deleted, a rank-one update of the trailing block), the factor is rebuilt from
//! scratch when rounding spoiled it, and the system is solved with it.

use crate::cholesky::{solve_transposed, store_inverse_row};
use crate::rows::{bounds_of, con_row, delta, held_bound, row_start, sub_products, sub_scaled};
use crate::settings::Tols;
use crate::{ActiveConstraint, ConstraintIndex, QpProblem, QpSettings, Real, Side};

/// Solver workspace: the working set, its factor and per-constraint flags.
#[derive(Clone, Debug)]
pub(crate) struct Workspace<T, const N: usize, const M: usize, const W: usize, const WL: usize> {
    /// Working set entries `0..n`.
    pub(crate) ws: [ActiveConstraint; W],
    /// Entries in use, `≤ W` (`commit` refuses at `W`, `set_working_set_from` keeps at
    /// most `W`, `rebuild` starts from 0): it bounds every loop over the working set.
    pub(crate) n: usize,
    /// Current (dual-feasible) multipliers of the working set (`W`).
    pub(crate) lam: [T; W],
    /// `y = L⁻¹(−d_W)` (`W`), `d_k = b_k + m̃_kᵀv`: the forward substitution of
    /// `λ*`'s system (its right-hand side `−d_W` is constant over a solve: `v`, the
    /// held bounds and the transformed rows do not change), kept with the factor.
    /// `commit` computes the new entry's from `d` and the entries above it, as a
    /// forward substitution does.
    pub(crate) y: [T; W],
    /// `ℓ = D⁻¹y` (`W`): the last row of the factor of the working-set matrix
    /// bordered by `−d_W`, so that each iteration solves only `Lᵀλ* = ℓ`. `commit`
    /// divides the new entry of `y` by its pivot; `remove` updates `ℓ` as the
    /// factor's own rows (the rank-one update of the bordered matrix), in `O(n)`,
    /// and sets `y = Dℓ` for the entries it changed.
    pub(crate) ly: [T; W],
    /// Scratch (`W`): the rank-one update's `β_j` per column, in `remove`.
    pub(crate) beta: [T; W],
    /// Scratch (`W`): right-hand side then `λ*` of the working-set system, rank-one
    /// vectors, null-space direction.
    pub(crate) tmp: [T; W],
    /// Packed `LDLᵀ` of the working-set matrix: row `r` at `r(r+1)/2`, holding
    /// `L[r][0..r]` then `D[r]`.
    pub(crate) ldl: [T; WL],
    /// `v = R⁻ᵀ f` (`N`).
    pub(crate) v: [T; N],
    /// `u = R x` (`N`).
    pub(crate) u: [T; N],
    /// `1/R_jj` once bound `j`'s row `e_jᵀ R⁻¹` is stored in this solve, its first
    /// nonzero entry; 0 before (`N`, 1/m of the variable's units: a finite `R_jj`
    /// has a nonzero inverse). `R` itself is kept, not inverted, and a bound's row
    /// is computed when it enters the working set, into the lower triangle of `h`
    /// (see [`store_inverse_row`]).
    pub(crate) rinv: [T; N],
    /// Side at which each row is active (`M`).
    pub(crate) row_state: [Option<Side>; M],
    /// Side at which each bound is active (`N`).
    pub(crate) bound_state: [Option<Side>; N],
    /// Appends since the last from-scratch factorisation.
    pub(crate) updates: u32,
    /// Pivot of the last `append` relative to its diagonal entry (of the pending
    /// row, once a removal has updated it).
    pub(crate) last_rel_pivot: T,
    /// Row `n` of [`Self::ldl`] holds a constraint whose pivot `append` found too
    /// small (it depends on the working set): it is not in the working set, but
    /// each `remove` updates it with the rows below the removed one, so that it
    /// enters, once its pivot has grown, without its row being formed again.
    pub(crate) pending: bool,
    /// The pending row's diagonal entry `m̃ᵀm̃ + δ`, for its relative pivot.
    pub(crate) pending_diag: T,
    /// Per row (`M`, one byte to keep the solver small): [`ROW_TRANSFORMED`] once
    /// the row holds `a_i R⁻¹` in this solve (rows are transformed only when they
    /// enter the working set); otherwise the length of its prefix that can be
    /// nonzero, in groups of four entries (its last nonzero entry rounded up to the
    /// four-sum groups of [`dot_groups`](crate::rows::dot_groups), so that a dot product over the prefix gives
    /// the same result as over all `N` entries), or [`ROW_FULL`].
    pub(crate) row_code: [u8; M],
}

/// [`Workspace::row_code`] of a row that holds `a_i R⁻¹`.
pub(crate) const ROW_TRANSFORMED: u8 = 0xFF;
/// [`Workspace::row_code`] of an untransformed row used over all `N` entries.
pub(crate) const ROW_FULL: u8 = 0xFE;

/// Why a constraint could not enter the working set.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum AppendError {
    /// It depends linearly on the working set (relative pivot below the tolerance).
    Singular,
    /// The working set already holds `W` constraints.
    Full,
}

impl<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize>
    Workspace<T, N, M, W, WL>
{
    pub(crate) fn state_mut(&mut self, c: ConstraintIndex) -> Option<&mut Option<Side>> {
        match c {
            ConstraintIndex::Bound(j) => self.bound_state.get_mut(j as usize),
            ConstraintIndex::Row(i) => self.row_state.get_mut(i as usize),
        }
    }

    /// Whether entry `e` may be in the working set of problem `p` (in range, bound of
    /// its side finite, not already active).
    pub(crate) fn admissible(&self, p: &QpProblem<T, N, M>, e: ActiveConstraint) -> bool {
        let (in_range, active) = match e.index {
            ConstraintIndex::Bound(j) => {
                let j = j as usize;
                (j < N, self.bound_state.get(j).is_some_and(|s| s.is_some()))
            }
            ConstraintIndex::Row(i) => {
                let i = i as usize;
                (
                    i < p.m && i < M,
                    self.row_state.get(i).is_some_and(|s| s.is_some()),
                )
            }
        };
        if !in_range || active {
            return false;
        }
        let (lo, hi) = bounds_of(p, e.index);
        match e.side {
            Side::Lower => lo.is_finite(),
            Side::Upper => hi.is_finite(),
        }
    }

    /// Starts a solve: clears the flags and (warm start) re-activates the given
    /// working set with `λ = 0`, its entries transformed two at a time
    /// ([`Self::prepare_pair`]), then factored, dropping inadmissible or dependent
    /// entries; returns how many it dropped (each an iteration against the cap:
    /// module `active_set`, *Counts*).
    pub(crate) fn start(
        &mut self,
        p: &mut QpProblem<T, N, M>,
        settings: &QpSettings<T>,
        tols: Tols<T>,
    ) -> u32 {
        let count = if settings.warm_start {
            self.n.min(W)
        } else {
            0
        };
        self.rinv.fill(T::ZERO);
        // Pairs of warm entries (`count ≤ W`).
        // wcet-bound: WS / 2
        for r in (0..count).step_by(2) {
            // A pair of warm entries, with the appends of the activation's
            // iterations: each append beyond the working set's capacity needs an
            // iteration that removes, so twice the appends plus the warm entries
            // are at most `K + 2R + P·W`, and the appends (first attempts and
            // retries) plus the pairs at most half of `K + 3R + P·W`, rounded up
            // (module `active_set`, *Counts*).
            // wcet-bound: (QP_MAX_ITER + 3 * QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS + 1) / 2 times per activation, counted in balance
            self.prepare_pair(p, r, count);
        }
        let dropped = self.rebuild(p, tols, count);
        self.lam.fill(T::ZERO);
        dropped as u32
    }

    /// [`Self::prepare`] of warm entries `r` and `r + 1` (those below `count`).
    /// Not inlined: its calls are counted per activation.
    #[inline(never)]
    fn prepare_pair(&mut self, p: &mut QpProblem<T, N, M>, r: usize, count: usize) {
        // wcet-bound: 2
        for k in r..(r + 2).min(count) {
            self.prepare(p, self.ws[k].index);
        }
    }

    /// Transforms row constraint `c` to `a_iᵀ R⁻¹` in place, or computes bound `c`'s
    /// row `e_jᵀ R⁻¹` into the lower triangle of `h` ([`store_inverse_row`]), unless
    /// already done in this
    /// solve. Only constraints that enter the working set are ever transformed: the
    /// others are checked as `a_iᵀ x` or `x_j`. Not inlined: its calls are counted
    /// per activation (one call, whatever its paths call).
    #[inline(never)]
    pub(crate) fn prepare(&mut self, p: &mut QpProblem<T, N, M>, c: ConstraintIndex) {
        let i = match c {
            ConstraintIndex::Row(i) => i as usize,
            ConstraintIndex::Bound(j) => {
                let j = j as usize;
                if let Some(inv) = self.rinv.get_mut(j) {
                    if *inv == T::ZERO {
                        store_inverse_row(&mut p.h, j);
                        *inv = T::ONE / p.h[j][j];
                    }
                }
                return;
            }
        };
        if i >= p.m {
            return;
        }
        let (Some(code), Some(row)) = (self.row_code.get_mut(i), p.a.get_mut(i)) else {
            return;
        };
        if *code != ROW_TRANSFORMED {
            // Once per row and solve (`validate` writes every used row's code at
            // the solve's start): at most NC per solve, over the MPC's solves.
            // wcet-bound: COLD_START_PASSES * NC times per activation
            solve_transposed(&p.h, row, 0);
            *code = ROW_TRANSFORMED;
        }
    }

    /// Rebuilds the factor from entries `ws[0..count]` (and their `lam`), dropping
    /// inadmissible and linearly dependent entries. Returns how many were dropped.
    #[inline(never)]
    pub(crate) fn rebuild(&mut self, p: &QpProblem<T, N, M>, tols: Tols<T>, count: usize) -> usize {
        self.row_state.fill(None);
        self.bound_state.fill(None);
        self.n = 0;
        self.updates = 0;
        let mut dropped = 0;
        // wcet-bound: WS
        for r in 0..count.min(W) {
            let e = self.ws[r];
            let l = self.lam[r];
            if !self.admissible(p, e) {
                dropped += 1;
                continue;
            }
            let k = self.n;
            match self.append_row(p, e, tols) {
                Ok(()) => self.lam[k] = l,
                Err(_) => dropped += 1,
            }
        }
        self.updates = 0;
        self.pending = false;
        dropped
    }

    /// Appends constraint `e` as row `n` of the factor. On `Singular`, the row `n` of
    /// the packed storage holds `L_new = D⁻¹L⁻¹ M_{W,e}` and its pivot, `n` is
    /// unchanged and the row is [`Self::pending`].
    #[inline(never)]
    pub(crate) fn append(
        &mut self,
        p: &QpProblem<T, N, M>,
        e: ActiveConstraint,
        tols: Tols<T>,
    ) -> Result<(), AppendError> {
        #[cfg(test)]
        crate::work::tests::APPEND_ROWS.with(|c| c.set(c.get() + self.n.min(W - 1) as u64));
        self.append_row(p, e, tols)
    }

    /// [`Self::append`]'s work, inlined into `append` and into [`Self::rebuild`]:
    /// its loops run `n` times (the rows already in the factor), so over one
    /// rebuild, which appends rows one by one (`n` = 0, 1, ... below `W`), they are
    /// bounded by sums over `n`, which the annotations for its copy in `rebuild`
    /// state.
    #[inline(always)]
    fn append_row(
        &mut self,
        p: &QpProblem<T, N, M>,
        e: ActiveConstraint,
        tols: Tols<T>,
    ) -> Result<(), AppendError> {
        let n = self.n;
        if n >= W {
            return Err(AppendError::Full);
        }
        let s = row_start(n);
        let re = con_row(p, &self.rinv, e.index);
        // b_l = M_{l,e}. Over an activation, `append`'s loops over the rows run
        // at most the rows its appends can find (`qp::work`): QP_APPEND_ROWS.
        // wcet-bound: QP_APPEND_ROWS per activation
        // wcet-bound in rebuild: WS * (WS - 1) / 2 per call
        for l in 0..n {
            self.ldl[s + l] = con_row(p, &self.rinv, self.ws[l].index).dot_row::<N>(&re);
        }
        // Forward solve with the unit lower L: y = L⁻¹ b.
        // wcet-bound: QP_APPEND_ROWS per activation
        // wcet-bound in rebuild: WS * (WS - 1) / 2 per call
        for l in 0..n {
            let sl = row_start(l);
            let mut acc = self.ldl[s + l];
            // Row l of L against y[0..l], as slices (no index checks in the
            // loop); the same products in the same order.
            let (row, y) = (
                self.ldl.get(sl..sl + l).unwrap_or(&[]),
                self.ldl.get(s..s + l).unwrap_or(&[]),
            );
            acc = sub_products(acc, core::hint::black_box(row), y);
            self.ldl[s + l] = acc;
        }
        let diag = re.dot_row::<N>(&re) + delta(p, e.index);
        let mut dn = diag;
        // wcet-bound: QP_APPEND_ROWS per activation
        // wcet-bound in rebuild: WS * (WS - 1) / 2 per call
        for l in 0..n {
            let dl = self.ldl[row_start(l) + l];
            let y = self.ldl[s + l];
            let lv = y / dl;
            self.ldl[s + l] = lv;
            dn -= y * lv;
        }
        self.ldl[s + n] = dn;
        self.last_rel_pivot = dn / diag;
        if !(dn > tols.pivot * diag) || !dn.is_finite() {
            self.pending = true;
            self.pending_diag = diag;
            return Err(AppendError::Singular);
        }
        self.commit(p, e);
        Ok(())
    }

    /// Makes the row `n` written by `append` (or the pending row) part of the
    /// factor, with its entries of `y` and `ℓ`.
    pub(crate) fn commit(&mut self, p: &QpProblem<T, N, M>, e: ActiveConstraint) {
        let n = self.n;
        self.pending = false;
        if n >= W {
            return;
        }
        self.ws[n] = e;
        let d = held_bound(p, e) + con_row(p, &self.rinv, e.index).dot(&self.v);
        // Row n of the forward substitution `L y = −d_W`.
        let s = row_start(n);
        let yn = sub_products(
            -d,
            self.ldl.get(s..s + n).unwrap_or(&[]),
            self.y.get(..n).unwrap_or(&[]),
        );
        self.y[n] = yn;
        self.ly[n] = yn / self.ldl[s + n];
        if let Some(st) = self.state_mut(e.index) {
            *st = Some(e.side);
        }
        self.n = n + 1;
        self.updates += 1;
    }

    /// Removes working-set entry `p` (and its multiplier): deletes its row and column
    /// of `LDLᵀ` and updates the trailing block by a rank-one update. A
    /// [`pending`](Self::pending) row below the working set's is updated with the
    /// others (it stays pending, one row up), and its new relative pivot is left in
    /// [`Self::last_rel_pivot`].
    #[inline(never)]
    pub(crate) fn remove(&mut self, pos: usize) {
        let n = self.n;
        if pos >= n {
            return;
        }
        let e = self.ws[pos];
        if let Some(st) = self.state_mut(e.index) {
            *st = None;
        }
        // Rows of the packed storage below the removed one that move: the working
        // set's, and the pending row (row `n`, only when `n < W`).
        let rows = (n + usize::from(self.pending)).min(W);
        let mut alpha = self.ldl[row_start(pos) + pos];
        for r in pos..(n - 1) {
            self.ws[r] = self.ws[r + 1];
            // Bounds the `for r in pos..(n - 1)` loop (its back edge is on this line).
            self.lam[r] = self.lam[r + 1]; // wcet-bound: WS
        }
        let nn = n - 1;
        self.n = nn;
        // Each row below the removed one moves up a row (old row r + 1 is the new row
        // r: destinations precede sources, so rows are done in order), dropping
        // column pos: its entries before pos are copied, its entry at pos is `z_r`
        // (the removed column), and the trailing block (columns pos..r) takes the
        // rank-one update by alpha z zᵀ, row by row: each column j's `p_j` (z's
        // entry, kept in `tmp`) and `β_j` are final once its own row is done, so
        // row r takes its columns pos..r in order, each entry with the same
        // operations in the same order as column by column. A column with `p_j = 0`
        // changes nothing (`β_j = 0`: its entries get `−0·l` and `+0·acc`, which
        // leave finite values as they are) and keeps its `d_j` and `α`; the loop
        // has no branch. The pending row (`r = nn`) needs its entries and its pivot
        // only: it is no column of the working set's. `rows ≤ W` bounds the loops.
        // The storage from new row pos on: new row r is its first r + 1 entries, old
        // row r + 1 the r + 2 after them, and the next new row starts where that
        // old row did.
        let mut rest: &mut [T] = self.ldl.get_mut(row_start(pos)..).unwrap_or(&mut []);
        // wcet-bound: WS
        for r in pos..(rows - 1) {
            let at = (r + 1).min(rest.len());
            let (new, after) = core::mem::take(&mut rest).split_at_mut(at);
            let (Some(old), Some(ps), Some(bs)) = (
                after.get(..r + 2),
                self.tmp.get(pos..r),
                self.beta.get(pos..r),
            ) else {
                break;
            };
            let (new_head, new_tail) = new.split_at_mut(pos.min(r));
            let (old_head, old_tail) = old.split_at(pos.min(r));
            for (d, &v) in new_head.iter_mut().zip(old_head) {
                // pos entries of each of the rows below pos: below W²/4 per call.
                // wcet-bound: WS * WS / 4 per call
                *d = v;
            }
            // old_tail: z_r, the entries of columns pos + 1..=r, the pivot.
            let Some((&zr, old_rest)) = old_tail.split_first() else {
                break;
            };
            let dr = old_rest.get(r - pos).copied().unwrap_or(T::ZERO);
            let mut acc = zr;
            // The slices' addresses through `black_box`: one pointer each (as
            // offsets from the workspace's base, each load's address would be
            // formed anew).
            let (new_tail, old_rest, ps, bs) = (
                core::hint::black_box(new_tail),
                core::hint::black_box(old_rest),
                core::hint::black_box(ps),
                core::hint::black_box(bs),
            );
            for (((l, &o), &pj), &bj) in new_tail.iter_mut().zip(old_rest).zip(ps).zip(bs) {
                // Σ (r − pos) over pos ≤ r < rows − 1 < W per call.
                // wcet-bound: WS * (WS - 1) / 2 per call
                acc -= pj * o;
                *l = o + bj * acc;
            }
            let d_new = if r == nn || acc != T::ZERO {
                dr + alpha * acc * acc
            } else {
                dr
            };
            if let Some(d) = new.last_mut() {
                *d = d_new;
            }
            rest = after;
            self.tmp[r] = acc;
            if r == nn {
                self.last_rel_pivot = d_new / self.pending_diag;
                break;
            }
            if acc != T::ZERO {
                self.beta[r] = acc * alpha / d_new;
                alpha = dr * alpha / d_new;
            } else {
                self.beta[r] = T::ZERO;
            }
        }
        // The bordered matrix's last row, `ℓ`, takes the same update: its entry at
        // pos is its `z`, its entries pos + 1..n move one to the left. Then
        // `y = Dℓ` where they changed.
        let mut acc = self.ly[pos];
        // wcet-bound: WS
        for j in pos..nn {
            let o = self.ly[j + 1];
            acc -= self.tmp[j] * o;
            let l = o + self.beta[j] * acc;
            self.ly[j] = l;
            self.y[j] = l * self.ldl[row_start(j) + j];
        }
    }

    /// `λ*` for the current working set, into `tmp`: `D Lᵀ λ* = y` (the
    /// forward half is kept in [`Self::y`]); false if not finite. Not inlined: its
    /// loops stay out of the QP's main loop, whose bound is matched by its lines.
    #[inline(never)]
    pub(crate) fn solve_lam_star_tmp(&mut self) -> bool {
        let n = self.n.min(W);
        // `ℓ = D⁻¹y`, kept with the factor.
        // wcet-bound: WS
        for r in 0..n {
            self.tmp[r] = self.ly[r];
        }
        self.lt_solve_tmp();
        // `x·0` is ±0 for a finite `x`, NaN otherwise: the sum is 0 exactly when
        // every entry is finite (no branch per entry).
        let mut probe = T::ZERO;
        // wcet-bound: WS
        for &v in self.tmp.iter().take(n) {
            probe += v * T::ZERO;
        }
        probe == T::ZERO
    }

    /// Solves `(M_WW + D) x = tmp` in place in `tmp[0..n]`.
    #[inline(never)]
    pub(crate) fn ldl_solve_tmp(&mut self) {
        let n = self.n;
        // wcet-bound: WS
        for r in 0..n {
            let s = row_start(r);
            let mut acc = self.tmp[r];
            // Row r of the packed L against x[0..r], as slices (no index checks
            // in the loop); the same products in the same order.
            let l = self.ldl.get(s..s + r).unwrap_or(&[]);
            acc = sub_products(acc, l, self.tmp.get(..r).unwrap_or(&[]));
            self.tmp[r] = acc;
        }
        self.ldl_back_tmp();
    }

    /// Solves `D Lᵀ x = tmp` in place in `tmp[0..n]`: the second half of
    /// [`Self::ldl_solve_tmp`].
    #[inline(always)]
    fn ldl_back_tmp(&mut self) {
        let n = self.n.min(W);
        // wcet-bound: WS
        for r in 0..n {
            self.tmp[r] /= self.ldl[row_start(r) + r];
        }
        self.lt_solve_tmp();
    }

    /// Solves `Lᵀ x = tmp` in place in `tmp[0..n]`, by columns of `Lᵀ` (rows of the
    /// packed `L`, contiguous): once `x_r` is final, its share leaves the entries
    /// above it.
    #[inline(always)]
    fn lt_solve_tmp(&mut self) {
        let n = self.n.min(W);
        // wcet-bound: WS
        for r in (1..n).rev() {
            let xr = self.tmp[r];
            if xr == T::ZERO {
                continue;
            }
            let s = row_start(r);
            let (t, l) = (
                self.tmp.get_mut(..r).unwrap_or(&mut []),
                self.ldl.get(s..s + r).unwrap_or(&[]),
            );
            // `t` and `l` have the same length r; their addresses through
            // `black_box`, as pointers (offsets from the workspace's base are past
            // a load's immediate range: each load would form its address anew).
            sub_scaled(core::hint::black_box(t), xr, core::hint::black_box(l));
        }
    }
}
