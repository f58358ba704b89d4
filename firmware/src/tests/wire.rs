//! The link's messages on the wire: the state's wire form, and frame sizes against the budgets.

use super::hover_input;
use crate::link::{self, Downlink, Input, Telemetry, Uplink, WireState};
use hamflight::State;
use nalgebra::Vector3;

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
