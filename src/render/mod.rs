//! Renderers: face-space points → images (DESIGN §10).
//!
//! A [`Renderer`] draws one frame's face onto a caller's canvas (which holds the background);
//! [`CpuRenderer`] is the reference (the piecewise affine warp of [`crate::warp`]), drawing the
//! face with a hard edge or blending it in with a feathered one; a GPU renderer implements the
//! same trait. [`stream`] renders a whole sequence batch by batch over a [`Background`] while the
//! caller consumes the frames in order, so memory does not grow with the sequence.

mod composite;
pub mod scale;
#[cfg(feature = "gpu")]
pub mod gpu;

use std::ops::Range;
use std::path::PathBuf;
use std::sync::mpsc;

use image::{Rgb, RgbImage};
use rayon::prelude::*;
use thiserror::Error;

pub use composite::{DEFAULT_FEATHER, Edge, feather_alpha};

use crate::Progress;
use crate::facespace::{FaceParams, Frames};
use crate::model::{FaceModel, ModelError};
use crate::video::{Source, VideoError};
use crate::warp::{self, WarpError};

/// The grey drawn behind faces when no background is given.
pub const BACKGROUND: Rgb<u8> = Rgb([96, 96, 96]);

/// Frames rendered together (in parallel) before they are handed on.
pub const BATCH: usize = 32;

/// What can go wrong rendering.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The parameters do not fit the model.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The warp failed (e.g. non-finite landmarks).
    #[error("warp: {0}")]
    Warp(#[from] WarpError),
    /// The background video failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The detail added to the model's texture failed (the recorded mouths' video could not
    /// be decoded: [`CpuRenderer::render_with`]).
    #[error(transparent)]
    Detail(Box<dyn std::error::Error + Send + Sync>),
    /// The background video ended before the frames did.
    #[error("{path}: the background video has {frames} frames, fewer than the {needed} to render")]
    BackgroundTooShort {
        /// The video.
        path: PathBuf,
        /// Frames it has.
        frames: usize,
        /// Frames needed.
        needed: usize,
    },
    /// The GPU failed while rendering.
    #[cfg(feature = "gpu")]
    #[error(transparent)]
    Gpu(#[from] gpu::GpuError),
    /// `--renderer gpu` in a build without the `gpu` feature.
    #[cfg(not(feature = "gpu"))]
    #[error("this build has no GPU renderer (built without the `gpu` feature)")]
    NoGpuSupport,
    /// A canvas of another size than the background.
    #[error("{what} is {found:?}, the frames are {expected:?}")]
    Size {
        /// What differs.
        what: String,
        /// Its size.
        found: (u32, u32),
        /// The size expected.
        expected: (u32, u32),
    },
}

/// Draws faces from face-space points.
pub trait Renderer: Sync {
    /// The model whose faces are drawn.
    fn model(&self) -> &FaceModel;

    /// Draws one frame's face onto `canvas`, which holds its background.
    fn render_into(&self, params: FaceParams<'_>, canvas: &mut RgbImage)
    -> Result<(), RenderError>;

    /// Draws frame `t` of the sequence `frames` onto `canvas`: its point alone, unless the
    /// renderer draws a sequence ([`crate::mouths::SampledRenderer`]).
    fn render_frame(
        &self,
        frames: &Frames,
        t: usize,
        canvas: &mut RgbImage,
    ) -> Result<(), RenderError> {
        self.render_into(frames.params(t), canvas)
    }

    /// Draws frames `start..start + canvases.len()` of `frames` onto their canvases (the CPU
    /// renderers: rayon across frames).
    fn render_batch(
        &self,
        frames: &Frames,
        start: usize,
        canvases: &mut [RgbImage],
    ) -> Result<(), RenderError> {
        canvases
            .par_iter_mut()
            .enumerate()
            .try_for_each(|(k, canvas)| self.render_frame(frames, start + k, canvas))
    }

    /// What renders, for reports (e.g. "CPU", or a GPU adapter and backend).
    fn describe(&self) -> String {
        "CPU".into()
    }
}

/// The reference renderer on the CPU: the face drawn with a hard edge, or blended onto the
/// canvas by a feathered alpha warped with the texture (DESIGN §10 compositing).
#[derive(Clone, Debug)]
pub struct CpuRenderer<'m> {
    model: &'m FaceModel,
    /// Per mask pixel, for a feathered edge.
    alpha: Option<Vec<f32>>,
}

impl<'m> CpuRenderer<'m> {
    /// A renderer of `model`'s faces with a hard edge.
    pub fn new(model: &'m FaceModel) -> Self {
        CpuRenderer { model, alpha: None }
    }

    /// A renderer whose faces fade into the canvas over the last `feather` reference-frame
    /// pixels inside the mesh boundary ([`feather_alpha`]), so no seam shows.
    pub fn feathered(model: &'m FaceModel, feather: f64) -> Self {
        Self::with_edge(model, Edge::Feathered(feather))
    }

    /// A renderer whose faces meet the canvas as `edge` says.
    pub fn with_edge(model: &'m FaceModel, edge: Edge) -> Self {
        CpuRenderer {
            model,
            alpha: edge.alpha(model),
        }
    }

    /// The feathered alpha per mask pixel, if any.
    pub fn alpha(&self) -> Option<&[f32]> {
        self.alpha.as_deref()
    }
}

impl Renderer for CpuRenderer<'_> {
    fn model(&self) -> &FaceModel {
        self.model
    }

    fn render_into(
        &self,
        params: FaceParams<'_>,
        canvas: &mut RgbImage,
    ) -> Result<(), RenderError> {
        self.render_with(params, |_| Ok(()), canvas)
    }
}

