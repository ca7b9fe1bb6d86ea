//! The statistics of a subjective study, as \[blend\] §6 and \[unitsel\] report them and as
//! scipy computes them (checked against `tests/reference/stats_scipy.py`): the Wilcoxon
//! signed-rank test of paired scores, the Kruskal–Wallis H test across conditions, and the
//! exact binomial test of a correct-identification rate with its Clopper–Pearson interval.

use serde::Serialize;

/// A Wilcoxon signed-rank test of paired differences `a − b`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Wilcoxon {
    /// Pairs given.
    pub n: usize,
    /// Pairs with a non-zero difference (zeros are dropped: Wilcoxon's own rule).
    pub nonzero: usize,
    /// W = min(W+, W−), the statistic scipy reports for a two-sided test.
    pub w: f64,
    /// Sum of the ranks of the positive differences.
    pub w_plus: f64,
    /// The normal deviate −|W+ − μ| / σ with the tie correction (0 when nothing is left).
    pub z: f64,
    /// Two-sided p-value.
    pub p: f64,
    /// How p was found: "exact", "permutation" or "normal".
    pub method: &'static str,
}

/// Largest sample for which the exact null distribution is used (scipy's `method='auto'`).
const EXACT_MAX: usize = 50;
/// Largest sample with ties or zeros for which every sign flip is enumerated (2^13 < 9999,
/// scipy's default number of resamples, so its permutation test is exact there).
const PERMUTATION_MAX: usize = 13;

/// The Wilcoxon signed-rank test of `a − b`, two-sided, zeros dropped, no continuity
/// correction — scipy's `wilcoxon(a, b)` defaults, including its choice of method: the exact
/// null distribution for n ≤ 50 without ties or zeros; all 2^n sign flips for n ≤ 13 with
/// them; else the normal approximation with the tie correction σ² = n(n+1)(2n+1)/24 −
/// Σ(t³−t)/48. `None` when the lengths differ or nothing is given.
pub fn wilcoxon(a: &[f64], b: &[f64]) -> Option<Wilcoxon> {
    if a.len() != b.len() || a.is_empty() {
        return None;
    }
    let n = a.len();
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let nonzero: Vec<f64> = d.iter().copied().filter(|&x| x != 0.0).collect();
    let m = nonzero.len();
    let magnitudes: Vec<f64> = nonzero.iter().map(|x| x.abs()).collect();
    let (ranks, ties) = average_ranks(&magnitudes);
    let w_plus: f64 = nonzero
        .iter()
        .zip(&ranks)
        .filter(|(x, _)| **x > 0.0)
        .map(|(_, r)| r)
        .sum::<f64>()
        + 0.0; // an empty sum is −0.0
    let total = (m * (m + 1)) as f64 / 2.0;
    let w_minus = total - w_plus;
    let mf = m as f64;
    let mean = mf * (mf + 1.0) / 4.0;
    let tie_sum: f64 = ties.iter().map(|&t| t.powi(3) - t).sum();
    let sd = ((mf * (mf + 1.0) * (2.0 * mf + 1.0) - tie_sum / 2.0) / 24.0).sqrt();
    let z = if sd > 0.0 {
        -((w_plus - mean) / sd).abs()
    } else {
        0.0
    };
    let has_ties = ties.iter().any(|&t| t > 1.0);
    let zeros = n - m;
    let (p, method) = if n <= EXACT_MAX && !has_ties && zeros == 0 {
        let dist = signed_rank_counts(m);
        let all: f64 = dist.iter().sum();
        let cdf = |k: usize| dist[..=k.min(dist.len() - 1)].iter().sum::<f64>() / all;
        let sf = |k: usize| dist[k.min(dist.len())..].iter().sum::<f64>() / all;
        let p = 2.0 * sf(w_plus.floor() as usize).min(cdf(w_plus.ceil() as usize));
        (p.min(1.0), "exact")
    } else if n <= PERMUTATION_MAX {
        (sign_flip_p(&ranks, w_plus), "permutation")
    } else {
        (2.0 * normal_sf(-z), "normal")
    };
    Some(Wilcoxon {
        n,
        nonzero: m,
        w: w_plus.min(w_minus),
        w_plus,
        z,
        p: p.min(1.0),
        method,
    })
}

