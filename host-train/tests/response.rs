//! The measured-input response (`host-train fit-response`, `score --response`): the identity
//! response is the blob's own prediction, the fit recovers a response it did not start from
//! on data made with it, a bad response file is an error that names it, and `train
//! --pin-rigid-body` keeps J and g at the vehicle's prior.
//! `cargo test --release -p host-train --test response`.

mod train_common;

use hamflight::model::{NominalModel, State, FEATURES, MASS_KG};
use host_train::io::VehicleDescription;
use host_train::pipeline::load_response;
use host_train::train::{
    fit_response, model_errors, response_errors, response_rollout, FitConfig, Response,
    TrainConfig, Window, Windows,
};
use nalgebra::{Matrix3, Vector3, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const HZ: f32 = 100.0;
const STEPS: usize = 20;

fn nominal() -> NominalModel {
    NominalModel::new(
        MASS_KG,
        Matrix3::from_diagonal(&Vector3::new(1.4e-5, 1.4e-5, 2.17e-5)),
    )
}

/// A response unlike the identity: weak, lagged torques, rate damping, a velocity moment, a
/// trim torque.
fn truth() -> Response {
    let mut r = Response {
        thrust_gain: 0.95,
        torque_gain: [0.3, 0.4, 0.6],
        torque_lag_s: 0.04,
        thrust_lag_s: 0.03,
        ..Response::identity()
    };
    r.accel_per_velocity[0][0] = -0.5;
    r.accel_per_velocity[1][1] = -0.5;
    r.accel_per_velocity[3][3] = -4.0;
    r.accel_per_velocity[4][4] = -3.0;
    r.accel_per_velocity[5][5] = -6.0;
    r.accel_per_velocity[3][1] = 5.0;
    r.accel_per_velocity[4][0] = -5.0;
    r.accel_bias[3] = 0.4;
    // The attitude loop's pull toward level: ω̇ₓ ← −5 (Rᵀe₃)ᵧ, ω̇ᵧ ← +5 (Rᵀe₃)ₓ.
    r.accel_per_tilt[0][1] = -5.0;
    r.accel_per_tilt[1][0] = 5.0;
    r
}

/// `n` windows of `STEPS` steps flown by the nominal model with `resp` under random wrenches
/// that change every step (as measured rotor speeds do).
fn windows(resp: &Response, n: usize, seed: u64) -> Windows {
    let model = nominal();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dt = 1.0 / HZ;
    let ws = (0..n)
        .map(|_| {
            let s0 = train_common::random_state(&mut rng, 0.3);
            let u: Vec<[f32; 4]> = (0..STEPS)
                .map(|_| {
                    let c: Vector4<f32> = train_common::random_control(&mut rng);
                    let scale = rng.gen_range(2.0..6.0);
                    [c.x, c.y * scale, c.z * scale, c.w * scale]
                })
                .collect();
            let mut states = vec![s0];
            response_rollout(&model, resp, &s0, &u, dt, |_, s| states.push(*s));
            assert_eq!(states.len(), STEPS + 1, "the truth's rollout stays finite");
            Window {
                states,
                u,
                realization: 0,
            }
        })
        .collect();
    Windows {
        windows: ws,
        sample_hz: HZ,
        window_len: STEPS + 1,
        mass_kg: MASS_KG,
        realizations: vec![],
        manifest_mass_kg: MASS_KG,
        vehicle: VehicleDescription::default(),
    }
}

#[test]
fn the_identity_response_is_the_blobs_own_prediction() {
    let data = windows(&truth(), 30, 1);
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let own = model_errors(&nominal(), &data, &ids);
    let with = response_errors(&nominal(), &Response::identity(), &data, &ids);
    assert_eq!(own, with);
    // ... and the truth's response predicts its own data exactly, which the blob alone does not.
    let exact = response_errors(&nominal(), &truth(), &data, &ids);
    let last = |v: &[f64]| *v.last().expect("steps");
    assert!(last(&exact.rate_mae_rad_s) < 1e-4, "{exact:?}");
    assert!(last(&own.rate_mae_rad_s) > 0.1, "{own:?}");
}

#[test]
fn the_fit_recovers_a_response_it_did_not_start_from() {
    let truth = truth();
    let data = windows(&truth, 120, 2);
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let start = Response {
        torque_gain: [0.1; 3],
        torque_lag_s: 0.05,
        ..Response::identity()
    };
    let cfg = FitConfig {
        iterations: 25,
        ..FitConfig::default()
    };
    let mut costs = vec![];
    let (fitted, steps) = fit_response(&nominal(), &data, &ids, &start, &cfg, |s| {
        costs.push(s.cost)
    });
    assert_eq!(costs.len(), steps.len());
    assert!(
        steps.windows(2).all(|w| w[1].cost <= w[0].cost),
        "the cost never rises: {costs:?}"
    );
    let first = steps.first().expect("start").cost;
    let last = steps.last().expect("end").cost;
    assert!(
        last < 1e-2 * first,
        "cost {first} -> {last}: {steps:?} {fitted:?}"
    );
    for a in 0..3 {
        let (got, want) = (fitted.torque_gain[a], truth.torque_gain[a]);
        assert!(
            (got - want).abs() < 0.05 * want,
            "torque gain {a}: {got} vs {want}"
        );
    }
    assert!(
        (fitted.torque_lag_s - truth.torque_lag_s).abs() < 0.005,
        "lag {} vs {}",
        fitted.torque_lag_s,
        truth.torque_lag_s
    );
    assert!((fitted.thrust_gain - truth.thrust_gain).abs() < 0.01);
    for (row, (got, want)) in fitted
        .accel_per_tilt
        .iter()
        .zip(&truth.accel_per_tilt)
        .enumerate()
    {
        for k in 0..2 {
            assert!(
                (got[k] - want[k]).abs() < 0.25,
                "tilt term ({row}, {k}): {} vs {}",
                got[k],
                want[k]
            );
        }
    }
    assert!(
        (fitted.thrust_lag_s - truth.thrust_lag_s).abs() < 0.005,
        "thrust lag {} vs {}",
        fitted.thrust_lag_s,
        truth.thrust_lag_s
    );
    // On fresh windows the fitted response predicts the rates to a fraction of the blob's error.
    let fresh = windows(&truth, 40, 3);
    let fids: Vec<usize> = (0..fresh.windows.len()).collect();
    let blob = response_errors(&nominal(), &Response::identity(), &fresh, &fids);
    let fit = response_errors(&nominal(), &fitted, &fresh, &fids);
    let at = |v: &[f64]| *v.last().expect("steps");
    assert!(
        at(&fit.rate_mae_rad_s) < 0.02 * at(&blob.rate_mae_rad_s),
        "rates {} vs blob {}",
        at(&fit.rate_mae_rad_s),
        at(&blob.rate_mae_rad_s)
    );
}

#[test]
fn a_bad_response_file_is_an_error_that_names_it() {
    let dir = train_common::scratch("response-file");
    let path = dir.join("r.json");
    std::fs::write(&path, "{\"thrust_gain\": 1.0}").expect("write");
    let e = load_response(&path).expect_err("incomplete");
    assert!(format!("{e:#}").contains("r.json"), "{e:#}");
    assert!(format!("{e:#}").contains("fit-response"), "{e:#}");
    // A whole response (bare, or inside fit-response's report) reads back as written.
    let r = truth();
    std::fs::write(&path, serde_json::to_string(&r).expect("json")).expect("write");
    assert_eq!(load_response(&path).expect("bare"), r);
    let wrapped = serde_json::json!({ "response": r, "windows": 3 });
    std::fs::write(&path, wrapped.to_string()).expect("write");
    assert_eq!(load_response(&path).expect("wrapped"), r);
    let missing = load_response(&dir.join("nope.json")).expect_err("missing");
    assert!(format!("{missing:#}").contains("nope.json"));
}

#[test]
fn a_pinned_rigid_body_keeps_j_and_g_at_the_prior() {
    // Data from a vehicle whose torques are much weaker than the prior's: trained freely, J and
    // g move; pinned, they stay the prior's exactly, and W still trains.
    let truth = NominalModel::new(
        MASS_KG,
        Matrix3::from_diagonal(&Vector3::new(4.0e-5, 4.0e-5, 6.0e-5)),
    );
    let a: Vec<[f32; FEATURES]> = vec![[0.0; FEATURES]; 2];
    let dir = train_common::scratch("pin-rigid-body");
    train_common::write_dataset(&dir, &truth, &a, 100, 5);
    let cfg = TrainConfig {
        epochs: 3,
        feature_epochs: 0,
        flight_check: false,
        flight_rotor_gains: false,
        pin_rigid_body: true,
        ..TrainConfig::default()
    };
    let out = dir.join("p.hfw");
    let with_rotor_gains = TrainConfig {
        flight_rotor_gains: true,
        ..cfg.clone()
    };
    let e = host_train::pipeline::run_train(&with_rotor_gains, &dir, &out, true)
        .expect_err("pinned rotation with per-flight rotor gains is refused");
    assert!(
        format!("{e:#}").contains("--no-flight-rotor-gains"),
        "{e:#}"
    );
    assert!(!out.exists(), "nothing written");
    host_train::pipeline::run_train(&cfg, &dir, &out, true).expect("trains");
    let model = host_train::control::load_learned(&out).expect("blob");
    let prior = hamflight::model::ModelWeights::prior();
    for rot in [
        Matrix3::identity(),
        hamflight::lie::exp(&Vector3::new(0.4, -0.3, 1.2)),
    ] {
        let s = State {
            rot,
            ..State::default()
        };
        let g = model.gain(&s.rot);
        let j_inv = model.inertia_inv(&s.rot);
        let prior_model = hamflight::model::LearnedModel::new(prior);
        let (g0, j0) = (prior_model.gain(&s.rot), prior_model.inertia_inv(&s.rot));
        assert!(
            (j_inv - j0).norm() <= 1e-6 * j0.norm(),
            "J⁻¹ {j_inv} vs {j0}"
        );
        assert_eq!(g, g0, "g is the true mixer's");
    }
}
