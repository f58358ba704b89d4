//! Safe Rust faces of `shim/bc_shim.c`: Bitcraze's sensor filters, Kalman estimator,
//! controllers and power distribution, each owned and freed by a Rust value.

use std::ptr::NonNull;

/// Bitcraze's `state_t`, field by field (`hf_bc_state` in the shim).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BcState {
    /// Position (m, world).
    pub p_m: [f32; 3],
    /// Velocity (m/s, world).
    pub v_m_s: [f32; 3],
    /// Attitude quaternion (x, y, z, w), body to world.
    pub q_xyzw: [f32; 4],
    /// Roll, pitch, yaw (deg), Bitcraze's legacy convention (pitch inverted).
    pub rpy_deg: [f32; 3],
    /// Acceleration (g, world, gravity removed).
    pub acc_g: [f32; 3],
}

/// A pose measurement (`hf_bc_pose`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct BcPose {
    /// Position (m, world).
    pub p_m: [f32; 3],
    /// Attitude (x, y, z, w).
    pub q_xyzw: [f32; 4],
    /// Position σ the filter assumes (m).
    pub std_pos_m: f32,
    /// Attitude σ the filter assumes.
    pub std_quat: f32,
    /// Non-zero: a full pose; zero: position only.
    pub with_attitude: i32,
}

/// A full-state setpoint (`hf_bc_setpoint`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct BcSetpoint {
    /// Position (m, world).
    pub p_m: [f32; 3],
    /// Velocity (m/s, world).
    pub v_m_s: [f32; 3],
    /// Acceleration (m/s², world).
    pub a_m_s2: [f32; 3],
    /// Jerk (m/s³, world).
    pub j_m_s3: [f32; 3],
    /// Yaw (deg).
    pub yaw_deg: f32,
}

#[repr(C)]
struct RawFilter {
    _p: [u8; 0],
}
#[repr(C)]
struct RawKalman {
    _p: [u8; 0],
}
#[repr(C)]
struct RawCtrl {
    _p: [u8; 0],
}

extern "C" {
    fn hf_bc_imu_filter_new(sample_hz: f32, gyro_hz: f32, acc_hz: f32) -> *mut RawFilter;
    fn hf_bc_imu_filter_free(f: *mut RawFilter);
    fn hf_bc_imu_filter_apply(f: *mut RawFilter, acc_g: *mut f32, gyro_dps: *mut f32);
    fn hf_bc_kalman_new(now_ms: u32, p0_m: *const f32, yaw0_rad: f32) -> *mut RawKalman;
    fn hf_bc_kalman_free(k: *mut RawKalman);
    fn hf_bc_kalman_imu(k: *mut RawKalman, acc_g: *const f32, gyro_dps: *const f32);
    fn hf_bc_kalman_step(
        k: *mut RawKalman,
        now_ms: u32,
        flying: i32,
        pose: *const BcPose,
        out: *mut BcState,
    ) -> i32;
    fn hf_bc_ctrl_new(kind: i32, mass_kg: f32) -> *mut RawCtrl;
    fn hf_bc_ctrl_free(c: *mut RawCtrl);
    fn hf_bc_ctrl_step(
        c: *mut RawCtrl,
        sp: *const BcSetpoint,
        acc_g: *const f32,
        gyro_dps: *const f32,
        st: *const BcState,
        tick: u32,
        motor_n: *mut f32,
    ) -> i32;
    fn hf_bc_power_force_torque(thrust_n: f32, torque_nm: *const f32, motor_n: *mut f32) -> i32;
    fn hf_bc_platform(arm_m: *mut f32, thrust_max_n: *mut f32, t2t: *mut f32, mass_kg: *mut f32);
}

/// Bitcraze's platform constants (`platform_defaults*.h`) the compiled code uses.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Platform {
    /// Motor to centre (m), `ARM_LENGTH`.
    pub arm_length_m: f32,
    /// One motor's largest thrust (N), `THRUST_MAX`.
    pub thrust_max_n: f32,
    /// Yaw torque per newton of thrust (m), `THRUST2TORQUE`.
    pub thrust_to_torque_m: f32,
    /// The mass Bitcraze's code assumes where it is not told one (kg), `CF_MASS`.
    pub cf_mass_kg: f32,
}

/// The platform constants of the compiled checkout.
pub fn platform() -> Platform {
    let (mut a, mut t, mut k, mut m) = (0.0, 0.0, 0.0, 0.0);
    // SAFETY: four valid out-pointers to f32.
    unsafe { hf_bc_platform(&mut a, &mut t, &mut k, &mut m) };
    Platform {
        arm_length_m: a,
        thrust_max_n: t,
        thrust_to_torque_m: k,
        cf_mass_kg: m,
    }
}

fn non_null<T>(p: *mut T, what: &str) -> anyhow::Result<NonNull<T>> {
    NonNull::new(p).ok_or_else(|| anyhow::anyhow!("{what}: allocation failed"))
}

/// The sensor task's 2-pole low-pass filters on the gyro and the accelerometer.
pub struct ImuFilter(NonNull<RawFilter>);

impl ImuFilter {
    /// Filters sampled at `sample_hz` with the two cutoffs (Hz).
    pub fn new(sample_hz: f32, gyro_hz: f32, acc_hz: f32) -> anyhow::Result<Self> {
        // SAFETY: plain values in, an owned pointer (or null) out.
        non_null(
            unsafe { hf_bc_imu_filter_new(sample_hz, gyro_hz, acc_hz) },
            "IMU filter",
        )
        .map(Self)
    }

