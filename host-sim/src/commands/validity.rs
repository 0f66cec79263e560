//! `host-sim validity`: the paper's Figure 3 ([`crate::closed_loop::validity`]),
//! its CSV, its plot and the lateral accelerations where the steering departs from
//! the kinematic bicycle's.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};

use crate::closed_loop::validity::{run_experiment, summary_line, ValidityConfig};
use crate::model::vehicle::{VehicleParams, G};
use crate::output::validity_files::{write_csv, write_plot};

/// Command-line arguments of `host-sim validity`.
#[derive(Debug, Clone, clap::Args)]
pub struct ValidityArgs {
    /// Vehicle file (TOML, see host-sim/vehicles/default.toml); the built-in car
    /// when omitted.
    #[arg(long, value_name = "V.toml")]
    pub vehicle: Option<PathBuf>,
    /// Road friction coefficient μ (1 = dry asphalt, the tyre's reference surface).
    #[arg(long, default_value_t = 1.0)]
    pub mu: f64,
    /// Circle radii, m, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "10,20,40,80")]
    pub radii: Vec<f64>,
    /// Output directory (created if missing) for validity.csv and validity.png.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Integration step of the plant, s.
    #[arg(long, default_value_t = crate::model::plant::DEFAULT_DT_S)]
    pub dt: f64,
}

/// `host-sim validity`: runs the experiment, writes the CSV and the plot, prints the
/// thresholds per radius.
pub fn run(args: &ValidityArgs) -> anyhow::Result<()> {
    let params = match &args.vehicle {
        Some(p) => VehicleParams::from_toml_file(p)?,
        None => VehicleParams::default(),
    };
    if args.radii.is_empty() {
        anyhow::bail!("--radii: give at least one radius, e.g. --radii 10,20,40,80");
    }
    let cfg = ValidityConfig {
        mu: args.mu,
        dt_s: args.dt,
        ..ValidityConfig::default()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output directory {}", args.out.display()))?;
    let total = (args.radii.len() * (cfg.steps_to_friction_limit + 1)) as u64;
    let progress = ProgressBar::new(total);
    if let Ok(style) = ProgressStyle::with_template("{bar:40} {pos}/{len} steady states {elapsed}")
    {
        progress.set_style(style);
    }
    let sweeps = run_experiment(&params, &args.radii, &cfg, &progress)?;
    progress.finish_and_clear();
    let csv_path = args.out.join("validity.csv");
    write_csv(&csv_path, &sweeps)?;
    let png_path = args.out.join("validity.png");
    write_plot(&png_path, &sweeps, cfg.mu)?;
    println!(
        "Lateral acceleration at which |delta_a - delta_th|/delta_th first exceeds 5/10/20 % \
         (mu = {}, 0.5 mu g = {:.2} m/s2):",
        cfg.mu,
        0.5 * cfg.mu * G
    );
    for s in &sweeps {
        println!("  {}", summary_line(s, cfg.mu));
    }
    println!("wrote {} and {}", csv_path.display(), png_path.display());
    Ok(())
}
