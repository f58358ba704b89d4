//! The UART link: state and setpoint in, telemetry out.
//!
//! Every message is a postcard-encoded [`Uplink`] or [`Downlink`], followed by the CRC-32
//! (IEEE 802.3, as [`hamflight::blob::crc32`], little-endian) of those bytes, COBS-encoded and
//! terminated by a zero byte:
//!
//! ```text
//! frame = COBS( postcard(msg) ‖ crc32_le(postcard(msg)) ) ‖ 0x00
//! ```
//!
//! A frame that fails COBS, the CRC or postcard is counted and dropped ([`FrameError`]); the
//! decoder resynchronises at the next zero byte.
//!
//! Sizes (postcard: f32 as 4 bytes, integers as varints, COBS 1 byte under 254; checked by the
//! firmware's host test `frame_sizes_fit_the_baud_budget`), delimiter included: an [`Input`] with
//! its setpoint is 120 bytes while the sequence number is below 2²¹ (35 min at 1 kHz; 122 at
//! most): 1 tag + 3 seq + 53 state + 57 setpoint, 4 CRC, 1 COBS, 1 delimiter. Without its
//! setpoint (the firmware keeps the last one) 64 (66); with an accelerometer 12 more. A
//! [`Telemetry`] is 84 bytes in flight, 98 at most. At 10 bits per byte (8N1) a UART carries
//! baud / 10 000 bytes per ms each way: docs/performance.md has the budget at 500 Hz
//! and 1 kHz.
//!
//! This file is also compiled into the host's processor-in-the-loop test
//! (`host-train/tests/pil_qemu.rs` includes it with `#[path]`), so both ends encode and decode
//! exactly the same bytes. It therefore depends only on `core`, `serde`, `postcard`, `cobs`
//! (postcard's own COBS crate), `nalgebra` and `hamflight`.

use hamflight::{Faults, Output, Setpoint, State};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Largest encoded frame (COBS overhead, CRC and delimiter included).
pub const MAX_FRAME: usize = 256;
/// Largest postcard payload of one message.
pub const MAX_PAYLOAD: usize = MAX_FRAME - 8;

/// The vehicle state on the wire (f32, SI units, the core's conventions): 52 bytes, plus the
/// accelerometer's 1 or 13.
///
/// A second form of the core's [`State`], kept on purpose: the wire carries the attitude as a
/// unit quaternion (4 floats) where the core's law works on R (9), which keeps the frame small
/// enough for a 1 kHz loop (see the module doc). The conversions are the two `From`s below, the
/// quaternion ↔ R steps [`hamflight::lie::quat_from_rot`] and [`hamflight::lie::rot_from_quat`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireState {
    /// Position p (m, world).
    pub p: [f32; 3],
    /// Attitude: the unit quaternion `[w, x, y, z]` of R (body → world, Hamilton, w ≥ 0 as sent).
    /// Not normalized on receipt: a norm off 1 by more than ≈ 1.4e-4, or a non-finite
    /// component, fails the controller's rotation check (`hamflight::ROTATION_TOLERANCE`, see
    /// [`hamflight::lie::rot_from_quat`]) and the step is a `bad_state` with the motors off.
    pub q: [f32; 4],
    /// Linear velocity v (m/s, body frame).
    pub v: [f32; 3],
    /// Angular velocity ω (rad/s, body frame).
    pub w: [f32; 3],
    /// The accelerometer's specific force (m/s², body frame), when the sender has one: the
    /// composite adaptation law uses it, and differences the velocity without it. One byte
    /// when absent.
    pub acc: Option<[f32; 3]>,
}

impl Default for WireState {
    /// At rest at the origin, level.
    fn default() -> Self {
        Self::from(&State::default())
    }
}

/// One control input: the latest state estimate and the setpoint to track.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Input {
    /// Sequence number, echoed in the telemetry of the step that used this input. It counts
    /// control periods (1 / [`Hello::loop_hz`]): +1 per period, so a gap of k says k − 1
    /// states were lost, and the controller integrates over k periods (at most as many as the
    /// firmware's own ticks since its last step; see `control_loop::dt_for`).
    pub seq: u32,
    /// State estimate.
    pub state: WireState,
    /// The setpoint (the core's own type, 56 bytes), or `None` (1 byte) to keep flying the last
    /// one received. A sender may send it only when it changes, and must send it again after a
    /// [`LinkStatus::WatchdogTripped`] (the trip forgets it) and before the first state counts:
    /// until the firmware has a setpoint, inputs do not step the controller.
    pub setpoint: Option<Setpoint>,
}

/// Host (companion computer, motion capture, PIL test) → firmware.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Uplink {
    /// A new state estimate and setpoint.
    Input(Input),
    /// Ask for a [`Downlink::Hello`] (the boot message may have been sent before anyone listened).
    Hello,
    /// Stop the motors, send a [`Downlink::Report`]; under QEMU also end the emulation.
    Finish,
}

