//! The table of the two adaptation laws in docs/adaptation.md: every scenario that exercises
//! the estimator, both laws side by side on both adaptive controllers.
//!
//! `cargo run --release -p host-train --example adaptation_table`

use host_train::control::registry;
use host_train::fly::eval::{self, Report};
use host_train::sim::scenario::Scenario;
use std::path::Path;

const SCENARIOS: [&str; 6] = [
    "paper-spiral",
    "paper-spiral-realistic",
    "step",
    "gust-spiral",
    "rotor-loss-mid",
    "hover-wind-step",
];
const CONTROLLERS: [&str; 4] = [
    "adaptive-gradient",
    "adaptive-composite",
    "geometric-adaptive-gradient",
    "geometric-adaptive-composite",
];

fn cm(x: Option<f64>) -> String {
    x.map_or("—".into(), |x| format!("{:.3}", 100.0 * x))
}

fn main() -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let weights = root.join(registry::DEFAULT_WEIGHTS);
    println!("| scenario | controller | RMSE t ≥ 5 s (cm) | max (cm) | events: peak (cm) / recovery (s) / RMSE 5 s after (cm) |");
    println!("| --- | --- | --- | --- | --- |");
    for s in SCENARIOS {
        let sc = Scenario::load(root.join(format!("scenarios/{s}.toml")))?;
        for c in CONTROLLERS {
            let mut ctrl = registry::by_name(c, &sc, Some(&weights))?;
            let log = eval::fly(&sc, ctrl.as_mut());
            let r = Report::from_flight(&log, &sc, None);
            let ev: Vec<String> = r
                .events
                .iter()
                .map(|e| {
                    format!(
                        "t = {} s: {} / {} / {}",
                        e.t_s,
                        cm(Some(e.peak_err_m)),
                        e.recovery_s.map_or("never".into(), |x| format!("{x:.2}")),
                        cm(e.rmse_after_m)
                    )
                })
                .collect();
            let crashed = if r.crashed { " (crashed)" } else { "" };
            println!(
                "| {s} | {c}{crashed} | {} | {} | {} |",
                cm(r.rmse_pos_window_m),
                cm(Some(r.max_err_m)),
                if ev.is_empty() {
                    "—".into()
                } else {
                    ev.join("; ")
                }
            );
        }
    }
    Ok(())
}
