//! A structural check of an MP4's boxes before the `mp4` crate parses them: that crate loops
//! forever or panics on some malformed sizes and counts (issue 17: box sizes 0, 1 or too
//! small on `mvhd`, `tkhd`, `mdhd`, `dref`…, an `stts` without entries). Every box must fit
//! its parent exactly, be at least as long as its fixed fields, and every sample table's
//! declared entry count must fit the box.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};

use super::Mp4Error;

/// Largest `moov` box read into memory for the check (a 10-hour video's tables are far less).
const MAX_MOOV: u64 = 256 << 20;

/// Boxes whose content is a sequence of boxes.
const CONTAINERS: &[&[u8; 4]] = &[
    b"moov", b"trak", b"mdia", b"minf", b"stbl", b"dinf", b"edts", b"mvex", b"moof", b"traf",
];

fn malformed(what: String) -> Mp4Error {
    Mp4Error::Malformed(what)
}

/// Checks the box structure of the file: top-level boxes by their headers, `moov` in full.
pub(super) fn check(file: &mut File) -> Result<(), Mp4Error> {
    let len = file.metadata()?.len();
    let mut at = 0u64;
    let mut moov = false;
    while at < len {
        if len - at < 8 {
            return Err(malformed(format!(
                "{} stray bytes at the end of the file",
                len - at
            )));
        }
        file.seek(SeekFrom::Start(at))?;
        let mut head = [0u8; 16];
        let n = (len - at).min(16) as usize;
        file.read_exact(&mut head[..n])?;
        let (size, header, kind) = box_header(&head[..n], len - at, true)?;
        if &kind == b"moov" {
            if size > MAX_MOOV {
                return Err(malformed(format!(
                    "moov box of {size} bytes (at most {MAX_MOOV})"
                )));
            }
            let mut body = vec![0u8; (size - header) as usize];
            file.seek(SeekFrom::Start(at + header))?;
            file.read_exact(&mut body)?;
            children(&body, "moov", 1)?;
            moov = true;
        }
        at += size;
    }
    if !moov {
        return Err(malformed("no moov box".into()));
    }
    Ok(())
}

/// A box header at the start of `bytes`, with `room` bytes left in its parent: (size, header
/// length, type). Size 0 ("to the end") is allowed only at the top level.
fn box_header(bytes: &[u8], room: u64, top: bool) -> Result<(u64, u64, [u8; 4]), Mp4Error> {
    let kind: [u8; 4] = bytes[4..8].try_into().expect("8 bytes");
    let name = String::from_utf8_lossy(&kind).into_owned();
    let size32 = u32::from_be_bytes(bytes[..4].try_into().expect("8 bytes"));
    let (size, header) = match size32 {
        0 if top => (room, 8),
        0 => {
            return Err(malformed(format!(
                "{name} box of size 0 inside another box"
            )));
        }
        1 => {
            if bytes.len() < 16 {
                return Err(malformed(format!("{name} box: truncated 64-bit size")));
            }
            (
                u64::from_be_bytes(bytes[8..16].try_into().expect("16 bytes")),
                16,
            )
        }
        s => (u64::from(s), 8),
    };
    if size < header {
        return Err(malformed(format!(
            "{name} box of {size} bytes, shorter than its header"
        )));
    }
    if size > room {
        return Err(malformed(format!(
            "{name} box of {size} bytes where {room} remain in its parent"
        )));
    }
    Ok((size, header, kind))
}

