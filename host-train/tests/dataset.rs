//! Data collection: shapes, determinism, loader errors, and re-simulation of stored windows.

use std::path::PathBuf;

use host_train::dataset::{collect, load, CollectConfig, CSV_HEADER};
use host_train::plant::{Disturbance, Effects, Plant, VehicleParams};

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
        ..CollectConfig::default()
    }
}

#[test]
fn collected_data_has_the_documented_shape_and_resimulates() {
    let dir = tmpdir("shape");
    let cfg = small();
    let m = collect(&dir, &cfg).unwrap();
    assert_eq!(m.realizations.len(), 2);
    let text = std::fs::read_to_string(dir.join("realization_00.csv")).unwrap();
    assert_eq!(text.lines().next().unwrap(), CSV_HEADER);
    assert_eq!(text.lines().count(), 1 + 60 * 5);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["format"], "hamflight-dataset-v1");
    assert_eq!(manifest["sample_hz"], 240.0);
    assert_eq!(manifest["window_len"], 5);
    assert_eq!(manifest["mass_kg"], 0.027);
    assert_eq!(manifest["gravity_m_s2"], 9.8);
    assert_eq!(manifest["seed"], 7);
    assert_eq!(manifest["realizations"][1]["file"], "realization_01.csv");
    assert_eq!(manifest["realizations"][1]["windows"], 60);

    let ds = load(&dir).unwrap();
    let params = VehicleParams::cf2x();
    for r in &ds.realizations {
        let w = r.meta.wind_m_s2;
        assert_eq!(w[2], 0.0);
        assert!(w[..2].iter().all(|x| [0.25, 0.5].contains(&x.abs())));
        let d = r.meta.rotor_efficiency;
        assert!(d[..2].iter().all(|x| (0.94..=0.98).contains(x)) && d[2] == 1.0 && d[3] == 1.0);
        assert_eq!(r.windows.len(), 60);
        for (k, win) in r.windows.iter().enumerate() {
            assert_eq!(win.states.len(), 5);
            let u = params.nominal_wrench(win.rpm);
            assert_eq!(u, win.wrench);
            for i in 1..5 {
                assert!((win.t_s[i] - win.t_s[i - 1] - 1.0 / 240.0).abs() < 1e-9);
            }
            // Re-simulate every few windows from its first state with its stored command.
            if k % 7 == 0 {
                let dist = Disturbance {
                    wind_m_s2: r.meta.wind_m_s2,
                    rotor_efficiency: r.meta.rotor_efficiency,
                    ..Disturbance::default()
                };
                let mut plant = Plant::new(params.clone(), dist, Effects::default(), win.states[0]);
                plant.set_t_s(win.t_s[0]);
                for i in 1..5 {
                    for _ in 0..10 {
                        plant.step(win.rpm, 1.0 / 2400.0);
                    }
                    let (a, b) = (plant.state(), &win.states[i]);
                    let err = (a.p_m - b.p_m).norm()
                        + (a.rot - b.rot).norm()
                        + (a.v_body_m_s - b.v_body_m_s).norm()
                        + (a.w_body_rad_s - b.w_body_rad_s).norm();
                    assert!(err < 1e-12, "window {k} step {i}: {err}");
                }
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
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
    collect(&a, &cfg).unwrap();
    collect(&b, &cfg).unwrap();
    for f in ["manifest.json", "realization_00.csv"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap()
        );
    }
    let c = tmpdir("det-c");
    collect(&c, &CollectConfig { seed: 4, ..cfg }).unwrap();
    assert_ne!(
        std::fs::read(a.join("realization_00.csv")).unwrap(),
        std::fs::read(c.join("realization_00.csv")).unwrap()
    );
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn loader_errors_name_file_and_line() {
    let dir = tmpdir("bad");
    let cfg = CollectConfig {
        realizations: 1,
        windows: 4,
        poses: 1,
        ..CollectConfig::default()
    };
    collect(&dir, &cfg).unwrap();
    let f = dir.join("realization_00.csv");
    let text = std::fs::read_to_string(&f).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    lines[3] = lines[3].replacen(",", ",x", 3);
    std::fs::write(&f, lines.join("\n")).unwrap();
    let e = format!("{:#}", load(&dir).unwrap_err());
    assert!(
        e.contains("realization_00.csv") && e.contains("line 4"),
        "{e}"
    );
    std::fs::remove_file(dir.join("manifest.json")).unwrap();
    let e = format!("{:#}", load(&dir).unwrap_err());
    assert!(e.contains("manifest.json"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
