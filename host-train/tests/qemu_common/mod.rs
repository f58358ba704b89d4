//! The QEMU side of the processor-in-the-loop test (`pil_qemu.rs`): the firmware's QEMU image
//! built, QEMU started with its UART on a TCP port, the host end of the firmware's link, and the
//! firmware as a host [`Controller`].

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use hamflight::Setpoint;
use host_train::control::Controller;
use host_train::sim::{PlantState, TrajectoryPoint};

use crate::link::{self, Downlink, FrameDecoder, Input, Uplink};
use crate::{repo, wire_state};

pub fn qemu_available() -> bool {
    Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

/// Adds the thumbv7em-none-eabihf standard library when rustup lacks it, as `cargo fw-build`
/// does (`firmware/tools/ensure-target.sh`): rustup installs rust-toolchain.toml's target only
/// when it installs the toolchain itself, so on a machine that already had 1.95.0 the
/// firmware build would fail with "can't find crate for `core`". Runs once per test binary.
fn ensure_target(firmware_dir: &Path) {
    static DONE: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    DONE.get_or_init(|| {
        let script = firmware_dir.join("tools/ensure-target.sh");
        let mut cmd = Command::new("bash");
        cmd.arg(&script);
        // The firmware's own rust-toolchain.toml must pick the toolchain, not the outer cargo's.
        cmd.env_remove("RUSTUP_TOOLCHAIN");
        let out = cmd
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", script.display()));
        assert!(
            out.status.success(),
            "{} failed: the thumbv7em-none-eabihf target is missing and could not be added \
             (rustup target add thumbv7em-none-eabihf):\n{}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    });
}

/// Serialises the firmware builds of the tests in this binary: they share the firmware's target
/// directory, where each build overwrites the same `release/qemu`, and each copies its ELF away
/// before the next starts.
static BUILD: Mutex<()> = Mutex::new(());

/// Builds the QEMU firmware (release) with `features` (`qemu` and more: `loop-1khz` runs the
/// loop at 1 kHz), with the default features (the composite adaptation law) or without them
/// (the paper's gradient law alone), in its own workspace's target directory, the one
/// `cargo fw-build` fills, and returns a copy of the ELF named after the features.
pub fn build_firmware(features: &str, default_features: bool) -> PathBuf {
    let dir = repo().join("firmware");
    let target = dir.join("target");
    let _lock: MutexGuard<()> = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    ensure_target(&dir);
    let mut cmd = Command::new("cargo");
    cmd.current_dir(&dir).args([
        "build",
        "--release",
        "--features",
        features,
        "--bin",
        "qemu",
        "--target-dir",
    ]);
    cmd.arg(&target);
    if !default_features {
        cmd.arg("--no-default-features");
    }
    // The outer cargo's settings must not leak into the firmware's own workspace.
    for var in [
        "CARGO_TARGET_DIR",
        "CARGO_BUILD_TARGET",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "RUSTUP_TOOLCHAIN",
        "CARGO_MAKEFLAGS",
    ] {
        cmd.env_remove(var);
    }
    let out = cmd
        .output()
        .expect("cannot run cargo to build the firmware");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // rustup adds rust-toolchain.toml's target only when it installs the toolchain.
    let hint = if stderr.contains("can't find crate for `core`") {
        "\nthe thumbv7em-none-eabihf target is missing: rustup target add thumbv7em-none-eabihf \
         (or run firmware/tools/ensure-target.sh)"
    } else {
        ""
    };
    assert!(
        out.status.success(),
        "firmware build failed (cd firmware && cargo build --release --features {features} --bin qemu{}):\n{stderr}{hint}",
        if default_features { "" } else { " --no-default-features" }
    );
    let built = target.join("thumbv7em-none-eabihf/release/qemu");
    let copy = target.join(format!(
        "pil-qemu-{}{}.elf",
        features.replace(',', "-"),
        if default_features { "" } else { "-gradient" }
    ));
    std::fs::copy(&built, &copy)
        .unwrap_or_else(|e| panic!("cannot copy {} to {}: {e}", built.display(), copy.display()));
    copy
}

/// QEMU with its output collected; killed on drop.
pub struct Qemu {
    child: Child,
    output: Arc<Mutex<String>>,
}

impl Qemu {
    pub fn start(elf: &Path, port: u16) -> Self {
        let mut child = Command::new("qemu-system-arm")
            .args(["-M", "netduinoplus2", "-nographic", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            // Deterministic instruction counting: SysTick then counts instructions, and the step
            // cost printed below is the same on every run.
            .args(["-icount", "shift=0"])
            // nodelay: the guest writes one byte at a time; with Nagle's algorithm against the
            // host's delayed ACKs every frame would wait ~40 ms.
            .args(["-serial", &format!("tcp:127.0.0.1:{port},nodelay=on")])
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("cannot start qemu-system-arm");
        let output = Arc::new(Mutex::new(String::new()));
        for stream in [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let out = Arc::clone(&output);
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    if let Ok(mut o) = out.lock() {
                        o.push_str(&line);
                        o.push('\n');
                    }
                }
            });
        }
        Self { child, output }
    }

    pub fn output(&self) -> String {
        self.output.lock().map(|o| o.clone()).unwrap_or_default()
    }

    /// Waits for QEMU to exit by itself (after Finish); true if it did in time.
    pub fn wait_exit(&mut self, timeout: Duration) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            if let Ok(Some(st)) = self.child.try_wait() {
                return st.success();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The host end of the firmware's link.
pub struct LinkPort {
    pub stream: TcpStream,
    pub dec: FrameDecoder,
    pub bad_frames: u32,
    pub buf: Vec<u8>,
    pub pos: usize,
}

impl LinkPort {
    pub fn send(&mut self, msg: &Uplink) {
        let mut buf = [0u8; link::MAX_FRAME];
        let n = link::encode(msg, &mut buf).expect("uplink frame fits");
        self.stream
            .write_all(&buf[..n])
            .expect("write to the firmware's UART");
    }

    /// Next message from the firmware, or None on timeout or a closed connection.
    pub fn recv(&mut self, timeout: Duration) -> Option<Downlink> {
        let t0 = Instant::now();
        loop {
            while let Some(&b) = self.buf.get(self.pos) {
                self.pos += 1;
                match self.dec.push::<Downlink>(b) {
                    Some(Ok(msg)) => return Some(msg),
                    Some(Err(_)) => self.bad_frames += 1,
                    None => {}
                }
            }
            let left = timeout.checked_sub(t0.elapsed())?;
            self.stream
                .set_read_timeout(Some(left.max(Duration::from_millis(1))))
                .ok()?;
            self.buf.resize(4096, 0);
            self.pos = 0;
            match (&self.stream).read(&mut self.buf) {
                Ok(0) | Err(_) => {
                    self.buf.clear();
                    return None;
                }
                Ok(n) => self.buf.truncate(n),
            }
        }
    }
}

/// The firmware as a host [`Controller`]: each step is one Input frame out, one Telemetry back.
pub struct QemuController {
    pub port: LinkPort,
    pub seq: u32,
    /// The setpoint last sent (the firmware holds it).
    pub sent_setpoint: Option<Setpoint>,
    /// Inputs sent without a setpoint.
    pub bare_inputs: u32,
    pub costs: Vec<u32>,
    pub last_a: Vec<f64>,
    pub faults_seen: u16,
}

impl Controller for QemuController {
    fn name(&self) -> &str {
        "qemu-firmware"
    }

    fn reset(&mut self) {}

    fn step(&mut self, _t: f64, state: &PlantState, r: &TrajectoryPoint, _dt: f64) -> [f64; 4] {
        self.seq += 1;
        let sp = Setpoint::from(r);
        let setpoint = if self.sent_setpoint == Some(sp) {
            self.bare_inputs += 1;
            None
        } else {
            self.sent_setpoint = Some(sp);
            Some(sp)
        };
        let input = Input {
            seq: self.seq,
            state: wire_state(state),
            setpoint,
        };
        self.port.send(&Uplink::Input(input));
        loop {
            match self.port.recv(Duration::from_secs(10)) {
                Some(Downlink::Telemetry(t)) if t.seq == self.seq => {
                    self.costs.push(t.step_cost);
                    self.last_a = t.a.iter().map(|&x| f64::from(x)).collect();
                    self.faults_seen |= t.faults;
                    return t.rpm.map(f64::from);
                }
                Some(_) => {} // status frames, stale telemetry
                None => panic!(
                    "no telemetry from the firmware for input {} within 10 s",
                    self.seq
                ),
            }
        }
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        Some(self.last_a.clone())
    }
}
