//! Idle footage: the talker's own recorded frames, tracked once when the talker is built, from
//! which every utterance takes a *living frame* — stretches of real video joined where the
//! frames match (\[graph\]: captured footage played back and joined where frames match;
//! \[unitsel\]'s background sequences), never played backwards, as long as the speech. The
//! synthesis then replaces only the lips and jaw, so blinks, eyes and head motion are the
//! footage's own.
//!
//! The folder: the clips (`NAME.mp4`, as recorded), `footage.json`, `landmarks.npy` (frames ×
//! landmarks × 2: every frame's tracked landmarks, clip after clip), `tracked.npy` (frames ×
//! face-space: pose ‖ shape ‖ appearance in the talker model's space) and `distance.npy`
//! (frames × frames: mean absolute grey difference of quarter-size frames, the join cost).

use std::path::{Path, PathBuf};

use image::RgbImage;
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::codec::{self, CodecError, EncodeOptions};
use crate::facespace::{Frames, Layout};
use crate::manifest::{self, ManifestError};
use crate::model::FaceModel;
use crate::shape::{Landmarks, Similarity};
use crate::video::{Source, VideoError};
use crate::{Progress, npy};

/// The footage folder format this build writes and reads.
pub const FOOTAGE_VERSION: u32 = 1;
const FORMAT: &str = "facespace-footage";
const MANIFEST: &str = "footage.json";

/// Footage shorter than this is refused: a second of video holds no blink and barely any
/// head motion to live on.
pub const MIN_SECONDS: f64 = 1.0;

/// The shortest stretch played between joins, in seconds: a jump every few frames would show
/// as jitter however well each join matches.
pub const MIN_RUN_SECONDS: f64 = 1.0;

/// What each frame shown again costs a join, in the footage's median steps: more than joins
/// between takes cost (GRID s1: 2–9 steps), so an utterance shorter than the footage never
/// shows a frame twice (a repeated blink is noticed), and a longer one tours it before
/// repeating as little as it can.
pub const REPEAT_COST: f32 = 10.0;

/// Frames over which two stretches dissolve into each other: a join between takes whose head
/// lies a pixel apart moves the picture by a sixth of that per frame, about a recorded step.
pub const DISSOLVE_FRAMES: usize = 6;

/// Most frames the join-cost matrix is built over (`distance.npy` is frames², 4 bytes each:
/// 64 MiB at this many).
pub const MAX_FRAMES: usize = 4096;

/// Frames are compared at this fraction of their size (a 4 × 4 box average): head motion and
/// blinks show, sensor noise mostly averages away.
const THUMB: u32 = 4;

/// What can go wrong with footage.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FootageError {
    /// The manifest or an array is missing, damaged or of another version.
    #[error("footage: {0}")]
    Manifest(#[from] ManifestError),
    /// A clip could not be read.
    #[error("footage: {0}")]
    Video(#[from] VideoError),
    /// A clip could not be tracked.
    #[error("footage: tracking: {0}")]
    Track(#[from] CodecError),
    /// Too little footage.
    #[error(
        "footage: {seconds:.2} s of video; at least {MIN_SECONDS} s is needed (give longer clips of the talker)"
    )]
    TooShort {
        /// How long it is.
        seconds: f64,
    },
    /// Too much footage for the join-cost matrix.
    #[error("footage: {frames} frames; at most {MAX_FRAMES} are used (give fewer clips)")]
    TooLong {
        /// How many frames.
        frames: usize,
    },
    /// The parts disagree with each other or with the talker's model.
    #[error("footage {dir}: {reason}")]
    Inconsistent {
        /// The folder.
        dir: PathBuf,
        /// What disagrees.
        reason: String,
    },
    /// A file could not be copied or written.
    #[error("footage {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// One recorded clip of the footage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Clip {
    /// Its file in the footage folder.
    pub file: String,
    /// Its frames (all tracked).
    pub frames: usize,
}

/// `footage.json`.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    fps: f64,
    width: u32,
    height: u32,
    model_hash: String,
    layout: Layout,
    landmarks: usize,
    clips: Vec<Clip>,
}

