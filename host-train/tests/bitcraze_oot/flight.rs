//! Flights through the C path: against the native controller, setpoints, phases, rates, faults.

use super::*;

#[test]
fn init_prints_the_model_and_the_self_test_passes() {
    let shim = Shim::new();
    let text = shim.debug_text();
    let crc = format!("{:08X}", hamflight_bitcraze::model::MODEL_CRC);
    assert!(
        text.contains("HAMFLIGHT: model default.hfw crc ") && text.contains(&crc),
        "DEBUG_PRINT at init names the blob and its CRC {crc}: {text:?}"
    );
    assert!(text.contains("500 Hz"), "{text:?}");
    // SAFETY: exclusive (the shim holds the lock).
    assert!(unsafe { controllerOutOfTreeTest() });
    // The parameters start at the core's defaults (as the first initialisation left them).
    let (f, b) = DEFAULTS.get().expect("recorded by Shim::new");
    let g = Gains::for_vehicle(&hamflight::VehicleFacts::of(&MODEL));
    let r = g.rates;
    let expected = [
        g.k_p,
        g.k_v,
        g.k_r,
        g.k_w,
        g.max_tilt_rad,
        r.c_p,
        r.c_v,
        r.c_r,
        r.c_w,
        r.a_max,
        0.05,
        0.3,
        g.composite.q_force,
        g.composite.q_torque,
        g.composite.r_force,
        g.composite.r_torque,
    ];
    assert_eq!(f.as_slice(), expected.as_slice(), "{F32_PARAMS:?}");
    // adapt on, no reset request, the composite law (the default).
    assert_eq!(b.as_slice(), [1, 0, 1, 0].as_slice(), "{U8_PARAMS:?}");
    assert_eq!(shim.param_f32("kp"), g.k_p);
}

#[test]
fn paper_spiral_through_the_c_path_matches_the_native_controller() {
    let gains = Gains {
        law: hamflight::AdaptationLaw::Gradient,
        ..Gains::for_vehicle(&hamflight::VehicleFacts::of(&MODEL))
    };
    c_path_matches_native(0, gains);
}

#[test]
fn the_law_parameter_selects_the_composite_law_and_matches_the_native_controller() {
    let gains = Gains {
        law: hamflight::AdaptationLaw::Composite,
        ..Gains::for_vehicle(&hamflight::VehicleFacts::of(&MODEL))
    };
    c_path_matches_native(1, gains);
}

#[test]
fn the_law_parameter_waits_until_the_vehicle_is_not_airborne() {
    let mut shim = Shim::new();
    let (mut plant, _, hold) = take_off_and_hold(&mut shim);
    assert_eq!((shim.log_u8("phase"), shim.log_u8("law")), (2, 1));
    // Written in the air: not applied (the parameter keeps the request).
    shim.set_param_u8("law", 0);
    fly_shim(&mut shim, &mut plant, 0.2, hold);
    assert_eq!(shim.log_u8("law"), 1, "no switch while airborne");
    assert_eq!(shim.param_u8("law"), 0);
    // Landed (the supervisor stops saying flying): the next ticks apply it.
    shim.supervisor(true, false);
    fly_shim(&mut shim, &mut plant, 0.01, hold);
    assert_eq!(shim.log_u8("phase"), 1);
    assert_eq!(shim.log_u8("law"), 0, "switched on the ground");
    // An unknown law is refused and the parameter reverts.
    shim.set_param_u8("law", 7);
    fly_shim(&mut shim, &mut plant, 0.01, hold);
    assert_eq!((shim.param_u8("law"), shim.log_u8("law")), (0, 0));
    // Refused Q and R revert; valid ones are taken.
    let q = shim.param_f32("qF");
    shim.set_param_f32("qF", -1.0);
    shim.set_param_f32("rT", 0.0);
    fly_shim(&mut shim, &mut plant, 0.01, hold);
    assert_eq!(shim.param_f32("qF"), q);
    assert_eq!(shim.param_f32("rT"), 1.0);
    shim.set_param_f32("rF", 2.0);
    fly_shim(&mut shim, &mut plant, 0.01, hold);
    assert_eq!(shim.param_f32("rF"), 2.0);
}

