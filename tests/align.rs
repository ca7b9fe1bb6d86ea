//! Forced alignment (`align`) and audio input (`audio`): the front end against pocketsphinx's
//! own, three GRID clips (recorded speech) against their reference labels, the TextGrid, the
//! resampler against an analytic sine, a transcript-only corpus, and every bad input.

use crate::common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use facespace::align::{self, AlignError, Aligner, frontend};
use facespace::audio::{self, Audio, AudioError};
use facespace::phonemes::{self, Phone, PhoneMap};

const CLIPS: [&str; 3] = ["bbbf9a", "bbbs7a", "bbwtzp"];

fn grid() -> PathBuf {
    common::root().join("tests/data/grid")
}

fn aligner() -> &'static Aligner {
    static A: OnceLock<Aligner> = OnceLock::new();
    A.get_or_init(|| Aligner::load_default(&[]).unwrap())
}

fn transcript(id: &str) -> String {
    std::fs::read_to_string(grid().join(format!("{id}.txt"))).unwrap()
}

fn clip_audio(id: &str) -> Audio {
    audio::read(&grid().join(format!("{id}.mp4")), 16_000, 600.0).unwrap()
}

/// The front end's cepstral mean equals the one pocketsphinx 5.1.1 reports for the same audio
/// (tests/reference/mfcc_pocketsphinx.py), fresh and with the noise estimate warmed.
#[test]
fn mfcc_front_end_matches_pocketsphinx() {
    let reference: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(grid().join("mfcc_pocketsphinx.json")).unwrap(),
    )
    .unwrap();
    let fe = frontend::FrontEnd::new();
    for id in CLIPS {
        // The WAV path of `audio::read`, 16-bit PCM.
        let a = audio::read(&grid().join(format!("{id}.wav")), 16_000, 600.0).unwrap();
        let pcm: Vec<f32> = a.samples.iter().map(|x| (x * 32768.0).round()).collect();
        for (kind, mut cep) in [("fresh", fe.cepstra(&pcm)), ("warm", fe.cepstra_warm(&pcm))] {
            let mean = frontend::cmn(&mut cep).unwrap();
            let want: Vec<f64> = reference[id][kind]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            for (k, (&got, &want)) in mean.iter().zip(&want).enumerate() {
                let tol = 2e-3 + 1e-4 * want.abs();
                assert!(
                    (got as f64 - want).abs() < tol,
                    "{id} {kind} c{k}: {got} vs pocketsphinx {want}"
                );
            }
            // After CMN the kept frames average zero.
            let kept: Vec<_> = cep.iter().filter(|c| c[0] + mean[0] >= 0.0).collect();
            let c1: f64 = kept.iter().map(|c| c[1] as f64).sum::<f64>() / kept.len() as f64;
            assert!(c1.abs() < 1e-3);
        }
    }
}

/// Three GRID clips (recorded speech; MP4 audio through symphonia and the edit list) land on
/// pocketsphinx's phone boundaries (phones/) and the corpus's word boundaries (align/) within
/// the tolerances.
#[test]
fn grid_clips_align_within_tolerance_of_their_reference_labels() {
    let mut phone_d = Vec::new();
    let mut word_d = Vec::new();
    for id in CLIPS {
        let a = clip_audio(id);
        let result = aligner()
            .align(&a.samples, a.rate, &transcript(id))
            .unwrap();
        let reference =
            phonemes::read_htk(&grid().join(format!("{id}.lab")), &PhoneMap::default()).unwrap();
        let speech = |s: &[phonemes::Segment]| -> Vec<phonemes::Segment> {
            s.iter()
                .filter(|p| p.phone != Phone::SIL)
                .copied()
                .collect()
        };
        let (r, o) = (speech(&reference), speech(&result.segments()));
        assert_eq!(
            r.iter().map(|s| s.phone).collect::<Vec<_>>(),
            o.iter().map(|s| s.phone).collect::<Vec<_>>(),
            "{id}: phone sequence"
        );
        for (a, b) in r.iter().zip(&o) {
            phone_d.push((a.start - b.start).abs());
        }
        phone_d.push((r.last().unwrap().end - o.last().unwrap().end).abs());
        let words: Vec<(f64, f64)> = common::grid::read_align(&grid().join(format!("{id}.align")))
            .into_iter()
            .map(|(start, end, _)| (start, end))
            .collect();
        assert_eq!(result.words.len(), words.len());
        for (w, (s, e)) in result.words.iter().zip(&words) {
            word_d.push((w.start - s).abs());
            word_d.push((w.end - e).abs());
        }
        // The phones tile the recording.
        assert_eq!(result.phones[0].start, 0.0);
        for p in result.phones.windows(2) {
            assert!((p[0].end - p[1].start).abs() < 1e-9 && p[0].end > p[0].start);
        }
        assert!((result.phones.last().unwrap().end - result.frames as f64 * 0.01).abs() < 1e-9);
    }
    let share =
        |v: &[f64], s: f64| v.iter().filter(|&&d| d <= s + 1e-9).count() as f64 / v.len() as f64;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        v[v.len() / 2]
    };
    assert!(
        share(&phone_d, 0.020) >= 0.90,
        "phones within 20 ms: {}",
        share(&phone_d, 0.020)
    );
    assert!(median(&mut phone_d) <= 0.010);
    assert!(
        share(&word_d, 0.080) >= 0.92,
        "words within 80 ms: {}",
        share(&word_d, 0.080)
    );
    assert!(median(&mut word_d) <= 0.020);
}

