//! `annotate`: a local page where a person places or corrects the 68 iBUG landmarks on each
//! frame of a folder (issue 15). The server only answers on the loopback interface unless
//! told otherwise, serves only the image files it listed, and writes `NAME.pts` atomically on
//! every change. Starting points: the frame's own `.pts`; else the model's fit (`--fit`); else
//! the previous frame's points; else the model's mean shape, which the page places from three
//! clicks (the eye centres and the mouth). The page draws the iBUG contours and point numbers,
//! moves, rotates and scales the whole shape, refits the model from the points shown, saves an
//! accepted start with one key, and removes a `.pts` when undo returns a frame to unmarked.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use thiserror::Error;

use crate::fit::{FitOptions, Fitter};
use crate::http::{self, Answer, HttpError, Reply, Request, Server};
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
    /// A frame's landmarks removed (undo back to unmarked).
    Removed(PathBuf),
    /// A request refused (path and reason).
    Refused(String, String),
    /// The server refused or dropped connections for want of resources (said once per
    /// episode).
    Notice(String),
}

impl Annotator {
    /// Binds `addr` for the images in `dir`. `model` gives the mean shape and, when `fit` is
    /// set, each unmarked frame's starting fit; a region model lends its whole-face tracker,
    /// since frames are marked with all 68 points. Non-loopback addresses need `allow_remote`.
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
    /// Model fits (a refit, a `--fit` start) run off the event loop ([`http::Answer::Later`]),
    /// so a flood of them never delays another answer; their refusals (422, 503) go to the
    /// page, not to `on_event`.
    pub fn run(&self, on_event: impl FnMut(Event), stop: impl Fn() -> bool) {
        let on_event = std::cell::RefCell::new(on_event);
        self.server.serve(
            |request| {
                let mut on_event = on_event.borrow_mut();
                let answer = self.answer(request, &mut *on_event);
                if let Answer::Now(reply) = &answer
                    && !reply.is_ok()
                {
                    let why = String::from_utf8_lossy(&reply.body).into_owned();
                    on_event(Event::Refused(request.path.clone(), why));
                }
                answer
            },
            stop,
            |notice| (on_event.borrow_mut())(Event::Notice(notice)),
        )
    }

