//! Unit tests of the C ABI, called as C would call it.

use super::*;
use crate::abi::*;
use core::ptr;
use nalgebra::Vector3;

fn zeroed() -> HfController {
    HfController {
        opaque: [0; CONTROLLER_STORAGE_BYTES],
    }
}

fn init() -> HfController {
    let mut c = zeroed();
    // SAFETY: valid storage.
    unsafe { hf_init(&mut c) };
    c
}

fn step(c: &mut HfController, s: &HfState, sp: &HfSetpoint, dt_s: f32) -> HfOutput {
    let mut out = HfOutput::default();
    // SAFETY: valid pointers.
    let f = unsafe { hf_step(c, s, sp, dt_s, &mut out) };
    assert_eq!(f, out.faults);
    out
}

fn estimate(c: &HfController) -> [f32; FEATURES] {
    let mut a = [f32::NAN; FEATURES];
    // SAFETY: valid pointers.
    unsafe { hf_get_estimate(c, &mut a) };
    a
}

/// A state off the setpoint, so the law and the adaptation both act.
fn displaced() -> HfState {
    let s = State {
        p_m: Vector3::new(0.05, -0.03, 0.48),
        v_body_m_s: Vector3::new(0.1, 0.0, -0.05),
        w_body_rad_s: Vector3::new(0.2, -0.1, 0.05),
        ..State::default()
    };
    HfState::from_core(&s)
}

fn hover_sp() -> HfSetpoint {
    HfSetpoint::from_core(&Setpoint::hover(Vector3::new(0.0, 0.0, 0.5), 0.0))
}

#[test]
fn zeroed_storage_is_not_initialised_and_gives_zero_output() {
    let mut c = zeroed();
    let out = step(&mut c, &displaced(), &hover_sp(), 0.002);
    assert_eq!(out.faults, FAULT_NOT_INIT);
    assert_eq!((out.thrust_n, out.torque_nm), (0.0, [0.0; 3]));
    // SAFETY: valid pointer.
    assert_eq!(unsafe { hf_last_faults(&c) }, FAULT_NOT_INIT);
    assert!(!unsafe { hf_get_adapt(&c) });
    assert_eq!(estimate(&c), [0.0; FEATURES]);
}

#[test]
fn null_pointers_are_reported_not_dereferenced() {
    let mut c = init();
    let (s, sp) = (displaced(), hover_sp());
    let mut out = HfOutput::default();
    // SAFETY: null or valid pointers throughout.
    unsafe {
        hf_init(ptr::null_mut());
        hf_reset(ptr::null_mut());
        assert_eq!(
            hf_step(&mut c, &s, &sp, 0.002, ptr::null_mut()),
            FAULT_NOT_INIT
        );
        assert_eq!(
            hf_step(&mut c, ptr::null(), &sp, 0.002, &mut out),
            FAULT_NOT_INIT
        );
        assert_eq!(out.thrust_n, 0.0);
        assert_eq!(
            hf_step(&mut c, &s, ptr::null(), 0.002, &mut out),
            FAULT_NOT_INIT
        );
        assert_eq!(
            hf_step(ptr::null_mut(), &s, &sp, 0.002, &mut out),
            FAULT_NOT_INIT
        );
        assert_eq!(hf_set_gains(&mut c, ptr::null()), ERR_NULL);
        hf_get_gains(&c, ptr::null_mut());
        hf_get_estimate(&c, ptr::null_mut());
        assert_eq!(hf_last_faults(ptr::null()), FAULT_NOT_INIT);
    }
}

#[test]
fn steps_match_the_native_controller_bit_for_bit() {
    let mut c = init();
    let mut native = FlightController::new(
        &model::MODEL,
        Gains::for_vehicle(&VehicleFacts::of(&model::MODEL)),
    );
    let (s, sp) = (displaced(), hover_sp());
    for _ in 0..50 {
        let out = step(&mut c, &s, &sp, 0.002);
        let o = native.step(&s.to_core(), &sp.to_core(), 0.002);
        assert_eq!(out.faults, fault_bits(&o.faults));
        assert_eq!(out.thrust_n, o.command.thrust_n);
        assert_eq!(out.torque_nm, <[f32; 3]>::from(o.command.torque_nm));
        assert_eq!(estimate(&c), <[f32; FEATURES]>::from(native.estimate()));
    }
    assert!(estimate(&c).iter().any(|a| *a != 0.0), "the adaptation ran");
    assert_eq!(out_faults_of(&c) & FAULT_MASK, 0);
}