/// The AAC priming samples and the padding are trimmed by the MP4's edit list: the sound
/// lasts what the edit list says (2.978 s), not the 3.04 s of decoded packets.
#[test]
fn mp4_audio_follows_its_edit_list() {
    let a = clip_audio("bbbf9a");
    assert_eq!(a.rate, 16_000);
    assert_eq!(a.samples.len(), 47_648);
}

#[test]
fn textgrid_has_word_and_phone_tiers_and_reads_back() {
    let a = clip_audio("bbbf9a");
    let result = aligner()
        .align(&a.samples, a.rate, &transcript("bbbf9a"))
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.TextGrid");
    result.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("name = \"words\"") && text.contains("name = \"phones\""));
    assert!(text.contains("text = \"blue\""));
    let phones = phonemes::read_textgrid(&path, Some("phones"), &PhoneMap::default()).unwrap();
    let segs = result.segments();
    let speech: Vec<_> = segs.iter().filter(|s| s.phone != Phone::SIL).collect();
    let read: Vec<_> = phones.iter().filter(|s| s.phone != Phone::SIL).collect();
    assert_eq!(speech.len(), read.len());
    for (a, b) in speech.iter().zip(&read) {
        assert_eq!(a.phone, b.phone);
        assert!((a.start - b.start).abs() < 1e-9);
    }
    let words = phonemes::read_textgrid(&path, Some("words"), &PhoneMap::default());
    // Words are not phones: the words tier is not a phone tier.
    assert!(words.is_err());
    // The .lab form is HTK phones.
    let lab = dir.path().join("out.lab");
    result.write(&lab).unwrap();
    assert_eq!(
        phonemes::read_htk(&lab, &PhoneMap::default()).unwrap(),
        segs
    );
}

/// A band-limited resampler: a 1 kHz sine at 44.1 kHz becomes the same sine sampled at 16 kHz.
#[test]
fn resampling_keeps_a_sine() {
    let f = 1000.0;
    let input = Audio {
        samples: (0..44_100)
            .map(|i| (2.0 * std::f64::consts::PI * f * i as f64 / 44_100.0).sin() as f32 * 0.5)
            .collect(),
        rate: 44_100,
    };
    let out = audio::resample(&input, 16_000);
    assert_eq!(out.rate, 16_000);
    assert_eq!(out.samples.len(), 16_000);
    for (k, &v) in out.samples.iter().enumerate().skip(200).take(15_600) {
        let want = (2.0 * std::f64::consts::PI * f * k as f64 / 16_000.0).sin() * 0.5;
        assert!((v as f64 - want).abs() < 5e-3, "sample {k}: {v} vs {want}");
    }
    // Above the new Nyquist frequency a tone is removed, not aliased.
    let high = Audio {
        samples: (0..44_100)
            .map(|i| (2.0 * std::f64::consts::PI * 12_000.0 * i as f64 / 44_100.0).sin() as f32)
            .collect(),
        rate: 44_100,
    };
    let out = audio::resample(&high, 16_000);
    let rms = (out.samples[200..15_800]
        .iter()
        .map(|v| (v * v) as f64)
        .sum::<f64>()
        / 15_600.0)
        .sqrt();
    assert!(rms < 0.02, "12 kHz tone leaks through at rms {rms}");
}

/// The resampler a chunk at a time (live sound, 48 and 24 kHz in, also up from 8 kHz) gives
/// the samples it gives the whole at once; a 1 kHz sine stays that sine between chunks.
#[test]
fn resampling_in_chunks_is_resampling_the_whole() {
    let mut rng = common::Rng::new(3);
    for from in [48_000u32, 24_000, 44_100, 8_000] {
        let sine: Vec<f32> = (0..from as usize)
            .map(|i| (std::f64::consts::TAU * 1000.0 * i as f64 / from as f64).sin() as f32 * 0.5)
            .collect();
        let whole = audio::resample(&Audio { samples: sine.clone(), rate: from }, 16_000).samples;
        let mut stream = audio::Resampler::new(from, 16_000);
        let (mut out, mut at) = (Vec::new(), 0);
        while at < sine.len() {
            let end = (at + 1 + (rng.uniform() * 2000.0) as usize).min(sine.len());
            out.extend(stream.push(&sine[at..end]));
            at = end;
        }
        out.extend(stream.finish());
        assert_eq!(out, whole, "{from} Hz");
        assert_eq!(out.len(), 16_000);
        for (k, &v) in out.iter().enumerate().skip(200).take(15_600) {
            let want = (std::f64::consts::TAU * 1000.0 * k as f64 / 16_000.0).sin() * 0.5;
            assert!((v as f64 - want).abs() < 5e-3, "{from} Hz, sample {k}: {v} vs {want}");
        }
    }
}

