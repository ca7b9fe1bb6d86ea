//! Small raster plots for reports: line plots of trajectories and matrix heat maps, drawn
//! with imageproc's primitives into an `RgbImage` with an embedded font (DejaVu Sans Mono,
//! `data/fonts`).

use std::sync::OnceLock;

use ab_glyph::FontRef;
use image::{Rgb, RgbImage};
use imageproc::drawing::{
    draw_antialiased_line_segment_mut, draw_filled_circle_mut, draw_filled_rect_mut, draw_text_mut,
    text_size,
};
use imageproc::pixelops::interpolate;
use imageproc::rect::Rect;

use crate::facespace::Layout;
use crate::phonemes::Segment;

static FONT_BYTES: &[u8] = include_bytes!("../data/fonts/DejaVuSansMono.ttf");

fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_BYTES).expect("embedded font parses"))
}

/// Axis and text colour.
pub const BLACK: Rgb<u8> = Rgb([0, 0, 0]);
/// Distinct series colours (Tableau 10).
pub const PALETTE: [Rgb<u8>; 6] = [
    Rgb([31, 119, 180]),
    Rgb([255, 127, 14]),
    Rgb([44, 160, 44]),
    Rgb([214, 39, 40]),
    Rgb([148, 103, 189]),
    Rgb([140, 86, 75]),
];

/// Draws `s` with its top-left corner at (x, y).
fn text(img: &mut RgbImage, x: f32, y: f32, size: f32, s: &str, color: Rgb<u8>) {
    draw_text_mut(
        img,
        color,
        x.round() as i32,
        y.round() as i32,
        size,
        font(),
        s,
    );
}

/// Width of `s` in pixels.
fn text_width(size: f32, s: &str) -> f32 {
    text_size(size, font(), s).0 as f32
}

/// An anti-aliased line.
fn line(img: &mut RgbImage, a: (f32, f32), b: (f32, f32), color: Rgb<u8>) {
    let p = |v: (f32, f32)| (v.0.round() as i32, v.1.round() as i32);
    draw_antialiased_line_segment_mut(img, p(a), p(b), color, interpolate);
}

fn fill_rect(img: &mut RgbImage, x: u32, y: u32, w: u32, h: u32, color: Rgb<u8>) {
    if w > 0 && h > 0 {
        draw_filled_rect_mut(img, Rect::at(x as i32, y as i32).of_size(w, h), color);
    }
}

/// A perceptually ordered colour for `v ∈ [0, 1]` (viridis, five stops, linear between).
pub fn viridis(v: f64) -> Rgb<u8> {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = v.clamp(0.0, 1.0) * 4.0;
    let i = (t as usize).min(3);
    let f = t - i as f64;
    Rgb(std::array::from_fn(|c| {
        (STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f).round() as u8
    }))
}

/// A labelled heat map of a square matrix (`values[i * n + j]`, expected in [0, 1]).
pub fn heat_map(values: &[f64], labels: &[&str], title: &str) -> RgbImage {
    let n = labels.len();
    let cell = 16u32;
    let margin = 44u32;
    let size = margin + n as u32 * cell + 70;
    let mut img = RgbImage::from_pixel(size, size + 24, Rgb([255, 255, 255]));
    text(&mut img, margin as f32, 4.0, 14.0, title, BLACK);
    let top = margin + 24;
    for i in 0..n {
        for j in 0..n {
            fill_rect(
                &mut img,
                margin + j as u32 * cell,
                top + i as u32 * cell,
                cell - 1,
                cell - 1,
                viridis(values[i * n + j]),
            );
        }
        let w = text_width(11.0, labels[i]);
        text(
            &mut img,
            margin as f32 - w - 4.0,
            (top + i as u32 * cell) as f32 + 1.0,
            11.0,
            labels[i],
            BLACK,
        );
        text(
            &mut img,
            (margin + i as u32 * cell) as f32 + 1.0,
            top as f32 - 14.0,
            9.0,
            labels[i],
            BLACK,
        );
    }
    // Colour bar.
    let bar_x = margin + n as u32 * cell + 12;
    for k in 0..(n as u32 * cell) {
        let v = 1.0 - k as f64 / (n as u32 * cell - 1) as f64;
        fill_rect(&mut img, bar_x, top + k, 14, 1, viridis(v));
    }
    text(&mut img, (bar_x + 18) as f32, top as f32, 11.0, "1", BLACK);
    text(
        &mut img,
        (bar_x + 18) as f32,
        (top + n as u32 * cell) as f32 - 12.0,
        11.0,
        "0",
        BLACK,
    );
    img
}

