//! The MPC's condensing (structured: nonzero column ranges, sparse `A_k`, Hessian
//! factor updated by Householder blocks) against a straightforward dense reference
//! written here: full `6 × 32` sensitivity products, `H` summed as dense outer
//! products, every row over all 32 columns. Both in `f64`; the QPs the MPC hands to
//! its solver must match the reference to `1e-9` relative to the largest entry of
//! each quantity (rounding of different summation orders is ~`1e-15`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
#![allow(clippy::needless_range_loop)]

use firmware::bicycle::{self, BicycleGeometry, DELTA, NU, NX, S, V, X, Y};
use firmware::mpc::{obstacle_offset, Mpc, MpcQpProblem, MpcSettings, SteeringReference};
use firmware::mpc::{MAX_OBSTACLE_ROWS, NV};
use firmware::obstacles::{
    obstacle_speed_cap, Obstacle, ObstacleManager, ObstacleSettings, Parabola,
};
use firmware::plan::{Plan, HORIZON, PLAN_DT_S};
use firmware::reference_path::ReferencePath;
use firmware::state_estimate::StateEstimate;
use firmware::validity::{
    kinematic_lateral_acceleration, kinematic_steering_for_radius, ValidityLimit,
};
use firmware::velocity_planner::v_heur;

const CAP: usize = 256;
/// Relative tolerance of every comparison (f64 on both sides).
const TOL: f64 = 1e-9;

/// Stadium: two 60 m straights, two 20 m half circles, 4 m half-widths.
fn stadium() -> Box<ReferencePath<f64, CAP>> {
    let (straight, radius, ds) = (60.0f64, 20.0f64, 2.0f64);
    let pi = std::f64::consts::PI;
    let arc = (pi * radius / ds) as usize;
    let line = (straight / ds) as usize;
    let mut rows = Vec::new();
    for i in 0..line {
        rows.push([i as f64 * ds, 0.0, 4.0, 4.0]);
    }
    for i in 0..arc {
        let a = -pi / 2.0 + pi * i as f64 / arc as f64;
        rows.push([
            straight + radius * a.cos(),
            radius + radius * a.sin(),
            4.0,
            4.0,
        ]);
    }
    for i in 0..line {
        rows.push([straight - i as f64 * ds, 2.0 * radius, 4.0, 4.0]);
    }
    for i in 0..arc {
        let a = pi / 2.0 + pi * i as f64 / arc as f64;
        rows.push([radius * a.cos(), radius + radius * a.sin(), 4.0, 4.0]);
    }
    let mut p = Box::new(ReferencePath::new());
    p.load_track(&rows, true).unwrap();
    p
}

/// The paper's settings with three passes on a cold start, whatever the ECU's
/// constants, and a cap no start here reaches: every pass's condensing is checked,
/// not the caps.
fn settings() -> MpcSettings<f64> {
    let geometry = BicycleGeometry {
        l_f_m: 1.2,
        l_r_m: 1.6,
    };
    let mut s = MpcSettings::paper(geometry, 0.6, 1.8);
    s.cold_start_iterations = 3;
    s.qp_max_iter = 200;
    s
}

fn obstacles(path: &ReferencePath<f64, CAP>, s: &MpcSettings<f64>) -> ObstacleManager<f64> {
    // A parked car on the right of the first straight, one on the left of the second.
    let boxes = [
        [[28.0, -2.5], [32.5, -2.5], [32.5, -0.6], [28.0, -0.6]],
        [[25.0, 40.6], [29.5, 40.6], [29.5, 42.5], [25.0, 42.5]],
    ];
    let list: Vec<Obstacle<f64>> = boxes
        .iter()
        .enumerate()
        .map(|(k, b)| Obstacle::from_vertices(k as u32, b).unwrap())
        .collect();
    let os = ObstacleSettings::for_vehicle(1.8, 4.45, 1.0, s.velocity.v_max_mps(1.0));
    let mut m = ObstacleManager::new();
    m.update(&os, path, &list).unwrap();
    m
}

/// The dense reference QP: `H` itself (not a factor), `f`, rows, bounds.
struct Reference {
    h: Vec<Vec<f64>>,
    f: Vec<f64>,
    rows: Vec<(Vec<f64>, f64, f64, f64)>,
    x_lo: Vec<f64>,
    x_hi: Vec<f64>,
}

impl Reference {
    fn cost(&mut self, row: &[f64], w: f64, d: f64) {
        for i in 0..NV {
            self.f[i] += w * row[i] * d;
            for j in 0..NV {
                self.h[i][j] += w * row[i] * row[j];
            }
        }
    }
}

