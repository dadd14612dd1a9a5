//! 8-node hex shape functions and element matrices for isotropic linear elasticity: plain
//! trilinear with full 2x2x2 Gauss integration ([`ElementKind::Hex8`], CalculiX C3D8) and
//! the Wilson-Taylor incompatible-mode element ([`ElementKind::Hex8I`], CalculiX C3D8I)
//! whose nine bubble DOFs are condensed per element (stiffness exactly, the bubble inertia
//! with the static bubble response; see [`hex8i_matrices`]).
//!
//! Element DOFs are node-major: node 0 x, y, z, node 1 x, y, z, ... (24 DOFs). All routines
//! work on fixed-size arrays and never allocate.

// Index loops over small fixed-size matrices read like the formulas they implement.
#![allow(clippy::needless_range_loop)]

use crate::config::ElementKind;

/// Natural coordinates of the 8 corner nodes in CalculiX/Abaqus order.
pub const CORNERS: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// Trilinear shape functions N_a(xi, eta, zeta).
pub fn shape_functions(xi: f64, eta: f64, zeta: f64) -> [f64; 8] {
    CORNERS.map(|c| 0.125 * (1.0 + c[0] * xi) * (1.0 + c[1] * eta) * (1.0 + c[2] * zeta))
}

/// Derivatives dN_a/d(xi, eta, zeta), one row per node.
pub fn shape_derivatives(xi: f64, eta: f64, zeta: f64) -> [[f64; 3]; 8] {
    CORNERS.map(|c| {
        [
            0.125 * c[0] * (1.0 + c[1] * eta) * (1.0 + c[2] * zeta),
            0.125 * c[1] * (1.0 + c[0] * xi) * (1.0 + c[2] * zeta),
            0.125 * c[2] * (1.0 + c[0] * xi) * (1.0 + c[1] * eta),
        ]
    })
}

/// A 24 x 24 element matrix on the element DOFs (node-major: node 0 x, y, z, node 1 ...).
pub type ElementMatrix = [[f64; 24]; 24];

/// Isotropic linear-elastic constants as the element routines need them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isotropic {
    /// Young's modulus E, Pa.
    pub youngs_modulus: f64,
    /// Poisson's ratio nu, -, in (-1, 0.5).
    pub poisson_ratio: f64,
    /// Mass density rho, kg/m^3.
    pub density: f64,
}

impl Isotropic {
    /// Lame constants (lambda, mu), Pa.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let mu = e / (2.0 * (1.0 + nu));
        let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        (lambda, mu)
    }
}

/// Why an element matrix could not be formed. The caller adds the element index and block.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ElementError {
    /// The Jacobian determinant is zero, negative or not finite at a point of the element
    /// (inverted, degenerate or wrongly numbered element).
    #[error(
        "non-positive Jacobian determinant {det:e} at natural point ({:.3}, {:.3}, {:.3}); \
         expected a positive volume with nodes in CalculiX order",
        point[0], point[1], point[2]
    )]
    NonPositiveJacobian {
        /// Determinant of dx/dxi, m^3.
        det: f64,
        /// Natural coordinates (xi, eta, zeta) of the point.
        point: [f64; 3],
    },
    /// The bubble-mode stiffness of a C3D8I element is not positive definite (degenerate
    /// element or invalid material constants).
    #[error("the incompatible-mode stiffness is not positive definite (degenerate element?)")]
    SingularIncompatibleModes,
}

/// The 2x2x2 Gauss points (all weights 1).
fn gauss_points() -> [[f64; 3]; 8] {
    let g = 1.0 / 3f64.sqrt();
    CORNERS.map(|c| [c[0] * g, c[1] * g, c[2] * g])
}

/// Jacobian `j[r][c] = dx_c / dxi_r` from natural derivatives and nodal coordinates.
fn jacobian(d: &[[f64; 3]; 8], x: &[[f64; 3]; 8]) -> [[f64; 3]; 3] {
    let mut j = [[0.0; 3]; 3];
    for (da, xa) in d.iter().zip(x) {
        for r in 0..3 {
            for c in 0..3 {
                j[r][c] += da[r] * xa[c];
            }
        }
    }
    j
}

