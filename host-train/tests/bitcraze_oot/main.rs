//! The Crazyflie out-of-tree controller through its C path: the very same shim the firmware
//! builds (`firmware/bitcraze-app/hamflight_oot.c`), compiled for the host against our stand-in
//! Bitcraze headers (`firmware/bitcraze-app/host-include/`) and linked with the host build of the
//! library, flown in the SITL the way crazyflie-firmware's stabilizer drives it: called at
//! 1 kHz with `tick`, with the state as Bitcraze's estimator gives it (position, quaternion
//! x y z w, world velocity) and the gyro in deg/s; its force/torque output is mixed with the
//! core's mixer, as the native controller's is. The core's step runs inline in the stabilizer's
//! call, as on the vehicle; the shim's app task (appMain: the boot self test, model swaps) runs
//! in a thread.
//!
//! Run in release (`cargo test --release -p host-train --test bitcraze_oot`).

use hamflight::mixer::Airframe;
use hamflight::model::LearnedModel;
use hamflight::{Gains, Wrench};
use hamflight_bitcraze::model::MODEL;
use host_train::control::{Controller, CoreController};
use host_train::fly::{fly_scenario, Report};
use host_train::sim::{Plant, PlantState, Scenario, TrajectoryPoint};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use std::ffi::{c_int, c_void, CStr, CString};
use std::path::Path;
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use ffi::*;
use native::{c_path_matches_native, c_path_matches_native_with};

/// The shim's app task (appMain) runs in a thread, started once.
static APP_TASK: OnceLock<()> = OnceLock::new();

/// The shim is global C state: one test at a time holds it.
static SHIM_LOCK: Mutex<()> = Mutex::new(());

/// Exclusive use of the C shim, freshly initialised (supervisor: cannot fly).
struct Shim {
    _guard: MutexGuard<'static, ()>,
    tick: u32,
}

/// The float and byte parameters of group `hamflight`.
const F32_PARAMS: [&str; 16] = [
    "kp",
    "kv",
    "kR",
    "kw",
    "maxTilt",
    "cp",
    "cv",
    "cR",
    "cw",
    "aMax",
    "airHeight",
    "leash",
    "qF",
    "qT",
    "rF",
    "rT",
];
const U8_PARAMS: [&str; 4] = ["adapt", "reset", "law", "revert"];

/// The parameters as the shim's first initialisation left them (its defaults).
static DEFAULTS: OnceLock<(Vec<f32>, Vec<u8>)> = OnceLock::new();

/// The info block, decoded.
#[derive(Debug)]
#[allow(dead_code)]
struct UpInfo {
    magic: u32,
    layout: u16,
    source: u8,
    state: u8,
    crc: u32,
    mass_kg: f32,
    version: u16,
    error: u8,
    capacity: u32,
    len: u32,
    staged_crc: u32,
    name: String,
}

impl Shim {
    /// The shim, initialised as at boot: the firmware keeps parameters across re-selections
    /// of the controller, so every test restores the defaults the first one saw.
    fn new() -> Self {
        let guard = SHIM_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: the lock gives exclusive use of the C globals.
        unsafe {
            hf_host_reset();
            controllerOutOfTreeInit();
        }
        let mut shim = Self {
            _guard: guard,
            tick: 0,
        };
        APP_TASK.get_or_init(|| shim.start_app_task());
        let (f, b) = DEFAULTS.get_or_init(|| {
            (
                F32_PARAMS.iter().map(|n| shim.param_f32(n)).collect(),
                U8_PARAMS.iter().map(|n| shim.param_u8(n)).collect(),
            )
        });
        for (n, v) in F32_PARAMS.iter().zip(f) {
            shim.set_param_f32(n, *v);
        }
        // A test that left an upload flying, pending or still swapping in the app task must not
        // change the next one's model: let a swap in progress end first.
        shim.wait_for_swap();
        if shim.log_u8("blobSrc") != 0 || shim.log_u8("upState") == UP_PENDING {
            shim.set_param_u8("revert", 1);
            shim.wait_for_swap();
            assert_eq!(
                shim.log_u8("blobSrc"),
                0,
                "reverted to the compiled-in blob"
            );
        }
        for (n, v) in F32_PARAMS.iter().zip(f) {
            shim.set_param_f32(n, *v);
        }
        for (n, v) in U8_PARAMS.iter().zip(b) {
            shim.set_param_u8(n, *v);
        }
        shim.tick = 0;
        shim
    }