/// Why the motors are off (or `Running`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LinkStatus {
    /// No valid state, or no setpoint, has arrived yet (or since the watchdog tripped).
    WaitingForState,
    /// The controller is flying on fresh input.
    Running,
    /// No valid state for longer than the watchdog timeout: motors off.
    WatchdogTripped,
    /// The weight blob was rejected at boot: motors stay off.
    BadBlob,
}

/// Bits of [`Telemetry::faults`].
pub mod fault_bits {
    /// The state had a non-finite component.
    pub const BAD_STATE: u16 = 1 << 0;
    /// The setpoint had a non-finite component.
    pub const BAD_SETPOINT: u16 = 1 << 1;
    /// dt out of range.
    pub const BAD_DT: u16 = 1 << 2;
    /// Non-finite or singular value inside the law.
    pub const NUMERIC: u16 = 1 << 3;
    /// Mixer scaled the yaw torque.
    pub const SAT_YAW: u16 = 1 << 4;
    /// Mixer scaled roll/pitch.
    pub const SAT_ROLL_PITCH: u16 = 1 << 5;
    /// Mixer shifted the collective thrust.
    pub const SAT_THRUST: u16 = 1 << 6;
    /// The tilt limit shaped the desired attitude.
    pub const TILT_LIMITED: u16 = 1 << 7;
}

/// The controller's [`Faults`] as [`fault_bits`].
pub fn fault_word(f: &Faults) -> u16 {
    use fault_bits::*;
    let mut w = 0;
    for (on, bit) in [
        (f.bad_state, BAD_STATE),
        (f.bad_setpoint, BAD_SETPOINT),
        (f.bad_dt, BAD_DT),
        (f.numeric, NUMERIC),
        (f.saturation.yaw, SAT_YAW),
        (f.saturation.roll_pitch, SAT_ROLL_PITCH),
        (f.saturation.thrust, SAT_THRUST),
        (f.tilt_limited, TILT_LIMITED),
    ] {
        if on {
            w |= bit;
        }
    }
    w
}

/// What one control step produced, sent after every step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// `seq` of the input this step used.
    pub seq: u32,
    /// Rotor speeds commanded (rpm), rotors 1..4.
    pub rpm: [f32; 4],
    /// Rotor thrusts commanded (N).
    pub thrust_n: [f32; 4],
    /// Duty written to the motor PWM, on a 16-bit scale (0..=65535).
    pub duty: [u16; 4],
    /// The disturbance-weight estimate a after the step.
    pub a: [f32; 6],
    /// Controller faults and conditions ([`fault_bits`]).
    pub faults: u16,
    /// Cost of the whole step (controller, PWM map and writes) in counter ticks; see
    /// [`Hello::cost_unit`].
    pub step_cost: u32,
    /// Frames dropped so far (COBS, CRC, decode or overflow errors).
    pub bad_frames: u32,
    /// Watchdog trips so far.
    pub watchdog_trips: u32,
}

impl Telemetry {
    /// Fills the controller part from a step's output.
    pub fn from_output(seq: u32, out: &Output, duty: [u16; 4]) -> Self {
        let mut a = [0.0; 6];
        for (dst, src) in a.iter_mut().zip(out.a.iter()) {
            *dst = *src;
        }
        Self {
            seq,
            rpm: out.rotors.rpm,
            thrust_n: out.rotors.thrust_n,
            duty,
            a,
            faults: fault_word(&out.faults),
            ..Self::default()
        }
    }
}

/// How [`Telemetry::step_cost`] counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum CostUnit {
    /// DWT cycle counter: CPU cycles at the core clock.
    Cycles,
    /// SysTick ticks at the 168 MHz QEMU `netduinoplus2` core clock, with `-icount shift=0`
    /// (one instruction per virtual nanosecond): instructions = ticks · 1000 / 168.
    QemuSysTick168MHz,
}

/// Which model the firmware flies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelKind {
    /// The learned model of the embedded weight blob.
    Learned,
    /// The nominal model (a build without trained weights).
    Nominal,
}

/// Sent at boot and on [`Uplink::Hello`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// Control-loop rate (Hz); one control period, the controller's dt while no state is lost,
    /// is 1 / `loop_hz`.
    pub loop_hz: u32,
    /// True if the weight blob passed every check at boot.
    pub blob_ok: bool,
    /// Length of the embedded blob (bytes).
    pub blob_len: u32,
    /// CRC-32 of the whole embedded blob, to check that a host uses the same one.
    pub blob_crc: u32,
    /// The model flown.
    pub model: ModelKind,
    /// Unit of the step cost.
    pub cost_unit: CostUnit,
    /// Watchdog timeout (control ticks without a fresh state).
    pub watchdog_ticks: u32,
}

