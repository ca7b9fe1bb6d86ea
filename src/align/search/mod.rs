//! The alignment graph (triphone HMMs of every pronunciation, optional silences) and its
//! Viterbi search with phone-level back-pointers: the graph and its best path (`graph`), the
//! acoustic model's scoring of states (`scoring`), and the frame-synchronous search over them
//! (`decoder`).

use super::frontend::FEATURE_DIM;
use super::model::{AcousticModel, STATES, STREAM_DIM, STREAMS, TOP_N, WordPosition};
use super::{Alignment, FRAMES_PER_SECOND, TimedPhone, TimedWord};

mod decoder;
mod graph;
mod scoring;

pub(crate) use decoder::*;
pub(crate) use graph::*;
pub(crate) use scoring::*;
