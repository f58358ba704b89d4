//! Compiles Bitcraze's flight code from a crazyflie-firmware checkout named by `$CRAZYFLIE_BASE`
//! (configured with `make cf2_defconfig && make prepare`), with our C shim, and turns on
//! `cfg(bitcraze)`. Without `$CRAZYFLIE_BASE` nothing is compiled and the binary explains how to
//! get it: the README's workspace build never needs a checkout.

use std::path::{Path, PathBuf};

/// Bitcraze's sources the study runs: the same set their own Python bindings compile, less the
/// trajectory planner and the range sensors' measurement models.
const SOURCES: &[&str] = &[
    "src/modules/src/controller/controller_pid.c",
    "src/modules/src/controller/position_controller_pid.c",
    "src/modules/src/controller/attitude_pid_controller.c",
    "src/modules/src/controller/controller_mellinger.c",
    "src/modules/src/controller/controller_brescianini.c",
    "src/modules/src/controller/controller_lee.c",
    "src/utils/src/pid.c",
    "src/utils/src/filter.c",
    "src/utils/src/num.c",
    "src/modules/src/power_distribution_quadrotor.c",
    "src/modules/src/axis3fSubSampler.c",
    "src/modules/src/kalman_core/kalman_core.c",
    "src/modules/src/kalman_core/mm_pose.c",
    "src/modules/src/kalman_core/mm_position.c",
];

const INCLUDES: &[&str] = &[
    "src/modules/interface",
    "src/modules/interface/controller",
    "src/modules/interface/kalman_core",
    "src/modules/interface/outlierfilter",
    "src/hal/interface",
    "src/utils/interface/lighthouse",
    "src/utils/interface",
    "build/include/generated",
    "src/config",
    "src/drivers/interface",
    "src/platform/interface",
];

fn fail(msg: String) -> ! {
    panic!("\n\nbitcraze-loop: {msg}\n\n");
}

fn main() {
    println!("cargo:rerun-if-env-changed=CRAZYFLIE_BASE");
    println!("cargo:rerun-if-changed=shim/bc_shim.c");
    println!("cargo:rerun-if-changed=shim/arm_math.h");
    println!("cargo:rustc-check-cfg=cfg(bitcraze)");
    let Some(base) = std::env::var_os("CRAZYFLIE_BASE") else {
        return;
    };
    let base = PathBuf::from(base);
    if !base
        .join("src/modules/src/kalman_core/kalman_core.c")
        .is_file()
    {
        fail(format!(
            "CRAZYFLIE_BASE={} is not a crazyflie-firmware checkout (no src/modules/src/kalman_core/kalman_core.c)",
            base.display()
        ));
    }
    if !base.join("build/include/generated/autoconf.h").is_file() {
        fail(format!(
            "{} is not configured: run `make cf2_defconfig && make prepare` in it first",
            base.display()
        ));
    }
    let mut b = cc::Build::new();
    b.include("shim");
    for inc in INCLUDES {
        b.include(base.join(inc));
    }
    for src in SOURCES {
        let p = base.join(src);
        if !p.is_file() {
            fail(format!("{} is missing from the checkout", p.display()));
        }
        println!("cargo:rerun-if-changed={}", p.display());
        b.file(p);
    }
    b.file("shim/bc_shim.c")
        .define("UNIT_TEST_MODE", None)
        .flag_if_supported("-fno-strict-aliasing")
        .flag_if_supported("-Wno-address-of-packed-member")
        .flag_if_supported("-Wno-pointer-to-int-cast")
        .warnings(false)
        .opt_level(2)
        .compile("bitcraze");
    println!("cargo:rustc-link-lib=m");
    println!("cargo:rustc-env=BITCRAZE_COMMIT={}", commit(&base));
    println!("cargo:rustc-cfg=bitcraze");
}

/// The checkout's commit (`git rev-parse HEAD`), or "unknown": the study's table names it.
fn commit(base: &Path) -> String {
    std::process::Command::new("git")
        .arg("-C")
        .arg(base)
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}
