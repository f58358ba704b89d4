//! The trainer's flight check (docs/own-vehicle.md): a good blob passes on its vehicle, a blob that
//! would crash the adaptive controller is refused with a reason, and `train` records the check.

use hamflight::model::ModelWeights;
use host_train::control::{load_learned, DEFAULT_WEIGHTS};
use host_train::io::VehicleDescription;
use host_train::pipeline::{
    flight_check_scenario_spec, require_flight_check, run_flight_check,
    FLIGHT_CHECK_ADAPTIVE_MARGIN,
};
use std::path::Path;

fn shipped() -> ModelWeights {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(DEFAULT_WEIGHTS);
    load_learned(&path).expect("shipped weights").weights
}

fn cf2x() -> VehicleDescription {
    VehicleDescription {
        inertia_kg_m2: Some([1.4e-5, 1.4e-5, 2.17e-5]),
        rotor_efficiency: Some([1.0; 4]),
        motor_tau_s: None,
        description: None,
    }
}

#[test]
fn shipped_blob_passes_on_the_stock_vehicle() {
    let c = run_flight_check(&shipped(), 0.027, &cf2x()).expect("check runs");
    println!("{c:?}");
    assert!(c.passed(), "{c:?}");
    // Adaptation must at least halve the error of the blob flown without it (RMSE over t ≥ 5 s).
    let (a, l) = (c.adaptive_rmse_m.unwrap(), c.learned_rmse_m.unwrap());
    assert!(a < 0.5 * l, "adaptive {a} m against {l} m");
}

/// A model whose input gain is `scale` × the trained one: the controller then commands 1/scale
/// of the wrench it needs, whatever the adaptation does.
fn wrong_gain(scale: f32) -> ModelWeights {
    let mut w = shipped();
    let l2 = &mut w.gain.l2;
    for v in l2.weight.iter_mut().flatten().chain(l2.bias.iter_mut()) {
        *v *= scale;
    }
    w
}

#[test]
fn a_blob_that_crashes_is_refused_with_a_reason() {
    for scale in [3.0f32, -1.0] {
        let c = run_flight_check(&wrong_gain(scale), 0.027, &cf2x()).expect("check runs");
        println!("g ×{scale}: {c:?}");
    }
    let w = wrong_gain(SCALE);
    let c = run_flight_check(&w, 0.027, &cf2x()).expect("check runs");
    println!("{c:?}");
    assert!(!c.passed() && c.adaptive_crash_s.is_some(), "{c:?}");
    let err = require_flight_check(&hamflight::model::LearnedModel::new(w), 0.027, &cf2x())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("flight check failed: adaptive (gradient law) crashed at")
            && err.contains("on the windy spiral")
            && err.contains("Nothing was written"),
        "{err}"
    );
    assert!(err.contains("--no-flight-check"), "{err}");
}

const SCALE: f32 = 3.0;

/// Features far from any the rates were tuned for (the wind columns also carrying a large body
/// torque) do not crash the adaptive controller, thanks to the normalized gradient: the check
/// passes them as "not worse than without adaptation".
#[test]
fn torque_coupled_features_fly_no_worse_than_without_adaptation() {
    use hamflight::model::FEATURES;
    let mut w = shipped();
    let l2 = &mut w.disturbance.l2;
    for row in 0..3 {
        for k in 0..FEATURES {
            let (f, t) = (row * FEATURES + k, (row + 3) * FEATURES + k);
            let (wf, bf) = (l2.weight[f], l2.bias[f]);
            for (dst, src) in l2.weight[t].iter_mut().zip(wf.iter()) {
                *dst += 30.0 * src;
            }
            l2.bias[t] += 30.0 * bf;
        }
    }
    let c = run_flight_check(&w, 0.027, &cf2x()).expect("check runs");
    println!("{c:?}");
    // Both laws fly these features no worse than without adaptation (within the check's
    // margin): the gradient law because its rate is normalized by the features' scale, the
    // composite law because its process noise is normalized by the same factor
    // (`Adaptation::feature_normalization`; docs/crazyflie-chain.md, "Per-blob scaling").
    let (g, none) = (
        c.flight("windy spiral", "gradient")
            .expect("gradient flight"),
        c.flight("windy spiral", "none").expect("reference flight"),
    );
    assert!(g.crash_s.is_none(), "{c:?}");
    assert!(
        g.rmse_m.unwrap() <= none.rmse_m.unwrap() + FLIGHT_CHECK_ADAPTIVE_MARGIN,
        "{c:?}"
    );
    let comp = c
        .flight("windy spiral", "composite")
        .expect("composite flight");
    assert!(comp.crash_s.is_none(), "{c:?}");
    assert!(
        comp.rmse_m.unwrap() <= none.rmse_m.unwrap() + FLIGHT_CHECK_ADAPTIVE_MARGIN,
        "{c:?}"
    );
    assert!(c.failure.is_none(), "{c:?}");
}

