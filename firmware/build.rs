//! Puts the workspace's `memory.x` on the linker search path for the ECU build,
//! and the control job first in its `.text` (a symbol ordering file).
//!
//! In a workspace the linker runs in the package directory, so the root
//! `memory.x` would not be found by `cortex-m-rt`'s `link.x` without this.
use std::{env, fs, path::PathBuf};

fn main() -> Result<(), String> {
    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rerun-if-changed=../memory.x");
    if !target.starts_with("thumb") {
        return Ok(());
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo did not set OUT_DIR")?);
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
