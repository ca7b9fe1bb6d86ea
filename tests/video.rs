//! Frame sources and sinks: MP4 (H.264) read and written without a system ffmpeg, Y4M, frame
//! folders; audio carried through; bad input.
use crate::common;

use std::path::{Path, PathBuf};

use facespace::video::{self, Sink, Source, VideoError};
use image::{Rgb, RgbImage};

fn sample() -> PathBuf {
    common::root().join("tests/data/video/high_bframes_aac.mp4")
}

/// A moving, textured test pattern.
fn pattern(i: u32, w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        let (fx, fy) = (x as f32 + 2.0 * i as f32, y as f32);
        Rgb([
            (128.0 + 100.0 * (fx / 9.0).sin()) as u8,
            (128.0 + 100.0 * (fy / 7.0).cos()) as u8,
            ((x + y + 3 * i) % 256) as u8,
        ])
    })
}

fn psnr(a: &RgbImage, b: &RgbImage) -> f64 {
    let mask = vec![true; (a.width() * a.height()) as usize];
    facespace::eval::psnr_masked(a, b, &mask)
}

fn write(path: &Path, frames: &[RgbImage], fps: f64, audio: Option<&Path>) -> usize {
    let mut sink = Sink::create(path, frames[0].width(), frames[0].height(), fps, audio).unwrap();
    for f in frames {
        sink.write(f).unwrap();
    }
    sink.finish().unwrap()
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn reads_high_profile_with_b_frames_like_ffmpeg() {
    let mut source = Source::open(&sample()).unwrap();
    let info = source.info();
    assert_eq!((info.width, info.height, info.frames), (360, 288, Some(24)));
    assert!((info.fps - 24.0).abs() < 1e-6, "{}", info.fps);
    let frames: Vec<RgbImage> = source.by_ref().map(|f| f.unwrap()).collect();
    assert_eq!(frames.len(), 24);
    // Presentation order and pixels agree with ffmpeg's decode (colour conversion and chroma
    // upsampling differ slightly).
    let reference = image::open(common::root().join("tests/data/video/frame10_ffmpeg.png"))
        .unwrap()
        .to_rgb8();
    let scores: Vec<f64> = frames.iter().map(|f| psnr(f, &reference)).collect();
    let best = (0..24)
        .max_by(|&a, &b| scores[a].total_cmp(&scores[b]))
        .unwrap();
    assert_eq!(best, 10, "{scores:?}");
    assert!(scores[10] > 35.0, "{}", scores[10]);
}

#[test]
fn mp4_round_trip_keeps_count_rate_and_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.mp4");
    let frames: Vec<RgbImage> = (0..30).map(|i| pattern(i, 96, 64)).collect();
    assert_eq!(write(&path, &frames, 24.0, None), 30);
    let back: Vec<RgbImage> = Source::open(&path).unwrap().map(|f| f.unwrap()).collect();
    assert_eq!(back.len(), 30);
    assert!((Source::open(&path).unwrap().info().fps - 24.0).abs() < 1e-6);
    for (a, b) in back.iter().zip(&frames) {
        let p = psnr(a, b);
        assert!(p > 33.0, "PSNR {p}");
    }
    assert_eq!(leftovers(dir.path()), ["out.mp4"]);
    // A standard decoder agrees, where one is installed.
    if let Some(ffprobe) = facespace::programs::system_ffmpeg().map(|f| f.with_file_name("ffprobe"))
        && ffprobe.is_file()
    {
        let out = std::process::Command::new(ffprobe)
            .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
            .args([
                "-show_entries",
                "stream=nb_read_frames,r_frame_rate,width,height",
            ])
            .args(["-of", "csv=p=0"])
            .arg(&path)
            .output()
            .unwrap();
        assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "96,64,24/1,30");
    }
}

/// Issue 38: an MP4 for viewers keeps a recorded face's fine detail. GRID s1's committed clip,
/// written as `say` writes its video and decoded: every frame within 41 dB of the clip's own
/// (42.2 dB on average at the writer's quantiser, 20; at OpenH264's own, 26, the writer's
/// until 2026-12-06, 38.2 dB; at 22, 41.0 dB with frames down to 40.7).
#[test]
fn mp4s_for_viewers_keep_a_recorded_faces_detail() {
    let clip = common::root().join("tests/data/grid/bbbf9a.mp4");
    let frames: Vec<RgbImage> = Source::open(&clip).unwrap().take(25).map(|f| f.unwrap()).collect();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("viewer.mp4");
    write(&out, &frames, 25.0, None);
    let back: Vec<RgbImage> = Source::open(&out).unwrap().map(|f| f.unwrap()).collect();
    assert_eq!(back.len(), frames.len());
    for (k, (a, b)) in frames.iter().zip(&back).enumerate() {
        let p = psnr(a, b);
        assert!(p > 41.0, "frame {k}: {p:.2} dB from the clip, written for viewers");
    }
}

