//! SVG figures of flights (plotters), each written whole (temporary file, then rename).

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;

use crate::io::flightlog::FlightLog;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One tick of a tracked flight: t (s), the true wind and the compensated specific force
/// R (W a)_v / m (both m/s², world frame).
pub type DisturbanceSample = (f64, Vector3<f64>, Vector3<f64>);

/// One point of the estimator's frequency response.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandwidthPoint {
    /// Wind frequency (Hz).
    pub frequency_hz: f64,
    /// |estimate| / |wind| at that frequency.
    pub amplitude_ratio: f64,
    /// Phase lag of the estimate behind the wind (degrees; positive = behind).
    pub lag_deg: f64,
}
use crate::io::files::write_atomic;

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn pe<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plotting failed: {e:?}")
}

fn bounds(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(0.02);
    (lo - pad, hi + pad)
}

/// Desired vs flown path of one or more flights: an x–y top view and x, y, z against time.
/// The desired path is taken from the first log; each log is overlaid with its label.
pub fn path_svg(logs: &[(&str, &FlightLog)], path: &Path) -> Result<()> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1300, 650)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (left, right) = root.split_horizontally(650);
        let all = || {
            logs.iter()
                .flat_map(|(_, l)| l.p_m.iter().chain(l.p_ref_m.iter()))
        };
        let (x0, x1) = bounds(all().map(|p| p[0]));
        let (y0, y1) = bounds(all().map(|p| p[1]));
        // Equal aspect on the top view.
        let half = 0.5 * (x1 - x0).max(y1 - y0);
        let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let title = logs
            .first()
            .map(|(_, l)| format!("{}: top view", l.scenario))
            .unwrap_or_default();
        let mut ch = ChartBuilder::on(&left)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(cx - half..cx + half, cy - half..cy + half)
            .map_err(pe)?;
        ch.configure_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .draw()
            .map_err(pe)?;
        if let Some((_, l)) = logs.first() {
            ch.draw_series(LineSeries::new(
                l.p_ref_m.iter().map(|p| (p[0], p[1])),
                BLACK.stroke_width(2),
            ))
            .map_err(pe)?
            .label("desired")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        }
        for (i, (name, l)) in logs.iter().enumerate() {
            let c = PALETTE[i % PALETTE.len()];
            ch.draw_series(LineSeries::new(l.p_m.iter().map(|p| (p[0], p[1])), c))
                .map_err(pe)?
                .label(name.to_string())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        ch.configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(pe)?;

        let t_max = logs
            .iter()
            .map(|(_, l)| l.planned_duration_s)
            .fold(0.1, f64::max);
        for (axis, area) in right.split_evenly((3, 1)).iter().enumerate() {
            let (lo, hi) = bounds(all().map(|p| p[axis]));
            let mut ch = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d(0.0..t_max, lo..hi)
                .map_err(pe)?;
            ch.configure_mesh()
                .x_desc("t (s)")
                .y_desc(["x (m)", "y (m)", "z (m)"][axis])
                .draw()
                .map_err(pe)?;
            if let Some((_, l)) = logs.first() {
                ch.draw_series(LineSeries::new(
                    l.t_s.iter().zip(&l.p_ref_m).map(|(t, p)| (*t, p[axis])),
                    BLACK.stroke_width(2),
                ))
                .map_err(pe)?;
            }
            for (i, (_, l)) in logs.iter().enumerate() {
                let c = PALETTE[i % PALETTE.len()];
                ch.draw_series(LineSeries::new(
                    l.t_s.iter().zip(&l.p_m).map(|(t, p)| (*t, p[axis])),
                    c,
                ))
                .map_err(pe)?;
            }
        }
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}

/// Position error |p − p*| (cm) against time for one or more flights.
pub fn error_svg(logs: &[(&str, &FlightLog)], path: &Path) -> Result<()> {
    let e_max = max_error_cm(logs, 0.1) * 1.05;
    error_figure(logs, path, "position error", 0.0..e_max, |e| e * 100.0)
}

/// Position error against time on a logarithmic axis (cm), so that millimetre and decimetre
/// errors read on one figure.
pub fn error_log_svg(logs: &[(&str, &FlightLog)], path: &Path) -> Result<()> {
    let cm = |e: f64| (e * 100.0).max(1e-4);
    let e_max = max_error_cm(logs, 0.01) * 1.5;
    let e_min = logs
        .iter()
        .flat_map(|(_, l)| l.err_m.iter())
        .filter(|e| e.is_finite())
        .fold(e_max, |a: f64, &b| a.min(cm(b)))
        .max(1e-3);
    error_figure(
        logs,
        path,
        "position error (log scale)",
        (e_min..e_max).log_scale(),
        cm,
    )
}

