//! Dense kernels of the contact solver: row dot products, `W x + c` and the Gauss-Seidel
//! sweep over a row-major block, with an AVX2 build chosen at run time on x86-64.
//!
//! Every dot product has one fixed evaluation order: four lanes over chunks of four entries
//! (lane l takes entries 4i + l), lanes summed as `(l0 + l1) + (l2 + l3)`, then the tail added
//! in order, products and sums rounded separately (no fused multiply-add). The AVX2 build
//! performs exactly these operations four lanes at a time, so results are bit-for-bit the same
//! on every x86-64 CPU, with or without AVX2.

use super::projection::project_pair;

/// A build of the dot-product kernel.
trait Kernel {
    /// Dot products of `R` rows with `x` (each row at least `x.len()` long).
    fn dots<const R: usize>(rows: [&[f64]; R], x: &[f64]) -> [f64; R];
}

/// Portable build.
struct Portable;

impl Kernel for Portable {
    #[inline(always)]
    fn dots<const R: usize>(rows: [&[f64]; R], x: &[f64]) -> [f64; R] {
        let n = x.len();
        let rows = rows.map(|r| &r[..n]);
        let nc = n / 4 * 4;
        let mut acc = [[0.0f64; 4]; R];
        let mut j = 0;
        while j < nc {
            for (a, row) in acc.iter_mut().zip(rows.iter()) {
                for l in 0..4 {
                    a[l] += row[j + l] * x[j + l];
                }
            }
            j += 4;
        }
        let mut out = [0.0; R];
        for ((o, a), row) in out.iter_mut().zip(acc.iter()).zip(rows.iter()) {
            let mut s = (a[0] + a[1]) + (a[2] + a[3]);
            for k in nc..n {
                s += row[k] * x[k];
            }
            *o = s;
        }
        out
    }
}

