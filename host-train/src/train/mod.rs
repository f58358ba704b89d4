//! Learning the Hamiltonian dynamics and disturbance model from collected windows (paper
//! Problem 1, Sec. 3): J⁻¹(q) and g(q) (θ), W(q, 𝔭) (φ) and one a_j per disturbance
//! realization, by RK4 through each window and Adam on the TSE(3) loss ℓ_p + ℓ_R + ℓ_ζ.
//!
//! Front door: code outside `host-train/src` imports these from here, never from a submodule
//! (`tools/front-door.py` checks it): [`fit`], [`TrainConfig`], [`TrainArgs`], [`TrainReport`];
//! the windows' [`load_windows`], [`split_windows`], [`batch_windows`] (`data::{load, split,
//! batch}`), [`Window`], [`Windows`], [`RealizationInfo`]; [`init_weights`], [`initial_params`],
//! [`initial_gradients`], [`gradients_at`], [`batch_loss`], [`batch_loss_reference`];
//! [`prediction_errors`], [`model_errors`]; [`backoff_candidates`] (`backoff::candidates`);
//! [`compare_blackbox`] (`blackbox::compare`), [`Errors`], [`BB_HIDDEN`]; the measured-input
//! response's [`fit_response`] (`response::fit`), [`response_rollout`] (`response::rollout`),
//! [`response_errors`], [`Response`], [`FitConfig`]; the port fit's [`fit_port`],
//! [`port_report`], [`default_port_start`], [`PORT_FIT_PARAMS`] (`port_fit::{fit, report,
//! default_start, FIT_PARAMS}`), [`PortFitConfig`], [`Scaling`]; the tensor model's [`TModel`],
//! [`Consts`], [`Forcing`], [`tensor_to_vec`] (`tensor_model::to_vec`); the fused kernel's
//! [`Isa`].
//!
//! - [`data`]: the dataset's windows as tensors, the held-out split;
//! - [`tensor_model`]: the networks and paper eq. 1–2 as batched burn tensor ops (flex +
//!   autodiff);
//! - [`loss`]: the windows' RK4 loss; [`adam`]: the optimizer; [`epochs`]: the epoch loop, its
//!   stages and the progress bar;
//! - [`blackbox`]: the black-box MLP baseline and the data-efficiency comparison;
//! - [`fused`]: the loss and its exact gradient as one hand-fused f32 kernel, what training
//!   runs (burn's autodiff of [`tensor_model`] is its reference);
//! - [`export`]: the weight blob (temp file, then rename) and the `FILE.hfw.json` report.
//!
//! Training here flies nothing: the flight check before a blob is written, `host-train train`
//! and `bench-train` are [`crate::pipeline`]'s.
//!
//! # Changing the model or the loss
//!
//! The equations live in three places that must agree; change them in this order:
//!
//! 1. the tensor model ([`tensor_model`]): the networks, paper eq. 1–2, RK4 and the loss as burn
//!    tensor ops, differentiated by burn's autodiff. It is the reference, and it must match the
//!    core's f32 inference (`src/model/`) where the two overlap;
//! 2. the fused kernel ([`fused`]): the same forward pass with its reverse pass written out by
//!    hand (`fused/rhs.rs` for eq. 1, `fused/group.rs` for RK4 and the loss, `fused/point.rs`
//!    and `fused/mlp.rs` for the heads). Until it is updated, train with
//!    `--gradient burn` ([`GradientPath::Burn`]);
//! 3. the parity test (`host-train/tests/train_parity.rs`): the core's inference against the
//!    tensor model, and the fused kernel's loss and gradients against burn's. It must pass
//!    before the fused path is trusted again.

pub mod adam;
pub mod backoff;
pub mod blackbox;
pub mod data;
pub mod epochs;
pub mod export;
pub mod fused;
pub mod init;
pub mod lm;
pub mod loss;
pub mod port_fit;
pub mod predict;
pub mod response;
pub mod tensor_model;

use anyhow::{bail, Result};
use hamflight::model::{FEATURES, HIDDEN};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub use export::TrainReport;

