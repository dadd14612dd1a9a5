//! Small ROMs built by hand for the integrator tests (and the integrator bench):
//! two Euler-Bernoulli cantilevers with a tip contact pair, a one-mode bar with residual
//! flexibility, a two-mode pair with one normal and one tangential mode, and a synthetic
//! contact patch of the size of the reference rig.

#![allow(dead_code)]

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use rand::{Rng, SeedableRng};
use rigtwin::rom::{ModeSelection, Rom, RomMeta, RomOutput};

/// Builds a Rom from its parts; K_gg is the inverse of G_res.
#[allow(clippy::too_many_arguments)]
pub fn rom_from_parts(
    omega: Vec<f64>,
    damping_ratio: Vec<f64>,
    phi_g: Mat<f64>,
    g_res: Mat<f64>,
    beta: Vec<f64>,
    clearance: f64,
    friction: f64,
    outputs: Vec<RomOutput>,
    reference_mode: usize,
) -> Rom {
    let n_pairs = phi_g.nrows() / 3;
    let k_gg = g_res
        .llt(Side::Lower)
        .map(|l| l.inverse())
        .unwrap_or_else(|_| Mat::zeros(g_res.nrows(), g_res.ncols()));
    let m = omega.len();
    Rom {
        meta: RomMeta {
            source: "test".into(),
            rig_name: "test".into(),
            selection: ModeSelection::Count { count: m },
            reference_mode,
            ..RomMeta::default()
        },
        labels: (0..m).map(|i| format!("m{i}")).collect(),
        omega,
        damping_ratio,
        phi_g,
        g_res,
        k_gg,
        beta,
        pair_area: vec![1e-6; n_pairs],
        pair_position: vec![[0.0; 3]; n_pairs],
        clearance,
        friction,
        outputs,
    }
}

/// `cos(x) cosh(x) = -1`, the r-th root (r >= 1) of the clamped-free beam.
fn cantilever_root(r: usize) -> f64 {
    let mut x = (2.0 * r as f64 - 1.0) * std::f64::consts::FRAC_PI_2;
    // f(x) = cos x + 1 / cosh x has the same roots and no overflow.
    for _ in 0..60 {
        let f = x.cos() + 1.0 / x.cosh();
        let df = -x.sin() - x.sinh() / (x.cosh() * x.cosh());
        let dx = f / df;
        x -= dx;
        if dx.abs() < 1e-15 * x {
            break;
        }
    }
    x
}

/// Clamped-free mode shape with `int_0^L shape^2 dx = L`, evaluated stably for large `bl`.
fn cantilever_shape(bl: f64, xi: f64) -> f64 {
    // shape = cosh bx - cos bx - s (sinh bx - sin bx), s = (cosh bL + cos bL) / (sinh bL + sin bL);
    // cosh bx - s sinh bx = (e^{bx} (1 - s) + e^{-bx} (1 + s)) / 2 with
    // 1 - s = (sin bL - cos bL - e^{-bL}) / (sinh bL + sin bL).
    let bx = bl * xi;
    let den = bl.sinh() + bl.sin();
    let s = (bl.cosh() + bl.cos()) / den;
    let one_minus_s = (bl.sin() - bl.cos() - (-bl).exp()) / den;
    0.5 * ((bx).exp() * one_minus_s + (-bx).exp() * (1.0 + s)) - bx.cos() + s * bx.sin()
}

/// One Euler-Bernoulli cantilever: circular frequencies, mass-normalised tip values,
/// participation `beta = int rho A phi dx`, and the tip's static flexibility.
pub struct Cantilever {
    pub omega: Vec<f64>,
    pub tip: Vec<f64>,
    pub beta: Vec<f64>,
    pub static_tip_flexibility: f64,
}

