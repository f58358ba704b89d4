//! The weight upload over the app's memory: registration, the slot, swap, rejection, busy.

use super::*;

/// The shipped blob with another vehicle mass (so its gains and force columns differ from the
/// compiled-in model's) and a nudged disturbance bias: a valid blob that is not the compiled-in
/// one. Returns the model and its bytes.
fn other_blob(mass_kg: f32) -> (LearnedModel, Vec<u8>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../weights/default.hfw");
    let bytes = std::fs::read(path).expect("the shipped blob");
    let mut m = LearnedModel::from_blob(&bytes).expect("valid");
    m.weights.mass_kg = mass_kg;
    m.weights.disturbance.l2.bias[0] += 0.01;
    let out = hamflight::blob::encode_model(&m);
    if (0.005..=5.0).contains(&mass_kg) {
        assert_eq!(LearnedModel::from_blob(&out), Ok(m), "round trip");
    }
    (m, out)
}

fn blob_crc(bytes: &[u8]) -> u32 {
    u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap())
}

/// Every 24-byte chunk offset of `blob`, in increasing order (cflib's).
fn chunks(blob: &[u8]) -> Vec<usize> {
    (0..blob.len()).step_by(CFLIB_CHUNK).collect()
}

#[test]
fn the_app_memory_is_registered_once_with_its_info_block() {
    let mut shim = Shim::new();
    // SAFETY: exclusive (the lock).
    let (ty, n, size) = unsafe {
        (
            hf_host_mem_type(),
            hf_host_mem_registrations(),
            hf_host_mem_size(),
        )
    };
    assert_eq!(ty, 0x18, "MEM_TYPE_APP");
    assert_eq!(
        n, 1,
        "registered once, at the first init, however often it is re-selected"
    );
    assert_eq!(size, UP_DATA + hamflight::blob::MAX_LEN as u32);
    let info = shim.up_info();
    assert_eq!((info.magic, info.layout), (u32::from_le_bytes(*b"HFUP"), 2));
    assert_eq!(info.source, 0, "compiled-in at boot");
    assert_eq!(info.crc, hamflight_bitcraze::model::MODEL_CRC);
    assert_eq!(info.mass_kg, MODEL.weights.mass_kg);
    assert_eq!(info.capacity as usize, hamflight::blob::MAX_LEN);
    assert_eq!(info.name, "default.hfw");
    assert_eq!(
        shim.log_u32("blobCrc"),
        hamflight_bitcraze::model::MODEL_CRC
    );
    assert!(shim
        .debug_text()
        .contains("active blob: compiled-in default.hfw crc"));
    // Reads that leave a region, and writes outside a session or the window, are refused.
    assert!(shim.mem_read(0x30, 24).is_none(), "past the info block");
    assert!(shim.mem_read(size - 10, 24).is_none(), "past the slot");
    assert!(!shim.mem_write(UP_DATA, &[1, 2, 3]), "data before BEGIN");
    assert!(
        !shim.mem_write(UP_CONTROL, &[UP_CMD_COMMIT]),
        "COMMIT before BEGIN"
    );
    assert!(
        !shim.mem_write(UP_CONTROL, &[UP_CMD_BEGIN, 0, 0, 0, 0]),
        "BEGIN of 0 B"
    );
    let too_big = (hamflight::blob::MAX_LEN as u32 + 1).to_le_bytes();
    let mut begin = vec![UP_CMD_BEGIN];
    begin.extend_from_slice(&too_big);
    assert!(
        !shim.mem_write(UP_CONTROL, &begin),
        "BEGIN over the capacity"
    );
    assert!(!shim.mem_write(8, &[0; 4]), "the info block is read-only");
}