/// Inverse of a 3x3 matrix with known determinant.
fn inverse(j: &[[f64; 3]; 3], det: f64) -> [[f64; 3]; 3] {
    let inv = 1.0 / det;
    [
        [
            (j[1][1] * j[2][2] - j[1][2] * j[2][1]) * inv,
            (j[0][2] * j[2][1] - j[0][1] * j[2][2]) * inv,
            (j[0][1] * j[1][2] - j[0][2] * j[1][1]) * inv,
        ],
        [
            (j[1][2] * j[2][0] - j[1][0] * j[2][2]) * inv,
            (j[0][0] * j[2][2] - j[0][2] * j[2][0]) * inv,
            (j[0][2] * j[1][0] - j[0][0] * j[1][2]) * inv,
        ],
        [
            (j[1][0] * j[2][1] - j[1][1] * j[2][0]) * inv,
            (j[0][1] * j[2][0] - j[0][0] * j[2][1]) * inv,
            (j[0][0] * j[1][1] - j[0][1] * j[1][0]) * inv,
        ],
    ]
}

/// Physical gradient `J^-1 dN/dxi` of one function.
fn map_gradient(jinv: &[[f64; 3]; 3], d: &[f64; 3]) -> [f64; 3] {
    [
        jinv[0][0] * d[0] + jinv[0][1] * d[1] + jinv[0][2] * d[2],
        jinv[1][0] * d[0] + jinv[1][1] * d[1] + jinv[1][2] * d[2],
        jinv[2][0] * d[0] + jinv[2][1] * d[1] + jinv[2][2] * d[2],
    ]
}

/// Natural derivatives of the shape functions, Jacobian determinant and inverse Jacobian.
type PointJacobian = ([[f64; 3]; 8], f64, [[f64; 3]; 3]);

/// Jacobian, its determinant (checked positive) and its inverse at a natural point.
fn checked_jacobian(x: &[[f64; 3]; 8], p: [f64; 3]) -> Result<PointJacobian, ElementError> {
    let d = shape_derivatives(p[0], p[1], p[2]);
    let j = jacobian(&d, x);
    let det = det3(&j);
    // NaN fails this test too.
    if !(det > 0.0 && det.is_finite()) {
        return Err(ElementError::NonPositiveJacobian { det, point: p });
    }
    Ok((d, det, inverse(&j, det)))
}

/// The 3x3 stiffness block of two functions with physical gradients `ga`, `gb` (per unit
/// volume): `k_ij = lambda ga_i gb_j + mu ga_j gb_i + mu (ga . gb) delta_ij`.
#[inline]
fn block(lambda: f64, mu: f64, ga: &[f64; 3], gb: &[f64; 3]) -> [[f64; 3]; 3] {
    let dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
    let mut k = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            k[i][j] = lambda * ga[i] * gb[j] + mu * ga[j] * gb[i];
        }
        k[i][i] += mu * dot;
    }
    k
}

/// Stiffness (N/m) and mass (kg) of one element on its 24 DOFs.
#[derive(Clone, Debug)]
pub struct ElementMatrices {
    /// Stiffness matrix, N/m.
    pub stiffness: ElementMatrix,
    /// Mass matrix, kg.
    pub mass: ElementMatrix,
}

/// Stiffness and mass of a hex of `kind` with corner coordinates `x` (m, CalculiX order):
/// [`hex8_stiffness`] with [`consistent_mass`] for C3D8, [`hex8i_matrices`] for C3D8I.
pub fn element_matrices(
    kind: ElementKind,
    x: &[[f64; 3]; 8],
    material: &Isotropic,
) -> Result<ElementMatrices, ElementError> {
    match kind {
        ElementKind::Hex8 => Ok(ElementMatrices {
            stiffness: hex8_stiffness(x, material)?,
            mass: consistent_mass(x, material.density)?,
        }),
        ElementKind::Hex8I => hex8i_matrices(x, material),
    }
}

/// Element stiffness matrix, N/m, of a hex of `kind` with corner coordinates `x` (m).
pub fn stiffness(
    kind: ElementKind,
    x: &[[f64; 3]; 8],
    material: &Isotropic,
) -> Result<ElementMatrix, ElementError> {
    match kind {
        ElementKind::Hex8 => hex8_stiffness(x, material),
        ElementKind::Hex8I => Ok(hex8i_matrices(x, material)?.stiffness),
    }
}