/// Stereo 8-bit 44.1 kHz WAV is mixed down and resampled, then aligned like the original.
#[test]
fn other_sample_formats_are_converted() {
    let a = clip_audio("bbbf9a");
    let up = audio::resample(&a, 44_100);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stereo8.wav");
    let mut data = Vec::new();
    for &s in &up.samples {
        let b = ((s * 127.0).round().clamp(-128.0, 127.0) as i32 + 128) as u8;
        data.extend_from_slice(&[b, b]);
    }
    std::fs::write(&path, wav_bytes(1, 2, 44_100, 8, &data)).unwrap();
    let back = audio::read(&path, 16_000, 600.0).unwrap();
    assert_eq!(back.rate, 16_000);
    assert!((back.samples.len() as i64 - a.samples.len() as i64).abs() <= 1);
    let result = aligner()
        .align(&back.samples, back.rate, &transcript("bbbf9a"))
        .unwrap();
    assert_eq!(result.words.len(), 6);
    let reference = aligner()
        .align(&a.samples, a.rate, &transcript("bbbf9a"))
        .unwrap();
    // 8-bit samples add noise at −48 dB: the words keep their places, but for the first
    // word's onset, an initial /b/ closure that silence borders (the reference's own weak spot).
    for (k, (x, y)) in result.words.iter().zip(&reference.words).enumerate() {
        let tol = if k == 0 { 0.15 } else { 0.031 };
        assert!(
            (x.start - y.start).abs() <= tol,
            "{} {} vs {}",
            x.word,
            x.start,
            y.start
        );
        assert!(
            (x.end - y.end).abs() <= 0.031,
            "{} {} vs {}",
            x.word,
            x.end,
            y.end
        );
    }
}

fn wav_bytes(format: u16, channels: u16, rate: u32, bits: u16, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"RIFF");
    out.extend_from_slice(&(36 + data.len() as u32).to_le_bytes());
    out.extend_from_slice(b"WAVEfmt ");
    out.extend_from_slice(&16u32.to_le_bytes());
    out.extend_from_slice(&format.to_le_bytes());
    out.extend_from_slice(&channels.to_le_bytes());
    out.extend_from_slice(&rate.to_le_bytes());
    let align = channels * bits / 8;
    out.extend_from_slice(&(rate * align as u32).to_le_bytes());
    out.extend_from_slice(&align.to_le_bytes());
    out.extend_from_slice(&bits.to_le_bytes());
    out.extend_from_slice(b"data");
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out
}

#[test]
fn words_missing_from_the_dictionary_are_all_named_and_a_dict_file_adds_them() {
    let a = clip_audio("bbbf9a");
    let err = aligner()
        .align(&a.samples, a.rate, "bin blurg by f nine zorp")
        .unwrap_err();
    match &err {
        AlignError::OutOfDictionary(w) => assert_eq!(w, &["blurg", "zorp"]),
        e => panic!("{e}"),
    }
    assert!(err.to_string().contains("--dict"));
    let dir = tempfile::tempdir().unwrap();
    let dict = dir.path().join("extra.dict");
    std::fs::write(&dict, "blurg B L UW\nzorp AH G EH N\n").unwrap();
    let with = Aligner::load_default(std::slice::from_ref(&dict)).unwrap();
    let r = with
        .align(&a.samples, a.rate, "bin blurg by f nine zorp")
        .unwrap();
    assert_eq!(r.words[1].word, "blurg");
    // A bad line is named with its file and line.
    std::fs::write(&dict, "ok OW K EY\nbad QQ X\n").unwrap();
    let e = Aligner::load_default(std::slice::from_ref(&dict))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("extra.dict:2") && e.contains("QQ"), "{e}");
}

#[test]
fn empty_silent_non_finite_and_overlong_inputs_are_refused() {
    let a = aligner();
    let text = transcript("bbbf9a");
    assert!(matches!(
        a.align(&[], 16_000, &text),
        Err(AlignError::EmptyAudio { samples: 0 })
    ));
    assert!(matches!(
        a.align(&vec![0.0; 48_000], 16_000, &text),
        Err(AlignError::Silent { .. })
    ));
    let mut nan = clip_audio("bbbf9a").samples;
    nan[1000] = f32::NAN;
    assert!(matches!(
        a.align(&nan, 16_000, &text),
        Err(AlignError::NotFinite { index: 1000 })
    ));
    assert!(matches!(
        a.align(&vec![0.1; 1000], 44_100, &text),
        Err(AlignError::SampleRate(44_100))
    ));
    assert!(matches!(
        a.align(&vec![0.1; 1000], 16_000, " ,. "),
        Err(AlignError::NoWords)
    ));
    // A transcript too long for the audio: 20 sentences in 3 s.
    let clip = clip_audio("bbbf9a");
    let long = vec![text.trim(); 20].join(" ");
    let e = a.align(&clip.samples, clip.rate, &long).unwrap_err();
    assert!(matches!(e, AlignError::TranscriptTooLong { .. }), "{e}");
    assert!(e.to_string().contains("too long for the audio"));
    // Past the length limit, refused before any work.
    let over = vec![0.1f32; (align::MAX_SECONDS * 16_000.0) as usize + 16];
    assert!(matches!(
        a.align(&over, 16_000, &text),
        Err(AlignError::TooLong { .. })
    ));
}

