//! The CMU Sphinx acoustic model files, read in their own binary formats: `mdef` (binary
//! BMDF: phones, triphone tree, senone sequences), `means` / `variances` /
//! `transition_matrices` (Sphinx-3 "s3" arrays with their checksum), `sendump` (8-bit
//! quantised mixture weights of a phonetically tied mixture model), `feat.params`, `noisedict`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::AlignError;

/// Gaussians per codebook that take part in a senone's score (pocketsphinx `-topn`).
pub const TOP_N: usize = 4;
/// Feature streams (`-svspec 0-12/13-25/26-38`) and their width.
pub const STREAMS: usize = 3;
/// Width of each stream.
pub const STREAM_DIM: usize = 13;
/// Emitting states per phone HMM.
pub const STATES: usize = 3;

/// `ln 1.0001 × 2^10`: the natural-log size of one unit of Sphinx's shifted 8-bit log scale
/// (log base 1.0001, `SENSCR_SHIFT` = 10), in which `sendump` stores −log mixture weights.
const SHIFTED_LOG_UNIT: f64 = 1024.0 * 0.000_099_995_000_333_308_33;

/// Word position of a phone, as the triphone tree keys it (`WORD_POSN_*` in `mdef.h`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordPosition {
    /// Inside a word.
    Internal = 0,
    /// A word's first phone.
    Begin = 1,
    /// A word's last phone.
    End = 2,
    /// A one-phone word.
    Single = 3,
}

/// A node of the triphone tree: a context value and either its children or a phone id.
#[derive(Clone, Copy, Debug)]
struct TreeNode {
    ctx: i16,
    n_down: i16,
    down_or_pid: i32,
}

/// One phone (CI or triphone) of `mdef`: its senone sequence and transition matrix.
#[derive(Clone, Copy, Debug)]
struct PhoneEntry {
    ssid: usize,
    tmat: usize,
}

/// The whole acoustic model, in natural-log units.
pub struct AcousticModel {
    /// The folder it was read from.
    pub dir: PathBuf,
    /// CI phone names in `mdef` order (`+NSN+ +SPN+ AA … ZH`, `SIL` among them).
    pub ci_names: Vec<String>,
    /// [`AcousticModel::ci`] of every one- and two-letter name ([`short_name`]; `u8::MAX`:
    /// none): the phone language model looks up each phone of 135 000 pronunciations.
    short_ci: Vec<u8>,
    ci_filler: Vec<bool>,
    /// The CI id of `SIL`.
    pub sil: usize,
    tree: Vec<TreeNode>,
    phones: Vec<PhoneEntry>,
    /// Senone ids of each senone sequence (3 per sequence).
    sseq: Vec<[u16; STATES]>,
    /// Codebook (= CI phone) of each senone.
    pub senone_codebook: Vec<u16>,
    /// Codebooks (one per CI phone).
    pub n_codebooks: usize,
    /// Gaussians per codebook and stream.
    pub n_density: usize,
    /// Per codebook, stream, dimension, density: the mean (transposed, so that one dimension of
    /// every density of a codebook is contiguous).
    pub means: Vec<f32>,
    /// Same layout: 1 / (2 σ²).
    pub inv_2var: Vec<f32>,
    /// Per codebook, stream, density: log of the Gaussian's normalising constant.
    pub log_norm: Vec<f32>,
    /// Per stream, density, senone: log mixture weight (≤ 0).
    pub log_mixw: Vec<f32>,
    /// Senones (tied states).
    pub n_senones: usize,
    /// Per transition matrix: `[from][to]` log probabilities, `to = 3` is the exit.
    pub tmats: Vec<[[f32; STATES + 1]; STATES]>,
    /// The front-end settings of `feat.params`.
    pub params: BTreeMap<String, String>,
    /// Filler words of `noisedict` and their phone (`<sil>` → SIL).
    pub fillers: BTreeMap<String, String>,
}

