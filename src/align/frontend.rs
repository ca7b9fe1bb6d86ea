//! The Sphinx MFCC front end, as `feat.params` of the en-us model asks (sphinxbase `fe` and
//! `feat`): 16 kHz, 100 frames/s, 25.625 ms Hamming windows of pre-emphasised (α = 0.97)
//! speech, a 512-point power spectrum, 25 unit-area triangular mel filters from 130 to 6800 Hz
//! (edges rounded to FFT bins), noise removal, `ln(· + 1e-4)`, the orthonormal DCT-II to 13
//! cepstra, a sinusoidal lifter of 22, batch cepstral mean normalisation, and the
//! `1s_c_d_dd` feature: c, c[t+2] − c[t−2], (c[t+3] − c[t−1]) − (c[t+1] − c[t−3]).

use std::sync::Arc;

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

/// The model's sample rate, Hz.
pub const SAMPLE_RATE: u32 = 16_000;
/// Samples between frames: 10 ms.
pub const FRAME_SHIFT: usize = 160;
/// Samples in a window: 0.025625 s × 16 000.
pub const FRAME_SIZE: usize = 410;
const FFT_SIZE: usize = 512;
const N_FILTERS: usize = 25;
const LOWER_HZ: f64 = 130.0;
const UPPER_HZ: f64 = 6800.0;
/// Cepstra per frame.
pub const N_CEP: usize = 13;
const LIFTER: f64 = 22.0;
const PRE_EMPHASIS: f32 = 0.97;
/// Added to each filter energy before the log (`LOG_FLOOR` of `fe_sigproc.c`).
const LOG_FLOOR: f64 = 1e-4;
/// Width of the feature: cepstra, deltas, double deltas.
pub const FEATURE_DIM: usize = 3 * N_CEP;

/// One triangular filter: its first FFT bin and weights.
struct Filter {
    start: usize,
    weights: Vec<f32>,
}

/// The precomputed window, filter bank, DCT and lifter, and an FFT plan.
pub struct FrontEnd {
    window: Vec<f32>,
    filters: Vec<Filter>,
    /// `[cepstrum][filter]`, orthonormal DCT-II rows with the lifter folded in.
    dct: Vec<[f64; N_FILTERS]>,
    fft: Arc<dyn Fft<f32>>,
}

impl Default for FrontEnd {
    fn default() -> Self {
        Self::new()
    }
}

fn mel(hz: f64) -> f64 {
    2595.0 * (1.0 + hz / 700.0).log10()
}

fn mel_inverse(m: f64) -> f64 {
    700.0 * (10f64.powf(m / 2595.0) - 1.0)
}

