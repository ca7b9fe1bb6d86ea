//! Frames out of a video for annotation: a training set starts as a few dozen frames spread
//! over the recording, marked by hand (issue 15's "frames and landmarks from your video").

use std::path::Path;

use rayon::prelude::*;

use super::{Source, VideoError, io_error, write_png};
use crate::{Progress, atomic, options};

/// Most frames one export writes.
pub const MAX_EXPORT: usize = 100_000;

/// `count` frame indices spread evenly over `total` frames, first and last included
/// (`round(i·(total − 1)/(count − 1))`); every frame when `count ≥ total`.
pub fn spread(total: usize, count: usize) -> Vec<usize> {
    if count >= total {
        return (0..total).collect();
    }
    if count == 1 {
        return vec![0];
    }
    (0..count)
        .map(|i| ((i * (total - 1)) as f64 / (count - 1) as f64).round() as usize)
        .collect()
}

/// Writes `count` frames spread over `input` as `out/NNNNNN.png` (NNNNNN = the frame's index
/// in the video, so landmarks tracked on the video line up with them); `out` is replaced
/// atomically (only if it is a frame folder facespace wrote). Returns the indices written.
pub fn export_frames(
    input: &Path,
    count: usize,
    out: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<Vec<usize>, VideoError> {
    options::count_in("frames to export", count, 1, MAX_EXPORT).map_err(|source| {
        VideoError::Option {
            path: out.into(),
            source,
        }
    })?;
    let total = match Source::open(input)?.info().frames {
        Some(n) => n,
        // Containers read through ffmpeg do not say: count them first.
        None => {
            let mut n = 0;
            for frame in Source::open(input)? {
                frame?;
                n += 1;
            }
            n
        }
    };
    if total == 0 {
        return Err(VideoError::NoFrames(input.into()));
    }
    let wanted = spread(total, count);
    atomic::replace_dir(
        out,
        "frames",
        |staged| {
            let mut next = wanted.iter().peekable();
            let mut batch = Vec::new();
            let flush = |batch: &mut Vec<(usize, image::RgbImage)>| {
                let written = batch
                    .par_iter()
                    .map(|(i, f)| write_png(&staged.join(format!("{i:06}.png")), f))
                    .collect::<Result<Vec<_>, _>>();
                batch.clear();
                written
            };
            let mut done = 0;
            for (i, frame) in Source::open(input)?.enumerate() {
                let frame = frame?;
                if next.peek() == Some(&&i) {
                    // A repeated index (never with `spread`) is written once.
                    while next.peek() == Some(&&i) {
                        next.next();
                    }
                    batch.push((i, frame));
                    done += 1;
                    if batch.len() == 16 {
                        flush(&mut batch)?;
                    }
                    progress(Progress {
                        stage: "exporting frames",
                        done,
                        total: wanted.len(),
                    });
                }
                if next.peek().is_none() {
                    break;
                }
            }
            flush(&mut batch)?;
            if next.peek().is_some() {
                // The container promised more frames than it holds.
                return Err(VideoError::Io {
                    path: input.into(),
                    source: std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        format!("ended after fewer than the {total} frames it declares"),
                    ),
                });
            }
            Ok(())
        },
        io_error(out),
    )?;
    Ok(wanted)
}

#[cfg(test)]
mod tests {
    use super::spread;

    #[test]
    fn spread_covers_first_and_last_evenly() {
        assert_eq!(spread(10, 4), [0, 3, 6, 9]);
        assert_eq!(spread(5, 1), [0]);
        assert_eq!(spread(3, 8), [0, 1, 2]);
        let s = spread(1337, 40);
        assert_eq!((s[0], s[39]), (0, 1336));
        assert!(s.windows(2).all(|w| (34..=35).contains(&(w[1] - w[0]))));
    }
}
