//! Crash-safe writes: everything is written beside its destination and renamed into place,
//! so a reader never sees a half-written file or folder, and a folder is replaced only when it
//! provably holds nothing but what facespace wrote there.
//!
//! Staging files and folders are named `.facespace-tmp-*` and hold an advisory lock
//! (`flock`) while their writer lives; the next write into the same folder removes any whose
//! lock is free, i.e. whose writer was killed. They are created as `.facespace-new-*`, locked,
//! then renamed, so a concurrent writer's clean-up never takes a live one for dead. The
//! destination's folder is resolved once, at the start: a parent symlink swapped mid-run
//! neither strands the staging nor sends the result elsewhere. Readers of replaced folders
//! retry when the folder was swapped under them ([`read_consistent`]). A folder is swapped in by one
//! `renameat2(RENAME_EXCHANGE)` on Linux, so the destination exists at every instant; where
//! the exchange is unsupported (another OS, a file system without it) two renames are used and
//! a crash between them leaves the previous folder as `.facespace-old-*` beside it.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Prefix of every staging file and folder (cleaned when unlocked).
const STAGING: &str = ".facespace-tmp-";
/// Prefix of a staging entry being created: renamed to [`STAGING`] once it is locked, so no
/// cleaner (in this process or another) ever sees an unlocked live staging entry.
const NEW: &str = ".facespace-new-";
/// A [`NEW`] entry still unlocked this long after it was first seen unlocked was left by a
/// writer killed while creating it (a live one locks it within microseconds).
const NEW_GRACE: std::time::Duration = std::time::Duration::from_millis(50);
/// Prefix of a previous folder kept by the two-rename fallback (never cleaned automatically).
const OLD: &str = ".facespace-old-";
/// Written into every folder [`replace_dir`] builds: its kind and the names it holds.
pub const OWNED: &str = ".facespace-owned.json";

#[derive(serde::Serialize, serde::Deserialize)]
struct Owned {
    kind: String,
    files: Vec<String>,
}

/// Why a destination is refused before anything is written ([`check_destination`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DestinationError {
    /// A device, FIFO or socket: renaming a file over it would replace it (as root,
    /// `/dev/null` itself).
    #[error(
        "refusing to write over {path}: it exists and is not a regular file or folder (a device or FIFO)"
    )]
    NotRegular {
        /// The destination.
        path: PathBuf,
    },
    /// The destination is one of the command's inputs (the same file, links resolved).
    #[error("refusing to write over {path}: it is also an input ({input}); give another output")]
    IsInput {
        /// The destination.
        path: PathBuf,
        /// The input it is.
        input: PathBuf,
    },
    /// The destination lies inside a folder the command reads (a talker, a model, a
    /// recordings folder): writing there would change or break that input.
    #[error(
        "refusing to write {path}: it lies inside the input folder {input}, which would then hold it; give an output outside it"
    )]
    InsideInput {
        /// The destination.
        path: PathBuf,
        /// The input folder holding it.
        input: PathBuf,
    },
    /// An input lies inside the destination folder, which the result replaces whole.
    #[error(
        "refusing to replace {path}: the input {input} lies inside that folder; give another output"
    )]
    HoldsInput {
        /// The destination folder.
        path: PathBuf,
        /// The input inside it.
        input: PathBuf,
    },
}

