//! The loop's time step: dt from the sequence numbers, across dropped frames and watchdog trips.

use super::{motors, off_input};
use crate::control_loop::{ControlLoop, NoCost, TickOutcome, WATCHDOG_TICKS};
use crate::link::Input;
use hamflight::model::NominalModel;
use hamflight::State;

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