// The layer's front door: what code outside host-train/src uses, by these names.
pub use backoff::candidates as backoff_candidates;
pub use blackbox::{compare as compare_blackbox, Errors, BB_HIDDEN};
pub use data::{
    batch as batch_windows, load as load_windows, split as split_windows, RealizationInfo, Window,
    Windows,
};
pub use epochs::{gradients_at, initial_gradients, initial_params};
pub use export::prediction_errors;
pub use fused::Isa;
pub use init::init_weights;
pub use loss::{batch_loss, batch_loss_reference};
pub use port_fit::{
    default_start as default_port_start, fit as fit_port, report as port_report, PortFitConfig,
    Scaling, FIT_PARAMS as PORT_FIT_PARAMS,
};
pub use predict::model_errors;
pub use response::{
    fit as fit_response, response_errors, rollout as response_rollout, FitConfig, Response,
};
pub use tensor_model::{to_vec as tensor_to_vec, Consts, Forcing, TModel};

/// Where the training loss's gradient comes from. Recorded in [`TrainConfig::gradient`] and so in
/// the training report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum GradientPath {
    /// The hand-fused f32 kernel ([`fused`]); where it declines a shape, burn's autodiff, with a
    /// warning.
    #[default]
    Fused,
    /// burn's autodiff of [`tensor_model`]'s equations (the reference the kernel is tested
    /// against; slower).
    Burn,
}

impl GradientPath {
    /// The environment's override: `HAMFLIGHT_TRAIN_BURN` set and neither empty nor `0`
    /// selects [`GradientPath::Burn`]; else `None`.
    pub fn from_env() -> Option<Self> {
        std::env::var_os("HAMFLIGHT_TRAIN_BURN")
            .filter(|v| !v.is_empty() && v != "0")
            .map(|_| GradientPath::Burn)
    }
}

