//! Figures of a closed-loop run, like the paper's Figures 5–8, plus the cost of
//! each task against its budget.

use std::path::Path;

use anyhow::Result;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::closed_loop::timeline::{LogRow, RunResult};
use crate::output::plot::{draw_error, draw_legend, register_font, FONT};
use crate::world::road_friction::RoadFriction;
use crate::world::road_grade::{RoadGrade, MAX_GRADE_PCT};
use crate::world::scenario::Scenario;

const W: u32 = 1400;

/// How a line of a time-series figure is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stroke {
    /// A solid line this wide, px.
    Solid(u32),
    /// A dashed line this wide, px.
    Dashed(u32),
}

/// One line of a time-series figure: drawn in the order given (the last on top)
/// and named in the legend.
#[derive(Clone, Debug)]
struct Line {
    y: Vec<f64>,
    label: &'static str,
    color: RGBColor,
    stroke: Stroke,
}

/// Dark green: the green of plotters is hard to read on white.
const DARK_GREEN: RGBColor = RGBColor(0, 150, 0);

/// One column of the log.
fn column(log: &[LogRow], f: impl Fn(&LogRow) -> f64) -> Vec<f64> {
    log.iter().map(f).collect()
}

/// A reference column: it exists from the first plan on (the actuators are safe
/// before), NaN before.
fn planned(log: &[LogRow], f: impl Fn(&LogRow) -> f64) -> Vec<f64> {
    column(log, |l| {
        if l.control_mode == "safe" && l.plan_status == "none" {
            f64::NAN
        } else {
            f(l)
        }
    })
}

/// The speed figure's lines: the references dashed, the measured speed solid,
/// wider and drawn last, so it shows where it follows them.
fn speed_lines(log: &[LogRow]) -> Vec<Line> {
    vec![
        Line {
            y: planned(log, |l| l.v_heur_mps),
            label: "V_heur: the velocity planner's speed",
            color: RED,
            stroke: Stroke::Dashed(2),
        },
        Line {
            y: planned(log, |l| l.v_ref_mps),
            label: "V^r: the plan's reference speed",
            color: DARK_GREEN,
            // Wider than V, which follows it closely: it shows on both sides.
            stroke: Stroke::Dashed(6),
        },
        Line {
            y: column(log, |l| l.v_mps),
            label: "V: measured",
            color: BLUE,
            stroke: Stroke::Solid(2),
        },
    ]
}

/// Draws every figure of a run into `dir`.
pub fn draw_all(dir: &Path, scenario: &Scenario, r: &RunResult) -> Result<()> {
    register_font()?;
    trajectory(&dir.join("trajectory.png"), scenario, r)?;
    let log = &r.log;
    let t = column(log, |l| l.t_s);
    time_series(
        &dir.join("speed.png"),
        "Speed (references from the first plan)",
        "m/s",
        &t,
        &speed_lines(log),
    )?;
    time_series(
        &dir.join("steering.png"),
        "Steering",
        "rad",
        &t,
        &[
            Line {
                y: column(log, |l| l.delta_cl_rad),
                label: "δ_cl: closed-loop part",
                color: DARK_GREEN,
                stroke: Stroke::Solid(2),
            },
            Line {
                y: column(log, |l| l.delta_rad),
                label: "δ: commanded",
                color: RED,
                stroke: Stroke::Dashed(2),
            },
            Line {
                y: column(log, |l| l.delta_applied_rad),
                label: "δ: applied (the steering actuator's)",
                color: BLUE,
                stroke: Stroke::Solid(2),
            },
        ],
    )?;
    time_series(
        &dir.join("torque_fl.png"),
        "Front-left wheel torque",
        "N·m",
        &t,
        &[Line {
            y: column(log, |l| l.torque_fl_nm),
            label: "front-left torque",
            color: BLUE,
            stroke: Stroke::Solid(2),
        }],
    )?;
    let mu_g = r.summary.mu * f64::from(firmware::G);
    time_series(
        &dir.join("lateral.png"),
        "Lateral error and lateral acceleration",
        "m, -",
        &t,
        &[
            Line {
                y: column(log, |l| l.ay_mps2 / mu_g),
                label: "a_y / (μ·g)",
                color: RED,
                stroke: Stroke::Solid(2),
            },
            Line {
                y: column(log, |l| l.lateral_error_m),
                label: "lateral error, m",
                color: BLUE,
                stroke: Stroke::Solid(2),
            },
        ],
    )?;
    histogram(
        &dir.join("plan_cost.png"),
        "plan task: cost per activation vs budget (red)",
        &r.plan_costs,
        r.summary.plan_budget_cycles,
        1e6,
        "ECU M cycles (1 M = 5.95 ms at 168 MHz)",
    )?;
    histogram(
        &dir.join("control_cost.png"),
        "control task: cost per activation vs budget (red)",
        &r.control_costs,
        r.summary.control_budget_cycles,
        1e3,
        "ECU k cycles (1 k = 5.95 µs at 168 MHz)",
    )?;
    Ok(())
}

