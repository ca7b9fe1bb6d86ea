//! Making a talker folder from its parts: a model, a codebook made with it, and clips of the
//! talker to track as idle footage. Each step leaves its part whole before the next starts
//! and `talker.json` is written last, so an interrupted build is not a talker yet, and the
//! next build keeps the parts already done (a model and codebook in place, footage of the same
//! clips tracked by the same model) instead of starting over.

use std::path::{Path, PathBuf};

use crate::footage::{Footage, FootageError};
use super::manifest::FORMAT;
use super::{
    MANIFEST, Provenance, Settings, TALKER_VERSION, Talker, TalkerError, TalkerManifest, Voice,
};
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::model::FaceModel;
use crate::mouths::Mouths;
use crate::sound_to_face::SoundToFace;
use crate::{Progress, atomic};

/// The sound-to-face map's folder in a talker.
const SOUND_TO_FACE: &str = "sound-to-face";

/// The record `talker build` keeps in a folder it makes: that it made it, and what each part
/// it may keep on a later run was made from. A non-empty folder without it is never built
/// into (it is someone else's), and a part is kept only when its inputs' fingerprint is the
/// one recorded (issue 69, R5-4 and R5-5).
pub const BUILD_RECORD: &str = "build.json";

const BUILD_FORMAT: &str = "facespace-talker-build";
const BUILD_VERSION: u32 = 1;

#[derive(Default, serde::Serialize, serde::Deserialize)]
struct BuildRecord {
    format: String,
    version: u32,
    /// Part name (`corpus`, `codebook`, `footage`, `mouths`) → its inputs' fingerprint.
    parts: std::collections::BTreeMap<String, String>,
}

impl BuildRecord {
    /// Takes `out` for a build: makes it (with an empty record) when it is missing or empty,
    /// reads the record when `talker build` made it, and refuses any other folder, naming a
    /// few of the files that show it is not ours.
    fn claim(out: &Path) -> Result<Self, TalkerError> {
        let io = |source| TalkerError::Io {
            path: out.to_path_buf(),
            source,
        };
        let record = out.join(BUILD_RECORD);
        if std::fs::symlink_metadata(&record).is_ok() {
            return crate::manifest::read(&record, BUILD_FORMAT, BUILD_VERSION).map_err(|source| {
                TalkerError::Manifest {
                    dir: out.to_path_buf(),
                    source: Box::new(source),
                }
            });
        }
        if std::fs::symlink_metadata(out).is_ok() {
            let found: Vec<String> = std::fs::read_dir(out)
                .map_err(io)?
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .take(4)
                .collect();
            if !found.is_empty() {
                return Err(TalkerError::NotOurs {
                    dir: out.to_path_buf(),
                    found: found.join(", "),
                });
            }
        }
        std::fs::create_dir_all(out).map_err(io)?;
        let fresh = BuildRecord {
            format: BUILD_FORMAT.into(),
            version: BUILD_VERSION,
            parts: Default::default(),
        };
        fresh.save(out)?;
        Ok(fresh)
    }

    /// Whether `part` was made from inputs of fingerprint `inputs`.
    fn made_from(&self, part: &str, inputs: &str) -> bool {
        self.parts.get(part).is_some_and(|f| f == inputs)
    }

    /// Records that `part` was made from `inputs` (before it is made, the record forgets it,
    /// so an interrupted making is never taken for a finished one).
    fn set(&mut self, out: &Path, part: &str, inputs: Option<&str>) -> Result<(), TalkerError> {
        match inputs {
            Some(f) => self.parts.insert(part.into(), f.into()),
            None => self.parts.remove(part),
        };
        self.save(out)
    }

    fn save(&self, out: &Path) -> Result<(), TalkerError> {
        let path = out.join(BUILD_RECORD);
        let json = serde_json::to_vec_pretty(self).expect("build record serialises");
        atomic::write_file(&path, &json).map_err(|source| TalkerError::Io { path, source })
    }
}

/// A fingerprint of files' names and contents (FNV-1a 64 over 64-bit little-endian words, in
/// hex) with `also` (a model's hash, a count) mixed in first: what decides whether a part made
/// from them can be kept.
fn fingerprint(files: &[PathBuf], also: &[&str]) -> Result<String, TalkerError> {
    use std::io::Read;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            h = (h ^ u64::from_le_bytes(word)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        h = (h ^ bytes.len() as u64).wrapping_mul(0x0000_0100_0000_01b3);
    };
    for a in also {
        eat(a.as_bytes());
    }
    let mut buffer = vec![0u8; 1 << 20];
    for path in files {
        let io = |source| TalkerError::Io {
            path: path.clone(),
            source,
        };
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        eat(name.as_bytes());
        let mut file = crate::safe_read::open_regular(path).map_err(io)?;
        loop {
            // Whole reads of the buffer, so the words fall alike however the file is read.
            let mut filled = 0;
            while filled < buffer.len() {
                match file.read(&mut buffer[filled..]).map_err(io)? {
                    0 => break,
                    n => filled += n,
                }
            }
            if filled == 0 {
                break;
            }
            eat(&buffer[..filled]);
            if filled < buffer.len() {
                break;
            }
        }
    }
    Ok(format!("{h:016x}"))
}

