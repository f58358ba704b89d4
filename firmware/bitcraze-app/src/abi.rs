//! The `#[repr(C)]` types of `include/hamflight.h` and their conversions to the core's types.
//!
//! Every type here has a twin in the header; `header_layout_matches_rust` (below) compares the
//! sizes, offsets and constants the host C compiler sees with these.

use hamflight::adapt::{AdaptationLaw, AdaptationRates, CompositeGains};
use hamflight::{Faults, Gains, Setpoint, State};
use nalgebra::{Matrix3, Vector3};

/// `HF_FEATURES`.
pub const FEATURES: usize = hamflight::model::FEATURES;
/// `HF_CONTROLLER_STORAGE_BYTES`.
pub const CONTROLLER_STORAGE_BYTES: usize = 1816;

/// `HF_MODEL_STORAGE_BYTES`: the upload slot, first the blob's bytes, then the model decoded
/// from them in place (the larger of the two, 8-byte aligned; asserted in `lib.rs`).
pub const MODEL_STORAGE_BYTES: usize = 9824;
/// `HF_BLOB_MAX_BYTES`: the largest weight blob (a current-version one).
pub const BLOB_MAX_BYTES: usize = hamflight::blob::MAX_LEN;

/// `HF_FAULT_BAD_STATE`.
pub const FAULT_BAD_STATE: u32 = 1 << 0;
/// `HF_FAULT_BAD_SETPOINT`.
pub const FAULT_BAD_SETPOINT: u32 = 1 << 1;
/// `HF_FAULT_BAD_DT`.
pub const FAULT_BAD_DT: u32 = 1 << 2;
/// `HF_FAULT_NUMERIC`.
pub const FAULT_NUMERIC: u32 = 1 << 3;
/// `HF_FAULT_NOT_INIT`.
pub const FAULT_NOT_INIT: u32 = 1 << 4;
/// `HF_FAULT_MASK`: any of these means a zero wrench.
pub const FAULT_MASK: u32 = 0x1F;
/// `HF_COND_SAT_YAW`.
pub const COND_SAT_YAW: u32 = 1 << 8;
/// `HF_COND_SAT_ROLL_PITCH`.
pub const COND_SAT_ROLL_PITCH: u32 = 1 << 9;
/// `HF_COND_SAT_THRUST`.
pub const COND_SAT_THRUST: u32 = 1 << 10;
/// `HF_COND_TILT_LIMITED`.
pub const COND_TILT_LIMITED: u32 = 1 << 11;

/// `HF_OK`.
pub const OK: u32 = 0;
/// `HF_ERR_BAD_GAINS`.
pub const ERR_BAD_GAINS: u32 = 1;
/// `HF_ERR_NULL`.
pub const ERR_NULL: u32 = 2;

/// `HF_ERR_BLOB_TRUNCATED` … `HF_ERR_SELF_TEST`: why a blob was refused (one per
/// [`hamflight::blob::BlobError`], then the self test).
pub const ERR_BLOB_TRUNCATED: u32 = 16;
/// `HF_ERR_BLOB_BAD_MAGIC`.
pub const ERR_BLOB_BAD_MAGIC: u32 = 17;
/// `HF_ERR_BLOB_VERSION`.
pub const ERR_BLOB_VERSION: u32 = 18;
/// `HF_ERR_BLOB_SHAPE`.
pub const ERR_BLOB_SHAPE: u32 = 19;
/// `HF_ERR_BLOB_CRC`.
pub const ERR_BLOB_CRC: u32 = 20;
/// `HF_ERR_BLOB_TRAILING`.
pub const ERR_BLOB_TRAILING: u32 = 21;
/// `HF_ERR_BLOB_MALFORMED`.
pub const ERR_BLOB_MALFORMED: u32 = 22;
/// `HF_ERR_BLOB_NON_FINITE`.
pub const ERR_BLOB_NON_FINITE: u32 = 23;
/// `HF_ERR_BLOB_MASS`.
pub const ERR_BLOB_MASS: u32 = 24;
/// `HF_ERR_BLOB_MOTOR_TAU`.
pub const ERR_BLOB_MOTOR_TAU: u32 = 25;
/// `HF_ERR_SELF_TEST`: the blob decoded but its hover step failed the self test.
pub const ERR_SELF_TEST: u32 = 26;
/// `HF_ERR_BLOB_PORT`: the port terms cannot be flown ([`hamflight::model::PortError`]).
pub const ERR_BLOB_PORT: u32 = 27;

