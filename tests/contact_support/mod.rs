//! Shared helpers of the contact tests: generators of Delassus matrices and impact-like free
//! velocities, a small dense solver, and the check of the contact law (Signorini + Coulomb)
//! at a computed solution.
#![allow(dead_code)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rigtwin::contact::ContactProblem;

/// A deterministic random generator for test problem number `seed`.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Pair positions of the reference patch: a 12 x 16 grid with spacing `h` (m), row-major.
pub fn patch_positions(h: f64) -> Vec<[f64; 2]> {
    let mut p = Vec::with_capacity(192);
    for i in 0..12 {
        for j in 0..16 {
            p.push([i as f64 * h, j as f64 * h]);
        }
    }
    p
}

/// A random symmetric positive semidefinite 3x3 matrix `B B^T` with B near `diag(1, s, s)`:
/// couples normal and tangential directions.
fn coupled_block(rng: &mut ChaCha8Rng, s: f64, coupling: f64) -> [[f64; 3]; 3] {
    let mut b = [[0.0; 3]; 3];
    for (i, row) in b.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            let base = if i == j {
                if i == 0 {
                    1.0
                } else {
                    s
                }
            } else {
                0.0
            };
            *x = base + coupling * rng.gen_range(-1.0..1.0);
        }
    }
    let mut a = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            a[i][j] = (0..3).map(|k| b[i][k] * b[j][k]).sum();
        }
    }
    a
}

/// A Delassus matrix shaped like `G_res / dt` of a contact patch (m/s/N), row-major 3n x 3n,
/// for the pairs at `positions` (m): a local compliance per node, an exponential (short-range,
/// Boussinesq-like) and a Gaussian (long-range, bending-like) kernel, each coupling the normal
/// and tangential directions through a random 3x3 block, and a rigid tilt of the patch in the
/// normal direction. Every term is positive (semi)definite, the local one definite.
pub fn physical_delassus(rng: &mut ChaCha8Rng, positions: &[[f64; 2]], h: f64) -> Vec<f64> {
    let n = positions.len();
    let d = 3 * n;
    let dt = 1e-5; // s
    let g0 = 2e-9; // m/N, order of a node's flexibility on a steel patch
    let local = [1.0, rng.gen_range(0.6..1.0), rng.gen_range(0.6..1.0)];
    let a1 = coupled_block(rng, 0.8, 0.15);
    let a2 = coupled_block(rng, 0.5, 0.25);
    let l1 = h * rng.gen_range(0.8..2.5);
    let l2 = h * rng.gen_range(4.0..12.0);
    let k1 = rng.gen_range(0.5..2.0);
    let k2 = rng.gen_range(0.2..1.5);
    let tilt = rng.gen_range(0.0..0.5) / (h * h * 64.0);
    let mut w = vec![0.0; d * d];
    for p in 0..n {
        for q in 0..n {
            let dx = positions[p][0] - positions[q][0];
            let dy = positions[p][1] - positions[q][1];
            let r2 = dx * dx + dy * dy;
            let e1 = k1 * (-r2.sqrt() / l1).exp();
            let e2 = k2 * (-r2 / (l2 * l2)).exp();
            for a in 0..3 {
                for b in 0..3 {
                    let mut v = e1 * a1[a][b] + e2 * a2[a][b];
                    if a == 0 && b == 0 {
                        v += tilt
                            * (positions[p][0] * positions[q][0]
                                + positions[p][1] * positions[q][1]);
                    }
                    if p == q && a == b {
                        v += local[a];
                    }
                    w[(3 * p + a) * d + 3 * q + b] = g0 / dt * v;
                }
            }
        }
    }
    // Exact symmetry (the kernel terms are symmetric up to the order of products).
    for i in 0..d {
        for j in i + 1..d {
            let s = 0.5 * (w[i * d + j] + w[j * d + i]);
            w[i * d + j] = s;
            w[j * d + i] = s;
        }
    }
    w
}

