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

/// Largest frame file served.
const MAX_FRAME_BYTES: u64 = 64 << 20;

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
    skipped: Vec<String>,
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
    /// The server refused or dropped connections for want of resources (said once per
    /// episode).
    Notice(String),
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
        // Only regular files with UTF-8 names: a symbolic link (perhaps to a file outside the
        // folder) or a FIFO is never listed, and a name the page could not send back intact
        // is left out rather than mangled.
        let (mut frames, mut skipped) = (Vec::new(), Vec::new());
        for path in video::image_files(dir).map_err(|e| folder(e.to_string()))? {
            let Some(name) = path.file_name() else {
                continue;
            };
            let regular = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file());
            match name.to_str() {
                Some(n) if regular => frames.push(n.to_owned()),
                Some(n) => skipped.push(format!("{n} (not a regular file)")),
                None => skipped.push(format!("{} (not a UTF-8 name)", name.to_string_lossy())),
            }
        }
        if frames.is_empty() {
            return Err(folder("no images (png, jpg) to annotate".into()));
        }
        let server = Server::bind(addr, allow_remote)?;
        Ok(Annotator {
            server,
            dir: dir.into(),
            frames,
            skipped,
            model,
            fit,
        })
    }

    /// The same server holding to other connection limits.
    pub fn with_limits(mut self, limits: http::Limits) -> Self {
        self.server = self.server.with_limits(limits);
        self
    }

    /// Images of the folder left out, with why (symbolic links, FIFOs, non-UTF-8 names).
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// The page's address.
    pub fn url(&self) -> String {
        self.server.url()
    }

    /// Serves requests until `stop` returns true (checked between requests and every 100 ms).
    pub fn run(&self, on_event: impl FnMut(Event), stop: impl Fn() -> bool) {
        let on_event = std::cell::RefCell::new(on_event);
        self.server.serve(
            |request| {
                let mut on_event = on_event.borrow_mut();
                let reply = self.answer(request, &mut *on_event);
                if !reply.is_ok() {
                    let why = String::from_utf8_lossy(&reply.body).into_owned();
                    on_event(Event::Refused(request.path.clone(), why));
                }
                reply
            },
            stop,
            |notice| (on_event.borrow_mut())(Event::Notice(notice)),
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
                    let bytes = crate::manifest::read_inside(&self.dir, &name, MAX_FRAME_BYTES)
                        .map_err(|e| (403, format!("{name}: {e}")))?;
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
        if std::fs::symlink_metadata(&pts).is_ok() {
            // Read only as a plain file of this folder (not a link to one outside it).
            let pts_name = pts.file_name().map(|n| n.to_string_lossy().into_owned());
            let text =
                crate::manifest::read_inside(&self.dir, &pts_name.unwrap_or_default(), 1 << 20)
                    .map_err(|e| (403, format!("{}: {e}", pts.display())))?;
            let l = shape::parse_pts(&String::from_utf8_lossy(&text), &pts)
                .map_err(|e| (500, e.to_string()))?;
            return Ok(json!({"points": l.points, "source": "pts"}));
        }
        if self.fit {
            let fitted = self.image(name).and_then(|image| {
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

    /// A listed frame, read as a plain file of the folder.
    fn image(&self, name: &str) -> Result<image::RgbImage, String> {
        let bytes = crate::manifest::read_inside(&self.dir, name, MAX_FRAME_BYTES)
            .map_err(|e| e.to_string())?;
        image::load_from_memory(&bytes)
            .map(|i| i.to_rgb8())
            .map_err(|e| format!("{name}: {e}"))
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
        // Inside the image, and spread out: a shape collapsed onto a point is no marking.
        let image = self.image(name).map_err(|e| (500, e))?;
        let (w, h) = (f64::from(image.width()), f64::from(image.height()));
        if let Some((k, p)) = landmarks
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !(0.0..=w).contains(&p[0]) || !(0.0..=h).contains(&p[1]))
        {
            return Err((
                400,
                format!(
                    "point {k} at ({}, {}) is outside the {w}×{h} image",
                    p[0], p[1]
                ),
            ));
        }
        let extent = |i: usize| {
            let v = landmarks.points.iter().map(|p| p[i]);
            v.clone().fold(f64::MIN, f64::max) - v.fold(f64::MAX, f64::min)
        };
        if extent(0) < 2.0 || extent(1) < 2.0 {
            return Err((
                400,
                "the points are all in one place (under 2 px apart)".into(),
            ));
        }
        let path = self.pts_path(name);
        shape::write_pts(&path, &landmarks).map_err(|e| (500, e.to_string()))?;
        Ok(path)
    }
}
