//! Open-contact prediction: which pairs go to the contact solver in a step.
//!
//! A pair is a *candidate* when it was closed in the previous step (`lambda_n > 0`), or when
//! its free normal gap (no contact force in this step) at the contact time level,
//! `p_k = Phi_n,k x_p + g0_n,k`, or that gap extrapolated `kappa` further steps at the
//! step's closing rate, `q_k = p_k + kappa (p_k - g_n,k^start)`, is closed (`<= 0`).
//! With `g^start = Phi_g (x_p - dt v_c) + g0 + G_res lambda^prev` this is
//! `q_k = Phi_n,k x_q + g0_n,k - kappa (G_res lambda^prev)_n,k`, `x_q = x_p + kappa dt v_c`.
//! All other pairs are open (`lambda = 0`) without a solve. The initial normal gap `g0_n,k`
//! is the clearance, plus a per-pair offset when one is set ([`InitialGap`]).
//!
//! Computing `p` and `q` for all pairs costs two passes over the `C x m` normal rows of
//! `Phi_g`, which alone would cap the open-contact step rate well below the goal. Instead the
//! prediction proves most pairs open from a cheap lower bound and computes the exact gaps only
//! for the remaining ones:
//!
//! `Phi_n,k x = sum_{i<L} Phi_n,ki x_i + sum_{i>=L} (Phi_n,ki / w_i) (w_i x_i)
//!            >= low_k(x) - b_k e(x)`,  `b_k = ||Phi_n,k,i>=L ./ w||_2`, `e(x) = ||w .* x_{i>=L}||_2`
//!
//! (Cauchy-Schwarz; `e` is the square root of twice the potential energy of the high modes
//! and stays small in open flight). `low_k` for all pairs costs `C L` multiply-adds (columns
//! of the first L modes stored contiguously), `e` one pass over the modes.
//!
//! Before that, one bound for the whole contact patch: the pairs of a patch move nearly
//! alike in the low modes, so with the midrange `r_i` of the low columns over the pairs and
//! their half-range `d_i` (`|Phi_n,ki - r_i| <= d_i` for every pair),
//!
//! `g0_n,k + Phi_n,k x >= min_k g0_n,k + sum_{i<L} (r_i x_i - d_i |x_i|) - max_k b_k e(x)`
//!
//! for every pair, in `2 L + m` operations. Where that proves `p` and `q` open, every pair not
//! closed in the previous step is open and the `C L` pass is skipped: in open flight, and for
//! most of each period in the impact band, the step no longer pays per pair.
//!
// NOTE: the bound is applied with a slack of `BOUND_SLACK` times the magnitudes involved,
// far above the rounding of the exact dot products (~m eps), so a pair is skipped only when
// its exactly computed `p` and `q` would both be positive too: the candidate set, and with it
// every result bit, is the same as with exact gaps for all pairs
// (`IntegratorParameters::report_gaps`, tested in tests/sim_determinism.rs).

use super::kernels::dot;

/// Number of low modes evaluated exactly in the bound (fewer if the ROM has fewer modes).
// NOTE: the lowest modes carry nearly all of the gap motion in open flight (the rig is driven
// near 1F-2F); 8 covers the first bending and edgewise modes of both beams. The cost is 2 C L
// multiply-adds per step.
pub(crate) const LOW_MODES: usize = 8;

/// Relative slack on the lower bound (see the module NOTE).
const BOUND_SLACK: f64 = 1e-10;

/// Precomputed data of the prediction.
#[derive(Clone, Debug)]
pub(crate) struct Predictor {
    n_pairs: usize,
    m: usize,
    low: usize,
    /// Normal rows of Phi_g, row-major `C x m` (row k = pair k).
    phi_n: Vec<f64>,
    /// The first `low` columns of `phi_n`, column-major `low x C` (entry `i C + k`).
    phi_low: Vec<f64>,
    /// `||Phi_n,k,i<L||_2` per pair.
    a_low: Vec<f64>,
    /// `||Phi_n,k,i>=L ./ w_i||_2` per pair (infinite if a high mode has w = 0).
    b_high: Vec<f64>,
    /// Circular frequencies of the modes `>= low`.
    omega_high: Vec<f64>,
    /// The patch bound (module documentation): midrange `r_i` and half-range `d_i` (widened
    /// by a few ulps) of each low column over the pairs, and `max_k b_k`.
    patch_mid: Vec<f64>,
    patch_half: Vec<f64>,
    b_max: f64,
    /// Steps whose pairs the patch bound proved open (kept for the unit tests only).
    #[cfg(test)]
    patch_open_steps: u64,
    /// Work arrays, `C` each.
    lo_p: Vec<f64>,
    lo_q: Vec<f64>,
}

