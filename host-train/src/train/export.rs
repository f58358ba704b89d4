//! Export: the weight blob (θ, φ and the network shapes; written whole through a temporary
//! file) and the JSON report next to it (`FILE.hfw.json`): configuration, training curve,
//! held-out N-step prediction errors of the learned and nominal models, the learned J (hover)
//! and g against the true ones, and the a_j with the true disturbances of their realizations.
//! The "true" values are the dataset manifest's vehicle ([`crate::io::dataset::VehicleDescription`]
//! and `mass_kg`): the inertia is omitted (null) when the manifest does not give it, and the
//! true g assumes nominal rotors when it gives no rotor efficiencies.

use super::data::Windows;
use super::epochs::{EpochStats, Trained};
use super::TrainConfig;
use anyhow::Result;
use hamflight::model::{
    true_input_gain, HamiltonianModel, LearnedModel, NominalModel, State, FEATURES, GRAVITY_M_S2,
};
use nalgebra::{Vector3, Vector4};
use serde::Serialize;
use std::path::Path;

pub use crate::io::files::write_atomic;

/// Root-mean-square prediction errors at each predicted step of the held-out windows.
#[derive(Clone, Debug, Serialize)]
pub struct PredictionErrors {
    /// ‖p − p̄‖ (m), RMS over windows, for steps 1..N.
    pub pos_m: Vec<f64>,
    /// Rotation angle of R̄ Rᵀ (rad).
    pub rot_rad: Vec<f64>,
    /// ‖v − v̄‖ (m/s), body frame.
    pub vel_m_s: Vec<f64>,
    /// ‖ω − ω̄‖ (rad/s), body frame.
    pub rate_rad_s: Vec<f64>,
}

/// Held-out errors on the disturbance-free flights.
#[derive(Clone, Debug, Serialize)]
pub struct CalmPredictionErrors {
    /// Held-out windows of disturbance-free flights.
    pub windows: usize,
    /// The learned model (a = 0).
    pub learned: PredictionErrors,
    /// The stock vehicle's nominal model.
    pub nominal: PredictionErrors,
}

/// What the written blob keeps of the learned features W ([`super::backoff`]).
#[derive(Clone, Debug, Serialize)]
pub struct FeatureBackoff {
    /// Directions of a along which the blob's W is the learned one (6: all), the nominal
    /// features elsewhere.
    pub excited_dims: usize,
    /// The share of the learned features' deviation from the nominal ones kept along those
    /// directions (1: as learned).
    pub kept: f32,
    /// The blobs that failed the flight check first: (excited_dims, kept, why).
    pub failed: Vec<(usize, f32, String)>,
}

impl Default for FeatureBackoff {
    fn default() -> Self {
        Self {
            excited_dims: FEATURES,
            kept: 1.0,
            failed: Vec::new(),
        }
    }
}

/// One realization's learned a_j next to its true disturbance.
#[derive(Clone, Debug, Serialize)]
pub struct RealizationReport {
    /// The manifest's wind (m/s², world frame), when known.
    pub true_wind_m_s2: Option<[f32; 3]>,
    /// The manifest's rotor efficiencies δᵢ, when known.
    pub true_rotor_efficiency: Option<[f32; 4]>,
    /// Marked disturbance-free at import (a_j pinned to 0).
    pub disturbance_free: bool,
    /// The learned a_j.
    pub a: [f32; FEATURES],
    /// The rotor efficiencies 1 + δηⱼ learned for this flight in the main stage (null when
    /// not learned: `--no-flight-rotor-gains`).
    pub learned_rotor_efficiency: Option<[f32; 4]>,
    /// W(hover) a_j: the learned disturbance wrench at hover [F (N, body); τ (N·m, body)].
    pub learned_wrench_at_hover: [f32; 6],
    /// The true disturbance wrench at hover: m w plus the rotor deficits at hover thrust (when
    /// the manifest gives the disturbance).
    pub true_wrench_at_hover: Option<[f32; 6]>,
}

