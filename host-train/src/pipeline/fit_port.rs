//! `host-train fit-port`: learn a blob's port terms (the input's gains and lags, the
//! dissipation, the gyrator, the learned potential; [`crate::train::port_fit`]) from logged
//! flights, and write them into a new blob: the model that `score` scores alone and that the
//! controller flies.
//!
//! Model selection on the training flights only: `--hold-out TYPE` leaves out every flight
//! whose file name starts with TYPE (the nano-drone benchmark's `square`, `random`,
//! `multisine`), fits on the rest and reports the held-out windows' errors.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use hamflight::blob;
use hamflight::model::HamiltonianModel;
use serde::Serialize;

use crate::control::adapter::load_learned;
use crate::io::files::write_atomic;
use crate::pipeline::fit_response::FitWindowArgs;
use crate::pipeline::prior_check::{self, PriorCheck};
use crate::sim::scenario::Scenario;
use crate::train::data;
use crate::train::port_fit::{self, PortFitConfig, PortReport, PortStructure};
use crate::train::predict::HorizonErrors;
use crate::train::response::{response_errors, FitStep, Response};

/// Arguments of `host-train fit-port`.
#[derive(Args, Debug, Clone)]
pub struct FitPortArgs {
    /// The weight blob to start from (its networks and rigid body are kept; `train`'s FILE.hfw,
    /// e.g. with `--pin-rigid-body`).
    #[arg(long, value_name = "FILE.hfw")]
    pub weights: PathBuf,
    /// The dataset to fit on (training flights imported with every state kept: `import
    /// --keep-repeated-states --trim-s 0 …`, so that long windows exist).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The windows and the solver.
    #[command(flatten)]
    pub fit: FitWindowArgs,
    /// Leave out the learned potential ½ bᵀKb (the pull toward a trim attitude).
    #[arg(long)]
    pub no_tilt: bool,
    /// Leave out the gyrator (torque from the body velocity: the rotors' flapping moment).
    #[arg(long)]
    pub no_gyrator: bool,
    /// Leave out the rotor drag.
    #[arg(long)]
    pub no_drag: bool,
    /// Leave out the rate damping (on closed-loop flights it stands in, in part, for the
    /// onboard attitude loop's effect, which the law then cancels on a vehicle that lacks it).
    #[arg(long)]
    pub no_rate_damping: bool,
    /// Hold the torques' effective gains at the starting blob's (the vehicle description's)
    /// instead of fitting them: flights flown in closed loop bias free torque gains toward zero
    /// (the onboard controller's torques cancel moments the model may not have), and a blob
    /// with such gains over-drives the real rotors.
    #[arg(long)]
    pub pin_torque_gains: bool,
    /// Hold the torques' lag behind the rotors at zero instead of fitting it, so that the
    /// blob's actuator chain is its motor lag alone (`--motor-tau-s`): on closed-loop flights
    /// a fitted lag stands in for the moments the onboard controller cancels, and the law,
    /// which designs its attitude loop and its lead for the chain's lag, over-compensates a
    /// vehicle whose rotors are faster.
    #[arg(long)]
    pub pin_torque_lag: bool,
    /// Pull the free torque gains toward the vehicle description's 1 with this weight: the
    /// fit's cost (the mean scaled error norm) of a unit deviation per axis; 0 (the default):
    /// no prior. Between free gains (0) and pinned ones (--pin-torque-gains).
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub torque_gain_prior: f64,
    /// Pull the rate damping toward zero with this weight: the fit's cost of 1/s of damping per
    /// axis; 0 (the default): no prior. Between a free damping (0) and none
    /// (--no-rate-damping).
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub rate_damping_prior: f64,
    /// Leave out the flights whose file name (the imported log's, else the dataset's) starts
    /// with TYPE from the fit and score them (model selection on the training flights: leave
    /// one flight type out).
    #[arg(long, value_name = "TYPE")]
    pub hold_out: Option<String>,
    /// The blob's motor time constant (s), the command → rotor-speed lag that logs of measured
    /// rotor speeds cannot show (default: the starting blob's).
    #[arg(long, value_name = "S")]
    pub motor_tau_s: Option<f32>,
    /// Fly the fitted blob and the untrained prior on this scenario (repeatable; a plant that is
    /// not the model, e.g. scenarios/bl-real-calm-spiral.toml) under both laws, and write
    /// nothing if the fitted blob crashes or tracks worse than the prior.
    #[arg(long, value_name = "FILE.toml")]
    pub flight_check: Vec<PathBuf>,
    /// Fly the fitted blob on this scenario (repeatable) under both laws and write nothing if
    /// it crashes: a plant it must survive without being compared with the prior (e.g.
    /// scenarios/bl-calm-spiral.toml, the description's rigid body: the other vehicle the
    /// logs could be).
    #[arg(long, value_name = "FILE.toml")]
    pub flight_survive: Vec<PathBuf>,
    /// Output: the blob with the fitted port terms (a report beside it, FILE.hfw.json).
    #[arg(long, value_name = "FILE.hfw")]
    pub out: PathBuf,
    /// No progress lines.
    #[arg(long)]
    pub quiet: bool,
}