fn bounds(points: impl Iterator<Item = [f64; 2]>) -> (f64, f64, f64, f64) {
    points.fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(x0, x1, y0, y1), p| (x0.min(p[0]), x1.max(p[0]), y0.min(p[1]), y1.max(p[1])),
    )
}

fn trajectory(path: &Path, sc: &Scenario, r: &RunResult) -> Result<()> {
    let tr = &sc.track;
    let (mut left, mut right) = (Vec::new(), Vec::new());
    let n = tr.points.len();
    for i in 0..n {
        let a = tr.points[if i == 0 {
            if tr.closed {
                n - 1
            } else {
                0
            }
        } else {
            i - 1
        }];
        let b = tr.points[if i + 1 == n {
            if tr.closed {
                0
            } else {
                n - 1
            }
        } else {
            i + 1
        }];
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l = dx.hypot(dy).max(1e-9);
        let (nx, ny) = (-dy / l, dx / l);
        let p = tr.points[i];
        left.push((p[0] + nx * tr.w_left[i], p[1] + ny * tr.w_left[i]));
        right.push((p[0] - nx * tr.w_right[i], p[1] - ny * tr.w_right[i]));
    }
    let (x0, x1, y0, y1) = bounds(
        left.iter()
            .chain(right.iter())
            .map(|p| [p.0, p.1])
            .chain(r.log.iter().map(|l| [l.x_m, l.y_m])),
    );
    let span = (x1 - x0).max(y1 - y0).max(1.0);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let h = 0.5 * span * 1.05;
    let root = BitMapBackend::new(path, (W, W)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{}: actual (blue), plans (green), obstacles (red){}",
                tr.name,
                match (sc.mu_patches.is_empty(), sc.grade_patches.is_empty()) {
                    (true, true) => "",
                    (false, true) => ", road patches (shaded)",
                    (true, false) => ", grades (thick edges)",
                    (false, false) => ", road patches (shaded), grades (thick edges)",
                }
            ),
            (FONT, 24),
        )
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(cx - h..cx + h, cy - h..cy + h)
        .map_err(|e| draw_error(path, e))?;
    chart
        .configure_mesh()
        .x_desc("X (m)")
        .y_desc("Y (m)")
        .label_style((FONT, 14))
        .draw()
        .map_err(|e| draw_error(path, e))?;
    let grey = RGBColor(150, 150, 150);
    for edge in [&left, &right] {
        let mut pts = edge.clone();
        if tr.closed {
            if let Some(&f) = edge.first() {
                pts.push(f);
            }
        }
        chart
            .draw_series(LineSeries::new(pts, grey.stroke_width(1)))
            .map_err(|e| draw_error(path, e))?;
    }
    draw_patches(&mut chart, path, sc, r.summary.mu, &left, &right)?;
    for o in &sc.obstacles {
        let poly: Vec<(f64, f64)> = o.vertices.iter().map(|p| (p[0], p[1])).collect();
        chart
            .draw_series(std::iter::once(Polygon::new(poly, RED.filled())))
            .map_err(|e| draw_error(path, e))?;
    }
    for p in &r.plans {
        chart
            .draw_series(LineSeries::new(
                p.xy.iter().map(|q| (q[0], q[1])),
                GREEN.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| draw_error(path, e))?;
    }
    chart
        .draw_series(
            r.log
                .iter()
                .step_by(10)
                .map(|l| Circle::new((l.x_m, l.y_m), 2, BLUE.filled())),
        )
        .map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}

