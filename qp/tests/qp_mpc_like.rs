//! A condensed MPC shaped like the firmware's (N = 32 inputs, W = 48; up to 96 rows,
//! more than the firmware MPC's 80) on a
//! receding horizon: two double integrators (x, y) over 16 steps of 0.2 s tracking a
//! lane change around an obstacle, with hard rate and speed rows, soft corridor and
//! obstacle rows, and bounds on the inputs. Checks f32 against f64 at every step, and
//! that warm starts take fewer iterations than cold starts.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

mod qp_util;

use qp::{ldl_len, QpProblem, QpSolver, QpStatus};
use qp_util::{max_abs_diff, to_f32_into};

const K: usize = 16;
const N: usize = 2 * K;
const M: usize = 96;
const W: usize = 48;
const DT: f64 = 0.2;

#[derive(Clone, Copy)]
struct State {
    px: f64,
    py: f64,
    vx: f64,
    vy: f64,
}

fn lane_y(x: f64) -> f64 {
    // Lane change to y = 3.5 between x = 60 and 75, back between 160 and 175.
    let s = |a: f64, b: f64| ((x - a) / (b - a)).clamp(0.0, 1.0);
    let sm = |t: f64| t * t * (3.0 - 2.0 * t);
    3.5 * (sm(s(60.0, 75.0)) - sm(s(160.0, 175.0)))
}

/// Fills the condensed QP for the state `x0` (in f64).
fn build(x0: State) -> QpProblem<f64, N, M> {
    let mut p = QpProblem::<f64, N, M>::new();
    // Position k (1..=K) of one axis as Φ_k·u + c_k.
    let phi = |k: usize, j: usize| {
        if j < k {
            DT * DT * (k as f64 - j as f64 - 0.5)
        } else {
            0.0
        }
    };
    let (qp_, ru, rdu) = (5.0, 0.2, 4.0);
    let vref = 20.0;
    for axis in 0..2 {
        let off = axis * K;
        let (p0, v0) = if axis == 0 {
            (x0.px, x0.vx)
        } else {
            (x0.py, x0.vy)
        };
        for k in 1..=K {
            let c = p0 + k as f64 * DT * v0;
            let r = if axis == 0 {
                x0.px + vref * k as f64 * DT
            } else {
                lane_y(x0.px + vref * k as f64 * DT)
            };
            for a in 0..K {
                p.f[off + a] += 2.0 * qp_ * phi(k, a) * (c - r);
                for b in 0..K {
                    p.h[off + a][off + b] += 2.0 * qp_ * phi(k, a) * phi(k, b);
                }
            }
        }
        for j in 0..K {
            p.h[off + j][off + j] += 2.0 * ru;
            if j + 1 < K {
                p.h[off + j][off + j] += 2.0 * rdu;
                p.h[off + j + 1][off + j + 1] += 2.0 * rdu;
                p.h[off + j][off + j + 1] -= 2.0 * rdu;
                p.h[off + j + 1][off + j] -= 2.0 * rdu;
            }
            p.x_lo[off + j] = if axis == 0 { -8.0 } else { -3.0 };
            p.x_hi[off + j] = if axis == 0 { 6.0 } else { 3.0 };
        }
        // Hard rate rows |u_{j+1} − u_j| ≤ 1.
        for j in 0..K - 1 {
            let mut a = [0.0; N];
            a[off + j + 1] = 1.0;
            a[off + j] = -1.0;
            p.push_row(&a, -1.0, 1.0, 0.0);
        }
    }
    // Hard speed rows 0 ≤ v_x,k ≤ 16.
    for k in 1..=K {
        let mut a = [0.0; N];
        for j in 0..k {
            a[j] = DT;
        }
        p.push_row(&a, -x0.vx, 16.0 - x0.vx, 0.0);
    }
    // Soft corridor rows |p_y,k − lane| ≤ 1.5 (lane at the nominal x of step k), and
    // soft obstacle rows p_y,k ≥ 4.2 while the nominal x is in [110, 140].
    for k in 1..=K {
        let mut a = [0.0; N];
        for j in 0..K {
            a[K + j] = phi(k, j);
        }
        let c = x0.py + k as f64 * DT * x0.vy;
        let xk = x0.px + x0.vx * k as f64 * DT;
        let l = lane_y(xk);
        p.push_row(&a, l - 1.5 - c, l + 1.5 - c, 100.0);
        if (110.0..=140.0).contains(&xk) {
            p.push_row(&a, 4.2 - c, f64::INFINITY, 100.0);
        }
    }
    p
}

