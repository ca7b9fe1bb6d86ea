//! Making a talker folder from its parts: a model, a codebook made with it, and clips of the
//! talker to track as idle footage. Each step leaves its part whole before the next starts
//! and `talker.json` is written last, so an interrupted build is not a talker yet, and the
//! next build keeps the parts already done (a model and codebook in place, footage of the same
//! clips tracked by the same model) instead of starting over.

use std::path::{Path, PathBuf};

use super::footage::{Footage, FootageError};
use super::{
    FORMAT, MANIFEST, Provenance, Settings, TALKER_VERSION, Talker, TalkerError, TalkerManifest,
    Voice,
};
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::model::FaceModel;
use crate::mouths::Mouths;
use crate::sound_to_face::SoundToFace;
use crate::{Progress, atomic};

/// The sound-to-face map's folder in a talker.
const SOUND_TO_FACE: &str = "sound-to-face";

/// What a talker is made of.
#[derive(Clone, Debug)]
pub struct Parts {
    /// The whole-face model folder.
    pub model: PathBuf,
    /// A codebook built with that model.
    pub codebook: PathBuf,
    /// Videos of the talker to take idle footage from.
    pub footage: Vec<PathBuf>,
    /// Sentences of the talker kept out of the codebook, to choose the settings on.
    pub validation: Option<Validation>,
    /// A folder of the codebook's recordings (`NAME.mp4`), from which recorded mouths are
    /// kept ([`crate::mouths`]); `None`: the talker draws the model's mouth.
    pub mouths_from: Option<PathBuf>,
    /// About how many recorded frames to keep ([`crate::mouths::DEFAULT_FRAMES`]).
    pub mouth_frames: usize,
}

/// Validation sentences: tracked with the model, never in the codebook.
#[derive(Clone, Debug)]
pub struct Validation {
    /// The sentences.
    pub sentences: Vec<Sentence>,
    /// Where they come from, in words (for `chosen_on`).
    pub about: String,
}

impl Validation {
    /// A corpus folder of validation sentences tracked with `model` (`corpus from-videos`),
    /// at `fps`.
    pub fn load(dir: &Path, model: &FaceModel, fps: f64) -> Result<Self, TalkerError> {
        let sentences = crate::corpus::load_checked(
            dir,
            fps,
            model.layout(),
            Some(&model.hash()),
            None,
            &crate::phonemes::PhoneMap::default(),
            crate::corpus::DEFAULT_TOLERANCE,
        )
        .map_err(|e| TalkerError::Corpus {
            dir: dir.to_path_buf(),
            source: Box::new(e),
        })?;
        Ok(Validation {
            sentences,
            about: format!("{}, kept out of the codebook", dir.display()),
        })
    }
}

/// The recordings road keeps every [`HOLD_OUT_EVERY`]-th sentence (by name) out of the
/// codebook to choose the settings on, when it has at least [`HOLD_OUT_FROM`] sentences.
pub const HOLD_OUT_EVERY: usize = 10;

/// See [`HOLD_OUT_EVERY`]: fewer sentences keep the given settings.
pub const HOLD_OUT_FROM: usize = 30;

/// Splits sentences (sorted by name) into the codebook's and the validation part
/// ([`HOLD_OUT_EVERY`]); all to the codebook under [`HOLD_OUT_FROM`].
pub fn hold_out(mut sentences: Vec<Sentence>) -> (Vec<Sentence>, Vec<Sentence>) {
    sentences.sort_by(|a, b| a.name.cmp(&b.name));
    if sentences.len() < HOLD_OUT_FROM {
        return (sentences, Vec::new());
    }
    let (mut train, mut validation) = (Vec::new(), Vec::new());
    for (i, s) in sentences.into_iter().enumerate() {
        if i % HOLD_OUT_EVERY == HOLD_OUT_EVERY / 2 {
            validation.push(s);
        } else {
            train.push(s);
        }
    }
    (train, validation)
}

/// Who the talker is and how it speaks.
#[derive(Clone, Debug)]
pub struct Identity {
    /// A name.
    pub name: String,
    /// The synthesis settings.
    pub settings: Settings,
    /// The voice for speech from text.
    pub voice: Option<Voice>,
    /// The recordings, in words.
    pub recordings: String,
}