/// Refuses a destination that exists as something other than a regular file or folder, that
/// is the same file as one of `inputs` (after links), or that is a folder holding one of
/// them. Checked before any work, so a command never runs long to then write over its own
/// input or a device (issue 39).
pub fn check_destination(path: &Path, inputs: &[&Path]) -> Result<(), DestinationError> {
    // Inside an input folder (after links, whether or not the destination exists yet).
    let resolved = resolve_destination(path);
    for input in inputs {
        if std::fs::metadata(input).is_ok_and(|m| m.is_dir())
            && let (Some(resolved), Ok(folder)) = (&resolved, input.canonicalize())
            && resolved != &folder
            && resolved.starts_with(&folder)
        {
            return Err(DestinationError::InsideInput {
                path: path.into(),
                input: input.to_path_buf(),
            });
        }
    }
    let Ok(meta) = std::fs::metadata(path) else {
        // Nothing there (or a dangling link, which the rename replaces): no input is it.
        return Ok(());
    };
    if !meta.is_file() && !meta.is_dir() {
        return Err(DestinationError::NotRegular { path: path.into() });
    }
    let real = path.canonicalize().ok();
    for input in inputs {
        let Ok(m) = std::fs::metadata(input) else {
            continue;
        };
        if same_file(&meta, &m) {
            return Err(DestinationError::IsInput {
                path: path.into(),
                input: input.to_path_buf(),
            });
        }
        if meta.is_dir()
            && let (Some(real), Ok(inside)) = (&real, input.canonicalize())
            && inside.starts_with(real)
        {
            return Err(DestinationError::HoldsInput {
                path: path.into(),
                input: input.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// Where `path` would be written, links resolved: the path itself when it exists, else its
/// nearest existing ancestor resolved with the rest appended (`None` if nothing resolves).
fn resolve_destination(path: &Path) -> Option<PathBuf> {
    let absolute = std::path::absolute(path).ok()?;
    let mut tail = Vec::new();
    let mut at = absolute.as_path();
    loop {
        if let Ok(real) = at.canonicalize() {
            return Some(tail.iter().rev().fold(real, |p, name| p.join(name)));
        }
        tail.push(at.file_name()?.to_owned());
        at = at.parent()?;
    }
}

/// Whether two metadata are of one file (device and inode on Unix).
fn same_file(a: &std::fs::Metadata, b: &std::fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        a.dev() == b.dev() && a.ino() == b.ino()
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut tmp = staging_file(path)?;
    tmp.write_all(bytes)?;
    persist(tmp, path)
}

/// A locked temporary file beside `path` (its folder created if need be), for [`persist`];
/// dropped instead, it is removed.
pub fn staging_file(path: &Path) -> io::Result<tempfile::NamedTempFile> {
    // A file is renamed only over a file: never over a device, FIFO or folder.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "it exists and is not a regular file (a device, FIFO or folder); not written over",
        ));
    }
    let dir = parent_of(path);
    std::fs::create_dir_all(dir)?;
    let dir = dir.canonicalize()?;
    clean_stale(&dir);
    let _creating = CREATING.lock().unwrap_or_else(|e| e.into_inner());
    // The destination's extension kept: a tool writing it (ffmpeg) picks its format by it.
    let suffix = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(NEW)
        .suffix(&suffix)
        .tempfile_in(&dir)?;
    lock(tmp.as_file());
    let (file, created) = tmp.into_parts();
    let staged = staging_name(&created);
    std::fs::rename(&created, &staged)?;
    created.keep().map_err(|e| e.error)?;
    Ok(tempfile::NamedTempFile::from_parts(
        file,
        tempfile::TempPath::try_from_path(staged)?,
    ))
}

/// The [`STAGING`] name of a [`NEW`] entry (the same random tail).
fn staging_name(created: &Path) -> PathBuf {
    let name = created
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    created.with_file_name(format!("{STAGING}{}", name.trim_start_matches(NEW)))
}

/// Flushes a [`staging_file`] to disk and renames it to `path`.
pub fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> io::Result<()> {
    // tempfile creates 0600 files; a written artefact is an ordinary readable file.
    #[cfg(unix)]
    tmp.as_file()
        .set_permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644))?;
    tmp.as_file().sync_all()?;
    // Into the folder the staging was made in (resolved when it was made).
    let destination = match (tmp.path().parent(), path.file_name()) {
        (Some(dir), Some(name)) => dir.join(name),
        _ => path.to_path_buf(),
    };
    tmp.persist(destination).map_err(|e| e.error)?;
    Ok(())
}

