//! Kinematic bicycle model of the paper (its Equation 1), with `ṡ = V`, and its
//! discretisation for the MPC.
//!
//! State `ξ = [s, X, Y, V, ψ, δ]` (m, m, m, m/s, rad, rad; indices [`S`], [`X`],
//! [`Y`], [`V`], [`PSI`], [`DELTA`]), input `u = [u1, u2]` (acceleration m/s²,
//! steering rate rad/s; [`U_ACCEL`], [`U_STEER_RATE`]):
//!
//! ```text
//! ṡ = V          Ẋ = V·cos(ψ + β(δ))      Ẏ = V·sin(ψ + β(δ))
//! V̇ = u1         ψ̇ = V·sin(β(δ)) / l_r     δ̇ = u2
//! β(δ) = atan(tan δ · l_r / (l_f + l_r))
//! ```
//!
//! [`BicycleGeometry::discretize`] integrates one interval with the input held
//! (classical RK4) and returns the exact Jacobians `A = ∂ξ⁺/∂ξ`, `B = ∂ξ⁺/∂u` of
//! that discrete map, propagated through the four stages by the chain rule.
//! Transcendental functions are the expensive part on the ECU (libm's `sinf`
//! and `sincosf` compute in `f64`), so a step makes 1 `sin_cos`, 1 `tan` and
//! 3 `sqrt` calls and no `atan`: `sin β = t/√(1+t²)`, `cos β = 1/√(1+t²)` with
//! `t = tan δ · l_r/(l_f + l_r)`, `ψ + β` through the addition formulas, and the
//! later RK4 stages' `tan δ`, `sin ψ`, `cos ψ` by addition formulas from the first
//! stage's (see [`BicycleGeometry::discretize`]).

use crate::Real;

/// Geometry of the kinematic bicycle (the front and rear wheels lumped on the axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BicycleGeometry<T> {
    /// Distance from the centre of gravity to the front axle `l_f`, m.
    pub l_f_m: T,
    /// Distance from the centre of gravity to the rear axle `l_r`, m.
    pub l_r_m: T,
}

impl<T: Real> BicycleGeometry<T> {
    /// Wheelbase `l_f + l_r`, m.
    pub fn wheelbase_m(&self) -> T {
        self.l_f_m + self.l_r_m
    }

    /// Slip angle at the centre of gravity `β(δ) = atan(tan δ · l_r/(l_f+l_r))`, rad.
    pub fn beta_rad(&self, delta_rad: T) -> T {
        self.beta_from_tan_rad(delta_rad.tan())
    }

    /// [`Self::beta_rad`] given `tan δ` (same value), rad.
    pub fn beta_from_tan_rad(&self, tan_delta: T) -> T {
        (tan_delta * self.l_r_m / self.wheelbase_m()).atan()
    }
}

/// Number of states of `ξ = [s, X, Y, V, ψ, δ]`.
pub const NX: usize = 6;
/// Number of inputs of `u = [u1, u2]`.
pub const NU: usize = 2;

/// Index of the curvilinear abscissa `s` (m) in the state.
pub const S: usize = 0;
/// Index of the global X position of the centre of gravity (m) in the state.
pub const X: usize = 1;
/// Index of the global Y position of the centre of gravity (m) in the state.
pub const Y: usize = 2;
/// Index of the speed `V` (m/s) in the state.
pub const V: usize = 3;
/// Index of the yaw angle `ψ` (rad, counter-clockwise, not wrapped) in the state.
pub const PSI: usize = 4;
/// Index of the front steering angle `δ` (rad, positive left) in the state.
pub const DELTA: usize = 5;

/// Index of the acceleration `u1` (m/s²) in the input.
pub const U_ACCEL: usize = 0;
/// Index of the steering rate `u2` (rad/s) in the input.
pub const U_STEER_RATE: usize = 1;

/// State `ξ = [s m, X m, Y m, V m/s, ψ rad, δ rad]` (index with [`S`], [`X`], …).
pub type State<T> = [T; NX];
/// Input `u = [u1 m/s², u2 rad/s]` (index with [`U_ACCEL`], [`U_STEER_RATE`]).
pub type Input<T> = [T; NU];

/// The state of a plan node as an array `ξ = [s, X, Y, V, ψ, δ]`.
pub fn state_from_node<T: Real>(n: &crate::plan::PlanNode<T>) -> State<T> {
    [n.s_m, n.x_m, n.y_m, n.v_mps, n.psi_rad, n.delta_rad]
}

