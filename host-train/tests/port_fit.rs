//! A synthetic vehicle with known port terms (drag, rate damping, the flapping gyrator, a tilt
//! torque from a potential, weak torques through a lag) is recovered by `fit-port`'s fit within
//! 10 % per term, and the fitted blob's port terms round-trip through the blob.

use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, State};
use host_train::train::{
    default_port_start, fit_port, port_report, response_rollout, PortFitConfig, RealizationInfo,
    Response, Scaling, Window, Windows, PORT_FIT_PARAMS,
};
use nalgebra::Vector3;

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

/// The scaled truth (fit parameter order: k_f, k_τ ×3, T_f, T_τ, drag /s ×3, damping /s ×3,
/// gyrator J⁻¹B ×9, K/J ×6).
fn truth_params() -> Vec<f64> {
    let mut p = vec![0.0; PORT_FIT_PARAMS];
    p[0] = 1.0;
    p[1..4].copy_from_slice(&[0.5, 0.4, 0.8]);
    p[4] = 0.02;
    p[5] = 0.04;
    p[6..9].copy_from_slice(&[0.6, 0.6, 0.9]);
    p[9..12].copy_from_slice(&[4.0, 4.5, 6.0]);
    p[13] = 5.0; // roll acceleration per v_y
    p[15] = -4.0; // pitch acceleration per v_x
    p[21] = 5.0; // k11: pitch pulled level
    p[22] = 4.0; // k22: roll pulled level
    p
}

fn base_model() -> LearnedModel {
    let mut w = ModelWeights::prior_with_inertia(&Vector3::new(2.3951e-5, 2.3951e-5, 3.2347e-5));
    w.mass_kg = 0.045;
    LearnedModel::new(w)
}

/// Windows of the truth flown from random states under random piecewise-constant wrenches.
fn synthetic(truth: &LearnedModel, n: usize, seed: u64) -> Windows {
    let mut rng = Rng(seed);
    let (hz, len) = (100.0f32, 51usize);
    let hover = 0.045 * 9.8;
    let mut windows = Vec::with_capacity(n);
    for _ in 0..n {
        let s0 = State {
            rot: hamflight::lie::exp(&Vector3::new(
                0.3 * rng.unit(),
                0.3 * rng.unit(),
                rng.unit(),
            )),
            v_body_m_s: Vector3::new(rng.unit(), rng.unit(), 0.5 * rng.unit()),
            w_body_rad_s: Vector3::new(rng.unit(), rng.unit(), 0.5 * rng.unit()),
            ..State::default()
        };
        let mut u = Vec::with_capacity(len - 1);
        let mut held = [0.0f32; 4];
        for k in 0..len - 1 {
            if k % 8 == 0 {
                held = [
                    hover * (1.0 + 0.2 * rng.unit()),
                    4e-5 * rng.unit(),
                    4e-5 * rng.unit(),
                    2e-5 * rng.unit(),
                ];
            }
            u.push(held);
        }
        let mut states = vec![s0];
        response_rollout(truth, &Response::identity(), &s0, &u, 1.0 / hz, |_, s| {
            states.push(*s)
        });
        assert_eq!(states.len(), len, "the truth's rollout stays finite");
        windows.push(Window {
            states,
            u,
            realization: 0,
        });
    }
    Windows {
        windows,
        sample_hz: hz,
        window_len: len,
        mass_kg: 0.045,
        realizations: vec![RealizationInfo {
            file: "synthetic.csv".into(),
            wind_m_s2: None,
            rotor_efficiency: None,
            disturbance_free: false,
            windows: n,
            source_file: None,
        }],
        manifest_mass_kg: 0.045,
        vehicle: Default::default(),
    }
}

