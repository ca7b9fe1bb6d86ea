//! `annotate`: a local page where a person places or corrects the 68 iBUG landmarks on each
//! frame of a folder (issue 15). The server only answers on the loopback interface unless
//! told otherwise, serves only the image files it listed, and writes `NAME.pts` atomically on
//! every change. Starting points: the frame's own `.pts`; else the model's fit; else the
//! model's mean shape, which the page places from two clicks on the eye centres.

use std::io::Read;
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use thiserror::Error;

use crate::fit::{FitOptions, Fitter};
use crate::model::FaceModel;
use crate::shape::{self, Landmarks};
use crate::video;

/// The page (HTML, CSS and JavaScript in one file).
const PAGE: &str = include_str!("page.html");

/// What can go wrong starting the server.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum AnnotateError {
    /// The folder cannot be listed or has no images.
    #[error("{path}: {reason}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A non-loopback address without permission.
    #[error(
        "{0} is not a loopback address: the page would be reachable from other machines; pass --allow-remote if that is meant"
    )]
    NotLoopback(SocketAddr),
    /// The address cannot be bound.
    #[error("cannot listen on {addr}: {reason}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        reason: String,
    },
}

/// A running annotation server.
pub struct Annotator {
    server: tiny_http::Server,
    dir: PathBuf,
    frames: Vec<String>,
    model: FaceModel,
    fit: bool,
}

/// What a request did, for the caller's log.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Landmarks saved.
    Saved(PathBuf),
    /// A request refused (path and reason).
    Refused(String, String),
}

impl Annotator {
    /// Binds `addr` for the images in `dir`. `model` gives the mean shape and, when `fit` is
    /// set, each unmarked frame's starting fit. Non-loopback addresses need `allow_remote`.
    pub fn bind(
        dir: &Path,
        model: FaceModel,
        fit: bool,
        addr: &str,
        allow_remote: bool,
    ) -> Result<Self, AnnotateError> {
        let folder = |reason: String| AnnotateError::Folder {
            path: dir.into(),
            reason,
        };
        let frames: Vec<String> = video::image_files(dir)
            .map_err(|e| folder(e.to_string()))?
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        if frames.is_empty() {
            return Err(folder("no images (png, jpg) to annotate".into()));
        }
        let bind = |reason: String| AnnotateError::Bind {
            addr: addr.into(),
            reason,
        };
        let resolved: Vec<SocketAddr> = addr
            .to_socket_addrs()
            .map_err(|e| bind(e.to_string()))?
            .collect();
        let first = *resolved.first().ok_or_else(|| bind("no address".into()))?;
        if let Some(a) = resolved.iter().find(|a| !a.ip().is_loopback())
            && !allow_remote
        {
            return Err(AnnotateError::NotLoopback(*a));
        }
        let server = tiny_http::Server::http(first).map_err(|e| bind(e.to_string()))?;
        Ok(Annotator {
            server,
            dir: dir.into(),
            frames,
            model,
            fit,
        })
    }

    /// The page's address.
    pub fn url(&self) -> String {
        match self.server.server_addr().to_ip() {
            Some(a) => format!("http://{a}/"),
            None => "http://localhost/".into(),
        }
    }

    /// Serves requests until `stop` returns true (checked between requests and every 100 ms).
    pub fn run(&self, mut on_event: impl FnMut(Event), stop: impl Fn() -> bool) {
        while !stop() {
            match self
                .server
                .recv_timeout(std::time::Duration::from_millis(100))
            {
                Ok(Some(request)) => self.answer(request, &mut on_event),
                Ok(None) => {}
                Err(_) => break,
            }
        }
    }

