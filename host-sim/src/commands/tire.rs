//! `host-sim tire`: the tyre forces of a CSV of slips ([`crate::model::tire_table`]).

use std::path::PathBuf;

use anyhow::Context;

use crate::model::tire_table::{compute, read_slips};
use crate::model::vehicle::VehicleParams;

/// Command-line arguments of `host-sim tire`.
#[derive(Debug, Clone, clap::Args)]
pub struct TireArgs {
    /// Vehicle file (TOML) whose `[tyre]` is used; the built-in tyre when omitted.
    #[arg(long, value_name = "V.toml")]
    pub vehicle: Option<PathBuf>,
    /// Input CSV with header kappa,alpha_rad,fz_n,mu.
    #[arg(long, value_name = "IN.csv")]
    pub input: PathBuf,
    /// Output CSV: the input columns plus fx_n,fy_n.
    #[arg(long, value_name = "OUT.csv")]
    pub out: PathBuf,
}

/// `host-sim tire`.
pub fn run(args: &TireArgs) -> anyhow::Result<()> {
    let params = match &args.vehicle {
        Some(p) => VehicleParams::from_toml_file(p)?,
        None => VehicleParams::default(),
    };
    let rows = read_slips(&args.input)?;
    let out = compute(&rows, &params.tyre);
    let mut w = csv::Writer::from_path(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for r in &out {
        w.serialize(r)
            .with_context(|| format!("cannot write {}", args.out.display()))?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    Ok(())
}
