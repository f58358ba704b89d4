//! The adaptation laws against disturbances that change and against windup and wrong
//! features (docs/adaptation.md): the composite law's bars, each next to the paper's gradient law
//! flown on the same scenario. Thresholds sit near 1.5× what the flights gave when they were set,
//! so that a regression shows; the current figures are in docs/adaptation.md (most of them in its
//! generated tables).
//!
//! Run in release: `cargo test --release -p host-train --test adaptation`.

use hamflight::model::{HamiltonianModel, ModelTerms, NominalModel, State};
use hamflight::{AdaptationLaw, Gains};
use host_train::control::{
    core_by_name, gains_with, load_learned, Controller, CoreController, DEFAULT_WEIGHTS,
};
use host_train::fly::{estimate_std, fly_scenario, measure_bandwidth_point, EventMetrics, Report};
use host_train::sim::{PlantState, TrajectoryPoint};

mod flight_common;
use flight_common::{fly, repo, scenario};

fn window(r: &Report) -> f64 {
    r.rmse_pos_window_m.expect("window scored")
}

fn event(r: &Report, k: usize) -> &EventMetrics {
    r.events.get(k).expect("event scored")
}

#[test]
fn the_composite_law_is_the_default_and_the_paper_law_selectable() {
    assert_eq!(Gains::default().law, AdaptationLaw::Composite);
    assert_eq!(Gains::paper().law, AdaptationLaw::Gradient);
    assert_eq!(
        gains_with(AdaptationLaw::Gradient).law,
        AdaptationLaw::Gradient
    );
    // The plain names fly the default law, the named ones theirs.
    let law_of = |name: &str| {
        core_by_name(name, Some(&repo(DEFAULT_WEIGHTS)))
            .expect("registered")
            .core_law()
    };
    assert_eq!(law_of("adaptive"), Some(AdaptationLaw::Composite));
    assert_eq!(law_of("geometric-adaptive"), Some(AdaptationLaw::Composite));
    assert_eq!(law_of("adaptive-gradient"), Some(AdaptationLaw::Gradient));
    assert_eq!(
        law_of("geometric-adaptive-gradient"),
        Some(AdaptationLaw::Gradient)
    );
    assert_eq!(law_of("learned"), None);
}

#[test]
fn gust_spiral_composite_three_times_better_than_the_paper_law() {
    let sc = scenario("gust-spiral");
    let c = window(&fly("adaptive-composite", &sc));
    let g = window(&fly("adaptive-gradient", &sc));
    // The composite law follows the gusts the gradient law lags behind: an absolute bar and 3×
    // better than the gradient law on the same flight.
    assert!(c <= 0.0072, "composite {c:.5} m");
    assert!(
        3.0 * c <= g,
        "composite {c:.5} m not 3x better than gradient {g:.5} m"
    );
}

#[test]
fn rotor_loss_mid_recovers_within_a_second() {
    let sc = scenario("rotor-loss-mid");
    let c = fly("adaptive-composite", &sc);
    let g = fly("adaptive-gradient", &sc);
    let (ce, ge) = (event(&c, 0), event(&g, 0));
    assert_eq!(ce.t_s, 12.0);
    // Bars: the composite law recovers (error below 1 cm for good) within 0.8 s and peaks under
    // 3.5 cm (the rotor-loss bars of docs/adaptation.md, kept while the torque observer is
    // designed for the attitude loop's 45° with the Crazyflie's chain: docs/crazyflie-chain.md,
    // "The composite law's torque observer, designed for the loop"), peaks at most 55 % of the
    // gradient law's peak and keeps the 5 s after the fault under 2.1 cm; the gradient law takes
    // over 2 s, if it recovers at all.
    let rec = ce.recovery_s.expect("composite recovers");
    assert!(rec <= 0.8, "recovery {rec} s");
    assert!(ce.peak_err_m <= 0.035, "{ce:?}");
    assert!(ce.peak_err_m <= 0.55 * ge.peak_err_m, "{ce:?} vs {ge:?}");
    assert!(ce.rmse_after_m.expect("scored") <= 0.021, "{ce:?}");
    assert!(ge.recovery_s.is_none_or(|r| r > 2.0), "gradient {ge:?}");
}

#[test]
fn hover_wind_step_peaks_below_60_percent_of_the_paper_law() {
    let sc = scenario("hover-wind-step");
    let c = fly("adaptive-composite", &sc);
    let g = fly("adaptive-gradient", &sc);
    assert_eq!(c.events.len(), 2, "{:?}", c.events);
    for k in 0..2 {
        let (ce, ge) = (event(&c, k), event(&g, k));
        // Bars per wind step: the composite law peaks under 1.4 cm and under 60 % of the
        // gradient law's peak, and settles within 0.5 s, sooner than the gradient law.
        assert!(ce.peak_err_m <= 0.014, "step {k}: {ce:?}");
        assert!(
            ce.peak_err_m <= 0.6 * ge.peak_err_m,
            "step {k}: {ce:?} vs {ge:?}"
        );
        let settle = ce.recovery_s.expect("composite settles");
        assert!(settle <= 0.5, "step {k}: settling {settle} s");
        assert!(ge.recovery_s.expect("gradient settles") > settle);
    }
}

