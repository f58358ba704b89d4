//! The flight check before a blob is written: every blob the trainer writes must fly both
//! adaptation laws without crashing.
//!
//! The new model flies, on the vehicle its dataset describes (the manifest's mass, the model's,
//! and its inertia, rotor efficiencies and motor lag when known, else the CF2X's), two short
//! scenarios in the SITL: a spiral under a constant wind, and the same spiral with one rotor
//! losing 30 % of its thrust mid-flight. On each it flies without adaptation, with the paper's
//! gradient law and with the composite law. The blob passes if no flight crashes and neither
//! law tracks worse than without adaptation (within [`ADAPTIVE_MARGIN`]). Otherwise `train`
//! tries its back-off ([`crate::train::backoff`]: the learned features only along the directions
//! the flights excited, then pulled toward the nominal ones) and writes the first blob that
//! passes; if none does it writes nothing and says which law failed on which scenario;
//! `--no-flight-check` skips the check. The core's normalized gradient law already makes the adaptation's rates hold for any
//! scale of learned features; this check is the end-to-end guard on top of it.

use crate::control::adapter::{airframe_of, gains_for, CoreController};
use crate::fly::eval::{self, Report};
use crate::io::dataset::VehicleDescription;
use crate::sim::scenario::Scenario;
use crate::train::export::{CheckFlight, FlightCheck};
use anyhow::{bail, Result};
use hamflight::model::{LearnedModel, ModelWeights};
use hamflight::{AdaptationLaw, Gains};

/// Adaptive may be this much worse than no adaptation (m of RMSE) before the check fails: the
/// two are equal to noise when the model already explains the wind.
pub const ADAPTIVE_MARGIN: f64 = 0.005;

/// The check's scenarios: (name, what is added to the windy spiral).
pub const CHECK_SCENARIOS: [(&str, &str); 2] = [
    ("windy spiral", ""),
    (
        "rotor loss",
        "rotor_efficiency = [1.0, 1.0, 1.0, 0.7]\nonset_s = 3.0\n",
    ),
];

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
    if let Some(d) = &vehicle.description {
        s.push_str(&format!(
            "gravity_m_s2 = {:?}\narm_xy_m = {:?}\nkf_n_per_rad_s2 = {:?}\n\
             km_nm_per_rad_s2 = {:?}\nthrust_to_weight = {:?}\n",
            d.gravity_m_s2,
            d.arm_xy_m,
            d.kf_n_per_rad_s2,
            d.km_nm_per_rad_s2,
            d.thrust_to_weight * d.mass_kg / mass_kg
        ));
    }
    let tau = vehicle
        .motor_tau_s
        .or(vehicle.description.as_ref().and_then(|d| d.motor_tau_s));
    if let Some(tau) = tau.filter(|t| *t > 0.0) {
        s.push_str(&format!("[effects]\nmotor_tau_s = {tau:?}\n"));
    }
    s
}

/// The check scenario `extra` adds to (a [`CHECK_SCENARIOS`] entry), on the vehicle of mass
/// `mass_kg` that `vehicle` describes.
///
/// # Errors
/// The scenario does not build (a vehicle description the plant refuses).
fn check_scenario(mass_kg: f64, vehicle: &VehicleDescription, extra: &str) -> Result<Scenario> {
    let toml = scenario_toml(mass_kg, vehicle);
    // The fault goes into the `[disturbance]` table in place of its onset at t = 0.
    let toml = if extra.is_empty() {
        toml
    } else {
        toml.replacen("onset_s = 0.0\n", extra, 1)
    };
    Scenario::from_toml_str(&toml, "the trainer's flight check", "flight-check")
}