/// A plan node from a state array `ξ = [s, X, Y, V, ψ, δ]`.
pub fn node_from_state<T: Real>(x: &State<T>) -> crate::plan::PlanNode<T> {
    crate::plan::PlanNode {
        s_m: x[S],
        x_m: x[X],
        y_m: x[Y],
        v_mps: x[V],
        psi_rad: x[PSI],
        delta_rad: x[DELTA],
    }
}

/// One step of the discrete model `ξ⁺ = F(ξ, u)` and its Jacobians at `(ξ, u)`.
///
/// Row-major: `a[i][j] = ∂ξ⁺_i/∂ξ_j` (dimensionless or in the ratio of the two
/// states' units), `b[i][j] = ∂ξ⁺_i/∂u_j` (state unit per input unit). The MPC's
/// linearisation is `ξ⁺ ≈ x_next + a·(ξ − ξ̄) + b·(u − ū)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Discretization<T> {
    /// `F(ξ, u)`, the state after the step (same units as [`State`]).
    pub x_next: State<T>,
    /// `∂F/∂ξ`, 6×6, row `i` = output state `i`. Its columns before
    /// [`FIRST_LIVE`] are the identity's, exactly (the dynamics do not depend on
    /// `s`, `X`, `Y`).
    pub a: [[T; NX]; NX],
    /// `∂F/∂u`, 6×2, row `i` = output state `i`, column `j` = input `j`.
    pub b: [[T; NU]; NX],
}

/// Quantities of one evaluation of `f` that depend on `δ` only: from one `tan`
/// and one `sqrt` ([`SteerTerms::new`]) or from `tan δ` and one `sqrt`.
#[derive(Clone, Copy)]
struct SteerTerms<T> {
    /// `sin β`.
    sin_b: T,
    /// `cos β`.
    cos_b: T,
    /// `dβ/dδ`.
    dbeta: T,
}

impl<T: Real> SteerTerms<T> {
    /// `β = atan(k·tan δ)`, `k = l_r/(l_f + l_r)`: `cos β = 1/√(1 + t²)`,
    /// `sin β = t·cos β`, `dβ/dδ = k·(1 + tan²δ)/(1 + t²)` with `t = k·tan δ`.
    /// Transcendental calls: 1 `tan`, 1 `sqrt`.
    #[inline]
    fn new(k: T, delta: T) -> Self {
        Self::from_tan(k, delta.tan())
    }

    /// As [`Self::new`] from `tan δ` (1 `sqrt`, no other call).
    #[inline]
    fn from_tan(k: T, td: T) -> Self {
        let t = k * td;
        let q = T::ONE + t * t;
        let cos_b = T::ONE / q.sqrt();
        Self {
            sin_b: t * cos_b,
            cos_b,
            dbeta: k * (T::ONE + td * td) / q,
        }
    }
}

/// `f(ξ, u)` and the non-zero partial derivatives of `f` with respect to the
/// state at one RK4 stage, given `(sin ψ, cos ψ)` of the stage. No call.
#[derive(Clone, Copy)]
struct Stage<T> {
    f: State<T>,
    /// `∂Ẋ/∂V, ∂Ẋ/∂ψ, ∂Ẋ/∂δ`.
    dx: [T; 3],
    /// `∂Ẏ/∂V, ∂Ẏ/∂ψ, ∂Ẏ/∂δ`.
    dy: [T; 3],
    /// `∂ψ̇/∂V, ∂ψ̇/∂δ`.
    dpsi: [T; 2],
}

