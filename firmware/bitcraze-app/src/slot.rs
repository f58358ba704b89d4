//! Weight blobs and the uploaded model's slot: `hf_blob_check` (every check, on the bytes where
//! they arrived), `hf_model_load` (the upload decoded in place behind the checks),
//! `hf_use_model` (fly the slot or the compiled-in model) and the compiled-in model's facts.

use super::*;

/// `bytes[..len]`, if `bytes` is non-null.
///
/// # Safety
/// `bytes` is null or valid for reading `len` bytes.
unsafe fn byte_slice<'a>(bytes: *const u8, len: u32) -> Option<&'a [u8]> {
    let len = usize::try_from(len).ok()?;
    // SAFETY: non-null and valid for len bytes by the contract.
    (!bytes.is_null()).then(|| unsafe { core::slice::from_raw_parts(bytes, len) })
}

/// `hf_blob_check`: every check of the blob decoder, nothing decoded; `*info` on success.
///
/// # Safety
/// `bytes` null or valid for `len` bytes; `info` null or writable.
#[no_mangle]
pub unsafe extern "C" fn hf_blob_check(bytes: *const u8, len: u32, info: *mut HfBlobInfo) -> u32 {
    // SAFETY: the caller's contract.
    let Some(bytes) = (unsafe { byte_slice(bytes, len) }) else {
        return abi::ERR_NULL;
    };
    match hamflight::blob::check(bytes) {
        Ok(i) => {
            // SAFETY: the caller's contract.
            if let Some(out) = unsafe { info.as_mut() } {
                *out = HfBlobInfo::from_core(&i);
            }
            abi::OK
        }
        Err(e) => abi::blob_error_code(e),
    }
}

/// Where the first network parameter lives in a loaded [`HfModel`]: after the magic and the
/// mass (`LearnedModel` starts with its `ModelWeights`, whose memory is the mass then the
/// parameters in blob order; both `repr(C)`, asserted in the core).
const PARAMS_AT: usize =
    core::mem::offset_of!(ModelInner, model) + core::mem::offset_of!(ModelWeights, inertia);
/// Bytes of the network parameters, in the blob and in memory alike.
const PARAMS_BYTES: usize = 4 * ModelWeights::PARAMS;

const _: () = {
    // The blob's parameters are little-endian f32s: moved as bytes, they are the f32s only on a
    // little-endian target (the Cortex-M4 and the hosts are).
    assert!(cfg!(target_endian = "little"));
    assert!(core::mem::offset_of!(ModelWeights, mass_kg) == 0);
    assert!(core::mem::offset_of!(ModelWeights, inertia) == 4);
    // The parameters move down (to PARAMS_AT from at least the header's end, where a version-1
    // blob's start), and end inside the model.
    assert!(PARAMS_AT <= hamflight::blob::HEADER_LEN);
    assert!(PARAMS_AT + PARAMS_BYTES <= core::mem::size_of::<ModelInner>());
};