impl AcousticModel {
    /// Reads the seven files of `dir` and checks them against each other.
    pub fn load(dir: &Path) -> Result<Self, AlignError> {
        let read = |name: &str| -> Result<Vec<u8>, AlignError> {
            let path = dir.join(name);
            let mut file = crate::safe_read::open_regular(&path).map_err(|e| AlignError::Model {
                path: path.clone(),
                why: e.to_string(),
            })?;
            let mut bytes = Vec::new();
            std::io::Read::read_to_end(&mut file, &mut bytes).map_err(|e| AlignError::Model {
                path: path.clone(),
                why: e.to_string(),
            })?;
            Ok(bytes)
        };
        let bad = |name: &str, why: String| AlignError::Model {
            path: dir.join(name),
            why,
        };
        let params = two_columns(&String::from_utf8_lossy(&read("feat.params")?));
        for (key, want) in [
            ("-feat", "1s_c_d_dd"),
            ("-svspec", "0-12/13-25/26-38"),
            ("-model", "ptm"),
            ("-transform", "dct"),
        ] {
            match params.get(key) {
                Some(v) if v == want => {}
                other => {
                    return Err(bad(
                        "feat.params",
                        format!("{key} is {other:?}; this aligner reads `{want}` models only"),
                    ));
                }
            }
        }
        let fillers = two_columns(&String::from_utf8_lossy(&read("noisedict")?));

        let mdef = Mdef::parse(&read("mdef")?).map_err(|why| bad("mdef", why))?;
        let (means_shape, means) = read_s3(&read("means")?).map_err(|why| bad("means", why))?;
        let (var_shape, vars) =
            read_s3(&read("variances")?).map_err(|why| bad("variances", why))?;
        let (tmat_shape, tmat_raw) = read_s3(&read("transition_matrices")?)
            .map_err(|why| bad("transition_matrices", why))?;

        // means/variances: n_mgau, n_feat, n_density, veclen[n_feat].
        let gauss_shape = |shape: &[u32], name: &str| -> Result<(usize, usize), AlignError> {
            if shape.len() != 3 + STREAMS
                || shape[1] as usize != STREAMS
                || shape[3..].iter().any(|&v| v as usize != STREAM_DIM)
            {
                return Err(bad(
                    name,
                    format!("shape {shape:?}: expected codebooks × 3 streams × densities × 13"),
                ));
            }
            Ok((shape[0] as usize, shape[2] as usize))
        };
        let (n_codebooks, n_density) = gauss_shape(&means_shape, "means")?;
        if gauss_shape(&var_shape, "variances")? != (n_codebooks, n_density) {
            return Err(bad("variances", "shape differs from the means'".into()));
        }
        if n_codebooks != mdef.ci_names.len() {
            return Err(bad(
                "means",
                format!(
                    "{n_codebooks} codebooks for {} CI phones: not a PTM model",
                    mdef.ci_names.len()
                ),
            ));
        }
        let expected = n_codebooks * STREAMS * n_density * STREAM_DIM;
        if means.len() != expected || vars.len() != expected {
            return Err(bad(
                "means",
                format!("{} values, expected {expected}", means.len()),
            ));
        }
        let (t_means, t_inv, log_norm) = gaussians(&means, &vars, n_codebooks, n_density);

        if tmat_shape.len() != 3
            || tmat_shape[1] as usize != STATES
            || tmat_shape[2] as usize != STATES + 1
            || tmat_raw.len() != tmat_shape[0] as usize * STATES * (STATES + 1)
        {
            return Err(bad(
                "transition_matrices",
                format!("shape {tmat_shape:?}: expected n × 3 × 4"),
            ));
        }
        let tmats: Vec<_> = tmat_raw
            .chunks_exact(STATES * (STATES + 1))
            .map(normalise_tmat)
            .collect();
        if mdef.phones.iter().any(|p| p.tmat >= tmats.len()) {
            return Err(bad(
                "mdef",
                "a phone names a transition matrix that does not exist".into(),
            ));
        }

        let n_senones = mdef.n_senones;
        let log_mixw = read_sendump(&read("sendump")?, n_density, n_senones)
            .map_err(|why| bad("sendump", why))?;
        let mut senone_codebook = vec![u16::MAX; n_senones];
        for (pid, p) in mdef.phones.iter().enumerate() {
            let ci = mdef.base_of(pid);
            for &s in &mdef.sseq[p.ssid] {
                senone_codebook[s as usize] = ci as u16;
            }
        }
        if senone_codebook.contains(&u16::MAX) {
            return Err(bad("mdef", "a senone belongs to no phone".into()));
        }
        let mut short_ci = vec![u8::MAX; 26 * 27];
        for (i, name) in mdef.ci_names.iter().enumerate().take(usize::from(u8::MAX) - 1) {
            if let Some(k) = short_name(name.as_bytes())
                && short_ci[k] == u8::MAX
            {
                short_ci[k] = i as u8;
            }
        }
        Ok(AcousticModel {
            dir: dir.to_owned(),
            ci_names: mdef.ci_names,
            short_ci,
            ci_filler: mdef.ci_filler,
            sil: mdef.sil,
            tree: mdef.tree,
            phones: mdef.phones,
            sseq: mdef.sseq,
            senone_codebook,
            n_codebooks,
            n_density,
            means: t_means,
            inv_2var: t_inv,
            log_norm,
            log_mixw,
            n_senones,
            tmats,
            params,
            fillers,
        })
    }

