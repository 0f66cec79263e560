//! Host simulator: the 9-DoF vehicle plant of the paper's Section IV, its tyres,
//! tracks and scenarios, and the deterministic timeline that closes the loop on
//! the `firmware` library.
//!
//! | module | concept |
//! |---|---|
//! | [`model`] | the vehicle model: parameters, tyres, the 9-DoF plant, tyre tables |
//! | [`world`] | the world: tracks, obstacles, road friction, scenarios, the road's windows, disturbances, faults |
//! | [`pil`] | processor in the loop: the ECU application in QEMU against the plant, its frames, deadlines, comparison |
//! | [`closed_loop`] | the closed loop: the plant against an ECU on a deterministic timeline, the modelled ECU, its cost model, the summary; the validity experiment |
//! | [`commands`] | the commands: each one's clap arguments and what it does |
//! | [`sweep`] | sweeps: many closed-loop runs (their figures) |
//! | [`output`] | what a run writes: its files, its figures, plotting helpers |
//! | [`qp_corpus`] | the MPC's QPs as JSON, for solver benchmarks (`qp-corpus` command) |
//! | [`wcet`] | worst-case stack bound and cycles-per-instruction bound of the ECU binary |

pub mod closed_loop;
pub mod commands;
pub mod model;
pub mod output;
pub mod pil;
pub mod qp_corpus;
pub mod sweep;
pub mod wcet;
pub mod world;
