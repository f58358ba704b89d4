//! Looks for `qemu-system-arm` on `PATH` at build time, so that a machine without QEMU sees the
//! processor-in-the-loop test (`tests/pil_qemu.rs`) as *ignored, with the reason* in the test
//! summary instead of a pass that did nothing.
//!
//! - Found: nothing changes; the test runs (and fails with the install command if QEMU has gone
//!   since).
//! - Missing and `CI` is not `true`: `cfg(hamflight_no_qemu)`, and the test is `#[ignore]`d with
//!   the install command as its reason.
//! - Missing under `CI=true`: no cfg; the test runs and fails with the install command.
//!
//! Installing QEMU later changes a `PATH` directory, which reruns this script.

use std::env;
use std::path::PathBuf;

const QEMU: &str = "qemu-system-arm";

fn main() {
    println!("cargo::rustc-check-cfg=cfg(hamflight_no_qemu)");
    println!("cargo::rerun-if-env-changed=PATH");
    println!("cargo::rerun-if-env-changed=CI");
    println!("cargo::rerun-if-changed=build.rs");

    let dirs: Vec<PathBuf> = env::var_os("PATH")
        .map(|p| env::split_paths(&p).collect())
        .unwrap_or_default();
    match dirs.iter().map(|d| d.join(QEMU)).find(|p| is_executable(p)) {
        Some(found) => println!("cargo::rerun-if-changed={}", found.display()),
        None => {
            // Adding a file to a directory changes the directory's mtime.
            for d in dirs.iter().filter(|d| d.is_dir()) {
                println!("cargo::rerun-if-changed={}", d.display());
            }
            let ci = env::var("CI").is_ok_and(|v| v == "true");
            if !ci {
                println!("cargo::rustc-cfg=hamflight_no_qemu");
            }
        }
    }
}

#[cfg(unix)]
fn is_executable(p: &std::path::Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    p.metadata()
        .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(not(unix))]
fn is_executable(p: &std::path::Path) -> bool {
    p.is_file() || p.with_extension("exe").is_file()
}