/// The largest finite error of `logs` in cm, at least `floor_cm`.
fn max_error_cm(logs: &[(&str, &FlightLog)], floor_cm: f64) -> f64 {
    logs.iter()
        .flat_map(|(_, l)| l.err_m.iter())
        .filter(|e| e.is_finite())
        .fold(floor_cm, |a: f64, &b| a.max(b * 100.0))
}

/// The error-against-time figure on the y axis `y` (linear or log), errors mapped by `to_y`.
fn error_figure<Y>(
    logs: &[(&str, &FlightLog)],
    path: &Path,
    what: &str,
    y: Y,
    to_y: impl Fn(f64) -> f64,
) -> Result<()>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (900, 450)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let t_max = logs
            .iter()
            .map(|(_, l)| l.planned_duration_s)
            .fold(0.1, f64::max);
        let title = logs
            .first()
            .map(|(_, l)| format!("{}: {what}", l.scenario))
            .unwrap_or_default();
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_max, y)
            .map_err(pe)?;
        ch.configure_mesh()
            .x_desc("t (s)")
            .y_desc("|p - p*| (cm)")
            .draw()
            .map_err(pe)?;
        for (i, (name, l)) in logs.iter().enumerate() {
            let c = PALETTE[i % PALETTE.len()];
            ch.draw_series(LineSeries::new(
                l.t_s
                    .iter()
                    .zip(&l.err_m)
                    .filter(|(_, e)| e.is_finite())
                    .map(|(t, e)| (*t, to_y(*e))),
                c,
            ))
            .map_err(pe)?
            .label(name.to_string())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        ch.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(pe)?;
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}

/// One panel of [`horizon_svg`]: its y label and its lines, `(name, values at steps 1..N)`.
pub type HorizonPanel<'a> = (&'a str, Vec<(&'a str, &'a [f64])>);

/// Errors against the prediction horizon: one panel per `(y label, lines)` in a 2 × 2 grid,
/// one line per `(name, values at steps 1..N)`, the x axis in seconds (step k at k `dt_s`).
pub fn horizon_svg(title: &str, dt_s: f64, panels: &[HorizonPanel<'_>], path: &Path) -> Result<()> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 750)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let root = root.titled(title, ("sans-serif", 18)).map_err(pe)?;
        let steps = panels
            .iter()
            .flat_map(|(_, lines)| lines.iter().map(|(_, v)| v.len()))
            .max()
            .unwrap_or(1);
        let t_max = steps as f64 * dt_s;
        for (area, (label, lines)) in root.split_evenly((2, 2)).iter().zip(panels) {
            // A line that diverges (3× above every other) runs off the top instead of
            // flattening the others.
            let mut tops: Vec<f64> = lines
                .iter()
                .map(|(_, v)| {
                    v.iter()
                        .copied()
                        .filter(|x| x.is_finite())
                        .fold(1e-6, f64::max)
                })
                .collect();
            tops.sort_by(|a, b| b.total_cmp(a));
            let hi = match (tops.first(), tops.get(1)) {
                (Some(&a), Some(&b)) if a > 3.0 * b => 1.5 * b,
                (Some(&a), _) => a * 1.05,
                _ => 1.0,
            };
            let mut ch = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_max, 0.0..hi)
                .map_err(pe)?;
            ch.configure_mesh()
                .x_desc("horizon (s)")
                .y_desc(*label)
                .draw()
                .map_err(pe)?;
            for (i, (name, v)) in lines.iter().enumerate() {
                let c = PALETTE[i % PALETTE.len()];
                let pts = v
                    .iter()
                    .enumerate()
                    .map(|(k, y)| ((k + 1) as f64 * dt_s, *y));
                ch.draw_series(LineSeries::new(pts, c.stroke_width(2)))
                    .map_err(pe)?
                    .label(name.to_string())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            }
            ch.configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(pe)?;
        }
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}