/// The recordings road: a talker's videos (each `NAME.mp4` with its words in `NAME.txt`, or
/// phone labels of the same stem) and a model of the talker. They become the corpus
/// (`T/corpus/`, kept: an interrupted build resumes after it), the codebook (appearance
/// re-centred per sentence, re-lit to the footage when spoken) and, from the
/// `footage_clips` recordings whose head sat as it usually does and alike
/// ([`super::footage::footage_takes`]), the idle footage.
#[derive(Clone, Debug)]
pub struct Recordings {
    /// The whole-face (or lower-face region) model of the talker.
    pub model: PathBuf,
    /// The folder of recordings.
    pub dir: PathBuf,
    /// How many recordings become idle footage.
    pub footage_clips: usize,
}

/// Makes the parts of a talker from `recordings` inside `out` (see [`Recordings`]), keeping
/// those already made, and returns them for [`build`].
pub fn parts_from_recordings(
    recordings: &Recordings,
    out: &Path,
    mut progress: impl FnMut(Progress) + Send,
) -> Result<Parts, TalkerError> {
    let dir = out.to_path_buf();
    let corpus_error = |e: crate::corpus::CorpusError| TalkerError::Corpus {
        dir: recordings.dir.clone(),
        source: Box::new(e),
    };
    let model = FaceModel::load(&recordings.model).map_err(|source| TalkerError::Model {
        dir: dir.clone(),
        source: Box::new(source),
    })?;
    let corpus = out.join("corpus");
    let done = crate::corpus::recorded_fps(&corpus).ok().flatten();
    let fps = match done {
        Some(fps) => fps,
        None => {
            let made = crate::corpus::from_recordings(
                &model,
                &recordings.dir,
                &corpus,
                &crate::codec::EncodeOptions::default(),
                &crate::corpus::Reading::default(),
                &mut progress,
            )
            .map_err(corpus_error)?;
            made.fps
        }
    };
    let codebook_error = |source| TalkerError::Codebook {
        dir: dir.clone(),
        source: Box::new(source),
    };
    let map = crate::phonemes::PhoneMap::default();
    let sentences = crate::corpus::load_checked(
        &corpus,
        fps,
        model.layout(),
        Some(&model.hash()),
        None,
        &map,
        crate::corpus::DEFAULT_TOLERANCE,
    )
    .map_err(corpus_error)?;
    let (train, validation) = hold_out(sentences);
    let codebook_dir = out.join("codebook");
    let hash = model.hash();
    let kept = Codebook::load(&codebook_dir).ok().filter(|cb| {
        cb.model_hash.as_deref() == Some(hash.as_str())
            && cb.sentences.len() == train.len()
            && cb.sentences.iter().zip(&train).all(|(c, t)| c.name == t.name)
    });
    let codebook = match kept {
        Some(cb) => cb,
        None => {
            let cb = Codebook::from_sentences(
                train,
                &model,
                fps,
                crate::codebook::SimilarityOptions::default(),
                crate::corpus::Photometric::Sentence,
                &mut progress,
            )
            .map_err(codebook_error)?;
            cb.save(&codebook_dir).map_err(codebook_error)?;
            cb
        }
    };
    let names = super::footage::footage_takes(&model, &codebook, recordings.footage_clips)
        .map_err(|source| TalkerError::Model {
            dir: dir.clone(),
            source: Box::new(source),
        })?;
    let footage = super::footage::take_videos(&recordings.dir, &names).map_err(|source| {
        TalkerError::Footage {
            dir: dir.clone(),
            source: Box::new(source),
        }
    })?;
    let about = format!(
        "every {HOLD_OUT_EVERY}th of the recordings, kept out of the codebook"
    );
    Ok(Parts {
        model: recordings.model.clone(),
        codebook: codebook_dir,
        footage,
        validation: (!validation.is_empty()).then_some(Validation {
            sentences: validation,
            about,
        }),
        mouths_from: Some(recordings.dir.clone()),
        mouth_frames: crate::mouths::DEFAULT_FRAMES,
    })
}

