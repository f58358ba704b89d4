//! Closed-loop checks of the baseline controllers and the scenario files.

use std::path::PathBuf;

use host_train::control::baseline_by_name as by_name;
use host_train::fly::{fly_scenario, Report};
use host_train::sim::Scenario;

fn scenario(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("scenarios")
        .join(format!("{name}.toml"));
    Scenario::load(&path).expect("shipped scenario loads")
}

fn run(scn: &str, ctrl: &str) -> Report {
    let s = scenario(scn);
    let mut c = by_name(ctrl, &s).unwrap();
    let log = fly_scenario(&s, c.as_mut());
    Report::from_log(&log, None)
}

#[test]
fn pid_flies_hover_without_crashing() {
    let r = run("hover", "pid");
    assert!(!r.crashed, "{r:?}");
    assert!(r.max_err_m < 0.01, "{r:?}");
}

#[test]
fn pid_flies_step_without_crashing() {
    let r = run("step", "pid");
    assert!(!r.crashed, "{r:?}");
    assert!(r.final_err_m < 0.05, "{r:?}");
}

#[test]
fn geometric_tracks_slow_circle() {
    let r = run("circle-slow", "geometric");
    assert!(!r.crashed, "{r:?}");
    assert!(r.rmse_pos_m < 0.02, "{r:?}");
}

#[test]
fn geometric_holds_hover_in_wind_and_rotor_failure() {
    for s in ["hover-wind", "rotor-failure", "diamond", "paper-spiral"] {
        let r = run(s, "geometric");
        assert!(!r.crashed, "{s}: {r:?}");
    }
}

#[test]
fn all_shipped_scenarios_load() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            Scenario::load(&p).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            n += 1;
        }
    }
    assert!(n >= 7);
}

#[test]
fn paper_spiral_is_as_designed() {
    let s = scenario("paper-spiral");
    assert_eq!(s.spec.duration_s, 30.0);
    let d = s.disturbance();
    assert_eq!(d.wind_m_s2, [0.75, 0.75, 0.0]);
    assert_eq!(d.rotor_efficiency, [0.8, 0.8, 1.0, 1.0]);
    assert_eq!(d.efficiency_onset_s, 0.0);
    for t in [0.0, 3.7, 12.0, 30.0] {
        let r = s.reference(t);
        let w = std::f64::consts::TAU * t / 10.0;
        let p = nalgebra::Vector3::new(0.5 * w.cos(), 0.5 * w.sin(), 0.5 + 0.03 * t);
        assert!((r.p_m - p).norm() < 1e-12);
        assert_eq!(r.yaw_rad, 0.0);
    }
    let s0 = s.initial_state();
    assert!((s0.p_m - s.reference(0.0).p_m).norm() < 1e-15);
    assert_eq!(s0.v_body_m_s.norm(), 0.0);
}

#[test]
fn trajectory_derivatives_are_consistent() {
    for name in ["paper-spiral", "diamond", "circle-slow"] {
        let s = scenario(name);
        let h = 1e-5;
        for t in [0.3, 1.7, 4.2, 6.9] {
            let (a, b) = (s.reference(t - h), s.reference(t + h));
            let c = s.reference(t);
            assert!(
                ((b.p_m - a.p_m) / (2.0 * h) - c.v_m_s).norm() < 1e-6,
                "{name} v"
            );
            assert!(
                ((b.v_m_s - a.v_m_s) / (2.0 * h) - c.a_m_s2).norm() < 1e-5,
                "{name} a"
            );
            assert!(
                ((b.a_m_s2 - a.a_m_s2) / (2.0 * h) - c.j_m_s3).norm() < 1e-4,
                "{name} j"
            );
        }
    }
}

#[test]
fn bad_scenario_errors_name_file_and_key() {
    let bad_key =
        "duration_s = 5.0\nwindd = 3\n[trajectory]\nkind = \"hover\"\nposition_m = [0,0,1]\n";
    let e = format!(
        "{:#}",
        Scenario::from_toml_str(bad_key, "bad.toml", "bad").unwrap_err()
    );
    assert!(e.contains("bad.toml") && e.contains("windd"), "{e}");

    let bad_type = "duration_s = \"long\"\n[trajectory]\nkind = \"hover\"\nposition_m = [0,0,1]\n";
    let e = format!(
        "{:#}",
        Scenario::from_toml_str(bad_type, "t.toml", "t").unwrap_err()
    );
    assert!(e.contains("t.toml") && e.contains("duration_s"), "{e}");

    let bad_kind = "duration_s = 5.0\n[trajectory]\nkind = \"loop\"\n";
    let e = format!(
        "{:#}",
        Scenario::from_toml_str(bad_kind, "k.toml", "k").unwrap_err()
    );
    assert!(e.contains("k.toml") && e.contains("loop"), "{e}");

    let bad_field = "duration_s = 5.0\n[trajectory]\nkind = \"circle\"\ncenter_m = [0,0,1]\nradius_m = 0.5\nperiod = 3\n";
    let e = format!(
        "{:#}",
        Scenario::from_toml_str(bad_field, "c.toml", "c").unwrap_err()
    );
    assert!(e.contains("c.toml") && e.contains("period"), "{e}");

    let bad_value = "duration_s = 5.0\n[trajectory]\nkind = \"hover\"\nposition_m = [0,0,1]\n[disturbance]\nrotor_efficiency = [0.8, 1, 1, 7]\n";
    let e = format!(
        "{:#}",
        Scenario::from_toml_str(bad_value, "v.toml", "v").unwrap_err()
    );
    assert!(
        e.contains("v.toml") && e.contains("rotor_efficiency"),
        "{e}"
    );

    let e = format!("{:#}", Scenario::load("/nonexistent/x.toml").unwrap_err());
    assert!(e.contains("/nonexistent/x.toml"), "{e}");
}

#[test]
fn unknown_controller_is_an_error() {
    let s = scenario("hover");
    let e = by_name("nope", &s).err().unwrap().to_string();
    assert!(
        e.contains("nope") && e.contains("pid") && e.contains("geometric"),
        "{e}"
    );
}
