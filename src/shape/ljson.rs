//! menpo's landmark JSON (`.ljson`, versions 2 and 3), so annotations made with menpo's
//! landmarker load like iBUG `.pts`. menpo writes points as `[y, x]`, 0-based pixel centres.

use std::path::Path;

use serde_json::Value;

use super::{Landmarks, ShapeError, read_pts};

/// Landmarks from a `.pts` or `.ljson` file, by extension.
pub fn read_landmarks(path: &Path) -> Result<Landmarks, ShapeError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("ljson") => read_ljson(path),
        _ => read_pts(path),
    }
}

/// Reads a menpo `.ljson` file.
pub fn read_ljson(path: &Path) -> Result<Landmarks, ShapeError> {
    let text = crate::safe_read::read_regular_string(path).map_err(|source| ShapeError::Io {
        path: path.into(),
        source,
    })?;
    parse_ljson(&text, path)
}

/// Parses `.ljson` text; `path` names the source in errors. Version 3 files may hold several
/// groups: the one with 68 points is taken (iBUG's layout), else the only one.
pub fn parse_ljson(text: &str, path: &Path) -> Result<Landmarks, ShapeError> {
    let err = |reason: String| ShapeError::Ljson {
        path: path.into(),
        reason,
    };
    let json: Value = serde_json::from_str(text).map_err(|e| err(format!("not JSON: {e}")))?;
    let points = match json.get("version").and_then(Value::as_u64) {
        Some(2) => json.pointer("/landmarks/points"),
        Some(3) => {
            let groups = json
                .get("groups")
                .and_then(Value::as_object)
                .ok_or_else(|| err("no \"groups\" object".into()))?;
            let points: Vec<(&String, &Value)> = groups
                .iter()
                .filter_map(|(name, g)| g.pointer("/landmarks/points").map(|p| (name, p)))
                .collect();
            let with_68: Vec<_> = points
                .iter()
                .filter(|(_, p)| p.as_array().is_some_and(|a| a.len() == 68))
                .collect();
            match (with_68.as_slice(), points.as_slice()) {
                ([(_, p)], _) | ([], [(_, p)]) => Some(*p),
                _ => {
                    let names: Vec<&str> = points.iter().map(|(n, _)| n.as_str()).collect();
                    return Err(err(format!(
                        "{} groups ({}) and not exactly one of 68 points: which to use is ambiguous",
                        names.len(),
                        names.join(", ")
                    )));
                }
            }
        }
        other => {
            return Err(err(format!(
                "ljson version {}, this build reads versions 2 and 3",
                other.map_or("(none)".into(), |v| v.to_string())
            )));
        }
    };
    let points = points
        .and_then(Value::as_array)
        .ok_or_else(|| err("no landmarks/points array".into()))?;
    if points.is_empty() {
        return Err(err("no points".into()));
    }
    let points = points
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let yx: Option<Vec<f64>> = p
                .as_array()
                .filter(|a| a.len() == 2)
                .and_then(|a| a.iter().map(Value::as_f64).collect());
            match yx {
                Some(v) if v.iter().all(|c| c.is_finite()) => Ok([v[1], v[0]]),
                _ => Err(err(format!(
                    "point {k} is {p}, not two finite numbers (a missing point is not allowed)"
                ))),
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Landmarks { points })
}