    /// The CI phone id of an ARPAbet name (`AA`, `SIL`, …), in any case.
    pub fn ci(&self, name: &str) -> Option<usize> {
        // The table holds ids below `u8::MAX` only: a model with more phones searches.
        match short_name(name.as_bytes()).filter(|_| self.ci_names.len() < usize::from(u8::MAX)) {
            Some(k) => Some(self.short_ci[k]).filter(|&c| c != u8::MAX).map(usize::from),
            None => self.ci_names.iter().position(|n| n.eq_ignore_ascii_case(name)),
        }
    }

    /// Whether a CI phone is a filler (silence or noise).
    pub fn is_filler(&self, ci: usize) -> bool {
        self.ci_filler[ci]
    }

    /// Senones and transition matrix of the context-independent phone `base` (a phone loop's
    /// units, which know no neighbours).
    pub fn context_independent(&self, base: usize) -> ([u16; STATES], usize) {
        let p = self.phones[base];
        (self.sseq[p.ssid], p.tmat)
    }

    /// Senones and transition matrix of `base` between `left` and `right` at `position`, the
    /// triphone if the model has it, else the nearest one, as `bin_mdef_phone_id_nearest`
    /// backs off: other word positions, then silence for filler (or word-edge) contexts, then
    /// the CI phone. Fillers are context independent.
    pub fn triphone(
        &self,
        base: usize,
        left: usize,
        right: usize,
        position: WordPosition,
    ) -> ([u16; STATES], usize) {
        let pid = if self.ci_filler[base] {
            base
        } else {
            self.nearest(base, left, right, position)
        };
        let p = self.phones[pid];
        (self.sseq[p.ssid], self.phones[base].tmat)
    }

    fn nearest(&self, b: usize, l: usize, r: usize, pos: WordPosition) -> usize {
        use WordPosition::*;
        let all = [Internal, Begin, End, Single];
        let try_all = |l, r| {
            self.lookup(b, l, r, pos).or_else(|| {
                all.iter()
                    .filter(|&&p| p != pos)
                    .find_map(|&p| self.lookup(b, l, r, p))
            })
        };
        if let Some(p) = try_all(l, r) {
            return p;
        }
        let new_l = if self.ci_filler[l] || matches!(pos, Begin | Single) {
            self.sil
        } else {
            l
        };
        let new_r = if self.ci_filler[r] || matches!(pos, End | Single) {
            self.sil
        } else {
            r
        };
        if (new_l, new_r) != (l, r)
            && let Some(p) = try_all(new_l, new_r)
        {
            return p;
        }
        b
    }