    /// Filters one sample in place: acceleration (g) and rates (deg/s), body.
    pub fn apply(&mut self, acc_g: &mut [f32; 3], gyro_dps: &mut [f32; 3]) {
        // SAFETY: an owned filter, two 3-element arrays.
        unsafe {
            hf_bc_imu_filter_apply(self.0.as_ptr(), acc_g.as_mut_ptr(), gyro_dps.as_mut_ptr())
        }
    }
}

impl Drop for ImuFilter {
    fn drop(&mut self) {
        // SAFETY: allocated by hf_bc_imu_filter_new, freed once.
        unsafe { hf_bc_imu_filter_free(self.0.as_ptr()) }
    }
}

/// Bitcraze's Kalman core, driven as their estimator task drives it.
pub struct Kalman(NonNull<RawKalman>);

impl Kalman {
    /// A filter started at `p0_m` with yaw `yaw0_rad`, at time `now_ms`.
    pub fn new(now_ms: u32, p0_m: [f32; 3], yaw0_rad: f32) -> anyhow::Result<Self> {
        // SAFETY: a 3-element array in, an owned pointer (or null) out.
        non_null(
            unsafe { hf_bc_kalman_new(now_ms, p0_m.as_ptr(), yaw0_rad) },
            "Kalman",
        )
        .map(Self)
    }

    /// One filtered IMU sample (g, deg/s) into the prediction's sub-samplers.
    pub fn imu(&mut self, acc_g: &[f32; 3], gyro_dps: &[f32; 3]) {
        // SAFETY: an owned filter, two 3-element arrays.
        unsafe { hf_bc_kalman_imu(self.0.as_ptr(), acc_g.as_ptr(), gyro_dps.as_ptr()) }
    }

    /// One 1 kHz iteration of the estimator task; `false` if the state left its bounds.
    pub fn step(&mut self, now_ms: u32, flying: bool, pose: Option<&BcPose>) -> (BcState, bool) {
        let mut out = BcState::default();
        let pose = pose.map_or(std::ptr::null(), |p| p as *const BcPose);
        // SAFETY: an owned filter, a valid or null pose, a valid out-pointer.
        let ok =
            unsafe { hf_bc_kalman_step(self.0.as_ptr(), now_ms, flying as i32, pose, &mut out) };
        (out, ok != 0)
    }
}

impl Drop for Kalman {
    fn drop(&mut self) {
        // SAFETY: allocated by hf_bc_kalman_new, freed once.
        unsafe { hf_bc_kalman_free(self.0.as_ptr()) }
    }
}

/// Which of Bitcraze's controllers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BcKind {
    /// `controller_pid.c`: cascaded PID.
    Pid = 0,
    /// `controller_mellinger.c`.
    Mellinger = 1,
    /// `controller_lee.c`: the geometric controller.
    Lee = 2,
    /// `controller_brescianini.c`.
    Brescianini = 3,
}

impl BcKind {
    /// By the study's name (`bc-pid`, `bc-mellinger`, `bc-lee`, `bc-brescianini`).
    pub fn by_name(name: &str) -> Option<Self> {
        Some(match name {
            "bc-pid" => Self::Pid,
            "bc-mellinger" => Self::Mellinger,
            "bc-lee" => Self::Lee,
            "bc-brescianini" => Self::Brescianini,
            _ => return None,
        })
    }
}

/// One of Bitcraze's controllers, with power distribution behind it. PID and Brescianini keep
/// file-static state in Bitcraze's code: fly one at a time.
pub struct BcController(NonNull<RawCtrl>);

impl BcController {
    /// A fresh controller told the vehicle's mass where it takes one (Mellinger, Lee).
    pub fn new(kind: BcKind, mass_kg: f32) -> anyhow::Result<Self> {
        // SAFETY: plain values in, an owned pointer (or null) out.
        non_null(
            unsafe { hf_bc_ctrl_new(kind as i32, mass_kg) },
            "controller",
        )
        .map(Self)
    }

    /// One 1 kHz stabilizer tick: the controller (which runs its own loops at their rates)
    /// and power distribution; per-motor thrust (N) into `motor_n`. Returns whether it capped.
    pub fn step(
        &mut self,
        sp: &BcSetpoint,
        acc_g: &[f32; 3],
        gyro_dps: &[f32; 3],
        st: &BcState,
        tick: u32,
        motor_n: &mut [f32; 4],
    ) -> bool {
        // SAFETY: an owned controller and valid pointers to fixed-size values.
        unsafe {
            hf_bc_ctrl_step(
                self.0.as_ptr(),
                sp,
                acc_g.as_ptr(),
                gyro_dps.as_ptr(),
                st,
                tick,
                motor_n.as_mut_ptr(),
            ) != 0
        }
    }
}

impl Drop for BcController {
    fn drop(&mut self) {
        // SAFETY: allocated by hf_bc_ctrl_new, freed once.
        unsafe { hf_bc_ctrl_free(self.0.as_ptr()) }
    }
}

/// Bitcraze's power distribution of a wrench (N, N·m) in force-torque mode, as the Crazyflie
/// app hands our controller's output to it; per-motor thrust (N). Returns whether it capped.
pub fn power_force_torque(thrust_n: f32, torque_nm: [f32; 3], motor_n: &mut [f32; 4]) -> bool {
    // SAFETY: a 3-element and a 4-element array.
    unsafe { hf_bc_power_force_torque(thrust_n, torque_nm.as_ptr(), motor_n.as_mut_ptr()) != 0 }
}
