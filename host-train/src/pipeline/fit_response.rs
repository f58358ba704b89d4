//! `host-train fit-response`: identify a blob's measured-input response
//! ([`crate::train::response`]) on a dataset, for `host-train score --response`.
//!
//! Windows of `--horizon` + 1 continuous states (every `--stride` samples, thinned evenly to at
//! most `--max-windows`) are rolled out from their first state under the logged wrench; the
//! response's 54 numbers are fitted by Levenberg–Marquardt to the position, velocity, attitude
//! and rate errors at steps 1, 2, 5, 10, 20, … N, each scaled by a typical error (0.1 m,
//! 0.5 m/s, 0.2 rad, 0.6 rad/s). Writes FILE (JSON: the response, the fit's history and the
//! windows' errors before and after).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;

use crate::control::adapter::load_learned;
use crate::io::dataset::WindowSpec;
use crate::io::files::write_atomic;
use crate::train::data;
use crate::train::predict::HorizonErrors;
use crate::train::response::{self, FitConfig, FitStep, ForceTerms, Response};

/// The windows a fit runs on and its solver, shared by `fit-response` and `fit-port`.
#[derive(Args, Debug, Clone)]
pub struct FitWindowArgs {
    /// Predicted steps per window (the benchmark's 50).
    #[arg(long, default_value_t = 50)]
    pub horizon: usize,
    /// Samples between window starts.
    #[arg(long, default_value_t = 5)]
    pub stride: usize,
    /// Windows used at most (thinned evenly over the dataset): the fit's cost grows with it.
    #[arg(long, default_value_t = 1500)]
    pub max_windows: usize,
    /// Levenberg–Marquardt iterations at most.
    #[arg(long, default_value_t = 20)]
    pub iterations: usize,
    /// The typical errors that weigh the residuals against each other: position (m), velocity
    /// (m/s), attitude (rad), rates (rad/s); a smaller scale weighs that quantity more.
    #[arg(long, value_delimiter = ',', default_values_t = [0.1, 0.5, 0.2, 0.6])]
    pub scales: Vec<f64>,
}

impl FitWindowArgs {
    /// The checked scales.
    ///
    /// # Errors
    /// A zero horizon, stride or window count; scales that are not four positive numbers.
    pub fn checked_scales(&self) -> Result<[f64; 4]> {
        if self.horizon == 0 || self.stride == 0 || self.max_windows == 0 {
            bail!("--horizon, --stride and --max-windows must be at least 1");
        }
        match self.scales.as_slice() {
            &[p, v, a, w] if [p, v, a, w].iter().all(|x| x.is_finite() && *x > 0.0) => {
                Ok([p, v, a, w])
            }
            _ => bail!("--scales takes four positive numbers: position, velocity, attitude, rates"),
        }
    }

    /// The window shape: horizon + 1 states every `stride` samples.
    pub fn spec(&self) -> WindowSpec {
        WindowSpec {
            len: self.horizon + 1,
            stride: self.stride,
        }
    }

    /// `ids` thinned evenly to at most `max_windows`.
    pub fn thin(&self, ids: Vec<usize>) -> Vec<usize> {
        let every = ids.len().div_ceil(self.max_windows).max(1);
        ids.into_iter().step_by(every).collect()
    }
}

/// Arguments of `host-train fit-response`.
#[derive(Args, Debug, Clone)]
pub struct FitResponseArgs {
    /// The weight blob whose predictions the response completes (`train`'s FILE.hfw).
    #[arg(long, value_name = "FILE.hfw")]
    pub weights: PathBuf,
    /// The dataset to fit on (training flights, imported with every state kept: `import
    /// --keep-repeated-states --trim-s 0 …`, so that long windows exist).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The windows and the solver.
    #[command(flatten)]
    pub fit: FitWindowArgs,
    /// The velocity term's force rows: `drag` (a linear drag per body axis), `full` (v̇ from
    /// every component of v and ω) or `none`.
    #[arg(long, value_enum, default_value_t = ForceTerms::Drag)]
    pub force_terms: ForceTerms,
    /// Leave out the angular acceleration linear in the tilt (the vehicle's own attitude
    /// loop's pull toward level; what it buys on the nano-drone benchmark: docs/benchmark.md).
    #[arg(long)]
    pub no_tilt: bool,
    /// Output: the response as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub out: PathBuf,
    /// No progress lines.
    #[arg(long)]
    pub quiet: bool,
}

