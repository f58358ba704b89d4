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
use crate::sim::scenario::{Scenario, ScenarioSpec, Trajectory, VehicleSpec};
use crate::train::export::{CheckFlight, FlightCheck};
use anyhow::{bail, Context, Result};
use hamflight::model::{LearnedModel, ModelWeights};
use hamflight::{AdaptationLaw, Gains};

/// Adaptive may be this much worse than no adaptation (m of RMSE) before the check fails: the
/// two are equal to noise when the model already explains the wind.
pub const ADAPTIVE_MARGIN: f64 = 0.005;

/// A rotor fault the check adds to the windy spiral.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotorFault {
    /// Each rotor's share of its thrust after the fault.
    pub rotor_efficiency: [f64; 4],
    /// When the fault strikes (s).
    pub onset_s: f64,
}

/// The check's scenarios: (name, the rotor fault added to the windy spiral).
pub const CHECK_SCENARIOS: [(&str, Option<RotorFault>); 2] = [
    ("windy spiral", None),
    (
        "rotor loss",
        Some(RotorFault {
            rotor_efficiency: [1.0, 1.0, 1.0, 0.7],
            onset_s: 3.0,
        }),
    ),
];

/// The check scenario: paper-spiral's path for 8 s under a 0.5 m/s² wind, on the vehicle of
/// mass `mass_kg` that `vehicle` describes.
pub fn scenario_spec(mass_kg: f64, vehicle: &VehicleDescription) -> ScenarioSpec {
    let mut s = ScenarioSpec::new(
        8.0,
        Trajectory::Spiral {
            center_m: [0.0, 0.0, 0.5],
            radius_m: 0.5,
            period_s: 10.0,
            climb_m_s: 0.03,
        },
    );
    s.name = Some("flight-check".into());
    s.description =
        Some("the trainer's flight check: paper-spiral's path, 8 s, wind 0.5 m/s²".into());
    s.seed = 7;
    s.disturbance.wind_m_s2 = [0.35, 0.35, 0.0];
    s.vehicle = VehicleSpec {
        mass_kg: Some(mass_kg),
        inertia_kg_m2: vehicle.inertia_kg_m2,
        rotor_efficiency: vehicle.rotor_efficiency,
        ..VehicleSpec::default()
    };
    if let Some(d) = &vehicle.description {
        s.vehicle.gravity_m_s2 = Some(d.gravity_m_s2);
        s.vehicle.arm_xy_m = Some(d.arm_xy_m);
        s.vehicle.kf_n_per_rad_s2 = Some(d.kf_n_per_rad_s2);
        s.vehicle.km_nm_per_rad_s2 = Some(d.km_nm_per_rad_s2);
        s.vehicle.thrust_to_weight = Some(d.thrust_to_weight * d.mass_kg / mass_kg);
    }
    let tau = vehicle
        .motor_tau_s
        .or(vehicle.description.as_ref().and_then(|d| d.motor_tau_s));
    if let Some(tau) = tau.filter(|t| *t > 0.0) {
        s.effects.motor_tau_s = tau;
    }
    s
}

/// The check scenario with `fault` (a [`CHECK_SCENARIOS`] entry), on the vehicle of mass
/// `mass_kg` that `vehicle` describes.
///
/// # Errors
/// The scenario does not build (a vehicle description the plant refuses).
fn check_scenario(
    mass_kg: f64,
    vehicle: &VehicleDescription,
    fault: Option<RotorFault>,
) -> Result<Scenario> {
    let mut spec = scenario_spec(mass_kg, vehicle);
    if let Some(f) = fault {
        spec.disturbance.rotor_efficiency = f.rotor_efficiency;
        spec.disturbance.onset_s = f.onset_s;
    }
    Scenario::from_spec("flight-check", spec).context("the trainer's flight check")
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
    for (name, fault) in CHECK_SCENARIOS {
        let sc = check_scenario(mass_kg, vehicle, fault)?;
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
