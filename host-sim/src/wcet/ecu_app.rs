//! What the analyses know of the ECU's RTIC application (`firmware/src/bin/ecu.rs`):
//! its tasks and the interrupts they run in, the sections bounded apart (the jobs,
//! the plan swap) with their budgets, the schedule, and for the stack bound its
//! priority levels and the functions that run once or with interrupts masked. The
//! numbers come from the firmware's own constants. The targets of its indirect
//! calls are read from the binary ([`super::indirect`]).

use super::stack::PriorityLevel;
/// The ECU's tasks as the RTIC application binds them: name and handler symbol.
/// `plan` runs in the priority-1 dispatcher, `control` in the priority-2 one, the
/// monotonic's timer queue in `SysTick`.
pub const ECU_TASKS: [(&str, &str); 3] = [
    ("control", "USART2"),
    ("plan", "USART1"),
    ("systick", "SysTick"),
];

/// The tasks' own work, bounded apart (the ECU app keeps them out of line):
/// section name, symbol, the task it runs in, its budget in cycles (what the ECU's
/// deadline monitor holds it to; `None`: no budget of its own).
pub const ECU_SECTIONS: [(&str, &str, &str, Option<u64>); 5] = [
    (
        "control_job",
        // Its symbol's fixed name (`#[export_name]`: placed first in `.text`).
        "ecu_control_job",
        "control",
        Some(firmware::deadline::CONTROL_BUDGET_CYCLES),
    ),
    (
        "plan_job",
        "ecu::plan_job",
        "plan",
        Some(firmware::deadline::PLAN_BUDGET_CYCLES),
    ),
    // An activation that adopts a window of the road instead of planning.
    (
        "window_job",
        "ecu::window_job",
        "plan",
        Some(firmware::deadline::PLAN_BUDGET_CYCLES),
    ),
    // The plan swap inside the `plan` lock: what blocks the control task.
    ("publish_plan", "ecu::publish_plan", "plan", None),
    // A frame of the road received before the plan or the adoption: part of the
    // activation's budget with either (the report adds it to both jobs).
    ("route_job", "ecu::route_job", "plan", None),
];

/// The ECU's schedule: task name, priority (higher preempts), period = deadline
/// in µs. SysTick is the monotonic's 1 kHz tick (`systick_monotonic!(Mono, 1_000)`
/// in the ECU app), above both tasks.
pub const ECU_SCHEDULE: [(&str, u8, u64); 3] = [
    ("systick", 3, 1_000),
    ("control", 2, firmware::tasks::CONTROL_PERIOD_US),
    ("plan", 1, firmware::tasks::PLAN_PERIOD_US),
];

/// Preemptions of one activation of `task` that meets its deadline:
/// `Σ_{higher} ⌈D / T_j⌉` over [`ECU_SCHEDULE`] (each a chance for a retry loop to
/// retry once). Faults are not counted: they end the activation.
pub fn preemptions_of(task: &str) -> u64 {
    let Some(&(_, prio, deadline)) = ECU_SCHEDULE.iter().find(|t| t.0 == task) else {
        return 0;
    };
    ECU_SCHEDULE
        .iter()
        .filter(|t| t.1 > prio)
        .map(|t| deadline.div_ceil(t.2))
        .sum()
}

/// The ECU's functions counted once in the stack bound: the safe stop's work,
/// entered with interrupts disabled (the panic handler and HardFault disable them
/// in a frame of a few bytes, then call `ecu::safe_stop`; the NMI handler calls it
/// at priority −2, where nothing preempts it), which never returns, and
/// only past `safe_stop`'s static guard (`STOPPING`): a second entry, a fault on
/// the work, exits in the guard's few bytes, so the work's frame is on the stack
/// at most once. Exact name: `ecu::safe_stop` itself, the guard, is counted
/// wherever it is called.
pub fn ecu_once() -> Vec<String> {
    vec!["ecu::safe_stop_work".to_string()]
}

/// The ECU's functions that run only with interrupts disabled: the clock set-up
/// and the set-up, called from RTIC's `init` before interrupts are enabled (their
/// frames are gone when the tasks first run).
pub fn ecu_masked() -> Vec<String> {
    vec![
        "ecu::app::configure_clock".to_string(),
        "ecu::app::set_up".to_string(),
        "ecu::app::open_link".to_string(),
    ]
}

/// The priority levels of the RTIC application `firmware/src/bin/ecu.rs`, for
/// [`super::stack::analyse_elf`]: thread mode runs `main` (init and idle); the
/// priority-1 (`plan`) and priority-2 (`control`) async tasks run in the
/// dispatchers `USART1` and `USART2` (RTIC v2 gives the dispatchers listed in
/// `dispatchers = [USART1, USART2]` to the priorities in increasing order: in the
/// disassembly `USART1` calls `Mpc::step_observed`, `USART2` `Link::receive`);
/// `SysTick`, the monotonic's interrupt, is the highest.
pub fn ecu_priority_levels() -> Vec<PriorityLevel> {
    let level = PriorityLevel::new;
    vec![
        level("thread (main: init, idle)", &["main"]),
        level("priority 1 (plan, dispatcher USART1)", &["USART1"]),
        level("priority 2 (control, dispatcher USART2)", &["USART2"]),
        level("SysTick (monotonic)", &["SysTick"]),
    ]
}