/// The talker's idle footage, tracked (module docs).
#[derive(Clone, Debug)]
pub struct Footage {
    /// The folder holding the clips.
    pub dir: PathBuf,
    /// The clips, in order; frame `g` of the footage is frame `g − start` of the clip holding it.
    pub clips: Vec<Clip>,
    /// Frames per second (every clip's).
    pub fps: f64,
    /// Frame size (every clip's).
    pub size: (u32, u32),
    /// [`FaceModel::hash`] of the model `tracked` is in.
    pub model_hash: String,
    /// Every frame's tracked landmarks.
    pub landmarks: Vec<Landmarks>,
    /// Every frame's face-space point (pose ‖ shape ‖ appearance).
    pub tracked: Frames,
    /// Join cost between frames: mean absolute grey difference at quarter size.
    pub distance: Array2<f32>,
}

/// A living frame: which footage frame is shown at each output frame, and where stretches
/// join.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Plan {
    /// Footage frame per output frame (during a dissolve, the stretch being left).
    pub frames: Vec<usize>,
    /// Per output frame, during a dissolve: the frame of the stretch being entered and its
    /// weight (the rest is `frames`' own).
    pub mix: Vec<Option<(usize, f32)>>,
    /// Output frames where a dissolve starts.
    pub joins: Vec<usize>,
    /// The cost of each join: [`Footage::distance`] between the two stretches averaged over
    /// its dissolve.
    pub join_costs: Vec<f32>,
    /// The footage's median cost between consecutive frames, for scale.
    pub median_step: f32,
}

impl Plan {
    /// Shows `len` frames from footage frame `from` on, unmixed.
    fn push_run(&mut self, from: usize, len: usize) {
        self.frames.extend(from..from + len);
        self.mix.extend(std::iter::repeat_n(None, len));
    }

    /// Whether output frame `t` shows one real frame, whole.
    pub fn is_pure(&self, t: usize) -> bool {
        self.mix.get(t).is_some_and(Option::is_none)
    }
}

impl Footage {
    /// Frames in all clips.
    pub fn len(&self) -> usize {
        self.landmarks.len()
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.landmarks.is_empty()
    }

    /// (clip, frame within it) of footage frame `g`.
    pub fn locate(&self, g: usize) -> (usize, usize) {
        let mut start = 0;
        for (c, clip) in self.clips.iter().enumerate() {
            if g < start + clip.frames {
                return (c, g - start);
            }
            start += clip.frames;
        }
        (self.clips.len().saturating_sub(1), g.saturating_sub(start))
    }

    /// The first footage frame of each clip, and one past the last frame.
    fn clip_starts(&self) -> Vec<usize> {
        let mut starts = vec![0];
        for c in &self.clips {
            starts.push(starts.last().copied().unwrap_or(0) + c.frames);
        }
        starts
    }

    /// The pose of footage frame `g`.
    pub fn pose(&self, g: usize) -> Similarity {
        self.tracked.params(g).pose
    }

    /// The path of clip `c`.
    pub fn clip_path(&self, c: usize) -> PathBuf {
        self.dir.join(&self.clips[c].file)
    }