impl CpuRenderer<'_> {
    /// [`Renderer::render_into`], with `detail` added to the model's texture (mask pixels ×
    /// RGB) before it is warped: how the recorded mouths, a layer above, draw their detail.
    pub fn render_with(
        &self,
        params: FaceParams<'_>,
        detail: impl FnOnce(&mut [f32]) -> Result<(), RenderError>,
        canvas: &mut RgbImage,
    ) -> Result<(), RenderError> {
        let mut r = self.model.reconstruct(params)?;
        detail(&mut r.texture)?;
        let (frame, points) = (&self.model.frame, &r.landmarks.points);
        match &self.alpha {
            Some(alpha) => {
                warp::from_reference_blend_into(frame, &r.texture, alpha, points, canvas)?
            }
            None => warp::from_reference_into(frame, &r.texture, points, canvas)?,
        }
        Ok(())
    }
}

/// Which renderer draws (`--renderer auto|gpu|cpu`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RendererChoice {
    /// A hardware GPU when one exists, else the CPU. A software adapter (Mesa's llvmpipe or
    /// lavapipe) is not used: it runs on the same cores as the CPU renderer, several times
    /// slower (BENCHMARKS.md).
    #[default]
    Auto,
    /// The GPU renderer on the best adapter found, software ones included; an error if there
    /// is none.
    Gpu,
    /// The CPU renderer.
    Cpu,
}

/// A renderer as chosen, with a note when it is not what was asked for or why the CPU draws.
pub struct ChosenRenderer<'m> {
    /// The renderer.
    pub renderer: Box<dyn Renderer + 'm>,
    /// Why the CPU renders under `Auto` (no adapter, or only a software one).
    pub note: Option<String>,
}