/// Training settings. Saved in the report next to the weights they produced.
#[derive(Clone, Debug, Serialize)]
pub struct TrainConfig {
    /// Epochs over the training windows (default 10, then [`TrainConfig::feature_epochs`]
    /// of the feature stage: 22 in all; docs/training.md).
    pub epochs: usize,
    /// Adam's peak learning rate (default 3e-3), reached after the warm-up and decayed by a
    /// cosine to 1/20 of it.
    pub lr: f64,
    /// The a_j's learning rate relative to `lr` (default 10: they are few, in m/s² units).
    pub a_lr_scale: f64,
    /// Minibatch size in windows (default 128).
    pub batch: usize,
    /// Seed of the initialization, the split and the minibatch order (default 0).
    pub seed: u64,
    /// Fraction of each realization's windows held out (default 0.1).
    pub heldout_frac: f64,
    /// Fraction of the remaining training windows used (default 1; for data-efficiency runs).
    pub data_frac: f64,
    /// Weight of the linear-velocity term of ℓ_ζ (default 50). The paper's ℓ is any distance on
    /// TSE(3); over a 17 ms window a unit of normalized force error moves v about 7× less than
    /// a unit of normalized torque error moves ω, so the plain sum (weight 1) all but ignores
    /// the forces — where the wind lives. 50 ≈ 7² balances them.
    pub vel_weight: f32,
    /// Decoupled weight decay λ on the W head's input layer (default 1; 0 turns it off): after
    /// each Adam step those weights shrink by lr·λ. Without it the features learn to vary
    /// steeply with attitude — under each realization's wind the vehicle hovers at its own tilt,
    /// so tilt can stand in for a_j — and the adaptation law then chases the features
    /// (docs/training.md, "Choosing the schedule").
    pub feature_decay: f64,
    /// Epochs of linear learning-rate warm-up before the cosine decay (default 1).
    pub warmup_epochs: usize,
    /// Early stop after this many epochs without a better held-out loss; the best epoch's
    /// weights are kept either way (default 0: run all epochs).
    pub patience: usize,
    /// Scale of the output layers' initial weights around the physical prior (default 0.05).
    pub init_out_gain: f32,
    /// Hidden width; fixed at compile time by the core ([`HIDDEN`]), checked here.
    pub hidden: usize,
    /// Number of disturbance features p; fixed by the core ([`FEATURES`]), checked here.
    pub features: usize,
    /// How windows are cut from the dataset's flights (default: 5 states every 4 samples).
    pub window: crate::io::dataset::WindowSpec,
    /// The vehicle's mass (kg), carried in the blob; `None` (default) takes the dataset
    /// manifest's `mass_kg`.
    pub mass_kg: Option<f64>,
    /// Learn one rotor gain deviation per rotor per flight (δηⱼ, the multiplicative twin of
    /// a_j; pinned to 0 for the disturbance-free flights and dropped in flight), so that a
    /// flight's weak rotors or sagging battery scale its own commands and not the shared g.
    pub flight_rotor_gains: bool,
    /// With `flight_rotor_gains`: epochs of the feature stage after training (J⁻¹ and g
    /// frozen, the rotor gains dropped, W and the a_j trained alone; default 12, chosen in
    /// docs/training.md, "Choosing the schedule").
    pub feature_epochs: usize,
    /// Fly the new blob in the SITL before writing it, and refuse to write one that crashes the
    /// adaptive controller ([`crate::pipeline::train`]; default true).
    pub flight_check: bool,
    /// When the learned features fail the flight check, keep them only along the directions
    /// the flights excited and pull them toward the nominal ones ([`backoff::candidates`]),
    /// and write the first blob that flies, saying so (default true); off, a failed check
    /// writes nothing.
    pub feature_backoff: bool,
    /// Scenarios the blob must also fly under both laws without a crash, full length (e.g.
    /// the plant the closed-loop replay identifies, and the rigid published one): a candidate
    /// that crashes one fails the check like the built-in flights, and the back-off goes on.
    pub flight_survive: Vec<std::path::PathBuf>,
    /// The motors' first-order time constant (s) written into the blob, what the composite
    /// law's prediction assumes; `None` (default) takes the manifest's `vehicle.motor_tau_s`
    /// (`import --motor-tau-s`), else [`hamflight::model::DEFAULT_MOTOR_TAU_S`].
    pub motor_tau_s: Option<f64>,
    /// Physics-guided structure of g (default true): g's body x and y force rows are written
    /// as zero, since no input of a quadrotor makes a body x or y force. The control law never
    /// used them (it inverts g on the actuated rows only), but the composite law's prediction
    /// does, and trained freely they take up large spurious entries (see `docs/vehicles.md`).
    /// Held at zero during training instead, the rest of the model fits worse (measured there).
    pub zero_unactuated_gain_rows: bool,
    /// Keep the rigid body at the vehicle description's (default false): J⁻¹ stays the prior's
    /// (the described inertia) and g the true mixer's, so only W and the a_j are learned. For
    /// logs whose measured rotor speeds cannot identify the torque effectiveness
    /// (docs/benchmark.md: the nano-drone flights show 8–34 % of it through a 70 ms lag); what
    /// those logs do identify goes into a measured-input response ([`response`]) for prediction.
    pub pin_rigid_body: bool,
    /// Where the loss's gradient comes from (default [`GradientPath::Fused`], or
    /// [`GradientPath::Burn`] when `HAMFLIGHT_TRAIN_BURN` overrides it: [`GradientPath::from_env`]).
    pub gradient: GradientPath,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 10,
            lr: 3e-3,
            a_lr_scale: 10.0,
            batch: 128,
            seed: 0,
            heldout_frac: 0.1,
            data_frac: 1.0,
            vel_weight: 50.0,
            feature_decay: 1.0,
            warmup_epochs: 1,
            patience: 0,
            init_out_gain: 0.05,
            hidden: HIDDEN,
            features: FEATURES,
            window: crate::io::dataset::WindowSpec::default(),
            mass_kg: None,
            flight_rotor_gains: true,
            feature_epochs: 12,
            flight_check: true,
            feature_backoff: true,
            flight_survive: Vec::new(),
            motor_tau_s: None,
            zero_unactuated_gain_rows: true,
            pin_rigid_body: false,
            gradient: GradientPath::from_env().unwrap_or_default(),
        }
    }
}

