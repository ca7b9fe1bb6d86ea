//! Blend synthesis on a hand-built codebook: selection follows the formula for C and N.
use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::Sentence;
use facespace::facespace::{Frames, Layout};
use facespace::phonemes::{Phone, Segment};
use facespace::synth::blend::{self, Blend};
use facespace::synth::{SynthError, Synthesis, Synthesiser};

const LAYOUT: Layout = Layout {
    shape: 1,
    appearance: 1,
};

/// Blend synthesis at the test's frame rate.
fn blend(cb: &Codebook, t: &[Segment], b: Blend) -> Result<Synthesis, SynthError> {
    b.synthesise(cb, t, FPS)
}
const FPS: f64 = 25.0;

fn ph(s: &str) -> Phone {
    Phone::parse(s).unwrap()
}

/// Each phone has its own constant parameter value, so S separates all phones.
fn value(p: Phone) -> f64 {
    p.index() as f64 * 0.37 % 5.0
}

/// A sentence of 0.2 s phones whose frames hold each phone's value (plus `bump` in the
/// appearance dimension, to tell sentences apart).
fn sentence(name: &str, phones: &[&str], bump: f32) -> Sentence {
    wiggly(name, phones, bump, 0.0)
}

/// [`sentence`] whose shape value also swings by `wiggle` · sin(2π · time into the phone /
/// 0.2 s) in every phone: motion that differs between sentences.
fn wiggly(name: &str, phones: &[&str], bump: f32, wiggle: f64) -> Sentence {
    let segments: Vec<Segment> = phones
        .iter()
        .enumerate()
        .map(|(i, p)| Segment {
            start: 0.2 * i as f64,
            end: 0.2 * (i + 1) as f64,
            phone: ph(p),
        })
        .collect();
    let n = (0.2 * phones.len() as f64 * FPS).round() as usize;
    let frames = (0..n)
        .flat_map(|f| {
            let t = f as f64 / FPS;
            let s = segments
                .iter()
                .find(|s| t >= s.start && t < s.end)
                .unwrap_or(segments.last().unwrap());
            let swing = wiggle * (std::f64::consts::TAU * (t - s.start) / 0.2).sin();
            let v = value(s.phone) as f32;
            [1.0, 0.0, 0.0, 0.0, v + swing as f32, v + bump]
        })
        .collect();
    Sentence {
        name: name.into(),
        source: "hand".into(),
        frames: Frames::from_rows(LAYOUT, FPS, frames).unwrap(),
        segments,
    }
}

fn codebook() -> Codebook {
    let sentences = vec![
        sentence("A", &["sil", "aa", "m", "iy", "sil"], 0.0), // m in (aa, iy)
        sentence("B", &["sil", "aa", "m", "ow", "sil"], 0.1), // m in (aa, ow)
        sentence("C", &["sil", "uw", "m", "iy", "sil"], 0.2), // m in (uw, iy)
        sentence("D", &["f", "aa", "m", "iy", "s"], 0.3),     // m in (aa, iy), second left f
        sentence("E", &["sil", "f", "s", "uw", "ow"], 0.4),
    ];
    let options = SimilarityOptions {
        gamma: Some(1.0),
        variance_weights: false,
        context_weights: false,
        ..Default::default()
    };
    Codebook::build(
        sentences,
        FPS,
        LAYOUT,
        None,
        options,
        &mut facespace::no_progress,
    )
    .unwrap()
}

/// A codebook of `sentences` with [`codebook`]'s similarity options.
fn like_codebook(sentences: Vec<Sentence>) -> Codebook {
    Codebook::build(
        sentences,
        FPS,
        LAYOUT,
        None,
        codebook().options.clone(),
        &mut facespace::no_progress,
    )
    .unwrap()
}

/// A codebook holding nothing but silence.
fn common_silence(like: &Codebook) -> Codebook {
    Codebook::build(
        vec![sentence("S", &["sil", "sil"], 0.0)],
        FPS,
        LAYOUT,
        None,
        like.options.clone(),
        &mut facespace::no_progress,
    )
    .unwrap()
}

fn target(phones: &[&str], dur: f64) -> Vec<Segment> {
    phones
        .iter()
        .enumerate()
        .map(|(i, p)| Segment {
            start: dur * i as f64,
            end: dur * (i + 1) as f64,
            phone: ph(p),
        })
        .collect()
}