/// One line series of a plot.
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Abscissae.
    pub x: &'a [f64],
    /// Ordinates.
    pub y: &'a [f64],
    /// Line colour.
    pub color: Rgb<u8>,
    /// Drawn as dots, not a line: a series that may lie on another line stays visible.
    pub dots: bool,
}

/// Tick positions at a "nice" step (1, 2 or 5 × 10^k) giving about five ticks in
/// `[lo, hi]`, and the decimals that step needs.
pub fn nice_ticks(lo: f64, hi: f64) -> (Vec<f64>, usize) {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return (vec![lo], 0);
    }
    let magnitude = 10f64.powf(((hi - lo) / 5.0).log10().floor());
    let ticks_at = |step: f64| -> Vec<f64> {
        ((lo / step).ceil() as i64..=(hi / step).floor() as i64)
            .map(|k| k as f64 * step)
            .collect()
    };
    // The 1-2-5 step whose tick count is nearest five.
    let step = [0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        .min_by_key(|&s| (ticks_at(s).len() as i64 - 5).abs())
        .expect("candidates");
    let ticks = ticks_at(step);
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    (ticks, decimals)
}

/// A plot's data area: where values land in pixels, with room for ticks and labels.
struct Axes {
    left: f32,
    top: f32,
    pw: f32,
    ph: f32,
    height: f32,
    x_min: f64,
    x_span: f64,
    y_min: f64,
    y_max: f64,
}

impl Axes {
    /// Axes over the points' range (y padded by 5%) on a `width × height` image, `bottom`
    /// pixels kept below the data area.
    fn new(
        (width, height): (u32, u32),
        xs: impl Iterator<Item = f64>,
        ys: impl Iterator<Item = f64>,
        bottom: f32,
    ) -> Self {
        let (left, right, top) = (60.0f32, 16.0f32, 28.0f32);
        let range = |v: &mut dyn Iterator<Item = f64>| {
            v.filter(|x| x.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                })
        };
        let (x_min, x_max) = range(&mut { xs });
        let (mut y_min, mut y_max) = range(&mut { ys });
        if y_max <= y_min || !y_max.is_finite() || !y_min.is_finite() {
            y_min = if y_min.is_finite() { y_min - 1.0 } else { 0.0 };
            y_max = y_min + 2.0;
        }
        let pad = 0.05 * (y_max - y_min);
        Axes {
            left,
            top,
            pw: width as f32 - left - right,
            ph: height as f32 - top - bottom,
            height: height as f32,
            x_min: if x_min.is_finite() { x_min } else { 0.0 },
            x_span: if x_max > x_min { x_max - x_min } else { 1.0 },
            y_min: y_min - pad,
            y_max: y_max + pad,
        }
    }

    fn px(&self, x: f64) -> f32 {
        self.left + ((x - self.x_min) / self.x_span) as f32 * self.pw
    }

    fn py(&self, y: f64) -> f32 {
        self.top + ((self.y_max - y) / (self.y_max - self.y_min)) as f32 * self.ph
    }

    /// Title, axes, ticks at 1-2-5 steps, and the axis labels.
    fn draw(&self, img: &mut RgbImage, title: &str, x_label: &str, y_label: &str) {
        self.draw_frame(img, title, x_label, y_label);
        let (top, ph) = (self.top, self.ph);
        let (x_ticks, x_decimals) = nice_ticks(self.x_min, self.x_min + self.x_span);
        for x in x_ticks {
            let label = format!("{x:.x_decimals$}");
            let px = self.px(x);
            text(
                img,
                px - 0.5 * text_width(10.0, &label),
                top + ph + 4.0,
                10.0,
                &label,
                BLACK,
            );
            line(img, (px, top + ph), (px, top + ph + 3.0), BLACK);
        }
    }

    /// Title, axes, the y ticks and the axis labels (the x ticks are the caller's).
    fn draw_frame(&self, img: &mut RgbImage, title: &str, x_label: &str, y_label: &str) {
        let (left, top, pw, ph) = (self.left, self.top, self.pw, self.ph);
        text(img, left, 6.0, 14.0, title, BLACK);
        line(img, (left, top + ph), (left + pw, top + ph), BLACK);
        line(img, (left, top), (left, top + ph), BLACK);
        let (y_ticks, y_decimals) = nice_ticks(self.y_min, self.y_max);
        for y in y_ticks {
            let label = format!("{y:.y_decimals$}");
            let py = self.py(y);
            text(
                img,
                left - text_width(10.0, &label) - 4.0,
                py - 6.0,
                10.0,
                &label,
                BLACK,
            );
            line(img, (left - 3.0, py), (left, py), BLACK);
        }
        text(
            img,
            left + pw - text_width(10.0, x_label),
            self.height - 14.0,
            10.0,
            x_label,
            BLACK,
        );
        text(img, left + 4.0, top + 2.0, 10.0, y_label, BLACK);
    }

    /// Legend entries in the top right corner, each drawn by `mark` at its left.
    fn legend<T>(
        &self,
        img: &mut RgbImage,
        entries: &[T],
        label: impl Fn(&T) -> &str,
        mut mark: impl FnMut(&mut RgbImage, &T, (f32, f32)),
    ) {
        let mut ly = self.top + 4.0;
        for e in entries {
            let lx = self.left + self.pw - text_width(10.0, label(e)) - 30.0;
            mark(img, e, (lx, ly + 6.0));
            text(img, lx + 24.0, ly, 10.0, label(e), BLACK);
            ly += 14.0;
        }
    }
}

