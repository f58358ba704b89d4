//! The flight controller's safety properties on the host: finite output for any finite state,
//! motors off and a fault flag for non-finite input, and the mixer's limits.

use hamflight::mixer::Airframe;
use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, NominalModel};
use hamflight::{FlightController, Gains, RotorCommand, Setpoint, State};
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

fn vec3(scale: f32) -> impl Strategy<Value = Vector3<f32>> {
    prop::array::uniform3(-scale..scale).prop_map(Vector3::from)
}

fn rotation() -> impl Strategy<Value = Matrix3<f32>> {
    vec3(3.2).prop_map(|phi| hamflight::lie::exp(&phi))
}

fn state() -> impl Strategy<Value = State> {
    (vec3(5.0), rotation(), vec3(5.0), vec3(20.0)).prop_map(|(p, r, v, w)| State {
        p_m: p,
        rot: r,
        v_body_m_s: v,
        w_body_rad_s: w,
    })
}

fn setpoint() -> impl Strategy<Value = Setpoint> {
    (
        vec3(5.0),
        vec3(3.0),
        vec3(10.0),
        vec3(30.0),
        -3.2f32..3.2,
        -2.0f32..2.0,
    )
        .prop_map(|(p, v, a, j, yaw, yaw_rate)| Setpoint {
            p_m: p,
            v_m_s: v,
            a_m_s2: a,
            j_m_s3: j,
            yaw_rad: yaw,
            yaw_rate_rad_s: yaw_rate,
        })
}

proptest! {
    #[test]
    fn output_is_finite_and_within_rotor_limits(s in state(), sp in setpoint(), steps in 1usize..20) {
        let mut fc = FlightController::new(NominalModel::default(), Gains::default());
        let max_t = Airframe::default().max_rotor_thrust_n();
        for _ in 0..steps {
            let out = fc.step(&s, &sp, 0.002);
            prop_assert!(!out.faults.is_fault());
            prop_assert!(out.rotors.thrust_n.iter().chain(out.rotors.rpm.iter()).all(|x| x.is_finite()));
            prop_assert!(out.rotors.thrust_n.iter().all(|t| *t >= 0.0 && *t <= max_t * (1.0 + 1e-6)));
            prop_assert!(out.a.iter().all(|x| x.is_finite()));
            prop_assert!(out.a.norm() <= fc.gains.rates.a_max * (1.0 + 1e-5));
        }
    }

    #[test]
    fn learned_model_output_is_finite(s in state(), sp in setpoint()) {
        let model = LearnedModel::new(ModelWeights::prior());
        let mut fc = FlightController::new(model, Gains::default());
        for _ in 0..5 {
            let out = fc.step(&s, &sp, 0.002);
            prop_assert!(!out.faults.is_fault());
            prop_assert!(out.rotors.thrust_n.iter().chain(out.rotors.rpm.iter()).all(|x| x.is_finite()));
            prop_assert!(out.a.iter().all(|x| x.is_finite()));
        }
    }
}

#[test]
fn non_finite_inputs_give_motors_off_and_a_fault() {
    let mut fc = FlightController::new(NominalModel::default(), Gains::default());
    let good = State {
        p_m: Vector3::new(0.0, 0.0, 1.0),
        ..State::default()
    };
    let sp = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut s = good;
        s.rot.m12 = bad;
        let out = fc.step(&s, &sp, 0.002);
        assert!(out.faults.bad_state && out.faults.is_fault());
        assert_eq!(out.rotors, RotorCommand::OFF);

        let mut s = good;
        s.w_body_rad_s.z = bad;
        assert_eq!(fc.step(&s, &sp, 0.002).rotors, RotorCommand::OFF);

        let mut p = sp;
        p.j_m_s3.y = bad;
        let out = fc.step(&good, &p, 0.002);
        assert!(out.faults.bad_setpoint);
        assert_eq!(out.rotors, RotorCommand::OFF);

        let out = fc.step(&good, &sp, bad);
        assert!(out.faults.bad_dt);
        assert_eq!(out.rotors, RotorCommand::OFF);
    }
    for dt in [0.0, -0.002, 0.5] {
        assert!(fc.step(&good, &sp, dt).faults.bad_dt);
    }
    // After the faults, a good input flies again, and the estimate was not corrupted.
    let out = fc.step(&good, &sp, 0.002);
    assert!(!out.faults.is_fault());
    assert!(out.a.iter().all(|x| x.is_finite()));
    let hover = 0.027 * 9.8;
    let total: f32 = out.rotors.thrust_n.iter().sum();
    assert!(
        (total - hover).abs() < 1e-3 * hover,
        "hover thrust {total} vs {hover}"
    );
}

