//! Generalised Procrustes analysis of a set of shapes.

use super::similarity::normalise;
use super::{Landmarks, Point, ShapeError, Similarity, align};

/// Result of generalised Procrustes analysis.
#[derive(Clone, Debug)]
pub struct Procrustes {
    /// The mean shape: centred, unit norm, in the orientation of the first shape.
    pub mean: Vec<Point>,
    /// Each shape mapped into the mean's frame: `poses[i].invert()` applied to shape `i`.
    /// These lie in the tangent plane of the mean (`x · mean = 1`, no rotation or
    /// translation component) because each pose is fitted from the mean onto the shape.
    pub aligned: Vec<Vec<Point>>,
    /// `poses[i]` maps the mean frame onto shape `i` in its image.
    pub poses: Vec<Similarity>,
    /// Alignment rounds until the mean settled.
    pub iterations: usize,
}

/// Generalised Procrustes analysis: align every shape to the mean, re-estimate the mean,
/// normalise it (centre, unit norm, orientation held to the previous estimate), repeat until
/// the mean moves less than 1e-12.
pub fn generalised_procrustes(shapes: &[Landmarks]) -> Result<Procrustes, ShapeError> {
    if shapes.len() < 2 {
        return Err(ShapeError::TooFewShapes(shapes.len()));
    }
    let n = shapes[0].len();
    for (i, s) in shapes.iter().enumerate() {
        s.validate(Some(n), &format!("shape {i}"))?;
    }
    let degenerate = |i: usize| ShapeError::Degenerate {
        what: format!("shape {i}"),
    };
    let mut mean = normalise(&shapes[0].points).ok_or_else(|| degenerate(0))?;
    let mut iterations = 0;
    loop {
        iterations += 1;
        let poses = shapes
            .iter()
            .enumerate()
            .map(|(i, s)| {
                align(&mean, &s.points)
                    .filter(|t| t.scale() > 0.0)
                    .ok_or_else(|| degenerate(i))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let aligned: Vec<Vec<Point>> = shapes
            .iter()
            .zip(&poses)
            .map(|(s, t)| t.invert().apply_all(&s.points))
            .collect();
        let mut next = vec![[0.0, 0.0]; n];
        for shape in &aligned {
            for (m, p) in next.iter_mut().zip(shape) {
                m[0] += p[0] / shapes.len() as f64;
                m[1] += p[1] / shapes.len() as f64;
            }
        }
        let next = normalise(&next).ok_or(ShapeError::Degenerate {
            what: "mean shape".into(),
        })?;
        // Hold the orientation: rotate the new mean onto the old one (rotation only).
        let t = align(&next, &mean).expect("normalised mean has extent");
        let rotation = Similarity {
            a: t.a / t.scale(),
            b: t.b / t.scale(),
            tx: 0.0,
            ty: 0.0,
        };
        let next = rotation.apply_all(&next);
        let change: f64 = next
            .iter()
            .zip(&mean)
            .map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2))
            .sum();
        mean = next;
        if change.sqrt() < 1e-12 || iterations >= 100 {
            // Re-derive poses and aligned shapes against the final mean.
            let poses: Vec<Similarity> = shapes
                .iter()
                .enumerate()
                .map(|(i, s)| align(&mean, &s.points).ok_or_else(|| degenerate(i)))
                .collect::<Result<_, _>>()?;
            let aligned = shapes
                .iter()
                .zip(&poses)
                .map(|(s, t)| t.invert().apply_all(&s.points))
                .collect();
            return Ok(Procrustes {
                mean,
                aligned,
                poses,
                iterations,
            });
        }
    }
}