/// Free gap velocities of an impact (m/s): approach with a tilt and curvature over the
/// positions, so some pairs separate, plus a tangential slide with a rotation about the patch
/// centre, so some pairs stick and some slip.
pub fn impact_velocity(rng: &mut ChaCha8Rng, positions: &[[f64; 2]], h: f64) -> Vec<f64> {
    let n = positions.len();
    let cx = positions.iter().map(|p| p[0]).sum::<f64>() / n as f64;
    let cy = positions.iter().map(|p| p[1]).sum::<f64>() / n as f64;
    let v0 = rng.gen_range(0.02..0.2); // approach speed, m/s
    let tilt = [rng.gen_range(-1.5..1.5), rng.gen_range(-1.5..1.5)];
    let curvature = rng.gen_range(0.0..0.05);
    // Tangential speed relative to the approach: below about mu the patch mostly sticks,
    // above it slides; draw both regimes.
    let ratio = if rng.gen_bool(0.5) {
        rng.gen_range(0.0..0.25)
    } else {
        rng.gen_range(0.25..0.8)
    };
    let angle = rng.gen_range(0.0..std::f64::consts::TAU);
    let slide = [v0 * ratio * angle.cos(), v0 * ratio * angle.sin()];
    let spin = v0 * rng.gen_range(-0.1..0.1) / (8.0 * h);
    let mut c = Vec::with_capacity(3 * n);
    for p in positions {
        let x = (p[0] - cx) / (8.0 * h);
        let y = (p[1] - cy) / (8.0 * h);
        let cn = -v0 * (1.0 + tilt[0] * x + tilt[1] * y - curvature * (x * x + y * y))
            + 0.05 * v0 * rng.gen_range(-1.0..1.0);
        c.push(cn);
        c.push(slide[0] - spin * (p[1] - cy));
        c.push(slide[1] + spin * (p[0] - cx));
    }
    c
}

/// A physically shaped problem: `n_pairs` pairs forming a compact region of the 12 x 16 patch
/// (a rectangle of grid rows and columns, trimmed to `n_pairs`), friction 0.4.
pub fn physical_problem(seed: u64, n_pairs: usize) -> ContactProblem {
    assert!((1..=192).contains(&n_pairs));
    let mut r = rng(seed);
    let h = 6e-3 / 15.0; // 16 nodes over the 6 mm long edge
    let all = patch_positions(h);
    let cols = ((n_pairs as f64 * 16.0 / 12.0).sqrt().ceil() as usize).clamp(1, 16);
    let rows = n_pairs.div_ceil(cols).min(12);
    let (r0, c0) = (r.gen_range(0..=12 - rows), r.gen_range(0..=16 - cols));
    let mut positions = Vec::with_capacity(n_pairs);
    'fill: for i in r0..r0 + rows {
        for j in c0..c0 + cols {
            if positions.len() == n_pairs {
                break 'fill;
            }
            positions.push(all[i * 16 + j]);
        }
    }
    assert_eq!(positions.len(), n_pairs);
    let w = physical_delassus(&mut r, &positions, h);
    let c = impact_velocity(&mut r, &positions, h);
    ContactProblem {
        w,
        c,
        mu: vec![0.4; n_pairs],
        label: format!("physical seed {seed}, {n_pairs} pairs"),
    }
}

/// A generic dense SPD problem: `W = B B^T / (3n) + delta I` with B uniform in [-1, 1],
/// normal `c` uniform in [-1.3, 0.7], tangential in [-0.3, 0.3], friction `mu`.
pub fn random_spd_problem(seed: u64, n_pairs: usize, mu: f64, delta: f64) -> ContactProblem {
    let mut r = rng(seed);
    let d = 3 * n_pairs;
    let b: Vec<f64> = (0..d * d).map(|_| r.gen_range(-1.0..1.0)).collect();
    let mut w = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let s: f64 = (0..d).map(|k| b[i * d + k] * b[j * d + k]).sum::<f64>() / d as f64
                + if i == j { delta } else { 0.0 };
            w[i * d + j] = s;
            w[j * d + i] = s;
        }
    }
    let c = (0..d)
        .map(|i| {
            if i % 3 == 0 {
                r.gen_range(-1.0..1.0) - 0.3
            } else {
                0.3 * r.gen_range(-1.0..1.0)
            }
        })
        .collect();
    ContactProblem {
        w,
        c,
        mu: vec![mu; n_pairs],
        label: format!("random SPD seed {seed}"),
    }
}

/// `W x + c` for a row-major square W.
pub fn apply(w: &[f64], x: &[f64], c: &[f64]) -> Vec<f64> {
    let d = x.len();
    (0..d)
        .map(|i| c[i] + (0..d).map(|j| w[i * d + j] * x[j]).sum::<f64>())
        .collect()
}

