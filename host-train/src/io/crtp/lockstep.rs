//! The link's timing: the handshake, and the lock-step exchange (one firmware tick per IMU
//! packet, answered by a tick-done packet) that makes a SITL flight deterministic.

use super::*;

/// The simulator's side of the handshake: waits for the firmware's handshake byte, answers it and
/// returns the firmware's address.
pub fn await_handshake(sock: &UdpSocket, timeout: Duration) -> io::Result<SocketAddr> {
    let end = Instant::now() + timeout;
    let mut buf = [0u8; 64];
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("no handshake from the firmware within {timeout:?}"),
            ));
        }
        sock.set_read_timeout(Some(left))?;
        match sock.recv_from(&mut buf) {
            Ok((1, addr)) if buf[0] == HANDSHAKE => {
                sock.send_to(&[HANDSHAKE], addr)?;
                return Ok(addr);
            }
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return Err(e),
        }
    }
}

/// What the firmware sent during one lock-step tick.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tick {
    /// The firmware's tick count (its tick-done packet).
    pub tick: u32,
    /// The motor packet of this tick, if the firmware sent one (at most one per tick; none before
    /// its stabilizer loop runs).
    pub motor: Option<[u16; 4]>,
    /// Every other datagram, in order (parameter answers, logs, console, ...).
    pub other: Vec<Vec<u8>>,
}

/// The simulator's end of a lock-stepped link (the firmware run with `CF2_LOCKSTEP=1`): packets
/// for the firmware go out with [`Lockstep::send`], then [`Lockstep::step`] sends the IMU sample
/// that advances the firmware's tick and waits until the firmware says that tick is done. No
/// wall clock is involved: the firmware's time is the number of IMU packets.
pub struct Lockstep {
    sock: UdpSocket,
    fw: SocketAddr,
    ticks: u32,
    timeout: Duration,
    /// The last motor command (zero until the first motor packet).
    pub pwm: [u16; 4],
    /// Motor packets received.
    pub motor_packets: u64,
}

impl Lockstep {
    /// The link on `sock` (after the handshake) to the firmware at `fw`; `timeout`: how long one
    /// tick may take before [`Lockstep::step`] gives up.
    pub fn new(sock: UdpSocket, fw: SocketAddr, timeout: Duration) -> Self {
        Lockstep {
            sock,
            fw,
            ticks: 0,
            timeout,
            pwm: [0; 4],
            motor_packets: 0,
        }
    }

    /// IMU packets sent, i.e. the firmware's tick count once the last step returned.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// Sends one datagram to the firmware; it is handled in the current tick, before the next
    /// IMU packet.
    pub fn send(&self, d: &[u8]) -> io::Result<()> {
        self.sock.send_to(d, self.fw).map(|_| ())
    }

    /// Sends the IMU packet `imu` (the next tick) and waits for that tick's tick-done packet,
    /// collecting what came before it. An error if it does not come within the timeout (with the
    /// likely cause: a firmware without the lock-step patch, or run without `CF2_LOCKSTEP=1`) or
    /// if the firmware reports another tick than the one expected.
    pub fn step(&mut self, imu: &[u8]) -> io::Result<Tick> {
        if parse_imu(imu).is_none() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "lock-step: a step sends an IMU packet",
            ));
        }
        self.send(imu)?;
        self.ticks += 1;
        let want = self.ticks;
        let mut out = Tick::default();
        let end = Instant::now() + self.timeout;
        let mut buf = [0u8; 64];
        loop {
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                let hint = if out.motor.is_some() {
                    "motor packets came, but no tick-done: the firmware runs on its wall-clock \
                     timer (built without patches/cf-lockstep.patch, or run without CF2_LOCKSTEP=1)"
                } else {
                    "is the firmware alive, built with patches/cf-lockstep.patch and run with \
                     CF2_LOCKSTEP=1?"
                };
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!(
                        "lock-step: no tick-done for tick {want} within {:?} ({hint})",
                        self.timeout
                    ),
                ));
            }
            self.sock.set_read_timeout(Some(left))?;
            let n = match self.sock.recv_from(&mut buf) {
                Ok((n, _)) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    continue
                }
                Err(e) => return Err(e),
            };
            let d = &buf[..n];
            if let Some(t) = parse_tick_done(d) {
                if t == want {
                    out.tick = t;
                    return Ok(out);
                }
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("lock-step: the firmware reports tick {t}, expected {want}"),
                ));
            }
            if let Some(pwm) = parse_motor(d) {
                self.pwm = pwm;
                self.motor_packets += 1;
                out.motor = Some(pwm);
            } else if d != [HANDSHAKE] {
                out.other.push(d.to_vec());
            }
        }
    }
}
