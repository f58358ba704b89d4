//! Host unit tests of the chip-independent parts.

use crate::control_loop::{ControlLoop, NoCost, TickOutcome, WATCHDOG_TICKS};
use crate::link::{self, Downlink, FrameDecoder, FrameError, Input, Telemetry, Uplink, WireState};
use crate::motor::{pwm_to_rpm, rpm_to_pwm, Motors};
use core::convert::Infallible;
use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use hamflight::model::{LearnedModel, ModelWeights, NominalModel};
use hamflight::{Setpoint, State};
use nalgebra::Vector3;

#[derive(Default)]
struct FakePwm(u16);
impl ErrorType for FakePwm {
    type Error = Infallible;
}
impl SetDutyCycle for FakePwm {
    fn max_duty_cycle(&self) -> u16 {
        255
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.0 = duty;
        Ok(())
    }
}

fn motors() -> Motors<FakePwm, FakePwm, FakePwm, FakePwm> {
    Motors {
        m1: FakePwm(7),
        m2: FakePwm(7),
        m3: FakePwm(7),
        m4: FakePwm(7),
    }
}

fn hover_input(seq: u32) -> Input {
    let p = Vector3::new(0.0, 0.0, 0.5);
    Input {
        seq,
        state: WireState::from(&State {
            p_m: p,
            ..State::default()
        }),
        setpoint: Some(Setpoint::hover(p, 0.0)),
    }
}

fn decode_all<T: for<'de> serde::Deserialize<'de>>(bytes: &[u8]) -> Vec<Result<T, FrameError>> {
    let mut d = FrameDecoder::new();
    bytes.iter().filter_map(|&b| d.push::<T>(b)).collect()
}

#[test]
fn frame_round_trip() {
    let msg = Uplink::Input(hover_input(42));
    let mut buf = [0u8; link::MAX_FRAME];
    let n = link::encode(&msg, &mut buf).unwrap();
    assert_eq!(buf[n - 1], 0);
    assert!(buf[..n - 1].iter().all(|&b| b != 0));
    let got = decode_all::<Uplink>(&buf[..n]);
    assert_eq!(got, vec![Ok(msg)]);
}

// ---- Reference framing, written from the COBS paper and the frame layout, independent of the
// `cobs` crate that link.rs uses: the oracle of the tests below. ----

/// COBS (Cheshire & Baker): each group is a code byte (1 + the non-zero bytes that follow, 0xFF
/// for a full group of 254 without an implied zero) and the bytes.
fn cobs_encode_reference(src: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    let mut code_at = 0;
    for &b in src {
        if b == 0 {
            out[code_at] = (out.len() - code_at) as u8;
            code_at = out.len();
            out.push(0);
        } else {
            out.push(b);
            if out.len() - code_at == 0xFF {
                out[code_at] = 0xFF;
                code_at = out.len();
                out.push(0);
            }
        }
    }
    out[code_at] = (out.len() - code_at) as u8;
    out
}

