//! NumPy `.npy` arrays (format versions 1–3), little-endian, C order, so that model, codebook
//! and clip folders open in Python with `numpy.load`.
//!
//! Read into `ndarray` arrays. The reader checks magic, header, dtype and shape, and compares
//! the data length the header declares with the file's length *before* allocating, so a
//! damaged or hostile header cannot ask for gigabytes (`ndarray-npy` allocates the declared
//! shape first, which is why this small reader stays). Only regular files are read (a FIFO
//! or device would hang or never end).

use std::io::Read;
use std::path::{Path, PathBuf};

use ndarray::{ArrayD, ArrayView, Dimension, IxDyn};
use thiserror::Error;

use crate::atomic;

/// What can go wrong reading or writing a `.npy` file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum NpyError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a regular file (a folder, FIFO or device).
    #[error("{path}: not a regular file")]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// The magic bytes are wrong.
    #[error("{path}: not a .npy file (bad magic bytes)")]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// The header cannot be parsed.
    #[error("{path}: malformed .npy header: {reason}")]
    BadHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The element type differs from the one expected.
    #[error("{path}: dtype {found} where {expected} was expected")]
    Dtype {
        /// The file.
        path: PathBuf,
        /// The dtype expected.
        expected: &'static str,
        /// The dtype found.
        found: String,
    },
    /// Fortran order is not read.
    #[error("{path}: Fortran-ordered arrays are not supported")]
    FortranOrder {
        /// The file.
        path: PathBuf,
    },
    /// Fewer data bytes than the shape needs.
    #[error("{path}: truncated: shape {shape:?} needs {expected} data bytes, file has {actual}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The declared shape.
        shape: Vec<usize>,
        /// Bytes the shape needs.
        expected: u64,
        /// Bytes present.
        actual: u64,
    },
    /// More data bytes than the shape needs.
    #[error("{path}: {actual} trailing bytes after the data of shape {shape:?}")]
    TrailingBytes {
        /// The file.
        path: PathBuf,
        /// The declared shape.
        shape: Vec<usize>,
        /// Extra bytes.
        actual: u64,
    },
    /// The shape differs from the one expected (`None` in `expected`: any length).
    #[error("{path}: array shape {found:?}, expected {}", describe(expected))]
    Shape {
        /// The file.
        path: PathBuf,
        /// The shape expected, `None` where any length is allowed.
        expected: Vec<Option<usize>>,
        /// The shape found.
        found: Vec<usize>,
    },
    /// A NaN or infinity.
    #[error("{path}: value {index} is not finite")]
    NotFinite {
        /// The file.
        path: PathBuf,
        /// Flat (row-major) index of the first non-finite value.
        index: usize,
    },
}

fn describe(expected: &[Option<usize>]) -> String {
    let dims: Vec<String> = expected
        .iter()
        .map(|d| d.map_or("any".to_owned(), |d| d.to_string()))
        .collect();
    format!("[{}]", dims.join(", "))
}

/// A scalar type stored in `.npy` files.
pub trait Element: Copy + Default {
    /// NumPy dtype descriptor, e.g. `<f4`.
    const DESCR: &'static str;
    /// Bytes per element.
    const SIZE: usize;
    /// Decodes one little-endian element.
    fn read_le(bytes: &[u8]) -> Self;
    /// Appends one element, little-endian.
    fn write_le(self, out: &mut Vec<u8>);
    /// Whether the value is finite (integers always are).
    fn finite(self) -> bool {
        true
    }
}

macro_rules! element {
    ($t:ty, $descr:literal $(, $finite:ident)?) => {
        impl Element for $t {
            const DESCR: &'static str = $descr;
            const SIZE: usize = std::mem::size_of::<$t>();
            fn read_le(bytes: &[u8]) -> Self {
                <$t>::from_le_bytes(bytes.try_into().expect("slice of SIZE bytes"))
            }
            fn write_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
            $(fn finite(self) -> bool {
                self.$finite()
            })?
        }
    };
}
element!(f32, "<f4", is_finite);
element!(f64, "<f8", is_finite);
element!(u8, "|u1");
element!(u16, "<u2");
element!(u32, "<u4");

const MAGIC: &[u8] = b"\x93NUMPY";
/// Longest header read (numpy writes a few hundred bytes; its own reader stops at 10 000).
const MAX_HEADER: usize = 65_536;

