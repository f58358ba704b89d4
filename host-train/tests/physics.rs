//! Physics checks of the SITL plant against closed forms.

use host_train::sim::{rot_from_rpy, Disturbance, Effects, Plant, PlantState, VehicleParams};
use nalgebra::{Matrix3, Vector3};

const DT: f64 = 1e-3;

#[test]
fn hover_rpm_holds_position() {
    let p0 = Vector3::new(0.1, -0.2, 1.0);
    let mut plant = Plant::nominal(PlantState::at_rest(p0, 0.3));
    let h = plant.params.hover_rpm();
    assert!((h - 14468.0).abs() < 5.0, "hover rpm {h}");
    for _ in 0..10_000 {
        plant.step([h; 4], DT);
    }
    let drift = (plant.state().p_m - p0).norm();
    assert!(drift < 1e-3, "drift {drift} m over 10 s");
}

#[test]
fn free_fall_matches_half_g_t_squared() {
    let mut plant = Plant::nominal(PlantState::at_rest(Vector3::new(0.0, 0.0, 50.0), 0.0));
    let t = 2.0;
    for _ in 0..2000 {
        plant.step([0.0; 4], DT);
    }
    let z = plant.state().p_m.z;
    let expect = 50.0 - 0.5 * 9.8 * t * t;
    assert!((z - expect).abs() < 1e-9, "z {z} vs {expect}");
    let vz = plant.state().v_world_m_s().z;
    assert!((vz + 9.8 * t).abs() < 1e-9);
}

fn torque_free(inertia: [f64; 3]) {
    let params = VehicleParams {
        gravity_m_s2: 0.0,
        inertia_kg_m2: inertia,
        ..VehicleParams::cf2x()
    };
    let s0 = PlantState {
        p_m: Vector3::zeros(),
        rot: rot_from_rpy(Vector3::new(0.3, -0.2, 1.0)),
        v_body_m_s: Vector3::new(0.1, 0.2, -0.3),
        w_body_rad_s: Vector3::new(3.0, -2.0, 5.0),
    };
    let mut plant = Plant::new(
        params.clone(),
        Disturbance::default(),
        Effects::default(),
        s0,
    );
    let l0 = s0.angular_momentum_world(&params);
    let e0 = s0.kinetic_energy(&params);
    for _ in 0..10_000 {
        plant.step([0.0; 4], DT);
    }
    let s = plant.state();
    let dl = (s.angular_momentum_world(&params) - l0).norm() / l0.norm();
    let de = (s.kinetic_energy(&params) - e0).abs() / e0;
    assert!(dl < 1e-6, "angular momentum drift {dl}");
    assert!(de < 1e-6, "kinetic energy drift {de}");
    // Free linear motion: straight line at constant world velocity.
    let v_w = s0.v_world_m_s();
    assert!((s.p_m - v_w * 10.0).norm() < 1e-9);
}

#[test]
fn spinning_body_conserves_momentum_and_energy() {
    torque_free(VehicleParams::cf2x().inertia_kg_m2);
}

#[test]
fn tumbling_asymmetric_body_conserves_momentum_and_energy() {
    torque_free([1.4e-5, 1.9e-5, 2.6e-5]);
}

#[test]
fn rotation_stays_orthonormal() {
    let params = VehicleParams {
        gravity_m_s2: 0.0,
        inertia_kg_m2: [1.4e-5, 1.9e-5, 2.6e-5],
        ..VehicleParams::cf2x()
    };
    let s0 = PlantState {
        w_body_rad_s: Vector3::new(7.0, -11.0, 13.0),
        ..PlantState::default()
    };
    let mut plant = Plant::new(params, Disturbance::default(), Effects::default(), s0);
    for _ in 0..100_000 {
        plant.step([0.0; 4], DT);
    }
    let r = plant.state().rot;
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    assert!(err < 1e-9, "‖RᵀR − I‖max = {err}");
    assert!((r.determinant() - 1.0).abs() < 1e-9);
}

