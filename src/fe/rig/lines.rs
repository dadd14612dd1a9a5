//! Grid lines of the rig's parts: graded spacing between breakpoints ([`sized`]), subsets
//! of a finer line set that keep touching faces conforming, unions, tributary lengths.

use crate::config::{ConfigError, Mount, RigModel};
use crate::fe::grid::{graded, join};

use super::Geometry;

/// Grid lines of every part (m).
pub(super) struct Lines {
    pub(super) beam_x: Vec<f64>,
    pub(super) clamp_x: Vec<f64>,
    pub(super) lower_y: Vec<f64>,
    /// Upper beam y lines in parameter space (tip width); physical = line x upper_scale(x).
    pub(super) upper_y: Vec<f64>,
    pub(super) probe_x: Vec<f64>,
    pub(super) probe_y: Vec<f64>,
    pub(super) patch_x: Vec<f64>,
    pub(super) patch_y: Vec<f64>,
    pub(super) base_y: Vec<f64>,
    pub(super) spacer_y: Vec<f64>,
    pub(super) top_y: Vec<f64>,
    pub(super) base_z: Vec<f64>,
    pub(super) lower_z: Vec<f64>,
    pub(super) lower_probe_z: Vec<f64>,
    pub(super) protrusion_z: Vec<f64>,
    pub(super) upper_probe_z: Vec<f64>,
    pub(super) upper_z: Vec<f64>,
    pub(super) spacer_z: Vec<f64>,
    pub(super) top_z: Vec<f64>,
}

impl Lines {
    pub(super) fn new(cfg: &RigModel, g: &Geometry) -> Self {
        let m = &cfg.mesh;
        let bm = &m.beams;
        let gr = m.growth;
        let pe = m.probes.element;
        let pg = m.probes.growth;
        let be = m.blocks.element;
        let [ny, nx] = cfg.patch_nodes();
        let sx = (g.patch_x.1 - g.patch_x.0) / (nx - 1) as f64;
        let sy = (g.patch_y.1 - g.patch_y.0) / (ny - 1) as f64;
        let sz = sx.min(sy);

        // Probe plan: seat edge -> patch edge graded down to the patch spacing.
        let patch_x = graded(g.patch_x.0, g.patch_x.1, nx - 1, 1.0);
        let patch_y = graded(g.patch_y.0, g.patch_y.1, ny - 1, 1.0);
        let probe_x = join(&[
            sized(g.seat_x.0, g.patch_x.0, pe, sx, pe, pg),
            patch_x.clone(),
            sized(g.patch_x.1, g.seat_x.1, sx, pe, pe, pg),
        ]);
        let half_seat = 0.5 * g.seat_w;
        let probe_y = join(&[
            sized(-half_seat, g.patch_y.0, pe, sy, pe, pg),
            patch_y.clone(),
            sized(g.patch_y.1, half_seat, sy, pe, pe, pg),
        ]);

        // Beams along x: clamp, free span, seat (subset of the probe lines), tip. The
        // accelerometers' x positions on the beams are grid lines too.
        let sensor_x: Vec<f64> = cfg
            .sensors
            .iter()
            .filter(|s| s.mount != Mount::Platform)
            .map(|s| s.x)
            .collect();
        let seat_keep = [g.seat_x.0, g.patch_x.0, g.patch_x.1, g.seat_x.1];
        let beam_x = join(&[
            sized(
                -g.lc,
                0.0,
                bm.clamp_element,
                bm.clamp_exit_element,
                bm.clamp_element.max(bm.clamp_exit_element),
                gr,
            ),
            span_lines(
                &[0.0, g.seat_x.0],
                &sensor_x,
                (bm.clamp_exit_element, bm.seat_element),
                bm.free_element,
                gr,
            ),
            subset(&probe_x, &seat_keep, bm.seat_element),
            span_lines(
                &[g.seat_x.1, g.l],
                &sensor_x,
                (bm.seat_element, bm.free_element),
                bm.free_element,
                gr,
            ),
        ]);
        let clamp_x: Vec<f64> = beam_x.iter().copied().filter(|&x| x <= 0.0).collect();

        // Beams across y: edge -> seat edge, seat (subset of the probe lines), seat -> edge.
        let seat_y_keep = [-half_seat, g.patch_y.0, g.patch_y.1, half_seat];
        let seat_y = subset(&probe_y, &seat_y_keep, bm.width_element);
        let beam_y = |w: f64| {
            let we = bm.width_element;
            join(&[
                sized(-0.5 * w, -half_seat, we, we, we, gr),
                seat_y.clone(),
                sized(half_seat, 0.5 * w, we, we, we, gr),
            ])
        };
        let lower_y = beam_y(cfg.parts.lower_beam.width);
        let upper_y = beam_y(g.w_tip);
        let root_scale = g.upper_scale(0.0);
        let upper_root_y: Vec<f64> = upper_y.iter().map(|y| y * root_scale).collect();

        // Blocks across y: the beam lines they touch plus a fill to the block width.
        let cw = cfg.parts.clamp.width;
        let block_y = |inner: &[f64]| {
            let (lo, hi) = (inner[0], inner[inner.len() - 1]);
            join(&[
                sized(-0.5 * cw, lo, be, be, be, gr),
                inner.to_vec(),
                sized(hi, 0.5 * cw, be, be, be, gr),
            ])
        };
        let base_y = block_y(&lower_y);
        let top_y = block_y(&upper_root_y);
        let spacer_y = block_y(&union(&lower_y, &upper_root_y));

        // Vertical stack.
        let t_l = cfg.parts.lower_beam.thickness;
        let t_u = cfg.parts.upper_beam.thickness;
        let tc = bm.thickness_cells;
        let z_lp_top = t_l + cfg.parts.lower_probe.height;
        let z_pr_bot = z_lp_top + cfg.contact.clearance;
        let h_pr = cfg.parts.protrusion.height;
        let z_pr_top = z_pr_bot + h_pr;
        let z_ub = z_pr_top + cfg.parts.upper_probe.height;
        let pr_cells = ((h_pr / sz).round() as usize).max(1);
        let hb = cfg.parts.clamp.base_height;
        let ht = cfg.parts.clamp.top_height;
        Lines {
            beam_x,
            clamp_x,
            lower_y,
            upper_y,
            probe_x,
            probe_y,
            patch_x,
            patch_y,
            base_y,
            spacer_y,
            top_y,
            base_z: sized(-hb, 0.0, be, be, be, gr),
            lower_z: graded(0.0, t_l, tc, 1.0),
            lower_probe_z: sized(t_l, z_lp_top, pe, sz, pe, pg),
            protrusion_z: graded(z_pr_bot, z_pr_top, pr_cells, 1.0),
            upper_probe_z: sized(z_pr_top, z_ub, sz, pe, pe, pg),
            upper_z: graded(z_ub, z_ub + t_u, tc, 1.0),
            spacer_z: sized(t_l, z_ub, be, be, be, gr),
            top_z: sized(z_ub + t_u, z_ub + t_u + ht, be, be, be, gr),
        }
    }
}

