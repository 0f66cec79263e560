//! Condensing (the Method's steps 2 and 3): one linearise–condense pass writes
//! the QP over the 32 inputs alone. Node by node, the sensitivities
//! `S_{k+1} = A_k S_k + B_k E_k` are propagated; each cost term joins the Hessian
//! factor `R` (`H = RᵀR`) as a block of Householder reflections; each constraint
//! (input bounds, friction ellipse, road, validity, obstacles, `V ≥ 0`) becomes a
//! row of `A` through a row of `S_k`. The pass's scratch, [`Condensing`], lives in
//! the workspace [`Mpc`].

// Index loops mirror the maths of the condensing; all ranges are const-bounded.
#![allow(clippy::needless_range_loop)]

use super::warm_start::{RowId, RowKind};
use super::*;
use crate::bicycle::FIRST_LIVE;

impl<T: Real> Mpc<T> {
    /// Linearises around `ū` from `xi0` and writes the condensed QP into the solver
    /// (Method, steps 2 and 3): input bounds and regularisation, then node by node
    /// the linearisation, the tracking costs, and the validity, road and obstacle
    /// rows. Costs and rows of node `k + 1` depend only on the inputs before it, so
    /// every loop runs over the first `NU·(k + 1)` columns only.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn condense<const CAP: usize>(
        &mut self,
        st: &MpcSettings<T>,
        validity: &ValidityLimit<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        xi0: &[T; NX],
        v0: T,
        mu: T,
        v_heur: &mut [T; HORIZON + 1],
        report: &mut MpcReport<T>,
    ) {
        let dt = T::lit(PLAN_DT_S);
        let u_bar = self.u_bar;
        let qp = self.solver.problem_mut();
        let c = &mut self.condensing;
        let accel = input_bounds_and_regularisation(qp, st, mu);
        let ay_limit = validity.ay_limit_mps2();
        let buffer = st.obstacle_offset_buffer_m;
        let cap = |s: T| obstacle_speed_cap(&st.velocity, path, obstacles, s, v0, ay_limit, buffer);
        // One pass here rather than one per node: a road blocked is rare.
        // wcet-bound: MAX_OBSTACLES
        let blocked = obstacles.iter().any(|o| o.blocks_road);
        v_heur[0] = velocity_planner::v_heur(&st.velocity, path, xi0[IS], v0, mu).min(cap(xi0[IS]));
        c.start(st);
        let mut window = CurvatureWindow::new();
        let mut xbar = *xi0;
        // wcet-bound: HORIZON
        for k in 0..HORIZON {
            // tan δ̄ once, for the friction ellipse and the linearisation.
            let tan_delta = xbar[IDELTA].tan();
            accel.friction_ellipse(qp, st, &xbar, tan_delta, k);
            xbar = c.linearise(&st.geometry, &xbar, tan_delta, &u_bar[k], k, dt);
            let node = k + 1;
            let ncols = NU * node;
            let (fr, at) = NodeFrame::new(path, &xbar);
            let vh =
                velocity_planner::v_heur_at(&st.velocity, path, &mut window, &at, fr.s, v0, mu)
                    .min(cap(fr.s));
            v_heur[node] = vh;
            c.tracking_costs(qp, st, path, obstacles, &xbar, &fr, vh, &u_bar, ncols);
            c.node = node as u8;
            c.node_first[node] = qp.m as u8;
            c.road_row(qp, st, &fr);
            c.validity_rows(qp, st, validity, &xbar, &u_bar, ncols);
            c.obstacle_rows(qp, st, path, obstacles, &fr, &u_bar, ncols);
            c.speed_row(
                qp,
                &xbar,
                &u_bar,
                ncols,
                if blocked { vh } else { T::INFINITY },
            );
        }
        c.node_first[HORIZON + 1] = qp.m as u8;
        report.rows = qp.m as u32;
        report.obstacle_rows = c.obstacle_rows as u32;
        report.obstacle_rows_dropped = c.dropped;
    }
}

