//! `study create`: every held-out sentence rendered under every condition, and each viewer's
//! randomised, counter-balanced order of trials.

use std::collections::hash_map::RandomState;
use std::hash::{BuildHasher, Hasher};
use std::path::{Path, PathBuf};

use super::{
    Condition, FORMAT, MANIFEST, Manifest, STIMULI, Stimulus, StudyError, Task, Trial, VERSION,
    Viewer,
};
use crate::codebook::Codebook;
use crate::corpus::{self, Sentence};
use crate::facespace::Frames;
use crate::model::FaceModel;
use crate::phonemes::PhoneMap;
use crate::render::{self, Background, Renderer};
use crate::rng::Rng;
use crate::synth::blend::Blend;
use crate::synth::output::OutputError;
use crate::synth::random::RandomLips;
use crate::synth::unit::UnitSelection;
use crate::synth::{Pose, Request, Smoothing, Synthesiser, synthesise};
use crate::video::Sink;
use crate::{Progress, atomic, options};

/// The face's extent (the larger side of its landmarks' box over the sentence) as a share of
/// the stimulus's side: room for the forehead, hair and neck around it.
pub const FACE_SHARE: f64 = 0.6;

/// A held-out sentence and its sound, if any.
#[derive(Clone, Debug)]
pub struct Heldout {
    /// The sentence (its tracked frames and phone timings).
    pub sentence: Sentence,
    /// `NAME.m4a` beside it, or the clip folder's `audio.m4a`.
    pub audio: Option<PathBuf>,
    /// `NAME.mp4` beside it: the recording it was tracked from, drawn behind every condition.
    pub video: Option<PathBuf>,
}

/// Reads the held-out sentences of `dir` (as `corpus` reads a corpus) with their sound, and
/// refuses any the codebook holds: synthesis would copy it.
pub fn load_heldout(
    dir: &Path,
    codebook: &Codebook,
    model_hash: &str,
) -> Result<Vec<Heldout>, StudyError> {
    let sentences = corpus::load_checked(
        dir,
        codebook.fps,
        codebook.layout,
        Some(model_hash),
        None,
        &PhoneMap::default(),
        corpus::DEFAULT_TOLERANCE,
    )
    .map_err(|e| StudyError::Design(format!("reading held-out sentences: {e}")))?;
    sentences
        .into_iter()
        .map(|sentence| {
            if codebook.sentences.iter().any(|s| s.name == sentence.name) {
                return Err(StudyError::Design(format!(
                    "held-out sentence {} is also in the codebook: its synthesis would copy the original; hold it out of the codebook",
                    sentence.name
                )));
            }
            let audio = [
                dir.join(format!("{}.m4a", sentence.name)),
                dir.join(format!("{}.fsp", sentence.name)).join("audio.m4a"),
            ]
            .into_iter()
            .find(|p| p.is_file());
            let video = Some(dir.join(format!("{}.mp4", sentence.name))).filter(|p| p.is_file());
            Ok(Heldout {
                sentence,
                audio,
                video,
            })
        })
        .collect()
}

/// What [`create`] makes.
#[derive(Clone, Debug)]
pub struct CreateOptions {
    /// The conditions (at least two, no repeats).
    pub conditions: Vec<Condition>,
    /// Viewers (1 … 1000), each with their own order and link.
    pub viewers: usize,
    /// The tests.
    pub task: Task,
    /// Smoothing weight λ of every smoothed condition (choose it on a validation split).
    pub smoothing: f64,
    /// Unit selection's weights.
    pub unit: UnitSelection,
    /// Seed of the orders and stimulus ids.
    pub seed: u64,
}

/// The rated pairs: the reference (the original when there is one, else the first condition)
/// with every other condition, and smoothed with unsmoothed when both are there.
pub fn pairs(conditions: &[Condition]) -> Vec<(Condition, Condition)> {
    let Some(&first) = conditions.first() else {
        return Vec::new();
    };
    let reference = if conditions.contains(&Condition::Original) {
        Condition::Original
    } else {
        first
    };
    let mut out: Vec<(Condition, Condition)> = conditions
        .iter()
        .filter(|&&c| c != reference)
        .map(|&c| (reference, c))
        .collect();
    let ab = (Condition::Smoothed, Condition::Unsmoothed);
    if conditions.contains(&ab.0) && conditions.contains(&ab.1) && !out.contains(&ab) {
        out.push(ab);
    }
    out
}

