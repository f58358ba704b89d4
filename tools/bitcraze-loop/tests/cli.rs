//! The study binary as a user meets it. Without a crazyflie-firmware checkout at build time (the
//! README's workspace build, CI) it must say how to get one and exit 2, never pretend to fly; with
//! one (`CRAZYFLIE_BASE` set when building) a short flight through Bitcraze's code must run and
//! print its table.

use std::process::Command;

fn study() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_bitcraze-loop"));
    // Scenario paths are relative to the repository root.
    c.current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    c
}

#[test]
fn help_explains_the_study_and_its_build() {
    let out = study().arg("--help").output().expect("runs");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "CRAZYFLIE_BASE",
        "--scenarios",
        "--controllers",
        "bc-lee",
        "--state",
    ] {
        assert!(text.contains(needle), "--help lacks {needle}:\n{text}");
    }
}

#[cfg(not(bitcraze))]
#[test]
fn without_a_checkout_it_says_how_to_get_one() {
    let out = study().output().expect("runs");
    assert_eq!(out.status.code(), Some(2), "exit code");
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(
        text.contains("make cf2_defconfig") && text.contains("CRAZYFLIE_BASE="),
        "{text}"
    );
}

#[cfg(bitcraze)]
#[test]
fn with_a_checkout_it_flies_ours_and_bitcraze_s() {
    let out = study()
        .args([
            "--scenarios",
            "scenarios/cf-hover-lag50.toml",
            "--controllers",
            "adaptive,bc-lee",
        ])
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("| cf-hover-lag50 |") && !text.contains("crash"),
        "{text}"
    );
}