/// A line plot with axes, ticks, a legend and optional shaded spans (`(x0, x1, label)`,
/// e.g. phone segments) along the bottom.
pub fn line_plot(
    title: &str,
    x_label: &str,
    series: &[Series],
    spans: &[(f64, f64, &str)],
    width: u32,
    height: u32,
) -> RgbImage {
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let axes = Axes::new(
        (width, height),
        series
            .iter()
            .flat_map(|s| s.x.iter().copied())
            .chain(spans.iter().flat_map(|s| [s.0, s.1])),
        series.iter().flat_map(|s| s.y.iter().copied()),
        if spans.is_empty() { 36.0 } else { 56.0 },
    );
    // Spans as alternating bands with labels.
    for (k, (a, b, label)) in spans.iter().enumerate() {
        let (xa, xb) = (axes.px(*a), axes.px(*b));
        if k % 2 == 0 {
            fill_rect(
                &mut img,
                xa as u32,
                axes.top as u32,
                (xb - xa).max(1.0) as u32,
                axes.ph as u32,
                Rgb([242, 242, 242]),
            );
        }
        let w = text_width(10.0, label);
        if w < xb - xa + 6.0 {
            let y = axes.top + axes.ph + 20.0;
            text(&mut img, 0.5 * (xa + xb) - 0.5 * w, y, 10.0, label, BLACK);
        }
    }
    axes.draw(&mut img, title, x_label, "");
    for s in series {
        let n = s.x.len().min(s.y.len());
        for k in 0..n {
            let at = (axes.px(s.x[k]), axes.py(s.y[k]));
            if s.dots {
                draw_filled_circle_mut(&mut img, (at.0.round() as i32, at.1.round() as i32), 2, s.color);
            } else if k > 0 {
                line(&mut img, (axes.px(s.x[k - 1]), axes.py(s.y[k - 1])), at, s.color);
            }
        }
    }
    axes.legend(
        &mut img,
        series,
        |s| s.label,
        |img, s, (x, y)| {
            if s.dots {
                for dx in [4.0, 10.0, 16.0] {
                    draw_filled_circle_mut(img, ((x + dx) as i32, y as i32), 2, s.color);
                }
            } else {
                line(img, (x, y), (x + 20.0, y), s.color)
            }
        },
    );
    img
}

/// One group of points of a scatter plot.
pub struct ScatterGroup<'a> {
    /// Legend text.
    pub label: &'a str,
    /// The points `(x, y)`.
    pub points: Vec<(f64, f64)>,
    /// Their colour.
    pub color: Rgb<u8>,
    /// Their radius, pixels.
    pub radius: i32,
}