/// The training report (`FILE.hfw.json`).
#[derive(Clone, Debug, Serialize)]
pub struct TrainReport {
    /// The configuration.
    pub config: TrainConfig,
    /// Windows used for training and held out.
    pub train_windows: usize,
    /// Held-out windows.
    pub heldout_windows: usize,
    /// Held-out loss of the initial model (the physical prior).
    pub initial_val_loss: f64,
    /// Final held-out loss.
    pub final_val_loss: f64,
    /// Wall time of training (s).
    pub train_time_s: f64,
    /// The training curve.
    pub curve: Vec<EpochStats>,
    /// Held-out errors: learned model with its a_j.
    pub heldout_learned: PredictionErrors,
    /// Held-out errors of the training model with rotor gains: the main stage's J⁻¹, g, W and
    /// a_j with each flight's rotor gains (null without them). The flying model is
    /// `heldout_learned`: the shared g cannot bend to one flight's rotors.
    pub heldout_learned_rotor_gains: Option<PredictionErrors>,
    /// Held-out errors: learned model with a = 0 (no disturbance compensation).
    pub heldout_learned_no_disturbance: PredictionErrors,
    /// Held-out errors on the disturbance-free flights' windows only: learned (a = 0) and the
    /// stock nominal model (null when no flight is marked disturbance-free). On the stock
    /// vehicle the nominal model is exact there, so this is the learned model's own error.
    pub heldout_calm: Option<CalmPredictionErrors>,
    /// Held-out errors: the stock vehicle's nominal model (the CF2X's constants, no
    /// disturbance).
    pub heldout_nominal: PredictionErrors,
    /// Held-out errors: the nominal model with the manifest's mass and inertia (null when the
    /// manifest gives no inertia).
    pub heldout_nominal_true_vehicle: Option<PredictionErrors>,
    /// The model's mass (kg): the blob's (`--mass-kg`, else the manifest's).
    pub mass_kg: f32,
    /// The dataset's mass (kg), the manifest's `mass_kg`.
    pub true_mass_kg: f32,
    /// The manifest's motor time constant (s): the commands were realized through it at import.
    pub motor_tau_s: Option<f64>,
    /// The motor time constant written into the blob (s): what the composite law's prediction
    /// assumes (`--motor-tau-s`, else the manifest's, else 0.05 s).
    pub blob_motor_tau_s: f32,
    /// The SITL flight check before writing ([`crate::pipeline::train`]); null when skipped.
    pub flight_check: Option<FlightCheck>,
    /// What the written blob keeps of the learned features: all of them, unless the flight
    /// check's back-off ([`super::backoff`]) had to keep less. The held-out errors and a_j
    /// above are the learned model's.
    pub features: FeatureBackoff,
    /// Learned J at hover (R = I), kg·m², row-major.
    pub learned_inertia_hover_kg_m2: [[f32; 3]; 3],
    /// The true J (kg·m²), from the manifest (null when it gives none).
    pub true_inertia_kg_m2: Option<[[f32; 3]; 3]>,
    /// Learned g at hover, rows body force x, y, z, torque x, y, z.
    pub learned_gain_hover: [[f32; 4]; 6],
    /// The true g of the described vehicle in the model's units: the realized wrench per unit
    /// of commanded wrench through the manifest's rotor efficiencies (nominal rotors when it
    /// gives none), force rows times the model's mass over the true mass.
    pub true_gain: [[f32; 4]; 6],
    /// Per realization: a_j and the true disturbance.
    pub realizations: Vec<RealizationReport>,
}

/// N-step prediction errors of `model` on windows `ids`, with a_j from `a` (None: a = 0).
pub fn prediction_errors<M: HamiltonianModel>(
    model: &M,
    data: &Windows,
    ids: &[usize],
    a: Option<&[[f32; FEATURES]]>,
) -> PredictionErrors {
    prediction_errors_with_rotor_gains(model, data, ids, a, &[])
}

