//! The commands of `host-sim`, one module each: its clap arguments and what it
//! does with them, on top of the library's layers (`main.rs` only dispatches).
//!
//! | module | concept |
//! |---|---|
//! | [`scenario_args`] | the scenario options `run`, `pil` and `sweep` share (one clap struct) and their checks |
//! | [`tire`] | `host-sim tire`: tyre forces for a CSV of slips |
//! | [`validity`] | `host-sim validity`: the paper's Figure 3 |
//! | [`qp_corpus`] | `host-sim qp-corpus`: the MPC's QPs of a scenario as JSON files |
//! | [`run`] | `host-sim run`: a closed-loop drive, its log, summary and figures |
//! | [`sweep`] | `host-sim sweep` and `sweep-merge`: cross products of runs, in parallel |
//! | [`pil`] | `host-sim pil`: the same drive with the ECU application in QEMU, `pil.json` |
//! | [`wcet`] | `host-sim wcet`: the PIL laps, the static analysis and the timing and memory report |
//! | [`docs`] | `host-sim docs`: the README's and `docs/`'s figures written from the timing report |

pub mod docs;
pub mod pil;
pub mod qp_corpus;
pub mod run;
pub mod scenario_args;
pub mod sweep;
pub mod tire;
pub mod validity;
pub mod wcet;
