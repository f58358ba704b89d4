//! The setpoint's jerk feed-forward through the C shim: a setpoint without jerk but with the
//! desired body rates (a full-state setpoint, crtp_commander_generic.c's fullStateDecoder) gets
//! the jerk those rates stand for; a setpoint's own jerk wins; zero rates give zero jerk.
//!
//! The shim's converted setpoint is not visible from outside, so each case compares the wrench
//! of one step from a freshly engaged shim (on the ground: no adaptation, the core just reset),
//! which depends on nothing but the state and the setpoint, with the wrench of the setpoint
//! carrying the expected jerk itself.

use super::*;

/// The state every case steps from: 0.5 m up, tilted a little, moving and turning, so that the
/// law's every term is at work.
fn state() -> PlantState {
    let mut s = PlantState::at_rest(Vector3::new(0.1, -0.2, 0.5), 0.2);
    s.rot = Rotation3::from_euler_angles(0.05, -0.08, 0.2).into_inner();
    s.v_body_m_s = Vector3::new(0.3, -0.1, 0.05);
    s.w_body_rad_s = Vector3::new(0.4, -0.3, 0.1);
    s
}

/// The reference: position, velocity, acceleration (about 8° of tilt), jerk and yaw.
struct Reference {
    p: [f32; 3],
    v: [f32; 3],
    a: Vector3<f64>,
    j: Vector3<f64>,
    yaw_rad: f64,
}

fn reference() -> Reference {
    Reference {
        p: [0.12, -0.18, 0.52],
        v: [0.4, -0.2, 0.1],
        a: Vector3::new(1.2, -0.7, 0.4),
        j: Vector3::new(6.0, 10.0, -4.0),
        yaw_rad: 0.3,
    }
}

/// The body rates (rad/s) a trajectory with acceleration `a`, jerk `j` and yaw `yaw` has, as
/// Bitcraze's pptraj.c (`poly4d_eval`) and Crazyswarm's `uav_trajectory` compute them, in f64,
/// with the jerk's part across the thrust axis (what the rates stand for).
fn flatness_rates(a: &Vector3<f64>, j: &Vector3<f64>, yaw: f64) -> (f64, f64, Vector3<f64>) {
    let thrust = a + Vector3::z() * 9.81;
    let z_b = thrust.normalize();
    let x_c = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let y_b = z_b.cross(&x_c).normalize();
    let x_b = y_b.cross(&z_b);
    let j_across = j - z_b * j.dot(&z_b);
    let h = j_across / thrust.norm();
    (-h.dot(&y_b), h.dot(&x_b), j_across)
}

/// What one setpoint sets besides position, velocity and acceleration.
#[derive(Clone)]
struct Feed {
    /// Modes x, y, z, yaw.
    modes: [c_int; 4],
    /// Modes roll, pitch, quaternion.
    modes_rpq: [c_int; 3],
    jerk: Vector3<f64>,
    /// Body rates roll, pitch (rad/s).
    rates: (f64, f64),
}

/// A full-state setpoint (fullStateDecoder): x, y, z modeAbs with position, velocity and
/// acceleration, the jerk 0, the attitude as a quaternion (here the yaw alone, as Crazyswarm's
/// cmdFullState sends it) in modeAbs, roll, pitch and yaw modeDisable, and the body rates.
fn full_state(rates: (f64, f64)) -> Feed {
    Feed {
        modes: [ABS, ABS, ABS, DISABLE],
        modes_rpq: [DISABLE, DISABLE, ABS],
        jerk: Vector3::zeros(),
        rates,
    }
}

/// The wrench of the first step of a freshly engaged shim, at [`state`] and the reference with
/// `feed`.
fn one_step(r: &Reference, feed: &Feed) -> [f32; 4] {
    let mut shim = Shim::new();
    shim.supervisor(true, false);
    shim.set_state(&state());
    let a = r.a.cast::<f32>();
    let j = feed.jerk.cast::<f32>();
    let (s, c) = (0.5 * r.yaw_rad).sin_cos();
    let q = [0.0, 0.0, s as f32, c as f32];
    // SAFETY: arrays of four ints, three and four floats; exclusive (the shim holds the lock).
    unsafe {
        hf_host_set_setpoint(
            feed.modes.as_ptr(),
            r.p.as_ptr(),
            r.v.as_ptr(),
            a.as_ptr(),
            j.as_ptr(),
            r.yaw_rad.to_degrees() as f32,
            0.0,
            0.0,
            false,
        );
        hf_host_set_setpoint_attitude(
            feed.modes_rpq.as_ptr(),
            feed.rates.0.to_degrees() as f32,
            feed.rates.1.to_degrees() as f32,
            q.as_ptr(),
        );
    }
    let w = shim.tick();
    assert_eq!(shim.log_u8("phase"), 1, "engaged, on the ground");
    assert_eq!(shim.log_u32("faults") & 0xFFFF_0000, 0, "no shim fault");
    w
}

