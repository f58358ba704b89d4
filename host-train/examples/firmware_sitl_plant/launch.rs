//! The firmware started and reached: our UDP sockets (the firmware's, cflib's relay), the threads
//! that read them, the firmware's process and console, and the handshake.

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use host_train::io::{crtp_await_handshake, parse_motor, CRTP_HANDSHAKE, CRTP_PORT_SIM};

use crate::crtp::{param_answer, Console, Firmware, FromFirmware};
use crate::Args;

/// The running firmware and our sockets to it and to cflib.
pub struct Link {
    /// Our socket to the firmware, and the firmware's address (from its handshake).
    pub sock: UdpSocket,
    pub fw_addr: SocketAddr,
    /// cflib's socket (`--cflib-port`), and cflib's address once it sent something.
    pub lib_sock: Option<UdpSocket>,
    pub lib_addr: Arc<Mutex<Option<SocketAddr>>>,
    /// What the firmware sent back, and cflib's packets waiting for the loop.
    pub shared: Arc<Mutex<FromFirmware>>,
    /// Packets relayed from the firmware to cflib, and from cflib to the firmware.
    pub relayed: Arc<AtomicU64>,
    pub cflib_sent: u64,
    stop: Arc<AtomicBool>,
    firmware: Firmware,
    pub console: Arc<Console>,
    pub console_path: PathBuf,
    /// When the firmware was started (wall clock).
    pub t_start: Instant,
}

/// What is left of the link once the firmware has been stopped.
pub struct Closed {
    pub motor_packets: u64,
    pub last_pwm: [u16; 4],
    pub param_written: Vec<(u16, [u8; 4])>,
    pub from_cflib_max: usize,
    /// The firmware's console lines of our app.
    pub hamflight_lines: Vec<String>,
    pub relayed: Arc<AtomicU64>,
    pub cflib_sent: u64,
}