#[test]
fn velocity_setpoints_fly_in_the_world_and_in_the_body_frame() {
    let sc = scenario("hover");
    let mut plant = sc.plant();
    let start = plant.state().p_m;
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0);
    let vel = [VELOCITY, VELOCITY, ABS, ABS];
    let z = start.z as f32;

    // World frame: 0.3 m/s along x for 3 s, then stop and hold for 2 s.
    fly_shim(&mut shim, &mut plant, 3.0, |s, _| {
        s.set_setpoint(vel, [0.0, 0.0, z], [0.3, 0.0, 0.0], 0.0, 0.0, 0.0, false)
    });
    fly_shim(&mut shim, &mut plant, 2.0, |s, _| {
        s.set_setpoint(vel, [0.0, 0.0, z], [0.0; 3], 0.0, 0.0, 0.0, false)
    });
    let moved = plant.state().p_m - start;
    println!("world-frame velocity: moved {moved:?} m");
    assert!((moved.x - 0.9).abs() < 0.05, "0.3 m/s for 3 s: {moved:?}");
    assert!(moved.y.abs() < 0.03 && moved.z.abs() < 0.03, "{moved:?}");

    // Turn to yaw 90° with a yaw-rate setpoint (45°/s for 2 s), holding position.
    let turn = [VELOCITY, VELOCITY, ABS, VELOCITY];
    fly_shim(&mut shim, &mut plant, 2.0, |s, _| {
        s.set_setpoint(turn, [0.0, 0.0, z], [0.0; 3], 0.0, 45.0, 0.0, false)
    });
    fly_shim(&mut shim, &mut plant, 1.0, |s, _| {
        s.set_setpoint(turn, [0.0, 0.0, z], [0.0; 3], 0.0, 0.0, 0.0, false)
    });
    let yaw_deg = plant.state().rpy().z.to_degrees();
    assert!((yaw_deg - 90.0).abs() < 3.0, "yaw {yaw_deg}°");

    // Body frame (cflib's hover setpoint): forward at 0.3 m/s is world +y now.
    let before = plant.state().p_m;
    fly_shim(&mut shim, &mut plant, 2.0, |s, _| {
        s.set_setpoint(turn, [0.0, 0.0, z], [0.3, 0.0, 0.0], 0.0, 0.0, 0.0, true)
    });
    fly_shim(&mut shim, &mut plant, 2.0, |s, _| {
        s.set_setpoint(turn, [0.0, 0.0, z], [0.0; 3], 0.0, 0.0, 0.0, true)
    });
    let moved = plant.state().p_m - before;
    println!("body-frame velocity at yaw 90°: moved {moved:?} m");
    assert!(
        (moved.y - 0.6).abs() < 0.05,
        "forward is +y at yaw 90°: {moved:?}"
    );
    assert!(moved.x.abs() < 0.05 && moved.z.abs() < 0.03, "{moved:?}");
}

#[test]
fn velocity_reference_stays_on_the_leash() {
    // A vehicle that cannot follow (its state is held fixed) must not see its reference run
    // away: the integrated reference stays within `leash` of the estimate.
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    let s = PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0);
    shim.set_state(&s);
    let leash = shim.param_f32("leash");
    for _ in 0..3000 {
        shim.set_setpoint(
            [VELOCITY, VELOCITY, ABS, ABS],
            [0.0, 0.0, 0.5],
            [1.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            false,
        );
        shim.tick();
    }
    // The thrust tilts forward as much as a `leash` position error asks, no more: compare with
    // the native controller at exactly that error.
    let w = shim.tick();
    let mut native = hamflight::FlightController::new(
        &MODEL,
        Gains::for_vehicle(&hamflight::VehicleFacts::of(&MODEL)),
    );
    let mut sp = hamflight::Setpoint::hover(Vector3::new(leash, 0.0, 0.5), 0.0);
    sp.v_m_s.x = 1.0;
    native.gains.adapt = false;
    let o = native.step(&(&s).into(), &sp, 0.002);
    assert!(
        (w[2] - o.command.torque_nm.y).abs() < 0.05 * o.command.torque_nm.y.abs(),
        "pitch torque {} vs native at the leash {}",
        w[2],
        o.command.torque_nm.y
    );
}

