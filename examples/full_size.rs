//! The synthesised face at full size, over real video (issue 25): the gradient step across the
//! region's border and the shimmer on the cheeks beside the nose (lips left out), each beside
//! the real video's value on the same pixels ([`facespace::eval::seams`]).
//!
//! - `cargo run --release --example full_size -- grid CORPUS [N]`: **recorded**, GRID s1. The
//!   first N (default all) sentences of a `corpus from-videos` corpus of his test split, each
//!   synthesised as the demo does (blend N = 5, λ = 3e-5, the committed codebook) from its own
//!   phone labels, drawn over its own video (pose replayed, appearance re-lit to the take).
//! - `cargo run --release --example full_size -- demo DIR BACKGROUND`: a `demo --talker
//!   fgnet` output folder (its `model` and `smoothed/trajectory.npy`) drawn again over its
//!   background video (**generated** corpus, real background).
//! - `... -- picture CORPUS SENTENCE FRAME FGNET_DIR OUT.png`: the README's full-size picture —
//!   one GRID test sentence's frame, real beside synthesised, with 3× crops of the nose and of
//!   the border at the jaw; and the FGNet demo's nose and cheeks at 3×, real beside synthesised.

use std::path::{Path, PathBuf};

use facespace::codebook::Codebook;
use facespace::codec::EncodeOptions;
use facespace::corpus;
use facespace::eval::seams::{Defects, measure};
use facespace::facespace::Frames;
use facespace::model::FaceModel;
use facespace::phonemes::PhoneMap;
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Renderer, feather_alpha, stream};
use facespace::synth::backdrop::{Backdrop, PoseMode};
use facespace::synth::{self, Request, Smoothing, blend::Blend};
use facespace::video::Source;
use image::RgbImage;

fn frames_of(path: &Path, n: usize) -> Vec<RgbImage> {
    let mut source = Source::open(path).unwrap();
    let mut out = Vec::new();
    while out.len() < n {
        match source.next_frame().unwrap() {
            Some(f) => out.push(f),
            None => break,
        }
    }
    out
}

fn render(model: &FaceModel, frames: &Frames, backdrop: &Backdrop) -> Vec<RgbImage> {
    let renderer = CpuRenderer::feathered(model, DEFAULT_FEATHER);
    let mut out = Vec::new();
    stream::<facespace::render::RenderError>(
        &renderer as &dyn Renderer,
        frames,
        backdrop.background().unwrap(),
        |f| {
            out.push(f);
            Ok(())
        },
        facespace::no_progress,
    )
    .unwrap();
    out
}

/// The window of `image` of side `side` centred at `c`, scaled `k`× (nearest neighbour).
fn crop(image: &RgbImage, c: [f64; 2], side: u32, k: u32) -> RgbImage {
    let x = (c[0] - f64::from(side) / 2.0).clamp(0.0, f64::from(image.width() - side)) as u32;
    let y = (c[1] - f64::from(side) / 2.0).clamp(0.0, f64::from(image.height() - side)) as u32;
    let window = image::imageops::crop_imm(image, x, y, side, side).to_image();
    image::imageops::resize(
        &window,
        side * k,
        side * k,
        image::imageops::FilterType::Nearest,
    )
}

/// Images side by side (`across`) or stacked, with a 4-pixel white gap.
fn join(images: &[RgbImage], across: bool) -> RgbImage {
    let along = |i: &RgbImage| if across { i.width() } else { i.height() };
    let beside = |i: &RgbImage| if across { i.height() } else { i.width() };
    let length = images.iter().map(|i| along(i) + 4).sum::<u32>() - 4;
    let breadth = images.iter().map(beside).max().unwrap();
    let (w, h) = if across {
        (length, breadth)
    } else {
        (breadth, length)
    };
    let mut out = RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut at = 0;
    for i in images {
        let (x, y) = if across { (at, 0) } else { (0, at) };
        image::imageops::overlay(&mut out, i, i64::from(x), i64::from(y));
        at += along(i) + 4;
    }
    out
}