    /// Ticks (with whatever state and setpoint are set) until no swap is pending or running:
    /// the app task swaps asynchronously, the stabilizer outputs zero meanwhile.
    fn wait_for_swap(&mut self) {
        let t0 = Instant::now();
        loop {
            let w = self.tick();
            let st = self.log_u8("upState");
            let swapping = self.log_u32("faults") & SWAPPING != 0;
            if st != UP_PENDING && st != UP_SWAPPING && !swapping {
                return;
            }
            if swapping {
                assert_eq!(w, [0.0; 4], "zero output while swapping");
            }
            assert!(t0.elapsed() < Duration::from_secs(20), "the swap ends");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// A memory-protocol write packet (false: the EIO status the client gets).
    fn mem_write(&mut self, addr: u32, data: &[u8]) -> bool {
        let len = u8::try_from(data.len()).expect("one packet");
        // SAFETY: a valid buffer of len bytes; exclusive.
        unsafe { hf_host_mem_write(addr, len, data.as_ptr()) }
    }

    /// A memory-protocol read packet.
    fn mem_read(&mut self, addr: u32, len: u8) -> Option<Vec<u8>> {
        let mut buf = vec![0u8; usize::from(len)];
        // SAFETY: a valid buffer of len bytes; exclusive.
        unsafe { hf_host_mem_read(addr, len, buf.as_mut_ptr()) }.then_some(buf)
    }

    /// Reads `len` bytes from `addr` the way cflib's `Memory.read` does: 24-byte packets.
    fn mem_read_all(&mut self, addr: u32, len: usize) -> Vec<u8> {
        let mut out = Vec::with_capacity(len);
        while out.len() < len {
            let n = (len - out.len()).min(CFLIB_CHUNK) as u8;
            let chunk = self
                .mem_read(addr + out.len() as u32, n)
                .expect("read accepted");
            out.extend_from_slice(&chunk);
        }
        out
    }

    /// The info block (0x00..0x40).
    fn up_info(&mut self) -> UpInfo {
        let b = self.mem_read_all(0, 0x40);
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap());
        let name_end = b[0x20..].iter().position(|c| *c == 0).unwrap_or(32);
        UpInfo {
            magic: u32_at(0),
            layout: u16::from_le_bytes([b[4], b[5]]),
            source: b[6],
            state: b[7],
            crc: u32_at(8),
            mass_kg: f32::from_bits(u32_at(0x0C)),
            version: u16::from_le_bytes([b[0x10], b[0x11]]),
            error: b[0x12],
            capacity: u32_at(0x14),
            len: u32_at(0x18),
            staged_crc: u32_at(0x1C),
            name: String::from_utf8_lossy(&b[0x20..0x20 + name_end]).into_owned(),
        }
    }

    /// BEGIN, the data in 24-byte chunks at the offsets `order` gives (cflib's own order is
    /// increasing), COMMIT. Returns whether every packet was accepted.
    fn upload(&mut self, blob: &[u8], order: &[usize]) -> bool {
        let mut begin = vec![UP_CMD_BEGIN];
        begin.extend_from_slice(&(blob.len() as u32).to_le_bytes());
        let mut ok = self.mem_write(UP_CONTROL, &begin);
        for &off in order {
            let end = (off + CFLIB_CHUNK).min(blob.len());
            ok &= self.mem_write(UP_DATA + off as u32, &blob[off..end]);
        }
        ok & self.mem_write(UP_CONTROL, &[UP_CMD_COMMIT])
    }

    /// Starts appMain, the shim's app task, in a thread and waits until its self test passed
    /// (a probe step stops reporting "not ready"), then initialises the shim again.
    fn start_app_task(&mut self) {
        // SAFETY: exclusive (the lock); the thread lives until the process ends.
        unsafe { hf_host_start_app_task() };
        self.supervisor(true, false);
        self.set_state(&PlantState::at_rest(Vector3::new(0.0, 0.0, 0.5), 0.0));
        self.set_setpoint([ABS; 4], [0.0, 0.0, 0.5], [0.0; 3], 0.0, 0.0, 0.0, false);
        let t0 = Instant::now();
        loop {
            self.tick = 0;
            self.tick();
            if self.log_u32("faults") & NOT_READY == 0 {
                break;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "the app task starts"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        // SAFETY: exclusive (the lock).
        unsafe {
            hf_host_reset();
            controllerOutOfTreeInit();
        }
        self.tick = 0;
    }

    fn supervisor(&mut self, can_fly: bool, is_flying: bool) {
        // SAFETY: exclusive (the lock).
        unsafe { hf_host_set_supervisor(can_fly, is_flying) };
    }

    fn find(&self, param: bool, name: &str, ty: u32) -> *mut c_void {
        let group = CString::new("hamflight").unwrap();
        let cname = CString::new(name).unwrap();
        let mut found = 0u32;
        // SAFETY: valid C strings and out pointer.
        let p = unsafe {
            hf_host_find(
                c_int::from(param),
                group.as_ptr(),
                cname.as_ptr(),
                &mut found,
            )
        };
        let kind = if param { "parameter" } else { "log" };
        assert!(!p.is_null(), "{kind} hamflight.{name} exists");
        assert_eq!(found, ty, "{kind} hamflight.{name} has type {ty}");
        p
    }

    fn set_param_f32(&mut self, name: &str, v: f32) {
        // SAFETY: a float parameter's address (type checked), exclusive.
        unsafe { *self.find(true, name, PARAM_FLOAT).cast::<f32>() = v };
    }

    fn param_f32(&self, name: &str) -> f32 {
        // SAFETY: as above.
        unsafe { *self.find(true, name, PARAM_FLOAT).cast::<f32>() }
    }

    fn set_param_u8(&mut self, name: &str, v: u8) {
        // SAFETY: a uint8 parameter's address (type checked), exclusive.
        unsafe { *self.find(true, name, PARAM_UINT8).cast::<u8>() = v };
    }

    fn param_u8(&self, name: &str) -> u8 {
        // SAFETY: as above.
        unsafe { *self.find(true, name, PARAM_UINT8).cast::<u8>() }
    }

    fn log_f32(&self, name: &str) -> f32 {
        // SAFETY: a float log variable's address (type checked).
        unsafe { *self.find(false, name, LOG_FLOAT).cast::<f32>() }
    }

    fn log_u8(&self, name: &str) -> u8 {
        // SAFETY: a uint8 log variable's address (type checked).
        unsafe { *self.find(false, name, LOG_UINT8).cast::<u8>() }
    }

    fn log_u32(&self, name: &str) -> u32 {
        // SAFETY: a uint32 log variable's address (type checked).
        unsafe { *self.find(false, name, LOG_UINT32).cast::<u32>() }
    }

    /// The adaptation estimate a, from the logs.
    fn estimate(&self) -> [f32; 6] {
        ["a0", "a1", "a2", "a3", "a4", "a5"].map(|n| self.log_f32(n))
    }

    /// The plant's state as Bitcraze's estimator and sensors give it.
    fn set_state(&mut self, s: &PlantState) {
        self.set_state_measured(s, None);
    }

    /// The state with the accelerometer's specific force (m/s², body), or without one the
    /// reading at rest (1 G along body z).
    fn set_state_measured(&mut self, s: &PlantState, acc_m_s2: Option<&Vector3<f64>>) {
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
        let q = [q.i, q.j, q.k, q.w].map(|v| v as f32);
        let p = s.p_m.cast::<f32>();
        let v = s.v_world_m_s().cast::<f32>();
        let gyro = s.w_body_rad_s.map(f64::to_degrees).cast::<f32>();
        // In G, as Bitcraze's sensors give it (the shim multiplies by 9.81).
        let acc = acc_m_s2
            .map_or(s.rot.transpose() * Vector3::z(), |a| a / 9.81)
            .cast::<f32>();
        // SAFETY: arrays of three (four) floats; exclusive.
        unsafe {
            hf_host_set_state(
                p.as_ptr(),
                q.as_ptr(),
                v.as_ptr(),
                gyro.as_ptr(),
                acc.as_ptr(),
            )
        };
    }

    /// An absolute setpoint (the high-level commander's): every axis and yaw in modeAbs.
    fn set_abs_setpoint(&mut self, r: &TrajectoryPoint) {
        let [p, v, a, j] = [r.p_m, r.v_m_s, r.a_m_s2, r.j_m_s3].map(|x| x.cast::<f32>());
        let modes = [ABS; 4];
        // SAFETY: arrays of four ints and three floats; exclusive.
        unsafe {
            hf_host_set_setpoint(
                modes.as_ptr(),
                p.as_ptr(),
                v.as_ptr(),
                a.as_ptr(),
                j.as_ptr(),
                r.yaw_rad.to_degrees() as f32,
                r.yaw_rate_rad_s.to_degrees() as f32,
                0.0,
                false,
            )
        };
    }

    /// Any setpoint: modes x, y, z, yaw.
    #[allow(clippy::too_many_arguments)]
    fn set_setpoint(
        &mut self,
        modes: [c_int; 4],
        p: [f32; 3],
        v: [f32; 3],
        yaw_deg: f32,
        yaw_rate_deg_s: f32,
        thrust: f32,
        velocity_body: bool,
    ) {
        let z = [0.0f32; 3];
        // SAFETY: as above.
        unsafe {
            hf_host_set_setpoint(
                modes.as_ptr(),
                p.as_ptr(),
                v.as_ptr(),
                z.as_ptr(),
                z.as_ptr(),
                yaw_deg,
                yaw_rate_deg_s,
                thrust,
                velocity_body,
            )
        };
    }

    fn set_null_setpoint(&mut self) {
        // SAFETY: exclusive.
        unsafe { hf_host_set_null_setpoint() };
    }

    /// One 1 kHz stabilizer tick: control_t's (thrustSi, torque[3]).
    fn tick(&mut self) -> [f32; 4] {
        let mut w = [f32::NAN; 4];
        // SAFETY: four floats; exclusive.
        let mode = unsafe { hf_host_tick(self.tick, w.as_mut_ptr()) };
        self.tick += 1;
        assert_eq!(mode, FORCE_TORQUE, "controlModeForceTorque");
        w
    }

    fn debug_text(&self) -> String {
        // SAFETY: a NUL-terminated buffer owned by the harness.
        unsafe { CStr::from_ptr(hf_host_debug_text()) }
            .to_string_lossy()
            .into_owned()
    }
}

/// The core's mixer on the shim's wrench: the rotor speeds the SITL plant takes.
fn rpm_of(w: [f32; 4]) -> [f64; 4] {
    let wrench = Wrench {
        thrust_n: w[0],
        torque_nm: Vector3::new(w[1], w[2], w[3]),
    };
    Airframe::default().mix(&wrench).0.rpm.map(f64::from)
}

fn scenario(name: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(format!("{name}.toml"));
    Scenario::load(path).expect("scenario loads")
}

/// The hover scenario's plant, flown from the ground for 0.5 s holding its start position (the
/// supervisor says flying, `airHeight` 0) until the shim is airborne; with that position and the
/// hold, to fly on.
fn take_off_and_hold(shim: &mut Shim) -> (Plant, Vector3<f32>, impl Fn(&mut Shim, f64) + Copy) {
    let mut plant = scenario("hover").plant();
    let start = plant.state().p_m.cast::<f32>();
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0);
    let hold = move |shim: &mut Shim, _t: f64| {
        shim.set_setpoint([ABS; 4], start.into(), [0.0; 3], 0.0, 0.0, 0.0, false)
    };
    fly_shim(shim, &mut plant, 0.5, hold);
    (plant, start, hold)
}

/// Flies the plant at 1 kHz with `setpoint(shim, t)` choosing the setpoint each tick.
fn fly_shim(
    shim: &mut Shim,
    plant: &mut Plant,
    seconds: f64,
    mut setpoint: impl FnMut(&mut Shim, f64),
) {
    let dt = 1e-3;
    let n = (seconds / dt).round() as u64;
    let t0 = plant.t_s();
    for k in 0..n {
        let t = t0 + k as f64 * dt;
        let s = *plant.state();
        assert!(s.is_finite() && s.p_m.z > 0.0, "flying at t = {t} s: {s:?}");
        // The plant's own specific force: the composite law (the default) reads it.
        shim.set_state_measured(&s, Some(&plant.accelerometer()));
        setpoint(shim, t);
        let cmd = plant.params.clamp_rpm(rpm_of(shim.tick()));
        plant.step(cmd, dt);
    }
}

mod ffi;
mod flight;
mod jerk;
mod native;
mod upload;