    /// Tracks `clips` (videos of the talker, every one at the same frame rate and size) with
    /// `model` and writes the footage folder `out` (module docs), copying the clips in.
    pub fn build(
        model: &FaceModel,
        clips: &[PathBuf],
        out: &Path,
        mut progress: impl FnMut(Progress),
    ) -> Result<Footage, FootageError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| FootageError::Io { path, source }
        };
        let dims = model.layout().dims();
        let (mut listed, mut landmarks, mut rows, mut thumbs) =
            (Vec::new(), Vec::new(), Vec::<f32>::new(), Vec::new());
        let (mut fps, mut size) = (None, None);
        for (k, path) in clips.iter().enumerate() {
            let source = Source::open(path)?;
            let info = source.info();
            let here = (info.fps, (info.width, info.height));
            match (fps, size) {
                (Some(f), Some(s)) if (f, s) != here => {
                    return Err(FootageError::Inconsistent {
                        dir: out.into(),
                        reason: format!(
                            "{} is {}×{} at {} fps, the first clip {}×{} at {f} fps; give clips of one recording set-up",
                            path.display(),
                            here.1.0,
                            here.1.1,
                            here.0,
                            s.0,
                            s.1
                        ),
                    });
                }
                _ => (fps, size) = (Some(here.0), Some(here.1)),
            }
            let mut n = 0;
            codec::track(
                model,
                source,
                &EncodeOptions::default(),
                |p| {
                    progress(Progress {
                        stage: "tracking the footage",
                        done: k * 1000 + p.done.min(999),
                        total: clips.len() * 1000,
                    })
                },
                |image, t| {
                    let start = rows.len();
                    rows.resize(start + dims, 0.0);
                    model.project_into(&image, &t.landmarks, &mut rows[start..])?;
                    landmarks.push(t.landmarks.clone());
                    thumbs.push(thumbnail(&image));
                    n += 1;
                    Ok(())
                },
            )?;
            let name = path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| format!("clip{k}.mp4"));
            listed.push(Clip {
                file: format!("{k:03}-{name}"),
                frames: n,
            });
        }
        let (fps, size) = (fps.unwrap_or(25.0), size.unwrap_or((0, 0)));
        let frames = landmarks.len();
        check_length(frames, fps)?;
        // Only now is anything written.
        std::fs::create_dir_all(out).map_err(io(out))?;
        for (clip, path) in listed.iter().zip(clips) {
            std::fs::copy(path, out.join(&clip.file)).map_err(io(path))?;
        }
        let tracked = Frames::from_rows(model.layout(), fps, rows).map_err(CodecError::from)?;
        let distance = distances(&thumbs);
        let footage = Footage {
            dir: out.into(),
            clips: listed,
            fps,
            size,
            model_hash: model.hash(),
            landmarks,
            tracked,
            distance,
        };
        footage.save()?;
        Ok(footage)
    }

    /// Writes `footage.json` and the arrays into [`Footage::dir`] (the clips are there).
    fn save(&self) -> Result<(), FootageError> {
        let n = self.landmarks.first().map_or(0, |l| l.points.len());
        let mut points = Array3::<f32>::zeros((self.len(), n, 2));
        for (i, l) in self.landmarks.iter().enumerate() {
            for (k, p) in l.points.iter().enumerate() {
                points[[i, k, 0]] = p[0] as f32;
                points[[i, k, 1]] = p[1] as f32;
            }
        }
        let npy_error = |e: npy::NpyError| FootageError::Manifest(e.into());
        npy::write(&self.dir.join("landmarks.npy"), points.view()).map_err(npy_error)?;
        npy::write(&self.dir.join("tracked.npy"), self.tracked.values()).map_err(npy_error)?;
        npy::write(&self.dir.join("distance.npy"), self.distance.view()).map_err(npy_error)?;
        let manifest = Manifest {
            format: FORMAT.into(),
            version: FOOTAGE_VERSION,
            fps: self.fps,
            width: self.size.0,
            height: self.size.1,
            model_hash: self.model_hash.clone(),
            layout: self.tracked.layout(),
            landmarks: n,
            clips: self.clips.clone(),
        };
        let json = serde_json::to_vec_pretty(&manifest).expect("footage manifest serialises");
        let path = self.dir.join(MANIFEST);
        crate::atomic::write_file(&path, &json).map_err(|source| FootageError::Io { path, source })
    }

    /// Loads the footage folder `dir`, checking every part against the manifest (the clips
    /// are opened only when shown).
    pub fn load(dir: &Path) -> Result<Footage, FootageError> {
        let m: Manifest = manifest::read(&dir.join(MANIFEST), FORMAT, FOOTAGE_VERSION)?;
        let inconsistent = |reason: String| FootageError::Inconsistent {
            dir: dir.into(),
            reason,
        };
        crate::facespace::check_fps(m.fps).map_err(|e| inconsistent(e.to_string()))?;
        let frames: usize = m.clips.iter().map(|c| c.frames).sum();
        check_length(frames, m.fps)?;
        for c in &m.clips {
            let path = manifest::member(dir, &c.file)?;
            if !path.is_file() {
                return Err(inconsistent(format!("the clip {} is missing", c.file)));
            }
        }
        let points: Array3<f32> =
            manifest::read_array(dir, "landmarks.npy", &[Some(frames), Some(m.landmarks), Some(2)])?;
        let dims = m.layout.dims();
        let tracked: Array2<f32> = manifest::read_array(dir, "tracked.npy", &[Some(frames), Some(dims)])?;
        let distance: Array2<f32> =
            manifest::read_array(dir, "distance.npy", &[Some(frames), Some(frames)])?;
        let landmarks = points
            .outer_iter()
            .map(|l| Landmarks {
                points: l
                    .outer_iter()
                    .map(|p| [f64::from(p[0]), f64::from(p[1])])
                    .collect(),
            })
            .collect();
        let tracked =
            Frames::new(m.layout, m.fps, tracked).map_err(|e| inconsistent(e.to_string()))?;
        Ok(Footage {
            dir: dir.into(),
            clips: m.clips,
            fps: m.fps,
            size: (m.width, m.height),
            model_hash: m.model_hash,
            landmarks,
            tracked,
            distance,
        })
    }

    /// The living frame for `n` output frames (module docs), from the first frame of clip
    /// `seed mod clips`. Each stretch plays forwards for at least [`MIN_RUN_SECONDS`] (or what
    /// is left), then dissolves over [`DISSOLVE_FRAMES`] frames into the stretch that joins
    /// best: the exit and entry whose overlapping frames differ least ([`Footage::distance`]
    /// averaged over the dissolve), so each frame of the join moves the picture by about a
    /// recorded step. Frames already shown cost a little more to enter again, so a long
    /// utterance tours the footage rather than looping a stretch. Never backwards: both
    /// stretches of a dissolve play forwards, in recorded order.
    pub fn plan(&self, n: usize, seed: u64) -> Plan {
        self.plan_from(n, self.clip_starts()[(seed % self.clips.len() as u64) as usize])
    }

    /// The best living frame for `n` output frames: [`Footage::plan`] from the start of every
    /// clip, the one whose worst join costs least (ties: the lower total) — unless several
    /// are about as good (worst join within 20 % of the best), when `seed` picks among those,
    /// so utterances do not all open on the same take. An utterance longer than the footage
    /// gets [`Footage::plan`] from the seed's clip.
    pub fn best_plan(&self, n: usize, seed: u64) -> Plan {
        // Longer than the footage, where the start matters least and each plan costs most:
        // one plan, from the seed's clip.
        if n > self.len() {
            return self.plan(n, seed);
        }
        let worst = |p: &Plan| p.join_costs.iter().copied().fold(0f32, f32::max);
        let mut plans: Vec<Plan> = self.clip_starts()[..self.clips.len()]
            .iter()
            .map(|&s| self.plan_from(n, s))
            .collect();
        plans.sort_by(|a, b| {
            worst(a)
                .total_cmp(&worst(b))
                .then(a.join_costs.iter().sum::<f32>().total_cmp(&b.join_costs.iter().sum()))
        });
        let good = worst(&plans[0]) * 1.2 + 1e-6;
        let count = plans.iter().take_while(|p| worst(p) <= good).count().max(1);
        plans.swap_remove((seed % count as u64) as usize)
    }

    /// [`Footage::plan`] from footage frame `first`.
    fn plan_from(&self, n: usize, first: usize) -> Plan {
        let starts = self.clip_starts();
        let clip_of = |g: usize| starts.partition_point(|&s| s <= g) - 1;
        let end_of = |g: usize| starts[clip_of(g) + 1];
        let start_of = |g: usize| starts[clip_of(g)];
        let median_step = self.median_step();
        let k = DISSOLVE_FRAMES;
        let min_run = ((MIN_RUN_SECONDS * self.fps).round() as usize).max(1);
        let mut shown = vec![false; self.len()];
        let mut plan = Plan {
            frames: Vec::with_capacity(n),
            mix: Vec::with_capacity(n),
            joins: Vec::new(),
            join_costs: Vec::new(),
            median_step,
        };
        let mut at = first.min(self.len().saturating_sub(1));
        while plan.frames.len() < n {
            let left = n - plan.frames.len();
            // Shown frames so far, as prefix sums: how much a candidate stretch repeats.
            let mut before = vec![0u32; self.len() + 1];
            for g in 0..self.len() {
                before[g + 1] = before[g] + u32::from(shown[g]);
            }
            // Frames from `at` before the clip ends or something shown comes up.
            let room = end_of(at) - at;
            let clear = (0..room).find(|&d| shown[at + d]).unwrap_or(room);
            if room >= left && (clear >= left || clear < min_run + k) {
                plan.push_run(at, left);
                break;
            }
            // Exit at `exit` (the last frame before the dissolve) after at least `min_run`
            // frames, with `k` frames after it to dissolve from, before anything shown when it
            // can; enter at `enter` (the first frame after it) with `k` frames before it to
            // dissolve into and `need` after.
            let cost = |exit: usize, enter: usize| {
                (1..=k)
                    .map(|d| self.distance[[exit + d, enter - k - 1 + d]])
                    .sum::<f32>()
                    / k as f32
            };
            let mut best: Option<(f32, usize, usize)> = None;
            let limit = if clear >= min_run + k { clear } else { room };
            let last_exit = (at + limit).saturating_sub(k + 1);
            // First as above; where that finds nothing (footage of a clip or two shorter than
            // a few stretches — a user's short background), loops back within a clip too,
            // never by less than a stretch.
            for strict in [true, false] {
                if best.is_some() {
                    break;
                }
                for exit in (at + min_run.saturating_sub(1))..=last_exit.min(at + left - 1) {
                    let played = exit + 1 - at + k;
                    if played >= left {
                        break;
                    }
                    // Enough to finish, or to play a stretch and dissolve out of it again.
                    let need = if strict { min_run + k } else { min_run }.min(left - played);
                    for enter in (k + 1)..self.len() {
                        if enter - k - 1 < start_of(enter) || end_of(enter) - enter < need {
                            continue;
                        }
                        // Never into what this stretch plays or just played, nor a skip of
                        // less than a stretch ahead of it; loosened, never back by less than a
                        // stretch.
                        let same = clip_of(enter) == clip_of(at);
                        let near = if strict {
                            enter + 2 * min_run >= at && enter <= exit + k + 1 + min_run
                        } else {
                            enter + min_run > exit && enter <= exit + k + 1
                        };
                        if same && near {
                            continue;
                        }
                        let repeated = before[enter + need] - before[enter - k];
                        let again = REPEAT_COST * median_step * repeated as f32;
                        let c = cost(exit, enter) + again;
                        // Ties: the later exit (longer stretches).
                        if best.is_none_or(|(b, ..)| c <= b) {
                            best = Some((c, exit, enter));
                        }
                    }
                }
            }
            let Some((_, exit, enter)) = best else {
                // Nothing to dissolve into (clips shorter than a stretch and its dissolve):
                // the clip plays to its end and again from its start, a cut.
                let run = (end_of(at) - at).min(left);
                plan.push_run(at, run);
                if plan.frames.len() < n {
                    let from = plan.frames[plan.frames.len() - 1];
                    plan.joins.push(plan.frames.len());
                    at = start_of(at);
                    plan.join_costs.push(self.distance[[from, at]]);
                }
                continue;
            };
            for g in (at..=exit + k).chain(enter - k..enter) {
                shown[g] = true;
            }
            plan.push_run(at, exit + 1 - at);
            plan.joins.push(plan.frames.len());
            plan.join_costs.push(cost(exit, enter));
            for d in 1..=k {
                plan.frames.push(exit + d);
                plan.mix
                    .push(Some((enter - k - 1 + d, d as f32 / (k + 1) as f32)));
            }
            at = enter;
        }
        plan.frames.truncate(n);
        plan.mix.truncate(n);
        plan
    }

    /// One video as footage, from its frames tracked and held in memory (nothing written; its
    /// first [`MAX_FRAMES`] frames): a user's background shorter than the speech is extended
    /// as a talker's footage is.
    pub fn of_video(
        path: &Path,
        size: (u32, u32),
        model_hash: String,
        landmarks: Vec<Landmarks>,
        tracked: Frames,
        thumbs: &[Vec<f32>],
    ) -> Footage {
        // The join costs are frames², so at most MAX_FRAMES of it (2.7 minutes at 25 fps).
        let n = landmarks.len().min(MAX_FRAMES);
        let (mut landmarks, tracked) = (landmarks, tracked.slice(0..n.min(tracked.len())));
        landmarks.truncate(n);
        let thumbs = &thumbs[..n.min(thumbs.len())];
        let file = path.file_name().map_or_else(String::new, |f| f.to_string_lossy().into_owned());
        Footage {
            dir: crate::atomic::parent_of(path).to_path_buf(),
            clips: vec![Clip {
                file,
                frames: landmarks.len(),
            }],
            fps: tracked.fps(),
            size,
            model_hash,
            landmarks,
            tracked,
            distance: distances(thumbs),
        }
    }

    /// The median join cost between consecutive frames of a clip: what one recorded step
    /// costs.
    pub fn median_step(&self) -> f32 {
        let starts = self.clip_starts();
        let mut steps: Vec<f32> = (1..self.len())
            .filter(|g| !starts.contains(g))
            .map(|g| self.distance[[g - 1, g]])
            .collect();
        if steps.is_empty() {
            return 0.0;
        }
        let mid = steps.len() / 2;
        *steps.select_nth_unstable_by(mid, f32::total_cmp).1
    }

    /// The frames of `plan`, decoded stretch by stretch (each clip opened where a stretch
    /// starts and read forwards: memory holds the frames of one rendered batch, never the
    /// footage).
    pub fn shown(&self, plan: &Plan) -> Shown {
        Shown {
            dir: self.dir.clone(),
            clips: self.clips.clone(),
            size: self.size,
            frames: plan.frames.clone(),
            mix: plan.mix.clone(),
            next: 0,
            readers: Vec::new(),
        }
    }
}