/// A scatter plot with axes, ticks and a legend; later groups are drawn over earlier ones.
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    groups: &[ScatterGroup],
    width: u32,
    height: u32,
) -> RgbImage {
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let all = || groups.iter().flat_map(|g| g.points.iter().copied());
    let axes = Axes::new(
        (width, height),
        all().map(|p| p.0),
        all().map(|p| p.1),
        36.0,
    );
    axes.draw(&mut img, title, x_label, y_label);
    for g in groups {
        for &(x, y) in &g.points {
            let c = (axes.px(x).round() as i32, axes.py(y).round() as i32);
            draw_filled_circle_mut(&mut img, c, g.radius, g.color);
        }
    }
    axes.legend(
        &mut img,
        groups,
        |g| g.label,
        |img, g, (x, y)| draw_filled_circle_mut(img, (x as i32 + 10, y as i32), g.radius, g.color),
    );
    img
}

/// Two panels over time — the first shape and the first appearance parameter — of each
/// `(label, frames, dots)` series (`frames × layout.dims()` values at `fps`; `dots`: drawn as
/// dots, for a series that may lie under a line), with the phones as bands along the bottom.
pub fn parameter_plot(
    layout: Layout,
    fps: f64,
    series: &[(&str, ndarray::ArrayView2<'_, f32>, bool)],
    target: &[Segment],
) -> RgbImage {
    let spans: Vec<(f64, f64, &str)> = target
        .iter()
        .map(|s| (s.start, s.end, s.phone.name()))
        .collect();
    let mut panels = Vec::new();
    for (title, k) in [
        ("first shape parameter", layout.shape_range().start),
        (
            "first appearance parameter",
            layout.appearance_range().start,
        ),
    ] {
        let cols: Vec<(Vec<f64>, Vec<f64>)> = series
            .iter()
            .map(|(_, m, _)| {
                (
                    (0..m.nrows()).map(|i| i as f64 / fps).collect(),
                    m.column(k.min(m.ncols() - 1))
                        .iter()
                        .map(|&v| f64::from(v))
                        .collect(),
                )
            })
            .collect();
        let s: Vec<Series> = series
            .iter()
            .zip(&cols)
            .enumerate()
            .map(|(i, ((label, _, dots), (x, y)))| Series {
                label,
                x,
                y,
                color: PALETTE[i % PALETTE.len()],
                dots: *dots,
            })
            .collect();
        panels.push(line_plot(title, "time (s)", &s, &spans, 900, 260));
    }
    stack(&panels)
}

/// The `p`-quantile (0 ≤ p ≤ 1) of sorted values by linear interpolation between order
/// statistics (numpy's default, Hyndman & Fan type 7).
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = (sorted.len() - 1) as f64 * p.clamp(0.0, 1.0);
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// The median (the mean of the middle two for an even count; NaN for none).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    quantile(&s, 0.5)
}

/// Box plots of `groups` side by side: the box spans the quartiles with the median across it,
/// whiskers reach the furthest values within 1.5 IQR of the box, values beyond are dots, and
/// a diamond marks the mean.
pub fn box_plot(title: &str, y_label: &str, labels: &[&str], groups: &[Vec<f64>]) -> RgbImage {
    let (width, height) = ((120 + 110 * groups.len()) as u32, 360u32);
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let k = groups.len() as f64;
    let axes = Axes::new(
        (width, height),
        [-0.5, k - 0.5].into_iter(),
        groups.iter().flatten().copied().chain([0.0, 5.0]),
        40.0,
    );
    axes.draw_frame(&mut img, title, "", y_label);
    for (i, (g, label)) in groups.iter().zip(labels).enumerate() {
        let x = axes.px(i as f64);
        text(
            &mut img,
            x - 0.5 * text_width(10.0, label),
            axes.top + axes.ph + 6.0,
            10.0,
            label,
            BLACK,
        );
        let mut v: Vec<f64> = g.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            continue;
        }
        v.sort_by(f64::total_cmp);
        let (q1, q2, q3) = (quantile(&v, 0.25), quantile(&v, 0.5), quantile(&v, 0.75));
        let reach = 1.5 * (q3 - q1);
        // As matplotlib: a whisker never ends inside the box.
        let low = v
            .iter()
            .copied()
            .find(|&x| x >= q1 - reach)
            .unwrap_or(q1)
            .min(q1);
        let high = v
            .iter()
            .rev()
            .copied()
            .find(|&x| x <= q3 + reach)
            .unwrap_or(q3)
            .max(q3);
        let color = PALETTE[i % PALETTE.len()];
        let half = 0.3 * axes.pw / k as f32;
        let (top, bottom) = (axes.py(q3), axes.py(q1));
        let rect = Rect::at((x - half) as i32, top as i32)
            .of_size((2.0 * half) as u32, ((bottom - top) as u32).max(1));
        draw_filled_rect_mut(
            &mut img,
            rect,
            interpolate(color, Rgb([255, 255, 255]), 0.35),
        );
        for (a, b) in [
            ((x - half, top), (x + half, top)),
            ((x - half, bottom), (x + half, bottom)),
            ((x - half, top), (x - half, bottom)),
            ((x + half, top), (x + half, bottom)),
            ((x - half, axes.py(q2)), (x + half, axes.py(q2))),
            ((x, top), (x, axes.py(high))),
            ((x, bottom), (x, axes.py(low))),
            (
                (x - 0.4 * half, axes.py(high)),
                (x + 0.4 * half, axes.py(high)),
            ),
            (
                (x - 0.4 * half, axes.py(low)),
                (x + 0.4 * half, axes.py(low)),
            ),
        ] {
            line(&mut img, a, b, BLACK);
        }
        for &o in v.iter().filter(|&&o| o < low || o > high) {
            draw_filled_circle_mut(&mut img, (x as i32, axes.py(o) as i32), 2, BLACK);
        }
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let (mx, my) = (x, axes.py(m));
        for (a, b) in [
            ((mx - 4.0, my), (mx, my - 4.0)),
            ((mx, my - 4.0), (mx + 4.0, my)),
            ((mx + 4.0, my), (mx, my + 4.0)),
            ((mx, my + 4.0), (mx - 4.0, my)),
        ] {
            line(&mut img, a, b, BLACK);
        }
    }
    img
}

