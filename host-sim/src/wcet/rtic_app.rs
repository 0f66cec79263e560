//! What the analyses know about the ECU's RTIC application
//! (`firmware/src/bin/ecu.rs`): its priority levels and which of its functions
//! run once or with interrupts masked, for the stack bound of [`super::stack`].

use super::stack::PriorityLevel;

/// The ECU's functions counted once in the stack bound: the panic handler's work,
/// entered with interrupts disabled (`rust_begin_unwind` disables them in a frame of
/// a few bytes, then calls it), which never returns.
pub fn ecu_once() -> Vec<String> {
    vec!["ecu::safe_stop".to_string()]
}

/// The ECU's functions that run only with interrupts disabled: the set-up, called
/// from RTIC's `init` before interrupts are enabled (their frames are gone when
/// the tasks first run).
pub fn ecu_masked() -> Vec<String> {
    vec![
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