/// The initial normal gap `g0_n,k` of every pair. The prediction is generic over it so that
/// the uniform case (one clearance, the default) compiles to exactly the scalar code.
pub(crate) trait InitialGap: Copy {
    /// `g0_n,k` of pair `k`, m.
    fn at(self, k: usize) -> f64;

    /// The smallest `g0_n,k` over the pairs and a bound on the largest magnitude, m.
    fn range(self) -> (f64, f64);
}

impl InitialGap for f64 {
    #[inline(always)]
    fn at(self, _k: usize) -> f64 {
        self
    }

    #[inline(always)]
    fn range(self) -> (f64, f64) {
        (self, self.abs())
    }
}

/// The clearance plus a per-pair offset (e.g. a tilted contact face).
#[derive(Clone, Copy, Debug)]
pub(crate) struct OffsetGap<'a> {
    /// Clearance, m.
    pub clearance: f64,
    /// Offset per pair (`C`), m.
    pub offset: &'a [f64],
    /// The smallest offset and the largest magnitude, m (set with the offsets, not per
    /// step).
    pub range: (f64, f64),
}

impl InitialGap for OffsetGap<'_> {
    #[inline(always)]
    fn at(self, k: usize) -> f64 {
        self.clearance + self.offset[k]
    }

    // NOTE: rounding is monotone, so `clearance + min offset` is exactly the smallest
    // `clearance + offset_k`; the magnitude only sizes the bound's slack.
    #[inline(always)]
    fn range(self) -> (f64, f64) {
        let (lowest, largest) = self.range;
        (self.clearance + lowest, self.clearance.abs() + largest)
    }
}

/// Where the prediction writes its result.
pub(crate) struct Prediction<'a> {
    /// Candidate pairs, ascending.
    pub cand: &'a mut Vec<usize>,
    /// Exact free normal gap `p` of each candidate (same order), m.
    pub p_cand: &'a mut Vec<f64>,
    /// Exact `p` of every pair (filled only when `Some`: exact mode, no bound), m.
    pub p_all: Option<&'a mut [f64]>,
}

impl Predictor {
    /// `phi_n` is row-major `C x m`, `omega` has `m` entries.
    pub(crate) fn new(phi_n: Vec<f64>, omega: &[f64], n_pairs: usize) -> Predictor {
        let m = omega.len();
        let low = LOW_MODES.min(m);
        let mut phi_low = vec![0.0; low * n_pairs];
        let mut a_low = vec![0.0; n_pairs];
        let mut b_high = vec![0.0; n_pairs];
        for k in 0..n_pairs {
            let row = &phi_n[k * m..(k + 1) * m];
            let mut a2 = 0.0;
            for (i, &v) in row[..low].iter().enumerate() {
                phi_low[i * n_pairs + k] = v;
                a2 += v * v;
            }
            let mut b2 = 0.0;
            for (&v, &w) in row[low..].iter().zip(&omega[low..]) {
                b2 += if v == 0.0 { 0.0 } else { (v / w) * (v / w) };
            }
            a_low[k] = a2.sqrt();
            // Inflate by a few ulps so that the rounding of b itself is covered.
            b_high[k] = b2.sqrt() * (1.0 + 1e-12);
        }
        let (mut patch_mid, mut patch_half) = (vec![0.0; low], vec![0.0; low]);
        for i in 0..low {
            let col = &phi_low[i * n_pairs..(i + 1) * n_pairs];
            let hi = col.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let lo = col.iter().copied().fold(f64::INFINITY, f64::min);
            if n_pairs > 0 {
                patch_mid[i] = 0.5 * (hi + lo);
                patch_half[i] = (hi - patch_mid[i]).max(patch_mid[i] - lo) * (1.0 + 1e-12);
            }
        }
        let b_max = b_high.iter().copied().fold(0.0, f64::max);
        Predictor {
            n_pairs,
            m,
            low,
            phi_n,
            phi_low,
            a_low,
            b_high,
            omega_high: omega[low..].to_vec(),
            patch_mid,
            patch_half,
            b_max,
            #[cfg(test)]
            patch_open_steps: 0,
            lo_p: vec![0.0; n_pairs],
            lo_q: vec![0.0; n_pairs],
        }
    }

