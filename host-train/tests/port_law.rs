//! The law flies what the model learned: on a plant whose rotors act weakly and late, with drag,
//! rate damping and a pull toward level (the kind of vehicle the nano-drone benchmark's flights
//! show, `scenarios/bl-real-*.toml`), a blob that carries those port terms tracks the spiral at
//! least 5× better than the untrained prior under both laws, and never crashes (the benchmark
//! vehicle's figures: docs/benchmark.md, "The flight check flies a plant that is not the
//! model"). The plant's residual is
//! linear in the tilt where the model's potential is not, and it acts on rotor speeds behind a
//! motor lag: the plant is not the model.

use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, PortTerms};
use hamflight::{AdaptationLaw, Gains};
use host_train::control::{airframe_of, gains_for, CoreController};
use host_train::fly::{fly_scenario, Report};
use host_train::pipeline::{prior_of, run_prior_check, run_safety_check};
use host_train::Scenario;
use nalgebra::Vector3;

const J: [f32; 3] = [2.3951e-5, 2.3951e-5, 3.2347e-5];
const MASS: f32 = 0.045;

/// The port terms of the vehicle, and the plant residual that says the same in the plant's
/// terms (accelerations).
fn vehicle() -> (PortTerms, String) {
    let gain = [0.3f32, 0.25, 0.5];
    let (torque_lag, thrust_lag) = (0.04f32, 0.02f32);
    let drag = [0.6f32, 0.6, 0.9];
    let damping = [4.0f32, 4.0, 6.0];
    let (k11, k22) = (5.0f32, 5.0f32);
    let mut p = PortTerms::IDENTITY;
    p.torque_gain_offset = gain.map(|k| k - 1.0);
    p.torque_lag_s = torque_lag;
    p.thrust_lag_s = thrust_lag;
    p.drag_n_s_m = drag.map(|d| d * MASS);
    p.rate_damping_nm_s = [damping[0] * J[0], damping[1] * J[1], damping[2] * J[2]];
    let jt = 0.5 * (J[0] + J[1]);
    p.tilt_stiffness_nm = [k11 * jt, k22 * jt, 0.0, 0.0, 0.0, 0.0];
    // Near level the potential's torque is τx = −k₂₂ b_y, τy = k₁₁ b_x (b = Rᵀe₃).
    let z = "0.0";
    let diag = |i: usize, d: f32| {
        let mut row = [
            z.to_string(),
            z.into(),
            z.into(),
            z.into(),
            z.into(),
            z.into(),
        ];
        row[i] = format!("{d:?}");
        format!("[{}]", row.join(", "))
    };
    let rows: Vec<String> = (0..3)
        .map(|i| diag(i, -drag[i]))
        .chain((0..3).map(|i| diag(i + 3, -damping[i])))
        .collect();
    let residual = format!(
        "[effects.residual]\nthrust_gain = 1.0\nthrust_lag_s = {thrust_lag:?}\n\
         torque_gain = {gain:?}\ntorque_lag_s = {torque_lag:?}\n\
         accel_per_velocity = [{}]\n\
         accel_bias = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n\
         accel_per_tilt = [[0.0, {:?}], [{:?}, 0.0], [0.0, 0.0]]\n",
        rows.join(", "),
        -k22,
        k11,
    );
    (p, residual)
}

fn scenario(kind: &str, residual: &str) -> Scenario {
    let traj = "[trajectory]\nkind = \"spiral\"\ncenter_m = [0.0, 0.0, 0.5]\nradius_m = 0.5\n\
                period_s = 10.0\nclimb_m_s = 0.03\n";
    let toml = format!(
        "name = \"port-law-{kind}\"\nduration_s = 12.0\ncontrol_hz = 500.0\nphysics_hz = 1000.0\n\
         seed = 0\nyaw_rad = 0.0\n{traj}\
         [vehicle]\nmass_kg = {MASS}\ninertia_kg_m2 = {J:?}\narm_xy_m = 0.0353\n\
         kf_n_per_rad_s2 = 3.7178e-8\nkm_nm_per_rad_s2 = 7.728e-11\nthrust_to_weight = 2.04\n\
         [effects]\nmotor_tau_s = 0.0325\n{residual}"
    );
    Scenario::from_toml_str(&toml, "port_law test", "port-law").expect("the test scenario builds")
}