#[inline]
fn stage<T: Real>(
    inv_lr: T,
    lag: T,
    x: &State<T>,
    u: &Input<T>,
    st: &SteerTerms<T>,
    (sp, cp): (T, T),
) -> Stage<T> {
    let v = x[V];
    // cos(ψ + β), sin(ψ + β) by the addition formulas: no call for β itself.
    let c0 = cp * st.cos_b - sp * st.sin_b;
    let s0 = sp * st.cos_b + cp * st.sin_b;
    // The course lags the kinematic one by `−ε = lag·a_y`, `a_y = V²·sin β/l_r`
    // ([`crate::sideslip`]): `(c, s)` is `(c0, s0)` turned by `ε`, with
    // `sin ε ≈ ε`, `cos ε ≈ 1 − ε²/2` (|ε| ≤ 0.12 rad: error ≤ 3e-4). `lag = 0`
    // gives `(c0, s0)` exactly.
    let vsb = v * st.sin_b * inv_lr;
    let eps = -lag * v * vsb;
    let ce = T::ONE - T::HALF * eps * eps;
    let c = c0 * ce - s0 * eps;
    let s = s0 * ce + c0 * eps;
    // ∂(c, s)/∂ε of those formulas, and ∂ε/∂V, ∂ε/∂δ.
    let (dc_e, ds_e) = (-(s0 + c0 * eps), c0 - s0 * eps);
    let de_v = -T::TWO * lag * vsb;
    let de_d = -lag * v * v * st.cos_b * st.dbeta * inv_lr;
    Stage {
        f: [v, v * c, v * s, u[U_ACCEL], vsb, u[U_STEER_RATE]],
        dx: [
            c + v * dc_e * de_v,
            -v * s,
            -v * s * st.dbeta + v * dc_e * de_d,
        ],
        dy: [
            s + v * ds_e * de_v,
            v * c,
            v * c * st.dbeta + v * ds_e * de_d,
        ],
        dpsi: [st.sin_b * inv_lr, v * st.cos_b * st.dbeta * inv_lr],
    }
}

/// First column of `[ξ; u]` that a stage's state can depend on: the dynamics do
/// not depend on `s`, `X`, `Y` (columns `0..FIRST_LIVE`), so every stage's
/// derivative with respect to them is zero and `∂ξ_next/∂(s, X, Y)` is the
/// identity. The Jacobian products run over the columns from here on only; the
/// MPC's sensitivity propagation reads the identity's columns as such
/// ([`Discretization::a`]).
pub const FIRST_LIVE: usize = V;
const _: () = assert!(S < FIRST_LIVE && X < FIRST_LIVE && Y < FIRST_LIVE);
const _: () = assert!(V >= FIRST_LIVE && PSI >= FIRST_LIVE && DELTA >= FIRST_LIVE);

/// `dk = J·M + [0 | B_c]`: derivative of a stage's `k = f(ξ_stage, u)` with
/// respect to `[ξ; u]` (6×8), given `M = ∂ξ_stage/∂[ξ; u]`. Columns before
/// [`FIRST_LIVE`] are zero (and left so).
#[inline]
fn stage_derivative<T: Real>(g: &Stage<T>, m: &[[T; NX + NU]; NX]) -> [[T; NX + NU]; NX] {
    let mut dk = [[T::ZERO; NX + NU]; NX];
    for j in FIRST_LIVE..NX + NU {
        let mv = m[V][j];
        let mp = m[PSI][j];
        let md = m[DELTA][j];
        dk[S][j] = mv;
        dk[X][j] = g.dx[0] * mv + g.dx[1] * mp + g.dx[2] * md;
        dk[Y][j] = g.dy[0] * mv + g.dy[1] * mp + g.dy[2] * md;
        dk[PSI][j] = g.dpsi[0] * mv + g.dpsi[1] * md;
    }
    dk[V][NX + U_ACCEL] = T::ONE;
    dk[DELTA][NX + U_STEER_RATE] = T::ONE;
    dk
}

/// Largest increment (rad) for which [`small_sin_cos`] uses its series.
const SMALL_ANGLE_RAD: f32 = 0.5;

/// `(sin d, cos d)` of a small angle `d` (rad) by Taylor series (degree 13 and
/// 14; truncation error below 3e-17 for `|d| ≤ 0.5`, i.e. at the rounding level
/// of `f64`), no libm call; `None` above [`SMALL_ANGLE_RAD`] or for non-finite `d`.
#[inline]
fn small_sin_cos<T: Real>(d: T) -> Option<(T, T)> {
    if !d.is_finite() || d.abs() > T::lit(SMALL_ANGLE_RAD) {
        return None;
    }
    let d2 = d * d;
    // Horner: each factor is 1 − d²/((k+1)(k+2))·(rest).
    let term = |div: f64, rest: T| T::ONE - d2 * T::from_f64(1.0 / div) * rest;
    let s = d * term(
        6.0,
        term(
            20.0,
            term(42.0, term(72.0, term(110.0, term(156.0, T::ONE)))),
        ),
    );
    let c = term(
        2.0,
        term(
            12.0,
            term(
                30.0,
                term(56.0, term(90.0, term(132.0, term(182.0, T::ONE)))),
            ),
        ),
    );
    Some((s, c))
}

