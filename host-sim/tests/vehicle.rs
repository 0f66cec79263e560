//! Vehicle files: the shipped template, and errors that name the field.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use host_sim::model::vehicle::{VehicleError, VehicleParams};

const TEMPLATE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/vehicles/default.toml");

fn template() -> String {
    std::fs::read_to_string(TEMPLATE).unwrap()
}

fn error_of(text: &str) -> String {
    VehicleParams::from_toml_str(text).unwrap_err().to_string()
}

#[test]
fn the_template_is_exactly_the_built_in_vehicle() {
    let v = VehicleParams::from_toml_file(TEMPLATE).unwrap();
    assert_eq!(v, VehicleParams::default());
    VehicleParams::default().validate().unwrap();
}

#[test]
fn a_missing_field_is_named() {
    let text = template().replace("mass_kg = 1500.0", "");
    let e = error_of(&text);
    assert!(e.contains("missing field") && e.contains("mass_kg"), "{e}");
    assert!(e.starts_with("vehicle file"), "{e}");
}

#[test]
fn an_unknown_field_is_named() {
    let text = template().replace("mass_kg = 1500.0", "mass_kg = 1500.0\nmass_lb = 3300.0");
    let e = error_of(&text);
    assert!(e.contains("unknown field") && e.contains("mass_lb"), "{e}");
    let text = template().replace("pcx1 = 1.685", "pcx1 = 1.685\nqbz1 = 8.9");
    let e = error_of(&text);
    assert!(e.contains("unknown field") && e.contains("qbz1"), "{e}");
}