#[test]
fn composite_bandwidth_at_1_hz() {
    let weights = repo(DEFAULT_WEIGHTS);
    let model = load_learned(&weights).expect("weights load");
    let mut c = CoreController::new("c", model, gains_with(AdaptationLaw::Composite));
    let mut g = CoreController::new("g", model, gains_with(AdaptationLaw::Gradient));
    let pc = measure_bandwidth_point(&mut c, 1.0).expect("measured");
    let pg = measure_bandwidth_point(&mut g, 1.0).expect("measured");
    // The composite estimate follows a 1 Hz wind (amplitude ratio 0.9–1.15, at most 24° of lag,
    // inside docs/adaptation.md's bar of ≥ 0.9 and ≤ 45°); the gradient law lags it by more
    // than 60° (its table: docs/adaptation.md, "Estimator bandwidth").
    assert!(
        (0.9..=1.15).contains(&pc.amplitude_ratio),
        "composite {pc:?}"
    );
    assert!(pc.lag_deg >= 0.0 && pc.lag_deg <= 24.0, "composite {pc:?}");
    assert!(pg.lag_deg > 60.0, "gradient {pg:?}");
}

#[test]
fn composite_no_worse_than_the_paper_law_on_the_paper_scenarios() {
    // `c_max`: the composite law's own bar (m); `today`: a fixed bar near the gradient law's
    // figure when the test was set, so that both laws getting worse together still fails. The
    // composite law must also beat the gradient law flown now.
    for (name, c_max, today) in [
        ("paper-spiral", 0.0006, 0.00039),
        ("paper-spiral-realistic", 0.0012, 0.0019),
    ] {
        let sc = scenario(name);
        let c = window(&fly("adaptive-composite", &sc));
        let g = window(&fly("adaptive-gradient", &sc));
        assert!(c <= c_max, "{name}: composite {c:.6} m");
        assert!(
            c <= today && c < g,
            "{name}: composite {c:.6} m, gradient {g:.6} m"
        );
    }
}

#[test]
fn no_windup_on_the_step() {
    let sc = scenario("step");
    // Every adaptive controller, either law, with setpoint shaping and the gradient term's
    // freeze: at most 0.05 cm over t ≥ 5 s. Without shaping the law winds up on the step's jump
    // and lands far above that (docs/adaptation.md).
    let d = window(&fly("adaptive", &sc));
    assert!(d <= 0.0005, "adaptive on step: {d:.6} m over t ≥ 5 s");
    let gd = window(&fly("geometric-adaptive", &sc));
    assert!(gd <= 0.0005, "geometric-adaptive on step: {gd:.6} m");
    let c = window(&fly("adaptive-composite", &sc));
    assert!(
        c <= 0.0005,
        "adaptive on step: {c:.6} m over t ≥ 5 s (bar 0.05 cm)"
    );
    let g = window(&fly("geometric-adaptive-composite", &sc));
    assert!(g <= 0.0005, "geometric-adaptive on step: {g:.6} m");
}

/// The composite estimate does not chatter on the noisy plant: its spread over t ≥ 10 s stays
/// near the gradient law's (which the noise barely moves).
#[test]
fn composite_estimate_is_calm_under_noise() {
    let sc = scenario("paper-spiral-realistic");
    let weights = repo(DEFAULT_WEIGHTS);
    let model = load_learned(&weights).expect("weights load");
    let mut stds = Vec::new();
    for law in [AdaptationLaw::Composite, AdaptationLaw::Gradient] {
        let mut c = CoreController::new("a", model, gains_with(law));
        let log = fly_scenario(&sc, &mut c);
        let s = estimate_std(&log, 10.0);
        assert_eq!(s.len(), 6);
        stds.push(s);
    }
    let (c, g) = (&stds[0], &stds[1]);
    println!("a std, composite {c:.4?}\na std, gradient  {g:.4?}");
    let max = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    // Thresholds: 1.5× the composite law's spread when they were set (force columns in m/s²,
    // torque columns in 1e-3 N·m; both laws' spread: docs/adaptation.md, "Estimate spread
    // under noise"). A longer low-pass on the torque rows would calm them further but costs the
    // attitude loop phase margin (`COMPOSITE_TORQUE_FILTER_S`).
    assert!(max(&c[..3]) <= CALM_FORCE, "force std {c:?}");
    assert!(max(&c[3..]) <= CALM_TORQUE, "torque std {c:?}");
}

