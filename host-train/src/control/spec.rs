//! Controller names, parsed once: the only place a name becomes a controller's model source,
//! adaptation switch and law. The command line (`eval`, `bridge`, `track`, `margins`), the
//! Python package, the studies and `tools/bitcraze-loop` all go through [`ControllerSpec`];
//! their `--help` lists come from [`ControllerSpec::ALL`].

use std::fmt;
use std::str::FromStr;

use anyhow::{bail, Result};
use hamflight::{AdaptationLaw, Gains};

/// Which model a core controller flies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelSource {
    /// The learned model of a weight blob.
    Learned,
    /// The nominal rigid body (the vehicle description's constants).
    Nominal,
}

/// What a name means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControllerKind {
    /// The core's energy-based controller.
    Core {
        /// Its model.
        model: ModelSource,
        /// Adaptation on (the paper's controller) or off.
        adapt: bool,
        /// The adaptation law the name selects; `None`: [`Gains::default`]'s (the composite).
        law: Option<AdaptationLaw>,
    },
    /// The DSL PID of gym-pybullet-drones.
    Pid,
    /// The Lee–Leok–McClamroch SE(3) controller on the true constants.
    Geometric,
}

/// A controller name and what it means ([`ControllerSpec::ALL`] lists them all).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControllerSpec {
    /// The name, as the command line spells it.
    pub name: &'static str,
    /// What it flies.
    pub kind: ControllerKind,
    /// One line for `--help`.
    pub about: &'static str,
}

const fn core(
    name: &'static str,
    model: ModelSource,
    adapt: bool,
    law: Option<AdaptationLaw>,
    about: &'static str,
) -> ControllerSpec {
    ControllerSpec {
        name,
        kind: ControllerKind::Core { model, adapt, law },
        about,
    }
}

impl ControllerSpec {
    /// Every controller, the core's first, then the baselines.
    pub const ALL: [ControllerSpec; 10] = [
        core(
            "adaptive",
            ModelSource::Learned,
            true,
            None,
            "learned Hamiltonian model + adaptation (the paper's controller; the composite law, the default)",
        ),
        core(
            "learned",
            ModelSource::Learned,
            false,
            None,
            "learned Hamiltonian model, adaptation off (the paper's \"without adaptation\")",
        ),
        core(
            "geometric-adaptive",
            ModelSource::Nominal,
            true,
            None,
            "nominal model + adaptation on a constant world force and body torque (composite law)",
        ),
        core(
            "ida-pbc",
            ModelSource::Nominal,
            false,
            None,
            "the energy-based law on the nominal model, no adaptation",
        ),
        core(
            "adaptive-gradient",
            ModelSource::Learned,
            true,
            Some(AdaptationLaw::Gradient),
            "adaptive with the paper's gradient adaptation law",
        ),
        core(
            "adaptive-composite",
            ModelSource::Learned,
            true,
            Some(AdaptationLaw::Composite),
            "adaptive with the composite (prediction-error) adaptation law",
        ),
        core(
            "geometric-adaptive-gradient",
            ModelSource::Nominal,
            true,
            Some(AdaptationLaw::Gradient),
            "geometric-adaptive with the paper's gradient adaptation law",
        ),
        core(
            "geometric-adaptive-composite",
            ModelSource::Nominal,
            true,
            Some(AdaptationLaw::Composite),
            "geometric-adaptive with the composite (prediction-error) adaptation law",
        ),
        ControllerSpec {
            name: "pid",
            kind: ControllerKind::Pid,
            about: "DSL PID of gym-pybullet-drones (the paper's data-collection controller)",
        },
        ControllerSpec {
            name: "geometric",
            kind: ControllerKind::Geometric,
            about: "Lee-Leok-McClamroch SE(3) controller on the true constants, no adaptation",
        },
    ];