/// Grid lines from `a` to `b` whose element size follows
/// `h(s) = min(h_max, h_a + (growth - 1) s, h_b + (growth - 1) (b - a - s))`: graded from
/// `h_a` at `a` and `h_b` at `b` by at most `growth` between neighbours, capped at `h_max`.
/// Returns at least the two end points (exact); a zero-length interval gives `[a]`.
pub fn sized(a: f64, b: f64, h_a: f64, h_b: f64, h_max: f64, growth: f64) -> Vec<f64> {
    let len = b - a;
    if len <= 1e-12 * (1.0 + a.abs().max(b.abs())) {
        return vec![a];
    }
    let r = (growth - 1.0).max(0.0);
    let h_a = h_a.min(h_max);
    let h_b = h_b.min(h_max);
    let h = |s: f64| h_max.min(h_a + r * s).min(h_b + r * (len - s));
    // NOTE: the cell count is the integral of 1/h; the lines equidistribute it. The
    // integrand is piecewise smooth and bounded (h >= min(h_a, h_b)), so a fine trapezoid
    // table is accurate to far below a cell.
    const SAMPLES: usize = 2048;
    let ds = len / SAMPLES as f64;
    let mut cum = Vec::with_capacity(SAMPLES + 1);
    cum.push(0.0);
    for k in 0..SAMPLES {
        let (s0, s1) = (k as f64 * ds, (k + 1) as f64 * ds);
        let last = cum[k];
        cum.push(last + 0.5 * ds * (1.0 / h(s0) + 1.0 / h(s1)));
    }
    let total = cum[SAMPLES];
    let n = (total.round() as usize).max(1);
    let mut pts = Vec::with_capacity(n + 1);
    pts.push(a);
    let mut k = 0;
    for i in 1..n {
        let target = total * i as f64 / n as f64;
        while k + 1 < SAMPLES && cum[k + 1] < target {
            k += 1;
        }
        let frac = (target - cum[k]) / (cum[k + 1] - cum[k]);
        pts.push(a + (k as f64 + frac) * ds);
    }
    pts.push(b);
    pts
}

/// Lines over `[span[0], span[1]]` with end sizes `ends`, passing through the points of
/// `extra` that lie inside the span at least half an element (`h_max`) away from the ends
/// and from each other; interior breakpoints get size `h_max`.
pub(super) fn span_lines(
    span: &[f64; 2],
    extra: &[f64],
    ends: (f64, f64),
    h_max: f64,
    growth: f64,
) -> Vec<f64> {
    let mut inner: Vec<f64> = extra
        .iter()
        .copied()
        .filter(|&x| x > span[0] + 0.5 * h_max && x < span[1] - 0.5 * h_max)
        .collect();
    inner.sort_by(f64::total_cmp);
    let mut points = vec![(span[0], ends.0)];
    for x in inner {
        if x - points[points.len() - 1].0 >= 0.5 * h_max {
            points.push((x, h_max));
        }
    }
    points.push((span[1], ends.1));
    let segments: Vec<Vec<f64>> = points
        .windows(2)
        .map(|w| sized(w[0].0, w[1].0, w[0].1, w[1].1, h_max, growth))
        .collect();
    join(&segments)
}

