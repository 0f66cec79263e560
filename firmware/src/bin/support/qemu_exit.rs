//! Ending a run under QEMU, shared by the ECU binaries.

use cortex_m_semihosting::debug;

/// Ends the QEMU run through semihosting: exit status 0 when `ok`, 1 otherwise
/// (the core waits for interrupts should the call return).
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}