/// C3D8 stiffness: trilinear, full 2x2x2 Gauss integration.
pub fn hex8_stiffness(
    x: &[[f64; 3]; 8],
    material: &Isotropic,
) -> Result<ElementMatrix, ElementError> {
    let (lambda, mu) = material.lame();
    let mut k = [[0.0; 24]; 24];
    for p in gauss_points() {
        let (d, det, jinv) = checked_jacobian(x, p)?;
        let g = d.map(|da| map_gradient(&jinv, &da));
        for a in 0..8 {
            for b in a..8 {
                let kab = block(lambda * det, mu * det, &g[a], &g[b]);
                for i in 0..3 {
                    for j in 0..3 {
                        k[3 * a + i][3 * b + j] += kab[i][j];
                    }
                }
            }
        }
    }
    mirror_upper(&mut k);
    Ok(k)
}

/// C3D8I stiffness and mass: the trilinear field plus the bubbles (1 - xi^2), (1 - eta^2),
/// (1 - zeta^2) per displacement component (9 internal DOFs), condensed per element with
/// the static bubble response `alpha = T u`, `T = -Kaa^-1 Kau`:
/// `K = Kuu - Kua Kaa^-1 Kau` (exact static condensation) and
/// `M = Muu + Mua T + T^T Mau + T^T Maa T`.
///
/// NOTE: Taylor's correction: the bubble gradients use the inverse Jacobian at the element
/// centre and are scaled by detJ0 / detJ, so that `int grad(bubble) dV = 0` on any
/// trilinear geometry and the element passes the constant-strain patch test. CalculiX maps
/// with the centre Jacobian but does not scale; both agree exactly on parallelepipeds.
///
/// NOTE: mass. CalculiX (2.20) integrates the bubbles into the C3D8I mass (2x2x2 Gauss) and
/// keeps the 9 bubble DOFs as dynamic DOFs. Condensing that mass with the static bubble
/// response keeps 24 DOFs per element and reproduces CalculiX's frequencies of the 60x4x2
/// steel cantilever within 0.1 % up to 11 kHz (200 f1), where the mass of the trilinear part
/// alone is up to 1.4 % stiffer there. Rigid translations carry no bubbles (T r = 0), so
/// the mass still sums to rho V per direction.
pub fn hex8i_matrices(
    x: &[[f64; 3]; 8],
    material: &Isotropic,
) -> Result<ElementMatrices, ElementError> {
    let IncompatibleParts { kuu, kua, kaa } = hex8i_parts(x, material)?;
    let t = static_bubble_response(&kua, &kaa)?;

    let mut k = kuu;
    for a in 0..24 {
        for b in a..24 {
            // Kua T is symmetric in exact arithmetic; average the two triangles.
            let ab: f64 = (0..9).map(|r| kua[a][r] * t[r][b]).sum();
            let ba: f64 = (0..9).map(|r| kua[b][r] * t[r][a]).sum();
            k[a][b] += 0.5 * (ab + ba);
            k[b][a] = k[a][b];
        }
    }

    let ms = bubble_scalar_mass(x, material.density)?;
    let mut m = [[0.0; 24]; 24];
    for a in 0..8 {
        for b in 0..8 {
            for i in 0..3 {
                m[3 * a + i][3 * b + i] = ms[a][b];
            }
        }
    }
    // (Mua T)[3a+i][c] = sum_k ms[a][8+k] t[3k+i][c];  (Maa T)[3k+i][c] likewise.
    let mut mua_t = [[0.0; 24]; 24];
    for a in 0..8 {
        for i in 0..3 {
            for c in 0..24 {
                mua_t[3 * a + i][c] = (0..3).map(|q| ms[a][8 + q] * t[3 * q + i][c]).sum();
            }
        }
    }
    let mut maa_t = [[0.0; 24]; 9];
    for k in 0..3 {
        for i in 0..3 {
            for c in 0..24 {
                maa_t[3 * k + i][c] = (0..3).map(|q| ms[8 + k][8 + q] * t[3 * q + i][c]).sum();
            }
        }
    }
    for r in 0..24 {
        for c in r..24 {
            let tmt: f64 = (0..9)
                .map(|q| 0.5 * (t[q][r] * maa_t[q][c] + t[q][c] * maa_t[q][r]))
                .sum();
            m[r][c] += mua_t[r][c] + mua_t[c][r] + tmt;
            m[c][r] = m[r][c];
        }
    }
    Ok(ElementMatrices {
        stiffness: k,
        mass: m,
    })
}