    /// Walks the triphone tree: position, base, left, right (fillers as silence).
    fn lookup(&self, b: usize, l: usize, r: usize, pos: WordPosition) -> Option<usize> {
        let as_ctx = |c: usize| if self.ci_filler[c] { self.sil } else { c } as i16;
        let ctx = [pos as i16, b as i16, as_ctx(l), as_ctx(r)];
        let (mut start, mut count) = (0usize, 4usize);
        for (level, &want) in ctx.iter().enumerate() {
            let nodes = self.tree.get(start..start + count)?;
            let node = nodes.iter().find(|n| n.ctx == want)?;
            if node.n_down == 0 {
                return (level == 3 || node.down_or_pid >= 0)
                    .then_some(node.down_or_pid as usize)
                    .filter(|&p| p < self.phones.len());
            }
            start = node.down_or_pid as usize;
            count = node.n_down as usize;
        }
        None
    }
}

/// `key value` lines (`feat.params`' `-key value`, `noisedict`'s `word PHONE`).
fn two_columns(text: &str) -> BTreeMap<String, String> {
    text.lines()
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            Some((it.next()?.to_owned(), it.next()?.to_owned()))
        })
        .collect()
}

/// Rows normalised, non-zero entries floored at `-tmatfloor` 1e-4 and renormalised, then logs
/// (pocketsphinx `tmat_init`); a zero stays impossible.
fn normalise_tmat(raw: &[f32]) -> [[f32; STATES + 1]; STATES] {
    let mut out = [[f32::NEG_INFINITY; STATES + 1]; STATES];
    for (from, row) in raw.chunks_exact(STATES + 1).enumerate() {
        let mut p: Vec<f64> = row.iter().map(|&v| v.max(0.0) as f64).collect();
        let sum: f64 = p.iter().sum();
        if sum > 0.0 {
            p.iter_mut().for_each(|v| *v /= sum);
        }
        p.iter_mut()
            .filter(|v| **v > 0.0)
            .for_each(|v| *v = v.max(1e-4));
        let sum: f64 = p.iter().sum();
        for (to, &v) in p.iter().enumerate() {
            if v > 0.0 {
                out[from][to] = (v / sum).ln() as f32;
            }
        }
    }
    out
}

/// Transposed means, 1/(2σ²) (variances floored at `-varfloor` 1e-4) and log normalisers.
fn gaussians(
    means: &[f32],
    vars: &[f32],
    n_codebooks: usize,
    n_density: usize,
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut t_means = vec![0.0; means.len()];
    let mut t_inv = vec![0.0; means.len()];
    let mut log_norm = vec![0.0; n_codebooks * STREAMS * n_density];
    for cb in 0..n_codebooks {
        for f in 0..STREAMS {
            let block = (cb * STREAMS + f) * n_density;
            for d in 0..n_density {
                let mut norm = 0.0f64;
                for k in 0..STREAM_DIM {
                    let src = (block + d) * STREAM_DIM + k;
                    let dst = block * STREAM_DIM + k * n_density + d;
                    let var = (vars[src] as f64).max(1e-4);
                    t_means[dst] = means[src];
                    t_inv[dst] = (1.0 / (2.0 * var)) as f32;
                    norm += (1.0 / (var * 2.0 * std::f64::consts::PI).sqrt()).ln();
                }
                log_norm[block + d] = norm as f32;
            }
        }
    }
    (t_means, t_inv, log_norm)
}

