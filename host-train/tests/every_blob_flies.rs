//! Every blob the trainer writes flies the adaptive controller without
//! crashing. Here the stock vehicle (three training seeds on a small collected dataset); the
//! heavy vehicle the nominal model does not know is `vehicle_mismatch.rs` (three more seeds).
//! Run in release: `cargo test --release -p host-train --test every_blob_flies`.

use host_train::control::core_by_name;
use host_train::data::{CollectArgs, CollectConfig};
use host_train::fly::{fly_scenario, Report};
use host_train::pipeline::run_train;
use host_train::sim::Scenario;
use host_train::train::TrainConfig;
use std::path::Path;

fn scenario(name: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(format!("{name}.toml"));
    Scenario::load(&path).expect("scenario loads")
}

#[test]
fn three_seeds_on_the_stock_vehicle_fly_adaptive_no_worse_than_learned() {
    let dir = std::env::temp_dir().join(format!("hamflight-every-blob-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let args = CollectArgs {
        out: dir.join("data"),
        config: CollectConfig {
            realizations: 4,
            windows: 360,
            ..CollectConfig::default()
        },
    };
    host_train::data::run_collect(&args).expect("collect");
    let scenarios = [scenario("paper-spiral"), scenario("paper-spiral-realistic")];
    for seed in 0..3u64 {
        let cfg = TrainConfig {
            epochs: 12,
            batch: 128,
            seed,
            ..TrainConfig::default()
        };
        let out = dir.join(format!("seed-{seed}.hfw"));
        let r = run_train(&cfg, &args.out, &out, true).expect("train writes a blob");
        let check = r.flight_check.as_ref().expect("the flight check ran");
        assert!(check.passed(), "seed {seed}: {check:?}");
        for sc in &scenarios {
            let fly = |name: &str| -> Report {
                let mut c = core_by_name(name, Some(&out)).expect("controller");
                let log = fly_scenario(sc, c.as_mut());
                Report::from_log(&log, None)
            };
            let (a, l) = (fly("adaptive"), fly("learned"));
            let (ra, rl) = (a.rmse_pos_window_m, l.rmse_pos_window_m);
            eprintln!(
                "seed {seed} {}: adaptive {:.3} cm, learned {:.3} cm",
                sc.name,
                100.0 * ra.unwrap_or(f64::NAN),
                100.0 * rl.unwrap_or(f64::NAN)
            );
            assert!(
                !a.crashed,
                "seed {seed} {}: adaptive crashed {a:?}",
                sc.name
            );
            assert!(!l.crashed, "seed {seed} {}: learned crashed {l:?}", sc.name);
            assert!(
                ra.unwrap_or(f64::INFINITY) <= rl.unwrap_or(0.0),
                "seed {seed} {}: adaptive {ra:?} worse than learned {rl:?}",
                sc.name
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