/// The `HF_ERR_BLOB_*` code of a blob error.
pub fn blob_error_code(e: hamflight::blob::BlobError) -> u32 {
    use hamflight::blob::BlobError as E;
    match e {
        E::Truncated => ERR_BLOB_TRUNCATED,
        E::BadMagic => ERR_BLOB_BAD_MAGIC,
        E::UnsupportedVersion(_) => ERR_BLOB_VERSION,
        E::ShapeMismatch => ERR_BLOB_SHAPE,
        E::Checksum => ERR_BLOB_CRC,
        E::TrailingBytes => ERR_BLOB_TRAILING,
        E::Malformed => ERR_BLOB_MALFORMED,
        E::NonFinite => ERR_BLOB_NON_FINITE,
        E::BadMass => ERR_BLOB_MASS,
        E::BadMotorTau => ERR_BLOB_MOTOR_TAU,
        E::BadPort(_) => ERR_BLOB_PORT,
    }
}

/// `hf_model_t`: storage the C side owns for a model received at run time (zeroed: empty).
#[repr(C, align(8))]
pub struct HfModel {
    /// The bytes; their meaning is private to [`crate`].
    pub opaque: [u8; MODEL_STORAGE_BYTES],
}

/// `hf_blob_info_t`: what a checked blob says of itself.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfBlobInfo {
    /// CRC-32 of the body, as stored in the blob.
    pub crc: u32,
    /// The whole blob's length (bytes).
    pub total_len_bytes: u32,
    /// The vehicle mass (kg).
    pub mass_kg: f32,
    /// The blob's format version.
    pub version: u16,
    /// Zero.
    pub reserved: u16,
}

impl HfBlobInfo {
    /// From the core's check.
    pub fn from_core(i: &hamflight::blob::BlobInfo) -> Self {
        Self {
            crc: i.crc,
            total_len_bytes: u32::try_from(i.total_len).unwrap_or(u32::MAX),
            mass_kg: i.mass_kg,
            version: i.version,
            reserved: 0,
        }
    }
}

/// `HF_LAW_GRADIENT`: the paper's gradient adaptation law.
pub const LAW_GRADIENT: u32 = 0;
/// `HF_LAW_COMPOSITE`: the composite (prediction-error, Kalman-gain) adaptation law.
pub const LAW_COMPOSITE: u32 = 1;

/// `hf_controller_t`: opaque storage the C side owns (zeroed or `hf_init`ed).
#[repr(C, align(8))]
pub struct HfController {
    /// The bytes; their meaning is private to [`crate`].
    pub opaque: [u8; CONTROLLER_STORAGE_BYTES],
}

/// `hf_state_t`: the core's [`State`] with R row-major, plus the accelerometer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfState {
    /// Position (m, world).
    pub p_m: [f32; 3],
    /// R (body → world), `rot[i][j]` = R_ij.
    pub rot: [[f32; 3]; 3],
    /// Linear velocity (m/s, body frame).
    pub v_body_m_s: [f32; 3],
    /// Angular velocity (rad/s, body frame).
    pub w_body_rad_s: [f32; 3],
    /// Measured specific force (m/s², body frame), for the composite adaptation law.
    pub specific_force_body_m_s2: [f32; 3],
    /// Nonzero if `specific_force_body_m_s2` holds a measurement.
    pub specific_force_valid: u8,
    /// Zero.
    pub reserved: [u8; 3],
}

impl HfState {
    /// The core's state.
    pub fn to_core(&self) -> State {
        let r = &self.rot;
        let [r0, r1, r2] = r;
        State {
            p_m: Vector3::from(self.p_m),
            rot: Matrix3::new(
                r0[0], r0[1], r0[2], r1[0], r1[1], r1[2], r2[0], r2[1], r2[2],
            ),
            v_body_m_s: Vector3::from(self.v_body_m_s),
            w_body_rad_s: Vector3::from(self.w_body_rad_s),
        }
    }

    /// From the core's state (no accelerometer).
    pub fn from_core(s: &State) -> Self {
        let r = &s.rot;
        Self {
            p_m: s.p_m.into(),
            rot: [
                [r.m11, r.m12, r.m13],
                [r.m21, r.m22, r.m23],
                [r.m31, r.m32, r.m33],
            ],
            v_body_m_s: s.v_body_m_s.into(),
            w_body_rad_s: s.w_body_rad_s.into(),
            ..Self::default()
        }
    }
}

