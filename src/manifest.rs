//! Folders described by a JSON manifest (model, codebook, clip): the format and version are
//! checked before the rest is parsed, so an unknown version is reported as such, not as a
//! missing field; the files a manifest names are plain file names inside its folder and
//! regular files; arrays are read with their shapes and finiteness checked.

use std::path::{Path, PathBuf};

use ndarray::{Array, Dimension};
use serde::de::DeserializeOwned;
use thiserror::Error;

use crate::npy::{self, Element, NpyError};

/// What can be wrong with a manifest folder; every variant names the file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ManifestError {
    /// The manifest could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The manifest is not valid JSON of the expected kind.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Another version of the format.
    #[error("{path}: {format} version {found}, this build reads version {supported}")]
    Version {
        /// The file.
        path: PathBuf,
        /// The format's name.
        format: &'static str,
        /// The version field as written.
        found: String,
        /// The version this build reads.
        supported: u32,
    },
    /// A file name in the manifest that would leave the folder, or a file of the folder that
    /// is a symbolic link or not a regular file.
    #[error("{dir}: {name:?} is not a plain file inside the folder (a name that leaves it, a symbolic link, or not a regular file)")]
    Escapes {
        /// The folder.
        dir: PathBuf,
        /// The name given.
        name: String,
    },
    /// An array file is damaged or does not match the manifest.
    #[error(transparent)]
    Npy(#[from] NpyError),
}

/// Reads `path`, checks `"format": format` and `"version": version`, then parses `T`.
pub fn read<T: DeserializeOwned>(
    path: &Path,
    format: &'static str,
    version: u32,
) -> Result<T, ManifestError> {
    read_versions(path, format, version..=version).map(|(t, _)| t)
}

/// [`read`] accepting any version in `versions` (older ones this build still reads); returns
/// the version found beside the contents.
pub fn read_versions<T: DeserializeOwned>(
    path: &Path,
    format: &'static str,
    versions: std::ops::RangeInclusive<u32>,
) -> Result<(T, u32), ManifestError> {
    // serde quotes the offending value: a 100 KB field is not echoed whole.
    let invalid = |reason: String| ManifestError::Invalid {
        path: path.into(),
        reason: crate::options::clipped(&reason, 300),
    };
    let meta = std::fs::metadata(path).map_err(|source| ManifestError::Io {
        path: path.into(),
        source,
    })?;
    if !meta.is_file() {
        return Err(invalid("not a regular file".into()));
    }
    let text = crate::safe_read::read_regular_string(path).map_err(|source| ManifestError::Io {
        path: path.into(),
        source,
    })?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(e.to_string()))?;
    if value.get("format").and_then(|f| f.as_str()) != Some(format) {
        return Err(invalid(format!(
            "not a {format} manifest (\"format\" field)"
        )));
    }
    let found = value.get("version");
    let Some(version) = found
        .and_then(|v| v.as_u64())
        .and_then(|v| u32::try_from(v).ok())
        .filter(|v| versions.contains(v))
    else {
        return Err(ManifestError::Version {
            path: path.into(),
            format,
            found: found.map_or("(none)".into(), |v| v.to_string()),
            supported: *versions.end(),
        });
    };
    Ok((
        serde_json::from_value(value).map_err(|e| invalid(e.to_string()))?,
        version,
    ))
}

/// `dir/name` when `name` is a plain file name (no separators, not `.` or `..`).
pub fn member(dir: &Path, name: &str) -> Result<PathBuf, ManifestError> {
    let plain = !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', '\0'])
        && Path::new(name).file_name() == Some(std::ffi::OsStr::new(name));
    if plain {
        Ok(dir.join(name))
    } else {
        Err(ManifestError::Escapes {
            dir: dir.into(),
            name: name.into(),
        })
    }
}

/// Most entries [`check_confined`] looks at: a codebook of 100 000 sentences.
const MAX_CONFINED_ENTRIES: usize = 100_000;

/// Refuses a folder whose parts `names` (files, or folders of files one level deep) are not
/// wholly inside it: any of them, or any file in them, that is a symbolic link (to
/// `/etc/passwd`, to another talker's model) or not a regular file or folder. A folder that a
/// manifest describes reads only what lies inside itself (issue 69, R5-13). Parts that do not
/// exist are left to their loaders, which name them.
pub fn check_confined(dir: &Path, names: &[&str]) -> Result<(), ManifestError> {
    let escapes = |path: &Path| ManifestError::Escapes {
        dir: dir.into(),
        name: path
            .strip_prefix(dir)
            .unwrap_or(path)
            .display()
            .to_string(),
    };
    let mut seen = 0usize;
    for name in names {
        let path = member(dir, name)?;
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.is_dir() {
            let entries = std::fs::read_dir(&path).map_err(|source| ManifestError::Io {
                path: path.clone(),
                source,
            })?;
            for entry in entries.flatten() {
                seen += 1;
                if seen > MAX_CONFINED_ENTRIES {
                    return Err(ManifestError::Invalid {
                        path: path.clone(),
                        reason: format!("more than {MAX_CONFINED_ENTRIES} files"),
                    });
                }
                let inner = entry.file_type().map_err(|source| ManifestError::Io {
                    path: entry.path(),
                    source,
                })?;
                if !(inner.is_file() || inner.is_dir()) {
                    return Err(escapes(&entry.path()));
                }
            }
        } else if !meta.is_file() {
            return Err(escapes(&path));
        }
    }
    Ok(())
}

/// Reads the array `name` of folder `dir` (see [`npy::read_checked`]).
pub fn read_array<T: Element, D: Dimension>(
    dir: &Path,
    name: &str,
    expected: &[Option<usize>],
) -> Result<Array<T, D>, ManifestError> {
    Ok(npy::read_checked(&member(dir, name)?, expected)?)
}
