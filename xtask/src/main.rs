//! `cargo xtask JOB`: the jobs behind the aliases in `.cargo/config.toml` that are more than one
//! cargo command. std only, so it builds in a second.
//!
//! - `fw-build`: builds every firmware binary with every feature set the READMEs mention
//!   ([`FIRMWARE_FEATURE_SETS`]; `--bins` skips a binary whose required features are off).
//! - `fw-report`: `firmware/report.sh` (cost and size table under QEMU), arguments passed on.
//! - `test-all`: every test there is: the README's `cargo test --workspace --release` (arguments
//!   passed on), then the firmware's host unit tests (`firmware/`, its own workspace, which the
//!   root workspace's test command cannot reach).
//!
//! Both first make sure the thumbv7em target is installed (`firmware/tools/ensure-target.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

/// Every firmware feature set the READMEs mention (`.ci/run` builds them through `cargo fw-build`):
/// with the default features (the composite law) or without them (`false`: the paper's gradient
/// law alone), and the features added.
const FIRMWARE_FEATURE_SETS: [(bool, &str); 9] = [
    (true, ""),
    (true, "loop-1khz"),
    (true, "qemu"),
    (true, "qemu,bench"),
    (true, "qemu,loop-1khz"),
    (true, "qemu,bench,loop-1khz"),
    (false, ""),
    (false, "qemu"),
    (false, "qemu,bench"),
];

fn firmware_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware")
}

/// A command run in `firmware/` without the outer cargo's settings (the firmware is its own
/// workspace, with its own target and toolchain file).
fn in_firmware(program: &str) -> Command {
    let mut cmd = Command::new(program);
    cmd.current_dir(firmware_dir());
    for var in [
        "RUSTUP_TOOLCHAIN",
        "CARGO_BUILD_TARGET",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "CARGO_MAKEFLAGS",
    ] {
        cmd.env_remove(var);
    }
    cmd
}

fn run(mut cmd: Command) -> Result<(), String> {
    let shown = format!("{cmd:?}");
    match cmd.status() {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("{shown} failed ({s})")),
        Err(e) => Err(format!("cannot run {shown}: {e}")),
    }
}

fn fw_build() -> Result<(), String> {
    run(in_firmware("tools/ensure-target.sh"))?;
    for (default_features, features) in FIRMWARE_FEATURE_SETS {
        let no_default = if default_features {
            ""
        } else {
            " --no-default-features"
        };
        eprintln!("firmware: cargo build --release --bins{no_default} --features '{features}'");
        let mut cmd = in_firmware("cargo");
        cmd.args(["build", "--release", "--bins", "--features", features]);
        if !default_features {
            cmd.arg("--no-default-features");
        }
        run(cmd)?;
    }
    Ok(())
}

fn fw_report(args: &[String]) -> Result<(), String> {
    let mut cmd = in_firmware("./report.sh");
    cmd.args(args);
    run(cmd)
}

/// The host's target triple (`rustc -vV`), for the firmware's host-side unit tests.
fn host_triple() -> Result<String, String> {
    let out = Command::new("rustc")
        .arg("-vV")
        .output()
        .map_err(|e| format!("cannot run rustc -vV: {e}"))?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_string))
        .ok_or_else(|| "rustc -vV printed no host triple".to_string())
}

fn test_all(args: &[String]) -> Result<(), String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut cmd = Command::new("cargo");
    cmd.current_dir(&root)
        .args(["test", "--workspace", "--release"])
        .args(args);
    eprintln!(
        "test-all: cargo test --workspace --release {}",
        args.join(" ")
    );
    run(cmd)?;
    let host = host_triple()?;
    eprintln!(
        "test-all: firmware host unit tests (cd firmware && cargo test --lib --target {host})"
    );
    let mut cmd = in_firmware("cargo");
    cmd.args(["test", "--lib", "--target", &host]);
    run(cmd)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.split_first() {
        Some((job, rest)) if job == "fw-build" && rest.is_empty() => fw_build(),
        Some((job, rest)) if job == "fw-report" => fw_report(rest),
        Some((job, rest)) if job == "test-all" => test_all(rest),
        _ => Err(format!(
            "usage: cargo xtask fw-build | fw-report | test-all (got {args:?}); \
             the aliases are in .cargo/config.toml"
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
