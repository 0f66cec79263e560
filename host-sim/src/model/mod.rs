//! The vehicle model: what the simulator drives in place of a car.
//!
//! | module | concept |
//! |---|---|
//! | [`vehicle`] | vehicle parameters, TOML vehicle files and their validation; what the firmware is told of the car |
//! | [`actuator`] | the steering and wheel-torque actuators: delay, first-order lag, rate limit |
//! | [`tire`] | Pacejka 2002 Magic Formula, combined slip |
//! | [`tire_table`] | tyre forces for a table of slips (what the `tire` command computes) |
//! | [`plant`] | the 9-DoF plant, RK4 at a fixed step |

pub mod actuator;
pub mod plant;
pub mod tire;
pub mod tire_table;
pub mod vehicle;