fn model(port: PortTerms) -> LearnedModel {
    let mut w = ModelWeights::prior_with_inertia(&Vector3::from(J));
    w.mass_kg = MASS;
    LearnedModel::new(w)
        .with_motor_tau_s(0.0325)
        .with_port(port)
}

#[test]
fn the_law_flies_the_learned_port_terms_where_the_prior_cannot() {
    let (port, residual) = vehicle();
    assert_eq!(port.validate(), Ok(()));
    let learned = model(port);
    let prior = prior_of(&learned);
    assert!(prior.port().is_identity());
    let kind = "spiral";
    {
        let sc = scenario(kind, &residual);
        for law in [AdaptationLaw::Gradient, AdaptationLaw::Composite] {
            let fly = |m: &LearnedModel| {
                let gains = Gains {
                    law,
                    ..gains_for(m)
                };
                let mut c = CoreController::new("test", *m, gains);
                c.set_airframe(airframe_of(&sc.vehicle));
                Report::from_log(&fly_scenario(&sc, &mut c), None)
            };
            let (a, p) = (fly(&learned), fly(&prior));
            assert_eq!(
                a.crash_time_s, None,
                "{kind}, {law:?}: the learned model crashed"
            );
            let ra = a.rmse_pos_window_m.expect("an RMSE over t ≥ 5 s");
            match (p.crash_time_s, p.rmse_pos_window_m) {
                (Some(_), _) => {}
                (None, Some(rp)) => assert!(
                    ra <= 0.2 * rp,
                    "{kind}, {law:?}: learned {ra:.5} m against the prior's {rp:.5} m"
                ),
                (None, None) => panic!("{kind}, {law:?}: the prior's flight has no RMSE"),
            }
        }
    }
    // The check that `fit-port --flight-check` runs agrees: the learned blob passes.
    let sc = scenario("spiral", &residual);
    let check = run_prior_check(&learned, &[sc]).expect("the check runs");
    assert_eq!(check.failure, None, "{:?}", check.flights);
}

/// The same check refuses a blob whose port terms are wrong for the plant (torques ten times
/// weaker than the plant's, so the law asks for ten times too much): it names the law and the
/// scenario.
#[test]
fn the_check_refuses_port_terms_that_fly_worse_than_the_prior() {
    let (_, residual) = vehicle();
    let mut wrong = PortTerms::IDENTITY;
    wrong.torque_gain_offset = [-0.97, -0.975, -0.95];
    wrong.torque_lag_s = 0.04;
    let sc = scenario("spiral", &residual);
    let check = run_prior_check(&model(wrong), &[sc]).expect("the check runs");
    let why = check.failure.expect("the wrong blob is refused");
    assert!(
        why.contains("law") && why.contains("port-law-spiral"),
        "{why}"
    );
}

/// A plant the blob only has to survive (`fit-port --flight-survive`): the rigid body, where
/// torques ten times too weak in the model make the law ask ten times too much, is lost and
/// the check says so; the rigid body's own model survives it, and is compared with no prior.
#[test]
fn the_survival_check_refuses_a_blob_that_loses_the_rigid_vehicle() {
    let rigid = scenario("rigid", "");
    let mut wrong = PortTerms::IDENTITY;
    wrong.torque_gain_offset = [-0.9, -0.9, -0.9];
    wrong.torque_lag_s = 0.04;
    let check =
        run_safety_check(&model(wrong), &[], std::slice::from_ref(&rigid)).expect("the check runs");
    let why = check
        .failure
        .expect("the blob that loses the rigid vehicle is refused");
    assert!(
        why.contains("crashed") && why.contains("port-law-rigid"),
        "{why}"
    );
    let check =
        run_safety_check(&model(PortTerms::IDENTITY), &[], &[rigid]).expect("the check runs");
    assert_eq!(check.failure, None, "{:?}", check.flights);
    assert_eq!(check.flights.len(), 2, "both laws flown");
    for f in &check.flights {
        assert!(!f.against_prior && f.prior_rmse_m.is_none() && f.prior_crash_s.is_none());
        assert!(f.rmse_m.is_some(), "{f:?}");
    }
}