/// The `count` sentences of `codebook` for the idle footage: the take where his head sat most
/// as it usually does, and the `count − 1` takes whose head sat nearest it in the picture.
/// `say` draws the lips where the footage's face puts them, so footage from takes with an
/// unusual head (pitched down, say) puts every drawn mouth where no recording of his has it
/// (GRID s1: the takes chosen by closeness alone had the upper lip 0.418 interocular distances
/// below the nose against a median of 0.440 over his 741 takes, the 18th percentile). Takes
/// whose head sat alike join with little to dissolve (GRID s1's takes sit 6.6 px apart on
/// average, a pixel's shift costs 4 recorded steps). Each sentence's mean face-space point
/// gives its shape (pose-free) and its landmarks in the picture ([`usual_and_alike`]).
pub fn footage_takes(
    model: &FaceModel,
    codebook: &crate::codebook::Codebook,
    count: usize,
) -> Result<Vec<String>, crate::model::ModelError> {
    let upper: Vec<usize> = if model.shape.n_landmarks() == 68 {
        (17..48).collect()
    } else {
        (0..model.shape.n_landmarks()).collect()
    };
    let mut shapes = Vec::with_capacity(codebook.sentences.len());
    let mut placed = Vec::with_capacity(codebook.sentences.len());
    for (k, s) in codebook.sentences.iter().enumerate() {
        let row: Vec<f32> = codebook.sentence_mean(k).into_iter().map(|m| m as f32).collect();
        let params = s.frames.layout().split(&row).map_err(crate::model::ModelError::from)?;
        shapes.push(
            params
                .shape
                .iter()
                .zip(&model.shape.pca.variances)
                .map(|(&b, &var)| f64::from(b) / f64::from(var).sqrt().max(f64::MIN_POSITIVE))
                .collect(),
        );
        let points = model.landmarks(params)?.points;
        placed.push(upper.iter().map(|&i| points[i]).collect());
    }
    Ok(usual_and_alike(&shapes, &placed, count)
        .into_iter()
        .map(|j| codebook.sentences[j].name.clone())
        .collect())
}

