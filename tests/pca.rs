//! PCA against analytic references: data of known rank, snapshot vs covariance method.
use crate::common;

use common::Rng;
use facespace::pca::{Components, PcaError, PcaModel};

/// `n` samples of `mean + Σ_k w_k e_k` with `rank` orthogonal directions of known spread.
fn low_rank_data(n: usize, d: usize, rank: usize, seed: u64) -> (Vec<Vec<f32>>, Vec<Vec<f64>>) {
    let mut rng = Rng::new(seed);
    // Orthonormal directions by Gram–Schmidt.
    let mut dirs: Vec<Vec<f64>> = Vec::new();
    while dirs.len() < rank {
        let mut v: Vec<f64> = (0..d).map(|_| rng.normal()).collect();
        for u in &dirs {
            let p: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(u).for_each(|(a, b)| *a -= p * b);
        }
        let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        dirs.push(v.into_iter().map(|a| a / norm).collect());
    }
    let mean: Vec<f64> = (0..d).map(|_| rng.range(0.0, 100.0)).collect();
    let data = (0..n)
        .map(|_| {
            let w: Vec<f64> = (0..rank)
                .map(|k| rng.normal() * 10.0 / (k + 1) as f64)
                .collect();
            (0..d)
                .map(|j| (mean[j] + (0..rank).map(|k| w[k] * dirs[k][j]).sum::<f64>()) as f32)
                .collect()
        })
        .collect();
    (data, dirs)
}

