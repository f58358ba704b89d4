//! The dataset format and data collection: shapes, determinism, loader errors, re-simulation of
//! stored flights with their per-step commands, the paper's windows, splits at gaps.

use std::path::PathBuf;

use host_train::data::{collect_dataset, CollectConfig};
use host_train::io::{
    dataset_windows, load_dataset, sample_segments, save_dataset, Dataset, WindowSpec,
    DATASET_CSV_HEADER, DATASET_FORMAT, DATASET_FORMAT_V1,
};
use host_train::sim::{Disturbance, Effects, Plant, VehicleParams};

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "hamflight-ds-{tag}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn small() -> CollectConfig {
    CollectConfig {
        realizations: 2,
        windows: 60,
        poses: 3,
        seed: 7,
        calm_realizations: 0,
        ..CollectConfig::default()
    }
}

/// The default collection ends with a calm realization (calm-air identifiability,
/// docs/training.md): no wind, rotors at 100 %, marked disturbance-free; the disturbed ones before
/// it are unchanged by it.
#[test]
fn default_collection_adds_a_calm_disturbance_free_realization() {
    let (with, without) = (tmpdir("calm-1"), tmpdir("calm-0"));
    let one = CollectConfig {
        calm_realizations: 1,
        ..small()
    };
    assert_eq!(CollectConfig::default().calm_realizations, 1);
    let m = collect_dataset(&with, &one).unwrap();
    collect_dataset(&without, &small()).unwrap();
    assert_eq!(m.realizations.len(), 3);
    let ds = load_dataset(&with).unwrap();
    let calm = &ds.realizations[2].meta;
    assert!(calm.disturbance_free);
    assert_eq!(calm.wind_m_s2, Some([0.0; 3]));
    assert_eq!(calm.rotor_efficiency, Some([1.0; 4]));
    assert!(ds.realizations[..2]
        .iter()
        .all(|r| !r.meta.disturbance_free));
    for f in ["realization_00.csv", "realization_01.csv"] {
        assert_eq!(
            std::fs::read(with.join(f)).unwrap(),
            std::fs::read(without.join(f)).unwrap()
        );
    }
    std::fs::remove_dir_all(&with).ok();
    std::fs::remove_dir_all(&without).ok();
}