/// Issue 68: a video written for viewers does not pulse — a keyframe drawn unlike the
/// frames before it made the frame-to-frame change jump 2.4× the source's every 2 s. Over
/// 12 s of a GRID clip played back and forth (the source), no decoded frame changes more than
/// 1.6× as much as the source does there, but at the one keyframe inside (frame 250).
#[test]
fn videos_for_viewers_do_not_pulse() {
    let clip = common::root().join("tests/data/grid/bbbf9a.mp4");
    let once: Vec<RgbImage> = Source::open(&clip).unwrap().map(|f| f.unwrap()).collect();
    let frames: Vec<RgbImage> = (0..300)
        .map(|i| {
            let k = i % (2 * once.len() - 2);
            once[if k < once.len() { k } else { 2 * once.len() - 2 - k }].clone()
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("viewer.mp4");
    write(&out, &frames, 25.0, None);
    let back: Vec<RgbImage> = Source::open(&out).unwrap().map(|f| f.unwrap()).collect();
    let change = |v: &[RgbImage], t: usize| {
        let (a, b) = (v[t - 1].as_raw(), v[t].as_raw());
        a.iter().zip(b).map(|(&x, &y)| f64::from(x.abs_diff(y))).sum::<f64>() / a.len() as f64
    };
    let worst = (1..frames.len())
        .filter(|&t| t != 250)
        .map(|t| (change(&back, t) / change(&frames, t).max(0.1), t))
        .fold((0.0, 0), |m, x| if x.0 > m.0 { x } else { m });
    assert!(worst.0 < 1.6, "frame {}: {:.2}× the source's change", worst.1, worst.0);
}

#[test]
fn audio_is_carried_from_mp4_to_mp4() {
    let dir = tempfile::tempdir().unwrap();
    let m4a = dir.path().join("audio.m4a");
    assert!(video::extract_audio(&sample(), &m4a).unwrap());
    let out = dir.path().join("with_sound.mp4");
    let frames: Vec<RgbImage> = (0..24).map(|i| pattern(i, 64, 48)).collect();
    write(&out, &frames, 24.0, Some(&m4a));
    let back = dir.path().join("back.m4a");
    assert!(video::extract_audio(&out, &back).unwrap());
    // The same AAC packets, byte for byte, in all three files' audio tracks.
    let packets = |p: &Path| facespace::mp4_file::AudioTrack::read(p).unwrap().unwrap().packets();
    assert_eq!(packets(&sample()), packets(&back));
    assert!(!packets(&sample()).is_empty());
    // A video without sound has none to extract.
    let silent = dir.path().join("silent.mp4");
    write(&silent, &frames, 24.0, None);
    assert!(!video::extract_audio(&silent, &dir.path().join("none.m4a")).unwrap());
}

/// A decoder started at a sync frame gives the same pictures as one that decoded everything
/// before it (so a video can be decoded in pieces side by side); elsewhere it is refused.
#[test]
fn decoding_from_a_sync_frame_matches_decoding_from_the_start() {
    use facespace::mp4_file::{Mp4Error, Reader};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gops.mp4");
    // Our writer starts a picture group every ten seconds: at 10 fps, frames 0, 100 and 200.
    let frames: Vec<RgbImage> = (0..205).map(|i| pattern(i, 64, 48)).collect();
    write(&path, &frames, 10.0, None);
    let mut whole = Reader::open(&path).unwrap();
    assert_eq!(whole.sync_frames(), [0, 100, 200]);
    let mut all = Vec::new();
    while let Some(f) = whole.next_frame().unwrap() {
        all.push(f);
    }
    for start in [200, 100, 0] {
        let mut piece = Reader::open(&path).unwrap();
        piece.seek(start).unwrap();
        let mut from = Vec::new();
        while let Some(f) = piece.next_frame().unwrap() {
            from.push(f);
        }
        assert!(from == all[start..], "from frame {start}");
    }
    let mut r = Reader::open(&path).unwrap();
    assert!(matches!(r.seek(7), Err(Mp4Error::NotSync(7))));
    assert!(matches!(r.seek(205), Err(Mp4Error::NotSync(205))));
    // Still usable after a refused seek.
    assert!(r.next_frame().unwrap().unwrap() == all[0]);
}

#[test]
fn y4m_and_frame_folders_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<RgbImage> = (0..5).map(|i| pattern(i, 33, 17)).collect();
    for name in ["clip.y4m", "frames"] {
        let path = dir.path().join(name);
        write(&path, &frames, 30.0, None);
        let back: Vec<RgbImage> = Source::open(&path).unwrap().map(|f| f.unwrap()).collect();
        assert_eq!(back.len(), 5);
        for (a, b) in back.iter().zip(&frames) {
            assert!(psnr(a, b) > 45.0, "{name}");
        }
    }
    // A frame folder is replaced only by another frame folder.
    std::fs::write(
        dir.path()
            .join("notes/keep.txt")
            .parent()
            .map(|p| {
                std::fs::create_dir_all(p).unwrap();
                p.join("keep.txt")
            })
            .unwrap(),
        "mine",
    )
    .unwrap();
    let mut sink = Sink::create(&dir.path().join("notes"), 33, 17, 30.0, None).unwrap();
    sink.write(&frames[0]).unwrap();
    assert!(sink.finish().is_err());
    assert!(dir.path().join("notes/keep.txt").is_file());
}

#[test]
fn bad_input_is_a_clear_error_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    // Truncated MP4.
    let bytes = std::fs::read(sample()).unwrap();
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let err = match Source::open(&cut) {
        Err(e) => e.to_string(),
        Ok(s) => s
            .map(|f| f.map(|_| ()))
            .collect::<Result<Vec<_>, _>>()
            .unwrap_err()
            .to_string(),
    };
    assert!(err.contains("cut.mp4"), "{err}");
    // Not a video at all.
    let junk = dir.path().join("junk.mp4");
    std::fs::write(&junk, b"hello").unwrap();
    assert!(matches!(
        Source::open(&junk),
        Err(VideoError::Mp4 {
            source: facespace::mp4_file::Mp4Error::Container(_)
                | facespace::mp4_file::Mp4Error::Malformed(_),
            ..
        })
    ));
    // Odd dimensions cannot be H.264 4:2:0.
    let odd = Sink::create(&dir.path().join("odd.mp4"), 361, 288, 25.0, None);
    assert!(odd.err().unwrap().to_string().contains("even"));
    // Zero frames: an error, and no file.
    let sink = Sink::create(&dir.path().join("empty.mp4"), 64, 48, 25.0, None).unwrap();
    assert!(matches!(sink.finish(), Err(VideoError::NoFrames(_))));
    // A frame of the wrong size, then the sink dropped: no file.
    let mut sink = Sink::create(&dir.path().join("mixed.y4m"), 64, 48, 25.0, None).unwrap();
    sink.write(&pattern(0, 64, 48)).unwrap();
    assert!(matches!(
        sink.write(&pattern(0, 32, 48)),
        Err(VideoError::FrameSize { .. })
    ));
    drop(sink);
    let mut left = leftovers(dir.path());
    left.sort();
    assert_eq!(left, ["cut.mp4", "junk.mp4"]);
    // Missing input and an empty folder.
    assert!(Source::open(&dir.path().join("nope.mp4")).is_err());
    let empty = dir.path().join("no_frames");
    std::fs::create_dir(&empty).unwrap();
    assert!(matches!(Source::open(&empty), Err(VideoError::NoFrames(_))));
}