#[test]
fn bad_audio_files_get_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Not audio at all.
    let text = d.join("words.wav");
    std::fs::write(&text, "bin blue by f nine again\n").unwrap();
    let e = audio::read(&text, 16_000, 600.0).unwrap_err();
    assert!(
        matches!(
            e,
            AudioError::Unsupported { .. } | AudioError::Decode { .. } | AudioError::Ffmpeg { .. }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("words.wav"));
    // A WAV whose format tag is no PCM codec.
    let odd = d.join("odd.wav");
    std::fs::write(&odd, wav_bytes(0x2222, 1, 16_000, 16, &[0; 3200])).unwrap();
    let e = audio::read(&odd, 16_000, 600.0).unwrap_err();
    assert!(e.to_string().contains("odd.wav"), "{e}");
    // Missing, a folder, and an MP4 without sound (the committed video fixture).
    assert!(matches!(
        audio::read(&d.join("none.wav"), 16_000, 600.0),
        Err(AudioError::Io { .. })
    ));
    assert!(audio::read(d, 16_000, 600.0).is_err());
    let silent_video = common::root().join("models/demo/background.mp4");
    let e = audio::read(&silent_video, 16_000, 600.0).unwrap_err();
    assert!(matches!(e, AudioError::NoAudio { .. }), "{e}");
    assert!(e.to_string().contains("no audio track"));
    // An empty WAV reads as no samples, which alignment refuses.
    let empty = d.join("empty.wav");
    std::fs::write(&empty, wav_bytes(1, 1, 16_000, 16, &[])).unwrap();
    let a = audio::read(&empty, 16_000, 600.0).unwrap();
    assert!(matches!(
        aligner().align(&a.samples, a.rate, "bin"),
        Err(AlignError::EmptyAudio { .. })
    ));
}

/// A 10-hour WAV (a sparse file: its header declares 1.15 GB of samples) is refused from its
/// header, without decoding it, in bounded memory.
#[test]
fn a_ten_hour_file_is_refused_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ten-hours.wav");
    let n: u32 = 10 * 3600 * 16_000 * 2;
    let mut header = wav_bytes(1, 1, 16_000, 16, &[]);
    let len = header.len();
    header[4..8].copy_from_slice(&(36 + n).to_le_bytes());
    header[len - 4..].copy_from_slice(&n.to_le_bytes());
    std::fs::write(&path, &header).unwrap();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(len as u64 + n as u64)
        .unwrap();
    let before = peak_rss_kb();
    let started = std::time::Instant::now();
    let e = audio::read(&path, 16_000, align::MAX_SECONDS).unwrap_err();
    assert!(matches!(e, AudioError::TooLong { .. }), "{e}");
    assert!(e.to_string().contains("ten-hours.wav"));
    assert!(started.elapsed().as_secs() < 20);
    if let (Some(b), Some(a)) = (before, peak_rss_kb()) {
        assert!(
            a.saturating_sub(b) < 200_000,
            "peak RSS grew by {} kB",
            a - b
        );
    }
}

fn peak_rss_kb() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// `corpus from-videos` with a transcript and no labels: a frame folder of the demo talker,
/// its sound (2 s of a GRID recording) beside it as NAME.wav, and NAME.txt → NAME.lab aligned.
#[test]
fn corpus_from_videos_aligns_transcripts() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    let frames = input.join("take1");
    std::fs::create_dir_all(&frames).unwrap();
    let clip = common::root().join("tests/data/clip");
    let mut n = 0;
    for e in std::fs::read_dir(&clip).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "jpg") {
            std::fs::copy(&p, frames.join(p.file_name().unwrap())).unwrap();
            n += 1;
        }
    }
    assert_eq!(n, 50);
    // 2.0 s of speech: bbbf9a from 0.5 s (its words run 0.74 … 2.12 s).
    let a = clip_audio("bbbf9a");
    let cut = Audio {
        samples: a.samples[8_000..40_000].to_vec(),
        rate: 16_000,
    };
    audio::write_wav(&input.join("take1.wav"), &cut).unwrap();
    std::fs::write(input.join("take1.txt"), transcript("bbbf9a")).unwrap();
    let out = dir.path().join("corpus");
    let o = common::facespace(&[
        "corpus",
        "from-videos",
        input.to_str().unwrap(),
        "--init",
        clip.join("01000.pts").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    let lab = phonemes::read_htk(&out.join("take1.lab"), &PhoneMap::default()).unwrap();
    let whole = aligner()
        .align(&a.samples, a.rate, &transcript("bbbf9a"))
        .unwrap()
        .segments();
    let speech = |s: &[phonemes::Segment]| {
        s.iter()
            .filter(|p| p.phone != Phone::SIL)
            .copied()
            .collect::<Vec<_>>()
    };
    let (cut_phones, whole_phones) = (speech(&lab), speech(&whole));
    assert_eq!(cut_phones.len(), whole_phones.len());
    let close = cut_phones
        .iter()
        .zip(&whole_phones)
        .filter(|(c, w)| (c.start + 0.5 - w.start).abs() <= 0.021)
        .count();
    assert!(
        close as f64 >= 0.9 * cut_phones.len() as f64,
        "{close} of {}",
        cut_phones.len()
    );
    assert!(out.join("take1.npy").is_file());
    // Another sentence's words (three of six differ) are not aligned to it: the recording is
    // named with the words that were not said, and `--accept-mismatch` takes them.
    std::fs::write(input.join("take1.txt"), transcript("bbwtzp")).unwrap();
    let init = clip.join("01000.pts");
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "corpus",
            "from-videos",
            input.to_str().unwrap(),
            "--init",
            init.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        common::facespace(&args)
    };
    let o = run(&dir.path().join("wrong"), &[]);
    let said = common::text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("take1") && said.contains("do not seem to be what is said"), "{said}");
    assert!(said.contains("worst: ") && said.contains("--accept-mismatch"), "{said}");
    let o = run(&dir.path().join("accepted"), &["--accept-mismatch"]);
    assert!(o.status.success(), "{}", common::text(&o));
}

