//! Reduced-order model: the sparse generalized eigen solver ([`eigen`]), MacNeal reduction
//! with relative-displacement boundary coordinates ([`macneal`]), mode labels ([`labels`]),
//! explicit-step stability limits ([`stability`]) and the versioned ROM file ([`file`](mod@file)).
//!
//! The ROM (DESIGN.md, "The model", step 3):
//! `g = Phi_g eta + G_res lambda + g0` and `eta'' + D eta' + Omega^2 eta = Phi_g^T lambda - beta a_base`,
//! with a massless boundary (M_red = diag(0, I)) and the exact static boundary flexibility.
//! In stiffness form `K_gg = G_res^-1`, `K_g_eta = -K_gg Phi_g`,
//! `K_eta_eta = Omega^2 + Phi_g^T K_gg Phi_g`.

pub mod build;
pub mod cache;
pub mod eigen;
pub mod error;
pub mod file;
pub mod info;
pub mod labels;
pub mod macneal;
pub mod stability;
mod truncate;

pub use error::RomError;

use faer::Mat;

/// How many free-interface modes to keep.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ModeSelection {
    /// All modes up to `ratio` x f(1FU) (the reference: 180).
    CutoffRatio {
        /// Cutoff as a multiple of the 1FU frequency.
        ratio: f64,
    },
    /// All modes up to a frequency, Hz.
    CutoffHz {
        /// Cutoff frequency, Hz.
        hz: f64,
    },
    /// The lowest `count` modes.
    Count {
        /// Number of modes.
        count: usize,
    },
}

impl Default for ModeSelection {
    fn default() -> Self {
        ModeSelection::CutoffRatio { ratio: 180.0 }
    }
}

/// A sensor output row of the ROM: the measured displacement is
/// `y = c_eta . eta + c_lambda . lambda` (relative to the base); velocities and
/// accelerations follow by differentiation in the integrator.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RomOutput {
    /// Channel name, e.g. "upper_tip".
    pub name: String,
    /// Modal participation (length n_modes), m per unit modal coordinate.
    pub c_eta: Vec<f64>,
    /// Residual static response to boundary forces (length 3 C), m/N.
    pub c_lambda: Vec<f64>,
}

/// Wall time of the build stages, s.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BuildTimings {
    /// Meshing and assembly of K and M (or reading CalculiX matrices).
    pub assembly: f64,
    /// Sparse Cholesky factorisation of K (symbolic + numeric).
    pub factorisation: f64,
    /// Eigen solve (Lanczos iterations, Ritz vectors, residuals).
    pub eigen: f64,
    /// Attachment modes: static flexibility, residual flexibility, its inverse, output rows.
    pub attachment: f64,
}

/// The reduced-order model with everything the integrator, the twin and reports need.
#[derive(Clone, Debug)]
pub struct Rom {
    /// Provenance and summary figures.
    pub meta: RomMeta,
    /// Natural circular frequencies of the retained free-interface modes, rad/s, ascending.
    pub omega: Vec<f64>,
    /// Modal damping ratios, one per mode.
    pub damping_ratio: Vec<f64>,
    /// Best-effort mode labels (1FL, 1FU, 1EL, ...), one per mode.
    pub labels: Vec<String>,
    /// Retained modes at the boundary, 3C x n_modes (rows: pair-major n, t1, t2).
    pub phi_g: Mat<f64>,
    /// Residual boundary flexibility, 3C x 3C, m/N (symmetric positive definite).
    pub g_res: Mat<f64>,
    /// Boundary stiffness K_gg = G_res^-1, 3C x 3C, N/m.
    pub k_gg: Mat<f64>,
    /// Modal participation of the base acceleration, beta = Phi^T M b (length n_modes), kg^0.5.
    pub beta: Vec<f64>,
    /// Tributary area of each contact pair, m^2.
    pub pair_area: Vec<f64>,
    /// Position of each contact pair (lower node), m.
    pub pair_position: Vec<[f64; 3]>,
    /// Nominal clearance (initial normal gap), m.
    pub clearance: f64,
    /// Coulomb friction coefficient (static = dynamic).
    pub friction: f64,
    /// Sensor output rows.
    pub outputs: Vec<RomOutput>,
}

/// Provenance and summary of a ROM build (the JSON of `rigtwin rom info` is built from it).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RomMeta {
    /// SHA-256 (hex) of the canonical rig description and reduction settings the ROM came from.
    pub config_hash: String,
    /// Where K and M came from: "native" or "calculix:JOB".
    pub source: String,
    /// Rig name from the description.
    pub rig_name: String,
    /// Free length l of the beams (the length unit of test plans: levels and clearances are
    /// given as fractions of l), m. 0 when unknown (synthetic ROMs).
    #[serde(default)]
    pub beam_length: f64,
    /// Free DOFs of the parent model.
    pub n_dof: usize,
    /// Mesh nodes and solid elements of the parent model.
    pub n_nodes: usize,
    /// Solid elements of the parent model.
    pub n_elements: usize,
    /// Mode selection used.
    pub selection: ModeSelection,
    /// Index of the mode taken as 1FU (the reference frequency omega_2).
    pub reference_mode: usize,
    /// Largest relative eigen residual ||K phi - w^2 M phi|| / (w^2 ||M phi||) over retained modes.
    pub max_eigen_residual: f64,
    /// Relative error of the ROM's static boundary flexibility against the parent model's,
    /// checked on random boundary loads.
    pub static_flexibility_error: f64,
    /// Build stage timings, s.
    pub timings: BuildTimings,
    /// Total build time, s.
    pub build_seconds: f64,
    /// Largest stable explicit step with all pairs open, in steps per 1FU period.
    pub stable_steps_per_period_open: f64,
    /// Same with all pairs closed (largest eigenvalue of Omega^2 + Phi_g^T K_gg Phi_g).
    pub stable_steps_per_period_closed: f64,
}

impl Rom {
    /// Number of retained modes.
    pub fn n_modes(&self) -> usize {
        self.omega.len()
    }

    /// Number of contact pairs C (the boundary has 3 C coordinates).
    pub fn n_pairs(&self) -> usize {
        self.pair_area.len()
    }

    /// Natural frequencies, Hz.
    pub fn frequencies_hz(&self) -> Vec<f64> {
        self.omega
            .iter()
            .map(|w| w / (2.0 * std::f64::consts::PI))
            .collect()
    }

    /// The reference circular frequency omega_2 (the 1FU mode), rad/s.
    pub fn omega_ref(&self) -> f64 {
        self.omega[self.meta.reference_mode]
    }
}