/// `hf_setpoint_t`: the core's [`Setpoint`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfSetpoint {
    /// p* (m, world).
    pub p_m: [f32; 3],
    /// ṗ* (m/s, world).
    pub v_m_s: [f32; 3],
    /// p̈* (m/s², world).
    pub a_m_s2: [f32; 3],
    /// p⃛* (m/s³, world).
    pub j_m_s3: [f32; 3],
    /// ψ* (rad).
    pub yaw_rad: f32,
    /// ψ̇* (rad/s).
    pub yaw_rate_rad_s: f32,
}

impl HfSetpoint {
    /// The core's setpoint.
    pub fn to_core(&self) -> Setpoint {
        Setpoint {
            p_m: Vector3::from(self.p_m),
            v_m_s: Vector3::from(self.v_m_s),
            a_m_s2: Vector3::from(self.a_m_s2),
            j_m_s3: Vector3::from(self.j_m_s3),
            yaw_rad: self.yaw_rad,
            yaw_rate_rad_s: self.yaw_rate_rad_s,
        }
    }

    /// From the core's setpoint.
    pub fn from_core(s: &Setpoint) -> Self {
        Self {
            p_m: s.p_m.into(),
            v_m_s: s.v_m_s.into(),
            a_m_s2: s.a_m_s2.into(),
            j_m_s3: s.j_m_s3.into(),
            yaw_rad: s.yaw_rad,
            yaw_rate_rad_s: s.yaw_rate_rad_s,
        }
    }
}

/// `hf_output_t`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfOutput {
    /// Collective thrust (N).
    pub thrust_n: f32,
    /// Body torques (N·m).
    pub torque_nm: [f32; 3],
    /// `HF_FAULT_*` | `HF_COND_*`.
    pub faults: u32,
}

/// `hf_gains_t`: the core's [`Gains`] without the adaptation switch.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfGains {
    /// k_p (N/m).
    pub k_p: f32,
    /// k_v (N·s/m).
    pub k_v: f32,
    /// k_R (N·m/rad).
    pub k_r: f32,
    /// k_ω (N·m·s/rad).
    pub k_w: f32,
    /// Tilt limit (rad).
    pub max_tilt_rad: f32,
    /// c_p.
    pub c_p: f32,
    /// c_v.
    pub c_v: f32,
    /// c_R.
    pub c_r: f32,
    /// c_ω.
    pub c_w: f32,
    /// a_max.
    pub a_max: f32,
}

impl HfGains {
    /// From the core's gains.
    pub fn from_core(g: &Gains) -> Self {
        Self {
            k_p: g.k_p,
            k_v: g.k_v,
            k_r: g.k_r,
            k_w: g.k_w,
            max_tilt_rad: g.max_tilt_rad,
            c_p: g.rates.c_p,
            c_v: g.rates.c_v,
            c_r: g.rates.c_r,
            c_w: g.rates.c_w,
            a_max: g.rates.a_max,
        }
    }

    /// The core's gains with the adaptation switch `adapt`, or `None` if any value is NaN,
    /// infinite or negative, or the tilt limit is not in (0, π/2).
    pub fn to_core(&self, adapt: bool) -> Option<Gains> {
        let all = [
            self.k_p, self.k_v, self.k_r, self.k_w, self.c_p, self.c_v, self.c_r, self.c_w,
            self.a_max,
        ];
        let tilt_ok = self.max_tilt_rad > 0.0 && self.max_tilt_rad < core::f32::consts::FRAC_PI_2;
        if !(tilt_ok && all.iter().all(|v| v.is_finite() && *v >= 0.0)) {
            return None;
        }
        // The robust options are not in the C API: they keep the core's defaults. The law and
        // the composite law's tuning have their own calls (`hf_set_gains` keeps them).
        let defaults = Gains::default();
        Some(Gains {
            k_p: self.k_p,
            k_v: self.k_v,
            k_r: self.k_r,
            k_w: self.k_w,
            max_tilt_rad: self.max_tilt_rad,
            rates: AdaptationRates {
                c_p: self.c_p,
                c_v: self.c_v,
                c_r: self.c_r,
                c_w: self.c_w,
                a_max: self.a_max,
                ..defaults.rates
            },
            adapt,
            ..defaults
        })
    }
}