/// A locked temporary folder in `parent`, removed when dropped.
pub struct StagingDir {
    path: PathBuf,
    _lock: Option<File>,
}

impl StagingDir {
    /// Creates one in the folder `parent` resolves to now (and first removes the staging
    /// that killed writers left there).
    pub fn new(parent: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(parent)?;
        let parent = parent.canonicalize()?;
        clean_stale(&parent);
        let _creating = CREATING.lock().unwrap_or_else(|e| e.into_inner());
        let created = tempfile::Builder::new()
            .prefix(NEW)
            .tempdir_in(&parent)?
            .keep();
        let lock = File::open(&created).ok();
        if let Some(f) = &lock {
            self::lock(f);
        }
        let path = staging_name(&created);
        if let Err(e) = std::fs::rename(&created, &path) {
            let _ = std::fs::remove_dir_all(&created);
            return Err(e);
        }
        Ok(Self { path, _lock: lock })
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// A file that lives in memory only (Linux `memfd_create`), opened by this process through
/// its path `/proc/self/fd/N`: for an intermediate file that must leave nothing on disk when
/// the process is killed (`serve`'s typed sentences, issue 69 R5-9). Elsewhere a temporary
/// file, removed when dropped.
pub struct MemoryFile {
    file: File,
    path: PathBuf,
    _temp: Option<tempfile::TempPath>,
}

impl MemoryFile {
    /// An empty one; `name` is shown in `/proc` listings only.
    pub fn new(name: &str) -> io::Result<Self> {
        #[cfg(target_os = "linux")]
        {
            use std::os::fd::{AsRawFd, FromRawFd};
            let c = std::ffi::CString::new(name).map_err(io::Error::other)?;
            // SAFETY: memfd_create takes a NUL-terminated name and returns a new descriptor
            // (or -1), which the File then owns.
            let fd = unsafe { libc::memfd_create(c.as_ptr(), libc::MFD_CLOEXEC) };
            if fd >= 0 {
                let file = unsafe { File::from_raw_fd(fd) };
                let path = PathBuf::from(format!("/proc/self/fd/{}", file.as_raw_fd()));
                return Ok(MemoryFile {
                    file,
                    path,
                    _temp: None,
                });
            }
        }
        let (file, temp) = tempfile::Builder::new()
            .prefix(name)
            .tempfile()?
            .into_parts();
        Ok(MemoryFile {
            path: temp.to_path_buf(),
            file,
            _temp: Some(temp),
        })
    }

    /// The open file.
    pub fn file(&self) -> &File {
        &self.file
    }

    /// A path this process opens it by.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Runs `read` on the folder `dir` until the folder was not replaced while it ran (its inode
/// and change time the same before and after; at most 5 tries): a reader of a folder swapped
/// in whole by [`replace_dir`] gets one version or tries again, never a mix.
pub fn read_consistent<T, E>(dir: &Path, mut read: impl FnMut() -> Result<T, E>) -> Result<T, E> {
    let mut tries = 0;
    loop {
        let before = identity(dir);
        let result = read();
        tries += 1;
        if identity(dir) == before || tries == 5 {
            return result;
        }
    }
}

/// Which file or folder is at a path: its device, inode and change time.
pub type Identity = (u64, u64, i64, i64);

/// The [`Identity`] of what is at `path` now (`None` if nothing can be read there, and off
/// Unix). The change time too: a folder removed by one swap can hand its inode number to a
/// folder swapped in later (two swaps during one read then looked like none), but a rename
/// sets the change time of what it moves, and a write that of what it writes, to the
/// nanosecond.
pub fn identity(path: &Path) -> Option<Identity> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(path)
            .ok()
            .map(|m| (m.dev(), m.ino(), m.ctime(), m.ctime_nsec()))
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// Builds a folder with `fill` in a staging sibling, then swaps it in for `target` (an
/// existing `target` is replaced only once the new one is complete). A non-empty `target` is
/// replaced only if an earlier save of the same `kind` wrote it and nothing has been added
/// since (its [`OWNED`] record lists every entry), so saving never deletes a user's files.
/// `io` turns this function's own I/O errors into the caller's.
pub fn replace_dir<E>(
    target: &Path,
    kind: &str,
    fill: impl FnOnce(&Path) -> Result<(), E>,
    io: impl Fn(io::Error) -> E,
) -> Result<(), E> {
    check_replaceable(target, kind).map_err(&io)?;
    let staging = StagingDir::new(parent_of(target)).map_err(&io)?;
    // The target in the folder the staging was made in (its parent resolved once).
    let resolved = match (staging.path().parent(), target.file_name()) {
        (Some(dir), Some(name)) => dir.join(name),
        _ => target.to_path_buf(),
    };
    let target = resolved.as_path();
    let staged = staging.path();
    fill(staged)?;
    let mut files: Vec<String> = std::fs::read_dir(staged)
        .map_err(&io)?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<io::Result<_>>()
        .map_err(&io)?;
    files.sort();
    let record = Owned {
        kind: kind.into(),
        files,
    };
    let json = serde_json::to_vec_pretty(&record).expect("ownership record serialises");
    write_file(&staged.join(OWNED), &json).map_err(&io)?;
    #[cfg(unix)]
    std::fs::set_permissions(staged, std::os::unix::fs::PermissionsExt::from_mode(0o755))
        .map_err(&io)?;
    // Checked again just before the swap: a user may have added files while we worked.
    check_replaceable(target, kind).map_err(&io)?;
    swap_in(staged, target).map_err(io)
    // `staging` drops here: it now holds the previous folder (or nothing) and is removed.
}

/// Whether `target` may be replaced by a folder of `kind` (see [`replace_dir`]).
fn check_replaceable(target: &Path, kind: &str) -> io::Result<()> {
    let refuse = |why: String| Err(io::Error::new(io::ErrorKind::AlreadyExists, why));
    let Ok(meta) = std::fs::metadata(target) else {
        return Ok(());
    };
    if !meta.is_dir() {
        return refuse("it exists and is not a folder; refusing to replace it".into());
    }
    let mut names = Vec::new();
    for e in std::fs::read_dir(target)? {
        names.push(e?.file_name().to_string_lossy().into_owned());
    }
    if names.is_empty() {
        return Ok(());
    }
    let record = std::fs::read(target.join(OWNED))
        .ok()
        .and_then(|b| serde_json::from_slice::<Owned>(&b).ok());
    let Some(record) = record else {
        return refuse(format!(
            "it is a non-empty folder facespace did not write (no valid {OWNED}); refusing to \
             replace it — choose a new or empty folder"
        ));
    };
    if record.kind != kind {
        return refuse(format!(
            "it holds a facespace {}, not a {kind}; refusing to replace it",
            record.kind
        ));
    }
    let mut foreign: Vec<&String> = names
        .iter()
        .filter(|n| *n != OWNED && !record.files.contains(n))
        .collect();
    if !foreign.is_empty() {
        foreign.sort();
        let shown: Vec<&str> = foreign.iter().take(3).map(|s| s.as_str()).collect();
        return refuse(format!(
            "it holds {} file(s) facespace did not write ({}{}); refusing to replace it",
            foreign.len(),
            shown.join(", "),
            if foreign.len() > 3 { ", …" } else { "" }
        ));
    }
    Ok(())
}

/// Puts the folder `staged` at `target`; afterwards `staged` holds the previous `target` (or
/// nothing) for its owner to remove.
fn swap_in(staged: &Path, target: &Path) -> io::Result<()> {
    if std::fs::symlink_metadata(target).is_err() {
        return std::fs::rename(staged, target);
    }
    if exchange(staged, target).is_ok() {
        return Ok(());
    }
    // Fallback: two renames; between them the destination is briefly missing.
    let old = tempfile::Builder::new()
        .prefix(OLD)
        .tempdir_in(parent_of(target))?
        .keep();
    std::fs::remove_dir(&old)?;
    std::fs::rename(target, &old)?;
    if let Err(e) = std::fs::rename(staged, target) {
        std::fs::rename(&old, target)?;
        return Err(e);
    }
    std::fs::rename(&old, staged)
}

/// Atomically exchanges two paths (Linux `renameat2(RENAME_EXCHANGE)`).
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| CString::new(p.as_os_str().as_bytes()).map_err(io::Error::other);
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: two valid NUL-terminated paths relative to the current directory.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_: &Path, _: &Path) -> io::Result<()> {
    Err(io::Error::from(io::ErrorKind::Unsupported))
}

/// Takes the advisory lock that marks a staging entry as alive (best effort: a file system
/// without locks only loses the clean-up).
fn lock(f: &File) {
    let _ = f.try_lock();
}

/// Held from creating a staging entry until it is locked, and while cleaning, so this
/// process never takes its own brand-new staging for a dead writer's. (Two processes
/// staging into one folder at the same instant could still race in that window.)
static CREATING: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Folders this process has already cleaned (once each is enough: anything stale is older).
static CLEANED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Removes the staging entries in `dir` whose writer is gone (their lock is free).
fn clean_stale(dir: &Path) {
    let key = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut cleaned = CLEANED.lock().unwrap_or_else(|e| e.into_inner());
        if cleaned.contains(&key) {
            return;
        }
        cleaned.push(key);
    }
    let _creating = CREATING.lock().unwrap_or_else(|e| e.into_inner());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let unlocked = |path: &Path| File::open(path).is_ok_and(|f| f.try_lock().is_ok());
    let remove = |path: &Path| {
        let _ = if path.is_dir() {
            std::fs::remove_dir_all(path)
        } else {
            std::fs::remove_file(path)
        };
    };
    let mut in_creation = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let path = e.path();
        if name.starts_with(STAGING) && unlocked(&path) {
            // Renamed to this only once locked: unlocked now means its writer is gone.
            remove(&path);
        } else if name.starts_with(NEW) && unlocked(&path) {
            in_creation.push(path);
        }
    }
    if !in_creation.is_empty() {
        // Perhaps being created this instant by another process: dead only if still
        // unlocked a moment later.
        std::thread::sleep(NEW_GRACE);
        for path in in_creation {
            if unlocked(&path) {
                remove(&path);
            }
        }
    }
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

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn failed_fill_leaves_the_old_folder_untouched() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("model");
        replace_dir(&target, "m", |d| std::fs::write(d.join("a"), "1"), |e| e).unwrap();
        let failed = replace_dir(
            &target,
            "m",
            |d| {
                std::fs::write(d.join("a"), "2")?;
                Err(io::Error::other("crash"))
            },
            |e| e,
        );
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(target.join("a")).unwrap(), "1");
        replace_dir(&target, "m", |d| std::fs::write(d.join("b"), "3"), |e| e).unwrap();
        assert_eq!(names(&target), [OWNED, "b"]);
        // Another kind of ours is not replaced.
        let err = replace_dir(&target, "other", |_| Ok(()), |e| e).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read_to_string(target.join("b")).unwrap(), "3");
        // The failed attempt's staging and the replaced folder are gone.
        assert_eq!(names(root.path()), ["model"]);
    }

    /// Issue 17's reproducer: a folder that merely contains the marker file, or ours with a
    /// user's file added, is never replaced.
    #[test]
    fn user_files_are_never_deleted() {
        let root = tempfile::tempdir().unwrap();
        let p = root.path().join("p");
        std::fs::create_dir(&p).unwrap();
        std::fs::write(p.join("thesis.tex"), "x").unwrap();
        std::fs::write(p.join("meta.json"), "{}").unwrap();
        let err = replace_dir(&p, "clip", |_| Ok(()), |e| e).unwrap_err();
        assert!(err.to_string().contains("did not write"), "{err}");
        assert!(p.join("thesis.tex").is_file());

        let ours = root.path().join("ours");
        replace_dir(
            &ours,
            "clip",
            |d| std::fs::write(d.join("meta.json"), "1"),
            |e| e,
        )
        .unwrap();
        std::fs::write(ours.join("notes.txt"), "mine").unwrap();
        let err = replace_dir(&ours, "clip", |_| Ok(()), |e| e).unwrap_err();
        assert!(err.to_string().contains("notes.txt"), "{err}");
        assert_eq!(
            std::fs::read_to_string(ours.join("notes.txt")).unwrap(),
            "mine"
        );
        // A forged record listing the user's file as ours would be needed to replace it;
        // an empty folder or none at all is fine.
        let empty = root.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        replace_dir(&empty, "clip", |d| std::fs::write(d.join("x"), "1"), |e| e).unwrap();
        // A file is never replaced by a folder.
        let file = root.path().join("file");
        std::fs::write(&file, "f").unwrap();
        assert!(replace_dir(&file, "clip", |_| Ok(()), |e| e).is_err());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "f");
    }

    /// Staging whose writer died (lock free) is removed by the next write; live staging
    /// (lock held) is left alone.
    #[test]
    fn stale_staging_is_cleaned_live_staging_kept() {
        let root = tempfile::tempdir().unwrap();
        let dead = root.path().join(format!("{STAGING}dead"));
        std::fs::create_dir(&dead).unwrap();
        std::fs::write(dead.join("frame.png"), "x").unwrap();
        std::fs::write(root.path().join(format!("{STAGING}deadfile")), "x").unwrap();
        let live = StagingDir::new(root.path()).unwrap();
        write_file(&root.path().join("out.json"), b"{}").unwrap();
        let left = names(root.path());
        assert_eq!(left.len(), 2, "{left:?}");
        assert!(live.path().is_dir() && root.path().join("out.json").is_file());
        drop(live);
        assert_eq!(names(root.path()), ["out.json"]);
    }

    /// The destination exists at every instant of a replace (Linux: one exchange).
    #[cfg(target_os = "linux")]
    #[test]
    fn replace_is_one_exchange() {
        let root = tempfile::tempdir().unwrap();
        let a = root.path().join("a");
        let b = root.path().join("b");
        std::fs::create_dir(&a).unwrap();
        std::fs::create_dir(&b).unwrap();
        std::fs::write(a.join("x"), "a").unwrap();
        std::fs::write(b.join("x"), "b").unwrap();
        exchange(&a, &b).unwrap();
        assert_eq!(std::fs::read_to_string(a.join("x")).unwrap(), "b");
        assert_eq!(std::fs::read_to_string(b.join("x")).unwrap(), "a");
    }

    /// Issue 27, F9: an entry being created (`.facespace-new-*`, not yet locked) is never
    /// taken for a dead writer's by another writer's clean-up; one left by a writer killed
    /// while creating it goes once it is old. Live staging is always locked.
    #[test]
    fn entries_being_created_are_never_cleaned() {
        let root = tempfile::tempdir().unwrap();
        // One being created by a live writer, which locks it 5 ms after the cleaner first
        // looks; one whose creator was killed before locking it.
        let young = root.path().join(format!("{NEW}young"));
        let old = root.path().join(format!("{NEW}old"));
        std::fs::create_dir(&young).unwrap();
        std::fs::create_dir(&old).unwrap();
        let creator = {
            let young = young.clone();
            std::thread::spawn(move || {
                std::thread::sleep(std::time::Duration::from_millis(5));
                let f = File::open(&young).unwrap();
                f.try_lock().unwrap();
                std::thread::sleep(std::time::Duration::from_millis(500));
                drop(f);
            })
        };
        let live = StagingDir::new(root.path()).unwrap();
        assert!(young.is_dir(), "a writer's entry in creation was removed");
        assert!(!old.exists(), "a killed creator's entry stayed");
        creator.join().unwrap();
        let name = live
            .path()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        assert!(name.starts_with(STAGING), "{name}");
        assert!(
            File::open(live.path()).unwrap().try_lock().is_err(),
            "live staging is unlocked"
        );
        let file = staging_file(&root.path().join("x.json")).unwrap();
        assert!(
            file.path()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(STAGING)
        );
        assert!(File::open(file.path()).unwrap().try_lock().is_err());
    }

    /// Issue 27, F11: the parent folder's symbolic link swapped while a folder is staged: the
    /// result lands where the run began, and no staging is left on either side.
    #[test]
    fn a_parent_link_swapped_mid_run_strands_nothing() {
        let root = tempfile::tempdir().unwrap();
        let (a, b) = (root.path().join("a"), root.path().join("b"));
        std::fs::create_dir(&a).unwrap();
        std::fs::create_dir(&b).unwrap();
        let link = root.path().join("link");
        std::os::unix::fs::symlink(&a, &link).unwrap();
        replace_dir(
            &link.join("out"),
            "t",
            |d| {
                std::fs::write(d.join("f"), "1")?;
                std::fs::remove_file(&link)?;
                std::os::unix::fs::symlink(&b, &link)
            },
            |e| e,
        )
        .unwrap();
        assert_eq!(std::fs::read_to_string(a.join("out/f")).unwrap(), "1");
        assert_eq!(names(&a), ["out"]);
        assert!(names(&b).is_empty(), "{:?}", names(&b));
        let file = staging_file(&link.join("g.json")).unwrap();
        std::fs::remove_file(&link).unwrap();
        std::os::unix::fs::symlink(&a, &link).unwrap();
        persist(file, &link.join("g.json")).unwrap();
        assert_eq!(names(&b), ["g.json"], "the file went where its staging was");
    }

    /// Issue 27, F10: a reader whose folder is swapped while it reads tries again and returns
    /// what one version gives.
    #[test]
    fn a_reader_retries_when_its_folder_is_swapped() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("cb");
        replace_dir(&dir, "t", |d| std::fs::write(d.join("v"), "1"), |e| e).unwrap();
        let mut calls = 0;
        let got = read_consistent(&dir, || {
            calls += 1;
            let v = std::fs::read_to_string(dir.join("v"));
            if calls == 1 {
                replace_dir(&dir, "t", |d| std::fs::write(d.join("v"), "2"), |e| e).unwrap();
            }
            v
        })
        .unwrap();
        assert_eq!((calls, got.as_str()), (2, "2"));
    }

    /// Issue 69: a destination inside a folder that is an input is refused — existing or
    /// not, through a link to the folder too — and one beside it is not.
    #[test]
    fn a_destination_inside_an_input_folder_is_refused() {
        let root = tempfile::tempdir().unwrap();
        let input = root.path().join("talker");
        std::fs::create_dir_all(input.join("mouths")).unwrap();
        std::fs::write(input.join("mouths/mouths.mp4"), b"kept").unwrap();
        let link = root.path().join("link");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        for inside in [
            input.join("mouths/mouths.mp4"),
            input.join("new/deeper/out.mp4"),
            link.join("out.mp4"),
        ] {
            let e = check_destination(&inside, &[&input]).unwrap_err();
            assert!(matches!(e, DestinationError::InsideInput { .. }), "{inside:?}: {e}");
        }
        check_destination(&root.path().join("out.mp4"), &[&input]).unwrap();
        check_destination(&root.path().join("talker2/out.mp4"), &[&input]).unwrap();
    }

    /// A memory file is read back through its path as written through it.
    #[test]
    fn a_memory_file_reads_back_by_its_path() {
        let m = MemoryFile::new("test").unwrap();
        std::fs::write(m.path(), b"speech").unwrap();
        assert_eq!(std::fs::read(m.path()).unwrap(), b"speech");
        assert!(std::fs::metadata(m.path()).unwrap().is_file());
        assert_eq!(m.file().metadata().unwrap().len(), 6);
    }
}
