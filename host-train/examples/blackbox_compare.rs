//! Data efficiency: structured (Hamiltonian) vs black-box MLP dynamics model, trained on 1/8, 1/2
//! and all of the training windows, compared on the same held-out windows.
//!
//! `cargo run --release -p host-train --example blackbox_compare -- [DATA_DIR] [EPOCHS] [FRACS]`
//! (defaults: `/tmp/hfdata`, 60, `0.125,0.5,1`). Prints a markdown table.

use anyhow::{Context, Result};
use host_train::train::{compare_blackbox, BB_HIDDEN};
use std::path::PathBuf;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data = PathBuf::from(args.first().map_or("/tmp/hfdata", String::as_str));
    let epochs: usize = args
        .get(1)
        .map_or(Ok(60), |s| s.parse())
        .context("EPOCHS")?;
    let fracs: Vec<f64> = args
        .get(2)
        .map_or("0.125,0.5,1", String::as_str)
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()
        .context("FRACS")?;
    let rows = compare_blackbox(&data, &fracs, epochs)?;
    println!(
        "Held-out 4-step RMS errors (pos m / rot rad / vel m/s / rate rad/s), {epochs} epochs, \
         batch 128, seed 0; black box: one tanh MLP, 2 hidden layers of {BB_HIDDEN}, {} params.\n",
        rows.first().map_or(0, |r| r.blackbox_params)
    );
    println!(
        "| data fraction | train windows | structured held-out (pos, rot, vel, rate) | structured loss | black-box held-out (pos, rot, vel, rate) | black-box loss | black-box ‖RᵀR−I‖_F (RMS / max) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in &rows {
        let e = |x: &host_train::train::Errors| {
            format!(
                "{:.2e}, {:.2e}, {:.2e}, {:.2e}",
                x.pos_m, x.rot_rad, x.vel_m_s, x.rate_rad_s
            )
        };
        println!(
            "| {} | {} | {} | {:.3e} | {} | {:.3e} | {:.1e} / {:.1e} |",
            r.data_frac,
            r.train_windows,
            e(&r.structured),
            r.structured_val_loss,
            e(&r.blackbox),
            r.blackbox_val_loss,
            r.blackbox_orth_err,
            r.blackbox_orth_err_max
        );
    }
    Ok(())
}
