//! The firmware tests' one car, `VehicleConfig::reference()`, is the simulator's
//! built-in car and its shipped vehicle file, as the ECU's configuration frame
//! would carry them.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::vehicle_config::VehicleConfig;
use host_sim::model::vehicle::{vehicle_config, VehicleParams};
use std::path::Path;

#[test]
fn the_reference_car_is_the_simulators_built_in_car_and_its_shipped_file() {
    let built_in = VehicleParams::default();
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../host-sim/vehicles/default.toml");
    let shipped = VehicleParams::from_toml_file(&file).unwrap();
    assert_eq!(vehicle_config::<f64>(&built_in), VehicleConfig::reference());
    assert_eq!(vehicle_config::<f64>(&shipped), VehicleConfig::reference());
    // As the ECU holds it (f32).
    assert_eq!(vehicle_config::<f32>(&built_in), VehicleConfig::reference());
}
