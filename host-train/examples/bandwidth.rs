//! The adaptation's bandwidth (docs/adaptation.md): amplitude ratio and phase lag of the
//! compensated specific force R (W a)_v / m against a sinusoidal wind of 0.5 m/s² along x,
//! hovering, for both adaptation laws on both adaptive controllers.
//!
//! `cargo run --release -p host-train --example bandwidth`

use hamflight::model::{HamiltonianModel, NominalModel};
use hamflight::AdaptationLaw;
use host_train::control::{gains_with, load_learned, CoreController};
use host_train::fly::{measure_bandwidth_point, BANDWIDTH_FREQUENCIES_HZ};

fn row<M: HamiltonianModel + Clone>(name: &str, model: M) -> anyhow::Result<()> {
    for law in [AdaptationLaw::Gradient, AdaptationLaw::Composite] {
        let mut ctrl = CoreController::new(name, model.clone(), gains_with(law));
        let mut cells = Vec::new();
        for f in BANDWIDTH_FREQUENCIES_HZ {
            let p = measure_bandwidth_point(&mut ctrl, f)?;
            cells.push(format!("{:.2} / {:.0}°", p.amplitude_ratio, p.lag_deg));
        }
        println!("| {name} | {law:?} | {} |", cells.join(" | "));
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    println!("| controller | law | 0.25 Hz | 0.5 Hz | 1 Hz | 2 Hz |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../weights/default.hfw");
    row("adaptive", load_learned(&weights)?)?;
    row("geometric-adaptive", NominalModel::default())?;
    Ok(())
}
