//! Similarity transforms (the pose of a face-space point) and their least-squares fit.

use serde::{Deserialize, Serialize};

use super::Point;

/// A similarity transform `p ↦ [a −b; b a] p + t`, with `a = s cos θ`, `b = s sin θ`.
/// This is the pose of a face-space point (DESIGN §1): `[a, b, tx, ty]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Similarity {
    /// `s cos θ`.
    pub a: f64,
    /// `s sin θ`.
    pub b: f64,
    /// Translation, x.
    pub tx: f64,
    /// Translation, y.
    pub ty: f64,
}

impl Similarity {
    /// The transform that changes nothing.
    pub const IDENTITY: Similarity = Similarity {
        a: 1.0,
        b: 0.0,
        tx: 0.0,
        ty: 0.0,
    };

    /// Scale `s`, rotation `angle` (radians, counter-clockwise in x-right/y-up terms), then
    /// translation.
    pub fn new(scale: f64, angle: f64, tx: f64, ty: f64) -> Self {
        Similarity {
            a: scale * angle.cos(),
            b: scale * angle.sin(),
            tx,
            ty,
        }
    }

    /// The scale `s`.
    pub fn scale(&self) -> f64 {
        self.a.hypot(self.b)
    }

    /// The rotation θ (radians).
    pub fn angle(&self) -> f64 {
        self.b.atan2(self.a)
    }

    /// The transformed point.
    pub fn apply(&self, p: Point) -> Point {
        [
            self.a * p[0] - self.b * p[1] + self.tx,
            self.b * p[0] + self.a * p[1] + self.ty,
        ]
    }

    /// Every point transformed.
    pub fn apply_all(&self, points: &[Point]) -> Vec<Point> {
        points.iter().map(|&p| self.apply(p)).collect()
    }

    /// The inverse transform (the scale must be non-zero).
    pub fn invert(&self) -> Self {
        let d = self.a * self.a + self.b * self.b;
        let (a, b) = (self.a / d, -self.b / d);
        Similarity {
            a,
            b,
            tx: -(a * self.tx - b * self.ty),
            ty: -(b * self.tx + a * self.ty),
        }
    }

    /// `self ∘ other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Similarity) -> Self {
        let t = self.apply([other.tx, other.ty]);
        Similarity {
            a: self.a * other.a - self.b * other.b,
            b: self.a * other.b + self.b * other.a,
            tx: t[0],
            ty: t[1],
        }
    }

    /// `[a, b, tx, ty]`: the pose block of a face-space vector.
    pub fn to_array(&self) -> [f64; 4] {
        [self.a, self.b, self.tx, self.ty]
    }

    /// From `[a, b, tx, ty]`.
    pub fn from_array(v: [f64; 4]) -> Self {
        Similarity {
            a: v[0],
            b: v[1],
            tx: v[2],
            ty: v[3],
        }
    }
}

/// The least-squares similarity `T` minimising `Σ |T(from_i) − to_i|²` (Umeyama / ordinary
/// Procrustes). `None` when `from` has no extent.
pub fn align(from: &[Point], to: &[Point]) -> Option<Similarity> {
    assert_eq!(from.len(), to.len(), "align: point counts differ");
    let cf = centroid(from);
    let ct = centroid(to);
    let (mut denom, mut num_a, mut num_b) = (0.0, 0.0, 0.0);
    for (f, t) in from.iter().zip(to) {
        let (fx, fy, tx, ty) = (f[0] - cf[0], f[1] - cf[1], t[0] - ct[0], t[1] - ct[1]);
        denom += fx * fx + fy * fy;
        num_a += fx * tx + fy * ty;
        num_b += fx * ty - fy * tx;
    }
    if denom <= f64::MIN_POSITIVE {
        return None;
    }
    let (a, b) = (num_a / denom, num_b / denom);
    Some(Similarity {
        a,
        b,
        tx: ct[0] - (a * cf[0] - b * cf[1]),
        ty: ct[1] - (b * cf[0] + a * cf[1]),
    })
}

/// The mean of the points.
pub fn centroid(points: &[Point]) -> Point {
    let n = points.len() as f64;
    let s = points
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
    [s[0] / n, s[1] / n]
}

/// Centres the points and scales them to unit Frobenius norm.
pub(super) fn normalise(points: &[Point]) -> Option<Vec<Point>> {
    let c = centroid(points);
    let centred: Vec<Point> = points.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect();
    let norm = centred
        .iter()
        .map(|p| p[0] * p[0] + p[1] * p[1])
        .sum::<f64>()
        .sqrt();
    (norm > f64::MIN_POSITIVE).then(|| centred.iter().map(|p| [p[0] / norm, p[1] / norm]).collect())
}
