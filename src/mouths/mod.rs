//! Recorded mouths (issue 38): the talker's own recorded lips, teeth and skin, drawn over the
//! synthesised face so the mouth looks recorded rather than like a PCA reconstruction.
//!
//! The appearance model keeps what its few dozen training frames share — the teeth come out a
//! grey band, stubble and lip lines are smoothed away. For each output frame a recorded frame
//! whose lips have the synthesised shape is chosen ([`Chooser`]: nearest lip shape, playing on
//! through recorded frames in order while they stay near, as \[graph\] plays captured frames
//! back and \[unitsel\] concatenates real mouth images), and its *detail* — the recorded
//! texture's luma less the model's own reconstruction of that frame, so only what the model
//! cannot draw — is added to the synthesised texture in the reference frame. The model keeps
//! the colour, lighting and low frequencies it tracks and re-lights; the recording gives the
//! rest, warped to the synthesised shape by the same piecewise affine warp. The recordings
//! are taken into the reference frame by bicubic sampling ([`crate::warp::sample_cubic`]):
//! the detail is resampled once more when drawn, and two bilinear passes lose the finest of it.
//!
//! The folder: `mouths.json`, `mouths.mp4` (the region drawn over the face — the lips and jaw
//! of [`crate::render::Edge::Articulators`] — of every kept frame in the reference frame, as
//! recorded: a Python user can watch it), `appearance.npy` (frames × `b_a`: each kept frame's
//! own appearance parameters, for its detail) and `keys.npy` (frames × 40: its lips in
//! reference-frame pixels).

mod renderer;

use std::path::{Path, PathBuf};

use image::RgbImage;
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::codebook::Codebook;
use crate::facespace::FaceParams;
use crate::manifest::{self, ManifestError};
use crate::model::FaceModel;
use crate::shape::Similarity;
use crate::mp4_file::Reader;
use crate::video::{Source, VideoError};
use crate::{Progress, npy};

pub use renderer::SampledRenderer;

/// The mouths folder format this build writes and reads.
pub const MOUTHS_VERSION: u32 = 1;
const FORMAT: &str = "facespace-mouths";
const MANIFEST: &str = "mouths.json";
const VIDEO: &str = "mouths.mp4";

/// iBUG-68 lip landmarks (outer 48–59, inner 60–67): the selection key.
pub const LIPS: std::ops::Range<usize> = 48..68;

/// Recorded frames kept by default: GRID s1's 741-sentence codebook holds 55 000; 40 of its
/// sentences (3 000 frames) cover his mouth shapes and keep the talker small (BENCHMARKS.md).
pub const DEFAULT_FRAMES: usize = 3000;

/// What leaving a recorded run for a nearer frame elsewhere costs, in pixels of mean lip
/// distance in the reference frame: a run plays on while its frames stay within this of the
/// nearest, so the detail changes source rarely (each change is a small jump in the teeth
/// and lip lines).
pub const SWITCH_COST: f32 = 1.2;

/// The video's quantiser (OpenH264's least): the detail is a few grey levels, which H.264's default (26) and the
/// talker videos' range (12–36) smooth away (BENCHMARKS.md: detail kept against QP).
pub const QP: u8 = 12;

/// The detail's gain when drawn: each resampling on its way (the recording into the reference
/// frame, the reference frame onto the picture) softens it. Chosen on GRID s1's validation
/// split by the discriminator ([`crate::eval::realism`]) with the synthesis drawn over each
/// clip's own video (a bicubic store, gain 1 / 1.25 / 1.5: 0.91 / 0.69 / 0.88; BENCHMARKS
/// "Recorded mouths").
pub const DETAIL_GAIN: f32 = 1.25;

/// What can go wrong with recorded mouths.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MouthsError {
    /// The manifest or an array is missing, damaged or of another version.
    #[error("mouths: {0}")]
    Manifest(#[from] ManifestError),
    /// A recording could not be read or the store's video written.
    #[error("mouths: {0}")]
    Video(#[from] VideoError),
    /// The parts disagree with each other or with the model.
    #[error("mouths {dir}: {reason}")]
    Inconsistent {
        /// The folder.
        dir: PathBuf,
        /// What disagrees.
        reason: String,
    },
    /// The model cannot key mouths (it has no iBUG-68 lips) or draws no region.
    #[error("mouths: {0}")]
    Model(String),
    /// A file could not be written.
    #[error("mouths {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// A recorded sentence whose frames are kept, in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stretch {
    /// The sentence's name (its recording's stem).
    pub name: String,
    /// Frames kept, from its first.
    pub frames: usize,
}

/// The rectangle of the reference frame the video holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Window {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width (even).
    pub width: u32,
    /// Height (even).
    pub height: u32,
}

