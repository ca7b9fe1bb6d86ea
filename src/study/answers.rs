//! The answer log `answers.jsonl`: one JSON line per answer, appended and fsynced before the
//! viewer is told it was stored, so a crash loses no acknowledged answer. Every submission is
//! checked against the manifest first — the viewer's secret, the trial being that viewer's
//! next one (no replays, no skipping), the answer fitting the trial, scores on the scale — and
//! a refused one stores nothing.

use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{ANSWERS, Manifest, SCALE, StudyError, Trial};

/// What a viewer answered.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Response {
    /// Scores of a pair's two clips, in the order shown, on the 1–50 scale.
    Scores {
        /// [first, second].
        scores: [f64; 2],
    },
    /// The Turing-test judgement.
    Judgement {
        /// True for "real".
        real: bool,
    },
}

/// One stored answer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    /// The viewer.
    pub viewer: String,
    /// The trial's index in the viewer's order.
    pub trial: usize,
    /// The stimulus ids shown (recorded so the log reads on its own).
    pub stimuli: Vec<String>,
    /// The answer.
    #[serde(flatten)]
    pub response: Response,
    /// Seconds since the Unix epoch when it was stored.
    pub at: f64,
    /// Seconds from this viewer's first fetch of the trial's last-fetched clip to the
    /// answer (absent in logs from before it was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after_fetch: Option<f64>,
}

/// Slack allowed on "answered after playing through": an answer may come this many seconds
/// before the clip's duration has passed since it was fetched (start-up and clock grain).
pub const ANSWER_SLACK_SECONDS: f64 = 0.5;

/// A submission as the page posts it.
#[derive(Deserialize)]
struct Submission {
    viewer: String,
    token: String,
    trial: usize,
    #[serde(flatten)]
    response: Response,
}

/// Why a submission was refused (nothing was stored).
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    /// HTTP status: 400 malformed, 403 wrong secret, 404 unknown viewer, 409 not the next
    /// trial, 422 an answer that does not fit.
    pub status: u16,
    /// Why.
    pub message: String,
}

fn refuse(status: u16, message: impl Into<String>) -> Refusal {
    Refusal {
        status,
        message: message.into(),
    }
}

/// Checks `response` against `trial` (the right kind; scores finite and on the scale).
pub fn check_response(trial: &Trial, response: &Response) -> Result<(), String> {
    match (trial, response) {
        (Trial::Rate { .. }, Response::Scores { scores }) => {
            for s in scores {
                if !(s.is_finite() && (SCALE[0]..=SCALE[1]).contains(s)) {
                    return Err(format!(
                        "score {s} is outside the scale {} … {}",
                        SCALE[0], SCALE[1]
                    ));
                }
            }
            Ok(())
        }
        (Trial::Judge { .. }, Response::Judgement { .. }) => Ok(()),
        (Trial::Rate { .. }, _) => Err("this trial asks for two scores".into()),
        (Trial::Judge { .. }, _) => Err("this trial asks real or synthetic".into()),
    }
}

/// The answers stored so far, each checked against the manifest, and a note when a torn last
/// line (a crash in mid-write, never acknowledged) was left out.
pub fn read(dir: &Path, manifest: &Manifest) -> Result<(Vec<Answer>, Option<String>), StudyError> {
    let path = dir.join(ANSWERS);
    let text = match crate::safe_read::read_regular_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((Vec::new(), None)),
        Err(source) => return Err(StudyError::Io { path, source }),
    };
    let (whole, torn) = match text.rfind('\n') {
        Some(i) => (&text[..=i], &text[i + 1..]),
        None => ("", text.as_str()),
    };
    let mut next = vec![0usize; manifest.viewers.len()];
    let mut answers = Vec::new();
    for (line_no, line) in whole.lines().enumerate() {
        let bad = |m: String| StudyError::invalid(&path, format!("line {}: {m}", line_no + 1));
        let a: Answer = serde_json::from_str(line).map_err(|e| bad(e.to_string()))?;
        let v = manifest
            .viewers
            .iter()
            .position(|v| v.id == a.viewer)
            .ok_or_else(|| bad(format!("viewer {} is not in the study", a.viewer)))?;
        if a.trial != next[v] {
            return Err(bad(format!(
                "viewer {} trial {} out of order (expected {})",
                a.viewer, a.trial, next[v]
            )));
        }
        let trial = manifest.viewers[v]
            .trials
            .get(a.trial)
            .ok_or_else(|| bad(format!("viewer {} has no trial {}", a.viewer, a.trial)))?;
        if trial.stimuli() != a.stimuli {
            return Err(bad("the stimuli differ from the manifest's".into()));
        }
        check_response(trial, &a.response).map_err(bad)?;
        next[v] += 1;
        answers.push(a);
    }
    let note = (!torn.is_empty()).then(|| {
        format!(
            "{}: a torn last line ({} bytes, a write cut by a crash before it was acknowledged) was left out",
            path.display(),
            torn.len()
        )
    });
    Ok((answers, note))
}