/// `facespace align` writes a TextGrid and names what it found.
#[test]
fn align_command_writes_a_textgrid() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bbbs7a.TextGrid");
    let o = common::facespace(&[
        "align",
        grid().join("bbbs7a.mp4").to_str().unwrap(),
        "--transcript",
        grid().join("bbbs7a.txt").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    assert!(common::text(&o).contains("seven"));
    assert!(std::fs::read_to_string(&out).unwrap().contains("\"seven\""));
    // An unknown word fails with the word named, exit 1, no output.
    let bad = dir.path().join("bad.lab");
    let o = common::facespace(&[
        "align",
        grid().join("bbbs7a.mp4").to_str().unwrap(),
        "--text",
        "bin qwxz by",
        "-o",
        bad.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(common::text(&o).contains("qwxz"));
    assert!(!bad.exists());
}

/// A damaged or truncated model file is named, never a panic.
#[test]
fn damaged_model_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let src = align::default_model_dir();
    for e in std::fs::read_dir(&src).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, dir.path().join(p.file_name().unwrap())).unwrap();
    }
    assert!(Aligner::load(dir.path(), &[]).is_ok());
    for (file, damage) in [
        ("means", "flip"),
        ("variances", "truncate"),
        ("mdef", "truncate"),
        ("sendump", "truncate"),
        ("transition_matrices", "flip"),
        ("feat.params", "other"),
    ] {
        let path = dir.path().join(file);
        let good = std::fs::read(&path).unwrap();
        let mut bad = good.clone();
        match damage {
            "flip" => {
                let n = bad.len();
                bad[n - 100] ^= 0x40;
            }
            "truncate" => bad.truncate(bad.len() * 2 / 3),
            _ => bad = b"-feat 1s_c_d\n-model ptm\n".to_vec(),
        }
        std::fs::write(&path, &bad).unwrap();
        let e = Aligner::load(dir.path(), &[]).err().unwrap().to_string();
        assert!(e.contains(file), "{file}: {e}");
        std::fs::write(&path, &good).unwrap();
    }
    std::fs::remove_file(dir.path().join("sendump")).unwrap();
    let e = Aligner::load(dir.path(), &[]).err().unwrap().to_string();
    assert!(e.contains("sendump"), "{e}");
}

/// Edit distance of `phones` from the committed clip `id`'s reference labels, silences left
/// out, and the reference's length.
fn phone_errors(id: &str, phones: &[align::TimedPhone]) -> (usize, usize) {
    let speech = |s: &[phonemes::Segment]| -> Vec<Phone> {
        s.iter().map(|s| s.phone).filter(|&p| p != Phone::SIL).collect()
    };
    let reference = phonemes::read_htk(&grid().join(format!("{id}.lab")), &PhoneMap::default()).unwrap();
    let reference = speech(&reference);
    (facespace::eval::edit_distance(&speech(&align::segments(phones)), &reference), reference.len())
}

/// Phones without words (issue 34): on the three committed clips (recorded) the recognised
/// phones tile the recording and come nearer their reference labels than chance — the phone
/// error rate stays under 85 % (63.9 % over GRID's test split, BENCHMARKS); and the bad
/// inputs of `align` are refused the same way: silence, nothing, NaN, too long.
#[test]
fn phones_are_recognised_without_words() {
    let a = aligner();
    let lm = a.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
    let (mut errors, mut total) = (0, 0);
    for id in CLIPS {
        let audio = clip_audio(id);
        let phones = a.recognise(&audio.samples, audio.rate, &lm).unwrap();
        assert_eq!(phones[0].start, 0.0);
        assert!(phones.windows(2).all(|w| w[0].end == w[1].start && w[0].end > w[0].start));
        assert!((phones.last().unwrap().end - audio.seconds()).abs() < 0.03, "{id}");
        let (e, n) = phone_errors(id, &phones);
        errors += e;
        total += n;
    }
    let per = errors as f64 / total as f64;
    assert!(per < 0.85, "PER {per}");
    let rate = frontend::SAMPLE_RATE;
    assert!(matches!(a.recognise(&vec![0.0; 48_000], rate, &lm), Err(AlignError::Silent { .. })));
    assert!(matches!(a.recognise(&[], rate, &lm), Err(AlignError::EmptyAudio { .. })));
    let mut nan = vec![0.1; 16_000];
    nan[7] = f32::NAN;
    assert!(matches!(a.recognise(&nan, rate, &lm), Err(AlignError::NotFinite { index: 7 })));
    let long = vec![0.0; (align::MAX_SECONDS as usize + 1) * rate as usize];
    assert!(matches!(a.recognise(&long, rate, &lm), Err(AlignError::TooLong { .. })));
    assert!(matches!(a.recognise(&nan, 8_000, &lm), Err(AlignError::SampleRate(8_000))));
    // Noise, tones and music are not speech: each is refused with what was heard; speech
    // under noise is still speech.
    for (name, sound) in not_speech() {
        match a.recognise(&sound, rate, &lm) {
            Err(e @ AlignError::NoSpeech { .. }) => assert!(e.to_string().contains("no speech"), "{name}: {e}"),
            other => panic!("{name}: {other:?}"),
        }
    }
    let mut rng = common::Rng::new(6);
    for id in CLIPS {
        let noisy: Vec<f32> = clip_audio(id).samples.iter().map(|&x| x + 0.02 * rng.normal() as f32).collect();
        assert!(a.recognise(&noisy, rate, &lm).is_ok(), "{id} with noise");
    }
}