/// `(sin(a + d), cos(a + d))` from `(sin a, cos a)` and a small increment `d`
/// (rad) by the addition formulas; falls back to one `sin_cos` call when `|d|`
/// exceeds [`SMALL_ANGLE_RAD`].
#[inline]
fn sin_cos_of_sum<T: Real>((sa, ca): (T, T), a: T, d: T) -> (T, T) {
    match small_sin_cos(d) {
        Some((sd, cd)) => (sa * cd + ca * sd, ca * cd - sa * sd),
        None => (a + d).sin_cos(),
    }
}

/// `tan(a + d)` from `tan a` and a small increment `d` (rad):
/// `(tan a + tan d)/(1 − tan a·tan d)`; falls back to one `tan` call when `|d|`
/// exceeds [`SMALL_ANGLE_RAD`] or the denominator is under 0.1 (`a + d` near ±π/2).
#[inline]
fn tan_of_sum<T: Real>(ta: T, a: T, d: T) -> T {
    if let Some((sd, cd)) = small_sin_cos(d) {
        let td = sd / cd;
        let den = T::ONE - ta * td;
        if den.abs() >= T::lit(0.1) {
            return (ta + td) / den;
        }
    }
    (a + d).tan()
}

impl<T: Real> BicycleGeometry<T> {
    /// Continuous dynamics `ξ̇ = f(ξ, u)` of the paper's Equation 1 with `ṡ = V`:
    /// `[V, V·cos(ψ+β), V·sin(ψ+β), u1, V·sin β / l_r, u2]` (units of the state per
    /// second). Transcendental calls: 1 `tan`, 1 `sqrt`, 1 `sin_cos`.
    pub fn dynamics(&self, x: &State<T>, u: &Input<T>) -> State<T> {
        let k = self.l_r_m / self.wheelbase_m();
        let st = SteerTerms::new(k, x[DELTA]);
        stage(T::ONE / self.l_r_m, T::ZERO, x, u, &st, x[PSI].sin_cos()).f
    }

    /// One classical RK4 step of length `dt_s` (s) of [`Self::dynamics`] with the
    /// input held constant, and its exact Jacobians (the chain rule through the
    /// four stages, not finite differences).
    ///
    /// Cost: **1 `sin_cos`, 1 `tan`, 3 `sqrt`**, no `atan`, and about 700
    /// multiply-adds (most for the Jacobians):
    /// * `sin β`, `cos β` come from `tan δ` algebraically (1 `sqrt` per distinct
    ///   `δ`: stages 2 and 3 share `δ + u2·dt/2`);
    /// * `tan δ` at the later stages comes from the tangent addition formula and
    ///   `sin ψ`, `cos ψ` at the later stages from the sine/cosine addition
    ///   formulas, the increments' sines and cosines by a Taylor series (exact to
    ///   about 2e-11 for increments up to 0.5 rad);
    /// * only if an increment exceeds 0.5 rad (`|u2|·dt` or `|ψ̇|·dt`; e.g.
    ///   `ψ̇ > 2.5 rad/s` at `dt = 0.2 s`, far outside the validity domain) does
    ///   that stage fall back to a `tan` or `sin_cos` call: worst case 3 `tan` and
    ///   4 `sin_cos`.
    pub fn discretize(&self, x: &State<T>, u: &Input<T>, dt_s: T) -> Discretization<T> {
        self.discretize_with_tan(x, u, dt_s, x[DELTA].tan())
    }

    /// [`Self::discretize`] given `tan_delta = x[DELTA].tan()` (same result; for a
    /// caller that needs `tan δ` itself: no `tan` call here).
    pub fn discretize_with_tan(
        &self,
        x: &State<T>,
        u: &Input<T>,
        dt_s: T,
        tan_delta: T,
    ) -> Discretization<T> {
        self.discretize_lagged(x, u, dt_s, tan_delta, T::ZERO)
    }