/// Kinematic steering that follows curvature `kappa` (1/m), signed, rad.
fn path_steering<T: Real>(geometry: &BicycleGeometry<T>, kappa: T) -> T {
    if kappa == T::ZERO {
        return T::ZERO;
    }
    let r = T::ONE / kappa.abs();
    let d = kinematic_steering_for_radius(geometry, r).unwrap_or(T::HALF * T::PI);
    if kappa > T::ZERO {
        d
    } else {
        -d
    }
}

/// Cost rows that one node adds to the Hessian (lateral, longitudinal, speed,
/// steering), appended to its factor as one block.
const COST_ROWS: usize = 4;

/// Scratch of one linearise–condense pass, kept in the workspace [`Mpc`] rather
/// than on the stack. Only the first `NU·(k + 1)` columns of a node's rows are
/// ever written or read (the inputs from node `k + 1` on do not reach it).
#[derive(Clone, Debug)]
pub(super) struct Condensing<T> {
    /// Sensitivities `S_k = ∂ξ_k/∂u` of the current node, alternating between the
    /// two buffers (`2 × NX × NV`; unit of `ξ_i` per unit of `u_j`).
    sens: [[[T; NV]; NX]; 2],
    /// Which buffer of `sens` holds `S_k`.
    cur: usize,
    /// The current node's cost rows, each scaled by `√w`, column-major
    /// (`NV × COST_ROWS`): the block appended to the Hessian factor.
    cost: [[T; COST_ROWS]; NV],
    /// Weight `w` and `√w` of each cost row (lateral, longitudinal, speed,
    /// steering), set by [`Condensing::start`].
    cost_weights: [(T, T); COST_ROWS],
    /// The QP row being built (`NV`).
    row: [T; NV],
    /// The current node's lateral-deviation row (`NV`) and its constant (m), kept
    /// from the tracking costs for the road row.
    lateral: ([T; NV], T),
    /// What each QP row pushed in this pass constrains (`NC`).
    pub(super) row_id: [RowId; NC],
    /// Node whose rows are being pushed (1..=HORIZON).
    pub(super) node: u8,
    /// First QP row of each node `1..=HORIZON`; entry `HORIZON + 1` is the row count
    /// (rows of node `n` are `node_first[n]..node_first[n + 1]`).
    pub(super) node_first: [u8; HORIZON + 2],
    /// Obstacle rows pushed in this pass.
    pub(super) obstacle_rows: usize,
    /// Obstacle rows linearised in this pass, pushed or refused by a full QP: what
    /// [`MAX_OBSTACLE_ROWS`] caps (a refused row has cost its linearisation too).
    pub(super) obstacle_linearisations: usize,
    /// Obstacle rows that found no room.
    pub(super) dropped: u32,
    /// Sideslip lag of the model, rad per m/s² ([`crate::sideslip`]).
    pub(super) lag: T,
}

/// The acceleration bounds of one pass, m/s² (`a_hi` before the friction ellipse),
/// and the grip `friction_usage·μ·g`, m/s².
struct AccelBounds<T> {
    a_hi: T,
    grip: T,
}

/// Input bounds (the acceleration's capped by the road's friction) and the input
/// regularisation `q_a u1² + q_δ̇ u2²`, which starts the Hessian factor `R`
/// (`H = RᵀR`) as a diagonal. Clears the QP.
fn input_bounds_and_regularisation<T: Real>(
    qp: &mut MpcQpProblem<T>,
    st: &MpcSettings<T>,
    mu: T,
) -> AccelBounds<T> {
    let w = &st.weights;
    qp.m = 0;
    qp.f = [T::ZERO; NV];
    for r in qp.h.iter_mut() {
        *r = [T::ZERO; NV];
    }
    let grip = st.friction_usage * mu * T::lit(crate::G);
    let a_lo = st.accel_min_mps2.max(-grip).min(T::ZERO);
    let a_hi = st
        .accel_max_mps2
        .min(grip * st.driven_load_share)
        .max(T::ZERO);
    // The Hessian is kept as its factor R (H = RᵀR), updated by Householder
    // reflections per block of squared cost terms: in f32, H itself would span
    // more than 1/ε.
    qp.h_factor = true;
    for k in 0..HORIZON {
        let (ia, ir) = (NU * k, NU * k + 1);
        qp.x_lo[ia] = a_lo;
        qp.x_hi[ia] = a_hi;
        qp.x_lo[ir] = -st.steer_rate_max_radps;
        qp.x_hi[ir] = st.steer_rate_max_radps;
        qp.h[ia][ia] = (T::TWO * w.q_accel).sqrt();
        qp.h[ir][ir] = (T::TWO * w.q_delta_rate).sqrt();
    }
    AccelBounds { a_hi, grip }
}

