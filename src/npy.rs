//! NumPy `.npy` arrays (format versions 1–3), little-endian, C order, so that a model
//! folder opens in Python with `numpy.load`. Readers validate magic, header, dtype,
//! shape and length and name the file in every error.

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::atomic;

/// What can go wrong reading or writing a `.npy` file.
#[derive(Debug, Error)]
pub enum NpyError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: not a .npy file (bad magic bytes)")]
    BadMagic { path: PathBuf },
    #[error("{path}: malformed .npy header: {reason}")]
    BadHeader { path: PathBuf, reason: String },
    #[error("{path}: dtype {found} where {expected} was expected")]
    Dtype {
        path: PathBuf,
        expected: &'static str,
        found: String,
    },
    #[error("{path}: Fortran-ordered arrays are not supported")]
    FortranOrder { path: PathBuf },
    #[error("{path}: truncated: shape {shape:?} needs {expected} data bytes, file has {actual}")]
    Truncated {
        path: PathBuf,
        shape: Vec<usize>,
        expected: usize,
        actual: usize,
    },
    #[error("{path}: {actual} trailing bytes after the data of shape {shape:?}")]
    TrailingBytes {
        path: PathBuf,
        shape: Vec<usize>,
        actual: usize,
    },
}

/// A scalar type stored in `.npy` files.
pub trait Element: Copy + Default {
    /// NumPy dtype descriptor, e.g. `<f4`.
    const DESCR: &'static str;
    const SIZE: usize;
    fn read_le(bytes: &[u8]) -> Self;
    fn write_le(self, out: &mut Vec<u8>);
}

macro_rules! element {
    ($t:ty, $descr:literal) => {
        impl Element for $t {
            const DESCR: &'static str = $descr;
            const SIZE: usize = std::mem::size_of::<$t>();
            fn read_le(bytes: &[u8]) -> Self {
                <$t>::from_le_bytes(bytes.try_into().expect("slice of SIZE bytes"))
            }
            fn write_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    };
}
element!(f32, "<f4");
element!(f64, "<f8");
element!(u8, "|u1");
element!(u16, "<u2");
element!(u32, "<u4");

/// An n-dimensional array: its shape and its elements in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct Array<T> {
    pub shape: Vec<usize>,
    pub data: Vec<T>,
}

const MAGIC: &[u8] = b"\x93NUMPY";

/// Encodes an array as `.npy` bytes (format 1.0, header padded to 64 bytes).
pub fn to_bytes<T: Element>(shape: &[usize], data: &[T]) -> Vec<u8> {
    assert_eq!(
        shape.iter().product::<usize>(),
        data.len(),
        "shape and data length differ"
    );
    let dims = match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {dims}, }}",
        T::DESCR
    );
    let unpadded = MAGIC.len() + 2 + 2 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(MAGIC.len() + 4 + header.len() + data.len() * T::SIZE);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for &x in data {
        x.write_le(&mut out);
    }
    out
}

