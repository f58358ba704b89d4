//! The rotor-loss set (`scenarios/rotor-loss-*.toml`, `scenarios/cf-rotor-loss-*.toml`): one
//! rotor to 55 % or 50 % at t = 10 s, 20 / 50 / 72 ms motor lag, steady wind, on the true state
//! and behind the Crazyflie's sensor chain; no crash under either law, a bounded recovery; the
//! composite law's answer to rotor-loss-mid; and the default law against the paper's on every
//! scenario. The figures: docs/adaptation.md, "Rotor loss" (`cargo run --release -p host-train
//! --example adaptation_table -- --rotor-loss`).

mod flight_common;

use flight_common::{fly, repo, scenario};
use host_train::fly::eval::Report;
use host_train::pipeline::vehicle_study::{self, VehicleStudyArgs};
use host_train::sim::scenario::Scenario;

const LAWS: [&str; 2] = ["adaptive-gradient", "adaptive-composite"];

/// The rotor-loss set's twelve scenario names.
fn rotor_loss_set() -> Vec<String> {
    let mut names = Vec::new();
    for chain in ["", "cf-"] {
        for share in [55, 50] {
            for lag in [20, 50, 72] {
                names.push(format!("{chain}rotor-loss-{share}-lag{lag}"));
            }
        }
    }
    names
}

fn recovery(r: &Report) -> Option<f64> {
    r.events.first().and_then(|e| e.recovery_s)
}

fn peak(r: &Report) -> f64 {
    r.events.first().map_or(f64::NAN, |e| e.peak_err_m)
}

/// No crash under either law anywhere in the set, and on the true state every flight is back
/// within 1 cm of the path inside a bound (the chain's own estimate error keeps some of its
/// flights above 1 cm for good, so there the bar is the peak).
#[test]
fn every_rotor_loss_is_survived_by_both_laws() {
    for name in rotor_loss_set() {
        let sc = scenario(&name);
        assert_eq!(sc.disturbance().efficiency_onset_s, 10.0, "{name}");
        for law in LAWS {
            // `fly` fails on a crash.
            let r = fly(law, &sc);
            let (pk, rec) = (peak(&r), recovery(&r));
            println!(
                "{name:24} {law:20} peak {:.2} cm, recovery {rec:?} s",
                pk * 100.0
            );
            // Measured: peak ≤ 28.7 cm (gradient, 50 %, 72 ms, true state), ≤ 34.7 cm with the
            // chain; the composite law ≤ 8.3 / 22.2 cm.
            let peak_bar = if law == "adaptive-composite" {
                0.34
            } else {
                0.52
            };
            assert!(pk <= peak_bar, "{name} {law}: peak {pk:.3} m");
            if !name.starts_with("cf-") {
                let rec = rec.unwrap_or_else(|| panic!("{name} {law}: never back within 1 cm"));
                let rec_bar = if law == "adaptive-composite" {
                    1.8
                } else {
                    5.5
                };
                assert!(rec <= rec_bar, "{name} {law}: recovery {rec:.2} s");
            }
        }
    }
}

/// The composite law's fault answer with its change detector: rotor-loss-mid (rotor 4 to 60 %
/// at t = 12 s) within 0.52 cm over t ≥ 5 s, peak ≤ 3.5 cm, back within 1 cm inside 0.8 s; the
/// attitude margins with the chain at 70 ms stay asserted in `sensor_chain.rs`.
#[test]
fn rotor_loss_mid_composite_recovers_fast() {
    let sc = scenario("rotor-loss-mid");
    let r = fly("adaptive-composite", &sc);
    let w = r.rmse_pos_window_m.expect("window scored");
    let rec = recovery(&r).expect("recovers");
    println!(
        "rotor-loss-mid composite: RMSE {:.3} cm, peak {:.2} cm, recovery {rec:.2} s",
        w * 100.0,
        peak(&r) * 100.0
    );
    assert!(w <= 0.0052, "RMSE {w:.5} m");
    assert!(peak(&r) <= 0.035, "peak {:.4} m", peak(&r));
    assert!(rec <= 0.8, "recovery {rec:.2} s");
}

/// The default law (the composite one) against the paper's gradient law on every scenario of
/// `scenarios/` flown with the shipped blob: never worse by more than max(1.5×, 0.05 cm), and
/// never a crash where the paper's law flies; one exception, bounded: `diamond`, a fast path
/// with no disturbance and no motor lag in the plant, where the composite law's prediction
/// assumes the blob's 50 ms lag (0.251 cm against 0.039 cm measured; 0.060 cm with the
/// plant's lag assumed). The `bl-*` scenarios (the brushless benchmark vehicle, 45 g) are left
/// out: the shipped blob describes a 27 g vehicle, and they are flown with a blob of their own.
#[test]
fn the_default_law_is_never_much_worse_than_the_paper_law() {
    let dir = repo("scenarios");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .expect("scenarios/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| {
            !p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("bl-"))
        })
        .collect();
    paths.sort();
    assert!(paths.len() >= 40, "{} scenarios", paths.len());
    for p in paths {
        let sc = Scenario::load(&p).expect("scenario loads");
        let d = fly("adaptive", &sc);
        let g = fly("adaptive-gradient", &sc);
        let (d, g) = (
            d.rmse_pos_window_m.expect("scored"),
            g.rmse_pos_window_m.expect("scored"),
        );
        println!(
            "{:28} default {:.3} cm, gradient {:.3} cm",
            sc.name,
            d * 100.0,
            g * 100.0
        );
        let bar = if sc.name == "diamond" {
            0.0035
        } else {
            (1.5 * g).max(g + 0.0005)
        };
        assert!(
            d <= bar,
            "{}: default {d:.5} m against the paper's law {g:.5} m",
            sc.name
        );
    }
}

/// With a blob learned on another vehicle (the light, 70 ms vehicle of `vehicle-study`), the
/// hardest rotor loss of the set on that vehicle is survived by both laws.
#[test]
fn a_blob_learned_on_another_vehicle_survives_the_rotor_loss() {
    let out = std::env::temp_dir().join(format!("hamflight-rotor-loss-{}", std::process::id()));
    let args = VehicleStudyArgs {
        seeds: 1,
        no_lag_comparison: true,
        epochs: 12,
        flight_s: 8.0,
        vehicle: "light".into(),
        rotor_loss: Some(repo("scenarios/light-rotor-loss-55.toml")),
        ..VehicleStudyArgs::new(&out)
    };
    let r = vehicle_study::run(&args).expect("study runs");
    println!("{}", vehicle_study::table(&r));
    let loss: Vec<_> = r
        .flights
        .iter()
        .filter(|f| f.scenario == "light-rotor-loss-55" && f.controller.contains("adaptive"))
        .collect();
    for law in ["adaptive-gradient", "adaptive-composite"] {
        assert!(
            loss.iter().any(|f| f.controller == law),
            "{law} flew the rotor loss: {loss:?}"
        );
    }
    for f in loss {
        assert!(!f.crashed, "{f:?}");
    }
    let _ = std::fs::remove_dir_all(&out);
}
