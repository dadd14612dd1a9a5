//! Contact-patch geometry used by the import: pairing the nodes of `CONTACT_LOWER` and
//! `CONTACT_UPPER`, the local frame of a pair and the tributary areas of a structured patch.
//! Pure functions; errors are messages the caller wraps with the deck's path.

/// Pairs with a node-to-node vector off the patch normal by more than this fraction of the
/// smallest node spacing are not considered to face each other.
const PAIR_TOLERANCE: f64 = 0.1;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Cross product.
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Unit vector, or `None` for a (numerically) zero vector.
pub(crate) fn unit(a: [f64; 3]) -> Option<[f64; 3]> {
    let l = norm(a);
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

/// Frame rows (n, t1, t2) for a unit normal `n`: t1 is +x projected into the plane normal to
/// n (+y when n is within 0.06 degrees of x), t2 = n x t1, so the frame is right-handed.
pub(crate) fn frame_from_normal(n: [f64; 3]) -> [[f64; 3]; 3] {
    let project = |e: [f64; 3]| sub(e, scale(n, dot(e, n)));
    let tx = project([1.0, 0.0, 0.0]);
    let t1 = if norm(tx) > 1e-3 {
        scale(tx, 1.0 / norm(tx))
    } else {
        let ty = project([0.0, 1.0, 0.0]);
        scale(ty, 1.0 / norm(ty))
    };
    [n, t1, cross(n, t1)]
}

fn centroid(p: &[[f64; 3]]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for x in p {
        for d in 0..3 {
            c[d] += x[d];
        }
    }
    scale(c, 1.0 / p.len().max(1) as f64)
}

/// Smallest distance between two distinct points (infinite for fewer than two points).
fn min_spacing(p: &[[f64; 3]]) -> f64 {
    let mut h = f64::INFINITY;
    for (i, a) in p.iter().enumerate() {
        for b in &p[i + 1..] {
            h = h.min(norm(sub(*a, *b)));
        }
    }
    h
}

/// Patch normal: the normal of the plane through the lower nodes, oriented towards the
/// centroid of the upper nodes (independent of the pairing). For a lower patch without area
/// (one node, or nodes on a line) the direction between the centroids; `None` when that is
/// zero too.
pub(crate) fn mean_normal(lower: &[[f64; 3]], upper: &[[f64; 3]]) -> Option<[f64; 3]> {
    let d = sub(centroid(upper), centroid(lower));
    let p0 = *lower.first()?;
    let (far, r2) = lower
        .iter()
        .map(|p| (*p, dot(sub(*p, p0), sub(*p, p0))))
        .fold((p0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let e = sub(far, p0);
    let (c, c2) = lower
        .iter()
        .map(|p| {
            let c = cross(e, sub(*p, p0));
            (c, dot(c, c))
        })
        .fold(([0.0; 3], 0.0), |a, b| if b.1 > a.1 { b } else { a });
    // NOTE: the plane normal is taken from the widest triangle of lower nodes; accepted when
    // that triangle is not degenerate (|e x (p - p0)| > 1e-6 |e|^2).
    if r2 > 0.0 && c2.sqrt() > 1e-6 * r2 {
        let n = scale(c, 1.0 / c2.sqrt());
        return Some(if dot(n, d) < 0.0 { scale(n, -1.0) } else { n });
    }
    let extent = r2.sqrt().max(norm(d));
    if norm(d) <= 1e-12 * extent {
        return None;
    }
    unit(d)
}

/// For each lower node k, the index of its upper partner. Pair order is kept when every
/// pair faces its partner (node-to-node vector along the mean normal within a tenth of the
/// smallest lower spacing); otherwise each lower node gets the upper node at the same
/// in-plane position.
pub(crate) fn pair_up(lower: &[[f64; 3]], upper: &[[f64; 3]]) -> Result<Vec<usize>, String> {
    if lower.len() != upper.len() {
        return Err(format!(
            "CONTACT_LOWER has {} nodes and CONTACT_UPPER {}: expected one upper node per lower node",
            lower.len(),
            upper.len()
        ));
    }
    let h = min_spacing(lower);
    if h == 0.0 {
        return Err("two nodes of CONTACT_LOWER coincide: expected distinct contact nodes".into());
    }
    let tol = PAIR_TOLERANCE * h;
    let n = mean_normal(lower, upper);
    let in_plane = |d: [f64; 3]| match n {
        Some(n) => norm(sub(d, scale(n, dot(d, n)))),
        None => norm(d),
    };
    if lower
        .iter()
        .zip(upper)
        .all(|(l, u)| in_plane(sub(*u, *l)) <= tol)
    {
        return Ok((0..lower.len()).collect());
    }
    let mut partner = Vec::with_capacity(lower.len());
    let mut taken = vec![false; upper.len()];
    for (k, l) in lower.iter().enumerate() {
        let (best, dist) = upper
            .iter()
            .enumerate()
            .map(|(j, u)| (j, in_plane(sub(*u, *l))))
            .fold(
                (usize::MAX, f64::INFINITY),
                |a, b| if b.1 < a.1 { b } else { a },
            );
        if best == usize::MAX || dist > tol || taken[best] {
            return Err(format!(
                "lower contact node #{} (position {:?}) has no unpaired upper contact node \
                 within {tol:.3e} m of its position in the contact plane: expected conforming \
                 node pairs",
                k + 1,
                l
            ));
        }
        taken[best] = true;
        partner.push(best);
    }
    Ok(partner)
}

/// Sorted distinct values of `v`, merged within `tol`.
fn grid_lines(v: &[f64], tol: f64) -> Vec<f64> {
    let mut s: Vec<f64> = v.to_vec();
    s.sort_by(f64::total_cmp);
    let mut lines: Vec<f64> = Vec::new();
    for x in s {
        if lines.last().is_none_or(|&l| x - l > tol) {
            lines.push(x);
        }
    }
    lines
}

fn line_index(lines: &[f64], x: f64, tol: f64) -> Option<usize> {
    lines.iter().position(|&l| (l - x).abs() <= tol)
}

/// Tributary lengths of grid lines: half the distance to each neighbour.
fn tributary(lines: &[f64]) -> Vec<f64> {
    let n = lines.len();
    (0..n)
        .map(|i| {
            let left = if i > 0 { lines[i] - lines[i - 1] } else { 0.0 };
            let right = if i + 1 < n {
                lines[i + 1] - lines[i]
            } else {
                0.0
            };
            0.5 * (left + right)
        })
        .collect()
}

/// Tributary areas of the nodes of a structured (tensor-grid) planar patch with unit normal
/// `n`: the product of the half-spacings to the neighbouring grid lines along t1 and t2.
/// This is the integral of the node's bilinear shape function over the patch.
pub(crate) fn structured_areas(points: &[[f64; 3]], n: [f64; 3]) -> Result<Vec<f64>, String> {
    let [_, t1, t2] = frame_from_normal(n);
    let s: Vec<f64> = points.iter().map(|p| dot(*p, t1)).collect();
    let r: Vec<f64> = points.iter().map(|p| dot(*p, t2)).collect();
    let h = min_spacing(points);
    let z0 = points.first().map_or(0.0, |p| dot(*p, n));
    if let Some(p) = points
        .iter()
        .find(|p| (dot(**p, n) - z0).abs() > PAIR_TOLERANCE * h)
    {
        return Err(format!(
            "the lower contact patch is not planar (node at {p:?} is off the plane normal to \
             {n:?}): expected a planar structured patch or `** rigtwin pair` area comments"
        ));
    }
    let tol = 1e-3 * h;
    let (ls, lr) = (grid_lines(&s, tol), grid_lines(&r, tol));
    if ls.len() < 2 || lr.len() < 2 || ls.len() * lr.len() != points.len() {
        return Err(format!(
            "the lower contact patch ({} nodes on {} x {} grid lines) is not a structured grid \
             of at least 2 x 2 nodes: expected one node per grid-line crossing or \
             `** rigtwin pair` area comments",
            points.len(),
            ls.len(),
            lr.len()
        ));
    }
    let (ws, wr) = (tributary(&ls), tributary(&lr));
    let mut seen = vec![false; points.len()];
    let mut areas = Vec::with_capacity(points.len());
    for k in 0..points.len() {
        let (i, j) = match (line_index(&ls, s[k], tol), line_index(&lr, r[k], tol)) {
            (Some(i), Some(j)) => (i, j),
            _ => return Err(format!("contact node #{} is off the patch grid", k + 1)),
        };
        let cell = i + ls.len() * j;
        if seen[cell] {
            return Err(format!(
                "contact nodes share the grid position of node #{}: expected one node per \
                 grid-line crossing",
                k + 1
            ));
        }
        seen[cell] = true;
        areas.push(ws[i] * wr[j]);
    }
    Ok(areas)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn patch(xs: &[f64], ys: &[f64], z: f64) -> Vec<[f64; 3]> {
        let mut p = Vec::new();
        for &y in ys {
            for &x in xs {
                p.push([x, y, z]);
            }
        }
        p
    }

    #[test]
    fn frame_is_right_handed_with_t1_along_x() {
        let f = frame_from_normal([0.0, 0.0, 1.0]);
        assert_eq!(f, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let f = frame_from_normal([1.0, 0.0, 0.0]);
        assert_eq!(f[1], [0.0, 1.0, 0.0]);
        assert_eq!(f[2], [0.0, 0.0, 1.0]);
    }

    #[test]
    fn resorted_upper_set_is_paired_by_position() {
        let lower = patch(&[0.0, 1.0, 3.0], &[0.0, 2.0], 0.0);
        let mut upper: Vec<[f64; 3]> = lower.iter().map(|p| [p[0], p[1], 0.01]).collect();
        assert_eq!(pair_up(&lower, &upper).unwrap(), vec![0, 1, 2, 3, 4, 5]);
        upper.reverse();
        assert_eq!(pair_up(&lower, &upper).unwrap(), vec![5, 4, 3, 2, 1, 0]);
        upper[0][0] += 0.5;
        assert!(pair_up(&lower, &upper).is_err());
    }

    #[test]
    fn graded_patch_areas_sum_to_the_patch_area() {
        let xs = [0.0, 0.1, 0.3, 0.7];
        let ys = [0.0, 0.2, 0.5];
        let a = structured_areas(&patch(&xs, &ys, 1.0), [0.0, 0.0, 1.0]).unwrap();
        let total: f64 = a.iter().sum();
        assert!((total - 0.7 * 0.5).abs() < 1e-14);
        assert!((a[0] - 0.05 * 0.1).abs() < 1e-15);
        assert!((a[6] - 0.3 * 0.25).abs() < 1e-15);
    }

    #[test]
    fn unstructured_patch_is_rejected() {
        let mut p = patch(&[0.0, 1.0], &[0.0, 1.0], 0.0);
        p.pop();
        assert!(structured_areas(&p, [0.0, 0.0, 1.0]).is_err());
    }
}