#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    model_hash: String,
    fps: f64,
    window: Window,
    stretches: Vec<Stretch>,
}

/// Recorded mouths, loaded (module docs).
#[derive(Clone, Debug)]
pub struct Mouths {
    /// [`FaceModel::hash`] of the model they belong to.
    pub model_hash: String,
    /// Frames per second of the recordings.
    pub fps: f64,
    /// The kept sentences, in order.
    pub stretches: Vec<Stretch>,
    /// The video's rectangle of the reference frame.
    pub window: Window,
    /// What the detail is multiplied by when drawn ([`DETAIL_GAIN`]).
    pub gain: f32,
    /// Mask-pixel indices of the region (the articulators' alpha above zero), mask order.
    pub pixels: Vec<u32>,
    /// The store's video, and what it was when loaded: a piece decoded later must come from
    /// that same file.
    video: PathBuf,
    loaded: Option<crate::atomic::Identity>,
    /// The video in pieces, one from each sync frame to the next, each piece's detail (frames
    /// × region pixels: recorded luma less the model's reconstruction, grey levels) decoded
    /// when a frame of it is first drawn: an utterance draws on a few of the store's pieces.
    pieces: Vec<Piece>,
    /// The model's luma over the region (its mean, then one row per appearance component)
    /// and each kept frame's own appearance: what a decoded frame's detail is measured from.
    luma: Vec<Vec<f32>>,
    appearance: Array2<f32>,
    /// Each region pixel's place in the video's frames.
    at: Vec<(u32, u32)>,
    /// Frames × 40: the lips in reference-frame pixels.
    keys: Array2<f32>,
    /// Per frame, the next frame of its recording (`u32::MAX` at a recording's end).
    next: Vec<u32>,
}

/// Frames `first..end` of the store's video, from a sync frame on, and their detail once
/// decoded (or why it could not be).
#[derive(Clone, Debug)]
struct Piece {
    first: usize,
    end: usize,
    detail: std::sync::OnceLock<Result<Vec<i8>, String>>,
}

/// One output frame's detail: up to two recorded frames and their weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pick {
    /// `(kept frame, weight)`; a weight of 0 leaves the entry out.
    pub frames: [(u32, f32); 2],
}

/// The region [`crate::render::Edge::Articulators`] draws: mask-pixel indices with a
/// positive alpha.
fn region(model: &FaceModel) -> Result<Vec<u32>, MouthsError> {
    let alpha = crate::render::Edge::Articulators(crate::render::DEFAULT_FEATHER)
        .alpha(model)
        .unwrap_or_default();
    let pixels: Vec<u32> = (0..alpha.len() as u32)
        .filter(|&i| alpha[i as usize] > 0.0)
        .collect();
    if pixels.is_empty() || model.articulators().is_none() {
        return Err(MouthsError::Model(
            "the model has no lips and jaw to draw (an iBUG-68 model is needed)".into(),
        ));
    }
    Ok(pixels)
}

/// The even-sized rectangle around `pixels` of `model`'s reference frame.
fn window(model: &FaceModel, pixels: &[u32]) -> Window {
    let frame = &model.frame;
    let at = |i: u32| &frame.pixels[i as usize];
    let (x0, x1) = pixels.iter().fold((u32::MAX, 0), |(a, b), &i| (a.min(at(i).x), b.max(at(i).x)));
    let (y0, y1) = pixels.iter().fold((u32::MAX, 0), |(a, b), &i| (a.min(at(i).y), b.max(at(i).y)));
    let even = |n: u32| n + n % 2;
    Window {
        x: x0,
        y: y0,
        width: even(x1 - x0 + 1),
        height: even(y1 - y0 + 1),
    }
}

/// The lips of shape parameters `b_s` in reference-frame pixels, flat (x, y, x, y, …): the
/// selection key.
pub fn lip_key(model: &FaceModel, shape: &[f32]) -> Vec<f32> {
    let p = &model.placement;
    let placed = Similarity::new(p.scale, 0.0, p.offset[0], p.offset[1]);
    let points = model.shape.instance(&placed, shape).points;
    points[LIPS]
        .iter()
        .flat_map(|q| [q[0] as f32, q[1] as f32])
        .collect()
}

