//! `host-train train`: training ([`crate::train`]), then the flight check ([`super::check`]),
//! then the blob and its report.

use super::check::{require, run_model as run_check, CHECK_SCENARIOS};
use super::prior_check;
use crate::sim::scenario::Scenario;
use crate::train::export;
use crate::train::{self as training, backoff, TrainArgs, TrainConfig, TrainReport};
use anyhow::{bail, Context, Result};
use std::path::Path;

/// Trains on the dataset in `data_dir`, flies the flight check (unless `cfg.flight_check` is
/// off; when the learned features fail it, the back-off's blobs in turn,
/// [`backoff::candidates`]) and writes `out` (the blob that passed) and `out.json` (the report,
/// whose `features` says what the blob keeps).
///
/// # Errors
/// As [`training::fit`]; a failed flight check ([`require`]); a failure writing the outputs.
pub fn run(cfg: &TrainConfig, data_dir: &Path, out: &Path, quiet: bool) -> Result<TrainReport> {
    // The scenarios to survive load before training, so a bad path fails in a second.
    let survive = cfg
        .flight_survive
        .iter()
        .map(|p| Scenario::load(p).with_context(|| format!("--flight-survive {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    let fitted = training::fit(cfg, data_dir, quiet)?;
    let mut report = fitted.report;
    let mut model = fitted.model;
    if cfg.flight_check {
        let (mass, vehicle) = (fitted.manifest_mass_kg, &fitted.vehicle);
        let a: Vec<_> = report
            .realizations
            .iter()
            .filter(|r| !r.disturbance_free)
            .map(|r| r.a)
            .collect();
        let tries = backoff::candidates(&fitted.model.weights, &a, cfg.feature_backoff);
        for (k, c) in tries.iter().enumerate() {
            let mut candidate = fitted.model;
            candidate.weights = c.weights;
            let last = k + 1 == tries.len();
            let check = if last {
                // The last try's failure is the error, with what to do about it.
                require(&candidate, mass, vehicle)?
            } else {
                run_check(&candidate, mass, vehicle)?
            };
            let why = match check.failure.clone() {
                Some(why) => Some(why),
                None if !survive.is_empty() => {
                    let s = prior_check::run_with_safety(&candidate, &[], &survive)?;
                    if s.failure.is_none() && !quiet {
                        for f in &s.flights {
                            eprintln!(
                                "flight-survive: {} law on {}: {}",
                                f.law,
                                f.scenario,
                                f.rmse_m
                                    .map_or("no RMSE".into(), |m| format!("{:.3} cm", 100.0 * m))
                            );
                        }
                    }
                    s.failure
                }
                None => None,
            };
            if let Some(why) = why {
                if last && check.failure.is_none() {
                    bail!(
                        "flight check failed: {why}. Nothing was written. No feature back-off \
                         flies every --flight-survive scenario: check that they describe the \
                         vehicle the flights came from, or train on more varied flights"
                    );
                }
                report.features.failed.push((c.excited_dims, c.kept, why));
                continue;
            }
            report.features.excited_dims = c.excited_dims;
            report.features.kept = c.kept;
            report.flight_check = Some(check);
            model = candidate;
            break;
        }
        if let Some((_, _, why)) = report.features.failed.first() {
            let f = &report.features;
            let kept = if f.excited_dims == 0 {
                "the nominal features (a world force and a body torque per axis)".to_string()
            } else {
                format!(
                    "the learned features along the {} of {} directions of a the flights \
                     excited ({:.0} % of their deviation from the nominal features) and the \
                     nominal ones elsewhere",
                    f.excited_dims,
                    hamflight::model::FEATURES,
                    100.0 * f.kept
                )
            };
            eprintln!(
                "note: the learned disturbance features failed the flight check ({why}); the \
                 blob has {kept}, which passes (report: `features`; --no-feature-backoff \
                 writes nothing instead)"
            );
        }
    }
    export::write(out, &model, &report)?;
    Ok(report)
}

/// Runs `host-train train` and prints a summary.
///
/// # Errors
/// As [`run`].
pub fn run_cli(args: &TrainArgs) -> Result<TrainReport> {
    let r = run(&args.config(), &args.data, &args.out, args.quiet)?;
    let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
    println!(
        "trained {} epochs on {} windows in {:.0} s: held-out loss {:.3e} -> {:.3e}",
        r.curve.len(),
        r.train_windows,
        r.train_time_s,
        r.initial_val_loss,
        r.final_val_loss
    );
    let errs = |e: &export::PredictionErrors| {
        format!(
            "{:.2e} / {:.2e} / {:.2e} / {:.2e}",
            last(&e.pos_m),
            last(&e.rot_rad),
            last(&e.vel_m_s),
            last(&e.rate_rad_s)
        )
    };
    println!(
        "held-out {}-step error (pos m / rot rad / vel m/s / rate rad/s): learned {}, nominal {}",
        r.heldout_learned.pos_m.len(),
        errs(&r.heldout_learned),
        errs(&r.heldout_nominal),
    );
    if let Some(n) = &r.heldout_nominal_true_vehicle {
        println!(
            "held-out {}-step error of the nominal model with the dataset's mass and inertia: {}",
            n.pos_m.len(),
            errs(n),
        );
    }
    if let Some(c) = &r.heldout_calm {
        println!(
            "held-out {}-step error on the {} windows of disturbance-free flights: learned {}, nominal {}",
            c.learned.pos_m.len(),
            c.windows,
            errs(&c.learned),
            errs(&c.nominal),
        );
    }
    if let Some(c) = &r.flight_check {
        let cm = |v: Option<f64>| v.map_or("—".into(), |m| format!("{:.2} cm", 100.0 * m));
        let cells: Vec<String> = CHECK_SCENARIOS
            .iter()
            .map(|(name, _)| {
                let of = |law: &str| {
                    c.flight(name, law).map_or("—".into(), |f| match f.crash_s {
                        Some(t) => format!("crash {t:.1} s"),
                        None => cm(f.rmse_m),
                    })
                };
                format!(
                    "{name}: gradient {}, composite {}, without adaptation {}",
                    of("gradient"),
                    of("composite"),
                    of("none")
                )
            })
            .collect();
        println!(
            "flight check (SITL, the dataset's vehicle, 8 s): {}: passed",
            cells.join("; ")
        );
    }
    println!(
        "wrote {} and {}.json",
        args.out.display(),
        args.out.display()
    );
    Ok(r)
}
