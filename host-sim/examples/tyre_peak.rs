//! The lateral force of a vehicle file's tyre against its slip angle, pure
//! slip at the front wheels' static load, at road friction 1, 0.5 and 0.3: where
//! it peaks and how much of the peak it gives at a few angles (the reference of
//! `firmware::tasks::FRONT_SLIP_HOLD_RAD`).
//!
//! `cargo run --release -p host-sim --example tyre_peak -- host-sim/vehicles/*.toml`

use host_sim::model::{tire, vehicle::VehicleParams};

fn main() {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.is_empty() {
        eprintln!("usage: tyre_peak VEHICLE.toml...");
        std::process::exit(2);
    }
    for f in files {
        let v = match VehicleParams::from_toml_file(&f) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("{f}: {e}");
                std::process::exit(1);
            }
        };
        let fz = v.static_loads_n()[0];
        for mu in [1.0, 0.5, 0.3] {
            let fy = |alpha: f64| tire::forces(0.0, alpha, fz, mu, &v.tyre).1.abs();
            // The peak on a 1 mrad grid up to 0.6 rad (the mechanical lock).
            let (alpha_peak, fy_peak) = (1..=600)
                .map(|i| (f64::from(i) * 1e-3, fy(f64::from(i) * 1e-3)))
                .fold((0.0, 0.0), |b, p| if p.1 > b.1 { p } else { b });
            let shares: Vec<String> = [0.05, 0.1, 0.15, 0.2, 0.3, 0.6]
                .iter()
                .map(|&a| format!("{a} rad {:.0} %", 100.0 * fy(a) / fy_peak))
                .collect();
            println!(
                "{f}: mu {mu}: front load {fz:.0} N, peak at {alpha_peak:.3} rad (Fy/(mu Fz) {:.3}); {}",
                fy_peak / (mu * fz),
                shares.join(", ")
            );
        }
    }
}
