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
//! With `--response FILE` the row `learned+response` (the blob with a measured-input response,
//! [`crate::train::response`]); with `--history-s S` as well, `learned+response+adapted`: the
//! same with a constant body force read from the S seconds of the flight before each window
//! ([`history_force_offset`]), what the adaptation law estimates online. That row sees more
//! than the window's first state and inputs, so it is outside the nano-drone benchmark's
//! protocol; every row is then scored on the windows that have that much flight before them.
//!
//! Beside the predictors, `logged_velocity_pos_mae_m`: the position the log's own world
//! velocities integrate to (trapezoid, from the window's first position), against the logged
//! position. It reads the future velocities, so it is not a predictor: it measures how well the
//! log's velocity and position agree, an error a predictor that starts from the logged
//! velocity will hardly beat (on the nano-drone benchmark's melon flights a large share of the
//! best predictor's error: docs/benchmark.md).
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
use crate::train::data::{self, Window, Windows};
use crate::train::predict::Acc;
pub use crate::train::predict::{model_errors, HorizonErrors};
use crate::train::response::Response;

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
    /// With --response: also score `learned+response+adapted`, the response with a constant
    /// body force estimated from the S seconds of the same flight before each window (what the
    /// adaptation law estimates online). Every row is then scored on the windows that have
    /// that much flight before them. Outside the benchmark's protocol, which gives a predictor
    /// only the window's first state and inputs.
    #[arg(long, value_name = "S", requires = "response")]
    pub history_s: Option<f64>,
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
    /// Per step: the mean over windows of ‖p₀ + ∫ R v dt − p‖ (m) with the logged velocities
    /// (module docs): the log's kinematic consistency, not a predictor.
    pub logged_velocity_pos_mae_m: Vec<f64>,
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

/// Per step k = 1 … N, the mean over windows `ids` of ‖p₀ + ∫ R v dt − p_k‖ (m): the log's own
/// world velocities integrated by the trapezoid rule against its positions.
pub fn logged_velocity_position_errors(data: &Windows, ids: &[usize]) -> Vec<f64> {
    let dt = 1.0 / f64::from(data.sample_hz);
    let n = data.window_len.saturating_sub(1);
    let mut sum = vec![0.0f64; n];
    let mut windows = 0usize;
    for w in ids.iter().filter_map(|&i| data.windows.get(i)) {
        let Some(s0) = w.states.first() else { continue };
        let world = |s: &hamflight::model::State| (s.rot * s.v_body_m_s).cast::<f64>();
        let mut p = s0.p_m.cast::<f64>();
        let mut v_prev = world(s0);
        for (k, e) in sum.iter_mut().enumerate() {
            let Some(t) = w.states.get(k + 1) else { break };
            let v = world(t);
            p += (v_prev + v) * (0.5 * dt);
            v_prev = v;
            *e += (p - t.p_m.cast::<f64>()).norm();
        }
        windows += 1;
    }
    let m = windows.max(1) as f64;
    sum.into_iter().map(|e| e / m).collect()
}

/// Splits each window of `data` into its first `k` steps (the history, `k` + 1 states and `k`
/// inputs) and the rest (the window scored, which starts where the history ends).
fn split_history(mut data: Windows, k: usize) -> (Windows, Vec<Window>) {
    if k == 0 {
        return (data, Vec::new());
    }
    let mut histories = Vec::with_capacity(data.windows.len());
    for w in data.windows.iter_mut() {
        let states = w.states.split_off(k);
        let u = w.u.split_off(k);
        let mut head = std::mem::replace(
            w,
            Window {
                states,
                u,
                realization: w.realization,
            },
        );
        if let Some(first) = w.states.first() {
            head.states.push(*first);
        }
        histories.push(head);
    }
    data.window_len = data.window_len.saturating_sub(k);
    (data, histories)
}

/// Steps of each history segment rolled out to read the force offset.
const HISTORY_SEGMENT: usize = 10;

