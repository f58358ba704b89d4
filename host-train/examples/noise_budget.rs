//! Where a scenario's tracking-error floor comes from: the scenario flown with each of its
//! measurement noises (`[effects.noise]`) switched off in turn, under the composite law, for the
//! learned blob and for the nominal model with the stock constants (`docs/vehicles.md`).
//!
//! `cargo run --release -p host-train --example noise_budget -- BLOB SCENARIO.toml [...]`
//!
//! Position errors add as variances, so each noise's share of the floor is
//! (RMSE² − RMSE²_without it) / (RMSE² − RMSE²_without any noise); the row "no noise" is what is
//! left when every σ is zero (the models' own error). Also printed: the ratio learned / nominal,
//! as is and without noise, which is what the calm-spiral bar compares.

use hamflight::model::{HamiltonianModel, NominalModel};
use hamflight::{AdaptationLaw, Gains, VehicleFacts};
use host_train::control::{load_learned, CoreController};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::{Scenario, StateNoise};
use std::path::PathBuf;

/// RMSE over the report window (m), or `None` on a crash.
fn rmse<M: HamiltonianModel>(sc: &Scenario, model: M) -> Option<f64> {
    let gains = Gains {
        law: AdaptationLaw::Composite,
        ..Gains::for_vehicle(&VehicleFacts::of(&model))
    };
    let mut c = CoreController::new("noise-budget", model, gains);
    let r = Report::from_log(&fly_scenario(sc, &mut c), None);
    r.rmse_pos_window_m.filter(|_| r.crash_time_s.is_none())
}

/// The noise variants: (name, the scenario's noise with that σ zeroed).
fn variants(n: &StateNoise) -> Vec<(&'static str, StateNoise)> {
    let with = |f: fn(&mut StateNoise)| {
        let mut m = n.clone();
        f(&mut m);
        m
    };
    vec![
        ("as the scenario has it", n.clone()),
        ("without position noise", with(|m| m.pos_m = 0.0)),
        ("without velocity noise", with(|m| m.vel_m_s = 0.0)),
        ("without attitude noise", with(|m| m.att_rad = 0.0)),
        ("without rate noise", with(|m| m.rate_rad_s = 0.0)),
        ("without accelerometer noise", with(|m| m.acc_m_s2 = 0.0)),
        ("no noise", StateNoise::default()),
    ]
}

fn cell(x: Option<f64>) -> String {
    x.map_or("crash".into(), |x| format!("{:.4}", 100.0 * x))
}

/// The share of the noise floor a variant removes, from the full and noise-free RMSEs.
fn share(full: Option<f64>, without: Option<f64>, clean: Option<f64>) -> String {
    match (full, without, clean) {
        (Some(f), Some(w), Some(c)) if f * f - c * c > 0.0 => {
            format!("{:.0} %", 100.0 * (f * f - w * w) / (f * f - c * c))
        }
        _ => "—".into(),
    }
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let Some(blob) = args.next().map(PathBuf::from) else {
        anyhow::bail!("usage: noise_budget BLOB SCENARIO.toml [SCENARIO.toml ...]");
    };
    let files: Vec<PathBuf> = args.map(PathBuf::from).collect();
    if files.is_empty() {
        anyhow::bail!("give at least one scenario (e.g. scenarios/mismatch-calm-spiral.toml)");
    }
    let learned = load_learned(&blob)?;
    let nominal = NominalModel::default();
    for f in &files {
        let base = Scenario::load(f)?;
        println!(
            "\n{} (blob {}), composite law, RMSE t ≥ 5 s (cm):\n",
            base.name,
            blob.display()
        );
        println!("| noise | learned | share of learned's floor | nominal, stock constants | share of nominal's floor |");
        println!("| --- | --- | --- | --- | --- |");
        let rows: Vec<(&str, Option<f64>, Option<f64>)> = variants(&base.spec.effects.noise)
            .into_iter()
            .map(|(name, noise)| {
                let mut sc = base.clone();
                sc.spec.effects.noise = noise;
                (name, rmse(&sc, learned), rmse(&sc, nominal))
            })
            .collect();
        let (full_l, full_n) = rows.first().map_or((None, None), |r| (r.1, r.2));
        let (clean_l, clean_n) = rows.last().map_or((None, None), |r| (r.1, r.2));
        for (name, l, n) in &rows {
            println!(
                "| {name} | {} | {} | {} | {} |",
                cell(*l),
                share(full_l, *l, clean_l),
                cell(*n),
                share(full_n, *n, clean_n)
            );
        }
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
            _ => "—".into(),
        };
        println!(
            "\nlearned / nominal: {} with the noise, {} without",
            ratio(full_l, full_n),
            ratio(clean_l, clean_n)
        );
    }
    Ok(())
}
