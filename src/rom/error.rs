//! Errors of the ROM build: model consistency, the sparse eigen solver, the MacNeal
//! reduction and the explicit-step stability checks.

/// What went wrong while building or checking a ROM.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RomError {
    /// A matrix or vector of the FE model has the wrong size.
    #[error("FE model: {what} has size {found}, expected {expected} (the number of free DOFs)")]
    Dimension {
        /// Which item, e.g. "mass matrix rows".
        what: String,
        /// Expected size.
        expected: usize,
        /// Size found.
        found: usize,
    },
    /// An index into the free DOFs is out of range.
    #[error("FE model: {what} refers to free DOF {dof}, but the model has only {n_dof} free DOFs")]
    DofOutOfRange {
        /// Which item, e.g. "contact pair 3 (upper node, y)".
        what: String,
        /// The offending DOF index.
        dof: usize,
        /// Number of free DOFs.
        n_dof: usize,
    },
    /// The mode selection is not usable.
    #[error("mode selection {0}")]
    InvalidSelection(String),
    /// The model has nothing the reduction can work on.
    #[error("FE model: {0}")]
    EmptyModel(String),
    /// A value of the model or of an intermediate result is NaN or infinite.
    #[error("non-finite value in {what}")]
    NonFinite {
        /// Where the value was found.
        what: String,
    },
    /// The stiffness matrix is not positive definite (a part is not clamped or tied).
    #[error(
        "stiffness matrix is not positive definite: {negative} negative and {zero} zero (or \
         roundoff-level) pivots in its LDL^T factorisation; check that every part is clamped or \
         tied to a clamped part by an interface layer"
    )]
    StiffnessNotPositiveDefinite {
        /// Negative pivots.
        negative: usize,
        /// Zero pivots.
        zero: usize,
    },
    /// The sparse factorisation of K - sigma M failed.
    #[error(
        "sparse LDL^T factorisation of K - sigma M failed at shift {shift_hz:.6e} Hz: {detail}"
    )]
    Factorisation {
        /// Shift as a frequency, Hz (negative for negative shifts).
        shift_hz: f64,
        /// Solver message.
        detail: String,
    },
    /// The eigen solver did not converge the requested modes.
    #[error(
        "eigen solver: {detail} ({found} modes verified, {wanted}; \
         try a larger basis (EigenOptions::max_basis) or a lower cutoff)"
    )]
    EigenNotConverged {
        /// Modes found and verified so far.
        found: usize,
        /// What was asked for.
        wanted: String,
        /// What failed.
        detail: String,
    },
    /// No mode looks like the first flap mode of the upper beam.
    #[error(
        "no mode labelled 1FU among the lowest {searched} modes (labels: {labels}); \
         the 1FU frequency defines the cutoff ratio: select modes by count or by a cutoff in Hz"
    )]
    NoReferenceMode {
        /// Number of modes searched.
        searched: usize,
        /// The labels found, comma separated.
        labels: String,
    },
    /// The residual boundary flexibility is not positive definite.
    #[error(
        "residual boundary flexibility G_res is not positive definite with {n_modes} retained modes \
         and {n_boundary} boundary coordinates ({detail}): too many modes are retained for the \
         boundary size; lower the cutoff"
    )]
    ResidualFlexibilityNotPositive {
        /// Retained modes.
        n_modes: usize,
        /// Boundary coordinates (3 per contact pair).
        n_boundary: usize,
        /// Numerical detail.
        detail: String,
    },
    /// A dense eigen or Cholesky decomposition failed.
    #[error("dense decomposition of {what} failed: {detail}")]
    Dense {
        /// Which matrix.
        what: String,
        /// Solver message.
        detail: String,
    },
    /// An explicit time step beyond the stability limit.
    #[error(
        "time step {dt:.6e} s exceeds the explicit stability limit {dt_max:.6e} s with {state} \
         (at least {min_steps_per_period:.1} steps per 1FU period are needed)"
    )]
    TimeStepTooLarge {
        /// Requested step, s.
        dt: f64,
        /// Largest stable step, s.
        dt_max: f64,
        /// Contact state the limit applies to, e.g. "all pairs open".
        state: String,
        /// The limit as steps per reference period.
        min_steps_per_period: f64,
    },
}