/// A trained model with its report, not yet checked in flight nor written.
pub struct Fitted {
    /// The model, as the blob will carry it.
    pub model: hamflight::model::LearnedModel,
    /// The training report (its `flight_check` not yet filled in).
    pub report: TrainReport,
    /// The dataset manifest's vehicle mass (kg).
    pub manifest_mass_kg: f64,
    /// The vehicle the dataset describes.
    pub vehicle: crate::io::dataset::VehicleDescription,
}

/// Trains on the dataset in `data_dir` (the flight check and the writing of the blob are
/// [`crate::pipeline::train::run`]'s).
///
/// # Errors
/// A dataset that cannot be read, or a `hidden`/`features` other than the core's compile-time
/// sizes.
pub fn fit(cfg: &TrainConfig, data_dir: &Path, quiet: bool) -> Result<Fitted> {
    if cfg.hidden != HIDDEN || cfg.features != FEATURES {
        bail!(
            "--hidden {} / --features {}: the core is compiled for HIDDEN = {HIDDEN}, FEATURES = \
             {FEATURES} (the firmware's fixed-size networks); change them in src/model/mod.rs",
            cfg.hidden,
            cfg.features
        );
    }
    let mut windows = data::load(data_dir, cfg.window)?;
    if let Some(m) = cfg.mass_kg {
        if (m as f32 - windows.mass_kg).abs() > 0.01 * windows.mass_kg {
            eprintln!(
                "note: --mass-kg {m} overrides the dataset's mass_kg {} (`{}`)",
                windows.mass_kg,
                data_dir.join("manifest.json").display()
            );
        }
        windows.mass_kg = m as f32;
    }
    let (lo, hi) = (hamflight::model::MIN_MASS_KG, hamflight::model::MAX_MASS_KG);
    if !(lo..=hi).contains(&windows.mass_kg) {
        bail!(
            "vehicle mass {} kg is outside {lo}..={hi} kg (set it with --mass-kg, or fix the \
             dataset's manifest.json)",
            windows.mass_kg
        );
    }
    if cfg.pin_rigid_body && cfg.flight_rotor_gains {
        bail!(
            "--pin-rigid-body needs --no-flight-rotor-gains: the per-flight rotor gains scale a \
             flight's torques too, which the pinned g holds at the mixer's (with g's torque part \
             pinned and its thrust free, the nano-drone flights traded a thrust gain of 9.0 \
             against rotor gains of 0.1, and the blob crashed)"
        );
    }
    if cfg.flight_rotor_gains && !windows.realizations.iter().any(|r| r.disturbance_free) {
        eprintln!(
            "note: no flight in `{}` is marked disturbance-free (`import --calm`), so the shared \
             g and the flights' rotor gains share a common scale that only their start at the \
             nominal g fixes; mark a calm flight, or train with --no-flight-rotor-gains",
            data_dir.display()
        );
    }
    let (train_ids, heldout) = data::split(&windows, cfg.heldout_frac, cfg.seed);
    let train_ids = data::subset(&windows, &train_ids, cfg.data_frac);
    let mut trained = epochs::train(cfg, &windows, &train_ids, &heldout, quiet);
    to_hover_feature_basis(&mut trained);
    if cfg.zero_unactuated_gain_rows {
        trained.weights = epochs::with_unactuated_gain_rows_zeroed(&trained.weights);
    }
    let tau = blob_motor_tau_s(cfg, &windows.vehicle)?;
    let model = hamflight::model::LearnedModel::new(trained.weights).with_motor_tau_s(tau);
    let mut report = export::report(cfg, &windows, &train_ids, &heldout, &trained);
    report.blob_motor_tau_s = tau;
    Ok(Fitted {
        model,
        report,
        manifest_mass_kg: f64::from(windows.manifest_mass_kg),
        vehicle: windows.vehicle.clone(),
    })
}

