//! Processor in the loop: the firmware's ECU application runs in QEMU
//! (`netduinoplus2`, an STM32F405 Cortex-M4F) and the simulator's plant closes the
//! loop with it, one sensor frame and one actuator frame per 10 ms control period.
//!
//! # Time
//!
//! QEMU runs with `-icount shift=N,sleep=off`: its virtual clock advances `2^N` ns
//! per executed instruction and jumps straight to the next timer when the CPU
//! sleeps, so the firmware's timers (RTIC's monotonic on SysTick, 168 MHz of
//! virtual time) are driven by what the firmware executes, not by the host. The
//! link is semihosting on two FIFOs (`ecu.down`, `ecu.up`): a semihosting call is
//! synchronous and takes no virtual time, so the host's own speed never shows in
//! the ECU's timeline and the run is deterministic. A UART would deliver bytes at
//! host-dependent virtual instants.
//!
//! The plant advances 10 ms between two sensor frames; the ECU's control task is
//! released by its own timer every 10 ms of virtual time and its plan task every
//! 100 ms; a plan takes effect when the ECU publishes it, so the firmware's real
//! execution time is what delays its plans. With `N = 4` an instruction takes
//! 16 ns of virtual time, i.e. 2.69 cycles at 168 MHz: above the cycles-per-
//! instruction bound of the timing report, so the PIL timeline is no faster than
//! the real ECU.
//!
//! # Frames
//!
//! See [`firmware::link`]: versioned, authenticated (a freshness value and
//! an 8-byte keyed BLAKE2s, [`firmware::link::secoc`]), CRC-32, COBS-delimited
//! postcard frames. Set-up: `Config`, `PathChunk`s, `Obstacle`s, `Start` →
//! `Ready`; then `Sensor` → `Actuation` every period; `Stop` → `Done`. Forged,
//! replayed, garbled, short, wrong-version, stale or out-of-order frames are
//! refused and counted on both sides; the ECU answers a sensor frame it refused
//! as a dropout (the safe actuation), saying so in its answer. The next
//! window of the road goes on a third FIFO (`ecu.route`), announced by the count
//! in the next sensor frame: the ECU's plan task reads it after it publishes.
//!
//! # Deadlines, counted twice
//!
//! Each actuation frame carries the control release it answers, its send
//! instant on the ECU's clock (the plant applies it from then) and the previous
//! control activation's response time (a control activation completes once its
//! frame has been written, which only the next frame can say); each plan event
//! its release, finish (the plan published) and end; the host counts misses and
//! skipped releases from these stamps, and budget
//! overruns from the measured ticks, as the driver does for any ECU. The ECU
//! counts them itself ([`firmware::deadline`]) and sends its counts in the same
//! frames; [`count_mismatches`](deadlines::count_mismatches) compares the two and `host-sim pil` fails when
//! they differ. The plant applies each actuation from the instant the ECU sent it
//! ([`crate::closed_loop::timeline`]).
//!
//! | module | concept |
//! |---|---|
//! | [`qemu`] | the ECU application in QEMU: process, FIFO link, set-up, exchange; [`QemuEcu`](qemu::QemuEcu) as the closed loop's ECU |
//! | [`frames`] | the link's frames to and from the simulator's types |
//! | [`link_fault`] | forged, replayed and corrupted sensor frames (`--link-fault`), and the in-process run's model of them |
//! | [`deadlines`] | the host's count of the ECU's skipped releases and budget overruns, against the ECU's own |
//! | [`comparison`] | the PIL run against the in-process one: the first divergence and its cause |
//! | [`report`] | `pil.json`: what `host-sim pil` adds to `run`'s outputs |
//! | [`usart`] | `--link usart`: the binary you flash in QEMU, its USART1 piped to the simulator, in a real-time loop (not lock-step); [`UsartEcu`](usart::UsartEcu) as the closed loop's ECU |
//!
//! The `pil` command is [`crate::commands::pil`].

use std::path::{Path, PathBuf};

/// Where `cargo ecu-lockstep` puts the ECU application, relative to the workspace root,
/// with the default target directory (`host-sim pil` and `wcet`'s `--elf`).
pub const ECU_ELF: &str = "target/thumbv7em-none-eabihf/release/ecu";

/// The ECU application `cargo ecu-lockstep` built for the workspace at `root`: under
/// `$CARGO_TARGET_DIR` when it is set (relative to `root` unless absolute), else
/// [`ECU_ELF`].
pub fn built_ecu_elf(root: &Path) -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => root.join(dir).join("thumbv7em-none-eabihf/release/ecu"),
        None => root.join(ECU_ELF),
    }
}

/// Where `cargo ecu` puts the binary you flash (the same application over
/// USART1, `defmt` over RTT, no semihosting; its own profile, `board`), relative
/// to the workspace root, with the default target directory. The processor in
/// the loop and the timing analysis run the lock-step build, [`ECU_ELF`].
pub const ECU_BOARD_ELF: &str = "target/thumbv7em-none-eabihf/board/ecu";

/// The flashed ECU binary `cargo ecu` built for the workspace at `root`:
/// under `$CARGO_TARGET_DIR` when it is set (relative to `root` unless absolute),
/// else [`ECU_BOARD_ELF`].
pub fn built_ecu_board_elf(root: &Path) -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => root.join(dir).join("thumbv7em-none-eabihf/board/ecu"),
        None => root.join(ECU_BOARD_ELF),
    }
}

pub mod comparison;
pub mod deadlines;
pub mod frames;
pub mod link_fault;
pub mod qemu;
pub mod report;
pub mod usart;
