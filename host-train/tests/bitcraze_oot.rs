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
use host_train::control::adapter::CoreController;
use host_train::control::controller::Controller;
use host_train::fly::eval;
use host_train::sim::plant::{Plant, PlantState};
use host_train::sim::scenario::Scenario;
use host_train::sim::trajectory::TrajectoryPoint;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::Path;
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

extern "C" {
    fn controllerOutOfTreeInit();
    fn controllerOutOfTreeTest() -> bool;
    fn hf_host_reset();
    fn hf_host_set_supervisor(can_fly: bool, is_flying: bool);
    fn hf_host_set_state(
        p: *const f32,
        q_xyzw: *const f32,
        v_world: *const f32,
        gyro_deg_s: *const f32,
        acc_g: *const f32,
    );
    fn hf_host_set_setpoint(
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
    fn hf_host_set_null_setpoint();
    fn hf_host_tick(tick: u32, wrench: *mut f32) -> c_int;
    fn hf_host_find(
        param: c_int,
        group: *const c_char,
        name: *const c_char,
        ty: *mut u32,
    ) -> *mut c_void;
    fn hf_host_debug_text() -> *const c_char;
    fn hf_host_start_app_task();
    fn hf_host_stall_app_task(on: bool);
    fn hf_host_mem_type() -> c_int;
    fn hf_host_mem_registrations() -> c_int;
    fn hf_host_mem_size() -> u32;
    fn hf_host_mem_read(addr: u32, len: u8, buffer: *mut u8) -> bool;
    fn hf_host_mem_write(addr: u32, len: u8, buffer: *const u8) -> bool;
}

/// Bitcraze's setpoint modes.
const DISABLE: c_int = 0;
const ABS: c_int = 1;
const VELOCITY: c_int = 2;
/// `controlModeForceTorque`.
const FORCE_TORQUE: c_int = 1;
/// Bitcraze's PARAM_FLOAT, PARAM_UINT8; LOG_FLOAT, LOG_UINT8, LOG_UINT32.
const PARAM_FLOAT: u32 = 0x06;
const PARAM_UINT8: u32 = 0x08;
const LOG_UINT8: u32 = 1;
const LOG_UINT32: u32 = 3;
const LOG_FLOAT: u32 = 7;

/// The shim's fault bit of the `faults` log: the app task's boot self test has not passed.
const NOT_READY: u32 = 1 << 16;

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

/// The shim's MEM_TYPE_APP layout (hamflight_oot.c, "Upload").
const UP_CONTROL: u32 = 0x40;
const UP_DATA: u32 = 0x1000;
const UP_CMD_BEGIN: u8 = 1;
const UP_CMD_COMMIT: u8 = 2;
const UP_PENDING: u8 = 2;
const UP_SWAPPING: u8 = 3;
const UP_ACTIVE: u8 = 4;
const UP_REJECTED: u8 = 5;
/// `HF_ERR_BLOB_TRUNCATED`, `HF_ERR_BLOB_CRC`, `HF_ERR_BLOB_MASS`.
const ERR_BLOB_TRUNCATED: u8 = 16;
const ERR_BLOB_CRC: u8 = 20;
const ERR_BLOB_MASS: u8 = 24;
/// The shim's fault bit of the `faults` log while the app task swaps the model.
const SWAPPING: u32 = 1 << 17;
/// cflib's `_WriteRequest.MAX_DATA_LENGTH` and `_ReadRequest.MAX_DATA_LENGTH` (0.1.34).
const CFLIB_CHUNK: usize = 24;

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

/// The shim as a host [`Controller`], called once per 1 kHz tick with the scenario's reference.
struct ShimController {
    shim: Shim,
}

impl Controller for ShimController {
    fn name(&self) -> &str {
        "adaptive (C shim)"
    }

    fn reset(&mut self) {
        self.shim.tick = 0;
    }

    fn step(&mut self, _t_s: f64, s: &PlantState, r: &TrajectoryPoint, _dt_s: f64) -> [f64; 4] {
        self.shim.set_state(s);
        self.shim.set_abs_setpoint(r);
        rpm_of(self.shim.tick())
    }

    fn step_measured(
        &mut self,
        _t_s: f64,
        s: &PlantState,
        acc_body_m_s2: Option<&Vector3<f64>>,
        r: &TrajectoryPoint,
        _dt_s: f64,
    ) -> [f64; 4] {
        self.shim.set_state_measured(s, acc_body_m_s2);
        self.shim.set_abs_setpoint(r);
        rpm_of(self.shim.tick())
    }

    fn adaptation_estimate(&self) -> Option<Vec<f64>> {
        Some(self.shim.estimate().iter().map(|v| f64::from(*v)).collect())
    }
}

fn scenario(name: &str) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios")
        .join(format!("{name}.toml"));
    Scenario::load(path).expect("scenario loads")
}

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