/// Each named scaled parameter `i` of the fit within 10 % of the truth's.
fn assert_within_ten_percent(p_true: &[f64], p_fit: &[f64], terms: &[(&str, usize)]) {
    for &(name, i) in terms {
        let (t, f) = (p_true[i], p_fit[i]);
        assert!(
            (f - t).abs() <= 0.1 * t.abs(),
            "{name}: fitted {f:.4}, true {t:.4}"
        );
    }
}

#[test]
fn a_known_vehicle_is_recovered_within_ten_percent_per_term() {
    let base = base_model();
    let scaling = Scaling::of(&base);
    let p_true = truth_params();
    let truth = base.with_port(scaling.to_port(&p_true));
    assert_eq!(truth.port().validate(), Ok(()));
    let data = synthetic(&truth, 120, 7);
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let cfg = PortFitConfig {
        iterations: 30,
        ..PortFitConfig::default()
    };
    let (fitted, steps) = fit_port(
        &base,
        &data,
        &ids,
        &default_port_start(&cfg.structure),
        &cfg,
        |_| {},
    );
    let first = steps.first().map(|s| s.cost).unwrap_or(f64::NAN);
    let last = steps.last().map(|s| s.cost).unwrap_or(f64::NAN);
    assert!(
        last < 0.05 * first,
        "the fit converged: cost {first} -> {last}"
    );
    let p_fit = scaling.to_params(fitted.port());
    let names = [
        "thrust gain",
        "roll torque gain",
        "pitch torque gain",
        "yaw torque gain",
        "thrust lag",
        "torque lag",
        "drag x",
        "drag y",
        "drag z",
        "roll damping",
        "pitch damping",
        "yaw damping",
    ];
    let mut checked = Vec::new();
    for (i, name) in names.iter().enumerate() {
        checked.push((*name, i));
    }
    checked.extend([
        ("flapping roll per v_y", 13),
        ("flapping pitch per v_x", 15),
    ]);
    checked.extend([("tilt k11", 21), ("tilt k22", 22)]);
    assert_within_ten_percent(&p_true, &p_fit, &checked);
    // The terms the truth does not have stay small against the ones it has.
    for i in [12, 14, 16, 17, 18, 19, 20, 24, 25, 26] {
        assert!(p_fit[i].abs() < 0.5, "parameter {i}: {}", p_fit[i]);
    }
    // The fitted model round-trips through a blob.
    let bytes = hamflight::blob::encode_model(&fitted);
    assert_eq!(LearnedModel::from_blob(&bytes), Ok(fitted));
    // And the report reads the same numbers back per axis.
    let r = port_report(&fitted);
    assert!((r.torque_lag_s - 0.04).abs() < 0.004, "{}", r.torque_lag_s);
    assert!((r.drag_per_s[2] - 0.9).abs() < 0.09, "{:?}", r.drag_per_s);
}

#[test]
fn pinned_torque_gains_stay_at_the_description_and_the_rest_is_recovered() {
    let base = base_model();
    let scaling = Scaling::of(&base);
    let mut p_true = truth_params();
    p_true[1..4].copy_from_slice(&[1.0, 1.0, 1.0]);
    let truth = base.with_port(scaling.to_port(&p_true));
    let data = synthetic(&truth, 80, 11);
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let mut cfg = PortFitConfig {
        iterations: 30,
        ..PortFitConfig::default()
    };
    cfg.structure.torque_gains = false;
    let start = default_port_start(&cfg.structure);
    assert_eq!(
        start.torque_gain_offset, [0.0; 3],
        "pinned gains start at 1"
    );
    let (fitted, _) = fit_port(&base, &data, &ids, &start, &cfg, |_| {});
    let p_fit = scaling.to_params(fitted.port());
    for (i, k) in p_fit.iter().enumerate().take(4).skip(1) {
        assert_eq!(*k, 1.0, "torque gain {i} moved: {k}");
    }
    assert_within_ten_percent(
        &p_true,
        &p_fit,
        &[
            ("torque lag", 5),
            ("roll damping", 9),
            ("flapping roll per v_y", 13),
            ("tilt k11", 21),
        ],
    );
}