#[test]
fn an_out_of_order_repeated_upload_swaps_in_on_the_ground_and_reverts() {
    let mut shim = Shim::new();
    let (m, blob) = other_blob(0.031);
    // Out of order (odd chunks first, then even ones backwards), with repeats.
    let all = chunks(&blob);
    let mut order: Vec<usize> = all.iter().copied().skip(1).step_by(2).collect();
    order.extend(all.iter().copied().step_by(2).rev());
    order.extend_from_slice(&all[3..9]);
    assert!(shim.upload(&blob, &order));
    // Read back before it flies (the tool's verification): the slot holds the blob.
    assert_eq!(shim.mem_read_all(UP_DATA, blob.len()), blob);
    let info = shim.up_info();
    assert_eq!((info.state, info.staged_crc), (UP_PENDING, blob_crc(&blob)));
    assert_eq!(info.len as usize, blob.len());
    assert_eq!(info.source, 0, "not yet");
    // The supervisor cannot fly (OFF): the next tick hands the swap to the app task.
    shim.wait_for_swap();
    let info = shim.up_info();
    assert_eq!((info.state, info.source, info.error), (UP_ACTIVE, 1, 0));
    assert_eq!((info.crc, info.mass_kg), (blob_crc(&blob), 0.031));
    assert_eq!(info.version, hamflight::blob::FORMAT_VERSION);
    assert_eq!(info.name, "uploaded");
    assert_eq!(shim.log_u32("blobCrc"), blob_crc(&blob));
    // The slot now holds the decoded model, not the blob: data reads are refused.
    assert!(
        shim.mem_read(UP_DATA, 24).is_none(),
        "no data reads after the swap"
    );
    let text = shim.debug_text();
    let crc = format!("{:08X}", blob_crc(&blob));
    assert!(text.contains(&format!("checked, crc {crc}")), "{text}");
    assert!(
        text.contains(&format!("active blob: uploaded crc {crc}, 31 g")),
        "{text}"
    );
    // The gain parameters are the new vehicle's.
    let g = Gains::for_vehicle(&hamflight::VehicleFacts::of(&m));
    assert_eq!(shim.param_f32("kp"), g.k_p);
    assert_ne!(
        g.k_p,
        Gains::for_vehicle(&hamflight::VehicleFacts::of(&MODEL)).k_p
    );
    // Armed on the ground: the hover thrust is the uploaded vehicle's weight, not the default's.
    shim.supervisor(true, true);
    shim.set_state(&PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0));
    shim.set_setpoint([ABS; 4], [0.0, 0.0, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
    shim.tick = 0;
    let w = shim.tick();
    let mut native = hamflight::FlightController::new(&m, g);
    let state = PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0);
    let o = native.step(
        &(&state).into(),
        &hamflight::Setpoint::hover(Vector3::new(0.0, 0.0, 0.5), 0.0),
        0.002,
    );
    assert!(
        (w[0] - o.command.thrust_n).abs() < 1e-4 * o.command.thrust_n,
        "thrust {} vs the uploaded model's {}",
        w[0],
        o.command.thrust_n
    );

    // revert = 1: the compiled-in blob again, at once on the ground.
    shim.supervisor(true, false);
    shim.set_param_u8("revert", 1);
    shim.wait_for_swap();
    assert_eq!(shim.param_u8("revert"), 0, "clears itself");
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
        (0, hamflight_bitcraze::model::MODEL_CRC)
    );
    assert!(shim.debug_text().ends_with(&format!(
        "active blob: compiled-in default.hfw crc {:08X}, 27 g\n",
        hamflight_bitcraze::model::MODEL_CRC
    )));
}

/// BEGIN of `len` bytes (false: refused).
fn begin(shim: &mut Shim, len: usize) -> bool {
    let mut begin = vec![UP_CMD_BEGIN];
    begin.extend_from_slice(&(len as u32).to_le_bytes());
    shim.mem_write(UP_CONTROL, &begin)
}

