//! Puts the workspace's `memory.x` on the linker search path for the ECU build.
//!
//! In a workspace the linker runs in the package directory, so the root
//! `memory.x` would not be found by `cortex-m-rt`'s `link.x` without this.
use std::{env, fs, path::PathBuf};

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rerun-if-changed=../memory.x");
    if !target.starts_with("thumb") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory = fs::read("../memory.x").expect("memory.x at the workspace root");
    fs::write(out.join("memory.x"), memory).expect("OUT_DIR is writable");
    println!("cargo:rustc-link-search={}", out.display());
}