/// Writes an array atomically (temporary file + rename).
pub fn write<T: Element>(path: &Path, shape: &[usize], data: &[T]) -> Result<(), NpyError> {
    atomic::write_file(path, &to_bytes(shape, data)).map_err(|source| NpyError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Reads an array whose dtype must be `T`.
pub fn read<T: Element>(path: &Path) -> Result<Array<T>, NpyError> {
    let bytes = std::fs::read(path).map_err(|source| NpyError::Io {
        path: path.to_owned(),
        source,
    })?;
    from_bytes(&bytes, path)
}

/// Decodes `.npy` bytes; `path` only names the source in errors.
pub fn from_bytes<T: Element>(bytes: &[u8], path: &Path) -> Result<Array<T>, NpyError> {
    let bad = |reason: &str| NpyError::BadHeader {
        path: path.to_owned(),
        reason: reason.to_owned(),
    };
    if bytes.len() < MAGIC.len() + 2 || &bytes[..MAGIC.len()] != MAGIC {
        return Err(NpyError::BadMagic {
            path: path.to_owned(),
        });
    }
    let major = bytes[MAGIC.len()];
    let (len_bytes, start) = match major {
        1 => (2, MAGIC.len() + 4),
        2 | 3 => (4, MAGIC.len() + 6),
        v => return Err(bad(&format!("unsupported format version {v}"))),
    };
    if bytes.len() < start {
        return Err(bad("file ends inside the header length"));
    }
    let len_field = &bytes[MAGIC.len() + 2..start];
    let header_len = if len_bytes == 2 {
        u16::from_le_bytes([len_field[0], len_field[1]]) as usize
    } else {
        u32::from_le_bytes([len_field[0], len_field[1], len_field[2], len_field[3]]) as usize
    };
    let data_start = start
        .checked_add(header_len)
        .ok_or_else(|| bad("header length overflows"))?;
    if bytes.len() < data_start {
        return Err(bad("file ends inside the header"));
    }
    let header =
        std::str::from_utf8(&bytes[start..data_start]).map_err(|_| bad("header is not text"))?;
    let descr = dict_value(header, "descr").ok_or_else(|| bad("no 'descr'"))?;
    let descr = descr.trim_matches(|c| c == '\'' || c == '"');
    if descr != T::DESCR && !(T::SIZE == 1 && descr.trim_start_matches(['|', '<']) == "u1") {
        return Err(NpyError::Dtype {
            path: path.to_owned(),
            expected: T::DESCR,
            found: descr.to_owned(),
        });
    }
    match dict_value(header, "fortran_order") {
        Some("False") => {}
        Some("True") => {
            return Err(NpyError::FortranOrder {
                path: path.to_owned(),
            });
        }
        _ => return Err(bad("no valid 'fortran_order'")),
    }
    let shape_text = dict_value(header, "shape").ok_or_else(|| bad("no 'shape'"))?;
    let shape = shape_text
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| bad(&format!("bad dimension {s:?} in shape")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| bad("shape overflows"))?;
    let expected = count
        .checked_mul(T::SIZE)
        .ok_or_else(|| bad("shape overflows"))?;
    let body = &bytes[data_start..];
    if body.len() < expected {
        return Err(NpyError::Truncated {
            path: path.to_owned(),
            shape,
            expected,
            actual: body.len(),
        });
    }
    if body.len() > expected {
        return Err(NpyError::TrailingBytes {
            path: path.to_owned(),
            shape,
            actual: body.len() - expected,
        });
    }
    let data = body.chunks_exact(T::SIZE).map(T::read_le).collect();
    Ok(Array { shape, data })
}

/// The raw text of `key`'s value in a Python dict literal (values here hold no nested braces
/// except the shape tuple, which holds no commas outside its parentheses).
fn dict_value<'h>(header: &'h str, key: &str) -> Option<&'h str> {
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[at + key.len() + 2..]
        .trim_start()
        .strip_prefix(':')?
        .trim_start();
    let end = if rest.starts_with('(') {
        rest.find(')')? + 1
    } else {
        rest.find([',', '}'])?
    };
    Some(rest[..end].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_alignment() {
        let data: Vec<f32> = (0..12).map(|i| i as f32 * 0.5 - 1.0).collect();
        let bytes = to_bytes(&[3, 4], &data);
        // The header (magic + version + length + dict) pads the data start to 64 bytes.
        assert_eq!((bytes.len() - data.len() * 4) % 64, 0);
        let back: Array<f32> = from_bytes(&bytes, Path::new("x.npy")).unwrap();
        assert_eq!(back.shape, vec![3, 4]);
        assert_eq!(back.data, data);
        let one: Array<u8> = from_bytes(&to_bytes(&[2], &[7u8, 9]), Path::new("y.npy")).unwrap();
        assert_eq!(one.shape, vec![2]);
    }

    #[test]
    fn reads_a_header_written_by_numpy() {
        // Header bytes exactly as numpy 2.x writes `np.save(f, np.zeros((2, 3), '<f8'))`.
        let mut bytes = b"\x93NUMPY\x01\x00v\x00".to_vec();
        let mut header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }".to_owned();
        header.push_str(&" ".repeat(118 - header.len() - 1));
        header.push('\n');
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&[0u8; 48]);
        let a: Array<f64> = from_bytes(&bytes, Path::new("np.npy")).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![0.0; 6]);
    }

    #[test]
    fn truncation_dtype_and_magic_are_named() {
        let bytes = to_bytes(&[10], &[1.0f32; 10]);
        let err = from_bytes::<f32>(&bytes[..bytes.len() - 3], Path::new("t.npy")).unwrap_err();
        assert!(
            matches!(
                err,
                NpyError::Truncated {
                    expected: 40,
                    actual: 37,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("t.npy"));
        let err = from_bytes::<f64>(&bytes, Path::new("d.npy")).unwrap_err();
        assert!(
            err.to_string().contains("<f4") && err.to_string().contains("<f8"),
            "{err}"
        );
        assert!(matches!(
            from_bytes::<f32>(b"hello", Path::new("m")),
            Err(NpyError::BadMagic { .. })
        ));
        assert!(matches!(
            from_bytes::<f32>(&bytes[..20], Path::new("h")),
            Err(NpyError::BadHeader { .. })
        ));
    }
}
