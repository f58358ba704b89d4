//! uSD-card deck logs and `host-train import`: the SITL writes version-2 logs and the importer
//! reads back exactly the logged values; every truncation, a flipped CRC byte and an unknown
//! event give the documented error or count and never a panic; a seeded randomized/mutation run
//! over the decoder; CSV import errors name the line; disturbance-free flights train with
//! a_j = 0. Run in release: `cargo test --release -p host-train --test usd_import`.

use std::path::Path;

use host_train::data::{airborne_flights, decode_csv, decode_usd, run_import, ImportArgs};
use host_train::fly::usd_logged_vars;
use host_train::io::{
    crc32, parse_usd, EventType, ParseOptions, UsdError, UsdWriter, Var, VarType,
    FIXED_FREQUENCY_ID, LEE_COMMAND_VARS,
};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod logs;
use logs::{args, csv_of, fix_crc, sitl_log, small_log, tmpdir};

#[test]
fn sitl_usd_log_round_trips_exactly() {
    let (bytes, rows) = sitl_log("paper-spiral-realistic", 2.0);
    // 500 Hz for 2 s: ticks 0..999 (the last tick only scores).
    assert_eq!(rows.len(), 1000);
    let (log, rep) = parse_usd(&bytes, ParseOptions::default()).unwrap();
    assert!(rep.crc_ok);
    assert_eq!(log.version, 2);
    assert_eq!(log.event_types.len(), 1);
    let et = &log.event_types[0];
    assert_eq!(et.id, FIXED_FREQUENCY_ID);
    assert_eq!(et.name, "fixedFrequency");
    let names: Vec<&str> = et.vars.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, usd_logged_vars());
    assert_eq!(names.len(), 20);
    assert!(et.vars.iter().all(|v| v.ty == VarType::F32));
    assert_eq!(log.events.len(), rows.len());
    for (ev, (t_us, vals)) in log.events.iter().zip(&rows) {
        assert_eq!(ev.timestamp_us, *t_us);
        assert_eq!(ev.values.as_slice(), vals.as_slice());
    }
    // The header is byte-exact: `name(f)\0` per variable, as the deck writes it.
    let needle = b"stateEstimate.qw(f)\0";
    assert!(bytes.windows(needle.len()).any(|w| w == needle));

    // The importer converts Bitcraze's conventions back to the plant's state.
    let d = decode_usd(
        Path::new("sitl.bin"),
        &bytes,
        &LEE_COMMAND_VARS.map(String::from),
        &[],
        ParseOptions::default(),
    )
    .unwrap();
    assert_eq!(d.samples.len(), rows.len());
    assert_eq!(d.skipped_events, 0);
    let deg = std::f64::consts::PI / 180.0;
    for (s, (t_us, v)) in d.samples.iter().zip(&rows) {
        assert_eq!(s.t_s, *t_us as f64 * 1e-6);
        assert_eq!(
            [s.state.p_m.x, s.state.p_m.y, s.state.p_m.z],
            [v[0], v[1], v[2]]
        );
        let v_world = s.state.rot * s.state.v_body_m_s;
        for k in 0..3 {
            assert!((v_world[k] - v[3 + k]).abs() < 1e-6, "{v_world} {v:?}");
            assert!((s.state.w_body_rad_s[k] - v[10 + k] * deg).abs() < 1e-12);
        }
        assert_eq!(s.wrench, [v[13], v[14], v[15], v[16]]);
        let acc = s.acc_body_m_s2.unwrap();
        assert!((acc[2] - v[19] * 9.81).abs() < 1e-12);
        // The rotation's third column matches the quaternion's.
        let (x, y, z, w) = (v[6], v[7], v[8], v[9]);
        let r13 = 2.0 * (x * z + w * y);
        assert!((s.state.rot[(0, 2)] - r13).abs() < 1e-5);
    }
}