impl Mouths {
    /// Keeps about `budget` recorded frames of `codebook`'s sentences for `model` (their
    /// recordings found by `recording`, from a sentence's name), evenly spread over the
    /// codebook, into the folder `out`, then loads it. Each frame's face is where the
    /// codebook tracked it (pose and shape), so nothing is tracked again.
    pub fn build(
        model: &FaceModel,
        codebook: &Codebook,
        recording: impl Fn(&str) -> Option<PathBuf> + Sync,
        budget: usize,
        out: &Path,
        mut progress: impl FnMut(Progress),
    ) -> Result<Mouths, MouthsError> {
        let pixels = region(model)?;
        let window = window(model, &pixels);
        let layout = model.layout();
        codebook
            .layout
            .expect(layout)
            .map_err(|e| MouthsError::Model(e.to_string()))?;
        let sentences = &codebook.sentences;
        if sentences.is_empty() {
            return Err(MouthsError::Model("the codebook has no sentences to keep mouths of".into()));
        }
        let mean_len = sentences.iter().map(|s| s.frames.len()).sum::<usize>()
            / sentences.len().max(1);
        let count = budget.div_ceil(mean_len.max(1)).clamp(1, sentences.len().max(1));
        let chosen: Vec<usize> = (0..count).map(|k| k * sentences.len() / count).collect();
        let missing: Vec<&str> = chosen
            .iter()
            .map(|&i| sentences[i].name.as_str())
            .filter(|n| recording(n).is_none())
            .collect();
        if let Some(first) = missing.first() {
            return Err(MouthsError::Inconsistent {
                dir: out.into(),
                reason: format!(
                    "{} of the {count} sentences kept have no recording (e.g. {first}); give the folder of the codebook's videos",
                    missing.len()
                ),
            });
        }
        // Each kept sentence's frames, in the reference frame's window, and their own b_a.
        let (w, h) = (window.width, window.height);
        let stage = "keeping recorded mouths";
        progress(Progress { stage, done: 0, total: count });
        let kept: Vec<(Vec<RgbImage>, Vec<f32>)> = chosen
            .par_iter()
            .map(|&i| -> Result<_, MouthsError> {
                let s = &sentences[i];
                let path = recording(&s.name).expect("checked above");
                let mut source = Source::open(&path)?;
                let (mut images, mut b_a) = (Vec::new(), Vec::new());
                let mut texture = vec![0f32; model.frame.n_pixels() * 3];
                for t in 0..s.frames.len() {
                    let Some(image) = source.next_frame()? else {
                        break;
                    };
                    let params = s.frames.params(t);
                    let landmarks = model
                        .landmarks(params)
                        .map_err(|e| MouthsError::Model(e.to_string()))?;
                    // Sampled bicubically: the detail is resampled again when drawn, and two
                    // bilinear passes smooth away what a viewer (and the discriminator) sees.
                    let (frame, cubic) = (&model.frame, crate::warp::Sampling::Cubic);
                    crate::warp::to_reference_with(frame, &image, &landmarks.points, &mut texture, cubic)
                        .map_err(|e| MouthsError::Model(e.to_string()))?;
                    b_a.extend(model.appearance.project(&texture));
                    let mut crop = RgbImage::new(w, h);
                    for &p in &pixels {
                        let m = &model.frame.pixels[p as usize];
                        let o = 3 * p as usize;
                        let rgb = [0, 1, 2].map(|c| texture[o + c].round().clamp(0.0, 255.0) as u8);
                        crop.put_pixel(m.x - window.x, m.y - window.y, image::Rgb(rgb));
                    }
                    images.push(crop);
                }
                Ok((images, b_a))
            })
            .collect::<Result<_, _>>()?;
        progress(Progress { stage, done: count, total: count });
        let stretches: Vec<Stretch> = chosen
            .iter()
            .zip(&kept)
            .map(|(&i, k)| Stretch {
                name: sentences[i].name.clone(),
                frames: k.0.len(),
            })
            .collect();
        let frames: usize = stretches.iter().map(|s| s.frames).sum();
        let appearance: Vec<f32> = kept.iter().flat_map(|k| k.1.iter().copied()).collect();
        let appearance =
            Array2::from_shape_vec((frames, layout.appearance), appearance).expect("b_a per frame");
        let keys: Vec<f32> = chosen
            .iter()
            .zip(&stretches)
            .flat_map(|(&i, s)| {
                let f = &sentences[i].frames;
                (0..s.frames).flat_map(move |t| lip_key(model, f.params(t).shape))
            })
            .collect();
        let keys = Array2::from_shape_vec((frames, 2 * LIPS.len()), keys).expect("a key per frame");
        let manifest = Manifest {
            format: FORMAT.into(),
            version: MOUTHS_VERSION,
            model_hash: model.hash(),
            fps: codebook.fps,
            window,
            stretches,
        };
        // Written whole beside `out`, then swapped in: a store is never half old, half new.
        let io = |source| MouthsError::Io {
            path: out.into(),
            source,
        };
        crate::atomic::replace_dir(
            out,
            FORMAT,
            |dir| {
                let video = dir.join(VIDEO);
                let mp4_error = |source| VideoError::Mp4 {
                    path: out.join(VIDEO),
                    source,
                };
                let mut sink =
                    crate::mp4_file::Writer::create_with_qp(&video, w, h, codebook.fps, QP)
                        .map_err(mp4_error)?;
                for image in kept.iter().flat_map(|k| &k.0) {
                    sink.write(image).map_err(mp4_error)?;
                }
                sink.finish(&video, None).map_err(mp4_error)?;
                let npy_error = |e: npy::NpyError| MouthsError::Manifest(e.into());
                npy::write(&dir.join("appearance.npy"), appearance.view()).map_err(npy_error)?;
                npy::write(&dir.join("keys.npy"), keys.view()).map_err(npy_error)?;
                let json = serde_json::to_vec_pretty(&manifest).expect("mouths manifest serialises");
                crate::atomic::write_file(&dir.join(MANIFEST), &json).map_err(io)
            },
            io,
        )?;
        Mouths::load(out, model)
    }