/// The hybrid search (issue 34): phones heard by another ear follow its scores — a made-up
/// ear that hears /aa/ in the first half of a clip and /m/ in the second, every other phone
/// far below, gives exactly those two phones, split at the half; and the sound is still
/// refused first when it is not speech, whatever the ear says. The acoustic model scores
/// every other frame for it (`-ds 2`): the evidence of even frames is the model's own, each
/// odd frame's from state scores midway between its neighbours'.
#[test]
fn another_ears_scores_drive_the_phone_loop() {
    let a = aligner();
    let audio = clip_audio("bbbf9a");
    let lm = a.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
    let flat = a.phone_loop(0.0, 0.0);
    let (aa, m) = (a.model.ci("AA").unwrap(), a.model.ci("M").unwrap());
    let phones = a.model.ci_names.len();
    let mut frames = 0;
    let ear = |heard: &align::Evidence| {
        frames = heard.scores.len();
        (0..frames)
            .map(|t| {
                let heard = if t < frames / 2 { aa } else { m };
                (0..phones).map(|c| if c == heard { 0.0 } else { -50.0 }).collect()
            })
            .collect()
    };
    let (got, heard) = a.recognise_by(&audio.samples, audio.rate, &lm, ear, &flat).unwrap();
    // The evidence given back is what the ear was given: the sound's acoustic evidence at
    // even frames, and between them at odd ones.
    let evidence = a.acoustic_evidence(&audio.samples, audio.rate).unwrap();
    assert_eq!(heard.scores.len(), frames);
    assert_eq!(evidence.scores.len(), frames);
    assert!(heard.cepstra == evidence.cepstra);
    let mut odd_differ = 0;
    for t in 0..frames {
        if t % 2 == 0 {
            assert_eq!(heard.scores[t], evidence.scores[t], "frame {t}");
        } else {
            let best = heard.scores[t].iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            assert!(best == 0.0 && heard.scores[t].iter().all(|v| v.is_finite()), "frame {t}");
            odd_differ += usize::from(heard.scores[t] != evidence.scores[t]);
        }
    }
    assert!(odd_differ > frames / 4, "odd frames heard: {odd_differ} of {frames} differ");
    let names: Vec<&str> = got.iter().map(|p| p.phone.as_str()).collect();
    assert_eq!(names, ["AA", "M"], "{got:?}");
    assert!((got[0].end - (frames / 2) as f64 * 0.01).abs() < 0.011, "{got:?}");
    assert!((got[1].end - frames as f64 * 0.01).abs() < 1e-9, "{got:?}");
    for (name, sound) in not_speech() {
        let e = a.recognise_by(&sound, frontend::SAMPLE_RATE, &lm, |_| unreachable!(), &flat);
        assert!(matches!(e, Err(AlignError::NoSpeech { .. })), "{name}: {e:?}");
    }
}

/// Frame downsampling's spreading: even frames kept, each odd one midway between its
/// neighbours, a last odd frame its previous; nothing for nothing.
#[test]
fn every_other_frame_spreads_over_all() {
    let mid = |a: &f32, b: &f32| 0.5 * (a + b);
    assert_eq!(align::every_other(vec![1.0, 3.0, 7.0], 5, mid), [1.0, 2.0, 3.0, 5.0, 7.0]);
    assert_eq!(align::every_other(vec![1.0, 3.0, 7.0], 6, mid), [1.0, 2.0, 3.0, 5.0, 7.0, 7.0]);
    assert_eq!(align::every_other(vec![4.0], 1, mid), [4.0]);
    assert_eq!(align::every_other(vec![4.0], 2, mid), [4.0, 4.0]);
    assert!(align::every_other(Vec::<f32>::new(), 0, mid).is_empty());
}

/// Three seconds each (16 kHz) of sounds that are not speech: white and brown noise, a pure
/// tone, plucked notes with their harmonics, sustained organ chords, and drums over a bass.
pub fn not_speech() -> Vec<(&'static str, Vec<f32>)> {
    let n = 48_000;
    let mut rng = common::Rng::new(5);
    let time = |i: usize| i as f32 / 16_000.0;
    let tone = |f: f32, t: f32| (std::f32::consts::TAU * f * t).sin();
    let harmonics = |f: f32, t: f32, k: usize| (1..=k).map(|h| tone(f * h as f32, t) / h as f32).sum::<f32>();
    let white: Vec<f32> = (0..n).map(|_| 0.1 * rng.normal() as f32).collect();
    let mut y = 0.0f32;
    let brown: Vec<f32> = (0..n)
        .map(|_| {
            y = 0.98 * y + 0.05 * rng.normal() as f32;
            y
        })
        .collect();
    let notes = [220.0, 277.2, 329.6, 440.0, 392.0, 349.2, 261.6, 293.7];
    let plucked: Vec<f32> = (0..n)
        .map(|i| {
            let t = time(i);
            let f = notes[(t / 0.25) as usize % notes.len()];
            0.2 * harmonics(f, t, 5) * (-(t % 0.25) * 6.0).exp()
        })
        .collect();
    let chords = [[220.0f32, 277.2, 329.6], [196.0, 246.9, 293.7], [174.6, 220.0, 261.6]];
    let organ: Vec<f32> = (0..n)
        .map(|i| {
            let t = time(i);
            0.1 * chords[t as usize % 3].iter().map(|&f| harmonics(f, t, 3)).sum::<f32>()
        })
        .collect();
    let drums: Vec<f32> = (0..n)
        .map(|i| {
            let t = time(i);
            let beat = t % 0.5;
            let kick = tone(60.0, beat) * (-beat * 20.0).exp();
            let hat = if t % 0.25 < 0.03 { 0.3 * rng.normal() as f32 } else { 0.0 };
            0.5 * kick + hat + 0.2 * tone([55.0, 73.4, 82.4, 65.4][(t / 0.5) as usize % 4], t)
        })
        .collect();
    let pure: Vec<f32> = (0..n).map(|i| 0.3 * tone(440.0, time(i))).collect();
    vec![
        ("white noise", white),
        ("brown noise", brown),
        ("a 440 Hz tone", pure),
        ("plucked notes", plucked),
        ("organ chords", organ),
        ("drums and bass", drums),
    ]
}