#[test]
fn selection_follows_the_context_score() {
    let cb = codebook();
    let t = target(&["sil", "aa", "m", "iy", "sil"], 0.2);
    let opts = Blend {
        context: 1,
        top_n: 4,
        ..Blend::default()
    };
    let chosen = blend::select(&cb, &t, 2, ph("m"), &opts);
    // Independent evaluation of s_j = S(l, l_j)/2 + S(r, r_j)/2 for the four occurrences.
    let s = |a: &str, b: &str| cb.similarity(ph(a), ph(b));
    let expected = [
        ("A", s("aa", "aa") / 2.0 + s("iy", "iy") / 2.0),
        ("B", s("aa", "aa") / 2.0 + s("iy", "ow") / 2.0),
        ("C", s("aa", "uw") / 2.0 + s("iy", "iy") / 2.0),
        ("D", 1.0),
    ];
    for (o, score) in &chosen {
        let name = &cb.sentences[o.sentence].name;
        let want = expected.iter().find(|(n, _)| n == name).unwrap().1;
        assert!((score - want).abs() < 1e-12, "{name}: {score} vs {want}");
    }
    assert!(
        chosen.windows(2).all(|w| w[0].1 >= w[1].1),
        "sorted best first"
    );
    // C = 1: A and D tie at 1.0 with equal durations; the context two phones out (sil … sil,
    // as in the target, for A; f … s for D) puts A first.
    let names: Vec<&str> = chosen
        .iter()
        .map(|(o, _)| cb.sentences[o.sentence].name.as_str())
        .collect();
    assert_eq!(&names[..2], ["A", "D"]);
    // C = 2: a target whose second contexts are f … s (as in D) prefers D, at weight 1/3.
    let t2 = target(&["f", "aa", "m", "iy", "s"], 0.2);
    let c2 = Blend {
        context: 2,
        top_n: 1,
        ..Blend::default()
    };
    assert_eq!(
        cb.sentences[blend::select(&cb, &t2, 2, ph("m"), &c2)[0].0.sentence].name,
        "D"
    );
    let c1 = Blend {
        context: 1,
        top_n: 1,
        ..Blend::default()
    };
    assert_eq!(
        cb.sentences[blend::select(&cb, &t2, 2, ph("m"), &c1)[0].0.sentence].name,
        "D",
        "C = 1 ties A and D; the tie goes to the deeper context (f … s), not to the name"
    );
}

/// Ties on the context score go to the nearer duration, then the deeper context — never to
/// the sentence's name: renaming the sentences (which reorders the corpus) changes nothing.
#[test]
fn ties_are_broken_by_duration_then_deeper_context_never_by_name() {
    let stretched = |name: &str, phones: &[&str], bump: f32, m_len: f64| {
        let mut s = sentence(name, phones, bump);
        // Lengthen the m (index 2) and shift what follows.
        let extra = m_len - 0.2;
        s.segments[2].end += extra;
        for seg in &mut s.segments[3..] {
            seg.start += extra;
            seg.end += extra;
        }
        let n = (s.segments.last().unwrap().end * FPS).round() as usize;
        let row: Vec<f32> = s.frames.values().row(0).to_vec();
        s.frames = Frames::from_rows(LAYOUT, FPS, row.repeat(n)).unwrap();
        s
    };
    let build = |names: [&str; 3], reverse: bool| {
        let mut sentences = vec![
            stretched(names[0], &["sil", "aa", "m", "iy", "sil"], 0.0, 0.4),
            stretched(names[1], &["sil", "aa", "m", "iy", "sil"], 0.1, 0.12),
            stretched(names[2], &["f", "aa", "m", "iy", "s"], 0.2, 0.12),
        ];
        if reverse {
            sentences.reverse();
        }
        like_codebook(sentences)
    };
    let one = Blend {
        context: 1,
        top_n: 1,
        ..Blend::default()
    };
    // A 0.12 s target m: the two short ones tie on C = 1 and on duration; the deeper context
    // (sil … sil) picks the second sentence. A 0.4 s m picks the long one.
    let short = vec![
        Segment { start: 0.0, end: 0.2, phone: ph("sil") },
        Segment { start: 0.2, end: 0.4, phone: ph("aa") },
        Segment { start: 0.4, end: 0.52, phone: ph("m") },
        Segment { start: 0.52, end: 0.72, phone: ph("iy") },
        Segment { start: 0.72, end: 0.92, phone: ph("sil") },
    ];
    let mut long = short.clone();
    long[2].end = 0.8;
    long[3] = Segment { start: 0.8, end: 1.0, phone: ph("iy") };
    long[4] = Segment { start: 1.0, end: 1.2, phone: ph("sil") };
    let cases = [["a", "b", "c"], ["z", "y", "x"], ["m", "a", "b"]];
    for (names, reverse) in cases.into_iter().flat_map(|n| [(n, false), (n, true)]) {
        let cb = build(names, reverse);
        let pick = |t: &[Segment]| {
            let o = blend::select(&cb, t, 2, ph("m"), &one)[0].0;
            cb.sentences[o.sentence].name.clone()
        };
        assert_eq!(pick(&short), names[1], "names {names:?}, reversed {reverse}");
        assert_eq!(pick(&long), names[0], "names {names:?}, reversed {reverse}");
    }
}

