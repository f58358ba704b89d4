//! The composite law's prediction term on synthetic data: it converges to the true weights, its
//! gain P stays symmetric, positive definite and bounded in f32, and bad measurements leave the
//! estimate alone.
// The composite law is behind the core's default `composite` feature.
#![cfg(feature = "composite")]

use hamflight::adapt::{Adaptation, CompositeGains, Measurement, PredictionInput, TORQUE_UNIT_NM};
use hamflight::mixer::Wrench;
use hamflight::model::{true_input_gain, HamiltonianModel, NominalModel, State, FEATURES};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

const DT_S: f32 = 0.002;

struct Rig {
    features: SMatrix<f32, 6, FEATURES>,
    gain: SMatrix<f32, 6, 4>,
    inertia: Matrix3<f32>,
    rot: Matrix3<f32>,
}

impl Rig {
    fn new(rot: Matrix3<f32>) -> Self {
        let s = State {
            rot,
            ..State::default()
        };
        let t = NominalModel::default().terms(&s);
        Self {
            features: t.features,
            gain: true_input_gain(),
            inertia: t.inertia_inv.try_inverse().expect("J invertible"),
            rot,
        }
    }

    /// One tick with ω growing at `alpha` (rad/s²) and the accelerometer reading `acc`.
    fn tick(
        &self,
        ad: &mut Adaptation,
        g: &CompositeGains,
        k: usize,
        alpha: Vector3<f32>,
        acc: Vector3<f32>,
    ) {
        self.tick_with(ad, g, k, alpha, acc, &Wrench::default());
    }

    fn tick_with(
        &self,
        ad: &mut Adaptation,
        g: &CompositeGains,
        k: usize,
        alpha: Vector3<f32>,
        acc: Vector3<f32>,
        u: &Wrench,
    ) {
        let v = Vector3::zeros();
        let w = alpha * (k as f32 * DT_S);
        let meas = Measurement {
            acc_body_m_s2: Some(acc),
        };
        let x = PredictionInput {
            features: &self.features,
            gain: &self.gain,
            mass_kg: 0.027,
            gravity_m_s2: 9.8,
            inertia: &self.inertia,
            rot: &self.rot,
            v_body_m_s: &v,
            w_body_rad_s: &w,
            measurement: &meas,
            feature_scale: Adaptation::feature_normalization(&self.features, 0.027),
            port: None,
        };
        ad.predict_step(g, 20.0, &x, DT_S);
        ad.record_input(u);
    }
}

fn assert_spd_bounded(p: &SMatrix<f32, FEATURES, FEATURES>, p_max: f32) {
    assert!(p.iter().all(|x| x.is_finite()), "{p}");
    assert!(
        (p - p.transpose()).norm() <= 1e-6 * p.norm().max(1.0),
        "not symmetric: {p}"
    );
    assert!(
        nalgebra::Cholesky::new(*p).is_some(),
        "not positive definite: {p}"
    );
    for i in 0..FEATURES {
        assert!(
            p[(i, i)] <= p_max * (1.0 + 1e-5),
            "P[{i}{i}] = {} > {p_max}",
            p[(i, i)]
        );
    }
}

#[test]
fn prediction_term_converges_to_the_true_weights() {
    let rig = Rig::new(hamflight::lie::exp(&Vector3::new(0.2, -0.1, 0.7)));
    let g = CompositeGains::default();
    // Wind specific force (world) and an angular acceleration from a body torque.
    let wind = Vector3::new(0.6, -0.4, 0.2);
    let alpha = Vector3::new(50.0, 0.0, 0.0);
    let torque_nm = rig.inertia * alpha;
    let acc = rig.rot.transpose() * wind;
    let mut ad = Adaptation::default();
    for k in 0..1000 {
        rig.tick(&mut ad, &g, k, alpha, acc);
    }
    let mut truth = SVector::<f32, FEATURES>::zeros();
    truth.fixed_rows_mut::<3>(0).copy_from(&wind);
    truth
        .fixed_rows_mut::<3>(3)
        .copy_from(&(torque_nm / TORQUE_UNIT_NM));
    let err = (ad.a - truth).norm() / truth.norm();
    assert!(err < 1e-3, "a = {} vs {truth} ({err})", ad.a);
    assert_spd_bounded(&ad.covariance(), g.p_max);
}

#[test]
fn gain_stays_bounded_without_excitation_and_bad_measurements_are_dropped() {
    let mut rig = Rig::new(Matrix3::identity());
    rig.features = SMatrix::zeros(); // nothing observable: P grows by Q dt per tick
    let g = CompositeGains {
        p_max: 5.0,
        ..CompositeGains::default()
    };
    let mut ad = Adaptation::default();
    for k in 0..20_000 {
        rig.tick(
            &mut ad,
            &g,
            k,
            Vector3::zeros(),
            Vector3::new(1.0, 0.0, 0.0),
        );
    }
    assert_spd_bounded(&ad.covariance(), g.p_max);
    assert!(
        ad.covariance()[(0, 0)] > 4.0,
        "P did not grow to its bound: {}",
        ad.covariance()
    );
    assert_eq!(ad.a, SVector::<f32, FEATURES>::zeros());

    let rig = Rig::new(Matrix3::identity());
    let mut ad = Adaptation::default();
    for k in 0..200 {
        rig.tick(
            &mut ad,
            &g,
            k,
            Vector3::zeros(),
            Vector3::new(0.5, 0.0, 0.0),
        );
    }
    assert!((ad.a.x - 0.5).abs() < 1e-3, "{}", ad.a);
    // A non-finite accelerometer falls back to velocity differences: at rest under the hover
    // thrust they read no disturbance, and the estimate decays towards it, finite throughout.
    let hover = Wrench {
        thrust_n: 0.027 * 9.8,
        torque_nm: Vector3::zeros(),
    };
    let nan = Vector3::new(f32::NAN, 0.0, 0.0);
    rig.tick_with(&mut ad, &g, 200, Vector3::zeros(), nan, &hover);
    for k in 201..1200 {
        rig.tick_with(&mut ad, &g, k, Vector3::zeros(), nan, &hover);
        assert!(ad.a.iter().all(|x| x.is_finite()));
    }
    assert!(ad.a.norm() < 1e-2, "{}", ad.a);
    assert_spd_bounded(&ad.covariance(), g.p_max);
}