    /// Loads the folder `dir` for `model` (its hash checked): the arrays, and the video's
    /// header checked against them; each piece of the video is decoded into its detail when a
    /// frame of it is first drawn ([`Mouths::detail`]).
    pub fn load(dir: &Path, model: &FaceModel) -> Result<Mouths, MouthsError> {
        Self::load_for(dir, model, &model.hash())
    }

    /// [`Mouths::load`] with the model's hash already taken (it reads every array of it).
    pub(crate) fn load_for(
        dir: &Path,
        model: &FaceModel,
        model_hash: &str,
    ) -> Result<Mouths, MouthsError> {
        let m: Manifest = manifest::read(&dir.join(MANIFEST), FORMAT, MOUTHS_VERSION)?;
        let inconsistent = |reason: String| MouthsError::Inconsistent {
            dir: dir.into(),
            reason,
        };
        if m.model_hash != model_hash {
            return Err(inconsistent(format!(
                "made for model {}, not this talker's {model_hash}",
                m.model_hash
            )));
        }
        let pixels = region(model)?;
        if window(model, &pixels) != m.window {
            return Err(inconsistent("the window differs from the model's region".into()));
        }
        let frames: usize = m.stretches.iter().map(|s| s.frames).sum();
        let n_a = model.layout().appearance;
        let appearance: Array2<f32> =
            manifest::read_array(dir, "appearance.npy", &[Some(frames), Some(n_a)])?;
        let keys: Array2<f32> =
            manifest::read_array(dir, "keys.npy", &[Some(frames), Some(2 * LIPS.len())])?;
        if keys.iter().chain(appearance.iter()).any(|v| !v.is_finite()) {
            return Err(inconsistent("an array holds a value that is not finite".into()));
        }
        let video = manifest::member(dir, VIDEO)?;
        let loaded = crate::atomic::identity(&video);
        let reader = Reader::open(&video).map_err(|source| VideoError::Mp4 {
            path: video.clone(),
            source,
        })?;
        if (reader.width, reader.height) != (m.window.width, m.window.height) {
            return Err(inconsistent(format!(
                "{VIDEO} is {}×{}, the manifest says {}×{}",
                reader.width, reader.height, m.window.width, m.window.height
            )));
        }
        if reader.frame_count() != frames {
            return Err(inconsistent(format!(
                "{VIDEO} has {} frames, the manifest {frames}",
                reader.frame_count()
            )));
        }
        // The model's luma over the region: mean and one row per component.
        let pca = &model.appearance.pca;
        let luma = |v: &[f32], p: u32| {
            let o = 3 * p as usize;
            crate::video::luma([v[o], v[o + 1], v[o + 2]].map(f64::from)) as f32
        };
        let luma: Vec<Vec<f32>> = std::iter::once(&pca.mean[..])
            .chain((0..n_a).map(|k| pca.component(k)))
            .map(|v| pixels.iter().map(|&p| luma(v, p)).collect())
            .collect();
        let syncs = reader.sync_frames();
        if frames > 0 && syncs.first() != Some(&0) {
            return Err(inconsistent(format!("{VIDEO} does not start with a sync frame")));
        }
        let mut firsts: Vec<usize> = syncs.into_iter().filter(|&f| f < frames).collect();
        firsts.sort_unstable();
        firsts.dedup();
        let pieces = firsts
            .iter()
            .enumerate()
            .map(|(k, &first)| Piece {
                first,
                end: firsts.get(k + 1).copied().unwrap_or(frames),
                detail: std::sync::OnceLock::new(),
            })
            .collect();
        let window = m.window;
        let at = pixels
            .iter()
            .map(|&p| {
                let q = &model.frame.pixels[p as usize];
                (q.x - window.x, q.y - window.y)
            })
            .collect();
        let mut next = Vec::with_capacity(frames);
        for s in &m.stretches {
            let start = next.len() as u32;
            next.extend((1..s.frames as u32).map(|k| start + k));
            if s.frames > 0 {
                next.push(u32::MAX);
            }
        }
        Ok(Mouths {
            model_hash: m.model_hash,
            fps: m.fps,
            stretches: m.stretches,
            window,
            gain: DETAIL_GAIN,
            pixels,
            loaded,
            video,
            pieces,
            luma,
            appearance,
            at,
            keys,
            next,
        })
    }