/// paper-spiral flown natively at 500 Hz with `gains` and through the shim at 1 kHz with
/// `hamflight.law` = `law`, the accelerometer given to both: asserts that the paths agree and
/// returns the largest position difference (m).
fn c_path_matches_native(law: u8, gains: Gains) -> f64 {
    c_path_matches_native_with(law, gains, &MODEL, None)
}

/// [`c_path_matches_native`] with `model` natively and, through the shim, `blob` uploaded over
/// the memory protocol before the flight (None: the compiled-in blob, which `model` then is).
fn c_path_matches_native_with(
    law: u8,
    gains: Gains,
    model: &LearnedModel,
    blob: Option<&[u8]>,
) -> f64 {
    let native_sc = scenario("paper-spiral");
    let mut native = CoreController::new("native", model, gains);
    let native_log = eval::fly(&native_sc, &mut native);

    // The same flight with the shim at the stabilizer's 1 kHz (the physics stays at 1 kHz). It
    // starts in the air and flying, so the airborne rule must not hold the adaptation back.
    let mut c_sc = native_sc.clone();
    c_sc.spec.control_hz = 1000.0;
    let mut shim = Shim::new();
    if let Some(blob) = blob {
        // On the ground (the supervisor cannot fly): the upload swaps in at once.
        let order: Vec<usize> = (0..blob.len()).step_by(CFLIB_CHUNK).collect();
        assert!(shim.upload(blob, &order), "every packet accepted");
        shim.wait_for_swap();
        assert_eq!(shim.log_u8("blobSrc"), 1, "the upload flies");
    }
    shim.set_param_u8("law", law);
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0);
    let mut c = ShimController { shim };
    let c_log = eval::fly(&c_sc, &mut c);

    assert!(native_log.crash_time_s.is_none() && c_log.crash_time_s.is_none());
    assert_eq!(c_log.p_m.len(), 2 * native_log.p_m.len() - 1);
    let max_diff_m = native_log
        .p_m
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let q = c_log.p_m[2 * k];
            (Vector3::from(*p) - Vector3::from(q)).norm()
        })
        .fold(0.0, f64::max);
    println!(
        "paper-spiral, law {law}: C path vs native, largest position difference {max_diff_m:.3e} m"
    );
    if let Some(k) = (0..native_log.p_m.len()).find(|&k| {
        (Vector3::from(native_log.p_m[k]) - Vector3::from(c_log.p_m[2 * k])).norm() > 1e-7
    }) {
        println!(
            "first difference above 1e-7 m at t = {} s",
            native_log.t_s[k]
        );
    }
    // The two paths differ only by f32 rounding of the conversions (quaternion, deg/s, world
    // velocity, the accelerometer in G): 5.5e-8 m (gradient law) and 8.1e-8 m (composite)
    // measured. A path that hands Bitcraze's power distribution the law's wrench instead of the
    // command (`Output::command`, with the motor-lag lead) drifts by millimetres: fail well
    // before that.
    assert!(
        max_diff_m < 1e-5,
        "C path drifts {max_diff_m} m from native"
    );
    let rmse = eval::Report::from_log(&c_log, None)
        .rmse_pos_window_m
        .unwrap();
    assert!(rmse < 0.01, "the C path tracks paper-spiral: RMSE {rmse} m");
    // The estimate the logs show is the native controller's.
    let a_native = native.inner().estimate();
    let a_c = c.shim.estimate();
    for (x, y) in a_native.iter().zip(a_c.iter()) {
        assert!(
            (x - y).abs() < 1e-3 * (1.0 + x.abs()),
            "a: native {a_native:?}, C {a_c:?}"
        );
    }
    assert!(c.shim.log_u32("cycles") > 0, "the step cost is logged");
    assert_eq!(c.shim.log_u8("phase"), 2, "airborne");
    assert_eq!(c.shim.log_u8("law"), law, "the law in use is logged");
    // The composite law's diagnostics: its prediction error and the trace of P, as the native
    // controller has them; zero under the gradient law.
    let eps_c = ["e0", "e1", "e2", "e3", "e4", "e5"].map(|n| c.shim.log_f32(n));
    let p_trace_c = c.shim.log_f32("pTrace");
    let ad = native.inner().adaptation();
    let eps_native: [f32; 6] = ad.prediction_error().map_or([0.0; 6], Into::into);
    let p_trace_native = ad.covariance_trace();
    for (x, y) in eps_native.iter().zip(eps_c.iter()) {
        assert!(
            (x - y).abs() < 1e-3 * (1.0 + x.abs()),
            "prediction error: native {eps_native:?}, C {eps_c:?}"
        );
    }
    assert!(
        (p_trace_native - p_trace_c).abs() <= 1e-4 * p_trace_native.abs(),
        "trace of P: native {p_trace_native}, C {p_trace_c}"
    );
    if law == 0 {
        assert_eq!((eps_c, p_trace_c), ([0.0; 6], 0.0));
    } else {
        assert!(p_trace_c > 0.0 && eps_c.iter().any(|e| *e != 0.0));
    }
    max_diff_m
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
    let mut plant = scenario("hover").plant();
    let start = plant.state().p_m.cast::<f32>();
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0);
    let hold = move |shim: &mut Shim, _t: f64| {
        shim.set_setpoint([ABS; 4], start.into(), [0.0; 3], 0.0, 0.0, 0.0, false)
    };
    fly_shim(&mut shim, &mut plant, 0.5, hold);
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
fn flight_phases_zero_output_ground_freeze_and_reset_after_landing() {
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
    // 1.4 cm measured 3 s after the 45° step.
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
    assert_eq!((info.magic, info.layout), (u32::from_le_bytes(*b"HFUP"), 1));
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
    // Read back before it flies (the tool's verification): the staging slot holds the blob.
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

#[test]
fn torn_and_bad_uploads_are_rejected_and_the_flying_blob_is_untouched() {
    let mut shim = Shim::new();
    let (_, good) = other_blob(0.029);
    assert!(shim.upload(&good, &chunks(&good)));
    shim.wait_for_swap();
    assert_eq!(shim.log_u8("blobSrc"), 1);
    let flying = shim.log_u32("blobCrc");
    assert_eq!(flying, blob_crc(&good));

    let (_, next) = other_blob(0.033);
    let reject = |shim: &mut Shim, bytes: &[u8], len: usize, order: &[usize], err: u8| {
        let mut begin = vec![UP_CMD_BEGIN];
        begin.extend_from_slice(&(len as u32).to_le_bytes());
        assert!(shim.mem_write(UP_CONTROL, &begin));
        for &off in order {
            let end = (off + CFLIB_CHUNK).min(bytes.len()).min(len);
            assert!(shim.mem_write(UP_DATA + off as u32, &bytes[off..end]));
        }
        assert!(shim.mem_write(UP_CONTROL, &[UP_CMD_COMMIT]));
        let info = shim.up_info();
        assert_eq!((info.state, info.error), (UP_REJECTED, err), "{info:?}");
        // Nothing to swap: ticks fly on with the blob that flew before.
        shim.tick();
        shim.tick();
        assert_eq!(
            (shim.log_u8("blobSrc"), shim.log_u32("blobCrc")),
            (1, flying)
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
    let mut begin = vec![UP_CMD_BEGIN];
    begin.extend_from_slice(&(next.len() as u32).to_le_bytes());
    assert!(shim.mem_write(UP_CONTROL, &begin));
    assert!(!shim.mem_write(UP_DATA + next.len() as u32 - 2, &[0; 4]));
    // And a good upload still goes through after all that.
    assert!(shim.upload(&next, &chunks(&next)));
    shim.wait_for_swap();
    assert_eq!(shim.log_u32("blobCrc"), blob_crc(&next));
}

#[test]
fn an_upload_in_flight_waits_for_the_landing() {
    let mut shim = Shim::new();
    let mut plant = scenario("hover").plant();
    let start = plant.state().p_m.cast::<f32>();
    shim.supervisor(true, true);
    shim.set_param_f32("airHeight", 0.0);
    let hold = move |shim: &mut Shim, _t: f64| {
        shim.set_setpoint([ABS; 4], start.into(), [0.0; 3], 0.0, 0.0, 0.0, false)
    };
    fly_shim(&mut shim, &mut plant, 0.5, hold);
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
fn a_flight_with_the_uploaded_blob_matches_the_native_controller_with_it() {
    let (m, blob) = other_blob(0.030);
    let gains = Gains {
        law: hamflight::AdaptationLaw::Gradient,
        ..Gains::for_vehicle(&hamflight::VehicleFacts::of(&m))
    };
    let d = c_path_matches_native_with(0, gains, &m, Some(&blob));
    println!("uploaded blob, paper-spiral: largest difference from native {d:.3e} m");
}
