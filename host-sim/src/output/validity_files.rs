//! The files of the validity experiment ([`crate::closed_loop::validity`]):
//! `validity.csv`, one row per steady state, and `validity.png`.

use std::path::Path;

use anyhow::Context;
use plotters::prelude::*;

use crate::closed_loop::validity::RadiusSweep;
use crate::model::vehicle::G;
use crate::output::plot;

/// Writes `validity.csv` (columns `radius_m,speed_mps,ay_mps2,delta_a_rad,delta_th_rad`).
pub fn write_csv(path: &Path, sweeps: &[RadiusSweep]) -> anyhow::Result<()> {
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_path(path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    w.write_record([
        "radius_m",
        "speed_mps",
        "ay_mps2",
        "delta_a_rad",
        "delta_th_rad",
    ])
    .with_context(|| format!("cannot write {}", path.display()))?;
    for p in sweeps.iter().flat_map(|s| s.points.iter()) {
        w.serialize(p)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// Draws `validity.png`: `δ_a` against speed per radius, `δ_th` as horizontal lines,
/// and a cross where the lateral acceleration reaches `0.5·μ·g`.
pub fn write_plot(path: &Path, sweeps: &[RadiusSweep], mu: f64) -> Result<(), plot::PlotError> {
    plot::register_font()?;
    let err = |e: &dyn std::fmt::Display| plot::draw_error(path, e);
    let root = BitMapBackend::new(path, (1100, 750)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let all = sweeps.iter().flat_map(|s| s.points.iter());
    let v_max = all
        .clone()
        .map(|p| p.speed_mps)
        .fold(1.0_f64, f64::max)
        .ceil();
    let d_max = all
        .map(|p| p.delta_a_rad.to_degrees())
        .chain(sweeps.iter().map(|s| s.delta_th_rad.to_degrees()))
        .fold(1.0_f64, f64::max)
        * 1.08;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Steering on circles: 9-DoF plant delta_a (dots) vs kinematic delta_th (thin lines), mu = {mu}"
            ),
            (plot::FONT, 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..v_max, 0.0..d_max)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("speed V (m/s)")
        .y_desc("front steering angle (deg)")
        .label_style((plot::FONT, 15))
        .draw()
        .map_err(|e| err(&e))?;
    let ay_lim = 0.5 * mu * G;
    for (i, s) in sweeps.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let th = s.delta_th_rad.to_degrees();
        chart
            .draw_series(LineSeries::new(
                [(0.0, th), (v_max, th)],
                color.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| err(&e))?;
        chart
            .draw_series(LineSeries::new(
                s.points
                    .iter()
                    .map(|p| (p.speed_mps, p.delta_a_rad.to_degrees())),
                color.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(format!("R = {} m", s.radius_m))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2)));
        chart
            .draw_series(
                s.points.iter().map(|p| {
                    Circle::new((p.speed_mps, p.delta_a_rad.to_degrees()), 2, color.filled())
                }),
            )
            .map_err(|e| err(&e))?;
        // Where a_y crosses 0.5·μ·g.
        if let Some(w) = s
            .points
            .windows(2)
            .find(|w| w[0].ay_mps2 < ay_lim && w[1].ay_mps2 >= ay_lim)
        {
            let f = (ay_lim - w[0].ay_mps2) / (w[1].ay_mps2 - w[0].ay_mps2);
            let v = w[0].speed_mps + f * (w[1].speed_mps - w[0].speed_mps);
            let d = w[0].delta_a_rad + f * (w[1].delta_a_rad - w[0].delta_a_rad);
            chart
                .draw_series([Cross::new((v, d.to_degrees()), 8, BLACK.stroke_width(2))])
                .map_err(|e| err(&e))?;
        }
    }
    chart
        .draw_series(Vec::<Cross<(f64, f64), i32>>::new())
        .map_err(|e| err(&e))?
        .label("a_y = 0.5 mu g")
        .legend(|(x, y)| Cross::new((x + 10, y), 6, BLACK.stroke_width(2)));
    plot::draw_legend(&mut chart).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