/// Ways each rank sum k = 0 … n(n+1)/2 arises from the 2^n sign choices of ranks 1 … n (exact
/// in f64 up to n = 50: every count is below 2^50).
fn signed_rank_counts(n: usize) -> Vec<f64> {
    let max = n * (n + 1) / 2;
    let mut counts = vec![0.0; max + 1];
    counts[0] = 1.0;
    for r in 1..=n {
        for k in (r..=max).rev() {
            counts[k] += counts[k - r];
        }
    }
    counts
}

/// Two-sided p of W+ over every sign flip of the (tied) ranks: 2 min(P(T ≤ w), P(T ≥ w)),
/// with scipy's relative tolerance of 100 ε for equal sums.
fn sign_flip_p(ranks: &[f64], w_plus: f64) -> f64 {
    let m = ranks.len();
    let gamma = (100.0 * f64::EPSILON * w_plus).abs();
    let (mut less, mut greater) = (0u64, 0u64);
    for mask in 0u64..(1 << m) {
        let s: f64 = (0..m)
            .filter(|i| mask >> i & 1 == 1)
            .map(|i| ranks[i])
            .sum();
        less += u64::from(s <= w_plus + gamma);
        greater += u64::from(s >= w_plus - gamma);
    }
    let all = (1u64 << m) as f64;
    (2.0 * (less.min(greater) as f64) / all).min(1.0)
}

/// 1-based ranks with ties given their average rank, and the size of each tie group.
pub fn average_ranks(values: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
    let mut ranks = vec![0.0; values.len()];
    let mut groups = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && values[order[end]] == values[order[start]] {
            end += 1;
        }
        let rank = (start + end + 1) as f64 / 2.0;
        for &i in &order[start..end] {
            ranks[i] = rank;
        }
        groups.push((end - start) as f64);
        start = end;
    }
    (ranks, groups)
}

/// A Kruskal–Wallis H test across groups.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KruskalWallis {
    /// H, corrected for ties (scipy's `kruskal` statistic).
    pub h: f64,
    /// Degrees of freedom: groups − 1.
    pub df: usize,
    /// p from χ² with `df` degrees of freedom.
    pub p: f64,
    /// Per group: its size, mean rank and z = (R̄ᵢ − R̄) / √(N(N+1)/12 · (1/nᵢ − 1/N)), the
    /// deviate Minitab and the papers' tables print beside the mean rank.
    pub groups: Vec<GroupRank>,
}

/// One group's place in the pooled ranking.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GroupRank {
    /// Observations.
    pub n: usize,
    /// Mean rank among all observations.
    pub mean_rank: f64,
    /// Its standardised deviation from the overall mean rank.
    pub z: f64,
}

/// The Kruskal–Wallis test: H = [12 / (N(N+1)) Σ Rᵢ²/nᵢ − 3(N+1)] / (1 − Σ(t³−t)/(N³−N)).
/// `None` with fewer than two non-empty groups or when every value is equal.
pub fn kruskal(groups: &[Vec<f64>]) -> Option<KruskalWallis> {
    if groups.len() < 2 || groups.iter().any(Vec::is_empty) {
        return None;
    }
    let all: Vec<f64> = groups.concat();
    let nf = all.len() as f64;
    let (ranks, ties) = average_ranks(&all);
    let correction = 1.0 - ties.iter().map(|&t| t.powi(3) - t).sum::<f64>() / (nf.powi(3) - nf);
    if correction <= 0.0 {
        return None;
    }
    let mut start = 0;
    let mut sum = 0.0;
    let mut out = Vec::with_capacity(groups.len());
    for g in groups {
        let r: f64 = ranks[start..start + g.len()].iter().sum();
        start += g.len();
        let ni = g.len() as f64;
        sum += r * r / ni;
        let mean_rank = r / ni;
        let spread = (nf * (nf + 1.0) / 12.0 * (1.0 / ni - 1.0 / nf)).sqrt();
        let z = if spread > 0.0 {
            (mean_rank - (nf + 1.0) / 2.0) / spread
        } else {
            0.0
        };
        out.push(GroupRank {
            n: g.len(),
            mean_rank,
            z,
        });
    }
    let h = (12.0 / (nf * (nf + 1.0)) * sum - 3.0 * (nf + 1.0)) / correction;
    let df = groups.len() - 1;
    Some(KruskalWallis {
        h,
        df,
        p: chi2_sf(h.max(0.0), df as f64),
        groups: out,
    })
}