/// Other containers go through a system ffmpeg when there is one (skipped otherwise): a
/// Matroska file written and read back, and an unfinished one leaves nothing.
#[test]
fn other_containers_through_ffmpeg() {
    if facespace::programs::system_ffmpeg().is_none() {
        eprintln!("no ffmpeg on PATH: skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.mkv");
    let frames: Vec<RgbImage> = (0..12).map(|i| pattern(i, 64, 48)).collect();
    assert_eq!(write(&path, &frames, 25.0, Some(&sample())), 12);
    let source = Source::open(&path).unwrap();
    assert!((source.info().fps - 25.0).abs() < 1e-6);
    let back: Vec<RgbImage> = source.map(|f| f.unwrap()).collect();
    assert_eq!(back.len(), 12);
    assert!(psnr(&back[5], &frames[5]) > 30.0);
    let mut sink = Sink::create(&dir.path().join("dropped.mkv"), 64, 48, 25.0, None).unwrap();
    sink.write(&frames[0]).unwrap();
    drop(sink);
    assert_eq!(leftovers(dir.path()), ["clip.mkv"]);
}

/// Damaged MP4s (truncated, bits flipped, box sizes overwritten) give errors, never a panic.
#[test]
fn corrupted_mp4s_never_panic() {
    let bytes = std::fs::read(sample()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut rng = common::Rng::new(1);
    for t in 0..90 {
        let mut b = bytes.clone();
        match t % 3 {
            0 => b.truncate((rng.uniform() * b.len() as f64) as usize),
            1 => {
                for _ in 0..8 {
                    let i = (rng.uniform() * b.len() as f64) as usize;
                    b[i] ^= 1 << (t % 8);
                }
            }
            _ => {
                let i = (rng.uniform() * 2000.0) as usize;
                b[i..i + 2].copy_from_slice(&[0xff, 0xff]);
            }
        }
        let path = dir.path().join(format!("{t}.mp4"));
        std::fs::write(&path, &b).unwrap();
        // Reading to the end or to the first error must not panic.
        if let Ok(source) = Source::open(&path) {
            for frame in source {
                if frame.is_err() {
                    break;
                }
            }
        }
    }
}

#[test]
fn y4m_headers_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    for (name, header) in [
        ("huge.y4m", "YUV4MPEG2 W999999 H999999 F25:1 C444\n"),
        ("zero.y4m", "YUV4MPEG2 W0 H10 F25:1\n"),
        ("rate.y4m", "YUV4MPEG2 W4 H4 F0:1\n"),
        ("chroma.y4m", "YUV4MPEG2 W4 H4 F25:1 C411\n"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, header).unwrap();
        let err = Source::open(&path).err().map(|e| e.to_string());
        assert!(
            err.as_deref().is_some_and(|e| e.contains(name)),
            "{name}: {err:?}"
        );
    }
}

/// Issue 17: MP4s whose box sizes or table counts are damaged (sizes 0, 1, 8, −4, +1000 or
/// doubled on every header and table box; entry counts 0 and 2³²−1; an `mdhd` timescale of
/// 0) used to make the `mp4` crate spin forever or panic. Each must now open, decode or fail
/// with an error within a few seconds.
#[test]
fn damaged_mp4_boxes_are_errors_not_hangs() {
    let src = std::fs::read(sample()).unwrap();
    let boxes: [&[u8; 4]; 20] = [
        b"mvhd", b"tkhd", b"mdhd", b"hdlr", b"vmhd", b"smhd", b"dref", b"stsz", b"stts", b"stsc",
        b"stco", b"stss", b"ctts", b"stsd", b"sgpd", b"sbgp", b"udta", b"elst", b"trak", b"stbl",
    ];
    let mut cases: Vec<(String, Vec<u8>)> = Vec::new();
    for name in boxes {
        for at in (4..src.len() - 4).filter(|&i| &src[i..i + 4] == name) {
            let size = u32::from_be_bytes(src[at - 4..at].try_into().unwrap());
            for new in [
                0,
                1,
                8,
                size.wrapping_sub(4),
                size + 1000,
                size.wrapping_mul(2),
            ] {
                let mut d = src.clone();
                d[at - 4..at].copy_from_slice(&new.to_be_bytes());
                cases.push((
                    format!("{} at {at}: size {new}", String::from_utf8_lossy(name)),
                    d,
                ));
            }
            let count_at = if name == b"stsz" { at + 16 } else { at + 8 };
            for new in [0u32, u32::MAX] {
                let mut d = src.clone();
                d[count_at..count_at + 4].copy_from_slice(&new.to_be_bytes());
                cases.push((
                    format!("{} at {at}: count {new}", String::from_utf8_lossy(name)),
                    d,
                ));
            }
            if name == b"mdhd" {
                let mut d = src.clone();
                d[at + 16..at + 20].copy_from_slice(&0u32.to_be_bytes());
                cases.push((format!("mdhd at {at}: timescale 0"), d));
            }
        }
    }
    assert!(cases.len() > 150, "{} cases", cases.len());
    let dir = tempfile::tempdir().unwrap();
    let mut errors = 0;
    for (k, (label, bytes)) in cases.into_iter().enumerate() {
        let path = dir.path().join(format!("case{k}.mp4"));
        std::fs::write(&path, bytes).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        let p = path.clone();
        std::thread::spawn(move || {
            let outcome = std::panic::catch_unwind(|| match Source::open(&p) {
                Ok(source) => source.take(30).find_map(Result::err).map(|e| e.to_string()),
                Err(e) => Some(e.to_string()),
            });
            let _ = tx.send(outcome);
        });
        match rx.recv_timeout(std::time::Duration::from_secs(20)) {
            Ok(Ok(error)) => errors += usize::from(error.is_some()),
            Ok(Err(_)) => panic!("{label}: panicked"),
            Err(_) => panic!("{label}: still running after 20 s (hang)"),
        }
    }
    assert!(errors > 100, "only {errors} damaged files were refused");
}
