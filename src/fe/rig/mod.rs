//! The rig mesher: turns the model sections of a rig description ([`RigModel`]) into the
//! parent [`Mesh`]. Every part is a
//! structured hex grid ([`BoxGrid`]) with graded lines and its own element block; parts
//! joined by an elastic interface layer get their own coincident nodes and zero-length
//! [`Spring`](crate::fe::mesh::Spring)s; the protrusion is fused to the upper probe (shared nodes).
//!
//! Grid lines are chosen so that touching faces conform:
//! - x: both beams share one set of lines (clamp, free span, probe seat, tip); the blocks take
//!   the beams' lines inside the clamp.
//! - plan of the probes: the seat edges, the contact patch lines (uniform, `contact.nodes`,
//!   or `reduction.contact_nodes` when given) and lines graded from the patch spacing up to
//!   `mesh.probes.element`; both probes and the protrusion share them.
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

mod lines;
mod parts;

use crate::config::{ConfigError, Mount, RigModel};
use crate::fe::grid::BoxGrid;
use crate::fe::mesh::{ContactPair, Mesh, PointMass, SensorPoint};

pub use lines::sized;
use lines::{index_of, tributary, Lines};
use parts::{invalid, BlockIds, Builder, FaceRegion};

/// Builds the parent mesh of the rig from the model sections of its description (validating
/// them first): `mesh_rig(cfg.model())` for a [`crate::config::RigConfig`].
///
/// Node sets: `LOWER` (lower beam + lower probe), `UPPER` (upper beam + upper probe +
/// protrusion), `CLAMP` (blocks), `FIXED` (base block bottom face), `CONTACT_LOWER` and
/// `CONTACT_UPPER` (the pairs' nodes), `SENSOR_<name>` per model-output sensor, `PLATFORM_<name>` per platform accelerometer. Contact pair (i, j) of the
/// patch (i along x, j along y) is at index `i + nodes_x * j`, frame n = +z, t1 = +x, t2 = +y.
pub fn mesh_rig(cfg: RigModel<'_>) -> Result<Mesh, ConfigError> {
    // A description built in code has not been through the parser's validation.
    cfg.validate()?;
    let g = Geometry::new(&cfg);
    let lines = Lines::new(&cfg, &g);
    let mut b = Builder::new(cfg);

    let ids = BlockIds::new(&mut b, &cfg);
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
            let lower_node = lprobe.node_at(&b, q[0], q[1], lp_top, cfg.patch_nodes_key())?;
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
            .ok_or_else(|| invalid(&cfg, &key, "no node on the mounting face"))?;
        // Platform accelerometers sit on the clamped base: they measure the prescribed base
        // motion, not a model output, so their set is PLATFORM_<name> (SENSOR_<name> sets are
        // model outputs, also in the CalculiX exchange).
        if s.mount == Mount::Platform {
            b.mesh
                .node_sets
                .insert(format!("PLATFORM_{}", s.name), vec![node]);
            continue;
        }
        b.mesh
            .node_sets
            .insert(format!("SENSOR_{}", s.name), vec![node]);
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
pub(super) struct Geometry {
    pub(super) l: f64,
    pub(super) lc: f64,
    pub(super) seat_x: (f64, f64),
    pub(super) seat_w: f64,
    pub(super) patch_x: (f64, f64),
    pub(super) patch_y: (f64, f64),
    pub(super) w_root: f64,
    pub(super) w_tip: f64,
    pub(super) x_taper_end: f64,
}

impl Geometry {
    fn new(cfg: &RigModel) -> Self {
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