/// An exact binomial test of a rate against ½, with its 95 % interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Binomial {
    /// Successes.
    pub k: usize,
    /// Trials.
    pub n: usize,
    /// k / n.
    pub rate: f64,
    /// Two-sided p of H₀: rate = ½ (scipy's `binomtest`: the outcomes no likelier than k).
    pub p: f64,
    /// Clopper–Pearson 95 % interval, low end.
    pub low: f64,
    /// Clopper–Pearson 95 % interval, high end.
    pub high: f64,
}

/// The binomial test of k successes in n trials against ½ (`None` for n = 0 or k > n).
pub fn binomial(k: usize, n: usize) -> Option<Binomial> {
    if n == 0 || k > n {
        return None;
    }
    let pmf = binomial_pmf(n, 0.5);
    let threshold = pmf[k] * (1.0 + 1e-7);
    let p = pmf
        .iter()
        .filter(|&&q| q <= threshold)
        .sum::<f64>()
        .min(1.0);
    let alpha = 0.025;
    // P(X ≥ k | q) rises with q; P(X ≤ k | q) falls with it.
    let low = if k == 0 {
        0.0
    } else {
        bisect(|q| binomial_pmf(n, q)[k..].iter().sum::<f64>() - alpha)
    };
    let high = if k == n {
        1.0
    } else {
        bisect(|q| alpha - binomial_pmf(n, q)[..=k].iter().sum::<f64>())
    };
    Some(Binomial {
        k,
        n,
        rate: k as f64 / n as f64,
        p,
        low,
        high,
    })
}

/// P(X = i) for i = 0 … n, X ~ Binomial(n, q), through logarithms (no overflow for large n).
fn binomial_pmf(n: usize, q: f64) -> Vec<f64> {
    let (lq, lr) = (q.ln(), (1.0 - q).ln());
    let mut log_choose = 0.0;
    (0..=n)
        .map(|i| {
            if i > 0 {
                log_choose += ((n - i + 1) as f64 / i as f64).ln();
            }
            let term = |count: usize, l: f64| if count == 0 { 0.0 } else { count as f64 * l };
            (log_choose + term(i, lq) + term(n - i, lr)).exp()
        })
        .collect()
}

/// The root in (0, 1) of an increasing function, to machine precision.
fn bisect(f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// P(Z > z) for a standard normal: erfc(z/√2)/2, erfc through the incomplete gamma function.
pub fn normal_sf(z: f64) -> f64 {
    let q = gamma_q(0.5, z * z / 2.0);
    if z >= 0.0 { q / 2.0 } else { 1.0 - q / 2.0 }
}

/// P(χ²_df > x) = Q(df/2, x/2).
pub fn chi2_sf(x: f64, df: f64) -> f64 {
    gamma_q(df / 2.0, x / 2.0)
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, nine terms: relative error below 1e-15).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x)Γ(1−x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularised upper incomplete gamma function Q(a, x): the power series of P for
/// x < a + 1, else Lentz's continued fraction (Numerical Recipes §6.2).
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let log_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-17 {
                break;
            }
        }
        1.0 - sum * log_front.exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let step = d * c;
            h *= step;
            if (step - 1.0).abs() < 1e-16 {
                break;
            }
        }
        log_front.exp() * h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_functions_match_closed_forms() {
        // Γ(n) = (n−1)!, Γ(½) = √π.
        assert!((ln_gamma(6.0) - 120f64.ln()).abs() < 1e-13);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-13);
        // χ² with 2 df: P(X > x) = e^{−x/2}; the normal tail at 1.959964 is 0.025.
        for x in [0.1, 1.0, 5.0, 40.0] {
            assert!((chi2_sf(x, 2.0) - (-x / 2.0f64).exp()).abs() < 1e-14);
        }
        assert!((normal_sf(1.959_963_984_540_054) - 0.025).abs() < 1e-13);
        assert!((normal_sf(-1.0) + normal_sf(1.0) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn signed_rank_counts_sum_to_two_to_the_n() {
        for n in [1, 5, 20, 50] {
            let c = signed_rank_counts(n);
            assert_eq!(c.iter().sum::<f64>(), 2f64.powi(n as i32));
            assert_eq!(c.len(), n * (n + 1) / 2 + 1);
        }
    }
}