    fn answer(&self, request: &Request, on_event: &mut impl FnMut(Event)) -> Answer<'_> {
        let path = request.path.as_str();
        let reply = match (request.post, path) {
            (false, "/") => Ok(Reply::ok(
                PAGE.as_bytes().to_vec(),
                "text/html; charset=utf-8",
            )),
            (false, "/api/frames") => Ok(Reply::json(self.listing())),
            (false, p) if p.starts_with("/frames/") => {
                self.frame(&p["/frames/".len()..]).and_then(|name| {
                    let bytes = crate::safe_read::read_inside(&self.dir, &name, MAX_FRAME_BYTES)
                        .map_err(|e| (403, format!("{name}: {e}")))?;
                    Ok(Reply::ok(bytes, http::mime(&name)))
                })
            }
            (false, p) if p.starts_with("/api/points/") => {
                match self.frame(&p["/api/points/".len()..]) {
                    Ok(name) => return self.points(name),
                    Err(e) => Err(e),
                }
            }
            (true, p) if p.starts_with("/api/points/") => self
                .frame(&p["/api/points/".len()..])
                .and_then(|name| self.save(&name, &request.body))
                .map(|change| match change {
                    Change::Saved(path) => {
                        on_event(Event::Saved(path.clone()));
                        Reply::json(json!({"saved": path.display().to_string()}))
                    }
                    Change::Removed(path) => {
                        on_event(Event::Removed(path.clone()));
                        Reply::json(json!({"removed": path.display().to_string()}))
                    }
                    Change::Unmarked => Reply::json(json!({"removed": null})),
                }),
            (true, p) if p.starts_with("/api/fit/") => {
                let checked = self
                    .frame(&p["/api/fit/".len()..])
                    .and_then(|name| self.posted(&name, &request.body))
                    .and_then(|posted| posted.ok_or((400, "points: none given".to_owned())));
                match checked {
                    Ok((start, image)) => {
                        return Answer::Later(Box::new(move || {
                            self.refit(&start, &image)
                                .map(Reply::json)
                                .unwrap_or_else(|(code, why)| Reply::error(code, why))
                        }));
                    }
                    Err(e) => Err(e),
                }
            }
            _ => Err((404, "not found".into())),
        };
        Answer::Now(reply.unwrap_or_else(|(code, why)| Reply::error(code, why)))
    }

    /// The frames, which of them are marked, the mean shape and, for the iBUG scheme, its
    /// contours and the point groups the page places from clicks (eyes, then mouth).
    fn listing(&self) -> Value {
        let marker = self.model.tracker();
        let marked: Vec<&String> = self
            .frames
            .iter()
            .filter(|f| std::fs::symlink_metadata(self.pts_path(f)).is_ok_and(|m| m.is_file()))
            .collect();
        let ibug = marker.shape.n_landmarks() == shape::IBUG_POINTS;
        let contours: Vec<Value> = shape::IBUG_CONTOURS
            .iter()
            .map(|&(first, last, closed)| json!([first, last, closed]))
            .collect();
        json!({
            "frames": self.frames,
            "marked": marked,
            "mean": marker.shape.mean(),
            "contours": if ibug { json!(contours) } else { json!([]) },
            "anchors": if ibug {
                json!(shape::IBUG_EYES_AND_MOUTH.map(|r| r.collect::<Vec<_>>()))
            } else {
                json!([])
            },
        })
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
    /// (the page starts from the previous frame's points, or places the mean from clicks).
    /// The model's fit runs off the event loop.
    fn points(&self, name: String) -> Answer<'_> {
        let pts = self.pts_path(&name);
        if std::fs::symlink_metadata(&pts).is_ok() {
            // Read only as a plain file of this folder (not a link to one outside it).
            let pts_name = pts.file_name().map(|n| n.to_string_lossy().into_owned());
            let read =
                crate::safe_read::read_inside(&self.dir, &pts_name.unwrap_or_default(), 1 << 20)
                    .map_err(|e| (403, format!("{}: {e}", pts.display())))
                    .and_then(|text| {
                        shape::parse_pts(&String::from_utf8_lossy(&text), &pts)
                            .map_err(|e| (500, e.to_string()))
                    });
            return Answer::Now(match read {
                Ok(l) => Reply::json(json!({"points": l.points, "source": "pts"})),
                Err((code, why)) => Reply::error(code, why),
            });
        }
        let none = || Reply::json(json!({"points": null, "source": "none"}));
        if !self.fit {
            return Answer::Now(none());
        }
        Answer::Later(Box::new(move || {
            let fitted = self.image(&name).and_then(|image| {
                let fitter = self.fitter()?;
                let start = fitter.search_start(&image).map_err(|e| e.to_string())?;
                let fit = fitter.fit(&image, &start).map_err(|e| e.to_string())?;
                Ok((untrusted(&fit, &image), fit))
            });
            // A fit the refit would refuse (unexplained, or off the image) is no start either.
            match fitted {
                Ok((None, fit)) => {
                    Reply::json(json!({"points": fit.landmarks.points, "source": "fit"}))
                }
                Ok((Some(why), _)) => {
                    Reply::json(json!({"points": null, "source": "none", "rejected": why}))
                }
                Err(_) => none(),
            }
        }))
    }

    fn fitter(&self) -> Result<Fitter<'_>, String> {
        Fitter::new(self.model.tracker(), FitOptions::default(), 2).map_err(|e| e.to_string())
    }

    /// The model fitted to a frame from the points the page shows (`{"points": …}`): the
    /// previous frame's marking, a placed mean or a rough drag, refined by AAM search.
    fn refit(&self, start: &Landmarks, image: &image::RgbImage) -> Result<Value, (u16, String)> {
        let fit = self
            .fitter()
            .and_then(|f| f.fit(image, start).map_err(|e| e.to_string()))
            .map_err(|e| (422, format!("the model could not be fitted: {e}")))?;
        if let Some(why) = untrusted(&fit, image) {
            return Err((
                422,
                format!("{why}: points kept; correct them by hand, or start from a model of this talker"),
            ));
        }
        Ok(json!({"points": fit.landmarks.points, "error": fit.error, "source": "fit"}))
    }

    /// A listed frame, read as a plain file of the folder.
    fn image(&self, name: &str) -> Result<image::RgbImage, String> {
        let bytes = crate::safe_read::read_inside(&self.dir, name, MAX_FRAME_BYTES)
            .map_err(|e| e.to_string())?;
        image::load_from_memory(&bytes)
            .map(|i| i.to_rgb8())
            .map_err(|e| format!("{name}: {e}"))
    }

    fn pts_path(&self, name: &str) -> PathBuf {
        self.dir.join(Path::new(name).with_extension("pts"))
    }

    /// Validates posted landmarks (`{"points": [[x, y], …]}`, or `null` for none): the
    /// marker's count, inside the image, spread out. Returns them with the frame they were
    /// checked against.
    fn posted(
        &self,
        name: &str,
        body: &str,
    ) -> Result<Option<(Landmarks, image::RgbImage)>, (u16, String)> {
        let value: Value = serde_json::from_str(body).map_err(|e| (400, e.to_string()))?;
        // Only an explicit `{"points": null}` unmarks: a body without the key (`{}`, `[]`,
        // `{"x": 1}`) would otherwise read as null and delete a hand-made `.pts`.
        let Some(points) = value.as_object().and_then(|o| o.get("points")) else {
            return Err((
                400,
                "the body must be {\"points\": [[x, y], …]} or {\"points\": null}".into(),
            ));
        };
        let points: Option<Vec<[f64; 2]>> =
            serde_json::from_value(points.clone()).map_err(|e| (400, format!("points: {e}")))?;
        let Some(points) = points else {
            return Ok(None);
        };
        let landmarks = Landmarks { points };
        landmarks
            .validate(Some(self.model.tracker().shape.n_landmarks()), name)
            .map_err(|e| (400, e.to_string()))?;
        // Inside the image, and spread out: a shape collapsed onto a point is no marking.
        let image = self.image(name).map_err(|e| (500, e))?;
        let (w, h) = (image.width(), image.height());
        if let Some((k, p)) = first_outside(&landmarks, &image) {
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
        Ok(Some((landmarks, image)))
    }

    /// Writes posted landmarks atomically, or with `{"points": null}` removes the frame's
    /// `.pts` (a plain file of the folder, never a link's target).
    fn save(&self, name: &str, body: &str) -> Result<Change, (u16, String)> {
        let path = self.pts_path(name);
        match self.posted(name, body)? {
            Some((landmarks, _)) => {
                shape::write_pts(&path, &landmarks).map_err(|e| (500, e.to_string()))?;
                Ok(Change::Saved(path))
            }
            None => match std::fs::symlink_metadata(&path) {
                Err(_) => Ok(Change::Unmarked),
                Ok(m) if m.is_file() => std::fs::remove_file(&path)
                    .map(|()| Change::Removed(path.clone()))
                    .map_err(|e| (500, format!("{}: {e}", path.display()))),
                Ok(_) => Err((
                    403,
                    format!("{}: not a regular file (not removed)", path.display()),
                )),
            },
        }
    }
}