/// `hf_model_load`: decode, in place, the blob held in the first `len` bytes of `*model`; empty
/// on any error.
///
/// Every check of [`hf_blob_check`] runs on the bytes first. Then the header's scalars and port
/// terms are copied out, the parameter block is moved (memmove) from its offset in the blob down
/// to where [`LearnedModel`] keeps it ([`PARAMS_AT`]), and the scalars, the port terms and the
/// magic are written. No self test here: [`hf_use_model`] runs it on the controller that flies it.
///
/// # Safety
/// `model` null or valid writable `hf_model_t` storage that nothing else reads or writes
/// meanwhile (no controller flies it); `info` null or writable.
#[no_mangle]
pub unsafe extern "C" fn hf_model_load(
    model: *mut HfModel,
    len: u32,
    info: *mut HfBlobInfo,
) -> u32 {
    if model.is_null() {
        return abi::ERR_NULL;
    }
    let Ok(len) = usize::try_from(len) else {
        return abi::ERR_BLOB_TRAILING;
    };
    if len > abi::MODEL_STORAGE_BYTES {
        // Longer than the slot, so longer than any blob.
        return abi::ERR_BLOB_TRAILING;
    }
    let base = model.cast::<u8>();
    let inner = model.cast::<ModelInner>();
    // SAFETY (whole function): `model` is non-null, aligned for a ModelInner and large enough
    // (asserted above), initialised (static storage is zeroed, then written as bytes) and
    // exclusive by the contract. The bytes are first read through a shared slice that ends with
    // the check; then they are moved through raw pointers; only then is the one `&mut
    // ModelInner` formed. No `&[u8]` and `&mut ModelInner` over the slot are ever alive at once.
    // Every bit pattern is a valid ModelInner (f32 and u32 fields only).
    let checked = {
        // SAFETY: see above; `len` <= the storage's size.
        let bytes = unsafe { core::slice::from_raw_parts(base.cast_const(), len) };
        hamflight::blob::check(bytes)
    };
    let checked = match checked {
        Ok(i) => i,
        Err(e) => {
            // SAFETY: see above.
            unsafe { (&raw mut (*inner).magic).write(0) };
            return abi::blob_error_code(e);
        }
    };
    // The parameters are the body's last PARAMS_BYTES, before the CRC, in every version.
    let from = checked.total_len - hamflight::blob::CRC_LEN - PARAMS_BYTES;
    // SAFETY: see above; `from + PARAMS_BYTES <= len` (the check passed) and `PARAMS_AT +
    // PARAMS_BYTES <= size_of::<ModelInner>()` (asserted); `copy` is a memmove.
    unsafe { core::ptr::copy(base.add(from), base.add(PARAMS_AT), PARAMS_BYTES) };
    // SAFETY: see above: no other reference to the slot is alive.
    let m = unsafe { &mut *inner };
    m.magic = 0;
    m.model.weights.mass_kg = checked.mass_kg;
    m.model.set_motor_tau_s(checked.motor_tau_s);
    m.model.set_port(checked.port);
    m.magic = MODEL_MAGIC;
    // SAFETY: the caller's contract.
    if let Some(out) = unsafe { info.as_mut() } {
        *out = HfBlobInfo::from_core(&checked);
    }
    abi::OK
}

/// `hf_use_model`: fly `ctl` with `*model` (null: the compiled-in one), gains for its mass,
/// after the self test ([`hf_self_test`]) on `ctl` itself. If the test fails, `ctl` flies the
/// compiled-in model and `HF_ERR_SELF_TEST` is returned.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `model` null or a `hf_model_t` that lives as long as `ctl` flies it
/// and is not written meanwhile (the shim's static, written only after switching away).
#[no_mangle]
pub unsafe extern "C" fn hf_use_model(ctl: *mut HfController, model: *const HfModel) -> u32 {
    // SAFETY: the caller's contract.
    let Some(inner) = (unsafe { inner_mut(ctl) }) else {
        return abi::ERR_NULL;
    };
    let m: &'static LearnedModel = if model.is_null() {
        &model::MODEL
    } else {
        let mi = model.cast::<ModelInner>();
        // SAFETY: non-null, aligned, valid for any bytes (see hf_model_load); 'static and not
        // written while flown, by the contract.
        let mi: &'static ModelInner = unsafe { &*mi };
        if mi.magic != MODEL_MAGIC {
            return abi::ERR_NULL;
        }
        &mi.model
    };
    fly(inner, m);
    if self_test(inner) {
        return abi::OK;
    }
    if !model.is_null() {
        fly(inner, &model::MODEL);
    }
    abi::ERR_SELF_TEST
}

/// `inner` flies `m`: default gains for its mass, the law, the composite tuning and the
/// adaptation switch kept, a = 0. Built in place.
fn fly(inner: &mut Inner, m: &'static LearnedModel) {
    let facts = facts_of(m);
    // SAFETY: a valid, aligned, exclusive, initialised field (no drop glue).
    unsafe { build(&raw mut inner.ctl, m, &facts, true) };
}

/// `hf_model_name`: the blob's file name, NUL-terminated, static.
#[no_mangle]
pub extern "C" fn hf_model_name() -> *const core::ffi::c_char {
    model::MODEL_NAME_NUL.as_ptr().cast()
}

/// `hf_model_crc`: the blob body's CRC-32.
#[no_mangle]
pub extern "C" fn hf_model_crc() -> u32 {
    model::MODEL_CRC
}

/// `hf_mass_kg`.
#[no_mangle]
pub extern "C" fn hf_mass_kg() -> f32 {
    model::MODEL.mass_kg()
}