/// The log open for appending, with where each viewer stands.
pub struct AnswerLog {
    path: PathBuf,
    file: File,
    manifest: Manifest,
    next: Vec<usize>,
    /// When each (viewer, stimulus) was first fetched in this server's life.
    fetched: std::collections::HashMap<(usize, String), std::time::Instant>,
}

impl AnswerLog {
    /// Opens (or creates) the log of the study in `dir`, checking what is stored; a torn last
    /// line from a crash is cut off so that new answers start on a line of their own.
    pub fn open(dir: &Path, manifest: Manifest) -> Result<(AnswerLog, Option<String>), StudyError> {
        let (answers, note) = read(dir, &manifest)?;
        let path = dir.join(ANSWERS);
        let io = |source| StudyError::Io {
            path: path.clone(),
            source,
        };
        let existed = path.exists();
        // Never through a symbolic link planted in the folder, never a FIFO or device.
        let mut options = OpenOptions::new();
        options.read(true).write(true).create(true).truncate(false);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::custom_flags(
            &mut options,
            libc::O_NOFOLLOW | libc::O_NONBLOCK,
        );
        let mut file = options.open(&path).map_err(io)?;
        if !file.metadata().map_err(io)?.is_file() {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file",
            )));
        }
        if note.is_some() {
            let mut text = String::new();
            std::io::Read::read_to_string(&mut file, &mut text).map_err(io)?;
            let keep = text.rfind('\n').map_or(0, |i| i + 1);
            file.set_len(keep as u64).map_err(io)?;
            file.sync_all().map_err(io)?;
        }
        file.seek(SeekFrom::End(0)).map_err(io)?;
        if !existed {
            // The new file's name is durable too.
            File::open(dir).and_then(|d| d.sync_all()).map_err(io)?;
        }
        let next = manifest
            .viewers
            .iter()
            .map(|v| answers.iter().filter(|a| a.viewer == v.id).count())
            .collect();
        Ok((
            AnswerLog {
                path,
                file,
                manifest,
                next,
                fetched: Default::default(),
            },
            note,
        ))
    }

    /// The study.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// The index of `viewer`'s next trial (= trials answered), after checking their secret.
    pub fn next_trial(&self, viewer: &str, token: &str) -> Result<usize, Refusal> {
        let v = self.viewer_index(viewer, token)?;
        Ok(self.next[v])
    }

    fn viewer_index(&self, viewer: &str, token: &str) -> Result<usize, Refusal> {
        let v = self
            .manifest
            .viewers
            .iter()
            .position(|v| v.id == viewer)
            .ok_or_else(|| refuse(404, format!("viewer {viewer:?} is not in this study")))?;
        if !constant_time_eq(self.manifest.viewers[v].token.as_bytes(), token.as_bytes()) {
            return Err(refuse(
                403,
                format!("wrong secret for viewer {viewer}: use the link made for them"),
            ));
        }
        Ok(v)
    }

    /// Notes that `viewer` (with their secret) fetched stimulus `id`, one of their trials'
    /// clips; the first fetch is what an answer's timing is measured from.
    pub fn fetch(&mut self, viewer: &str, token: &str, id: &str) -> Result<(), Refusal> {
        self.fetched_at(viewer, token, id, std::time::Instant::now())
    }

    /// [`fetch`](Self::fetch) for a fetch known to have happened at `at` (one replayed from
    /// elsewhere); the earliest fetch counts.
    pub fn fetched_at(
        &mut self,
        viewer: &str,
        token: &str,
        id: &str,
        at: std::time::Instant,
    ) -> Result<(), Refusal> {
        let v = self.viewer_index(viewer, token)?;
        let theirs = self.manifest.viewers[v]
            .trials
            .iter()
            .any(|t| t.stimuli().contains(&id));
        if !theirs {
            return Err(refuse(
                404,
                format!("{id} is not a clip of viewer {viewer}"),
            ));
        }
        let first = self.fetched.entry((v, id.to_owned())).or_insert(at);
        *first = (*first).min(at);
        Ok(())
    }

    /// Seconds since `viewer` fetched the last of `trial`'s clips, after checking each has
    /// had its whole duration (less [`ANSWER_SLACK_SECONDS`]) since its fetch.
    fn played_through(&self, v: usize, trial: &Trial) -> Result<f64, Refusal> {
        let mut after = f64::INFINITY;
        for id in trial.stimuli() {
            let Some(at) = self.fetched.get(&(v, id.to_owned())) else {
                return Err(refuse(
                    425,
                    format!("clip {id} was never fetched: answer after playing it"),
                ));
            };
            let seconds = at.elapsed().as_secs_f64();
            let duration = self
                .manifest
                .stimulus(id)
                .map_or(0.0, |s| s.frames as f64 / self.manifest.fps);
            if seconds + ANSWER_SLACK_SECONDS < duration {
                return Err(refuse(
                    425,
                    format!(
                        "answered {seconds:.2} s after fetching clip {id}, which lasts {duration:.2} s: play it through first"
                    ),
                ));
            }
            after = after.min(seconds);
        }
        Ok(after)
    }

    /// Checks and stores a submission (`{"viewer", "token", "trial", "scores": [a, b]}` or
    /// `{…, "real": bool}`); returns the stored answer once it is on disk.
    pub fn submit(&mut self, body: &str) -> Result<Answer, Refusal> {
        let s: Submission =
            serde_json::from_str(body).map_err(|e| refuse(400, format!("not an answer: {e}")))?;
        let v = self.viewer_index(&s.viewer, &s.token)?;
        let viewer = &self.manifest.viewers[v];
        let next = self.next[v];
        if next == viewer.trials.len() {
            return Err(refuse(
                409,
                format!("viewer {} has answered every trial", viewer.id),
            ));
        }
        if s.trial != next {
            let why = if s.trial < next {
                format!(
                    "trial {} of viewer {} is already answered (answers are final)",
                    s.trial, viewer.id
                )
            } else {
                format!(
                    "trial {} of viewer {} is not the next one ({next})",
                    s.trial, viewer.id
                )
            };
            return Err(refuse(409, why));
        }
        let trial = &viewer.trials[next];
        check_response(trial, &s.response).map_err(|m| refuse(422, m))?;
        let after_fetch = self.played_through(v, trial)?;
        let answer = Answer {
            viewer: s.viewer,
            trial: s.trial,
            stimuli: trial.stimuli().iter().map(|s| s.to_string()).collect(),
            response: s.response,
            at: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
            after_fetch: Some(after_fetch),
        };
        let mut line = serde_json::to_string(&answer).expect("an answer serialises");
        line.push('\n');
        // One write of the whole line, then fsync: acknowledged answers survive a crash. A
        // failed write (a full disk) is cut back off, so the log stays whole lines.
        let len = self.file.stream_position();
        let written = self
            .file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.sync_data());
        if let Err(e) = written {
            if let Ok(len) = len {
                let _ = self.file.set_len(len);
                let _ = self.file.seek(SeekFrom::Start(len));
            }
            return Err(refuse(500, format!("{}: {e}", self.path.display())));
        }
        self.next[v] += 1;
        Ok(answer)
    }
}

/// Equality that takes as long whatever the first differing byte (a secret compared by a
/// server should not leak its prefix through timing).
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}
