//! Processor in the loop: the firmware's control loop, built for QEMU's `netduinoplus2`
//! (STM32F405), flies paper-spiral against the SITL plant over its UART, in lock-step (the plant
//! advances one control period per telemetry frame). The flown path must match the same
//! controller run natively on the host to the bit, and track at least as well: at 500 Hz with
//! both adaptation laws, and at 1 kHz (firmware feature `loop-1khz`, the scenario's control rate
//! raised to match).
//!
//! The host sends the setpoint only when it changed (along paper-spiral it changes every tick),
//! and the attitude as the link's unit quaternion; the native run sees the same state, through
//! the same `link::WireState` conversions.
//!
//! Needs `qemu-system-arm` (Debian: `apt-get install qemu-system-arm`). Without it on `PATH` at
//! build time the test is reported as *ignored* with that install command as the reason
//! (`host-train/build.rs`); under `CI=true`, or if QEMU vanished after the build, it fails with it.
//!
//! `HAMFLIGHT_PIL_SECONDS` sets the simulated flight length (default 10 s, at least 10);
//! `HAMFLIGHT_PIL_SCENARIO` another scenario file (default `scenarios/paper-spiral.toml`).

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hamflight::model::{HamiltonianModel, LearnedModel, NominalModel};
use hamflight::{AdaptationLaw, FlightController, Gains, State};
use host_train::control::Controller;
use host_train::fly::{fly_scenario, Report};
use host_train::sim::{PlantState, Scenario, TrajectoryPoint};

/// The firmware's link frames, compiled from the very same file.
#[allow(dead_code)]
#[path = "../../firmware/src/link.rs"]
mod link;

use link::{CostUnit, Downlink, FrameDecoder, Hello, ModelKind, Uplink, WireState};

mod qemu_common;
use qemu_common::{build_firmware, qemu_available, LinkPort, Qemu, QemuController};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The blob the firmware embeds (firmware/build.rs: `HAMFLIGHT_WEIGHTS` relative to firmware/,
/// else weights/default.hfw).
fn weights_path() -> PathBuf {
    match std::env::var_os("HAMFLIGHT_WEIGHTS") {
        Some(p) => {
            let p = PathBuf::from(p);
            if p.is_absolute() {
                p
            } else {
                repo().join("firmware").join(p)
            }
        }
        None => repo().join("weights/default.hfw"),
    }
}

/// The state as the firmware receives it: the plant's, rounded to f32, its attitude through the
/// link's quaternion and back ([`WireState`]'s two conversions, the very code both ends run).
fn wire_state(state: &PlantState) -> WireState {
    WireState::from(&State::from(state))
}

/// The same controller on the host: the core compiled for x86-64, stepped exactly as the
/// firmware's control loop steps it (dt = 1 / loop rate as f32, the state as the link delivers
/// it).
struct NativeController<M> {
    inner: FlightController<M>,
    dt_s: f32,
}

impl<M: HamiltonianModel> Controller for NativeController<M> {
    fn name(&self) -> &str {
        "native"
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn step(&mut self, _t: f64, state: &PlantState, r: &TrajectoryPoint, _dt: f64) -> [f64; 4] {
        let state = State::from(&wire_state(state));
        let out = self.inner.step(&state, &r.into(), self.dt_s);
        out.rotors.rpm.map(f64::from)
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        Some(
            self.inner
                .estimate()
                .iter()
                .map(|&x| f64::from(x))
                .collect(),
        )
    }
}

fn pil_seconds() -> f64 {
    std::env::var("HAMFLIGHT_PIL_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .unwrap_or(10.0)
        .max(10.0)
}

/// How to get QEMU (the `ignore` reason below says the same; it must be a literal).
const INSTALL_QEMU: &str = "install it with `apt-get install qemu-system-arm` (Debian/Ubuntu)";

// Without QEMU on PATH at build time (and CI not `true`), build.rs sets `hamflight_no_qemu`: the
// summary then lists this test as ignored with the reason, never as a pass.
#[test]
#[cfg_attr(
    hamflight_no_qemu,
    ignore = "qemu-system-arm not found on PATH at build time; install it with `apt-get install qemu-system-arm` (Debian/Ubuntu), then rerun"
)]
fn paper_spiral_on_qemu_matches_native() {
    pil_flight(AdaptationLaw::Gradient, Rate::Hz500);
}

/// The `loop-1khz` image: paper-spiral at a 1 kHz control rate ("1 kHz end to end" in
/// docs/performance.md), bit-identical to the native run at 1 kHz.
#[test]
#[cfg_attr(
    hamflight_no_qemu,
    ignore = "qemu-system-arm not found on PATH at build time; install it with `apt-get install qemu-system-arm` (Debian/Ubuntu), then rerun"
)]
fn paper_spiral_at_1khz_on_qemu_matches_native() {
    pil_flight(AdaptationLaw::Gradient, Rate::Hz1000);
}

