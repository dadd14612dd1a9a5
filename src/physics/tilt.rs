//! A tilted protrusion: per-pair initial normal gap offsets from a rotation of the contact
//! face about an axis in the contact plane.
//!
//! The contact normal is z (the rig's pair frames are n = z, t1 = x, t2 = y); the pivot is the
//! area centroid `c` of the pairs (positions of the lower nodes, tributary areas from the ROM).
//! Rotating the upper face by `theta` about the unit axis `a = (a_x, a_y, 0)` through `c` moves
//! the face point at in-plane offset `d = p - c` along z by `(R d - d)_z = sin(theta) (a x d)_z
//! = sin(theta) (a_x d_y - a_y d_x)` (exact for a rigid rotation); that is pair k's gap offset.
//! The in-plane shift of the face points, `O(theta^2 |d|)`, is neglected (the pairs stay
//! paired). The area-weighted mean offset is zero: the mean gap stays the clearance.

use super::TiltSpec;

/// Gap offsets (m, one per pair) of a tilt `spec` (valid) for pairs at `positions` (m) with
/// tributary `areas` (m^2).
pub fn gap_offsets(positions: &[[f64; 3]], areas: &[f64], spec: &TiltSpec) -> Vec<f64> {
    let total: f64 = areas.iter().sum();
    let (mut cx, mut cy) = (0.0, 0.0);
    for (p, a) in positions.iter().zip(areas) {
        cx += a * p[0];
        cy += a * p[1];
    }
    if total > 0.0 {
        cx /= total;
        cy /= total;
    }
    let norm = spec.axis[0].hypot(spec.axis[1]);
    let (ax, ay) = (spec.axis[0] / norm, spec.axis[1] / norm);
    let s = spec.angle.sin();
    positions
        .iter()
        .map(|p| s * (ax * (p[1] - cy) - ay * (p[0] - cx)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Round-off of the centroid (~1e-16 of the 0.3 m positions) times the tilt, m.
    const TOL: f64 = 1e-16;

    /// A 3 x 4 patch, 6 mm along x, 4.2 mm along y, centred at (0.285, 0.001), uniform areas.
    fn patch() -> (Vec<[f64; 3]>, Vec<f64>) {
        let mut pos = Vec::new();
        for j in 0..3 {
            for i in 0..4 {
                pos.push([0.282 + 0.002 * i as f64, -0.0011 + 0.0021 * j as f64, 0.018]);
            }
        }
        let n = pos.len();
        (pos, vec![1e-6; n])
    }

    #[test]
    fn offsets_match_the_rotated_face() {
        let (pos, area) = patch();
        let theta = 2e-3;
        // About y, positive: the tip-side edge (x = 0.288) moves down by sin(theta) 3 mm.
        let off = gap_offsets(
            &pos,
            &area,
            &TiltSpec {
                angle: theta,
                axis: [0.0, 1.0],
            },
        );
        for (p, o) in pos.iter().zip(&off) {
            let expected = -theta.sin() * (p[0] - 0.285);
            assert!((o - expected).abs() < TOL, "{o} vs {expected}");
        }
        assert!(off[3] < 0.0 && off[0] > 0.0);
        assert!((off[3] + theta.sin() * 0.003).abs() < TOL);
        // About x (axis not normalised): the gap varies across y, +y side opens.
        let off = gap_offsets(
            &pos,
            &area,
            &TiltSpec {
                angle: theta,
                axis: [2.0, 0.0],
            },
        );
        for (p, o) in pos.iter().zip(&off) {
            let expected = theta.sin() * (p[1] - 0.001);
            assert!((o - expected).abs() < TOL, "{o} vs {expected}");
        }
        // Against the rotation matrix (Rodrigues) about a diagonal axis: z of R d - d.
        let axis: [f64; 2] = [1.0, -2.0];
        let off = gap_offsets(&pos, &area, &TiltSpec { angle: 0.05, axis });
        let n = axis[0].hypot(axis[1]);
        let a = [axis[0] / n, axis[1] / n, 0.0];
        let (s, c) = 0.05f64.sin_cos();
        for (p, o) in pos.iter().zip(&off) {
            let d = [p[0] - 0.285, p[1] - 0.001, 0.0];
            let cross_z = a[0] * d[1] - a[1] * d[0];
            let dot = a[0] * d[0] + a[1] * d[1];
            let rz = d[2] * c + cross_z * s + a[2] * dot * (1.0 - c);
            assert!((o - (rz - d[2])).abs() < TOL, "{o} vs {}", rz - d[2]);
        }
    }

    #[test]
    fn mean_gap_is_kept_and_zero_tilt_gives_zero_offsets() {
        let (pos, mut area) = patch();
        // Graded areas: the weighted mean offset is still zero.
        for (k, a) in area.iter_mut().enumerate() {
            *a *= 1.0 + k as f64;
        }
        let off = gap_offsets(
            &pos,
            &area,
            &TiltSpec {
                angle: 0.01,
                axis: [0.3, 1.0],
            },
        );
        let mean: f64 =
            off.iter().zip(&area).map(|(o, a)| o * a).sum::<f64>() / area.iter().sum::<f64>();
        assert!(mean.abs() < TOL, "{mean}");
        let zero = gap_offsets(
            &pos,
            &area,
            &TiltSpec {
                angle: 0.0,
                axis: [0.0, 1.0],
            },
        );
        assert!(zero.iter().all(|&o| o == 0.0));
    }
}