/// Of takes given by their mean shape (`shapes`: shape parameters in standard deviations of
/// the model, so every mode counts alike) and where their head sat in the picture (`placed`:
/// a few landmarks), the usual one — whose shape lies nearest the median of every take's,
/// mode by mode — first, then its `count − 1` nearest by the RMS distance of `placed`
/// (the first of equals first).
fn usual_and_alike(shapes: &[Vec<f64>], placed: &[Vec<crate::shape::Point>], count: usize) -> Vec<usize> {
    let Some(first) = shapes.first() else {
        return Vec::new();
    };
    let median: Vec<f64> = (0..first.len())
        .map(|k| crate::plot::median(&shapes.iter().map(|s| s[k]).collect::<Vec<_>>()))
        .collect();
    let unusual = |s: &[f64]| s.iter().zip(&median).map(|(a, m)| (a - m).powi(2)).sum::<f64>();
    let usual = (0..shapes.len())
        .min_by(|&a, &b| unusual(&shapes[a]).total_cmp(&unusual(&shapes[b])).then(a.cmp(&b)))
        .expect("at least one take");
    let distance = |a: &[crate::shape::Point], b: &[crate::shape::Point]| {
        let sum: f64 = a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sum();
        (sum / a.len().max(1) as f64).sqrt()
    };
    let mut near: Vec<(f64, usize)> = (0..placed.len()).map(|j| (distance(&placed[usual], &placed[j]), j)).collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1 != usual).cmp(&(b.1 != usual))).then(a.1.cmp(&b.1)));
    near.into_iter().take(count).map(|(_, j)| j).collect()
}