/// Keeps about `frames` recorded mouths of `codebook`'s sentences, recorded as `from/NAME.mp4`,
/// in `out/mouths` (with `reuse`, those already there for the model when about as many), and
/// returns the part's name for the manifest.
fn keep_mouths(
    model: &FaceModel,
    codebook: &Codebook,
    from: &Path,
    frames: usize,
    out: &Path,
    reuse: bool,
    progress: impl FnMut(Progress),
) -> Result<Option<String>, TalkerError> {
    let dir = out.join("mouths");
    // Kept when within a sentence of the number asked for.
    let kept = Mouths::load(&dir, model)
        .ok()
        .filter(|m| reuse && m.len().abs_diff(frames) <= m.len() / m.stretches.len().max(1));
    if kept.is_none() {
        let recording = |name: &str| Some(from.join(format!("{name}.mp4"))).filter(|p| p.is_file());
        Mouths::build(model, codebook, recording, frames, &dir, progress).map_err(|source| {
            TalkerError::Mouths {
                dir: out.to_path_buf(),
                source: Box::new(source),
            }
        })?;
    }
    Ok(Some("mouths".into()))
}

/// Gives the talker `dir` recorded mouths kept from `from` (a folder of its codebook's
/// recordings, `NAME.mp4`), about `frames` of them, or takes them away (`frames` = 0), keeping
/// everything else; `talker.json` is rewritten last.
pub fn set_mouths(
    dir: &Path,
    from: &Path,
    frames: usize,
    progress: impl FnMut(Progress),
) -> Result<Talker, TalkerError> {
    // The talker as it is but for its mouths, which may be missing or damaged.
    let talker = Talker::load_without_mouths(dir)?;
    let mut manifest = talker.manifest.clone();
    manifest.mouths = match frames {
        0 => None,
        _ => keep_mouths(&talker.model, &talker.codebook, from, frames, dir, false, progress)?,
    };
    write_manifest(dir, &manifest)?;
    Talker::load(dir)
}

/// Learns the sound-to-face map of `model` and `codebook` from their recordings in `from`
/// into `out/sound-to-face`; returns the part's name for the manifest.
fn learn_sound_to_face(
    model: &FaceModel,
    codebook: &Codebook,
    from: &Path,
    out: &Path,
    least_frames: usize,
    progress: impl FnMut(Progress),
) -> Result<String, TalkerError> {
    let failed = |source| TalkerError::SoundToFace {
        dir: out.into(),
        source: Box::new(source),
    };
    let aligner = crate::align::Aligner::load_default(&[]).map_err(|e| TalkerError::Align {
        path: from.into(),
        source: Box::new(e),
    })?;
    let map = SoundToFace::learn(model, codebook, &aligner, from, least_frames, progress)
        .map_err(failed)?;
    map.save(&out.join(SOUND_TO_FACE)).map_err(failed)?;
    Ok(SOUND_TO_FACE.into())
}

/// Gives the talker `dir` a sound-to-face map learnt from `from` (a folder of its
/// codebook's recordings, `NAME.mp4`; at least `least_frames` frames of them with sound),
/// keeping everything else; `talker.json` is rewritten last.
pub fn set_sound_to_face(
    dir: &Path,
    from: &Path,
    least_frames: usize,
    progress: impl FnMut(Progress),
) -> Result<Talker, TalkerError> {
    let talker = Talker::load(dir)?;
    let mut manifest = talker.manifest.clone();
    manifest.sound_to_face = Some(learn_sound_to_face(
        &talker.model,
        &talker.codebook,
        from,
        dir,
        least_frames,
        progress,
    )?);
    write_manifest(dir, &manifest)?;
    Talker::load(dir)
}

/// Writes `talker.json` into `dir` atomically.
fn write_manifest(dir: &Path, manifest: &TalkerManifest) -> Result<(), TalkerError> {
    let path = dir.join(MANIFEST);
    let json = serde_json::to_vec_pretty(manifest).expect("talker manifest serialises");
    atomic::write_file(&path, &json).map_err(|source| TalkerError::Io { path, source })
}

