//! The ECU's set-up from frames: the same path as the simulator's loader, bit for
//! bit, and a named refusal for every way the frames can be wrong.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use firmware::link::{ConfigFrame, ObstacleFrame, PathChunkFrame, SetupError, PATH_CHUNK_ROWS};
use firmware::mpc::MpcSettings;
use firmware::obstacles::MAX_VERTICES;
use firmware::reference_path::ReferencePath;
use firmware::setup::Setup;
use firmware::tasks::PlanTask;
use firmware::vehicle_config::VehicleConfig;

const CAP: usize = 256;

fn car() -> VehicleConfig<f32> {
    VehicleConfig::reference()
}

/// A closed loop of 100 noisy points round a 40 m circle, 4 m half-widths.
fn rows() -> Vec<[f32; 4]> {
    (0..100)
        .map(|i| {
            let a = i as f32 * 0.0628318;
            let r = 40.0 + 0.03 * ((i * 7919) % 13) as f32;
            [r * a.cos(), r * a.sin(), 4.0, 4.0]
        })
        .collect()
}

fn config(rows: usize, obstacles: u8) -> ConfigFrame {
    ConfigFrame {
        vehicle: car(),
        mu_planner: 1.0,
        closed: true,
        path_rows: rows as u16,
        obstacles,
    }
}

fn chunks(rows: &[[f32; 4]]) -> Vec<PathChunkFrame> {
    rows.chunks(PATH_CHUNK_ROWS)
        .enumerate()
        .map(|(c, ch)| {
            let mut f = PathChunkFrame {
                first: (c * PATH_CHUNK_ROWS) as u16,
                count: ch.len() as u8,
                rows: [[0.0; 4]; PATH_CHUNK_ROWS],
            };
            f.rows[..ch.len()].copy_from_slice(ch);
            f
        })
        .collect()
}

fn planner() -> Box<PlanTask<f32, CAP>> {
    Box::new(PlanTask::new(MpcSettings::unset(), 0.0))
}

#[test]
fn the_path_from_frames_is_the_simulator_s_path_bit_for_bit() {
    let rows = rows();
    let mut p = planner();
    let mut s = Setup::new();
    s.config(&config(rows.len(), 0), &mut p);
    for c in chunks(&rows) {
        s.path_chunk(&c, &mut p);
    }
    s.finish(&mut p).unwrap();
    let mut direct: Box<ReferencePath<f32, CAP>> = Box::new(ReferencePath::new());
    direct.load_track(&rows, true).unwrap();
    assert_eq!(p.path.len(), direct.len());
    assert_eq!(p.path.length_m().to_bits(), direct.length_m().to_bits());
    for k in 0..400 {
        let s_m = k as f32 * 0.7;
        assert_eq!(p.path.position_at(s_m), direct.position_at(s_m));
        assert_eq!(
            p.path.curvature_at(s_m).to_bits(),
            direct.curvature_at(s_m).to_bits()
        );
        assert_eq!(
            p.path.heading_at(s_m).to_bits(),
            direct.heading_at(s_m).to_bits()
        );
    }
    // The planner got the car's settings.
    assert_eq!(p.settings, car().mpc_settings());
}

#[test]
fn every_wrong_set_up_is_refused_with_its_reason() {
    let rows = rows();
    let refuse = |f: &dyn Fn(&mut Setup, &mut PlanTask<f32, CAP>)| {
        let mut p = planner();
        let mut s = Setup::new();
        f(&mut s, &mut p);
        s.finish(&mut p).expect_err("refused")
    };
    // No configuration.
    assert_eq!(refuse(&|_, _| {}).error, SetupError::NoConfig);
    // A NaN in the car.
    let e = refuse(&|s, p| {
        let mut c = config(rows.len(), 0);
        c.vehicle.mass_kg = f32::NAN;
        s.config(&c, p);
    });
    assert_eq!(e.error, SetupError::InvalidConfig);
    // More rows than the ECU holds.
    let e = refuse(&|s, p| s.config(&config(CAP + 1, 0), p));
    assert_eq!((e.error, e.detail), (SetupError::PathTooLong, CAP as u16));
    // A chunk out of order.
    let e = refuse(&|s, p| {
        s.config(&config(rows.len(), 0), p);
        let c = chunks(&rows);
        s.path_chunk(&c[1], p);
    });
    assert_eq!((e.error, e.detail), (SetupError::PathChunkOutOfRange, 16));
    // Rows missing.
    let e = refuse(&|s, p| {
        s.config(&config(rows.len(), 0), p);
        s.path_chunk(&chunks(&rows)[0], p);
    });
    assert_eq!((e.error, e.detail), (SetupError::MissingPathRow, 16));
    // A non-finite row.
    let e = refuse(&|s, p| {
        let mut bad = rows.clone();
        bad[37][1] = f32::INFINITY;
        s.config(&config(bad.len(), 0), p);
        for c in chunks(&bad) {
            s.path_chunk(&c, p);
        }
    });
    assert_eq!((e.error, e.detail), (SetupError::InvalidPathRow, 37));
    // An obstacle across the whole road.
    let e = refuse(&|s, p| {
        s.config(&config(rows.len(), 1), p);
        for c in chunks(&rows) {
            s.path_chunk(&c, p);
        }
        let mut o = ObstacleFrame {
            index: 0,
            total: 1,
            id: 7,
            count: 4,
            vertices: [[0.0; 2]; MAX_VERTICES],
        };
        o.vertices[..4].copy_from_slice(&[[34.0, -1.0], [46.0, -1.0], [46.0, 1.0], [34.0, 1.0]]);
        s.obstacle(&o);
    });
    assert_eq!((e.error, e.detail), (SetupError::ObstacleBlocksRoad, 0));
    // An obstacle announced but never sent.
    let e = refuse(&|s, p| {
        s.config(&config(rows.len(), 1), p);
        for c in chunks(&rows) {
            s.path_chunk(&c, p);
        }
    });
    assert_eq!(e.error, SetupError::MissingObstacle);
}
