//! The bootstrap loop (issue 15; its own module, not `model`'s, since it tracks a video
//! through `codec` and a model must not depend on the tracker built on it): after a first model from a few hand-marked frames, the
//! frames of the talker's video it explains worst — the highest fit residual, or appearance
//! outside the span of its training frames — spread over time, exported with the fitted
//! landmarks as a starting point to correct and add to the training set.

use std::path::Path;

use crate::codec::{self, CodecError, EncodeOptions};
use crate::model::FaceModel;
use crate::shape::{self, Landmarks};
use crate::video::{self, Source};
use crate::{Progress, atomic};

/// A frame proposed for marking.
#[derive(Clone, Debug, PartialEq)]
pub struct Suggestion {
    /// Its index in the video.
    pub index: usize,
    /// Residual RMS of the fit (grey levels).
    pub residual: f64,
    /// The largest |b_k| / σ_k over the shape and appearance parameters.
    pub largest_sd: f64,
    /// The ranking score: `residual · (1 + max(0, largest_sd − 3))`.
    pub score: f64,
}

/// Parameters beyond this many standard deviations lie outside what the training frames span.
const SPAN_SD: f64 = 3.0;

/// Tracks `input` with `model` (lost frames allowed: they are what is wanted) and writes the
/// `count` worst-explained frames, at least `len / (2·count)` frames apart, to `out` as
/// `NNNNNN.png` with `NNNNNN.pts` (the fit), replacing `out` atomically. Best first.
pub fn suggest(
    model: &FaceModel,
    input: &Path,
    count: usize,
    out: &Path,
    options: &EncodeOptions,
    progress: impl FnMut(Progress),
) -> Result<Vec<Suggestion>, CodecError> {
    crate::options::count_in("frames to suggest", count, 1, video::MAX_EXPORT)?;
    let options = EncodeOptions {
        allow_lost: true,
        ..options.clone()
    };
    let sd: Vec<f64> = model
        .shape
        .pca
        .variances
        .iter()
        .chain(&model.appearance.pca.variances)
        .map(|&v| f64::from(v).sqrt())
        .collect();
    let mut scored = Vec::new();
    let mut fits: Vec<Landmarks> = Vec::new();
    codec::track(
        model,
        Source::open(input)?,
        &options,
        progress,
        |image, t| {
            let params = model.project(&image, &t.landmarks)?;
            let largest_sd = params[crate::facespace::POSE_DIMS..]
                .iter()
                .zip(&sd)
                .map(|(&b, &s)| if s > 0.0 { f64::from(b).abs() / s } else { 0.0 })
                .fold(0.0, f64::max);
            scored.push(Suggestion {
                index: scored.len(),
                residual: t.error,
                largest_sd,
                score: t.error * (1.0 + (largest_sd - SPAN_SD).max(0.0)),
            });
            fits.push(t.landmarks.clone());
            Ok(())
        },
    )?;
    let gap = scored.len() / (2 * count);
    let mut ranked = scored.clone();
    ranked.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut chosen: Vec<Suggestion> = Vec::with_capacity(count);
    for s in ranked {
        if chosen.len() == count {
            break;
        }
        if chosen.iter().all(|c| c.index.abs_diff(s.index) > gap) {
            chosen.push(s);
        }
    }
    let mut wanted: Vec<usize> = chosen.iter().map(|c| c.index).collect();
    wanted.sort_unstable();
    atomic::replace_dir(
        out,
        "suggestions",
        |staged| -> Result<(), CodecError> {
            let mut next = wanted.iter().peekable();
            for (i, frame) in Source::open(input)?.enumerate() {
                if next.peek().is_none() {
                    break;
                }
                let frame = frame?;
                if next.peek() == Some(&&i) {
                    next.next();
                    video::write_png(&staged.join(format!("{i:06}.png")), &frame)?;
                    shape::write_pts(&staged.join(format!("{i:06}.pts")), &fits[i])
                        .map_err(crate::model::ModelError::from)?;
                }
            }
            Ok(())
        },
        |source| CodecError::Io {
            path: out.into(),
            source,
        },
    )?;
    Ok(chosen)
}