impl FrontEnd {
    /// Precomputes the window, filters, DCT and FFT plan.
    pub fn new() -> Self {
        // The symmetric Hamming window of `fe_create_hamming` (0.54 − 0.46 cos 2πi/(N−1)).
        let window = (0..FRAME_SIZE)
            .map(|i| {
                let i = i.min(FRAME_SIZE - 1 - i);
                (0.54
                    - 0.46
                        * (2.0 * std::f64::consts::PI * i as f64 / (FRAME_SIZE as f64 - 1.0)).cos())
                    as f32
            })
            .collect();
        // `fe_build_melfilters`: centres equally spaced in mel, edges rounded to DFT points,
        // unit area (peak 2 / (right − left)).
        let bin_hz = SAMPLE_RATE as f64 / FFT_SIZE as f64;
        let (mel_lo, mel_hi) = (mel(LOWER_HZ), mel(UPPER_HZ));
        let mel_bw = (mel_hi - mel_lo) / (N_FILTERS + 1) as f64;
        let filters = (0..N_FILTERS)
            .map(|i| {
                let f: [f64; 3] = std::array::from_fn(|j| {
                    let hz = mel_inverse((i + j) as f64 * mel_bw + mel_lo) as f32 as f64;
                    ((hz / bin_hz + 0.5) as i64) as f64 * bin_hz
                });
                let mut start = None;
                let mut weights = Vec::new();
                for j in 0..=FFT_SIZE / 2 {
                    let hz = j as f64 * bin_hz;
                    if hz < f[0] {
                        continue;
                    }
                    if hz > f[2] || j == FFT_SIZE / 2 {
                        break;
                    }
                    start.get_or_insert(j);
                    let lo = (hz - f[0]) / (f[1] - f[0]) * 2.0 / (f[2] - f[0]);
                    let hi = (f[2] - hz) / (f[2] - f[1]) * 2.0 / (f[2] - f[0]);
                    weights.push(lo.min(hi) as f32);
                }
                Filter {
                    start: start.unwrap_or(0),
                    weights,
                }
            })
            .collect();
        let n = N_FILTERS as f64;
        let dct = (0..N_CEP)
            .map(|i| {
                let scale = if i == 0 {
                    (1.0 / n).sqrt()
                } else {
                    (2.0 / n).sqrt()
                };
                let lifter = 1.0 + LIFTER / 2.0 * (i as f64 * std::f64::consts::PI / LIFTER).sin();
                std::array::from_fn(|j| {
                    let c = if i == 0 {
                        1.0
                    } else {
                        (std::f64::consts::PI / n * i as f64 * (j as f64 + 0.5)).cos()
                    };
                    c * scale * lifter
                })
            })
            .collect();
        FrontEnd {
            window,
            filters,
            dct,
            fft: FftPlanner::new().plan_fft_forward(FFT_SIZE),
        }
    }

    /// Number of frames for `n` samples: every full window, then the remainder as one
    /// zero-padded frame (as `fe_end_utt` does).
    pub fn frame_count(n: usize) -> usize {
        if n == 0 {
            0
        } else if n < FRAME_SIZE {
            1
        } else {
            2 + (n - FRAME_SIZE) / FRAME_SHIFT
        }
    }

    /// The 13 liftered cepstra of every frame of `samples` (16 kHz, in int16 units), the
    /// noise estimate starting from the first frame.
    pub fn cepstra(&self, samples: &[f32]) -> Vec<[f32; N_CEP]> {
        let mut energies = self.filter_energies(samples);
        let mut noise = NoiseRemoval::default();
        energies.iter_mut().for_each(|e| noise.apply(e));
        energies.iter().map(|e| self.cepstrum(e)).collect()
    }

    /// The cepstra with the noise estimate first run over the whole recording, so that it
    /// starts from the recording's own floor rather than its first frame (what pocketsphinx's
    /// phone pass sees after its word pass over the same audio).
    pub fn cepstra_warm(&self, samples: &[f32]) -> Vec<[f32; N_CEP]> {
        let mut energies = self.filter_energies(samples);
        let mut noise = NoiseRemoval::default();
        for e in &energies {
            noise.apply(&mut e.clone());
        }
        energies.iter_mut().for_each(|e| noise.apply(e));
        energies.iter().map(|e| self.cepstrum(e)).collect()
    }

    /// `ln(e + 1e-4)`, the DCT and the lifter.
    fn cepstrum(&self, energies: &[f64; N_FILTERS]) -> [f32; N_CEP] {
        let logs = energies.map(|e| (e + LOG_FLOOR).ln());
        std::array::from_fn(|i| {
            self.dct[i]
                .iter()
                .zip(&logs)
                .map(|(c, l)| c * l)
                .sum::<f64>() as f32
        })
    }

    /// The mel filter energies of every frame (before noise removal).
    fn filter_energies(&self, samples: &[f32]) -> Vec<[f64; N_FILTERS]> {
        let mut scratch = Scratch::new(self);
        (0..Self::frame_count(samples.len()))
            .map(|t| {
                let start = t * FRAME_SHIFT;
                let end = (start + FRAME_SIZE).min(samples.len());
                let prior = start.checked_sub(1).map_or(0.0, |k| samples[k]);
                self.frame_energies(&samples[start..end], prior, &mut scratch)
            })
            .collect()
    }