/// Encodes an array as `.npy` bytes (format 1.0, header padded to 64 bytes), in logical
/// (row-major) order whatever the array's memory layout.
pub fn to_bytes<T: Element, D: Dimension>(array: ArrayView<'_, T, D>) -> Vec<u8> {
    let shape = array.shape();
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
    let mut out = Vec::with_capacity(MAGIC.len() + 4 + header.len() + array.len() * T::SIZE);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for &x in array.iter() {
        x.write_le(&mut out);
    }
    out
}

/// Writes an array atomically (temporary file + rename).
pub fn write<T: Element, D: Dimension>(
    path: &Path,
    array: ArrayView<'_, T, D>,
) -> Result<(), NpyError> {
    atomic::write_file(path, &to_bytes(array)).map_err(|source| NpyError::Io {
        path: path.to_owned(),
        source,
    })
}

/// A parsed header: element descriptor and shape, and where the data starts.
struct Header {
    shape: Vec<usize>,
    data_start: usize,
    /// Bytes of data the shape needs.
    data_len: u64,
}

/// Parses the header at the start of `bytes` (which must hold all of it).
fn parse_header<T: Element>(bytes: &[u8], path: &Path) -> Result<Header, NpyError> {
    let bad = |reason: &str| NpyError::BadHeader {
        path: path.to_owned(),
        reason: reason.to_owned(),
    };
    if bytes.len() < MAGIC.len() + 2 || &bytes[..MAGIC.len()] != MAGIC {
        return Err(NpyError::BadMagic {
            path: path.to_owned(),
        });
    }
    let (len_bytes, start) = match bytes[MAGIC.len()] {
        1 => (2, MAGIC.len() + 4),
        2 | 3 => (4, MAGIC.len() + 6),
        v => return Err(bad(&format!("unsupported format version {v}"))),
    };
    let len_field = bytes
        .get(MAGIC.len() + 2..start)
        .ok_or_else(|| bad("file ends inside the header length"))?;
    let header_len = if len_bytes == 2 {
        u16::from_le_bytes([len_field[0], len_field[1]]) as usize
    } else {
        u32::from_le_bytes([len_field[0], len_field[1], len_field[2], len_field[3]]) as usize
    };
    if header_len > MAX_HEADER {
        return Err(bad(&format!(
            "header of {header_len} bytes (at most {MAX_HEADER} are read)"
        )));
    }
    let data_start = start + header_len;
    let header = bytes
        .get(start..data_start)
        .ok_or_else(|| bad("file ends inside the header"))?;
    let header = std::str::from_utf8(header).map_err(|_| bad("header is not text"))?;
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
    let data_len = shape
        .iter()
        .try_fold(T::SIZE as u64, |acc, &d| acc.checked_mul(d as u64))
        .ok_or_else(|| bad("shape overflows"))?;
    Ok(Header {
        shape,
        data_start,
        data_len,
    })
}

/// Checks that `available` data bytes are what the header declares.
fn check_length(header: &Header, available: u64, path: &Path) -> Result<(), NpyError> {
    if available < header.data_len {
        return Err(NpyError::Truncated {
            path: path.to_owned(),
            shape: header.shape.clone(),
            expected: header.data_len,
            actual: available,
        });
    }
    if available > header.data_len {
        return Err(NpyError::TrailingBytes {
            path: path.to_owned(),
            shape: header.shape.clone(),
            actual: available - header.data_len,
        });
    }
    Ok(())
}

fn decode<T: Element>(header: Header, body: &[u8]) -> ArrayD<T> {
    let data = body.chunks_exact(T::SIZE).map(T::read_le).collect();
    ArrayD::from_shape_vec(IxDyn(&header.shape), data).expect("length checked against the shape")
}

