//! Host unit tests of the chip-independent parts.

use crate::control_loop::{ControlLoop, NoCost, TickOutcome, WATCHDOG_TICKS};
use crate::link::{
    self, Downlink, FrameDecoder, FrameError, Input, Telemetry, Uplink, WireSetpoint, WireState,
};
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
    assert_eq!(State::from(&WireState::from(&s)), s);
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
        setpoint: WireSetpoint::from(&Setpoint::hover(p, 0.0)),
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
                let r = reference.step(
                    &State::from(&input.state),
                    &Setpoint::from(&input.setpoint),
                    dt_s,
                );
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
fn dt_is_one_period_after_a_watchdog_trip_and_capped() {
    use crate::control_loop::{dt_for, DT_S};
    assert_eq!(dt_for(None), DT_S);
    assert_eq!(dt_for(Some(0)), DT_S);
    assert_eq!(dt_for(Some(1)), DT_S);
    assert_eq!(dt_for(Some(3)), 3.0 * DT_S);
    assert_eq!(dt_for(Some(u32::MAX)), WATCHDOG_TICKS as f32 * DT_S);
    assert!(dt_for(Some(u32::MAX)) <= 0.1);

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
            let r = reference.step(
                &State::from(&input.state),
                &Setpoint::from(&input.setpoint),
                DT_S,
            );
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
