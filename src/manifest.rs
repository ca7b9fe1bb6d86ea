//! JSON manifests of model and codebook folders: format and version are checked before the
//! rest is parsed, so an unknown version is reported as such, not as a missing field.

use std::path::Path;

use serde::de::DeserializeOwned;

/// What can be wrong with a manifest; the caller names the file.
#[derive(Debug)]
pub enum ManifestError {
    Io(std::io::Error),
    Invalid(String),
    Version(u32),
}

/// Reads `path`, checks `"format": format` and `"version": version`, then parses `T`.
pub fn read<T: DeserializeOwned>(
    path: &Path,
    format: &str,
    version: u32,
) -> Result<T, ManifestError> {
    let text = std::fs::read_to_string(path).map_err(ManifestError::Io)?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| ManifestError::Invalid(e.to_string()))?;
    if value.get("format").and_then(|f| f.as_str()) != Some(format) {
        return Err(ManifestError::Invalid(format!(
            "not a {format} manifest (\"format\" field)"
        )));
    }
    let found = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0) as u32;
    if found != version {
        return Err(ManifestError::Version(found));
    }
    serde_json::from_value(value).map_err(|e| ManifestError::Invalid(e.to_string()))
}