#[test]
fn top_n_and_weights() {
    let cb = codebook();
    let t = target(&["sil", "aa", "m", "iy", "sil"], 0.2);
    for n in 1..=4 {
        let s = blend(
            &cb,
            &t,
            Blend {
                context: 1,
                top_n: n,
                ..Blend::default()
            },
        )
        .unwrap();
        let m = &s.phones[2];
        assert_eq!(m.chosen.len(), n);
        let total: f64 = m.chosen.iter().map(|c| c.score).sum();
        for c in &m.chosen {
            assert!((c.weight - c.score / total).abs() < 1e-12);
        }
        assert!((m.chosen.iter().map(|c| c.weight).sum::<f64>() - 1.0).abs() < 1e-12);
    }
}

/// With N = 1 and the source's own timing, the output copies the source trajectory; with
/// twice the duration it is the source on a clock running at half speed.
#[test]
fn single_example_is_copied_and_time_warped() {
    let cb = codebook();
    let t = target(&["sil", "aa", "m", "iy", "sil"], 0.2);
    let s = blend(
        &cb,
        &t,
        Blend {
            context: 1,
            top_n: 1,
            ..Blend::default()
        },
    )
    .unwrap();
    let a = &cb.trajectories[0];
    // Frames inside /m/ (0.4–0.6 s) come from sentence A's /m/.
    for (k, &time) in s
        .frames
        .times()
        .iter()
        .enumerate()
        .filter(|(_, t)| **t >= 0.4 && **t < 0.6)
    {
        let want = a.eval(time);
        let got = s.frames.row(k);
        // The frames are stored in f32: equal to the f64 trajectory within its rounding.
        assert!(
            got.iter()
                .zip(&want)
                .all(|(g, w)| (f64::from(*g) - w).abs() < 1e-6 * w.abs().max(1.0)),
            "{got:?} vs {want:?}"
        );
    }
    let slow = target(&["sil", "aa", "m", "iy", "sil"], 0.4);
    let s = blend(
        &cb,
        &slow,
        Blend {
            context: 1,
            top_n: 1,
            ..Blend::default()
        },
    )
    .unwrap();
    for (k, &time) in s
        .frames
        .times()
        .iter()
        .enumerate()
        .filter(|(_, t)| **t >= 0.8 && **t < 1.2)
    {
        let want = a.eval(0.4 + (time - 0.8) / 2.0);
        assert!((f64::from(s.frames.row(k)[5]) - want[5]).abs() < 1e-6 * want[5].abs().max(1.0));
    }
    // 2 s at 25 fps: the 50 frames that start within the utterance.
    assert_eq!(s.frames.len(), 50);
}

#[test]
fn fallbacks_and_bad_input() {
    let cb = codebook();
    // /b/ is absent; /m/ shares its viseme class.
    let t = target(&["sil", "aa", "b", "iy", "sil"], 0.2);
    let s = blend(&cb, &t, Blend::default()).unwrap();
    assert_eq!(s.phones[2].used, ph("m"));
    assert!(
        s.warnings[0].contains("/b/ at 0.40 s is absent")
            && s.warnings[0].contains("its viseme class"),
        "{:?}",
        s.warnings
    );
    // /k/: no phone of its class in the codebook: the nearest class present by mouth shape
    // (phonemes::nearest_visemes) lends its most frequent phone.
    let t = target(&["sil", "k", "sil"], 0.2);
    let s = blend(&cb, &t, Blend::default()).unwrap();
    let lender = facespace::phonemes::nearest_visemes(ph("k").viseme())
        .into_iter()
        .find(|&c| c != 0 && cb.present().iter().any(|p| p.viseme() == c))
        .unwrap();
    assert_eq!(s.phones[1].used.viseme(), lender);
    assert!(
        s.warnings[0].contains("nearest viseme class"),
        "{:?}",
        s.warnings
    );
    // A codebook of silence alone can lend nothing.
    let silent = common_silence(&cb);
    assert_eq!(
        blend(&silent, &t, Blend::default()).unwrap_err(),
        SynthError::NoFallback { phone: ph("k") }
    );
    assert_eq!(
        blend(&cb, &[], Blend::default()).unwrap_err(),
        SynthError::Empty
    );
    let mut t = target(&["sil", "aa", "m", "sil"], 0.2);
    t[2].end = t[2].start; // zero length
    t[3].start = t[2].end;
    let s = blend(&cb, &t, Blend::default()).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("zero length")),
        "{:?}",
        s.warnings
    );
    let mut bad = target(&["sil", "aa"], 0.2);
    bad[1].end = f64::NAN;
    assert!(matches!(
        blend(&cb, &bad, Blend::default()),
        Err(SynthError::BadSegment { index: 1, .. })
    ));
    assert!(matches!(
        blend(
            &cb,
            &target(&["sil"], 0.2),
            Blend {
                top_n: 0,
                ..Default::default()
            }
        ),
        Err(SynthError::Option(_))
    ));
}

