//! `host-train demo`: the project end to end. Collects a dataset as in the paper's Sec. 4,
//! trains the Hamiltonian model, flies paper-spiral with every controller and writes
//! `report.json`, figures like the paper's Fig. 2 and a table.

use crate::control::registry;
use crate::data::collect::{self, CollectConfig};
use crate::fly::eval::{self, FlightLog, Report};
use crate::pipeline::train as pipeline_train;
use crate::report::plot;
use crate::sim::scenario::Scenario;
use crate::train;
use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The headline scenario, built in so the demo runs from any directory.
pub const PAPER_SPIRAL_TOML: &str = include_str!("../../../scenarios/paper-spiral.toml");

/// The controllers the demo flies, in table order.
pub const DEMO_CONTROLLERS: [&str; 5] = [
    "pid",
    "geometric",
    "geometric-adaptive",
    "learned",
    "adaptive",
];

/// Arguments of `host-train demo`.
#[derive(Args, Debug, Clone)]
pub struct DemoArgs {
    /// Output directory: data/, weights.hfw(.json), report.json and the SVG figures.
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    pub out: PathBuf,
    /// Kept for scripts: the demo trains as the shipped weights were trained (the training
    /// default) with or without it.
    #[arg(long, hide = true)]
    pub full: bool,
    /// Skip collection and training and fly with this weight blob.
    #[arg(long, value_name = "FILE")]
    pub weights: Option<PathBuf>,
    /// Training epochs (default: the training default, as for the shipped weights).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Seed of the data collection and the training.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scenario to fly instead of the built-in paper-spiral.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
}

/// What `report.json` holds.
#[derive(Serialize, Debug)]
pub struct DemoReport {
    /// The scenario flown.
    pub scenario: String,
    /// The weight blob the learned controllers used.
    pub weights: String,
    /// Training summary (absent with `--weights`).
    pub training: Option<serde_json::Value>,
    /// One report per controller, in [`DEMO_CONTROLLERS`] order.
    pub controllers: Vec<Report>,
    /// The controller with the lowest `rmse_pos_window_m` among those that did not crash.
    pub best: Option<String>,
    /// Wall time of each stage (s).
    pub wall_s: serde_json::Value,
}

fn fmt_cm(v: Option<f64>) -> String {
    v.map_or("—".into(), |m| format!("{:.3}", 100.0 * m))
}

/// The results table, as printed and as pasted into the README.
pub fn table(reports: &[Report]) -> String {
    let mut s = String::from(
        "| controller | crashed | RMSE t ≥ 5 s (cm) | RMSE whole (cm) | max error (cm) |\n\
         | --- | --- | --- | --- | --- |\n",
    );
    for r in reports {
        let crashed = match r.crash_time_s {
            Some(t) => format!("yes, at {t:.2} s"),
            None => "no".into(),
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            r.controller,
            crashed,
            if r.crashed {
                "—".into()
            } else {
                fmt_cm(r.rmse_pos_window_m)
            },
            fmt_cm(Some(r.rmse_pos_m)),
            fmt_cm(Some(r.max_err_m)),
        ));
    }
    s
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> Result<DemoReport> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory `{}`", args.out.display()))?;
    let mut wall = serde_json::Map::new();
    let scenario = match &args.scenario {
        Some(p) => Scenario::load(p)?,
        None => {
            Scenario::from_toml_str(PAPER_SPIRAL_TOML, "built-in paper-spiral", "paper-spiral")?
        }
    };

    let (weights, training) = match &args.weights {
        Some(w) => (w.clone(), None),
        None => {
            let data = args.out.join("data");
            let t0 = Instant::now();
            eprintln!(
                "[1/3] collecting the dataset (paper Sec. 4) into {}",
                data.display()
            );
            let cfg = CollectConfig {
                seed: args.seed,
                ..CollectConfig::default()
            };
            let manifest = collect::collect(&data, &cfg)?;
            let samples: usize = manifest.realizations.iter().map(|r| r.samples).sum();
            eprintln!(
                "      {} realizations, {samples} samples in {:.1} s",
                manifest.realizations.len(),
                t0.elapsed().as_secs_f64()
            );
            wall.insert("collect".into(), t0.elapsed().as_secs_f64().into());

            let t0 = Instant::now();
            let mut tc = train::TrainConfig {
                seed: args.seed,
                ..train::TrainConfig::default()
            };
            tc.epochs = args.epochs.unwrap_or(tc.epochs);
            let out = args.out.join("weights.hfw");
            eprintln!("[2/3] training the Hamiltonian model, {} epochs", tc.epochs);
            let report = pipeline_train::run(&tc, &data, &out, false)?;
            wall.insert("train".into(), t0.elapsed().as_secs_f64().into());
            (out, Some(serde_json::to_value(&report)?))
        }
    };

    let t0 = Instant::now();
    eprintln!(
        "[3/3] flying {} with {} controllers",
        scenario.name,
        DEMO_CONTROLLERS.len()
    );
    let pb = indicatif::ProgressBar::new(DEMO_CONTROLLERS.len() as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template("      {msg:20} [{bar:30}] {pos}/{len}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut logs: Vec<(&str, FlightLog)> = Vec::new();
    for name in DEMO_CONTROLLERS {
        pb.set_message(name);
        let mut ctrl = registry::by_name(name, &scenario, Some(&weights))?;
        logs.push((name, eval::fly(&scenario, ctrl.as_mut())));
        pb.inc(1);
    }
    pb.finish_and_clear();
    wall.insert("fly".into(), t0.elapsed().as_secs_f64().into());

    let reports: Vec<Report> = logs
        .iter()
        .map(|(_, l)| Report::from_log(l, args.scenario.as_deref()))
        .collect();
    write_figures(&args.out, &logs)?;
    let best = reports
        .iter()
        .filter(|r| !r.crashed)
        .filter_map(|r| r.rmse_pos_window_m.map(|e| (e, r.controller.clone())))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, n)| n);
    let report = DemoReport {
        scenario: scenario.name.clone(),
        weights: weights.display().to_string(),
        training,
        controllers: reports,
        best,
        wall_s: wall.into(),
    };
    eval::write_json_atomic(&args.out.join("report.json"), &report)?;
    Ok(report)
}

fn write_figures(out: &Path, logs: &[(&str, FlightLog)]) -> Result<()> {
    let find = |n: &str| {
        logs.iter()
            .find(|(name, _)| *name == n)
            .map(|(n, l)| (*n, l))
    };
    let all: Vec<(&str, &FlightLog)> = logs.iter().map(|(n, l)| (*n, l)).collect();
    // Fig. 2 (a)/(b): the learned model without and with adaptation.
    let pair: Vec<(&str, &FlightLog)> = ["learned", "adaptive"]
        .iter()
        .filter_map(|n| find(n))
        .collect();
    plot::path_svg(&pair, &out.join("path.svg"))?;
    plot::path_svg(&all, &out.join("path_all.svg"))?;
    plot::error_svg(&all, &out.join("error.svg"))?;
    plot::error_log_svg(&all, &out.join("error_log.svg"))?;
    if let Some((_, log)) = find("adaptive") {
        plot::adaptation_svg(
            "adaptive (learned features)",
            log,
            &out.join("adaptation.svg"),
        )?;
    }
    if let Some((_, log)) = find("geometric-adaptive") {
        plot::adaptation_svg(
            "geometric-adaptive (world force, body torque)",
            log,
            &out.join("adaptation_geometric.svg"),
        )?;
    }
    Ok(())
}