/// The constant body-frame acceleration (m/s²) that `history` says `response` misses: the
/// history is cut into `HISTORY_SEGMENT`-step pieces, each rolled out from its logged first
/// state, and the end velocity's miss (world frame, over the piece's duration) is turned into
/// the body frame at the piece's middle and averaged. Zero for a history shorter than a piece.
pub fn history_force_offset<M: hamflight::model::HamiltonianModel>(
    model: &M,
    response: &Response,
    history: &Window,
    dt_s: f32,
) -> Vector3<f32> {
    let mut sum = Vector3::zeros();
    let mut n = 0usize;
    let mut j = 0;
    while j + HISTORY_SEGMENT < history.states.len() {
        let (Some(s0), Some(end), Some(mid), Some(u)) = (
            history.states.get(j),
            history.states.get(j + HISTORY_SEGMENT),
            history.states.get(j + HISTORY_SEGMENT / 2),
            history.u.get(j..j + HISTORY_SEGMENT),
        ) else {
            break;
        };
        let mut last = None;
        crate::train::response::rollout(model, response, s0, u, dt_s, |_, s| last = Some(*s));
        if let Some(p) = last {
            let miss = end.rot * end.v_body_m_s - p.rot * p.v_body_m_s;
            let a_world = miss / (HISTORY_SEGMENT as f32 * dt_s);
            if a_world.iter().all(|x| x.is_finite()) {
                sum += mid.rot.transpose() * a_world;
                n += 1;
            }
        }
        j += HISTORY_SEGMENT;
    }
    if n == 0 {
        Vector3::zeros()
    } else {
        sum / n as f32
    }
}

