//! Planning and control firmware of an automated car, after Polack et al.,
//! *Guaranteeing Consistency in a Motion Planning and Control Architecture Using a
//! Kinematic Bicycle Model* (ACC 2018).
//!
//! `no_std`, no heap, no `alloc`, no recursion; every size is a compile-time
//! constant. One module per concept of the paper:
//!
//! | module | concept |
//! |---|---|
//! | [`reference_path`] | centre line: arc length, projection, heading, curvature |
//! | [`bicycle`] | kinematic bicycle model, its discretisation and Jacobians |
//! | [`sideslip`] | online estimate of how far a real car's course lags the kinematic bicycle's in a bend |
//! | [`validity`] | the validity limit `δ_max(V)` keeping `a_y ≤ 0.5·μ·g` |
//! | [`velocity_planner`] | local velocity planner, `V_heur` |
//! | [`obstacles`] | obstacle manager: one forbidden parabola per obstacle |
//! | [`mpc`] | the local MPC planner (linearise, condense, solve; warm start by row identity) |
//! | [`pid`] | PID controller |
//! | [`longitudinal_estimator`] | online estimate of the car's effective mass and driving resistances |
//! | [`friction`] | online friction check: `μ̂` from what the tyres deliver |
//! | [`low_level`] | low-level control: torque dispatch, `δ = δ_ol + δ_cl` |
//! | [`plan`], [`state_estimate`] | the two resources the tasks share |
//! | [`tasks`] | the 100 Hz `control` and 10 Hz `plan` tasks |
//! | [`timing`] | the ECU's clock and the tasks' periods, each written once |
//! | [`clock_tree`] | the STM32F405's clock tree from the board's crystal to the ECU's clock, RM0090's sequence over a register-access trait |
//! | [`deadline`] | the tasks' releases, response times, misses and overruns on the ECU's clock; the watchdog |
//! | [`vehicle_config`] | the car's numbers the settings derive from |
//! | [`link`] | frames between the ECU and the simulator (processor-in-the-loop) |
//!
//! The maths is generic over [`Real`] (`f32` on the ECU). Units are SI (m, s,
//! rad, N, N·m, kg); vehicle frame x forward, y left; yaw counter-clockwise.
#![cfg_attr(not(test), no_std)]

pub mod bicycle;
pub mod clock_tree;
pub mod deadline;
pub mod friction;
pub mod link;
pub mod longitudinal_estimator;
pub mod low_level;
pub mod mpc;
pub mod obstacles;
pub mod pid;
pub mod plan;
pub mod reference_path;
pub mod setup;
pub mod sideslip;
pub mod state_estimate;
pub mod tasks;
pub mod timing;
pub mod validity;
pub mod vehicle_config;
pub mod velocity_planner;

/// The scalar trait, from the QP solver's crate (`qp`), which the MPC's solver uses.
pub use qp::Real;

/// Standard gravity, m/s².
pub const G: f32 = 9.81;