    /// The core's controllers ([`ControllerKind::Core`]).
    pub fn core_specs() -> impl Iterator<Item = &'static ControllerSpec> {
        Self::ALL.iter().filter(|s| s.is_core())
    }

    /// The spec of `name`.
    ///
    /// # Errors
    /// An unknown name; the message lists every name.
    pub fn parse(name: &str) -> Result<Self> {
        match Self::ALL.iter().find(|s| s.name == name) {
            Some(s) => Ok(*s),
            None => bail!(
                "unknown controller `{name}`: expected one of {}",
                Self::ALL.map(|s| s.name).join(", ")
            ),
        }
    }

    /// The spec of a core controller's `name`.
    ///
    /// # Errors
    /// An unknown name or a baseline; the message lists the core's names.
    pub fn parse_core(name: &str) -> Result<Self> {
        match Self::parse(name) {
            Ok(s) if s.is_core() => Ok(s),
            _ => bail!(
                "unknown controller `{name}` (a core controller): expected one of {}",
                core_names().join(", ")
            ),
        }
    }

    /// Whether it is the core's controller (not a baseline).
    pub fn is_core(&self) -> bool {
        matches!(self.kind, ControllerKind::Core { .. })
    }

    /// The model a core controller flies; `None` for a baseline.
    pub fn model(&self) -> Option<ModelSource> {
        match self.kind {
            ControllerKind::Core { model, .. } => Some(model),
            _ => None,
        }
    }

    /// `base` (the gains for the model's vehicle) with this name's adaptation switch and law.
    pub fn gains(&self, base: Gains) -> Gains {
        match self.kind {
            ControllerKind::Core { adapt, law, .. } => Gains {
                adapt,
                law: law.unwrap_or(base.law),
                ..base
            },
            _ => base,
        }
    }
}

impl FromStr for ControllerSpec {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        Self::parse(s)
    }
}

impl fmt::Display for ControllerSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// The core's names, in [`ControllerSpec::ALL`]'s order.
pub fn core_names() -> Vec<&'static str> {
    ControllerSpec::core_specs().map(|s| s.name).collect()
}

/// A clap parser of every name, its `--help` listing each with its line.
pub fn parser() -> clap::builder::PossibleValuesParser {
    possible(ControllerSpec::ALL.iter())
}

/// A clap parser of the core's names ([`parser`] without the baselines).
pub fn core_parser() -> clap::builder::PossibleValuesParser {
    possible(ControllerSpec::core_specs())
}

fn possible<'a>(
    specs: impl Iterator<Item = &'a ControllerSpec>,
) -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        specs
            .map(|s| clap::builder::PossibleValue::new(s.name).help(s.about))
            .collect::<Vec<_>>(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_parses_to_itself_and_is_listed_once() {
        for s in ControllerSpec::ALL {
            assert_eq!(ControllerSpec::parse(s.name).ok(), Some(s));
            assert_eq!(
                ControllerSpec::ALL
                    .iter()
                    .filter(|t| t.name == s.name)
                    .count(),
                1
            );
        }
        assert!(ControllerSpec::parse("adaptiv").is_err());
        assert!(ControllerSpec::parse_core("pid").is_err());
    }

    #[test]
    fn names_set_the_law_and_the_switch_the_plain_names_keep_the_default() {
        let base = Gains::default();
        let g = |n: &str| ControllerSpec::parse(n).map(|s| s.gains(base)).ok();
        assert_eq!(
            g("adaptive").map(|g| (g.adapt, g.law)),
            Some((true, base.law))
        );
        assert_eq!(g("learned").map(|g| g.adapt), Some(false));
        assert_eq!(g("ida-pbc").map(|g| g.adapt), Some(false));
        assert_eq!(
            g("adaptive-gradient").map(|g| g.law),
            Some(AdaptationLaw::Gradient)
        );
        assert_eq!(
            g("geometric-adaptive-composite").map(|g| g.law),
            Some(AdaptationLaw::Composite)
        );
        assert_eq!(
            ControllerSpec::parse("geometric-adaptive")
                .ok()
                .and_then(|s| s.model()),
            Some(ModelSource::Nominal)
        );
    }
}