fn out_faults_of(c: &HfController) -> u32 {
    // SAFETY: valid pointer.
    unsafe { hf_last_faults(c) }
}

#[test]
fn faults_give_a_zero_wrench() {
    let mut c = init();
    let mut s = displaced();
    s.p_m[2] = f32::NAN;
    let out = step(&mut c, &s, &hover_sp(), 0.002);
    assert_ne!(out.faults & FAULT_BAD_STATE, 0);
    assert_eq!((out.thrust_n, out.torque_nm), (0.0, [0.0; 3]));
    let out = step(&mut c, &displaced(), &hover_sp(), 0.0);
    assert_ne!(out.faults & FAULT_BAD_DT, 0);
    let mut sp = hover_sp();
    sp.yaw_rad = f32::INFINITY;
    let out = step(&mut c, &displaced(), &sp, 0.002);
    assert_ne!(out.faults & FAULT_BAD_SETPOINT, 0);
    assert_eq!(out_faults_of(&c), out.faults);
}

#[test]
fn adaptation_switch_freezes_and_reset_clears() {
    let mut c = init();
    let (s, sp) = (displaced(), hover_sp());
    for _ in 0..10 {
        step(&mut c, &s, &sp, 0.002);
    }
    let a = estimate(&c);
    assert!(a.iter().any(|v| *v != 0.0));
    // SAFETY: valid pointers.
    unsafe { hf_set_adapt(&mut c, false) };
    assert!(!unsafe { hf_get_adapt(&c) });
    for _ in 0..10 {
        step(&mut c, &s, &sp, 0.002);
    }
    assert_eq!(estimate(&c), a, "frozen while off");
    // SAFETY: valid pointer.
    unsafe { hf_reset(&mut c) };
    assert_eq!(estimate(&c), [0.0; FEATURES]);
    assert!(!unsafe { hf_get_adapt(&c) }, "reset keeps the switch");
}

#[test]
fn gains_round_trip_and_bad_gains_are_refused() {
    let mut c = init();
    let mut g = HfGains::default();
    // SAFETY: valid pointers throughout.
    unsafe { hf_get_gains(&c, &mut g) };
    assert_eq!(
        g,
        HfGains::from_core(&Gains::for_vehicle(&VehicleFacts::of(&model::MODEL)))
    );
    let stiffer = HfGains {
        k_p: 2.0 * g.k_p,
        ..g
    };
    assert_eq!(unsafe { hf_set_gains(&mut c, &stiffer) }, OK);
    let bad = HfGains { k_v: f32::NAN, ..g };
    assert_eq!(unsafe { hf_set_gains(&mut c, &bad) }, ERR_BAD_GAINS);
    let mut now = HfGains::default();
    unsafe { hf_get_gains(&c, &mut now) };
    assert_eq!(now, stiffer, "a refused set leaves the last good gains");
    assert!(
        unsafe { hf_get_adapt(&c) },
        "setting gains keeps the adaptation switch"
    );
}

#[test]
fn compiled_in_model_is_the_blob() {
    let path = env!("HAMFLIGHT_BLOB_PATH");
    let bytes = std::fs::read(path).expect("the blob build.rs read");
    let from_blob = LearnedModel::from_blob(&bytes).expect("a valid blob");
    assert_eq!(model::MODEL, from_blob, "every parameter bit-exact");
    let body = &bytes[hamflight::blob::HEADER_LEN..bytes.len() - hamflight::blob::CRC_LEN];
    assert_eq!(hf_model_crc(), hamflight::blob::crc32(body));
    // SAFETY: a static NUL-terminated string.
    let name = unsafe { core::ffi::CStr::from_ptr(hf_model_name()) };
    let file = std::path::Path::new(path).file_name().unwrap();
    assert_eq!(name.to_str().unwrap(), file.to_str().unwrap());
}

