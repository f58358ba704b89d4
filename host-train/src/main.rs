//! `host-train`: the host-side CLI of hamflight. Thin: each subcommand dispatches to a library
//! function of the `host_train` crate.

use anyhow::Result;
use clap::{Parser, Subcommand};

/// SITL quadrotor, data collection, training and evaluation for hamflight.
#[derive(Parser, Debug)]
#[command(name = "host-train", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Collect training data as in the paper's Sec. 4: the DSL PID flies to random poses under
    /// M disturbance realizations; writes DIR/manifest.json and DIR/realization_NN.csv.
    Collect(host_train::data::collect::CollectArgs),
    /// Import flight logs (Bitcraze uSD-card deck binary logs, or the documented CSV) into a
    /// dataset for `train`: one realization per log, airborne flights only.
    Import(host_train::data::import::ImportArgs),
    /// Learn the Hamiltonian model and disturbance features (paper Problem 1) from a dataset;
    /// writes FILE.hfw (the weight blob) and FILE.hfw.json (training report).
    Train(host_train::train::TrainArgs),
    /// Score a blob's open-loop multi-step predictions on any dataset (flights it did not
    /// train on): MAE and RMSE of position, velocity, attitude and body rates per horizon, for
    /// the learned model, the nominal model with the vehicle's constants, and the hold and
    /// zero-order baselines; prints a table, writes DIR/score.json and DIR/score.svg.
    Score(host_train::pipeline::score::ScoreArgs),
    /// Fit a blob's measured-input response on a dataset: the torques' effective gain and lag,
    /// a body acceleration linear in the body velocity and a constant one, what a real log's
    /// measured rotor speeds need beyond the blob's rigid body; writes FILE.json for
    /// `score --response`.
    FitResponse(host_train::pipeline::fit_response::FitResponseArgs),
    /// Learn a blob's port terms from logged flights (the input's effective gains and lags,
    /// the rotor drag and rate damping, the rotors' flapping gyrator, a learned potential of the
    /// attitude) and write them into a new blob, which `score` scores alone and the controller
    /// flies; `--hold-out TYPE` fits without a flight type and scores it (model selection on
    /// training flights).
    FitPort(host_train::pipeline::fit_port::FitPortArgs),
    /// Replay our port of Bitcraze's Mellinger controller along logged closed-loop flights
    /// (nanodrone.py --loop-out): R² of the logged motor commands per motor and axis, which
    /// logged wrench columns can be trusted; --fit identifies gains, trims and a delay on train/.
    Onboard(host_train::pipeline::onboard::OnboardArgs),
    /// Closed-loop replay: fly candidate plants (scenario vehicles) under the reproduced onboard
    /// controller along logged flights from the logged state; position and attitude RMSE over
    /// 10/50/100/300-row windows and whole flights, figures; --fit identifies the torque gains
    /// and flapping against that error on train/.
    Replay(host_train::pipeline::replay::ReplayArgs),
    /// Time training epochs (forward, backward, Adam) at batch 128, 256 and the full 7,776
    /// windows, the sizes of the PyTorch comparison in docs/performance.md; prints seconds per
    /// epoch.
    BenchTrain(host_train::pipeline::bench::BenchArgs),
    /// The robustness matrix: plant rotor lag × blob motor lag × command delay ×
    /// jitter, both laws; writes out/robustness.json and prints a table.
    Robustness(host_train::pipeline::robustness::RobustnessArgs),
    /// Fly a scenario with a controller; writes DIR/report.json, DIR/path.svg, DIR/error.svg.
    Eval(host_train::fly::eval::EvalArgs),
    /// Fly a scenario with both adaptation laws (the paper's gradient law and the composite law)
    /// and plot each estimate against the true wind: DIR/disturbance.svg, DIR/track.json; with
    /// --bandwidth also the estimator's frequency response, DIR/bandwidth.svg.
    Track(host_train::fly::track::TrackArgs),
    /// Drive a core controller from an external simulator: one JSON request per line on stdin
    /// (time, p, R, body v and ω, setpoint), one JSON reply per line on stdout (rotor commands,
    /// thrust, torques, a, faults). See docs/formats.md for the protocol.
    Bridge(host_train::bridge::BridgeArgs),
    /// The whole project in one command: collect a dataset, train the Hamiltonian model, fly
    /// paper-spiral with pid, geometric, geometric-adaptive, learned and adaptive; writes
    /// DIR/report.json and SVG figures, prints a table.
    Demo(host_train::pipeline::demo::DemoArgs),
    /// The study on a vehicle the nominal model does not know (0.034 kg, inertia ×1.3,
    /// rotor 3 at 90 %, 20 ms motor lag, drag, noise): log Lee flights as uSD logs, import,
    /// train N seeds, fly the calm spiral and paper-spiral on it; writes DIR/report.json and
    /// DIR/table.md, prints the table.
    VehicleStudy(host_train::pipeline::vehicle_study::VehicleStudyArgs),
    /// Measure a loop's stability margins in SITL: break the attitude loop at the plant input
    /// (or the position loop at its measurement), inject a sine per frequency, read the return
    /// ratio off the flight; prints crossover, phase and gain margins, writes DIR/margins.json.
    Margins(host_train::fly::margins::MarginsArgs),
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Margins(args) => {
            let rows = host_train::fly::margins::run(&args)?;
            print!(
                "{}",
                host_train::fly::margins::table(&args.scenario.display().to_string(), &rows)
            );
        }
        Command::FitResponse(args) => {
            let r = host_train::pipeline::fit_response::run(&args)?;
            let at = |e: &host_train::train::predict::HorizonErrors| {
                host_train::train::predict::mae_line(e, r.horizon)
            };
            println!("MAE at {} steps on the fitted windows:", r.horizon);
            println!("  blob alone     {}", at(&r.errors_blob));
            println!("  with response  {}", at(&r.errors_fitted));
            println!("wrote {} in {:.1} s", args.out.display(), r.elapsed_s);
        }
        Command::Replay(args) => {
            host_train::pipeline::replay::run(&args)?;
        }
        Command::Onboard(args) => {
            let r = host_train::pipeline::onboard::run(&args)?;
            print!("{}", host_train::pipeline::onboard::table(&r));
        }
        Command::FitPort(args) => {
            let r = host_train::pipeline::fit_port::run(&args)?;
            let at = |e: &host_train::train::predict::HorizonErrors| {
                host_train::train::predict::mae_line(e, r.horizon)
            };
            let p = &r.port;
            println!("learned ({}):", p.identifiability);
            println!(
                "  thrust gain {:.3}, lag {:.1} ms; torque gains {:.3} / {:.3} / {:.3}, lag {:.1} ms",
                p.thrust_gain,
                p.thrust_lag_s * 1e3,
                p.torque_gain[0],
                p.torque_gain[1],
                p.torque_gain[2],
                p.torque_lag_s * 1e3
            );
            println!(
                "  drag {:.2} / {:.2} / {:.2} 1/s; rate damping {:.2} / {:.2} / {:.2} 1/s",
                p.drag_per_s[0],
                p.drag_per_s[1],
                p.drag_per_s[2],
                p.rate_damping_per_s[0],
                p.rate_damping_per_s[1],
                p.rate_damping_per_s[2]
            );
            println!(
                "  flapping: roll accel {:.2} per v_y, pitch accel {:.2} per v_x (rad/s² per m/s); \
                 tilt stiffness / J: {:?}",
                p.gyrator_rad_s2_per_m_s[0][1], p.gyrator_rad_s2_per_m_s[1][0], p.tilt_rad_s2
            );
            if let Some(c) = &r.flight_check {
                println!(
                    "flight check (RMSE t ≥ 5 s; against the untrained prior, or survived alone):"
                );
                for f in &c.flights {
                    let cm = |x: Option<f64>, crash: Option<f64>| match (x, crash) {
                        (_, Some(t)) => format!("crash at {t:.2} s"),
                        (Some(x), None) => format!("{:.3} cm", 100.0 * x),
                        (None, None) => "-".to_string(),
                    };
                    let prior = if f.against_prior {
                        format!("prior {:>18}", cm(f.prior_rmse_m, f.prior_crash_s))
                    } else {
                        "(survive)".to_string()
                    };
                    println!(
                        "  {:<22} {:<9} fitted {:>18}   {prior}",
                        f.scenario,
                        f.law,
                        cm(f.rmse_m, f.crash_s),
                    );
                }
            }
            println!("MAE at {} steps:", r.horizon);
            println!("  start blob, fitted windows   {}", at(&r.errors_start));
            println!("  fitted blob, fitted windows  {}", at(&r.errors_fitted));
            if let (Some(e), Some(t)) = (&r.errors_held_out, &r.hold_out) {
                println!("  fitted blob, held-out `{t}`  {}", at(e));
            }
            println!(
                "wrote {} (and .json) in {:.1} s",
                args.out.display(),
                r.elapsed_s
            );
        }
        Command::Robustness(args) => {
            let r = host_train::pipeline::robustness::run(&args)?;
            print!("{}", host_train::pipeline::robustness::table(&r));
            eprintln!("wrote {} in {:.1} s", args.out.display(), r.elapsed_s);
        }
        Command::Score(args) => {
            let s = host_train::pipeline::score::run(&args)?;
            print!("{}", host_train::pipeline::score::table(&s));
            if let Some(dir) = &args.out {
                println!("wrote {}/score.json and score.svg", dir.display());
            }
        }
        Command::Collect(args) => {
            let t0 = std::time::Instant::now();
            let m = host_train::data::collect::run(&args)?;
            let n: usize = m.realizations.iter().map(|r| r.samples).sum();
            println!(
                "wrote {} realizations, {n} samples to {} in {:.2} s",
                m.realizations.len(),
                args.out.display(),
                t0.elapsed().as_secs_f64()
            );
        }
        Command::Import(args) => {
            let files = host_train::data::import::run(&args)?;
            for f in &files {
                println!(
                    "{}: {} samples, {} kept in {} flights{}{}{}",
                    f.file,
                    f.samples_in,
                    f.samples_kept,
                    f.flights,
                    if f.skipped_events > 0 {
                        format!(", {} events of other types skipped", f.skipped_events)
                    } else {
                        String::new()
                    },
                    if f.crc_ok {
                        ""
                    } else {
                        ", CRC mismatch (decoded anyway)"
                    },
                    if f.disturbance_free {
                        ", disturbance-free"
                    } else {
                        ""
                    },
                );
            }
            println!(
                "wrote {} realizations to {}",
                files.len(),
                args.out.display()
            );
        }
        Command::Train(args) => {
            host_train::pipeline::train::run_cli(&args)?;
        }
        Command::BenchTrain(args) => {
            host_train::pipeline::bench::run(&args)?;
        }
        Command::Eval(args) => {
            let r = host_train::fly::eval::run(&args)?;
            println!("{}", serde_json::to_string_pretty(&r)?);
        }
        Command::Track(args) => {
            let r = host_train::fly::track::run_track(&args)?;
            for l in &r.laws {
                println!(
                    "{} / {} law: estimate − true wind, RMS over t ≥ 5 s: {:.3} m/s²",
                    r.controller, l.law, l.rms_error_m_s2
                );
            }
            for (law, pts) in &r.bandwidth {
                for p in pts {
                    println!(
                        "{law} law at {:.2} Hz: amplitude ratio {:.2}, lag {:.0}°",
                        p.frequency_hz, p.amplitude_ratio, p.lag_deg
                    );
                }
            }
            println!("figures and track.json in {}", args.out.display());
        }
        Command::Bridge(args) => host_train::bridge::run(&args)?,
        Command::Demo(args) => {
            let t0 = std::time::Instant::now();
            let r = host_train::pipeline::demo::run(&args)?;
            println!("\n{} — {}\n", r.scenario, r.weights);
            println!("{}", host_train::pipeline::demo::table(&r.controllers));
            if let Some(best) = &r.best {
                println!("best by RMSE over t ≥ 5 s: {best}");
            }
            println!(
                "report and figures in {} ({:.0} s)",
                args.out.display(),
                t0.elapsed().as_secs_f64()
            );
        }
        Command::VehicleStudy(args) => {
            let r = host_train::pipeline::vehicle_study::run(&args)?;
            println!("{}", host_train::pipeline::vehicle_study::table(&r));
            println!(
                "report.json, table.md, logs/, data/ and the blobs in {} ({:.0} s)",
                args.out.display(),
                r.wall_s
            );
        }
    }
    Ok(())
}
