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
pub mod slot;
pub use slot::{
    hf_blob_check, hf_mass_kg, hf_model_crc, hf_model_load, hf_model_name, hf_use_model,
};

use abi::{HfBlobInfo, HfComposite, HfController, HfGains, HfModel, HfOutput, HfSetpoint, HfState};
use hamflight::model::{HamiltonianModel, LearnedModel, ModelWeights, GRAVITY_M_S2};
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

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Marks a loaded (decoded and checked) [`ModelInner`] ("HFMD").
const MODEL_MAGIC: u32 = 0x4846_4D44;

/// What lives in a [`HfModel`]'s storage once loaded (before: the blob's bytes). `repr(C)`: the
/// first network parameter is at the constant [`PARAMS_AT`].
#[repr(C)]
struct ModelInner {
    /// [`MODEL_MAGIC`] once loaded; zeroed storage reads 0.
    magic: u32,
    /// Every bit pattern of these f32/u32 fields is a valid model (zero bytes are
    /// `LearnedModel::new(ModelWeights::ZERO)`), so it is decoded in place.
    model: LearnedModel,
}

const _: () = {
    assert!(core::mem::size_of::<ModelInner>() <= abi::MODEL_STORAGE_BYTES);
    // The slot holds the upload's bytes, then the model decoded from them in place: the larger
    // of the two, rounded up to its 8-byte alignment, and no more.
    assert!(abi::BLOB_MAX_BYTES <= abi::MODEL_STORAGE_BYTES);
    assert!(
        abi::MODEL_STORAGE_BYTES
            == max(abi::BLOB_MAX_BYTES, core::mem::size_of::<ModelInner>()).div_ceil(8) * 8
    );
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
/// Built in place, field by field: no whole [`Inner`] passes through the stack (the app task's
/// stack is sized by its deepest call).
///
/// # Safety
/// `ctl` is null or points to writable `hf_controller_t` storage that nothing else accesses
/// meanwhile.
#[no_mangle]
pub unsafe extern "C" fn hf_init(ctl: *mut HfController) {
    if ctl.is_null() {
        return;
    }
    let p = ctl.cast::<Inner>();
    let facts = facts_of(&model::MODEL);
    // SAFETY: non-null, writable, large and aligned enough for an Inner (asserted above) and
    // exclusive by the contract.
    unsafe { init_at(p, &facts) };
}

/// [`hf_init`]'s writes, each field through a raw pointer (no reference to the partly built
/// Inner), the magic last, so no reader sees a half-built controller as one. Out of line: the
/// fields' temporaries are not in [`hf_init`]'s frame while it runs the model.
///
/// # Safety
/// `p` is valid for writes, aligned and exclusive.
#[inline(never)]
unsafe fn init_at(p: *mut Inner, facts: &VehicleFacts) {
    // SAFETY: the caller's contract.
    unsafe {
        (&raw mut (*p).magic).write(0);
        (&raw mut (*p).last_faults).write(abi::FAULT_NOT_INIT);
        build(&raw mut (*p).ctl, &model::MODEL, facts, false);
        (&raw mut (*p).state).write(State::default());
        (&raw mut (*p).setpoint).write(Setpoint::default());
        (&raw mut (*p).meas).write(Measurement::default());
        (&raw mut (*p).out).write(Output::default());
        (&raw mut (*p).magic).write(MAGIC);
    }
}

/// `m`'s vehicle facts. Out of line, with nothing but pointers in its callers' frames: it runs
/// the model, the deepest call of the app task besides a step.
#[inline(never)]
fn facts_of(m: &LearnedModel) -> VehicleFacts {
    VehicleFacts::of(m)
}

/// Writes `FlightController::new(m, gains for facts)` to `c`, in place
/// ([`FlightController::write_new`]: no 1.4 KB temporary on the stack). With `keep`, the law,
/// the composite tuning and the adaptation switch of the controller at `c` are kept.
///
/// # Safety
/// `c` is valid for writes and aligned, and initialised if `keep`; whatever it held is
/// overwritten without a drop (the controller has no drop glue).
#[inline(never)]
unsafe fn build(
    c: *mut FlightController<&'static LearnedModel>,
    m: &'static LearnedModel,
    facts: &VehicleFacts,
    keep: bool,
) {
    let mut gains = Gains::for_vehicle(facts);
    if keep {
        // SAFETY: initialised if `keep` (the caller's contract).
        let cur = unsafe { &(*c).gains };
        (gains.law, gains.composite, gains.adapt) = (cur.law, cur.composite, cur.adapt);
    }
    // SAFETY: the caller's contract.
    unsafe { FlightController::write_new(c, m, gains) };
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

/// `hf_self_test`: one hover step of `ctl` itself, with its gains: no fault and thrust m g ±
/// 20 %; then a = 0. False if `ctl` is not initialised. The shim runs it right after `hf_init`
/// and `hf_use_model` gave the controller its model's default gains.
///
/// # Safety
/// `ctl` as for [`hf_step`] (the caller owns it: no step runs meanwhile).
#[no_mangle]
pub unsafe extern "C" fn hf_self_test(ctl: *mut HfController) -> bool {
    // SAFETY: the caller's contract.
    unsafe { inner_mut(ctl) }.is_some_and(self_test)
}

/// One hover step of the controller in `inner` (no scratch controller: the stack holds only
/// the step): no fault, thrust m g ± 20 %. The step's traces go: a = 0, no last output.
#[inline(never)]
fn self_test(inner: &mut Inner) -> bool {
    let weight_n = inner.ctl.model().mass_kg() * GRAVITY_M_S2;
    inner.ctl.reset();
    hover_inputs(inner);
    inner.ctl.step_into(
        &inner.state,
        &inner.setpoint,
        &inner.meas,
        0.002,
        &mut inner.out,
    );
    let o = &inner.out;
    let ok = !o.faults.is_fault() && (o.wrench.thrust_n - weight_n).abs() <= 0.2 * weight_n;
    inner.ctl.reset();
    clear_output(inner);
    ok
}

/// The self test's inputs: at rest at the origin, hover there. Out of line: the temporaries
/// are off the stack before the step runs.
#[inline(never)]
fn hover_inputs(inner: &mut Inner) {
    inner.state = State::default();
    inner.setpoint = Setpoint::default();
    inner.meas = Measurement::default();
}

/// No last output (after the self test).
#[inline(never)]
fn clear_output(inner: &mut Inner) {
    inner.out = Output::default();
    inner.last_faults = abi::FAULT_NOT_INIT;
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
