//! The ECU's timing facts, each written once: the core clock and the two tasks'
//! periods. A leaf module (it imports nothing) that the library's tasks, the
//! deadline monitor, the friction check, the RTIC application and the simulator
//! all read.

/// Core clock of the ECU (the STM32F405 at its rated 168 MHz), Hz.
pub const ECU_CLOCK_HZ: u32 = 168_000_000;
/// Period (= deadline) of the `control` task, µs.
pub const CONTROL_PERIOD_US: u64 = 10_000;
/// Period (= deadline) of the `plan` task, µs.
pub const PLAN_PERIOD_US: u64 = 100_000;
/// Tick of the ECU application's monotonic (its SysTick interrupt's period), µs:
/// the control period, of which every release is a whole multiple, so that the
/// tick interrupts the tasks as rarely as the releases allow (the response times
/// are read from the core clock, not from the tick).
pub const MONO_TICK_US: u64 = CONTROL_PERIOD_US;

const _: () = assert!(
    CONTROL_PERIOD_US.is_multiple_of(MONO_TICK_US) && PLAN_PERIOD_US.is_multiple_of(MONO_TICK_US),
    "every release must fall on a monotonic tick"
);
