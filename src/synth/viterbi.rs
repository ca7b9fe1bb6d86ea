//! The minimum-cost path through a lattice (Viterbi 1967): one candidate list per step, a cost
//! per candidate and a cost per transition between candidates of consecutive steps. Unit
//! selection minimises its path cost with it directly; the dynamic-phoneme graph maximises a
//! product of probabilities, i.e. minimises the sum of their negative logarithms.

/// The cheapest path: the chosen candidate index at every step and the total cost. Ties go to
/// the earlier candidate. `None` when a step has no candidates or every path costs ∞.
///
/// Costs `O(Σ_i |C_{i−1}|·|C_i|)` transition evaluations and `O(Σ_i |C_i|)` memory.
pub fn cheapest_path(
    sizes: &[usize],
    mut unary: impl FnMut(usize, usize) -> f64,
    mut transition: impl FnMut(usize, usize, usize) -> f64,
) -> Option<(Vec<usize>, f64)> {
    if sizes.is_empty() || sizes.contains(&0) {
        return None;
    }
    let mut cost: Vec<f64> = (0..sizes[0]).map(|c| unary(0, c)).collect();
    let mut back: Vec<Vec<u32>> = Vec::with_capacity(sizes.len());
    back.push(Vec::new());
    for (step, &size) in sizes.iter().enumerate().skip(1) {
        let mut next = Vec::with_capacity(size);
        let mut from = Vec::with_capacity(size);
        for c in 0..size {
            let (mut best, mut arg) = (f64::INFINITY, 0u32);
            for (p, &pc) in cost.iter().enumerate() {
                if pc == f64::INFINITY {
                    continue;
                }
                let total = pc + transition(step, p, c);
                if total < best {
                    (best, arg) = (total, p as u32);
                }
            }
            next.push(best + unary(step, c));
            from.push(arg);
        }
        cost = next;
        back.push(from);
    }
    let (mut last, total) = cost.iter().enumerate().fold(
        (0, f64::INFINITY),
        |(bi, bc), (i, &c)| {
            if c < bc { (i, c) } else { (bi, bc) }
        },
    );
    if !total.is_finite() {
        return None;
    }
    let mut path = vec![0; sizes.len()];
    for step in (0..sizes.len()).rev() {
        path[step] = last;
        if step > 0 {
            last = back[step][last] as usize;
        }
    }
    Some((path, total))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Every path, enumerated: the reference the dynamic programme must agree with.
    fn brute_force(sizes: &[usize], unary: &[Vec<f64>], transition: &[Vec<Vec<f64>>]) -> f64 {
        let mut best = f64::INFINITY;
        let mut path = vec![0; sizes.len()];
        loop {
            let mut cost = unary[0][path[0]];
            for s in 1..sizes.len() {
                cost += transition[s][path[s - 1]][path[s]] + unary[s][path[s]];
            }
            best = best.min(cost);
            // Next path, odometer order.
            let mut s = 0;
            loop {
                if s == sizes.len() {
                    return best;
                }
                path[s] += 1;
                if path[s] < sizes[s] {
                    break;
                }
                path[s] = 0;
                s += 1;
            }
        }
    }

    proptest! {
        #[test]
        fn finds_the_minimum_of_every_path(
            sizes in prop::collection::vec(1usize..5, 1..6),
            seed in any::<u64>(),
        ) {
            let mut rng = crate::rng::Rng::new(seed);
            let unary: Vec<Vec<f64>> = sizes
                .iter()
                .map(|&n| (0..n).map(|_| rng.range(0.0, 10.0)).collect())
                .collect();
            let transition: Vec<Vec<Vec<f64>>> = (0..sizes.len())
                .map(|s| {
                    let prev = if s == 0 { 1 } else { sizes[s - 1] };
                    (0..prev)
                        .map(|_| (0..sizes[s]).map(|_| rng.range(0.0, 10.0)).collect())
                        .collect()
                })
                .collect();
            let (path, cost) = cheapest_path(
                &sizes,
                |s, c| unary[s][c],
                |s, p, c| transition[s][p][c],
            )
            .unwrap();
            let want = brute_force(&sizes, &unary, &transition);
            prop_assert!((cost - want).abs() < 1e-9, "{cost} vs {want}");
            // The path's own cost is the reported one.
            let mut again = unary[0][path[0]];
            for s in 1..sizes.len() {
                again += transition[s][path[s - 1]][path[s]] + unary[s][path[s]];
            }
            prop_assert!((again - cost).abs() < 1e-9);
        }
    }

    #[test]
    fn empty_steps_and_impossible_paths() {
        assert!(cheapest_path(&[], |_, _| 0.0, |_, _, _| 0.0).is_none());
        assert!(cheapest_path(&[2, 0, 2], |_, _| 0.0, |_, _, _| 0.0).is_none());
        assert!(cheapest_path(&[2, 2], |_, _| 0.0, |_, _, _| f64::INFINITY).is_none());
    }
}