/// Shuffles in place (Fisher–Yates).
fn shuffle<T>(items: &mut [T], rng: &mut Rng) {
    for i in (1..items.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        items.swap(i, j);
    }
}

/// One viewer's trials: the Turing block (every stimulus once, shuffled) and then the rating
/// block (every sentence × pair in both orders, shuffled, never a pair right after its mirror).
pub fn trials(
    stimuli: &[Stimulus],
    sentences: &[String],
    pairs: &[(Condition, Condition)],
    task: Task,
    rng: &mut Rng,
) -> Vec<Trial> {
    let id = |sentence: &str, c: Condition| {
        stimuli
            .iter()
            .find(|s| s.sentence == sentence && s.condition == c)
            .map(|s| s.id.clone())
            .expect("every sentence is rendered under every condition")
    };
    let mut out = Vec::new();
    if task != Task::Rating {
        let mut judge: Vec<Trial> = stimuli
            .iter()
            .map(|s| Trial::Judge {
                stimulus: s.id.clone(),
            })
            .collect();
        shuffle(&mut judge, rng);
        out.extend(judge);
    }
    if task != Task::Turing {
        let mut rate = Vec::new();
        for s in sentences {
            for &(a, b) in pairs {
                let (a, b) = (id(s, a), id(s, b));
                rate.push(Trial::Rate {
                    first: a.clone(),
                    second: b.clone(),
                });
                rate.push(Trial::Rate {
                    first: b,
                    second: a,
                });
            }
        }
        shuffle(&mut rate, rng);
        // Move a trial that repeats the previous pair (mirrored) to a later place.
        for i in 1..rate.len() {
            let same = |x: &Trial, y: &Trial| {
                let (mut p, mut q) = (x.stimuli(), y.stimuli());
                p.sort();
                q.sort();
                p == q
            };
            if same(&rate[i - 1], &rate[i])
                && let Some(j) = (i + 1..rate.len())
                    .find(|&j| !same(&rate[i - 1], &rate[j]) && !same(&rate[j], &rate[i]))
            {
                rate.swap(i, j);
            }
        }
        out.extend(rate);
    }
    out
}

/// A secret for a viewer's link: 128 bits from the standard library's randomly keyed hasher
/// (not derived from the seed, which the manifest records).
fn secret() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    (0..2u64)
        .map(|i| {
            let mut h = RandomState::new().build_hasher();
            h.write_u64(i);
            h.write_u128(nanos);
            h.write_u32(std::process::id());
            format!("{:016x}", h.finish())
        })
        .collect()
}

/// The synthesiser and smoothing of a synthetic condition.
fn synthesiser(c: Condition, options: &CreateOptions) -> (Box<dyn Synthesiser>, Smoothing) {
    let on = Smoothing::On(options.smoothing);
    match c {
        Condition::Blend(n) => (
            Box::new(Blend {
                top_n: n,
                ..Blend::default()
            }),
            on,
        ),
        Condition::RandomLips => (Box::new(RandomLips { seed: options.seed }), on),
        Condition::Unit => (Box::new(options.unit), on),
        Condition::Unsmoothed => (Box::new(Blend::default()), Smoothing::Off),
        Condition::Smoothed | Condition::Original => (Box::new(Blend::default()), on),
    }
}

/// The frames of `sentence` under condition `c`: its own trajectory for the original, else
/// synthesised from its phone timings with its own head poses replayed (so only the
/// articulation differs between conditions).
fn condition_frames(
    c: Condition,
    sentence: &Sentence,
    codebook: &Codebook,
    options: &CreateOptions,
) -> Result<Frames, StudyError> {
    if c == Condition::Original {
        return Ok(sentence.frames.clone());
    }
    let (synth, smoothing) = synthesiser(c, options);
    let request = Request {
        pose: Pose::Replay(sentence.frames.iter().map(|p| p.pose).collect()),
        ..Request::new(sentence.segments.clone(), codebook.fps, smoothing)
    };
    let synth_error = |source| StudyError::Synth {
        sentence: sentence.name.clone(),
        condition: c,
        source: Box::new(source),
    };
    let u = synthesise(synth.as_ref(), codebook, request).map_err(synth_error)?;
    Ok(u.variants()[0].1.clone())
}