/// The inverse; `None` for a zero byte or a group running past the end.
fn cobs_decode_reference(enc: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut r = 0;
    while r < enc.len() {
        let code = enc[r] as usize;
        if code == 0 || r + code > enc.len() {
            return None;
        }
        let group = &enc[r + 1..r + code];
        if group.contains(&0) {
            return None;
        }
        out.extend_from_slice(group);
        r += code;
        if code != 0xFF && r < enc.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// CRC-32/ISO-HDLC bit by bit.
fn crc32_reference(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// What the decoder must make of the bytes between two delimiters.
fn frame_reference<T: for<'de> serde::Deserialize<'de>>(
    frame: &[u8],
) -> Option<Result<T, FrameError>> {
    if frame.is_empty() {
        return None;
    }
    if frame.len() > link::MAX_FRAME {
        return Some(Err(FrameError::Overflow));
    }
    let Some(raw) = cobs_decode_reference(frame) else {
        return Some(Err(FrameError::Cobs));
    };
    if raw.len() < 4 {
        return Some(Err(FrameError::Crc));
    }
    let (body, crc) = raw.split_at(raw.len() - 4);
    if crc32_reference(body).to_le_bytes() != crc {
        return Some(Err(FrameError::Crc));
    }
    Some(postcard::from_bytes(body).map_err(|_| FrameError::Decode))
}

fn postcard_bytes<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = [0u8; 512];
    postcard::to_slice(msg, &mut buf).unwrap().to_vec()
}

/// The frame of `msg` by the reference: COBS(postcard ‖ CRC-32 LE) ‖ 0.
fn frame_by_reference<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut raw = postcard_bytes(msg);
    let crc = crc32_reference(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut f = cobs_encode_reference(&raw);
    f.push(0);
    f
}

struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    /// A finite f32 of any bit pattern (±0, subnormal, huge), often with zero bytes in it.
    fn f32(&mut self) -> f32 {
        loop {
            let bits = match self.below(4) {
                0 => 0,
                1 => (self.next_u64() as u32) & 0xFF00_FF00,
                _ => self.next_u64() as u32,
            };
            let x = f32::from_bits(bits);
            if x.is_finite() {
                return x;
            }
        }
    }
    fn f32s<const N: usize>(&mut self) -> [f32; N] {
        core::array::from_fn(|_| self.f32())
    }
    /// A wire quaternion: a unit one (as a sender makes it), one off unit norm by up to ±1e-3,
    /// any finite bits, or one with a NaN or infinite component.
    fn quat(&mut self) -> [f32; 4] {
        let unit = hamflight::lie::quat_from_rot(&hamflight::lie::exp(&Vector3::new(
            self.below(2001) as f32 * 3e-3 - 3.0,
            self.below(2001) as f32 * 3e-3 - 3.0,
            self.below(2001) as f32 * 3e-3 - 3.0,
        )));
        match self.below(5) {
            0 | 1 => unit,
            2 => {
                let k = 1.0 + (self.below(2001) as f32 - 1000.0) * 1e-6;
                unit.map(|c| c * k)
            }
            3 => self.f32s(),
            _ => {
                let mut q = unit;
                if let Some(c) = q.get_mut(self.below(4)) {
                    *c = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][self.below(3)];
                }
                q
            }
        }
    }
}

fn random_uplink(rng: &mut SplitMix64) -> Uplink {
    match rng.below(6) {
        0 => Uplink::Hello,
        1 => Uplink::Finish,
        _ => Uplink::Input(Input {
            seq: rng.next_u64() as u32,
            state: WireState {
                p: rng.f32s(),
                q: rng.quat(),
                v: rng.f32s(),
                w: rng.f32s(),
                acc: if rng.below(2) == 0 {
                    None
                } else {
                    Some(rng.f32s())
                },
            },
            setpoint: if rng.below(3) == 0 {
                None
            } else {
                Some(Setpoint {
                    p_m: rng.f32s().into(),
                    v_m_s: rng.f32s().into(),
                    a_m_s2: rng.f32s().into(),
                    j_m_s3: rng.f32s().into(),
                    yaw_rad: rng.f32(),
                    yaw_rate_rad_s: rng.f32(),
                })
            },
        }),
    }
}

fn random_downlink(rng: &mut SplitMix64) -> Downlink {
    let word = |rng: &mut SplitMix64| rng.next_u64() as u32 >> rng.below(32);
    match rng.below(4) {
        0 => Downlink::Status(link::LinkStatus::WatchdogTripped),
        1 => Downlink::Report(link::Report {
            steps: word(rng),
            total_step_cost: rng.next_u64() >> rng.below(64),
            stack_peak_bytes: word(rng),
            ..link::Report::default()
        }),
        _ => Downlink::Telemetry(Telemetry {
            seq: word(rng),
            rpm: rng.f32s(),
            thrust_n: rng.f32s(),
            duty: [rng.next_u64() as u16; 4],
            a: rng.f32s(),
            faults: rng.next_u64() as u16,
            step_cost: word(rng),
            bad_frames: word(rng),
            watchdog_trips: word(rng),
        }),
    }
}

/// Bit-exact comparison of decoded messages (postcard re-encoding: f32 -0.0 vs 0.0 differ).
fn same<T: serde::Serialize>(a: &Result<T, FrameError>, b: &Result<T, FrameError>) -> bool {
    match (a, b) {
        (Ok(x), Ok(y)) => postcard_bytes(x) == postcard_bytes(y),
        (Err(x), Err(y)) => x == y,
        _ => false,
    }
}

