//! Processor in the loop (being split along its concepts: see the next commit).

pub mod qemu;
