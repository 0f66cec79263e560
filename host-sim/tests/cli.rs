//! The command line: `host-sim tire` round trip and error messages.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

use host_sim::tire::{forces, TireParams};

fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

#[test]
fn tire_round_trip_on_a_small_csv() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.csv");
    let out = dir.path().join("out.csv");
    std::fs::write(
        &input,
        "kappa,alpha_rad,fz_n,mu\n0.0,0.0,4000,1\n0.1,0.0,4000,1\n0.0,0.05,3000,0.8\n-0.2,-0.1,5000,1\n",
    )
    .unwrap();
    let st = host_sim()
        .args(["tire", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(st.success());
    let mut r = csv::Reader::from_path(&out).unwrap();
    assert_eq!(
        r.headers().unwrap(),
        vec!["kappa", "alpha_rad", "fz_n", "mu", "fx_n", "fy_n"]
    );
    let rows: Vec<Vec<f64>> = r
        .records()
        .map(|rec| rec.unwrap().iter().map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 4);
    let p = TireParams::default();
    for row in &rows {
        let (fx, fy) = forces(row[0], row[1], row[2], row[3], &p);
        assert_eq!((row[4], row[5]), (fx, fy));
    }
    assert!(rows[1][4] > 3000.0);
    assert!(rows[2][5] > 1000.0);
    assert!(rows[3][4] < 0.0 && rows[3][5] < 0.0);
}

#[test]
fn a_bad_row_is_reported_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.csv");
    std::fs::write(
        &input,
        "kappa,alpha_rad,fz_n,mu\n0.1,0,4000,1\n0.1,zero,4000,1\n",
    )
    .unwrap();
    let o = host_sim()
        .args(["tire", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(dir.path().join("out.csv"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("line 3"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    std::fs::write(&input, "kappa,alpha_rad,fz_n,mu\n0.1,0,-4000,1\n").unwrap();
    let o = host_sim()
        .args(["tire", "--input"])
        .arg(&input)
        .arg("--out")
        .arg(dir.path().join("out.csv"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("line 2") && err.contains("fz_n"),
        "{err}"
    );
}

#[test]
fn a_bad_vehicle_file_is_reported_with_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let car = dir.path().join("x.toml");
    let template = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/vehicles/default.toml"
    ))
    .unwrap();
    std::fs::write(&car, template.replace("mass_kg = 1500.0", "mass_kg = -3")).unwrap();
    let o = host_sim()
        .args(["validity", "--radii", "20", "--vehicle"])
        .arg(&car)
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("x.toml") && err.contains(r#"field "mass_kg": must be positive, got -3"#),
        "{err}"
    );
}

#[test]
fn an_ecu_clock_that_is_not_positive_is_refused_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    for mhz in ["0", "-5", "nan", "inf"] {
        let o = host_sim()
            .args(["run", "--no-plots", &format!("--ecu-mhz={mhz}"), "--out"])
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--ecu-mhz must be a positive"), "{mhz}: {err}");
    }
}

#[test]
fn a_bad_mu_patch_is_refused_with_the_reason_and_the_lap_length() {
    let dir = tempfile::tempdir().unwrap();
    for (spec, want) in [
        ("300:200", "START_M:LENGTH_M:MU"),
        ("300:x:0.5", "LENGTH_M \"x\" is not a finite number"),
        ("300:0:0.5", "LENGTH_M must be a positive length"),
        ("300:-20:0.5", "LENGTH_M must be a positive length"),
        ("300:200:0", "MU must be a friction coefficient in (0, 2]"),
        ("300:200:nan", "MU \"nan\" is not a finite number"),
        ("-5:200:0.5", "START_M must be ≥ 0"),
        // The paper track's lap is 980.6 m long.
        (
            "5000:200:0.5",
            "past the end of the lap of track `paper` (980.6",
        ),
        ("0:3000:0.5", "does not fit track `paper` (980.6"),
    ] {
        for cmd in ["run", "pil", "sweep"] {
            let mut c = host_sim();
            c.arg(cmd).arg(format!("--mu-patch={spec}"));
            if cmd == "sweep" {
                c.args(["--tracks", "paper"]);
            }
            let o = c
                .arg("--no-plots")
                .arg("--out")
                .arg(dir.path())
                .output()
                .unwrap();
            assert!(!o.status.success(), "{cmd} {spec}");
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(err.contains(want), "{cmd} {spec}: {err}");
            assert!(!err.contains("panicked"), "{cmd} {spec}: {err}");
        }
    }
}

#[test]
fn run_refuses_a_bad_load_noise_or_delay() {
    let dir = tempfile::tempdir().unwrap();
    for (arg, want) in [
        ("--mass-scale=0", "--mass-scale wants factors in (0.2, 5)"),
        ("--mass-scale=nan", "--mass-scale wants factors"),
        ("--noise=loud", "none, low, medium, high or a number"),
        ("--delay-ms=-10", "--delay-ms wants delays in [0, 1000] ms"),
    ] {
        let o = host_sim()
            .arg("run")
            .arg(arg)
            .args(["--no-plots", "--out"])
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(!o.status.success(), "{arg}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(want), "{arg}: {err}");
    }
}