#[test]
fn self_test_passes_and_mass_is_the_blobs() {
    let mut c = init();
    // SAFETY: valid storage.
    assert!(unsafe { hf_self_test(&mut c) });
    let path = env!("HAMFLIGHT_BLOB_PATH");
    let bytes = std::fs::read(path).unwrap();
    let from_blob = hamflight::blob::decode(&bytes).expect("a valid blob");
    assert_eq!(hf_mass_kg(), from_blob.mass_kg);
    assert!(hf_mass_kg() > 0.0);
}

#[test]
fn law_selection_composite_tuning_and_diagnostics() {
    let mut c = init();
    let mut eps = [f32::NAN; 6];
    // SAFETY: valid pointers throughout; null ones are reported.
    unsafe {
        // The composite law is the default; the paper's gradient law is selectable.
        assert_eq!(hf_get_law(&c), LAW_COMPOSITE);
        assert_eq!(hf_set_law(&mut c, 7), ERR_BAD_GAINS);
        assert_eq!(hf_set_law(ptr::null_mut(), LAW_COMPOSITE), ERR_NULL);
        assert_eq!(hf_get_law(ptr::null()), LAW_GRADIENT);
        assert_eq!(hf_set_law(&mut c, LAW_GRADIENT), OK);
        assert_eq!(hf_get_law(&c), LAW_GRADIENT);
        assert!(!hf_get_prediction_error(&c, &mut eps));
        assert_eq!((eps, hf_p_trace(&c)), ([0.0; 6], 0.0));
    }
    // Under the gradient law the composite diagnostics stay empty.
    for _ in 0..5 {
        step(&mut c, &displaced(), &hover_sp(), 0.002);
    }
    // SAFETY: as above.
    unsafe {
        assert!(!hf_get_prediction_error(&c, &mut eps));
        assert_eq!(hf_set_law(&mut c, LAW_COMPOSITE), OK);
        assert_eq!(hf_get_law(&c), LAW_COMPOSITE);
    }
    assert_eq!(estimate(&c), [0.0; FEATURES], "a change of law resets a");
    // The composite law as the core runs it, bit for bit.
    let gains = Gains {
        law: hamflight::AdaptationLaw::Composite,
        ..Gains::for_vehicle(&VehicleFacts::of(&model::MODEL))
    };
    let mut native = FlightController::new(&model::MODEL, gains);
    for _ in 0..5 {
        let out = step(&mut c, &displaced(), &hover_sp(), 0.002);
        let n = native.step_measured(
            &displaced().to_core(),
            &hover_sp().to_core(),
            // displaced() carries no accelerometer (specific_force_valid = 0).
            &hamflight::adapt::Measurement::default(),
            0.002,
        );
        assert_eq!(out.thrust_n, n.wrench.thrust_n);
    }
    // SAFETY: as above.
    unsafe {
        assert!(hf_get_prediction_error(&c, &mut eps));
        let e: [f32; 6] = native.adaptation().prediction_error().unwrap().into();
        assert_eq!(eps, e);
        assert_eq!(hf_p_trace(&c), native.adaptation().covariance_trace());
        assert!(hf_p_trace(&c) > 0.0);
    }
    assert_eq!(estimate(&c), <[f32; FEATURES]>::from(native.estimate()));

    // Q and R: refused values leave the tuning alone; hf_set_gains keeps law and tuning.
    let mut t = HfComposite::default();
    // SAFETY: as above.
    unsafe {
        hf_get_composite(&c, &mut t);
        let d = hamflight::control::Gains::default().composite;
        assert_eq!(t, HfComposite::from_core(&d));
        for bad in [
            HfComposite { q_force: -1.0, ..t },
            HfComposite { r_torque: 0.0, ..t },
            HfComposite {
                r_force: f32::NAN,
                ..t
            },
        ] {
            assert_eq!(hf_set_composite(&mut c, &bad), ERR_BAD_GAINS);
        }
        assert_eq!(hf_set_composite(&mut c, ptr::null()), ERR_NULL);
        let new = HfComposite { q_force: 2.0, ..t };
        assert_eq!(hf_set_composite(&mut c, &new), OK);
        let mut g = HfGains::default();
        hf_get_gains(&c, &mut g);
        assert_eq!(hf_set_gains(&mut c, &g), OK);
        let mut back = HfComposite::default();
        hf_get_composite(&c, &mut back);
        assert_eq!(back, new);
        assert_eq!(hf_get_law(&c), LAW_COMPOSITE);
    }
}

