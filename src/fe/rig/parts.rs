//! Assembly of the part grids into one [`Mesh`]: global node numbering (with the fused
//! protrusion nodes), element blocks, coincident-node lookup on touching faces and the
//! interface-layer springs.

use std::collections::BTreeMap;

use crate::config::{ConfigError, LayerSpec, RigModel};
use crate::fe::grid::BoxGrid;
use crate::fe::mesh::{ElementBlock, ElementKind, HexElement, Material, Mesh, Spring};

use super::lines::find_line;

pub(super) fn invalid(cfg: &RigModel, key: &str, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        file: cfg.source.to_string(),
        key: key.to_string(),
        value: String::from("(mesher)"),
        expected: expected.to_string(),
    }
}

/// One meshed part: the global index of each local node, its grid dims and its physical
/// plan lines (meaningful for box parts; the tapered beam keeps its parameter lines).
pub(super) struct Part {
    pub(super) map: Vec<usize>,
    pub(super) dims: [usize; 3],
    pub(super) xs: Vec<f64>,
    pub(super) ys: Vec<f64>,
}

impl Part {
    pub(super) fn global(&self, i: usize, j: usize, k: usize) -> usize {
        self.map[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    pub(super) fn top_k(&self) -> usize {
        self.dims[2] - 1
    }

    /// Global nodes of the face k, in grid order.
    pub(super) fn face_nodes(&self, k: usize) -> Vec<usize> {
        let mut v = Vec::with_capacity(self.dims[0] * self.dims[1]);
        for j in 0..self.dims[1] {
            for i in 0..self.dims[0] {
                v.push(self.global(i, j, k));
            }
        }
        v
    }

    /// Global node of a box part at plan position (x, y) on face k.
    pub(super) fn node_at(
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
                        &b.cfg,
                        key,
                        "conforming grid lines (internal meshing inconsistency)",
                    ))
                }
            }
            _ => Err(ConfigError::Invalid {
                file: b.cfg.source.to_string(),
                key: key.to_string(),
                value: format!("node at ({x}, {y})"),
                expected: String::from(
                    "a coincident node on the touching face (internal meshing inconsistency)",
                ),
            }),
        }
    }

    /// Face node nearest to the plan position (x, y).
    pub(super) fn nearest_on_face(&self, b: &Builder, k: usize, x: f64, y: f64) -> Option<usize> {
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
pub(super) struct FaceRegion<'p> {
    pub(super) part: &'p Part,
    pub(super) k: usize,
    pub(super) i: (usize, usize),
    pub(super) j: (usize, usize),
}

/// Element block indices of the parts.
pub(super) struct BlockIds {
    pub(super) base: usize,
    pub(super) spacer: usize,
    pub(super) top: usize,
    pub(super) lower_beam: usize,
    pub(super) upper_beam: usize,
    pub(super) lower_probe: usize,
    pub(super) upper_probe: usize,
    pub(super) protrusion: usize,
}

impl BlockIds {
    pub(super) fn new(b: &mut Builder, cfg: &RigModel) -> Self {
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
pub(super) struct Builder<'a> {
    pub(super) cfg: RigModel<'a>,
    pub(super) mesh: Mesh,
    pub(super) material_index: BTreeMap<String, usize>,
}

impl<'a> Builder<'a> {
    pub(super) fn new(cfg: RigModel<'a>) -> Self {
        let mut mesh = Mesh::default();
        let mut material_index = BTreeMap::new();
        for (name, m) in cfg.materials {
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

    pub(super) fn block(&mut self, name: &str, material: &str, kind: ElementKind) -> usize {
        // Materials were validated to exist.
        let material = self.material_index.get(material).copied().unwrap_or(0);
        self.mesh.blocks.push(ElementBlock {
            name: name.to_string(),
            material,
            kind,
        });
        self.mesh.blocks.len() - 1
    }

    pub(super) fn add_part(&mut self, block: usize, grid: BoxGrid, xs: &[f64], ys: &[f64]) -> Part {
        self.add_part_fused(block, grid, xs, ys, &[])
    }

    /// Adds a part; `fused` lists (local node, existing global node) pairs that are shared.
    pub(super) fn add_part_fused(
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
    pub(super) fn layer_springs(
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
