//! What the analyses know of the ECU's sources: the firmware's constants its loop
//! annotations may name (read from the firmware crate itself, so they cannot
//! drift from the code), the loop bounds of the dependencies' code it runs, and
//! the workspace's crates whose sources carry annotations.

use ::wcet::annotations::{Annotation, Scope, SourceDir};
use std::collections::BTreeMap;
use std::path::Path;

/// The firmware's constants an annotation may name, with their values (read from
/// the firmware crate itself, so they cannot drift from the code).
pub fn firmware_constants() -> BTreeMap<&'static str, u64> {
    use firmware::{link, mpc, obstacles, plan, tasks};
    BTreeMap::from([
        ("HORIZON", plan::HORIZON as u64),
        // The flashed build's USART link.
        ("RX_BUDGET_BYTES", u64::from(link::usart::RX_BUDGET_BYTES)),
        ("NX", firmware::bicycle::NX as u64),
        ("NU", firmware::bicycle::NU as u64),
        ("NV", mpc::NV as u64),
        ("NC", mpc::NC as u64),
        ("WS", mpc::WS as u64),
        ("ROWS_PER_NODE", mpc::ROWS_PER_NODE as u64),
        ("MAX_OBSTACLE_ROWS", mpc::MAX_OBSTACLE_ROWS as u64),
        ("QP_MAX_ITER", u64::from(mpc::QP_MAX_ITER)),
        ("COLD_START_PASSES", u64::from(mpc::COLD_START_PASSES)),
        (
            "QP_MAX_REFACTORIZATIONS",
            u64::from(mpc::QP_MAX_REFACTORIZATIONS),
        ),
        ("QP_APPEND_ROWS", mpc::QP_APPEND_ROWS),
        ("QP_APPEND_GROUPS", mpc::QP_APPEND_GROUPS),
        ("MAX_OBSTACLES", obstacles::MAX_OBSTACLES as u64),
        ("MAX_VERTICES", obstacles::MAX_VERTICES as u64),
        (
            "MAX_CURVATURE_WINDOW_STEPS",
            firmware::reference_path::MAX_CURVATURE_WINDOW_STEPS as u64,
        ),
        ("ECU_PATH_ROWS", tasks::ECU_PATH_ROWS as u64),
        (
            "MAX_SEARCH_SEGMENTS",
            firmware::reference_path::MAX_SEARCH_SEGMENTS as u64,
        ),
        ("PATH_CHUNK_ROWS", link::PATH_CHUNK_ROWS as u64),
        ("MAX_FRAME_BYTES", link::MAX_FRAME_BYTES as u64),
        ("MAX_DOWN_FRAME_BYTES", link::MAX_DOWN_FRAME_BYTES as u64),
        ("MAX_UP_FRAME_BYTES", link::MAX_UP_FRAME_BYTES as u64),
        (
            "MAX_UP_MAC_INPUT_BYTES",
            link::MAX_UP_MAC_INPUT_BYTES as u64,
        ),
        (
            "MAX_DOWN_MAC_INPUT_BYTES",
            link::MAX_DOWN_MAC_INPUT_BYTES as u64,
        ),
        (
            "MAX_DRIVING_DOWN_MAC_INPUT_BYTES",
            link::MAX_DRIVING_DOWN_MAC_INPUT_BYTES as u64,
        ),
        (
            "MAX_DRIVING_DOWN_FRAME_BYTES",
            link::MAX_DRIVING_DOWN_FRAME_BYTES as u64,
        ),
        (
            "ROUTE_FRAMES",
            link::route_frames(tasks::ECU_PATH_ROWS) as u64,
        ),
        ("TORQUE_HISTORY", firmware::friction::TORQUE_HISTORY as u64),
        (
            "ECU_PATH_SEARCH_STEPS",
            firmware::reference_path::ECU_PATH_SEARCH_STEPS as u64,
        ),
    ])
}

/// Loop bounds of the dependencies' code the ECU runs (whose sources are not
/// ours to annotate), each keyed by the crate's file (`crate-version/src/file.rs`,
/// as the DWARF line table names it, so a new version of the crate is not
/// matched) and the line the analysis reports for the loop, with why it holds.
/// Checked against the traces like the firmware's annotations.
pub fn dependency_facts() -> Vec<Annotation> {
    dependency_facts_with(&firmware_constants())
}

/// [`dependency_facts`] with the firmware's `constants` bound as given (a task's
/// light activations, [`super::ecu_app::LightActivations`]): none of today's
/// facts depends on them (the link's encoder, whose bound did, is the firmware's
/// own code, annotated there).
pub fn dependency_facts_with(_constants: &BTreeMap<&'static str, u64>) -> Vec<Annotation> {
    let fact = |file: &str, line: u32, bound: u64, why: &str| Annotation {
        file: file.to_string(),
        line,
        expression: format!("{bound} ({why})"),
        bound,
        scope: Scope::Entry,
        within: None,
        counter: None,
    };
    let mut facts = vec![fact(
        "crc-3.4.0/src/crc32.rs",
        150,
        15,
        "the bytes left after the 16-byte slices",
    )];
    // compiler_builtins' u64 division (`u64_div_rem`, the delegate algorithm):
    // restoring long division, one quotient bit per step, the bit `pow_lo`
    // (`1 << shl`, shl < 32) shifted right each step, returning before it reaches
    // 0: at most 32 steps. The binary's three loops do 4 steps a pass (their
    // latches shift `pow_lo` by 4): 8 back edges.
    for line in [94, 154, 179] {
        facts.push(fact(
            "int/specialized_div_rem/delegate.rs",
            line,
            8,
            "restoring division: 32 quotient bits, 4 a pass",
        ));
    }
    facts
}

/// The workspace's crates whose code the ECU runs and whose sources carry loop
/// annotations, as their source folders from the workspace root (which is also
/// how the reports name their files: `qp/src/factor.rs`).
pub const FIRMWARE_CRATE_SOURCES: [&str; 2] = ["firmware/src", "qp/src"];

/// The source folders of [`FIRMWARE_CRATE_SOURCES`] under the workspace root
/// `root`.
pub fn workspace_sources(root: &Path) -> Vec<SourceDir> {
    FIRMWARE_CRATE_SOURCES
        .iter()
        .map(|&label| SourceDir {
            dir: root.join(label),
            label,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_real_sources_carry_the_qp_and_firmware_annotations() {
        // The QP's iteration cap is read from the qp crate.
        let a = ::wcet::annotations::scan_sources_with(
            &workspace_sources(Path::new("..")),
            &firmware_constants(),
        )
        .unwrap_or_default();
        assert!(a
            .iter()
            .any(|a| a.file.starts_with("qp/src/") && a.expression == "QP_MAX_ITER"));
        assert!(a.iter().any(|a| a.file == "firmware/src/mpc.rs"));
    }
}
