//! Worst-case analyses on the real ECU binary `mpc_step`. The tests that read it are
//! ignored by `cargo test` and fail when it is missing: build it first (`.ci/ecu-check`
//! does, or `cargo build --release -p firmware --target thumbv7em-none-eabihf
//! --features ecu --bin mpc_step`), then `cargo test -p host-sim --test wcet_ecu --
//! --ignored --skip cpi_bound_of_a_qemu_log` (as `.ci/run` does). They also need
//! `llvm-objdump` (`rustup component add llvm-tools`). `cpi_bound_of_a_qemu_log` is
//! run by hand on a QEMU log.
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;

use host_sim::wcet::cpi::{analyse_log, elf_functions, Region};
use host_sim::wcet::stack::{analyse_elf, llvm_objdump_path, PriorityLevel};

/// How to build `mpc_step`.
const BUILD: &str =
    "cargo build --release -p firmware --target thumbv7em-none-eabihf --features ecu --bin mpc_step";

/// `WCET_ELF`, or `mpc_step` in the workspace's target directory (which may not
/// exist).
fn mpc_step_path() -> PathBuf {
    std::env::var_os("WCET_ELF")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let target = std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target"));
            target.join("thumbv7em-none-eabihf/release/mpc_step")
        })
}

/// The `mpc_step` binary; fails when it has not been built.
fn mpc_step() -> PathBuf {
    let path = mpc_step_path();
    assert!(
        path.is_file(),
        "the ECU binary {} is missing: build it first ({BUILD})",
        path.display()
    );
    path
}

#[test]
#[ignore = "needs the ECU binary mpc_step (cargo build --release -p firmware --target thumbv7em-none-eabihf --features ecu --bin mpc_step) and llvm-objdump; .ci/run runs it"]
fn stack_bound_of_mpc_step_main() {
    let elf = mpc_step();
    if let Err(e) = llvm_objdump_path() {
        panic!("llvm-objdump is needed: {e}");
    }
    let levels = [
        PriorityLevel {
            name: "thread".into(),
            roots: vec!["main".into()],
        },
        PriorityLevel {
            name: "SysTick".into(),
            roots: vec!["SysTick".into()],
        },
    ];
    let report = analyse_elf(&elf, &levels).expect("analysing mpc_step");
    println!("{}", serde_json::to_string_pretty(&report).unwrap());
    let main = &report.levels[0].roots[0];
    // main → the entry function → the MPC step: the path goes through the planner.
    assert!(main
        .worst_path
        .iter()
        .any(|e| e.function.starts_with("firmware::")));
    let path_sum: u32 = main.worst_path.iter().map(|e| e.frame_bytes).sum();
    assert_eq!(path_sum, main.depth_bytes);
    // The MPC's workspaces are statics: the stack stays well under the 128 KB of RAM,
    // and the step's own frame (kilobytes of condensing temporaries) is counted.
    assert!(
        main.depth_bytes > 1024 && main.depth_bytes < 64 * 1024,
        "{}",
        main.depth_bytes
    );
    // No function counted once, none masked: the bound is the sum of the levels,
    // HardFault and NMI (from the vector table) on top.
    let sum: u32 = report.levels.iter().map(|l| l.contribution_bytes).sum();
    assert_eq!(report.total_bytes, sum);
    let listed: Vec<&str> = report
        .levels
        .iter()
        .flat_map(|l| &l.roots)
        .flat_map(|r| r.exceptions.iter().map(String::as_str))
        .collect();
    assert!(
        listed.contains(&"HardFault") && listed.contains(&"NMI") && listed.contains(&"SysTick"),
        "{listed:?}"
    );
    assert!(report.unplaced_handlers.is_empty());
    // The formatting machinery calls through `dyn Write`: reported, bound unsound.
    assert!(!report.indirect_calls.is_empty());
    assert!(!report.sound);
}

/// Run by hand on a log written by
/// `qemu-system-arm ... -d in_asm,exec,nochain -D LOG -kernel mpc_step`:
/// `WCET_QEMU_LOG=LOG cargo test -p host-sim --test wcet_ecu -- --ignored --exact
/// cpi_bound_of_a_qemu_log --nocapture` (regions of `mpc_step` when it is built).
#[test]
#[ignore = "by hand: needs WCET_QEMU_LOG, a qemu-system-arm -d in_asm,exec,nochain log"]
fn cpi_bound_of_a_qemu_log() {
    let log = std::env::var_os("WCET_QEMU_LOG")
        .map(PathBuf::from)
        .expect("set WCET_QEMU_LOG to a qemu-system-arm -d in_asm,exec,nochain log");
    let limit = std::env::var("WCET_MAX_TBS")
        .ok()
        .and_then(|s| s.parse().ok());
    let elf = mpc_step_path();
    let regions = if elf.is_file() {
        let symbols = elf_functions(&elf).expect("reading the ELF symbols");
        vec![
            Region::from_prefix(&symbols, "firmware::"),
            Region::from_prefix(&symbols, "firmware::mpc::"),
            // The QP solver is its own crate, outside the `firmware::` region.
            Region::from_prefix(&symbols, "qp::"),
        ]
    } else {
        eprintln!("{} not built: no regions", elf.display());
        Vec::new()
    };
    let file = std::fs::File::open(&log).expect("opening the log");
    let started = std::time::Instant::now();
    let report = analyse_log(
        std::io::BufReader::with_capacity(1 << 20, file),
        limit,
        &regions,
    )
    .expect("parsing the log");
    println!("{}", serde_json::to_string_pretty(&report).unwrap());
    println!("parsed in {:.1} s", started.elapsed().as_secs_f64());
    assert!(report.total.instructions > 0);
    assert!(report.total.cpi_bound >= 1.0);
}