/// Whether `a` and `b` are the same folder.
fn same(a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// Makes (or completes) the talker folder `out` from `parts` (module docs) and loads it.
pub fn build(
    identity: &Identity,
    parts: &Parts,
    out: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<Talker, TalkerError> {
    let dir = out.to_path_buf();
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| TalkerError::Io { path, source }
    };
    std::fs::create_dir_all(out).map_err(io(out))?;
    let model_error = |source| TalkerError::Model {
        dir: dir.clone(),
        source: Box::new(source),
    };
    let codebook_error = |source| TalkerError::Codebook {
        dir: dir.clone(),
        source: Box::new(source),
    };
    let model = FaceModel::load(&parts.model).map_err(model_error)?;
    let codebook = Codebook::load(&parts.codebook).map_err(codebook_error)?;
    codebook.check_model(&model).map_err(codebook_error)?;
    if !same(&parts.model, &out.join("model")) {
        model.save(&out.join("model")).map_err(model_error)?;
    }
    if !same(&parts.codebook, &out.join("codebook")) {
        codebook.save(&out.join("codebook")).map_err(codebook_error)?;
    }
    let footage_dir = out.join("footage");
    let done = Footage::load(&footage_dir).ok().filter(|f| {
        f.model_hash == model.hash()
            && f.clips.len() == parts.footage.len()
            && f.clips.iter().zip(&parts.footage).all(|(c, p)| {
                p.file_name()
                    .is_some_and(|n| c.file.ends_with(&*n.to_string_lossy()))
            })
    });
    if done.is_none() {
        Footage::build(&model, &parts.footage, &footage_dir, &mut progress).map_err(
            |source: FootageError| TalkerError::Footage {
                dir: dir.clone(),
                source: Box::new(source),
            },
        )?;
    }
    let mouths = match &parts.mouths_from {
        Some(from) if parts.mouth_frames > 0 => {
            keep_mouths(&model, &codebook, from, parts.mouth_frames, out, true, &mut progress)?
        }
        _ => None,
    };
    // Recordings without sound, or under a minute of them, teach no map: the talker then
    // hears phones without words.
    let sound_to_face = match &parts.mouths_from {
        Some(from) => match learn_sound_to_face(
            &model,
            &codebook,
            from,
            out,
            crate::sound_to_face::LEAST_FRAMES,
            &mut progress,
        ) {
            Err(TalkerError::SoundToFace { source, .. })
                if matches!(*source, crate::sound_to_face::SoundToFaceError::Learn(_)) =>
            {
                None
            }
            learnt => Some(learnt?),
        },
        None => None,
    };
    let mut settings = identity.settings.clone();
    if let Some(v) = &parts.validation {
        progress(Progress {
            stage: "choosing the settings on validation sentences",
            done: 0,
            total: 1,
        });
        let choice = crate::eval::systems::choose_settings(
            &model,
            &codebook,
            &v.sentences,
            &crate::eval::systems::TOP_N_GRID,
            &crate::eval::systems::SETTINGS_LAMBDA_GRID,
        )?;
        if let Some(choice) = choice {
            settings = Settings::chosen(&choice, &v.about, settings.appearance_gain);
        }
    }
    let manifest = TalkerManifest {
        format: FORMAT.into(),
        version: TALKER_VERSION,
        name: identity.name.clone(),
        model: "model".into(),
        codebook: "codebook".into(),
        footage: "footage".into(),
        mouths,
        sound_to_face,
        settings,
        voice: identity.voice.clone(),
        provenance: Provenance {
            recordings: identity.recordings.clone(),
            made_by: "facespace talker build".into(),
            facespace: env!("CARGO_PKG_VERSION").into(),
        },
    };
    write_manifest(out, &manifest)?;
    Talker::load(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::facespace::{Frames, Layout};

    fn sentences(n: usize) -> Vec<Sentence> {
        let layout = Layout::new(1, 1);
        (0..n)
            .rev()
            .map(|i| Sentence {
                name: format!("s{i:03}"),
                source: String::new(),
                frames: Frames::new(layout, 25.0, ndarray::Array2::zeros((2, layout.dims())))
                    .unwrap(),
                segments: Vec::new(),
            })
            .collect()
    }

    /// Every 10th sentence by name goes to validation from 30 sentences on, none before;
    /// the parts are disjoint and together the whole.
    #[test]
    fn hold_out_keeps_every_tenth_apart() {
        let (train, validation) = hold_out(sentences(29));
        assert_eq!((train.len(), validation.len()), (29, 0));
        let (train, validation) = hold_out(sentences(45));
        let names = |v: &[Sentence]| v.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&validation), ["s005", "s015", "s025", "s035"]);
        assert_eq!(train.len(), 41);
        assert!(train.iter().all(|s| !names(&validation).contains(&s.name)));
        assert!(train.windows(2).all(|w| w[0].name < w[1].name));
    }
}
