//! `study serve`: the viewers' page. Each viewer opens their own link; the page asks for the
//! viewer's next trial, plays it, and posts the answer, which is on disk before the page moves
//! on — so a reload or a restarted server resumes exactly where the viewer stopped.

use std::path::{Path, PathBuf};

use serde_json::json;

use super::answers::{AnswerLog, Refusal};
use super::{Manifest, SCALE, STIMULI, StudyError, Trial};
use crate::http::{self, Reply, Request, Server};

/// The page (HTML, CSS and JavaScript in one file).
const PAGE: &str = include_str!("page.html");

/// Largest stimulus file served (a clip of a few seconds is a few MB).
const MAX_STIMULUS: u64 = 256 << 20;

/// What a request did, for the caller's log.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// An answer stored: viewer and trial.
    Stored(String, usize),
    /// A request refused (path and reason).
    Refused(String, String),
    /// The server refused or dropped connections for want of resources (said once per
    /// episode).
    Notice(String),
}

/// A running study server.
pub struct StudyServer {
    server: Server,
    dir: PathBuf,
    log: AnswerLog,
}

impl StudyServer {
    /// Opens the study in `dir` (checking its manifest and the answers so far) and binds
    /// `addr`; a non-loopback address needs `allow_remote`. Returns the note of a torn last
    /// answer line cut off, if there was one.
    pub fn bind(
        dir: &Path,
        addr: &str,
        allow_remote: bool,
    ) -> Result<(StudyServer, Option<String>), StudyError> {
        let manifest = Manifest::load(dir)?;
        let (log, note) = AnswerLog::open(dir, manifest)?;
        let server = Server::bind(addr, allow_remote)?;
        Ok((
            StudyServer {
                server,
                dir: dir.into(),
                log,
            },
            note,
        ))
    }

    /// The same server holding to other connection limits.
    pub fn with_limits(self, limits: http::Limits) -> Self {
        StudyServer {
            server: self.server.with_limits(limits),
            ..self
        }
    }

    /// The server's address.
    pub fn url(&self) -> String {
        self.server.url()
    }

    /// Each viewer's link.
    pub fn links(&self) -> Vec<(String, String)> {
        let m = self.log.manifest();
        m.viewers
            .iter()
            .map(|v| (v.id.clone(), m.link(&self.url(), v)))
            .collect()
    }

    /// Serves until `stop` returns true (checked between requests and every 100 ms).
    pub fn run(&mut self, on_event: impl FnMut(Event), stop: impl Fn() -> bool) {
        let StudyServer { server, dir, log } = self;
        let on_event = std::cell::RefCell::new(on_event);
        server.serve(
            |request| {
                let mut on_event = on_event.borrow_mut();
                let reply = answer(dir, log, request, &mut *on_event)
                    .unwrap_or_else(|r| Reply::error(r.status, r.message));
                if !reply.is_ok() {
                    let why = String::from_utf8_lossy(&reply.body).into_owned();
                    on_event(Event::Refused(request.path.clone(), why));
                }
                reply.into()
            },
            stop,
            |notice| (on_event.borrow_mut())(Event::Notice(notice)),
        )
    }
}

fn not_found() -> Refusal {
    Refusal {
        status: 404,
        message: "not found".into(),
    }
}

fn answer(
    dir: &Path,
    log: &mut AnswerLog,
    request: &Request,
    on_event: &mut impl FnMut(Event),
) -> Result<Reply, Refusal> {
    let path = request.path.as_str();
    match (request.post, path) {
        (false, "/") => Ok(Reply::ok(
            PAGE.as_bytes().to_vec(),
            "text/html; charset=utf-8",
        )),
        (false, "/api/next") => {
            let viewer = request.param("viewer").unwrap_or("");
            let token = request.param("token").unwrap_or("");
            let next = log.next_trial(viewer, token)?;
            let trials = &log
                .manifest()
                .viewer(viewer)
                .expect("next_trial checked the viewer")
                .trials;
            let trial = trials.get(next);
            Ok(Reply::json(json!({
                "viewer": viewer,
                "trial": next,
                "total": trials.len(),
                "done": trial.is_none(),
                "kind": trial.map(|t| match t { Trial::Rate { .. } => "rate", Trial::Judge { .. } => "judge" }),
                // Each clip's address carries the viewer's secret: stimuli go to viewers only.
                "stimuli": trial.map(|t| t.stimuli().iter().map(|id| format!("/{STIMULI}/{id}.mp4?viewer={}&token={}", http::percent_encode(viewer), http::percent_encode(token))).collect::<Vec<_>>()),
                "scale": SCALE,
            })))
        }
        (true, "/api/answer") => {
            let stored = log.submit(&request.body)?;
            on_event(Event::Stored(stored.viewer.clone(), stored.trial));
            Ok(Reply::json(json!({"stored": stored.trial})))
        }
        (false, p) => {
            let file = p
                .strip_prefix(&format!("/{STIMULI}/"))
                .ok_or_else(not_found)?;
            let id = file.strip_suffix(".mp4").ok_or_else(not_found)?;
            let name = log
                .manifest()
                .stimulus(id)
                .ok_or_else(not_found)?
                .file_name();
            let viewer = request.param("viewer").unwrap_or("");
            let token = request.param("token").unwrap_or("");
            if viewer.is_empty() || token.is_empty() {
                return Err(Refusal {
                    status: 403,
                    message: "stimuli are served with a viewer's link only".into(),
                });
            }
            log.fetch(viewer, token, id)?;
            let folder = dir.join(STIMULI);
            let bytes =
                crate::safe_read::read_inside(&folder, &name, MAX_STIMULUS).map_err(|e| {
                    Refusal {
                        status: 500,
                        message: format!("{}: {e}", folder.join(&name).display()),
                    }
                })?;
            Ok(Reply::ok(bytes, http::mime(file)))
        }
        _ => Err(not_found()),
    }
}