#[test]
fn a_negative_mass_is_rejected_with_its_value() {
    let text = template().replace("mass_kg = 1500.0", "mass_kg = -3.0");
    let e = error_of(&text);
    assert!(
        e.contains(r#"field "mass_kg": must be positive, got -3"#),
        "{e}"
    );
}

#[test]
fn non_finite_numbers_are_rejected() {
    let e = error_of(&template().replace("iz_kg_m2 = 2500.0", "iz_kg_m2 = nan"));
    assert!(e.contains(r#""iz_kg_m2""#) && e.contains("finite"), "{e}");
    let e = error_of(&template().replace("pky1 = -14.95", "pky1 = inf"));
    assert!(e.contains(r#""tyre.pky1""#) && e.contains("finite"), "{e}");
    let e = error_of(&template().replace("lr_m = 1.55", "lr_m = 0.0"));
    assert!(e.contains(r#""lr_m""#), "{e}");
}

#[test]
fn a_tyre_with_the_wrong_sign_convention_is_explained() {
    let e = error_of(&template().replace("pky1 = -14.95", "pky1 = 14.95"));
    assert!(e.contains("tyre.pky1") && e.contains("ISO"), "{e}");
}

#[test]
fn tyre_coefficients_default_to_zero_and_scales_to_one() {
    let text = template();
    let start = text.find("\n[tyre]").unwrap() + 1;
    let minimal = format!(
        "{}[tyre]\nfnomin = 4000.0\npcx1 = 1.6\npdx1 = 1.0\npkx1 = 20.0\npcy1 = 1.3\npdy1 = -1.0\npky1 = -15.0\npky2 = 2.0\n",
        &text[..start]
    );
    let v = VehicleParams::from_toml_str(&minimal).unwrap();
    assert_eq!(v.tyre.pex1, 0.0);
    assert_eq!(v.tyre.rvy6, 0.0);
    assert_eq!(v.tyre.lmux, 1.0);
    assert_eq!(v.tyre.lvyka, 1.0);
}

#[test]
fn the_rolling_resistance_is_optional_and_checked() {
    let line = template()
        .lines()
        .find(|l| l.starts_with("crr = "))
        .unwrap()
        .to_string();
    // Absent: none.
    let v = VehicleParams::from_toml_str(&template().replace(&line, "")).unwrap();
    assert_eq!(v.crr, 0.0);
    assert_eq!(VehicleParams::default().crr, 0.012);
    for (bad, says) in [
        ("crr = -0.01", "must be zero or positive"),
        ("crr = 0.2", "must be at most 0.1"),
        ("crr = nan", "finite"),
    ] {
        let e = error_of(&template().replace(&line, bad));
        assert!(
            e.contains(r#"field "crr""#) && e.contains(says),
            "{bad}: {e}"
        );
    }
}

#[test]
fn the_actuators_table_is_optional_and_its_fields_are_named() {
    // The template with its `[actuators]` table's lines replaced by `table`.
    let text = template();
    let a = text.find("[actuators]\n").unwrap();
    let b = a + text[a..].find("\n\n").unwrap();
    let with = |table: &str| format!("{}[actuators]\n{table}{}", &text[..a], &text[b..]);
    let without = VehicleParams::from_toml_str(&with("")).unwrap();
    assert_eq!(without, VehicleParams::default());
    let v = VehicleParams::from_toml_str(&with(
        "steering_time_constant_s = 0.08\ntorque_rate_limit_nm_per_s = 20000.0\nsteering_rate_limit_rad_per_s = inf",
    ))
    .unwrap();
    assert_eq!(v.actuators.steering_time_constant_s, 0.08);
    assert_eq!(v.actuators.torque_rate_limit_nm_per_s, 20000.0);
    assert_eq!(v.actuators.steering_rate_limit_rad_per_s, f64::INFINITY);
    assert_eq!(v.actuators.torque_delay_s, 0.0);
    let e = error_of(&with("steering_lag_s = 0.1"));
    assert!(
        e.contains("unknown field") && e.contains("steering_lag_s"),
        "{e}"
    );
    let e = error_of(&with("torque_delay_s = 1.5"));
    assert!(
        e.contains(r#"field "actuators.torque_delay_s""#) && e.contains("[0, 1] s"),
        "{e}"
    );
    let e = error_of(&with("steering_rate_limit_rad_per_s = 0.0"));
    assert!(
        e.contains(r#"field "actuators.steering_rate_limit_rad_per_s""#),
        "{e}"
    );
}

#[test]
fn an_unreadable_file_names_the_path() {
    let e = VehicleParams::from_toml_file("/nonexistent/car.toml").unwrap_err();
    assert!(matches!(e, VehicleError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/car.toml"), "{e}");
}

/// The light and heavy cars shipped beside the template.
fn shipped(name: &str) -> VehicleParams {
    let p = format!("{}/vehicles/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    VehicleParams::from_toml_file(&p).unwrap_or_else(|e| panic!("{p}: {e}"))
}

#[test]
fn the_light_and_heavy_cars_are_valid_and_differ_from_the_default_as_their_class() {
    let d = VehicleParams::default();
    let light = shipped("light");
    let heavy = shipped("heavy");
    for v in [&light, &heavy] {
        v.validate().unwrap();
        // Yaw inertia near m·l_f·l_r (NHTSA's measurements; the files' sources).
        let k = v.iz_kg_m2 / (v.mass_kg * v.lf_m * v.lr_m);
        assert!((0.85..=1.15).contains(&k), "I_z/(m·l_f·l_r) = {k}");
        // Most of the weight on the front (driven) axle, as for the default car.
        assert!(v.lr_m > v.lf_m);
    }
    assert!(light.mass_kg < 0.85 * d.mass_kg && light.iz_kg_m2 < d.iz_kg_m2);
    assert!(light.lf_m + light.lr_m < d.lf_m + d.lr_m);
    assert!(heavy.mass_kg > 1.4 * d.mass_kg && heavy.iz_kg_m2 > 1.5 * d.iz_kg_m2);
    assert!(heavy.h_m > d.h_m + 0.1, "SUV: higher centre of gravity");
    // SUV: the static stability factor of the class, T/(2h) in [1.0, 1.3].
    let ssf = heavy.lw_m / heavy.h_m;
    assert!((1.0..=1.3).contains(&ssf), "{ssf}");
    // Other tyres: a nominal load near each car's static front wheel load, and the
    // SUV's all-season tyre grips less than the book's.
    for v in [&light, &heavy] {
        let front = v.static_loads_n()[0];
        assert!(
            (v.tyre.fnomin / front - 1.0).abs() < 0.1,
            "{} vs {front}",
            v.tyre.fnomin
        );
    }
    assert!(heavy.tyre.lmuy < 1.0 && heavy.tyre.lky < 1.0);
    assert_ne!(heavy.tyre, d.tyre);
}