/// Three takes of /m/ between /aa/ and /iy/ whose motion disagrees, and a target of the same
/// phones.
fn three_takes_of_m() -> (Codebook, Vec<Segment>) {
    let sentences = vec![
        wiggly("A", &["sil", "aa", "m", "iy", "sil"], 0.0, 1.0),
        wiggly("B", &["sil", "aa", "m", "iy", "sil"], 0.1, -0.6),
        wiggly("C", &["sil", "aa", "m", "iy", "sil"], 0.2, 0.3),
    ];
    (like_codebook(sentences), target(&["sil", "aa", "m", "iy", "sil"], 0.2))
}

/// Variance-preserving blending scales each group's deviations from the utterance mean by one
/// gain, between 1 and √N, keeps the mean, and leaves a single example (N = 1) as it is.
#[test]
fn variance_preservation_scales_the_motion_by_one_gain() {
    let (cb, t) = three_takes_of_m();
    for n in [1, 3] {
        let run = |preserve_variance| {
            blend(
                &cb,
                &t,
                Blend {
                    context: 1,
                    top_n: n,
                    preserve_variance,
                    appearance_gain: 1.0,
                },
            )
            .unwrap()
            .frames
        };
        let (plain, kept) = (run(false), run(true));
        // The shape column moves and the examples disagree: its gain is above 1 for N = 3. The
        // appearance column only differs between sentences by a constant: nothing to restore.
        for column in [4, 5] {
            let (p, k) = (plain.column(column).to_vec(), kept.column(column).to_vec());
            let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
            let (mp, mk) = (mean(&p), mean(&k));
            assert!((mp - mk).abs() < 1e-5, "the mean moved: {mp} → {mk}");
            let spread = |v: &[f32], m: f64| {
                v.iter()
                    .map(|&x| (f64::from(x) - m).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            let gain = spread(&k, mk) / spread(&p, mp);
            if n == 1 || column == 5 {
                assert!(
                    (gain - 1.0).abs() < 1e-5,
                    "N = {n}, column {column}: gain {gain}"
                );
            } else {
                assert!(
                    gain > 1.0 + 1e-3 && gain <= 3f64.sqrt() + 1e-9,
                    "gain {gain}"
                );
            }
            for (a, b) in p.iter().zip(&k) {
                let want = mp + gain * (f64::from(*a) - mp);
                assert!((want - f64::from(*b)).abs() < 1e-4, "{b} is not {want}");
            }
        }
    }
}

/// The appearance gain scales the appearance's deviations from the utterance's mean by
/// exactly that factor, keeps its mean, and leaves the shape alone.
#[test]
fn appearance_gain_scales_only_the_appearance_about_its_mean() {
    let (cb, t) = three_takes_of_m();
    let run = |appearance_gain| {
        let options = Blend {
            context: 1,
            top_n: 1,
            preserve_variance: true,
            appearance_gain,
        };
        blend(&cb, &t, options).unwrap().frames
    };
    let (one, lively) = (run(1.0), run(1.5));
    assert_eq!(one.column(4).to_vec(), lively.column(4).to_vec(), "the shape changed");
    let (a, b) = (one.column(5).to_vec(), lively.column(5).to_vec());
    let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
    let m = mean(&a);
    assert!((m - mean(&b)).abs() < 1e-5, "the mean moved");
    let spread: f64 = a.iter().map(|&x| (f64::from(x) - m).abs()).sum();
    assert!(spread > 1e-3, "the appearance does not move: nothing to test");
    for (x, y) in a.iter().zip(&b) {
        let want = m + 1.5 * (f64::from(*x) - m);
        assert!((want - f64::from(*y)).abs() < 1e-4, "{y} is not {want}");
    }
}