impl<T: Real> AccelBounds<T> {
    /// Friction ellipse on the plan's traction: the upper acceleration bound of
    /// interval `k` shrinks with the lateral acceleration the nominal trajectory
    /// needs at its start (`xbar`), so that the plan does not ask the driven tyres
    /// for more than `friction_usage·μ·g` in all. Braking keeps its bound: slowing
    /// down is what restores the validity domain.
    fn friction_ellipse(
        &self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        xbar: &[T; NX],
        tan_delta: T,
        k: usize,
    ) {
        // kinematic_lateral_acceleration(geometry, V̄, δ̄) from tan δ̄ (same value).
        let g = &st.geometry;
        let v = xbar[IV];
        let ay = v * v * g.beta_from_tan_rad(tan_delta).sin() / g.l_r_m;
        let r = (ay / self.grip).abs().min(T::ONE);
        qp.x_hi[NU * k] = self.a_hi * (T::ONE - r * r).sqrt();
    }
}

/// The nominal state at a node seen from the path point at its abscissa.
struct NodeFrame<T> {
    /// Predicted abscissa `s̄`, m.
    s: T,
    /// Path tangent `t` (unit, `[x, y]`).
    t: [T; 2],
    /// Path normal `n` (unit, to the left, `[x, y]`).
    n: [T; 2],
    /// Path curvature `κ`, 1/m.
    kappa: T,
    /// Longitudinal deviation `ē_x = tᵀ(P̄ − p(s̄))`, m.
    ex: T,
    /// Lateral deviation `ē_y = nᵀ(P̄ − p(s̄))`, m.
    ey: T,
    /// Track half-widths at `s̄`, m (`None` for a path without widths).
    widths: Option<crate::reference_path::Widths<T>>,
}

impl<T: Real> NodeFrame<T> {
    /// The frame and the path sample it was built from.
    fn new<const CAP: usize>(
        path: &ReferencePath<T, CAP>,
        xbar: &[T; NX],
    ) -> (Self, crate::reference_path::PathSample<T>) {
        let s = xbar[IS];
        let at = path.sample_at(s);
        let p = at.position;
        let (sin_h, cos_h) = at.heading_rad.sin_cos();
        let kappa = at.curvature_1pm;
        let (t, n) = ([cos_h, sin_h], [-sin_h, cos_h]);
        let (dx, dy) = (xbar[IX] - p[0], xbar[IY] - p[1]);
        let fr = Self {
            s,
            t,
            n,
            kappa,
            ex: t[0] * dx + t[1] * dy,
            ey: n[0] * dx + n[1] * dy,
            widths: at.widths,
        };
        (fr, at)
    }
}

impl<T: Real> Condensing<T> {
    pub(super) const fn new() -> Self {
        Self {
            sens: [[[T::ZERO; NV]; NX]; 2],
            cur: 0,
            cost: [[T::ZERO; COST_ROWS]; NV],
            cost_weights: [(T::ZERO, T::ZERO); COST_ROWS],
            row: [T::ZERO; NV],
            lateral: ([T::ZERO; NV], T::ZERO),
            row_id: [RowId::NONE; NC],
            node: 0,
            node_first: [0; HORIZON + 2],
            obstacle_rows: 0,
            obstacle_linearisations: 0,
            dropped: 0,
            lag: T::ZERO,
        }
    }

    /// Starts a pass: `S_0 = 0` (`ξ_0` is given), no rows.
    fn start(&mut self, st: &MpcSettings<T>) {
        let w = &st.weights;
        for (r, q) in [w.q_y, w.q_x, w.q_v, w.q_delta].into_iter().enumerate() {
            let wr = T::TWO * q;
            let sw = if wr > T::ZERO { wr.sqrt() } else { T::ZERO };
            self.cost_weights[r] = (wr, sw);
        }
        self.cur = 0;
        self.obstacle_rows = 0;
        self.obstacle_linearisations = 0;
        self.dropped = 0;
    }

