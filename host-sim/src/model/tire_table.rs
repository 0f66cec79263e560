//! Tyre forces for a table of slips (what `host-sim tire` computes).
//!
//! Input CSV with header `kappa,alpha_rad,fz_n,mu`; output CSV with the same columns
//! plus `fx_n,fy_n`, the combined-slip forces in the tyre frame (N) of
//! [`crate::model::tire::forces`] for the vehicle's tyre (the left-hand, unmirrored one).

use std::path::Path;

use anyhow::Context;

use crate::model::tire::{self, TireParams};

/// One input row.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlipRow {
    /// Slip ratio, dimensionless (positive when driving).
    pub kappa: f64,
    /// Slip angle, rad (positive when the wheel points left of its velocity).
    pub alpha_rad: f64,
    /// Normal load, N.
    pub fz_n: f64,
    /// Road friction coefficient.
    pub mu: f64,
}

/// One output row.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ForceRow {
    /// Slip ratio, dimensionless.
    pub kappa: f64,
    /// Slip angle, rad.
    pub alpha_rad: f64,
    /// Normal load, N.
    pub fz_n: f64,
    /// Road friction coefficient.
    pub mu: f64,
    /// Longitudinal force, tyre frame, N.
    pub fx_n: f64,
    /// Lateral force, tyre frame, N.
    pub fy_n: f64,
}

/// Reads the slips of `input`, checking every row (errors name the file and line).
pub fn read_slips(input: &Path) -> anyhow::Result<Vec<SlipRow>> {
    let name = input.display();
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(input)
        .with_context(|| format!("cannot read {name}"))?;
    let mut rows = Vec::new();
    for (i, rec) in reader.deserialize::<SlipRow>().enumerate() {
        let line = i + 2;
        let row = rec.map_err(|e| {
            let line = e.position().map_or(line as u64, |p| p.line());
            anyhow::anyhow!(
                "{name} line {line}: {e}; each row needs four numbers under the header \
                 kappa,alpha_rad,fz_n,mu"
            )
        })?;
        for (col, v) in [
            ("kappa", row.kappa),
            ("alpha_rad", row.alpha_rad),
            ("fz_n", row.fz_n),
            ("mu", row.mu),
        ] {
            if !v.is_finite() {
                anyhow::bail!("{name} line {line}: {col} must be a finite number, got {v}");
            }
        }
        if row.fz_n < 0.0 {
            anyhow::bail!(
                "{name} line {line}: fz_n must be zero or positive, got {}",
                row.fz_n
            );
        }
        if row.mu < 0.0 {
            anyhow::bail!(
                "{name} line {line}: mu must be zero or positive, got {}",
                row.mu
            );
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Forces for each row.
pub fn compute(rows: &[SlipRow], tyre: &TireParams) -> Vec<ForceRow> {
    rows.iter()
        .map(|r| {
            let (fx, fy) = tire::forces(r.kappa, r.alpha_rad, r.fz_n, r.mu, tyre);
            ForceRow {
                kappa: r.kappa,
                alpha_rad: r.alpha_rad,
                fz_n: r.fz_n,
                mu: r.mu,
                fx_n: fx,
                fy_n: fy,
            }
        })
        .collect()
}
