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
    let text = read_regular_string(path).map_err(|source| ManifestError::Io {
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

/// Opens `path` for reading only if it is a regular file (symbolic links followed): a FIFO
/// would block the open forever, a device (`/dev/zero`) never ends. The open itself does not
/// block (`O_NONBLOCK`, no effect on regular files) and the type is checked again on the
/// opened file, so a FIFO swapped in between is refused too. Refusal is an error of kind
/// `InvalidInput`.
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    let not_regular = || {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a FIFO, device or folder)",
        )
    };
    if !std::fs::metadata(path)?.is_file() {
        return Err(not_regular());
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let file = options.open(path)?;
    if !file.metadata()?.is_file() {
        return Err(not_regular());
    }
    Ok(file)
}

/// Opens `name` in `dir` for a server to hand out: a plain name (no separator, not `.` or
/// `..`), not a symbolic link (`O_NOFOLLOW`), a regular file (never a FIFO or device, opened
/// without blocking), and — checked on the opened file itself — really inside `dir`.
pub fn open_inside(dir: &Path, name: &str) -> std::io::Result<std::fs::File> {
    let refuse = |why: &str| std::io::Error::new(std::io::ErrorKind::InvalidInput, why.to_owned());
    if name.is_empty() || name == "." || name == ".." || name.contains(['/', '\\', '\0']) {
        return Err(refuse("not a plain file name"));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(
        &mut options,
        libc::O_NONBLOCK | libc::O_NOFOLLOW,
    );
    let file = options.open(dir.join(name)).map_err(|e| {
        if e.raw_os_error() == Some(libc::ELOOP) {
            refuse("a symbolic link (not served)")
        } else {
            e
        }
    })?;
    if !file.metadata()?.is_file() {
        return Err(refuse("not a regular file (a FIFO, device or folder)"));
    }
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let real = std::fs::read_link(format!("/proc/self/fd/{}", file.as_raw_fd()))?;
        if !real.starts_with(dir.canonicalize()?) {
            return Err(refuse("outside the served folder"));
        }
    }
    Ok(file)
}

/// The bytes of [`open_inside`]`(dir, name)`, refused past `max` bytes.
pub fn read_inside(dir: &Path, name: &str, max: u64) -> std::io::Result<Vec<u8>> {
    let file = open_inside(dir, name)?;
    let len = file.metadata()?.len();
    if len > max {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{len} bytes, more than the {max} served"),
        ));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    std::io::Read::read_to_end(&mut std::io::Read::take(file, max + 1), &mut bytes)?;
    Ok(bytes)
}

/// Largest text or small input file read whole ([`read_regular`]): far more than any
/// transcript, label file, landmark file or manifest holds, far less than memory.
pub const MAX_READ: u64 = 64 << 20;

/// The bytes of a regular file ([`open_regular`]), refused past [`MAX_READ`] bytes.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    let file = open_regular(path)?;
    let len = file.metadata()?.len();
    let too_long = |len: u64| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{len} bytes, more than the {MAX_READ} read"),
        )
    };
    if len > MAX_READ {
        return Err(too_long(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    std::io::Read::read_to_end(&mut std::io::Read::take(file, MAX_READ + 1), &mut bytes)?;
    if bytes.len() as u64 > MAX_READ {
        return Err(too_long(bytes.len() as u64));
    }
    Ok(bytes)
}

/// The text of a regular UTF-8 file ([`read_regular`]).
pub fn read_regular_string(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_regular(path)?).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "stream did not contain valid UTF-8",
        )
    })
}

/// Reads the array `name` of folder `dir` (see [`npy::read_checked`]).
pub fn read_array<T: Element, D: Dimension>(
    dir: &Path,
    name: &str,
    expected: &[Option<usize>],
) -> Result<Array<T, D>, ManifestError> {
    Ok(npy::read_checked(&member(dir, name)?, expected)?)
}