#[test]
fn frames_are_byte_identical_to_the_reference_framing() {
    let mut rng = SplitMix64(1);
    let mut buf = [0u8; link::MAX_FRAME];
    for _ in 0..2000 {
        let up = random_uplink(&mut rng);
        let n = link::encode(&up, &mut buf).unwrap();
        assert_eq!(&buf[..n], &frame_by_reference(&up)[..], "{up:?}");
        let down = random_downlink(&mut rng);
        let n = link::encode(&down, &mut buf).unwrap();
        assert_eq!(&buf[..n], &frame_by_reference(&down)[..], "{down:?}");
    }
    // COBS edge cases: long runs without zeros (a full 254-byte group) and all zeros.
    for len in [0usize, 1, 253, 254, 255, 300] {
        for fill in [0u8, 1, 0xFF] {
            let src: Vec<u8> = (0..len)
                .map(|i| if i % 7 == 3 { 0 } else { fill })
                .collect();
            let mut enc = vec![0u8; len + len / 254 + 2];
            let n = cobs::try_encode(&src, &mut enc).unwrap();
            if len > 0 {
                assert_eq!(
                    &enc[..n],
                    &cobs_encode_reference(&src)[..],
                    "len {len} fill {fill}"
                );
            }
            assert_eq!(
                cobs_decode_reference(&cobs_encode_reference(&src)),
                Some(src)
            );
        }
    }
}

/// Feeds `stream` to a fresh decoder and to the reference; both must yield the same results in
/// the same order.
fn check_stream<T>(stream: &[u8]) -> usize
where
    T: for<'de> serde::Deserialize<'de> + serde::Serialize + core::fmt::Debug,
{
    let got = decode_all::<T>(stream);
    let want: Vec<Result<T, FrameError>> = stream
        .split(|&b| b == 0)
        .take(stream.split(|&b| b == 0).count() - 1) // bytes after the last delimiter wait
        .filter_map(frame_reference::<T>)
        .collect();
    assert_eq!(got.len(), want.len(), "{got:?}\n{want:?}");
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(same(g, w), "result {k}: {g:?} vs {w:?}");
    }
    got.len()
}

/// The stable-toolchain counterpart of `fuzz/fuzz_targets/link_frame.rs`, run by the README's
/// test command: 3,000 seeded streams of valid, corrupted, truncated, spliced and overlong
/// frames and random bytes, for both directions. The decoder never panics, yields exactly what
/// the reference framing says (message, or which error) in order, and resynchronises at every
/// delimiter.
#[test]
fn randomized_streams_decode_as_the_reference_says() {
    let mut rng = SplitMix64(0x11AC);
    let mut outcomes = [0usize; 5]; // ok, Overflow, Cobs, Crc, Decode
    for case in 0..3000 {
        let mut stream = Vec::new();
        for _ in 0..1 + rng.below(8) {
            let mut frame = if case % 2 == 0 {
                frame_by_reference(&random_uplink(&mut rng))
            } else {
                frame_by_reference(&random_downlink(&mut rng))
            };
            match rng.below(8) {
                0 | 1 => {} // intact
                2 => {
                    let k = rng.below(frame.len() - 1);
                    frame[k] ^= 1 << rng.below(8); // may create a zero: a split frame
                }
                3 => {
                    let k = rng.below(frame.len() - 1);
                    frame[k] = rng.next_u64() as u8;
                }
                4 => {
                    let keep = rng.below(frame.len());
                    frame.drain(keep..frame.len() - 1); // truncated, still delimited
                }
                5 => {
                    // Overlong: random non-zero bytes past MAX_FRAME.
                    frame = (0..link::MAX_FRAME + 1 + rng.below(300))
                        .map(|_| 1 + rng.below(255) as u8)
                        .collect();
                    frame.push(0);
                }
                6 => {
                    // Random bytes, zeros included.
                    frame = (0..rng.below(80)).map(|_| rng.next_u64() as u8).collect();
                }
                _ => {
                    let k = rng.below(frame.len());
                    frame.insert(k, rng.next_u64() as u8);
                }
            }
            stream.extend_from_slice(&frame);
        }
        stream.push(0);
        let n = if case % 2 == 0 {
            check_stream::<Uplink>(&stream)
        } else {
            check_stream::<Downlink>(&stream)
        };
        assert!(n > 0 || stream.iter().all(|&b| b == 0));
        // Tally what the decoder saw, to show that every path is reached.
        for r in decode_all::<Uplink>(&stream) {
            let k = match r {
                Ok(_) => 0,
                Err(FrameError::Overflow) => 1,
                Err(FrameError::Cobs) => 2,
                Err(FrameError::Crc) => 3,
                Err(FrameError::Decode) => 4,
            };
            outcomes[k] += 1;
        }
    }
    assert!(
        outcomes.iter().all(|&n| n > 0),
        "ok/Overflow/Cobs/Crc/Decode: {outcomes:?}"
    );
}

