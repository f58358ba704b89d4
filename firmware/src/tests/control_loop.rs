//! The control loop: stepping on fresh input, the watchdog, the held setpoint, bad states.

use super::{decode_all, hover_input, motors, off_input, random_uplink, SplitMix64};
use crate::control_loop::{ControlLoop, NoCost, TickOutcome, WATCHDOG_TICKS};
use crate::link::{self, Input, Uplink};
use hamflight::model::NominalModel;
use hamflight::State;

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