    /// [`Self::discretize_with_tan`] of the model whose course lags the kinematic
    /// one by `lag·a_y` (`lag` in rad per m/s², `a_y = V²·sin β/l_r`): the sideslip
    /// a real car's rear tyres add in a bend ([`crate::sideslip`]). `lag = 0`: the
    /// paper's model, bit for bit.
    pub fn discretize_lagged(
        &self,
        x: &State<T>,
        u: &Input<T>,
        dt_s: T,
        tan_delta: T,
        lag: T,
    ) -> Discretization<T> {
        let k = self.l_r_m / self.wheelbase_m();
        let inv_lr = T::ONE / self.l_r_m;
        let h2 = dt_s * T::HALF;
        // δ at the stages: δ, δ + h/2·u2 (twice), δ + h·u2 (δ̇ = u2 is constant).
        // tan of the later ones by the addition formula from tan δ (one call).
        let td1 = tan_delta;
        let td23 = tan_of_sum(td1, x[DELTA], h2 * u[U_STEER_RATE]);
        let td4 = tan_of_sum(td1, x[DELTA], dt_s * u[U_STEER_RATE]);
        let st1 = SteerTerms::from_tan(k, td1);
        let st23 = SteerTerms::from_tan(k, td23);
        let st4 = SteerTerms::from_tan(k, td4);
        // sin/cos of ψ at the stages by the addition formulas from ψ (one call).
        let sc1 = x[PSI].sin_cos();

        let mut ident = [[T::ZERO; NX + NU]; NX];
        for (i, row) in ident.iter_mut().enumerate() {
            row[i] = T::ONE;
        }
        let advance = |x: &State<T>, kf: &State<T>, c: T| {
            let mut y = *x;
            for (yi, ki) in y.iter_mut().zip(kf.iter()) {
                *yi += c * *ki;
            }
            y
        };
        let advance_m = |dk: &[[T; NX + NU]; NX], c: T| {
            let mut m = ident;
            for (mr, dr) in m.iter_mut().zip(dk.iter()) {
                for (mv, dv) in mr[FIRST_LIVE..].iter_mut().zip(dr[FIRST_LIVE..].iter()) {
                    *mv += c * *dv;
                }
            }
            m
        };

        let g1 = stage(inv_lr, lag, x, u, &st1, sc1);
        let dk1 = stage_derivative(&g1, &ident);
        let x2 = advance(x, &g1.f, h2);
        let g2 = stage(
            inv_lr,
            lag,
            &x2,
            u,
            &st23,
            sin_cos_of_sum(sc1, x[PSI], x2[PSI] - x[PSI]),
        );
        let dk2 = stage_derivative(&g2, &advance_m(&dk1, h2));
        let x3 = advance(x, &g2.f, h2);
        let g3 = stage(
            inv_lr,
            lag,
            &x3,
            u,
            &st23,
            sin_cos_of_sum(sc1, x[PSI], x3[PSI] - x[PSI]),
        );
        let dk3 = stage_derivative(&g3, &advance_m(&dk2, h2));
        let x4 = advance(x, &g3.f, dt_s);
        let g4 = stage(
            inv_lr,
            lag,
            &x4,
            u,
            &st4,
            sin_cos_of_sum(sc1, x[PSI], x4[PSI] - x[PSI]),
        );
        let dk4 = stage_derivative(&g4, &advance_m(&dk3, dt_s));

        let w = dt_s / T::lit(6.0);
        // Each entry written once, in place (no zeroed matrix, no copy of one):
        // `∂ξ_next/∂(s, X, Y)` is the identity (see FIRST_LIVE); the other columns
        // are `I + w·(dk1 + 2·(dk2 + dk3) + dk4)`.
        let d = |i: usize, j: usize| {
            ident[i][j] + w * (dk1[i][j] + T::TWO * (dk2[i][j] + dk3[i][j]) + dk4[i][j])
        };
        Discretization {
            x_next: core::array::from_fn(|i| {
                x[i] + w * (g1.f[i] + T::TWO * (g2.f[i] + g3.f[i]) + g4.f[i])
            }),
            a: core::array::from_fn(|i| {
                core::array::from_fn(|j| {
                    if j >= FIRST_LIVE {
                        d(i, j)
                    } else if i == j {
                        T::ONE
                    } else {
                        T::ZERO
                    }
                })
            }),
            b: core::array::from_fn(|i| core::array::from_fn(|j| d(i, NX + j))),
        }
    }

