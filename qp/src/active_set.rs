//! The dual active-set iteration: multipliers of the working set, the step to the
//! first blocking multiplier and its removal, the most violated constraint and its
//! addition (with the null-space swap of a dependent one), the final refinement and
//! the output of the solution.
//!
//! # Counts
//!
//! Every iteration does at most one of: an append (`append`'s first attempt: the
//! row enters, or stays pending when it depends on the working set), a removal
//! (a blocking multiplier's, or a null-space step's, which may also let the
//! pending row enter), or the end of the solve (a refactorization may follow a
//! failed check of optimality). A refactorization may append once more (the
//! retry of a pending row). The entries a refactorization or the warm start
//! drops count as iterations. With `K` the iteration cap, `R` the
//! refactorization cap and `P` the solves (the MPC's passes) sharing them, `A`
//! appends, `Rm` removals, `n_s` warm entries and `D` drops:
//!
//! * `A + Rm + D ≤ K + R`: the appends beyond their iterations are the retries;
//! * per solve, the entries plus the pending row, `Φ ≤ W`, start at the warm
//!   entries kept, `n_s` less the start's drops, grow by one per append and
//!   shrink by one per removal (and by the drops and a discarded pending row),
//!   so `A ≤ W − n_s + Rm + D + R` and `Rm ≤ W + A`.
//!
//! Hence `2A + n_s ≤ K + 2R + P·W` and `Rm ≤ (K + R + P·W)/2`: a working set of
//! `W` entries is reached by `W` appends or warm entries, and each append past it
//! needs a removal, so at most about half of an activation's iterations append
//! and half remove, and a warm start takes its share of the appends. The
//! iterations that neither append nor remove end a solve or refactor: at most
//! `P + R`. The timing annotations cap the calls of `append` (with the
//! transformations and the warm entries: counted in `balance`), `remove`,
//! `primal` and `most_violated` so; the traces check them.

use crate::cholesky::solve_upper;
use crate::factor::{AppendError, Workspace, ROW_FULL, ROW_TRANSFORMED};
use crate::rows::{bounds_of, con_row, delta, dot_groups, held_bound, row_start, sign, sub_scaled};
use crate::settings::Tols;
use crate::{
    ActiveConstraint, ConstraintIndex, QpProblem, QpSettings, QpSolution, QpStatus, Real, Side,
};

