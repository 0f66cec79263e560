//! Figures of a sweep: outcome rates per level of each factor that varies, the
//! largest lateral error and |a_y|/μg per track and friction against their bounds,
//! and the distribution of the consistency distance (plan vs executed).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use plotters::prelude::*;

use crate::output::plot::{draw_error, draw_legend, register_font, FONT};
use crate::sweep::aggregate::{Aggregate, TrackMu, BOUNDS};
use crate::sweep::table::{Row, FACTOR_COLUMNS};
use crate::world::faults::Outcome;

const W: u32 = 1400;
const H: u32 = 700;

/// The label of a category axis at `x`: category `i` spans `[i, i + 1)` and is
/// named at its middle only.
fn category_label<S: ToString>(names: &[S], x: f64) -> String {
    let i = x.floor() as usize;
    if (x - x.floor() - 0.5).abs() < 1e-6 {
        names.get(i).map(|s| s.to_string()).unwrap_or_default()
    } else {
        String::new()
    }
}

fn outcome_color(o: Outcome) -> RGBColor {
    match o {
        Outcome::Ok => RGBColor(60, 160, 60),
        Outcome::StoppedSafely => RGBColor(80, 140, 220),
        Outcome::DeadlineMiss => RGBColor(240, 170, 40),
        Outcome::OffRoad => RGBColor(200, 60, 200),
        Outcome::Collision => RGBColor(220, 40, 40),
        Outcome::Failed => RGBColor(90, 90, 90),
    }
}

/// Draws every sweep figure into `dir`.
pub fn draw_all(dir: &Path, rows: &[Row], agg: &Aggregate) -> Result<()> {
    register_font()?;
    for f in FACTOR_COLUMNS.iter().skip(1) {
        if let Some(levels) = agg.by_factor.get(f) {
            if levels.len() > 1 || *f == "track" {
                outcome_rates(&dir.join(format!("outcomes_by_{f}.png")), f, levels)?;
            }
        }
    }
    per_track(
        &dir.join("lateral_error.png"),
        "largest |lateral error| from the centre line per track and μ, bound dashed",
        "m",
        agg,
        |t| t.lat_max_m,
        None,
        BOUNDS.lateral_error_m,
    )?;
    per_track(
        &dir.join("ay_over_mu_g.png"),
        "largest |a_y|/μg per track: car (filled), plan's kinematic a_y (hollow), bound dashed",
        "|a_y| / μg",
        agg,
        |t| t.ay_over_mu_g,
        Some(|t: &TrackMu| t.plan_ay_over_mu_g),
        BOUNDS.ay_over_mu_g,
    )?;
    consistency(&dir.join("consistency.png"), rows)?;
    Ok(())
}

fn outcome_rates(
    path: &Path,
    factor: &str,
    levels: &BTreeMap<String, BTreeMap<&'static str, usize>>,
) -> Result<()> {
    let root = BitMapBackend::new(path, (W, H)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let n = levels.len();
    let names: Vec<&String> = levels.keys().collect();
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("outcome rates by {factor}"), (FONT, 22))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..n as f64, 0.0..1.0)
        .map_err(|e| draw_error(path, e))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.max(1) * 2 + 1)
        .x_label_formatter(&|x| category_label(&names, *x))
        .x_label_style((FONT, if n > 10 { 11 } else { 14 }))
        .y_desc("fraction of runs")
        .draw()
        .map_err(|e| draw_error(path, e))?;
    for o in Outcome::ALL.iter().rev() {
        let color = outcome_color(*o);
        let bars: Vec<Rectangle<(f64, f64)>> = levels
            .values()
            .enumerate()
            .filter_map(|(i, counts)| {
                let total: usize = counts.values().sum();
                if total == 0 {
                    return None;
                }
                // Stack in the order of Outcome::ALL reversed (ok at the bottom).
                let below: usize = Outcome::ALL
                    .iter()
                    .rev()
                    .take_while(|p| *p != o)
                    .map(|p| counts.get(p.name()).copied().unwrap_or(0))
                    .sum();
                let mine = counts.get(o.name()).copied().unwrap_or(0);
                if mine == 0 {
                    return None;
                }
                let (y0, y1) = (
                    below as f64 / total as f64,
                    (below + mine) as f64 / total as f64,
                );
                Some(Rectangle::new(
                    [(i as f64 + 0.15, y0), (i as f64 + 0.85, y1)],
                    color.filled(),
                ))
            })
            .collect();
        chart
            .draw_series(bars)
            .map_err(|e| draw_error(path, e))?
            .label(o.name())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
    }
    draw_legend(&mut chart).map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}