#[test]
fn default_gains_are_pinned() {
    let g = Gains::default();
    assert_eq!((g.k_p, g.k_v), (16.0 * 0.027, 8.0 * 0.027));
    // The attitude loop of `Gains::for_vehicle` for the CF2X (J_x = 1.4e-5 kg·m², 50 ms motor
    // lag compensated to 6 ms, 5 ms of sensor delay): ω_c = 1 / (3 · 11 ms).
    let wc = 1.0 / (3.0 * 0.011f32);
    assert!((g.k_w - 1.4e-5 * wc).abs() < 1e-8, "k_w {}", g.k_w);
    assert!(
        (g.k_r - 1.4e-5 * wc * wc / 3.0).abs() < 1e-7,
        "k_r {}",
        g.k_r
    );
    assert_eq!(
        (g.lag.motor_tau_s, g.lag.target_tau_s),
        (0.05, hamflight::control::LAG_TARGET_S)
    );
    assert_eq!(g.velocity_consistency_tau_s, 0.3);
    let stiff = Gains::for_mass_kg(0.027);
    assert_eq!((stiff.k_r, stiff.k_w), (0.015, 0.002));
    assert_eq!(
        (g.rates.c_p, g.rates.c_v, g.rates.c_r, g.rates.c_w),
        (800.0, 500.0, 16_000.0, 1_600.0)
    );
    assert_eq!(
        (stiff.rates.c_r, stiff.rates.c_w),
        (20_000.0, 2_000.0),
        "the perfect-state rates keep the full torque channel"
    );
    assert!(g.adapt);
    // The composite law is the default where it is compiled in (the default features).
    assert_eq!(g.law, hamflight::AdaptationLaw::Composite);
    assert!(g.rates.drive_max_m.is_infinite() && g.rates.soft_freeze_m.is_infinite());
    assert_eq!(
        (g.rates.saturated_drive_m, g.rates.saturated_drive_rad),
        (0.02, 0.05),
        "saturation bounds the drive, never switches it off"
    );
    let p = Gains::paper();
    assert_eq!(p.law, hamflight::AdaptationLaw::Gradient);
    assert_eq!(
        (p.k_r, p.k_w, p.rates.c_p, p.rates.c_r),
        (1.0, 0.08, 0.04, 0.5)
    );
}

fn hover_pair() -> (State, Setpoint) {
    let s = State {
        p_m: Vector3::new(0.0, 0.0, 1.0),
        ..State::default()
    };
    (s, Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0))
}

fn flies(fc: &mut FlightController<NominalModel>, rot: Matrix3<f32>) -> bool {
    let (mut s, sp) = hover_pair();
    s.rot = rot;
    let out = fc.step(&s, &sp, 0.002);
    if out.faults.bad_state {
        assert!(out.faults.is_fault());
        assert_eq!(out.rotors, RotorCommand::OFF);
    }
    !out.faults.bad_state
}

#[test]
fn near_rotations_fly() {
    let mut fc = FlightController::new(NominalModel::default(), Gains::default());
    let base = hamflight::lie::exp(&Vector3::new(0.3, -0.2, 2.0));
    // Rounding-level perturbations of single entries, and a quaternion normalized to 1e-5.
    for (i, eps) in [(0usize, 1e-5f32), (4, -2e-5), (7, 5e-5), (8, 1e-4)] {
        let mut r = base;
        r[i] += eps;
        assert!(flies(&mut fc, r), "entry {i} off by {eps}: refused");
    }
    let q = nalgebra::Quaternion::new(0.9, 0.1, -0.3, 0.2);
    let q = q / q.norm() * (1.0 + 1e-5);
    let unit = nalgebra::UnitQuaternion::new_unchecked(q);
    assert!(flies(&mut fc, unit.to_rotation_matrix().into_inner()));
    // A full-turn rotation from the core's own exp map.
    assert!(flies(
        &mut fc,
        hamflight::lie::exp(&Vector3::new(3.1, 0.0, 0.0))
    ));
}