/// A name of one or two ASCII letters, in any case, as an index below 26 × 27; any other
/// name `None`.
fn short_name(name: &[u8]) -> Option<usize> {
    let letter = |c: u8| c.is_ascii_alphabetic().then(|| usize::from(c.to_ascii_uppercase() - b'A'));
    match *name {
        [a] => Some(letter(a)? * 27 + 26),
        [a, b] => Some(letter(a)? * 27 + letter(b)?),
        _ => None,
    }
}

/// Little-endian reader over a byte slice that reports truncation.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| {
                format!(
                    "truncated: {n} more bytes wanted at byte {} of {}",
                    self.at,
                    self.bytes.len()
                )
            })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn count(&mut self, what: &str, max: usize) -> Result<usize, String> {
        let v = self.i32()?;
        if v < 0 || v as usize > max {
            return Err(format!("{what} = {v} is out of range (0..={max})"));
        }
        Ok(v as usize)
    }
}

/// An s3 array file: the ASCII header up to `endhdr`, the byte-order magic, the shape words,
/// the element count, the f32 data and (with `chksum0`) the checksum of every data word.
/// Returns (shape, data).
pub(crate) fn read_s3(bytes: &[u8]) -> Result<(Vec<u32>, Vec<f32>), String> {
    if !bytes.starts_with(b"s3\n") {
        return Err("not a Sphinx-3 array file (no `s3` header)".into());
    }
    let end = bytes
        .windows(7)
        .position(|w| w == b"endhdr\n")
        .ok_or("the header has no `endhdr`")?;
    let header = String::from_utf8_lossy(&bytes[3..end]);
    let checksummed = header
        .lines()
        .any(|l| l.trim_start().starts_with("chksum0"));
    let mut r = Reader { bytes, at: end + 7 };
    let magic = r.u32()?;
    if magic != 0x1122_3344 {
        return Err(format!(
            "byte-order magic {magic:#x}: only little-endian files are read"
        ));
    }
    let data_start = r.at;
    // The shape words precede the element count; read words until their product (and the
    // layout's own rule) matches the count that follows them.
    let mut words = Vec::new();
    loop {
        let w = r.u32()?;
        let product: Option<u64> = gauss_or_plain_product(&words);
        if let Some(p) = product
            && words.len() >= 3
            && p == w as u64
        {
            let n = w as usize;
            let tail = bytes.len() - r.at;
            let want = n.checked_mul(4).ok_or("element count overflows")?;
            if tail != want + if checksummed { 4 } else { 0 } {
                return Err(format!(
                    "{n} values declared but {tail} bytes follow (truncated or padded file)"
                ));
            }
            let data: Vec<f32> = r
                .take(want)?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            if checksummed {
                // Every word after the byte-order magic, shape and count included.
                let mut sum = 0u32;
                for c in bytes[data_start..r.at].chunks_exact(4) {
                    sum = sum
                        .rotate_left(20)
                        .wrapping_add(u32::from_le_bytes(c.try_into().unwrap()));
                }
                let stored = r.u32()?;
                if stored != sum {
                    return Err(format!(
                        "checksum {stored:#x} does not match the contents ({sum:#x}): damaged file"
                    ));
                }
            }
            return Ok((words, data));
        }
        words.push(w);
        if words.len() > 16 {
            return Err("no element count matches the shape words".into());
        }
    }
}

/// Product of a shape as its file layout multiplies it: gaussian files are
/// `n_mgau, n_feat, n_density, veclen[n_feat]` (product n_mgau × n_density × Σ veclen);
/// plain arrays multiply every word.
fn gauss_or_plain_product(words: &[u32]) -> Option<u64> {
    if words.len() >= 3 && words.len() == 3 + words[1] as usize {
        let veclen: u64 = words[3..].iter().map(|&v| v as u64).sum();
        return Some(words[0] as u64 * words[2] as u64 * veclen);
    }
    if words.len() == 3 {
        return Some(words.iter().map(|&v| v as u64).product());
    }
    None
}

