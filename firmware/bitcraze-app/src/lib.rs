//! # hamflight-bitcraze — hamflight as Bitcraze's out-of-tree controller
//!
//! The C ABI of `include/hamflight.h` over the core's [`FlightController`], flying a
//! [`LearnedModel`] that is a `static` in flash: `build.rs` decodes the weight blob at build time
//! into literal constants, so there is no RAM copy of the ~10 KB of weights and no decode at
//! boot. The Crazyflie side (conversions from Bitcraze's `state_t`/`setpoint_t`, rates, flight
//! phases, parameters and logs) is the C shim `hamflight_oot.c` next to this crate.
//!
//! Builds:
//! - the firmware's library: `cargo build -p hamflight-bitcraze --profile bitcraze --target
//!   thumbv7em-none-eabihf` (the app's `Makefile` does this);
//! - the host: an rlib with the C shim, our stand-in Bitcraze headers (`host-include/`) and
//!   their harness compiled in, for the tests in `host-train/tests/bitcraze_oot/`.
//!
//! Every exported function is allocation-free and panic-free and checks its pointers for NULL.
//! On the target a panic (there is no reachable one) executes an undefined instruction, so the
//! firmware's hard-fault handler takes over; it never formats a message.
#![no_std]
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

#[cfg(not(target_os = "none"))]
extern crate std;

pub mod abi;

use abi::{HfBlobInfo, HfComposite, HfController, HfGains, HfModel, HfOutput, HfSetpoint, HfState};
use hamflight::model::{HamiltonianModel, LearnedModel, GRAVITY_M_S2};
use hamflight::{FlightController, Gains, Measurement, Output, Setpoint, State, VehicleFacts};

/// The compiled-in weights: `MODEL`, `MODEL_NAME`, `MODEL_NAME_NUL`, `MODEL_CRC`.
pub mod model {
    include!(concat!(env!("OUT_DIR"), "/model.rs"));
}

/// Marks an initialised [`Inner`] ("HFCT").
const MAGIC: u32 = 0x4846_4354;

/// What lives in a [`HfController`]'s storage.
#[repr(C)]
struct Inner {
    /// [`MAGIC`] once initialised; zeroed storage reads 0.
    magic: u32,
    /// The faults of the last step.
    last_faults: u32,
    ctl: FlightController<&'static LearnedModel>,
    /// The step's inputs and output in the core's types: converted here rather than on
    /// `hf_step`'s stack, which the stabilizer task shares with Bitcraze's own code.
    state: State,
    setpoint: Setpoint,
    meas: Measurement,
    out: Output,
}

impl Inner {
    /// The step's inputs in the core's types, converted in place. Out of line, so that the
    /// conversion's temporaries are off the stack before the step runs.
    #[inline(never)]
    fn load_inputs(&mut self, state: &HfState, setpoint: &HfSetpoint) {
        // The accelerometer reaches the composite adaptation law when the shim marks it valid
        // (the paper's gradient law does not read it).
        self.meas = Measurement {
            acc_body_m_s2: (state.specific_force_valid != 0)
                .then(|| nalgebra::Vector3::from(state.specific_force_body_m_s2)),
        };
        self.state = state.to_core();
        self.setpoint = setpoint.to_core();
    }
}

/// Marks a loaded, self-tested [`ModelInner`] ("HFMD").
const MODEL_MAGIC: u32 = 0x4846_4D44;

/// What lives in a [`HfModel`]'s storage.
#[repr(C)]
struct ModelInner {
    /// [`MODEL_MAGIC`] once loaded and self-tested; zeroed storage reads 0.
    magic: u32,
    /// Every bit pattern of these f32/u32 fields is a valid model (zero bytes are
    /// `LearnedModel::new(ModelWeights::ZERO)`), so it is decoded in place.
    model: LearnedModel,
}

const _: () = {
    assert!(core::mem::size_of::<ModelInner>() <= abi::MODEL_STORAGE_BYTES);
    assert!(core::mem::align_of::<ModelInner>() <= core::mem::align_of::<HfModel>());
    assert!(core::mem::size_of::<Inner>() <= abi::CONTROLLER_STORAGE_BYTES);
    assert!(core::mem::align_of::<Inner>() <= core::mem::align_of::<HfController>());
};