/// The largest difference of two wrenches' components.
fn gap(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn full_state_body_rates_rebuild_the_jerk_they_stand_for() {
    let r = reference();
    let (wx, wy, j_across) = flatness_rates(&r.a, &r.j, r.yaw_rad);
    assert!(wx.abs() > 0.1 && wy.abs() > 0.1, "rates {wx} {wy} rad/s");
    // The full-state setpoint: body rates, no jerk.
    let from_rates = one_step(&r, &full_state((wx, wy)));
    // The same setpoint carrying the expected jerk itself, and no rates.
    let with_jerk = one_step(
        &r,
        &Feed {
            jerk: j_across,
            ..full_state((0.0, 0.0))
        },
    );
    let again = one_step(
        &r,
        &Feed {
            jerk: j_across,
            ..full_state((0.0, 0.0))
        },
    );
    assert_eq!(with_jerk, again, "one step from a fresh shim is repeatable");
    let without = one_step(&r, &full_state((0.0, 0.0)));
    let effect = gap(&with_jerk, &without);
    let off = gap(&from_rates, &with_jerk);
    println!(
        "wrench from the rates {from_rates:?}, with the jerk {with_jerk:?}, without {without:?}: \
         the jerk moves it by {effect:.3e}, the rebuilt one is {off:.3e} off"
    );
    assert!(effect > 1e-4, "the jerk matters here: {effect:e}");
    assert!(
        off <= effect * 1e-3,
        "the rebuilt jerk's wrench {from_rates:?} is the expected jerk's {with_jerk:?} \
         (off by {off:e}, the jerk's effect {effect:e})"
    );
    // The rates of the jerk's part across the thrust axis are the jerk's: the part along it,
    // the thrust's rate, is not in the rates (nor needed by the attitude).
    let (wx2, wy2, _) = flatness_rates(&r.a, &j_across, r.yaw_rad);
    assert!((wx2 - wx).abs() < 1e-12 && (wy2 - wy).abs() < 1e-12);

    // The high-level commander's form (yaw modeAbs, no quaternion) rebuilds it as well.
    let hlc = |jerk: Vector3<f64>, rates| Feed {
        modes: [ABS; 4],
        modes_rpq: [DISABLE, DISABLE, DISABLE],
        jerk,
        rates,
    };
    let hlc_rates = one_step(&r, &hlc(Vector3::zeros(), (wx, wy)));
    let hlc_jerk = one_step(&r, &hlc(j_across, (0.0, 0.0)));
    let off = gap(&hlc_rates, &hlc_jerk);
    assert!(off <= effect * 1e-3, "high-level form: off by {off:e}");
}

#[test]
fn a_setpoint_jerk_wins_over_its_body_rates() {
    let r = reference();
    // Rates of another trajectory's jerk: were they used, the wrench would differ.
    let other = Vector3::new(-4.0, 1.0, 0.5);
    let (wx, wy, other_across) = flatness_rates(&r.a, &other, r.yaw_rad);
    let both = one_step(
        &r,
        &Feed {
            jerk: r.j,
            ..full_state((wx, wy))
        },
    );
    let jerk_only = one_step(
        &r,
        &Feed {
            jerk: r.j,
            ..full_state((0.0, 0.0))
        },
    );
    assert_eq!(both, jerk_only, "the setpoint's jerk, as it is");
    let rates_jerk = one_step(
        &r,
        &Feed {
            jerk: other_across,
            ..full_state((0.0, 0.0))
        },
    );
    assert!(gap(&both, &rates_jerk) > 1e-4, "the rates were not used");
}

#[test]
fn zero_body_rates_or_rate_commands_give_zero_jerk() {
    let r = reference();
    let no_jerk = |feed: Feed| Feed {
        jerk: Vector3::zeros(),
        rates: (0.0, 0.0),
        ..feed
    };
    // A full-state setpoint without rates (the plant's streamed setpoints): zero jerk, as a
    // position setpoint with acceleration feed-forward has.
    let zero = one_step(&r, &full_state((0.0, 0.0)));
    let position = one_step(
        &r,
        &Feed {
            modes: [ABS; 4],
            ..no_jerk(full_state((0.0, 0.0)))
        },
    );
    let (wx, wy, _) = flatness_rates(&r.a, &r.j, r.yaw_rad);
    let rates = one_step(&r, &full_state((wx, wy)));
    assert!(gap(&zero, &rates) > 1e-4, "rates would change the wrench");
    // The yaw of the quaternion is the yaw reference's, up to rounding.
    assert!(gap(&zero, &position) < 1e-6, "{zero:?} {position:?}");
    // Rates that are not a trajectory's feed-forward are not used: roll and pitch in
    // modeVelocity (a manual rate command), or an axis not in modeAbs.
    let cases = [
        Feed {
            modes_rpq: [VELOCITY, VELOCITY, ABS],
            ..full_state((wx, wy))
        },
        Feed {
            modes_rpq: [DISABLE, VELOCITY, ABS],
            ..full_state((wx, wy))
        },
        Feed {
            modes: [ABS, ABS, VELOCITY, DISABLE],
            ..full_state((wx, wy))
        },
        Feed {
            modes: [ABS, DISABLE, ABS, DISABLE],
            ..full_state((wx, wy))
        },
    ];
    for case in cases {
        let without = one_step(&r, &no_jerk(case.clone()));
        let w = one_step(&r, &case);
        assert_eq!(
            w, without,
            "modes {:?} {:?}: the rates ignored",
            case.modes, case.modes_rpq
        );
    }
}