/// `sendump`: length-prefixed title and header strings up to a zero length, the rows and
/// columns (densities × senones), then per stream per density one byte per senone:
/// −log w in shifted 8-bit units. Returns ln w per (stream, density, senone).
fn read_sendump(bytes: &[u8], n_density: usize, n_senones: usize) -> Result<Vec<f32>, String> {
    let mut r = Reader { bytes, at: 0 };
    let mut clusters = 0;
    let mut first = true;
    loop {
        let n = r.count("string length", 1000)?;
        if n == 0 {
            if first {
                return Err("empty title".into());
            }
            break;
        }
        first = false;
        let s = String::from_utf8_lossy(r.take(n)?);
        if let Some(v) = s.strip_prefix("cluster_count ") {
            clusters = v.trim_end_matches('\0').trim().parse().unwrap_or(-1);
        }
    }
    if clusters != 0 {
        return Err(format!(
            "clustered mixture weights (cluster_count {clusters}) are not read"
        ));
    }
    let rows = r.count("rows", 1 << 16)?;
    let cols = r.count("columns", 1 << 20)?;
    if rows != n_density || cols != n_senones {
        return Err(format!(
            "{rows} × {cols} weights for {n_density} densities × {n_senones} senones"
        ));
    }
    let data = r.take(STREAMS * rows * cols)?;
    if r.at != bytes.len() {
        return Err(format!("{} bytes after the weights", bytes.len() - r.at));
    }
    Ok(data
        .iter()
        .map(|&q| -(q as f64 * SHIFTED_LOG_UNIT) as f32)
        .collect())
}

/// The binary model definition (`bin_mdef.h`).
struct Mdef {
    ci_names: Vec<String>,
    ci_filler: Vec<bool>,
    sil: usize,
    n_senones: usize,
    tree: Vec<TreeNode>,
    phones: Vec<PhoneEntry>,
    /// Base phone of each triphone (from its `info.cd.ctx[0]`).
    bases: Vec<usize>,
    sseq: Vec<[u16; STATES]>,
}

impl Mdef {
    fn base_of(&self, pid: usize) -> usize {
        self.bases[pid]
    }