/// [`prediction_errors`] with each flight's command realized through its rotor gains δηⱼ
/// (A diag(1 + δηⱼ) A⁻¹ u, [`rotor_scaling`]; a flight without an entry gets none).
pub fn prediction_errors_with_rotor_gains<M: HamiltonianModel>(
    model: &M,
    data: &Windows,
    ids: &[usize],
    a: Option<&[[f32; FEATURES]]>,
    rotor_gain: &[[f32; 4]],
) -> PredictionErrors {
    let scalings: Vec<nalgebra::Matrix4<f32>> = rotor_gain
        .iter()
        .map(|d| rotor_scaling(&d.map(|x| 1.0 + x)))
        .collect();
    let e = super::predict::rollout_errors(model, data, ids, a, &scalings);
    PredictionErrors {
        pos_m: e.pos_rmse_m,
        rot_rad: e.att_rmse_rad,
        vel_m_s: e.vel_body_rmse_m_s,
        rate_rad_s: e.rate_rmse_rad_s,
    }
}

/// The CF2X's rotor positions (x, y) (m) and reaction-torque signs, rotors 1..4 (docs/design.md,
/// "The vehicle").
const ROTORS: [(f32, f32, f32); 4] = [
    (0.028, -0.028, -1.0),
    (-0.028, -0.028, 1.0),
    (-0.028, 0.028, -1.0),
    (0.028, 0.028, 1.0),
];
/// km / kf (m): reaction torque per newton of thrust.
const KM_OVER_KF_M: f32 = 7.94e-12 / 3.16e-10;

/// The true disturbance wrench at hover (R = I) of a vehicle of mass `true_mass_kg`, in the
/// units of a model of mass `model_mass_kg` (force rows scaled by their ratio): body force m w +
/// Σ ΔFᵢ e₃, torque Σ rᵢ × ΔFᵢ e₃ plus the reaction-torque deficit, with
/// ΔFᵢ = −(1 − δᵢ) m g / 4 at hover thrust.
pub fn true_wrench_at_hover(
    wind_m_s2: &[f32; 3],
    eff: &[f32; 4],
    model_mass_kg: f32,
    true_mass_kg: f32,
) -> [f32; 6] {
    let ratio = model_mass_kg / true_mass_kg;
    let mut f = Vector3::from(*wind_m_s2) * true_mass_kg;
    let mut t = Vector3::zeros();
    for (&(x, y, s), &d) in ROTORS.iter().zip(eff.iter()) {
        let df = -(1.0 - d) * true_mass_kg * GRAVITY_M_S2 / 4.0;
        f.z += df;
        t += Vector3::new(y * df, -x * df, s * KM_OVER_KF_M * df);
    }
    f *= ratio;
    [f.x, f.y, f.z, t.x, t.y, t.z]
}

/// The CF2X mixer A: the wrench [f; τx; τy; τz] (N, N·m) of rotor thrusts T (N) is A T.
pub fn rotor_mixer() -> nalgebra::Matrix4<f32> {
    nalgebra::Matrix4::from_fn(|r, c| {
        let (x, y, s) = ROTORS[c];
        [1.0, y, -x, s * KM_OVER_KF_M][r]
    })
}

/// The realized wrench per commanded wrench of a CF2X whose rotors make `eff` of their nominal
/// thrust: A diag(eff) A⁻¹ (the mixer inverse, the rotors' factors, the mixer).
pub fn rotor_scaling(eff: &[f32; 4]) -> nalgebra::Matrix4<f32> {
    let a = rotor_mixer();
    let a_inv = a.try_inverse().unwrap_or_else(nalgebra::Matrix4::identity);
    a * nalgebra::Matrix4::from_diagonal(&Vector4::from(*eff)) * a_inv
}

/// The rotor maps in the training model's units, in row form (a row x maps to x · M, M stored
/// row-major): u/CONTROL_SCALE → the CF2X's rotor thrusts (A⁻¹ S), and back (S⁻¹ A); S is
/// diag(CONTROL_SCALE). A flight's rotor gains act between them ([`rotor_scaling`]).
pub fn normalized_rotor_maps() -> ([[f32; 4]; 4], [[f32; 4]; 4]) {
    let mixer = rotor_mixer();
    let scale =
        nalgebra::Matrix4::from_diagonal(&Vector4::from(hamflight::model::learned::CONTROL_SCALE));
    let mixer_inv = mixer
        .try_inverse()
        .unwrap_or_else(nalgebra::Matrix4::identity);
    let scale_inv = scale
        .try_inverse()
        .unwrap_or_else(nalgebra::Matrix4::identity);
    let row_form = |m: nalgebra::Matrix4<f32>| -> [[f32; 4]; 4] {
        std::array::from_fn(|i| std::array::from_fn(|j| m[(j, i)]))
    };
    (row_form(mixer_inv * scale), row_form(scale_inv * mixer))
}

