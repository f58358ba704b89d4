//! Fly one scenario with one controller and print its score: the host's first program.
//!
//!     cargo run --release -p host-train --example fly_one [-- SCENARIO.toml [CONTROLLER]]
//!
//! `host-train eval` does the same and also writes the plots; `ControllerSpec::ALL` lists the
//! controller names.
use host_train::control::by_name;
use host_train::fly::{fly_scenario, Report};
use host_train::Scenario;

fn main() {
    if let Err(e) = run() {
        eprintln!("fly_one: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let file = args
        .next()
        .unwrap_or_else(|| "scenarios/paper-spiral.toml".into());
    let name = args.next().unwrap_or_else(|| "adaptive".into());
    let scenario = Scenario::load(&file)?;
    // The controller mixes for the scenario's vehicle; learned ones fly weights/default.hfw.
    let mut controller = by_name(&name, &scenario, None)?;
    let log = fly_scenario(&scenario, controller.as_mut());
    let report = Report::from_flight(&log, &scenario, Some(file.as_ref()));
    match (report.crash_time_s, report.rmse_pos_window_m) {
        (Some(t), _) => anyhow::bail!("{} / {}: crashed at {t:.2} s", report.scenario, name),
        (None, rmse) => println!(
            "{} / {}: position RMSE {:.3} cm (t >= {} s), peak error {:.2} cm",
            report.scenario,
            report.controller,
            rmse.unwrap_or(report.rmse_pos_m) * 100.0,
            report.window_start_s,
            report.max_err_m * 100.0
        ),
    }
    Ok(())
}