    fn answer(&self, mut request: tiny_http::Request, on_event: &mut impl FnMut(Event)) {
        let url = request.url().to_owned();
        let path = url.split('?').next().unwrap_or("").to_owned();
        let method = request.method().clone();
        let reply = match (method, path.as_str()) {
            (tiny_http::Method::Get, "/") => Ok(Reply::new(
                PAGE.as_bytes().to_vec(),
                "text/html; charset=utf-8",
            )),
            (tiny_http::Method::Get, "/api/frames") => Ok(Reply::json(json!({
                "frames": self.frames,
                "mean": self.model.shape.mean(),
                "eyes": [[36, 37, 38, 39, 40, 41], [42, 43, 44, 45, 46, 47]],
            }))),
            (tiny_http::Method::Get, p) if p.starts_with("/frames/") => {
                self.frame(&p["/frames/".len()..]).and_then(|name| {
                    let bytes =
                        std::fs::read(self.dir.join(&name)).map_err(|e| (500, e.to_string()))?;
                    Ok(Reply::new(bytes, mime(&name)))
                })
            }
            (tiny_http::Method::Get, p) if p.starts_with("/api/points/") => self
                .frame(&p["/api/points/".len()..])
                .and_then(|name| self.points(&name).map(Reply::json)),
            (tiny_http::Method::Post, p) if p.starts_with("/api/points/") => {
                let mut body = String::new();
                let read = request
                    .as_reader()
                    .take(1 << 20)
                    .read_to_string(&mut body)
                    .map_err(|e| (400, e.to_string()));
                read.and_then(|_| self.frame(&p["/api/points/".len()..]))
                    .and_then(|name| self.save(&name, &body))
                    .map(|saved| {
                        on_event(Event::Saved(saved.clone()));
                        Reply::json(json!({"saved": saved.display().to_string()}))
                    })
            }
            _ => Err((404, "not found".into())),
        };
        let response = match reply {
            Ok(r) => tiny_http::Response::from_data(r.body).with_header(
                tiny_http::Header::from_bytes("Content-Type", r.mime).expect("valid header"),
            ),
            Err((code, why)) => {
                on_event(Event::Refused(path.clone(), why.clone()));
                tiny_http::Response::from_data(why.into_bytes()).with_status_code(code)
            }
        };
        let _ = request.respond(response);
    }

    /// The frame named (URL-encoded) `raw`, if it is one of the listed images.
    fn frame(&self, raw: &str) -> Result<String, (u16, String)> {
        let name = percent_decode(raw).ok_or((400, "bad name encoding".to_owned()))?;
        if self.frames.contains(&name) {
            Ok(name)
        } else {
            Err((404, format!("{name:?} is not a frame of this folder")))
        }
    }

    /// Starting points for a frame: its `.pts`, else the model's fit (when asked), else none
    /// (the page places the mean shape from two eye clicks).
    fn points(&self, name: &str) -> Result<Value, (u16, String)> {
        let pts = self.pts_path(name);
        if pts.is_file() {
            let l = shape::read_pts(&pts).map_err(|e| (500, e.to_string()))?;
            return Ok(json!({"points": l.points, "source": "pts"}));
        }
        if self.fit {
            let fitted = video::read_frame(&self.dir.join(name))
                .map_err(|e| e.to_string())
                .and_then(|image| {
                    let fitter = Fitter::new(&self.model, FitOptions::default(), 2)
                        .map_err(|e| e.to_string())?;
                    let start = fitter.search_start(&image).map_err(|e| e.to_string())?;
                    fitter.fit(&image, &start).map_err(|e| e.to_string())
                });
            if let Ok(fit) = fitted {
                return Ok(json!({"points": fit.landmarks.points, "source": "fit"}));
            }
        }
        Ok(json!({"points": null, "source": "none"}))
    }

    fn pts_path(&self, name: &str) -> PathBuf {
        self.dir.join(Path::new(name).with_extension("pts"))
    }

    /// Validates and writes posted landmarks (`{"points": [[x, y], …]}`) atomically.
    fn save(&self, name: &str, body: &str) -> Result<PathBuf, (u16, String)> {
        let value: Value = serde_json::from_str(body).map_err(|e| (400, e.to_string()))?;
        let points: Vec<[f64; 2]> = serde_json::from_value(value["points"].clone())
            .map_err(|e| (400, format!("points: {e}")))?;
        let landmarks = Landmarks { points };
        landmarks
            .validate(Some(self.model.shape.n_landmarks()), name)
            .map_err(|e| (400, e.to_string()))?;
        let path = self.pts_path(name);
        shape::write_pts(&path, &landmarks).map_err(|e| (500, e.to_string()))?;
        Ok(path)
    }
}

struct Reply {
    body: Vec<u8>,
    mime: &'static str,
}

impl Reply {
    fn new(body: Vec<u8>, mime: &'static str) -> Self {
        Reply { body, mime }
    }
    fn json(v: Value) -> Self {
        Reply::new(v.to_string().into_bytes(), "application/json")
    }
}

fn mime(name: &str) -> &'static str {
    match Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => "image/png",
        Some("jpg" | "jpeg") => "image/jpeg",
        _ => "application/octet-stream",
    }
}

/// Decodes `%XX` escapes (UTF-8); `None` for a malformed escape or invalid UTF-8.
fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}