#[test]
fn scaled_sheared_and_reflected_matrices_are_bad_states() {
    let mut fc = FlightController::new(NominalModel::default(), Gains::default());
    let base = hamflight::lie::exp(&Vector3::new(0.3, -0.2, 2.0));
    for k in [1.001f32, 0.999, 1.01, 0.5, 2.0, 0.0] {
        assert!(!flies(&mut fc, base * k), "R × {k} accepted");
    }
    for shear in [1e-3f32, 0.01, 0.3] {
        let mut s = Matrix3::identity();
        s.m12 = shear;
        assert!(!flies(&mut fc, base * s), "R sheared by {shear} accepted");
    }
    // Reflections: orthogonal with det −1, which RᵀR = I alone does not catch.
    let mirror = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    for r in [-base, base * mirror, mirror] {
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-5);
        assert!(!flies(&mut fc, r), "reflection accepted: {r}");
    }
    // After all of that, a rotation flies at once and the estimate was not touched.
    assert!(flies(&mut fc, base));
    assert!(fc.estimate().iter().all(|a| a.is_finite()));
}

#[test]
fn rotation_tolerance_is_documented_value() {
    assert_eq!(hamflight::ROTATION_TOLERANCE, 1e-3);
    let mut r = Matrix3::<f32>::identity();
    r.m11 = 1.0 + 0.4e-3; // ‖RᵀR − I‖ ≈ 0.8e-3: inside
    assert!(hamflight::is_rotation(&r));
    r.m11 = 1.0 + 0.6e-3; // ≈ 1.2e-3: outside
    assert!(!hamflight::is_rotation(&r));
}

/// The vehicle's mass is data: a blob's mass sets the hover thrust and the
/// translational gains, for the learned and the nominal model alike.
#[test]
fn the_models_mass_sets_hover_thrust_and_gains() {
    let g_m_s2 = hamflight::model::GRAVITY_M_S2;
    for mass_kg in [0.027f32, 0.034, 0.05] {
        let learned = LearnedModel::new(ModelWeights {
            mass_kg,
            ..ModelWeights::prior()
        });
        let nominal = NominalModel::new(
            mass_kg,
            Matrix3::from_diagonal(&Vector3::new(1.4e-5, 1.4e-5, 2.17e-5)),
        );
        assert_eq!(learned.mass_kg(), mass_kg);
        assert_eq!(nominal.mass_kg(), mass_kg);
        let gains = Gains::for_mass_kg(mass_kg);
        assert!(
            (gains.k_p - 16.0 * mass_kg).abs() < 1e-7 && (gains.k_v - 8.0 * mass_kg).abs() < 1e-7
        );
        let hover = State::default();
        for thrust_n in [
            FlightController::new(learned, gains).step(&hover, &Setpoint::default(), 0.002),
            FlightController::new(nominal, gains).step(&hover, &Setpoint::default(), 0.002),
        ]
        .map(|o| o.wrench.thrust_n)
        {
            let weight_n = mass_kg * g_m_s2;
            assert!(
                (thrust_n - weight_n).abs() < 0.02 * weight_n,
                "{mass_kg} kg: thrust {thrust_n} N against weight {weight_n} N"
            );
        }
    }
    assert_eq!(
        Gains::default(),
        Gains::for_vehicle(&hamflight::VehicleFacts::default())
    );
}