/// The motor lag the blob carries: `--motor-tau-s`, else the manifest's (the lag applied at
/// import, else the vehicle description's), else the default.
fn blob_motor_tau_s(
    cfg: &TrainConfig,
    vehicle: &crate::io::dataset::VehicleDescription,
) -> Result<f32> {
    let tau = cfg
        .motor_tau_s
        .or(vehicle.motor_tau_s)
        .or(vehicle.description.as_ref().and_then(|d| d.motor_tau_s))
        .map_or(hamflight::model::DEFAULT_MOTOR_TAU_S, |t| t as f32);
    let max = hamflight::model::MAX_MOTOR_TAU_S;
    if !(0.0..=max).contains(&tau) {
        bail!("motor time constant {tau} s is outside 0..={max} s (--motor-tau-s, or the manifest's vehicle.motor_tau_s)");
    }
    Ok(tau)
}

/// `host-train train`: the command-line face of [`crate::pipeline::train::run`]; also
/// [`TrainJob`], the same arguments as a typed (serde) job. A key left out takes the
/// command line's default ([`TrainArgs::default`], which reads what the flags' defaults read);
/// an unknown key is an error.
#[derive(clap::Args, Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainArgs {
    /// Dataset directory written by `host-train collect` or `host-train import`.
    #[arg(long, value_name = "DIR")]
    pub data: std::path::PathBuf,
    /// Output weight blob; the report goes to FILE.json next to it. Required, so that training
    /// never overwrites the shipped `weights/default.hfw` unless this names it.
    #[arg(long, value_name = "FILE.hfw")]
    pub out: std::path::PathBuf,
    /// Epochs of the main stage (J⁻¹, g, W, the a_j and the rotor gains), then
    /// `--feature-epochs` of the feature stage.
    #[arg(long, default_value_t = TrainConfig::default().epochs)]
    pub epochs: usize,
    /// Adam's peak learning rate (after the warm-up; cosine-decayed to 1/20).
    #[arg(long, default_value_t = TrainConfig::default().lr)]
    pub lr: f64,
    /// Minibatch size (windows).
    #[arg(long, default_value_t = TrainConfig::default().batch)]
    pub batch: usize,
    /// Seed (initialization, split, minibatch order).
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
    /// Hidden width: must equal the core's compile-time HIDDEN (the firmware's fixed networks).
    #[arg(long, default_value_t = HIDDEN)]
    pub hidden: usize,
    /// Disturbance features p: must equal the core's compile-time FEATURES.
    #[arg(long, default_value_t = FEATURES)]
    pub features: usize,
    /// Fraction of each realization's windows held out for validation.
    #[arg(long, default_value_t = TrainConfig::default().heldout_frac)]
    pub heldout: f64,
    /// Fraction of the training windows used (data-efficiency runs).
    #[arg(long, default_value_t = TrainConfig::default().data_frac)]
    pub data_frac: f64,
    /// Weight of ‖v − v̄‖² in ℓ_ζ.
    #[arg(long, default_value_t = TrainConfig::default().vel_weight)]
    pub vel_weight: f32,
    /// Epochs of linear learning-rate warm-up before the cosine decay.
    #[arg(long, default_value_t = TrainConfig::default().warmup_epochs)]
    pub warmup_epochs: usize,
    /// Stop after this many epochs without a better held-out loss (0: never); the best
    /// epoch's weights are written.
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    pub patience: usize,
    /// Decoupled weight decay on the feature network's input layer (0 = off).
    #[arg(long, default_value_t = TrainConfig::default().feature_decay)]
    pub feature_decay: f64,
    /// States per training window (N + 1 in the paper's notation).
    #[arg(long, default_value_t = crate::io::dataset::WindowSpec::default().len)]
    pub window_len: usize,
    /// Samples between the starts of consecutive windows (4 with `collect`'s defaults: one held
    /// command per window; 1 uses every sample as a start).
    #[arg(long, default_value_t = crate::io::dataset::WindowSpec::default().stride)]
    pub stride: usize,
    /// The vehicle's mass (kg), written into the blob: the controller's gains and the model's
    /// M = diag(m I, J) use it. Default: the dataset manifest's `mass_kg` (what `collect` flew,
    /// or what `import --mass-kg` was told).
    #[arg(long, value_name = "KG")]
    pub mass_kg: Option<f64>,
    /// Epochs of the feature stage (with the per-flight rotor gains): W and the a_j trained
    /// alone on the shared J and g, the rotor gains dropped, as the adaptive controller flies.
    #[arg(long, default_value_t = TrainConfig::default().feature_epochs)]
    pub feature_epochs: usize,
    /// Do not learn a rotor gain per rotor per flight. By default each flight (realization)
    /// gets four rotor gains next to its a_j, the multiplicative twin of a_j (pinned to 1 on
    /// `--calm` flights, dropped in flight), so that one flight's weak rotors or sagging
    /// battery scale that flight's commands and not the shared g; this assumes the CF2X mixer.
    /// With this flag the shared g absorbs the flights' mean thrust deficit (calm-air
    /// identifiability, docs/training.md).
    #[arg(long)]
    pub no_flight_rotor_gains: bool,
    /// Write the blob without the flight check: by default the new model first flies an 8 s
    /// spiral under wind in the SITL, adaptive and without adaptation, on the dataset's vehicle,
    /// and nothing is written if adaptive crashes or tracks worse.
    #[arg(long)]
    pub no_flight_check: bool,
    /// Write nothing when the learned features fail the flight check. By default the trainer
    /// then keeps them only along the directions of a the flights excited (nominal elsewhere),
    /// pulls those toward the nominal features (50, 25, 10 % kept), then tries the nominal
    /// features, and writes the first blob that passes, saying what it kept: flights without
    /// a deliberate disturbance teach W along one or two directions, and the adaptation law
    /// chases the untaught rest.
    #[arg(long)]
    pub no_feature_backoff: bool,
    /// A scenario the blob must also fly, full length, under both laws without a crash
    /// (repeatable): e.g. scenarios/bl-id-calm-spiral.toml, the vehicle the closed-loop replay
    /// identifies from the flights, and scenarios/bl-calm-spiral.toml, the rigid published one.
    /// A learned W that crashes one goes through the same back-off; the error names the
    /// scenario and the law.
    #[arg(long = "flight-survive", value_name = "FILE.toml")]
    pub flight_survive: Vec<std::path::PathBuf>,
    /// The motors' first-order time constant (s) written into the blob, what the composite
    /// adaptation law's prediction assumes. Default: the manifest's `vehicle.motor_tau_s` (what
    /// `import --motor-tau-s` was told), else 0.05 s.
    #[arg(long, value_name = "S")]
    pub motor_tau_s: Option<f64>,
    /// Write g's body x and y force rows as trained. By default they are written as zero: no
    /// input of a quadrotor makes a body x or y force, the control law never uses them, and
    /// trained freely they learn spurious entries that the composite adaptation law's
    /// prediction turns into force errors at every attitude manoeuvre.
    #[arg(long)]
    pub free_gain: bool,
    /// Keep J and g at the vehicle description's (the prior: its inertia, the true mixer); learn
    /// only the disturbance features W and the a_j. For real logs whose rotor speeds do not
    /// identify the torque effectiveness (the nano-drone benchmark); fit what they do show with
    /// `host-train fit-response`. Needs --no-flight-rotor-gains.
    #[arg(long)]
    pub pin_rigid_body: bool,
    /// Where the loss's gradient comes from: `fused` (the hand-fused kernel) or `burn` (burn's
    /// autodiff, the reference). Default: fused, or burn when `HAMFLIGHT_TRAIN_BURN=1`.
    #[arg(long, value_enum, value_name = "PATH")]
    pub gradient: Option<GradientPath>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// A typed training configuration that the CLI (`host-train train`) and Python