/// What `fit-port` writes beside the blob.
#[derive(Clone, Debug, Serialize)]
pub struct FitPortReport {
    /// The fitted terms per axis, and what they can say.
    pub port: PortReport,
    /// The structure fitted.
    pub structure: PortStructure,
    /// The torque gains' prior weight (`--torque-gain-prior`; 0: none).
    pub torque_gain_prior: f64,
    /// The rate damping's prior weight (`--rate-damping-prior`; 0: none).
    pub rate_damping_prior: f64,
    /// The starting blob.
    pub weights: String,
    /// The dataset.
    pub data: String,
    /// The held-out flight type, if any.
    pub hold_out: Option<String>,
    /// Windows fitted on.
    pub windows: usize,
    /// Predicted steps per window.
    pub horizon: usize,
    /// The fit's iterations.
    pub steps: Vec<FitStep>,
    /// The fitted windows' errors with the starting blob.
    pub errors_start: HorizonErrors,
    /// The same windows with the fitted blob.
    pub errors_fitted: HorizonErrors,
    /// The held-out windows' errors with the fitted blob (with `--hold-out`).
    pub errors_held_out: Option<HorizonErrors>,
    /// The flight check against the untrained prior (with `--flight-check`).
    pub flight_check: Option<PriorCheck>,
    /// Wall time (s).
    pub elapsed_s: f64,
}

