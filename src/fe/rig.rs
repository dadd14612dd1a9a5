//! The rig mesher: turns a validated [`RigConfig`] into the parent [`Mesh`]. Every part is a
//! structured hex grid ([`BoxGrid`]) with graded lines and its own element block; parts
//! joined by an elastic interface layer get their own coincident nodes and zero-length
//! [`Spring`]s; the protrusion is fused to the upper probe (shared nodes).
//!
//! Grid lines are chosen so that touching faces conform:
//! - x: both beams share one set of lines (clamp, free span, probe seat, tip); the blocks take
//!   the beams' lines inside the clamp.
//! - plan of the probes: the seat edges, the contact patch lines (uniform, `contact.nodes`)
//!   and lines graded from the patch spacing up to `mesh.probes.element`; both probes and
//!   the protrusion share them.
//! - the beams under the seat take a subset of the probe's plan lines (about
//!   `mesh.beams.seat_element` apart along x, `width_element` across), so every beam face
//!   node under the seat coincides with a probe face node; the probe-beam layer springs sit
//!   on those nodes and the finer probe face nodes in between are not tied (the layer is a
//!   spring bed at the beam's resolution, which keeps the patch refinement out of the beams).
//! - the clamp blocks' y lines are the union of the lines of the beams they touch plus a
//!   fill out to the block width.
//!
//! Coordinates (SI): x along the beams (clamp exit x = 0, tips x = l), y across, z up. The
//! base block spans z in [-base_height, 0]; the lower beam [0, t_l]; the lower probe sits on
//! it; the protrusion's bottom face is `clearance` above the lower probe's top face; the
//! upper probe, the upper beam and the top block follow upwards. The spacer block fills
//! [t_l, z of the upper beam's bottom face].

use std::collections::BTreeMap;

use crate::config::{ConfigError, LayerSpec, Mount, RigConfig};
use crate::fe::grid::{graded, join, BoxGrid};
use crate::fe::mesh::{
    ContactPair, ElementBlock, ElementKind, HexElement, Material, Mesh, PointMass, SensorPoint,
    Spring,
};