/// Why a fit must not replace or start anyone's points: a fit the model cannot explain (as the
/// tracker judges a lost face; NaN counts as unexplained), or one that left the image (a
/// diverged search) would only give worse points than none. `None`: it can be offered.
fn untrusted(fit: &crate::fit::FitResult, image: &image::RgbImage) -> Option<String> {
    let threshold = crate::fit::DEFAULT_REINIT_ERROR;
    let inside = first_outside(&fit.landmarks, image).is_none();
    (!fit.explained() || !inside).then(|| {
        format!(
            "the model does not explain this face (residual {:.1} grey levels, a face it was built for fits under {threshold}{})",
            fit.error,
            if inside { "" } else { "; the fit left the image" }
        )
    })
}

/// The first point outside the image (its index and the point), if any.
fn first_outside<'a>(
    landmarks: &'a Landmarks,
    image: &image::RgbImage,
) -> Option<(usize, &'a shape::Point)> {
    let (w, h) = (f64::from(image.width()), f64::from(image.height()));
    landmarks
        .points
        .iter()
        .enumerate()
        .find(|(_, p)| !(0.0..=w).contains(&p[0]) || !(0.0..=h).contains(&p[1]))
}

/// What a posted marking did to a frame's `.pts`.
enum Change {
    Saved(PathBuf),
    Removed(PathBuf),
    /// Asked to remove, but there was none.
    Unmarked,
}