#[test]
fn the_torque_gain_prior_pulls_toward_the_description_in_proportion_to_its_weight() {
    let base = base_model();
    let scaling = Scaling::of(&base);
    let p_true = truth_params();
    let truth = base.with_port(scaling.to_port(&p_true));
    let data = synthetic(&truth, 60, 13);
    let ids: Vec<usize> = (0..data.windows.len()).collect();
    let gains = |weight: f64| -> Vec<f64> {
        let cfg = PortFitConfig {
            iterations: 30,
            torque_gain_prior: weight,
            ..PortFitConfig::default()
        };
        let start = default_port_start(&cfg.structure);
        let (fitted, _) = fit_port(&base, &data, &ids, &start, &cfg, |_| {});
        scaling.to_params(fitted.port())[1..4].to_vec()
    };
    // A weight far below the data's pull leaves the gains where the data put them.
    let weak = gains(1e-4);
    for (k, t) in weak.iter().zip(&p_true[1..4]) {
        assert!(
            (k - t).abs() <= 0.1 * t,
            "weak prior: gain {k:.3}, true {t:.3}"
        );
    }
    // A weight far above it holds them at the description's 1.
    let strong = gains(100.0);
    for k in &strong {
        assert!((k - 1.0).abs() < 0.05, "strong prior: gain {k:.3}");
    }
    // In between, every gain sits between the two.
    let mid = gains(0.05);
    for ((m, w), s) in mid.iter().zip(&weak).zip(&strong) {
        assert!(m > w && m < s, "gain {m:.3} not between {w:.3} and {s:.3}");
    }
}

#[test]
fn a_pinned_torque_lag_stays_at_zero_and_a_lagged_truth_is_then_missed() {
    let base = base_model();
    let scaling = Scaling::of(&base);
    let mut p_true = truth_params();
    p_true[1..4].copy_from_slice(&[1.0, 1.0, 1.0]);
    // A vehicle whose torques act without a lag behind the rotors: pinning the lag costs nothing.
    p_true[5] = 0.0;
    let fit = |truth_params: &[f64], seed: u64| {
        let truth = base.with_port(scaling.to_port(truth_params));
        let data = synthetic(&truth, 80, seed);
        let ids: Vec<usize> = (0..data.windows.len()).collect();
        let mut cfg = PortFitConfig {
            iterations: 30,
            ..PortFitConfig::default()
        };
        cfg.structure.torque_gains = false;
        cfg.structure.torque_lag = false;
        let start = default_port_start(&cfg.structure);
        assert_eq!(start.torque_lag_s, 0.0, "a pinned lag starts at zero");
        let (fitted, steps) = fit_port(&base, &data, &ids, &start, &cfg, |_| {});
        (scaling.to_params(fitted.port()), steps)
    };
    let (p_fit, steps) = fit(&p_true, 17);
    assert_eq!(p_fit[5], 0.0, "the torque lag moved: {}", p_fit[5]);
    assert_within_ten_percent(
        &p_true,
        &p_fit,
        &[
            ("roll damping", 9),
            ("flapping roll per v_y", 13),
            ("tilt k11", 21),
        ],
    );
    let cost_unlagged = steps.last().map(|s| s.cost).unwrap_or(f64::NAN);
    // On a vehicle that does lag its torques, the pinned fit cannot follow: its cost stays
    // higher (the structure is a choice the training flights must make, not a free lunch).
    let mut lagged = p_true.clone();
    lagged[5] = 0.04;
    let (p_lag, steps_lag) = fit(&lagged, 17);
    assert_eq!(p_lag[5], 0.0);
    let cost_lagged = steps_lag.last().map(|s| s.cost).unwrap_or(f64::NAN);
    assert!(
        cost_lagged > 2.0 * cost_unlagged,
        "pinned lag on a lagged truth: cost {cost_lagged} against {cost_unlagged}"
    );
}