/// What `fit-response` writes.
#[derive(Clone, Debug, Serialize)]
pub struct FitReport {
    /// The fitted response (`score --response` reads this file).
    pub response: Response,
    /// The blob.
    pub weights: String,
    /// The dataset.
    pub data: String,
    /// Windows fitted on.
    pub windows: usize,
    /// Predicted steps per window.
    pub horizon: usize,
    /// The fit's iterations.
    pub steps: Vec<FitStep>,
    /// The fitted windows' errors with the blob alone.
    pub errors_blob: HorizonErrors,
    /// The same windows with the response.
    pub errors_fitted: HorizonErrors,
    /// Wall time (s).
    pub elapsed_s: f64,
}

/// Reads a response from `fit-response`'s output (or a bare [`Response`] JSON).
///
/// # Errors
/// An unreadable file, JSON that is not a response, or a non-finite number.
pub fn load_response(path: &std::path::Path) -> Result<Response> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the response `{}`", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("`{}` is not JSON", path.display()))?;
    let inner = value.get("response").cloned().unwrap_or(value);
    let r: Response = serde_json::from_value(inner).with_context(|| {
        format!(
            "`{}` is not a response (write one with `host-train fit-response`)",
            path.display()
        )
    })?;
    if !r.is_finite() {
        bail!(
            "the response `{}` holds a non-finite number",
            path.display()
        );
    }
    Ok(r)
}

/// Runs `host-train fit-response`.
///
/// # Errors
/// An unreadable blob or dataset, a zero horizon, stride or window count, no window of
/// horizon + 1 continuous states, a failure writing FILE.
pub fn run(args: &FitResponseArgs) -> Result<FitReport> {
    let scales = args.fit.checked_scales()?;
    let t0 = Instant::now();
    let model = load_learned(&args.weights)?;
    let spec = args.fit.spec();
    let data = data::load(&args.data, spec).with_context(|| {
        format!(
            "the fit needs windows of {} continuous states (--horizon {}); import the flights \
             with --keep-repeated-states --trim-s 0 so that long stretches stay whole",
            spec.len, args.fit.horizon
        )
    })?;
    let n = data.windows.len();
    let ids = args.fit.thin((0..n).collect());
    if !args.quiet {
        eprintln!(
            "fitting the response on {} of {n} windows of {} steps ({} threads)",
            ids.len(),
            args.fit.horizon,
            FitConfig::default().threads
        );
    }
    // Start with the torques weak and unlagged: a full-gain start diverges on real logs.
    let start = Response {
        torque_gain: [0.1; 3],
        torque_lag_s: 0.05,
        ..Response::identity()
    };
    let cfg = FitConfig {
        iterations: args.fit.iterations,
        scales,
        force: args.force_terms,
        tilt: !args.no_tilt,
        ..FitConfig::default()
    };
    let quiet = args.quiet;
    let (fitted, steps) = response::fit(&model, &data, &ids, &start, &cfg, |s| {
        if !quiet {
            eprintln!(
                "  iteration {:>2}: cost {:.5} (λ {:.1e}, {:.1} s)",
                s.iteration,
                s.cost,
                s.lambda,
                t0.elapsed().as_secs_f64()
            );
        }
    });
    let report = FitReport {
        errors_blob: response::response_errors(&model, &Response::identity(), &data, &ids),
        errors_fitted: response::response_errors(&model, &fitted, &data, &ids),
        response: fitted,
        weights: args.weights.display().to_string(),
        data: args.data.display().to_string(),
        windows: ids.len(),
        horizon: args.fit.horizon,
        steps,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    write_atomic(&args.out, serde_json::to_string_pretty(&report)?.as_bytes())?;
    Ok(report)
}