fn model_storage() -> std::boxed::Box<HfModel> {
    std::boxed::Box::new(HfModel {
        opaque: [0; MODEL_STORAGE_BYTES],
    })
}

/// The shipped blob with its body edited by `edit` and the CRC made right again.
fn edited_blob(edit: impl FnOnce(&mut [u8])) -> std::vec::Vec<u8> {
    use hamflight::blob::{crc32, CRC_LEN, HEADER_LEN};
    let mut bytes = std::fs::read(env!("HAMFLIGHT_BLOB_PATH")).unwrap();
    let end = bytes.len() - CRC_LEN;
    edit(&mut bytes[HEADER_LEN..end]);
    let crc = crc32(&bytes[HEADER_LEN..end]);
    bytes[end..].copy_from_slice(&crc.to_le_bytes());
    bytes
}

/// The shipped blob with the mass 0.031 kg (the body's first f32): valid, not the compiled-in
/// one.
fn other_blob() -> (LearnedModel, std::vec::Vec<u8>) {
    let blob = edited_blob(|body| body[..4].copy_from_slice(&0.031f32.to_le_bytes()));
    let m = LearnedModel::from_blob(&blob).unwrap();
    assert_eq!(m.weights.mass_kg, 0.031);
    (m, blob)
}

#[test]
fn blob_check_reports_the_blob_and_each_refusal() {
    let (m, blob) = other_blob();
    let mut info = HfBlobInfo::default();
    // SAFETY: valid pointers and lengths throughout; null ones are reported.
    unsafe {
        assert_eq!(
            hf_blob_check(blob.as_ptr(), blob.len() as u32, &mut info),
            OK
        );
        assert_eq!(info.mass_kg, m.weights.mass_kg);
        assert_eq!(info.total_len_bytes as usize, blob.len());
        assert_eq!(info.version, hamflight::blob::FORMAT_VERSION);
        let crc = u32::from_le_bytes(blob[blob.len() - 4..].try_into().unwrap());
        assert_eq!(info.crc, crc);
        assert_eq!(hf_blob_check(ptr::null(), 10, &mut info), ERR_NULL);
        assert_eq!(
            hf_blob_check(blob.as_ptr(), 3, ptr::null_mut()),
            ERR_BLOB_TRUNCATED
        );
        let mut bad = blob.clone();
        bad[40] ^= 4;
        assert_eq!(
            hf_blob_check(bad.as_ptr(), bad.len() as u32, ptr::null_mut()),
            ERR_BLOB_CRC
        );
        bad[0] = b'X';
        assert_eq!(
            hf_blob_check(bad.as_ptr(), bad.len() as u32, ptr::null_mut()),
            ERR_BLOB_BAD_MAGIC
        );
    }
}

/// Copies `blob` into the slot (as the shim's upload does) and decodes it there.
///
/// # Safety
/// `info` null or writable.
unsafe fn load(slot: &mut HfModel, blob: &[u8], info: *mut HfBlobInfo) -> u32 {
    slot.opaque[..blob.len()].copy_from_slice(blob);
    // SAFETY: valid storage, exclusive; the caller's contract for `info`.
    unsafe { hf_model_load(slot, blob.len() as u32, info) }
}

/// The model decoded in the slot.
fn loaded(slot: &HfModel) -> &LearnedModel {
    // SAFETY: aligned and large enough (asserted in lib.rs); any bytes are a ModelInner.
    let mi = unsafe { &*(slot as *const HfModel).cast::<ModelInner>() };
    assert_eq!(mi.magic, MODEL_MAGIC);
    &mi.model
}

