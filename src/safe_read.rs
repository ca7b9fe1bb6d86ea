//! Reading files that come from users and the network without being fooled: regular files
//! only (a FIFO blocks an open forever, a device never ends), inside the folder they claim to
//! be in (no links out), and bounded in size. Below every format reader (`npy`, `manifest`,
//! audio, video, labels), so none of them reads a path raw.

use std::path::Path;

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