#[test]
fn rotor_efficiency_scales_thrust_and_torque() {
    let dist = Disturbance {
        rotor_efficiency: [0.7, 1.0, 0.9, 1.0],
        efficiency_onset_s: 1.0,
        ..Disturbance::default()
    };
    let params = VehicleParams::cf2x();
    let plant = Plant::new(
        params.clone(),
        dist,
        Effects::default(),
        PlantState::default(),
    );
    let nominal = Plant::nominal(PlantState::default());
    let rpm = [15000.0, 14000.0, 13000.0, 12000.0];
    let s = PlantState::default();
    let before = plant.forces(0.5, &s, &rpm);
    let after = plant.forces(1.5, &s, &rpm);
    let nom = nominal.forces(1.5, &s, &rpm);
    for i in 0..4 {
        assert_eq!(before.rotor_thrust_n[i], nom.rotor_thrust_n[i]);
        let d = [0.7, 1.0, 0.9, 1.0][i];
        let expect = d * params.kf_n_per_rpm2 * rpm[i] * rpm[i];
        assert!((after.rotor_thrust_n[i] - expect).abs() < 1e-15);
    }
    // Yaw torque: rotor reaction torques scaled too.
    let km = params.km_nm_per_rpm2;
    let tz = km * (-0.7 * rpm[0].powi(2) + rpm[1].powi(2) - 0.9 * rpm[2].powi(2) + rpm[3].powi(2));
    assert!((after.torque_body_nm.z - tz).abs() < 1e-15);
}

#[test]
fn wind_produces_m_w_force() {
    let w = Vector3::new(0.5, -0.25, 0.1);
    let dist = Disturbance {
        wind_m_s2: w.into(),
        ..Disturbance::default()
    };
    let params = VehicleParams::cf2x();
    let s = PlantState {
        rot: rot_from_rpy(Vector3::new(0.2, 0.1, -0.4)),
        ..PlantState::default()
    };
    let windy = Plant::new(params.clone(), dist.clone(), Effects::default(), s);
    let calm = Plant::nominal(s);
    let rpm = [14000.0; 4];
    let df = s.rot
        * (windy.forces(0.0, &s, &rpm).force_body_n - calm.forces(0.0, &s, &rpm).force_body_n);
    assert!((df - params.mass_kg * w).norm() < 1e-15);

    // Closed form in flight: at hover thrust, level, the wind accelerates the body by w.
    let p0 = Vector3::new(0.0, 0.0, 1.0);
    let mut plant = Plant::new(
        params.clone(),
        dist,
        Effects::default(),
        PlantState::at_rest(p0, 0.0),
    );
    let h = params.hover_rpm();
    for _ in 0..1000 {
        plant.step([h; 4], DT);
    }
    let disp = plant.state().p_m - p0;
    assert!((disp - 0.5 * w).norm() < 1e-9, "displacement {disp:?}");
}

#[test]
fn nominal_wrench_and_its_inverse_agree() {
    let p = VehicleParams::cf2x();
    assert!((p.max_rpm() - 21703.0).abs() < 10.0);
    let rpm = [15000.0, 14000.0, 13000.0, 12500.0];
    let u = p.nominal_wrench(rpm);
    let back = p.wrench_to_rpm(u);
    for i in 0..4 {
        assert!((back[i] - rpm[i]).abs() < 1e-6, "{back:?}");
    }
    // Signs: rotors 3, 4 (left, +y) make +τx; rotors 2, 3 (back, −x) make +τy; 2, 4 make +τz.
    let h = p.hover_rpm();
    let u = p.nominal_wrench([h, h, h * 1.1, h * 1.1]);
    assert!(u[1] > 0.0 && u[2].abs() < 1e-12);
    let u = p.nominal_wrench([h, h * 1.1, h * 1.1, h]);
    assert!(u[2] > 0.0 && u[1].abs() < 1e-12);
    let u = p.nominal_wrench([h, h * 1.1, h, h * 1.1]);
    assert!(u[3] > 0.0 && u[1].abs() < 1e-12 && u[2].abs() < 1e-12);
    // Saturation keeps every rotor in range and keeps roll torque when thrust is too high.
    let sat = p.wrench_to_rpm([0.7, 2e-3, 0.0, 0.0]);
    assert!(sat.iter().all(|r| (0.0..=p.max_rpm() + 1e-9).contains(r)));
    let us = p.nominal_wrench(sat);
    assert!((us[1] - 2e-3).abs() < 1e-9, "roll torque kept: {us:?}");
}

#[test]
fn motor_lag_is_first_order() {
    let params = VehicleParams::cf2x();
    let effects = Effects {
        motor_tau_s: 0.05,
        ..Effects::default()
    };
    let mut plant = Plant::new(
        params.clone(),
        Disturbance::default(),
        effects,
        PlantState::at_rest(Vector3::new(0.0, 0.0, 10.0), 0.0),
    );
    plant.set_rotor_rpm([10000.0; 4]);
    for _ in 0..50 {
        plant.step([20000.0; 4], DT);
    }
    let expect = 20000.0 - 10000.0 * (-1.0f64).exp();
    assert!((plant.rotor_rpm()[0] - expect).abs() < 1e-3);
}
