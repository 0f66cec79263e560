//! What `host-sim pil` adds to `run`'s outputs: `pil.json`, written by `pil` and
//! read back through this same type.

use crate::closed_loop::cost_model::{CostModel, ModelError};
use crate::closed_loop::ecu::EcuCounts;
use crate::pil::comparison::Comparison;
use crate::pil::deadlines::TickOverruns;
use crate::pil::qemu::InjectedFrames;
use firmware::link::RefusalCounts;

/// A link fault of the run, in `pil.json`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinkFaultReport {
    /// The fault, `KIND:N`.
    pub fault: String,
    /// Its first replaced sensor frame's instant, s.
    pub start_s: f64,
    /// The frames injected and what the ECU did with them.
    pub frames: InjectedFrames,
}

/// What `host-sim pil` adds to `run`'s outputs (`pil.json`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PilReport {
    /// QEMU's `-icount shift`.
    pub icount_shift: u32,
    /// Virtual time per instruction, ns.
    pub ns_per_instruction: f64,
    /// The ECU application run.
    pub elf: String,
    /// Deepest stack use seen on the ECU (painted stack), bytes.
    pub stack_high_water_bytes: u32,
    /// The ECU's stack region, bytes.
    pub stack_size_bytes: u32,
    /// Frames the ECU refused.
    pub ecu_rejected_frames: u32,
    /// Of those, the ones refused by reason (forged, replayed, corrupt), frames.
    pub ecu_refused_frames: RefusalCounts,
    /// Frames the host refused.
    pub host_rejected_frames: u64,
    /// Of those (the ECU's frames), the ones refused by reason, frames.
    pub host_refused_frames: RefusalCounts,
    /// The link fault injected (`--link-fault`), and what the ECU did with its
    /// frames; null without one.
    pub link_fault: Option<LinkFaultReport>,
    /// Actuation frames answering an older sensor frame.
    pub stale_frames: u64,
    /// Largest control activation, instructions.
    pub control_max_instructions: f64,
    /// Median control activation, instructions.
    pub control_p50_instructions: f64,
    /// Largest plan activation, instructions.
    pub plan_max_instructions: f64,
    /// Largest warm (one-pass) plan activation, instructions.
    pub warm_max_instructions: f64,
    /// Largest cold-start plan activation, instructions.
    pub cold_max_instructions: f64,
    /// The simulator's cost model against the measurements.
    pub model_error: ModelError,
    /// The cost model refitted on this run's activations.
    pub refit: Option<CostModel>,
    /// Against the in-process run (f32, same inputs).
    pub comparison: Option<Comparison>,
    /// The host's count of budget overruns on the ECU's clock (from the frames'
    /// ticks), beside the ECU's own (`summary.json`'s `ecu_*_budget_overruns`).
    pub tick_overruns: TickOverruns,
    /// Where the ECU's own deadline counts differ from the host's (empty: they
    /// agree; otherwise `host-sim pil` fails).
    pub count_mismatches: Vec<String>,
    /// The ECU's own counts at the end of the run, per task: releases, misses,
    /// skipped releases, budget overruns, largest response time (µs); watchdog
    /// trips.
    pub ecu_counts: Option<EcuCounts>,
    /// Wall time of the PIL run, s.
    pub wall_s: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pil_json_reads_back_as_written() -> anyhow::Result<()> {
        let report = PilReport {
            icount_shift: 4,
            ns_per_instruction: 16.0,
            elf: "target/thumbv7em-none-eabihf/release/ecu".into(),
            stack_high_water_bytes: 6216,
            stack_size_bytes: 80200,
            plan_max_instructions: 994430.5,
            refit: Some(CostModel::default()),
            comparison: Some(Comparison {
                rows_compared: 2001,
                identical: false,
                first_divergence_s: Some(12.5),
                cause: "a different 10 ms control period".into(),
            }),
            tick_overruns: TickOverruns {
                plan: 1,
                control: 2,
            },
            count_mismatches: vec!["plan deadline misses: ECU 1, host 0".into()],
            ecu_counts: Some(EcuCounts::default()),
            ecu_refused_frames: RefusalCounts {
                auth: 20,
                replay: 0,
                corrupt: 1,
            },
            link_fault: Some(LinkFaultReport {
                fault: "forge:20".into(),
                start_s: 20.0,
                frames: InjectedFrames {
                    injected: RefusalCounts {
                        auth: 20,
                        ..RefusalCounts::default()
                    },
                    refused_as_expected: 20,
                    ..InjectedFrames::default()
                },
            }),
            ..PilReport::default()
        };
        let back: PilReport = serde_json::from_str(&serde_json::to_string_pretty(&report)?)?;
        assert_eq!(back, report);
        Ok(())
    }
}
