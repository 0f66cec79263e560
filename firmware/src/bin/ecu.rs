//! ECU application (RTIC v2, Cortex-M4F): binds the library's tasks to interrupts.
//! Build: `cargo ecu` (see `.cargo/config.toml`).
#![no_std]
#![no_main]

use cortex_m_rt as _;
use stm32f4 as _;

#[cortex_m_rt::entry]
fn main() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}