/// Uncondensed C3D8I stiffness: trilinear part `kuu`, coupling `kua` to the bubble DOFs and
/// bubble part `kaa`; bubble q (0: 1 - xi^2, 1: 1 - eta^2, 2: 1 - zeta^2) owns the bubble
/// DOFs 3q..3q+3 (x, y, z).
struct IncompatibleParts {
    kuu: ElementMatrix,
    kua: [[f64; 9]; 24],
    kaa: [[f64; 9]; 9],
}

/// The uncondensed C3D8I stiffness with Taylor's correction (see [`hex8i_matrices`]).
fn hex8i_parts(x: &[[f64; 3]; 8], material: &Isotropic) -> Result<IncompatibleParts, ElementError> {
    let (lambda, mu) = material.lame();
    let (_, det0, jinv0) = checked_jacobian(x, [0.0; 3])?;
    let mut kuu = [[0.0; 24]; 24];
    let mut kua = [[0.0; 9]; 24];
    let mut kaa = [[0.0; 9]; 9];
    for p in gauss_points() {
        let (d, det, jinv) = checked_jacobian(x, p)?;
        let g = d.map(|da| map_gradient(&jinv, &da));
        let scale = det0 / det;
        let h: [[f64; 3]; 3] = std::array::from_fn(|q| {
            let mut db = [0.0; 3];
            db[q] = -2.0 * p[q];
            map_gradient(&jinv0, &db).map(|v| v * scale)
        });
        for a in 0..8 {
            for b in a..8 {
                let kab = block(lambda * det, mu * det, &g[a], &g[b]);
                for i in 0..3 {
                    for j in 0..3 {
                        kuu[3 * a + i][3 * b + j] += kab[i][j];
                    }
                }
            }
            for (qb, hb) in h.iter().enumerate() {
                let kab = block(lambda * det, mu * det, &g[a], hb);
                for i in 0..3 {
                    for j in 0..3 {
                        kua[3 * a + i][3 * qb + j] += kab[i][j];
                    }
                }
            }
        }
        for qa in 0..3 {
            for qb in qa..3 {
                let kab = block(lambda * det, mu * det, &h[qa], &h[qb]);
                for i in 0..3 {
                    for j in 0..3 {
                        kaa[3 * qa + i][3 * qb + j] += kab[i][j];
                    }
                }
            }
        }
    }
    mirror_upper(&mut kuu);
    for r in 0..9 {
        for c in 0..r {
            kaa[r][c] = kaa[c][r];
        }
    }
    Ok(IncompatibleParts { kuu, kua, kaa })
}

/// `T = -Kaa^-1 Kau` (9 x 24): the bubble amplitudes that minimise the energy for given
/// nodal displacements.
fn static_bubble_response(
    kua: &[[f64; 9]; 24],
    kaa: &[[f64; 9]; 9],
) -> Result<[[f64; 24]; 9], ElementError> {
    let l = cholesky9(kaa).ok_or(ElementError::SingularIncompatibleModes)?;
    let mut t = [[0.0; 24]; 9];
    for c in 0..24 {
        // Forward L y = Kau[:, c], backward L^T z = y, t = -z.
        let mut y = [0.0; 9];
        for r in 0..9 {
            let mut s = kua[c][r];
            for q in 0..r {
                s -= l[r][q] * y[q];
            }
            y[r] = s / l[r][r];
        }
        let mut z = [0.0; 9];
        for r in (0..9).rev() {
            let mut s = y[r];
            for q in r + 1..9 {
                s -= l[q][r] * z[q];
            }
            z[r] = s / l[r][r];
        }
        for r in 0..9 {
            t[r][c] = -z[r];
        }
    }
    Ok(t)
}

/// Scalar mass of the 8 trilinear functions and the 3 bubbles (1 - xi^2), (1 - eta^2),
/// (1 - zeta^2), kg, 2x2x2 Gauss as CalculiX integrates the C3D8I mass.
fn bubble_scalar_mass(x: &[[f64; 3]; 8], density: f64) -> Result<[[f64; 11]; 11], ElementError> {
    let mut m = [[0.0; 11]; 11];
    for p in gauss_points() {
        let (_, det, _) = checked_jacobian(x, p)?;
        let n8 = shape_functions(p[0], p[1], p[2]);
        let mut n = [0.0; 11];
        n[..8].copy_from_slice(&n8);
        for q in 0..3 {
            n[8 + q] = 1.0 - p[q] * p[q];
        }
        for a in 0..11 {
            for b in a..11 {
                m[a][b] += density * det * n[a] * n[b];
            }
        }
    }
    for a in 0..11 {
        for b in 0..a {
            m[a][b] = m[b][a];
        }
    }
    Ok(m)
}