    /// Decodes `piece` of the video into its detail, from the file that was loaded.
    fn decode(&self, piece: &Piece) -> Result<Vec<i8>, String> {
        let changed = || {
            format!("{VIDEO} changed since the talker was loaded (load it again)")
        };
        if crate::atomic::identity(&self.video) != self.loaded {
            return Err(changed());
        }
        let mut reader = Reader::open(&self.video).map_err(|e| e.to_string())?;
        reader.seek(piece.first).map_err(|e| e.to_string())?;
        let (n, window) = (self.pixels.len(), self.window);
        let mut detail = vec![0i8; (piece.end - piece.first) * n];
        let mut model_luma = vec![0f32; n];
        for (k, out) in detail.chunks_exact_mut(n).enumerate() {
            let frame = piece.first + k;
            let image = reader
                .next_frame()
                .map_err(|e| e.to_string())?
                .ok_or_else(|| format!("{VIDEO} ends before frame {frame}"))?;
            if image.dimensions() != (window.width, window.height) {
                return Err(format!(
                    "{VIDEO}'s frame {frame} is {:?}, its header says {}×{}",
                    image.dimensions(),
                    window.width,
                    window.height
                ));
            }
            model_luma.copy_from_slice(&self.luma[0]);
            for (row, &bk) in self.luma[1..].iter().zip(self.appearance.row(frame).iter()) {
                model_luma.iter_mut().zip(row).for_each(|(o, &r)| *o += bk * r);
            }
            for ((o, &(x, y)), m) in out.iter_mut().zip(&self.at).zip(&model_luma) {
                let px = image.get_pixel(x, y).0;
                let y = crate::video::luma(px.map(f64::from)) as f32;
                *o = (y - m).round().clamp(-127.0, 127.0) as i8;
            }
        }
        if crate::atomic::identity(&self.video) != self.loaded {
            return Err(changed());
        }
        Ok(detail)
    }

    /// Frames kept.
    pub fn len(&self) -> usize {
        self.next.len()
    }

    /// Whether no frame is kept.
    pub fn is_empty(&self) -> bool {
        self.next.is_empty()
    }

    /// The detail of kept frame `k`, per region pixel: its piece of the video is decoded the
    /// first time (one thread decodes it, others asking wait for it) and kept.
    pub fn detail(&self, k: usize) -> Result<&[i8], MouthsError> {
        let inconsistent = |reason: String| MouthsError::Inconsistent {
            dir: self.video.parent().unwrap_or(Path::new("")).into(),
            reason,
        };
        let piece = (self.pieces.partition_point(|p| p.first <= k))
            .checked_sub(1)
            .map(|i| &self.pieces[i])
            .filter(|p| k < p.end)
            .ok_or_else(|| inconsistent(format!("no kept frame {k} (of {})", self.len())))?;
        let detail = piece.detail.get_or_init(|| self.decode(piece));
        let detail = detail.as_ref().map_err(|reason| inconsistent(reason.clone()))?;
        let n = self.pixels.len();
        Ok(&detail[(k - piece.first) * n..][..n])
    }