    /// The state after one [`Self::discretize`] step, bit for bit, without its
    /// Jacobians (same transcendental calls, about a tenth of the arithmetic): for
    /// a rollout that needs no sensitivities (the plan under the optimal inputs).
    pub fn step(&self, x: &State<T>, u: &Input<T>, dt_s: T) -> State<T> {
        self.step_lagged(x, u, dt_s, T::ZERO)
    }

    /// [`Self::step`] of the lagged model ([`Self::discretize_lagged`]), bit for bit
    /// its `x_next`.
    pub fn step_lagged(&self, x: &State<T>, u: &Input<T>, dt_s: T, lag: T) -> State<T> {
        let k = self.l_r_m / self.wheelbase_m();
        let inv_lr = T::ONE / self.l_r_m;
        let h2 = dt_s * T::HALF;
        let td1 = x[DELTA].tan();
        let td23 = tan_of_sum(td1, x[DELTA], h2 * u[U_STEER_RATE]);
        let td4 = tan_of_sum(td1, x[DELTA], dt_s * u[U_STEER_RATE]);
        let st1 = SteerTerms::from_tan(k, td1);
        let st23 = SteerTerms::from_tan(k, td23);
        let st4 = SteerTerms::from_tan(k, td4);
        let sc1 = x[PSI].sin_cos();
        let advance = |kf: &State<T>, c: T| {
            let mut y = *x;
            for (yi, ki) in y.iter_mut().zip(kf.iter()) {
                *yi += c * *ki;
            }
            y
        };
        let f1 = stage(inv_lr, lag, x, u, &st1, sc1).f;
        let x2 = advance(&f1, h2);
        let sc2 = sin_cos_of_sum(sc1, x[PSI], x2[PSI] - x[PSI]);
        let f2 = stage(inv_lr, lag, &x2, u, &st23, sc2).f;
        let x3 = advance(&f2, h2);
        let sc3 = sin_cos_of_sum(sc1, x[PSI], x3[PSI] - x[PSI]);
        let f3 = stage(inv_lr, lag, &x3, u, &st23, sc3).f;
        let x4 = advance(&f3, dt_s);
        let sc4 = sin_cos_of_sum(sc1, x[PSI], x4[PSI] - x[PSI]);
        let f4 = stage(inv_lr, lag, &x4, u, &st4, sc4).f;
        let w = dt_s / T::lit(6.0);
        let mut out = *x;
        for i in 0..NX {
            out[i] += w * (f1[i] + T::TWO * (f2[i] + f3[i]) + f4[i]);
        }
        out
    }

    /// `substeps` RK4 steps of `dt_s / substeps` each (at least 1), chaining the
    /// Jacobians (`A = A₂·A₁`, `B = A₂·B₁ + B₂`). Cost: `substeps` times that of
    /// [`Self::discretize`] plus one 6×6 by 6×8 product per extra substep.
    pub fn discretize_substeps(
        &self,
        x: &State<T>,
        u: &Input<T>,
        dt_s: T,
        substeps: usize,
    ) -> Discretization<T> {
        let n = substeps.max(1);
        let h = dt_s / T::from_usize(n);
        let mut acc = self.discretize(x, u, h);
        for _ in 1..n {
            let step = self.discretize(&acc.x_next, u, h);
            let mut a = [[T::ZERO; NX]; NX];
            let mut b = step.b;
            for ((a_row, b_row), s_row) in a.iter_mut().zip(b.iter_mut()).zip(step.a.iter()) {
                for ((s_ik, acc_a_row), acc_b_row) in
                    s_row.iter().zip(acc.a.iter()).zip(acc.b.iter())
                {
                    for (aij, acc_kj) in a_row.iter_mut().zip(acc_a_row.iter()) {
                        *aij += *s_ik * *acc_kj;
                    }
                    for (bij, acc_kj) in b_row.iter_mut().zip(acc_b_row.iter()) {
                        *bij += *s_ik * *acc_kj;
                    }
                }
            }
            acc = Discretization {
                x_next: step.x_next,
                a,
                b,
            };
        }
        acc
    }
}

/// Free-function form of [`BicycleGeometry::discretize`]: one RK4 step of
/// `dt_s` (s) from state `x` under input `u`, with analytic Jacobians.
pub fn discretize<T: Real>(
    geom: &BicycleGeometry<T>,
    x: &State<T>,
    u: &Input<T>,
    dt_s: T,
) -> Discretization<T> {
    geom.discretize(x, u, dt_s)
}
