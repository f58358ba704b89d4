//! `host-train score`: open-loop multi-step prediction errors of a blob on any dataset.
//!
//! Every window of `--horizon` + 1 continuous states (a new one every `--stride` samples) of
//! every flight is rolled out from its first state under the logged wrench, step by step at the
//! dataset's rate (RK4, as training integrates), by four predictors:
//! - `learned`: the blob's model with a = 0 (an unseen flight has no learned a_j);
//! - `nominal`: the rigid body with the vehicle's mass and inertia (`--vehicle`, else the
//!   manifest's description or inertia, else the CF2X's) and the logged wrench;
//! - `hold`: constant world velocity and constant body rates (p += v dt, R ← R exp(ω dt));
//! - `zero-order`: every state held at the window's first (the error a predictor must beat to
//!   say anything).
//!
//! For each predicted step k = 1 … N it reports the mean (MAE) and the root mean square (RMSE)
//! over windows of the error norms: position ‖p̂ − p‖ (m), velocity ‖R̂ v̂ − R v‖ (world frame,
//! m/s; the body-frame norm, as the training report uses, is kept too), attitude as the
//! geodesic angle of R̂ Rᵀ (rad), body rates ‖ω̂ − ω‖ (rad/s). The mean of the error norm is
//! the metric of the nano-drone system-identification benchmark (docs/benchmark.md).
//!
//! Writes `DIR/score.json` and `DIR/score.svg` (MAE against horizon, one panel per quantity)
//! when `--out DIR` is given, and prints a table at 1, 10 and N steps.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use hamflight::lie;
use hamflight::model::{LearnedModel, NominalModel};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::control::adapter::load_learned;
use crate::io::dataset::WindowSpec;
use crate::io::files::write_atomic;
use crate::sim::vehicle::VehicleFile;
use crate::train::data::{self, Windows};
use crate::train::predict::Acc;
pub use crate::train::predict::{model_errors, HorizonErrors};

/// Arguments of `host-train score`.
#[derive(Args, Clone, Debug)]
pub struct ScoreArgs {
    /// The weight blob (`train`'s FILE.hfw).
    #[arg(long, value_name = "FILE.hfw")]
    pub weights: PathBuf,
    /// The dataset to predict (`collect` or `import` output): flights the blob did not see.
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Predicted steps per window (the benchmark's 50 = 0.5 s at 100 Hz).
    #[arg(long, default_value_t = 50)]
    pub horizon: usize,
    /// Samples between window starts (1: every start).
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// The vehicle for the nominal model (a TOML file or `cf2x`) [default: the dataset's].
    #[arg(long, value_name = "FILE|cf2x")]
    pub vehicle: Option<PathBuf>,
    /// Write DIR/score.json and DIR/score.svg.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// A measured-input response (`host-train fit-response`'s FILE.json): adds the row
    /// `learned+response`, the blob with the response's torque gain and lag and velocity term.
    #[arg(long, value_name = "FILE.json")]
    pub response: Option<PathBuf>,
}

/// One predictor's row.
#[derive(Clone, Debug, Serialize)]
pub struct PredictorScore {
    /// `learned`, `nominal`, `hold` or `zero-order`.
    pub name: String,
    /// Its errors.
    pub errors: HorizonErrors,
}

/// `score.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Score {
    /// The blob scored.
    pub weights: String,
    /// The dataset.
    pub data: String,
    /// Windows scored.
    pub windows: usize,
    /// Predicted steps.
    pub horizon: usize,
    /// The dataset's rate (Hz).
    pub sample_hz: f64,
    /// The nominal model's mass (kg) and diag(J) (kg·m²).
    pub nominal_mass_kg: f64,
    /// diag(J) of the nominal model.
    pub nominal_inertia_kg_m2: [f64; 3],
    /// Every predictor.
    pub predictors: Vec<PredictorScore>,
}

/// Errors of the kinematic predictors over windows `ids`: `hold` keeps the world velocity and
/// body rates, `zero-order` the whole first state.
pub fn baseline_errors(data: &Windows, ids: &[usize], hold: bool) -> HorizonErrors {
    let dt = 1.0 / data.sample_hz;
    let n = data.window_len.saturating_sub(1);
    let mut acc = Acc::new(n);
    for w in ids.iter().filter_map(|&i| data.windows.get(i)) {
        let Some(s0) = w.states.first().copied() else {
            continue;
        };
        let v_world = s0.rot * s0.v_body_m_s;
        let step = lie::exp(&(s0.w_body_rad_s * dt));
        let mut s = s0;
        for k in 0..n {
            let Some(t) = w.states.get(k + 1) else { break };
            if hold {
                s.p_m += v_world * dt;
                s.rot *= step;
                // The world velocity stays: its body coordinates turn with R.
                s.v_body_m_s = s.rot.transpose() * v_world;
            }
            acc.add(k, &s, t);
        }
        acc.n += 1;
    }
    acc.finish()
}