/// The controller in `p`, if `p` is non-null and initialised.
///
/// # Safety
/// `p` is null or points to a `hf_controller_t` that is zeroed or was `hf_init`ed, and no other
/// reference to it is live.
unsafe fn inner_mut<'a>(p: *mut HfController) -> Option<&'a mut Inner> {
    if p.is_null() {
        return None;
    }
    let inner = p.cast::<Inner>();
    // SAFETY: non-null, aligned (align of HfController ≥ align of Inner) and its first four
    // bytes are initialised (zeroed or written by hf_init).
    let magic = unsafe { core::ptr::read(inner.cast::<u32>()) };
    // SAFETY: the magic says hf_init wrote a whole Inner here; exclusive by the contract.
    (magic == MAGIC).then(|| unsafe { &mut *inner })
}

/// [`inner_mut`] for shared access.
///
/// # Safety
/// As [`inner_mut`], with no mutable reference live.
unsafe fn inner_ref<'a>(p: *const HfController) -> Option<&'a Inner> {
    // SAFETY: forwarded contract; the result is only read.
    unsafe { inner_mut(p.cast_mut()).map(|i| &*i) }
}

/// `hf_init`: the compiled-in model, default gains, adaptation on, a = 0. NULL is ignored.
///
/// # Safety
/// `ctl` is null or points to writable `hf_controller_t` storage.
#[no_mangle]
pub unsafe extern "C" fn hf_init(ctl: *mut HfController) {
    if ctl.is_null() {
        return;
    }
    let inner = Inner {
        magic: MAGIC,
        last_faults: abi::FAULT_NOT_INIT,
        ctl: FlightController::new(
            &model::MODEL,
            Gains::for_vehicle(&VehicleFacts::of(&model::MODEL)),
        ),
        state: State::default(),
        setpoint: Setpoint::default(),
        meas: Measurement::default(),
        out: Output::default(),
    };
    // SAFETY: non-null, writable and large and aligned enough (asserted above).
    unsafe { ctl.cast::<Inner>().write(inner) };
}

/// `hf_reset`: a = 0.
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_reset(ctl: *mut HfController) {
    // SAFETY: the caller's contract.
    if let Some(inner) = unsafe { inner_mut(ctl) } {
        inner.ctl.reset();
    }
}

/// `hf_step`: one control step; writes `*out` and returns its fault bits.
///
/// # Safety
/// Each pointer is null or valid for its type (`ctl` zeroed or `hf_init`ed); no other access to
/// `*ctl` runs at the same time.
#[no_mangle]
pub unsafe extern "C" fn hf_step(
    ctl: *mut HfController,
    state: *const HfState,
    setpoint: *const HfSetpoint,
    dt_s: f32,
    out: *mut HfOutput,
) -> u32 {
    // SAFETY: the caller's contract for every pointer.
    let (inner, state, setpoint, out) = unsafe {
        (
            inner_mut(ctl),
            state.as_ref(),
            setpoint.as_ref(),
            out.as_mut(),
        )
    };
    let Some(out) = out else {
        return abi::FAULT_NOT_INIT;
    };
    *out = HfOutput {
        faults: abi::FAULT_NOT_INIT,
        ..HfOutput::default()
    };
    let (Some(inner), Some(state), Some(setpoint)) = (inner, state, setpoint) else {
        return abi::FAULT_NOT_INIT;
    };
    inner.load_inputs(state, setpoint);
    inner.ctl.step_into(
        &inner.state,
        &inner.setpoint,
        &inner.meas,
        dt_s,
        &mut inner.out,
    );
    let o = &inner.out;
    let faults = abi::fault_bits(&o.faults);
    if !o.faults.is_fault() {
        // The command, not the law's wrench: it carries the motor-lag lead the attitude gains
        // were designed with, which Bitcraze's power distribution then mixes.
        out.thrust_n = o.command.thrust_n;
        out.torque_nm = o.command.torque_nm.into();
    }
    out.faults = faults;
    inner.last_faults = faults;
    faults
}

/// `hf_get_gains`: zeros if `ctl` is not initialised.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `out` null or writable.
#[no_mangle]
pub unsafe extern "C" fn hf_get_gains(ctl: *const HfController, out: *mut HfGains) {
    // SAFETY: the caller's contract.
    let (inner, out) = unsafe { (inner_ref(ctl), out.as_mut()) };
    if let Some(out) = out {
        *out = inner
            .map(|i| HfGains::from_core(&i.ctl.gains))
            .unwrap_or_default();
    }
}