/// The live front end (issue 34) gives the same features however the sound is cut into
/// chunks, and the same as the batch front end's cepstra put through a running mean (prior
/// 40, 3, −1 worth 100 frames, frames with c0 ≥ 0 counted) and the `1s_c_d_dd` deltas.
#[test]
fn live_front_end_matches_the_batch_one_chunk_by_chunk() {
    let audio = clip_audio(CLIPS[0]);
    let pcm: Vec<f32> = audio.samples.iter().map(|&x| f32::from(audio::to_pcm16(x))).collect();
    let fe = frontend::FrontEnd::new();
    let mut whole = frontend::Stream::new(&fe);
    let mut at_once = whole.push(&pcm);
    at_once.extend(whole.finish());
    let mut rng = common::Rng::new(11);
    let mut chunked = frontend::Stream::new(&fe);
    let (mut feats, mut at) = (Vec::new(), 0);
    while at < pcm.len() {
        let n = 1 + (rng.uniform() * 900.0) as usize;
        let end = (at + n).min(pcm.len());
        feats.extend(chunked.push(&pcm[at..end]));
        at = end;
    }
    feats.extend(chunked.finish());
    assert_eq!(feats, at_once);
    let mut cepstra = fe.cepstra(&pcm);
    assert_eq!(cepstra.len(), feats.len());
    let (mut sum, mut n) = ([0f64; frontend::N_CEP], 100.0);
    sum[0] = 4000.0;
    sum[1] = 300.0;
    sum[2] = -100.0;
    for c in cepstra.iter_mut() {
        if c[0] >= 0.0 {
            sum.iter_mut().zip(c.iter()).for_each(|(s, &v)| *s += v as f64);
            n += 1.0;
        }
        c.iter_mut().zip(&sum).for_each(|(v, s)| *v -= (s / n) as f32);
    }
    let reference = frontend::features(&cepstra);
    for (t, (a, b)) in feats.iter().zip(&reference).enumerate() {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-3, "frame {t}: {x} vs {y}");
        }
    }
}

/// Live phone recognition (issue 34): in 20 ms chunks the phones tile the recording, every
/// frame is given out within the bound its lag and least piece set (plus the look-ahead,
/// the window and the chunk), and they are as near the reference as the batch recogniser's
/// (PER under 85 %); bad input is refused as in batch.
#[test]
fn live_phones_arrive_within_their_lag() {
    let a = aligner();
    let lm = a.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
    let bound = (align::STREAM_LAG_FRAMES + align::STREAM_LEAST_PIECE + 4) as f64 * 0.01
        + frontend::FRAME_SIZE as f64 / 16_000.0
        + 0.02;
    let (mut errors, mut total) = (0, 0);
    for id in CLIPS {
        let audio = clip_audio(id);
        let mut live = a.recogniser(audio.rate, &lm).unwrap();
        let mut phones = Vec::new();
        for chunk in audio.samples.chunks(320) {
            for p in live.push(chunk).unwrap() {
                assert!(live.seconds() - p.start <= bound, "{id}: {p:?} out at {}", live.seconds());
                phones.push(p);
            }
        }
        phones.extend(live.finish().unwrap());
        assert_eq!(phones[0].start, 0.0);
        assert!(phones.windows(2).all(|w| w[0].end == w[1].start && w[0].end > w[0].start));
        assert!((phones.last().unwrap().end - audio.seconds()).abs() < 0.03, "{id}");
        let merged = align::merge_pieces(phones.clone());
        assert!(merged.len() <= phones.len());
        assert!(merged.windows(2).all(|w| w[0].phone != w[1].phone), "{id}");
        let (e, n) = phone_errors(id, &merged);
        errors += e;
        total += n;
    }
    let per = errors as f64 / total as f64;
    assert!(per < 0.85, "PER {per}");
    let rate = frontend::SAMPLE_RATE;
    assert!(matches!(a.recogniser(8_000, &lm), Err(AlignError::SampleRate(8_000))));
    let mut live = a.recogniser(rate, &lm).unwrap();
    live.push(&[0.1; 500]).unwrap();
    let mut nan = vec![0.1; 100];
    nan[3] = f32::INFINITY;
    assert!(matches!(live.push(&nan), Err(AlignError::NotFinite { index: 503 })));
    let live = a.recogniser(rate, &lm).unwrap();
    assert!(matches!(live.finish(), Err(AlignError::EmptyAudio { samples: 0 })));
    // A stream longer than the records kept between compactions (75 s: 2¹⁸ records are
    // about 65 s of a 40-phone loop) still tiles, and its last clip's phones are the first's.
    let audio = clip_audio(CLIPS[1]);
    let mut live = a.recogniser(rate, &lm).unwrap();
    let mut phones = Vec::new();
    for _ in 0..25 {
        for chunk in audio.samples.chunks(16_000) {
            phones.extend(live.push(chunk).unwrap());
        }
    }
    phones.extend(live.finish().unwrap());
    assert!(phones.windows(2).all(|w| w[0].end == w[1].start && w[0].end > w[0].start));
    assert!((phones.last().unwrap().end - 25.0 * audio.seconds()).abs() < 0.03);
    let during = |from: f64, to: f64| -> Vec<String> {
        let mut v: Vec<String> = align::merge_pieces(phones.clone())
            .into_iter()
            .filter(|p| p.start >= from + 0.5 && p.end <= to - 0.5 && p.phone != "SIL")
            .map(|p| p.phone)
            .collect();
        v.dedup();
        v
    };
    let d = audio.seconds();
    let (second, last) = (during(d, 2.0 * d), during(24.0 * d, 25.0 * d));
    assert!(facespace::eval::edit_distance(&second, &last) * 4 <= second.len(), "{second:?} vs {last:?}");
    // Silence streams as silence: no error (a live microphone is quiet between turns).
    let mut live = a.recogniser(rate, &lm).unwrap();
    live.push(&vec![0.0; 16_000]).unwrap();
    assert!(!live.finish().unwrap().is_empty());
}