/// Scores `model` on every window of `data` (`ids` = all), with `nominal` as the physics row.
pub fn score_windows(
    model: &LearnedModel,
    nominal: &NominalModel,
    data: &Windows,
    ids: &[usize],
) -> Vec<PredictorScore> {
    let row = |name: &str, errors| PredictorScore {
        name: name.into(),
        errors,
    };
    vec![
        row("learned", model_errors(model, data, ids)),
        row("nominal", model_errors(nominal, data, ids)),
        row("hold", baseline_errors(data, ids, true)),
        row("zero-order", baseline_errors(data, ids, false)),
    ]
}

/// Runs `host-train score`.
///
/// # Errors
/// An unreadable blob, dataset or vehicle file; a zero horizon or stride; a dataset with no
/// window of horizon + 1 continuous states; a failure writing the outputs.
pub fn run(args: &ScoreArgs) -> Result<Score> {
    if args.horizon == 0 || args.stride == 0 {
        bail!("--horizon and --stride must be at least 1");
    }
    let model = load_learned(&args.weights)?;
    let spec = WindowSpec {
        len: args.horizon + 1,
        stride: args.stride,
    };
    let data = data::load(&args.data, spec).with_context(|| {
        format!(
            "scoring needs windows of {} continuous states (--horizon {})",
            spec.len, args.horizon
        )
    })?;
    let vehicle = args.vehicle.as_deref().map(VehicleFile::load).transpose()?;
    let described = vehicle.or_else(|| data.vehicle.description.clone());
    let (mass, j) = match &described {
        Some(v) => (v.mass_kg, v.inertia_kg_m2),
        None => (
            f64::from(data.manifest_mass_kg),
            data.vehicle
                .inertia_kg_m2
                .unwrap_or(VehicleFile::cf2x().inertia_kg_m2),
        ),
    };
    let nominal = NominalModel::new(
        mass as f32,
        Matrix3::from_diagonal(&Vector3::from(j.map(|x| x as f32))),
    );
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let mut score = Score {
        weights: args.weights.display().to_string(),
        data: args.data.display().to_string(),
        windows: ids.len(),
        horizon: args.horizon,
        sample_hz: f64::from(data.sample_hz),
        nominal_mass_kg: mass,
        nominal_inertia_kg_m2: j,
        predictors: score_windows(&model, &nominal, &data, &ids),
    };
    if let Some(path) = &args.response {
        let response = crate::pipeline::fit_response::load_response(path)?;
        score.predictors.insert(
            1,
            PredictorScore {
                name: "learned+response".into(),
                errors: crate::train::response::response_errors(&model, &response, &data, &ids),
            },
        );
    }
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create `{}`", dir.display()))?;
        write_atomic(
            &dir.join("score.json"),
            serde_json::to_string_pretty(&score)?.as_bytes(),
        )?;
        plot(&score, &dir.join("score.svg"))?;
    }
    Ok(score)
}

/// The printed table: MAE of each quantity at 1, 10 and N steps, one row per predictor.
pub fn table(s: &Score) -> String {
    let steps: Vec<usize> = [1, 10, s.horizon]
        .into_iter()
        .filter(|k| *k <= s.horizon)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let at = |v: &[f64], k: usize| v.get(k - 1).copied().unwrap_or(f64::NAN);
    let mut out = format!(
        "{} windows of {} steps at {:.0} Hz; MAE (mean error norm) at steps {:?}\n\
         {:<11} {:>26} {:>26} {:>26} {:>26}\n",
        s.windows,
        s.horizon,
        s.sample_hz,
        steps,
        "predictor",
        "position (m)",
        "velocity (m/s, world)",
        "attitude (rad)",
        "body rates (rad/s)"
    );
    for p in &s.predictors {
        let e = &p.errors;
        let cell = |v: &[f64]| {
            steps
                .iter()
                .map(|k| format!("{:.4}", at(v, *k)))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        out += &format!(
            "{:<11} {:>26} {:>26} {:>26} {:>26}\n",
            p.name,
            cell(&e.pos_mae_m),
            cell(&e.vel_mae_m_s),
            cell(&e.att_mae_rad),
            cell(&e.rate_mae_rad_s)
        );
    }
    out
}

/// MAE against the horizon (s), one panel per quantity, one line per predictor.
fn plot(s: &Score, path: &Path) -> Result<()> {
    type Pick = fn(&HorizonErrors) -> &Vec<f64>;
    let picks: [(&str, Pick); 4] = [
        ("position MAE (m)", |e| &e.pos_mae_m),
        ("velocity MAE (m/s)", |e| &e.vel_mae_m_s),
        ("attitude MAE (rad)", |e| &e.att_mae_rad),
        ("body-rate MAE (rad/s)", |e| &e.rate_mae_rad_s),
    ];
    let panels: Vec<crate::report::plot::HorizonPanel<'_>> = picks
        .iter()
        .map(|(label, pick)| {
            let lines = s
                .predictors
                .iter()
                .map(|p| (p.name.as_str(), pick(&p.errors).as_slice()))
                .collect();
            (*label, lines)
        })
        .collect();
    crate::report::plot::horizon_svg(
        &format!(
            "open-loop prediction error, {} windows ({})",
            s.windows, s.data
        ),
        1.0 / s.sample_hz,
        &panels,
        path,
    )
}