#[test]
fn collected_data_has_the_documented_shape_and_resimulates() {
    let dir = tmpdir("shape");
    let cfg = small();
    let m = collect_dataset(&dir, &cfg).unwrap();
    assert_eq!(m.realizations.len(), 2);
    let text = std::fs::read_to_string(dir.join("realization_00.csv")).unwrap();
    assert_eq!(text.lines().next().unwrap(), DATASET_CSV_HEADER);
    // 3 flights (poses) of 20 windows of 4 steps: 81 samples each.
    assert_eq!(text.lines().count(), 1 + 3 * 81);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["format"], DATASET_FORMAT);
    assert_eq!(manifest["sample_hz"], 240.0);
    assert_eq!(manifest["mass_kg"], 0.027);
    assert_eq!(manifest["gravity_m_s2"], 9.8);
    assert_eq!(manifest["source"], "collect");
    assert_eq!(manifest["seed"], 7);
    assert_eq!(manifest["realizations"][1]["file"], "realization_01.csv");
    assert_eq!(manifest["realizations"][1]["flights"], 3);
    assert_eq!(manifest["realizations"][1]["samples"], 243);
    assert_eq!(manifest["realizations"][1]["disturbance_free"], false);

    let ds = load_dataset(&dir).unwrap();
    // The paper's windows: 5 states every 4 samples, one held command each, 60 per realization.
    let at = dataset_windows(&ds, WindowSpec::default()).unwrap();
    assert_eq!(at.len(), 120);
    for w in &at {
        let s = &ds.realizations[w.realization].flights[w.flight].samples[w.start..w.start + 5];
        assert!(s[..4]
            .iter()
            .all(|x| x.wrench == s[0].wrench && x.rpm == s[0].rpm));
    }
    let params = VehicleParams::cf2x();
    for r in &ds.realizations {
        let w = r.meta.wind_m_s2.unwrap();
        assert_eq!(w[2], 0.0);
        assert!(w[..2].iter().all(|x| [0.25, 0.5].contains(&x.abs())));
        let d = r.meta.rotor_efficiency.unwrap();
        assert!(d[..2].iter().all(|x| (0.94..=0.98).contains(x)) && d[2] == 1.0 && d[3] == 1.0);
        assert_eq!(r.flights.len(), 3);
        for flight in &r.flights {
            assert_eq!(sample_segments(&flight.samples, 240.0), vec![0..81]);
            for (k, pair) in flight.samples.windows(2).enumerate() {
                let (a, b) = (&pair[0], &pair[1]);
                assert!((b.t_s - a.t_s - 1.0 / 240.0).abs() < 1e-9);
                let rpm = a.rpm.unwrap();
                assert_eq!(params.nominal_wrench(rpm), a.wrench);
                // Re-simulate every few steps from the stored state with its own command.
                if k % 7 == 0 {
                    let dist = Disturbance {
                        wind_m_s2: w,
                        rotor_efficiency: d,
                        ..Disturbance::default()
                    };
                    let mut plant = Plant::new(params.clone(), dist, Effects::default(), a.state);
                    plant.set_t_s(a.t_s);
                    for _ in 0..10 {
                        plant.step(rpm, 1.0 / 2400.0);
                    }
                    let (x, y) = (plant.state(), &b.state);
                    let err = (x.p_m - y.p_m).norm()
                        + (x.rot - y.rot).norm()
                        + (x.v_body_m_s - y.v_body_m_s).norm()
                        + (x.w_body_rad_s - y.w_body_rad_s).norm();
                    assert!(err < 1e-12, "step {k}: {err}");
                }
            }
        }
    }
    // save ∘ load is the identity: the CSVs bit for bit; the manifest's numbers to the last
    // digits (serde_json's default float parser is not always correctly rounded).
    let again = tmpdir("again");
    save_dataset(&again, &ds).unwrap();
    for f in ["realization_00.csv", "realization_01.csv"] {
        assert_eq!(
            std::fs::read(dir.join(f)).unwrap(),
            std::fs::read(again.join(f)).unwrap(),
            "{f}"
        );
    }
    let back = load_dataset(&again).unwrap();
    for (a, b) in back.realizations.iter().zip(&ds.realizations) {
        assert_eq!(a.flights, b.flights);
        assert_eq!(
            (a.meta.flights, a.meta.samples),
            (b.meta.flights, b.meta.samples)
        );
        let (ea, eb) = (
            a.meta.rotor_efficiency.unwrap(),
            b.meta.rotor_efficiency.unwrap(),
        );
        assert!(ea.iter().zip(&eb).all(|(x, y)| (x - y).abs() < 1e-15));
    }
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&again).ok();
}

#[test]
fn collection_is_deterministic_for_a_seed() {
    let (a, b) = (tmpdir("det-a"), tmpdir("det-b"));
    let cfg = CollectConfig {
        realizations: 1,
        windows: 20,
        poses: 2,
        seed: 3,
        ..CollectConfig::default()
    };
    collect_dataset(&a, &cfg).unwrap();
    collect_dataset(&b, &cfg).unwrap();
    for f in ["manifest.json", "realization_00.csv"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap()
        );
    }
    let c = tmpdir("det-c");
    collect_dataset(&c, &CollectConfig { seed: 4, ..cfg }).unwrap();
    assert_ne!(
        std::fs::read(a.join("realization_00.csv")).unwrap(),
        std::fs::read(c.join("realization_00.csv")).unwrap()
    );
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

