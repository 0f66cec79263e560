//! The command line: `host-sim tire` round trip, error messages, and `run`, `pil` and
//! `sweep` speaking one language (the same scenario options, spelt alike).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::Command;

use host_sim::closed_loop::summary::Summary;
use host_sim::model::tire::{forces, TireParams};

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
fn a_bad_grade_or_actuator_is_refused_with_the_reason_in_run_pil_and_sweep() {
    let dir = tempfile::tempdir().unwrap();
    for (args, want) in [
        (&["--grade=300:200"][..], "wants START_M:LENGTH_M:PERCENT"),
        (
            &["--grade=300:200:6%"],
            "PERCENT \"6%\" is not a finite number",
        ),
        (
            &["--grade=300:200:35"],
            "PERCENT must be a grade in [-30, 30] %",
        ),
        (&["--grade", "-5:200:6"], "START_M must be ≥ 0"),
        (&["--grade=300:0:6"], "LENGTH_M must be a positive length"),
        // The paper track's lap is 980.6 m long.
        (
            &["--grade=5000:200:6"],
            "past the end of the lap of track `paper` (980.6",
        ),
        (&["--grade=0:3000:-6"], "does not fit track `paper` (980.6"),
        (
            &["--grade=100:300:6", "--grade=300:300:-6"],
            "give each stretch of road one grade",
        ),
        (&["--actuator=steering_lag_s=0.1"], "no actuator field"),
        (&["--actuator=torque_delay_s"], "wants KEY=VALUE"),
        (&["--actuator=torque_delay_s=2"], "must be in [0, 1] s"),
        (
            &["--actuator=steering_rate_limit_rad_per_s=0"],
            "a rate limit must be positive",
        ),
    ] {
        for cmd in ["run", "pil", "sweep"] {
            let mut c = host_sim();
            c.arg(cmd).args(args);
            if cmd == "sweep" {
                c.args(["--track", "paper"]);
            }
            let o = c
                .arg("--no-plots")
                .arg("--out")
                .arg(dir.path())
                .output()
                .unwrap();
            assert!(!o.status.success(), "{cmd} {args:?}");
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(err.contains(want), "{cmd} {args:?}: {err}");
            assert!(!err.contains("panicked"), "{cmd} {args:?}: {err}");
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

/// The clap definition of `run`, `pil` and `sweep` as their structs give it.
fn commands() -> [(&'static str, clap::Command); 3] {
    use clap::Args;
    [
        (
            "run",
            host_sim::commands::run::RunCommand::augment_args(clap::Command::new("run")),
        ),
        (
            "pil",
            host_sim::commands::pil::PilCommand::augment_args(clap::Command::new("pil")),
        ),
        (
            "sweep",
            host_sim::commands::sweep::SweepArgs::augment_args(clap::Command::new("sweep")),
        ),
    ]
}

/// An argument's spelling and meaning as clap holds them: long name, hidden
/// aliases, value names, defaults, help.
fn signature(a: &clap::Arg) -> String {
    format!(
        "{:?} {:?} {:?} {:?} {:?} {:?}",
        a.get_long(),
        a.get_all_aliases(),
        a.get_value_names(),
        a.get_default_values(),
        a.get_value_delimiter(),
        a.get_help().map(ToString::to_string),
    )
}

#[test]
fn run_pil_and_sweep_spell_every_scenario_option_alike() {
    use clap::Args;
    let shared =
        host_sim::commands::scenario_args::ScenarioArgs::augment_args(clap::Command::new("x"));
    let names: Vec<&str> = shared
        .get_arguments()
        .filter_map(|a| a.get_long())
        .collect();
    for want in [
        "track",
        "open",
        "obstacles",
        "seed",
        "mu",
        "mu-planner",
        "vehicle",
        "mass-scale",
        "noise",
        "delay-ms",
        "fault",
        "mu-patch",
        "grade",
        "actuator",
        "laps",
        "duration",
        "initial-speed",
    ] {
        assert!(names.contains(&want), "--{want} is not a shared option");
    }
    for a in shared.get_arguments() {
        for (cmd, c) in commands() {
            let b = c
                .get_arguments()
                .find(|b| b.get_id() == a.get_id())
                .unwrap_or_else(|| panic!("`{cmd}` lacks {:?}", a.get_long()));
            assert_eq!(signature(a), signature(b), "`{cmd}` --{:?}", a.get_long());
        }
    }
    // No command adds its own spelling of a shared option.
    for (cmd, c) in commands() {
        for b in c.get_arguments() {
            if shared.get_arguments().any(|a| a.get_id() == b.get_id()) {
                continue;
            }
            let long = b.get_long().unwrap_or_default();
            for a in shared.get_arguments() {
                let spellings: Vec<&str> = a
                    .get_long()
                    .into_iter()
                    .chain(a.get_all_aliases().unwrap_or_default())
                    .collect();
                assert!(
                    !spellings.contains(&long),
                    "`{cmd}` --{long} shadows a shared option"
                );
            }
        }
    }
}

#[test]
fn the_same_words_parse_to_the_same_scenario_in_run_pil_and_sweep_old_spellings_included() {
    use clap::FromArgMatches;
    let words = [
        "--track",
        "paper",
        "--obstacles",
        "random:3",
        "--seed",
        "2",
        "--mu",
        "0.8",
        "--mu-planner",
        "0.7",
        "--vehicle",
        "car.toml",
        "--mass-scale",
        "1.1",
        "--noise",
        "low",
        "--delay-ms",
        "20",
        "--fault",
        "mu-high:1.2",
        "--mu-patch",
        "100:50:0.5",
        "--grade",
        "200:100:-6",
        "--actuator",
        "torque_time_constant_s=0.05",
        "--laps",
        "2",
        "--duration",
        "30",
        "--initial-speed",
        "12",
        "--open",
        "--out",
        "o",
    ];
    let old = words.map(|w| match w {
        "--track" => "--tracks",
        "--mu-planner" => "--planner-mu",
        "--fault" => "--faults",
        w => w,
    });
    let mut parsed = Vec::new();
    for w in [&words, &old] {
        for (cmd, c) in commands() {
            let m = c
                .clone()
                .try_get_matches_from(std::iter::once(cmd).chain(w.iter().copied()))
                .unwrap_or_else(|e| panic!("`{cmd}` {w:?}: {e}"));
            let scenario = match cmd {
                "run" => {
                    host_sim::commands::run::RunCommand::from_arg_matches(&m)
                        .unwrap()
                        .scenario
                }
                "pil" => {
                    host_sim::commands::pil::PilCommand::from_arg_matches(&m)
                        .unwrap()
                        .run
                        .scenario
                }
                _ => {
                    host_sim::commands::sweep::SweepArgs::from_arg_matches(&m)
                        .unwrap()
                        .scenario
                }
            };
            parsed.push((cmd, scenario));
        }
    }
    let first = &parsed[0].1;
    assert_eq!(first.obstacles.to_string(), "random:3");
    assert_eq!(first.mu_planner, vec![0.7]);
    assert_eq!(first.faults[0].to_string(), "mu-high:1.2");
    for (cmd, p) in &parsed {
        assert_eq!(p, first, "`{cmd}` read the same words differently");
    }
}

#[test]
fn the_help_of_run_pil_and_sweep_lists_every_fault_scenario_from_the_table() {
    for cmd in ["run", "pil", "sweep"] {
        let o = host_sim().args([cmd, "--help"]).output().unwrap();
        assert!(o.status.success());
        let help = String::from_utf8_lossy(&o.stdout);
        for k in &host_sim::world::faults::FAULT_KINDS {
            assert!(
                help.contains(&k.usage()),
                "`{cmd} --help` lacks {}",
                k.usage()
            );
            assert!(help.contains(k.expected), "`{cmd} --help`: {}", k.expected);
            if let Some(p) = k.param {
                assert!(
                    help.contains(&format!(
                        "{}: {}, default {}",
                        p.placeholder, p.meaning, p.default
                    )),
                    "`{cmd} --help`: the default of {}",
                    k.name
                );
            }
        }
    }
}

/// Runs `host-sim args`, expecting failure; its standard error.
fn fails(args: &[&str]) -> String {
    let o = host_sim().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{args:?} exited 0: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    err
}

#[test]
fn a_missing_path_is_refused_before_any_run_with_the_forms_accepted_and_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    for cmd in ["run", "pil", "sweep"] {
        let err = fails(&[cmd, "--obstacles", "/no/such.csv", "--out", out]);
        assert!(
            err.contains("--obstacles /no/such.csv: no such file")
                && err.contains("random:N")
                && err.contains("id,x_m,y_m"),
            "{cmd}: {err}"
        );
        let err = fails(&[cmd, "--track", "/no/such/folder", "--out", out]);
        assert!(
            err.contains("--track /no/such/folder: no such file or folder")
                && err.contains("paper"),
            "{cmd}: {err}"
        );
        let err = fails(&[cmd, "--vehicle", "/no/car.toml", "--out", out]);
        assert!(
            err.contains("--vehicle /no/car.toml: no such file"),
            "{cmd}: {err}"
        );
    }
    assert!(
        !Path::new(out).exists(),
        "nothing is written when an argument is refused"
    );
    // A file that cannot be read names itself and its cause, once (as `main`
    // prints an error: the chain of causes on one line).
    let missing = dir.path().join("missing.csv");
    for path in [missing.as_path(), dir.path()] {
        let e = host_sim::world::obstacle_file::load_obstacles_path(path).unwrap_err();
        let chain = format!("{:#}", anyhow::Error::new(e));
        assert_eq!(chain.matches("(os error").count(), 1, "{chain}");
        assert!(chain.contains(&path.display().to_string()), "{chain}");
        let e = host_sim::world::track::Track::from_csv_path(path, true).unwrap_err();
        let chain = format!("{:#}", anyhow::Error::new(e));
        assert_eq!(chain.matches("(os error").count(), 1, "{chain}");
    }
    let e = host_sim::model::vehicle::VehicleParams::from_toml_file(&missing).unwrap_err();
    let chain = format!("{:#}", anyhow::Error::new(e));
    assert_eq!(chain.matches("(os error").count(), 1, "{chain}");
}

#[test]
fn run_and_pil_take_one_value_of_each_option_and_pil_refuses_what_it_cannot_apply() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    for cmd in ["run", "pil"] {
        let err = fails(&[cmd, "--mu", "1,0.5", "--out", out]);
        assert!(
            err.contains("--mu 1,0.5: `") && err.contains("give one value"),
            "{err}"
        );
        let err = fails(&[cmd, "--track", "paper", "paper", "--out", out]);
        assert!(err.contains("give one value"), "{err}");
    }
    for (args, want) in [
        (&["--noise", "low"][..], "PIL does not apply them"),
        (&["--delay-ms", "50"][..], "PIL does not apply them"),
        (&["--fault", "dropout-nan"][..], "PIL cannot apply it"),
        (&["--fault", "late-obstacle"][..], "PIL cannot apply it"),
        (&["--fault", "overrun"][..], "PIL cannot apply it"),
        (&["--fault", "steer-rate"][..], "PIL cannot apply it"),
        (&["--precision", "f64"][..], "PIL runs are f32 only"),
        (&["--ecu-mhz", "100"][..], "the ECU's own (virtual) clock"),
    ] {
        let err = fails(&[&["pil"][..], args, &["--out", out]].concat());
        assert!(err.contains(want), "pil {args:?}: {err}");
    }
    let err = fails(&[
        "run",
        "--fault",
        "overrun",
        "--ecu-mhz",
        "100",
        "--out",
        out,
    ]);
    assert!(err.contains("sets the ECU clock itself"), "{err}");
}

#[test]
fn run_places_random_obstacles_from_its_seed_as_the_sweep_does() {
    let dir = tempfile::tempdir().unwrap();
    let clearance = |seed: &str| -> Option<f64> {
        let out = dir.path().join(seed);
        let o = host_sim()
            .args(["run", "--obstacles", "random:3", "--seed", seed])
            .args(["--duration", "1", "--no-plots", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let s: Summary =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
                .unwrap();
        s.min_obstacle_clearance_m
    };
    let a = clearance("0");
    assert!(a.is_some(), "no obstacle placed: {a:?}");
    assert_eq!(a, clearance("0"));
    assert_ne!(a, clearance("1"), "the seed draws other obstacles");
}

#[test]
fn a_sweep_whose_track_is_missing_exits_non_zero_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let err = fails(&[
        "sweep",
        "--tracks",
        "/no/such/folder",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(err.contains("/no/such/folder"), "{err}");
    assert!(!out.join("sweep.csv").exists());
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = fails(&["sweep", "--track", empty.to_str().unwrap(), "--list"]);
    assert!(err.contains("no *.csv track file"), "{err}");
}

#[test]
fn run_with_a_sweep_runs_factors_replays_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = |s: &str| dir.path().join(s).display().to_string();
    let factors = [
        "--track",
        "paper",
        "--mu",
        "0.8",
        "--obstacles",
        "random:3",
        "--noise",
        "low",
        "--delay-ms",
        "20",
        "--mass-scale",
        "1.2",
        "--fault",
        "steer-rate:0.4",
        "--grade",
        "50:100:-6",
        "--actuator",
        "steering_time_constant_s=0.05",
        "--seed",
        "1",
        "--duration",
        "6",
        "--no-plots",
    ];
    for (cmd, out) in [("sweep", d("sweep")), ("run", d("run"))] {
        let o = host_sim()
            .arg(cmd)
            .args(factors)
            .args(["--out", &out])
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{cmd}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let mut r = csv::Reader::from_path(dir.path().join("sweep/sweep.csv")).unwrap();
    let head: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let row: Vec<String> = r
        .records()
        .next()
        .unwrap()
        .unwrap()
        .iter()
        .map(String::from)
        .collect();
    let summary: Summary = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("run/summary.json")).unwrap(),
    )
    .unwrap();
    let summary = serde_json::to_value(&summary).unwrap();
    let cell = |k: &str| &row[head.iter().position(|h| h == k).unwrap()];
    assert_ne!(cell("obstacle_count"), "0");
    assert_eq!(cell("fault"), "steer-rate:0.4");
    assert_eq!(cell("grade_patches"), "50:100:-6");
    assert_eq!(cell("actuators"), "steering_time_constant_s=0.05");
    let mut compared = 0;
    for (k, v) in summary.as_object().unwrap() {
        let Some(i) = head.iter().position(|h| h == k) else {
            continue; // host wall time: not in sweep.csv
        };
        let got = match v {
            serde_json::Value::Null => String::new(),
            serde_json::Value::String(s) => s.clone(),
            v => v.to_string(),
        };
        let same = got == row[i]
            || matches!((got.parse::<f64>(), row[i].parse::<f64>()), (Ok(a), Ok(b)) if a == b);
        assert!(same, "{k}: run {got}, sweep {}", row[i]);
        compared += 1;
    }
    assert!(compared > 40, "{compared} fields compared");
}
