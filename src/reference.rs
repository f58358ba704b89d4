//! Reference generation: the setpoint a trajectory gives the controller at one instant.

use nalgebra::Vector3;

/// A flat-output setpoint: desired position and its derivatives up to jerk (world frame), and the
/// desired yaw. What a trajectory generator or a companion computer sends each tick.
///
/// With the `serde` feature this one type is also the setpoint of the firmware's link (postcard:
/// 14 f32, 56 bytes, no names) and of the bridge's JSON lines, under the bridge's documented names
/// `p`, `v`, `a`, `j`, `yaw`, `yaw_rate` (all but `p` default to zero; unknown names are errors).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct Setpoint {
    /// Desired position p* (m, world).
    #[cfg_attr(feature = "serde", serde(rename = "p"))]
    pub p_m: Vector3<f32>,
    /// Desired velocity ṗ* (m/s, world).
    #[cfg_attr(feature = "serde", serde(rename = "v", default))]
    pub v_m_s: Vector3<f32>,
    /// Desired acceleration p̈* (m/s², world).
    #[cfg_attr(feature = "serde", serde(rename = "a", default))]
    pub a_m_s2: Vector3<f32>,
    /// Desired jerk p⃛* (m/s³, world).
    #[cfg_attr(feature = "serde", serde(rename = "j", default))]
    pub j_m_s3: Vector3<f32>,
    /// Desired yaw ψ* (rad), about world z.
    #[cfg_attr(feature = "serde", serde(rename = "yaw", default))]
    pub yaw_rad: f32,
    /// Desired yaw rate ψ̇* (rad/s).
    #[cfg_attr(feature = "serde", serde(rename = "yaw_rate", default))]
    pub yaw_rate_rad_s: f32,
}

impl Default for Setpoint {
    fn default() -> Self {
        Self::hover(Vector3::zeros(), 0.0)
    }
}

impl Setpoint {
    /// Hold position `p_m` with yaw `yaw_rad`.
    pub fn hover(p_m: Vector3<f32>, yaw_rad: f32) -> Self {
        Self {
            p_m,
            v_m_s: Vector3::zeros(),
            a_m_s2: Vector3::zeros(),
            j_m_s3: Vector3::zeros(),
            yaw_rad,
            yaw_rate_rad_s: 0.0,
        }
    }

    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        crate::fpu::all_finite(
            [self.p_m, self.v_m_s, self.a_m_s2, self.j_m_s3]
                .iter()
                .flat_map(|v| v.iter().copied())
                .chain([self.yaw_rad, self.yaw_rate_rad_s]),
        )
    }
}

/// The desired attitude R* and body rate ω* of the reference frame (Lee et al. 2010, as the
/// paper's Sec. 4 constructs them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttitudeReference {
    /// R* = [b₁*, b₂*, b₃*] (body → world).
    pub rot: nalgebra::Matrix3<f32>,
    /// ω* = (R*ᵀ Ṙ*)^∨, the reference frame's body rate (rad/s).
    pub w_rad_s: Vector3<f32>,
    /// The tilt limit (or a non-upward force) changed b₃*.
    pub tilt_limited: bool,
}

/// A tilt limit with its cosine and sine precomputed (they cost two libm calls each step
/// otherwise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TiltLimit {
    /// Largest angle between b₃* and world z (rad).
    pub max_rad: f32,
    cos: f32,
    sin: f32,
}

impl TiltLimit {
    /// A limit of `max_rad` (rad).
    pub fn new(max_rad: f32) -> Self {
        Self {
            max_rad,
            cos: sin_cos(max_rad).1,
            sin: sin_cos(max_rad).0,
        }
    }
}