/// (`hamflight.train`) both call directly: [`TrainArgs`], built from serde (JSON) instead of a
/// command line.
pub type TrainJob = TrainArgs;

impl Default for TrainArgs {
    /// The command line's defaults (from [`TrainConfig::default`], as the flags'), with empty
    /// `data` and `out` (which the command line requires).
    fn default() -> Self {
        let c = TrainConfig::default();
        let w = crate::io::dataset::WindowSpec::default();
        Self {
            data: std::path::PathBuf::new(),
            out: std::path::PathBuf::new(),
            epochs: c.epochs,
            lr: c.lr,
            batch: c.batch,
            seed: c.seed,
            hidden: HIDDEN,
            features: FEATURES,
            heldout: c.heldout_frac,
            data_frac: c.data_frac,
            vel_weight: c.vel_weight,
            warmup_epochs: c.warmup_epochs,
            patience: c.patience,
            feature_decay: c.feature_decay,
            window_len: w.len,
            stride: w.stride,
            mass_kg: None,
            feature_epochs: c.feature_epochs,
            no_flight_rotor_gains: false,
            no_flight_check: false,
            no_feature_backoff: false,
            flight_survive: Vec::new(),
            motor_tau_s: None,
            free_gain: false,
            pin_rigid_body: false,
            gradient: None,
            quiet: false,
        }
    }
}