/// Makes the renderer `choice` names for `model`'s faces, meeting the canvas as `edge` says
/// (`None`: a hard edge; `Some(f)`: feathered over `f` pixels; or an [`Edge`]). Only
/// [`RendererChoice::Gpu`] can fail for want of a GPU.
pub fn choose_renderer<'m>(
    choice: RendererChoice,
    model: &'m FaceModel,
    edge: impl Into<Edge>,
) -> Result<ChosenRenderer<'m>, RenderError> {
    let feather = edge.into();
    let cpu = || -> Box<dyn Renderer + 'm> { Box::new(CpuRenderer::with_edge(model, feather)) };
    let chosen = |renderer, note| Ok(ChosenRenderer { renderer, note });
    match choice {
        RendererChoice::Cpu => chosen(cpu(), None),
        #[cfg(feature = "gpu")]
        RendererChoice::Gpu => {
            let gpu = gpu::Gpu::new(gpu::Backends::Any)?;
            chosen(Box::new(gpu::GpuRenderer::new(&gpu, model, feather)?), None)
        }
        #[cfg(not(feature = "gpu"))]
        RendererChoice::Gpu => Err(RenderError::NoGpuSupport),
        #[cfg(feature = "gpu")]
        RendererChoice::Auto => match gpu::Gpu::new(gpu::Backends::Any) {
            Ok(g) if g.is_software() => chosen(
                cpu(),
                Some(format!(
                    "the only GPU adapter is {}, a software one, slower than the CPU renderer: rendering on the CPU (--renderer gpu uses it)",
                    g.describe()
                )),
            ),
            Ok(g) => match gpu::GpuRenderer::new(&g, model, feather) {
                Ok(r) => chosen(Box::new(r), None),
                Err(e) => chosen(cpu(), Some(format!("{e}: rendering on the CPU"))),
            },
            Err(e) => chosen(cpu(), Some(format!("{e}: rendering on the CPU"))),
        },
        #[cfg(not(feature = "gpu"))]
        RendererChoice::Auto => chosen(
            cpu(),
            Some("built without the gpu feature: rendering on the CPU".into()),
        ),
    }
}

/// What faces are drawn over.
pub enum Background {
    /// A flat [`BACKGROUND`] canvas of this size.
    Plain {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// The same image behind every frame.
    Still(RgbImage),
    /// The frames of a video, one per rendered frame.
    Video(Box<Source>),
    /// Frames held in memory, played forwards then backwards
    /// ([`ping_pong`]) for as long as there are frames to render.
    Loop {
        /// The frames (at least one).
        frames: Vec<RgbImage>,
        /// Rendered frames handed out so far.
        next: usize,
    },
    /// Frames made as they are shown (a talker's living frame: stretches of its footage).
    Frames(Box<dyn FrameSource>),
}

/// Frames a [`Background`] plays one after another, made as they are shown: what a layer
/// above (a talker's footage) gives the renderer without the renderer knowing it.
pub trait FrameSource: Send {
    /// The size of every frame.
    fn size(&self) -> (u32, u32);
    /// The next frame.
    fn next_frame(&mut self) -> Result<RgbImage, RenderError>;
}

impl Background {
    /// A plain canvas large enough for every frame's face (pose included), with even sides
    /// for 4:2:0 video.
    pub fn plain_for(model: &FaceModel, frames: &Frames) -> Background {
        let (mut w, mut h) = (16.0f64, 16.0f64);
        for p in frames.iter() {
            if let Ok(l) = model.landmarks(p) {
                let (_, hi) = l.bounds();
                w = w.max(hi[0] + 20.0);
                h = h.max(hi[1] + 20.0);
            }
        }
        let even = |v: f64| ((v.min(4096.0).ceil() as u32) + 1) & !1;
        Background::Plain {
            width: even(w),
            height: even(h),
        }
    }

    /// The size of every canvas.
    pub fn size(&self) -> (u32, u32) {
        match self {
            Background::Plain { width, height } => (*width, *height),
            Background::Still(image) => image.dimensions(),
            Background::Video(source) => (source.info().width, source.info().height),
            Background::Loop { frames, .. } => frames.first().map_or((0, 0), |f| f.dimensions()),
            Background::Frames(source) => source.size(),
        }
    }