impl Link {
    /// Binds the sockets, starts the threads that read them (the firmware's only when not in
    /// lock-step: then the loop reads it), starts the firmware (`CF2_LOCKSTEP=1` with
    /// `--lockstep`) with its console into `--out`/console.log, and waits 10 s at most for its
    /// handshake.
    pub fn start(args: &Args) -> Result<Link> {
        let sock = UdpSocket::bind(("127.0.0.1", args.port))
            .with_context(|| format!("cannot bind udp 127.0.0.1:{}", args.port))?;
        sock.set_read_timeout(Some(Duration::from_millis(100)))?;
        let lib_sock = if args.cflib_port != 0 {
            let s = UdpSocket::bind(("127.0.0.1", args.cflib_port))
                .with_context(|| format!("cannot bind udp 127.0.0.1:{}", args.cflib_port))?;
            s.set_read_timeout(Some(Duration::from_millis(100)))?;
            Some(s)
        } else {
            None
        };
        let shared = Arc::new(Mutex::new(FromFirmware::default()));
        let lib_addr: Arc<Mutex<Option<SocketAddr>>> = Arc::new(Mutex::new(None));
        let stop = Arc::new(AtomicBool::new(false));
        let relayed = Arc::new(AtomicU64::new(0));

        // Receiving thread (wall clock only; in lock-step the loop reads the firmware's packets):
        // handshake, motor commands, relay of the rest to cflib.
        if !args.lockstep {
            let sock = sock.try_clone()?;
            let lib = lib_sock.as_ref().map(|s| s.try_clone()).transpose()?;
            let (shared, lib_addr, stop, relayed) = (
                shared.clone(),
                lib_addr.clone(),
                stop.clone(),
                relayed.clone(),
            );
            thread::spawn(move || {
                let mut buf = [0u8; 128];
                while !stop.load(Ordering::Relaxed) {
                    let Ok((n, addr)) = sock.recv_from(&mut buf) else {
                        continue;
                    };
                    let d = &buf[..n];
                    let mut sh = shared.lock().unwrap();
                    if sh.fw_addr.is_none() {
                        if d == [CRTP_HANDSHAKE] {
                            let _ = sock.send_to(&[CRTP_HANDSHAKE], addr);
                            sh.fw_addr = Some(addr);
                        }
                        continue;
                    }
                    if n > 0 && d[0] >> 4 == CRTP_PORT_SIM {
                        if let Some(pwm) = parse_motor(d) {
                            sh.pwm = pwm;
                            sh.motor_packets += 1;
                        }
                        continue;
                    }
                    param_answer(d, &mut sh);
                    drop(sh);
                    if let (Some(lib), Some(a)) = (&lib, *lib_addr.lock().unwrap()) {
                        let _ = lib.send_to(d, a);
                        relayed.fetch_add(1, Ordering::Relaxed);
                    }
                }
            });
        }
        if let Some(lib) = &lib_sock {
            let lib = lib.try_clone()?;
            let (shared, lib_addr, stop) = (shared.clone(), lib_addr.clone(), stop.clone());
            // cflib's packets wait here for the loop, which sends them one per millisecond
            // between the sensor stream's packets (see the loop).
            thread::spawn(move || {
                let mut buf = [0u8; 128];
                while !stop.load(Ordering::Relaxed) {
                    let Ok((n, addr)) = lib.recv_from(&mut buf) else {
                        continue;
                    };
                    *lib_addr.lock().unwrap() = Some(addr);
                    let mut sh = shared.lock().unwrap();
                    sh.from_cflib.push_back(buf[..n].to_vec());
                    sh.from_cflib_max = sh.from_cflib_max.max(sh.from_cflib.len());
                }
            });
        }

        // --- the firmware ------------------------------------------------------------------
        let console_path = args.out.join("console.log");
        let fw_path = args.firmware.canonicalize()?;
        // printf to a pipe is block-buffered: stdbuf makes the console line-buffered.
        let mut cmd = if Path::new("/usr/bin/stdbuf").exists() {
            let mut c = Command::new("/usr/bin/stdbuf");
            c.args(["-oL", "-eL"]).arg(&fw_path);
            c
        } else {
            Command::new(&fw_path)
        };
        if args.lockstep {
            cmd.env("CF2_LOCKSTEP", "1");
        } else {
            cmd.env_remove("CF2_LOCKSTEP");
        }
        cmd.arg(args.port.to_string())
            .arg("127.0.0.1")
            .stdout(Stdio::piped())
            .stderr(Stdio::null());
        let t_start = Instant::now();
        let mut child = Firmware(cmd.spawn().context("cannot start the firmware")?);
        let console = Arc::new(Console {
            lines: Mutex::new(Vec::new()),
            cond: Condvar::new(),
        });
        {
            let out = child.0.stdout.take().unwrap();
            let console = console.clone();
            let mut file = std::fs::File::create(&console_path)?;
            thread::spawn(move || {
                for line in BufReader::new(out).lines() {
                    let Ok(line) = line else { break };
                    let _ = writeln!(file, "{line}");
                    console.lines.lock().unwrap().push(line);
                    console.cond.notify_all();
                }
            });
        }
        let hs_end = Instant::now() + Duration::from_secs(10);
        let fw_addr = if args.lockstep {
            let a = crtp_await_handshake(&sock, Duration::from_secs(10))?;
            shared.lock().unwrap().fw_addr = Some(a);
            a
        } else {
            loop {
                if let Some(a) = shared.lock().unwrap().fw_addr {
                    break a;
                }
                if Instant::now() > hs_end {
                    bail!("no handshake from the firmware within 10 s");
                }
                thread::sleep(Duration::from_millis(5));
            }
        };
        println!(
            "[{:6.2} s] handshake from {fw_addr}",
            t_start.elapsed().as_secs_f64()
        );
        Ok(Link {
            sock,
            fw_addr,
            lib_sock,
            lib_addr,
            shared,
            relayed,
            cflib_sent: 0,
            stop,
            firmware: child,
            console,
            console_path,
            t_start,
        })
    }

    /// One datagram to the firmware (a lost one is the protocol's business, as over UDP).
    pub fn send(&self, d: &[u8]) {
        let _ = self.sock.send_to(d, self.fw_addr);
    }

    /// cflib's next waiting packet, if any, to the firmware.
    pub fn forward_cflib(&mut self) {
        let next = self.shared.lock().unwrap().from_cflib.pop_front();
        if let Some(pk) = next {
            self.send(&pk);
            self.cflib_sent += 1;
        }
    }

    /// Whether the firmware's process has exited.
    pub fn firmware_exited(&mut self) -> Result<bool> {
        Ok(self.firmware.0.try_wait()?.is_some())
    }

    /// Stops the threads and the firmware, keeping what the summary needs.
    pub fn close(self) -> Closed {
        let (motor_packets, last_pwm, param_written, from_cflib_max) = {
            let sh = self.shared.lock().unwrap();
            (
                sh.motor_packets,
                sh.pwm,
                sh.param_written.clone(),
                sh.from_cflib_max,
            )
        };
        self.stop.store(true, Ordering::Relaxed);
        let hamflight_lines = self.console.grep("HAMFLIGHT");
        drop(self.firmware);
        Closed {
            motor_packets,
            last_pwm,
            param_written,
            from_cflib_max,
            hamflight_lines,
            relayed: self.relayed,
            cflib_sent: self.cflib_sent,
        }
    }
}
