//! Memory footprint of the solver at the MPC's sizes.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

use firmware::qp::{ldl_len, QpSolver};

/// The MPC's configuration: N = 32 variables, M = 96 rows, W = 48 working set, f32.
type MpcQp = QpSolver<f32, 32, 96, 48, { ldl_len(48) }>;

/// Bound on the f32 size, bytes. The problem data alone (H 4096 + A 12288 + bounds,
/// f and soft weights 1536) is 17 920 B; the packed LDLᵀ of a 48-entry working set is
/// 4704 B; the rest is vectors of length N, M or W.
const SIZE_BOUND: usize = 24 * 1024;

static SOLVER: MpcQp = MpcQp::new();

#[test]
fn f32_size_for_the_mpc() {
    let size = core::mem::size_of::<MpcQp>();
    println!("size_of QpSolver<f32, 32, 96, 48> = {size} bytes");
    assert!(size <= SIZE_BOUND, "{size} > {SIZE_BOUND}");
    // Usable as a static initialiser.
    assert_eq!(SOLVER.working_set().len(), 0);
}