/// A letter as the talker says it: GRID s1 (Scottish) says Z "zed", which the American
/// dictionary lacks. On lrwz5a ("lay red with z five again", test split, committed as
/// `lrwz5a.wav`) the aligner given the model folder's `variants.dict` chooses Z EH D, the word
/// where the corpus's own alignment puts it, and the true transcript fits; the same model
/// folder without that file squeezes "z" into the "d" of "zed" and refuses its true words.
#[test]
fn a_letter_said_as_the_talker_says_it_fits() {
    let audio = audio::read(&grid().join("lrwz5a.wav"), 16_000, 600.0).unwrap();
    let text = transcript("lrwz5a");
    let check = |a: &Aligner| {
        let lm = a.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
        a.align_checked(&audio.samples, audio.rate, &text, &lm).unwrap()
    };
    let (alignment, fit) = check(aligner());
    assert!(fit.matches(), "{fit:?}");
    let z = alignment.words.iter().position(|w| w.word == "z").unwrap();
    let phones: Vec<&str> = alignment.phones.iter().filter(|p| p.word == Some(z)).map(|p| p.phone.as_str()).collect();
    assert_eq!(phones, ["Z", "EH", "D"]);
    // The corpus's own word alignment (`align/lrwz5a.align` in GRID s1's folder, not committed
    // here; 25 000 units a second): z 1.31–1.72 s.
    let word = &alignment.words[z];
    assert!((word.start - 1.31).abs() < 0.05 && (word.end - 1.72).abs() < 0.05, "{word:?}");

    let american = tempfile::tempdir().unwrap();
    for entry in std::fs::read_dir(align::default_model_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.file_name().unwrap() != align::VARIANTS {
            std::fs::copy(&path, american.path().join(path.file_name().unwrap())).unwrap();
        }
    }
    let (_, fit) = check(&Aligner::load(american.path(), &[]).unwrap());
    assert!(!fit.matches(), "without the variant: {fit:?}");
}

/// Do the words match the speech? (issue 34) On the three committed clips (recorded, none
/// used to set the thresholds) each true transcript fits and each other clip's transcript
/// does not, its worst words among those it does not share; `align` warns about the latter.
#[test]
fn transcripts_of_other_sentences_do_not_fit() {
    let a = aligner();
    let lm = a.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
    for id in CLIPS {
        let audio = clip_audio(id);
        let (_, fit) = a.align_checked(&audio.samples, audio.rate, &transcript(id), &lm).unwrap();
        assert!(fit.matches(), "{id}: {fit:?}");
        for other in CLIPS.iter().filter(|o| **o != id) {
            let text = transcript(other);
            let (alignment, fit) = a.align_checked(&audio.samples, audio.rate, &text, &lm).unwrap();
            assert!(!fit.matches(), "{id} with {other}'s words: {fit:?}");
            let said = align::dict::words(&transcript(id));
            let worst = &alignment.words[fit.worst(1)[0]].word;
            assert!(!said.contains(worst), "{id} with {other}'s words: worst {worst}");
        }
    }
    let o = common::facespace(&[
        "align",
        grid().join("bbbf9a.wav").to_str().unwrap(),
        "--transcript",
        grid().join("bbwtzp.txt").to_str().unwrap(),
        "-o",
        tempfile::tempdir().unwrap().path().join("x.lab").to_str().unwrap(),
    ]);
    assert!(o.status.success());
    assert!(common::text(&o).contains("may not be what was said"), "{}", common::text(&o));
}