    /// The mel filter energies of one window (zero-padded when short), `prior` the sample
    /// before it: pre-emphasis runs over the continuous signal (`pre_emphasis_prior`).
    fn frame_energies(&self, window: &[f32], prior: f32, scratch: &mut Scratch) -> [f64; N_FILTERS] {
        let buf = &mut scratch.buf;
        buf.iter_mut().for_each(|c| *c = Complex32::new(0.0, 0.0));
        let mut before = prior;
        for (k, &x) in window.iter().enumerate() {
            buf[k].re = (x - PRE_EMPHASIS * before) * self.window[k];
            before = x;
        }
        self.fft.process_with_scratch(buf, &mut scratch.fft);
        for (p, c) in scratch.power.iter_mut().zip(buf.iter()) {
            *p = c.norm_sqr();
        }
        std::array::from_fn(|i| {
            let f = &self.filters[i];
            f.weights
                .iter()
                .zip(&scratch.power[f.start..])
                .map(|(&w, &p)| w as f64 * p as f64)
                .sum()
        })
    }
}

/// Buffers one frame's transform reuses.
struct Scratch {
    buf: Vec<Complex32>,
    fft: Vec<Complex32>,
    power: [f32; FFT_SIZE / 2 + 1],
}

impl Scratch {
    fn new(frontend: &FrontEnd) -> Self {
        Scratch {
            buf: vec![Complex32::new(0.0, 0.0); FFT_SIZE],
            fft: vec![Complex32::new(0.0, 0.0); frontend.fft.get_inplace_scratch_len()],
            power: [0.0; FFT_SIZE / 2 + 1],
        }
    }
}

/// The front end a chunk of samples at a time, for live recognition: the same windows,
/// filters and noise removal as [`FrontEnd::cepstra`] (its noise estimate starts from the
/// first frame), a running CMN ([`LiveCmn`]) instead of the batch one, and each feature out
/// as soon as the three cepstra after it exist (30 ms of look-ahead, as `1s_c_d_dd` needs).
pub struct Stream<'f> {
    frontend: &'f FrontEnd,
    scratch: Scratch,
    /// Samples not yet consumed by a full window, from the next frame's start.
    pending: Vec<f32>,
    /// The sample before `pending[0]` (0 at the start).
    prior: f32,
    /// Whether any sample arrived.
    started: bool,
    noise: NoiseRemoval,
    cmn: LiveCmn,
    /// Normalised cepstra of every frame so far (the last seven are the ones used).
    cepstra: Vec<[f32; N_CEP]>,
    /// Features given out.
    emitted: usize,
}

impl<'f> Stream<'f> {
    /// A stream with nothing in it yet.
    pub fn new(frontend: &'f FrontEnd) -> Self {
        Stream {
            frontend,
            scratch: Scratch::new(frontend),
            pending: Vec::new(),
            prior: 0.0,
            started: false,
            noise: NoiseRemoval::default(),
            cmn: LiveCmn::default(),
            cepstra: Vec::new(),
            emitted: 0,
        }
    }

    /// Takes `samples` (16 kHz, int16 units) and returns the features now complete.
    pub fn push(&mut self, samples: &[f32]) -> Vec<[f32; FEATURE_DIM]> {
        self.started |= !samples.is_empty();
        self.pending.extend_from_slice(samples);
        let mut start = 0;
        while start + FRAME_SIZE <= self.pending.len() {
            let prior = start.checked_sub(1).map_or(self.prior, |k| self.pending[k]);
            let window = &self.pending[start..start + FRAME_SIZE];
            let mut energies = self.frontend.frame_energies(window, prior, &mut self.scratch);
            self.add_frame(&mut energies);
            start += FRAME_SHIFT;
        }
        if start > 0 {
            self.prior = self.pending[start - 1];
            self.pending.drain(..start);
        }
        self.ready(false)
    }

