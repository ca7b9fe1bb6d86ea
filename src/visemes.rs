//! Mouth shapes for 2D rigs: the nine of Rhubarb Lip Sync (A–F basic, G, H, X extended; its
//! README, "Mouth shapes"), from phone timings and — with a talker — the mouth opening its
//! face makes, written in Rhubarb's TSV, JSON and Moho switch (`.dat`) layouts so that the
//! tools animators already load them into read ours.
//!
//! Times are whole centiseconds, as Rhubarb's: cues join where the shape does not change, the
//! first starts at 0 and the last ends at the recording's duration (truncated to 0.01 s).

use serde::Serialize;
use thiserror::Error;

use crate::phonemes::{Phone, Segment};

/// One of Rhubarb's mouth shapes, with its documented meaning.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub enum Shape {
    /// Closed mouth for P, B, M (slight pressure between the lips).
    A,
    /// Slightly open mouth, clenched teeth: most consonants (K, S, T…) and EE as in bee.
    B,
    /// Open mouth: EH as in men, AE as in bat; the in-between from A or B to D.
    C,
    /// Wide open mouth: AA as in father.
    D,
    /// Slightly rounded mouth: AO as in off, ER as in bird; the in-between from C or D to F.
    E,
    /// Puckered lips: UW as in you, OW as in show, W as in way.
    F,
    /// Upper teeth on the lower lip: F, V (extended).
    G,
    /// Tongue raised behind the upper teeth: long L (extended).
    H,
    /// Idle, lips closed and relaxed: pauses (extended).
    X,
}

impl Shape {
    /// Every shape, A to X.
    pub const ALL: [Shape; 9] = [
        Shape::A,
        Shape::B,
        Shape::C,
        Shape::D,
        Shape::E,
        Shape::F,
        Shape::G,
        Shape::H,
        Shape::X,
    ];

    /// The letter Rhubarb writes.
    pub fn letter(self) -> char {
        b"ABCDEFGHX"[self as usize] as char
    }

    /// The shape a letter names.
    pub fn from_letter(c: char) -> Option<Shape> {
        Shape::ALL
            .into_iter()
            .find(|s| s.letter() == c.to_ascii_uppercase())
    }

    /// The basic shape (A–F) that stands in for an extended one left out: G → B, H → C,
    /// X → A (Rhubarb's mapping).
    pub fn basic(self) -> Shape {
        match self {
            Shape::G => Shape::B,
            Shape::H => Shape::C,
            Shape::X => Shape::A,
            s => s,
        }
    }

    /// Its Preston Blair name (`--dat-preston-blair`, what OpenToonz reads).
    pub fn preston_blair(self) -> &'static str {
        ["MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"][self as usize]
    }

    /// The shape of a phone, by the documented meanings above; `None` for /hh/, which takes
    /// the shape of the sound it breathes into.
    pub fn of_phone(phone: Phone) -> Option<Shape> {
        Some(match phone.name() {
            "sil" => Shape::X,
            "p" | "b" | "m" => Shape::A,
            "f" | "v" => Shape::G,
            "l" => Shape::H,
            "uw" | "ow" | "w" => Shape::F,
            "ao" | "er" | "oy" | "uh" => Shape::E,
            "aa" | "ay" | "aw" => Shape::D,
            "eh" | "ae" | "ah" | "ey" => Shape::C,
            "hh" => return None,
            _ => Shape::B,
        })
    }

    /// A diphthong's two targets — the vowel it starts on and the one it glides to — as the
    /// shapes above: /ay/ D → B, /aw/ D → E, /ey/ C → B, /ow/ E → F, /oy/ E → B (Rhubarb's
    /// README draws "Hi" so, D then B). `None` for a monophthong or a consonant.
    pub fn of_diphthong(phone: Phone) -> Option<(Shape, Shape)> {
        Some(match phone.name() {
            "ay" => (Shape::D, Shape::B),
            "aw" => (Shape::D, Shape::E),
            "ey" => (Shape::C, Shape::B),
            "ow" => (Shape::E, Shape::F),
            "oy" => (Shape::E, Shape::B),
            _ => return None,
        })
    }

    /// The shapes a phone's time holds: a diphthong's onset for its first [`GLIDE_ONSET`] and
    /// its glide for the rest ([`Shape::of_diphthong`]), any other phone its one shape
    /// ([`Shape::of_phone`]); `None` for /hh/.
    fn targets(phone: Phone) -> Option<(Shape, Shape)> {
        Shape::of_diphthong(phone).or_else(|| Shape::of_phone(phone).map(|s| (s, s)))
    }
}

