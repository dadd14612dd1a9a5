//! Small dense kernels of the integrator with one fixed evaluation order.
//!
//! Every reduction has a fixed lane structure (eight lanes for dot products, lane `l` takes
//! entries `8 i + l`, lanes summed as a fixed tree, then the tail in order), products and sums
//! rounded separately (Rust never contracts to fused multiply-add). The integrator compiles its
//! whole step twice, once plain and once inside an AVX2 `#[target_feature]` function chosen at
//! run time; the vectoriser then performs exactly these operations several lanes at a time, so
//! both builds give bit-identical results on every x86-64 CPU.

/// `sum_i a_i b_i` over `min(a.len(), b.len())` entries with eight fixed lanes.
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ta, tb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ta.iter().zip(tb) {
        s += x * y;
    }
    s
}

/// `y += alpha x` over `min(x.len(), y.len())` entries.
#[inline(always)]
pub(crate) fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

/// Four-lane accumulator for fused reductions over modal vectors (lane `i % 4`, lanes summed
/// as `(l0 + l1) + (l2 + l3)`).
#[derive(Clone, Copy, Default)]
pub(crate) struct Lanes4([f64; 4]);

impl Lanes4 {
    #[inline(always)]
    pub(crate) fn add(&mut self, lane: usize, x: f64) {
        self.0[lane] += x;
    }

    #[inline(always)]
    pub(crate) fn sum(&self) -> f64 {
        (self.0[0] + self.0[1]) + (self.0[2] + self.0[3])
    }
}

/// Whether the CPU runs the AVX2 build.
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_matches_a_plain_sum_up_to_rounding() {
        for n in [0usize, 1, 7, 8, 9, 31, 150] {
            let a: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
            let b: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos()).collect();
            let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert!((dot(&a, &b) - plain).abs() <= 1e-13 * (n as f64 + 1.0));
        }
    }

    #[test]
    fn dot_has_the_documented_lane_order() {
        // Entries chosen so that another summation order changes the rounding.
        let mut a = vec![1.0; 19];
        a[0] = 1e16;
        a[8] = -1e16;
        a[12] = 3.0;
        let b = vec![1.0; 19];
        let mut acc = [0.0f64; 8];
        for chunk in 0..2 {
            for l in 0..8 {
                acc[l] += a[8 * chunk + l];
            }
        }
        let mut expected =
            ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
        for x in &a[16..] {
            expected += x;
        }
        assert_eq!(dot(&a, &b).to_bits(), expected.to_bits());
        let naive: f64 = a.iter().sum();
        assert_ne!(
            naive.to_bits(),
            expected.to_bits(),
            "test entries must be order-sensitive"
        );
    }
}
