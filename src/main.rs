//! The `facespace` command line: a thin clap layer over the library.

mod cli;

fn main() {
    // Like other Unix tools, end quietly when the reader of our output goes away
    // (`facespace … | head`) instead of panicking on a failed print.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Mesa's Vulkan driver complains on stderr when XDG_RUNTIME_DIR is unset (containers, CI);
    // we never present to a window, so any private writable folder will do.
    #[cfg(unix)]
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // SAFETY: no other thread exists yet.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) }
    }
    if let Err(err) = cli::run() {
        eprintln!("error: {}", error_chain(&err));
        std::process::exit(1);
    }
}

/// The context chain joined by ": ". Library errors already display their sources, so a cause
/// whose text the message so far contains is not repeated.
fn error_chain(err: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if message.contains(&text) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message
}
