//! A headless Chromium driven over the DevTools protocol (`--remote-debugging-pipe`: JSON
//! messages ending in NUL on file descriptors 3 and 4), so browser tests use the shipped pages
//! as they are — no test hook in them — and act on them from outside, as a person would.

use std::io::{BufRead, BufReader, Write};
use std::os::fd::{FromRawFd, OwnedFd};
use std::os::unix::process::CommandExt;
use std::sync::mpsc;
use std::time::Duration;

use serde_json::{Value, json};

/// A running headless Chromium.
pub struct Browser {
    child: std::process::Child,
    to: std::fs::File,
    from: mpsc::Receiver<Value>,
    next: u64,
    _profile: tempfile::TempDir,
}

/// A tab's session.
pub struct Page(String);

fn pipe() -> (OwnedFd, OwnedFd) {
    let mut fds = [0; 2];
    // SAFETY: pipe2 writes two new descriptors into the array it is given.
    assert_eq!(unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) }, 0);
    // SAFETY: both descriptors were just opened and are owned here alone.
    unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) }
}

impl Browser {
    /// Starts `chromium` headless with an empty profile.
    pub fn launch(chromium: &str) -> Browser {
        Self::launch_with(chromium, &[])
    }

    /// [`Browser::launch`] with extra command-line switches (WebGL on SwiftShader, a WAV
    /// file as the microphone).
    pub fn launch_with(chromium: &str, extra: &[String]) -> Browser {
        use std::os::fd::AsRawFd;
        let profile = tempfile::tempdir().unwrap();
        let (their_in, our_out) = pipe();
        let (our_in, their_out) = pipe();
        let (fd3, fd4) = (their_in.as_raw_fd(), their_out.as_raw_fd());
        let mut command = std::process::Command::new(chromium);
        command
            .args([
                "--headless=new",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--autoplay-policy=no-user-gesture-required",
                "--remote-debugging-pipe",
                &format!("--user-data-dir={}", profile.path().display()),
            ])
            .args(extra)
            .arg("about:blank")
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null());
        // SAFETY: only async-signal-safe fcntl and dup2 calls between fork and exec.
        unsafe {
            command.pre_exec(move || {
                // Both ends first moved above 4, so that neither dup2 below can overwrite the
                // other (pipe2 may have handed out 3 and 4 themselves, swapped).
                let (read, write) = (
                    libc::fcntl(fd3, libc::F_DUPFD_CLOEXEC, 10),
                    libc::fcntl(fd4, libc::F_DUPFD_CLOEXEC, 10),
                );
                if read < 0 || write < 0 || libc::dup2(read, 3) < 0 || libc::dup2(write, 4) < 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        let child = command.spawn().unwrap();
        drop((their_in, their_out));
        let (tx, rx) = mpsc::channel();
        let reader = std::fs::File::from(our_in);
        std::thread::spawn(move || {
            let mut reader = BufReader::new(reader);
            loop {
                let mut message = Vec::new();
                match reader.read_until(0, &mut message) {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {
                        message.pop();
                        if let Ok(v) = serde_json::from_slice::<Value>(&message)
                            && tx.send(v).is_err()
                        {
                            return;
                        }
                    }
                }
            }
        });
        Browser {
            child,
            to: std::fs::File::from(our_out),
            from: rx,
            next: 1,
            _profile: profile,
        }
    }

    /// Sends a command (to a page's session or the browser) and waits for its result.
    fn call(&mut self, session: Option<&Page>, method: &str, params: Value) -> Value {
        let id = self.next;
        self.next += 1;
        let mut message = json!({"id": id, "method": method, "params": params});
        if let Some(Page(s)) = session {
            message["sessionId"] = json!(s);
        }
        let mut bytes = serde_json::to_vec(&message).unwrap();
        bytes.push(0);
        self.to.write_all(&bytes).unwrap();
        loop {
            let reply = self
                .from
                .recv_timeout(Duration::from_secs(120))
                .unwrap_or_else(|_| panic!("Chromium did not answer {method}"));
            if reply["id"] == json!(id) {
                if let Some(e) = reply.get("error") {
                    panic!("{method}: {e}");
                }
                return reply["result"].clone();
            }
        }
    }

    /// Opens `url` in a new tab and waits for its load event.
    pub fn open(&mut self, url: &str) -> Page {
        let target = self.call(None, "Target.createTarget", json!({"url": "about:blank"}));
        let attached = self.call(
            None,
            "Target.attachToTarget",
            json!({"targetId": target["targetId"], "flatten": true}),
        );
        let page = Page(attached["sessionId"].as_str().unwrap().to_owned());
        self.call(Some(&page), "Page.enable", json!({}));
        self.call(Some(&page), "Page.navigate", json!({"url": url}));
        loop {
            let event = self
                .from
                .recv_timeout(Duration::from_secs(120))
                .unwrap_or_else(|_| panic!("{url} never loaded"));
            if event["method"] == "Page.loadEventFired" && event["sessionId"] == json!(page.0) {
                return page;
            }
        }
    }

    /// Evaluates `expression` in the page (awaiting a promise) and returns its value; a
    /// thrown error fails the test with its text.
    pub fn eval(&mut self, page: &Page, expression: &str) -> Value {
        let r = self.call(
            Some(page),
            "Runtime.evaluate",
            json!({"expression": expression, "awaitPromise": true, "returnByValue": true}),
        );
        if let Some(e) = r.get("exceptionDetails") {
            panic!("the page threw: {e}");
        }
        r["result"]["value"].clone()
    }

    /// The page as a PNG, as shown.
    pub fn screenshot(&mut self, page: &Page) -> Vec<u8> {
        let r = self.call(Some(page), "Page.captureScreenshot", json!({"format": "png"}));
        base64(r["data"].as_str().unwrap())
    }

    /// Waits until `condition` (a JavaScript expression) is true in the page.
    pub fn wait_for(&mut self, page: &Page, condition: &str) {
        let script = format!(
            "(async () => {{ for (let i = 0; i < 600; i++) {{ try {{ if ({condition}) return true; }} catch (e) {{}} await new Promise(r => setTimeout(r, 50)); }} return false; }})()"
        );
        assert_eq!(
            self.eval(page, &script),
            json!(true),
            "the page never reached {condition}"
        );
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Bytes of standard base64 (as the DevTools protocol and `btoa` give them).
pub fn base64(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let bytes: Vec<u8> = s.bytes().filter(|&c| c != b'=').collect();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    for chunk in bytes.chunks(4) {
        let word = chunk
            .iter()
            .enumerate()
            .fold(0u32, |w, (i, &c)| w | (u32::from(value(c)) << (18 - 6 * i)));
        for k in 0..chunk.len() - 1 {
            out.push((word >> (16 - 8 * k)) as u8);
        }
    }
    out
}