/// Steel cantilever of length `l`, width `b`, thickness `t` (m) with `n` modes.
pub fn cantilever(l: f64, b: f64, t: f64, n: usize) -> Cantilever {
    let (e, rho) = (2.1e11, 7850.0);
    let area = b * t;
    let inertia = b * t * t * t / 12.0;
    let mass = rho * area * l;
    let mut omega = vec![];
    let mut tip = vec![];
    let mut beta = vec![];
    for r in 1..=n {
        let bl = cantilever_root(r);
        omega.push(bl * bl * (e * inertia / (rho * area * l.powi(4))).sqrt());
        let norm = 1.0 / mass.sqrt();
        tip.push(cantilever_shape(bl, 1.0) * norm);
        // Simpson on 4000 intervals.
        let k = 4000;
        let mut s = 0.0;
        for i in 0..=k {
            let w = if i == 0 || i == k {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            s += w * cantilever_shape(bl, i as f64 / k as f64);
        }
        let integral = s / (3.0 * k as f64) * l;
        beta.push(rho * area * integral * norm);
    }
    Cantilever {
        omega,
        tip,
        beta,
        static_tip_flexibility: l.powi(3) / (3.0 * e * inertia),
    }
}

/// Two steel cantilevers (l = 0.3 m; lower 20 x 6 mm, upper 20 x 6.5 mm so that
/// 1FL / 1FU ~ 0.92) with `n` modes each and one contact pair at the tips (upper above lower,
/// normal gap = upper tip - lower tip + clearance). Tangential coordinates have only residual
/// (axial) flexibility. Modes sorted by frequency; the reference mode is 1FU. Outputs:
/// "lower_tip", "upper_tip".
pub fn two_cantilevers(n: usize, clearance: f64, friction: f64, zeta: f64) -> Rom {
    two_cantilevers_with_layer(n, clearance, friction, zeta, 0.0)
}

/// [`two_cantilevers`] with an elastic layer of normal flexibility `layer` (m/N) between the
/// tips, added to the residual flexibility of the normal gap.
pub fn two_cantilevers_with_layer(
    n: usize,
    clearance: f64,
    friction: f64,
    zeta: f64,
    layer: f64,
) -> Rom {
    let l = 0.3;
    let lower = cantilever(l, 0.02, 0.006, n);
    let upper = cantilever(l, 0.02, 0.0065, n);
    // (omega, tip participation in the gap, beta, beam: 0 lower / 1 upper, tip value)
    let mut modes: Vec<(f64, f64, f64, usize, f64)> = vec![];
    for r in 0..n {
        modes.push((
            lower.omega[r],
            -lower.tip[r],
            lower.beta[r],
            0,
            lower.tip[r],
        ));
        modes.push((upper.omega[r], upper.tip[r], upper.beta[r], 1, upper.tip[r]));
    }
    modes.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    let m = modes.len();
    let reference_mode = modes.iter().position(|md| md.3 == 1).unwrap();
    let res = |c: &Cantilever| {
        c.static_tip_flexibility
            - c.tip
                .iter()
                .zip(&c.omega)
                .map(|(p, w)| p * p / (w * w))
                .sum::<f64>()
    };
    let (res_l, res_u) = (res(&lower), res(&upper));
    let e = 2.1e11;
    let axial = l / (e * 0.02 * 0.006) + l / (e * 0.02 * 0.0065);
    let phi_g = Mat::from_fn(3, m, |r, i| if r == 0 { modes[i].1 } else { 0.0 });
    let g_res = Mat::from_fn(3, 3, |r, s| match (r, s) {
        (0, 0) => res_l + res_u + layer,
        (1, 1) | (2, 2) => axial,
        _ => 0.0,
    });
    let outputs = vec![
        RomOutput {
            name: "lower_tip".into(),
            c_eta: modes
                .iter()
                .map(|md| if md.3 == 0 { md.4 } else { 0.0 })
                .collect(),
            c_lambda: vec![-res_l, 0.0, 0.0],
        },
        RomOutput {
            name: "upper_tip".into(),
            c_eta: modes
                .iter()
                .map(|md| if md.3 == 1 { md.4 } else { 0.0 })
                .collect(),
            c_lambda: vec![res_u, 0.0, 0.0],
        },
    ];
    rom_from_parts(
        modes.iter().map(|md| md.0).collect(),
        vec![zeta; m],
        phi_g,
        g_res,
        modes.iter().map(|md| md.2).collect(),
        clearance,
        friction,
        outputs,
        reference_mode,
    )
}

/// One mode (circular frequency `omega`, unit gap participation, no base participation
/// unless `beta` != 0) and one pair whose normal gap is `eta + g_n lambda_n + clearance`:
/// a mass on a spring hitting a wall through a massless spring of flexibility `g_n`.
/// Output "tip" = the gap without clearance.
pub fn bar_one_mode(omega: f64, g_n: f64, clearance: f64, beta: f64) -> Rom {
    let phi_g = Mat::from_fn(3, 1, |r, _| if r == 0 { 1.0 } else { 0.0 });
    let g_res = Mat::from_fn(3, 3, |r, s| if r == s { g_n } else { 0.0 });
    rom_from_parts(
        vec![omega],
        vec![0.0],
        phi_g,
        g_res,
        vec![beta],
        clearance,
        0.0,
        vec![RomOutput {
            name: "tip".into(),
            c_eta: vec![1.0],
            c_lambda: vec![g_n, 0.0, 0.0],
        }],
        0,
    )
}

/// Two modes and one pair: mode 0 moves the normal gap (`phi = 1`), mode 1 the t1 gap
/// (`phi = 1`); both with circular frequency `omega`, damping ratio `zeta`, base participation
/// `beta = [1, beta_t]`; residual flexibility `g` on all three coordinates.
pub fn normal_tangential_pair(
    omega: f64,
    zeta: f64,
    g: f64,
    beta_t: f64,
    clearance: f64,
    friction: f64,
) -> Rom {
    let phi_g = Mat::from_fn(3, 2, |r, i| if r == i { 1.0 } else { 0.0 });
    let g_res = Mat::from_fn(3, 3, |r, s| if r == s { g } else { 0.0 });
    rom_from_parts(
        vec![omega, omega * (1.0 + 1e-9)],
        vec![zeta, zeta],
        phi_g,
        g_res,
        vec![1.0, beta_t],
        clearance,
        friction,
        vec![],
        0,
    )
}

/// A synthetic ROM of the reference rig's size: `m` modes (1FU at `f1` Hz, up to 180 x f1),
/// an `nx x ny` patch of contact pairs with 0.4 mm spacing, smooth mode shapes over the patch
/// (rigid translation and rotations of the tip plus local waves for higher modes), a residual
/// flexibility from a positive definite multiquadric kernel (local elastic coupling) plus a
/// small smooth low-rank part, two tip sensors. Deterministic for a given `seed`.
pub fn synthetic_patch(m: usize, nx: usize, ny: usize, clearance: f64, seed: u64) -> Rom {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = nx * ny;
    let nb = 3 * n;
    let h = 4e-4;
    let pos: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            (
                (k % nx) as f64 * h - 0.5 * (nx - 1) as f64 * h,
                (k / nx) as f64 * h - 0.5 * (ny - 1) as f64 * h,
            )
        })
        .collect();
    let w1 = 2.0 * std::f64::consts::PI * 55.0;
    let omega: Vec<f64> = (0..m)
        .map(|i| {
            if i == 0 {
                return 0.918 * w1;
            }
            let s = (i - 1) as f64 / (m - 2).max(1) as f64;
            w1 * (1.0 + 179.0 * s * s)
        })
        .collect();
    let phi_g = Mat::from_fn(nb, m, |_, _| 0.0);
    let mut phi_g = phi_g;
    let mut beta = vec![0.0; m];
    for i in 0..m {
        let amp = 3.8 * if i % 2 == 0 { -1.0 } else { 1.0 };
        let (ax, ay) = (rng.gen_range(-30.0..30.0), rng.gen_range(-30.0..30.0));
        let (kx, ky) = (
            rng.gen_range(0.0..2000.0) * (i as f64 / m as f64),
            rng.gen_range(0.0..2000.0) * (i as f64 / m as f64),
        );
        let (tx, ty) = (rng.gen_range(-0.3..0.3), rng.gen_range(-0.3..0.3));
        let local = 0.2 * (i as f64 / m as f64);
        for (k, &(x, y)) in pos.iter().enumerate() {
            let wave = (kx * x + ky * y).sin();
            phi_g[(3 * k, i)] = amp * (1.0 + ax * x + ay * y + local * wave);
            phi_g[(3 * k + 1, i)] = amp * (tx + 0.1 * local * wave);
            phi_g[(3 * k + 2, i)] = amp * (ty + 0.1 * local * (ky * x - kx * y).cos());
        }
        beta[i] = 0.4 / (1.0 + i as f64);
    }
    // Residual flexibility: 2 (1 - nu^2) / (pi E) / sqrt(r^2 + a^2) (normal and tangential,
    // no normal-tangential coupling) plus a smooth rank-one part.
    let c = 2.0 * 0.91 / (std::f64::consts::PI * 2.1e11);
    let a2 = (0.6 * h) * (0.6 * h);
    let g_res = Mat::from_fn(nb, nb, |r, s| {
        let (k, ka) = (r / 3, r % 3);
        let (l, la) = (s / 3, s % 3);
        if ka != la {
            return 0.0;
        }
        let (dx, dy) = (pos[k].0 - pos[l].0, pos[k].1 - pos[l].1);
        let kern = c / (dx * dx + dy * dy + a2).sqrt();
        let scale = if ka == 0 { 1.0 } else { 0.8 };
        scale * kern + if ka == 0 { 2e-10 } else { 0.0 }
    });
    let outputs = vec![
        RomOutput {
            name: "lower_tip".into(),
            c_eta: (0..m).map(|i| if i % 2 == 0 { 3.8 } else { 0.0 }).collect(),
            c_lambda: (0..nb)
                .map(|r| if r % 3 == 0 { -1e-9 / n as f64 } else { 0.0 })
                .collect(),
        },
        RomOutput {
            name: "upper_tip".into(),
            c_eta: (0..m).map(|i| if i % 2 == 1 { 3.8 } else { 0.0 }).collect(),
            c_lambda: (0..nb)
                .map(|r| if r % 3 == 0 { 1e-9 / n as f64 } else { 0.0 })
                .collect(),
        },
    ];
    rom_from_parts(
        omega,
        vec![0.005; m],
        phi_g,
        g_res,
        beta,
        clearance,
        0.4,
        outputs,
        1,
    )
}

/// Circular frequency of a ROM's reference mode.
pub fn omega_ref(rom: &Rom) -> f64 {
    rom.omega[rom.meta.reference_mode]
}
