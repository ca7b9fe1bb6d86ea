//! Synthesis of face-space trajectories from phonemes (DESIGN §8).

pub mod blend;
pub mod smooth;