    /// Ends the stream: the remainder as one zero-padded frame (as [`FrontEnd::frame_count`]
    /// counts it), and the last features with the final frame replicated after them.
    pub fn finish(&mut self) -> Vec<[f32; FEATURE_DIM]> {
        if self.started && !self.pending.is_empty() {
            let window = std::mem::take(&mut self.pending);
            let mut energies = self.frontend.frame_energies(&window, self.prior, &mut self.scratch);
            self.add_frame(&mut energies);
        }
        self.ready(true)
    }

    fn add_frame(&mut self, energies: &mut [f64; N_FILTERS]) {
        self.noise.apply(energies);
        let mut c = self.frontend.cepstrum(energies);
        self.cmn.normalise(&mut c);
        self.cepstra.push(c);
    }

    /// The features whose look-ahead is complete (all of them at the end).
    fn ready(&mut self, end: bool) -> Vec<[f32; FEATURE_DIM]> {
        let n = self.cepstra.len();
        let upto = if end { n } else { n.saturating_sub(3) };
        let out = (self.emitted..upto)
            .map(|t| feature(&self.cepstra, t as isize))
            .collect();
        self.emitted = upto.max(self.emitted);
        // Only the last seven cepstra are ever looked at again.
        let keep_from = self.emitted.saturating_sub(3).min(n);
        if keep_from > 64 {
            self.cepstra.drain(..keep_from);
            self.emitted -= keep_from;
        }
        out
    }
}

/// Live CMN: the running mean of the frames so far whose c0 is not negative (the frames
/// [`cmn`] averages), started from a prior mean worth [`LIVE_CMN_PRIOR_FRAMES`] frames, so
/// that the first frames of a stream are normalised before its own mean is known.
struct LiveCmn {
    sum: [f64; N_CEP],
    n: f64,
}

/// The prior mean of [`LiveCmn`]: pocketsphinx's `-cmninit` default (`40,3,-1`, the rest 0).
const LIVE_CMN_PRIOR: [f64; 3] = [40.0, 3.0, -1.0];
/// Frames the prior mean counts as.
pub const LIVE_CMN_PRIOR_FRAMES: f64 = 100.0;

impl Default for LiveCmn {
    fn default() -> Self {
        let mut sum = [0.0; N_CEP];
        for (s, &p) in sum.iter_mut().zip(&LIVE_CMN_PRIOR) {
            *s = p * LIVE_CMN_PRIOR_FRAMES;
        }
        LiveCmn {
            sum,
            n: LIVE_CMN_PRIOR_FRAMES,
        }
    }
}

impl LiveCmn {
    fn normalise(&mut self, c: &mut [f32; N_CEP]) {
        if c[0] >= 0.0 {
            self.sum.iter_mut().zip(c.iter()).for_each(|(s, &v)| *s += v as f64);
            self.n += 1.0;
        }
        for (v, s) in c.iter_mut().zip(&self.sum) {
            *v -= (s / self.n) as f32;
        }
    }
}