/// Checks the options before any work.
fn check(options: &CreateOptions, heldout: &[Heldout]) -> Result<(), StudyError> {
    let design = |m: String| Err(StudyError::Design(m));
    let c = &options.conditions;
    if c.len() < 2 {
        return design(format!(
            "{} condition(s): a study compares at least two",
            c.len()
        ));
    }
    if let Some(dup) = c.iter().find(|x| c.iter().filter(|y| y == x).count() > 1) {
        return design(format!("condition {dup} given twice"));
    }
    if options.task != Task::Rating && !c.contains(&Condition::Original) {
        return design(
            "the Turing test asks \"real or synthetic?\": it needs the original among the conditions (or --task rating)".into(),
        );
    }
    if heldout.is_empty() {
        return design("no held-out sentences".into());
    }
    options::count_in("viewers", options.viewers, 1, 1000)
        .map_err(|e| StudyError::Design(e.to_string()))?;
    options::in_range("smoothing λ", options.smoothing, 0.0, f64::MAX)
        .map_err(|e| StudyError::Design(e.to_string()))?;
    Ok(())
}

/// Renders every held-out sentence under every condition into `dir/stimuli/ID.mp4` (sound
/// muxed when the sentence has it; one canvas size for all, so size gives nothing away) and
/// writes `study.json` with each viewer's order. The folder is built beside `dir` and swapped
/// in whole; a folder facespace did not write, or one holding answers, is never replaced.
pub fn create(
    dir: &Path,
    model: &FaceModel,
    codebook: &Codebook,
    heldout: &[Heldout],
    renderer: &dyn Renderer,
    options: &CreateOptions,
    mut progress: impl FnMut(Progress),
) -> Result<Manifest, StudyError> {
    check(options, heldout)?;
    let mut rng = Rng::new(options.seed);
    let mut planned: Vec<(Stimulus, Frames, usize)> = Vec::new();
    for (index, h) in heldout.iter().enumerate() {
        for &c in &options.conditions {
            let frames = condition_frames(c, &h.sentence, codebook, options)?;
            let id = loop {
                let id = format!("{:08x}", rng.next_u64() as u32);
                if planned.iter().all(|p| p.0.id != id) {
                    break id;
                }
            };
            let stimulus = Stimulus {
                id,
                sentence: h.sentence.name.clone(),
                condition: c,
                frames: frames.len(),
                audio: h.audio.is_some(),
            };
            planned.push((stimulus, frames, index));
        }
    }
    let over_recordings = !heldout.is_empty() && heldout.iter().all(|h| h.video.is_some());
    let faces: Vec<FaceBox> = heldout
        .iter()
        .map(|h| FaceBox::of(model, &h.sentence.frames))
        .collect();
    let side = faces.iter().map(|f| f.extent).fold(16.0, f64::max) / FACE_SHARE;
    let even = |v: f64| ((v.ceil() as u32) + 1) & !1;
    let (mut width, mut height) = (even(side), even(side));
    if over_recordings {
        // Never wider or taller than the recordings themselves.
        for h in heldout {
            if let Some(v) = &h.video {
                let source = crate::video::Source::open(v)
                    .map_err(|e| StudyError::Design(format!("{}: {e}", v.display())))?;
                let info = source.info();
                width = width.min(info.width & !1);
                height = height.min(info.height & !1);
            }
        }
    }
    let stimuli: Vec<Stimulus> = planned.iter().map(|p| p.0.clone()).collect();
    let sentences: Vec<String> = heldout.iter().map(|h| h.sentence.name.clone()).collect();
    let pairs = pairs(&options.conditions);
    let viewers = (1..=options.viewers)
        .map(|v| Viewer {
            id: format!("v{v:02}"),
            token: secret(),
            trials: trials(&stimuli, &sentences, &pairs, options.task, &mut rng),
        })
        .collect();
    let manifest = Manifest {
        format: FORMAT.into(),
        version: VERSION,
        task: options.task,
        conditions: options.conditions.clone(),
        pairs,
        sentences,
        smoothing: options.smoothing,
        seed: options.seed,
        fps: codebook.fps,
        model_hash: model.hash(),
        stimuli,
        canvas: [width, height],
        over_recordings,
        viewers,
    };
    let io = |source| StudyError::Io {
        path: dir.into(),
        source,
    };
    atomic::replace_dir(
        dir,
        "study",
        |staged| {
            let folder = staged.join(STIMULI);
            std::fs::create_dir(&folder).map_err(io)?;
            for (i, (stimulus, frames, index)) in planned.iter().enumerate() {
                let h = &heldout[*index];
                let behind = Behind {
                    video: h.video.as_deref().filter(|_| over_recordings),
                    face: faces[*index],
                    size: (width, height),
                };
                progress(Progress {
                    stage: "rendering stimuli",
                    done: i,
                    total: planned.len(),
                });
                let path = folder.join(stimulus.file_name());
                render_clip(&path, renderer, frames, &behind, h.audio.as_deref()).map_err(
                    |source| StudyError::Render {
                        path,
                        source: Box::new(source),
                    },
                )?;
            }
            let json = serde_json::to_vec_pretty(&manifest).expect("the manifest serialises");
            atomic::write_file(&staged.join(MANIFEST), &json).map_err(io)
        },
        io,
    )?;
    Ok(manifest)
}