/// The share of a diphthong's time its first target holds before the glide (Rhubarb gives
/// the onset 0.6 of it too). A fixed phonetic prior, not tuned on GRID.
pub const GLIDE_ONSET: f64 = 0.6;

/// Which extended shapes (G, H, X) a rig has; the others fall back to their basic shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Extended {
    /// G is drawn.
    pub g: bool,
    /// H is drawn.
    pub h: bool,
    /// X is drawn.
    pub x: bool,
}

impl Default for Extended {
    /// All three (Rhubarb's default, `GHX`).
    fn default() -> Self {
        Extended {
            g: true,
            h: true,
            x: true,
        }
    }
}

impl Extended {
    /// From Rhubarb's `--extendedShapes` string (`GHX`, `GX`, `""`…).
    pub fn parse(s: &str) -> Result<Self, VisemeError> {
        let mut e = Extended {
            g: false,
            h: false,
            x: false,
        };
        for c in s.chars() {
            match c.to_ascii_uppercase() {
                'G' => e.g = true,
                'H' => e.h = true,
                'X' => e.x = true,
                _ => return Err(VisemeError::ExtendedShape(c)),
            }
        }
        Ok(e)
    }

    /// `shape` as this rig draws it.
    pub fn map(self, shape: Shape) -> Shape {
        let kept = match shape {
            Shape::G => self.g,
            Shape::H => self.h,
            Shape::X => self.x,
            _ => true,
        };
        if kept { shape } else { shape.basic() }
    }
}

/// A shape held from `start` to `end`, in centiseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Cue {
    /// Start, centiseconds.
    pub start: u32,
    /// End, centiseconds.
    pub end: u32,
    /// The shape.
    pub shape: Shape,
}

/// Errors of viseme tracks.
#[derive(Debug, Error)]
pub enum VisemeError {
    /// Not a shape letter of `--extended-shapes`.
    #[error("extended shapes: {0:?} is not G, H or X")]
    ExtendedShape(char),
    /// A duration that is not a finite, positive number of seconds.
    #[error("the recording lasts {0} s: a viseme track needs a positive, finite duration")]
    Duration(f64),
    /// Phone times that are not finite.
    #[error("phone {index} ({phone:?}) has a time that is not a finite number")]
    BadSegment {
        /// Its index.
        index: usize,
        /// The phone.
        phone: Phone,
    },
    /// A `.dat` frame rate outside Rhubarb's range.
    #[error("a Moho .dat frame rate must be between 24 and 100 fps, not {0}")]
    FrameRate(f64),
}

fn centiseconds(t: f64) -> u32 {
    (t.max(0.0) * 100.0).round() as u32
}