/// Builds the parent mesh of the rig.
///
/// Node sets: `LOWER` (lower beam + lower probe), `UPPER` (upper beam + upper probe +
/// protrusion), `CLAMP` (blocks), `FIXED` (base block bottom face), `CONTACT_LOWER` and
/// `CONTACT_UPPER` (the pairs' nodes), `SENSOR_<name>` per sensor. Contact pair (i, j) of the
/// patch (i along x, j along y) is at index `i + nodes_x * j`, frame n = +z, t1 = +x, t2 = +y.
pub fn mesh_rig(cfg: &RigConfig) -> Result<Mesh, ConfigError> {
    let g = Geometry::new(cfg);
    let lines = Lines::new(cfg, &g);
    let mut b = Builder::new(cfg);

    let ids = BlockIds::new(&mut b, cfg);
    // Solid parts.
    let base = b.add_part(
        ids.base,
        BoxGrid::new(&lines.clamp_x, &lines.base_y, &lines.base_z, |q| q),
        &lines.clamp_x,
        &lines.base_y,
    );
    let spacer = b.add_part(
        ids.spacer,
        BoxGrid::new(&lines.clamp_x, &lines.spacer_y, &lines.spacer_z, |q| q),
        &lines.clamp_x,
        &lines.spacer_y,
    );
    let top = b.add_part(
        ids.top,
        BoxGrid::new(&lines.clamp_x, &lines.top_y, &lines.top_z, |q| q),
        &lines.clamp_x,
        &lines.top_y,
    );
    let lower = b.add_part(
        ids.lower_beam,
        BoxGrid::new(&lines.beam_x, &lines.lower_y, &lines.lower_z, |q| q),
        &lines.beam_x,
        &lines.lower_y,
    );
    let upper = b.add_part(
        ids.upper_beam,
        BoxGrid::new(&lines.beam_x, &lines.upper_y, &lines.upper_z, |q| {
            [q[0], q[1] * g.upper_scale(q[0]), q[2]]
        }),
        &lines.beam_x,
        &lines.upper_y,
    );
    let lprobe = b.add_part(
        ids.lower_probe,
        BoxGrid::new(&lines.probe_x, &lines.probe_y, &lines.lower_probe_z, |q| q),
        &lines.probe_x,
        &lines.probe_y,
    );
    let uprobe = b.add_part(
        ids.upper_probe,
        BoxGrid::new(&lines.probe_x, &lines.probe_y, &lines.upper_probe_z, |q| q),
        &lines.probe_x,
        &lines.probe_y,
    );
    // The protrusion's top face is fused to the upper probe's bottom face.
    let prot_grid = BoxGrid::new(&lines.patch_x, &lines.patch_y, &lines.protrusion_z, |q| q);
    let top_k = prot_grid.dims[2] - 1;
    let mut fused = Vec::new();
    for j in 0..prot_grid.dims[1] {
        for i in 0..prot_grid.dims[0] {
            let q = prot_grid.nodes[prot_grid.node(i, j, top_k)];
            let target = uprobe.node_at(&b, q[0], q[1], 0, "parts.protrusion")?;
            fused.push((prot_grid.node(i, j, top_k), target));
        }
    }
    let prot = b.add_part_fused(
        ids.protrusion,
        prot_grid,
        &lines.patch_x,
        &lines.patch_y,
        &fused,
    );

    // Interface layers (first part = beam, second = block or probe).
    let clamp_i = (
        0,
        index_of(&lines.beam_x, 0.0, "beam x line at the clamp exit")?,
    );
    let seat_x = (
        index_of(&lines.beam_x, g.seat_x.0, "beam x line at the seat start")?,
        index_of(&lines.beam_x, g.seat_x.1, "beam x line at the seat end")?,
    );
    let lower_seat_y = (
        index_of(
            &lines.lower_y,
            -0.5 * g.seat_w,
            "lower beam y line at the seat edge",
        )?,
        index_of(
            &lines.lower_y,
            0.5 * g.seat_w,
            "lower beam y line at the seat edge",
        )?,
    );
    let upper_seat_y = (
        index_of(
            &lines.upper_y,
            -0.5 * g.seat_w,
            "upper beam y line at the seat edge",
        )?,
        index_of(
            &lines.upper_y,
            0.5 * g.seat_w,
            "upper beam y line at the seat edge",
        )?,
    );
    let all_lower_y = (0, lines.lower_y.len() - 1);
    let all_upper_y = (0, lines.upper_y.len() - 1);
    let (lk_bot, lk_top) = (0, lines.lower_z.len() - 1);
    let (uk_bot, uk_top) = (0, lines.upper_z.len() - 1);
    let region = |part, k, i, j| FaceRegion { part, k, i, j };
    // In the order of `cfg.layers.named()` (the mesh's layer indices).
    let faces = [
        (
            region(&lower, lk_bot, clamp_i, all_lower_y),
            &base,
            base.top_k(),
        ),
        (region(&lower, lk_top, clamp_i, all_lower_y), &spacer, 0),
        (
            region(&upper, uk_bot, clamp_i, all_upper_y),
            &spacer,
            spacer.top_k(),
        ),
        (region(&upper, uk_top, clamp_i, all_upper_y), &top, 0),
        (region(&lower, lk_top, seat_x, lower_seat_y), &lprobe, 0),
        (
            region(&upper, uk_bot, seat_x, upper_seat_y),
            &uprobe,
            uprobe.top_k(),
        ),
    ];
    for (layer, ((face, other, bk), (_, spec))) in
        faces.into_iter().zip(cfg.layers.named()).enumerate()
    {
        b.layer_springs(&face, other, bk, spec, layer)?;
    }

    // Contact pairs: protrusion bottom face over the lower probe's top face.
    let area_x = tributary(&lines.patch_x);
    let area_y = tributary(&lines.patch_y);
    let lp_top = lprobe.top_k();
    for (j, ay) in area_y.iter().enumerate() {
        for (i, ax) in area_x.iter().enumerate() {
            let upper_node = prot.global(i, j, 0);
            let q = b.mesh.nodes[upper_node];
            let lower_node = lprobe.node_at(&b, q[0], q[1], lp_top, "contact.nodes")?;
            b.mesh.contact_pairs.push(ContactPair {
                lower: lower_node,
                upper: upper_node,
                frame: [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                area: ax * ay,
            });
        }
    }

    // Fixed nodes: base block bottom face.
    let fixed: Vec<usize> = base.face_nodes(0);
    b.mesh.fixed_nodes = fixed.clone();

    // Sensors and point masses.
    for (idx, s) in cfg.sensors.iter().enumerate() {
        let key = format!("sensors[{idx}]");
        let (part, k) = match s.mount {
            Mount::LowerBeamTop => (&lower, lk_top),
            Mount::LowerBeamBottom => (&lower, lk_bot),
            Mount::UpperBeamTop => (&upper, uk_top),
            Mount::UpperBeamBottom => (&upper, uk_bot),
            Mount::Platform => (&base, 0),
        };
        let node = part
            .nearest_on_face(&b, k, s.x, s.y)
            .ok_or_else(|| invalid(cfg, &key, "no node on the mounting face"))?;
        b.mesh
            .node_sets
            .insert(format!("SENSOR_{}", s.name), vec![node]);
        if s.mount == Mount::Platform {
            continue;
        }
        let norm = s.direction.iter().map(|d| d * d).sum::<f64>().sqrt();
        b.mesh.sensors.push(SensorPoint {
            name: s.name.clone(),
            node,
            direction: s.direction.map(|d| d / norm),
        });
        if s.mass > 0.0 {
            b.mesh.point_masses.push(PointMass {
                name: s.name.clone(),
                node,
                mass: s.mass,
            });
        }
    }

    // Node sets.
    let sets = [
        ("LOWER", vec![&lower, &lprobe]),
        ("UPPER", vec![&upper, &uprobe, &prot]),
        ("CLAMP", vec![&base, &spacer, &top]),
    ];
    for (name, parts) in sets {
        let mut v: Vec<usize> = parts.iter().flat_map(|p| p.map.iter().copied()).collect();
        v.sort_unstable();
        v.dedup();
        b.mesh.node_sets.insert(name.to_string(), v);
    }
    let sorted = |mut v: Vec<usize>| {
        v.sort_unstable();
        v.dedup();
        v
    };
    b.mesh.node_sets.insert("FIXED".into(), sorted(fixed));
    let cl: Vec<usize> = b.mesh.contact_pairs.iter().map(|c| c.lower).collect();
    let cu: Vec<usize> = b.mesh.contact_pairs.iter().map(|c| c.upper).collect();
    b.mesh.node_sets.insert("CONTACT_LOWER".into(), sorted(cl));
    b.mesh.node_sets.insert("CONTACT_UPPER".into(), sorted(cu));
    Ok(b.mesh)
}

/// Derived geometry (m).
struct Geometry {
    l: f64,
    lc: f64,
    seat_x: (f64, f64),
    seat_w: f64,
    patch_x: (f64, f64),
    patch_y: (f64, f64),
    w_root: f64,
    w_tip: f64,
    x_taper_end: f64,
}

impl Geometry {
    fn new(cfg: &RigConfig) -> Self {
        let s = &cfg.probe_seat;
        let pr = &cfg.parts.protrusion;
        let seat_x = (s.x_center - 0.5 * s.length, s.x_center + 0.5 * s.length);
        let cx = s.x_center + pr.offset[0];
        let cy = pr.offset[1];
        Geometry {
            l: cfg.rig.beam_length,
            lc: cfg.parts.clamp.length,
            seat_x,
            seat_w: s.width,
            patch_x: (cx - 0.5 * pr.length, cx + 0.5 * pr.length),
            patch_y: (cy - 0.5 * pr.width, cy + 0.5 * pr.width),
            w_root: cfg.parts.upper_beam.width_root,
            w_tip: cfg.parts.upper_beam.width_tip,
            x_taper_end: seat_x.0,
        }
    }

    /// Ratio of the upper beam's width at x to its tip width (the y map of its grid, whose
    /// parameter lines span the tip width).
    fn upper_scale(&self, x: f64) -> f64 {
        let w = if x <= 0.0 {
            self.w_root
        } else if x >= self.x_taper_end {
            self.w_tip
        } else {
            self.w_root + (self.w_tip - self.w_root) * (x / self.x_taper_end)
        };
        w / self.w_tip
    }
}

/// Grid lines of every part (m).
struct Lines {
    beam_x: Vec<f64>,
    clamp_x: Vec<f64>,
    lower_y: Vec<f64>,
    /// Upper beam y lines in parameter space (tip width); physical = line x upper_scale(x).
    upper_y: Vec<f64>,
    probe_x: Vec<f64>,
    probe_y: Vec<f64>,
    patch_x: Vec<f64>,
    patch_y: Vec<f64>,
    base_y: Vec<f64>,
    spacer_y: Vec<f64>,
    top_y: Vec<f64>,
    base_z: Vec<f64>,
    lower_z: Vec<f64>,
    lower_probe_z: Vec<f64>,
    protrusion_z: Vec<f64>,
    upper_probe_z: Vec<f64>,
    upper_z: Vec<f64>,
    spacer_z: Vec<f64>,
    top_z: Vec<f64>,
}

impl Lines {
    fn new(cfg: &RigConfig, g: &Geometry) -> Self {
        let m = &cfg.mesh;
        let bm = &m.beams;
        let gr = m.growth;
        let pe = m.probes.element;
        let pg = m.probes.growth;
        let be = m.blocks.element;
        let [ny, nx] = cfg.contact.nodes;
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
fn span_lines(
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
fn subset(lines: &[f64], keep: &[f64], h: f64) -> Vec<f64> {
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
fn union(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = a.iter().chain(b).copied().collect();
    v.sort_by(f64::total_cmp);
    join(&[v])
}

/// Tributary length of each line of an ascending set: half of each adjacent interval.
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

/// Index of the line equal to `v` (to a relative 1e-9 of the set's extent).
fn index_of(lines: &[f64], v: f64, what: &str) -> Result<usize, ConfigError> {
    find_line(lines, v).ok_or_else(|| ConfigError::Invalid {
        file: String::from("(rig mesher)"),
        key: what.to_string(),
        value: v.to_string(),
        expected: String::from("a grid line there (internal meshing inconsistency)"),
    })
}

fn find_line(lines: &[f64], v: f64) -> Option<usize> {
    let extent = lines.last().copied().unwrap_or(0.0) - lines.first().copied().unwrap_or(0.0);
    let tol = 1e-9 * extent.abs().max(1e-12);
    let i = lines.partition_point(|&p| p < v - tol);
    (i < lines.len() && (lines[i] - v).abs() <= tol).then_some(i)
}

fn invalid(cfg: &RigConfig, key: &str, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        file: cfg.source.clone(),
        key: key.to_string(),
        value: String::from("(mesher)"),
        expected: expected.to_string(),
    }
}

/// One meshed part: its grid, the global index of each local node, its physical plan lines
/// (for box parts) and its grid dims.
struct Part {
    map: Vec<usize>,
    dims: [usize; 3],
    xs: Vec<f64>,
    ys: Vec<f64>,
}

impl Part {
    fn global(&self, i: usize, j: usize, k: usize) -> usize {
        self.map[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    fn top_k(&self) -> usize {
        self.dims[2] - 1
    }

    /// Global nodes of the face k, in grid order.
    fn face_nodes(&self, k: usize) -> Vec<usize> {
        let mut v = Vec::with_capacity(self.dims[0] * self.dims[1]);
        for j in 0..self.dims[1] {
            for i in 0..self.dims[0] {
                v.push(self.global(i, j, k));
            }
        }
        v
    }

    /// Global node of a box part at plan position (x, y) on face k.
    fn node_at(
        &self,
        b: &Builder,
        x: f64,
        y: f64,
        k: usize,
        key: &str,
    ) -> Result<usize, ConfigError> {
        match (find_line(&self.xs, x), find_line(&self.ys, y)) {
            (Some(i), Some(j)) => {
                let n = self.global(i, j, k);
                let q = b.mesh.nodes[n];
                let tol = 1e-9 * (1.0 + q[0].abs() + q[1].abs());
                if (q[0] - x).abs() <= tol && (q[1] - y).abs() <= tol {
                    Ok(n)
                } else {
                    Err(invalid(
                        b.cfg,
                        key,
                        "conforming grid lines (internal meshing inconsistency)",
                    ))
                }
            }
            _ => Err(ConfigError::Invalid {
                file: b.cfg.source.clone(),
                key: key.to_string(),
                value: format!("node at ({x}, {y})"),
                expected: String::from(
                    "a coincident node on the touching face (internal meshing inconsistency)",
                ),
            }),
        }
    }

    /// Face node nearest to the plan position (x, y).
    fn nearest_on_face(&self, b: &Builder, k: usize, x: f64, y: f64) -> Option<usize> {
        self.face_nodes(k).into_iter().min_by(|&m, &n| {
            let d = |id: usize| {
                let q = b.mesh.nodes[id];
                (q[0] - x).powi(2) + (q[1] - y).powi(2)
            };
            d(m).total_cmp(&d(n))
        })
    }
}

/// A rectangle of a beam face: the part, the face's layer index along z and the line index
/// ranges (inclusive) along x and y.
struct FaceRegion<'p> {
    part: &'p Part,
    k: usize,
    i: (usize, usize),
    j: (usize, usize),
}

/// Element block indices of the parts.
struct BlockIds {
    base: usize,
    spacer: usize,
    top: usize,
    lower_beam: usize,
    upper_beam: usize,
    lower_probe: usize,
    upper_probe: usize,
    protrusion: usize,
}

impl BlockIds {
    fn new(b: &mut Builder, cfg: &RigConfig) -> Self {
        let p = &cfg.parts;
        BlockIds {
            base: b.block("base_block", &p.clamp.material, p.clamp.element),
            spacer: b.block("spacer_block", &p.clamp.material, p.clamp.element),
            top: b.block("top_block", &p.clamp.material, p.clamp.element),
            lower_beam: b.block("lower_beam", &p.lower_beam.material, p.lower_beam.element),
            upper_beam: b.block("upper_beam", &p.upper_beam.material, p.upper_beam.element),
            lower_probe: b.block(
                "lower_probe",
                &p.lower_probe.material,
                p.lower_probe.element,
            ),
            upper_probe: b.block(
                "upper_probe",
                &p.upper_probe.material,
                p.upper_probe.element,
            ),
            protrusion: b.block("protrusion", &p.protrusion.material, p.protrusion.element),
        }
    }
}

/// Accumulates the mesh.
struct Builder<'a> {
    cfg: &'a RigConfig,
    mesh: Mesh,
    material_index: BTreeMap<String, usize>,
}

impl<'a> Builder<'a> {
    fn new(cfg: &'a RigConfig) -> Self {
        let mut mesh = Mesh::default();
        let mut material_index = BTreeMap::new();
        for (name, m) in &cfg.materials {
            material_index.insert(name.clone(), mesh.materials.len());
            mesh.materials.push(Material {
                name: name.clone(),
                youngs_modulus: m.youngs_modulus,
                poisson_ratio: m.poisson_ratio,
                density: m.density,
            });
        }
        mesh.layers = cfg
            .layers
            .named()
            .iter()
            .map(|(n, _)| n.to_string())
            .collect();
        Builder {
            cfg,
            mesh,
            material_index,
        }
    }

    fn block(&mut self, name: &str, material: &str, kind: ElementKind) -> usize {
        // Materials were validated to exist.
        let material = self.material_index.get(material).copied().unwrap_or(0);
        self.mesh.blocks.push(ElementBlock {
            name: name.to_string(),
            material,
            kind,
        });
        self.mesh.blocks.len() - 1
    }

    fn add_part(&mut self, block: usize, grid: BoxGrid, xs: &[f64], ys: &[f64]) -> Part {
        self.add_part_fused(block, grid, xs, ys, &[])
    }

    /// Adds a part; `fused` lists (local node, existing global node) pairs that are shared.
    fn add_part_fused(
        &mut self,
        block: usize,
        grid: BoxGrid,
        xs: &[f64],
        ys: &[f64],
        fused: &[(usize, usize)],
    ) -> Part {
        let shared: BTreeMap<usize, usize> = fused.iter().copied().collect();
        let mut map = Vec::with_capacity(grid.nodes.len());
        for (local, q) in grid.nodes.iter().enumerate() {
            if let Some(&g) = shared.get(&local) {
                map.push(g);
            } else {
                map.push(self.mesh.nodes.len());
                self.mesh.nodes.push(*q);
            }
        }
        for cell in &grid.cells {
            self.mesh.elements.push(HexElement {
                nodes: cell.map(|n| map[n]),
                block,
            });
        }
        Part {
            map,
            dims: grid.dims,
            xs: xs.to_vec(),
            ys: ys.to_vec(),
        }
    }

    /// Springs of one interface layer between a beam face region (a region of constant
    /// width) and the coincident nodes of the box part `other` on its face `bk`. Tributary
    /// areas are the beam face's dual cells inside the region.
    fn layer_springs(
        &mut self,
        face: &FaceRegion,
        other: &Part,
        bk: usize,
        spec: LayerSpec,
        layer: usize,
    ) -> Result<(), ConfigError> {
        let (a, ak, ir, jr) = (face.part, face.k, face.i, face.j);
        let key = format!("layers.{}", self.mesh.layers[layer]);
        for j in jr.0..=jr.1 {
            for i in ir.0..=ir.1 {
                let n = a.global(i, j, ak);
                let q = self.mesh.nodes[n];
                let coord =
                    |ii: usize, jj: usize, c: usize| self.mesh.nodes[a.global(ii, jj, ak)][c];
                let mut lx = 0.0;
                if i > ir.0 {
                    lx += 0.5 * (q[0] - coord(i - 1, j, 0));
                }
                if i < ir.1 {
                    lx += 0.5 * (coord(i + 1, j, 0) - q[0]);
                }
                let mut ly = 0.0;
                if j > jr.0 {
                    ly += 0.5 * (q[1] - coord(i, j - 1, 1));
                }
                if j < jr.1 {
                    ly += 0.5 * (coord(i, j + 1, 1) - q[1]);
                }
                let area = lx * ly;
                let m = other.node_at(self, q[0], q[1], bk, &key)?;
                self.mesh.springs.push(Spring {
                    a: n,
                    b: m,
                    stiffness: [
                        spec.tangential * area,
                        spec.tangential * area,
                        spec.normal * area,
                    ],
                    layer,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sized_grades_between_end_sizes() {
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
    fn sized_uniform_when_no_growth() {
        let p = sized(0.0, 1.0, 0.25, 0.25, 0.25, 1.0);
        assert_eq!(p.len(), 5);
        assert!((p[2] - 0.5).abs() < 1e-12);
        assert_eq!(sized(2.0, 2.0, 0.1, 0.1, 0.1, 1.2), vec![2.0]);
    }

    #[test]
    fn subset_keeps_breakpoints_and_uses_existing_lines() {
        let lines: Vec<f64> = (0..=20).map(|i| i as f64 * 0.5).collect();
        let s = subset(&lines, &[0.0, 3.0, 10.0], 2.0);
        assert!(s.contains(&3.0));
        assert_eq!(s[0], 0.0);
        assert_eq!(*s.last().unwrap(), 10.0);
        assert!(s.iter().all(|v| lines.contains(v)));
        assert!(s.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn tributary_sums_to_length() {
        let t = tributary(&[0.0, 1.0, 3.0, 4.0]);
        assert_eq!(t, vec![0.5, 1.5, 1.5, 0.5]);
    }
}