fn one_flight_dataset() -> (PathBuf, Dataset) {
    let dir = tmpdir("one");
    let cfg = CollectConfig {
        realizations: 1,
        windows: 10,
        poses: 1,
        calm_realizations: 0,
        ..CollectConfig::default()
    };
    collect_dataset(&dir, &cfg).unwrap();
    let ds = load_dataset(&dir).unwrap();
    (dir, ds)
}

#[test]
fn gaps_and_backward_timestamps_split_a_flight_and_flags_cut_windows() {
    let (dir, mut ds) = one_flight_dataset();
    let n = ds.realizations[0].flights[0].samples.len();
    assert_eq!(n, 41);
    let spec = |len, stride| WindowSpec { len, stride };
    assert_eq!(dataset_windows(&ds, spec(5, 4)).unwrap().len(), 10);
    assert_eq!(dataset_windows(&ds, spec(5, 1)).unwrap().len(), 37);
    assert_eq!(dataset_windows(&ds, spec(9, 8)).unwrap().len(), 5);
    assert!(dataset_windows(&ds, spec(1, 1)).is_err());
    assert!(dataset_windows(&ds, spec(5, 0)).is_err());
    {
        let s = &mut ds.realizations[0].flights[0].samples;
        // A gap of one missing sample after sample 12, and a backwards timestamp at 30.
        for x in s.iter_mut().skip(13) {
            x.t_s += 1.0 / 240.0;
        }
        s[30].t_s = s[29].t_s - 1e-4;
    }
    let seg = sample_segments(&ds.realizations[0].flights[0].samples, 240.0);
    assert_eq!(seg, vec![0..13, 13..30, 30..31, 31..41]);
    // 13 → 3 windows, 17 → 4, 1 → 0, 10 → 2.
    assert_eq!(dataset_windows(&ds, spec(5, 4)).unwrap().len(), 9);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn loader_errors_name_file_and_line() {
    let (dir, _) = one_flight_dataset();
    let f = dir.join("realization_00.csv");
    let text = std::fs::read_to_string(&f).unwrap();
    let good: Vec<String> = text.lines().map(String::from).collect();
    let with_line = |k: usize, line: String| {
        let mut l = good.clone();
        l[k] = line;
        std::fs::write(&f, l.join("\n") + "\n").unwrap();
        format!("{:#}", load_dataset(&dir).unwrap_err())
    };
    let e = with_line(3, good[3].replacen(',', ",x", 3));
    assert!(
        e.contains("realization_00.csv") && e.contains("line 4"),
        "{e}"
    );
    // Not a rotation: r11 scaled.
    let mut cols: Vec<String> = good[5].split(',').map(String::from).collect();
    cols[5] = "2.0".into();
    let e = with_line(5, cols.join(","));
    assert!(e.contains("line 6") && e.contains("not a rotation"), "{e}");
    // Flight index jumps back.
    let mut cols: Vec<String> = good[7].split(',').map(String::from).collect();
    cols[0] = "3".into();
    let e = with_line(7, cols.join(","));
    assert!(e.contains("line 8") && e.contains("out of order"), "{e}");
    let e = with_line(0, "flight,t_s".into());
    assert!(e.contains("line 1") && e.contains("header"), "{e}");
    std::fs::write(&f, &text).unwrap();
    load_dataset(&dir).unwrap();

    let mpath = dir.join("manifest.json");
    let manifest = std::fs::read_to_string(&mpath).unwrap();
    std::fs::write(&mpath, manifest.replace(DATASET_FORMAT, DATASET_FORMAT_V1)).unwrap();
    let e = format!("{:#}", load_dataset(&dir).unwrap_err());
    assert!(
        e.contains("manifest.json") && e.contains("no longer read") && e.contains("collect"),
        "{e}"
    );
    std::fs::remove_file(&mpath).unwrap();
    let e = format!("{:#}", load_dataset(&dir).unwrap_err());
    assert!(e.contains("manifest.json"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