/// `Σ coef · S[state]` over all columns.
fn combine(sens: &[Vec<f64>], terms: &[(usize, f64)]) -> Vec<f64> {
    (0..NV)
        .map(|j| terms.iter().map(|&(i, c)| c * sens[i][j]).sum())
        .collect()
}

fn dot_u(row: &[f64], u: &[[f64; NU]; HORIZON]) -> f64 {
    (0..NV).map(|j| row[j] * u[j / NU][j % NU]).sum()
}

/// The condensed QP of the MPC's method, written the plain way.
#[allow(clippy::too_many_arguments)]
fn reference(
    st: &MpcSettings<f64>,
    path: &ReferencePath<f64, CAP>,
    obstacles: &[Parabola<f64>],
    xi0: [f64; NX],
    v0: f64,
    mu: f64,
    u: &[[f64; NU]; HORIZON],
) -> Reference {
    let w = st.weights;
    let dt = PLAN_DT_S as f64;
    let validity = ValidityLimit {
        geometry: st.geometry,
        mu,
        ay_fraction: st.ay_fraction,
        delta_mech_max_rad: st.delta_mech_max_rad,
    };
    let grip = st.friction_usage * mu * firmware::G as f64;
    let a_lo = st.accel_min_mps2.max(-grip).min(0.0);
    let a_hi = st.accel_max_mps2.min(grip * st.driven_load_share).max(0.0);
    let mut r = Reference {
        h: vec![vec![0.0; NV]; NV],
        f: vec![0.0; NV],
        rows: Vec::new(),
        x_lo: vec![0.0; NV],
        x_hi: vec![0.0; NV],
    };
    for k in 0..HORIZON {
        r.x_lo[2 * k] = a_lo;
        r.x_hi[2 * k] = a_hi;
        r.x_lo[2 * k + 1] = -st.steer_rate_max_radps;
        r.x_hi[2 * k + 1] = st.steer_rate_max_radps;
        r.h[2 * k][2 * k] = 2.0 * w.q_accel;
        r.h[2 * k + 1][2 * k + 1] = 2.0 * w.q_delta_rate;
    }
    let mut sens = vec![vec![0.0; NV]; NX];
    let mut x = xi0;
    let mut obstacle_rows = 0;
    for k in 0..HORIZON {
        let ay = kinematic_lateral_acceleration(&st.geometry, x[V], x[DELTA]);
        let q = (ay / grip).abs().min(1.0);
        r.x_hi[2 * k] = a_hi * (1.0 - q * q).sqrt();
        let lin = bicycle::discretize(&st.geometry, &x, &u[k], dt);
        // S_{k+1} = A S_k + B E_k, dense.
        let mut next = vec![vec![0.0; NV]; NX];
        for i in 0..NX {
            for j in 0..NV {
                next[i][j] = (0..NX).map(|l| lin.a[i][l] * sens[l][j]).sum();
            }
            next[i][2 * k] += lin.b[i][0];
            next[i][2 * k + 1] += lin.b[i][1];
        }
        sens = next;
        x = lin.x_next;
        let s = x[S];
        let p = path.position_at(s);
        let h = path.heading_at(s);
        let kappa = path.curvature_at(s);
        let (t, n) = ([h.cos(), h.sin()], [-h.sin(), h.cos()]);
        let (dx, dy) = (x[X] - p[0], x[Y] - p[1]);
        let (ex, ey) = (t[0] * dx + t[1] * dy, n[0] * dx + n[1] * dy);
        // Costs.
        let row_y = combine(&sens, &[(X, n[0]), (Y, n[1]), (S, -kappa * ex)]);
        let d_y = ey - dot_u(&row_y, u);
        let ey_ref = obstacle_offset(path, obstacles, s, st.obstacle_offset_buffer_m);
        r.cost(&row_y, 2.0 * w.q_y, d_y - ey_ref);
        let row = combine(&sens, &[(X, t[0]), (Y, t[1]), (S, kappa * ey - 1.0)]);
        let d = ex - dot_u(&row, u);
        r.cost(&row, 2.0 * w.q_x, d);
        // V_heur, capped near obstacles on the outside of a bend.
        let cap = obstacle_speed_cap(
            &st.velocity,
            path,
            obstacles,
            s,
            v0,
            st.ay_fraction * mu * f64::from(firmware::G),
            st.obstacle_offset_buffer_m,
        );
        let vh = v_heur(&st.velocity, path, s, v0, mu).min(cap);
        let row = combine(&sens, &[(V, 1.0)]);
        let d = x[V] - dot_u(&row, u) - vh;
        r.cost(&row, 2.0 * w.q_v, d);
        let delta_ref = match st.steering_reference {
            SteeringReference::Zero => 0.0,
            SteeringReference::PathCurvature if kappa == 0.0 => 0.0,
            SteeringReference::PathCurvature => {
                let d = kinematic_steering_for_radius(&st.geometry, 1.0 / kappa.abs())
                    .unwrap_or(std::f64::consts::FRAC_PI_2);
                (d * kappa.signum()).clamp(-st.delta_mech_max_rad, st.delta_mech_max_rad)
            }
        };
        let row = combine(&sens, &[(DELTA, 1.0)]);
        let d = x[DELTA] - dot_u(&row, u) - delta_ref;
        r.cost(&row, 2.0 * w.q_delta, d);
        // Rows: road, validity ±, obstacles.
        let wd = path.widths_at(s).unwrap();
        let keep = st.half_width_m + st.road_margin_m;
        let (lo, hi) = (-(wd.right_m - keep), wd.left_m - keep);
        assert!(lo <= hi);
        r.rows
            .push((row_y.clone(), lo - d_y, hi - d_y, 2.0 * w.q_road));
        let (dmax, slope) = validity.delta_max_and_slope(x[V]);
        // The slack weight per rad² scales with (δ_mech/δ_max)², the ratio capped at 100.
        let mech = validity.delta_mech_max_rad;
        let ratio = (mech / dmax).min(100.0);
        let rho_validity = 2.0 * w.q_delta_tol * ratio * ratio;
        for sign in [1.0, -1.0] {
            let row = combine(&sens, &[(DELTA, sign), (V, -slope)]);
            let d = sign * x[DELTA] - slope * x[V] - dot_u(&row, u);
            let hi = dmax - slope * x[V] - d;
            r.rows.push((row, f64::NEG_INFINITY, hi, rho_validity));
        }
        for o in obstacles {
            if !o.reaches_road || !o.is_relevant_at_s(path, s) {
                continue;
            }
            assert!(obstacle_rows < MAX_OBSTACLE_ROWS);
            obstacle_rows += 1;
            let sigma = o.sigma();
            let dxi = path.unwrap_s(s, o.s_m) - o.s_m - o.xi0_m;
            let g = sigma * (ey - o.eta_apex_m) + o.steepness_1pm * dxi * dxi;
            let dg_ds = 2.0 * o.steepness_1pm * dxi;
            let row = combine(
                &sens,
                &[
                    (X, sigma * n[0]),
                    (Y, sigma * n[1]),
                    (S, dg_ds - sigma * kappa * ex),
                ],
            );
            let d = g - dot_u(&row, u);
            r.rows.push((row, -d, f64::INFINITY, 2.0 * w.q_obs));
        }
    }
    r
}

