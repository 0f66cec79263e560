//! Tests of the kinematic bicycle model and its RK4 discretisation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::bicycle::{
    discretize, node_from_state, state_from_node, BicycleGeometry, Discretization, DELTA,
    FIRST_LIVE, NU, NX, PSI, S, V, X, Y,
};
use firmware::Real;
use proptest::prelude::*;

fn geom() -> BicycleGeometry<f64> {
    BicycleGeometry {
        l_f_m: 1.2,
        l_r_m: 1.6,
    }
}

/// Central finite differences of the discrete map.
fn fd(
    g: &BicycleGeometry<f64>,
    x: &[f64; 6],
    u: &[f64; 2],
    dt: f64,
    n: usize,
) -> Discretization<f64> {
    let base = g.discretize_substeps(x, u, dt, n);
    let mut a = [[0.0; NX]; NX];
    let mut b = [[0.0; NU]; NX];
    let h = 1e-6;
    for j in 0..NX {
        let (mut xp, mut xm) = (*x, *x);
        xp[j] += h;
        xm[j] -= h;
        let p = g.discretize_substeps(&xp, u, dt, n).x_next;
        let m = g.discretize_substeps(&xm, u, dt, n).x_next;
        for i in 0..NX {
            a[i][j] = (p[i] - m[i]) / (2.0 * h);
        }
    }
    for j in 0..NU {
        let (mut up, mut um) = (*u, *u);
        up[j] += h;
        um[j] -= h;
        let p = g.discretize_substeps(x, &up, dt, n).x_next;
        let m = g.discretize_substeps(x, &um, dt, n).x_next;
        for i in 0..NX {
            b[i][j] = (p[i] - m[i]) / (2.0 * h);
        }
    }
    Discretization {
        x_next: base.x_next,
        a,
        b,
    }
}

fn assert_jacobians_match(x: [f64; 6], u: [f64; 2], dt: f64, n: usize) {
    let g = geom();
    let an = g.discretize_substeps(&x, &u, dt, n);
    let num = fd(&g, &x, &u, dt, n);
    for i in 0..NX {
        for j in 0..NX {
            assert!(
                (an.a[i][j] - num.a[i][j]).abs() < 1e-6 * (1.0 + num.a[i][j].abs()),
                "A[{i}][{j}]: {} vs {} at x={x:?} u={u:?}",
                an.a[i][j],
                num.a[i][j]
            );
        }
        for j in 0..NU {
            assert!(
                (an.b[i][j] - num.b[i][j]).abs() < 1e-6 * (1.0 + num.b[i][j].abs()),
                "B[{i}][{j}]: {} vs {}",
                an.b[i][j],
                num.b[i][j]
            );
        }
    }
}

#[test]
fn jacobians_match_finite_differences() {
    for (x, u) in [
        ([0.0, 0.0, 0.0, 15.0, 0.0, 0.0], [0.0, 0.0]),
        ([12.0, 3.0, -4.0, 15.0, 0.7, 0.05], [1.5, -0.3]),
        ([100.0, -50.0, 20.0, 6.0, -2.5, -0.3], [-8.0, 0.5]),
        ([5.0, 1.0, 1.0, 0.5, 3.0, 0.45], [6.0, 0.2]),
        ([5.0, 1.0, 1.0, 25.0, 10.0, -0.02], [-3.0, -0.5]),
    ] {
        assert_jacobians_match(x, u, 0.2, 1);
        assert_jacobians_match(x, u, 0.2, 3);
    }
}

proptest! {
    #[test]
    fn jacobians_match_finite_differences_anywhere(
        v in 0.0f64..35.0, psi in -7.0f64..7.0, delta in -0.5f64..0.5,
        a in -8.0f64..6.0, r in -0.5f64..0.5, n in 1usize..4,
    ) {
        assert_jacobians_match([3.0, 10.0, -2.0, v, psi, delta], [a, r], 0.2, n);
    }
}