/// The same with the composite adaptation law on both sides (no accelerometer on the link: both
/// difference the velocity), bit-identical to native.
#[test]
#[cfg_attr(
    hamflight_no_qemu,
    ignore = "qemu-system-arm not found on PATH at build time; install it with `apt-get install qemu-system-arm` (Debian/Ubuntu), then rerun"
)]
fn composite_law_on_qemu_matches_native() {
    pil_flight(AdaptationLaw::Composite, Rate::Hz500);
}

/// The firmware's loop rate under test.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Rate {
    /// The default build.
    Hz500,
    /// `loop-1khz`.
    Hz1000,
}

fn pil_flight(law: AdaptationLaw, rate: Rate) {
    // The composite law is the firmware's default feature; the paper's law alone is the image
    // without it.
    let mut features = String::from("qemu");
    let default_features = law == AdaptationLaw::Composite;
    if rate == Rate::Hz1000 {
        features.push_str(",loop-1khz");
    }
    // The firmware's gains (firmware/src/control_loop.rs `default_gains`): the model's vehicle.
    let gains_of = |facts: hamflight::VehicleFacts| Gains {
        law,
        ..Gains::for_vehicle(&facts)
    };
    assert!(
        qemu_available(),
        "qemu-system-arm is not installed, so the processor-in-the-loop test cannot run; {INSTALL_QEMU}"
    );
    let path = std::env::var_os("HAMFLIGHT_PIL_SCENARIO")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("scenarios/paper-spiral.toml"));
    let mut scenario =
        Scenario::load(&path).unwrap_or_else(|e| panic!("cannot load {}: {e:#}", path.display()));
    scenario.spec.duration_s = scenario.spec.duration_s.min(pil_seconds());
    assert!(scenario.spec.duration_s >= 10.0);
    if rate == Rate::Hz1000 {
        // One physics step per tick (physics_hz ≥ 1000 is the scenario's floor).
        scenario.spec.control_hz = 1000.0;
    }

    let elf = build_firmware(&features, default_features);
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind a local port for the UART");
    let port = listener.local_addr().expect("local addr").port();
    let mut qemu = Qemu::start(&elf, port);
    listener
        .set_nonblocking(true)
        .expect("nonblocking listener");
    let t0 = Instant::now();
    let stream = loop {
        match listener.accept() {
            Ok((s, _)) => break s,
            Err(_) if t0.elapsed() < Duration::from_secs(20) => {
                std::thread::sleep(Duration::from_millis(10))
            }
            Err(e) => panic!("QEMU did not connect its UART: {e}\n{}", qemu.output()),
        }
    };
    stream.set_nonblocking(false).expect("blocking stream");
    stream.set_nodelay(true).expect("nodelay");
    let mut port = LinkPort {
        stream,
        dec: FrameDecoder::new(),
        bad_frames: 0,
        buf: Vec::new(),
        pos: 0,
    };

    // QEMU connects before the guest runs, so the boot Hello arrives; only if it does not, ask
    // (sending earlier could hit the USART before the firmware enabled it: QEMU drops those bytes).
    let mut asked = false;
    let hello: Hello = loop {
        match port.recv(Duration::from_secs(10)) {
            Some(Downlink::Hello(h)) => break h,
            Some(_) => {}
            None if !asked => {
                asked = true;
                port.send(&Uplink::Hello);
            }
            None => panic!("no Hello from the firmware\n{}", qemu.output()),
        }
    };
    assert!(
        hello.blob_ok,
        "the firmware rejected its weight blob\n{}",
        qemu.output()
    );
    assert_eq!(
        f64::from(hello.loop_hz),
        scenario.spec.control_hz,
        "firmware loop rate differs from the scenario's control rate"
    );
    assert_eq!(hello.cost_unit, CostUnit::QemuSysTick168MHz);

    let mut fw = QemuController {
        port,
        seq: 0,
        sent_setpoint: None,
        bare_inputs: 0,
        costs: Vec::new(),
        last_a: Vec::new(),
        faults_seen: 0,
    };
    let log_fw = fly_scenario(&scenario, &mut fw);
    fw.port.send(&Uplink::Finish);
    let report = loop {
        match fw.port.recv(Duration::from_secs(10)) {
            Some(Downlink::Report(r)) => break r,
            Some(_) => {}
            None => panic!("no Report after Finish\n{}", qemu.output()),
        }
    };
    assert!(
        qemu.wait_exit(Duration::from_secs(10)),
        "QEMU did not exit cleanly after Finish\n{}",
        qemu.output()
    );

    // The model the firmware flies (firmware/src/control_loop.rs `load_model`), on the host.
    let dt_s = 1.0 / hello.loop_hz as f32;
    let log_host = match hello.model {
        ModelKind::Nominal => {
            let mut native = NativeController {
                inner: FlightController::new(
                    NominalModel::default(),
                    gains_of(hamflight::VehicleFacts::of(&NominalModel::default())),
                ),
                dt_s,
            };
            fly_scenario(&scenario, &mut native)
        }
        ModelKind::Learned => {
            let wp = weights_path();
            let blob =
                std::fs::read(&wp).unwrap_or_else(|e| panic!("cannot read {}: {e}", wp.display()));
            assert_eq!(
                hamflight::blob::crc32(&blob),
                hello.blob_crc,
                "the firmware embeds another blob than {}",
                wp.display()
            );
            let model =
                LearnedModel::from_blob(&blob).unwrap_or_else(|e| panic!("{}: {e}", wp.display()));
            let gains = gains_of(hamflight::VehicleFacts::of(&model));
            let mut native = NativeController {
                inner: FlightController::new(model, gains),
                dt_s,
            };
            fly_scenario(&scenario, &mut native)
        }
    };

    let r_fw = Report::from_log(&log_fw, Some(&path));
    let r_host = Report::from_log(&log_host, Some(&path));
    let max_dev = log_fw
        .p_m
        .iter()
        .zip(&log_host.p_m)
        .map(|(a, b)| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max);
    let insns: Vec<f64> = fw
        .costs
        .iter()
        .map(|&c| f64::from(c) * 1000.0 / 168.0)
        .collect();
    let mean = insns.iter().sum::<f64>() / insns.len().max(1) as f64;
    let max = insns.iter().copied().fold(0.0, f64::max);
    println!(
        "PIL paper-spiral {:.1} s at {} Hz, {:?} model, {law:?} law: {} steps ({} without a setpoint), max |p_qemu - p_host| = {:.3e} m, \
         RMSE(t>=5 s) qemu {:.4} m / host {:.4} m, whole {:.4} / {:.4} m",
        scenario.spec.duration_s,
        hello.loop_hz,
        hello.model,
        fw.costs.len(),
        fw.bare_inputs,
        max_dev,
        r_fw.rmse_pos_window_m.unwrap_or(f64::NAN),
        r_host.rmse_pos_window_m.unwrap_or(f64::NAN),
        r_fw.rmse_pos_m,
        r_host.rmse_pos_m
    );
    println!(
        "PIL step cost: mean {mean:.0} instructions, max {max:.0} (≈ {:.1} / {:.1} µs at 168 MHz, 1 instruction/cycle); \
         stack peak {} of {} bytes; bad frames fw {} / host {}; watchdog trips {}",
        mean / 168.0,
        max / 168.0,
        report.stack_peak_bytes,
        report.stack_size_bytes,
        report.bad_frames,
        fw.port.bad_frames,
        report.watchdog_trips
    );

    // The firmware is the native controller: same path (to the tick of a crash, if any), same
    // tracking, clean link.
    assert_eq!(
        log_fw.p_m.len(),
        log_host.p_m.len(),
        "flights of different length (firmware crash {:?} s, native {:?} s)",
        r_fw.crash_time_s,
        r_host.crash_time_s
    );
    assert!(
        max_dev <= 1e-3,
        "flown path differs from the native run by {max_dev:.3e} m (> 1 mm)"
    );
    // Same code, same IEEE operations (the M4F's vfma/vsqrt round as the host's fma/sqrt do):
    // the paths must agree to the bit, not just within the millimetre above.
    assert!(
        max_dev == 0.0,
        "the firmware is not bit-identical to the host build: paths differ by {max_dev:.3e} m"
    );
    assert!(
        r_fw.rmse_pos_m <= r_host.rmse_pos_m + 1e-4,
        "firmware tracks worse than native: {} vs {} m",
        r_fw.rmse_pos_m,
        r_host.rmse_pos_m
    );
    assert_eq!(report.bad_frames, 0, "the firmware dropped frames");
    assert_eq!(fw.port.bad_frames, 0, "the host dropped frames");
    assert_eq!(report.steps as usize, fw.costs.len());
    // And it must actually fly the whole flight.
    assert!(
        !r_host.crashed,
        "the controller crashes paper-spiral at t = {:?} s even natively on the host (the firmware \
         matched it within {max_dev:.1e} m): the {:?} model ({}) cannot fly it, a model problem, \
         not a firmware one",
        r_host.crash_time_s,
        hello.model,
        if hello.model == ModelKind::Learned {
            weights_path().display().to_string()
        } else {
            "nominal".to_string()
        }
    );
    assert!(!r_fw.crashed, "the QEMU firmware crashed: {r_fw:?}");
}
