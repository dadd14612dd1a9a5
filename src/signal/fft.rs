//! Complex FFTs for the band spectra and the wavelet transform: a plan of one size around
//! `rustfft` (any length; the callers pad to powers of two, which rustfft serves with its
//! fastest kernels) on `num_complex` values, as rustfft re-exports them.

use std::sync::Arc;

/// A complex number (`num_complex::Complex<f64>`).
pub(crate) type Complex = rustfft::num_complex::Complex<f64>;

/// 0 + 0i.
pub(crate) const ZERO: Complex = Complex::new(0.0, 0.0);

/// FFT plan for one size, with its scratch space (so transforms do not allocate).
pub(crate) struct Fft {
    n: usize,
    forward: Arc<dyn rustfft::Fft<f64>>,
    inverse: Arc<dyn rustfft::Fft<f64>>,
    scratch: Vec<Complex>,
}

impl std::fmt::Debug for Fft {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fft").field("n", &self.n).finish()
    }
}

impl Fft {
    /// Plan for size `n` (>= 1).
    pub fn new(n: usize) -> Self {
        let mut planner = rustfft::FftPlanner::new();
        let forward = planner.plan_fft_forward(n);
        let inverse = planner.plan_fft_inverse(n);
        let len = forward
            .get_inplace_scratch_len()
            .max(inverse.get_inplace_scratch_len());
        Fft {
            n,
            forward,
            inverse,
            scratch: vec![ZERO; len],
        }
    }

    /// `X_j = sum_k x_k exp(-2 pi i j k / n)`, in place.
    pub fn forward(&mut self, buf: &mut [Complex]) {
        assert_eq!(buf.len(), self.n, "FFT buffer length");
        self.forward.process_with_scratch(buf, &mut self.scratch);
    }

    /// `x_k = (1/n) sum_j X_j exp(2 pi i j k / n)`, in place.
    pub fn inverse(&mut self, buf: &mut [Complex]) {
        assert_eq!(buf.len(), self.n, "FFT buffer length");
        self.inverse.process_with_scratch(buf, &mut self.scratch);
        let s = 1.0 / self.n as f64;
        buf.iter_mut().for_each(|v| *v = v.scale(s));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn naive_dft(x: &[Complex]) -> Vec<Complex> {
        let n = x.len();
        (0..n)
            .map(|j| {
                x.iter().enumerate().fold(ZERO, |acc, (k, &v)| {
                    let (s, c) =
                        (-std::f64::consts::TAU * ((j * k) % n) as f64 / n as f64).sin_cos();
                    acc + v * Complex::new(c, s)
                })
            })
            .collect()
    }

    /// The radix-2 Cooley-Tukey this module computed before it used rustfft (issue 18, item
    /// 8), kept as the reference that the results did not move beyond round-off.
    fn legacy_radix2(buf: &mut [Complex]) {
        let n = buf.len();
        let twiddles: Vec<Complex> = (0..n / 2)
            .map(|k| {
                let (s, c) = (-std::f64::consts::TAU * k as f64 / n as f64).sin_cos();
                Complex::new(c, s)
            })
            .collect();
        let mut j = 0;
        for i in 1..n {
            let mut bit = n >> 1;
            while j & bit != 0 {
                j ^= bit;
                bit >>= 1;
            }
            j |= bit;
            if i < j {
                buf.swap(i, j);
            }
        }
        let mut len = 2;
        while len <= n {
            let half = len / 2;
            let stride = n / len;
            for block in buf.chunks_exact_mut(len) {
                let (lo, hi) = block.split_at_mut(half);
                for (k, (a, b)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
                    let t = *b * twiddles[k * stride];
                    *b = *a - t;
                    *a += t;
                }
            }
            len <<= 1;
        }
    }

    fn random(n: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<Complex> {
        (0..n)
            .map(|_| Complex::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)))
            .collect()
    }

    #[test]
    fn matches_the_naive_dft_and_inverts_at_any_length() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for n in (1..=9)
            .map(|l| 1 << (l - 1))
            .chain([3, 5, 12, 100, 257, 1000])
        {
            let x = random(n, &mut rng);
            let mut fft = Fft::new(n);
            let mut y = x.clone();
            fft.forward(&mut y);
            for (a, b) in y.iter().zip(naive_dft(&x)) {
                assert!((*a - b).norm() < 1e-12 * n as f64, "n = {n}");
            }
            fft.inverse(&mut y);
            for (a, b) in y.iter().zip(&x) {
                assert!(
                    (*a - *b).norm() < 1e-14 * (n as f64).log2().max(1.0),
                    "n = {n}"
                );
            }
        }
    }

    /// rustfft equals the former radix-2 transform within round-off: every bin within a few
    /// ulps of the spectrum's largest magnitude times log2 n.
    #[test]
    fn equals_the_former_radix2_within_round_off() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(18);
        for log_n in 0..=16 {
            let n = 1usize << log_n;
            let x = random(n, &mut rng);
            let mut ours = x.clone();
            Fft::new(n).forward(&mut ours);
            let mut legacy = x;
            legacy_radix2(&mut legacy);
            let scale = legacy.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let worst = ours
                .iter()
                .zip(&legacy)
                .map(|(a, b)| (*a - *b).norm())
                .fold(0.0, f64::max);
            let bound = 8.0 * f64::EPSILON * scale * (log_n.max(1) as f64);
            assert!(worst <= bound, "n = {n}: {worst:e} > {bound:e}");
        }
    }
}