#[test]
fn corrupted_frame_is_dropped_and_decoder_resyncs() {
    let mut buf = [0u8; link::MAX_FRAME];
    let n = link::encode(&Uplink::Hello, &mut buf).unwrap();
    let mut bytes = buf[..n].to_vec();
    bytes[1] ^= 0x10; // flip a payload bit
    bytes.extend_from_slice(&buf[..n]);
    let got = decode_all::<Uplink>(&bytes);
    assert_eq!(got, vec![Err(FrameError::Crc), Ok(Uplink::Hello)]);
}

#[test]
fn overlong_frame_is_an_overflow() {
    let mut bytes = vec![1u8; link::MAX_FRAME + 10];
    bytes.push(0);
    assert_eq!(
        decode_all::<Uplink>(&bytes),
        vec![Err(FrameError::Overflow)]
    );
}

#[test]
fn telemetry_fits_a_frame() {
    let t = Telemetry {
        seq: u32::MAX,
        step_cost: u32::MAX,
        bad_frames: u32::MAX,
        watchdog_trips: u32::MAX,
        faults: u16::MAX,
        duty: [u16::MAX; 4],
        ..Telemetry::default()
    };
    let mut buf = [0u8; link::MAX_FRAME];
    assert!(link::encode(&Downlink::Telemetry(t), &mut buf).is_ok());
}

#[test]
fn pwm_map_matches_gym_pybullet_drones() {
    assert_eq!(rpm_to_pwm(0.0), 0);
    assert_eq!(rpm_to_pwm(f32::NAN), 0);
    assert_eq!(rpm_to_pwm(-5.0), 0);
    assert_eq!(rpm_to_pwm(1e9), u16::MAX);
    // Hover of the CF2X: 14 468 rpm ↔ PWM ≈ 38 725.
    let pwm = rpm_to_pwm(14_468.0);
    assert!((pwm as i32 - 38_725).abs() <= 1, "{pwm}");
    assert!((pwm_to_rpm(pwm) - 14_468.0).abs() < 0.5);
}

#[test]
fn loop_steps_only_on_fresh_input_and_watchdog_stops_motors() {
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    let mut m = motors();
    // No state yet: motors off, nothing to report.
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!(m.m1.0, 0);
    l.on_input(hover_input(1));
    let TickOutcome::Stepped(t) = l.tick(&mut m, &mut NoCost) else {
        panic!("expected a step")
    };
    assert_eq!(t.seq, 1);
    assert!(t.rpm.iter().all(|r| *r > 10_000.0), "{:?}", t.rpm);
    assert!(m.m1.0 > 0);
    // Hold for WATCHDOG_TICKS - 1 ticks, trip on the last.
    for _ in 1..WATCHDOG_TICKS {
        assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
        assert!(m.m1.0 > 0);
    }
    assert_eq!(
        l.tick(&mut m, &mut NoCost),
        TickOutcome::Stopped(link::LinkStatus::WatchdogTripped)
    );
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    // A valid state resumes control.
    l.on_input(hover_input(2));
    assert!(matches!(
        l.tick(&mut m, &mut NoCost),
        TickOutcome::Stepped(_)
    ));
    assert!(m.m1.0 > 0);
}

/// A fresh `static` slot for [`crate::control_loop::load_model`] (leaked: tests only).
fn slot() -> &'static mut LearnedModel {
    Box::leak(Box::new(LearnedModel::new(ModelWeights::ZERO)))
}