/// The true input gain g (R = I) of the CF2X airframe whose rotors make `eff` of their nominal
/// thrust: the realized wrench per unit of commanded wrench (the mixer inverse, the rotors'
/// factors, the mixer), force rows times `model_mass_kg / true_mass_kg`.
pub fn true_gain_of(eff: &[f32; 4], model_mass_kg: f32, true_mass_kg: f32) -> [[f32; 4]; 6] {
    let realized = rotor_scaling(eff);
    let g = true_input_gain();
    let ratio = model_mass_kg / true_mass_kg;
    std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            // Rows 2..5 of g are the identity on [f; τ]: apply the realized map there.
            let v = if r >= 2 {
                realized[(r - 2, c)]
            } else {
                g[(r, c)]
            };
            if r < 3 {
                v * ratio
            } else {
                v
            }
        })
    })
}

/// Builds the report.
pub fn report(
    cfg: &TrainConfig,
    data: &Windows,
    train_ids: &[usize],
    heldout: &[usize],
    trained: &Trained,
) -> TrainReport {
    let learned = LearnedModel::new(trained.weights);
    let nominal = NominalModel::default();
    let hover = State::default();
    let terms = learned.terms(&hover);
    let j = terms
        .inertia_inv
        .try_inverse()
        .unwrap_or_else(nalgebra::Matrix3::zeros);
    let model_mass = terms.mass_kg;
    let true_mass = data.manifest_mass_kg;
    let true_j = data
        .vehicle
        .inertia_kg_m2
        .map(|j| nalgebra::Matrix3::from_diagonal(&Vector3::from(j.map(|x| x as f32))));
    let true_vehicle = true_j.map(|j| NominalModel::new(true_mass, j));
    let rotor_eff = data
        .vehicle
        .rotor_efficiency
        .map_or([1.0; 4], |e| e.map(|x| x as f32));
    let realizations = data
        .realizations
        .iter()
        .zip(trained.a.iter())
        .enumerate()
        .map(|(j, (r, a))| {
            let d = terms.features * nalgebra::SVector::<f32, FEATURES>::from_row_slice(a);
            RealizationReport {
                true_wind_m_s2: r.wind_m_s2,
                true_rotor_efficiency: r.rotor_efficiency,
                disturbance_free: r.disturbance_free,
                a: *a,
                learned_rotor_efficiency: trained.rotor_gain.get(j).map(|d| d.map(|x| 1.0 + x)),
                learned_wrench_at_hover: std::array::from_fn(|k| d[k]),
                true_wrench_at_hover: match (r.wind_m_s2, r.rotor_efficiency) {
                    (Some(w), Some(e)) => Some(true_wrench_at_hover(&w, &e, model_mass, true_mass)),
                    (Some(w), None) => {
                        Some(true_wrench_at_hover(&w, &[1.0; 4], model_mass, true_mass))
                    }
                    (None, Some(e)) => {
                        Some(true_wrench_at_hover(&[0.0; 3], &e, model_mass, true_mass))
                    }
                    (None, None) => None,
                },
            }
        })
        .collect();
    let g = terms.gain;
    TrainReport {
        config: cfg.clone(),
        train_windows: train_ids.len(),
        heldout_windows: heldout.len(),
        initial_val_loss: trained.initial_val_loss,
        final_val_loss: trained.curve.last().map_or(f64::NAN, |e| e.val_loss),
        train_time_s: trained.curve.last().map_or(0.0, |e| e.elapsed_s),
        curve: trained.curve.clone(),
        heldout_learned: prediction_errors(&learned, data, heldout, Some(&trained.a)),
        heldout_learned_rotor_gains: trained.main_stage.as_ref().map(|m| {
            prediction_errors_with_rotor_gains(
                &LearnedModel::new(m.weights),
                data,
                heldout,
                Some(&m.a),
                &trained.rotor_gain,
            )
        }),
        heldout_learned_no_disturbance: prediction_errors(&learned, data, heldout, None),
        heldout_calm: calm_errors(&learned, &nominal, data, heldout),
        heldout_nominal: prediction_errors(&nominal, data, heldout, None),
        heldout_nominal_true_vehicle: true_vehicle
            .map(|m| prediction_errors(&m, data, heldout, None)),
        mass_kg: model_mass,
        true_mass_kg: true_mass,
        motor_tau_s: data.vehicle.motor_tau_s,
        blob_motor_tau_s: hamflight::model::DEFAULT_MOTOR_TAU_S,
        flight_check: None,
        features: FeatureBackoff::default(),
        learned_inertia_hover_kg_m2: std::array::from_fn(|r| std::array::from_fn(|c| j[(r, c)])),
        true_inertia_kg_m2: true_j
            .map(|tj| std::array::from_fn(|r| std::array::from_fn(|c| tj[(r, c)]))),
        learned_gain_hover: std::array::from_fn(|r| std::array::from_fn(|c| g[(r, c)])),
        true_gain: true_gain_of(&rotor_eff, model_mass, true_mass),
        realizations,
    }
}

