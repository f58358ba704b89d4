//! The replay's figure: per flight, the logged path and attitude against each plant's replay.

use super::closed_loop::Flown;
use crate::io::files::write_atomic;
use crate::io::LoopFlight;
use anyhow::{anyhow, Result};
use plotters::prelude::*;
use std::path::Path;

const COLORS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
];

fn pe<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plotting failed: {e:?}")
}

/// x, y, z (m) and roll, pitch (rad) against time: the log in black, each replay in colour.
pub fn replay_svg(f: &LoopFlight, runs: &[(String, Flown)], path: &Path) -> Result<()> {
    type Pick = fn(&crate::io::OnboardState) -> f64;
    let panels: [(&str, Pick); 5] = [
        ("x (m)", |s| s.p_m.x),
        ("y (m)", |s| s.p_m.y),
        ("z (m)", |s| s.p_m.z),
        ("roll (rad)", |s| s.q.euler_angles().0),
        ("pitch (rad)", |s| s.q.euler_angles().1),
    ];
    let Some(start) = runs.iter().map(|(_, r)| r.start).min() else {
        return Ok(());
    };
    let end = runs
        .iter()
        .map(|(_, r)| r.start + r.states.len())
        .max()
        .unwrap_or(start)
        .min(f.len().saturating_sub(1));
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1100, 1100)).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        let root = root
            .titled(
                &format!("{}: logged (black) against closed-loop replay", f.name),
                ("sans-serif", 18),
            )
            .map_err(pe)?;
        let (t0, t1) = (f.t_s[start], f.t_s[end].max(f.t_s[start] + 0.01));
        for (area, (label, pick)) in root.split_evenly((5, 1)).iter().zip(panels) {
            let logged: Vec<(f64, f64)> = (start..=end)
                .map(|k| (f.t_s[k], pick(&f.state[k])))
                .collect();
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for &(_, y) in &logged {
                lo = lo.min(y);
                hi = hi.max(y);
            }
            let pad = ((hi - lo) * 0.3).max(0.05);
            let mut ch = ChartBuilder::on(area)
                .margin(6)
                .x_label_area_size(25)
                .y_label_area_size(55)
                .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
                .map_err(pe)?;
            ch.configure_mesh().y_desc(label).draw().map_err(pe)?;
            ch.draw_series(LineSeries::new(logged, BLACK.stroke_width(2)))
                .map_err(pe)?
                .label("logged")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            for (i, (name, r)) in runs.iter().enumerate() {
                let c = COLORS[i % COLORS.len()];
                let pts = r.states.iter().enumerate().filter_map(|(j, s)| {
                    f.t_s
                        .get(r.start + 1 + j)
                        .map(|t| (*t, pick(s).clamp(lo - pad, hi + pad)))
                });
                ch.draw_series(LineSeries::new(pts, c.stroke_width(1)))
                    .map_err(pe)?
                    .label(name.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            }
            ch.configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(pe)?;
        }
        root.present().map_err(pe)?;
    }
    write_atomic(path, buf.as_bytes())
}
