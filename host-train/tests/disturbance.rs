//! Time-varying wind, mid-flight faults and the synthesized accelerometer (the adaptation scenario
//! format), and the event scores of report.json.

use host_train::fly::{event_metrics, FlightLog, RECOVERED_ERR_M};
use host_train::sim::{Plant, PlantState, Scenario};
use nalgebra::Vector3;

fn from_toml(extra: &str) -> anyhow::Result<Scenario> {
    let text = format!(
        "duration_s = 20.0\n[trajectory]\nkind = \"hover\"\nposition_m = [0.0, 0.0, 1.0]\n{extra}"
    );
    Scenario::from_toml_str(&text, "test.toml", "test")
}

#[test]
fn sines_and_steps_add_to_the_wind() {
    let sc = from_toml(
        "[disturbance]\nwind_m_s2 = [0.1, 0.0, 0.0]\n\
         [[disturbance.wind_sines]]\namplitude_m_s2 = [0.4, 0.0, 0.0]\nfrequency_hz = 0.5\n\
         [[disturbance.wind_sines]]\namplitude_m_s2 = [0.0, 0.3, 0.0]\nfrequency_hz = 1.0\nphase_rad = 0.5\n\
         [[disturbance.wind_steps]]\nwind_m_s2 = [0.0, 0.0, 0.7]\nfrom_s = 6.0\nuntil_s = 16.0\n",
    )
    .expect("parses");
    let p = sc.plant();
    for t in [0.0, 0.3, 5.99, 6.0, 10.0, 15.99, 16.0] {
        let tau = core::f64::consts::TAU;
        let want = Vector3::new(
            0.1 + 0.4 * (tau * 0.5 * t).sin(),
            0.3 * (tau * t + 0.5).sin(),
            if (6.0..16.0).contains(&t) { 0.7 } else { 0.0 },
        );
        assert!(
            (p.wind_at(t) - want).norm() < 1e-12,
            "t = {t}: {}",
            p.wind_at(t)
        );
    }
    assert_eq!(sc.spec.disturbance.event_times_s(), vec![6.0, 16.0]);
}

#[test]
fn a_mid_flight_rotor_fault_is_an_event() {
    let sc = from_toml("[disturbance]\nrotor_efficiency = [1.0, 1.0, 1.0, 0.6]\nonset_s = 12.0\n")
        .expect("parses");
    assert_eq!(sc.spec.disturbance.event_times_s(), vec![12.0]);
    let p = sc.plant();
    assert_eq!(p.disturbance.efficiency_at(11.9), [1.0; 4]);
    assert_eq!(p.disturbance.efficiency_at(12.0), [1.0, 1.0, 1.0, 0.6]);
}

#[test]
fn bad_wind_keys_name_the_key() {
    for (bad, key) in [
        (
            "[[disturbance.wind_sines]]\namplitude_m_s2 = [0.4, 0.0, 0.0]\nfrequency_hz = -1.0\n",
            "wind_sines[0]",
        ),
        (
            "[[disturbance.wind_steps]]\nwind_m_s2 = [0.4, 0.0, 0.0]\nfrom_s = 6.0\nuntil_s = 5.0\n",
            "wind_steps[0]",
        ),
        (
            "[[disturbance.wind_steps]]\nwind_m_s2 = [0.4, 0.0, 0.0]\nfrom_s = 6.0\ngust = 1\n",
            "gust",
        ),
    ] {
        let e = format!("{:#}", from_toml(bad).expect_err("refused"));
        assert!(e.contains("test.toml") && e.contains(key), "{e}");
    }
}

#[test]
fn accelerometer_reads_the_specific_force_in_the_body_frame() {
    let sc = from_toml("[disturbance]\nwind_m_s2 = [0.5, -0.25, 0.0]\n").expect("parses");
    let mut p: Plant = sc.plant();
    let rot = host_train::sim::rot_from_rpy(Vector3::new(0.1, -0.2, 0.3));
    p.set_state(PlantState { rot, ..*p.state() });
    // Rotors at hover speed (the plant's start): thrust m g along body z, plus the wind.
    let thrust = 4.0 * p.params.kf_n_per_rpm2 * p.params.hover_rpm().powi(2);
    let want = Vector3::new(0.0, 0.0, thrust / p.params.mass_kg)
        + rot.transpose() * Vector3::new(0.5, -0.25, 0.0);
    assert!(
        (p.accelerometer() - want).norm() < 1e-9,
        "{}",
        p.accelerometer()
    );
    // Noise only when asked, from the caller's stream.
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
    assert_eq!(p.measure_accelerometer(&mut rng), p.accelerometer());
    p.effects.noise.acc_m_s2 = 0.05;
    let d = (p.measure_accelerometer(&mut rng) - p.accelerometer()).norm();
    assert!(d > 0.0 && d < 0.5, "{d}");
}

#[test]
fn event_scores_peak_recovery_and_rmse() {
    let sc = from_toml(
        "[[disturbance.wind_steps]]\nwind_m_s2 = [0.8, 0.6, 0.0]\nfrom_s = 6.0\nuntil_s = 16.0\n",
    )
    .expect("parses");
    // A synthetic log: 3 cm from 6 s decaying to 0 by 6.5 s; never recovers after 16 s.
    let mut log = FlightLog::default();
    for k in 0..=2000 {
        let t = k as f64 * 0.01;
        let e = if (6.0..6.5).contains(&t) {
            0.03 * (6.5 - t) / 0.5
        } else if t >= 16.0 {
            0.02
        } else {
            0.0
        };
        log.t_s.push(t);
        log.err_m.push(e);
    }
    let ev = event_metrics(&sc, &log);
    assert_eq!(ev.len(), 2);
    assert!((ev[0].t_s - 6.0).abs() < 1e-12);
    assert!((ev[0].peak_err_m - 0.03).abs() < 1e-9);
    // Below 1 cm from 6 + 0.5·(2/3) s on.
    let rec = ev[0].recovery_s.expect("recovers");
    assert!((rec - 0.34).abs() < 0.011, "{rec}");
    assert_eq!(RECOVERED_ERR_M, 0.01);
    assert_eq!(ev[1].recovery_s, None);
    assert!((ev[1].rmse_after_m.expect("scored") - 0.02).abs() < 1e-12);
}
