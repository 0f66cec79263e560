//! Build-time configuration of the firmware:
//!
//! * the link key: the AES-128 key that authenticates the frames between the ECU
//!   and the simulator (`link::secoc`), from the environment variable
//!   `ECU_LINK_KEY` (32 hexadecimal digits) or, without it, the development key
//!   below, written to `$OUT_DIR/link_key.rs`;
//! * the workspace's `memory.x` on the linker search path for the ECU build (in a
//!   workspace the linker runs in the package directory, so the root `memory.x`
//!   would not be found by `cortex-m-rt`'s `link.x` without this), and the control
//!   job first in the ECU's `.text` (a symbol ordering file);
//! * the flashed build (feature `board-usart`) refused outside its profile
//!   `board`, so that its ELF never replaces the lock-step one.
use std::{env, fs, path::PathBuf};

/// The environment variable that sets the link key at build time.
const KEY_VAR: &str = "ECU_LINK_KEY";

/// The development link key, for the simulator only: the ASCII bytes of
/// `DEV-ONLY-SIM-KEY`, so that it reads as what it is wherever it shows. It is
/// public (it is in this repository): a vehicle's key is never this one, nor in
/// a build or a repository (docs/pil-and-hil.md, "Authenticated frames").
const DEV_KEY_HEX: &str = "4445562d4f4e4c592d53494d2d4b4559";

/// The 16 bytes of a key written as 32 hexadecimal digits, or what is wrong with
/// it (never the digits themselves: the key is a secret).
fn parse_key(hex: &str) -> Result<[u8; 16], String> {
    let hex = hex.trim();
    if hex.len() != 32 || !hex.is_ascii() {
        return Err(format!(
            "{KEY_VAR} must be 32 hexadecimal digits (an AES-128 key), got {} characters; unset it to build with the development key",
            hex.chars().count()
        ));
    }
    let mut key = [0u8; 16];
    for (i, byte) in key.iter_mut().enumerate() {
        let digits = &hex[2 * i..2 * i + 2];
        *byte = u8::from_str_radix(digits, 16).map_err(|_| {
            format!(
                "{KEY_VAR}: characters {}-{} are not hexadecimal digits (0-9, a-f)",
                2 * i + 1,
                2 * i + 2
            )
        })?;
    }
    Ok(key)
}

fn main() -> Result<(), String> {
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);

    println!("cargo:rerun-if-env-changed={KEY_VAR}");
    let (key, from_env) = match env::var(KEY_VAR) {
        Ok(hex) => (parse_key(&hex)?, true),
        Err(env::VarError::NotPresent) => (parse_key(DEV_KEY_HEX)?, false),
        Err(env::VarError::NotUnicode(_)) => {
            return Err(format!(
                "{KEY_VAR} is not valid Unicode: give 32 hexadecimal digits"
            ))
        }
    };
    let bytes: Vec<String> = key.iter().map(|b| format!("0x{b:02x}")).collect();
    let source = format!(
        "/// The link key this build authenticates its frames with (`{KEY_VAR}` at build\n\
         /// time, else the development key).\n\
         pub const LINK_KEY: LinkKey = [{}];\n\
         /// Whether [`LINK_KEY`] came from `{KEY_VAR}` (false: the development key).\n\
         pub const LINK_KEY_FROM_ENV: bool = {from_env};\n",
        bytes.join(", ")
    );
    fs::write(out.join("link_key.rs"), source)
        .map_err(|e| format!("writing link_key.rs to OUT_DIR: {e}"))?;

    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rerun-if-changed=../memory.x");
    if !target.starts_with("thumb") {
        return Ok(());
    }
    // The flashed build (feature `board-usart`) has its own profile, `board`, so
    // its ELF (`<target dir>/thumbv7em-none-eabihf/board/ecu`) never replaces the
    // lock-step one (`.../release/ecu`) that the processor in the loop and the
    // timing analysis read. OUT_DIR is `<profile dir>/build/<package>-<hash>/out`.
    if env::var_os("CARGO_FEATURE_BOARD_USART").is_some() {
        let profile_dir = out.ancestors().nth(3).and_then(|p| p.file_name());
        if profile_dir.is_none_or(|d| d != "board") {
            return Err(
                "the feature `board-usart` builds the flashed ECU binary: build it with `cargo ecu` \
                 (--profile board), so that it does not replace the lock-step binary in release/"
                    .into(),
            );
        }
    }
    let memory =
        fs::read("../memory.x").map_err(|e| format!("memory.x at the workspace root: {e}"))?;
    fs::write(out.join("memory.x"), memory).map_err(|e| format!("writing to OUT_DIR: {e}"))?;
    println!("cargo:rustc-link-search={}", out.display());
    // The control job first in `.text` (right after `Reset`): its bound is then
    // independent of the size of the code that would otherwise come before it.
    let order = out.join("symbol-order.txt");
    fs::write(&order, "ecu_control_job\n").map_err(|e| format!("writing to OUT_DIR: {e}"))?;
    println!(
        "cargo:rustc-link-arg-bins=--symbol-ordering-file={}",
        order.display()
    );
    println!("cargo:rustc-link-arg-bins=--no-warn-symbol-ordering");
    Ok(())
}