/// Runs `host-train fit-port`.
///
/// # Errors
/// An unreadable blob or dataset, bad arguments, no window to fit or score, a fitted model
/// the blob format refuses, a failure writing FILE.
pub fn run(args: &FitPortArgs) -> Result<FitPortReport> {
    let scales = args.fit.checked_scales()?;
    let t0 = Instant::now();
    let mut base = load_learned(&args.weights)?;
    if let Some(tau) = args.motor_tau_s {
        if !(0.0..=hamflight::model::MAX_MOTOR_TAU_S).contains(&tau) {
            bail!("--motor-tau-s must be in 0..=1 s, got {tau}");
        }
        base = base.with_motor_tau_s(tau);
    }
    let scenarios = args
        .flight_check
        .iter()
        .map(Scenario::load)
        .collect::<Result<Vec<_>>>()?;
    let survive = args
        .flight_survive
        .iter()
        .map(Scenario::load)
        .collect::<Result<Vec<_>>>()?;
    let spec = args.fit.spec();
    let data = data::load(&args.data, spec).with_context(|| {
        format!(
            "the fit needs windows of {} continuous states (--horizon {}); import the flights \
             with --keep-repeated-states --trim-s 0 so that long stretches stay whole",
            spec.len, args.fit.horizon
        )
    })?;
    let held = |i: usize| -> bool {
        let Some(t) = &args.hold_out else {
            return false;
        };
        data.windows
            .get(i)
            .and_then(|w| data.realizations.get(w.realization))
            .is_some_and(|r| {
                std::path::Path::new(r.source_file.as_deref().unwrap_or(&r.file))
                    .file_name()
                    .and_then(|f| f.to_str())
                    .is_some_and(|f| f.starts_with(t.as_str()))
            })
    };
    let (fit_all, held_all): (Vec<usize>, Vec<usize>) =
        (0..data.windows.len()).partition(|&i| !held(i));
    let ids = args.fit.thin(fit_all);
    let held_ids = args.fit.thin(held_all);
    if ids.is_empty() {
        bail!("no window left to fit on");
    }
    if args.hold_out.is_some() && held_ids.is_empty() {
        bail!(
            "--hold-out {}: no flight's file name starts with it",
            args.hold_out.as_deref().unwrap_or("")
        );
    }
    let structure = PortStructure {
        tilt: !args.no_tilt,
        gyrator: !args.no_gyrator,
        drag: !args.no_drag,
        rate_damping: !args.no_rate_damping,
        torque_gains: !args.pin_torque_gains,
        torque_lag: !args.pin_torque_lag,
    };
    for (flag, w) in [
        ("--torque-gain-prior", args.torque_gain_prior),
        ("--rate-damping-prior", args.rate_damping_prior),
    ] {
        if !(w.is_finite() && w >= 0.0) {
            bail!("{flag} must be a finite weight ≥ 0, got {w}");
        }
    }
    let cfg = PortFitConfig {
        iterations: args.fit.iterations,
        scales,
        structure,
        torque_gain_prior: args.torque_gain_prior,
        rate_damping_prior: args.rate_damping_prior,
        ..PortFitConfig::default()
    };
    if !args.quiet {
        eprintln!(
            "fitting the port terms on {} windows of {} steps ({} threads){}",
            ids.len(),
            args.fit.horizon,
            cfg.threads,
            args.hold_out
                .as_ref()
                .map(|t| format!(", {} windows of `{t}` held out", held_ids.len()))
                .unwrap_or_default()
        );
    }
    let quiet = args.quiet;
    let (model, steps) = port_fit::fit(
        &base,
        &data,
        &ids,
        &port_fit::default_start(&structure),
        &cfg,
        |s| {
            if !quiet {
                eprintln!(
                    "  iteration {:>2}: cost {:.5} (λ {:.1e}, {:.1} s)",
                    s.iteration,
                    s.cost,
                    s.lambda,
                    t0.elapsed().as_secs_f64()
                );
            }
        },
    );
    model
        .port()
        .validate()
        .map_err(|e| anyhow::anyhow!("the fitted port terms cannot be flown: {e:?}"))?;
    let flight_check = if scenarios.is_empty() && survive.is_empty() {
        None
    } else {
        if !quiet {
            eprintln!("flight check: the fitted blob against the untrained prior, both laws");
        }
        let c = prior_check::run_with_safety(&model, &scenarios, &survive)?;
        if let Some(why) = &c.failure {
            let lost_a_survival = c
                .flights
                .iter()
                .any(|f| !f.against_prior && f.crash_s.is_some());
            let advice = if lost_a_survival {
                "The fitted terms lose a vehicle the blob must survive (--flight-survive): \
                 pull the torque gains toward the description (--torque-gain-prior W, or \
                 --pin-torque-gains), or fit with fewer terms"
            } else {
                "The fitted terms make the vehicle of the check scenario fly worse than a blob \
                 that knows only its rigid body: fit with fewer terms (--no-tilt, \
                 --no-gyrator, --pin-torque-lag), pull the rate damping toward zero \
                 (--rate-damping-prior W), on more varied flights, or check that the \
                 scenario describes the vehicle the flights came from"
            };
            bail!("flight check failed: {why}. Nothing was written. {advice}");
        }
        Some(c)
    };
    let id = Response::identity();
    let report = FitPortReport {
        port: port_fit::report(&model),
        structure,
        torque_gain_prior: args.torque_gain_prior,
        rate_damping_prior: args.rate_damping_prior,
        weights: args.weights.display().to_string(),
        data: args.data.display().to_string(),
        hold_out: args.hold_out.clone(),
        windows: ids.len(),
        horizon: args.fit.horizon,
        steps,
        errors_start: response_errors(&base, &id, &data, &ids),
        errors_fitted: response_errors(&model, &id, &data, &ids),
        errors_held_out: (!held_ids.is_empty())
            .then(|| response_errors(&model, &id, &data, &held_ids)),
        flight_check,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    let bytes = blob::encode_model(&model);
    check_decodes(&bytes)?;
    write_atomic(&args.out, &bytes)?;
    let mut json_path = args.out.clone().into_os_string();
    json_path.push(".json");
    write_atomic(
        std::path::Path::new(&json_path),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    Ok(report)
}

/// The written blob decodes to a model that can fly (the port terms pass the decoder's checks).
fn check_decodes(bytes: &[u8]) -> Result<()> {
    hamflight::model::LearnedModel::from_blob(bytes)
        .map(|_| ())
        .map_err(|e| anyhow::anyhow!("the fitted blob does not decode: {e}"))
}