/// `hf_composite_t`: the composite law's Kalman tuning (the rest of
/// [`hamflight::adapt::CompositeGains`] keeps its values).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HfComposite {
    /// Process noise Q of the force columns of a ((m/s²)² per second).
    pub q_force: f32,
    /// Process noise Q of the torque columns of a ((1e-3 N·m)² per second).
    pub q_torque: f32,
    /// Measurement variance R of the force rows, per sample ((m/s²)²).
    pub r_force: f32,
    /// Measurement variance R of the torque rows, per sample ((1e-3 N·m)²).
    pub r_torque: f32,
}

impl HfComposite {
    /// From the core's composite gains.
    pub fn from_core(g: &CompositeGains) -> Self {
        Self {
            q_force: g.q_force,
            q_torque: g.q_torque,
            r_force: g.r_force,
            r_torque: g.r_torque,
        }
    }

    /// `base` with this Q and R, or `None` unless Q ≥ 0 and R > 0, all finite.
    pub fn to_core(&self, base: &CompositeGains) -> Option<CompositeGains> {
        let q_ok = [self.q_force, self.q_torque]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0);
        let r_ok = [self.r_force, self.r_torque]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0);
        (q_ok && r_ok).then_some(CompositeGains {
            q_force: self.q_force,
            q_torque: self.q_torque,
            r_force: self.r_force,
            r_torque: self.r_torque,
            ..*base
        })
    }
}

/// The core's law for `HF_LAW_*`, `None` for any other value.
pub fn law_from_c(law: u32) -> Option<AdaptationLaw> {
    match law {
        LAW_GRADIENT => Some(AdaptationLaw::Gradient),
        LAW_COMPOSITE => Some(AdaptationLaw::Composite),
        _ => None,
    }
}

/// `HF_LAW_*` of the core's law.
pub fn law_to_c(law: AdaptationLaw) -> u32 {
    match law {
        AdaptationLaw::Gradient => LAW_GRADIENT,
        AdaptationLaw::Composite => LAW_COMPOSITE,
    }
}

