//! The table of the two adaptation laws in docs/adaptation.md: every scenario that exercises
//! the estimator, both laws side by side on both adaptive controllers.
//!
//! `cargo run --release -p host-train --example adaptation_table`; with `-- --rotor-loss`, the
//! rotor-loss set's table instead: every `rotor-loss-*` scenario, both laws, on the true state and
//! behind the Crazyflie's sensor chain (the `cf-` twin).

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

/// One flight's report.
fn flight(root: &Path, scenario: &str, controller: &str) -> anyhow::Result<Report> {
    let sc = Scenario::load(root.join(format!("scenarios/{scenario}.toml")))?;
    let weights = root.join(registry::DEFAULT_WEIGHTS);
    let mut ctrl = registry::by_name(controller, &sc, Some(&weights))?;
    let log = eval::fly(&sc, ctrl.as_mut());
    Ok(Report::from_flight(&log, &sc, None))
}

/// The rotor-loss set: RMSE over t ≥ 5 s, the peak after the fault and the recovery time, per
/// scenario, law and state source.
fn rotor_loss_table(root: &Path) -> anyhow::Result<()> {
    println!("| rotor, lag | law | true state: RMSE (cm) / peak (cm) / recovery (s) | sensor chain: RMSE (cm) / peak (cm) / recovery (s) |");
    println!("| --- | --- | --- | --- |");
    let cell = |r: &Report| {
        let e = r.events.first();
        let rec = e
            .and_then(|e| e.recovery_s)
            .map_or("never < 1 cm".into(), |x| format!("{x:.2}"));
        let crashed = r
            .crash_time_s
            .map_or(String::new(), |t| format!(" (crash at {t:.2} s)"));
        format!(
            "{} / {} / {rec}{crashed}",
            cm(r.rmse_pos_window_m),
            cm(e.map(|e| e.peak_err_m))
        )
    };
    for share in [55, 50] {
        for lag in [20, 50, 72] {
            for law in ["gradient", "composite"] {
                let name = format!("rotor-loss-{share}-lag{lag}");
                let c = format!("adaptive-{law}");
                let t = flight(root, &name, &c)?;
                let ch = flight(root, &format!("cf-{name}"), &c)?;
                println!(
                    "| 1 to {share} %, {lag} ms | {law} | {} | {} |",
                    cell(&t),
                    cell(&ch)
                );
            }
        }
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    if std::env::args().any(|a| a == "--rotor-loss") {
        return rotor_loss_table(&root);
    }
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