#[test]
fn flight_phases_zero_output_ground_freeze_touchdown_hold_and_reset_after_landing() {
    let mut shim = Shim::new();
    let ground = PlantState::at_rest(Vector3::new(0.2, -0.1, 0.0), 0.0);
    let hover_sp =
        |s: &mut Shim| s.set_setpoint([ABS; 4], [0.2, -0.1, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
    shim.set_state(&ground);
    hover_sp(&mut shim);

    // The supervisor cannot fly (not armed): zero output.
    for _ in 0..10 {
        assert_eq!(shim.tick(), [0.0; 4]);
    }
    assert_eq!(shim.log_u8("phase"), 0);

    // Armed, motors spinning (the supervisor says flying), still on the ground: the output is
    // live, the adaptation frozen at a = 0 however large the error.
    shim.supervisor(true, true);
    for _ in 0..1000 {
        shim.set_state(&ground);
        let w = shim.tick();
        assert!(
            w[0] > 0.0,
            "thrust builds up on the ground: {w:?}, tick {}, faults {:#x}",
            shim.tick,
            shim.log_u32("faults")
        );
    }
    assert_eq!(shim.log_u8("phase"), 1, "ground");
    assert_eq!(shim.estimate(), [0.0; 6], "frozen on the ground");

    // Lifted 3 cm (below the 5 cm of `airHeight`): still frozen.
    let mut low = ground;
    low.p_m.z = 0.03;
    for _ in 0..200 {
        shim.set_state(&low);
        shim.tick();
    }
    assert_eq!(shim.estimate(), [0.0; 6], "frozen below airHeight");

    // Airborne at 10 cm: the adaptation runs.
    let mut up = ground;
    up.p_m.z = 0.1;
    for _ in 0..200 {
        shim.set_state(&up);
        shim.tick();
    }
    assert_eq!(shim.log_u8("phase"), 2, "airborne");
    let a = shim.estimate();
    assert!(a.iter().any(|v| *v != 0.0), "adapting in the air: {a:?}");

    // Adaptation off by parameter: frozen (not reset); on again: it moves.
    shim.set_param_u8("adapt", 0);
    for _ in 0..100 {
        shim.tick();
    }
    assert_eq!(shim.estimate(), a, "frozen by the adapt parameter");
    shim.set_param_u8("adapt", 1);
    // The reset parameter clears a once and clears itself.
    shim.set_param_u8("reset", 1);
    shim.tick();
    shim.tick();
    assert_eq!(shim.param_u8("reset"), 0);

    // Touch-down: still flying (the supervisor has not said landed), the setpoint at the ground
    // and the vehicle on it, the floor pushing back: a is held, neither learned nor reset.
    for _ in 0..100 {
        shim.tick();
    }
    shim.set_setpoint([ABS; 4], [0.2, -0.1, -0.05], [0.0; 3], 0.0, 0.0, 0.0, false);
    shim.set_state(&ground);
    shim.tick();
    shim.tick();
    let held = shim.estimate();
    assert!(held.iter().any(|v| *v != 0.0));
    for _ in 0..300 {
        shim.set_state(&ground);
        shim.tick();
    }
    assert_eq!(shim.log_u8("phase"), 2, "still airborne for the supervisor");
    assert_eq!(shim.estimate(), held, "held at touch-down");
    // The setpoint high again (a go-around) with the vehicle still low: it learns again.
    hover_sp(&mut shim);
    for _ in 0..100 {
        shim.set_state(&ground);
        shim.tick();
    }
    assert_ne!(shim.estimate(), held, "learning again on a go-around");

    // Landed: the supervisor no longer says flying. a resets and stays frozen.
    for _ in 0..100 {
        shim.tick();
    }
    assert!(shim.estimate().iter().any(|v| *v != 0.0));
    shim.supervisor(true, false);
    shim.set_state(&ground);
    for _ in 0..100 {
        shim.tick();
    }
    assert_eq!(shim.log_u8("phase"), 1, "back on the ground");
    assert_eq!(shim.estimate(), [0.0; 6], "reset after landing");

    // A zero-thrust attitude setpoint (cflib's send_setpoint(0, 0, 0, 0)) and the commander's
    // null setpoint: zero output.
    shim.supervisor(true, true);
    shim.set_setpoint(
        [DISABLE, DISABLE, DISABLE, ABS],
        [0.0; 3],
        [0.0; 3],
        0.0,
        0.0,
        0.0,
        false,
    );
    for _ in 0..10 {
        assert_eq!(shim.tick(), [0.0; 4]);
    }
    assert_eq!(shim.log_u8("phase"), 0);
    hover_sp(&mut shim);
    assert!(shim.tick()[0] > 0.0, "engages again");
    shim.set_null_setpoint();
    for _ in 0..10 {
        assert_eq!(shim.tick(), [0.0; 4]);
    }
    assert_eq!(
        shim.log_f32("thrust"),
        0.0,
        "the logged wrench is the output"
    );
}

#[test]
fn runs_at_500_hz_on_even_ticks_and_refuses_bad_gains() {
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    let s = PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0);
    shim.set_state(&s);
    shim.set_setpoint([ABS; 4], [0.1, 0.0, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
    let w0 = shim.tick(); // tick 0: executes
    assert!(w0[0] > 0.0);
    // Tick 1 does not execute: control_t keeps its value even when the setpoint changes.
    shim.set_setpoint([ABS; 4], [-0.1, 0.0, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
    assert_eq!(shim.tick(), w0);
    assert_ne!(shim.tick(), w0, "tick 2 executes");

    // A negative gain written by the client is refused and the parameter reverts.
    let kp = shim.param_f32("kp");
    shim.set_param_f32("kp", -1.0);
    shim.tick();
    shim.tick();
    assert_eq!(shim.param_f32("kp"), kp);
    // A good one is taken: a stiffer k_p pushes harder towards the same setpoint.
    shim.tick(); // 5
    let before = shim.tick(); // 6 executes
    shim.set_param_f32("kp", 2.0 * kp);
    shim.tick(); // 7
    let after = shim.tick(); // 8 executes
    assert!(after[2].abs() > before[2].abs(), "{before:?} -> {after:?}");
}

#[test]
fn absolute_yaw_setpoints_are_in_degrees() {
    let sc = scenario("hover");
    let mut plant = sc.plant();
    let p = plant.state().p_m.cast::<f32>();
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    fly_shim(&mut shim, &mut plant, 3.0, |s, _| {
        s.set_setpoint([ABS; 4], p.into(), [0.0; 3], 45.0, 0.0, 0.0, false)
    });
    let yaw_deg = plant.state().rpy().z.to_degrees();
    assert!(
        (yaw_deg - 45.0).abs() < 1.0,
        "yaw {yaw_deg}° for a 45° setpoint"
    );
    let drift = (plant.state().p_m.cast::<f32>() - p).norm();
    // Holds position while it turns: under 3 cm of drift 3 s after the 45° step.
    assert!(drift < 0.03, "holds position while turning: {drift} m");
}

#[test]
fn a_degenerate_quaternion_is_a_state_fault_with_zero_output() {
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    let zero_q = [0.0f32; 4];
    let v = [0.0f32; 3];
    let p = [0.0f32, 0.0, 0.5];
    // SAFETY: arrays of three (four) floats; exclusive.
    unsafe {
        hf_host_set_state(
            p.as_ptr(),
            zero_q.as_ptr(),
            v.as_ptr(),
            v.as_ptr(),
            v.as_ptr(),
        )
    };
    shim.set_setpoint([ABS; 4], p, [0.0; 3], 0.0, 0.0, 0.0, false);
    assert_eq!(shim.tick(), [0.0; 4]);
    let faults = shim.log_u32("faults");
    assert_eq!(faults & 0x1F, 1, "HF_FAULT_BAD_STATE only: {faults:#x}");
}

/// Un-stalls the app task when dropped, so a failing test cannot hang the others.
struct Stall;

impl Stall {
    fn on() -> Self {
        // SAFETY: the flag is the harness's own, behind a mutex.
        unsafe { hf_host_stall_app_task(true) };
        Stall
    }
}

impl Drop for Stall {
    fn drop(&mut self) {
        // SAFETY: as above.
        unsafe { hf_host_stall_app_task(false) };
    }
}

#[test]
fn the_step_runs_inline_and_a_stalled_swap_never_blocks_the_stabilizer() {
    let mut shim = Shim::new();
    shim.supervisor(true, true);
    let s = PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0);
    shim.set_state(&s);
    shim.set_setpoint([ABS; 4], [0.0, 0.0, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
    // The step runs in the stabilizer's own call: with the app task hung, every executed tick
    // still flies.
    let stall = Stall::on();
    for _ in 0..6 {
        let w = shim.tick();
        if shim.tick % 2 == 1 {
            assert!(w[0] > 0.0, "tick {} flies: {w:?}", shim.tick - 1);
        }
        assert_eq!(shim.log_u32("faults") & (NOT_READY | SWAPPING), 0);
    }
    // A revert on the ground hands the app task a swap it cannot take while hung: the
    // stabilizer outputs zero at once and does not wait.
    shim.set_param_u8("revert", 1);
    let t0 = Instant::now();
    for _ in 0..20 {
        assert_eq!(shim.tick(), [0.0; 4], "zero output while the swap waits");
        assert_ne!(shim.log_u32("faults") & SWAPPING, 0);
    }
    assert!(
        t0.elapsed() < Duration::from_millis(200),
        "20 ticks without waiting: {:?}",
        t0.elapsed()
    );
    // Back: the swap runs, and the next executed tick flies again.
    drop(stall);
    shim.wait_for_swap();
    shim.tick = 0;
    let w = shim.tick();
    assert!(w[0] > 0.0, "flies again after the swap: {w:?}");
    assert_eq!(shim.log_u32("faults") & (NOT_READY | SWAPPING), 0);
}