/// The cues of `segments` over a recording of `duration` seconds: each phone's shape
/// ([`Shape::of_phone`]; a diphthong's two, [`Shape::of_diphthong`]; /hh/ takes the next
/// phone's first), mapped for the rig, joined where equal, X (or A) where no phone is, the
/// last ending at the duration truncated to 0.01 s. A track to draw goes through [`hold`]
/// last (after [`open_by_face`], which chooses on the phones' own cues).
pub fn cues(
    segments: &[Segment],
    duration: f64,
    extended: Extended,
) -> Result<Vec<Cue>, VisemeError> {
    if !(duration.is_finite() && duration > 0.0) {
        return Err(VisemeError::Duration(duration));
    }
    if let Some((index, s)) = segments
        .iter()
        .enumerate()
        .find(|(_, s)| !(s.start.is_finite() && s.end.is_finite()))
    {
        return Err(VisemeError::BadSegment {
            index,
            phone: s.phone,
        });
    }
    let end = (duration * 100.0 + 1e-6).floor() as u32;
    let rest = extended.map(Shape::X);
    let mut out: Vec<Cue> = Vec::new();
    let mut at = 0;
    for (i, s) in segments.iter().enumerate() {
        // /hh/ breathes into the next sounding phone's shape.
        let (onset, glide) = Shape::targets(s.phone).unwrap_or_else(|| {
            let next = segments[i + 1..]
                .iter()
                .filter(|n| n.phone != Phone::SIL)
                .find_map(|n| Shape::targets(n.phone))
                .map_or(Shape::C, |t| t.0);
            (next, next)
        });
        let (a, b) = (centiseconds(s.start).min(end), centiseconds(s.end).min(end));
        let from = at.max(a);
        let turn = (f64::from(a) + GLIDE_ONSET * f64::from(b.saturating_sub(a))).round() as u32;
        join(&mut out, at, a, rest);
        join(&mut out, from, turn.max(from), extended.map(onset));
        join(&mut out, turn.max(from), b, extended.map(glide));
        at = at.max(b);
    }
    join(&mut out, at, end, rest);
    if out.is_empty() {
        out.push(Cue {
            start: 0,
            end: 0,
            shape: rest,
        });
    }
    Ok(out)
}

/// Least length of a sounding cue, centiseconds: longer than a frame at 24 fps (4.2 cs, the
/// lowest rate Rhubarb's Moho export takes), so that every shape is drawn in at least one frame
/// instead of flashing by between frames.
pub const LEAST_CUE: u32 = 5;

/// `cues` with no sounding cue shorter than [`LEAST_CUE`], shortest first: a closure (A) — the
/// shape a viewer misses most — or a sound with no sounding neighbour borrows the time from its
/// neighbours (a sounding one down to the least, a rest all of it), and a closure that still
/// falls short takes its shorter sounding neighbour whole; any other short shape gives its time
/// to its longer sounding neighbour. Equal neighbours are joined again.
pub fn hold(cues: &[Cue], extended: Extended) -> Vec<Cue> {
    let rest = extended.map(Shape::X);
    if cues.iter().all(|c| c.end <= c.start) {
        // A recording shorter than a centisecond: its one empty cue, as it is.
        return cues.to_vec();
    }
    let mut cues = rejoined(cues);
    let len = |c: &Cue| c.end - c.start;
    let short = |c: &Cue| c.shape != rest && len(c) < LEAST_CUE;
    // Each pass merges, lengthens or gives up on one cue (a borrow that leaves a sound short
    // empties a pause beside it, so that the next pass merges it).
    let mut given_up: Vec<(u32, u32)> = Vec::new();
    for _ in 0..=3 * cues.len() {
        let Some(k) = (0..cues.len())
            .filter(|&k| short(&cues[k]) && !given_up.contains(&(cues[k].start, cues[k].end)))
            .min_by_key(|&k| (len(&cues[k]), k))
        else {
            break;
        };
        let mut neighbours: Vec<usize> = [k.checked_sub(1), (k + 1 < cues.len()).then_some(k + 1)].into_iter().flatten().collect();
        // The longer sounding neighbour (the earlier of equals).
        let longer = neighbours
            .iter()
            .copied()
            .filter(|&j| cues[j].shape != rest)
            .max_by_key(|&j| (len(&cues[j]), j < k));
        if let Some(j) = longer.filter(|_| cues[k].shape != Shape::A) {
            if j < k {
                cues[j].end = cues[k].end;
            } else {
                cues[j].start = cues[k].start;
            }
            cues[k].end = cues[k].start;
        } else {
            // Borrow, the neighbour with the most to spare first.
            let spare = |c: &Cue| if c.shape == rest { len(c) } else { len(c).saturating_sub(LEAST_CUE) };
            neighbours.sort_by_key(|&j| std::cmp::Reverse((spare(&cues[j]), j < k)));
            let mut lent = 0;
            for &j in &neighbours {
                let take = (LEAST_CUE - len(&cues[k]).min(LEAST_CUE)).min(spare(&cues[j]));
                lent += take;
                if j < k {
                    cues[j].end -= take;
                    cues[k].start -= take;
                } else {
                    cues[j].start += take;
                    cues[k].end += take;
                }
            }
            if len(&cues[k]) < LEAST_CUE && (cues[k].shape == Shape::A || lent == 0) {
                // A closure still short takes its shorter sounding neighbour whole.
                let shorter = neighbours
                    .iter()
                    .copied()
                    .filter(|&j| cues[j].shape != rest)
                    .min_by_key(|&j| (len(&cues[j]), j > k));
                match shorter {
                    Some(j) if cues[k].shape == Shape::A => {
                        if j < k {
                            cues[k].start = cues[j].start;
                        } else {
                            cues[k].end = cues[j].end;
                        }
                        cues[j].end = cues[j].start;
                    }
                    _ => given_up.push((cues[k].start, cues[k].end)),
                }
            }
        }
        cues = rejoined(&cues);
    }
    cues
}

