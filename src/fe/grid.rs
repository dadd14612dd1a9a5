//! Structured hex grids: a box of `nx x ny x nz` cells given by its grid lines in parameter
//! space, mapped to physical space by a part-specific map (identity for boxes, a width scaling
//! for tapered beams). Graded spacing comes from the grid lines ([`graded`]).

/// A structured grid of hex cells. Node (i, j, k) has index `i + nx1 * (j + ny1 * k)` with
/// `nx1 = xs.len()`, `ny1 = ys.len()`.
#[derive(Clone, Debug)]
pub struct BoxGrid {
    /// Node coordinates in physical space, m.
    pub nodes: Vec<[f64; 3]>,
    /// Number of grid lines along each axis.
    pub dims: [usize; 3],
    /// Hex connectivity (local node indices, CalculiX order), one per cell, cell (i, j, k)
    /// at index `i + nx * (j + ny * k)`.
    pub cells: Vec<[usize; 8]>,
}

impl BoxGrid {
    /// Builds the grid on the tensor product of `xs`, `ys`, `zs` (strictly increasing), each
    /// point mapped by `map`.
    pub fn new(xs: &[f64], ys: &[f64], zs: &[f64], map: impl Fn([f64; 3]) -> [f64; 3]) -> Self {
        let (nx1, ny1, nz1) = (xs.len(), ys.len(), zs.len());
        let mut nodes = Vec::with_capacity(nx1 * ny1 * nz1);
        for &z in zs {
            for &y in ys {
                for &x in xs {
                    nodes.push(map([x, y, z]));
                }
            }
        }
        let id = |i: usize, j: usize, k: usize| i + nx1 * (j + ny1 * k);
        let mut cells = Vec::with_capacity((nx1 - 1) * (ny1 - 1) * (nz1 - 1));
        for k in 0..nz1 - 1 {
            for j in 0..ny1 - 1 {
                for i in 0..nx1 - 1 {
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
        BoxGrid {
            nodes,
            dims: [nx1, ny1, nz1],
            cells,
        }
    }

    /// Local index of node (i, j, k).
    pub fn node(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }
}

/// `n` intervals from `a` to `b` with sizes in geometric progression: the last interval is
/// `ratio` times the first (ratio 1 gives uniform spacing). Returns `n + 1` points, exact
/// end points.
pub fn graded(a: f64, b: f64, n: usize, ratio: f64) -> Vec<f64> {
    assert!(n >= 1, "graded: at least one interval");
    let q = if n > 1 {
        ratio.powf(1.0 / (n - 1) as f64)
    } else {
        1.0
    };
    let weights: Vec<f64> = (0..n).map(|i| q.powi(i as i32)).collect();
    let total: f64 = weights.iter().sum();
    let mut pts = Vec::with_capacity(n + 1);
    let mut s = a;
    pts.push(a);
    for w in &weights[..n - 1] {
        s += (b - a) * w / total;
        pts.push(s);
    }
    pts.push(b);
    pts
}

/// Concatenates grid-line segments, dropping the duplicated joint points.
pub fn join(segments: &[Vec<f64>]) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for seg in segments {
        for &p in seg {
            if out
                .last()
                .is_none_or(|&l| (p - l).abs() > 1e-12 * (1.0 + p.abs()))
            {
                out.push(p);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_ends_and_ratio() {
        let p = graded(0.0, 1.0, 4, 8.0);
        assert_eq!(p.len(), 5);
        assert_eq!(p[0], 0.0);
        assert_eq!(p[4], 1.0);
        let first = p[1] - p[0];
        let last = p[4] - p[3];
        assert!((last / first - 8.0).abs() < 1e-12);
    }

    #[test]
    fn box_grid_counts_and_orientation() {
        let g = BoxGrid::new(&[0.0, 1.0, 2.0], &[0.0, 1.0], &[0.0, 0.5], |p| p);
        assert_eq!(g.nodes.len(), 12);
        assert_eq!(g.cells.len(), 2);
        let v = crate::fe::hex8::hex_volume(&g.cells[1].map(|n| g.nodes[n]));
        assert!((v - 0.5).abs() < 1e-14, "positive volume in CalculiX order");
    }
}