    fn parse(bytes: &[u8]) -> Result<Self, String> {
        let mut r = Reader { bytes, at: 0 };
        if r.take(4)? != b"BMDF" {
            return Err(
                "not a binary model definition (no BMDF marker; text mdef is not read)".into(),
            );
        }
        let version = r.i32()?;
        if version != 1 {
            return Err(format!("BMDF version {version}, expected 1"));
        }
        let header_len = r.count("header length", 1 << 16)?;
        r.take(header_len)?;
        let n_ci = r.count("n_ciphone", 255)?;
        let n_phone = r.count("n_phone", 1 << 20)?;
        let n_emit = r.count("n_emit_state", 16)?;
        if n_emit != STATES {
            return Err(format!(
                "{n_emit} emitting states per phone, expected {STATES}"
            ));
        }
        let _n_ci_sen = r.count("n_ci_sen", 1 << 16)?;
        let n_sen = r.count("n_sen", 1 << 16)?;
        let _n_tmat = r.count("n_tmat", 1 << 16)?;
        let n_sseq = r.count("n_sseq", 1 << 20)?;
        let _n_ctx = r.count("n_ctx", 16)?;
        let n_tree = r.count("n_cd_tree", 1 << 22)?;
        let _sil = r.i32()?;
        let names_start = r.at;
        let mut ci_names = Vec::with_capacity(n_ci);
        for _ in 0..n_ci {
            let rest = &bytes[r.at..];
            let len = rest
                .iter()
                .position(|&b| b == 0)
                .ok_or("unterminated phone name")?;
            ci_names.push(String::from_utf8_lossy(&rest[..len]).into_owned());
            r.at += len + 1;
        }
        let names_len = r.at - names_start;
        r.take(names_len.div_ceil(4) * 4 - names_len)?;
        let mut tree = Vec::with_capacity(n_tree);
        for _ in 0..n_tree {
            let b = r.take(8)?;
            tree.push(TreeNode {
                ctx: i16::from_le_bytes([b[0], b[1]]),
                n_down: i16::from_le_bytes([b[2], b[3]]),
                down_or_pid: i32::from_le_bytes(b[4..8].try_into().unwrap()),
            });
        }
        let mut phones = Vec::with_capacity(n_phone);
        let mut ci_filler = vec![false; n_ci];
        let mut bases = Vec::with_capacity(n_phone);
        #[allow(clippy::needless_range_loop)]
        // `pid` names the phone in errors and indexes two tables
        for pid in 0..n_phone {
            let b = r.take(12)?;
            let ssid = i32::from_le_bytes(b[0..4].try_into().unwrap());
            let tmat = i32::from_le_bytes(b[4..8].try_into().unwrap());
            if ssid < 0 || ssid as usize >= n_sseq || tmat < 0 {
                return Err(format!(
                    "phone {pid}: senone sequence {ssid} or matrix {tmat} out of range"
                ));
            }
            if pid < n_ci {
                ci_filler[pid] = b[8] != 0;
                bases.push(pid);
            } else {
                let base = b[9] as usize;
                if base >= n_ci {
                    return Err(format!("triphone {pid} has base {base} of {n_ci}"));
                }
                bases.push(base);
            }
            phones.push(PhoneEntry {
                ssid: ssid as usize,
                tmat: tmat as usize,
            });
        }
        let sseq_size = r.count("senone sequence size", 1 << 24)?;
        if sseq_size != n_sseq * STATES {
            return Err(format!(
                "{sseq_size} senone ids for {n_sseq} sequences of {STATES}"
            ));
        }
        let raw = r.take(sseq_size * 2)?;
        let mut sseq = Vec::with_capacity(n_sseq);
        for c in raw.chunks_exact(2 * STATES) {
            let mut s = [0u16; STATES];
            for (k, v) in s.iter_mut().enumerate() {
                *v = u16::from_le_bytes([c[2 * k], c[2 * k + 1]]);
                if *v as usize >= n_sen {
                    return Err(format!("senone {v} of {n_sen}"));
                }
            }
            sseq.push(s);
        }
        for n in &tree {
            if n.n_down > 0
                && (n.down_or_pid < 0 || (n.down_or_pid as usize + n.n_down as usize) > tree.len())
            {
                return Err("triphone tree points outside itself".into());
            }
        }
        let sil = ci_names
            .iter()
            .position(|n| n == "SIL")
            .ok_or("no SIL phone")?;
        Ok(Mdef {
            ci_names,
            ci_filler,
            sil,
            n_senones: n_sen,
            tree,
            phones,
            bases,
            sseq,
        })
    }
}

#[cfg(test)]
mod tests {
    /// The table of short names gives what a search of every name ignoring case gives, for
    /// every one- and two-letter name in either case, longer ones and ones not letters.
    #[test]
    fn ci_matches_a_search_of_every_name() {
        let Ok(aligner) = crate::align::Aligner::load_default(&[]) else {
            panic!("the committed acoustic model loads");
        };
        let m = &aligner.model;
        let linear = |name: &str| m.ci_names.iter().position(|n| n.eq_ignore_ascii_case(name));
        let letters: Vec<char> = ('a'..='z').chain('A'..='Z').collect();
        let mut names: Vec<String> = letters.iter().map(|c| c.to_string()).collect();
        for &a in &letters {
            for &b in &letters {
                names.push(format!("{a}{b}"));
            }
        }
        names.extend(["", "sil", "Sil", "+NSN+", "+nsn+", "ZHA", "a1", "1a", "é", "aé"].map(String::from));
        let mut found = 0;
        for name in &names {
            assert_eq!(m.ci(name), linear(name), "{name:?}");
            found += usize::from(linear(name).is_some());
        }
        assert!(found > 2 * 39, "{found} names found: the phones in both cases");
    }
}