/// R* and ω* from the desired world force `f_w` (N) with its rate `f_dot_w` (N/s) and the yaw.
///
/// b₃* = F/‖F‖ (tilted at most `tilt.max_rad` from world z; a force with no upward component
/// gives b₃* = e₃), b₁c = [cos ψ*, sin ψ*, 0], b₂* = b₃* × b₁c / ‖·‖, b₁* = b₂* × b₃*. The rates
/// differentiate these products exactly given Ḟ; while the tilt limit is active b₃* stays on the
/// cone and ḃ₃* is the turn of F's horizontal direction alone.
pub fn desired_attitude(
    f_w: &Vector3<f32>,
    f_dot_w: &Vector3<f32>,
    yaw_rad: f32,
    yaw_rate_rad_s: f32,
    tilt: &TiltLimit,
) -> AttitudeReference {
    let e3 = Vector3::z();
    let n = crate::fpu::sqrt(f_w.norm_squared());
    let cos_max = tilt.cos;
    let (b3, b3_dot, tilt_limited) = if !n.is_finite() || n <= 1e-6 || f_w.z <= 0.0 {
        (e3, Vector3::zeros(), true)
    } else {
        let b3 = f_w / n;
        if b3.z >= cos_max {
            let b3_dot = (f_dot_w - b3 * b3.dot(f_dot_w)) / n;
            (b3, b3_dot, false)
        } else {
            let horiz = Vector3::new(b3.x, b3.y, 0.0);
            let hn = crate::fpu::sqrt(horiz.norm_squared());
            if hn > 1e-9 {
                // On the cone b₃* = e₃ cos θ + d sin θ turns with the horizontal direction d of
                // F alone: ḋ = (Ḟ_h − d (d·Ḟ_h)) / ‖F_h‖.
                let dir = horiz / hn;
                let fh_dot = Vector3::new(f_dot_w.x, f_dot_w.y, 0.0);
                let d_dot = (fh_dot - dir * dir.dot(&fh_dot)) / (hn * n);
                (e3 * cos_max + dir * tilt.sin, d_dot * tilt.sin, true)
            } else {
                (
                    e3 * cos_max + Vector3::x() * tilt.sin,
                    Vector3::zeros(),
                    true,
                )
            }
        }
    };
    let (s, c) = sin_cos(yaw_rad);
    let b1c = Vector3::new(c, s, 0.0);
    let b1c_dot = Vector3::new(-s, c, 0.0) * yaw_rate_rad_s;
    let cvec = b3.cross(&b1c);
    let cn = crate::fpu::sqrt(cvec.norm_squared());
    // |b₃ × b₁c| ≥ cos(max tilt) > 0 because b₁c is horizontal.
    let cn = if cn > 1e-6 { cn } else { 1e-6 };
    let b2 = cvec / cn;
    let c_dot = b3_dot.cross(&b1c) + b3.cross(&b1c_dot);
    let b2_dot = (c_dot - b2 * b2.dot(&c_dot)) / cn;
    let b1 = b2.cross(&b3);
    let b1_dot = b2_dot.cross(&b3) + b2.cross(&b3_dot);
    let rot = nalgebra::Matrix3::from_columns(&[b1, b2, b3]);
    let rot_dot = nalgebra::Matrix3::from_columns(&[b1_dot, b2_dot, b3_dot]);
    let w_rad_s = crate::lie::vee(&(rot.transpose() * rot_dot));
    AttitudeReference {
        rot,
        w_rad_s,
        tilt_limited,
    }
}

/// (sin x, cos x) in f32 arithmetic alone: x is reduced by multiples of π/2 (Cody–Waite, π/2 in
/// three parts whose products with the quadrant count are exact for |x| < 6,000 rad), then the
/// Taylor series to r⁹ and r¹⁰ on |r| ≤ π/4 (truncation error below 2·10⁻⁹). Absolute error
/// ≈ 1e-7 for |x| ≤ 6,000 rad (tested against f64); larger x is first wrapped by whole turns
/// of the f32 2π (to 0 past 2²⁴ rad, where an f32 angle has no phase left); a NaN or infinite x
/// gives NaN.
///
/// It replaces `libm`'s `sinf`/`cosf`, whose Payne–Hanek reduction and double-precision kernels
/// are software f64 on the single-precision M4F: slow, and large in flash (docs/performance.md,
/// "Where the step goes").
pub fn sin_cos(x: f32) -> (f32, f32) {
    const TWO_OVER_PI: f32 = core::f32::consts::FRAC_2_PI;
    const PIO2_HI: f32 = 1.570_312_5;
    const PIO2_MID: f32 = 4.837_513e-4;
    const PIO2_LO: f32 = 7.549_79e-8;
    // Beyond the exact-reduction range, wrap by whole turns first. No `%`: `fmodf` pulls in
    // libm's 64-bit integer division, 160 B of stack on the stabilizer task's worst path. The
    // wrap's error is of the order of one f32 step of x (≤ 1 rad), which no f32 angle that large
    // resolves anyway; past 2²⁴ rad one step is 2 rad, there is no phase left, and x wraps to 0.
    let x = if x.abs() > 6000.0 {
        if x.abs() < 16_777_216.0 {
            // |x / 2π| < 2^22: the truncation fits an i32 exactly.
            let turns = (x * (1.0 / core::f32::consts::TAU)) as i32 as f32;
            x - turns * core::f32::consts::TAU
        } else if x.is_finite() {
            0.0
        } else {
            x
        }
    } else {
        x
    };
    let q = x * TWO_OVER_PI;
    // Round to nearest; `as` saturates, so a huge or NaN x cannot overflow.
    let k = if q >= 0.0 { q + 0.5 } else { q - 0.5 } as i32;
    let kf = k as f32;
    let r = ((x - kf * PIO2_HI) - kf * PIO2_MID) - kf * PIO2_LO;
    let r2 = r * r;
    let sin_r =
        r + r * r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 / 362_880.0)));
    let cos_r = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 - r2 / 3_628_800.0))));
    let (s, c) = match k & 3 {
        0 => (sin_r, cos_r),
        1 => (cos_r, -sin_r),
        2 => (-sin_r, -cos_r),
        _ => (-cos_r, sin_r),
    };
    if x.is_finite() {
        (s, c)
    } else {
        (f32::NAN, f32::NAN)
    }
}
