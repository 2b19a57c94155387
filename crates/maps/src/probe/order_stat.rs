//! A sorted multiset of numbers that answers the median and the median absolute deviation after each insertion or removal in O(√n + log² n), so iterated rejection need not sort every residual again after every rejected point.
//!
//! The values live in sorted blocks of about [`BLOCK`] (a block splits at twice that), so an
//! insertion or removal moves at most one block's values and finding the k-th value walks the
//! block lengths. The MAD is the median of `|x − m|`: the deviations of the values at or above
//! the median m, `x − m`, ascend with x, those below, `m − x`, descend with x, so the k-th
//! smallest deviation is the k-th of two sorted sequences, found by bisection.

/// Target block length.
const BLOCK: usize = 1024;

/// 1.4826 · MAD is a consistent estimator of σ for normally distributed values.
const MAD_TO_SIGMA: f64 = 1.4826;

/// The multiset (values compared by `f64::total_cmp`).
#[derive(Debug, Clone, Default)]
pub(super) struct SortedValues {
    blocks: Vec<Vec<f64>>,
    len: usize,
}

impl SortedValues {
    /// The values, sorted.
    pub(super) fn new(mut values: Vec<f64>) -> SortedValues {
        values.sort_by(f64::total_cmp);
        let len = values.len();
        SortedValues {
            blocks: values.chunks(BLOCK).map(<[f64]>::to_vec).collect(),
            len,
        }
    }

    /// Number of values.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// The block a value belongs in: the first whose last value is not below it (or the last).
    fn block_for(&self, x: f64) -> usize {
        let b = self
            .blocks
            .partition_point(|blk| blk.last().is_some_and(|l| l.total_cmp(&x).is_lt()));
        b.min(self.blocks.len().saturating_sub(1))
    }

    /// Add a value.
    pub(super) fn insert(&mut self, x: f64) {
        if self.blocks.is_empty() {
            self.blocks.push(vec![x]);
            self.len = 1;
            return;
        }
        let b = self.block_for(x);
        let blk = &mut self.blocks[b];
        let at = blk.partition_point(|v| v.total_cmp(&x).is_lt());
        blk.insert(at, x);
        if blk.len() > 2 * BLOCK {
            let tail = blk.split_off(BLOCK);
            self.blocks.insert(b + 1, tail);
        }
        self.len += 1;
    }

    /// Remove one value equal to `x` (bit for bit); false when there is none.
    pub(super) fn remove(&mut self, x: f64) -> bool {
        if self.blocks.is_empty() {
            return false;
        }
        let b = self.block_for(x);
        let blk = &mut self.blocks[b];
        let at = blk.partition_point(|v| v.total_cmp(&x).is_lt());
        if at >= blk.len() || blk[at].total_cmp(&x).is_ne() {
            return false;
        }
        blk.remove(at);
        if blk.is_empty() {
            self.blocks.remove(b);
        }
        self.len -= 1;
        true
    }

    /// 1.4826 · median(|x − median(x)|), the medians of an even count the mean of the middle
    /// two; 0 for no values.
    pub(super) fn robust_sigma(&self) -> f64 {
        let n = self.len;
        if n == 0 {
            return 0.0;
        }
        let mut starts = Vec::with_capacity(self.blocks.len());
        let mut s = 0;
        for blk in &self.blocks {
            starts.push(s);
            s += blk.len();
        }
        let get = |k: usize| {
            let b = starts.partition_point(|&s| s <= k) - 1;
            self.blocks[b][k - starts[b]]
        };
        let middle = |at: &dyn Fn(usize) -> f64| {
            if n % 2 == 1 {
                at(n / 2)
            } else {
                0.5 * (at(n / 2 - 1) + at(n / 2))
            }
        };
        let m = middle(&get);
        // Values below m: indices 0..a; at or above: a..n.
        let a = {
            let (mut lo, mut hi) = (0, n);
            while lo < hi {
                let mid = (lo + hi) / 2;
                if get(mid).total_cmp(&m).is_lt() {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        let up = |t: usize| get(a + t) - m;
        let down = |t: usize| m - get(a - 1 - t);
        let kth = |k: usize| kth_of_two(&up, n - a, &down, a, k);
        MAD_TO_SIGMA * middle(&kth)
    }
}

/// The k-th smallest (0-based) of two ascending sequences of lengths `la` and `lb`.
fn kth_of_two(
    a: &dyn Fn(usize) -> f64,
    la: usize,
    b: &dyn Fn(usize) -> f64,
    lb: usize,
    k: usize,
) -> f64 {
    // i values from a and j = k + 1 − i from b are the k + 1 smallest when
    // a[i − 1] ≤ b[j] and b[j − 1] ≤ a[i].
    let (mut lo, mut hi) = ((k + 1).saturating_sub(lb), (k + 1).min(la));
    loop {
        let i = (lo + hi) / 2;
        let j = k + 1 - i;
        if i < hi && j > 0 && b(j - 1).total_cmp(&a(i)).is_gt() {
            lo = i + 1;
        } else if i > lo && j < lb && a(i - 1).total_cmp(&b(j)).is_gt() {
            hi = i - 1;
        } else {
            let from_a = (i > 0).then(|| a(i - 1));
            let from_b = (j > 0).then(|| b(j - 1));
            return match (from_a, from_b) {
                (Some(x), Some(y)) => x.max(y),
                (Some(x), None) | (None, Some(x)) => x,
                (None, None) => f64::NAN,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition, by sorting: 1.4826 · median(|x − median(x)|).
    fn by_sorting(values: &[f64]) -> f64 {
        fn median(v: &mut [f64]) -> f64 {
            v.sort_by(f64::total_cmp);
            let n = v.len();
            if n % 2 == 1 {
                v[n / 2]
            } else {
                0.5 * (v[n / 2 - 1] + v[n / 2])
            }
        }
        if values.is_empty() {
            return 0.0;
        }
        let m = median(&mut values.to_vec());
        let mut d: Vec<f64> = values.iter().map(|x| (x - m).abs()).collect();
        1.4826 * median(&mut d)
    }

    #[test]
    fn robust_sigma_equals_the_sorting_definition_through_inserts_and_removals() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [1usize, 2, 3, 4, 5, 10, 101, 2500, 5000] {
            let mut values: Vec<f64> = (0..n)
                .map(|_| {
                    let x: f64 = rng.random_range(-3.0..3.0);
                    // Ties and a few far outliers.
                    if rng.random_bool(0.1) {
                        (x * 2.0).round()
                    } else if rng.random_bool(0.02) {
                        x * 100.0
                    } else {
                        x
                    }
                })
                .collect();
            let mut set = SortedValues::new(values.clone());
            assert_eq!(
                set.robust_sigma().to_bits(),
                by_sorting(&values).to_bits(),
                "n {n}"
            );
            for step in 0..300 {
                if !values.is_empty() && rng.random_bool(0.5) {
                    let k = rng.random_range(0..values.len());
                    let x = values.swap_remove(k);
                    assert!(set.remove(x));
                } else {
                    let x = rng.random_range(-5.0..5.0);
                    values.push(x);
                    set.insert(x);
                }
                assert_eq!(set.len(), values.len());
                assert_eq!(
                    set.robust_sigma().to_bits(),
                    by_sorting(&values).to_bits(),
                    "n {n}, step {step}"
                );
            }
        }
        let mut empty = SortedValues::new(Vec::new());
        assert_eq!(empty.robust_sigma(), 0.0);
        assert!(!empty.remove(1.0));
        empty.insert(2.0);
        assert_eq!(empty.robust_sigma(), 0.0);
    }
}
