//! A small in-place radix-2 complex FFT for the wavelet transform (power-of-two sizes only).
//!
//! NOTE: written here rather than pulling a crate: the wavelet transform needs one size per
//! call, power-of-two padding is natural for its zero-padded convolutions, and an iterative
//! Cooley-Tukey with a precomputed twiddle table (each twiddle from its own `sin_cos`, so no
//! error accumulates in the table) is accurate to a few ulps times log2 n.

use std::ops::{Add, Mul, Sub};

/// A complex number.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Complex {
    pub re: f64,
    pub im: f64,
}

impl Complex {
    pub const ZERO: Complex = Complex { re: 0.0, im: 0.0 };

    pub fn new(re: f64, im: f64) -> Self {
        Complex { re, im }
    }

    pub fn norm(self) -> f64 {
        self.re.hypot(self.im)
    }

    pub fn scale(self, s: f64) -> Self {
        Complex::new(self.re * s, self.im * s)
    }

    fn conj(self) -> Self {
        Complex::new(self.re, -self.im)
    }
}

impl Add for Complex {
    type Output = Complex;
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
}

impl Sub for Complex {
    type Output = Complex;
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
}

impl Mul for Complex {
    type Output = Complex;
    fn mul(self, o: Complex) -> Complex {
        Complex::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}

/// FFT plan for one power-of-two size.
#[derive(Debug, Clone)]
pub(crate) struct Fft {
    n: usize,
    /// `exp(-2 pi i k / n)` for `k < n / 2`.
    twiddles: Vec<Complex>,
}

impl Fft {
    /// Plan for size `n`, a power of two (>= 1).
    pub fn new(n: usize) -> Self {
        assert!(n.is_power_of_two(), "FFT size {n} is not a power of two");
        let twiddles = (0..n / 2)
            .map(|k| {
                let (s, c) = (-std::f64::consts::TAU * k as f64 / n as f64).sin_cos();
                Complex::new(c, s)
            })
            .collect();
        Fft { n, twiddles }
    }

    /// `X_j = sum_k x_k exp(-2 pi i j k / n)`, in place.
    pub fn forward(&self, buf: &mut [Complex]) {
        self.transform(buf, false);
    }

    /// `x_k = (1/n) sum_j X_j exp(2 pi i j k / n)`, in place.
    pub fn inverse(&self, buf: &mut [Complex]) {
        self.transform(buf, true);
        let s = 1.0 / self.n as f64;
        buf.iter_mut().for_each(|v| *v = v.scale(s));
    }

    fn transform(&self, buf: &mut [Complex], inverse: bool) {
        let n = self.n;
        assert_eq!(buf.len(), n, "FFT buffer length");
        // Bit-reversal permutation.
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
                    let w = self.twiddles[k * stride];
                    let w = if inverse { w.conj() } else { w };
                    let t = *b * w;
                    *b = *a - t;
                    *a = *a + t;
                }
            }
            len <<= 1;
        }
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
                x.iter().enumerate().fold(Complex::ZERO, |acc, (k, &v)| {
                    let (s, c) =
                        (-std::f64::consts::TAU * ((j * k) % n) as f64 / n as f64).sin_cos();
                    acc + v * Complex::new(c, s)
                })
            })
            .collect()
    }

    #[test]
    fn matches_the_naive_dft_and_inverts() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for log_n in 0..9 {
            let n = 1 << log_n;
            let x: Vec<Complex> = (0..n)
                .map(|_| Complex::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)))
                .collect();
            let fft = Fft::new(n);
            let mut y = x.clone();
            fft.forward(&mut y);
            for (a, b) in y.iter().zip(naive_dft(&x)) {
                assert!((*a - b).norm() < 1e-12 * n as f64, "n = {n}");
            }
            fft.inverse(&mut y);
            for (a, b) in y.iter().zip(&x) {
                assert!((*a - *b).norm() < 1e-14 * (log_n + 1) as f64, "n = {n}");
            }
        }
    }
}