#[test]
fn bad_blob_keeps_motors_off() {
    let slot = slot();
    let err = crate::control_loop::load_model(b"not a blob", slot).unwrap_err();
    assert_eq!(err, hamflight::blob::BlobError::BadMagic);
    let mut l = ControlLoop::<crate::control_loop::Model>::new(Err(err));
    let mut m = motors();
    l.on_input(hover_input(1));
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    assert_eq!(l.status(), link::LinkStatus::BadBlob);
}

#[test]
fn embedded_blob_passes_its_checks_and_decodes_in_place() {
    let model = crate::control_loop::load_model(crate::WEIGHT_BLOB, slot());
    assert!(model.is_ok());
    // The model flies the slot, which now holds exactly what decoding by value gives.
    #[cfg(not(hamflight_untrained))]
    assert_eq!(
        model.map(|m| m.weights),
        hamflight::blob::decode(crate::WEIGHT_BLOB)
    );
}

#[test]
fn wire_state_round_trips() {
    let s = State {
        p_m: Vector3::new(1.0, 2.0, 3.0),
        rot: nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3).into_inner(),
        v_body_m_s: Vector3::new(0.1, 0.2, 0.3),
        w_body_rad_s: Vector3::new(-1.0, 0.5, 2.0),
    };
    let back = State::from(&WireState::from(&s));
    assert_eq!(
        (back.p_m, back.v_body_m_s, back.w_body_rad_s),
        (s.p_m, s.v_body_m_s, s.w_body_rad_s)
    );
    // The attitude goes through its unit quaternion: equal to f32 rounding, still a rotation.
    assert!(
        (back.rot - s.rot).norm() < 1e-6,
        "{} vs {}",
        back.rot,
        s.rot
    );
    assert!(hamflight::is_rotation(&back.rot));
}

/// An input off the hover point (position, velocity and attitude errors), so that the
/// adaptation law moves the estimate every step.
fn off_input(seq: u32) -> Input {
    let k = seq as f32;
    let p = Vector3::new(0.0, 0.0, 0.5);
    Input {
        seq,
        state: WireState::from(&State {
            p_m: p + Vector3::new(0.05 + 0.001 * k, -0.03, 0.02),
            rot: nalgebra::Rotation3::from_euler_angles(0.05, -0.03, 0.1).into_inner(),
            v_body_m_s: Vector3::new(0.1, 0.0, -0.05),
            w_body_rad_s: Vector3::new(0.2, -0.1, 0.05),
        }),
        setpoint: Some(Setpoint::hover(p, 0.0)),
    }
}

/// Feeds `arrivals[k]` (an input or a dropped frame) at tick k into the loop, and steps a
/// reference controller on the same states with `dt_of(ticks since its last step)`; returns
/// the loop's and the reference's estimates after each step.
fn fly_with_drops(
    arrivals: &[Option<Input>],
    dt_of: impl Fn(u32) -> f32,
) -> Vec<([f32; 6], [f32; 6])> {
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    let mut reference =
        hamflight::FlightController::new(NominalModel::default(), hamflight::Gains::default());
    let mut m = motors();
    let mut out = Vec::new();
    let mut since: Option<u32> = None;
    for arrival in arrivals {
        since = since.map(|n| n + 1);
        match arrival {
            Some(input) => {
                l.on_input(*input);
                let TickOutcome::Stepped(t) = l.tick(&mut m, &mut NoCost) else {
                    panic!("a fresh input must step")
                };
                let dt_s = dt_of(since.unwrap_or(1));
                let r = reference.step(&State::from(&input.state), &input.setpoint.unwrap(), dt_s);
                assert!(!r.faults.is_fault(), "{:?}", r.faults);
                since = Some(0);
                let mut a = [0.0; 6];
                a.iter_mut().zip(r.a.iter()).for_each(|(d, s)| *d = *s);
                out.push((t.a, a));
            }
            None => assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle),
        }
    }
    out
}

