//! Crash-safe writes: everything is written beside its destination and renamed into place,
//! so a reader never sees a half-written file or model folder.

use std::io::{self, Write};
use std::path::Path;

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut tmp = staging_file(path)?;
    tmp.write_all(bytes)?;
    persist(tmp, path)
}

/// A temporary file beside `path` (its folder created if need be), for [`persist`]; dropped
/// instead, it is removed.
pub fn staging_file(path: &Path) -> io::Result<tempfile::NamedTempFile> {
    let dir = parent_of(path);
    std::fs::create_dir_all(dir)?;
    tempfile::Builder::new().prefix(".tmp-").tempfile_in(dir)
}

/// Flushes a [`staging_file`] to disk and renames it to `path`.
pub fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> io::Result<()> {
    // tempfile creates 0600 files; a written artefact is an ordinary readable file.
    #[cfg(unix)]
    tmp.as_file()
        .set_permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644))?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Builds a folder with `fill` in a temporary sibling, then swaps it in for `target`
/// (an existing `target` is replaced only once the new one is complete). A non-empty
/// `target` is replaced only if it holds `marker` (e.g. `model.json`), so saving never wipes
/// a folder of something else. `io` turns this function's own I/O errors into the caller's.
pub fn replace_dir<E>(
    target: &Path,
    marker: &str,
    fill: impl FnOnce(&Path) -> Result<(), E>,
    io: impl Fn(io::Error) -> E,
) -> Result<(), E> {
    if target.exists()
        && !target.join(marker).is_file()
        && std::fs::read_dir(target).map_err(&io)?.next().is_some()
    {
        return Err(io(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "it exists and is not a folder of this kind (no {marker}); refusing to replace it"
            ),
        )));
    }
    let parent = parent_of(target);
    std::fs::create_dir_all(parent).map_err(&io)?;
    let tmp = tempfile::Builder::new()
        .prefix(".tmp-")
        .tempdir_in(parent)
        .map_err(&io)?;
    fill(tmp.path())?;
    let staged = tmp.keep();
    #[cfg(unix)]
    std::fs::set_permissions(&staged, std::os::unix::fs::PermissionsExt::from_mode(0o755))
        .map_err(&io)?;
    let swap = || -> io::Result<()> {
        if target.exists() {
            let old = tempfile::Builder::new()
                .prefix(".old-")
                .tempdir_in(parent)?
                .keep();
            std::fs::remove_dir(&old)?;
            std::fs::rename(target, &old)?;
            if let Err(e) = std::fs::rename(&staged, target) {
                std::fs::rename(&old, target)?;
                return Err(e);
            }
            std::fs::remove_dir_all(&old)
        } else {
            std::fs::rename(&staged, target)
        }
    };
    swap().map_err(io)
}

/// The folder `path` is in (`.` for a bare file name).
pub fn parent_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_fill_leaves_the_old_folder_untouched() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("model");
        replace_dir(&target, "a", |d| std::fs::write(d.join("a"), "1"), |e| e).unwrap();
        let failed = replace_dir(
            &target,
            "a",
            |d| {
                std::fs::write(d.join("a"), "2")?;
                Err(io::Error::other("crash"))
            },
            |e| e,
        );
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(target.join("a")).unwrap(), "1");
        replace_dir(&target, "a", |d| std::fs::write(d.join("b"), "3"), |e| e).unwrap();
        // A folder without the marker is never replaced.
        let err = replace_dir(&target, "a", |_| Ok(()), |e| e).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::AlreadyExists);
        assert!(!target.join("a").exists());
        assert_eq!(std::fs::read_to_string(target.join("b")).unwrap(), "3");
        let left: Vec<_> = std::fs::read_dir(root.path()).unwrap().collect();
        // The failed attempt's temporary folder is removed when its guard drops.
        assert_eq!(left.len(), 1, "{left:?}");
    }
}