/// The video of each take named in `names` among the recordings in `dir` (`NAME.mp4`, or
/// another extension `corpus from-videos` reads): a take that is not there is an error
/// naming it.
pub fn take_videos(dir: &Path, names: &[String]) -> Result<Vec<PathBuf>, FootageError> {
    names
        .iter()
        .map(|name| {
            crate::corpus::VIDEO_EXTENSIONS
                .iter()
                .map(|x| dir.join(format!("{name}.{x}")))
                .find(|p| p.is_file())
                .ok_or_else(|| FootageError::Inconsistent {
                    dir: dir.into(),
                    reason: format!("no video of the codebook's sentence {name} ({name}.mp4)"),
                })
        })
        .collect()
}

fn check_length(frames: usize, fps: f64) -> Result<(), FootageError> {
    let seconds = frames as f64 / fps;
    if seconds < MIN_SECONDS {
        return Err(FootageError::TooShort { seconds });
    }
    if frames > MAX_FRAMES {
        return Err(FootageError::TooLong { frames });
    }
    Ok(())
}

/// The footage frames of a plan as a stream of canvases ([`Footage::shown`]).
pub struct Shown {
    dir: PathBuf,
    clips: Vec<Clip>,
    size: (u32, u32),
    frames: Vec<usize>,
    mix: Vec<Option<(usize, f32)>>,
    next: usize,
    /// Open clips (two at most: a dissolve reads two): index, source, the frame it gives next.
    readers: Vec<(usize, Source, usize)>,
}