    /// `pick`'s detail as [`CpuRenderer::render_with`](crate::render::CpuRenderer::render_with)
    /// adds it to the model's texture.
    pub fn drawing<'a>(
        &'a self,
        pick: &'a Pick,
    ) -> impl FnOnce(&mut [f32]) -> Result<(), crate::render::RenderError> + 'a {
        move |texture| {
            self.add_detail(pick, texture)
                .map_err(|e| crate::render::RenderError::Detail(Box::new(e)))
        }
    }

    /// Adds `pick`'s detail to `texture` (mask pixels × RGB): the same luma step on each
    /// channel.
    pub fn add_detail(&self, pick: &Pick, texture: &mut [f32]) -> Result<(), MouthsError> {
        for &(k, w) in &pick.frames {
            if w == 0.0 {
                continue;
            }
            for (&p, &d) in self.pixels.iter().zip(self.detail(k as usize)?) {
                let o = 3 * p as usize;
                let step = self.gain * w * f32::from(d);
                texture[o..o + 3].iter_mut().for_each(|v| *v += step);
            }
        }
        Ok(())
    }

    /// Mean lip distance (pixels) of kept frame `k` to `key`.
    fn distance(&self, k: usize, key: &[f32]) -> f32 {
        let row = self.keys.row(k);
        let row = row.as_slice().expect("keys are contiguous");
        let sum: f32 = row
            .chunks_exact(2)
            .zip(key.chunks_exact(2))
            .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
            .sum();
        sum / LIPS.len() as f32
    }
}

/// Chooses, frame by frame, the recorded frames whose detail an output sequence takes (module
/// docs): the kept frame whose lips lie nearest the synthesised ones, unless the run playing
/// has a next frame within [`SWITCH_COST`] of that; on a change the old run's next frame
/// stays in at half weight for that one frame, so no edge of teeth or lips jumps whole.
/// Streaming: each frame depends only on the frames before it (a live session uses it as is).
#[derive(Clone, Debug)]
pub struct Chooser<'m> {
    mouths: &'m Mouths,
    model: &'m FaceModel,
    switch_cost: f32,
    playing: Option<u32>,
}

impl<'m> Chooser<'m> {
    /// A chooser over `mouths` for frames of `model`, leaving a run at [`SWITCH_COST`].
    pub fn new(mouths: &'m Mouths, model: &'m FaceModel) -> Self {
        Self::with_switch_cost(mouths, model, SWITCH_COST)
    }

    /// [`Chooser::new`] with another switch cost (pixels).
    pub fn with_switch_cost(mouths: &'m Mouths, model: &'m FaceModel, switch_cost: f32) -> Self {
        Chooser {
            mouths,
            model,
            switch_cost,
            playing: None,
        }
    }

    /// The detail of the next output frame, whose face is `params`.
    pub fn next(&mut self, params: FaceParams<'_>) -> Pick {
        let key = lip_key(self.model, params.shape);
        let m = self.mouths;
        let (best, best_d) = (0..m.len())
            .map(|k| (k as u32, m.distance(k, &key)))
            .fold((0, f32::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        let follow = self
            .playing
            .map(|k| m.next[k as usize])
            .filter(|&k| k != u32::MAX);
        match follow {
            Some(k) if k == best || m.distance(k as usize, &key) <= best_d + self.switch_cost => {
                self.playing = Some(k);
                Pick { frames: [(k, 1.0), (0, 0.0)] }
            }
            Some(k) => {
                self.playing = Some(best);
                Pick { frames: [(best, 0.5), (k, 0.5)] }
            }
            None => {
                self.playing = Some(best);
                Pick { frames: [(best, 1.0), (0, 0.0)] }
            }
        }
    }

    /// The recorded mouths it chooses from.
    pub fn mouths(&self) -> &'m Mouths {
        self.mouths
    }

    /// Forgets the run playing (after an interruption the next frame starts afresh).
    pub fn reset(&mut self) {
        self.playing = None;
    }
}