impl TrainArgs {
    /// The configuration these arguments describe.
    pub fn config(&self) -> TrainConfig {
        TrainConfig {
            epochs: self.epochs,
            lr: self.lr,
            batch: self.batch,
            seed: self.seed,
            hidden: self.hidden,
            features: self.features,
            heldout_frac: self.heldout,
            data_frac: self.data_frac,
            vel_weight: self.vel_weight,
            feature_decay: self.feature_decay,
            warmup_epochs: self.warmup_epochs,
            patience: self.patience,
            window: crate::io::dataset::WindowSpec {
                len: self.window_len,
                stride: self.stride,
            },
            mass_kg: self.mass_kg,
            flight_rotor_gains: !self.no_flight_rotor_gains,
            feature_epochs: self.feature_epochs,
            flight_check: !self.no_flight_check,
            feature_backoff: !self.no_feature_backoff,
            flight_survive: self.flight_survive.clone(),
            motor_tau_s: self.motor_tau_s,
            zero_unactuated_gain_rows: !self.free_gain,
            pin_rigid_body: self.pin_rigid_body,
            gradient: self
                .gradient
                .unwrap_or_else(|| TrainConfig::default().gradient),
            ..TrainConfig::default()
        }
    }
}

/// Changes the trained features to the basis in which they equal the nominal ones at hover
/// ([`hamflight::model::learned::hover_feature_basis`]): W' = W T, a_j' = T⁻¹ a_j. The model's
/// predictions W a_j are unchanged; the adaptation law's rates then act on force and torque
/// separately. Left as is (with a warning) if W at hover is ill-conditioned.
pub fn to_hover_feature_basis(trained: &mut epochs::Trained) {
    use hamflight::model::learned::hover_feature_basis;
    let Some(t) = hover_feature_basis(&trained.weights.disturbance) else {
        eprintln!("warning: W at hover is ill-conditioned; features left in the trained basis");
        return;
    };
    let Some(t_inv) = t.try_inverse() else {
        eprintln!("warning: feature basis not invertible; features left in the trained basis");
        return;
    };
    trained.weights = trained.weights.with_feature_basis(&t);
    for a in trained.a.iter_mut() {
        let v = t_inv * nalgebra::SVector::<f32, FEATURES>::from(*a);
        *a = v.into();
    }
}

#[cfg(test)]
mod args_tests {
    use super::TrainArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: TrainArgs,
    }

    /// The typed job's defaults are the command line's.
    #[test]
    fn serde_defaults_are_the_flags_defaults() {
        let cli = Cli::try_parse_from(["train", "--data", "d", "--out", "o.hfw"]).unwrap();
        let job: TrainArgs = serde_json::from_str(r#"{"data": "d", "out": "o.hfw"}"#).unwrap();
        assert_eq!(format!("{:?}", cli.args), format!("{job:?}"));
        let err = serde_json::from_str::<TrainArgs>(r#"{"epoch": 3}"#).unwrap_err();
        assert!(err.to_string().contains("epoch"), "{err}");
    }
}