/// Lower Cholesky factor of a symmetric 9x9 matrix; `None` if not positive definite.
fn cholesky9(a: &[[f64; 9]; 9]) -> Option<[[f64; 9]; 9]> {
    let mut l = [[0.0; 9]; 9];
    for j in 0..9 {
        let mut d = a[j][j];
        for q in 0..j {
            d -= l[j][q] * l[j][q];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let djj = d.sqrt();
        l[j][j] = djj;
        for i in j + 1..9 {
            let mut s = a[i][j];
            for q in 0..j {
                s -= l[i][q] * l[j][q];
            }
            l[i][j] = s / djj;
        }
    }
    Some(l)
}

/// Copies the upper triangle onto the lower one.
fn mirror_upper(k: &mut ElementMatrix) {
    for r in 0..24 {
        for c in 0..r {
            k[r][c] = k[c][r];
        }
    }
}

/// Consistent mass per direction, kg: `m_ab = rho int N_a N_b dV` (trilinear shape
/// functions, 2x2x2 Gauss, exact for trilinear geometry). The C3D8 mass matrix is
/// `m_ab * I_3` on the DOFs of nodes a and b.
pub fn scalar_mass(x: &[[f64; 3]; 8], density: f64) -> Result<[[f64; 8]; 8], ElementError> {
    let mut m = [[0.0; 8]; 8];
    for p in gauss_points() {
        let (_, det, _) = checked_jacobian(x, p)?;
        let n = shape_functions(p[0], p[1], p[2]);
        let w = density * det;
        for a in 0..8 {
            for b in a..8 {
                m[a][b] += w * n[a] * n[b];
            }
        }
    }
    for a in 0..8 {
        for b in 0..a {
            m[a][b] = m[b][a];
        }
    }
    Ok(m)
}

/// C3D8 consistent mass matrix on the 24 element DOFs, kg ([`scalar_mass`] times I_3).
pub fn consistent_mass(x: &[[f64; 3]; 8], density: f64) -> Result<ElementMatrix, ElementError> {
    let s = scalar_mass(x, density)?;
    let mut m = [[0.0; 24]; 24];
    for a in 0..8 {
        for b in 0..8 {
            for i in 0..3 {
                m[3 * a + i][3 * b + i] = s[a][b];
            }
        }
    }
    Ok(m)
}

/// Volume of a trilinear hex from its 8 corner coordinates (2x2x2 Gauss, exact for
/// trilinear geometry).
pub fn hex_volume(x: &[[f64; 3]; 8]) -> f64 {
    let g = 1.0 / 3f64.sqrt();
    let mut v = 0.0;
    for &xi in &[-g, g] {
        for &eta in &[-g, g] {
            for &zeta in &[-g, g] {
                let d = shape_derivatives(xi, eta, zeta);
                let mut j = [[0.0; 3]; 3];
                for (a, xa) in x.iter().enumerate() {
                    for r in 0..3 {
                        for c in 0..3 {
                            j[r][c] += d[a][r] * xa[c];
                        }
                    }
                }
                v += det3(&j);
            }
        }
    }
    v
}

/// Determinant of a 3x3 matrix.
pub fn det3(j: &[[f64; 3]; 3]) -> f64 {
    j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1])
        - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
        + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::{Mat, Side};

    const STEEL: Isotropic = Isotropic {
        youngs_modulus: 210e9,
        poisson_ratio: 0.3,
        density: 7850.0,
    };

    /// Box element [0, a] x [0, b] x [0, c].
    fn brick(a: f64, b: f64, c: f64) -> [[f64; 3]; 8] {
        CORNERS.map(|n| {
            [
                0.5 * a * (1.0 + n[0]),
                0.5 * b * (1.0 + n[1]),
                0.5 * c * (1.0 + n[2]),
            ]
        })
    }

    /// A visibly distorted (non-parallelepiped, still convex) element.
    fn distorted() -> [[f64; 3]; 8] {
        [
            [0.0, 0.0, 0.0],
            [2.2, 0.1, -0.2],
            [2.0, 1.3, 0.1],
            [-0.3, 0.9, 0.0],
            [0.2, -0.1, 1.1],
            [1.9, 0.2, 0.8],
            [2.4, 1.1, 1.3],
            [0.1, 1.2, 0.9],
        ]
    }

    fn eigenvalues(k: &ElementMatrix) -> Vec<f64> {
        let m = Mat::from_fn(24, 24, |i, j| k[i][j]);
        m.self_adjoint_eigenvalues(Side::Lower)
            .expect("eigenvalues")
    }

    fn max_asymmetry(k: &ElementMatrix) -> f64 {
        let scale = k.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        let mut worst = 0.0f64;
        for r in 0..24 {
            for c in 0..24 {
                worst = worst.max((k[r][c] - k[c][r]).abs() / scale);
            }
        }
        worst
    }

    fn apply(k: &ElementMatrix, u: &[f64; 24]) -> [f64; 24] {
        std::array::from_fn(|r| (0..24).map(|c| k[r][c] * u[c]).sum())
    }

    fn rigid_and_elastic_spectrum(x: &[[f64; 3]; 8], kind: ElementKind) {
        let k = stiffness(kind, x, &STEEL).expect("valid element");
        let ev = eigenvalues(&k);
        let max = ev[23];
        for (i, &e) in ev.iter().enumerate().take(6) {
            assert!(
                e.abs() < 1e-10 * max,
                "{kind:?}: eigenvalue {i} = {e:e} (max {max:e})"
            );
        }
        assert!(
            ev[6] > 1e-4 * max,
            "{kind:?}: spurious zero-energy mode, 7th eigenvalue {:e} (max {max:e})",
            ev[6]
        );
    }

    #[test]
    fn six_rigid_body_modes_and_no_spurious_ones() {
        for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
            rigid_and_elastic_spectrum(&brick(0.01, 0.004, 0.003), kind);
            rigid_and_elastic_spectrum(&distorted(), kind);
        }
    }

    #[test]
    fn rigid_body_motion_has_zero_force() {
        let x = distorted();
        for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
            let k = stiffness(kind, &x, &STEEL).unwrap();
            let scale = k.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
            // Small rotation about an arbitrary axis plus a translation.
            let w = [0.3, -0.7, 0.2];
            let mut u = [0.0; 24];
            for (a, xa) in x.iter().enumerate() {
                let rot = [
                    w[1] * xa[2] - w[2] * xa[1],
                    w[2] * xa[0] - w[0] * xa[2],
                    w[0] * xa[1] - w[1] * xa[0],
                ];
                for i in 0..3 {
                    u[3 * a + i] = rot[i] + 0.1 * (i as f64 + 1.0);
                }
            }
            let f = apply(&k, &u);
            let fmax = f.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(
                fmax < 1e-12 * scale,
                "{kind:?}: rigid motion force {fmax:e}"
            );
        }
    }

    #[test]
    fn matrices_are_symmetric() {
        for x in [brick(0.02, 0.005, 0.003), distorted()] {
            for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
                let k = stiffness(kind, &x, &STEEL).unwrap();
                assert!(max_asymmetry(&k) < 1e-14, "{kind:?}");
            }
            for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
                let m = element_matrices(kind, &x, &STEEL).unwrap().mass;
                assert!(max_asymmetry(&m) < 1e-15, "{kind:?}");
            }
        }
    }

    #[test]
    fn mass_sums_to_rho_v_per_direction_and_is_positive_definite() {
        for x in [brick(0.02, 0.005, 0.003), distorted()] {
            let rho_v = 7850.0 * hex_volume(&x);
            for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
                let m = element_matrices(kind, &x, &STEEL).unwrap().mass;
                // r_d^T M r_e = rho V delta_de for the unit translations r_d.
                for d in 0..3 {
                    for e in 0..3 {
                        let s: f64 = (0..8)
                            .flat_map(|a| (0..8).map(move |b| (a, b)))
                            .map(|(a, b)| m[3 * a + d][3 * b + e])
                            .sum();
                        let expected = if d == e { rho_v } else { 0.0 };
                        assert!(
                            (s - expected).abs() < 1e-12 * rho_v,
                            "{kind:?} ({d}, {e}): {s} vs {expected}"
                        );
                    }
                }
                let ev = eigenvalues(&m);
                assert!(
                    ev[0] > 1e-4 * ev[23],
                    "{kind:?}: mass not positive definite {ev:?}"
                );
            }
            // C3D8: no coupling between directions at all.
            let m = consistent_mass(&x, 7850.0).unwrap();
            let cross: f64 = (0..24)
                .flat_map(|r| (0..24).map(move |c| (r, c)))
                .filter(|(r, c)| r % 3 != c % 3)
                .map(|(r, c)| m[r][c].abs())
                .sum();
            assert_eq!(cross, 0.0);
        }
    }

    /// Linear field u = A x + c: a single element must return exactly the nodal forces of
    /// the constant stress, `f_a = int sigma grad(N_a) dV`, so the bubbles stay unloaded.
    #[test]
    fn linear_field_gives_constant_stress_forces() {
        let x = distorted();
        let a = [
            [1.0e-3, 2.0e-4, -3.0e-4],
            [5.0e-4, -7.0e-4, 1.0e-4],
            [-2.0e-4, 3.0e-4, 9.0e-4],
        ];
        let mut u = [0.0; 24];
        for (n, xn) in x.iter().enumerate() {
            for i in 0..3 {
                u[3 * n + i] = a[i][0] * xn[0] + a[i][1] * xn[1] + a[i][2] * xn[2] + 1e-3;
            }
        }
        let (lambda, mu) = STEEL.lame();
        let tr = a[0][0] + a[1][1] + a[2][2];
        let sigma: [[f64; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                mu * (a[i][j] + a[j][i]) + if i == j { lambda * tr } else { 0.0 }
            })
        });
        let mut expected = [0.0; 24];
        for p in gauss_points() {
            let (d, det, jinv) = checked_jacobian(&x, p).unwrap();
            for (n, dn) in d.iter().enumerate() {
                let g = map_gradient(&jinv, dn);
                for i in 0..3 {
                    expected[3 * n + i] += det * (0..3).map(|j| sigma[i][j] * g[j]).sum::<f64>();
                }
            }
        }
        let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
            let f = apply(&stiffness(kind, &x, &STEEL).unwrap(), &u);
            for r in 0..24 {
                assert!(
                    (f[r] - expected[r]).abs() < 1e-10 * scale,
                    "{kind:?} dof {r}: {} vs {}",
                    f[r],
                    expected[r]
                );
            }
        }
    }

    /// Patch test: 2 x 2 x 2 distorted elements around one interior node. With a linear
    /// displacement field prescribed on the 26 boundary nodes, the interior node must
    /// follow the field exactly.
    #[test]
    fn patch_test_with_distorted_interior_node() {
        let id = |i: usize, j: usize, k: usize| i + 3 * (j + 3 * k);
        let mut nodes = [[0.0; 3]; 27];
        for k in 0..3 {
            for j in 0..3 {
                for i in 0..3 {
                    // Irregular but valid positions: shift each node by a fixed pattern.
                    let s = ((i * 7 + j * 13 + k * 5) % 11) as f64 / 11.0 - 0.5;
                    nodes[id(i, j, k)] = [
                        i as f64 * 1.0 + 0.15 * s,
                        j as f64 * 0.6 - 0.1 * s,
                        k as f64 * 0.4 + 0.06 * s,
                    ];
                }
            }
        }
        nodes[id(1, 1, 1)] = [1.23, 0.52, 0.47];
        let mut cells = Vec::new();
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    cells.push([
                        id(i, j, k),
                        id(i + 1, j, k),
                        id(i + 1, j + 1, k),
                        id(i, j + 1, k),
                        id(i, j, k + 1),
                        id(i + 1, j, k + 1),
                        id(i + 1, j + 1, k + 1),
                        id(i, j + 1, k + 1),
                    ]);
                }
            }
        }
        let field = |p: [f64; 3]| {
            [
                1e-3 * p[0] - 2e-4 * p[1] + 4e-4 * p[2],
                3e-4 * p[0] + 6e-4 * p[1] - 1e-4 * p[2],
                -5e-4 * p[0] + 2e-4 * p[1] + 8e-4 * p[2],
            ]
        };
        let centre = id(1, 1, 1);
        for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
            // Rows of the interior node: K_ii u_i = -K_ib u_b.
            let mut kii = [[0.0; 3]; 3];
            let mut rhs = [0.0; 3];
            for cell in &cells {
                let x = cell.map(|n| nodes[n]);
                let k = stiffness(kind, &x, &STEEL).unwrap();
                let a = cell.iter().position(|&n| n == centre).unwrap();
                for (b, &nb) in cell.iter().enumerate() {
                    let ub = field(nodes[nb]);
                    for i in 0..3 {
                        for j in 0..3 {
                            if nb == centre {
                                kii[i][j] += k[3 * a + i][3 * b + j];
                            } else {
                                rhs[i] -= k[3 * a + i][3 * b + j] * ub[j];
                            }
                        }
                    }
                }
            }
            let det = det3(&kii);
            let inv = inverse(&kii, det);
            let u = map_gradient(&inv, &rhs);
            let exact = field(nodes[centre]);
            for i in 0..3 {
                assert!(
                    (u[i] - exact[i]).abs() < 1e-10 * 1e-3,
                    "{kind:?} component {i}: {} vs {}",
                    u[i],
                    exact[i]
                );
            }
        }
    }

    /// Pure bending of one slender element (10:1): C3D8I reproduces the exact strain energy
    /// of the Euler-Bernoulli field, C3D8 locks in shear and is far too stiff.
    #[test]
    fn hex8i_bends_exactly_and_hex8_locks() {
        let (l, b, h) = (0.05, 0.02, 0.005);
        let x = CORNERS.map(|n| [0.5 * l * n[0], 0.5 * b * n[1], 0.5 * h * n[2]]);
        let kappa = 0.1;
        let nu = STEEL.poisson_ratio;
        let mut u = [0.0; 24];
        for (a, p) in x.iter().enumerate() {
            let (px, py, pz) = (p[0], p[1], p[2]);
            u[3 * a] = -kappa * px * pz;
            u[3 * a + 1] = nu * kappa * py * pz;
            u[3 * a + 2] = 0.5 * kappa * (px * px + nu * pz * pz - nu * py * py);
        }
        let exact = 0.5 * STEEL.youngs_modulus * kappa * kappa * (b * h * h * h / 12.0) * l;
        let energy = |kind| {
            let k = stiffness(kind, &x, &STEEL).unwrap();
            0.5 * apply(&k, &u)
                .iter()
                .zip(&u)
                .map(|(f, v)| f * v)
                .sum::<f64>()
        };
        let e8i = energy(ElementKind::Hex8I);
        let e8 = energy(ElementKind::Hex8);
        assert!(
            (e8i / exact - 1.0).abs() < 1e-10,
            "C3D8I energy ratio {}",
            e8i / exact
        );
        assert!(
            e8 / exact > 5.0,
            "C3D8 should lock: energy ratio {}",
            e8 / exact
        );
    }

    #[test]
    fn hex8i_stays_stable_on_a_strongly_distorted_element() {
        // A trapezoidal, skewed, warped element with a corner pulled far inwards.
        let mut x = distorted();
        x[6] = [1.2, 0.8, 0.9];
        x[2] = [2.6, 1.6, -0.1];
        rigid_and_elastic_spectrum(&x, ElementKind::Hex8I);
        let k = hex8i_matrices(&x, &STEEL).unwrap().stiffness;
        assert!(k.iter().flatten().all(|v| v.is_finite()));
        // Condensation only softens: K8I <= K8 in the energy sense, checked on the eigenvalues.
        let ev8 = eigenvalues(&hex8_stiffness(&x, &STEEL).unwrap());
        let ev8i = eigenvalues(&k);
        assert!(ev8i
            .iter()
            .zip(&ev8)
            .all(|(a, b)| *a <= *b * (1.0 + 1e-12) + 1e-6 * ev8[23]));
    }

    #[test]
    fn inverted_element_is_an_error_not_a_panic() {
        let mut x = brick(1.0, 1.0, 1.0);
        x.swap(0, 4);
        x.swap(1, 5);
        x.swap(2, 6);
        x.swap(3, 7);
        for kind in [ElementKind::Hex8, ElementKind::Hex8I] {
            let err = stiffness(kind, &x, &STEEL).unwrap_err();
            assert!(matches!(err, ElementError::NonPositiveJacobian { det, .. } if det < 0.0));
        }
        assert!(scalar_mass(&x, 1.0).is_err());
        let mut nan = brick(1.0, 1.0, 1.0);
        nan[3][1] = f64::NAN;
        assert!(stiffness(ElementKind::Hex8I, &nan, &STEEL).is_err());
    }
}
