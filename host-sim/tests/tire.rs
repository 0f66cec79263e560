//! PAC2002 tyre: pure-slip sanity and the friction ellipse of combined slip.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::model::tire::{forces, pure_slip_forces, TireParams};

fn grid(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f64> {
    (0..=n).map(move |i| lo + (hi - lo) * i as f64 / n as f64)
}

/// Peaks of the pure-slip forces `|F_x0(κ)|` and `|F_y0(α)|`, N.
fn pure_peaks(fz: f64, mu: f64, p: &TireParams) -> (f64, f64) {
    let px = grid(-1.0, 1.0, 4000)
        .map(|k| pure_slip_forces(k, 0.0, fz, mu, p).0.abs())
        .fold(0.0, f64::max);
    let py = grid(-1.5, 1.5, 4000)
        .map(|a| pure_slip_forces(0.0, a, fz, mu, p).1.abs())
        .fold(0.0, f64::max);
    (px, py)
}

#[test]
fn combined_force_never_exceeds_the_larger_pure_slip_peak() {
    let p = TireParams::default();
    let mut worst = 0.0_f64;
    for fz in [1000.0, 2500.0, 4000.0, 6000.0, 8000.0] {
        for mu in [0.3, 0.6, 1.0] {
            let (px, py) = pure_peaks(fz, mu, &p);
            let bound = px.max(py);
            for k in grid(-1.0, 1.0, 200) {
                for a in grid(-0.6, 0.6, 200) {
                    let (fx, fy) = forces(k, a, fz, mu, &p);
                    let f = fx.hypot(fy);
                    worst = worst.max(f / bound);
                    // 1e-4: resolution of the grid search for the pure-slip peaks.
                    assert!(
                        f <= bound * (1.0 + 1e-4),
                        "fz={fz} mu={mu} kappa={k} alpha={a}: |F|={f} > {bound}"
                    );
                }
            }
        }
    }
    // The bound is reached (the ellipse is the limit), not far inside it.
    assert!(worst > 0.99, "{worst}");
}

#[test]
fn longitudinal_force_is_odd_ish_with_its_peak_near_mu_fz_pdx1() {
    let p = TireParams::default();
    for mu in [0.5, 1.0] {
        let fz = p.fnomin;
        let peak = grid(0.0, 1.0, 2000)
            .map(|k| forces(k, 0.0, fz, mu, &p).0)
            .fold(f64::MIN, f64::max);
        let expected = mu * fz * p.pdx1;
        assert!(
            (peak - expected).abs() < 0.03 * expected,
            "{peak} vs {expected}"
        );
        for k in [0.05, 0.1, 0.3] {
            let (fp, _) = forces(k, 0.0, fz, mu, &p);
            let (fm, _) = forces(-k, 0.0, fz, mu, &p);
            assert!(fp > 0.0 && fm < 0.0);
            // Odd up to the small shifts S_Hx.
            assert!((fp + fm).abs() < 0.1 * fp, "kappa={k}: {fp} {fm}");
        }
    }
}

#[test]
fn lateral_force_has_the_sign_of_the_slip_angle_and_its_peak_near_mu_fz_pdy1() {
    let p = TireParams::default();
    let fz = p.fnomin;
    for a in [0.01, 0.05, 0.1, 0.3] {
        assert!(forces(0.0, a, fz, 1.0, &p).1 > 0.0);
        assert!(forces(0.0, -a, fz, 1.0, &p).1 < 0.0);
    }
    let peak = grid(0.0, 1.0, 2000)
        .map(|a| forces(0.0, a, fz, 1.0, &p).1)
        .fold(f64::MIN, f64::max);
    let expected = fz * p.pdy1.abs();
    assert!(
        (peak - expected).abs() < 0.05 * expected,
        "{peak} vs {expected}"
    );
}

#[test]
fn friction_scales_the_peaks() {
    let p = TireParams::default();
    let (px1, py1) = pure_peaks(4000.0, 1.0, &p);
    let (px5, py5) = pure_peaks(4000.0, 0.5, &p);
    assert!((px5 / px1 - 0.5).abs() < 0.02, "{}", px5 / px1);
    assert!((py5 / py1 - 0.5).abs() < 0.02, "{}", py5 / py1);
}

#[test]
fn combined_slip_reduces_each_force() {
    let p = TireParams::default();
    let (fx_pure, _) = forces(0.1, 0.0, 4000.0, 1.0, &p);
    let (fx_comb, _) = forces(0.1, 0.1, 4000.0, 1.0, &p);
    assert!(fx_comb < 0.9 * fx_pure);
    let (_, fy_pure) = forces(0.0, 0.1, 4000.0, 1.0, &p);
    let (_, fy_comb) = forces(0.1, 0.1, 4000.0, 1.0, &p);
    assert!(fy_comb < 0.9 * fy_pure);
}