fn report(what: &str, d: &Defects) {
    println!(
        "{what}: border |∇| {:.2} vs real {:.2} ({:.2}×); cheek shimmer {:.3} vs real {:.3} grey/frame ({:.2}×, Δ {:+.3})",
        d.border,
        d.border_real,
        d.border / d.border_real,
        d.shimmer,
        d.shimmer_real,
        d.shimmer / d.shimmer_real,
        d.shimmer - d.shimmer_real
    );
}

/// One GRID sentence synthesised as the demo does over its own video: the frames drawn, the
/// rendered images and the real ones.
fn grid_sentence(
    model: &FaceModel,
    cb: &Codebook,
    s: &facespace::corpus::Sentence,
) -> (Frames, Vec<RgbImage>, Vec<RgbImage>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let clip: PathBuf = root.join(format!("../shared/data/grid-s1/clips/{}.mp4", s.name));
    // The demo's settings when BENCHMARKS' table was made (blend N = 5, λ = 3e-5).
    let blend = Blend {
        top_n: 5,
        ..Blend::default()
    };
    let frames = synth::frame_count(&s.segments, 25.0);
    let backdrop = Backdrop::video(
        model,
        &clip,
        PoseMode::Replay,
        frames,
        &EncodeOptions::default(),
        facespace::no_progress,
    )
    .unwrap();
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(
            s.segments.clone(),
            25.0,
            Smoothing::On(3e-5),
        )
    };
    let mut u = synth::synthesise(&blend, cb, request).unwrap();
    backdrop.match_lighting(model, cb, &mut u);
    backdrop.anchor_region(model, &mut u).unwrap();
    let drawn = u.smoothed.clone().unwrap_or(u.synthesis.frames.clone());
    let rendered = render(model, &drawn, &backdrop);
    let real = frames_of(&clip, rendered.len());
    (drawn, rendered, real)
}

/// Photometric matching tried on the border (issue 25): per channel, the face's offset (and,
/// with `gain`, its gain, clamped to [0.8, 1.25]) fitted by least squares on the pixels where
/// the face is blended in at 0.5 ≤ α < 1 against the background there, then applied to the
/// face wherever it is drawn: `out' = out + α·((g − 1)·face + o)`.
fn match_border(
    model: &FaceModel,
    alpha: &[f32],
    frames: &Frames,
    rendered: &mut [RgbImage],
    background: &[RgbImage],
    gain: bool,
) {
    for (t, (out, bg)) in rendered.iter_mut().zip(background).enumerate() {
        let (w, h) = out.dimensions();
        let points = model.landmarks(frames.params(t)).unwrap().points;
        let a = facespace::eval::seams::alpha_on_canvas(model, alpha, &points, w, h).unwrap();
        // The face's own colour where it is drawn: out = α·face + (1 − α)·bg, solved for face.
        let face: Vec<[f64; 3]> = (0..a.len())
            .map(|i| {
                let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
                let (o, b) = (out.get_pixel(x, y).0, bg.get_pixel(x, y).0);
                std::array::from_fn(|c| {
                    let alpha = f64::from(a[i]).max(1e-6);
                    (f64::from(o[c]) - (1.0 - alpha) * f64::from(b[c])) / alpha
                })
            })
            .collect();
        let band: Vec<usize> = (0..a.len())
            .filter(|&i| a[i] >= 0.5 && a[i] < 0.996)
            .collect();
        if band.len() < 20 {
            continue;
        }
        let mut fit = [(1.0f64, 0.0f64); 3];
        for (c, f) in fit.iter_mut().enumerate() {
            let n = band.len() as f64;
            let (mut sf, mut sb, mut sff, mut sfb) = (0.0, 0.0, 0.0, 0.0);
            for &i in &band {
                let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
                let (fv, bv) = (face[i][c], f64::from(bg.get_pixel(x, y).0[c]));
                sf += fv;
                sb += bv;
                sff += fv * fv;
                sfb += fv * bv;
            }
            let var = sff / n - (sf / n).powi(2);
            let g = if gain && var > 1.0 {
                ((sfb / n - sf / n * sb / n) / var).clamp(0.8, 1.25)
            } else {
                1.0
            };
            *f = (g, sb / n - g * sf / n);
        }
        for i in 0..a.len() {
            if a[i] <= 0.0 {
                continue;
            }
            let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
            let mut p = out.get_pixel(x, y).0;
            for (c, &(g, o)) in fit.iter().enumerate() {
                let v = f64::from(p[c]) + f64::from(a[i]) * ((g - 1.0) * face[i][c] + o);
                p[c] = v.round().clamp(0.0, 255.0) as u8;
            }
            out.put_pixel(x, y, image::Rgb(p));
        }
    }
}