/// Marks the road's patches on the trajectory figure between the edges `left`,
/// `right` (one point per track point) and lists them in a legend: the patches of
/// their own friction (`--mu-patch`) shaded blue, the darker the lower their μ;
/// the stretches with a grade (`--grade`) as thick edges, orange uphill and purple
/// downhill, the stronger the steeper.
fn draw_patches<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    path: &Path,
    sc: &Scenario,
    base_mu: f64,
    left: &[(f64, f64)],
    right: &[(f64, f64)],
) -> Result<()> {
    let tr = &sc.track;
    if (sc.mu_patches.is_empty() && sc.grade_patches.is_empty()) || left.len() < 2 {
        return Ok(());
    }
    let road = RoadFriction::new(base_mu, &sc.mu_patches, &tr.name, tr.length(), tr.closed)?;
    let grade = RoadGrade::new(&sc.grade_patches, &tr.name, tr.length(), tr.closed)?;
    // Arc length of each edge point, the first point again at the lap's end.
    let mut s_pts = tr.arc_lengths();
    let (mut l, mut r) = (left.to_vec(), right.to_vec());
    if tr.closed {
        s_pts.push(tr.length());
        l.push(left[0]);
        r.push(right[0]);
    }
    let at = |edge: &[(f64, f64)], s: f64| -> (f64, f64) {
        let k = s_pts.partition_point(|&x| x <= s).clamp(1, s_pts.len() - 1);
        let (s0, s1) = (s_pts[k - 1], s_pts[k]);
        let f = if s1 > s0 {
            ((s - s0) / (s1 - s0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (a, b) = (edge[k - 1], edge[k]);
        (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
    };
    // An edge from arc length a to b, through the track's points between.
    let along = |edge: &[(f64, f64)], a: f64, b: f64| -> Vec<(f64, f64)> {
        let mut pts = vec![at(edge, a)];
        pts.extend(
            s_pts
                .iter()
                .filter(|&&x| x > a && x < b)
                .map(|&x| at(edge, x)),
        );
        pts.push(at(edge, b));
        pts
    };
    let blue = RGBColor(30, 110, 230);
    for (i, p) in sc.mu_patches.iter().enumerate() {
        // The spans of this patch (two when it runs over the lap line).
        let spans: Vec<(f64, f64)> = road.patch_spans(i).collect();
        let shade = blue.mix((0.15 + 0.5 * (1.0 - p.mu / base_mu.max(p.mu))).min(0.65));
        for (n, &(a, b)) in spans.iter().enumerate() {
            let mut poly = along(&l, a, b);
            poly.extend(along(&r, a, b).into_iter().rev());
            let series = chart
                .draw_series(std::iter::once(Polygon::new(poly, shade.filled())))
                .map_err(|e| draw_error(path, e))?;
            if n == 0 {
                series
                    .label(format!(
                        "patch {}: μ {} from {} m, {} m long",
                        i + 1,
                        p.mu,
                        p.start_m,
                        p.length_m
                    ))
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 6), (x + 16, y + 6)], shade.filled())
                    });
            }
        }
    }
    let (uphill, downhill) = (RGBColor(235, 120, 0), RGBColor(140, 40, 180));
    for (i, p) in sc.grade_patches.iter().enumerate() {
        let base = if p.percent >= 0.0 { uphill } else { downhill };
        let color = base.mix((0.4 + 0.6 * p.percent.abs() / MAX_GRADE_PCT).min(1.0));
        let style = color.stroke_width(5);
        for (n, (a, b)) in grade.patch_spans(i).enumerate() {
            for edge in [&l, &r] {
                let series = chart
                    .draw_series(LineSeries::new(along(edge, a, b), style))
                    .map_err(|e| draw_error(path, e))?;
                if n == 0 && std::ptr::eq(edge, &l) {
                    series
                        .label(format!(
                            "grade {}: {:+} % from {} m, {} m long",
                            i + 1,
                            p.percent,
                            p.start_m,
                            p.length_m
                        ))
                        .legend(move |(x, y)| {
                            PathElement::new([(x, y), (x + 16, y)], color.stroke_width(5))
                        });
                }
            }
        }
    }
    draw_legend(chart).map_err(|e| draw_error(path, e))?;
    Ok(())
}

fn time_series(path: &Path, title: &str, unit: &str, t: &[f64], lines: &[Line]) -> Result<()> {
    let root = BitMapBackend::new(path, (W, 450)).into_drawing_area();
    draw_time_series(&root, title, unit, t, lines).map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}

/// Draws `lines` against `t` on `root`, in order (the last on top), with a legend.
fn draw_time_series<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    unit: &str,
    t: &[f64],
    lines: &[Line],
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let t1 = t.last().copied().unwrap_or(1.0).max(1e-3);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for line in lines {
        for &v in &line.y {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        lo = -1.0;
        hi = 1.0;
    }
    let span = (hi - lo).max(1e-6);
    let pad = 0.05 * span;
    // Head room above the data for the legend (upper right), so it hides none of it:
    // about 24 px per line in a plot area of the height less the caption, margins
    // and the time axis.
    let plot_px = (f64::from(root.dim_in_pixel().1) - 110.0).max(50.0);
    let legend = ((24.0 * lines.len() as f64 + 16.0) / plot_px).min(0.6);
    let top = hi + pad + (span + 2.0 * pad) * legend / (1.0 - legend);
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t1, (lo - pad)..top)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(unit)
        .label_style((FONT, 14))
        .draw()
        .map_err(err)?;
    for line in lines {
        let (color, stroke) = (line.color, line.stroke);
        let style = match stroke {
            Stroke::Solid(w) | Stroke::Dashed(w) => color.stroke_width(w),
        };
        // Non-finite samples break the line (nothing is drawn there).
        let points: Vec<(f64, f64)> = t.iter().copied().zip(line.y.iter().copied()).collect();
        let mut labelled = false;
        for run in points.split(|p| !p.1.is_finite()).filter(|r| !r.is_empty()) {
            let series = match stroke {
                Stroke::Solid(_) => chart
                    .draw_series(LineSeries::new(run.iter().copied(), style))
                    .map_err(err)?,
                Stroke::Dashed(_) => chart
                    .draw_series(DashedLineSeries::new(run.iter().copied(), 8, 5, style))
                    .map_err(err)?,
            };
            if !labelled {
                labelled = true;
                series.label(line.label).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3))
                });
            }
        }
    }
    draw_legend(&mut chart).map_err(err)?;
    Ok(())
}