impl crate::render::FrameSource for Shown {
    fn size(&self) -> (u32, u32) {
        Shown::size(self)
    }

    fn next_frame(&mut self) -> Result<RgbImage, crate::render::RenderError> {
        Ok(Shown::next_frame(self)?)
    }
}

impl Shown {
    /// The frame size.
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// The same frames again from the first.
    pub fn fresh(&self) -> Shown {
        Shown {
            dir: self.dir.clone(),
            clips: self.clips.clone(),
            size: self.size,
            frames: self.frames.clone(),
            mix: self.mix.clone(),
            next: 0,
            readers: Vec::new(),
        }
    }

    /// The next shown frame (past the plan's end, its last frame again).
    pub fn next_frame(&mut self) -> Result<RgbImage, VideoError> {
        let t = self.next.min(self.frames.len().saturating_sub(1));
        let Some(&g) = self.frames.get(t) else {
            return Err(VideoError::NoFrames(self.dir.clone()));
        };
        self.next += 1;
        let mut frame = self.frame(g)?;
        if let Some(Some((other, w))) = self.mix.get(t).copied() {
            let other = self.frame(other)?;
            for (p, q) in frame.pixels_mut().zip(other.pixels()) {
                for c in 0..3 {
                    let v = (1.0 - w) * f32::from(p.0[c]) + w * f32::from(q.0[c]);
                    p.0[c] = v.round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        Ok(frame)
    }

    /// Footage frame `g`, read forwards from an open clip where one can give it.
    fn frame(&mut self, g: usize) -> Result<RgbImage, VideoError> {
        let (mut clip, mut start) = (0, 0);
        while clip + 1 < self.clips.len() && g >= start + self.clips[clip].frames {
            start += self.clips[clip].frames;
            clip += 1;
        }
        let wanted = g - start;
        let k = match self
            .readers
            .iter()
            .position(|(c, _, at)| *c == clip && *at <= wanted)
        {
            Some(k) => k,
            None => {
                if self.readers.len() == 2 {
                    self.readers.remove(0);
                }
                let path = self.dir.join(&self.clips[clip].file);
                self.readers.push((clip, Source::open(&path)?, 0));
                self.readers.len() - 1
            }
        };
        let (_, source, at) = &mut self.readers[k];
        loop {
            let frame = source
                .next_frame()?
                .ok_or_else(|| VideoError::NoFrames(source.path().into()))?;
            *at += 1;
            if *at > wanted {
                return Ok(frame);
            }
        }
    }
}

/// The grey image at 1/[`THUMB`] size (box average), as floats.
pub(crate) fn thumbnail(image: &RgbImage) -> Vec<f32> {
    let (w, h) = (image.width() / THUMB, image.height() / THUMB);
    let mut out = vec![0f32; (w * h) as usize];
    for y in 0..h * THUMB {
        for x in 0..w * THUMB {
            let grey = crate::video::luma(image.get_pixel(x, y).0.map(f64::from)) as f32;
            out[((y / THUMB) * w + x / THUMB) as usize] += grey;
        }
    }
    let area = (THUMB * THUMB) as f32;
    out.iter_mut().for_each(|v| *v /= area);
    out
}

/// Mean absolute difference between every pair of thumbnails.
fn distances(thumbs: &[Vec<f32>]) -> Array2<f32> {
    use rayon::prelude::*;
    let n = thumbs.len();
    let rows: Vec<Vec<f32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            (0..n)
                .map(|j| {
                    let (a, b) = (&thumbs[i], &thumbs[j]);
                    let sum: f32 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
                    sum / a.len().max(1) as f32
                })
                .collect()
        })
        .collect();
    Array2::from_shape_vec((n, n), rows.concat()).expect("n × n")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The usual take is the one nearest the median shape, even where a tighter group of
    /// unusual takes sits elsewhere; its company is the takes placed nearest it.
    #[test]
    fn the_usual_head_and_its_nearest_are_chosen() {
        // Takes 0–2: an unusual shape (+3 s.d.), placed exactly alike. Takes 3–8: usual shapes
        // around 0, placed 0–3 px apart.
        let mut shapes = vec![vec![3.0, 0.0]; 3];
        shapes.extend([[0.3, -0.1], [0.05, 0.02], [-0.2, 0.1], [0.1, 0.3], [-0.4, -0.2], [0.0, -0.05]].map(|s| s.to_vec()));
        let at = |x: f64| vec![[x, 0.0], [x + 10.0, 0.0]];
        let mut placed = vec![at(50.0); 3];
        placed.extend([1.0, 0.0, 2.5, 0.5, 1.5, 3.0].map(at));
        // The median of the 9 is (0.1, 0), nearest take 4; then by place 6 (0.5 px), 3 (1 px).
        assert_eq!(usual_and_alike(&shapes, &placed, 3), vec![4, 6, 3]);
        assert_eq!(usual_and_alike(&shapes, &placed, 20).len(), 9);
        assert!(usual_and_alike(&[], &[], 4).is_empty());
        // A tie in place: the usual take itself first, then the first of equals.
        let placed = vec![at(0.0); 9];
        assert_eq!(usual_and_alike(&shapes, &placed, 3), vec![4, 0, 1]);
    }
}