/// The shipped (version 4) blob rewritten as format `version` (1 to 3): the fields that version
/// lacks dropped, the header and the CRC made right.
fn as_version(blob: &[u8], version: u16) -> std::vec::Vec<u8> {
    use hamflight::blob::{crc32, CRC_LEN, HEADER_LEN};
    let body = &blob[HEADER_LEN..blob.len() - CRC_LEN];
    let params = &body[4 * (2 + 27)..];
    let mut new_body = std::vec::Vec::new();
    if version >= 2 {
        new_body.extend_from_slice(&body[..4]);
    }
    if version >= 3 {
        new_body.extend_from_slice(&body[4..8]);
    }
    new_body.extend_from_slice(params);
    let mut out = blob[..HEADER_LEN].to_vec();
    out[4..6].copy_from_slice(&version.to_le_bytes());
    out[24..28].copy_from_slice(&(new_body.len() as u32).to_le_bytes());
    out.extend_from_slice(&new_body);
    out.extend_from_slice(&crc32(&new_body).to_le_bytes());
    out
}

#[test]
fn a_blob_decodes_in_place_as_the_core_decodes_it_in_every_version() {
    let (_, v4) = other_blob();
    // Parameters 0, 1, 2, ... (scaled: finite, distinct): a moved or misordered one shows.
    let counting = edited_blob(|body| {
        for (i, c) in body[4 * (2 + 27)..].chunks_exact_mut(4).enumerate() {
            c.copy_from_slice(&((i % 1000) as f32 * 1e-3).to_le_bytes());
        }
    });
    let mut c = LearnedModel::from_blob(&counting).unwrap();
    let mut n = 0;
    for (i, p) in c.weights.params_mut().enumerate() {
        assert_eq!(*p, (i % 1000) as f32 * 1e-3);
        n += 1;
    }
    assert_eq!(n, hamflight::model::ModelWeights::PARAMS);
    let mut slot = model_storage();
    for blob in [
        v4.clone(),
        counting,
        as_version(&v4, 3),
        as_version(&v4, 2),
        as_version(&v4, 1),
    ] {
        let want = LearnedModel::from_blob(&blob).unwrap();
        let mut info = HfBlobInfo::default();
        // Stale bytes of the last model in the slot must not matter.
        // SAFETY: valid pointers.
        assert_eq!(unsafe { load(&mut slot, &blob, &mut info) }, OK);
        assert_eq!(loaded(&slot), &want);
        assert_eq!(info.total_len_bytes as usize, blob.len());
    }
}

#[test]
fn a_loaded_model_flies_bit_for_bit_as_the_native_controller_and_can_be_left() {
    let (m, blob) = other_blob();
    let mut slot = model_storage();
    let mut c = init();
    let mut info = HfBlobInfo::default();
    // SAFETY: valid pointers; the slot outlives the controller's use of it (dropped last).
    unsafe {
        assert_eq!(
            hf_use_model(&mut c, &*slot),
            ERR_NULL,
            "an empty slot is refused"
        );
        assert_eq!(load(&mut slot, &blob, &mut info), OK);
        assert_eq!(info.mass_kg, 0.031);
        assert_eq!(hf_set_law(&mut c, LAW_COMPOSITE), OK);
        assert_eq!(hf_use_model(&mut c, &*slot), OK);
        assert_eq!(hf_get_law(&c), LAW_COMPOSITE, "the law is kept");
        let mut g = HfGains::default();
        hf_get_gains(&c, &mut g);
        let gains = Gains {
            law: hamflight::AdaptationLaw::Composite,
            ..Gains::for_vehicle(&VehicleFacts::of(&m))
        };
        assert_eq!(g, HfGains::from_core(&gains), "the new mass's gains");
        let mut native = FlightController::new(&m, gains);
        let (s, sp) = (displaced(), hover_sp());
        for _ in 0..20 {
            let out = step(&mut c, &s, &sp, 0.002);
            let o = native.step_measured(
                &s.to_core(),
                &sp.to_core(),
                &hamflight::adapt::Measurement::default(),
                0.002,
            );
            assert_eq!(out.thrust_n, o.command.thrust_n);
            assert_eq!(out.torque_nm, <[f32; 3]>::from(o.command.torque_nm));
        }
        // Back to the compiled-in model: its hover thrust again.
        assert_eq!(hf_use_model(&mut c, ptr::null()), OK);
        let out = step(
            &mut c,
            &HfState::from_core(&State::default()),
            &HfSetpoint::default(),
            0.002,
        );
        let mut builtin = FlightController::new(
            &model::MODEL,
            Gains {
                law: hamflight::AdaptationLaw::Composite,
                ..Gains::for_vehicle(&VehicleFacts::of(&model::MODEL))
            },
        );
        let o = builtin.step(&State::default(), &Setpoint::default(), 0.002);
        assert_eq!(out.thrust_n, o.command.thrust_n);
        // A bad blob leaves the slot empty: nothing can fly it.
        let mut bad = blob.clone();
        bad[60] ^= 1;
        assert_eq!(load(&mut slot, &bad, &mut info), ERR_BLOB_CRC);
        assert_eq!(hf_use_model(&mut c, &*slot), ERR_NULL);
        assert_eq!(hf_model_load(ptr::null_mut(), 1, &mut info), ERR_NULL);
        assert_eq!(
            hf_model_load(&mut *slot, MODEL_STORAGE_BYTES as u32 + 1, &mut info),
            ERR_BLOB_TRAILING,
            "longer than the slot"
        );
        assert_eq!(hf_use_model(ptr::null_mut(), ptr::null()), ERR_NULL);
    }
}