#[test]
fn straight_line_is_exact() {
    let g = geom();
    let d = discretize(&g, &[0.0, 1.0, 2.0, 10.0, 0.0, 0.0], &[2.0, 0.0], 0.2);
    // s and X follow V·t + a·t²/2 exactly (RK4 is exact for quadratics).
    assert!((d.x_next[S] - (2.0 + 0.04)).abs() < 1e-12);
    assert!((d.x_next[X] - (1.0 + 2.0 + 0.04)).abs() < 1e-12);
    assert!((d.x_next[Y] - 2.0).abs() < 1e-12);
    assert!((d.x_next[V] - 10.4).abs() < 1e-12);
    assert_eq!(d.x_next[PSI], 0.0);
    assert_eq!(d.b[V][0], 0.2);
    assert_eq!(d.b[DELTA][1], 0.2);
}

#[test]
fn constant_steering_follows_the_kinematic_circle() {
    // R = l_r / sin β; the centre of gravity stays on that circle.
    let g = geom();
    let delta: f64 = 0.1;
    let beta = g.beta_rad(delta);
    let r = g.l_r_m / beta.sin();
    let mut x = [0.0, 0.0, 0.0, 10.0, 0.0, delta];
    // Centre of the circle: left of the velocity direction ψ + β.
    let c = [-r * beta.sin(), r * beta.cos()];
    for _ in 0..50 {
        x = g.discretize(&x, &[0.0, 0.0], 0.2).x_next;
        let d = ((x[X] - c[0]).powi(2) + (x[Y] - c[1]).powi(2)).sqrt();
        assert!((d - r).abs() < 1e-6 * r, "{d} vs {r}");
    }
    assert!((x[PSI] - 10.0 * 10.0 / r).abs() < 1e-9);
    // ψ̇ agrees with the continuous model.
    let f = g.dynamics(&[0.0, 0.0, 0.0, 10.0, 0.0, delta], &[0.0, 0.0]);
    assert!((f[PSI] - 10.0 / r).abs() < 1e-12);
}

#[test]
fn substeps_converge_at_fourth_order() {
    let g = geom();
    let x = [0.0, 0.0, 0.0, 12.0, 0.3, 0.2];
    let u = [1.0, -0.4];
    let reference = g.discretize_substeps(&x, &u, 0.2, 256).x_next;
    let err = |n: usize| {
        let y = g.discretize_substeps(&x, &u, 0.2, n).x_next;
        (0..NX)
            .map(|i| (y[i] - reference[i]).abs())
            .fold(0.0, f64::max)
    };
    let (e1, e2, e4) = (err(1), err(2), err(4));
    assert!(e1 < 1e-4, "{e1}");
    // Halving the step divides the error by about 2⁴ = 16.
    assert!(e1 / e2 > 10.0 && e1 / e2 < 24.0, "{e1} {e2}");
    assert!(e2 / e4 > 10.0 && e2 / e4 < 24.0, "{e2} {e4}");
}

#[test]
fn f32_agrees_with_f64_and_is_deterministic() {
    let g32 = BicycleGeometry {
        l_f_m: 1.2f32,
        l_r_m: 1.6,
    };
    let x = [1.0f32, 2.0, 3.0, 14.0, 0.4, 0.1];
    let u = [0.5f32, 0.3];
    let d1 = g32.discretize(&x, &u, 0.2);
    let d2 = g32.discretize(&x, &u, 0.2);
    assert_eq!(format!("{d1:?}"), format!("{d2:?}"));
    let d64 = geom().discretize(&x.map(f64::from), &u.map(f64::from), 0.2);
    for i in 0..NX {
        assert!(
            (f64::from(d1.x_next[i]) - d64.x_next[i]).abs() < 1e-4 * (1.0 + d64.x_next[i].abs())
        );
        for j in 0..NX {
            assert!((f64::from(d1.a[i][j]) - d64.a[i][j]).abs() < 1e-4 * (1.0 + d64.a[i][j].abs()));
        }
    }
}

#[test]
fn plan_node_round_trip() {
    let x = [1.0, 2.0, 3.0, 4.0, 5.0, 0.1];
    assert_eq!(state_from_node(&node_from_state(&x)), x);
}