/// `cues` with the empty ones dropped and equal neighbours joined.
fn rejoined(cues: &[Cue]) -> Vec<Cue> {
    let mut out = Vec::with_capacity(cues.len());
    for c in cues {
        join(&mut out, c.start, c.end, c.shape);
    }
    out
}

/// Appends `shape` from `start` to `end` (centiseconds) to contiguous cues, extending the last
/// one when it has the same shape; an empty span adds nothing.
fn join(cues: &mut Vec<Cue>, start: u32, end: u32, shape: Shape) {
    if end <= start {
        return;
    }
    match cues.last_mut() {
        Some(last) if last.shape == shape => last.end = end,
        _ => cues.push(Cue { start, end, shape }),
    }
}

/// Re-chooses the degree of opening (B, C or D) of each cue from the mouth opening a talker's
/// face makes there: `opening(t_cs)` is the mean inner-mouth height over the cue, and
/// `levels` the talker's typical height for B, C and D (e.g. medians over its codebook's
/// /iy/, /eh/ and /aa/); each B/C/D cue takes the nearest level. Closures, rounding, teeth on
/// lip, tongue and rest are kept from the phones. Equal neighbours are joined again.
pub fn open_by_face(
    cues: &[Cue],
    levels: [f64; 3],
    mut opening: impl FnMut(u32, u32) -> Option<f64>,
) -> Vec<Cue> {
    let mut out: Vec<Cue> = Vec::with_capacity(cues.len());
    for c in cues {
        let mut shape = c.shape;
        if matches!(shape, Shape::B | Shape::C | Shape::D)
            && let Some(h) = opening(c.start, c.end).filter(|h| h.is_finite())
        {
            let nearest = (0..3)
                .min_by(|&a, &b| (levels[a] - h).abs().total_cmp(&(levels[b] - h).abs()))
                .unwrap_or(0);
            shape = [Shape::B, Shape::C, Shape::D][nearest];
        }
        join(&mut out, c.start, c.end, shape);
    }
    out
}

fn seconds(cs: u32) -> String {
    format!("{}.{:02}", cs / 100, cs % 100)
}

/// Rhubarb's TSV: `start<TAB>shape` per cue, then the end of the recording with the closed
/// mouth.
pub fn tsv(cues: &[Cue], extended: Extended) -> String {
    let mut s = String::new();
    for c in cues {
        s.push_str(&format!("{}\t{}\n", seconds(c.start), c.shape.letter()));
    }
    let end = cues.last().map_or(0, |c| c.end);
    s.push_str(&format!(
        "{}\t{}\n",
        seconds(end),
        extended.map(Shape::X).letter()
    ));
    s
}

/// Rhubarb's JSON: the sound file and duration, then every cue's start, end and shape, laid
/// out as its README shows.
pub fn json(cues: &[Cue], sound_file: &str) -> String {
    let end = cues.last().map_or(0, |c| c.end);
    let mut s = String::from("{\n  \"metadata\": {\n");
    s.push_str(&format!(
        "    \"soundFile\": {},\n",
        serde_json::to_string(sound_file).expect("a string serialises")
    ));
    s.push_str(&format!("    \"duration\": {}\n  }},\n", seconds(end)));
    s.push_str("  \"mouthCues\": [\n");
    for (i, c) in cues.iter().enumerate() {
        let comma = if i + 1 < cues.len() { "," } else { "" };
        s.push_str(&format!(
            "    {{ \"start\": {}, \"end\": {}, \"value\": \"{}\" }}{comma}\n",
            seconds(c.start),
            seconds(c.end),
            c.shape.letter()
        ));
    }
    s.push_str("  ]\n}\n");
    s
}