/// Where a sentence's face lies: the centre and larger side of its landmarks' box over
/// every frame of its tracked trajectory.
#[derive(Clone, Copy, Debug)]
struct FaceBox {
    centre: [f64; 2],
    extent: f64,
}

impl FaceBox {
    fn of(model: &FaceModel, frames: &Frames) -> FaceBox {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in frames.iter() {
            if let Ok(l) = model.landmarks(p) {
                let (a, b) = l.bounds();
                for k in 0..2 {
                    lo[k] = lo[k].min(a[k]);
                    hi[k] = hi[k].max(b[k]);
                }
            }
        }
        if !(lo[0].is_finite() && hi[0].is_finite()) {
            return FaceBox {
                centre: [0.0, 0.0],
                extent: 16.0,
            };
        }
        FaceBox {
            centre: [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
            extent: (hi[0] - lo[0]).max(hi[1] - lo[1]),
        }
    }
}

/// What a stimulus is drawn over and which window of it is kept.
struct Behind<'a> {
    /// The sentence's recording, or none for plain grey.
    video: Option<&'a Path>,
    /// Its face, which the window centres.
    face: FaceBox,
    /// The window, width × height.
    size: (u32, u32),
}

/// Renders `frames` over their recording (replayed forwards then backwards if the frames
/// outlast it) or a plain canvas, keeps the window of `behind.size` centred on the face
/// (inside the frame), and writes it as an MP4 at `path`.
fn render_clip(
    path: &Path,
    renderer: &dyn Renderer,
    frames: &Frames,
    behind: &Behind<'_>,
    audio: Option<&Path>,
) -> Result<(), OutputError> {
    let background = match behind.video {
        Some(video) => {
            let images = crate::video::Source::open(video)?.collect::<Result<Vec<_>, _>>()?;
            if images.is_empty() {
                return Err(crate::video::VideoError::NoFrames(video.into()).into());
            }
            Background::Loop {
                frames: images,
                next: 0,
            }
        }
        None => {
            let (w, h) = Background::plain_for(renderer.model(), frames).size();
            Background::Plain {
                width: w.max(behind.size.0),
                height: h.max(behind.size.1),
            }
        }
    };
    let (full_w, full_h) = background.size();
    let (width, height) = (behind.size.0.min(full_w), behind.size.1.min(full_h));
    let corner = |centre: f64, side: u32, full: u32| {
        (centre - f64::from(side) / 2.0)
            .round()
            .clamp(0.0, f64::from(full - side)) as u32
    };
    let (x0, y0) = (
        corner(behind.face.centre[0], width, full_w),
        corner(behind.face.centre[1], height, full_h),
    );
    let mut sink = Sink::create(path, width, height, frames.fps(), audio)?;
    render::stream(
        renderer,
        frames,
        background,
        |image| {
            let window = image::imageops::crop_imm(&image, x0, y0, width, height).to_image();
            Ok::<(), OutputError>(sink.write(&window)?)
        },
        |_| {},
    )?;
    sink.finish()?;
    Ok(())
}