type Metric = fn(&TrackMu) -> f64;

fn per_track(
    path: &Path,
    title: &str,
    unit: &str,
    agg: &Aggregate,
    metric: Metric,
    second: Option<Metric>,
    bound: f64,
) -> Result<()> {
    let mut tracks: Vec<&str> = Vec::new();
    let mut mus: Vec<&str> = Vec::new();
    for t in &agg.per_track_mu {
        if !tracks.contains(&t.track.as_str()) {
            tracks.push(&t.track);
        }
        if !mus.contains(&t.mu.as_str()) {
            mus.push(&t.mu);
        }
    }
    let ymax = agg
        .per_track_mu
        .iter()
        .flat_map(|t| [metric(t), second.map_or(0.0, |f| f(t))])
        .filter(|x| x.is_finite())
        .fold(bound, f64::max)
        * 1.15;
    let root = BitMapBackend::new(path, (W, H)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let n = tracks.len().max(1);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..n as f64, 0.0..ymax)
        .map_err(|e| draw_error(path, e))?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n * 2 + 1)
        .x_label_formatter(&|x| category_label(&tracks, *x))
        .x_label_style((FONT, if n > 10 { 11 } else { 14 }))
        .y_desc(unit)
        .draw()
        .map_err(|e| draw_error(path, e))?;
    let palette = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    for (k, mu) in mus.iter().enumerate() {
        let color = palette[k % palette.len()];
        let dx = 0.3 + 0.4 * k as f64 / mus.len().max(1) as f64;
        let pts: Vec<(f64, f64, f64)> = agg
            .per_track_mu
            .iter()
            .filter(|t| t.mu == *mu)
            .filter_map(|t| {
                let i = tracks.iter().position(|x| *x == t.track)?;
                Some((i as f64 + dx, metric(t), second.map_or(f64::NAN, |f| f(t))))
            })
            .collect();
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.1.is_finite())
                    .map(|p| Circle::new((p.0, p.1), 6, color.filled())),
            )
            .map_err(|e| draw_error(path, e))?
            .label(format!("μ = {mu}"))
            .legend(move |(x, y)| Circle::new((x + 6, y), 5, color.filled()));
        if second.is_some() {
            chart
                .draw_series(
                    pts.iter()
                        .filter(|p| p.2.is_finite())
                        .map(|p| Circle::new((p.0, p.2), 6, color.stroke_width(2))),
                )
                .map_err(|e| draw_error(path, e))?;
        }
    }
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, bound), (n as f64, bound)],
            8,
            6,
            BLACK.stroke_width(2),
        ))
        .map_err(|e| draw_error(path, e))?;
    draw_legend(&mut chart).map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}

fn consistency(path: &Path, rows: &[Row]) -> Result<()> {
    let xs: Vec<f64> = rows
        .iter()
        .map(|r| r.consistency_m)
        .filter(|x| x.is_finite())
        .collect();
    let xmax = xs.iter().copied().fold(BOUNDS.consistency_m, f64::max) * 1.1;
    let bins = 30usize;
    let w = xmax / bins as f64;
    let mut counts = vec![0usize; bins];
    for x in &xs {
        counts[((x / w) as usize).min(bins - 1)] += 1;
    }
    let cmax = counts.iter().copied().max().unwrap_or(1).max(1);
    let root = BitMapBackend::new(path, (W, H)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "consistency: largest distance plan vs executed, per run (bound dashed)",
            (FONT, 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..xmax, 0.0..cmax as f64 * 1.1)
        .map_err(|e| draw_error(path, e))?;
    chart
        .configure_mesh()
        .x_desc("m")
        .y_desc("runs")
        .draw()
        .map_err(|e| draw_error(path, e))?;
    chart
        .draw_series(counts.iter().enumerate().map(|(i, &c)| {
            Rectangle::new(
                [(i as f64 * w, 0.0), ((i + 1) as f64 * w, c as f64)],
                BLUE.mix(0.6).filled(),
            )
        }))
        .map_err(|e| draw_error(path, e))?;
    chart
        .draw_series(DashedLineSeries::new(
            [
                (BOUNDS.consistency_m, 0.0),
                (BOUNDS.consistency_m, cmax as f64 * 1.1),
            ],
            8,
            6,
            RED.stroke_width(2),
        ))
        .map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}