/// A `demo --talker fgnet` output folder drawn again over `background`: its region model, its
/// smoothed frames, the rendered images, the background's own and the backdrop.
fn fgnet_demo(
    dir: &Path,
    background: &Path,
) -> (FaceModel, Frames, Vec<RgbImage>, Vec<RgbImage>, Backdrop) {
    let model = FaceModel::load(&dir.join("model")).unwrap();
    let tracker = FaceModel::load(&facespace::demo::default_model()).unwrap();
    let values: ndarray::ArrayD<f32> =
        facespace::npy::read(&dir.join("smoothed/trajectory.npy")).unwrap();
    let frames = Frames::from_rows(model.layout(), 24.0, values.iter().copied().collect()).unwrap();
    let backdrop = Backdrop::video(
        &tracker,
        background,
        PoseMode::Replay,
        frames.len(),
        &EncodeOptions::default(),
        facespace::no_progress,
    )
    .unwrap();
    let rendered = render(&model, &frames, &backdrop);
    let real = frames_of(background, rendered.len());
    (model, frames, rendered, real, backdrop)
}

fn mean(all: &[Defects]) -> Defects {
    let n = all.len().max(1) as f64;
    let sum = |f: fn(&Defects) -> f64| all.iter().map(f).sum::<f64>() / n;
    Defects {
        border: sum(|d| d.border),
        border_real: sum(|d| d.border_real),
        shimmer: sum(|d| d.shimmer),
        shimmer_real: sum(|d| d.shimmer_real),
    }
}

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    match a.first().map(String::as_str) {
        Some("grid") => {
            let model = FaceModel::load(&root.join("models/grid/model")).unwrap();
            let cb = Codebook::load(&root.join("models/grid/codebook")).unwrap();
            let test = corpus::load(
                Path::new(&a[1]),
                25.0,
                model.layout(),
                None,
                &PhoneMap::default(),
            )
            .unwrap();
            let n = a.get(2).map_or(test.len(), |s| s.parse().unwrap());
            let alpha = feather_alpha(&model, DEFAULT_FEATHER);
            let matching = std::env::var_os("MATCH").is_some();
            let mut all = Vec::new();
            let (mut offset, mut gained) = (Vec::new(), Vec::new());
            for s in test.iter().take(n) {
                let (drawn, rendered, real) = grid_sentence(&model, &cb, s);
                let d = measure(&model, &alpha, &drawn, &rendered, &real).unwrap();
                report(&s.name, &d);
                all.push(d);
                if matching {
                    for (gain, out) in [(false, &mut offset), (true, &mut gained)] {
                        let mut r = rendered.clone();
                        match_border(&model, &alpha, &drawn, &mut r, &real, gain);
                        out.push(measure(&model, &alpha, &drawn, &r, &real).unwrap());
                    }
                }
            }
            if matching {
                report("GRID s1, border offset matched", &mean(&offset));
                report("GRID s1, border gain and offset matched", &mean(&gained));
            }
            report(
                &format!("GRID s1 (recorded), mean of {}", all.len()),
                &mean(&all),
            );
        }
        Some("demo") => {
            let (model, frames, rendered, real, backdrop) =
                fgnet_demo(Path::new(&a[1]), Path::new(&a[2]));
            if std::env::var_os("MATCH").is_some() {
                let alpha = feather_alpha(&model, DEFAULT_FEATHER);
                for (gain, what) in [(false, "offset"), (true, "gain and offset")] {
                    let mut r = rendered.clone();
                    match_border(&model, &alpha, &frames, &mut r, &real, gain);
                    report(
                        &format!("FGNet demo, border {what} matched"),
                        &measure(&model, &alpha, &frames, &r, &real).unwrap(),
                    );
                }
            }
            if std::env::var_os("PARTS").is_some() {
                // Where the shimmer comes from: appearance held at its mean, or cut to its
                // first k components.
                let range = model.layout().appearance_range();
                for keep in [0usize, 1, 3, 10, range.len()] {
                    let mut f = frames.clone();
                    let n = f.len() as f32;
                    let means: Vec<f32> = range
                        .clone()
                        .map(|k| f.column(k).iter().sum::<f32>() / n)
                        .collect();
                    for mut row in f.values_mut().rows_mut() {
                        for (j, k) in range.clone().enumerate() {
                            if j >= keep {
                                row[k] = means[j];
                            }
                        }
                    }
                    let r = render(&model, &f, &backdrop);
                    let alpha = feather_alpha(&model, DEFAULT_FEATHER);
                    report(
                        &format!("appearance: first {keep} varying, rest at mean"),
                        &measure(&model, &alpha, &f, &r, &real).unwrap(),
                    );
                }
            }
            report(
                "FGNet demo (generated corpus, real background)",
                &measure(
                    &model,
                    &feather_alpha(&model, DEFAULT_FEATHER),
                    &frames,
                    &rendered,
                    &real,
                )
                .unwrap(),
            );
        }
        Some("picture") => {
            let model = FaceModel::load(&root.join("models/grid/model")).unwrap();
            let cb = Codebook::load(&root.join("models/grid/codebook")).unwrap();
            let layout = model.layout();
            let test =
                corpus::load(Path::new(&a[1]), 25.0, layout, None, &PhoneMap::default()).unwrap();
            let s = test.iter().find(|s| s.name == a[2]).expect("the sentence");
            let t: usize = a[3].parse().unwrap();
            let (drawn, rendered, real) = grid_sentence(&model, &cb, s);
            let p = model.landmarks(drawn.params(t)).unwrap().points;
            let (nose, jaw) = (p[30], p[4]);
            let grid = join(
                &[
                    join(&[real[t].clone(), rendered[t].clone()], true),
                    join(
                        &[
                            crop(&real[t], nose, 56, 3),
                            crop(&rendered[t], nose, 56, 3),
                            crop(&real[t], jaw, 56, 3),
                            crop(&rendered[t], jaw, 56, 3),
                        ],
                        true,
                    ),
                ],
                false,
            );
            // The FGNet demo's frame 18 (nose and cheeks, the region's border), drawn again.
            let (region, frames, fgnet, fgnet_real, _) =
                fgnet_demo(Path::new(&a[4]), &facespace::demo::default_background());
            let q = region.landmarks(frames.params(18)).unwrap().points;
            let centre = [(q[31][0] + q[35][0]) / 2.0, q[33][1] + 4.0];
            let fg = join(
                &[
                    crop(&fgnet_real[18], centre, 80, 3),
                    crop(&fgnet[18], centre, 80, 3),
                ],
                true,
            );
            join(&[grid, fg], false).save(&a[5]).unwrap();
        }
        _ => eprintln!("usage: full_size grid CORPUS [N] | demo DIR BACKGROUND | picture …"),
    }
}