/// Batch CMN (`cmn.c`): the mean over frames whose c0 is not negative, subtracted from every
/// frame. `None` when no frame has c0 ≥ 0 (no signal at all).
pub fn cmn(cepstra: &mut [[f32; N_CEP]]) -> Option<[f32; N_CEP]> {
    let mut sum = [0f64; N_CEP];
    let mut n = 0usize;
    for c in cepstra.iter().filter(|c| c[0] >= 0.0) {
        sum.iter_mut().zip(c).for_each(|(s, &v)| *s += v as f64);
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let mean = sum.map(|s| (s / n as f64) as f32);
    for c in cepstra.iter_mut() {
        c.iter_mut().zip(&mean).for_each(|(v, m)| *v -= m);
    }
    Some(mean)
}

/// `1s_c_d_dd` with the first and last frame replicated three times at the edges.
pub fn features(cepstra: &[[f32; N_CEP]]) -> Vec<[f32; FEATURE_DIM]> {
    (0..cepstra.len() as isize).map(|t| feature(cepstra, t)).collect()
}

/// The `1s_c_d_dd` feature of frame `t`: cepstra, deltas over ±2 frames, double deltas.
fn feature(cepstra: &[[f32; N_CEP]], t: isize) -> [f32; FEATURE_DIM] {
    let n = cepstra.len() as isize;
    let at = |t: isize| &cepstra[t.clamp(0, n - 1) as usize];
    let mut f = [0f32; FEATURE_DIM];
    for i in 0..N_CEP {
        f[i] = at(t)[i];
        f[N_CEP + i] = at(t + 2)[i] - at(t - 2)[i];
        f[2 * N_CEP + i] = (at(t + 3)[i] - at(t - 1)[i]) - (at(t + 1)[i] - at(t - 3)[i]);
    }
    f
}

/// The noise removal of `fe_noise.c` (float build): a smoothed power, a slow lower envelope as
/// the noise estimate, the signal above it floored by its own envelope and temporal masking,
/// and a gain (limited to 1/20…20) smoothed over ±4 filters applied to the filter energies.
struct NoiseRemoval {
    started: bool,
    power: [f64; N_FILTERS],
    noise: [f64; N_FILTERS],
    floor: [f64; N_FILTERS],
    peak: [f64; N_FILTERS],
}

impl Default for NoiseRemoval {
    fn default() -> Self {
        NoiseRemoval {
            started: false,
            power: [0.0; N_FILTERS],
            noise: [0.0; N_FILTERS],
            floor: [0.0; N_FILTERS],
            peak: [0.0; N_FILTERS],
        }
    }
}

const SMOOTH_WINDOW: usize = 4;
const LAMBDA_POWER: f64 = 0.7;
const LAMBDA_A: f64 = 0.995;
const LAMBDA_B: f64 = 0.5;
const LAMBDA_T: f64 = 0.85;
const MU_T: f64 = 0.2;
const MAX_GAIN: f64 = 20.0;

fn lower_envelope(buf: &[f64; N_FILTERS], floor: &mut [f64; N_FILTERS]) {
    for (f, &b) in floor.iter_mut().zip(buf) {
        *f = if b >= *f {
            LAMBDA_A * *f + (1.0 - LAMBDA_A) * b
        } else {
            LAMBDA_B * *f + (1.0 - LAMBDA_B) * b
        };
    }
}

impl NoiseRemoval {
    fn apply(&mut self, spec: &mut [f64; N_FILTERS]) {
        if !self.started {
            self.power = *spec;
            self.noise = spec.map(|s| s / MAX_GAIN);
            self.floor = self.noise;
            self.peak = [0.0; N_FILTERS];
            self.started = true;
        }
        for (p, &s) in self.power.iter_mut().zip(spec.iter()) {
            *p = LAMBDA_POWER * *p + (1.0 - LAMBDA_POWER) * s;
        }
        lower_envelope(&self.power, &mut self.noise);
        let mut signal: [f64; N_FILTERS] =
            std::array::from_fn(|i| (self.power[i] - self.noise[i]).max(1.0));
        lower_envelope(&signal, &mut self.floor);
        // Temporal masking.
        for (s, p) in signal.iter_mut().zip(self.peak.iter_mut()) {
            let cur = *s;
            *p *= LAMBDA_T;
            if *s < LAMBDA_T * *p {
                *s = *p * MU_T;
            }
            if cur > *p {
                *p = cur;
            }
        }
        let gain: [f64; N_FILTERS] = std::array::from_fn(|i| {
            let s = signal[i].max(self.floor[i]);
            let g = if s < MAX_GAIN * self.power[i] {
                s / self.power[i]
            } else {
                MAX_GAIN
            };
            g.max(1.0 / MAX_GAIN)
        });
        for (i, v) in spec.iter_mut().enumerate() {
            let lo = i.saturating_sub(SMOOTH_WINDOW);
            let hi = (i + SMOOTH_WINDOW).min(N_FILTERS - 1);
            let mean = gain[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64;
            *v *= mean;
        }
    }
}
