//! Writing the demo corpus as a corpus folder (with how it was made), optionally rendered.

use thiserror::Error;

use super::{Corpus, CorpusOptions, Split};
use crate::model::FaceModel;
use crate::phonemes::{self, PhonemeError};

impl Corpus {
    /// Writes the corpus folder: `train/`, `validation/` and `heldout/` (the test split) with
    /// `NAME.npy`, `NAME.lab` and `NAME.txt`, and `corpus.json` describing how it was made. With a renderer, every
    /// frame is also drawn over `background` into `frames/NAME/`.
    pub fn save(
        &self,
        dir: &std::path::Path,
        model: &FaceModel,
        options: &CorpusOptions,
        still_frame_name: &str,
        frames: Option<(&dyn crate::render::Renderer, &image::RgbImage)>,
        progress: impl FnMut(crate::Progress),
    ) -> Result<(), SaveError> {
        // Built whole beside `dir` and swapped in: a killed run leaves no partial train/, and
        // a folder facespace did not write is never replaced.
        crate::atomic::replace_dir(
            dir,
            "demo corpus",
            |staged| self.save_into(staged, model, options, still_frame_name, frames, progress),
            |source| SaveError::Io {
                path: dir.into(),
                source,
            },
        )
    }

    fn save_into(
        &self,
        dir: &std::path::Path,
        model: &FaceModel,
        options: &CorpusOptions,
        still_frame_name: &str,
        frames: Option<(&dyn crate::render::Renderer, &image::RgbImage)>,
        mut progress: impl FnMut(crate::Progress),
    ) -> Result<(), SaveError> {
        for g in &self.sentences {
            let s = &g.sentence;
            let part = dir.join(g.split.folder());
            crate::npy::write(&part.join(format!("{}.npy", s.name)), s.frames.values())?;
            phonemes::write_labels(&part.join(format!("{}.lab", s.name)), &s.segments)?;
            let txt = part.join(format!("{}.txt", s.name));
            crate::atomic::write_file(&txt, format!("{}\n", g.text).as_bytes())
                .map_err(|source| SaveError::Io { path: txt, source })?;
        }
        // Each split folder records its frame rate for `codebook build`.
        for split in [Split::Train, Split::Validation, Split::Test] {
            let part = dir.join(split.folder());
            if part.is_dir() {
                crate::corpus::write_manifest(&part, options.fps)
                    .map_err(|(path, source)| SaveError::Io { path, source })?;
            }
        }
        let names = |split: Split| -> Vec<&str> {
            self.sentences
                .iter()
                .filter(|g| g.split == split)
                .map(|g| g.sentence.name.as_str())
                .collect()
        };
        let manifest = serde_json::json!({
            "generator": "facespace corpus demo",
            "note": "Trajectories are GENERATED (dominance-function coarticulation over real face-space points of the demo training frames), not recorded. Phone sequences come from the CMU dictionary, durations from a table with seeded jitter.",
            "options": options,
            "model_hash": model.hash(),
            "still_frame": still_frame_name,
            "fps": options.fps,
            "train": names(Split::Train),
            "validation": names(Split::Validation),
            "heldout": names(Split::Test),
            "texts": self.sentences.iter().map(|g| (&g.sentence.name, &g.text)).collect::<std::collections::BTreeMap<_, _>>(),
        });
        let path = dir.join("corpus.json");
        let json = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        crate::atomic::write_file(&path, json.as_bytes())
            .map_err(|source| SaveError::Io { path, source })?;
        if let Some((renderer, background)) = frames {
            for (i, g) in self.sentences.iter().enumerate() {
                let s = &g.sentence;
                let (w, h) = background.dimensions();
                let mut sink = crate::video::Sink::create(
                    &dir.join("frames").join(&s.name),
                    w,
                    h,
                    s.frames.fps(),
                    None,
                )?;
                crate::render::stream(
                    renderer,
                    &s.frames,
                    crate::render::Background::Still(background.clone()),
                    |f| Ok::<(), SaveError>(sink.write(&f)?),
                    crate::no_progress,
                )?;
                sink.finish()?;
                progress(crate::Progress {
                    stage: "rendering",
                    done: i + 1,
                    total: self.sentences.len(),
                });
            }
        }
        Ok(())
    }
}

/// What can go wrong writing the demo corpus.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum SaveError {
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// An array could not be written.
    #[error(transparent)]
    Npy(#[from] crate::npy::NpyError),
    /// A label file could not be written.
    #[error(transparent)]
    Phonemes(#[from] PhonemeError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
    /// A frame could not be written.
    #[error(transparent)]
    Video(#[from] crate::video::VideoError),
}