/// `Output::command` is the wrench an outside mixer must be handed: what `rotors` mixes (so the
/// motor-lag lead of `Gains::for_vehicle` is in it), equal to the law's `wrench` in thrust, and
/// different from it in torque while the attitude moves.
#[test]
fn the_command_is_what_the_rotors_mix_and_carries_the_lag_lead() {
    let gains = Gains::default();
    assert!(
        gains.lag.ratio().is_some(),
        "the default gains compensate the motor lag"
    );
    let mut fc = FlightController::new(NominalModel::default(), gains);
    let (s, sp) = hover_pair();
    let airframe = Airframe::default();
    let mut torque_lead_nm = 0.0f32;
    for k in 0..200 {
        // A roll that swings: the law's torque changes every tick, so the lead shows.
        let phi = 0.1 * (k as f32 * 0.05).sin();
        let tilted = State {
            rot: Matrix3::new(
                1.0,
                0.0,
                0.0,
                0.0,
                phi.cos(),
                -phi.sin(),
                0.0,
                phi.sin(),
                phi.cos(),
            ),
            ..s
        };
        let out = fc.step(&tilted, &sp, 0.002);
        assert!(!out.faults.is_fault());
        assert_eq!(out.command.thrust_n, out.wrench.thrust_n);
        let (mixed, _) = airframe.mix(&out.command);
        assert_eq!(
            mixed, out.rotors,
            "tick {k}: rotors are not the command mixed"
        );
        torque_lead_nm = torque_lead_nm.max((out.command.torque_nm - out.wrench.torque_nm).norm());
    }
    assert!(
        torque_lead_nm > 1e-6,
        "the command never differed from the law's wrench: no lead ({torque_lead_nm} N·m)"
    );
}

/// The stock nominal model with J and the torque rows of g and W scaled by `k` per axis: the
/// same vehicle as data would show it (J ω̇ = g_τ u + W a fits as well with all three scaled).
struct SplitModel {
    inner: NominalModel,
    k: Vector3<f32>,
}

impl HamiltonianModel for SplitModel {
    fn terms(&self, state: &State) -> hamflight::model::ModelTerms {
        let mut t = self.inner.terms(state);
        let k_inv = Matrix3::from_diagonal(&self.k.map(|x| 1.0 / x));
        t.inertia_inv = k_inv * t.inertia_inv;
        for (i, ki) in self.k.iter().enumerate() {
            t.gain.row_mut(3 + i).scale_mut(*ki);
            t.features.row_mut(3 + i).scale_mut(*ki);
        }
        t
    }
}

/// The thrusts the controller designed for `model` commands at rest with a small attitude
/// error about every axis, without adaptation (`axis_scale`: keep the design's per-axis factor).
fn split_thrusts<M: HamiltonianModel>(model: M, axis_scale: bool) -> [f32; 4] {
    let mut g = Gains::for_vehicle(&hamflight::VehicleFacts::of(&model));
    g.adapt = false;
    if !axis_scale {
        g.attitude_axis_scale = Vector3::new(1.0, 1.0, 1.0);
    }
    let mut fc = FlightController::new(model, g);
    let (mut s, sp) = hover_pair();
    s.rot = hamflight::lie::exp(&Vector3::new(0.04, -0.03, 0.05));
    let out = fc.step(&s, &sp, 0.002);
    assert!(!out.faults.is_fault(), "{:?}", out.faults);
    out.rotors.thrust_n
}

/// Paper eq. (ida_pbc_control) on a learned model: the attitude loop the vehicle sees does not
/// depend on how the model split its inertia and input gain per axis (k_R,i and k_ω,i scale
/// with J_i, `Gains::attitude_axis_scale`), where one shared k_R sized on J_x would not.
#[test]
fn attitude_loop_is_invariant_to_the_split_of_j_and_g() {
    let k = Vector3::new(0.9, 1.5, 3.0);
    let stock = split_thrusts(NominalModel::default(), true);
    let split = split_thrusts(
        SplitModel {
            inner: NominalModel::default(),
            k,
        },
        true,
    );
    let shared = split_thrusts(
        SplitModel {
            inner: NominalModel::default(),
            k,
        },
        false,
    );
    let diff = |a: &[f32; 4], b: &[f32; 4]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    // The attitude error's share of each rotor's thrust.
    let hover = 0.027 * 9.81 / 4.0;
    let spread = stock
        .iter()
        .map(|t| (t - hover).abs())
        .fold(0.0f32, f32::max);
    assert!(
        spread > 1e-3,
        "the attitude error commands torque: {stock:?}"
    );
    assert!(
        diff(&stock, &split) < 1e-3 * spread.max(1e-3) + 1e-6,
        "per-axis split changed the thrusts: {stock:?} vs {split:?}"
    );
    assert!(
        diff(&stock, &shared) > 0.1 * spread,
        "a shared k_R should not be invariant: {stock:?} vs {shared:?}"
    );
}