#[test]
fn the_check_flies_the_described_vehicle() {
    let heavy = VehicleDescription {
        inertia_kg_m2: Some([1.82e-5, 1.82e-5, 2.82e-5]),
        rotor_efficiency: Some([1.0, 1.0, 0.9, 1.0]),
        motor_tau_s: Some(0.02),
        description: None,
    };
    let spec = flight_check_scenario_spec(0.034, &heavy);
    assert_eq!(spec.vehicle.mass_kg, Some(0.034));
    assert_eq!(
        spec.vehicle.inertia_kg_m2,
        Some([1.82e-5, 1.82e-5, 2.82e-5])
    );
    assert_eq!(spec.vehicle.rotor_efficiency, Some([1.0, 1.0, 0.9, 1.0]));
    assert_eq!(spec.effects.motor_tau_s, 0.02);
    // The stock blob on that vehicle still flies (the adaptation absorbs the mass error).
    let c = run_flight_check(&shipped(), 0.034, &heavy).expect("check runs");
    println!("{c:?}");
    assert!(c.adaptive_crash_s.is_none(), "{c:?}");
}

/// Features that vary steeply with attitude along directions of a no flight excited (what
/// flights without a deliberate disturbance teach: the nano-drone benchmark's) fail the check;
/// the trainer's back-off keeps the learned features along the excited direction only, and
/// that blob flies.
#[test]
fn untaught_feature_directions_are_backed_off_to_the_nominal_ones() {
    use hamflight::model::FEATURES;
    use host_train::train::backoff_candidates;
    // The nominal features plus a steep pseudo-random attitude dependence in every column but
    // the z force's (a small LCG: deterministic, no dependencies).
    let mut w = ModelWeights::prior_with_inertia(&nalgebra::Vector3::new(1.4e-5, 1.4e-5, 2.17e-5));
    let mut s = 12_345u32;
    let mut next = move |amp: f32| {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        amp * ((s >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0)
    };
    let d = &mut w.disturbance;
    d.l0.weight
        .iter_mut()
        .flatten()
        .for_each(|v| *v = next(HIDDEN_AMP));
    d.l1.weight
        .iter_mut()
        .flatten()
        .for_each(|v| *v = next(HIDDEN_AMP));
    for (row, weights) in d.l2.weight.iter_mut().enumerate() {
        if row % FEATURES != 2 {
            weights.iter_mut().for_each(|v| *v = next(OUTPUT_AMP));
        }
    }
    let c = run_flight_check(&w, 0.027, &cf2x()).expect("check runs");
    println!("random: {c:?}");
    // The adaptation chases the features' attitude dependence: worse than without, refused.
    assert!(!c.passed(), "{c:?}");
    // The flights' a_j: thrust offsets along z, a little noise elsewhere.
    let a: Vec<[f32; FEATURES]> = (0..8)
        .map(|j| {
            let n = 0.02 * ((j % 3) as f32 - 1.0);
            [n, -n, -0.4 - 0.15 * j as f32, 0.0, n, 0.0]
        })
        .collect();
    let tries = backoff_candidates(&w, &a, true);
    let excited = &tries[1];
    assert_eq!((excited.excited_dims, excited.kept), (1, 1.0));
    let c = run_flight_check(&excited.weights, 0.027, &cf2x()).expect("check runs");
    println!("excited only: {c:?}");
    // Kept along the excited direction only, the features fly.
    assert!(c.passed(), "{c:?}");
}

/// The steepness of the hidden layers and the size of the output layer's attitude dependence.
const HIDDEN_AMP: f32 = 2.0;
const OUTPUT_AMP: f32 = 2.0;

/// `train --flight-survive` with a scenario that does not load fails before training starts
/// (not after minutes of it), names the option and the file, and writes nothing.
#[test]
fn a_missing_survive_scenario_fails_before_training() {
    let dir = std::env::temp_dir().join("hamflight-survive-missing");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("out.hfw");
    let cfg = host_train::train::TrainConfig {
        flight_survive: vec![dir.join("no-such-scenario.toml")],
        ..Default::default()
    };
    let err = host_train::pipeline::run_train(&cfg, &dir.join("no-dataset"), &out, true)
        .expect_err("a missing scenario must fail");
    let msg = format!("{err:#}");
    assert!(
        msg.contains("--flight-survive") && msg.contains("no-such-scenario.toml"),
        "the error names the option and the file: {msg}"
    );
    assert!(!out.exists(), "nothing is written");
}