#[test]
fn every_truncation_and_flipped_crc_byte_gives_the_documented_error() {
    let bytes = small_log();
    let (log, _) = parse_usd(&bytes, ParseOptions::default()).unwrap();
    assert_eq!(log.events.len(), 7);
    assert_eq!(log.events[3].values, vec![42.0]);
    assert_eq!(log.events[5].values, vec![2.0, -4.0, 200.0]);
    for n in 0..bytes.len() {
        let e = parse_usd(&bytes[..n], ParseOptions::default()).unwrap_err();
        let documented = matches!(
            e,
            UsdError::TooShort { .. }
                | UsdError::TruncatedHeader { .. }
                | UsdError::CrcMismatch { .. }
                | UsdError::BadName { .. }
        );
        assert!(documented, "prefix {n}: {e:?}");
        assert!(e.to_string().starts_with("byte "), "{e}");
        // Decoding anyway yields a prefix of the events, or a documented error.
        let lax = ParseOptions {
            allow_bad_crc: true,
        };
        if let Ok((l, rep)) = parse_usd(&bytes[..n], lax) {
            assert!(!rep.crc_ok || n == bytes.len());
            assert!(l.events.len() <= log.events.len());
            for (a, b) in l.events.iter().zip(&log.events) {
                assert!(a == b || a.offset + 4 > n - 4, "prefix {n}");
            }
        }
    }
    for k in 1..=4 {
        let mut b = bytes.clone();
        let at = b.len() - k;
        b[at] ^= 0x5a;
        match parse_usd(&b, ParseOptions::default()) {
            Err(UsdError::CrcMismatch {
                offset,
                stored,
                computed,
            }) => {
                assert_eq!(offset, bytes.len() - 4);
                assert_ne!(stored, computed);
            }
            other => panic!("flipped CRC byte {k}: {other:?}"),
        }
    }
    let e = parse_usd(&bytes[..bytes.len() - 3], ParseOptions::default()).unwrap_err();
    assert!(e.to_string().contains("CRC mismatch"), "{e}");
}

#[test]
fn unknown_event_types_are_skipped_and_counted_and_undeclared_ids_rejected() {
    let (bytes, _) = sitl_log("hover", 0.2);
    // Add a declared event type the importer does not use, with three events.
    let (log, _) = parse_usd(&bytes, ParseOptions::default()).unwrap();
    let mut types = log.event_types.clone();
    types.push(EventType {
        id: 3,
        name: "estTDOA".into(),
        vars: vec![Var {
            name: "x".into(),
            ty: VarType::F16,
        }],
    });
    let mut w = UsdWriter::new(types);
    for (k, ev) in log.events.iter().enumerate() {
        w.event(0, ev.timestamp_us, &ev.values);
        if k % 30 == 0 {
            w.event(1, ev.timestamp_us, &[1.5]);
        }
    }
    let bytes2 = w.finish();
    let d = decode_usd(
        Path::new("x.bin"),
        &bytes2,
        &LEE_COMMAND_VARS.map(String::from),
        &[],
        ParseOptions::default(),
    )
    .unwrap();
    assert_eq!(d.samples.len(), log.events.len());
    assert_eq!(d.skipped_events, log.events.len().div_ceil(30));
    let (l2, _) = parse_usd(&bytes2, ParseOptions::default()).unwrap();
    assert_eq!(l2.events[1].values, vec![1.5]);

    // An id the header does not declare: the error names its offset.
    let (log, _) = parse_usd(&small_log(), ParseOptions::default()).unwrap();
    let at = log.events[1].offset;
    let mut b = small_log();
    b[at] = 0x34;
    b[at + 1] = 0x12;
    fix_crc(&mut b);
    assert_eq!(
        parse_usd(&b, ParseOptions::default()).unwrap_err(),
        UsdError::UndeclaredEvent {
            offset: at,
            id: 0x1234
        }
    );
    // A missing variable is named.
    let e = decode_usd(
        Path::new("small.bin"),
        &small_log(),
        &LEE_COMMAND_VARS.map(String::from),
        &[],
        ParseOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("small.bin") && e.contains("stateEstimate.x") && e.contains("lacks"),
        "{e}"
    );
}