/// Refuses an output folder that is one of `inputs`, lies inside one, or holds one that is
/// not a part this build made (those inside `out` when `out` is ours).
fn check_output(out: &Path, inputs: &[&Path]) -> Result<(), TalkerError> {
    let real_out = out.canonicalize().ok();
    let outside: Vec<&Path> = inputs
        .iter()
        .copied()
        .filter(|i| {
            !matches!((&real_out, i.canonicalize()), (Some(o), Ok(i)) if i != *o && i.starts_with(o))
        })
        .collect();
    atomic::check_destination(out, &outside)?;
    Ok(())
}

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
/// ([`crate::footage::footage_takes`]), the idle footage.
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
    check_output(out, &[&recordings.model, &recordings.dir])?;
    let mut record = BuildRecord::claim(out)?;
    let corpus_error = |e: crate::corpus::CorpusError| TalkerError::Corpus {
        dir: recordings.dir.clone(),
        source: Box::new(e),
    };
    let model = FaceModel::load(&recordings.model).map_err(|source| TalkerError::Model {
        dir: dir.clone(),
        source: Box::new(source),
    })?;
    let hash = model.hash();
    // The corpus (and the codebook made from it) are kept only when made from these very
    // recordings with this model: the same names with other contents are other recordings.
    // Every file of the folder, as the recordings are read (links followed).
    let files = crate::video::files_where(&recordings.dir, |_| true).map_err(|source| TalkerError::Io {
        path: recordings.dir.clone(),
        source,
    })?;
    let inputs = fingerprint(&files, &[&hash])?;
    let corpus = out.join("corpus");
    let done = crate::corpus::recorded_fps(&corpus)
        .ok()
        .flatten()
        .filter(|_| record.made_from("corpus", &inputs));
    let fps = match done {
        Some(fps) => fps,
        None => {
            record.set(out, "corpus", None)?;
            record.set(out, "codebook", None)?;
            let made = crate::corpus::from_recordings(
                &model,
                &recordings.dir,
                &corpus,
                &crate::codec::EncodeOptions::default(),
                &crate::corpus::Reading::default(),
                &mut progress,
            )
            .map_err(corpus_error)?;
            record.set(out, "corpus", Some(&inputs))?;
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
    let made_from_corpus = record.made_from("codebook", &inputs);
    let kept = Codebook::load(&codebook_dir).ok().filter(|cb| {
        made_from_corpus
            && cb.model_hash.as_deref() == Some(hash.as_str())
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
            record.set(out, "codebook", Some(&inputs))?;
            cb
        }
    };
    let names = crate::footage::footage_takes(&model, &codebook, recordings.footage_clips)
        .map_err(|source| TalkerError::Model {
            dir: dir.clone(),
            source: Box::new(source),
        })?;
    let footage = crate::footage::take_videos(&recordings.dir, &names).map_err(|source| {
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
    reuse: Option<&mut BuildRecord>,
    progress: impl FnMut(Progress),
) -> Result<Option<String>, TalkerError> {
    let dir = out.join("mouths");
    // Kept when made from the same recordings, model and codebook, and within a sentence of
    // the number asked for.
    let recordings: Vec<PathBuf> = codebook
        .sentences
        .iter()
        .map(|s| from.join(format!("{}.mp4", s.name)))
        .filter(|p| p.is_file())
        .collect();
    let (kept, mut record) = match reuse {
        Some(record) => {
            let inputs = fingerprint(&recordings, &[&model.hash(), &codebook.content_hash()])?;
            let kept = record.made_from("mouths", &inputs).then(|| Mouths::load(&dir, model).ok()).flatten().filter(|m| {
                m.len().abs_diff(frames) <= m.len() / m.stretches.len().max(1)
            });
            (kept, Some((record, inputs)))
        }
        None => (None, None),
    };
    if kept.is_none() {
        let recording = |name: &str| Some(from.join(format!("{name}.mp4"))).filter(|p| p.is_file());
        if let Some((record, _)) = &mut record {
            record.set(out, "mouths", None)?;
        }
        Mouths::build(model, codebook, recording, frames, &dir, progress).map_err(|source| {
            TalkerError::Mouths {
                dir: out.to_path_buf(),
                source: Box::new(source),
            }
        })?;
        if let Some((record, inputs)) = record {
            record.set(out, "mouths", Some(&inputs))?;
        }
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
        _ => keep_mouths(&talker.model, &talker.codebook, from, frames, dir, None, progress)?,
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
    let mut inputs: Vec<&Path> = vec![&parts.model, &parts.codebook];
    inputs.extend(parts.footage.iter().map(PathBuf::as_path));
    inputs.extend(parts.mouths_from.as_deref());
    check_output(out, &inputs)?;
    let mut record = BuildRecord::claim(out)?;
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
    let footage_inputs = fingerprint(&parts.footage, &[&model.hash()])?;
    let done = Footage::load(&footage_dir).ok().filter(|f| {
        record.made_from("footage", &footage_inputs)
            && f.model_hash == model.hash()
            && f.clips.len() == parts.footage.len()
    });
    if done.is_none() {
        record.set(out, "footage", None)?;
        Footage::build(&model, &parts.footage, &footage_dir, &mut progress).map_err(
            |source: FootageError| TalkerError::Footage {
                dir: dir.clone(),
                source: Box::new(source),
            },
        )?;
        record.set(out, "footage", Some(&footage_inputs))?;
    }
    let mouths = match &parts.mouths_from {
        Some(from) if parts.mouth_frames > 0 => {
            keep_mouths(&model, &codebook, from, parts.mouth_frames, out, Some(&mut record), &mut progress)?
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
        let choice = crate::synth::systems::choose_settings(
            &model,
            &codebook,
            &v.sentences,
            &crate::synth::systems::TOP_N_GRID,
            &crate::synth::systems::SETTINGS_LAMBDA_GRID,
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