#[test]
fn adaptation_integrates_the_real_time_across_dropped_frames() {
    use crate::control_loop::DT_S;
    // Ticks 0..12 with frames 3, 6, 7 and 9 dropped (gaps of 2 and 3 periods).
    let dropped = [3, 6, 7, 9];
    let arrivals: Vec<Option<Input>> = (0..12)
        .map(|k| (!dropped.contains(&k)).then(|| off_input(k)))
        .collect();
    // The loop agrees exactly with a controller stepped with dt = ticks since the last step.
    let real = fly_with_drops(&arrivals, |ticks| ticks as f32 * DT_S);
    assert_eq!(real.len(), 8);
    for (k, (fw, reference)) in real.iter().enumerate() {
        assert_eq!(fw, reference, "step {k}");
    }
    // ...and not with one stepped with the fixed period (the old behaviour): the test bites.
    let fixed = fly_with_drops(&arrivals, |_| DT_S);
    let (fw, fixed_ref) = fixed.last().unwrap();
    let diff = fw
        .iter()
        .zip(fixed_ref)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(diff > 1e-6, "estimates differ by only {diff}");
    // Without drops the two agree: dt is the period.
    let all: Vec<Option<Input>> = (0..12).map(|k| Some(off_input(k))).collect();
    for (fw, reference) in fly_with_drops(&all, |_| DT_S) {
        assert_eq!(fw, reference);
    }
}

#[test]
fn dt_follows_the_sequence_bounded_by_the_ticks() {
    use crate::control_loop::{dt_for, DT_S};
    // First state, or the first after a watchdog trip: one period.
    assert_eq!(dt_for(None, 1), DT_S);
    assert_eq!(dt_for(None, 5), DT_S);
    // Consecutive states: one period, however many ticks the firmware waited (lock-step host).
    assert_eq!(dt_for(Some(1), 1), DT_S);
    assert_eq!(dt_for(Some(7), 1), DT_S);
    // Lost states: the gap, bounded by the ticks that passed.
    assert_eq!(dt_for(Some(3), 3), 3.0 * DT_S);
    assert_eq!(dt_for(Some(2), 3), 2.0 * DT_S);
    // Repeated, restarted (backwards) or jumping sequence: one period.
    assert_eq!(dt_for(Some(3), 0), DT_S);
    assert_eq!(dt_for(Some(3), 0u32.wrapping_sub(4)), DT_S);
    assert_eq!(dt_for(Some(WATCHDOG_TICKS), WATCHDOG_TICKS + 1), DT_S);
    // The longest dt is the watchdog timeout, inside the core's (0, 0.1] s.
    assert_eq!(
        dt_for(Some(u32::MAX), WATCHDOG_TICKS),
        WATCHDOG_TICKS as f32 * DT_S
    );
    assert!(WATCHDOG_TICKS as f32 * DT_S <= 0.1);
}

/// Like [`fly_with_drops`], but with `ticks` timer ticks and inputs `(tick, seq)`.
fn fly_schedule(
    ticks: u32,
    inputs: &[(u32, u32)],
    dt_periods: &[u32],
) -> (Vec<[f32; 6]>, Vec<[f32; 6]>) {
    use crate::control_loop::DT_S;
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    let mut reference =
        hamflight::FlightController::new(NominalModel::default(), hamflight::Gains::default());
    let mut m = motors();
    let (mut fw, mut re) = (Vec::new(), Vec::new());
    let mut steps = 0;
    for tick in 0..ticks {
        if let Some(&(_, seq)) = inputs.iter().find(|(t, _)| *t == tick) {
            let mut input = off_input(steps);
            input.seq = seq;
            l.on_input(input);
            let r = reference.step(
                &State::from(&input.state),
                &input.setpoint.unwrap(),
                dt_periods[steps as usize] as f32 * DT_S,
            );
            let mut a = [0.0; 6];
            a.iter_mut().zip(r.a.iter()).for_each(|(d, s)| *d = *s);
            re.push(a);
            steps += 1;
        }
        if let TickOutcome::Stepped(t) = l.tick(&mut m, &mut NoCost) {
            fw.push(t.a);
        }
    }
    (fw, re)
}

