//! Training sets: images with hand-marked landmarks of the same file stem.

use std::path::{Path, PathBuf};

use image::RgbImage;
use rayon::prelude::*;

use super::ModelError;
use crate::shape::{self, Landmarks};
use crate::video;

/// How far (as a fraction of the image size) a landmark may lie outside its image before the
/// pair is taken to be from different frames.
const OUTSIDE_TOLERANCE: f64 = 0.05;

/// One training image with its hand-marked landmarks.
#[derive(Clone, Debug)]
pub struct TrainingExample {
    /// Where it came from (recorded in the model's `source`).
    pub name: String,
    /// The image.
    pub image: RgbImage,
    /// Its landmarks.
    pub landmarks: Landmarks,
}

/// Loads every image in `images` with the `.pts` (or menpo `.ljson`) file of the same stem
/// from `landmarks` (default: the same folder), checking that the pairs belong together.
pub fn load_training_set(
    images: &Path,
    landmarks: Option<&Path>,
) -> Result<Vec<TrainingExample>, ModelError> {
    Ok(load_marked(images, landmarks, false)?.0)
}

/// [`load_training_set`] of the images that have landmarks, when `skip_unmarked` (a frame
/// folder only partly marked on the annotate page); also returns the images left out.
pub fn load_marked(
    images: &Path,
    landmarks: Option<&Path>,
    skip_unmarked: bool,
) -> Result<(Vec<TrainingExample>, Vec<PathBuf>), ModelError> {
    let pts_dir = landmarks.unwrap_or(images);
    let io = |dir: &Path| {
        let dir = dir.to_path_buf();
        move |source| ModelError::Io { path: dir, source }
    };
    let mut image_paths = video::image_files(images).map_err(io(images))?;
    let mut unmarked = Vec::new();
    if skip_unmarked {
        let marked = |p: &PathBuf| {
            let stem = pts_dir.join(p.file_stem().unwrap_or_default());
            stem.with_extension("pts").is_file() || stem.with_extension("ljson").is_file()
        };
        (image_paths, unmarked) = image_paths.into_iter().partition(marked);
    }
    if image_paths.is_empty() {
        return Err(ModelError::NoImages { dir: images.into() });
    }
    let stems: Vec<&std::ffi::OsStr> = image_paths.iter().filter_map(|p| p.file_stem()).collect();
    let mut marked = video::files_with_extension(pts_dir, "pts").map_err(io(pts_dir))?;
    marked.extend(video::files_with_extension(pts_dir, "ljson").map_err(io(pts_dir))?);
    let orphan = marked
        .into_iter()
        .find(|p| !p.file_stem().is_some_and(|s| stems.contains(&s)));
    if let Some(pts) = orphan {
        return Err(ModelError::OrphanLandmarks { pts });
    }
    let examples = image_paths
        .par_iter()
        .map(|image_path| {
            // iBUG .pts, or menpo's .ljson where there is no .pts.
            let stem = pts_dir.join(image_path.file_stem().unwrap_or_default());
            let pts = [stem.with_extension("pts"), stem.with_extension("ljson")]
                .into_iter()
                .find(|p| p.is_file())
                .ok_or_else(|| ModelError::MissingLandmarks {
                    image: image_path.clone(),
                    pts: stem.with_extension("pts"),
                })?;
            let landmarks = shape::read_landmarks(&pts)?;
            let image =
                crate::video::read_image(image_path).map_err(|source| ModelError::Image {
                    path: image_path.clone(),
                    source,
                })?;
            check_inside(&landmarks, &image, &pts, image_path)?;
            Ok::<_, ModelError>((
                pts,
                TrainingExample {
                    name: image_path.display().to_string(),
                    image,
                    landmarks,
                },
            ))
        })
        .collect::<Result<Vec<(PathBuf, TrainingExample)>, _>>()?;
    let (first_pts, first) = &examples[0];
    for (pts, ex) in &examples {
        if ex.landmarks.len() != first.landmarks.len() {
            return Err(ModelError::LandmarkCount {
                path: pts.clone(),
                expected: first.landmarks.len(),
                found: ex.landmarks.len(),
                first: first_pts.clone(),
            });
        }
    }
    Ok((examples.into_iter().map(|(_, e)| e).collect(), unmarked))
}

fn check_inside(
    landmarks: &Landmarks,
    image: &RgbImage,
    pts: &Path,
    image_path: &Path,
) -> Result<(), ModelError> {
    let (w, h) = (image.width() as f64, image.height() as f64);
    let (mx, my) = (OUTSIDE_TOLERANCE * w, OUTSIDE_TOLERANCE * h);
    match landmarks
        .points
        .iter()
        .position(|p| p[0] < -mx || p[1] < -my || p[0] > w + mx || p[1] > h + my)
    {
        Some(index) => Err(ModelError::LandmarksOutsideImage {
            pts: pts.into(),
            image: image_path.into(),
            index,
            point: landmarks.points[index],
            width: image.width(),
            height: image.height(),
        }),
        None => Ok(()),
    }
}

/// Fewest and most reference-frame pixels [`face_pixels`] chooses.
pub const FACE_PIXELS: std::ops::RangeInclusive<usize> = 5_000..=200_000;

/// The reference-frame size that matches the faces of `examples` as recorded: the median,
/// over the examples, of the area their landmarks' convex hull covers in the image, rounded
/// to a thousand and held within [`FACE_PIXELS`] — so a model of a face 120 px wide draws it
/// at about its own resolution (GRID s1: ≈ 20 000) and one of a 720×576 close-up keeps the
/// detail that a fixed count would blur at full size (issue 33).
pub fn face_pixels(examples: &[TrainingExample]) -> usize {
    let mut areas: Vec<f64> = examples
        .iter()
        .filter_map(|e| {
            let p = &e.landmarks.points;
            let triangles = crate::mesh::delaunay(p).ok()?;
            Some(
                triangles
                    .iter()
                    .map(|t| {
                        let [a, b, c] = t.map(|v| p[v as usize]);
                        crate::mesh::signed_area(a, b, c).abs() / 2.0
                    })
                    .sum(),
            )
        })
        .collect();
    if areas.is_empty() {
        return *FACE_PIXELS.start();
    }
    areas.sort_by(f64::total_cmp);
    let median = areas[areas.len() / 2];
    (((median / 1000.0).round() as usize) * 1000).clamp(*FACE_PIXELS.start(), *FACE_PIXELS.end())
}