/// `hf_set_gains`: `HF_OK`, or an error with the gains unchanged.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `gains` null or valid.
#[no_mangle]
pub unsafe extern "C" fn hf_set_gains(ctl: *mut HfController, gains: *const HfGains) -> u32 {
    // SAFETY: the caller's contract.
    let (Some(inner), Some(gains)) = (unsafe { inner_mut(ctl) }, unsafe { gains.as_ref() }) else {
        return abi::ERR_NULL;
    };
    match gains.to_core(inner.ctl.gains.adapt) {
        Some(g) => {
            // The law and the composite law's tuning have their own calls, and the vehicle's
            // lag compensation, per-axis attitude factor and velocity consistency are not in
            // the C API: kept.
            let cur = &inner.ctl.gains;
            inner.ctl.gains = Gains {
                law: cur.law,
                composite: cur.composite,
                lag: cur.lag,
                attitude_axis_scale: cur.attitude_axis_scale,
                velocity_consistency_tau_s: cur.velocity_consistency_tau_s,
                ..g
            };
            abi::OK
        }
        None => abi::ERR_BAD_GAINS,
    }
}

/// `hf_set_law`: `HF_OK`, `HF_ERR_BAD_GAINS` for an unknown law, `HF_ERR_NULL`. A change of
/// law resets the adaptation.
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_set_law(ctl: *mut HfController, law: u32) -> u32 {
    // SAFETY: the caller's contract.
    let Some(inner) = (unsafe { inner_mut(ctl) }) else {
        return abi::ERR_NULL;
    };
    let Some(law) = abi::law_from_c(law) else {
        return abi::ERR_BAD_GAINS;
    };
    if inner.ctl.gains.law != law {
        inner.ctl.gains.law = law;
        inner.ctl.reset();
    }
    abi::OK
}

/// `hf_get_law`: `HF_LAW_GRADIENT` if `ctl` is not initialised.
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_get_law(ctl: *const HfController) -> u32 {
    // SAFETY: the caller's contract.
    unsafe { inner_ref(ctl) }.map_or(abi::LAW_GRADIENT, |i| abi::law_to_c(i.ctl.gains.law))
}

/// `hf_set_composite`: the composite law's Q and R; `HF_OK`, or an error with them unchanged.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `tuning` null or valid.
#[no_mangle]
pub unsafe extern "C" fn hf_set_composite(
    ctl: *mut HfController,
    tuning: *const HfComposite,
) -> u32 {
    // SAFETY: the caller's contract.
    let (Some(inner), Some(t)) = (unsafe { inner_mut(ctl) }, unsafe { tuning.as_ref() }) else {
        return abi::ERR_NULL;
    };
    match t.to_core(&inner.ctl.gains.composite) {
        Some(c) => {
            inner.ctl.gains.composite = c;
            abi::OK
        }
        None => abi::ERR_BAD_GAINS,
    }
}

/// `hf_get_composite`: zeros if `ctl` is not initialised.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `out` null or writable.
#[no_mangle]
pub unsafe extern "C" fn hf_get_composite(ctl: *const HfController, out: *mut HfComposite) {
    // SAFETY: the caller's contract.
    let (inner, out) = unsafe { (inner_ref(ctl), out.as_mut()) };
    if let Some(out) = out {
        *out = inner
            .map(|i| HfComposite::from_core(&i.ctl.gains.composite))
            .unwrap_or_default();
    }
}

/// `hf_get_prediction_error`: the composite law's last ε; false and zeros if there is none.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `eps` null or valid for 6 floats.
#[no_mangle]
pub unsafe extern "C" fn hf_get_prediction_error(
    ctl: *const HfController,
    eps: *mut [f32; 6],
) -> bool {
    // SAFETY: the caller's contract.
    let (inner, eps) = unsafe { (inner_ref(ctl), eps.as_mut()) };
    let e = inner.and_then(|i| i.ctl.adaptation().prediction_error());
    if let Some(out) = eps {
        *out = e.map_or([0.0; 6], Into::into);
    }
    e.is_some()
}

/// `hf_p_trace`: the trace of the composite law's P (0 before its first update).
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_p_trace(ctl: *const HfController) -> f32 {
    // SAFETY: the caller's contract.
    unsafe { inner_ref(ctl) }.map_or(0.0, |i| i.ctl.adaptation().covariance_trace())
}

/// `hf_set_adapt`: the adaptation law on or off (off freezes a).
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_set_adapt(ctl: *mut HfController, on: bool) {
    // SAFETY: the caller's contract.
    if let Some(inner) = unsafe { inner_mut(ctl) } {
        inner.ctl.gains.adapt = on;
    }
}

/// `hf_get_adapt`: false if `ctl` is not initialised.
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_get_adapt(ctl: *const HfController) -> bool {
    // SAFETY: the caller's contract.
    unsafe { inner_ref(ctl) }.is_some_and(|i| i.ctl.gains.adapt)
}

