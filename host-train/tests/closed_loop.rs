//! The core flown against the SITL plant, closed loop: every controller tracks without
//! disturbance, the adaptive controller holds paper-spiral with the shipped weights, and the
//! adaptation converges to the true disturbance.
//!
//! Run in release (`cargo test --release`): each flight is 15–30 simulated seconds at 500 Hz.

use hamflight::model::{HamiltonianModel, NominalModel};
use hamflight::Gains;
use host_train::eval::{self, Report};
use host_train::flight::{self, CoreController};
use host_train::Scenario;
use std::path::{Path, PathBuf};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

fn scenario(name: &str) -> Scenario {
    Scenario::load(repo(&format!("scenarios/{name}.toml"))).expect("scenario loads")
}

fn weights() -> PathBuf {
    repo(flight::DEFAULT_WEIGHTS)
}

fn fly(name: &str, sc: &Scenario) -> Report {
    let mut ctrl = flight::by_name(name, sc, Some(&weights())).expect("controller exists");
    let log = eval::fly(sc, ctrl.as_mut());
    Report::from_log(&log, None)
}

const ALL: [&str; 6] = [
    "pid",
    "geometric",
    "ida-pbc",
    "geometric-adaptive",
    "learned",
    "adaptive",
];

#[test]
fn every_controller_tracks_hover_and_a_slow_circle_without_disturbance() {
    for sc_name in ["hover", "circle-slow"] {
        let sc = scenario(sc_name);
        for name in ALL {
            let r = fly(name, &sc);
            assert!(!r.crashed, "{name} crashed on {sc_name}");
            assert!(
                r.rmse_pos_m < 0.02,
                "{name} on {sc_name}: RMSE {:.4} m ≥ 2 cm",
                r.rmse_pos_m
            );
        }
    }
}

#[test]
fn adaptive_holds_paper_spiral_and_beats_learned_threefold() {
    let sc = scenario("paper-spiral");
    let adaptive = fly("adaptive", &sc);
    let learned = fly("learned", &sc);
    let a = adaptive.rmse_pos_window_m.expect("window scored");
    assert!(!adaptive.crashed, "adaptive crashed: {adaptive:?}");
    assert!(a <= 0.03, "adaptive window RMSE {a:.4} m > 3 cm");
    let l = if learned.crashed {
        f64::INFINITY
    } else {
        learned.rmse_pos_window_m.unwrap_or(f64::INFINITY)
    };
    assert!(
        3.0 * a <= l,
        "adaptive {a:.4} m is not 3x better than learned {l:.4} m"
    );
}

#[test]
fn crashes_are_reported_not_silent() {
    // The DSL PID has no roll/pitch integral: two weak rotors on one side roll it away.
    let sc = scenario("paper-spiral");
    for name in ALL {
        let r = fly(name, &sc);
        let flew_whole = (r.duration_s - r.planned_duration_s).abs() < 1e-6;
        assert_eq!(r.crashed, r.crash_time_s.is_some(), "{name}");
        assert!(
            r.crashed || (flew_whole && r.max_err_m <= eval::CRASH_ERR_M),
            "{name}: not flagged as crashed but the flight ended early or diverged: {r:?}"
        );
        if r.crashed {
            assert!(r.duration_s < r.planned_duration_s, "{name}");
        }
    }
}

/// Flies `sc` with a core controller and returns the compensated force R (W a)_v (N, world)
/// at the end.
fn compensated_world_force<M: HamiltonianModel>(
    sc: &Scenario,
    ctrl: &mut CoreController<M>,
    until_s: f64,
) -> nalgebra::Vector3<f64> {
    use host_train::Controller;
    let mut plant = sc.plant();
    let dt = sc.control_dt_s();
    let steps = (until_s / dt).round() as usize;
    let mut state = *plant.state();
    for k in 0..steps {
        let t = k as f64 * dt;
        state = *plant.state();
        let rpm = ctrl.step(t, &state, &sc.reference(t), dt);
        plant.advance(rpm, dt, 1.0 / sc.spec.physics_hz);
    }
    let core_state: hamflight::State = (&state).into();
    let w = ctrl.inner().model().terms(&core_state).features;
    let wa = w * ctrl.inner().estimate();
    let f_body = nalgebra::Vector3::new(wa[0], wa[1], wa[2]).cast::<f64>();
    state.rot * f_body
}

#[test]
fn adaptation_converges_to_a_constant_wind() {
    let sc = scenario("hover-wind");
    let wind = nalgebra::Vector3::from(sc.spec.disturbance.wind_m_s2);
    let truth = wind * 0.027;
    let mut nominal = CoreController::new(
        "geometric-adaptive",
        NominalModel::default(),
        Gains::default(),
    );
    let mut learned = CoreController::new(
        "adaptive",
        flight::load_learned(&weights()).expect("shipped weights load"),
        Gains::default(),
    );
    let f_nominal = compensated_world_force(&sc, &mut nominal, 5.0);
    let rel = (f_nominal - truth).norm() / truth.norm();
    assert!(
        rel < 0.10,
        "geometric-adaptive: compensated force {f_nominal:?} N vs wind force {truth:?} N ({:.1} % off)",
        100.0 * rel
    );

    // The learned model's g carries the training realizations' average thrust deficit (their
    // weak rotors), so on a vehicle with nominal rotors the estimate also holds an upward force
    // that cancels that bias: (1 − g_f) m g with g_f the learned thrust gain at hover. The wind
    // itself is the horizontal part.
    let f_learned = compensated_world_force(&sc, &mut learned, 5.0);
    let hover = hamflight::State::default();
    let g_f = f64::from(learned.inner().model().terms(&hover).gain[(2, 0)]);
    let expected = nalgebra::Vector3::new(truth.x, truth.y, (1.0 - g_f) * 0.027 * 9.8);
    let rel = (f_learned - expected).norm() / truth.norm();
    assert!(
        rel < 0.10,
        "adaptive: compensated force {f_learned:?} N vs wind force + g bias {expected:?} N \
         ({:.1} % off)",
        100.0 * rel
    );
}

/// A plant the model never saw: motor lag, rotor drag, ground effect and noisy state estimates.
/// The adaptive controller still holds paper-spiral to millimetres.
#[test]
fn adaptive_holds_paper_spiral_on_a_less_ideal_plant() {
    let sc = scenario("paper-spiral-realistic");
    let r = fly("adaptive", &sc);
    assert!(!r.crashed, "{r:?}");
    let e = r.rmse_pos_window_m.expect("window scored");
    assert!(e < 0.01, "adaptive on the realistic plant: {e:.4} m");
}
