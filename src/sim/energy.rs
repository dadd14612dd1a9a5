//! Energy terms of the discrete leapfrog system, reported per step for tests and diagnostics.
//!
//! Modal coordinates are mass-normalised, so all terms are in J. With the step
//! `a .* v^{j+1/2} = b .* v^{j-1/2} - Omega^2 eta^j + f^j`, `a = 1/dt + D/2`, `b = 1/dt - D/2`,
//! `f^j = Phi_g^T lambda^j - beta a_base(t^j)` and `eta^{j+1} = eta^j + dt v^{j+1/2}`,
//! multiplying by `(eta^{j+1} - eta^{j-1}) / 2 = dt (v^{j+1/2} + v^{j-1/2}) / 2` gives the exact
//! discrete balance
//!
//! `E^{j+1/2} - E^{j-1/2} = -dt vbar^T D vbar + f^j . dt vbar`,  `vbar = (v^{j+1/2} + v^{j-1/2}) / 2`,
//!
//! for the leapfrog ("shadow") energy `E^{j+1/2} = 1/2 |v^{j+1/2}|^2 + 1/2 eta^j^T Omega^2 eta^{j+1}`.
//! Without damping, excitation and contact it is conserved to round-off, while the plain
//! energy `1/2 |v|^2 + 1/2 eta^T Omega^2 eta` oscillates by O((w dt)^2) around it without drift.
//! The right-hand side splits into the base work, the damping loss and the contact work,
//! accumulated in [`EnergyAccounts`]. The boundary's elastic energy `1/2 lambda^T G_res lambda`
//! is reported separately: for frictionless contact the contact work on the modes is (up to
//! the time discretisation) minus its change.

/// Energy terms after one step, J.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Energy {
    /// Modal kinetic energy `1/2 |v^{j+1/2}|^2` with the half-step velocity of the step, J.
    pub kinetic: f64,
    /// Modal potential energy at the end of the step `1/2 eta^{j+1}^T Omega^2 eta^{j+1}`, J.
    pub potential: f64,
    /// Cross potential `1/2 eta^j^T Omega^2 eta^{j+1}` over the step (leapfrog form), J.
    pub potential_mid: f64,
    /// Elastic energy of the boundary `1/2 lambda^T G_res lambda` with the step's contact
    /// forces, J.
    pub boundary: f64,
    /// Cumulative work and losses up to and including this step.
    pub accounts: EnergyAccounts,
}

impl Energy {
    /// The leapfrog ("shadow") energy `kinetic + potential_mid`, J: changes only by the
    /// accounted work (see the module docs).
    pub fn leapfrog(&self) -> f64 {
        self.kinetic + self.potential_mid
    }

    /// The plain mechanical energy of the modes `kinetic + potential`, J.
    pub fn mechanical(&self) -> f64 {
        self.kinetic + self.potential
    }

    /// Leapfrog energy plus the boundary's elastic energy, J.
    pub fn total(&self) -> f64 {
        self.leapfrog() + self.boundary
    }
}

/// Cumulative work done on the modes since the state was created, J. Carried in the state,
/// so it continues across runs.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
pub struct EnergyAccounts {
    /// Work of the base excitation's inertia load `sum_j -a_base^j beta . dt vbar`, J.
    pub base_work: f64,
    /// Energy removed by modal damping `sum_j dt vbar^T D vbar` (>= 0), J.
    pub damping_dissipated: f64,
    /// Work of the contact forces on the modes `sum_j (Phi_g^T lambda^j) . dt vbar`, J.
    pub contact_work: f64,
}

impl EnergyAccounts {
    /// Net work put into the modes: base work minus damping loss plus contact work, J.
    pub fn net(&self) -> f64 {
        self.base_work - self.damping_dissipated + self.contact_work
    }
}