/// The first failure among `flights` (in [`CHECK_SCENARIOS`] order, the laws in order), named
/// by law and scenario.
fn first_failure(flights: &[CheckFlight]) -> Option<String> {
    let cm = |m: f64| format!("{:.2} cm", 100.0 * m);
    for (k, (name, _)) in CHECK_SCENARIOS.into_iter().enumerate() {
        let of = |law: &str| flights.iter().find(|f| f.scenario == name && f.law == law);
        let laws = [
            ("gradient", of("gradient")?),
            ("composite", of("composite")?),
        ];
        for (law, f) in laws {
            if let Some(t) = f.crash_s {
                return Some(format!(
                    "adaptive ({law} law) crashed at {t:.2} s on the {name}"
                ));
            }
        }
        let none = of("none")?;
        // Without adaptation a rotor loss may bring the vehicle down: that is what the laws are
        // for, so only the windy spiral requires the model itself to fly.
        let baseline = match none.crash_s {
            Some(t) if k == 0 => {
                return Some(format!(
                    "the model without adaptation crashed at {t:.2} s on the {name}"
                ))
            }
            Some(_) => Some(f64::INFINITY),
            None => none.rmse_m,
        };
        for (law, f) in laws {
            match (f.rmse_m, baseline) {
                (Some(ra), Some(rl)) if ra > rl + ADAPTIVE_MARGIN => {
                    return Some(format!(
                        "adaptive ({law} law) tracks worse than without adaptation on the {name} \
                         ({} against {})",
                        cm(ra),
                        cm(rl)
                    ))
                }
                (Some(_), Some(_)) => {}
                _ => {
                    return Some(format!(
                        "no RMSE over t ≥ 5 s on the {name} (the flight ended early)"
                    ))
                }
            }
        }
    }
    None
}

/// Flies `weights` on the check scenarios ([`CHECK_SCENARIOS`]), without adaptation and under
/// both laws, with the gains of the vehicle the blob describes, on a vehicle of `mass_kg` (the
/// dataset's, which `--mass-kg` may have overridden for the model) that `vehicle` describes.
///
/// # Errors
/// Only if a check scenario does not build (a vehicle description the plant refuses).
pub fn run(
    weights: &ModelWeights,
    mass_kg: f64,
    vehicle: &VehicleDescription,
) -> Result<FlightCheck> {
    run_model(&LearnedModel::new(*weights), mass_kg, vehicle)
}

/// [`run`] for a whole model (its networks and its motor lag).
///
/// # Errors
/// As [`run`].
pub fn run_model(
    model: &LearnedModel,
    mass_kg: f64,
    vehicle: &VehicleDescription,
) -> Result<FlightCheck> {
    let model = *model;
    let base = gains_for(&model);
    let mut flights = Vec::new();
    let mut description = String::new();
    for (name, extra) in CHECK_SCENARIOS {
        let sc = check_scenario(mass_kg, vehicle, extra)?;
        if description.is_empty() {
            description = sc.spec.description.clone().unwrap_or_default();
        }
        let laws: [(&str, Gains); 3] = [
            (
                "none",
                Gains {
                    adapt: false,
                    ..base
                },
            ),
            (
                "gradient",
                Gains {
                    law: AdaptationLaw::Gradient,
                    ..base
                },
            ),
            (
                "composite",
                Gains {
                    law: AdaptationLaw::Composite,
                    ..base
                },
            ),
        ];
        for (law, gains) in laws {
            let mut c = CoreController::new("check", model, gains);
            if vehicle.description.is_some() {
                // The mixer of the described airframe, as the vehicle's own firmware has it.
                c.set_airframe(airframe_of(&sc.vehicle));
            }
            let r = Report::from_log(&eval::fly(&sc, &mut c), None);
            flights.push(CheckFlight {
                scenario: name.to_string(),
                law: law.to_string(),
                rmse_m: r.rmse_pos_window_m,
                crash_s: r.crash_time_s,
            });
        }
    }
    let failure = first_failure(&flights);
    let of = |law: &str| {
        flights
            .iter()
            .find(|f| f.scenario == CHECK_SCENARIOS[0].0 && f.law == law)
            .cloned()
    };
    let (a, l) = (of("gradient"), of("none"));
    Ok(FlightCheck {
        scenario: format!("{description}; and with rotor 4 at 70 % from t = 3 s"),
        adaptive_rmse_m: a.as_ref().and_then(|f| f.rmse_m),
        adaptive_crash_s: a.as_ref().and_then(|f| f.crash_s),
        learned_rmse_m: l.as_ref().and_then(|f| f.rmse_m),
        learned_crash_s: l.as_ref().and_then(|f| f.crash_s),
        flights,
        failure,
    })
}

/// [`run`], turned into an error that names what failed and what to try.
///
/// # Errors
/// The check failed, or could not run.
pub fn require(
    model: &LearnedModel,
    mass_kg: f64,
    vehicle: &VehicleDescription,
) -> Result<FlightCheck> {
    let c = run_model(model, mass_kg, vehicle)?;
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
