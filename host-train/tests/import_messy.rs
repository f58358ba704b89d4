//! `host-train import` on small synthetic CSV logs, each with one defect real logs have:
//! repeated states, rotor-speed glitches, an aggressive low-thrust descent, a landing on a
//! table, a quaternion that is not unit length, rotor speeds without a vehicle description,
//! and no mass at all.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use host_train::data::{fix_rotor_glitches, run_import, FileSummary, ImportArgs};
use host_train::io::load_dataset;
use host_train::sim::{VehicleFile, RPM_PER_RAD_S};

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hamflight-messy-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// The benchmark's Crazyflie 2.1 Brushless constants (docs/benchmark.md).
const VEHICLE: &str = "name = \"test-brushless\"\nmass_kg = 0.045\ngravity_m_s2 = 9.81\n\
     inertia_kg_m2 = [2.3951e-5, 2.3951e-5, 3.2347e-5]\narm_xy_m = 0.0353\n\
     kf_n_per_rad_s2 = 3.7178e-8\nkm_nm_per_rad_s2 = 7.728e-11\nthrust_to_weight = 2.5\n";

fn vehicle() -> VehicleFile {
    VehicleFile::from_toml_str(VEHICLE, "test").expect("parses")
}

/// One CSV row at 100 Hz: state at `p` moving with `v` (world), level, and the four rotor
/// speeds as eRPM of 12-pole motors.
struct Row {
    t: f64,
    p: [f64; 3],
    v: [f64; 3],
    q: [f64; 4],
    w_rad_s: [f64; 4],
}

fn csv(rows: &[Row]) -> String {
    let mut s =
        String::from("t_s,px_m,py_m,pz_m,qw,qx,qy,qz,vx_world_m_s,vy_world_m_s,vz_world_m_s,wx_rad_s,wy_rad_s,wz_rad_s,erpm1,erpm2,erpm3,erpm4\n");
    for r in rows {
        let e = r.w_rad_s.map(|w| w * RPM_PER_RAD_S * 6.0);
        writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},0,0,0,{},{},{},{}",
            r.t,
            r.p[0],
            r.p[1],
            r.p[2],
            r.q[0],
            r.q[1],
            r.q[2],
            r.q[3],
            r.v[0],
            r.v[1],
            r.v[2],
            e[0],
            e[1],
            e[2],
            e[3]
        )
        .expect("string");
    }
    s
}

fn hover_rad_s() -> f64 {
    let v = vehicle();
    (v.mass_kg * v.gravity_m_s2 / (4.0 * v.kf_n_per_rad_s2)).sqrt()
}

/// `n` samples at 100 Hz cruising at 0.5 m/s along x at 1 m.
fn cruise(n: usize) -> Vec<Row> {
    (0..n)
        .map(|k| {
            let t = k as f64 * 0.01;
            Row {
                t,
                p: [0.5 * t, 0.0, 1.0],
                v: [0.5, 0.0, 0.0],
                q: [1.0, 0.0, 0.0, 0.0],
                w_rad_s: [hover_rad_s(); 4],
            }
        })
        .collect()
}

fn import(
    dir: &Path,
    text: &str,
    tweak: impl FnOnce(&mut ImportArgs),
) -> anyhow::Result<Vec<FileSummary>> {
    let log = dir.join("log.csv");
    std::fs::write(&log, text).expect("write log");
    let vf = dir.join("vehicle.toml");
    std::fs::write(&vf, VEHICLE).expect("write vehicle");
    let mut a = ImportArgs {
        logs: vec![log],
        vehicle: Some(vf),
        mass_kg: None,
        motor_poles: Some(12),
        ..ImportArgs::new(dir.join("data"), 0.0)
    };
    tweak(&mut a);
    run_import(&a)
}

#[test]
fn rotor_speeds_become_the_realized_wrench_and_the_vehicle_is_saved() {
    let dir = tmpdir("speeds");
    let s = import(&dir, &csv(&cruise(400)), |_| {}).expect("imports");
    assert_eq!(s[0].flights, 1);
    assert_eq!((s[0].repeated_states, s[0].rotor_glitches), (0, 0));
    let ds = load_dataset(dir.join("data")).expect("loads");
    assert_eq!(ds.manifest.mass_kg, 0.045);
    assert_eq!(ds.manifest.gravity_m_s2, 9.81);
    let d = ds.manifest.vehicle.description.as_ref().expect("saved");
    assert_eq!(d.arm_xy_m, 0.0353);
    assert_eq!(
        ds.manifest.vehicle.inertia_kg_m2,
        Some(vehicle().inertia_kg_m2)
    );
    let f = &ds.realizations[0].flights[0].samples[0];
    // Four rotors at hover speed carry m g; the speeds are kept (as rpm).
    assert!(
        (f.wrench[0] / (0.045 * 9.81) - 1.0).abs() < 1e-9,
        "{:?}",
        f.wrench
    );
    let rpm = f.rpm.expect("rotor speeds kept");
    assert!((rpm[0] / (hover_rad_s() * RPM_PER_RAD_S) - 1.0).abs() < 1e-9);
}

