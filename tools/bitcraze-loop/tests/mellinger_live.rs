//! With Bitcraze's code compiled in (`CRAZYFLIE_BASE` at build time): the live comparison of
//! their C Mellinger with host-train's port on the synthetic inputs (`--mellinger-reference`)
//! must agree within 2 PWM counts per motor, and the C's commands must equal the committed
//! fixture's (host-train/tests/data/mellinger_c_reference.csv) within the same 2 counts, so the
//! fixture stays what the C computes.
#![cfg(bitcraze)]

use std::process::Command;

#[test]
fn c_mellinger_and_the_port_agree_live() {
    let dir = std::env::temp_dir().join(format!("mel-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ref.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_bitcraze-loop"))
        .arg("--mellinger-reference")
        .arg(&path)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let worst: f64 = text
        .rsplit("= ")
        .next()
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no difference printed: {text}"));
    assert!(worst <= 2.0, "C vs port: {worst} counts");
    let live = std::fs::read_to_string(&path).unwrap();
    let fixture = include_str!("../../../host-train/tests/data/mellinger_c_reference.csv");
    let (a, b): (Vec<&str>, Vec<&str>) = (live.lines().collect(), fixture.lines().collect());
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(&b).enumerate().skip(1) {
        let cx: Vec<f64> = x.split(',').skip(24).map(|c| c.parse().unwrap()).collect();
        let cy: Vec<f64> = y.split(',').skip(24).map(|c| c.parse().unwrap()).collect();
        for k in 0..4 {
            assert!(
                (cx[k] - cy[k]).abs() <= 2.0,
                "line {}: live {cx:?} vs fixture {cy:?}",
                i + 1
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
