//! Flying (layer 3): the one SITL loop and its scores, events, adaptation tracking, margins and uSD recording.

pub mod eval;
pub mod events;
pub mod margins;
pub mod track;
pub mod usdrecord;
