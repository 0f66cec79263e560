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