fn max_abs<'a>(v: impl Iterator<Item = &'a f64>) -> f64 {
    v.fold(0.0f64, |m, x| m.max(x.abs()))
}

fn close(what: &str, a: f64, b: f64, scale: f64) {
    let ok = (a == b) || (a - b).abs() <= TOL * scale.max(1e-300);
    assert!(ok, "{what}: {a} vs reference {b} (scale {scale})");
}

/// Compares the solver's problem (Hessian given as its factor `R`) with the
/// reference.
fn compare(p: &MpcQpProblem<f64>, r: &Reference) {
    assert!(p.h_factor);
    // H = RᵀR from the upper triangle.
    let hs = max_abs(r.h.iter().flatten());
    for i in 0..NV {
        for j in 0..NV {
            let h: f64 = (0..=i.min(j)).map(|k| p.h[k][i] * p.h[k][j]).sum();
            close(&format!("H[{i}][{j}]"), h, r.h[i][j], hs);
        }
    }
    let fs = max_abs(r.f.iter());
    for i in 0..NV {
        close(&format!("f[{i}]"), p.f[i], r.f[i], fs);
        close(&format!("x_lo[{i}]"), p.x_lo[i], r.x_lo[i], 1.0);
        close(&format!("x_hi[{i}]"), p.x_hi[i], r.x_hi[i], 1.0);
    }
    assert_eq!(p.m, r.rows.len(), "row count");
    for (i, (row, lo, hi, rho)) in r.rows.iter().enumerate() {
        let scale = max_abs(row.iter());
        for j in 0..NV {
            close(&format!("A[{i}][{j}]"), p.a[i][j], row[j], scale);
        }
        close(&format!("lo[{i}]"), p.lo[i], *lo, 1.0 + lo.abs());
        close(&format!("hi[{i}]"), p.hi[i], *hi, 1.0 + hi.abs());
        close(&format!("soft[{i}]"), p.soft[i], *rho, *rho);
    }
}

