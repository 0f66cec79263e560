//! The world the car drives in: the road, what stands on it, its friction, the
//! scenario put together from them, the windows of the road the ECU is sent, and the
//! conditions a run can add (disturbances at the ECU's boundary, named faults).
//!
//! | module | concept |
//! |---|---|
//! | [`track`] | track files (racetrack-database CSV), projection, curvature |
//! | [`csv_value`] | a track or obstacle file read line by line (optional header, `#` comments), and one number read from a cell, with errors that locate it |
//! | [`obstacle_file`] | obstacle files (`id,x_m,y_m`), polygon distances, footprints |
//! | [`obstacle_placement`] | boxes on any track; random obstacles from a seed |
//! | [`lap_patches`] | stretches of road along a lap with a value of their own (`START_M:LENGTH_M:VALUE`), shared by friction and grade |
//! | [`road_friction`] | friction that changes along the road (`--mu-patch`); μ̂ judged against it |
//! | [`road_grade`] | the road's grade along the lap (`--grade`); the grade under the car |
//! | [`scenario`] | the built-in `paper` scenario and `--track`/`--obstacles` resolution |
//! | [`route`] | the windows of the road the ECU holds, sent as the car moves on |
//! | [`disturbance`] | noise, delay, dropout, steering rate limit, late obstacle at the ECU's boundary |
//! | [`faults`] | named fault scenarios with their expected behaviour; run outcomes |

pub mod csv_value;
pub mod disturbance;
pub mod faults;
pub mod lap_patches;
pub mod obstacle_file;
pub mod obstacle_placement;
pub mod road_friction;
pub mod road_grade;
pub mod route;
pub mod scenario;
pub mod track;