    /// The canvases of the next `n` frames (`needed` in all, for the error message).
    pub(crate) fn canvases(
        &mut self,
        n: usize,
        needed: usize,
    ) -> Result<Vec<RgbImage>, RenderError> {
        Ok(match self {
            Background::Plain { width, height } => {
                vec![RgbImage::from_pixel(*width, *height, BACKGROUND); n]
            }
            Background::Still(image) => vec![image.clone(); n],
            Background::Video(source) => (0..n)
                .map(|_| {
                    source
                        .next_frame()?
                        .ok_or_else(|| RenderError::BackgroundTooShort {
                            path: source.path().into(),
                            frames: source.frames_read(),
                            needed,
                        })
                })
                .collect::<Result<_, _>>()?,
            Background::Frames(source) => (0..n)
                .map(|_| source.next_frame())
                .collect::<Result<_, _>>()?,
            Background::Loop { frames, next } => {
                let out = (*next..*next + n)
                    .map(|t| frames[ping_pong(t, frames.len())].clone())
                    .collect();
                *next += n;
                out
            }
        })
    }
}

/// Runs `produce` over batches of `0..total` on a worker thread while this thread hands each
/// item of the previous batch to `consume`, in order: rendering in parallel overlaps the
/// sequential consumer (a video encoder, say). Stops at the first error of either side.
pub fn pipeline<T: Send, E: Send>(
    total: usize,
    mut produce: impl FnMut(Range<usize>) -> Result<Vec<T>, E> + Send,
    mut consume: impl FnMut(T) -> Result<(), E>,
    mut progress: impl FnMut(Progress),
) -> Result<(), E> {
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::sync_channel::<Result<Vec<T>, E>>(1);
        scope.spawn(move || {
            let mut done = 0;
            while done < total {
                let end = (done + BATCH).min(total);
                let batch = produce(done..end);
                let failed = batch.is_err();
                if tx.send(batch).is_err() || failed {
                    break;
                }
                done = end;
            }
        });
        let mut done = 0;
        for batch in rx {
            for item in batch? {
                consume(item)?;
                done += 1;
            }
            progress(Progress {
                stage: "rendering",
                done,
                total,
            });
        }
        Ok(())
    })
}

/// Renders every frame of `frames` over `background` (batches in parallel on a worker
/// thread) and hands each image to `consume`, in order.
pub fn stream<E: Send + From<RenderError>>(
    renderer: &dyn Renderer,
    frames: &Frames,
    mut background: Background,
    consume: impl FnMut(RgbImage) -> Result<(), E>,
    progress: impl FnMut(Progress),
) -> Result<(), E> {
    let total = frames.len();
    pipeline(
        total,
        |range| {
            let mut canvases = background.canvases(range.len(), total)?;
            renderer.render_batch(frames, range.start, &mut canvases)?;
            Ok(canvases)
        },
        consume,
        progress,
    )
}

/// Every frame of `frames` rendered over `background`, in memory (for measuring what a viewer
/// sees before any video encoding; [`stream`] for anything long).
pub fn images(
    renderer: &dyn Renderer,
    frames: &Frames,
    background: Background,
) -> Result<Vec<RgbImage>, RenderError> {
    let mut out = Vec::with_capacity(frames.len());
    stream(
        renderer,
        frames,
        background,
        |image| -> Result<(), RenderError> {
            out.push(image);
            Ok(())
        },
        crate::no_progress,
    )?;
    Ok(out)
}

/// Index of frame `t` in a sequence of `n` played forwards, then backwards, and so on
/// (`0, 1, …, n−1, n−2, …, 1, 0, 1, …`), so a loop of background frames never jumps.
pub fn ping_pong(t: usize, n: usize) -> usize {
    if n <= 1 {
        return 0;
    }
    let period = 2 * n - 2;
    let i = t % period;
    if i < n { i } else { period - i }
}