/// [`TrainReport::heldout_calm`]: the held-out windows of the disturbance-free flights.
fn calm_errors(
    learned: &LearnedModel,
    nominal: &NominalModel,
    data: &Windows,
    heldout: &[usize],
) -> Option<CalmPredictionErrors> {
    let calm: Vec<usize> = heldout
        .iter()
        .copied()
        .filter(|&i| {
            data.windows
                .get(i)
                .and_then(|w| data.realizations.get(w.realization))
                .is_some_and(|r| r.disturbance_free)
        })
        .collect();
    (!calm.is_empty()).then(|| CalmPredictionErrors {
        windows: calm.len(),
        learned: prediction_errors(learned, data, &calm, None),
        nominal: prediction_errors(nominal, data, &calm, None),
    })
}

/// Writes the blob to `out` and the report to `out.json` (appending `.json` to the file name).
///
/// # Errors
/// Any I/O failure.
pub fn write(out: &Path, model: &LearnedModel, report: &TrainReport) -> Result<()> {
    write_atomic(out, &hamflight::blob::encode_model(model))?;
    let mut json_path = out.as_os_str().to_owned();
    json_path.push(".json");
    let json = serde_json::to_vec_pretty(report)?;
    write_atomic(Path::new(&json_path), &json)
}

/// One flight of the check.
#[derive(Clone, Debug, Serialize)]
pub struct CheckFlight {
    /// The check scenario's name ([`crate::pipeline::check::CHECK_SCENARIOS`]).
    pub scenario: String,
    /// `none` (adaptation off), `gradient` or `composite`.
    pub law: String,
    /// RMSE over t ≥ 5 s (m), or `None` if it crashed before.
    pub rmse_m: Option<f64>,
    /// Crash time (s), if any.
    pub crash_s: Option<f64>,
}

/// What the check flew and found; saved in the training report.
#[derive(Clone, Debug, Serialize)]
pub struct FlightCheck {
    /// The check scenarios' description.
    pub scenario: String,
    /// The gradient law on the windy spiral: RMSE over t ≥ 5 s (m), or `None` if it crashed.
    pub adaptive_rmse_m: Option<f64>,
    /// The gradient law on the windy spiral: crash time (s), if any.
    pub adaptive_crash_s: Option<f64>,
    /// Without adaptation on the windy spiral: RMSE over t ≥ 5 s (m).
    pub learned_rmse_m: Option<f64>,
    /// Without adaptation on the windy spiral: crash time (s), if any.
    pub learned_crash_s: Option<f64>,
    /// Every flight: each scenario without adaptation and under both laws.
    pub flights: Vec<CheckFlight>,
    /// Why it failed, or `None` if it passed.
    pub failure: Option<String>,
}

impl FlightCheck {
    /// True if the blob may be written.
    pub fn passed(&self) -> bool {
        self.failure.is_none()
    }

    /// The flight of `law` on `scenario`.
    pub fn flight(&self, scenario: &str, law: &str) -> Option<&CheckFlight> {
        self.flights
            .iter()
            .find(|f| f.scenario == scenario && f.law == law)
    }
}