/// Histogram of activation costs (cycles) against the budget, the axis in the
/// readable unit `unit` (`scale` cycles each, e.g. 1e6 for M cycles).
fn histogram(
    path: &Path,
    title: &str,
    costs: &[f64],
    budget: f64,
    scale: f64,
    unit: &str,
) -> Result<()> {
    let costs: Vec<f64> = costs.iter().map(|c| c / scale).collect();
    let budget = budget / scale;
    let max = costs.iter().copied().fold(0.0f64, f64::max).max(budget) * 1.05;
    let bins = 60usize;
    let width = (max / bins as f64).max(f64::MIN_POSITIVE);
    let mut counts = vec![0u32; bins + 1];
    for &c in &costs {
        let i = ((c / width) as usize).min(bins);
        counts[i] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
    let root = BitMapBackend::new(path, (W, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 22))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..max, 0.0..top)
        .map_err(|e| draw_error(path, e))?;
    chart
        .configure_mesh()
        .x_desc(unit)
        .y_desc("activations")
        .label_style((FONT, 14))
        .draw()
        .map_err(|e| draw_error(path, e))?;
    chart
        .draw_series(counts.iter().enumerate().map(|(i, &c)| {
            let x0 = i as f64 * width;
            Rectangle::new([(x0, 0.0), (x0 + width, c as f64)], BLUE.filled())
        }))
        .map_err(|e| draw_error(path, e))?;
    chart
        .draw_series(LineSeries::new(
            [(budget, 0.0), (budget, top)],
            RED.stroke_width(3),
        ))
        .map_err(|e| draw_error(path, e))?;
    root.present().map_err(|e| draw_error(path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pixels of exactly `c` in an RGB buffer.
    fn count(buf: &[u8], c: RGBColor) -> usize {
        buf.chunks(3).filter(|p| p == &[c.0, c.1, c.2]).count()
    }

    /// The speed figure of `log`, as RGB pixels, and its blue (measured) pixels.
    fn speed_pixels(log: &[LogRow]) -> usize {
        register_font().unwrap_or(());
        let (w, h) = (600u32, 300u32);
        let mut buf = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            let t = column(log, |l| l.t_s);
            let drawn = draw_time_series(&root, "speed", "m/s", &t, &speed_lines(log));
            assert_eq!(drawn, Ok(()));
            assert_eq!(root.present().map_err(|e| e.to_string()), Ok(()));
        }
        count(&buf, BLUE)
    }

    fn log(v: impl Fn(f64) -> f64, reference: bool) -> Vec<LogRow> {
        (0..500)
            .map(|k| {
                let t = k as f64 * 0.01;
                let r = if reference { v(t) } else { f64::NAN };
                LogRow {
                    t_s: t,
                    v_mps: v(t),
                    v_ref_mps: r,
                    v_heur_mps: r,
                    control_mode: "track",
                    plan_status: "optimal",
                    ..LogRow::default()
                }
            })
            .collect()
    }

    #[test]
    fn the_measured_speed_is_drawn_on_top_of_the_references_and_in_the_legend() {
        let v = |t: f64| 10.0 + t;
        // The measured speed alone, then under references equal to it: as much of
        // it shows (it is drawn last), not only its legend sample.
        let alone = speed_pixels(&log(v, false));
        let covered = speed_pixels(&log(v, true));
        assert!(alone > 500, "{alone} blue pixels");
        assert!(
            covered * 10 >= alone * 9,
            "the references hide the measured speed: {covered} of {alone} blue pixels show"
        );
        let lines = speed_lines(&log(v, true));
        assert_eq!(lines.last().map(|l| l.label), Some("V: measured"));
        assert!(lines.iter().all(|l| !l.label.is_empty()));
        let colors: Vec<RGBColor> = lines.iter().map(|l| l.color).collect();
        assert!(colors[..2].iter().all(|&c| c != BLUE), "{colors:?}");
    }
}