/// Solves the dense system `a x = b` (row-major k x k) by Gaussian elimination with partial
/// pivoting; None when singular.
pub fn dense_solve(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let k = b.len();
    let mut m = a.to_vec();
    let mut x = b.to_vec();
    for col in 0..k {
        let piv =
            (col..k).max_by(|&i, &j| m[i * k + col].abs().total_cmp(&m[j * k + col].abs()))?;
        if m[piv * k + col].abs() < 1e-300 {
            return None;
        }
        if piv != col {
            for j in 0..k {
                m.swap(piv * k + j, col * k + j);
            }
            x.swap(piv, col);
        }
        for i in col + 1..k {
            let f = m[i * k + col] / m[col * k + col];
            for j in col..k {
                m[i * k + j] -= f * m[col * k + j];
            }
            x[i] -= f * x[col];
        }
    }
    for col in (0..k).rev() {
        let s: f64 = (col + 1..k).map(|j| m[col * k + j] * x[j]).sum();
        x[col] = (x[col] - s) / m[col * k + col];
    }
    Some(x)
}

/// Largest violation of the contact law at (lambda, gamma = W lambda + c), each condition
/// normalised by the problem's force scale F = max |lambda| and velocity scale
/// V = max |c|: lambda_n >= 0, gamma_n >= 0, lambda_n gamma_n = 0, |lambda_t| <= mu lambda_n,
/// gamma_t antiparallel to lambda_t, and gamma_t = 0 unless |lambda_t| = mu lambda_n.
/// Gamma is recomputed from lambda, so the solver's own gamma is not trusted.
pub fn law_violation(problem: &ContactProblem, lambda: &[f64]) -> f64 {
    let gamma = apply(&problem.w, lambda, &problem.c);
    let f = lambda
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(1e-300);
    let v = problem
        .c
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(1e-300);
    let mut worst = 0.0f64;
    for (k, &mu) in problem.mu.iter().enumerate() {
        let l = &lambda[3 * k..3 * k + 3];
        let g = &gamma[3 * k..3 * k + 3];
        let lt = l[1].hypot(l[2]);
        let gt = g[1].hypot(g[2]);
        let slack = mu * l[0] - lt; // >= 0, zero on the rim
        let checks = [
            -l[0] / f,
            -g[0] / v,
            (l[0] * g[0]).abs() / (f * v),
            -slack / f,
            // antiparallel: cross product zero, dot product not positive
            (l[1] * g[2] - l[2] * g[1]).abs() / (f * v),
            (l[1] * g[1] + l[2] * g[2]) / (f * v),
            // no sliding inside the disk (only for pairs with normal force)
            if l[0] > 0.0 {
                slack.max(0.0) * gt / (f * v)
            } else {
                0.0
            },
        ];
        for x in checks {
            worst = worst.max(x);
        }
    }
    worst
}

/// The Python that runs the Siconos peer script: `$RIGTWIN_SICONOS_PYTHON`, else
/// `/usr/bin/python3` (Debian's python3-siconos loads there).
pub fn siconos_python() -> String {
    std::env::var("RIGTWIN_SICONOS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".to_string())
}

/// The Siconos fc3d NSGS peer script.
pub fn siconos_script() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/siconos/solve_fc3d.py")
}

/// Whether siconos is importable by `python`; the reason when not.
pub fn siconos_available(python: &str) -> Result<(), String> {
    match std::process::Command::new(python)
        .args(["-c", "import siconos.numerics"])
        .output()
    {
        Ok(out) if out.status.success() => Ok(()),
        Ok(out) => Err(format!(
            "{python} cannot import siconos.numerics: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("no message")
        )),
        Err(e) => Err(format!("cannot run {python}: {e}")),
    }
}

/// The Python to run the peer with, or `None` after printing why test `name` is skipped.
/// Panics instead of skipping when `RIGTWIN_REQUIRE_SICONOS` is set (CI).
pub fn siconos_or_skip(name: &str) -> Option<String> {
    let python = siconos_python();
    match siconos_available(&python) {
        Ok(()) => Some(python),
        Err(why) if std::env::var_os("RIGTWIN_REQUIRE_SICONOS").is_some() => {
            panic!("RIGTWIN_REQUIRE_SICONOS is set but {why}")
        }
        Err(why) => {
            eprintln!("SKIPPED {name}: {why}");
            None
        }
    }
}

/// CPU time of the calling thread, s (Linux; `None` elsewhere): timings that the load of a
/// shared machine does not enter.
#[cfg(target_os = "linux")]
pub fn thread_cpu_seconds() -> Option<f64> {
    #[repr(C)]
    struct Timespec {
        tv_sec: i64,
        tv_nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec (two 64-bit fields on 64-bit Linux) into `t`.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    (rc == 0).then_some(t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64)
}

#[cfg(not(target_os = "linux"))]
pub fn thread_cpu_seconds() -> Option<f64> {
    None
}
