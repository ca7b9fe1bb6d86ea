//! Subjective evaluation (issue 16): the statistics of \[blend\] §6 and \[unitsel\].

pub mod stats;
