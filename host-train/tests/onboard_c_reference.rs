//! Our port of Bitcraze's Mellinger controller and legacy power distribution
//! (`host_train::control::Mellinger`) against the C itself: the fixture
//! `tests/data/mellinger_c_reference.csv` holds synthetic inputs (an analytic climbing spiral
//! with errors, a saturating roll excursion, a free-fall reference; no benchmark data) and the
//! motor commands Bitcraze's `controller_mellinger.c` + `power_distribution_quadrotor.c`
//! (firmware 2025.09, compiled by tools/bitcraze-loop) produced, one 500 Hz step per row.
//! Regenerate: `CRAZYFLIE_BASE=… ./target/release/bitcraze-loop --mellinger-reference FILE`.
//!
//! Tolerance: 2 PWM counts (3.1e-5 of full scale) per motor. The C computes in f32, the port in
//! f64; the int16/int32 truncations can then land one count apart, twice in a row at most
//! (the roll/pitch halving, then the motor sum).

use host_train::control::{Mellinger, OnboardConfig, OnboardLaw};
use host_train::io::{OnboardSetpoint, OnboardState};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

const FIXTURE: &str = include_str!("data/mellinger_c_reference.csv");
const TOLERANCE_COUNTS: f64 = 2.0;

#[test]
fn port_matches_bitcraze_c_mellinger() {
    let mut cfg = OnboardConfig::cf21bl_2025_09();
    cfg.mass_kg = f64::from(0.0393f32); // the mass the C was given, as f32
    cfg.idle_cmd = 0.0; // the C build (cf2_defconfig) does not arm: idle thrust 0
    let mut port = Mellinger::new(cfg);
    let mut lines = FIXTURE.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    assert_eq!(header.len(), 28);
    assert_eq!(header[24], "c_pwm1");
    let (mut rows, mut worst, mut exact, mut capped, mut off) = (0, 0.0f64, 0, 0, 0);
    for (i, line) in lines.enumerate() {
        let v: Vec<f64> = line
            .split(',')
            .map(|c| {
                c.parse::<f32>()
                    .map(f64::from)
                    .unwrap_or_else(|_| panic!("line {}: {c}", i + 2))
            })
            .collect();
        assert_eq!(v.len(), 28, "line {}", i + 2);
        let state = OnboardState {
            p_m: Vector3::new(v[1], v[2], v[3]),
            v_m_s: Vector3::new(v[4], v[5], v[6]),
            q: UnitQuaternion::new_unchecked(Quaternion::new(v[7], v[8], v[9], v[10])),
            w_body_rad_s: Vector3::new(v[11], v[12], v[13]),
        };
        let sp = OnboardSetpoint {
            p_m: Vector3::new(v[14], v[15], v[16]),
            v_m_s: Vector3::new(v[17], v[18], v[19]),
            a_m_s2: Vector3::new(v[20], v[21], v[22]),
            yaw_rad: v[23],
        };
        let ours = port.step(&state, &sp, 0.002).0.map(|m| m * 65535.0);
        let c = [v[24], v[25], v[26], v[27]];
        let err = (0..4).map(|k| (ours[k] - c[k]).abs()).fold(0.0, f64::max);
        assert!(
            err <= TOLERANCE_COUNTS,
            "line {}: port {ours:?} vs C {c:?} ({err} counts)",
            i + 2
        );
        worst = worst.max(err);
        exact += usize::from(err == 0.0);
        capped += usize::from(c.contains(&65535.0));
        off += usize::from(c == [0.0; 4]);
        rows += 1;
    }
    assert_eq!(rows, 600);
    // The fixture exercises the cap and the in-step reset, not only the linear range.
    assert!(capped > 20, "{capped} capped rows");
    assert!(off >= 25, "{off} rows with zero thrust");
    assert!(
        exact * 10 > rows * 9,
        "only {exact} of {rows} rows exact (worst {worst})"
    );
}