    /// Linearise (Method, step 2): `ξ̄_{k+1} = F(ξ̄_k, ū_k)` (returned) and
    /// `S_{k+1} = A_k S_k + B_k E_k`, where `S_k`'s columns from `NU·k` on are
    /// zero and `A_k`'s structural zeros are skipped.
    fn linearise(
        &mut self,
        geometry: &BicycleGeometry<T>,
        xbar: &[T; NX],
        tan_delta: T,
        u: &[T; NU],
        k: usize,
        dt: T,
    ) -> [T; NX] {
        let lin = geometry.discretize_lagged(xbar, u, dt, tan_delta, self.lag);
        let used = NU * k;
        let (a, b) = self.sens.split_at_mut(1);
        let (old, new) = if self.cur == 0 {
            (&a[0], &mut b[0])
        } else {
            (&b[0], &mut a[0])
        };
        // wcet-bound: NX
        for i in 0..NX {
            let out = &mut new[i];
            // Row i of A has at most four nonzeros: the identity's in the columns
            // before FIRST_LIVE (its own, if i is one of them: the others are zero
            // exactly, `Discretization::a`), and the three live columns. Its
            // nonzero terms are summed in column order in one pass per entry, the
            // same sums as adding one column after the other to a zero row.
            let mut terms: [(&[T; NV], T); 4] = [(&old[0], T::ZERO); 4];
            let mut cnt = 0;
            if let Some(&aii) = lin.a[i].get(..FIRST_LIVE).and_then(|r| r.get(i)) {
                if aii != T::ZERO {
                    terms[0] = (&old[i], aii);
                    cnt = 1;
                }
            }
            for l in FIRST_LIVE..NX {
                let ail = lin.a[i][l];
                if ail != T::ZERO {
                    if let Some(t) = terms.get_mut(cnt) {
                        *t = (&old[l], ail);
                        cnt += 1;
                    }
                }
            }
            let [(s0, a0), (s1, a1), (s2, a2), (s3, a3)] = terms;
            // `o` is `out[..NU·k]` with k < HORIZON: fewer than NV entries.
            let o = &mut out[..used];
            match cnt {
                // WCET: fewer than NV f32.
                // wcet-bound: NV * 4 bytes
                0 => o.fill(T::ZERO),
                1 => {
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = a0 * s0[j];
                    }
                }
                2 => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = a0 * s0[j] + a1 * s1[j];
                    }
                }
                3 => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = (a0 * s0[j] + a1 * s1[j]) + a2 * s2[j];
                    }
                }
                _ => {
                    // wcet-bound: NV
                    for (j, d) in o.iter_mut().enumerate() {
                        *d = ((a0 * s0[j] + a1 * s1[j]) + a2 * s2[j]) + a3 * s3[j];
                    }
                }
            }
            out[used] = lin.b[i][0];
            out[used + 1] = lin.b[i][1];
        }
        self.cur ^= 1;
        lin.x_next
    }

    /// `row = Σ coef · S_k[state]` over the first `ncols` columns (the rest zero);
    /// returns the row's constant `nominal − row·ū`.
    fn lin_row<const K: usize>(
        &mut self,
        terms: &[(usize, T); K],
        nominal: T,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) -> T {
        lin_row_into(
            &self.sens[self.cur],
            &mut self.row,
            terms,
            nominal,
            u_bar,
            ncols,
        )
    }

    /// Puts `½·w·(rowᵀu + d)²` into block column `r`: `f += w·d·row` now, the
    /// Hessian term `w·row·rowᵀ` when the block is appended ([`add_square_root_rows`]).
    /// The weight is `w` of row `r` and its root `√w` (0 unless `w > 0`), both
    /// from [`Condensing::start`].
    fn cost_row(&mut self, qp: &mut MpcQpProblem<T>, r: usize, ncols: usize, d: T) {
        let wr = self.cost_weights[r];
        cost_row_of(qp, &mut self.cost, wr, &self.row, r, ncols, d);
    }

    /// Cost terms (Method, step 3) of the node: lateral deviation about the
    /// obstacle-clearing offset, longitudinal deviation, speed towards `V_heur`
    /// (`vh`, m/s), steering towards its reference; their squares join the
    /// Hessian factor as one block.
    #[allow(clippy::too_many_arguments)]
    fn tracking_costs<const CAP: usize>(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        xbar: &[T; NX],
        fr: &NodeFrame<T>,
        vh: T,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        // Lateral deviation: e_y ≈ ē_y + nᵀδP − κ ē_x δs, about the reference
        // offset that clears the obstacles' parabolas (0 away from them).
        // Built in the kept lateral row itself (no copy).
        let terms = [(IX, fr.n[0]), (IY, fr.n[1]), (IS, -fr.kappa * fr.ex)];
        let sens = &self.sens[self.cur];
        let d = lin_row_into(sens, &mut self.lateral.0, &terms, fr.ey, u_bar, ncols);
        self.lateral.1 = d;
        let ey_ref = obstacle_offset(path, obstacles, fr.s, st.obstacle_offset_buffer_m);
        let wr = self.cost_weights[0];
        cost_row_of(
            qp,
            &mut self.cost,
            wr,
            &self.lateral.0,
            0,
            ncols,
            d - ey_ref,
        );
        // Longitudinal deviation: e_x ≈ ē_x + tᵀδP + (κ ē_y − 1) δs.
        let terms = [
            (IX, fr.t[0]),
            (IY, fr.t[1]),
            (IS, fr.kappa * fr.ey - T::ONE),
        ];
        let d = self.lin_row(&terms, fr.ex, u_bar, ncols);
        self.cost_row(qp, 1, ncols, d);
        // Speed towards V_heur.
        let d = self.lin_row(&[(IV, T::ONE)], xbar[IV], u_bar, ncols) - vh;
        self.cost_row(qp, 2, ncols, d);
        // Steering towards its reference.
        let delta_ref = match st.steering_reference {
            SteeringReference::Zero => T::ZERO,
            SteeringReference::PathCurvature => path_steering(&st.geometry, fr.kappa)
                .clamp(-st.delta_mech_max_rad, st.delta_mech_max_rad),
        };
        let d = self.lin_row(&[(IDELTA, T::ONE)], xbar[IDELTA], u_bar, ncols) - delta_ref;
        self.cost_row(qp, 3, ncols, d);
        add_square_root_rows(&mut qp.h, &mut self.cost, ncols);
    }

    /// Row `sub` of kind `kind` at the current node.
    fn id_here(&self, kind: RowKind, sub: u16) -> RowId {
        RowId {
            kind,
            node: self.node,
            sub,
        }
    }

    /// Appends `row` with bounds `lo ≤ rowᵀu ≤ hi` and soft weight `rho`, as row
    /// `sub` of its kind at the current node.
    fn push(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        kind: RowKind,
        sub: u16,
        lo: T,
        hi: T,
        rho: T,
    ) -> bool {
        let id = self.id_here(kind, sub);
        push_row_of(qp, &mut self.row_id, &self.row, id, lo, hi, rho)
    }

    /// Road limits (soft): `−(w_right − b) ≤ e_y ≤ w_left − b`, `b` the half-width
    /// plus the margin, on the lateral deviation's row (kept by
    /// [`Condensing::tracking_costs`] of the same node).
    fn road_row(&mut self, qp: &mut MpcQpProblem<T>, st: &MpcSettings<T>, fr: &NodeFrame<T>) {
        let Some(wd) = fr.widths else {
            return;
        };
        let keep = st.half_width_m + st.road_margin_m;
        let hi = wd.left_m - keep;
        let lo = -(wd.right_m - keep);
        let (lo, hi) = if lo <= hi {
            (lo, hi)
        } else {
            let mid = T::HALF * (lo + hi);
            (mid, mid)
        };
        let (row, d) = (&self.lateral.0, self.lateral.1);
        let rho = T::TWO * st.weights.q_road;
        let id = self.id_here(RowKind::Road, 0);
        push_row_of(qp, &mut self.row_id, row, id, lo - d, hi - d, rho);
    }

    /// The car does not reverse (soft, weight [`SPEED_ROW_WEIGHT`]): `V ≥ 0` at a
    /// node whose linearised speed `V̄` is under [`SPEED_ROW_BELOW_MPS`] (`V` is
    /// exactly linear in the accelerations, so the row is exact), and `V ≤ cap`
    /// (m/s; `+∞` for none): the node's speed reference when an obstacle blocks
    /// the road ([`obstacle_speed_cap`] then stops the car before it), so that a
    /// car standing before it does not plan to creep on. After the obstacle rows
    /// of the node: when the rows are full, an obstacle keeps its row.
    fn speed_row(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        xbar: &[T; NX],
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
        cap: T,
    ) {
        if !xbar[IV].is_finite() || xbar[IV] >= T::lit(SPEED_ROW_BELOW_MPS) {
            return;
        }
        let d = self.lin_row(&[(IV, T::ONE)], xbar[IV], u_bar, ncols);
        let rho = T::lit(SPEED_ROW_WEIGHT);
        let hi = if cap.is_finite() {
            cap - d
        } else {
            T::INFINITY
        };
        self.push(qp, RowKind::Speed, 0, -d, hi, rho);
    }

    /// Validity (soft): `±δ ≤ δ_max(V̄) + δ_max'(V̄)(V − V̄) + δ_tol`.
    fn validity_rows(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        validity: &ValidityLimit<T>,
        xbar: &[T; NX],
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        let (dmax, slope) = validity.delta_max_and_slope(xbar[IV]);
        // The rows `±S_δ − δ_max'·S_V` in one pass over the sensitivities, each
        // entry accumulated as [`Condensing::lin_row`] does (same values).
        let sens = &self.sens[self.cur];
        let (sd, sv) = (&sens[IDELTA], &sens[IV]);
        let mut minus = [T::ZERO; NV];
        let plus = &mut self.row;
        plus.fill(T::ZERO);
        let neg_slope = -slope;
        // ncols = NU·(k + 1) <= NU·HORIZON = NV (condense, the only caller).
        if neg_slope == T::ZERO {
            // wcet-bound: NV
            for j in 0..ncols {
                plus[j] += sd[j];
                minus[j] += -sd[j];
            }
        } else {
            // wcet-bound: NV
            for j in 0..ncols {
                let t = neg_slope * sv[j];
                plus[j] = (plus[j] + sd[j]) + t;
                minus[j] = (minus[j] + -sd[j]) + t;
            }
        }
        // The slack's weight grows as `δ_max(V̄)` shrinks ([`MpcWeights::q_delta_tol`]):
        // `q_δtol·(δ_mech/δ_max)²`, the ratio capped at 100 (`δ_max(V)` → 0 as V → ∞).
        let mech = validity.delta_mech_max_rad;
        let ratio = mech / dmax.max(mech * T::lit(0.01));
        let rho = T::TWO * st.weights.q_delta_tol * ratio * ratio;
        let sv_bar = slope * xbar[IV];
        let d = (xbar[IDELTA] - sv_bar) - dot(&self.row, u_bar, ncols);
        let hi = dmax - sv_bar - d;
        self.push(qp, RowKind::Validity, 0, -T::INFINITY, hi, rho);
        let d = (-xbar[IDELTA] - sv_bar) - dot(&minus, u_bar, ncols);
        let hi = dmax - sv_bar - d;
        let id = self.id_here(RowKind::Validity, 1);
        push_row_of(qp, &mut self.row_id, &minus, id, -T::INFINITY, hi, rho);
    }

    /// Obstacles (soft), in the path frame: the parabola's directrix is parallel
    /// to the path, so with ξ ≈ s − s_o and η ≈ e_y near the obstacle,
    /// g = σ·(e_y − η_a) + c·(s − s_o − ξ0)² ≥ 0, linearised at the nominal
    /// (s̄, ē_y). Curvilinear coordinates keep it right on a curved road, where the
    /// obstacle's own Cartesian frame would not be.
    #[allow(clippy::too_many_arguments)]
    fn obstacle_rows<const CAP: usize>(
        &mut self,
        qp: &mut MpcQpProblem<T>,
        st: &MpcSettings<T>,
        path: &ReferencePath<T, CAP>,
        obstacles: &[Parabola<T>],
        fr: &NodeFrame<T>,
        u_bar: &[[T; NU]; HORIZON],
        ncols: usize,
    ) {
        // `obstacles`: the plan task's parabolas, a heapless::Vec of MAX_OBSTACLES.
        // wcet-bound: MAX_OBSTACLES
        for o in obstacles {
            let Some(s) = o.relevant_s_at(path, fr.s) else {
                continue;
            };
            if self.obstacle_linearisations >= MAX_OBSTACLE_ROWS {
                self.dropped += 1;
                continue;
            }
            self.obstacle_linearisations += 1;
            let sigma = o.sigma();
            let dxi = s - o.s_m - o.xi0_m;
            let g = sigma * (fr.ey - o.eta_apex_m) + o.steepness_1pm * dxi * dxi;
            let dg_ds = T::TWO * o.steepness_1pm * dxi;
            // ∂g/∂(X, Y, s) through e_y's and s's rows.
            let terms = [
                (IX, sigma * fr.n[0]),
                (IY, sigma * fr.n[1]),
                (IS, dg_ds - sigma * fr.kappa * fr.ex),
            ];
            // Past the check above, which counts every linearisation (pushed or
            // refused): at most MAX_OBSTACLE_ROWS per pass.
            // wcet-bound: MAX_OBSTACLE_ROWS * COLD_START_PASSES times per activation
            let d = self.lin_row(&terms, g, u_bar, ncols);
            if self.push(
                qp,
                RowKind::Obstacle,
                o.id as u16,
                -d,
                T::INFINITY,
                T::TWO * st.weights.q_obs,
            ) {
                self.obstacle_rows += 1;
            } else {
                // No room in the QP: dropped like a row past the cap.
                self.dropped += 1;
            }
        }
    }
}

