//! Host simulator: the 9-DoF vehicle plant of the paper's Section IV, its tyres,
//! tracks and scenarios, and the deterministic timeline that closes the loop on
//! the `firmware` library.
//!
//! One folder per layer, each listing its modules:
//!
//! | module | layer |
//! |---|---|
//! | [`model`] | the vehicle model: parameters, tyres, the 9-DoF plant, tyre tables |
//! | [`world`] | the world: tracks, obstacles, road friction, scenarios, the road's windows, disturbances, faults |
//! | [`closed_loop`] | the closed loop: the plant against an ECU on a deterministic timeline, the modelled ECU, its cost model, the summary, one run's set-up; the validity experiment |
//! | [`pil`] | processor in the loop: the ECU application in QEMU against the plant, its frames, deadlines, comparison |
//! | [`sweep`] | sweeps: many closed-loop runs in parallel, `sweep.csv`, `sweep.json`, their figures |
//! | [`output`] | what a run writes: its files, its figures, plotting helpers |
//! | [`qp_corpus`] | the MPC's QPs as JSON, for solver benchmarks |
//! | [`wcet`] | worst-case timing and memory analysis of the ECU binary |
//! | [`stats`] | order statistics (median, percentile), each definition once |
//! | [`commands`] | the commands: each one's clap arguments and what it does |

pub mod closed_loop;
pub mod commands;
pub mod model;
pub mod output;
pub mod pil;
pub mod qp_corpus;
pub mod stats;
pub mod sweep;
pub mod wcet;
pub mod world;
