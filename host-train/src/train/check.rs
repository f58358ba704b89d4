//! The flight check before a blob is written (issue 10 item 4): every blob the trainer writes
//! must fly the adaptive controller without crashing.
//!
//! The new model flies, adaptive and without adaptation, a short spiral under a constant wind
//! in the SITL, on the vehicle its dataset describes: the manifest's mass (the model's), and its
//! inertia, rotor efficiencies and motor lag when known (else the CF2X's). The blob passes if
//! neither flight crashes and adaptive is not worse than without adaptation (within
//! [`ADAPTIVE_MARGIN`]). Otherwise `train` writes nothing and says why; `--no-flight-check`
//! skips the check. The core's normalized gradient law already makes the adaptation's rates hold
//! for any scale of learned features; this check is the end-to-end guard on top of it.

use crate::dataset::VehicleDescription;
use crate::eval::{self, Report};
use crate::flight::CoreController;
use crate::scenario::Scenario;
use anyhow::{bail, Result};
use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights};
use hamflight::Gains;
use serde::Serialize;

/// Adaptive may be this much worse than no adaptation (m of RMSE) before the check fails: the
/// two are equal to noise when the model already explains the wind.
pub const ADAPTIVE_MARGIN: f64 = 0.005;

/// What the check flew and found; saved in the training report.
#[derive(Clone, Debug, Serialize)]
pub struct FlightCheck {
    /// The check scenario's description.
    pub scenario: String,
    /// Adaptive: RMSE over t ≥ 5 s (m), or `None` if it crashed before.
    pub adaptive_rmse_m: Option<f64>,
    /// Adaptive: crash time (s), if any.
    pub adaptive_crash_s: Option<f64>,
    /// Without adaptation: RMSE over t ≥ 5 s (m).
    pub learned_rmse_m: Option<f64>,
    /// Without adaptation: crash time (s), if any.
    pub learned_crash_s: Option<f64>,
    /// Why it failed, or `None` if it passed.
    pub failure: Option<String>,
}

impl FlightCheck {
    /// True if the blob may be written.
    pub fn passed(&self) -> bool {
        self.failure.is_none()
    }
}

/// The check scenario's TOML: paper-spiral's path for 8 s under a 0.5 m/s² wind, on the vehicle
/// of mass `mass_kg` that `vehicle` describes.
pub fn scenario_toml(mass_kg: f64, vehicle: &VehicleDescription) -> String {
    let mut s = String::from(
        "name = \"flight-check\"\n\
         description = \"the trainer's flight check: paper-spiral's path, 8 s, wind 0.5 m/s²\"\n\
         duration_s = 8.0\ncontrol_hz = 500.0\nphysics_hz = 1000.0\nseed = 7\nyaw_rad = 0.0\n\
         [trajectory]\nkind = \"spiral\"\ncenter_m = [0.0, 0.0, 0.5]\nradius_m = 0.5\n\
         period_s = 10.0\nclimb_m_s = 0.03\n\
         [disturbance]\nwind_m_s2 = [0.35, 0.35, 0.0]\nonset_s = 0.0\n",
    );
    s.push_str(&format!("[vehicle]\nmass_kg = {mass_kg:?}\n"));
    if let Some(j) = vehicle.inertia_kg_m2 {
        s.push_str(&format!("inertia_kg_m2 = {j:?}\n"));
    }
    if let Some(e) = vehicle.rotor_efficiency {
        s.push_str(&format!("rotor_efficiency = {e:?}\n"));
    }
    if let Some(tau) = vehicle.motor_tau_s.filter(|t| *t > 0.0) {
        s.push_str(&format!("[effects]\nmotor_tau_s = {tau:?}\n"));
    }
    s
}

/// Flies `weights` adaptive and without adaptation on the check scenario, on a vehicle of
/// `mass_kg` (the dataset's, which `--mass-kg` may have overridden for the model) that `vehicle`
/// describes.
///
/// # Errors
/// Only if the check scenario does not build (a vehicle description the plant refuses).
pub fn run(
    weights: &ModelWeights,
    mass_kg: f64,
    vehicle: &VehicleDescription,
) -> Result<FlightCheck> {
    let model = LearnedModel::new(*weights);
    let sc = Scenario::from_toml_str(
        &scenario_toml(mass_kg, vehicle),
        "the trainer's flight check",
        "flight-check",
    )?;
    let fly = |adapt: bool| -> Report {
        let gains = Gains {
            adapt,
            ..Gains::for_mass_kg(model.mass_kg())
        };
        let mut c = CoreController::new("check", model, gains);
        Report::from_log(&eval::fly(&sc, &mut c), None)
    };
    let (a, l) = (fly(true), fly(false));
    let failure = match (a.crash_time_s, l.crash_time_s) {
        (Some(t), _) => Some(format!("adaptive crashed at {t:.2} s")),
        (None, Some(t)) => Some(format!("the model without adaptation crashed at {t:.2} s")),
        (None, None) => match (a.rmse_pos_window_m, l.rmse_pos_window_m) {
            (Some(ra), Some(rl)) if ra > rl + ADAPTIVE_MARGIN => Some(format!(
                "adaptive tracks worse than without adaptation ({:.2} cm against {:.2} cm)",
                100.0 * ra,
                100.0 * rl
            )),
            (Some(_), Some(_)) => None,
            _ => Some("no RMSE over t ≥ 5 s (the flight ended early)".into()),
        },
    };
    Ok(FlightCheck {
        scenario: sc.spec.description.clone().unwrap_or_default(),
        adaptive_rmse_m: a.rmse_pos_window_m,
        adaptive_crash_s: a.crash_time_s,
        learned_rmse_m: l.rmse_pos_window_m,
        learned_crash_s: l.crash_time_s,
        failure,
    })
}

/// [`run`], turned into an error that names what failed and what to try.
///
/// # Errors
/// The check failed, or could not run.
pub fn require(
    weights: &ModelWeights,
    mass_kg: f64,
    vehicle: &VehicleDescription,
) -> Result<FlightCheck> {
    let c = run(weights, mass_kg, vehicle)?;
    if let Some(why) = &c.failure {
        bail!(
            "flight check failed: {why} (SITL, {}, on the dataset's vehicle). Nothing was \
             written. Try more or more varied flights, a larger --feature-decay (e.g. 10), or \
             --no-flight-check to write the blob anyway",
            c.scenario
        );
    }
    Ok(c)
}