/// Appends the rows of `x` (`NV × COST_ROWS`, column-major, entries from column
/// `ncols` on zero) to the upper-triangular factor `r` (`H = RᵀR`): after the call
/// `RᵀR` gains `Σ_rows x xᵀ`. One Householder reflection per column over the
/// `COST_ROWS + 1` entries `[R_jj; x_·j]` (positive diagonal kept), `O(ncols²)`;
/// `x` is zeroed.
#[inline(never)]
fn add_square_root_rows<T: Real>(
    r: &mut [[T; NV]; NV],
    x: &mut [[T; COST_ROWS]; NV],
    ncols: usize,
) {
    let n = ncols.min(NV);
    // wcet-bound: NV
    for k in 0..n {
        let v = x[k];
        x[k] = [T::ZERO; COST_ROWS];
        let mut sigma = T::ZERO;
        for vi in v {
            sigma += vi * vi;
        }
        if sigma == T::ZERO {
            continue;
        }
        let rkk = r[k][k];
        let mu = (rkk * rkk + sigma).sqrt();
        // w = [R_kk − μ; v], computed without cancellation when R_kk ≥ 0.
        let w0 = if rkk > T::ZERO {
            -sigma / (rkk + mu)
        } else {
            rkk - mu
        };
        let beta = T::TWO / (w0 * w0 + sigma);
        r[k][k] = mu;
        let (rk, xs) = (&mut r[k], &mut x[k + 1..n]);
        // The four rows as scalars (registers), summed in the order of the rows.
        let [v0, v1, v2, v3] = v;
        // Σ (n − 1 − k) over k < n ≤ NV per call (not inlined).
        // wcet-bound: NV * (NV - 1) / 2 per call
        for (rkj, xj) in rk[k + 1..n].iter_mut().zip(xs.iter_mut()) {
            let [x0, x1, x2, x3] = *xj;
            let mut d = w0 * *rkj;
            d += v0 * x0;
            d += v1 * x1;
            d += v2 * x2;
            d += v3 * x3;
            let t = beta * d;
            *rkj -= t * w0;
            *xj = [x0 - t * v0, x1 - t * v1, x2 - t * v2, x3 - t * v3];
        }
    }
}