const CALM_FORCE: f64 = 0.084;
const CALM_TORQUE: f64 = 0.0135;

/// A model whose features are wrong on purpose: scaled, or with a constant bias added.
#[derive(Clone, Copy)]
struct WrongFeatures<M> {
    inner: M,
    scale: f32,
    bias: f32,
}

impl<M: HamiltonianModel> HamiltonianModel for WrongFeatures<M> {
    fn terms(&self, state: &State) -> ModelTerms {
        let mut t = self.inner.terms(state);
        t.features *= self.scale;
        t.features.iter_mut().for_each(|w| *w += self.bias);
        t
    }
}

#[test]
fn wrong_features_keep_the_estimate_bounded_and_the_vehicle_up() {
    let sc = scenario("paper-spiral");
    let nominal = NominalModel::default();
    let cases = [(5.0, 0.0), (0.2, 0.0), (1.0, 0.01), (1.0, -0.01)];
    for law in [AdaptationLaw::Composite, AdaptationLaw::Gradient] {
        for (scale, bias) in cases {
            let model = WrongFeatures {
                inner: nominal,
                scale,
                bias,
            };
            let gains = gains_with(law);
            let mut c = CoreController::new("wrong", model, gains);
            let log = fly_scenario(&sc, &mut c);
            let r = Report::from_log(&log, None);
            assert!(!r.crashed, "{law:?} ×{scale} +{bias}: crashed {r:?}");
            let worst = log
                .adaptation
                .iter()
                .map(|a| a.iter().map(|x| x * x).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            assert!(
                worst <= f64::from(gains.rates.a_max) * (1.0 + 1e-5),
                "{law:?} ×{scale} +{bias}: ‖a‖ reached {worst}"
            );
            println!(
                "{law:?} ×{scale} +{bias}: window {:.4} cm, max {:.3} cm, max ‖a‖ {worst:.3}",
                100.0 * window(&r),
                100.0 * r.max_err_m
            );
            // Bars: 1.5 cm for the composite law, 15 cm for the gradient law, whose normalization
            // (ȧ divided by max(1, ‖W̃‖²/(2p))) slows it so much for features biased far from
            // nominal that it flies about as without adaptation; without the normalization
            // features 5× too large crash it (docs/adaptation.md).
            let bar = if law == AdaptationLaw::Composite {
                0.015
            } else {
                0.15
            };
            assert!(window(&r) <= bar, "{law:?} ×{scale} +{bias}: {r:?}");
        }
    }
}

/// Without an accelerometer the composite law differences the velocity; it still holds the
/// paper-spiral (the firmware's case).
#[test]
fn composite_without_an_accelerometer() {
    struct NoAccelerometer<C>(C);
    impl<C: Controller> Controller for NoAccelerometer<C> {
        fn name(&self) -> &str {
            self.0.name()
        }
        fn reset(&mut self) {
            self.0.reset();
        }
        fn step(&mut self, t: f64, s: &PlantState, r: &TrajectoryPoint, dt: f64) -> [f64; 4] {
            self.0.step(t, s, r, dt)
        }
    }
    let weights = repo(DEFAULT_WEIGHTS);
    let model = load_learned(&weights).expect("weights load");
    for name in ["paper-spiral", "rotor-loss-mid"] {
        let sc = scenario(name);
        let c = CoreController::new("c", model, gains_with(AdaptationLaw::Composite));
        let mut c = NoAccelerometer(c);
        let log = fly_scenario(&sc, &mut c);
        let r = Report::from_flight(&log, &sc, None);
        assert!(!r.crashed, "{name}: {r:?}");
        // Bars: 0.03 cm on paper-spiral, 0.95 cm on rotor-loss-mid, where the torque observer,
        // slowed for the attitude loop's margin, answers the fault late
        // (`COMPOSITE_Q_TORQUE`).
        let bar = if name == "paper-spiral" {
            0.0003
        } else {
            0.0095
        };
        assert!(window(&r) <= bar, "{name}: {:.6} m", window(&r));
    }
}

/// RotorPy's Crazyflie has a 72 ms motor lag: the composite law's assumed lag (50 ms) keeps it
/// stable there (with none assumed it crashes in 0.8 s).
#[test]
fn composite_holds_a_72_ms_motor_lag() {
    let mut sc = scenario("paper-spiral-realistic");
    sc.spec.effects.motor_tau_s = 0.072;
    let c = window(&fly("adaptive-composite", &sc));
    let g = window(&fly("adaptive-gradient", &sc));
    // Bars: at most 0.12 cm, and better than the gradient law on the same lag.
    assert!(
        c <= 0.0012 && c < g,
        "composite {c:.6} m, gradient {g:.6} m"
    );
}
