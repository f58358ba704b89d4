//! `host-train bench-train`: seconds per training epoch at several batch sizes, on the sizes of
//! the PyTorch comparison in docs/performance.md (hidden 16, p = 6, g and W on the attitude,
//! windows of N = 5 states, RK4; 7,776 windows: the paper's 8 × 1080 less the 10 % held out). The
//! windows come from a fresh `collect` of the paper's 8 disturbed realizations (no calm one) in a
//! temporary directory. Compare with a PyTorch reference implementation of the same training step
//! (hidden 16, 6 features, 7,776 windows, attitude inputs, batch B), run back to back on the same
//! machine.

use crate::data::collect::{self, CollectConfig};
use crate::train::{data, epochs, TrainConfig};
use anyhow::{bail, Context, Result};
use serde::Serialize;

/// Arguments of `host-train bench-train`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {
    /// Batch sizes in windows; 0 means the full set (one step per epoch).
    #[arg(long, value_delimiter = ',', default_values_t = vec![128, 256, 0])]
    pub batch: Vec<usize>,
    /// Training windows per epoch.
    #[arg(long, default_value_t = 7776)]
    pub windows: usize,
    /// Timed epochs per batch size (after one untimed warm-up epoch); the median is reported.
    #[arg(long, default_value_t = 5)]
    pub epochs: usize,
    /// Time the trainer without its speed-ups (docs/performance.md): the unfused reference loss
    /// (each head on its own, J⁻¹ recomputed).
    #[arg(long)]
    pub reference: bool,
    /// Time burn's autodiff of the fused tensor ops (the trainer before the hand-fused kernel,
    /// `train::fused`) instead of the kernel.
    #[arg(long)]
    pub burn: bool,
}

/// One batch size's timing.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    /// Windows per minibatch.
    pub batch: usize,
    /// Median seconds per epoch.
    pub median_s: f64,
    /// Fastest epoch (s).
    pub min_s: f64,
    /// Slowest epoch (s).
    pub max_s: f64,
    /// Median process CPU time per epoch, all threads (s): steadier than wall time on a
    /// machine shared with other jobs.
    pub median_cpu_s: Option<f64>,
}

/// Runs the benchmark and prints one line per batch size.
///
/// # Errors
/// The collection or its reading failing, or fewer windows collected than asked for.
pub fn run(args: &BenchArgs) -> Result<Vec<BenchRow>> {
    let dir = std::env::temp_dir().join(format!("hamflight-bench-train-{}", std::process::id()));
    let cc = CollectConfig {
        calm_realizations: 0,
        ..CollectConfig::default()
    };
    collect::collect(&dir, &cc).context("collecting the benchmark's windows")?;
    // The PyTorch reference's problem: the paper's model, no per-flight rotor gains.
    let cfg = TrainConfig {
        flight_rotor_gains: false,
        ..TrainConfig::default()
    };
    let windows = data::load(&dir, cfg.window);
    std::fs::remove_dir_all(&dir).ok();
    let windows = windows?;
    if windows.windows.len() < args.windows {
        bail!(
            "--windows {}: the collection has only {}",
            args.windows,
            windows.windows.len()
        );
    }
    let (train, _) = data::split(&windows, 0.1, cfg.seed);
    let mut ids = train;
    ids.extend(0..windows.windows.len());
    ids.truncate(args.windows);
    let mut rows = Vec::new();
    for &b in &args.batch {
        let batch = if b == 0 { ids.len() } else { b };
        let c = TrainConfig {
            batch,
            ..cfg.clone()
        };
        let mut runs = epochs::time_epochs(
            &c,
            &windows,
            &ids,
            args.epochs + 1,
            args.reference,
            args.burn,
        );
        runs.remove(0);
        let mut t: Vec<f64> = runs.iter().map(|r| r.0).collect();
        t.sort_by(f64::total_cmp);
        let mut cpu: Vec<f64> = runs.iter().filter_map(|r| r.1).collect();
        cpu.sort_by(f64::total_cmp);
        let row = BenchRow {
            batch,
            median_s: t.get(t.len() / 2).copied().unwrap_or(f64::NAN),
            min_s: t.first().copied().unwrap_or(f64::NAN),
            max_s: t.last().copied().unwrap_or(f64::NAN),
            median_cpu_s: cpu.get(cpu.len() / 2).copied(),
        };
        println!(
            "hamflight ({}) hidden={} p={} windows={} N={} batch={}: \
             epoch median {:.3} s (min {:.3}, max {:.3}), CPU {}",
            if args.reference {
                "burn flex, reference ops"
            } else if args.burn {
                "burn flex"
            } else {
                "fused kernel"
            },
            cfg.hidden,
            cfg.features,
            ids.len(),
            cfg.window.len,
            batch,
            row.median_s,
            row.min_s,
            row.max_s,
            row.median_cpu_s
                .map_or("n/a".into(), |c| format!("{c:.3} s"))
        );
        rows.push(row);
    }
    Ok(rows)
}