/// AVX2 build; only reachable from functions compiled with AVX2 after run-time detection.
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Kernel for Avx2 {
    #[inline(always)]
    fn dots<const R: usize>(rows: [&[f64]; R], x: &[f64]) -> [f64; R] {
        // SAFETY: `Avx2` is private to this module and used only inside `#[target_feature(enable
        // = "avx2")]` functions, which are called only after `is_x86_feature_detected!("avx2")`.
        unsafe { dots_avx2(rows, x) }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn dots_avx2<const R: usize>(rows: [&[f64]; R], x: &[f64]) -> [f64; R] {
    use std::arch::x86_64::{
        _mm256_add_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_setzero_pd, _mm256_storeu_pd,
    };
    let n = x.len();
    // Bounds: every row is cut to n entries here, so the unaligned loads below at
    // j..j+4 <= nc <= n stay inside the slices.
    let rows = rows.map(|r| &r[..n]);
    let nc = n / 4 * 4;
    let mut acc = [_mm256_setzero_pd(); R];
    let mut j = 0;
    while j < nc {
        let xv = _mm256_loadu_pd(x.as_ptr().add(j));
        for (a, row) in acc.iter_mut().zip(rows.iter()) {
            *a = _mm256_add_pd(*a, _mm256_mul_pd(_mm256_loadu_pd(row.as_ptr().add(j)), xv));
        }
        j += 4;
    }
    let mut out = [0.0; R];
    for ((o, a), row) in out.iter_mut().zip(acc.iter()).zip(rows.iter()) {
        let mut lanes = [0.0f64; 4];
        _mm256_storeu_pd(lanes.as_mut_ptr(), *a);
        let mut s = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
        for k in nc..n {
            s += row[k] * x[k];
        }
        *o = s;
    }
    out
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// `y = W x + c` for a row-major square block `w` (`m x m`, m = `x.len()`).
// NOTE: W is symmetric, but a half-stored (triangular) product reads W with a stride in one of
// its two passes; below ~100 active pairs the block sits in L2 and the full row-major product
// is faster. Symmetry is used where it pays: gamma of all pairs reads W's rows of the nonzero
// forces as columns (see `ContactSolver::solve`).
pub(crate) fn matvec(w: &[f64], x: &[f64], c: &[f64], y: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx2() {
            // SAFETY: AVX2 is available, checked just above.
            unsafe { matvec_avx2(w, x, c, y) };
            return;
        }
    }
    matvec_with::<Portable>(w, x, c, y)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn matvec_avx2(w: &[f64], x: &[f64], c: &[f64], y: &mut [f64]) {
    matvec_with::<Avx2>(w, x, c, y)
}

#[inline(always)]
fn matvec_with<K: Kernel>(w: &[f64], x: &[f64], c: &[f64], y: &mut [f64]) {
    let m = x.len();
    let mut i = 0;
    // Four rows at a time share the loads of x.
    while i + 4 <= m {
        let d = K::dots(
            [
                &w[i * m..],
                &w[(i + 1) * m..],
                &w[(i + 2) * m..],
                &w[(i + 3) * m..],
            ],
            x,
        );
        for r in 0..4 {
            y[i + r] = c[i + r] + d[r];
        }
        i += 4;
    }
    while i < m {
        y[i] = c[i] + K::dots([&w[i * m..]], x)[0];
        i += 1;
    }
}

/// One projected Gauss-Seidel sweep over a row-major block `w` (`m x m`): pair by pair, the
/// pair's gap velocity from the latest forces, then the projected step with step sizes `eps`.
/// Returns (||change||^2, ||lambda_new||^2).
pub(crate) fn gauss_seidel_sweep(
    w: &[f64],
    c: &[f64],
    eps: &[f64],
    mu: &[f64],
    lam: &mut [f64],
) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx2() {
            // SAFETY: AVX2 is available, checked just above.
            return unsafe { gauss_seidel_sweep_avx2(w, c, eps, mu, lam) };
        }
    }
    gauss_seidel_sweep_with::<Portable>(w, c, eps, mu, lam)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gauss_seidel_sweep_avx2(
    w: &[f64],
    c: &[f64],
    eps: &[f64],
    mu: &[f64],
    lam: &mut [f64],
) -> (f64, f64) {
    gauss_seidel_sweep_with::<Avx2>(w, c, eps, mu, lam)
}

#[inline(always)]
fn gauss_seidel_sweep_with<K: Kernel>(
    w: &[f64],
    c: &[f64],
    eps: &[f64],
    mu: &[f64],
    lam: &mut [f64],
) -> (f64, f64) {
    let m = lam.len();
    let (mut d2, mut n2) = (0.0, 0.0);
    for (k, &mu_k) in mu.iter().enumerate() {
        let b = 3 * k;
        let g = K::dots([&w[b * m..], &w[(b + 1) * m..], &w[(b + 2) * m..]], lam);
        let trial = [
            lam[b] - eps[b] * (c[b] + g[0]),
            lam[b + 1] - eps[b + 1] * (c[b + 1] + g[1]),
            lam[b + 2] - eps[b + 2] * (c[b + 2] + g[2]),
        ];
        let (p, _) = project_pair(mu_k, trial);
        for a in 0..3 {
            let d = p[a] - lam[b + a];
            d2 += d * d;
            n2 += p[a] * p[a];
            lam[b + a] = p[a];
        }
    }
    (d2, n2)
}

/// `y += f x`.
#[inline]
pub(crate) fn axpy(f: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += f * xi;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(m: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let w = (0..m * m)
            .map(|k| ((k * 7919 % 1000) as f64 - 500.0) * 1e-3)
            .collect();
        let x = (0..m).map(|i| (i as f64 * 0.37).sin()).collect();
        let c = (0..m).map(|i| (i as f64 * 0.11).cos()).collect();
        (w, x, c)
    }

    #[test]
    fn matvec_matches_the_naive_product() {
        for m in [1, 3, 4, 5, 9, 12, 31, 60] {
            let (w, x, c) = block(m);
            let mut y = vec![0.0; m];
            matvec(&w, &x, &c, &mut y);
            for i in 0..m {
                let naive: f64 = c[i] + (0..m).map(|j| w[i * m + j] * x[j]).sum::<f64>();
                assert!(
                    (y[i] - naive).abs() <= 1e-13 * (1.0 + naive.abs()),
                    "m {m} row {i}"
                );
            }
        }
    }

    #[test]
    fn builds_agree_bit_for_bit() {
        for m in [3, 7, 12, 33, 60] {
            let (w, x, c) = block(m);
            let mut y = vec![0.0; m];
            let mut z = vec![0.0; m];
            matvec(&w, &x, &c, &mut y);
            matvec_with::<Portable>(&w, &x, &c, &mut z);
            assert_eq!(y, z, "m {m}");
            // Row grouping does not change a row's result.
            for i in 0..m {
                let single = c[i] + Portable::dots([&w[i * m..]], &x)[0];
                assert_eq!(single.to_bits(), y[i].to_bits(), "m {m} row {i}");
            }
        }
    }
}
