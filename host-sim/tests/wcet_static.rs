//! The static WCET analysis of the ECU binary (`cargo ecu-lockstep`): every
//! indirect call resolved, no recursion, and the loop annotations, flow facts
//! and traces checked on it. The hand-counted small programs are the `wcet`
//! crate's (`wcet/tests/hand_counted.rs`).
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::wcet::annotations::SourceDir;

/// The ECU application (built by `cargo ecu-lockstep`; CI runs this after building it),
/// failing the test when it was not built.
fn ecu_elf() -> std::path::PathBuf {
    let elf =
        host_sim::pil::built_ecu_elf(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
    assert!(
        elf.is_file(),
        "{} is missing: build it with `cargo ecu-lockstep`",
        elf.display()
    );
    elf
}

#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn the_ecu_binary_resolves_every_indirect_call_and_has_no_recursion() {
    let elf = &ecu_elf();
    let a = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    assert!(
        a.unresolved_indirect_calls.is_empty(),
        "{:?}",
        a.unresolved_indirect_calls
    );
    assert!(a.recursions.is_empty(), "{:?}", a.recursions);
    // Every task is found and reaches code; the loops listed are the tasks' own.
    for t in &a.tasks {
        assert!(t.functions > 0, "{}", t.name);
        assert!(t.bounded_loops <= t.loops);
    }
    let plan = a.tasks.iter().find(|t| t.name == "plan").unwrap();
    assert!(plan.loops > 50, "the MPC's loops: {}", plan.loops);
    // Every loop of every task has a bound, and every task and section a static
    // bound; the control task's own work stays within its goal of 2,000
    // instructions, statically.
    assert_eq!(a.unbounded_loops, 0);
    for t in &a.tasks {
        assert!(t.static_bound_instructions.is_some(), "{t:?}");
    }
    let job = a.tasks.iter().find(|t| t.name == "control_job").unwrap();
    let bound = job.static_bound_instructions.unwrap();
    assert!(bound <= 2_000, "ControlTask::run: {bound} instructions");
    // Each bound recognised from the binary names a source line.
    for l in a.loops.iter().filter(|l| l.bound.is_some()) {
        assert!(l.line > 0, "{l:?}");
    }
    // memory.x keeps data out of flash, so the model charges flash wait states to
    // the constant pools alone (else it says why not).
    let data = a
        .assumptions
        .iter()
        .find(|s| s.starts_with("Data:"))
        .unwrap();
    assert!(data.contains("only pc-relative loads"), "{data}");
}

/// The firmware crates' sources in this workspace (`firmware/src`, `qp/src`).
fn workspace_sources() -> Vec<SourceDir> {
    host_sim::wcet::ecu_sources::workspace_sources(std::path::Path::new(".."))
}

/// A copy of the firmware crates' sources (`firmware/src`, `qp/src`) with `edit`
/// applied to one file, `file` from the workspace root (line count unchanged, so
/// the ELF's line table still matches), and its source folders.
fn edited_sources(
    file: &str,
    edit: impl Fn(&str) -> String,
) -> (tempfile::TempDir, Vec<SourceDir>) {
    let dir = tempfile::tempdir().unwrap();
    let mut edited = false;
    for from in workspace_sources() {
        let src = from.dir.as_path();
        let mut stack = vec![src.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                let rel = std::path::Path::new(from.label).join(p.strip_prefix(src).unwrap());
                if p.is_dir() {
                    stack.push(p);
                } else {
                    let text = std::fs::read_to_string(&p).unwrap();
                    let text = if rel == std::path::Path::new(file) {
                        let new = edit(&text);
                        assert_ne!(new, text, "the edit changed nothing in {file}");
                        assert_eq!(new.lines().count(), text.lines().count());
                        edited = true;
                        new
                    } else {
                        text
                    };
                    let to = dir.path().join(rel);
                    if let Some(parent) = to.parent() {
                        std::fs::create_dir_all(parent).unwrap();
                    }
                    std::fs::write(to, text).unwrap();
                }
            }
        }
    }
    assert!(edited, "no file {file} in the firmware crates' sources");
    let sources = host_sim::wcet::ecu_sources::workspace_sources(dir.path());
    (dir, sources)
}

#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn a_loop_whose_annotation_is_removed_is_refused() {
    let elf = &ecu_elf();
    let before = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    let (_dir, edited) = edited_sources("firmware/src/mpc.rs", |t| {
        t.replace(
            "// wcet-bound: COLD_START_PASSES",
            "// (bound removed by a test)",
        )
    });
    let after = host_sim::wcet::analyse(elf, &edited, &[]).unwrap();
    assert!(
        after.unbounded_loops > before.unbounded_loops,
        "{} -> {}",
        before.unbounded_loops,
        after.unbounded_loops
    );
    let passes = |a: &host_sim::wcet::analysis::StaticAnalysis| {
        a.loops
            .iter()
            .filter(|l| l.file == "firmware/src/mpc.rs" && l.bound.is_none())
            .count()
    };
    assert!(passes(&after) > passes(&before));
    let plan = after.tasks.iter().find(|t| t.name == "plan").unwrap();
    assert!(plan.static_bound_instructions.is_none());
    assert!(plan
        .refused
        .as_deref()
        .unwrap_or("")
        .contains("without a bound"));
}