#[test]
fn condensed_mpc_receding_horizon() {
    type S64 = QpSolver<f64, N, M, W, { ldl_len(W) }>;
    type S32 = QpSolver<f32, N, M, W, { ldl_len(W) }>;
    let mut cold64 = Box::new(S64::new());
    cold64.settings.warm_start = false;
    let mut warm64 = Box::new(S64::new());
    let mut cold32 = Box::new(S32::new());
    cold32.settings.warm_start = false;
    let mut warm32 = Box::new(S32::new());
    let mut x = State {
        px: 0.0,
        py: 0.0,
        vx: 14.0,
        vy: 0.0,
    };
    let (mut ic64, mut iw64, mut ic32, mut iw32) = (0u32, 0u32, 0u32, 0u32);
    let (mut worst_du, mut max_m, mut max_ws) = (0.0f64, 0usize, 0usize);
    let mut worst_cold32 = 0u32;
    let mut worst_warm32 = 0u32;
    for step in 0..100 {
        let p = build(x);
        max_m = max_m.max(p.m);
        *cold64.problem_mut() = p.clone();
        *warm64.problem_mut() = p.clone();
        to_f32_into(&p, cold32.problem_mut());
        to_f32_into(&p, warm32.problem_mut());
        for (name, st) in [
            ("cold64", cold64.solve()),
            ("warm64", warm64.solve()),
            ("cold32", cold32.solve()),
            ("warm32", warm32.solve()),
        ] {
            assert_eq!(st, QpStatus::Optimal, "step {step} {name}");
        }
        ic64 += cold64.solution().iterations;
        iw64 += warm64.solution().iterations;
        ic32 += cold32.solution().iterations;
        iw32 += warm32.solution().iterations;
        worst_cold32 = worst_cold32.max(cold32.solution().iterations);
        worst_warm32 = worst_warm32.max(warm32.solution().iterations);
        max_ws = max_ws.max(warm32.working_set().len());
        let u64_ = cold64.solution().x;
        for (a, b) in u64_.iter().zip(warm64.solution().x.iter()) {
            assert!((a - b).abs() < 1e-8, "step {step}: warm/cold f64 differ");
        }
        for s32 in [&cold32, &warm32] {
            let du = max_abs_diff(&u64_, &s32.solution().x);
            worst_du = worst_du.max(du);
            // Inputs are in m/s² (range ±8): 1e-2 m/s² in f32.
            assert!(du < 1e-2, "step {step}: f32 input differs by {du}");
        }
        // Apply the first inputs exactly to the double integrators.
        let (ax, ay) = (u64_[0], u64_[K]);
        x.px += DT * x.vx + 0.5 * DT * DT * ax;
        x.vx += DT * ax;
        x.py += DT * x.vy + 0.5 * DT * DT * ay;
        x.vy += DT * ay;
    }
    println!(
        "condensed MPC, 100 steps (m ≤ {max_m}, |W| ≤ {max_ws}): f64 cold {ic64} / warm {iw64}, \
         f32 cold {ic32} (worst {worst_cold32}) / warm {iw32} (worst {worst_warm32}) iterations; \
         worst |Δu| f32 vs f64 {worst_du:e}"
    );
    assert!(iw64 < ic64 && iw32 < ic32);
    assert!(
        x.py.abs() < 1.0 && x.px > 200.0,
        "the plant should have passed the manoeuvre: {:.1} {:.2}",
        x.px,
        x.py
    );
}
