//! The core flown against the SITL plant, closed loop: every controller tracks without
//! disturbance, the adaptive controller holds paper-spiral with the shipped weights, and the
//! adaptation converges to the true disturbance. Thresholds sit near 3× what the flights gave
//! when they were set, so that a regression shows (today's figures: docs/adaptation.md and
//! docs/crazyflie-chain.md).
//!
//! Run in release (`cargo test --release`): each flight is 15–30 simulated seconds at 500 Hz.

use hamflight::model::{HamiltonianModel, NominalModel};
use hamflight::Gains;
use host_train::control::{by_name, load_learned, CoreController, DEFAULT_WEIGHTS};
use host_train::fly::{fly_scenario, Report, CRASH_ERR_M};
use host_train::sim::Scenario;
use std::path::{Path, PathBuf};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

fn scenario(name: &str) -> Scenario {
    Scenario::load(repo(&format!("scenarios/{name}.toml"))).expect("scenario loads")
}

fn weights() -> PathBuf {
    repo(DEFAULT_WEIGHTS)
}

fn fly(name: &str, sc: &Scenario) -> Report {
    let mut ctrl = by_name(name, sc, Some(&weights())).expect("controller exists");
    let log = fly_scenario(sc, ctrl.as_mut());
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

/// Largest whole-flight RMSE (m) per controller on hover and circle-slow: about 3× what each
/// flew when the bars were set.
fn tracking_bar(name: &str, sc_name: &str) -> f64 {
    // The nominal-model controllers hold hover exactly; `learned` carries its model's bias
    // without adaptation, and `adaptive` has the start-up transient of a from 0 on that bias,
    // hence their looser bars.
    let cm = match (name, sc_name) {
        ("learned", _) => 4.1,
        ("adaptive", "hover") => 0.57,
        (_, "hover") => 0.001,
        ("pid", _) => 1.4,
        _ => 1.0,
    };
    cm / 100.0
}

#[test]
fn every_controller_tracks_hover_and_a_slow_circle_without_disturbance() {
    for sc_name in ["hover", "circle-slow"] {
        let sc = scenario(sc_name);
        for name in ALL {
            let r = fly(name, &sc);
            println!("{sc_name} {name}: {:.4} cm", 100.0 * r.rmse_pos_m);
            assert!(!r.crashed, "{name} crashed on {sc_name}");
            let bar = tracking_bar(name, sc_name);
            assert!(
                r.rmse_pos_m <= bar,
                "{name} on {sc_name}: RMSE {:.5} m > {bar} m",
                r.rmse_pos_m
            );
        }
    }
}

#[test]
fn adaptive_holds_paper_spiral_and_beats_learned_eightyfold() {
    let sc = scenario("paper-spiral");
    let adaptive = fly("adaptive", &sc);
    let learned = fly("learned", &sc);
    let a = adaptive.rmse_pos_window_m.expect("window scored");
    assert!(!adaptive.crashed, "adaptive crashed: {adaptive:?}");
    // `adaptive` flies the composite law (docs/adaptation.md); bar 0.1 cm.
    assert!(a <= 0.001, "adaptive window RMSE {a:.6} m > 0.1 cm");
    assert!(!learned.crashed, "learned crashed: {learned:?}");
    let l = learned.rmse_pos_window_m.expect("window scored");
    // Without adaptation the learned model alone must be at least 80× worse.
    assert!(
        80.0 * a <= l,
        "adaptive {a:.6} m is not 80x better than learned {l:.5} m"
    );
}

/// The paper's claim: the learned model's features beat hand-chosen ones. It holds with the
/// paper's gradient law; with the composite law (the default) the nominal model (the vehicle's
/// true constants) predicts the measured force better and wins instead (see docs/adaptation.md).
#[test]
fn adaptive_beats_geometric_adaptive_with_the_paper_law() {
    for (sc_name, margin) in [("paper-spiral", 1.3), ("paper-spiral-realistic", 1.03)] {
        let sc = scenario(sc_name);
        let a = fly("adaptive-gradient", &sc);
        let g = fly("geometric-adaptive-gradient", &sc);
        let (a, g) = (
            a.rmse_pos_window_m.expect("scored"),
            g.rmse_pos_window_m.expect("scored"),
        );
        // The learned features win by `margin`: a clear factor on paper-spiral, a small one on
        // the realistic plant, whose noise and unmodelled effects both models share.
        assert!(
            margin * a <= g,
            "{sc_name}: adaptive {a:.6} m vs geometric-adaptive {g:.6} m"
        );
    }
}

#[test]
fn crashes_are_reported_not_silent() {
    // The DSL PID has no roll/pitch integral: two weak rotors on one side roll it away.
    let sc = scenario("paper-spiral");
    for name in ALL {
        let r = fly(name, &sc);
        let flew_whole = (r.duration_s - r.planned_duration_s).abs() < 1e-6;
        if name == "pid" {
            // It crashes well inside the first 1.5 s, and the flight stops there.
            let t = r.crash_time_s.expect("the DSL PID crashes on paper-spiral");
            assert!(r.crashed && t < 1.5, "pid: {r:?}");
            assert!(
                (r.duration_s - t).abs() < 1e-9,
                "pid stopped at the crash: {r:?}"
            );
            assert!(r.rmse_pos_window_m.is_none(), "pid scored after its crash");
            let mut ctrl = by_name(name, &sc, None).expect("pid exists");
            let log = fly_scenario(&sc, ctrl.as_mut());
            let z = log.p_m.last().map(|p| p[2]).unwrap_or(f64::NAN);
            let e = log.err_m.last().copied().unwrap_or(f64::NAN);
            assert!(
                z < 0.0 || e > CRASH_ERR_M,
                "pid flagged as crashed at z = {z} m, error {e} m: neither crash condition"
            );
        } else {
            assert!(
                !r.crashed && r.crash_time_s.is_none() && flew_whole,
                "{name}: crashed or ended early: {r:?}"
            );
            assert!(r.max_err_m <= 0.2, "{name}: max error {} m", r.max_err_m);
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
    use host_train::control::Controller;
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
        load_learned(&weights()).expect("shipped weights load"),
        Gains::default(),
    );
    let f_nominal = compensated_world_force(&sc, &mut nominal, 5.0);
    let rel = (f_nominal - truth).norm() / truth.norm();
    println!("geometric-adaptive: {:.3} % off", 100.0 * rel);
    // The nominal features are the true ones: the estimate's force matches the wind closely.
    assert!(
        rel < REL_NOMINAL,
        "geometric-adaptive: compensated force {f_nominal:?} N vs wind force {truth:?} N ({:.1} % off)",
        100.0 * rel
    );

    // Whatever thrust deficit the learned g still carries (g_f, the learned thrust gain at
    // hover: near 1 with the calm realization in the training data, lower without; see
    // docs/training.md, "Calm air"), the
    // estimate also holds an upward force that cancels it on a vehicle with nominal rotors:
    // (1 − g_f) m g. The wind itself is the horizontal part.
    let f_learned = compensated_world_force(&sc, &mut learned, 5.0);
    let hover = hamflight::State::default();
    let g_f = f64::from(learned.inner().model().terms(&hover).gain[(2, 0)]);
    let expected = nalgebra::Vector3::new(truth.x, truth.y, (1.0 - g_f) * 0.027 * 9.8);
    let rel = (f_learned - expected).norm() / truth.norm();
    println!("adaptive: {:.3} % off", 100.0 * rel);
    // A blob trained without a calm realization would carry a larger g bias and fail this.
    assert!(
        rel < REL_LEARNED,
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
    // `adaptive` flies the composite law (docs/adaptation.md); bar 0.55 cm.
    assert!(e < 0.0055, "adaptive on the realistic plant: {e:.5} m");
}

const REL_NOMINAL: f64 = 0.0135;
const REL_LEARNED: f64 = 0.0225;