    /// Predicts the candidates of one step.
    ///
    /// - `x_p`, `x_q`: modal displacements of the free gap and of the extrapolated gap (`m`);
    /// - `g0`: initial normal gap per pair, m;
    /// - `lambda_prev`: forces of the previous step (`3C`), pairs with `lambda_n > 0` are
    ///   always candidates;
    /// - `r_prev`: `G_res lambda^prev` (`3C`) when the previous step had closed pairs;
    /// - `kappa`: extrapolation in steps.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn predict<G: InitialGap>(
        &mut self,
        x_p: &[f64],
        x_q: &[f64],
        g0: G,
        lambda_prev: &[f64],
        r_prev: Option<&[f64]>,
        kappa: f64,
        out: Prediction<'_>,
    ) {
        let n = self.n_pairs;
        let m = self.m;
        let n_cand_prev = out.cand.len();
        out.cand.clear();
        out.p_cand.clear();
        let candidate = |p: f64, q: f64| !(p > 0.0 && q > 0.0);
        // NOTE: in held contact (at least half the pairs candidates in the previous step, whose
        // candidates `out.cand` still holds) the bound proves few pairs open, and its pass over
        // the low modes is pure cost (about 5 % of the simulated rig's time with the probes
        // touching, issue 16): the gaps are then formed exactly for every pair, as in exact
        // mode. The same candidates and the same bits either way; the choice only saves time.
        if out.p_all.is_some() || 2 * n_cand_prev >= n {
            let mut p_all = out.p_all;
            for k in 0..n {
                let row = &self.phi_n[k * m..(k + 1) * m];
                let p = g0.at(k) + dot(row, x_p);
                if let Some(all) = p_all.as_deref_mut() {
                    all[k] = p;
                }
                if lambda_prev[3 * k] > 0.0 {
                    out.cand.push(k);
                    out.p_cand.push(p);
                    continue;
                }
                let rn = r_prev.map_or(0.0, |r| r[3 * k]);
                let q = g0.at(k) + dot(row, x_q) - kappa * rn;
                if candidate(p, q) {
                    out.cand.push(k);
                    out.p_cand.push(p);
                }
            }
            return;
        }

        let low = self.low;
        let (mut e_p, mut e_q) = (0.0, 0.0);
        for ((&w, &xp), &xq) in self.omega_high.iter().zip(&x_p[low..]).zip(&x_q[low..]) {
            e_p += (w * xp) * (w * xp);
            e_q += (w * xq) * (w * xq);
        }
        let (e_p, e_q) = (e_p.sqrt(), e_q.sqrt());

        // The whole patch open and no pair closed in the previous step (`r_prev` is None
        // exactly when the state lists no closed pair, and a state holds a positive normal
        // force only on its closed pairs: `Integrator::check_state`): no candidate.
        if r_prev.is_none() {
            let (g_lo, g_big) = g0.range();
            if self.patch_open(x_p, g_lo, g_big, e_p) && self.patch_open(x_q, g_lo, g_big, e_q) {
                #[cfg(test)]
                {
                    self.patch_open_steps += 1;
                }
                return;
            }
        }

        // Lower bounds: exact low-mode part for all pairs (columns, vectorised over pairs).
        for (k, (lp, lq)) in self.lo_p.iter_mut().zip(self.lo_q.iter_mut()).enumerate() {
            *lp = g0.at(k);
            *lq = g0.at(k);
        }
        for i in 0..low {
            let col = &self.phi_low[i * n..(i + 1) * n];
            let (xp, xq) = (x_p[i], x_q[i]);
            for ((lp, lq), &c) in self.lo_p.iter_mut().zip(self.lo_q.iter_mut()).zip(col) {
                *lp += c * xp;
                *lq += c * xq;
            }
        }
        let (mut nx_p, mut nx_q) = (0.0, 0.0);
        for (&xp, &xq) in x_p[..low].iter().zip(&x_q[..low]) {
            nx_p += xp * xp;
            nx_q += xq * xq;
        }
        let (nx_p, nx_q) = (nx_p.sqrt(), nx_q.sqrt());

        for k in 0..n {
            let closed_prev = lambda_prev[3 * k] > 0.0;
            let rn = r_prev.map_or(0.0, |r| r[3 * k]);
            if !closed_prev {
                let (a, b) = (self.a_low[k], self.b_high[k]);
                let lb_p = self.lo_p[k] - b * e_p;
                let lb_q = self.lo_q[k] - kappa * rn - b * e_q;
                let c_abs = g0.at(k).abs();
                let sl_p = BOUND_SLACK * (a * nx_p + b * e_p + c_abs);
                let sl_q = BOUND_SLACK * (a * nx_q + b * e_q + c_abs + (kappa * rn).abs());
                if lb_p > sl_p && lb_q > sl_q {
                    continue;
                }
            }
            let row = &self.phi_n[k * m..(k + 1) * m];
            let p = g0.at(k) + dot(row, x_p);
            if closed_prev {
                out.cand.push(k);
                out.p_cand.push(p);
                continue;
            }
            let q = g0.at(k) + dot(row, x_q) - kappa * rn;
            if candidate(p, q) {
                out.cand.push(k);
                out.p_cand.push(p);
            }
        }
    }

    /// Whether the patch bound proves the gap of modal displacement `x` open at every pair:
    /// `g_lo` the smallest initial gap, `g_big` the largest magnitude, `e` the high modes'
    /// `e(x)`. Applied with the slack of the per-pair bound (module NOTE); an infinite `b_max`
    /// (a high mode with w = 0) makes the bound NaN, which proves nothing.
    #[inline(always)]
    fn patch_open(&self, x: &[f64], g_lo: f64, g_big: f64, e: f64) -> bool {
        let (mut lb, mut size) = (g_lo, g_big);
        for ((&r, &d), &xi) in self
            .patch_mid
            .iter()
            .zip(&self.patch_half)
            .zip(&x[..self.low])
        {
            lb += r * xi - d * xi.abs();
            size += (r * xi).abs() + d * xi.abs();
        }
        let high = self.b_max * e;
        lb - high > BOUND_SLACK * (size + high)
    }

    /// Steps whose pairs the patch bound proved open (the rest formed the per-pair bounds or
    /// the exact gaps).
    #[cfg(test)]
    pub(crate) fn patch_open_steps(&self) -> u64 {
        self.patch_open_steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The bounded prediction, and the held-contact one (every gap formed), give exactly the
    /// candidates and gaps of the exact one.
    #[test]
    fn bounded_prediction_equals_exact_prediction() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (n, m) = (40, 30);
        let omega: Vec<f64> = (0..m).map(|i| 100.0 * (1.0 + i as f64).powi(2)).collect();
        let phi_n: Vec<f64> = (0..n * m).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut pred = Predictor::new(phi_n, &omega, n);
        let (mut n_cand, mut n_skipped) = (0, 0);
        for trial in 0..200 {
            let scale = 1e-4 * (1.0 + trial as f64 / 20.0);
            let x_p: Vec<f64> = (0..m)
                .map(|i| rng.gen_range(-scale..scale) / (1.0 + i as f64))
                .collect();
            let x_q: Vec<f64> = x_p
                .iter()
                .map(|x| x + rng.gen_range(-scale..scale) * 0.1)
                .collect();
            let mut lambda = vec![0.0; 3 * n];
            if trial % 3 == 0 {
                lambda[3 * (trial % n)] = 1.0;
            }
            let r: Vec<f64> = (0..3 * n).map(|_| rng.gen_range(0.0..1e-5)).collect();
            let r_prev = (trial % 2 == 0).then_some(&r[..]);
            // Candidates and the bits of their gaps, from `last` (the last step's candidates)
            // and, in exact mode, every gap.
            let mut run = |last: Vec<usize>, exact: bool| {
                let (mut cand, mut p) = (last, vec![]);
                let mut all = vec![0.0; n];
                pred.predict(
                    &x_p,
                    &x_q,
                    3e-4,
                    &lambda,
                    r_prev,
                    1.0,
                    Prediction {
                        cand: &mut cand,
                        p_cand: &mut p,
                        p_all: exact.then_some(&mut all[..]),
                    },
                );
                let bits: Vec<u64> = p.iter().map(|x| x.to_bits()).collect();
                (cand, bits)
            };
            let bounded = run(vec![], false);
            let exact = run(vec![], true);
            // The held-contact path: as if every pair had been a candidate in the last step.
            let held = run((0..n).collect(), false);
            assert_eq!(bounded, exact, "trial {trial}");
            assert_eq!(held, exact, "trial {trial}");
            n_cand += bounded.0.len();
            n_skipped += n - bounded.0.len();
        }
        // Both outcomes must occur for the comparison to mean anything.
        assert!(n_cand > 100 && n_skipped > 100, "{n_cand} {n_skipped}");
    }

    /// On a patch whose pairs move nearly alike (a common row plus a few percent per pair, as
    /// the rig's contact patch), the patch bound proves many steps open and changes no
    /// candidate and no bit of the exact prediction, with one clearance and with a per-pair
    /// offset (a tilted face).
    #[test]
    fn patch_bound_equals_exact_prediction() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (n, m) = (48, 24);
        let omega: Vec<f64> = (0..m).map(|i| 100.0 * (1.0 + i as f64).powi(2)).collect();
        let common: Vec<f64> = (0..m).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let phi_n: Vec<f64> = (0..n * m)
            .map(|j| common[j % m] * (1.0 + rng.gen_range(-0.05..0.05)))
            .collect();
        let offset: Vec<f64> = (0..n).map(|k| 2e-5 * (k as f64 / n as f64 - 0.5)).collect();
        let mut pred = Predictor::new(phi_n, &omega, n);
        let (mut steps, mut open_before) = (0u64, 0);
        for tilted in [false, true] {
            for trial in 0..300 {
                // Amplitudes from far open to past the clearance of 3e-4 m.
                let scale = 2e-3 * ((trial + 1) as f64 / 300.0);
                let x_p: Vec<f64> = (0..m)
                    .map(|i| rng.gen_range(-scale..scale) / (1.0 + i as f64).powi(2))
                    .collect();
                let x_q: Vec<f64> = x_p
                    .iter()
                    .map(|x| x + rng.gen_range(-scale..scale) * 0.01)
                    .collect();
                // No pair closed in the previous step (`r_prev` None: the forces are zero).
                let lambda = vec![0.0; 3 * n];
                let mut run = |exact: bool| {
                    let (mut cand, mut p) = (vec![], vec![]);
                    let mut all = vec![0.0; n];
                    let out = Prediction {
                        cand: &mut cand,
                        p_cand: &mut p,
                        p_all: exact.then_some(&mut all[..]),
                    };
                    if tilted {
                        let g0 = OffsetGap {
                            clearance: 3e-4,
                            offset: &offset,
                            range: (
                                offset.iter().copied().fold(f64::INFINITY, f64::min),
                                offset.iter().fold(0.0, |big, o| o.abs().max(big)),
                            ),
                        };
                        pred.predict(&x_p, &x_q, g0, &lambda, None, 1.0, out);
                    } else {
                        pred.predict(&x_p, &x_q, 3e-4, &lambda, None, 1.0, out);
                    }
                    let bits: Vec<u64> = p.iter().map(|x| x.to_bits()).collect();
                    (cand, bits)
                };
                let bounded = run(false);
                let exact = run(true);
                assert_eq!(bounded, exact, "tilted {tilted}, trial {trial}");
                steps += 1;
            }
            let open = pred.patch_open_steps() - open_before;
            open_before = pred.patch_open_steps();
            // Both paths must occur for the comparison to mean anything.
            assert!(
                open > 50 && open < 250,
                "tilted {tilted}: {open} of 300 patch-open"
            );
        }
        assert_eq!(steps, 600);
    }
}