/// Plain RK4 of Equation 1 with std's sin/cos/tan/atan, for reference.
fn reference_rk4(g: &BicycleGeometry<f64>, x: [f64; 6], u: [f64; 2], dt: f64) -> [f64; 6] {
    let f = |x: [f64; 6]| {
        let beta = (x[DELTA].tan() * g.l_r_m / (g.l_f_m + g.l_r_m)).atan();
        [
            x[V],
            x[V] * (x[PSI] + beta).cos(),
            x[V] * (x[PSI] + beta).sin(),
            u[0],
            x[V] * beta.sin() / g.l_r_m,
            u[1],
        ]
    };
    let add = |x: [f64; 6], k: [f64; 6], c: f64| {
        let mut y = x;
        for i in 0..6 {
            y[i] += c * k[i];
        }
        y
    };
    let k1 = f(x);
    let k2 = f(add(x, k1, dt / 2.0));
    let k3 = f(add(x, k2, dt / 2.0));
    let k4 = f(add(x, k3, dt));
    let mut y = x;
    for i in 0..6 {
        y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    y
}

#[test]
fn addition_formulas_match_plain_rk4_including_fallbacks() {
    let g = geom();
    for (x, u) in [
        ([0.0, 0.0, 0.0, 15.0, 0.3, 0.1], [1.0, 0.4]),
        ([0.0, 0.0, 0.0, 30.0, -4.0, -0.5], [-8.0, -0.5]),
        // Steering increment 1 rad (> 0.5): tan fallback.
        ([0.0, 0.0, 0.0, 10.0, 1.0, 0.0], [0.0, 5.0]),
        // Yaw increment > 0.5 rad at the last stage: sin_cos fallback.
        ([0.0, 0.0, 0.0, 30.0, 2.0, 0.6], [0.0, 0.0]),
    ] {
        let ours = g.discretize(&x, &u, 0.2).x_next;
        let theirs = reference_rk4(&g, x, u, 0.2);
        // The MPC's map at a zero sideslip lag, against the same independent
        // RK4 of the paper's Equation 1 (not against `discretize`, which calls
        // it): the λ = 0 path is the paper's model.
        let lag0 = g.discretize_lagged(&x, &u, 0.2, x[DELTA].tan(), 0.0).x_next;
        for i in 0..NX {
            assert!(
                (ours[i] - theirs[i]).abs() < 1e-10 * (1.0 + theirs[i].abs()),
                "{i}: {ours:?} {theirs:?}"
            );
            assert!(
                (lag0[i] - theirs[i]).abs() < 1e-10 * (1.0 + theirs[i].abs()),
                "{i}: {lag0:?} {theirs:?}"
            );
        }
        assert_jacobians_match(x, u, 0.2, 1);
    }
}

#[test]
fn step_is_discretize_without_jacobians_bit_for_bit_and_a_zero_lag_is_the_kinematic_model() {
    let g32 = BicycleGeometry {
        l_f_m: 1.2f32,
        l_r_m: 1.6,
    };
    let g64 = BicycleGeometry {
        l_f_m: 1.2f64,
        l_r_m: 1.6,
    };
    for i in 0..200 {
        let t = i as f64;
        let x = [
            t,
            3.0 * (0.3 * t).sin(),
            -2.0 + 0.1 * t,
            0.5 + 0.15 * t,
            (0.7 * t).sin() * 4.0,
            0.5 * (1.3 * t).cos(),
        ];
        // Includes increments beyond the series' range (|u2|·dt > 0.5 rad).
        let u = [6.0 * (0.9 * t).cos(), 4.0 * (0.4 * t).sin()];
        let dt = if i % 3 == 0 { 0.2 } else { 0.05 };
        let s64 = g64.step(&x, &u, dt);
        assert_eq!(s64, g64.discretize(&x, &u, dt).x_next);
        let x32 = x.map(|v| v as f32);
        let u32_ = u.map(|v| v as f32);
        let dt32 = dt as f32;
        let plain = g32.discretize(&x32, &u32_, dt32);
        assert_eq!(g32.step(&x32, &u32_, dt32), plain.x_next);
        // The lagged model at a zero lag is the kinematic one, bit for bit, and its
        // step is its discretisation's state at any lag.
        let tan_delta = Real::tan(x32[DELTA]);
        assert_eq!(
            g32.discretize_lagged(&x32, &u32_, dt32, tan_delta, 0.0),
            plain
        );
        assert_eq!(g32.step_lagged(&x32, &u32_, dt32, 0.0), plain.x_next);
        let lag = 0.02 * (0.5 + 0.5 * (0.2 * t as f32).sin());
        assert_eq!(
            g32.step_lagged(&x32, &u32_, dt32, lag),
            g32.discretize_lagged(&x32, &u32_, dt32, tan_delta, lag)
                .x_next
        );
    }
}

/// Central finite differences of the lagged map ([`BicycleGeometry::step_lagged`]).
fn assert_lagged_jacobians_match(x: [f64; 6], u: [f64; 2], dt: f64, lag: f64) {
    let g = geom();
    let an = g.discretize_lagged(&x, &u, dt, Real::tan(x[DELTA]), lag);
    let h = 1e-6;
    let col = |p: [f64; 6], m: [f64; 6]| -> [f64; 6] {
        std::array::from_fn(|i| (p[i] - m[i]) / (2.0 * h))
    };
    for j in 0..NX + NU {
        let (p, m) = if j < NX {
            let (mut xp, mut xm) = (x, x);
            xp[j] += h;
            xm[j] -= h;
            (
                g.step_lagged(&xp, &u, dt, lag),
                g.step_lagged(&xm, &u, dt, lag),
            )
        } else {
            let (mut up, mut um) = (u, u);
            up[j - NX] += h;
            um[j - NX] -= h;
            (
                g.step_lagged(&x, &up, dt, lag),
                g.step_lagged(&x, &um, dt, lag),
            )
        };
        for (i, num) in col(p, m).into_iter().enumerate() {
            let an_ij = if j < NX { an.a[i][j] } else { an.b[i][j - NX] };
            assert!(
                (an_ij - num).abs() < 1e-6 * (1.0 + num.abs()),
                "lag {lag}: d{i}/d{j}: {an_ij} vs {num} at x={x:?} u={u:?}"
            );
        }
    }
}

proptest! {
    #[test]
    fn lagged_jacobians_match_finite_differences_anywhere(
        v in 0.0f64..35.0, psi in -7.0f64..7.0, delta in -0.5f64..0.5,
        a in -8.0f64..6.0, r in -0.5f64..0.5, lag in 0.0f64..0.03,
    ) {
        assert_lagged_jacobians_match([3.0, 10.0, -2.0, v, psi, delta], [a, r], 0.1, lag);
    }
}

proptest! {
    /// The MPC's sensitivity propagation takes the columns of `A` before
    /// `FIRST_LIVE` as the identity's, exactly (in f32, as on the ECU).
    #[test]
    fn the_jacobian_is_the_identity_in_the_columns_before_the_live_ones(
        v in 0.0f32..35.0, psi in -7.0f32..7.0, delta in -0.5f32..0.5,
        a in -8.0f32..6.0, r in -0.5f32..0.5, lag in 0.0f32..0.03,
    ) {
        let g = BicycleGeometry { l_f_m: 1.2f32, l_r_m: 1.6 };
        let x = [3.0f32, 10.0, -2.0, v, psi, delta];
        let d = g.discretize_lagged(&x, &[a, r], 0.1, Real::tan(delta), lag);
        for (i, row) in d.a.iter().enumerate() {
            for (j, &aij) in row.iter().enumerate().take(FIRST_LIVE) {
                prop_assert_eq!(aij.to_bits(), if i == j { 1.0f32 } else { 0.0 }.to_bits());
            }
        }
    }
}

#[test]
fn the_lagged_course_turns_out_of_the_bend_by_lag_times_lateral_acceleration() {
    let g = geom();
    // A left bend at 20 m/s, steering held: the heading turns as the kinematic
    // car's, the course lags it by λ·a_y.
    let (v, delta, lag) = (20.0, 0.04, 0.015);
    let x = [0.0, 0.0, 0.0, v, 0.0, delta];
    let kin = g.step_lagged(&x, &[0.0, 0.0], 0.01, 0.0);
    let lagged = g.step_lagged(&x, &[0.0, 0.0], 0.01, lag);
    assert_eq!(kin[PSI], lagged[PSI]);
    let beta = g.beta_rad(delta);
    let ay = v * v * beta.sin() / g.l_r_m;
    let course = |s: [f64; 6]| s[Y].atan2(s[X]);
    let turn = course(lagged) - course(kin);
    assert!(
        (turn + lag * ay).abs() < 1e-2 * lag * ay,
        "course turned {turn}, expected {}",
        -lag * ay
    );
    // And the speed along it is the same.
    assert!((lagged[X].hypot(lagged[Y]) - kin[X].hypot(kin[Y])).abs() < 1e-5);
}