/// Sent on [`Uplink::Finish`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Control steps run.
    pub steps: u32,
    /// Largest step cost seen (same unit as the telemetry).
    pub max_step_cost: u32,
    /// Smallest step cost seen.
    pub min_step_cost: u32,
    /// Sum of all step costs (mean = total / steps).
    pub total_step_cost: u64,
    /// Peak stack use since reset (bytes), from the painted stack.
    pub stack_peak_bytes: u32,
    /// Size of the stack region (bytes).
    pub stack_size_bytes: u32,
    /// Peak stack use during boot (blob decoding), before the loop started (bytes).
    pub stack_boot_peak_bytes: u32,
    /// Frames dropped.
    pub bad_frames: u32,
    /// Watchdog trips.
    pub watchdog_trips: u32,
}

/// Firmware → host.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Downlink {
    /// Boot message.
    Hello(Hello),
    /// One control step.
    Telemetry(Telemetry),
    /// The motors went off without a step (watchdog, bad blob, no state yet).
    Status(LinkStatus),
    /// Final statistics.
    Report(Report),
}

/// The sender's side: R → its unit quaternion ([`hamflight::lie::quat_from_rot`]); no
/// accelerometer.
impl From<&State> for WireState {
    fn from(s: &State) -> Self {
        Self {
            p: s.p_m.into(),
            q: hamflight::lie::quat_from_rot(&s.rot),
            v: s.v_body_m_s.into(),
            w: s.w_body_rad_s.into(),
            acc: None,
        }
    }
}

/// The receiver's side: the quaternion → R ([`hamflight::lie::rot_from_quat`], unnormalized, so
/// that the controller's rotation check sees a malformed quaternion).
impl From<&WireState> for State {
    fn from(s: &WireState) -> Self {
        Self {
            p_m: Vector3::from(s.p),
            rot: hamflight::lie::rot_from_quat(&s.q),
            v_body_m_s: Vector3::from(s.v),
            w_body_rad_s: Vector3::from(s.w),
        }
    }
}

/// Why a frame was dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// More than [`MAX_FRAME`] bytes without a delimiter.
    Overflow,
    /// Not valid COBS.
    Cobs,
    /// Shorter than a CRC, or the CRC does not match.
    Crc,
    /// The payload is not a valid message.
    Decode,
}

/// Encodes `msg` as one complete frame (delimiter included) into `out`; returns its length.
/// The COBS step is the `cobs` crate's (the one postcard uses).
///
/// # Errors
/// [`FrameError::Overflow`] if the message does not fit `out` (or [`MAX_PAYLOAD`]).
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_PAYLOAD + 4];
    let n = postcard::to_slice(msg, &mut raw[..MAX_PAYLOAD])
        .map_err(|_| FrameError::Overflow)?
        .len();
    let crc = hamflight::blob::crc32(raw.get(..n).ok_or(FrameError::Overflow)?);
    raw.get_mut(n..n + 4)
        .ok_or(FrameError::Overflow)?
        .copy_from_slice(&crc.to_le_bytes());
    let body = raw.get(..n + 4).ok_or(FrameError::Overflow)?;
    let len = cobs::try_encode(body, out).map_err(|_| FrameError::Overflow)?;
    *out.get_mut(len).ok_or(FrameError::Overflow)? = 0;
    Ok(len + 1)
}

/// Accumulates received bytes and yields one message per frame.
#[derive(Clone, Debug)]
pub struct FrameDecoder {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflowed: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME],
            len: 0,
            overflowed: false,
        }
    }

    /// Feeds one byte. Returns a message or an error when `byte` ends a frame, `None` otherwise
    /// (empty frames, i.e. repeated delimiters, are ignored).
    pub fn push<T: for<'de> Deserialize<'de>>(
        &mut self,
        byte: u8,
    ) -> Option<Result<T, FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflowed = true,
            }
            return None;
        }
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.overflowed, false) {
            return Some(Err(FrameError::Overflow));
        }
        if len == 0 {
            return None;
        }
        Some(self.finish(len))
    }

    fn finish<T: for<'de> Deserialize<'de>>(&mut self, len: usize) -> Result<T, FrameError> {
        let frame = self.buf.get_mut(..len).ok_or(FrameError::Overflow)?;
        let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
        let body_len = n.checked_sub(4).ok_or(FrameError::Crc)?;
        let body = frame.get(..body_len).ok_or(FrameError::Crc)?;
        let crc = frame
            .get(body_len..n)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
            .ok_or(FrameError::Crc)?;
        if hamflight::blob::crc32(body) != crc {
            return Err(FrameError::Crc);
        }
        postcard::from_bytes(body).map_err(|_| FrameError::Decode)
    }
}
