//! Host simulator: the 9-DoF vehicle plant of the paper's Section IV, its tyres,
//! tracks and scenarios, and the deterministic timeline that closes the loop on
//! the `firmware` library.
//!
//! | module | concept |
//! |---|---|
//! | [`model`] | the vehicle model: parameters, tyres, the 9-DoF plant, tyre tables |
//! | [`validity`] | the paper's Figure 3: `δ_a` vs `δ_th` on circles (`validity` command) |
//! | [`track`] | track files (racetrack-database CSV), projection, curvature |
//! | [`obstacle_file`] | obstacle files (`id,x_m,y_m`), polygon distances, footprints |
//! | [`road_friction`] | friction that changes along the road (`--mu-patch`); μ̂ judged against it |
//! | [`scenario`] | the built-in `paper` scenario and `--track`/`--obstacles` resolution |
//! | [`scenario_options`] | the scenario options `run`, `pil` and `sweep` share (one clap struct), their checks, the set-up of one run |
//! | [`cost_model`] | the tasks' cost model on the ECU (instructions), fitted on PIL measurements |
//! | [`pil`] | processor in the loop: the ECU application in QEMU against the plant |
//! | [`closed_loop`] | the deterministic timeline: the plant against an ECU, budgets, deadlines |
//! | [`ecu`] | what runs the firmware: the `Ecu` trait, the modelled ECU on the host |
//! | [`route`] | the windows of the road the ECU holds, sent as the car moves on |
//! | [`run`] | the `run` command: log, summary, figures |
//! | [`disturbance`] | noise, delay, dropout, steering rate limit, late obstacle at the ECU's boundary |
//! | [`faults`] | named fault scenarios with their expected behaviour; run outcomes |
//! | [`obstacle_placement`] | boxes on any track; random obstacles from a seed |
//! | [`sweep`] | the `sweep` and `sweep-merge` commands: cross products of runs, in parallel |
//! | [`sweep_figures`] | the sweep's figures |
//! | [`figures`] | the closed-loop figures (the paper's Figures 5–8, task costs) |
//! | [`plot`] | plotting helpers (embedded font) |
//! | [`qp_corpus`] | the MPC's QPs as JSON, for solver benchmarks (`qp-corpus` command) |
//! | [`wcet`] | worst-case stack bound and cycles-per-instruction bound of the ECU binary |

pub mod closed_loop;
pub mod cost_model;
pub mod csv_value;
pub mod disturbance;
pub mod ecu;
pub mod faults;
pub mod figures;
pub mod model;
pub mod obstacle_file;
pub mod obstacle_placement;
pub mod pil;
pub mod plot;
pub mod qp_corpus;
pub mod road_friction;
pub mod route;
pub mod run;
pub mod scenario;
pub mod scenario_options;
pub mod sweep;
pub mod sweep_figures;
pub mod track;
pub mod validity;
pub mod wcet;
