//! Host unit tests of the chip-independent parts.

use crate::control_loop::{ControlLoop, NoCost, TickOutcome, WATCHDOG_TICKS};
use crate::link::{
    self, Downlink, FrameDecoder, FrameError, Input, Telemetry, Uplink, WireSetpoint, WireState,
};
use crate::motor::{pwm_to_rpm, rpm_to_pwm, Motors};
use core::convert::Infallible;
use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use hamflight::model::NominalModel;
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
        setpoint: WireSetpoint::from(&Setpoint::hover(p, 0.0)),
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

#[test]
fn cobs_round_trips_long_and_zero_runs() {
    for len in [0usize, 1, 253, 254, 255, 300] {
        for fill in [0u8, 1, 0xFF] {
            let src: Vec<u8> = (0..len)
                .map(|i| if i % 7 == 3 { 0 } else { fill })
                .collect();
            let mut enc = vec![0u8; len + len / 254 + 2];
            let n = link::cobs_encode(&src, &mut enc).unwrap();
            assert!(enc[..n].iter().all(|&b| b != 0));
            let m = link::cobs_decode(&mut enc[..n]).unwrap();
            assert_eq!(&enc[..m], &src[..], "len {len} fill {fill}");
        }
    }
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

#[test]
fn bad_blob_keeps_motors_off() {
    let err = crate::control_loop::load_model(b"not a blob").unwrap_err();
    assert_eq!(err, hamflight::blob::BlobError::BadMagic);
    let mut l = ControlLoop::<crate::control_loop::Model>::new(Err(err));
    let mut m = motors();
    l.on_input(hover_input(1));
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    assert_eq!(l.status(), link::LinkStatus::BadBlob);
}

#[test]
fn embedded_blob_passes_its_checks() {
    assert!(crate::control_loop::load_model(crate::WEIGHT_BLOB).is_ok());
}

#[test]
fn wire_state_round_trips() {
    let s = State {
        p_m: Vector3::new(1.0, 2.0, 3.0),
        rot: nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3).into_inner(),
        v_body_m_s: Vector3::new(0.1, 0.2, 0.3),
        w_body_rad_s: Vector3::new(-1.0, 0.5, 2.0),
    };
    assert_eq!(State::from(&WireState::from(&s)), s);
}
