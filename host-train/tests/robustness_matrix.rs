//! The robustness matrix's guarded cells: with the blob's motor lag matching the plant's (0, 20,
//! 50, 80 ms), both shipped laws fly calm-spiral with 0 and 8 ms of added command delay, with and
//! without 6 ms of jitter, with no crash and no limit cycle. The full matrix, the mismatched
//! cells and the delay margins: `host-train robustness` (docs/envelope.md).

use host_train::pipeline::{
    fly_robustness_cell as fly_cell, load_robustness_scenario as load_scenario,
};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn matched_lags_fly_8_ms_of_delay_and_6_ms_of_jitter_without_a_limit_cycle() {
    let weights = root().join("weights/default.hfw");
    let sc = load_scenario(&root().join("scenarios"), "calm-spiral", 10.0).expect("scenario");
    let mut failures = Vec::new();
    for law in ["adaptive", "adaptive-gradient"] {
        for lag_ms in [0.0, 20.0, 50.0, 80.0] {
            for (delay_ms, jitter_ms) in [(0.0, 0.0), (8.0, 0.0), (8.0, 6.0)] {
                let (s, _) = fly_cell(&weights, law, &sc, lag_ms, lag_ms, delay_ms, jitter_ms)
                    .expect("flies");
                if s.crashed || s.limit_cycle || s.rmse_m > 0.05 {
                    failures.push(format!(
                        "{law} lag {lag_ms} ms delay {delay_ms}+{jitter_ms} ms: {s:?}"
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn the_delay_line_delays_the_commands() {
    let weights = root().join("weights/default.hfw");
    let sc = load_scenario(&root().join("scenarios"), "calm-spiral", 4.0).expect("scenario");
    let (_, a) = fly_cell(&weights, "adaptive", &sc, 20.0, 20.0, 0.0, 0.0).expect("flies");
    let (_, b) = fly_cell(&weights, "adaptive", &sc, 20.0, 20.0, 8.0, 0.0).expect("flies");
    let (_, c) = fly_cell(&weights, "adaptive", &sc, 20.0, 20.0, 8.0, 6.0).expect("flies");
    let differ = |x: &[f64], y: &[f64]| x.iter().zip(y).any(|(p, q)| (p - q).abs() > 1e-9);
    assert!(differ(&a.err_m, &b.err_m), "8 ms of delay changed nothing");
    assert!(differ(&b.err_m, &c.err_m), "6 ms of jitter changed nothing");
}

/// The motor-lag watch (`Gains::lag_watch`, on by default) on the cells a wrong stated lag
/// breaks: each fails without it (crash or limit cycle) and flies with it.
#[test]
fn the_lag_watch_flies_the_mismatched_cells() {
    use host_train::pipeline::fly_robustness_cell_watched as watched;
    let weights = root().join("weights/default.hfw");
    let sc = load_scenario(&root().join("scenarios"), "hover", 6.0).expect("scenario");
    // (plant lag, blob lag, delay, jitter) ms.
    let cells = [
        (80.0, 0.0, 8.0, 6.0),
        (0.0, 80.0, 8.0, 0.0),
        (20.0, 80.0, 8.0, 0.0),
        (0.0, 50.0, 8.0, 6.0),
    ];
    let mut failures = Vec::new();
    for law in ["adaptive", "adaptive-gradient"] {
        for (pl, bl, d, j) in cells {
            let fly = |on| {
                watched(&weights, law, &sc, (pl, bl), d, j, on)
                    .expect("flies")
                    .0
            };
            let (off, on) = (fly(false), fly(true));
            println!("{law} plant {pl} blob {bl} delay {d}+{j}: off {off:?}, on {on:?}");
            if law == "adaptive" && !off.failed() {
                failures.push(format!(
                    "{law} {pl}/{bl} {d}+{j}: fails no more without the watch"
                ));
            }
            if on.failed() || on.rmse_m > 0.02 {
                failures.push(format!("{law} {pl}/{bl} {d}+{j} with the watch: {on:?}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