/// An activation of the plan task adopts a window of the road or plans, never
/// both (`ecu::window_job` and `ecu::plan_job` on the two branches of one test):
/// the task's bound is the larger job's plus what every activation does (the
/// dispatch, the plan's publication: tens of thousands of cycles), not their sum,
/// nor a mix of fractions of both (the IPET's entry counts are integers; with
/// continuous ones the bound took half of each job and a whole cap per activation,
/// 2.5 M cycles over the larger job).
#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn a_plan_activation_is_bounded_by_its_larger_job_not_both() {
    let elf = &ecu_elf();
    let cycles = |a: &host_sim::wcet::analysis::StaticAnalysis, name: &str| {
        a.tasks
            .iter()
            .find(|t| t.name == name)
            .and_then(|t| t.static_bound_cycles)
            .unwrap()
    };
    let a = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    let (task, plan, window, route) = (
        cycles(&a, "plan"),
        cycles(&a, "plan_job"),
        cycles(&a, "window_job"),
        cycles(&a, "route_job"),
    );
    // Both jobs are large (which is the larger has changed with what a window's
    // frames cost to verify): the task is bounded by the larger, after the route
    // frame every activation may read first (`route_job`, on both branches).
    assert!(window > 1_000_000 && plan > 1_000_000, "{plan} {window}");
    assert!(route < 1_000_000, "{route}");
    let larger = plan.max(window) + route;
    assert!(
        task >= larger,
        "the task {task} < its larger job after a route frame, {plan} or {window}, + {route}"
    );
    assert!(
        task <= larger + 200_000,
        "the task {task} is more than its larger job after a route frame, {plan} or {window}, + {route}, and 200 k"
    );
}

/// The control task's activations that carry no plan event (all but one per plan
/// activation) are bounded apart, with the frame's and the MAC's byte caps at an
/// actuation frame's: the event's bytes through the MAC are BLAKE2s blocks the
/// light bound does not hold, the event's charge is the step between the two bounds,
/// and the report says what the light activations leave out.
#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn a_control_activation_without_a_plan_event_is_bounded_apart() {
    use firmware::link;
    let elf = &ecu_elf();
    let a = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    let control = a.tasks.iter().find(|t| t.name == "control").unwrap();
    let full = control.static_bound_cycles.unwrap();
    let light = control.light_bound_cycles.unwrap();
    // At least one compression of at least 2,000 cycles per 64 bytes of the event.
    let blocks = (link::MAX_UP_MAC_INPUT_BYTES
        - link::mac_input_bytes(link::MAX_ACTUATION_PAYLOAD_BYTES))
        / 64;
    assert!(blocks >= 3, "{blocks}");
    assert!(
        light + blocks as u64 * 2_000 <= full,
        "light {light}, full {full}, {blocks} blocks"
    );
    // The lock-step build's one kind of extra work: the event, once an
    // activation, charged the whole step from the light bound to the full one.
    let [event] = control.light_extras.as_slice() else {
        panic!("{:?}", control.light_extras);
    };
    assert_eq!(event.what, "a plan event in its frame");
    assert_eq!(event.bounds[0], [light, full, full]);
    assert_eq!(event.charge.unit_cycles, (full - light) as f64);
    assert_eq!(event.charge.per_activation, 1);
    // No other task or section has light activations.
    assert!(a
        .tasks
        .iter()
        .filter(|t| t.name != "control")
        .all(|t| t.light_bound_cycles.is_none() && t.light_extras.is_empty()));
    assert!(a.markdown().contains(&format!(
        "activations without a plan event in its frame: {light} cycles"
    )));
}

/// The QP solver's annotations are read from its own crate (`qp/src`): without its
/// iteration cap, the solver's main loop is unbounded.
#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn a_qp_loop_whose_annotation_is_removed_is_refused() {
    let elf = &ecu_elf();
    let before = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    let unbounded_in_qp = |a: &host_sim::wcet::analysis::StaticAnalysis| {
        a.loops
            .iter()
            .filter(|l| l.file == "qp/src/active_set.rs" && l.bound.is_none())
            .count()
    };
    assert_eq!(unbounded_in_qp(&before), 0);
    assert!(before.loops.iter().any(|l| l.file.starts_with("qp/src/")));
    let (_dir, edited) = edited_sources("qp/src/active_set.rs", |t| {
        t.replace(
            "// wcet-bound: QP_MAX_ITER per activation",
            "// (bound removed by a test)",
        )
    });
    let after = host_sim::wcet::analyse(elf, &edited, &[]).unwrap();
    assert!(after.unbounded_loops > before.unbounded_loops);
    assert!(unbounded_in_qp(&after) > 0);
    let plan = after.tasks.iter().find(|t| t.name == "plan").unwrap();
    assert!(plan.static_bound_instructions.is_none());
}

