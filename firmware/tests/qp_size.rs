//! Memory footprint of the QP solver the MPC uses ([`firmware::mpc::MpcQp`]).
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::needless_range_loop
)]

use firmware::mpc::{MpcQp, NC, NV, WS};
use qp::ldl_len;

/// The MPC's solver in f32: N = `NV` = 32 variables, M = `NC` = 80 rows, W = `WS` =
/// 48 working-set entries.
type Solver = MpcQp<f32>;

/// f32 values of the solver, by what they hold: the problem (H `NV²` = 1024, A
/// `NC·NV` = 2560, f, x_lo, x_hi `3·NV` = 96, lo, hi, soft `3·NC` = 240: 3920, that
/// is 15 680 B), the packed LDLᵀ of the working set (`ldl_len(WS)` = 1176, 4704 B),
/// the working set's multipliers, the forward substitution `y` and `ℓ = D⁻¹y` of
/// their system, the rank-one update's β and scratch (`5·WS` = 240), three vectors
/// of length N (`v`, `u`, the bounds' `1/R_jj`: 96) and the solution (x,
/// λ_bounds `2·NV` = 64, λ_rows `NC` = 80): 5576 values, 22 304 B.
const F32_VALUES: usize =
    NV * NV + NC * NV + 3 * NV + 3 * NC + ldl_len(WS) + 5 * WS + 3 * NV + 2 * NV + NC;

/// Bytes of the solver's bookkeeping arrays: the working set (6 B an entry: 288 B),
/// a state byte per variable (active side: `NV` = 32 B) and per row (active side,
/// transformation code: `2·NC` = 160 B): 480 B.
const INDEX_BYTES: usize = 6 * WS + NV + 2 * NC;

/// Allowance for the scalars (settings, counters, the working-set length and row
/// count as `usize`, status and flags) and padding, bytes. Measured on the host
/// (64-bit `usize`): 22 880 B in all, 96 B of them scalars and padding.
const SCALAR_BYTES: usize = 128;

/// Bound on the size, bytes: 22 304 + 480 + 128 = 22 912 B. A field or an array
/// added to the solver, or the MPC's sizes grown, fails it.
const SIZE_BOUND: usize = 4 * F32_VALUES + INDEX_BYTES + SCALAR_BYTES;

static SOLVER: Solver = Solver::new();

#[test]
fn f32_size_of_the_mpcs_qp_solver() {
    let size = core::mem::size_of::<Solver>();
    println!(
        "size_of MpcQp<f32> (QpSolver<f32, {NV}, {NC}, {WS}>) = {size} bytes, bound {SIZE_BOUND}"
    );
    assert_eq!((NV, NC, WS), (32, 80, 48), "the comments' arithmetic");
    assert_eq!(SIZE_BOUND, 22_912);
    assert!(size <= SIZE_BOUND, "{size} > {SIZE_BOUND}");
    // The arrays alone are most of it: the bound is not loose.
    assert!(size >= 4 * F32_VALUES + INDEX_BYTES, "{size}");
    // Usable as a static initialiser.
    assert_eq!(SOLVER.working_set().len(), 0);
}