fn check_recovers_rank(n: usize, d: usize, rank: usize) {
    let (data, dirs) = low_rank_data(n, d, rank, 3 + d as u64);
    let rows: Vec<&[f32]> = data.iter().map(|r| r.as_slice()).collect();
    let model = PcaModel::fit(
        &rows,
        Components::Variance {
            fraction: 1.0,
            max: None,
        },
    )
    .unwrap();
    assert_eq!(model.n_components(), rank, "n={n} d={d}");
    assert!((model.variance_ratio() - 1.0).abs() < 1e-5);
    assert!(
        model.variances.windows(2).all(|w| w[0] >= w[1]),
        "variances sorted descending"
    );
    // Components are orthonormal and span the true subspace.
    for a in 0..rank {
        for b in 0..rank {
            let dot: f64 = model
                .component(a)
                .iter()
                .zip(model.component(b))
                .map(|(x, y)| *x as f64 * *y as f64)
                .sum();
            assert!(
                (dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-5,
                "components {a},{b}: {dot}"
            );
        }
        let in_span: f64 = dirs
            .iter()
            .map(|u| {
                u.iter()
                    .zip(model.component(a))
                    .map(|(x, y)| x * *y as f64)
                    .sum::<f64>()
                    .powi(2)
            })
            .sum();
        assert!(
            (in_span - 1.0).abs() < 1e-4,
            "component {a} leaves the subspace: {in_span}"
        );
    }
    // Every sample is reconstructed from its projection.
    for r in &data {
        let back = model.reconstruct(&model.project(r));
        let err = back
            .iter()
            .zip(r)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(err < 1e-3, "reconstruction error {err}");
    }
}

#[test]
fn snapshot_method_recovers_known_rank() {
    check_recovers_rank(12, 500, 4); // n < d: Gram matrix
    // Samples longer than the Gram matrix's column blocks (2048), not a multiple of them.
    check_recovers_rank(9, 2_100, 3);
}

/// Full-rank data spanning several column blocks: every kept component is a unit
/// eigenvector of the scatter matrix with its variance (`‖X_c v‖² / (n − 1) = λ`,
/// `X_cᵀ X_c v = (n − 1) λ v`), components orthogonal, all variances summing to the total.
#[test]
fn snapshot_components_are_eigenvectors_across_blocks() {
    let (n, d) = (8, 4_500);
    let mut rng = Rng::new(15);
    let data: Vec<Vec<f32>> = (0..n)
        .map(|_| (0..d).map(|_| rng.range(0.0, 255.0) as f32).collect())
        .collect();
    let rows: Vec<&[f32]> = data.iter().map(|r| r.as_slice()).collect();
    let pca = PcaModel::fit(&rows, Components::Count(n)).unwrap();
    assert_eq!(pca.n_components(), n - 1);
    let centred: Vec<Vec<f64>> = data
        .iter()
        .map(|r| {
            r.iter()
                .zip(&pca.mean)
                .map(|(&x, &m)| f64::from(x) - f64::from(m))
                .collect()
        })
        .collect();
    let dof = (n - 1) as f64;
    for k in 0..pca.n_components() {
        let v: Vec<f64> = pca.component(k).iter().map(|&x| f64::from(x)).collect();
        let xv: Vec<f64> = centred
            .iter()
            .map(|r| r.iter().zip(&v).map(|(a, b)| a * b).sum())
            .collect();
        let lambda = f64::from(pca.variances[k]);
        let var = xv.iter().map(|a| a * a).sum::<f64>() / dof;
        assert!(
            (var - lambda).abs() < 1e-4 * lambda,
            "component {k}: {var} vs {lambda}"
        );
        // X_cᵀ (X_c v) − (n − 1) λ v, relative to (n − 1) λ.
        let mut residual = 0f64;
        for j in 0..d {
            let xtxv: f64 = centred.iter().zip(&xv).map(|(r, a)| r[j] * a).sum();
            residual = residual.max((xtxv - dof * lambda * v[j]).abs());
        }
        assert!(
            residual < 1e-3 * dof * lambda,
            "component {k}: residual {residual}"
        );
        for l in 0..k {
            let c: f64 = pca
                .component(l)
                .iter()
                .zip(&v)
                .map(|(&a, b)| f64::from(a) * b)
                .sum();
            assert!(c.abs() < 1e-4, "components {l} and {k}: cos {c}");
        }
    }
    let sum: f64 = pca.variances.iter().map(|&l| f64::from(l)).sum();
    assert!((sum - pca.total_variance).abs() < 1e-4 * pca.total_variance);
}

#[test]
fn covariance_method_recovers_known_rank() {
    check_recovers_rank(200, 10, 3); // n > d: covariance matrix
}

#[test]
fn truncation_by_fraction_count_and_cap() {
    let (data, _) = low_rank_data(40, 30, 6, 5);
    let rows: Vec<&[f32]> = data.iter().map(|r| r.as_slice()).collect();
    let all = PcaModel::fit(&rows, Components::Count(30)).unwrap();
    assert_eq!(
        all.n_components(),
        6,
        "a count beyond the rank is capped at the rank"
    );
    let total: f64 = all.variances.iter().map(|&v| v as f64).sum();
    let frac = (all.variances[0] as f64 + all.variances[1] as f64) / total;
    let two = PcaModel::fit(
        &rows,
        Components::Variance {
            fraction: frac - 1e-6,
            max: None,
        },
    )
    .unwrap();
    assert_eq!(two.n_components(), 2);
    let three = PcaModel::fit(
        &rows,
        Components::Variance {
            fraction: frac + 1e-4,
            max: None,
        },
    )
    .unwrap();
    assert_eq!(three.n_components(), 3);
    let capped = PcaModel::fit(
        &rows,
        Components::Variance {
            fraction: 1.0,
            max: Some(4),
        },
    )
    .unwrap();
    assert_eq!(capped.n_components(), 4);
    assert_eq!(
        PcaModel::fit(&rows, Components::Count(2))
            .unwrap()
            .n_components(),
        2
    );
}

#[test]
fn bad_input_is_a_typed_error() {
    let a = [1.0f32, 2.0, 3.0];
    let b = [1.0f32, 2.0];
    let nan = [1.0f32, f32::NAN, 3.0];
    assert!(matches!(
        PcaModel::fit(&[&a], Components::Count(1)),
        Err(PcaError::TooFewSamples(1))
    ));
    assert!(matches!(
        PcaModel::fit(&[&a, &b], Components::Count(1)),
        Err(PcaError::Ragged { index: 1, .. })
    ));
    assert!(matches!(
        PcaModel::fit(&[&a, &nan], Components::Count(1)),
        Err(PcaError::NotFinite {
            index: 1,
            position: 1
        })
    ));
    assert!(matches!(
        PcaModel::fit(&[&a, &a], Components::Count(1)),
        Err(PcaError::NoVariance)
    ));
    let bad = Components::Variance {
        fraction: 1.5,
        max: None,
    };
    assert!(matches!(
        PcaModel::fit(&[&a, &nan], bad),
        Err(PcaError::BadComponents(_))
    ));
    assert!(matches!(
        PcaModel::fit(&[&a, &b], Components::Count(0)),
        Err(PcaError::BadComponents(_))
    ));
}

/// Weighted projection (issue 33's anchoring) against references: equal weights give the
/// plain projection; a sample in the span is recovered whatever the weights; off the span,
/// the solution makes the weighted residual orthogonal to every component (the normal
/// equations), and weighting some values more fits them closer. Weights that are negative or
/// leave too few values are refused.
#[test]
fn weighted_projection_solves_the_normal_equations() {
    let (data, _) = low_rank_data(40, 12, 3, 21);
    let rows: Vec<&[f32]> = data.iter().map(|r| r.as_slice()).collect();
    let model = PcaModel::fit(&rows, Components::Count(3)).unwrap();
    let uniform = model.weighted(&[2.0; 12]).unwrap();
    let x = &data[5];
    let plain = model.project(x);
    let w = uniform.project(&model, x);
    assert!(plain.iter().zip(&w).all(|(a, b)| (a - b).abs() < 1e-3), "{plain:?} {w:?}");

    let weights: Vec<f64> = (0..12).map(|i| if i < 4 { 10.0 } else { 0.5 }).collect();
    let skewed = model.weighted(&weights).unwrap();
    let inside = model.reconstruct(&[3.0, -2.0, 1.0]);
    let b = skewed.project(&model, &inside);
    assert!(b.iter().zip([3.0, -2.0, 1.0]).all(|(a, e)| (a - e).abs() < 1e-3), "{b:?}");

    let mut rng = Rng::new(9);
    let off: Vec<f32> = x.iter().map(|v| v + rng.normal() as f32 * 5.0).collect();
    let b = skewed.project(&model, &off);
    let fit = model.reconstruct(&b);
    for k in 0..3 {
        let g: f64 = (0..12)
            .map(|i| weights[i] * f64::from(off[i] - fit[i]) * f64::from(model.component(k)[i]))
            .sum();
        assert!(g.abs() < 1e-2, "component {k}: {g}");
    }
    let err = |fit: &[f32]| -> f64 { (0..4).map(|i| f64::from(off[i] - fit[i]).powi(2)).sum() };
    let plain_fit = model.reconstruct(&model.project(&off));
    assert!(err(&fit) < err(&plain_fit), "{} vs {}", err(&fit), err(&plain_fit));

    let mut bad = vec![1.0; 12];
    bad[3] = -1.0;
    assert!(model.weighted(&bad).is_none());
    assert!(model.weighted(&[1.0; 5]).is_none());
    assert!(model.weighted(&[0.0; 12]).is_none());
}