/// Images one above the other (as wide as the widest).
pub fn stack(panels: &[RgbImage]) -> RgbImage {
    let w = panels.iter().map(|p| p.width()).max().unwrap_or(0);
    let h = panels.iter().map(|p| p.height()).sum();
    let mut out = RgbImage::new(w, h);
    let mut y = 0;
    for p in panels {
        image::imageops::replace(&mut out, p, 0, y);
        y += i64::from(p.height());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{nice_ticks, quantile};

    /// numpy.percentile(x, [0, 25, 50, 75, 100]) for x = [1, 2, 4, 7, 11] and [3, 1] (linear).
    #[test]
    fn quantiles_match_numpy() {
        let x = [1.0, 2.0, 4.0, 7.0, 11.0];
        let want = [1.0, 2.0, 4.0, 7.0, 11.0];
        for (p, w) in [0.0, 0.25, 0.5, 0.75, 1.0].iter().zip(want) {
            assert_eq!(quantile(&x, *p), w);
        }
        assert_eq!(quantile(&[1.0, 2.0, 4.0, 7.0], 0.25), 1.75);
        assert_eq!(quantile(&[1.0, 3.0], 0.5), 2.0);
        assert!(quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn ticks_fall_on_round_steps() {
        assert_eq!(nice_ticks(0.0, 199.96), (vec![0.0, 50.0, 100.0, 150.0], 0));
        assert_eq!(
            nice_ticks(12.387, 37.919),
            (vec![15.0, 20.0, 25.0, 30.0, 35.0], 0)
        );
        let (t, d) = nice_ticks(0.389, 0.933);
        assert_eq!(d, 1);
        assert_eq!(t.len(), 6);
        assert!((t[0] - 0.4).abs() < 1e-12 && (t[5] - 0.9).abs() < 1e-12);
        let (t, d) = nice_ticks(-0.013, 0.021);
        assert_eq!((t.len(), d), (4, 2));
        assert!(t.iter().all(|v| (-0.013..=0.021).contains(v)));
        assert_eq!(nice_ticks(1.0, 1.0), (vec![1.0], 0));
    }
}