impl<T: Real, const N: usize, const M: usize, const W: usize, const WL: usize>
    Workspace<T, N, M, W, WL>
{
    /// `λ*` for the current working set, into `tmp` (`−d_W` solved with the
    /// factor); false if not finite.
    pub(crate) fn solve_lam_star(&mut self) -> bool {
        self.solve_lam_star_tmp()
    }

    pub(crate) fn is_equality(p: &QpProblem<T, N, M>, c: ConstraintIndex) -> bool {
        let (lo, hi) = bounds_of(p, c);
        lo == hi
    }

    /// `u = −v − M̃_Wᵀ λ`, and `x = R⁻¹ u` into `x`. Not inlined: its calls are
    /// capped per activation.
    #[inline(never)]
    pub(crate) fn primal(&mut self, p: &QpProblem<T, N, M>, x: &mut [T; N]) {
        for (u, v) in self.u.iter_mut().zip(self.v.iter()) {
            *u = -*v;
        }
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k];
            if l == T::ZERO {
                continue;
            }
            let row = con_row(p, &self.rinv, self.ws[k].index);
            if let Some(u0) = self.u.get_mut(row.start) {
                *u0 -= l * row.head;
            }
            let u = self.u.get_mut(row.start + 1..).unwrap_or(&mut []);
            // `u` and the tail have the same length.
            sub_scaled(u, l, row.tail);
        }
        solve_upper(&p.h, &self.u, x);
    }

    /// Most violated inactive constraint (beyond `tol`), given `u` and `x`. `skip` is
    /// chosen only if no other constraint is violated (anti-cycling). Not inlined:
    /// its calls are capped per activation.
    #[inline(never)]
    pub(crate) fn most_violated(
        &self,
        p: &QpProblem<T, N, M>,
        x: &[T; N],
        tol: T,
        skip: Option<ConstraintIndex>,
    ) -> Option<ActiveConstraint> {
        // The largest violation beyond `tol` so far, of `cand` (its constraint and
        // value: the side follows from it at the end); `skip` only as a fallback.
        // A violation `max(lo − val, val − hi)` compared with the best (the common
        // case, nothing to do) is the only test of each inactive constraint.
        let mut best = tol;
        let mut cand: Option<(ConstraintIndex, T)> = None;
        let mut fallback: Option<(ConstraintIndex, T)> = None;
        let (skip_bound, skip_row) = match skip {
            Some(ConstraintIndex::Bound(j)) => (j as usize, usize::MAX),
            Some(ConstraintIndex::Row(i)) => (usize::MAX, i as usize),
            None => (usize::MAX, usize::MAX),
        };
        // The first violation above `best` at the skipped constraint sets the
        // fallback (once another is a candidate, `best > tol` and it is not used).
        let mut consider = |viol: T, val: T, index: ConstraintIndex, skipped: bool| {
            if viol > best {
                if skipped {
                    fallback = Some((index, val));
                } else {
                    best = viol;
                    cand = Some((index, val));
                }
            }
        };
        // `N` through `black_box`: a loop of a constant trip count would be unrolled,
        // and its annotation (source iterations) would bound the unrolled trips.
        let bounds = core::hint::black_box(N).min(N);
        // wcet-bound: NV
        for j in 0..bounds {
            if self.bound_state[j].is_none() {
                let val = x[j];
                let (dl, du) = (p.x_lo[j] - val, val - p.x_hi[j]);
                let viol = if dl > du { dl } else { du };
                consider(viol, val, ConstraintIndex::Bound(j as u16), j == skip_bound);
            }
        }
        // wcet-bound: NC
        for (i, a) in p.a.iter().enumerate().take(p.m) {
            if self.row_state[i].is_none() {
                // m̃_iᵀu once the row is transformed, else a_iᵀx (the same value),
                // over the row's nonzero prefix (its whole groups of four).
                let code = self.row_code[i];
                let (y, groups, rest) = if code == ROW_TRANSFORMED {
                    (&self.u, N / 4, true)
                } else if code == ROW_FULL {
                    (x, N / 4, true)
                } else {
                    (x, code as usize, false)
                };
                let val = dot_groups(core::hint::black_box(a), y, groups, rest);
                let (dl, du) = (p.lo[i] - val, val - p.hi[i]);
                let viol = if dl > du { dl } else { du };
                consider(viol, val, ConstraintIndex::Row(i as u16), i == skip_row);
            }
        }
        cand.or(fallback).map(|(index, val)| {
            let (lo, hi) = bounds_of(p, index);
            let side = if lo - val > val - hi {
                Side::Lower
            } else {
                Side::Upper
            };
            ActiveConstraint { index, side }
        })
    }

    /// Refactors from scratch (dropping dependent entries, and a pending row) and
    /// counts it: `Ok(false)`, and nothing done, once `max_refactorizations` were
    /// made in this solve. Each entry it drops counts as an iteration against the
    /// cap, as a removal does (`Err(IterationLimit)` when that passes the cap): the
    /// working set then shrinks only by counted iterations, which bounds the
    /// additions of a solve (module `active_set`, *Counts*).
    pub(crate) fn refactor(
        &mut self,
        p: &QpProblem<T, N, M>,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
        settings: &QpSettings<T>,
    ) -> Result<bool, QpStatus> {
        if sol.refactorizations >= settings.max_refactorizations {
            return Ok(false);
        }
        let n = self.n;
        // The MPC gives each pass what is left of the activation's
        // QP_MAX_REFACTORIZATIONS (firmware's mpc.rs `step_inner`).
        // wcet-bound: QP_MAX_REFACTORIZATIONS times per activation
        let dropped = self.rebuild(p, tols, n) as u32;
        sol.refactorizations += 1;
        sol.removed += dropped;
        sol.iterations = sol.iterations.saturating_add(dropped);
        if sol.iterations > settings.max_iter {
            return Err(QpStatus::IterationLimit);
        }
        Ok(true)
    }

    /// The main loop; returns the exit status (the solution is written by `output`).
    pub(crate) fn iterate(
        &mut self,
        p: &mut QpProblem<T, N, M>,
        settings: &QpSettings<T>,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
    ) -> QpStatus {
        // Anti-cycling: a constraint that left by a zero-length step (degenerate dual)
        // is re-added only if no other constraint is violated, until the next addition.
        let mut blocked: Option<ConstraintIndex> = None;
        let mut checked_refactor = false;
        loop {
            // One back edge per iteration, counted in `sol.iterations` ≤ `settings.max_iter`,
            // which the MPC (firmware's mpc.rs `step_inner`) sets to what is left of the activation's
            // `qp_max_iter` (QP_MAX_ITER on the ECU) after its earlier passes.
            // Its iterations and `add`'s null-space steps (below) each count one
            // against the same cap: one counter.
            // wcet-bound: QP_MAX_ITER per activation, counted in qp_iterations
            if sol.iterations >= settings.max_iter {
                return QpStatus::IterationLimit;
            }
            // The compiler splits this loop: a path that skips its head is a binary
            // loop of its own, nested in it; their back edges together are its
            // iterations.
            // wcet-bound: same loop
            sol.iterations += 1;
            if !self.solve_lam_star() {
                match self.refactor(p, tols, sol, settings) {
                    Ok(true) => {}
                    Ok(false) => return QpStatus::NumericalError,
                    Err(st) => return st,
                }
                if !self.solve_lam_star() {
                    return QpStatus::NumericalError;
                }
            }
            // Blocking multiplier on the way from λ to λ*.
            let mut block: Option<(usize, T)> = None;
            // wcet-bound: WS
            for k in 0..self.n {
                let e = self.ws[k];
                // One back edge per entry (no `continue`): the compiler keeps one
                // loop, bounded by `n ≤ W` above.
                let ls = if Self::is_equality(p, e.index) {
                    T::ZERO
                } else {
                    sign::<T>(e.side) * self.tmp[k]
                };
                if ls < -tols.dual {
                    let l = (sign::<T>(e.side) * self.lam[k]).max(T::ZERO);
                    let ratio = l / (l - ls);
                    if block.is_none_or(|(_, r)| ratio < r) {
                        block = Some((k, ratio));
                    }
                }
            }
            if let Some((pos, alpha)) = block {
                // wcet-bound: WS
                for k in 0..self.n {
                    let mut l = self.lam[k] + alpha * (self.tmp[k] - self.lam[k]);
                    let e = self.ws[k];
                    if !Self::is_equality(p, e.index) && sign::<T>(e.side) * l < T::ZERO {
                        l = T::ZERO;
                    }
                    self.lam[k] = l;
                }
                blocked = if alpha > T::ZERO {
                    None
                } else {
                    Some(self.ws[pos].index)
                };
                // A removal needs an entry added before it (or the start's), and
                // each takes an iteration: at most `(K + R + P·W)/2` per activation
                // (module `active_set`, *Counts*).
                // wcet-bound: (QP_MAX_ITER + QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS) / 2 times per activation, counted in removals
                self.remove(pos);
                sol.removed += 1;
                continue;
            }
            for k in 0..self.n {
                self.lam[k] = self.tmp[k];
            }
            // An iteration that removes nothing adds (one append, at most
            // `(K + 2R + P·W)/2` of them), or ends the pass, or refactors (module
            // `active_set`, *Counts*). The cap is on the block that makes this call,
            // which also calls `most_violated` (one cap per block).
            // wcet-bound: (QP_MAX_ITER + 2 * QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS) / 2 + COLD_START_PASSES + QP_MAX_REFACTORIZATIONS times per activation
            self.primal(p, &mut sol.x);
            let Some(e) = self.most_violated(p, &sol.x, tols.primal, blocked) else {
                // Optimal if the working set itself holds; if it does not, the factor is
                // inaccurate: refactor (which also drops dependent entries) once and go on.
                // The check allows 10× the primal tolerance: with 40+ active
                // constraints in f32 the factor's own rounding reaches ~10⁻³
                // relative, which is a converged optimum, not a wrong one.
                if self.working_set_holds(p, tols.primal * T::lit(10.0)) {
                    self.refine(p, &mut sol.x);
                    return QpStatus::Optimal;
                }
                if checked_refactor {
                    return QpStatus::NumericalError;
                }
                checked_refactor = true;
                match self.refactor(p, tols, sol, settings) {
                    Ok(true) => {}
                    Ok(false) => return QpStatus::NumericalError,
                    Err(st) => return st,
                }
                continue;
            };
            blocked = None;
            if let Err(st) = self.add(p, e, tols, sol, settings) {
                return st;
            }
        }
    }

    /// Adds the violated constraint `e`. If it depends linearly on the working set
    /// (its pivot too small: the row stays [`pending`](Workspace::pending)), moves
    /// `λ` along the dual null-space direction (which keeps `u` and raises the dual
    /// cost) until a multiplier reaches zero and removes that constraint, whose
    /// removal updates the pending row's pivot, until the row enters: each such
    /// step an iteration against `max_iter` (past it, `IterationLimit`); no
    /// multiplier reaching zero means infeasible.
    pub(crate) fn add(
        &mut self,
        p: &mut QpProblem<T, N, M>,
        e: ActiveConstraint,
        tols: Tols<T>,
        sol: &mut QpSolution<T, N, M>,
        settings: &QpSettings<T>,
    ) -> Result<(), QpStatus> {
        let max_iter = settings.max_iter;
        // One transformation per `add`, one `add` per main-loop iteration that
        // adds, and its first append (below, in the same block of the binary as
        // this call): counted with the retries and the warm start's pairs of
        // entries (module `active_set`, *Counts*; `Workspace::start`).
        // wcet-bound: (QP_MAX_ITER + 3 * QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS + 1) / 2 times per activation, counted in balance
        self.prepare(p, e.index);
        let p = &*p;
        // The first attempt is the main loop's iteration's; a retry follows a
        // refactorization.
        let mut first = self.append(p, e, tols);
        if first == Err(AppendError::Singular) && self.updates > 0 {
            // The small pivot may be accumulated rounding: refactor (which drops the
            // pending row) and retry once, within the solve's refactorization cap.
            match self.refactor(p, tols, sol, settings) {
                Ok(true) => {
                    // wcet-bound: (QP_MAX_ITER + 3 * QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS + 1) / 2 times per activation, counted in balance
                    first = self.append(p, e, tols);
                }
                Ok(false) => {}
                Err(st) => return Err(st),
            }
        }
        match first {
            Ok(()) => {
                self.lam[self.n - 1] = T::ZERO;
                sol.added += 1;
                return Ok(());
            }
            Err(AppendError::Full) => return Err(QpStatus::WorkingSetFull),
            Err(AppendError::Singular) => {}
        }
        let sigma = sign::<T>(e.side);
        // Multiplier the new constraint has accumulated over null-space steps.
        let mut lam_e = T::ZERO;
        // Each null-space step is an iteration of its own against `max_iter` (what
        // is left of the activation's cap) and removes an entry, so there are fewer
        // than W of them per `add`; a back edge follows each but the last.
        // wcet-bound: QP_MAX_ITER per activation
        for _ in 0..W {
            if sol.iterations >= max_iter {
                self.pending = false;
                return Err(QpStatus::IterationLimit);
            }
            sol.iterations += 1;
            // One call per null-space step: an iteration, with the main loop's.
            // wcet-bound: QP_MAX_ITER times per activation, counted in qp_iterations
            let block = self.null_space_step(p, sigma, tols.noise);
            let n = self.n;
            let Some((pos, t)) = block else {
                // No multiplier limits the ray. With an exactly dependent row the dual
                // is unbounded: infeasible. With a small but real pivot (nearly
                // dependent, not at rounding level) the dual is bounded along the ray:
                // the row is taken as independent after all, with its small pivot.
                let rel = self.last_rel_pivot;
                if rel.is_finite() && rel > tols.rounding {
                    self.commit(p, e);
                    self.lam[self.n - 1] = lam_e;
                    sol.added += 1;
                    return Ok(());
                }
                self.pending = false;
                return Err(QpStatus::Infeasible);
            };
            // wcet-bound: WS
            for k in 0..n {
                let mut l = self.lam[k] + t * sigma * self.tmp[k];
                let ek = self.ws[k];
                if !Self::is_equality(p, ek.index) && sign::<T>(ek.side) * l < T::ZERO {
                    l = T::ZERO;
                }
                self.lam[k] = l;
            }
            lam_e += t * sigma;
            // wcet-bound: (QP_MAX_ITER + QP_MAX_REFACTORIZATIONS + COLD_START_PASSES * WS) / 2 times per activation, counted in removals
            self.remove(pos);
            sol.removed += 1;
            // The removal updated the pending row: it enters once its pivot passes
            // the test `append` made.
            let dn = self.ldl[row_start(self.n) + self.n];
            if dn > tols.pivot * self.pending_diag && dn.is_finite() {
                self.commit(p, e);
                self.lam[self.n - 1] = lam_e;
                sol.added += 1;
                return Ok(());
            }
        }
        self.pending = false;
        Err(QpStatus::NumericalError)
    }

    /// The dual null-space direction of a constraint `e` that depends on the
    /// working set, into `tmp` (`λ_e` grows by `t·σ`, `λ_W` by `t·σ·c` with
    /// `c = −(M_WW + D)⁻¹ M_{W,e} = −L⁻ᵀ L_new`), and the first multiplier it
    /// drives to zero with its step `t`; `None` when no multiplier limits the ray.
    /// Not inlined: its triangular solve is bounded per call.
    #[inline(never)]
    fn null_space_step(
        &mut self,
        p: &QpProblem<T, N, M>,
        sigma: T,
        noise_tol: T,
    ) -> Option<(usize, T)> {
        let n = self.n;
        let s = row_start(n);
        // `Lᵀ c = −L_new` (L unit lower triangular) by columns of Lᵀ, i.e. by the
        // contiguous rows of the packed L, as `ldl_solve_tmp`'s second half: once
        // c_r is final, its share leaves the entries above it.
        // wcet-bound: WS
        for r in 0..n {
            self.tmp[r] = -self.ldl[s + r];
        }
        // wcet-bound: WS
        for r in (1..n).rev() {
            let cr = self.tmp[r];
            let sr = row_start(r);
            let (t, l) = (
                self.tmp.get_mut(..r).unwrap_or(&mut []),
                self.ldl.get(sr..sr + r).unwrap_or(&[]),
            );
            // `t` and `l` have the same length r; their addresses through
            // `black_box` (as in `ldl_back_tmp`).
            sub_scaled(core::hint::black_box(t), cr, core::hint::black_box(l));
        }
        let mut cmax = T::ZERO;
        // wcet-bound: WS
        for r in 0..n {
            cmax = cmax.max(self.tmp[r].abs());
        }
        // Rates below this are rounding noise of a zero coefficient.
        let noise = noise_tol * (T::ONE + cmax);
        let mut block: Option<(usize, T)> = None;
        for k in 0..n {
            let ek = self.ws[k];
            // Bounds the `for k in 0..n` loop (n ≤ W; back edges at the `continue`s).
            // wcet-bound: WS
            if Self::is_equality(p, ek.index) {
                continue;
            }
            let sg = sign::<T>(ek.side);
            let rate = sg * sigma * self.tmp[k];
            // wcet-bound: WS
            if rate < -noise {
                let t = (sg * self.lam[k]).max(T::ZERO) / -rate;
                if block.is_none_or(|(_, r)| t < r) {
                    block = Some((k, t));
                }
            }
        }
        block
    }

    /// One step of iterative refinement of the multipliers at the optimum: the
    /// residuals `r_k = m̃_kᵀu − b_k − λ_k/ρ_k` of the working-set equations give
    /// `Δλ = (M̃_W M̃_Wᵀ + D_W)⁻¹ r` with the same factor; kept (and `u`, `x`
    /// recomputed) only if every multiplier keeps its sign.
    pub(crate) fn refine(&mut self, p: &QpProblem<T, N, M>, x: &mut [T; N]) {
        // wcet-bound: WS
        for k in 0..self.n {
            let e = self.ws[k];
            let b = held_bound(p, e);
            self.tmp[k] =
                con_row(p, &self.rinv, e.index).dot(&self.u) - b - self.lam[k] * delta(p, e.index);
        }
        self.ldl_solve_tmp();
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k] + self.tmp[k];
            let e = self.ws[k];
            if !l.is_finite() || (!Self::is_equality(p, e.index) && sign::<T>(e.side) * l < T::ZERO)
            {
                return;
            }
        }
        // wcet-bound: WS
        for k in 0..self.n {
            self.lam[k] += self.tmp[k];
        }
        self.primal(p, x);
    }

    /// Whether every working-set constraint holds at `u`: `m̃_kᵀu = b_k + λ_k/ρ_k`
    /// within `tol` relative to `1 + |b_k + λ_k/ρ_k|`.
    pub(crate) fn working_set_holds(&self, p: &QpProblem<T, N, M>, tol: T) -> bool {
        // `n ≤ W` entries checked.
        // wcet-bound: WS
        (0..self.n).all(|k| {
            let e = self.ws[k];
            let b = held_bound(p, e);
            let val = con_row(p, &self.rinv, e.index).dot(&self.u);
            let target = b + self.lam[k] * delta(p, e.index);
            // Relative to the magnitudes involved: rows are formed in the working
            // precision, so their rounding scales with them.
            (val - target).abs() <= tol * (T::ONE + target.abs().max(val.abs()))
        })
    }

    /// Writes `x` (unless `fresh`), multipliers and cost for the current iterate.
    /// `fresh`: `u` and `sol.x` already belong to the current multipliers (the
    /// optimal exit), so the primal point is not recomputed.
    pub(crate) fn output(
        &mut self,
        p: &QpProblem<T, N, M>,
        sol: &mut QpSolution<T, N, M>,
        fresh: bool,
    ) {
        if !fresh {
            self.primal(p, &mut sol.x);
        }
        sol.lambda_rows.fill(T::ZERO);
        sol.lambda_bounds.fill(T::ZERO);
        let mut soft_cost = T::ZERO;
        // wcet-bound: WS
        for k in 0..self.n {
            let l = self.lam[k];
            match self.ws[k].index {
                ConstraintIndex::Bound(j) => {
                    if let Some(d) = sol.lambda_bounds.get_mut(j as usize) {
                        *d = l;
                    }
                }
                ConstraintIndex::Row(i) => {
                    if let Some(d) = sol.lambda_rows.get_mut(i as usize) {
                        *d = l;
                    }
                    soft_cost += T::HALF * l * l * delta(p, self.ws[k].index);
                }
            }
        }
        let mut c = T::ZERO;
        for (u, v) in self.u.iter().zip(self.v.iter()) {
            c += *u * (T::HALF * *u + *v);
        }
        sol.objective = c + soft_cost;
        sol.working_set_len = self.n as u16;
    }
}
