//! The C shim's entry points and its host harness (firmware/bitcraze-app/host-include/
//! host_harness.c), linked from the host build of `hamflight-bitcraze`, and the numbers of its
//! ABI (Bitcraze's modes and types, the upload memory's layout).

use std::ffi::{c_char, c_int, c_void};

extern "C" {
    pub(crate) fn controllerOutOfTreeInit();
    pub(crate) fn controllerOutOfTreeTest() -> bool;
    pub(crate) fn hf_host_reset();
    pub(crate) fn hf_host_set_supervisor(can_fly: bool, is_flying: bool);
    pub(crate) fn hf_host_set_state(
        p: *const f32,
        q_xyzw: *const f32,
        v_world: *const f32,
        gyro_deg_s: *const f32,
        acc_g: *const f32,
    );
    pub(crate) fn hf_host_set_setpoint(
        modes: *const c_int,
        p: *const f32,
        v: *const f32,
        a: *const f32,
        j: *const f32,
        yaw_deg: f32,
        yaw_rate_deg_s: f32,
        thrust: f32,
        velocity_body: bool,
    );
    pub(crate) fn hf_host_set_setpoint_attitude(
        modes_rpq: *const c_int,
        roll_rate_deg_s: f32,
        pitch_rate_deg_s: f32,
        q_xyzw: *const f32,
    );
    pub(crate) fn hf_host_set_null_setpoint();
    pub(crate) fn hf_host_tick(tick: u32, wrench: *mut f32) -> c_int;
    pub(crate) fn hf_host_find(
        param: c_int,
        group: *const c_char,
        name: *const c_char,
        ty: *mut u32,
    ) -> *mut c_void;
    pub(crate) fn hf_host_debug_text() -> *const c_char;
    pub(crate) fn hf_host_start_app_task();
    pub(crate) fn hf_host_stall_app_task(on: bool);
    pub(crate) fn hf_host_mem_type() -> c_int;
    pub(crate) fn hf_host_mem_registrations() -> c_int;
    pub(crate) fn hf_host_mem_size() -> u32;
    pub(crate) fn hf_host_mem_read(addr: u32, len: u8, buffer: *mut u8) -> bool;
    pub(crate) fn hf_host_mem_write(addr: u32, len: u8, buffer: *const u8) -> bool;
}

/// Bitcraze's setpoint modes.
pub(crate) const DISABLE: c_int = 0;
pub(crate) const ABS: c_int = 1;
pub(crate) const VELOCITY: c_int = 2;
/// `controlModeForceTorque`.
pub(crate) const FORCE_TORQUE: c_int = 1;
/// Bitcraze's PARAM_FLOAT, PARAM_UINT8; LOG_FLOAT, LOG_UINT8, LOG_UINT32.
pub(crate) const PARAM_FLOAT: u32 = 0x06;
pub(crate) const PARAM_UINT8: u32 = 0x08;
pub(crate) const LOG_UINT8: u32 = 1;
pub(crate) const LOG_UINT32: u32 = 3;
pub(crate) const LOG_FLOAT: u32 = 7;

/// The shim's fault bit of the `faults` log: the app task's boot self test has not passed.
pub(crate) const NOT_READY: u32 = 1 << 16;

/// The shim's MEM_TYPE_APP layout (hamflight_oot.c, "Upload").
pub(crate) const UP_CONTROL: u32 = 0x40;
pub(crate) const UP_DATA: u32 = 0x1000;
pub(crate) const UP_CMD_BEGIN: u8 = 1;
pub(crate) const UP_CMD_COMMIT: u8 = 2;
pub(crate) const UP_IDLE: u8 = 0;
pub(crate) const UP_PENDING: u8 = 2;
pub(crate) const UP_SWAPPING: u8 = 3;
pub(crate) const UP_ACTIVE: u8 = 4;
pub(crate) const UP_REJECTED: u8 = 5;
/// `HF_ERR_BLOB_TRUNCATED`, `HF_ERR_BLOB_CRC`, `HF_ERR_BLOB_MASS`.
pub(crate) const ERR_BLOB_TRUNCATED: u8 = 16;
pub(crate) const ERR_BLOB_CRC: u8 = 20;
/// The shim's refusals of a BEGIN while an uploaded blob flies (HF_UP_ERR_BUSY_*).
pub(crate) const UP_ERR_BUSY_FLYING: u8 = 64;
pub(crate) const UP_ERR_BUSY_REVERTING: u8 = 65;
pub(crate) const ERR_BLOB_MASS: u8 = 24;
/// The shim's fault bit of the `faults` log while the app task swaps the model.
pub(crate) const SWAPPING: u32 = 1 << 17;
/// cflib's `_WriteRequest.MAX_DATA_LENGTH` and `_ReadRequest.MAX_DATA_LENGTH` (0.1.34).
pub(crate) const CFLIB_CHUNK: usize = 24;