#[test]
fn lock_step_host_gets_one_period_per_state_however_long_the_firmware_waits() {
    // A state every third tick, consecutive seq (the PIL test's lock-step): dt = one period,
    // the plant's step, not the three ticks the firmware idled.
    let inputs: Vec<(u32, u32)> = (0..8).map(|k| (3 * k, 100 + k)).collect();
    let (fw, re) = fly_schedule(24, &inputs, &[1; 8]);
    assert_eq!(fw.len(), 8);
    assert_eq!(fw, re);
    // The same schedule with seq skipping by 3 (states lost on the link): three periods.
    let inputs: Vec<(u32, u32)> = (0..8).map(|k| (3 * k, 3 * k)).collect();
    let (fw, re) = fly_schedule(24, &inputs, &[1, 3, 3, 3, 3, 3, 3, 3]);
    assert_eq!(fw, re);
    // A sender that jumps seq by 5 while only 2 ticks pass: bounded by the ticks.
    let inputs: Vec<(u32, u32)> = (0..6).map(|k| (2 * k, 5 * k)).collect();
    let (fw, re) = fly_schedule(12, &inputs, &[1, 2, 2, 2, 2, 2]);
    assert_eq!(fw, re);
}

#[test]
fn dt_is_one_period_after_a_watchdog_trip() {
    use crate::control_loop::DT_S;
    // Through a trip: the first state after it integrates one period, not the whole gap.
    let mut arrivals: Vec<Option<Input>> = vec![Some(off_input(0)), Some(off_input(1))];
    arrivals.extend((0..WATCHDOG_TICKS + 5).map(|_| None));
    arrivals.push(Some(off_input(2)));
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    let mut reference =
        hamflight::FlightController::new(NominalModel::default(), hamflight::Gains::default());
    let mut m = motors();
    let mut last = None;
    for arrival in &arrivals {
        if let Some(input) = arrival {
            l.on_input(*input);
            let r = reference.step(&State::from(&input.state), &input.setpoint.unwrap(), DT_S);
            last = Some(r.a);
        }
        let outcome = l.tick(&mut m, &mut NoCost);
        if let (Some(_), TickOutcome::Stepped(t)) = (arrival, outcome) {
            let a = last.unwrap();
            assert!(t.a.iter().zip(a.iter()).all(|(x, y)| x == y));
        }
    }
    assert_eq!(l.report().watchdog_trips, 1);
}

/// The frame sizes the link's module doc, `crazyflie.rs`'s baud rate and docs/performance.md's link
/// budget are computed from (postcard varints at their longest, and at a sequence number below 2²¹).
#[test]
fn frame_sizes_fit_the_baud_budget() {
    let len = |msg: &Uplink| {
        let mut buf = [0u8; link::MAX_FRAME];
        link::encode(msg, &mut buf).unwrap()
    };
    let full = |seq| Uplink::Input(hover_input(seq));
    let bare = |seq| {
        Uplink::Input(Input {
            setpoint: None,
            ..hover_input(seq)
        })
    };
    assert_eq!(len(&full(u32::MAX)), 122);
    assert_eq!(len(&full((1 << 21) - 1)), 120);
    assert_eq!(len(&bare(u32::MAX)), 66);
    assert_eq!(len(&bare((1 << 21) - 1)), 64);
    let with_acc = Uplink::Input(Input {
        state: WireState {
            acc: Some([0.0, 0.0, 9.81]),
            ..hover_input(1).state
        },
        ..hover_input((1 << 21) - 1)
    });
    assert_eq!(len(&with_acc), 132);
    let mut buf = [0u8; link::MAX_FRAME];
    let worst = Telemetry {
        seq: u32::MAX,
        step_cost: u32::MAX,
        bad_frames: u32::MAX,
        watchdog_trips: u32::MAX,
        faults: u16::MAX,
        duty: [u16::MAX; 4],
        ..Telemetry::default()
    };
    assert_eq!(
        link::encode(&Downlink::Telemetry(worst), &mut buf).unwrap(),
        98
    );
    // In flight: seq < 2²¹, duty ≥ 2¹⁴, a few faults bits, a step of < 2²¹ cycles, no errors.
    let typical = Telemetry {
        seq: (1 << 21) - 1,
        step_cost: 30_000,
        faults: 0x70,
        duty: [40_000; 4],
        ..Telemetry::default()
    };
    assert_eq!(
        link::encode(&Downlink::Telemetry(typical), &mut buf).unwrap(),
        84
    );
    // 8N1: 10 bits a byte. Uplink with the setpoint every tick, downlink at its longest.
    let bytes_per_ms = |baud: u32| baud / 10 / 1000;
    assert!(120 * crate::control_loop::LOOP_HZ / 1000 <= bytes_per_ms(2_000_000) * 6 / 10);
    assert!(98 * 500 / 1000 <= bytes_per_ms(1_000_000) / 2);
}