#[test]
#[ignore = "needs the ECU binary and QEMU: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn an_annotation_below_the_true_trip_count_is_caught_by_a_trace() {
    let elf = &ecu_elf();
    let out = tempfile::tempdir().unwrap();
    let trace = out.path().join("trace.log");
    // One simulated second of the paper lap: the cold start walks the whole
    // window of the road (320 rows).
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args([
            "pil",
            "--obstacles",
            "paper",
            "--duration",
            "1",
            "--no-plots",
            "--no-compare",
        ])
        .arg("--elf")
        .arg(elf)
        .arg("--trace")
        .arg(&trace)
        .arg("--out")
        .arg(out.path().join("pil"))
        .status()
        .unwrap();
    assert!(status.success());
    let honest =
        host_sim::wcet::analyse(elf, &workspace_sources(), std::slice::from_ref(&trace)).unwrap();
    assert!(honest.violations.is_empty(), "{:?}", honest.violations);
    assert!(honest
        .loops
        .iter()
        .any(|l| l.observed_max.unwrap_or(0) >= 300));
    let (_dir, edited) = edited_sources("firmware/src/reference_path/loading.rs", |t| {
        t.replace("// wcet-bound: ECU_PATH_ROWS", "// wcet-bound: 10")
    });
    let wrong = host_sim::wcet::analyse(elf, &edited, std::slice::from_ref(&trace)).unwrap();
    assert!(!wrong.violations.is_empty());
    assert!(
        wrong
            .violations
            .iter()
            .any(|v| v.contains("bound 10 back edges")),
        "{:?}",
        wrong.violations
    );
    // A flow fact per activation below its true count: every poll of the control
    // task crosses its cycle's back edges at least twice.
    let honest_fact = honest
        .flow_facts
        .iter()
        .find(|f| {
            f.sources
                .iter()
                .any(|s| s.contains("firmware/src/bin/ecu.rs"))
                && f.bound == 3
        })
        .unwrap();
    assert!(
        honest_fact.observed_max.unwrap_or(0) >= 2,
        "{honest_fact:?}"
    );
    let (_dir, edited) = edited_sources("firmware/src/bin/ecu.rs", |t| {
        t.replace(
            "// wcet-bound: 3 per activation",
            "// wcet-bound: 1 per activation",
        )
    });
    let wrong = host_sim::wcet::analyse(elf, &edited, &[trace]).unwrap();
    assert!(
        wrong
            .violations
            .iter()
            .any(|v| v.contains("flow fact") && v.contains("bound 1")),
        "{:?}",
        wrong.violations
    );
}

/// One source loop the compiler split into nested binary loops (the pairs of
/// `obstacles::minimal_apex`: the path of a zero `dx` skips its head) shares its
/// bound only where the source says
/// so (`// wcet-bound: same loop`): without it the inner loop is refused, with a
/// message that names the lines it may be written on.
#[test]
#[ignore = "needs the ECU binary: `cargo ecu-lockstep`, then `cargo test -p host-sim --test wcet_static -- --ignored`"]
fn a_split_loop_without_its_own_annotation_is_refused() {
    let elf = &ecu_elf();
    let before = host_sim::wcet::analyse(elf, &workspace_sources(), &[]).unwrap();
    assert_eq!(before.unbounded_loops, 0);
    assert!(before.loops.iter().any(|l| l
        .source
        .as_deref()
        .unwrap_or("")
        .contains("firmware/src/obstacles.rs")
        && l.source.as_deref().unwrap_or("").contains("`same loop`")));
    let (_dir, edited) = edited_sources("firmware/src/obstacles.rs", |t| {
        t.replace("// wcet-bound: same loop", "// (removed by a test)")
    });
    let after = host_sim::wcet::analyse(elf, &edited, &[]).unwrap();
    let refused: Vec<_> = after.loops.iter().filter(|l| l.bound.is_none()).collect();
    assert_eq!(refused.len(), 1, "{refused:?}");
    let why = refused[0].why_unbounded.as_deref().unwrap_or("");
    assert!(
        why.contains("enclosing loop's")
            && why.contains("same loop")
            && why.contains("firmware/src/obstacles.rs:"),
        "{why}"
    );
}
