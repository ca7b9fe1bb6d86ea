//! Tracking a clip for the examples that score against it.

use std::path::Path;

use facespace::codec::{self, EncodeOptions};
use facespace::facespace::Frames;
use facespace::model::FaceModel;
use facespace::shape::Point;
use facespace::video::Source;
use image::RgbImage;

/// Every frame of `clip`, its tracked face-space points (projected with `model`) and the
/// tracked landmarks.
pub fn tracked(model: &FaceModel, clip: &Path) -> (Vec<RgbImage>, Frames, Vec<Vec<Point>>) {
    let source = Source::open(clip).unwrap();
    let fps = source.info().fps;
    let (mut images, mut rows, mut marks) = (Vec::new(), Vec::new(), Vec::new());
    codec::track(
        model,
        source,
        &EncodeOptions::default(),
        facespace::no_progress,
        |image, t| {
            let start = rows.len();
            rows.resize(start + model.layout().dims(), 0.0);
            model.project_into(&image, &t.landmarks, &mut rows[start..])?;
            marks.push(t.landmarks.points.clone());
            images.push(image);
            Ok(())
        },
    )
    .unwrap();
    let frames = Frames::from_rows(model.layout(), fps, rows).unwrap();
    (images, frames, marks)
}