/// Errors of `response` with each window's constant body force read from its history
/// ([`history_force_offset`]) added to the response's.
fn adapted_errors(
    model: &LearnedModel,
    response: &Response,
    data: &Windows,
    histories: &[Window],
) -> HorizonErrors {
    let dt = 1.0 / data.sample_hz;
    let n = data.window_len.saturating_sub(1);
    let mut acc = Acc::new(n);
    for (w, h) in data.windows.iter().zip(histories) {
        let c = history_force_offset(model, response, h, dt);
        let mut adapted = response.clone();
        for (b, x) in adapted.accel_bias.iter_mut().zip(c.iter()) {
            *b += *x;
        }
        crate::train::response::add_window(&mut acc, model, &adapted, w, dt);
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
    // With a history, windows are cut longer and split: the first `k` steps are the history.
    let k = match args.history_s {
        None => 0,
        Some(h) if h.is_finite() && h > 0.0 => {
            let rate_hz = crate::io::dataset::load_manifest(&args.data)?.sample_hz;
            (h * rate_hz).round().max(1.0) as usize
        }
        Some(h) => bail!("--history-s must be a positive number of seconds (got {h})"),
    };
    let spec = WindowSpec {
        len: args.horizon + 1 + k,
        stride: args.stride,
    };
    let data = data::load(&args.data, spec).with_context(|| {
        format!(
            "scoring needs windows of {} continuous states (--horizon {})",
            spec.len, args.horizon
        )
    })?;
    let (data, histories) = split_history(data, k);
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
        logged_velocity_pos_mae_m: logged_velocity_position_errors(&data, &ids),
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
        if k > 0 {
            score.predictors.insert(
                2,
                PredictorScore {
                    name: "learned+response+adapted".into(),
                    errors: adapted_errors(&model, &response, &data, &histories),
                },
            );
        }
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
    out += &format!(
        "{:<11} {:>26}   (the log's velocities integrated: its kinematic consistency, not a \
         predictor)\n",
        "∫ logged v",
        steps
            .iter()
            .map(|k| format!("{:.4}", at(&s.logged_velocity_pos_mae_m, *k)))
            .collect::<Vec<_>>()
            .join(" / ")
    );
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
        .enumerate()
        .map(|(i, (label, pick))| {
            let mut lines: Vec<(&str, &[f64])> = s
                .predictors
                .iter()
                .map(|p| (p.name.as_str(), pick(&p.errors).as_slice()))
                .collect();
            if i == 0 {
                lines.push(("∫ logged v", s.logged_velocity_pos_mae_m.as_slice()));
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use hamflight::model::State;

    /// A window flown at 1 m/s along world x, tilted so that body and world frames differ,
    /// with the logged velocity `scale` times the true one.
    fn window(scale: f32) -> Window {
        let rot = *nalgebra::Rotation3::from_euler_angles(0.0, 0.0, 0.7).matrix();
        let v_world = Vector3::new(1.0, 0.0, 0.0);
        let states = (0..=10)
            .map(|k| State {
                p_m: v_world * (k as f32 * 0.01),
                rot,
                v_body_m_s: rot.transpose() * v_world * scale,
                ..State::default()
            })
            .collect();
        Window {
            states,
            u: vec![[0.0; 4]; 10],
            realization: 0,
        }
    }

    fn windows(scale: f32) -> Windows {
        Windows {
            windows: vec![window(scale)],
            sample_hz: 100.0,
            window_len: 11,
            mass_kg: 0.045,
            realizations: Vec::new(),
            manifest_mass_kg: 0.045,
            vehicle: Default::default(),
        }
    }

    #[test]
    fn logged_velocity_integral_measures_the_logs_consistency() {
        let exact = logged_velocity_position_errors(&windows(1.0), &[0]);
        assert_eq!(exact.len(), 10);
        assert!(exact.iter().all(|e| *e < 1e-6), "{exact:?}");
        // Velocities logged 10 % too large: after 0.1 s the integral is 1 cm ahead.
        let inflated = logged_velocity_position_errors(&windows(1.1), &[0]);
        let last = inflated.last().copied().unwrap_or(0.0);
        assert!((last - 0.01).abs() < 1e-5, "{inflated:?}");
    }

    #[test]
    fn the_history_gives_back_the_force_offset_the_model_misses() {
        use hamflight::model::HamiltonianModel;
        let model = hamflight::model::NominalModel::default();
        let dt = 0.01;
        let offset = Vector3::new(0.3, -0.2, -0.8);
        let mut truth = Response::identity();
        truth.accel_bias[..3].copy_from_slice(offset.as_slice());
        // A tilted hover with slowly turning body rates, flown by the truth.
        let hover_n = model.mass_kg() * hamflight::model::GRAVITY_M_S2;
        let u: Vec<[f32; 4]> = (0..50)
            .map(|k| [hover_n, 1e-6 * (k as f32 * 0.2).sin(), 0.0, 0.0])
            .collect();
        let s0 = State {
            rot: *nalgebra::Rotation3::from_euler_angles(0.1, -0.05, 0.3).matrix(),
            ..State::default()
        };
        let mut states = vec![s0];
        crate::train::response::rollout(&model, &truth, &s0, &u, dt, |_, s| states.push(*s));
        let history = Window {
            states,
            u,
            realization: 0,
        };
        let c = history_force_offset(&model, &Response::identity(), &history, dt);
        assert!(
            (c - offset).norm() < 0.02 * offset.norm(),
            "{c:?} against {offset:?}"
        );
        // The truth itself leaves nothing to estimate.
        let c = history_force_offset(&model, &truth, &history, dt);
        assert!(c.norm() < 1e-3, "{c:?}");
        // Too short a history: zero.
        let short = Window {
            states: history.states[..5].to_vec(),
            u: history.u[..4].to_vec(),
            realization: 0,
        };
        assert_eq!(
            history_force_offset(&model, &Response::identity(), &short, dt),
            Vector3::zeros()
        );
    }

    #[test]
    fn a_window_splits_into_its_history_and_the_window_scored() {
        let whole = windows(1.0);
        let (scored, histories) = split_history(whole.clone(), 4);
        assert_eq!(scored.window_len, 7);
        let (w, h) = (&scored.windows[0], &histories[0]);
        assert_eq!((w.states.len(), w.u.len()), (7, 6));
        assert_eq!((h.states.len(), h.u.len()), (5, 4));
        // The history ends where the window scored starts, and both are the original's.
        assert_eq!(h.states[4], w.states[0]);
        assert_eq!(w.states[0], whole.windows[0].states[4]);
        assert_eq!(h.states[0], whole.windows[0].states[0]);
        let (same, none) = split_history(whole.clone(), 0);
        assert!(none.is_empty());
        assert_eq!(same.windows[0].states, whole.windows[0].states);
    }
}
