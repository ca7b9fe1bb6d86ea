//! The first-frame search: no landmarks, only an image (DESIGN §4).

use image::RgbImage;

use super::level::{Level, scale_points};
use super::{FitError, Fitter};
use crate::shape::{Landmarks, Point};
use crate::warp::GreyImage;

impl Fitter<'_> {
    /// A first-frame start with no landmarks: the mean shape tried on a grid of positions
    /// (steps of a tenth of the face width) and scales (0.6–1.5 of the model's reference
    /// size) one octave below the coarsest pyramid level, scored by the projected-out
    /// residual against the mean appearance; the best dozen distinct places are each fitted
    /// on the coarsest level, and the lowest residual wins. Costs a few hundred warps of a
    /// few thousand pixels and twelve coarse fits.
    pub fn search_start(&self, image: &RgbImage) -> Result<Landmarks, FitError> {
        const SHORTLIST: usize = 12;
        // One octave below the coarsest level; built here, as only a first frame needs it.
        let search = Level::new(self.model, 2 * self.levels[0].factor)?;
        let grey = GreyImage::from_rgb(image);
        let mut candidates = self.grid_scores(&search, &grey)?;
        if candidates.is_empty() {
            return Err(FitError::TooSmall {
                width: image.width(),
                height: image.height(),
            });
        }
        // The best few *distinct* places (non-maximum suppression): neighbours of one
        // wrong minimum would otherwise fill the shortlist.
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut shortlist: Vec<(f64, Vec<Point>)> = Vec::with_capacity(SHORTLIST);
        for c in candidates {
            let (lo, hi) = Landmarks {
                points: c.1.clone(),
            }
            .bounds();
            let centre = crate::shape::centroid(&c.1);
            let apart = shortlist.iter().all(|k| {
                let other = crate::shape::centroid(&k.1);
                (centre[0] - other[0]).hypot(centre[1] - other[1]) > 0.25 * (hi[0] - lo[0])
            });
            if apart {
                shortlist.push(c);
                if shortlist.len() == SHORTLIST {
                    break;
                }
            }
        }
        let candidates = shortlist;
        let (level, ratio) = (&self.levels[0], search.factor as f64);
        let coarse = downsample(grey, level.factor);
        let mut best = (f64::INFINITY, Vec::new());
        for (_, placed) in candidates {
            let start = Landmarks {
                points: scale_points(&placed, ratio / level.factor as f64),
            };
            let (fitted, _, _, r) = self.fit_level(level, &coarse, &start, true)?;
            let r = r.unwrap_or(f64::INFINITY);
            if r < best.0 {
                best = (r, fitted.points);
            }
        }
        Ok(Landmarks {
            points: scale_points(&best.1, level.factor as f64),
        })
    }

    /// Residual of the mean shape at every grid position and scale on `level`'s image.
    fn grid_scores(
        &self,
        level: &Level,
        grey: &GreyImage,
    ) -> Result<Vec<(f64, Vec<Point>)>, FitError> {
        let coarse = downsample(grey.clone(), level.factor);
        let mean = self.model.shape.mean();
        let mut texture = vec![0f32; level.frame.n_pixels()];
        let mut out = Vec::new();
        let base = self.model.placement.scale / level.factor as f64;
        for scale in [0.6, 0.75, 0.9, 1.05, 1.25, 1.5] {
            let s = base * scale;
            let pts: Vec<Point> = mean.iter().map(|p| [s * p[0], s * p[1]]).collect();
            let (lo, hi) = Landmarks {
                points: pts.clone(),
            }
            .bounds();
            let step = (0.1 * (hi[0] - lo[0])).max(1.0);
            let (w, h) = (coarse.width as f64, coarse.height as f64);
            let mut cy = -lo[1];
            while cy + hi[1] <= h {
                let mut cx = -lo[0];
                while cx + hi[0] <= w {
                    let placed: Vec<Point> = pts.iter().map(|p| [p[0] + cx, p[1] + cy]).collect();
                    out.push((level.score(&coarse, &placed, &mut texture)?, placed));
                    cx += step;
                }
                cy += step;
            }
        }
        Ok(out)
    }
}

/// `image` halved until it is `factor` times smaller.
fn downsample(mut image: GreyImage, factor: usize) -> GreyImage {
    let mut f = 1;
    while f < factor {
        image = image.half();
        f *= 2;
    }
    image
}

impl Level {
    /// Projected-out residual of the mean appearance with the mesh at `placed` on `image`.
    fn score(
        &self,
        image: &GreyImage,
        placed: &[Point],
        error: &mut [f32],
    ) -> Result<f64, FitError> {
        self.error_into(image, placed, error)?;
        Ok(self.residual(error))
    }
}