/// Rhubarb's Moho switch file: `MohoSwitch1`, then `frame shape` at each cue's first frame
/// (frames count from 1 at `fps`, 24–100; a cue starting in the same frame as the last one
/// written is left out), then the closed mouth at the frame of the end. `preston_blair` writes
/// the Preston Blair names.
pub fn dat(
    cues: &[Cue],
    fps: f64,
    preston_blair: bool,
    extended: Extended,
) -> Result<String, VisemeError> {
    if !(24.0..=100.0).contains(&fps) {
        return Err(VisemeError::FrameRate(fps));
    }
    let frame = |cs: u32| 1 + (fps * f64::from(cs) / 100.0 + 1e-9).floor() as u64;
    let name = |s: Shape| {
        if preston_blair {
            s.preston_blair().to_owned()
        } else {
            s.letter().to_string()
        }
    };
    let mut s = String::from("MohoSwitch1\n");
    let mut last = 0;
    for c in cues {
        let f = frame(c.start);
        if f == last {
            continue;
        }
        s.push_str(&format!("{f} {}\n", name(c.shape)));
        last = f;
    }
    let mut f = frame(cues.last().map_or(0, |c| c.end));
    if f == last {
        f += 1;
    }
    s.push_str(&format!("{f} {}\n", name(extended.map(Shape::X))));
    Ok(s)
}

/// The inner-mouth height of each frame's shape without its pose (iBUG 61–63 over 67–65, in
/// the shape model's units): the opening the face makes, whatever the head does.
pub fn openings(model: &crate::model::FaceModel, frames: &crate::facespace::Frames) -> Vec<f64> {
    frames.iter().map(|p| opening(model, p.shape)).collect()
}

/// The opening of one shape (`b_s`) without its pose; see [`openings`].
fn opening(model: &crate::model::FaceModel, shape: &[f32]) -> f64 {
    let points = model
        .shape
        .instance(&crate::shape::Similarity::IDENTITY, shape)
        .points;
    crate::eval::mouth::inner_mouth_height(&points)
}

/// A talker's typical opening ([`openings`]) for B, C and D: the median, over its codebook's
/// /iy/, /eh/ and /aa/ (each shape's defining vowel in Rhubarb's list), of the opening at each
/// such phone's middle frame. `None` without a 68-point face or without one of the vowels.
pub fn face_levels(
    model: &crate::model::FaceModel,
    codebook: &crate::codebook::Codebook,
) -> Option<[f64; 3]> {
    if model.shape.n_landmarks() != 68 {
        return None;
    }
    let mut levels = [0.0; 3];
    for (k, name) in ["iy", "eh", "aa"].iter().enumerate() {
        let phone = Phone::parse(name)?;
        let mut heights: Vec<f64> = Vec::new();
        for s in &codebook.sentences {
            for g in s.segments.iter().filter(|g| g.phone == phone) {
                let t = ((0.5 * (g.start + g.end)) * codebook.fps).round() as usize;
                if t < s.frames.len() {
                    heights.push(opening(model, s.frames.params(t).shape));
                }
            }
        }
        if heights.is_empty() {
            return None;
        }
        heights.sort_by(f64::total_cmp);
        levels[k] = heights[heights.len() / 2];
    }
    Some(levels)
}

/// The mean of `openings` (one per frame at `fps`) over the frames starting inside
/// `[start, end)` centiseconds; `None` when no frame does.
pub fn mean_opening(openings: &[f64], fps: f64, start: u32, end: u32) -> Option<f64> {
    let first = (f64::from(start) / 100.0 * fps).ceil() as usize;
    let last = ((f64::from(end) / 100.0 * fps).ceil() as usize).min(openings.len());
    (first < last).then(|| openings[first..last].iter().sum::<f64>() / (last - first) as f64)
}