#[test]
fn torn_and_bad_uploads_are_rejected_and_the_flying_blob_is_untouched() {
    let mut shim = Shim::new();
    let (_, good) = other_blob(0.029);
    assert!(shim.upload(&good, &chunks(&good)));
    shim.wait_for_swap();
    assert_eq!(shim.log_u8("blobSrc"), 1);
    assert_eq!(shim.log_u32("blobCrc"), blob_crc(&good));
    // The uploaded blob flies from the slot: on the ground a BEGIN is refused and hands the
    // controller back to the compiled-in blob; then one is accepted.
    assert!(!begin(&mut shim, good.len()), "busy while the upload flies");
    assert_eq!(shim.up_info().error, UP_ERR_BUSY_REVERTING);
    shim.wait_for_swap();
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.up_info().state),
        (0, UP_IDLE),
        "the compiled-in blob flies again"
    );
    let flying = shim.log_u32("blobCrc");
    assert_eq!(flying, hamflight_bitcraze::model::MODEL_CRC);

    let (_, next) = other_blob(0.033);
    let reject = |shim: &mut Shim, bytes: &[u8], len: usize, order: &[usize], err: u8| {
        assert!(begin(shim, len));
        for &off in order {
            let end = (off + CFLIB_CHUNK).min(bytes.len()).min(len);
            assert!(shim.mem_write(UP_DATA + off as u32, &bytes[off..end]));
        }
        assert!(shim.mem_write(UP_CONTROL, &[UP_CMD_COMMIT]));
        let info = shim.up_info();
        assert_eq!((info.state, info.error), (UP_REJECTED, err), "{info:?}");
        // Rejected at the commit: the bytes stay readable.
        let n = len.min(24);
        assert_eq!(
            shim.mem_read(UP_DATA, n as u8).as_deref(),
            Some(&bytes[..n])
        );
        // Nothing to swap: ticks fly on with the blob that flew before.
        shim.tick();
        shim.tick();
        assert_eq!(
            (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
            (0, flying)
        );
        assert_eq!(shim.up_info().crc, flying);
    };
    // Torn: one chunk in the middle never arrived.
    let mut torn = chunks(&next);
    torn.remove(torn.len() / 2);
    reject(&mut shim, &next, next.len(), &torn, ERR_BLOB_CRC);
    // Torn at the end: the last chunk (the CRC) never arrived.
    let mut short = chunks(&next);
    short.pop();
    reject(&mut shim, &next, next.len(), &short, ERR_BLOB_CRC);
    // A flipped bit in the body.
    let mut flipped = next.clone();
    flipped[100] ^= 0x10;
    reject(
        &mut shim,
        &flipped,
        flipped.len(),
        &chunks(&flipped),
        ERR_BLOB_CRC,
    );
    // Announced shorter than the blob's own header says.
    let len = next.len() - 4;
    let order: Vec<usize> = (0..len).step_by(CFLIB_CHUNK).collect();
    reject(&mut shim, &next, len, &order, ERR_BLOB_TRUNCATED);
    // A vehicle mass outside the decoder's range (its CRC is right).
    let (_, heavy) = other_blob(0.0);
    reject(
        &mut shim,
        &heavy,
        heavy.len(),
        &chunks(&heavy),
        ERR_BLOB_MASS,
    );
    // A write past the announced length is refused.
    assert!(begin(&mut shim, next.len()));
    assert!(!shim.mem_write(UP_DATA + next.len() as u32 - 2, &[0; 4]));
    // And a good upload still goes through after all that.
    assert!(shim.upload(&next, &chunks(&next)));
    shim.wait_for_swap();
    assert_eq!(shim.log_u32("blobCrc"), blob_crc(&next));
}

#[test]
fn an_upload_in_flight_waits_for_the_landing() {
    let mut shim = Shim::new();
    let (mut plant, start, hold) = take_off_and_hold(&mut shim);
    assert_eq!(shim.log_u8("phase"), 2, "airborne");
    let (_, blob) = other_blob(0.030);
    assert!(shim.upload(&blob, &chunks(&blob)));
    assert_eq!(shim.up_info().state, UP_PENDING);
    // 1 s more in the air: the thrust never drops out, the compiled-in blob keeps flying.
    let dt = 1e-3;
    for _ in 0..1000 {
        let s = *plant.state();
        shim.set_state(&s);
        hold(&mut shim, 0.0);
        let w = shim.tick();
        assert!(w[0] > 0.0, "flying on");
        plant.step(plant.params.clamp_rpm(rpm_of(w)), dt);
    }
    assert!(
        (plant.state().p_m.cast::<f32>() - start).norm() < 0.02,
        "held the hover"
    );
    assert_eq!(shim.log_u8("phase"), 2);
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.up_info().state),
        (0, UP_PENDING),
        "waits while airborne"
    );
    // Landed (the supervisor stops saying flying): it swaps in.
    shim.supervisor(true, false);
    shim.wait_for_swap();
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
        (1, blob_crc(&blob))
    );
    assert_eq!(shim.up_info().state, UP_ACTIVE);
}