#[test]
fn repeated_states_are_dropped_without_cutting_the_flight() {
    let dir = tmpdir("repeat");
    let mut rows = cruise(600);
    // Every 10th sample repeats the previous state (a dropped packet, filled in).
    for k in (10..600).step_by(10) {
        let (p, v) = (rows[k - 1].p, rows[k - 1].v);
        rows[k].p = p;
        rows[k].v = v;
    }
    let s = import(&dir, &csv(&rows), |_| {}).expect("imports");
    assert_eq!(s[0].repeated_states, 59);
    assert_eq!(s[0].flights, 1, "the 10 ms gaps must not cut the flight");
    // 6 s airborne, 0.5 s trimmed at each end, the repeats gone.
    assert!(
        s[0].samples_kept > 400 && s[0].samples_kept < 460,
        "{:?}",
        s[0]
    );
}

#[test]
fn rotor_speed_glitches_are_interpolated_and_counted() {
    let dir = tmpdir("glitch");
    let mut rows = cruise(400);
    let w = hover_rad_s();
    rows[200].w_rad_s[2] = 6e6 / 6.0 / RPM_PER_RAD_S; // 6e6 eRPM
    rows[201].w_rad_s[1] = 0.1 * w; // a one-sample dropout
    rows[300].w_rad_s[0] = -5.0;
    let s = import(&dir, &csv(&rows), |_| {}).expect("imports");
    assert_eq!(s[0].rotor_glitches, 3, "{:?}", s[0]);
    let ds = load_dataset(dir.join("data")).expect("loads");
    let f = &ds.realizations[0].flights[0].samples;
    assert!(f
        .iter()
        .all(|x| (x.wrench[0] / (0.045 * 9.81) - 1.0).abs() < 1e-9));
    // Without the fix the 6e6 eRPM reading would be over 2,000 × the weight.
    let mut v = vec![[w; 4]; 3];
    v[1][2] = 6e6 / 6.0 / RPM_PER_RAD_S;
    let n = fix_rotor_glitches(
        &[0.0, 0.01, 0.02],
        &mut v,
        vehicle().max_rotor_speed_rad_s(),
    )
    .expect("fixes");
    assert_eq!(n, 1);
    assert!((v[1][2] - w).abs() < 1e-9);
}

#[test]
fn an_aggressive_descent_is_flight_and_a_table_landing_is_not() {
    let dir = tmpdir("descent");
    let mut rows = cruise(800);
    let low = 0.3 * hover_rad_s(); // thrust 0.09 m g, below the rule's 0.25
                                   // 2.0–2.5 s: dropping at 1 m/s with the motors nearly off, still 0.5 m up.
    for r in rows.iter_mut().filter(|r| (2.0..2.5).contains(&r.t)) {
        r.w_rad_s = [low; 4];
        r.v = [0.5, 0.0, -1.0];
    }
    // 5.0–6.0 s: standing on a 0.5 m table, motors idle.
    for r in rows.iter_mut().filter(|r| (5.0..6.0).contains(&r.t)) {
        r.w_rad_s = [low; 4];
        r.v = [0.0; 3];
        r.p = [2.5, 0.0, 0.5];
    }
    let s = import(&dir, &csv(&rows), |_| {}).expect("imports");
    // Flight 0–5 s (the descent inside it) and 6–8 s: two flights.
    assert_eq!(s[0].flights, 2, "{:?}", s[0]);
    let ds = load_dataset(dir.join("data")).expect("loads");
    let first = &ds.realizations[0].flights[0].samples;
    assert!(first.iter().any(|x| (2.0..2.5).contains(&x.t_s)));
    assert!(first.iter().all(|x| x.t_s < 4.6));
}

#[test]
fn bad_input_is_an_error_that_names_the_row_or_the_flag() {
    let dir = tmpdir("bad");
    let mut rows = cruise(300);
    rows[150].q = [0.9, 0.0, 0.0, 0.0];
    let e = import(&dir, &csv(&rows), |_| {}).expect_err("non-unit quaternion");
    let msg = format!("{e:#}");
    assert!(
        msg.contains("line 152") && msg.contains("norm 0.9000"),
        "{msg}"
    );

    let text = csv(&cruise(300));
    let e = import(&dir, &text, |a| a.vehicle = None).expect_err("no mass");
    assert!(format!("{e:#}").contains("--mass-kg"), "{e:#}");
    let e = import(&dir, &text, |a| {
        a.vehicle = None;
        a.mass_kg = Some(0.045);
    })
    .expect_err("speeds need coefficients");
    assert!(format!("{e:#}").contains("--vehicle"), "{e:#}");
    let e = import(&dir, &text, |a| a.motor_poles = None).expect_err("eRPM needs poles");
    assert!(format!("{e:#}").contains("--motor-poles"), "{e:#}");
    let e = import(&dir, &text, |a| a.motor_tau_s = Some(0.03)).expect_err("speeds are realized");
    assert!(format!("{e:#}").contains("--motor-tau-s"), "{e:#}");
    assert!(
        !dir.join("data").join("manifest.json").exists(),
        "nothing written"
    );
}
