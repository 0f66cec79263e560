//! `host-sim sweep`: the cross product of tracks, frictions, vehicles, loads,
//! noise levels, delays, faults and seeds, run in parallel, one row per run in
//! `sweep.csv`, the aggregate in `sweep.json`, figures and a text summary.
//!
//! # Runs
//!
//! The runs are the cross product in the order track, μ, μ_planner, vehicle, mass
//! scale, noise, delay, fault, seed; a run's `index` is its place in that order and
//! addresses it on its own (`--list` prints them, `--only I/N` runs those whose
//! index is `I` modulo `N`, so shards are balanced across tracks; `sweep-merge`
//! joins the shards' `sweep.csv` files). Every run is deterministic: the firmware
//! runs in `f32` on the modelled ECU, and every random draw (obstacles, noise)
//! comes from a seed made of the track's name and the run's `seed` column, so the
//! same command writes the same `sweep.csv` whatever the thread count or shard.
//!
//! # Factors
//!
//! The scenario options `run` and `pil` take too
//! ([`crate::commands::scenario_args::ScenarioArgs`]), lists here:
//!
//! - `--mass-scale k`: the plant's mass and inertias × k; the firmware is told the
//!   nominal car (an unknown load).
//! - `--noise`: a level name (`none` 0, `low` 1, `medium` 2, `high` 4) or a number,
//!   multiplying [`crate::world::disturbance::NOISE_UNIT`] (σ of 0.05 m on X and Y, 0.005
//!   rad on the heading, 0.05 m/s on the speed, 0.005 rad/s on the yaw rate).
//! - `--delay-ms`: the estimate the tasks see is that old (rounded to 10 ms).
//! - `--fault`: see [`crate::world::faults`] (`--help` lists them).
//! - `--obstacles random:N`: see [`crate::world::obstacle_placement`].
//! - `--seed` (a list) or `--seeds N` (0..N).
//! - `--mu-patch START_M:LENGTH_M:MU` (repeatable): patches of road with their own
//!   friction, the same in every run (not a factor), checked against every track's
//!   lap before the first run; see [`crate::world::road_friction`].
//!
//! # The friction check against the road
//!
//! Per run (summary fields, so columns of `sweep.csv`; definitions in
//! [`crate::world::road_friction`]): `friction_mu_min` (the lowest `μ̂`), `road_mu_min`,
//! `mu_false_drop` (at some 10 ms sample `μ̂ < 0.9·min` of the road μ under the car
//! over the last 10 s) and `mu_false_drop_s` (when first), `mu_recovery_s` (the
//! slowest return to `μ̂ ≥ 0.9·road μ` after leaving a patch of lower grip) and
//! `mu_unrecovered_exits`. The aggregate counts the false drops per track and μ
//! (`mu_false_drops`, a missed bound).
//!
//! # Outcome and off-road
//!
//! [`crate::world::faults::Outcome`], worst first. Off-road: at some 10 ms sample the
//! centre of gravity was farther from the centre line than the road's local
//! half-width on that side. `max_edge_excess_m` is how far the body's side went
//! past the edge (negative: the margin left).
//!
//! With obstacles, each run's are written to `obstacles/<index>.csv`. `host-sim run`
//! with a run's factors (`--track T --mu … --fault … --seed S`, its `--obstacles`)
//! sets the run up as the sweep did ([`crate::closed_loop::set_up::set_up`]) and
//! replays it.
//!
//! # Exit status
//!
//! [`verdict`](crate::commands::sweep::verdict): non-zero when a run could not run (an error row: outcome `failed`,
//! an error, no summary), after every output is written; with `--strict` also when
//! a run did not show its expected behaviour. Laps that ran and ended badly are
//! measurements (`sweep.json`). A missing track, folder, obstacle or vehicle file is
//! refused before the first run.
//!
//! `sweep.csv` holds every field of `summary.json` except the host's wall-time
//! figures (`plan_host_us_p50`, `plan_host_us_max`, `sim_speed_x_realtime`), which
//! differ from one run of the same command to the next.
//!
//! | module | concept |
//! |---|---|
//! | [`execute`] | one run of a sweep as a row of `sweep.csv`; many in parallel |
//! | [`table`] | `sweep.csv`: its columns, writing it, reading its rows back |
//! | [`aggregate`] | `sweep.json` and `summary.txt`: the aggregate of the rows, its bounds |
//! | [`figures`] | the sweep's figures |
//!
//! The `sweep` and `sweep-merge` commands are [`crate::commands::sweep`].

pub mod aggregate;
pub mod execute;
pub mod figures;
pub mod table;