#[test]
fn setpoint_is_held_between_inputs_and_forgotten_on_a_watchdog_trip() {
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    // The loop's own gains: those of the model's facts (its J comes back through J⁻¹, so the
    // per-axis attitude factor is one only to rounding, and this compares bit for bit).
    let facts = hamflight::VehicleFacts::of(&NominalModel::default());
    let mut reference = hamflight::FlightController::new(
        NominalModel::default(),
        crate::control_loop::default_gains(&facts),
    );
    let mut m = motors();
    let bare = |seq| Input {
        setpoint: None,
        ..off_input(seq)
    };
    // A state without any setpoint yet: no step, motors off.
    l.on_input(bare(1));
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    assert_eq!(l.status(), link::LinkStatus::WaitingForState);
    // One with a setpoint, then states alone: each flies the held setpoint, exactly as a
    // controller given that setpoint every step.
    let sp = off_input(2).setpoint.unwrap();
    for seq in 2..8 {
        l.on_input(if seq == 2 { off_input(seq) } else { bare(seq) });
        let TickOutcome::Stepped(t) = l.tick(&mut m, &mut NoCost) else {
            panic!("input {seq} did not step")
        };
        let want = reference.step(
            &State::from(&off_input(seq).state),
            &sp,
            crate::control_loop::DT_S,
        );
        assert_eq!(t.rpm, want.rotors.rpm, "input {seq}");
        // Flying, not off. (Not every rotor: these repeated states are not a motion, and the
        // composite law, the default, reads their constant rates as a torque to cancel.)
        assert!(t.rpm.iter().any(|r| *r > 1000.0), "{:?}", t.rpm);
    }
    // Silence until the watchdog trips: the setpoint is forgotten, a bare state does not step.
    while l.tick(&mut m, &mut NoCost) != TickOutcome::Stopped(link::LinkStatus::WatchdogTripped) {}
    l.on_input(bare(100));
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    l.on_input(off_input(101));
    assert!(matches!(
        l.tick(&mut m, &mut NoCost),
        TickOutcome::Stepped(_)
    ));
}

/// Decoded inputs of every kind (random fields; unit, slightly and far off-unit and non-finite
/// quaternions) through the control loop: never a panic; a quaternion whose norm is off 1 by
/// more than 2e-4 (the documented tolerance is ≈ 1.4e-4: `hamflight::lie::rot_from_quat`) or
/// with a non-finite component is a `bad_state` with the motors off; one within 1e-4 is not.
#[test]
fn malformed_quaternions_are_bad_states_never_panics() {
    let mut rng = SplitMix64(0x9A7);
    let mut l = ControlLoop::new(Ok(NominalModel::default()));
    let mut m = motors();
    let (mut refused, mut accepted) = (0, 0);
    for seq in 1..4000u32 {
        let Uplink::Input(mut input) = random_uplink(&mut rng) else {
            continue;
        };
        input.seq = seq;
        // Through the frame codec, as the firmware receives it.
        let mut buf = [0u8; link::MAX_FRAME];
        let n = link::encode(&Uplink::Input(input), &mut buf).unwrap();
        let Some(Ok(Uplink::Input(input))) = decode_all::<Uplink>(&buf[..n]).pop() else {
            panic!("{input:?} did not decode")
        };
        let q = input.state.q;
        let norm = q.iter().map(|&c| f64::from(c).powi(2)).sum::<f64>().sqrt();
        l.on_input(input);
        let TickOutcome::Stepped(t) = l.tick(&mut m, &mut NoCost) else {
            continue; // no setpoint held yet
        };
        let bad = t.faults & link::fault_bits::BAD_STATE != 0;
        if !norm.is_finite() || (norm - 1.0).abs() > 2e-4 {
            assert!(bad, "q = {q:?} (|q| = {norm}) was accepted");
            assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
            refused += 1;
        } else if (norm - 1.0).abs() < 1e-4 {
            assert!(!bad, "q = {q:?} (|q| = {norm}) was refused");
            accepted += 1;
        }
    }
    assert!(refused > 500 && accepted > 500, "{refused} / {accepted}");
}
