//! The flight check against the untrained prior: a blob whose learned terms make it track worse
//! than the prior on the same vehicle, on a plant that is not its model, is refused.
//!
//! Each scenario (a vehicle as its flights show it: the rigid body of its description plus the
//! residual its logs measured, `scenarios/bl-real-*.toml`) is flown under both adaptation laws
//! by the candidate and by the prior (the physical prior's networks, `ModelWeights::prior`,
//! on the candidate's mass, hover inertia and motor lag, with no port terms). The candidate
//! fails if it crashes, or if the prior flew and the candidate's RMSE over t ≥ 5 s is above
//! the prior's.
//!
//! A second kind of scenario only has to be survived: a plant the candidate must fly without a
//! crash under both laws, with no comparison (for example the rigid body of the description,
//! `scenarios/bl-calm-spiral.toml`, the other reading of logs that cannot tell the two apart;
//! the prior is that plant's exact model there, so no learned blob can beat it).

use anyhow::Result;
use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, State};
use hamflight::{AdaptationLaw, Gains};
use serde::Serialize;

use crate::control::adapter::{airframe_of, gains_for, CoreController};
use crate::fly::eval::{self, Report};
use crate::sim::scenario::Scenario;

/// One flight of the check.
#[derive(Clone, Debug, Serialize)]
pub struct PriorFlight {
    /// The scenario's name.
    pub scenario: String,
    /// `gradient` or `composite`.
    pub law: String,
    /// The candidate's RMSE over t ≥ 5 s (m), if it flew that long.
    pub rmse_m: Option<f64>,
    /// When the candidate crashed (s).
    pub crash_s: Option<f64>,
    /// The prior's RMSE (m).
    pub prior_rmse_m: Option<f64>,
    /// When the prior crashed (s).
    pub prior_crash_s: Option<f64>,
    /// Whether the flight was compared with the prior (else it only had to be survived).
    pub against_prior: bool,
}

/// The check's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct PriorCheck {
    /// Every flight.
    pub flights: Vec<PriorFlight>,
    /// The first failure, named; `None` if the candidate passed.
    pub failure: Option<String>,
}

/// The untrained prior on `model`'s vehicle: the physical prior's networks with its mass, hover
/// inertia and motor lag, and no port terms.
pub fn prior_of(model: &LearnedModel) -> LearnedModel {
    let terms = model.terms(&State::default());
    let j = terms
        .inertia_inv
        .try_inverse()
        .map(|j| j.diagonal())
        .unwrap_or_else(|| nalgebra::Vector3::new(1.4e-5, 1.4e-5, 2.17e-5));
    let mut w = ModelWeights::prior_with_inertia(&j);
    w.mass_kg = model.weights.mass_kg;
    LearnedModel::new(w).with_motor_tau_s(model.motor_tau_s())
}

/// Flies `model` and its prior on `scenarios` under both laws.
///
/// # Errors
/// None today (the signature leaves room for a scenario that cannot be flown).
pub fn run(model: &LearnedModel, scenarios: &[Scenario]) -> Result<PriorCheck> {
    run_with_safety(model, scenarios, &[])
}

/// [`run`] on `scenarios`, then `model` alone on `survive` under both laws: there it fails
/// only if it crashes or does not fly 5 s.
///
/// # Errors
/// None today (the signature leaves room for a scenario that cannot be flown).
pub fn run_with_safety(
    model: &LearnedModel,
    scenarios: &[Scenario],
    survive: &[Scenario],
) -> Result<PriorCheck> {
    let prior = prior_of(model);
    let fly = |m: &LearnedModel, sc: &Scenario, law: AdaptationLaw| -> Report {
        let gains = Gains {
            law,
            ..gains_for(m)
        };
        let mut c = CoreController::new("check", *m, gains);
        c.set_airframe(airframe_of(&sc.vehicle));
        Report::from_log(&eval::fly(sc, &mut c), None)
    };
    let mut flights = Vec::new();
    let mut failure = None;
    let flown = scenarios
        .iter()
        .map(|sc| (sc, true))
        .chain(survive.iter().map(|sc| (sc, false)));
    for (sc, against_prior) in flown {
        for (name, law) in [
            ("gradient", AdaptationLaw::Gradient),
            ("composite", AdaptationLaw::Composite),
        ] {
            let a = fly(model, sc, law);
            let p = against_prior.then(|| fly(&prior, sc, law));
            let f = PriorFlight {
                scenario: sc.name.clone(),
                law: name.to_string(),
                rmse_m: a.rmse_pos_window_m,
                crash_s: a.crash_time_s,
                prior_rmse_m: p.as_ref().and_then(|p| p.rmse_pos_window_m),
                prior_crash_s: p.as_ref().and_then(|p| p.crash_time_s),
                against_prior,
            };
            if failure.is_none() {
                failure = verdict(&f);
            }
            flights.push(f);
        }
    }
    Ok(PriorCheck { flights, failure })
}

/// Why flight `f` fails the check, if it does.
fn verdict(f: &PriorFlight) -> Option<String> {
    let cm = |m: f64| format!("{:.3} cm", 100.0 * m);
    let (law, sc) = (&f.law, &f.scenario);
    if let Some(t) = f.crash_s {
        return Some(format!("the {law} law crashed at {t:.2} s on {sc}"));
    }
    match (f.rmse_m, f.prior_rmse_m, f.prior_crash_s) {
        (None, ..) => Some(format!("no RMSE over t ≥ 5 s on {sc} ({law} law)")),
        (Some(a), Some(p), None) if a > p => Some(format!(
            "the {law} law tracks worse than the untrained prior on {sc} ({} against {})",
            cm(a),
            cm(p)
        )),
        _ => None,
    }
}
