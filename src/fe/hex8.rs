//! 8-node hex shape functions and element matrices: plain trilinear (C3D8) and the
//! incompatible-mode formulation (C3D8I) whose bubble modes are condensed per element.

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
