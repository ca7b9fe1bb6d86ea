//! iBUG `.pts` files (1-based coordinates on disk, 0-based pixel centres in memory) and
//! sequences of landmark sets (`.npy` or a folder of `.pts`).

use std::path::Path;

use super::{Landmarks, ShapeError};
use crate::atomic;

/// Reads an iBUG `.pts` file (`version: 1`, `n_points: N`, `{`, N lines `x y`, `}`).
pub fn read_pts(path: &Path) -> Result<Landmarks, ShapeError> {
    let text = crate::safe_read::read_regular_string(path).map_err(|source| ShapeError::Io {
        path: path.into(),
        source,
    })?;
    parse_pts(&text, path)
}

/// Parses `.pts` text; `path` names the source in errors.
pub fn parse_pts(text: &str, path: &Path) -> Result<Landmarks, ShapeError> {
    let err = |line: usize, reason: String| ShapeError::Parse {
        path: path.into(),
        line,
        reason,
    };
    let mut declared = None;
    let mut points = Vec::new();
    let mut state = 0; // 0: header, 1: inside braces, 2: after the closing brace
    let mut last_line = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        last_line = line_no;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        match state {
            0 => {
                if line == "{" {
                    state = 1;
                } else if let Some((key, value)) = line.split_once(':') {
                    match key.trim() {
                        "version" if value.trim() != "1" => {
                            return Err(err(
                                line_no,
                                format!("unsupported version {:?}", value.trim()),
                            ));
                        }
                        "n_points" => {
                            let n = value.trim().parse::<usize>();
                            declared = Some(n.map_err(|_| {
                                err(line_no, format!("bad n_points {:?}", value.trim()))
                            })?);
                        }
                        _ => {} // other header keys are allowed and ignored
                    }
                } else {
                    return Err(err(
                        line_no,
                        format!("expected a header line or '{{', found {line:?}"),
                    ));
                }
            }
            1 if line == "}" => state = 2,
            1 => {
                let mut it = line.split_whitespace();
                let mut coord = |name| -> Result<f64, ShapeError> {
                    let s = it
                        .next()
                        .ok_or_else(|| err(line_no, format!("missing {name} coordinate")))?;
                    let v = s
                        .parse::<f64>()
                        .map_err(|_| err(line_no, format!("bad {name} coordinate {s:?}")))?;
                    if v.is_finite() {
                        Ok(v)
                    } else {
                        Err(err(line_no, format!("{name} coordinate is {v}")))
                    }
                };
                let (x, y) = (coord("x")?, coord("y")?);
                if it.next().is_some() {
                    return Err(err(
                        line_no,
                        format!("expected two coordinates, found {line:?}"),
                    ));
                }
                points.push([x - 1.0, y - 1.0]);
            }
            _ => {
                return Err(err(
                    line_no,
                    format!("text after the closing '}}': {line:?}"),
                ));
            }
        }
    }
    let declared = declared.ok_or_else(|| err(1, "no n_points header".into()))?;
    if state != 2 {
        return Err(err(
            last_line,
            "missing closing '}' (file truncated?)".into(),
        ));
    }
    if points.len() != declared {
        return Err(err(
            last_line,
            format!(
                "n_points says {declared} but {} points follow",
                points.len()
            ),
        ));
    }
    Ok(Landmarks { points })
}

/// Formats landmarks as iBUG `.pts` text (1-based coordinates).
pub fn format_pts(landmarks: &Landmarks) -> String {
    let mut s = format!("version: 1\nn_points: {}\n{{\n", landmarks.len());
    for p in &landmarks.points {
        s.push_str(&format!("{:.6} {:.6}\n", p[0] + 1.0, p[1] + 1.0));
    }
    s.push_str("}\n");
    s
}

/// Writes a `.pts` file atomically.
pub fn write_pts(path: &Path, landmarks: &Landmarks) -> Result<(), ShapeError> {
    atomic::write_file(path, format_pts(landmarks).as_bytes()).map_err(|source| ShapeError::Io {
        path: path.into(),
        source,
    })
}

/// Writes a sequence of landmark sets: a `.npy` (frames × landmarks × 2, pixel centres
/// 0-based) when `path` ends in `.npy`, else a folder of `.pts` files named `names[i].pts`
/// (default `000000.pts`, …).
pub fn write_sequence(
    path: &Path,
    landmarks: &[Landmarks],
    names: Option<&[String]>,
) -> Result<(), ShapeError> {
    if path.extension().is_some_and(|e| e == "npy") {
        let n = landmarks.first().map_or(0, Landmarks::len);
        for (i, l) in landmarks.iter().enumerate() {
            l.validate(Some(n), &format!("{}: frame {i}", path.display()))?;
        }
        let flat: Vec<f32> = landmarks.iter().flat_map(Landmarks::to_flat).collect();
        let array = ndarray::Array3::from_shape_vec((landmarks.len(), n, 2), flat)
            .expect("every set has n points");
        crate::npy::write(path, array.view())?;
        return Ok(());
    }
    // A folder of .pts is staged and swapped in whole: never mixed into, or overwriting, a
    // folder of hand-made landmarks (or the input frames' own).
    atomic::replace_dir(
        path,
        "landmarks",
        |staged| {
            for (i, lm) in landmarks.iter().enumerate() {
                let name = names
                    .and_then(|n| n.get(i).cloned())
                    .unwrap_or_else(|| format!("{i:06}"));
                write_pts(&staged.join(format!("{name}.pts")), lm)?;
            }
            Ok(())
        },
        |source| ShapeError::Io {
            path: path.into(),
            source,
        },
    )
}