/// `hf_get_estimate`: copies a (zeros if `ctl` is not initialised).
///
/// # Safety
/// `ctl` as for [`hf_step`]; `a` null or valid for `HF_FEATURES` floats.
#[no_mangle]
pub unsafe extern "C" fn hf_get_estimate(ctl: *const HfController, a: *mut [f32; abi::FEATURES]) {
    // SAFETY: the caller's contract.
    let (inner, a) = unsafe { (inner_ref(ctl), a.as_mut()) };
    if let Some(a) = a {
        *a = inner
            .map(|i| i.ctl.estimate().into())
            .unwrap_or([0.0; abi::FEATURES]);
    }
}

/// `hf_last_faults`.
///
/// # Safety
/// `ctl` as for [`hf_step`].
#[no_mangle]
pub unsafe extern "C" fn hf_last_faults(ctl: *const HfController) -> u32 {
    // SAFETY: the caller's contract.
    unsafe { inner_ref(ctl) }.map_or(abi::FAULT_NOT_INIT, |i| i.last_faults)
}

/// `hf_self_test`: one hover step on a scratch controller gives no fault and m g ± 20 %.
#[no_mangle]
pub extern "C" fn hf_self_test() -> bool {
    self_test(&model::MODEL)
}

/// One hover step of `model` on a scratch controller: no fault, thrust m g ± 20 %.
fn self_test(model: &LearnedModel) -> bool {
    let weight_n = model.mass_kg() * GRAVITY_M_S2;
    let mut ctl = FlightController::new(model, Gains::for_vehicle(&VehicleFacts::of(model)));
    let o = ctl.step(&State::default(), &Setpoint::default(), 0.002);
    !o.faults.is_fault() && (o.wrench.thrust_n - weight_n).abs() <= 0.2 * weight_n
}

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

/// `hf_model_load`: decode in place into `*model` and self-test it; empty on any error.
///
/// # Safety
/// `model` null or valid writable `hf_model_t` storage that no controller flies; `bytes` null
/// or valid for `len` bytes; `info` null or writable.
#[no_mangle]
pub unsafe extern "C" fn hf_model_load(
    model: *mut HfModel,
    bytes: *const u8,
    len: u32,
    info: *mut HfBlobInfo,
) -> u32 {
    // SAFETY: the caller's contract.
    let Some(bytes) = (unsafe { byte_slice(bytes, len) }) else {
        return abi::ERR_NULL;
    };
    if model.is_null() {
        return abi::ERR_NULL;
    }
    let inner = model.cast::<ModelInner>();
    // SAFETY: non-null, aligned and large enough (asserted above), exclusive by the contract.
    // Every field is an f32 or a u32, so any bytes (zeroed or stale) are a valid ModelInner.
    let inner = unsafe { &mut *inner };
    inner.magic = 0;
    let checked = match hamflight::blob::check(bytes) {
        Ok(i) => i,
        Err(e) => return abi::blob_error_code(e),
    };
    if let Err(e) = hamflight::blob::decode_model_into(bytes, &mut inner.model) {
        return abi::blob_error_code(e);
    }
    if !self_test(&inner.model) {
        return abi::ERR_SELF_TEST;
    }
    inner.magic = MODEL_MAGIC;
    // SAFETY: the caller's contract.
    if let Some(out) = unsafe { info.as_mut() } {
        *out = HfBlobInfo::from_core(&checked);
    }
    abi::OK
}

/// `hf_use_model`: fly `ctl` with `*model` (null: the compiled-in one), gains for its mass.
///
/// # Safety
/// `ctl` as for [`hf_step`]; `model` null or a `hf_model_t` that lives as long as `ctl` flies it
/// and is not loaded into meanwhile (the shim's static, reloaded only after switching away).
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
    let cur = inner.ctl.gains;
    let gains = Gains {
        law: cur.law,
        composite: cur.composite,
        adapt: cur.adapt,
        ..Gains::for_vehicle(&VehicleFacts::of(m))
    };
    inner.ctl = FlightController::new(m, gains);
    abi::OK
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

/// A panic is a bug (the API is panic-free): fault the CPU without formatting anything, so the
/// firmware's hard-fault handler stops the motors.
#[cfg(target_os = "none")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {
        // SAFETY: `udf` only raises the undefined-instruction fault.
        unsafe { core::arch::asm!("udf #0") };
    }
}

#[cfg(test)]
mod tests;
