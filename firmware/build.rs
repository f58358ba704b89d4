//! Puts the right `memory.x` on the linker path and picks the weight blob to embed.
//!
//! - Memory, per binary (so that every binary links right whatever the features): `crazyflie`
//!   gets the repository's `memory.x` (flash from 0x08004000, after the 16 KiB bootloader),
//!   `qemu` the same map with flash at 0x08000000 (QEMU boots there, no bootloader).
//! - Weights: `HAMFLIGHT_WEIGHTS` (a path, relative to `firmware/` or absolute) or by default
//!   `../weights/default.hfw`. If the default file does not exist yet, a checked blob of
//!   `ModelWeights::default()` is written to OUT_DIR and embedded instead, with a warning, and
//!   `cfg(hamflight_untrained)` makes the firmware fly the nominal model (still checking the blob).
//!   The chosen path reaches the code as `env!("HAMFLIGHT_BLOB_PATH")`.

use std::env;
use std::fs;
use std::path::{Path, PathBuf};

const DEFAULT_WEIGHTS: &str = "../weights/default.hfw";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let target = env::var("TARGET").unwrap_or_default();

    // Memory layout (only meaningful for the embedded target; harmless elsewhere).
    let board_memory = manifest.join("../memory.x");
    println!("cargo:rerun-if-changed={}", board_memory.display());
    let memory = fs::read_to_string(&board_memory)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", board_memory.display()));
    const BOOTLOADER_FLASH: &str = "FLASH : ORIGIN = 0x08004000, LENGTH = 1024K - 16K";
    assert!(
        memory.contains(BOOTLOADER_FLASH),
        "{} no longer has the line `{BOOTLOADER_FLASH}` that the QEMU map replaces",
        board_memory.display()
    );
    // QEMU loads the ELF at its link address and boots from 0x08000000: no bootloader.
    let qemu_memory = memory.replace(
        BOOTLOADER_FLASH,
        "FLASH : ORIGIN = 0x08000000, LENGTH = 1024K",
    );
    if target.starts_with("thumb") {
        // cortex-m-rt's link.x INCLUDEs memory.x from the linker's search path: one directory
        // per binary.
        for (bin, map) in [("crazyflie", &memory), ("qemu", &qemu_memory)] {
            let dir = out.join(format!("memory-{bin}"));
            fs::create_dir_all(&dir).expect("create a memory.x directory in OUT_DIR");
            fs::write(dir.join("memory.x"), map).expect("write memory.x to OUT_DIR");
            println!("cargo:rustc-link-arg-bin={bin}=-L{}", dir.display());
        }
    }

    // Weight blob.
    println!("cargo:rerun-if-env-changed=HAMFLIGHT_WEIGHTS");
    println!("cargo::rustc-check-cfg=cfg(hamflight_untrained)");
    let mut untrained = false;
    let blob_path = match env::var_os("HAMFLIGHT_WEIGHTS") {
        Some(p) => {
            let p = PathBuf::from(p);
            let p = if p.is_absolute() { p } else { manifest.join(p) };
            if !p.is_file() {
                panic!(
                    "HAMFLIGHT_WEIGHTS={} does not name a file (relative paths start at firmware/)",
                    p.display()
                );
            }
            p
        }
        None => {
            let p = manifest.join(DEFAULT_WEIGHTS);
            // Watch the directory too, so that the blob appearing triggers a rebuild.
            println!(
                "cargo:rerun-if-changed={}",
                manifest.join("../weights").display()
            );
            if p.is_file() {
                p
            } else {
                println!(
                    "cargo:warning=no trained weights at {}; embedding ModelWeights::default() \
                     and flying the nominal model",
                    p.display()
                );
                untrained = true;
                write_default_blob(&out)
            }
        }
    };
    println!("cargo:rerun-if-changed={}", blob_path.display());
    if untrained {
        // No trained networks: the all-zero ones have g = 0 and cannot fly.
        println!("cargo:rustc-cfg=hamflight_untrained");
    }
    println!(
        "cargo:rustc-env=HAMFLIGHT_BLOB_PATH={}",
        blob_path.display()
    );
    println!("cargo:rerun-if-changed=build.rs");
}

fn write_default_blob(out: &Path) -> PathBuf {
    let p = out.join("default-untrained.hfw");
    let bytes = hamflight::blob::encode(&hamflight::model::ModelWeights::default());
    fs::write(&p, bytes).expect("write default blob to OUT_DIR");
    p
}