/// Reads an array whose dtype must be `T`; the file's length is checked against the header
/// before the data is read.
pub fn read<T: Element>(path: &Path) -> Result<ArrayD<T>, NpyError> {
    let io = |source| NpyError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = crate::safe_read::open_regular(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidInput {
            NpyError::NotAFile {
                path: path.to_owned(),
            }
        } else {
            io(e)
        }
    })?;
    let meta = file.metadata().map_err(io)?;
    let mut head = Vec::new();
    (&mut file)
        .take((MAGIC.len() + 6 + MAX_HEADER) as u64)
        .read_to_end(&mut head)
        .map_err(io)?;
    let header = parse_header::<T>(&head, path)?;
    check_length(&header, meta.len() - header.data_start as u64, path)?;
    let mut body = head.split_off(header.data_start);
    let rest = header.data_len as usize - body.len().min(header.data_len as usize);
    body.reserve_exact(rest);
    (&mut file)
        .take(rest as u64)
        .read_to_end(&mut body)
        .map_err(io)?;
    // The file may have changed since its length was read.
    check_length(&header, body.len() as u64, path)?;
    Ok(decode(header, &body))
}

/// Decodes `.npy` bytes held in memory; `path` only names the source in errors.
pub fn from_bytes<T: Element>(bytes: &[u8], path: &Path) -> Result<ArrayD<T>, NpyError> {
    let header = parse_header::<T>(bytes, path)?;
    let body = &bytes[header.data_start..];
    check_length(&header, body.len() as u64, path)?;
    Ok(decode(header, body))
}

/// Reads an array of `D`'s rank whose shape matches `expected` (`None`: any length) and whose
/// values are all finite.
pub fn read_checked<T: Element, D: Dimension>(
    path: &Path,
    expected: &[Option<usize>],
) -> Result<ndarray::Array<T, D>, NpyError> {
    let a = read::<T>(path)?;
    let fits = a.ndim() == expected.len()
        && a.shape()
            .iter()
            .zip(expected)
            .all(|(&n, e)| e.is_none_or(|e| e == n));
    if !fits {
        return Err(NpyError::Shape {
            path: path.to_owned(),
            expected: expected.to_vec(),
            found: a.shape().to_vec(),
        });
    }
    if let Some(index) = a.iter().position(|v| !v.finite()) {
        return Err(NpyError::NotFinite {
            path: path.to_owned(),
            index,
        });
    }
    Ok(a.into_dimensionality::<D>().expect("rank checked"))
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
    use ndarray::{Array1, Array2};

    #[test]
    fn round_trip_and_alignment() {
        let data = Array2::from_shape_fn((3, 4), |(i, j)| (i * 4 + j) as f32 * 0.5 - 1.0);
        let bytes = to_bytes(data.view());
        // The header (magic + version + length + dict) pads the data start to 64 bytes.
        assert_eq!((bytes.len() - data.len() * 4) % 64, 0);
        let back = from_bytes::<f32>(&bytes, Path::new("x.npy")).unwrap();
        assert_eq!(back.shape(), &[3, 4]);
        assert_eq!(back.into_dimensionality::<ndarray::Ix2>().unwrap(), data);
        // A transposed view is written in its logical order.
        let t = from_bytes::<f32>(&to_bytes(data.t()), Path::new("t.npy")).unwrap();
        assert_eq!(t.into_dimensionality::<ndarray::Ix2>().unwrap(), data.t());
        let one = from_bytes::<u8>(&to_bytes(Array1::from(vec![7u8, 9]).view()), Path::new("y"));
        assert_eq!(one.unwrap().shape(), &[2]);
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
        let a = from_bytes::<f64>(&bytes, Path::new("np.npy")).unwrap();
        assert_eq!(a.shape(), &[2, 3]);
        assert!(a.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn truncation_dtype_and_magic_are_named() {
        let bytes = to_bytes(Array1::from(vec![1.0f32; 10]).view());
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

    #[test]
    fn a_huge_declared_shape_is_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bomb.npy");
        let mut bytes = to_bytes(Array1::from(vec![0.0f32; 4]).view());
        let start = bytes.len() - 16;
        let text = String::from_utf8_lossy(&bytes[10..start])
            .replacen("(4,)", "(4000000000000,)", 1)
            .replacen(&" ".repeat(12), "", 1);
        bytes.splice(10..start, text.bytes());
        std::fs::write(&path, &bytes).unwrap();
        let err = read::<f32>(&path).unwrap_err();
        assert!(matches!(err, NpyError::Truncated { .. }), "{err}");
        // Not a regular file: refused, not read forever.
        assert!(matches!(
            read::<f32>(Path::new("/dev/zero")),
            Err(NpyError::NotAFile { .. })
        ));
    }
}