#[test]
fn randomized_and_mutated_logs_never_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x05d_10c);
    let (sitl, _) = sitl_log("hover", 0.1);
    let seeds = [small_log(), sitl];
    let cmd = LEE_COMMAND_VARS.map(String::from);
    let (mut ok, mut err) = (0usize, 0usize);
    for i in 0..6000 {
        let base = &seeds[i % seeds.len()];
        let mut b = base.clone();
        match rng.gen_range(0..6) {
            0 => {
                let n = rng.gen_range(0..64);
                b = (0..n).map(|_| rng.gen()).collect();
                if rng.gen() && !b.is_empty() {
                    b[0] = 0xBC;
                }
            }
            1 => {
                for _ in 0..rng.gen_range(1..8) {
                    let k = rng.gen_range(0..b.len());
                    b[k] ^= 1 << rng.gen_range(0..8);
                }
            }
            2 => {
                let k = rng.gen_range(0..b.len());
                b.truncate(k);
            }
            3 => {
                let k = rng.gen_range(0..b.len());
                for _ in 0..rng.gen_range(1..16) {
                    b.insert(k, rng.gen());
                }
            }
            4 => {
                let k = rng.gen_range(0..b.len());
                let n = rng.gen_range(1..16).min(b.len() - k);
                b.drain(k..k + n);
            }
            _ => {
                // Header fields: counts, ids, type characters.
                let k = rng.gen_range(0..b.len().min(400));
                b[k] = *[0u8, 0xff, b'(', b')', b'f', b'x', 1, 200]
                    .get(rng.gen_range(0..8))
                    .unwrap_or(&0);
            }
        }
        if rng.gen_bool(0.7) {
            fix_crc(&mut b);
        }
        let lax = ParseOptions {
            allow_bad_crc: rng.gen(),
        };
        match parse_usd(&b, lax) {
            Ok(_) => ok += 1,
            Err(e) => {
                assert!(e.to_string().starts_with("byte "), "{e}");
                err += 1;
            }
        }
        let _ = decode_usd(Path::new("fuzz.bin"), &b, &cmd, &[], lax);
        let _ = decode_csv(Path::new("fuzz.csv"), &b, Some(12));
    }
    eprintln!("6000 inputs: {ok} decoded, {err} rejected");
    assert!(ok > 500 && err > 500, "{ok} decoded, {err} rejected");
}

