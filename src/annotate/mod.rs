//! `annotate`: a local page where a person places or corrects the 68 iBUG landmarks on each
//! frame of a folder (issue 15). The server only answers on the loopback interface unless
//! told otherwise, serves only the image files it listed, and writes `NAME.pts` atomically on
//! every change. Starting points: the frame's own `.pts`; else the model's fit; else the
//! model's mean shape, which the page places from two clicks on the eye centres.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use thiserror::Error;

use crate::fit::{FitOptions, Fitter};
use crate::http::{self, HttpError, Reply, Request, Server};
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
    /// The server could not start.
    #[error(transparent)]
    Http(#[from] HttpError),
}

/// A running annotation server.
pub struct Annotator {
    server: Server,
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
        let server = Server::bind(addr, allow_remote)?;
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
        self.server.url()
    }

    /// Serves requests until `stop` returns true (checked between requests and every 100 ms).
    pub fn run(&self, mut on_event: impl FnMut(Event), stop: impl Fn() -> bool) {
        self.server.serve(
            |request| {
                let reply = self.answer(request, &mut on_event);
                if !reply.is_ok() {
                    let why = String::from_utf8_lossy(&reply.body).into_owned();
                    on_event(Event::Refused(request.path.clone(), why));
                }
                reply
            },
            stop,
        )
    }

    fn answer(&self, request: &Request, on_event: &mut impl FnMut(Event)) -> Reply {
        let path = request.path.as_str();
        let reply = match (request.post, path) {
            (false, "/") => Ok(Reply::ok(
                PAGE.as_bytes().to_vec(),
                "text/html; charset=utf-8",
            )),
            (false, "/api/frames") => Ok(Reply::json(json!({
                "frames": self.frames,
                "mean": self.model.shape.mean(),
                "eyes": [[36, 37, 38, 39, 40, 41], [42, 43, 44, 45, 46, 47]],
            }))),
            (false, p) if p.starts_with("/frames/") => {
                self.frame(&p["/frames/".len()..]).and_then(|name| {
                    let bytes =
                        std::fs::read(self.dir.join(&name)).map_err(|e| (500, e.to_string()))?;
                    Ok(Reply::ok(bytes, http::mime(&name)))
                })
            }
            (false, p) if p.starts_with("/api/points/") => self
                .frame(&p["/api/points/".len()..])
                .and_then(|name| self.points(&name).map(Reply::json)),
            (true, p) if p.starts_with("/api/points/") => self
                .frame(&p["/api/points/".len()..])
                .and_then(|name| self.save(&name, &request.body))
                .map(|saved| {
                    on_event(Event::Saved(saved.clone()));
                    Reply::json(json!({"saved": saved.display().to_string()}))
                }),
            _ => Err((404, "not found".into())),
        };
        reply.unwrap_or_else(|(code, why)| Reply::error(code, why))
    }

    /// The frame named `name`, if it is one of the listed images.
    fn frame(&self, name: &str) -> Result<String, (u16, String)> {
        let name = name.to_owned();
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