/// Checks the boxes filling `body` (the content of `parent`).
fn children(body: &[u8], parent: &str, depth: usize) -> Result<(), Mp4Error> {
    if depth > 16 {
        return Err(malformed(format!(
            "boxes nested deeper than 16 in {parent}"
        )));
    }
    let mut at = 0usize;
    while at < body.len() {
        let room = body.len() - at;
        if room < 8 {
            return Err(malformed(format!(
                "{room} stray bytes at the end of {parent}"
            )));
        }
        let (size, header, kind) =
            box_header(&body[at..(at + 16).min(body.len())], room as u64, false)?;
        let content = &body[at + header as usize..at + size as usize];
        let name = String::from_utf8_lossy(&kind);
        // Metadata the crate also walks (udta → meta → ilst → items → data): a zero-sized
        // box there made it loop forever (found by the fuzz suite).
        if CONTAINERS.contains(&&kind) || parent == "ilst" || &kind == b"udta" || &kind == b"ilst" {
            children(content, &name, depth + 1)?;
        } else if &kind == b"meta" {
            // ISO meta is a full box (4 bytes of version and flags); QuickTime's is not.
            let full = content.len() >= 4 && content[..4] == [0, 0, 0, 0];
            children(&content[if full { 4 } else { 0 }..], &name, depth + 1)?;
        } else {
            leaf(&kind, content)?;
        }
        at += size as usize;
    }
    Ok(())
}

/// Checks a leaf box's fixed fields and table sizes (`content`: after the header).
fn leaf(kind: &[u8; 4], content: &[u8]) -> Result<(), Mp4Error> {
    let name = String::from_utf8_lossy(kind);
    let version = content.first().copied().unwrap_or(0);
    let u32_at = |i: usize| -> Option<u64> {
        content
            .get(i..i + 4)
            .map(|b| u64::from(u32::from_be_bytes(b.try_into().expect("4"))))
    };
    // (bytes of fixed fields after the header, table: (offset of the count, bytes per entry)).
    let (fixed, table): (usize, Option<(usize, u64)>) = match kind {
        b"mvhd" => (if version == 1 { 112 } else { 100 }, None),
        b"tkhd" => (if version == 1 { 96 } else { 84 }, None),
        b"mdhd" => (if version == 1 { 36 } else { 24 }, None),
        b"hdlr" => (24, None),
        b"vmhd" => (12, None),
        b"smhd" => (8, None),
        b"dref" | b"stsd" => (8, None),
        b"stts" | b"ctts" => (8, Some((4, 8))),
        b"stsc" => (8, Some((4, 12))),
        b"stco" | b"stss" => (8, Some((4, 4))),
        b"co64" => (8, Some((4, 8))),
        b"elst" => (8, Some((4, if version == 1 { 20 } else { 12 }))),
        b"stsz" => {
            let per = if u32_at(4) == Some(0) { 4 } else { 0 };
            (12, Some((8, per)))
        }
        b"sgpd" | b"sbgp" => (12, None),
        _ => (0, None),
    };
    if content.len() < fixed {
        return Err(malformed(format!(
            "{name} box has {} bytes of content, its fields need {fixed}",
            content.len()
        )));
    }
    if let Some((at, per)) = table {
        let count = u32_at(at).unwrap_or(0);
        if count * per > (content.len() - fixed) as u64 {
            return Err(malformed(format!(
                "{name} box declares {count} entries, more than its {} bytes hold",
                content.len()
            )));
        }
        if kind == b"stsc" {
            // Each entry: first chunk (1-based), samples per chunk, description index; a zero
            // samples-per-chunk made the crate divide by zero (found by the fuzz suite).
            for e in 0..count as usize {
                let at = fixed + 12 * e;
                if u32_at(at) == Some(0) || u32_at(at + 4) == Some(0) {
                    return Err(malformed(format!(
                        "stsc entry {e} has a zero first chunk or samples per chunk"
                    )));
                }
            }
        }
        if kind == b"stts" && count == 0 {
            return Err(malformed(
                "stts box has no entries (no sample timing)".into(),
            ));
        }
    }
    if kind == b"mdhd" {
        let timescale = if version == 1 { u32_at(20) } else { u32_at(12) };
        if timescale == Some(0) {
            return Err(malformed("mdhd box with a timescale of 0".into()));
        }
    }
    Ok(())
}