/// The adaptation estimate a(t) of one flight, one line per component (the paper's Fig. 2
/// companion: how fast the disturbance weights settle).
pub fn adaptation_svg(label: &str, log: &FlightLog, path: &Path) -> Result<()> {
    let p = log.adaptation.iter().map(Vec::len).max().unwrap_or(0);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (900, 450)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let (lo, hi) = bounds(log.adaptation.iter().flatten().copied());
        let t_max = log.planned_duration_s.max(0.1);
        let mut ch = ChartBuilder::on(&root)
            .caption(
                format!("{}: adaptation estimate a(t), {label}", log.scenario),
                ("sans-serif", 20),
            )
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_max, lo..hi)
            .map_err(pe)?;
        ch.configure_mesh()
            .x_desc("t (s)")
            .y_desc("a_k")
            .draw()
            .map_err(pe)?;
        for k in 0..p {
            let c = PALETTE[k % PALETTE.len()];
            ch.draw_series(LineSeries::new(
                log.t_s
                    .iter()
                    .zip(&log.adaptation)
                    .filter_map(|(t, a)| a.get(k).map(|v| (*t, *v))),
                c,
            ))
            .map_err(pe)?
            .label(format!("a{k}"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        ch.configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(pe)?;
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}

/// The adaptation's estimate against the true disturbance: world x and y of the compensated
/// specific force R (W a)_v / m and of the wind (m/s²) against time, one line per law.
pub fn disturbance_svg(
    title: &str,
    series: &[(&str, &[DisturbanceSample])],
    path: &Path,
) -> Result<()> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1000, 650)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let root = root
            .titled(
                &format!("{title}: disturbance estimate against the true wind"),
                ("sans-serif", 20),
            )
            .map_err(pe)?;
        let t_max = series
            .iter()
            .flat_map(|(_, s)| s.last().map(|p| p.0))
            .fold(0.1, f64::max);
        for (axis, area) in root.split_evenly((2, 1)).iter().enumerate() {
            let (lo, hi) = bounds(
                series
                    .iter()
                    .flat_map(|(_, s)| s.iter().flat_map(move |(_, d, e)| [d[axis], e[axis]])),
            );
            let mut ch = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_max, lo..hi)
                .map_err(pe)?;
            ch.configure_mesh()
                .x_desc("t (s)")
                .y_desc(["world x (m/s²)", "world y (m/s²)"][axis])
                .draw()
                .map_err(pe)?;
            // At most ~3,000 points a line: the figure stays small and the lines unchanged.
            let every = |s: &[DisturbanceSample]| (s.len() / 3000).max(1);
            if let Some((_, s)) = series.first() {
                ch.draw_series(LineSeries::new(
                    s.iter().step_by(every(s)).map(|(t, d, _)| (*t, d[axis])),
                    BLACK.stroke_width(2),
                ))
                .map_err(pe)?
                .label("true wind")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            }
            for (i, (name, s)) in series.iter().enumerate() {
                let c = PALETTE[i % PALETTE.len()];
                ch.draw_series(LineSeries::new(
                    s.iter().step_by(every(s)).map(|(t, _, e)| (*t, e[axis])),
                    c,
                ))
                .map_err(pe)?
                .label(format!("estimate, {name} law"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            }
            ch.configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(pe)?;
        }
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}

/// The estimator's frequency response, one line per law: amplitude ratio and phase lag of the
/// estimate against a sinusoidal wind.
pub fn bandwidth_svg(
    controller: &str,
    series: &[(&str, &[BandwidthPoint])],
    path: &Path,
) -> Result<()> {
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (900, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let root = root
            .titled(
                &format!("{controller}: adaptation bandwidth (hover, sinusoidal wind)"),
                ("sans-serif", 20),
            )
            .map_err(pe)?;
        let f_max = series
            .iter()
            .flat_map(|(_, s)| s.iter().map(|p| p.frequency_hz))
            .fold(0.5, f64::max)
            * 1.1;
        let panels = root.split_evenly((2, 1));
        for (k, area) in panels.iter().enumerate() {
            let val = |p: &BandwidthPoint| {
                if k == 0 {
                    p.amplitude_ratio
                } else {
                    p.lag_deg
                }
            };
            let (lo, hi) = bounds(series.iter().flat_map(|(_, s)| s.iter().map(val)));
            let mut ch = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..f_max, lo.min(0.0)..hi)
                .map_err(pe)?;
            ch.configure_mesh()
                .x_desc("wind frequency (Hz)")
                .y_desc(["amplitude ratio", "phase lag (°)"][k])
                .draw()
                .map_err(pe)?;
            for (i, (name, s)) in series.iter().enumerate() {
                let c = PALETTE[i % PALETTE.len()];
                ch.draw_series(LineSeries::new(
                    s.iter().map(|p| (p.frequency_hz, val(p))),
                    c.stroke_width(2),
                ))
                .map_err(pe)?
                .label(format!("{name} law"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
                ch.draw_series(
                    s.iter()
                        .map(|p| Circle::new((p.frequency_hz, val(p)), 4, c.filled())),
                )
                .map_err(pe)?;
            }
            ch.configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(pe)?;
        }
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}