/// `Gains::for_vehicle`'s per-axis factors: ones on the stock vehicle and on a uniformly scaled
/// one (whose gains scale through J_x), each axis's J_i over the design axis's otherwise, and
/// the composite observer's torque noise with its square.
#[test]
fn per_axis_factors_follow_the_inertia() {
    use hamflight::VehicleFacts;
    let stock = VehicleFacts::default();
    let ones = Vector3::new(1.0f32, 1.0, 1.0);
    for s in [1.0f32, 1.3, 0.8] {
        let facts = VehicleFacts {
            inertia_kg_m2: stock.inertia_kg_m2 * s,
            ..stock
        };
        let g = Gains::for_vehicle(&facts);
        assert!((g.attitude_axis_scale - ones).amax() < 1e-6, "×{s}");
        assert!(g
            .composite
            .r_torque_axis
            .iter()
            .all(|r| (r - 1.0).abs() < 1e-6));
    }
    assert_eq!(Gains::default().attitude_axis_scale, ones);
    let split = VehicleFacts {
        inertia_kg_m2: stock
            .inertia_kg_m2
            .component_mul(&Vector3::new(0.9, 1.5, 3.0)),
        ..stock
    };
    let g = Gains::for_vehicle(&split);
    let want = Vector3::new(1.0, 1.5 / 0.9, 3.0 / 0.9);
    assert!(
        (g.attitude_axis_scale - want).amax() < 1e-5,
        "{:?}",
        g.attitude_axis_scale
    );
    for (r, w) in g.composite.r_torque_axis.iter().zip(want.iter()) {
        assert!((r - w * w).abs() < 1e-4, "{r} vs {}", w * w);
    }
    // k_R and k_ω themselves are sized on the smaller of J_x and J_y.
    let wc = 1.0 / (3.0 * 0.011f32);
    assert!((g.k_w - 0.9 * 1.4e-5 * wc).abs() < 1e-8, "k_w {}", g.k_w);
    // A non-physical inertia keeps the shared gains.
    let bad = VehicleFacts {
        inertia_kg_m2: Vector3::new(1.4e-5, f32::NAN, 2.0e-5),
        ..stock
    };
    assert_eq!(Gains::for_vehicle(&bad).attitude_axis_scale, ones);
}

/// Altitude first: with a demand far past the tilt limit and the body still turning
/// towards it, the thrust's vertical component is the weight (the law's F_z at zero height
/// error), not the larger one the plain projection F·b₃ gives; a body tilted past a vertical
/// demand keeps the projection.
#[test]
fn the_thrust_keeps_the_vertical_force_while_the_body_lags_the_demand() {
    let gains = Gains {
        shaping_omega_rad_s: 0.0,
        ..Gains::default()
    };
    let weight_n = NominalModel::default().mass_kg() * hamflight::model::GRAVITY_M_S2;
    let pitched = |theta: f32| State {
        p_m: Vector3::new(0.0, 0.0, 1.0),
        // About body y: the body axis b₃ = (sin θ, 0, cos θ) leans towards +x.
        rot: Matrix3::new(
            theta.cos(),
            0.0,
            theta.sin(),
            0.0,
            1.0,
            0.0,
            -theta.sin(),
            0.0,
            theta.cos(),
        ),
        ..State::default()
    };
    for theta in [0.0f32, 0.15, 0.3, 0.5] {
        let mut fc = FlightController::new(NominalModel::default(), gains);
        let far = Setpoint::hover(Vector3::new(0.9, 0.0, 1.0), 0.0);
        let out = fc.step(&pitched(theta), &far, 0.002);
        assert!(
            out.faults.tilt_limited,
            "θ = {theta}: the step is past the limit"
        );
        let up_n = out.wrench.thrust_n * theta.cos();
        assert!(
            (up_n - weight_n).abs() < 1e-3 * weight_n,
            "θ = {theta}: vertical thrust {up_n} N against the weight {weight_n} N"
        );
    }
    // A body tilted past a vertical demand: the projection (less than the weight upwards).
    let mut fc = FlightController::new(NominalModel::default(), gains);
    let theta = 0.3f32;
    let out = fc.step(
        &pitched(theta),
        &Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0),
        0.002,
    );
    assert!(!out.faults.tilt_limited);
    assert!(
        (out.wrench.thrust_n - weight_n * theta.cos()).abs() < 1e-3 * weight_n,
        "{} N",
        out.wrench.thrust_n
    );
}