/// Lines of `lines` about `h` apart that include every point of `keep` (which must be lines
/// of `lines`, ascending): between two kept points, `round(distance / h)` cells whose inner
/// lines are the lines of `lines` nearest to a uniform division.
pub(super) fn subset(lines: &[f64], keep: &[f64], h: f64) -> Vec<f64> {
    let tol = 1e-12 * (1.0 + lines.iter().fold(0.0f64, |m, v| m.max(v.abs())));
    let mut out = Vec::new();
    for w in keep.windows(2) {
        let (a, b) = (w[0], w[1]);
        out.push(a);
        if b - a <= tol {
            continue;
        }
        let inner: Vec<f64> = lines
            .iter()
            .copied()
            .filter(|&p| p > a + tol && p < b - tol)
            .collect();
        let m = (((b - a) / h).round() as usize).max(1);
        let mut last = a;
        for q in 1..m {
            let target = a + (b - a) * q as f64 / m as f64;
            let nearest = inner
                .iter()
                .copied()
                .min_by(|p, r| (p - target).abs().total_cmp(&(r - target).abs()));
            if let Some(p) = nearest {
                if p > last + tol {
                    out.push(p);
                    last = p;
                }
            }
        }
    }
    if let Some(&last) = keep.last() {
        out.push(last);
    }
    join(&[out])
}

/// Sorted union of two ascending line sets (coincident lines merged).
pub(super) fn union(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = a.iter().chain(b).copied().collect();
    v.sort_by(f64::total_cmp);
    join(&[v])
}

/// Tributary length of each line of an ascending set: half of each adjacent interval.
pub(super) fn tributary(lines: &[f64]) -> Vec<f64> {
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

/// Index of the line equal to `v` (to a relative 1e-9 of the set's extent).
pub(super) fn index_of(lines: &[f64], v: f64, what: &str) -> Result<usize, ConfigError> {
    find_line(lines, v).ok_or_else(|| ConfigError::Invalid {
        file: String::from("(rig mesher)"),
        key: what.to_string(),
        value: v.to_string(),
        expected: String::from("a grid line there (internal meshing inconsistency)"),
    })
}

pub(super) fn find_line(lines: &[f64], v: f64) -> Option<usize> {
    let extent = lines.last().copied().unwrap_or(0.0) - lines.first().copied().unwrap_or(0.0);
    let tol = 1e-9 * extent.abs().max(1e-12);
    let i = lines.partition_point(|&p| p < v - tol);
    (i < lines.len() && (lines[i] - v).abs() <= tol).then_some(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    pub(super) fn sized_grades_between_end_sizes() {
        let p = sized(0.0, 10.0, 0.1, 0.1, 1.0, 1.2);
        assert_eq!(p[0], 0.0);
        assert_eq!(*p.last().unwrap(), 10.0);
        let h: Vec<f64> = p.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(h[0] < 0.15 && *h.last().unwrap() < 0.15, "{h:?}");
        assert!(h.iter().cloned().fold(0.0, f64::max) <= 1.05);
        for w in h.windows(2) {
            let r = w[1] / w[0];
            assert!(r < 1.3 && r > 1.0 / 1.3, "growth {r}");
        }
    }

    #[test]
    pub(super) fn sized_uniform_when_no_growth() {
        let p = sized(0.0, 1.0, 0.25, 0.25, 0.25, 1.0);
        assert_eq!(p.len(), 5);
        assert!((p[2] - 0.5).abs() < 1e-12);
        assert_eq!(sized(2.0, 2.0, 0.1, 0.1, 0.1, 1.2), vec![2.0]);
    }

    #[test]
    pub(super) fn subset_keeps_breakpoints_and_uses_existing_lines() {
        let lines: Vec<f64> = (0..=20).map(|i| i as f64 * 0.5).collect();
        let s = subset(&lines, &[0.0, 3.0, 10.0], 2.0);
        assert!(s.contains(&3.0));
        assert_eq!(s[0], 0.0);
        assert_eq!(*s.last().unwrap(), 10.0);
        assert!(s.iter().all(|v| lines.contains(v)));
        assert!(s.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    pub(super) fn tributary_sums_to_length() {
        let t = tributary(&[0.0, 1.0, 3.0, 4.0]);
        assert_eq!(t, vec![0.5, 1.5, 1.5, 0.5]);
    }
}