#[test]
fn the_self_test_steps_the_controller_and_leaves_no_trace() {
    let mut c = init();
    let (s, sp) = (displaced(), hover_sp());
    // SAFETY: valid pointers.
    unsafe {
        hf_set_adapt(&mut c, true);
        let mut g = HfGains::default();
        hf_get_gains(&c, &mut g);
        g.k_p *= 1.5;
        assert_eq!(hf_set_gains(&mut c, &g), OK);
        for _ in 0..50 {
            step(&mut c, &s, &sp, 0.002);
        }
        assert!(estimate(&c).iter().any(|v| *v != 0.0));
        assert!(hf_self_test(&mut c));
        assert_eq!(estimate(&c), [0.0; FEATURES], "a = 0 after the test");
        let mut back = HfGains::default();
        hf_get_gains(&c, &mut back);
        assert_eq!(back, g, "the gains are kept");
        assert!(hf_get_adapt(&c));
        assert!(!hf_self_test(ptr::null_mut()));
        let mut z = zeroed();
        assert!(!hf_self_test(&mut z));
    }
    // After the test it steps as a fresh controller with those gains.
    let mut fresh = init();
    // SAFETY: valid pointers.
    unsafe {
        let mut g = HfGains::default();
        hf_get_gains(&c, &mut g);
        assert_eq!(hf_set_gains(&mut fresh, &g), OK);
        hf_set_adapt(&mut fresh, true);
    }
    for _ in 0..5 {
        assert_eq!(
            step(&mut c, &s, &sp, 0.002),
            step(&mut fresh, &s, &sp, 0.002)
        );
    }
}

#[test]
fn a_blob_that_fails_the_self_test_does_not_fly() {
    // Valid in every format check, but every network parameter zero (after the mass, the
    // motor lag and the port terms): no input gain, so no thrust.
    let blob = edited_blob(|body| body[4 * (2 + 27)..].fill(0));
    let mut slot = model_storage();
    // SAFETY: valid pointers.
    unsafe {
        assert_eq!(
            hf_blob_check(blob.as_ptr(), blob.len() as u32, ptr::null_mut()),
            OK
        );
        assert_eq!(load(&mut slot, &blob, ptr::null_mut()), OK);
        let mut c = init();
        assert_eq!(hf_use_model(&mut c, &*slot), ERR_SELF_TEST);
        // The compiled-in model flies: its hover thrust.
        let out = step(
            &mut c,
            &HfState::from_core(&State::default()),
            &HfSetpoint::default(),
            0.002,
        );
        let mut builtin = FlightController::new(
            &model::MODEL,
            Gains::for_vehicle(&VehicleFacts::of(&model::MODEL)),
        );
        let o = builtin.step(&State::default(), &Setpoint::default(), 0.002);
        assert_eq!(out.thrust_n, o.command.thrust_n);
    }
}
