//! The ECU's core clock as the binary sets it (`wcet.json`'s `clock`): its
//! frequency and source from the firmware's constants ([`firmware::clock_tree`]),
//! the function that sets it as the ELF's symbol table names it, and what the
//! same sequence does on QEMU's `netduinoplus2`, whose RCC reads 0.

pub use ::wcet::target::ClockReport;
use ::wcet::{demangle, parse_elf, read_elf};
use anyhow::Result;
use firmware::clock_tree::{self, ClockRegisters, Register};
use std::path::Path;

/// QEMU 7.2's `netduinoplus2`: RCC, PWR and the flash interface are unimplemented
/// devices, whose reads return 0 and whose writes do nothing.
struct QemuUnimplemented;

impl ClockRegisters for QemuUnimplemented {
    fn read(&mut self, _: Register) -> u32 {
        0
    }

    fn write(&mut self, _: Register, _: u32) {}
}

/// The path of the function that sets the clock, as the compiler names it
/// (`firmware::clock_tree::configure`, its generic argument dropped): the name
/// its symbol demangles to.
pub fn configure_fn() -> &'static str {
    let name = std::any::type_name_of_val(&clock_tree::configure::<QemuUnimplemented>);
    name.split('<').next().unwrap_or(name)
}

/// From the firmware's constants; `configured_in` as given.
pub fn of_firmware(configured_in: Option<String>) -> ClockReport {
    let pll = clock_tree::PLL;
    ClockReport {
        sysclk_hz: u64::from(clock_tree::SYSCLK_HZ),
        source: format!(
            "HSE {} MHz → PLL (M {}, N {}, P {}, Q {})",
            f64::from(clock_tree::HSE_HZ) / 1e6,
            pll.m,
            pll.n,
            pll.p,
            pll.q
        ),
        configured_in,
        in_qemu: format!("{:?}", clock_tree::configure(&mut QemuUnimplemented)),
    }
}

/// From the firmware's constants and the ELF: `configured_in` is
/// [`configure_fn`] when the ELF defines a function of that name.
pub fn of_elf(elf: &Path) -> Result<ClockReport> {
    use object::{Object, ObjectSymbol, SymbolKind};
    let data = read_elf(elf)?;
    let file = parse_elf(elf, &data)?;
    let wanted = configure_fn();
    let defined = file.symbols().any(|s| {
        s.is_definition()
            && s.kind() == SymbolKind::Text
            && s.name().is_ok_and(|n| demangle(n) == wanted)
    });
    Ok(of_firmware(defined.then(|| wanted.to_string())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_is_the_firmwares_and_qemu_takes_the_fixed_path() {
        let c = of_firmware(None);
        assert_eq!(c.sysclk_hz, 168_000_000);
        assert_eq!(c.source, "HSE 25 MHz → PLL (M 25, N 336, P 2, Q 7)");
        assert_eq!(c.in_qemu, "Ok(Fixed)");
        assert_eq!(configure_fn(), "firmware::clock_tree::configure");
    }

    #[test]
    fn the_function_is_found_among_an_elfs_symbols() -> Result<()> {
        // Registers the optimiser cannot see through: on QEMU's (reads a
        // constant 0, writes nothing) a release build folds the never-inlined
        // call to its constant result and drops the function.
        struct Opaque;
        impl ClockRegisters for Opaque {
            fn read(&mut self, _: Register) -> u32 {
                std::hint::black_box(0)
            }
            fn write(&mut self, _: Register, value: u32) {
                std::hint::black_box(value);
            }
        }
        // This test binary defines it, called here: found by its demangled name,
        // as in the ECU's ELF.
        let _ = clock_tree::configure(&mut Opaque);
        let c = of_elf(&std::env::current_exe()?)?;
        assert_eq!(c.configured_in.as_deref(), Some(configure_fn()));
        // A file that is not an ELF is an error, not a missing function.
        let tmp = tempfile::tempdir()?;
        let text = tmp.path().join("not-an-elf");
        std::fs::write(&text, "text")?;
        assert!(of_elf(&text).is_err());
        Ok(())
    }
}