/// The `HF_FAULT_*` and `HF_COND_*` bits of the core's faults.
pub fn fault_bits(f: &Faults) -> u32 {
    [
        (f.bad_state, FAULT_BAD_STATE),
        (f.bad_setpoint, FAULT_BAD_SETPOINT),
        (f.bad_dt, FAULT_BAD_DT),
        (f.numeric, FAULT_NUMERIC),
        (f.saturation.yaw, COND_SAT_YAW),
        (f.saturation.roll_pitch, COND_SAT_ROLL_PITCH),
        (f.saturation.thrust, COND_SAT_THRUST),
        (f.tilt_limited, COND_TILT_LIMITED),
    ]
    .iter()
    .filter(|(on, _)| *on)
    .fold(0, |acc, (_, bit)| acc | bit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    extern "C" {
        /// `host-include/layout_check.c`: sizes, offsets and constants as C sees them.
        static hf_c_layout: [u32; LAYOUT_LEN];
    }

    const LAYOUT_LEN: usize = 76;

    /// The same list, in the same order, as Rust sees it.
    fn rust_layout() -> [u32; LAYOUT_LEN] {
        let v: [usize; LAYOUT_LEN] = [
            size_of::<HfController>(),
            align_of::<HfController>(),
            size_of::<HfState>(),
            offset_of!(HfState, p_m),
            offset_of!(HfState, rot),
            offset_of!(HfState, v_body_m_s),
            offset_of!(HfState, w_body_rad_s),
            offset_of!(HfState, specific_force_body_m_s2),
            offset_of!(HfState, specific_force_valid),
            offset_of!(HfState, reserved),
            size_of::<HfSetpoint>(),
            offset_of!(HfSetpoint, p_m),
            offset_of!(HfSetpoint, v_m_s),
            offset_of!(HfSetpoint, a_m_s2),
            offset_of!(HfSetpoint, j_m_s3),
            offset_of!(HfSetpoint, yaw_rad),
            offset_of!(HfSetpoint, yaw_rate_rad_s),
            size_of::<HfOutput>(),
            offset_of!(HfOutput, thrust_n),
            offset_of!(HfOutput, torque_nm),
            offset_of!(HfOutput, faults),
            size_of::<HfGains>(),
            offset_of!(HfGains, k_p),
            offset_of!(HfGains, k_v),
            offset_of!(HfGains, k_r),
            offset_of!(HfGains, k_w),
            offset_of!(HfGains, max_tilt_rad),
            offset_of!(HfGains, c_p),
            offset_of!(HfGains, c_v),
            offset_of!(HfGains, c_r),
            offset_of!(HfGains, c_w),
            offset_of!(HfGains, a_max),
            FEATURES,
            CONTROLLER_STORAGE_BYTES,
            FAULT_BAD_STATE as usize,
            FAULT_BAD_SETPOINT as usize,
            FAULT_BAD_DT as usize,
            FAULT_NUMERIC as usize,
            FAULT_NOT_INIT as usize,
            FAULT_MASK as usize,
            COND_SAT_YAW as usize,
            COND_SAT_ROLL_PITCH as usize,
            COND_SAT_THRUST as usize,
            COND_TILT_LIMITED as usize,
            OK as usize,
            ERR_BAD_GAINS as usize,
            ERR_NULL as usize,
            size_of::<bool>(),
            size_of::<f32>(),
            align_of::<HfState>(),
            align_of::<HfSetpoint>(),
            align_of::<HfOutput>(),
            align_of::<HfGains>(),
            size_of::<HfComposite>(),
            offset_of!(HfComposite, q_force),
            offset_of!(HfComposite, q_torque),
            offset_of!(HfComposite, r_force),
            offset_of!(HfComposite, r_torque),
            LAW_GRADIENT as usize,
            LAW_COMPOSITE as usize,
            size_of::<HfModel>(),
            align_of::<HfModel>(),
            MODEL_STORAGE_BYTES,
            BLOB_MAX_BYTES,
            size_of::<HfBlobInfo>(),
            offset_of!(HfBlobInfo, crc),
            offset_of!(HfBlobInfo, total_len_bytes),
            offset_of!(HfBlobInfo, mass_kg),
            offset_of!(HfBlobInfo, version),
            offset_of!(HfBlobInfo, reserved),
            ERR_BLOB_TRUNCATED as usize,
            ERR_BLOB_CRC as usize,
            ERR_BLOB_MOTOR_TAU as usize,
            ERR_SELF_TEST as usize,
            ERR_BLOB_PORT as usize,
            0xC0DE,
        ];
        v.map(|x| x as u32)
    }

    #[test]
    fn header_layout_matches_rust() {
        // SAFETY: a constant array defined in C with exactly LAYOUT_LEN elements (its last one,
        // 0xC0DE, checks that the lengths agree).
        let c = unsafe { hf_c_layout };
        let r = rust_layout();
        for (i, (a, b)) in c.iter().zip(r.iter()).enumerate() {
            assert_eq!(
                a, b,
                "layout entry {i} (see layout_check.c): C {a}, Rust {b}"
            );
        }
    }

    #[test]
    fn fault_mask_covers_exactly_the_faults() {
        let faults = FAULT_BAD_STATE | FAULT_BAD_SETPOINT | FAULT_BAD_DT | FAULT_NUMERIC;
        assert_eq!(faults | FAULT_NOT_INIT, FAULT_MASK);
        let conds = COND_SAT_YAW | COND_SAT_ROLL_PITCH | COND_SAT_THRUST | COND_TILT_LIMITED;
        assert_eq!(conds & FAULT_MASK, 0);
    }

    #[test]
    fn state_round_trips_through_the_c_layout() {
        let s = State {
            p_m: Vector3::new(1.0, 2.0, 3.0),
            rot: Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            v_body_m_s: Vector3::new(0.1, 0.2, 0.3),
            w_body_rad_s: Vector3::new(-1.0, -2.0, -3.0),
        };
        let c = HfState::from_core(&s);
        // Row-major: rot[0][1] is R_12 = −1 (R maps body x to world y).
        assert_eq!(c.rot[0][1], -1.0);
        assert_eq!(c.rot[1][0], 1.0);
        assert_eq!(c.to_core(), s);
    }

    #[test]
    fn gains_are_validated() {
        let g = HfGains::from_core(&Gains::default());
        assert_eq!(g.to_core(true), Some(Gains::default()));
        for bad in [
            HfGains { k_p: -1.0, ..g },
            HfGains { c_w: f32::NAN, ..g },
            HfGains {
                a_max: f32::INFINITY,
                ..g
            },
            HfGains {
                max_tilt_rad: 0.0,
                ..g
            },
            HfGains {
                max_tilt_rad: 1.6,
                ..g
            },
        ] {
            assert_eq!(bad.to_core(true), None, "{bad:?}");
        }
    }
}