/// Every pass of a cold start (around `ū = 0`, then around each pass's optimum)
/// and of the following warm steps, on curves and past obstacles.
#[test]
fn condensing_matches_the_dense_reference() {
    let path = stadium();
    let st = settings();
    let obs = obstacles(&path, &st);
    let mut mpc: Box<Mpc<f64>> = Box::default();
    let mut plan = Plan::zeroed();
    // Start before the first parked car, then on the curve.
    let starts = [
        (10.0, 0.3, 0.0, 15.0, 0.0),
        (62.0, 1.0, 0.35, 12.0, 0.08),
        (20.0, 40.5, std::f64::consts::PI, 14.0, 0.0),
    ];
    let (mut checked, mut passes) = (0, 0);
    for &(x, y, psi, v, delta) in &starts {
        mpc.reset();
        let mut est = StateEstimate {
            stamp_us: 0,
            x_m: x,
            y_m: y,
            psi_rad: psi,
            vx_mps: v,
            vy_mps: 0.0,
            yaw_rate_radps: 0.0,
            delta_rad: delta,
            ..StateEstimate::zeroed()
        };
        for step in 0..4 {
            // Each pass's QP and the nominal inputs it was built around.
            let mut qps: Vec<Box<MpcQpProblem<f64>>> = Vec::new();
            let mut sols: Vec<[f64; NV]> = Vec::new();
            let warm_u = plan.inputs;
            // The warm start's shift, 0.1 s in nodes, computed as the MPC does.
            let shift = (100_000f32 as f64 * 1e-6f32 as f64) / (PLAN_DT_S as f64);
            // Its projection hint: the last plan's abscissa `shift` nodes on.
            let s_hint = (step > 0)
                .then(|| plan.nodes[0].s_m + (plan.nodes[1].s_m - plan.nodes[0].s_m) * shift);
            let report = mpc
                .step_observed(
                    &st,
                    &path,
                    obs.parabolas(),
                    &est,
                    1.0,
                    &mut plan,
                    |q| qps.push(Box::new(q.problem().clone())),
                    |s| sols.push(s.x),
                )
                .unwrap();
            passes += report.passes;
            let proj = path.project([est.x_m, est.y_m], s_hint).unwrap();
            let v0 = est.speed_mps();
            let xi0 = [
                proj.s_m,
                est.x_m,
                est.y_m,
                v0,
                est.psi_rad,
                est.delta_rad
                    .clamp(-st.delta_mech_max_rad, st.delta_mech_max_rad),
            ];
            for (pass, qp) in qps.iter().enumerate() {
                let u = if pass > 0 {
                    let x = sols[pass - 1];
                    core::array::from_fn(|k| [x[2 * k], x[2 * k + 1]])
                } else if report.warm {
                    // Shifted by about half an interval: each new interval averages
                    // the two old ones it overlaps (the last one extended), with the
                    // MPC's own floating-point operations.
                    core::array::from_fn(|k| {
                        let a = shift + k as f64;
                        let (w0, w1) = ((k + 1) as f64 - a, (a + 1.0) - (k + 1) as f64);
                        let (p, q) = (warm_u[k], warm_u[(k + 1).min(HORIZON - 1)]);
                        [w0 * p[0] + w1 * q[0], w0 * p[1] + w1 * q[1]]
                    })
                } else {
                    [[0.0; NU]; HORIZON]
                };
                let r = reference(&st, &path, obs.parabolas(), xi0, v0, 1.0, &u);
                compare(qp, &r);
                checked += 1;
            }
            // Follow the plan for 0.1 s (half a node: interpolate).
            let (a, b) = (plan.nodes[0], plan.nodes[1]);
            est.stamp_us += 100_000;
            est.x_m = 0.5 * (a.x_m + b.x_m);
            est.y_m = 0.5 * (a.y_m + b.y_m);
            est.psi_rad = 0.5 * (a.psi_rad + b.psi_rad);
            est.vx_mps = 0.5 * (a.v_mps + b.v_mps);
            est.delta_rad = 0.5 * (a.delta_rad + b.delta_rad);
        }
    }
    // Every pass of 3 cold starts (up to 3 passes each) and 9 warm steps (1 each).
    assert_eq!(checked, passes);
    assert!(checked >= 15, "{checked} QPs checked");
}
