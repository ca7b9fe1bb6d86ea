//! The talker's manifest (`talker.json`): its parts, settings, voice and provenance, and the
//! one check of it.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::TalkerError;
use crate::manifest::{self, ManifestError};
use crate::synth::Synthesiser;
use crate::synth::blend::Blend;
use crate::synth::graph::Graph;
use crate::synth::unit::UnitSelection;

/// The talker folder format this build writes and reads.
pub const TALKER_VERSION: u32 = 1;
pub(super) const FORMAT: &str = "facespace-talker";
/// The talker's manifest.
pub const MANIFEST: &str = "talker.json";

/// How a talker synthesises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Top-N context blending.
    Blend,
    /// Unit selection.
    Unit,
    /// The dynamic-phoneme graph.
    Graph,
}

/// The synthesis settings a talker carries (chosen on a validation part kept apart from what
/// is reported).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// How to synthesise.
    pub mode: Mode,
    /// Examples blended per phone, N.
    pub top_n: usize,
    /// Context width C.
    pub context: usize,
    /// Smoothing weight λ of the cubic smoothing spline.
    pub smoothing: f64,
    /// Blend's appearance gain ([`Blend::appearance_gain`]); 1 in talkers made before it.
    #[serde(default = "unit_gain")]
    pub appearance_gain: f64,
    /// Where they were chosen, in words.
    pub chosen_on: String,
}

fn unit_gain() -> f64 {
    1.0
}

/// The largest appearance gain a talker may carry: beyond it the texture swings far outside
/// anything recorded (GRID s1's is 1.15).
pub const MAX_APPEARANCE_GAIN: f64 = 4.0;

/// The most examples a talker blends per phone: far more than any choice made on validation
/// sentences (3–12), few enough that a blend stays quick.
pub const MAX_TOP_N: usize = 1000;

impl Settings {
    /// Refuses settings no synthesis can use, naming the field (`prefix` before its name:
    /// `settings.` in a manifest, `--` on the command line): N from 1 to
    /// [`MAX_TOP_N`], C up to [`crate::synth::blend::MAX_CONTEXT`], λ
    /// from 0 to [`crate::synth::MAX_SMOOTHING`], the appearance gain in (0,
    /// [`MAX_APPEARANCE_GAIN`]]. Checked when a talker loads and before `talker build` does
    /// any work (issue 69, R5-14: `--smoothing NaN` built for minutes).
    pub fn check(&self, prefix: &str, separator: char) -> Result<(), crate::options::InvalidOption> {
        use crate::options::{count_in, in_range};
        let name = |field: &str| format!("{prefix}{}", field.replace('_', &separator.to_string()));
        count_in(&name("top_n"), self.top_n, 1, MAX_TOP_N)?;
        count_in(&name("context"), self.context, 0, crate::synth::blend::MAX_CONTEXT)?;
        in_range(&name("smoothing"), self.smoothing, 0.0, crate::synth::MAX_SMOOTHING)?;
        in_range(
            &name("appearance_gain"),
            self.appearance_gain,
            f64::MIN_POSITIVE,
            MAX_APPEARANCE_GAIN,
        )?;
        Ok(())
    }

    /// The blend settings chosen on validation sentences (`split`: which, in words), with
    /// the appearance gain given.
    pub fn chosen(
        choice: &crate::synth::systems::SettingsChoice,
        split: &str,
        appearance_gain: f64,
    ) -> Self {
        Settings {
            mode: Mode::Blend,
            top_n: choice.chosen.top_n,
            context: 1,
            smoothing: choice.chosen.smoothing,
            appearance_gain,
            chosen_on: choice.describe(split),
        }
    }

    /// The synthesiser these settings name.
    pub fn synthesiser(&self) -> Box<dyn Synthesiser> {
        match self.mode {
            Mode::Blend => Box::new(Blend {
                context: self.context,
                top_n: self.top_n,
                preserve_variance: true,
                appearance_gain: self.appearance_gain,
            }),
            Mode::Unit => Box::new(UnitSelection::default()),
            Mode::Graph => Box::new(Graph::default()),
        }
    }
}

/// The text-to-speech voice that suits the talker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Voice {
    /// Festival's name for it (`kal_diphone`).
    pub festival: String,
    /// The Debian package that installs it, for the hint when it is missing.
    pub package: String,
}

/// Where the talker came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The recordings, in words (corpus, split, licence).
    pub recordings: String,
    /// How the folder was made.
    pub made_by: String,
    /// The facespace version that made it.
    pub facespace: String,
}

/// `talker.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TalkerManifest {
    /// Always `facespace-talker`.
    pub format: String,
    /// [`TALKER_VERSION`].
    pub version: u32,
    /// Who this is.
    pub name: String,
    /// The whole-face model folder (a name inside the talker folder).
    pub model: String,
    /// The codebook folder.
    pub codebook: String,
    /// The footage folder.
    pub footage: String,
    /// The recorded mouths folder ([`crate::mouths`]), when the talker keeps them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mouths: Option<String>,
    /// The learnt map from sound to face ([`crate::sound_to_face`]), when the talker has
    /// one: lips from a recording without its words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sound_to_face: Option<String>,
    /// The synthesis settings.
    pub settings: Settings,
    /// The voice for speech from text.
    pub voice: Option<Voice>,
    /// Where it came from.
    pub provenance: Provenance,
}


/// The manifest of the talker folder `dir`, checked as [`Talker::load`] checks it: only
/// regular files inside the folder (`talker.json`, then every part it names and the files in
/// them), its format and version, and settings a synthesis can use.
pub fn read_manifest(dir: &Path) -> Result<TalkerManifest, TalkerError> {
    let manifest_error = |source| TalkerError::Manifest {
        dir: dir.into(),
        source: Box::new(source),
    };
    manifest::check_confined(dir, &[MANIFEST]).map_err(manifest_error)?;
    let m: TalkerManifest =
        manifest::read(&dir.join(MANIFEST), FORMAT, TALKER_VERSION).map_err(manifest_error)?;
    let parts = [Some(&m.model), Some(&m.codebook), Some(&m.footage), m.mouths.as_ref(), m.sound_to_face.as_ref()];
    let parts: Vec<&str> = parts.into_iter().flatten().map(String::as_str).collect();
    manifest::check_confined(dir, &parts).map_err(manifest_error)?;
    if let Err(why) = m.settings.check("settings.", '_') {
        return Err(manifest_error(ManifestError::Invalid {
            path: dir.join(MANIFEST),
            reason: why.to_string(),
        }));
    }
    Ok(m)
}