#[test]
fn a_stop_setpoint_in_flight_resumes_airborne_and_an_upload_still_waits() {
    // cflib sends a zero setpoint (thrust 0, z disabled) when it closes a link; with another pilot
    // streaming setpoints the controller stops for one tick and engages again. It must come back
    // airborne, with the ground it took off from: once it took the current height for the ground
    // and was never airborne again (no adaptation, and an upload swapped in flight; found flying
    // the whole firmware in SITL).
    let mut shim = Shim::new();
    let mut plant = scenario("hover").plant();
    let start = plant.state().p_m.cast::<f32>();
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0); // airborne at once at the scenario's 1 m
    let hold = move |shim: &mut Shim, _t: f64| {
        shim.set_setpoint([ABS; 4], start.into(), [0.0; 3], 0.0, 0.0, 0.0, false)
    };
    fly_shim(&mut shim, &mut plant, 0.5, hold);
    assert_eq!(shim.log_u8("phase"), 2, "airborne");
    shim.set_param_f32("airHeight", 0.05);
    let (_, blob) = other_blob(0.030);
    assert!(shim.upload(&blob, &chunks(&blob)));
    assert_eq!(shim.up_info().state, UP_PENDING);
    // One tick of the stop setpoint, then the pilot's setpoints again for 1 s.
    let dt = 1e-3;
    for k in 0..1000 {
        let s = *plant.state();
        shim.set_state(&s);
        if k == 0 {
            shim.set_null_setpoint();
        } else {
            hold(&mut shim, 0.0);
        }
        let w = shim.tick();
        // zero on the stop's tick and the odd tick after it (the 500 Hz gate), then flying on
        // zero on the stop's tick and the odd tick after it (the 500 Hz gate), then flying on
        assert_eq!(w[0] == 0.0, k < 2, "tick {k}: thrust {}", w[0]);
        plant.step(plant.params.clamp_rpm(rpm_of(w)), dt);
    }
    assert_eq!(shim.log_u8("phase"), 2, "airborne again");
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.up_info().state),
        (0, UP_PENDING),
        "the upload still waits for the landing"
    );
    assert!(
        (plant.state().p_m.cast::<f32>() - start).norm() < 0.02,
        "held the hover"
    );
    // Landed: it swaps in.
    shim.supervisor(true, false);
    shim.wait_for_swap();
    assert_eq!(shim.up_info().state, UP_ACTIVE);
}

#[test]
fn a_flight_with_the_uploaded_blob_matches_the_native_controller_with_it() {
    let (m, blob) = other_blob(0.030);
    let gains = Gains {
        law: hamflight::AdaptationLaw::Gradient,
        ..Gains::for_vehicle(&hamflight::VehicleFacts::of(&m))
    };
    let d = c_path_matches_native_with(0, gains, &m, Some(&blob));
    println!("uploaded blob, paper-spiral: largest difference from native {d:.3e} m");
}

#[test]
fn an_upload_while_an_uploaded_blob_flies_waits_for_the_landing() {
    // The uploaded blob flies from the one slot: a new upload in flight is refused (the client
    // waits), and goes through once landed.
    let mut shim = Shim::new();
    let (_, first) = other_blob(0.029);
    assert!(shim.upload(&first, &chunks(&first)));
    shim.wait_for_swap();
    assert_eq!(shim.log_u8("blobSrc"), 1);
    let (mut plant, start, hold) = take_off_and_hold(&mut shim);
    assert_eq!(shim.log_u8("phase"), 2, "airborne");
    let (_, next) = other_blob(0.031);
    assert!(!begin(&mut shim, next.len()), "refused in flight");
    let info = shim.up_info();
    assert_eq!((info.state, info.error), (UP_ACTIVE, UP_ERR_BUSY_FLYING));
    // 0.2 s more in the air: the uploaded blob flies on, no revert, still refused.
    fly_shim(&mut shim, &mut plant, 0.2, hold);
    assert!(!begin(&mut shim, next.len()));
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
        (1, blob_crc(&first))
    );
    assert!(
        (plant.state().p_m.cast::<f32>() - start).norm() < 0.02,
        "held the hover"
    );
    // Landed: a BEGIN hands back to the compiled-in blob, the retry is accepted.
    shim.supervisor(true, false);
    shim.tick();
    shim.tick();
    assert_eq!(shim.log_u8("phase"), 1, "landed");
    assert!(!begin(&mut shim, next.len()));
    assert_eq!(shim.up_info().error, UP_ERR_BUSY_REVERTING);
    shim.wait_for_swap();
    assert_eq!(shim.log_u8("blobSrc"), 0);
    assert!(shim.upload(&next, &chunks(&next)));
    shim.wait_for_swap();
    assert_eq!(
        (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
        (1, blob_crc(&next))
    );
}