/// [`Condensing::lin_row`] into `row`, from the sensitivities `sens`; at most three
/// terms (`K ≤ 3`, checked at compile time).
fn lin_row_into<T: Real, const K: usize>(
    sens: &[[T; NV]; NX],
    row: &mut [T; NV],
    terms: &[(usize, T); K],
    nominal: T,
    u_bar: &[[T; NU]; HORIZON],
    ncols: usize,
) -> T {
    const { assert!(K <= 3, "lin_row_into sums at most three terms") };
    let n = ncols.min(NV);
    // The terms with a nonzero coefficient (at most three), summed in their order
    // in one pass per entry, with the dot product `row·ū` in the same pass (the
    // same sums as adding one term after the other to a zero row).
    let mut used: [(&[T; NV], T); 3] = [(&sens[0], T::ZERO); 3];
    let mut cnt = 0;
    // `terms` has 1 or 3 entries (the arrays of tracking_costs and obstacle_rows);
    // the compiler splits this loop, its parts at the two annotated lines below: 3 each.
    for &(state, coef) in terms {
        if coef == T::ZERO {
            continue;
        }
        // wcet-bound: 3
        if let Some(srow) = sens.get(state) {
            // wcet-bound: 3
            if let Some(t) = used.get_mut(cnt) {
                *t = (srow, coef);
                cnt += 1;
            }
        }
    }
    if let Some(tail) = row.get_mut(n..) {
        // WCET: `row` holds NV f32.
        // wcet-bound: NV * 4 bytes
        tail.fill(T::ZERO);
    }
    let u = u_bar.as_flattened();
    let mut acc = T::ZERO;
    let [(s0, c0), (s1, c1), (s2, c2)] = used;
    // No more terms than `K` (so the single-term rows' copy has no two- or
    // three-term path); no term at all is the first entry with a zero coefficient:
    // a zero row (each entry `0·s`, ±0) and its product with ū.
    match cnt.min(K) {
        0 | 1 => {
            // wcet-bound: NV
            for j in 0..n {
                let r = c0 * s0[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
        2 => {
            // wcet-bound: NV
            for j in 0..n {
                let r = c0 * s0[j] + c1 * s1[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
        _ => {
            // wcet-bound: NV
            for j in 0..n {
                let r = (c0 * s0[j] + c1 * s1[j]) + c2 * s2[j];
                row[j] = r;
                acc += r * u[j];
            }
        }
    }
    nominal - acc
}

/// [`Condensing::cost_row`] of `row` with `(w, √w)`.
fn cost_row_of<T: Real>(
    qp: &mut MpcQpProblem<T>,
    cost: &mut [[T; COST_ROWS]; NV],
    (w, sw): (T, T),
    row: &[T; NV],
    r: usize,
    ncols: usize,
    d: T,
) {
    // ncols = NU·(k + 1) <= NU·HORIZON = NV (tracking_costs, from condense).
    // wcet-bound: NV
    for j in 0..ncols {
        qp.f[j] += w * row[j] * d;
        cost[j][r] = sw * row[j];
    }
}

/// [`Condensing::push`] of `row`.
fn push_row_of<T: Real>(
    qp: &mut MpcQpProblem<T>,
    row_id: &mut [RowId; NC],
    row: &[T; NV],
    id: RowId,
    lo: T,
    hi: T,
    rho: T,
) -> bool {
    match qp.push_row(row, lo, hi, rho) {
        Some(i) => {
            if let Some(k) = row_id.get_mut(i) {
                *k = id;
            }
            true
        }
        None => false,
    }
}

fn dot<T: Real>(row: &[T; NV], u: &[[T; NU]; HORIZON], ncols: usize) -> T {
    let mut acc = T::ZERO;
    // ncols <= NV: NU·(k + 1) from condense, or `ncols.min(NV)` in lin_row_into.
    // wcet-bound: NV
    for j in 0..ncols {
        acc += row[j] * u[j / 2][j % 2];
    }
    acc
}