#[test]
fn import_writes_airborne_flights_and_csv_errors_name_the_line() {
    let dir = tmpdir("import");
    let (bytes, rows) = sitl_log("paper-spiral-realistic", 3.0);
    let usd = dir.join("flight.bin");
    std::fs::write(&usd, &bytes).unwrap();
    let csv = dir.join("flight.csv");
    std::fs::write(&csv, csv_of(&rows)).unwrap();
    let out = dir.join("data");
    let mut a = args(&out);
    a.logs = vec![usd.clone()];
    a.calm = vec![csv.clone()];
    let files = run_import(&a).unwrap();
    assert_eq!(files.len(), 2);
    // 1500 samples (t = 0 … 2.998 s), 0.5 s trimmed at both ends: 1000 kept.
    assert_eq!(files[0].samples_in, 1500);
    assert_eq!(files[0].samples_kept, 1000);
    assert_eq!(files[0].flights, 1);
    assert!(files[1].disturbance_free);
    let ds = host_train::io::load_dataset(&out).unwrap();
    assert!((ds.manifest.sample_hz - 500.0).abs() < 1e-6);
    assert_eq!(ds.manifest.source, "import");
    assert!(ds.realizations[1].meta.disturbance_free);
    assert!(!ds.realizations[0].meta.disturbance_free);
    // The CSV's commands were held over the rows that left them empty.
    let f = &ds.realizations[1].flights[0].samples;
    assert_eq!(f[1].wrench, f[0].wrench);
    let w = host_train::io::dataset_windows(&ds, Default::default()).unwrap();
    assert_eq!(w.len(), 2 * 249);

    // Ground: samples below the minimum height are excluded.
    let mut high = args(&dir.join("high"));
    high.logs = vec![usd.clone()];
    high.min_height_m = 10.0;
    let e = format!("{:#}", run_import(&high).unwrap_err());
    assert!(e.contains("flight.bin") && e.contains("no airborne"), "{e}");
    assert!(!dir.join("high/manifest.json").exists());

    // Bad CSV: the error names the file and line, and nothing is written.
    let text = csv_of(&rows);
    let mut lines: Vec<&str> = text.lines().collect();
    let broken = lines[7].replacen(',', ",oops", 1);
    lines[7] = &broken;
    std::fs::write(&csv, lines.join("\n")).unwrap();
    let mut b = args(&dir.join("bad"));
    b.logs = vec![usd.clone(), csv.clone()];
    let e = format!("{:#}", run_import(&b).unwrap_err());
    assert!(e.contains("flight.csv") && e.contains("line 8"), "{e}");
    assert!(!dir.join("bad").exists());
    // A flipped CRC byte in the uSD file is reported with the file and offset.
    let mut c = bytes.clone();
    let n = c.len();
    c[n - 1] ^= 1;
    std::fs::write(&usd, &c).unwrap();
    let e = format!("{:#}", run_import(&b).unwrap_err());
    assert!(
        e.contains("flight.bin") && e.contains(&format!("byte {}", n - 4)) && e.contains("CRC"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn disturbance_free_flights_train_with_a_pinned_to_zero() {
    let dir = tmpdir("calm");
    let (windy, _) = sitl_log("hover-wind", 4.0);
    let (calm, _) = sitl_log("hover", 4.0);
    std::fs::write(dir.join("windy.bin"), windy).unwrap();
    std::fs::write(dir.join("calm.bin"), calm).unwrap();
    let out = dir.join("data");
    let mut a = args(&out);
    a.logs = vec![dir.join("windy.bin")];
    a.calm = vec![dir.join("calm.bin")];
    run_import(&a).unwrap();
    // Two epochs on 4 s of hover identify no inertia (J comes out several times the stock
    // one): the flight check may refuse to fly such a model (its gradient law can crash on the
    // rotor loss), and this test is about the calm flight's a, not about flying.
    let cfg = host_train::train::TrainConfig {
        epochs: 2,
        batch: 64,
        flight_check: false,
        ..Default::default()
    };
    let r = host_train::pipeline::run_train(&cfg, &out, &dir.join("w.hfw"), true).unwrap();
    assert_eq!(r.realizations.len(), 2);
    assert!(r.realizations[1].disturbance_free);
    assert!(
        r.realizations[1].a.iter().all(|&x| x == 0.0),
        "{:?}",
        r.realizations[1].a
    );
    assert!(r.realizations[0].a.iter().any(|&x| x != 0.0));
    assert!(r.realizations[0].true_wind_m_s2.is_none());
    std::fs::remove_dir_all(&dir).ok();
}

#[derive(clap::Parser)]
struct EvalCli {
    #[command(flatten)]
    eval: host_train::fly::EvalArgs,
}

#[test]
fn eval_log_usd_writes_a_log_that_imports() {
    use clap::Parser;
    let dir = tmpdir("cli");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/hover.toml");
    let log = dir.join("hover.bin");
    let cli = EvalCli::parse_from([
        "eval".as_ref(),
        "--scenario".as_ref(),
        scenario.as_os_str(),
        "--controller".as_ref(),
        "geometric".as_ref(),
        "--out".as_ref(),
        dir.join("eval").as_os_str(),
        "--log-usd".as_ref(),
        log.as_os_str(),
    ] as [&std::ffi::OsStr; 9]);
    let report = host_train::fly::run_eval(&cli.eval).unwrap();
    assert!(!report.crashed);
    let bytes = std::fs::read(&log).unwrap();
    let (l, rep) = parse_usd(&bytes, ParseOptions::default()).unwrap();
    assert!(rep.crc_ok);
    // 10 s at 500 Hz: one event per controller step.
    assert_eq!(l.events.len(), 5000);
    let mut a = args(&dir.join("data"));
    a.logs = vec![log];
    let files = run_import(&a).unwrap();
    assert_eq!(files[0].samples_in, 5000);
    assert_eq!(files[0].samples_kept, 4500);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn version_1_logs_have_millisecond_timestamps() {
    let mut b = vec![0xBC];
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&FIXED_FREQUENCY_ID.to_le_bytes());
    b.extend_from_slice(b"fixedFrequency\0");
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(b"a.x(f)\0a.n(h)\0");
    for k in 0..3u32 {
        b.extend_from_slice(&FIXED_FREQUENCY_ID.to_le_bytes());
        b.extend_from_slice(&(10 * k).to_le_bytes());
        b.extend_from_slice(&(k as f32 + 0.25).to_le_bytes());
        b.extend_from_slice(&(-7i16).to_le_bytes());
    }
    b.extend_from_slice(&crc32(&b).to_le_bytes());
    let (log, rep) = parse_usd(&b, ParseOptions::default()).unwrap();
    assert!(rep.crc_ok);
    assert_eq!(log.version, 1);
    let ts: Vec<u64> = log.events.iter().map(|e| e.timestamp_us).collect();
    assert_eq!(ts, vec![0, 10_000, 20_000]);
    assert_eq!(log.events[2].values, vec![2.25, -7.0]);
    // Version 3 is refused by name.
    b[1] = 3;
    assert_eq!(
        parse_usd(&b, ParseOptions::default()).unwrap_err(),
        UsdError::UnsupportedVersion { version: 3 }
    );
}

#[test]
fn ground_take_off_and_landing_are_excluded_by_the_documented_rule() {
    use host_train::io::Sample;
    use host_train::sim::PlantState;
    // 500 Hz: 1 s on the ground (z = 0, motors idle), 3 s airborne at 0.5 m with hover thrust,
    // a 50 ms gap at t = 2.5 s, then 1 s landed again with the motors still spinning (thrust
    // above the rule's fraction, but z below the minimum height).
    let hover_n = 0.027 * 9.8;
    let mut samples = Vec::new();
    for k in 0..2500u32 {
        let t = f64::from(k) * 0.002;
        if (2.5..2.55).contains(&t) {
            continue;
        }
        let air = (1.0..4.0).contains(&t);
        let mut state = PlantState::default();
        state.p_m.z = if air { 0.5 } else { 0.0 };
        samples.push(Sample {
            t_s: t,
            state,
            wrench: [if t < 1.0 { 0.0 } else { hover_n }, 0.0, 0.0, 0.0],
            rpm: None,
            acc_body_m_s2: None,
        });
    }
    let a = args(Path::new("unused"));
    let flights = airborne_flights(&samples, &a);
    let spans: Vec<(f64, f64, usize)> = flights
        .iter()
        .map(|f| {
            let s = &f.samples;
            (s[0].t_s, s[s.len() - 1].t_s, s.len())
        })
        .collect();
    // The 50 ms gap (dropped packets) stays inside the flight: airborne 1.0–3.998 s, 0.5 s
    // off each end, 25 samples missing.
    assert_eq!(spans.len(), 1, "{spans:?}");
    assert!((spans[0].0 - 1.5).abs() < 1e-9 && (spans[0].1 - 3.498).abs() < 1e-9);
    assert_eq!(spans[0].2, 1000 - 25);
    // A gap longer than --max-gap-s ends the flight: airborne 1.0–2.498 s and 2.55–3.998 s.
    let a = ImportArgs {
        max_gap_s: 0.02,
        ..a
    };
    let flights = airborne_flights(&samples, &a);
    let spans: Vec<(f64, f64, usize)> = flights
        .iter()
        .map(|f| {
            let s = &f.samples;
            (s[0].t_s, s[s.len() - 1].t_s, s.len())
        })
        .collect();
    assert_eq!(spans.len(), 2, "{spans:?}");
    assert!((spans[0].0 - 1.5).abs() < 1e-9 && (spans[0].1 - 1.998).abs() < 1e-9);
    assert!((spans[1].0 - 3.05).abs() < 1e-9 && (spans[1].1 - 3.498).abs() < 1e-9);
    assert_eq!(spans[0].2, 250);
    assert!(flights
        .iter()
        .flat_map(|f| &f.samples)
        .all(|s| s.state.p_m.z >= 0.1 && s.wrench[0] > 0.0));
    // Without trimming, the stretches are the airborne samples themselves.
    let untrimmed = ImportArgs { trim_s: 0.0, ..a };
    let n: usize = airborne_flights(&samples, &untrimmed)
        .iter()
        .map(|f| f.samples.len())
        .sum();
    assert_eq!(n, 1500 - 25);
}
