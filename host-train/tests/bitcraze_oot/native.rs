//! The C path against the native controller: the shim as a host [`Controller`], and
//! paper-spiral flown both ways.

use super::*;

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

/// paper-spiral flown natively at 500 Hz with `gains` and through the shim at 1 kHz with
/// `hamflight.law` = `law`, the accelerometer given to both: asserts that the paths agree and
/// returns the largest position difference (m).
pub(crate) fn c_path_matches_native(law: u8, gains: Gains) -> f64 {
    c_path_matches_native_with(law, gains, &MODEL, None)
}

/// [`c_path_matches_native`] with `model` natively and, through the shim, `blob` uploaded over
/// the memory protocol before the flight (None: the compiled-in blob, which `model` then is).
pub(crate) fn c_path_matches_native_with(
    law: u8,
    gains: Gains,
    model: &LearnedModel,
    blob: Option<&[u8]>,
) -> f64 {
    let native_sc = scenario("paper-spiral");
    let mut native = CoreController::new("native", model, gains);
    let native_log = fly_scenario(&native_sc, &mut native);

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
    let c_log = fly_scenario(&c_sc, &mut c);

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
    // velocity, the accelerometer in G), far below the 10 µm bar. A path that hands Bitcraze's
    // power distribution the law's wrench instead of the command (`Output::command`, with the
    // motor-lag lead) drifts by millimetres: fail well before that.
    assert!(
        max_diff_m < 1e-5,
        "C path drifts {max_diff_m} m from native"
    );
    let rmse = Report::from_log(&c_log, None).rmse_pos_window_m.unwrap();
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
