//! CalculiX exchange of the FE parent model: [`export`] writes a [`Mesh`](crate::fe::Mesh) as
//! two CalculiX decks, [`import`] reads the stiffness and mass matrices CalculiX writes back
//! into an [`FeModel`](crate::fe::FeModel), [`run_ccx`] runs the solver and
//! [`read_dat_frequencies`] reads its eigenfrequencies.
//!
//! # What `ccx` writes (format reference)
//!
//! Established by running small cantilevers (two C3D8 or C3D8I elements, a SPRING2 interface
//! between coincident nodes, a MASS element, `*BOUNDARY` on the root face) through CalculiX
//! 2.20 (Debian `calculix-ccx`). `sim-fixtures/calculix/cantilever/` holds such a deck with
//! the files ccx wrote for it.
//!
//! **Units.** CalculiX has none; the decks are written in SI, so stiffness is N/m, mass kg,
//! frequencies Hz (the `.dat` column `CYCLES/TIME`).
//!
//! **`*FREQUENCY,SOLVER=MATRIXSTORAGE`** takes no data line (a line with the number of modes
//! gives a "card image cannot be interpreted" warning), computes no eigenvalues and writes:
//! - `JOB.sti` (stiffness) and `JOB.mas` (mass): one entry per line, `i j value`, whitespace
//!   separated (`1 2  1.6826923076923e+08`), 1-based, only `i <= j` (one triangle), column by
//!   column: `1 1`, `1 2`, `2 2`, `1 3`, `2 3`, `3 3`, ... Every column ends with its diagonal,
//!   so the largest index is the matrix dimension. Both files share one sparsity pattern;
//!   zeros inside the pattern are written (`0.0000000000000e+00`), and cancellation leaves
//!   rounding noise (`3e-8` next to `1e9`).
//! - `JOB.dof`: one line per matrix row, `node.dir` (`13.2` = node 13, y), ordered by node then
//!   direction. DOFs removed by `*BOUNDARY` are absent (a whole node or a single direction),
//!   and so are nodes no element uses.
//!
//! **C3D8I** is not condensed: ccx expands every C3D8I element with 3 extra nodes, numbered
//! after the largest node number of the deck, 3 per C3D8I element in element order. Their 9
//! DOFs (the incompatible-mode amplitudes) appear in `.sti`, `.mas` and `.dof` like ordinary
//! nodes (a two-element C3D8I cantilever: 27 node DOFs, 18 internal ones), and they carry
//! mass: ccx integrates the bubble functions into the consistent mass with 2x2x2 Gauss
//! points (`4/9 rho V` on each bubble diagonal, coupled to the corner DOFs). At those points
//! the three bubbles of one direction are equal, so 6 of each element's 9 bubble-DOF
//! combinations have no mass at all: ccx's M is only positive semidefinite (168 massless
//! combinations for 28 C3D8I elements, measured), which defeats any solver that factorises
//! M. [`import`] keeps the bubble DOFs as [`DofGroup::Internal`](crate::fe::DofGroup) DOFs
//! (node = CalculiX number minus one, no coordinates, 0 in the base-excitation vector);
//! [`condense_internal_dofs`] condenses them with the static bubble response, which gives
//! the native Hex8I matrices of [`assemble`](crate::fe::assemble) entry by entry (2e-14
//! relative, measured) with a positive definite M. The condensed model is slightly stiffer
//! than ccx's in the higher modes of coarse meshes (two 8-cell cantilevers: within 0.05 % up
//! to the 8th mode, 0.17 % at the 10th, 17 f1). C3D8 adds no DOFs.
//!
//! **Springs and masses are in the matrices.** `*ELEMENT,TYPE=SPRING2` + `*SPRING,ELSET=..`
//! with the data lines `d1,d2` (DOF at the first and second node) and `k` adds `k` on the
//! two diagonal entries and `-k` on the coupling; it works between coincident nodes (zero
//! length). `*ELEMENT,TYPE=MASS` + `*MASS,ELSET=..` with `m` adds `m` on the three
//! translational diagonal entries (ccx then warns that its internal material `MASS` has no
//! elastic constants: harmless). The solids' mass is the consistent mass.
//!
//! **Eigenvalues (`*FREQUENCY` with a number of modes).** `JOB.dat` holds a block
//! ```text
//!      E I G E N V A L U E   O U T P U T
//!
//!  MODE NO    EIGENVALUE                       FREQUENCY
//!                                      REAL PART            IMAGINARY PART
//!                            (RAD/TIME)      (CYCLES/TIME     (RAD/TIME)
//!
//!       1   0.1984539E+09   0.1408737E+05   0.2242074E+04   0.0000000E+00
//! ```
//! (7 significant digits) followed by participation factors and effective masses.
//!
//! **Pitfalls found on the way.**
//! - ccx exits with status 0 even when it fails; failures are `*ERROR` lines on stdout
//!   ([`run_ccx`] checks for them). On failure the `.dat` may hold zero eigenvalues.
//! - ARPACK fails (`*ERROR in d[n,s]aupd: info=-3`, zero eigenvalues written) when more than
//!   about a fifth of the equations are requested as modes (27 equations: 5 modes work, 6
//!   fail; 45 equations: 9 work, 10 fail).
//! - Numeric fields are read as 20 characters: longer numbers are silently truncated
//!   (`1.00000000000000000000e-2` became `1.0`). A real without a decimal point on a
//!   `*SPRING` data line (`1e6`, `1000000`) is taken for the DOF line ("*SPRING card without
//!   data"). The export writes every real with a decimal point in at most 20 characters
//!   (shortest exact form, else at least 13 significant digits).
//! - `*INCLUDE` paths are resolved against ccx's working directory, not the including file;
//!   the exported decks are therefore self-contained.
//! - A keyword line continued on the next line (`*NSET,` + `NSET=FIX`) breaks ccx's set
//!   count ("increase nset_"); the export never continues keyword lines.
//! - Keywords and parameters are case-insensitive, set names are upper-cased, long comment
//!   lines and data lines of 185 characters are fine, `*NSET,GENERATE` works.
//!
//! # The decks rigtwin writes
//! [`export`] writes `JOB.inp` (a `*FREQUENCY` step for the requested modes) and
//! `JOB_matrix.inp` (the same model, `*FREQUENCY,SOLVER=MATRIXSTORAGE`). Nodes are the mesh
//! nodes numbered from 1; solids come first (one element set per mesh block, named after the
//! block), then the interface springs (SPRING2, one element per spring and global direction,
//! grouped into sets `SPR_<LAYER>_<X|Y|Z>_<k>` of equal stiffness), then the point masses
//! (`MASS_<k>`). Node sets: every `mesh.node_sets` entry, `BC_FIXED` (the clamped nodes,
//! `*BOUNDARY` 1-3), and the sets describing the reduction's index data:
//! - `CONTACT_LOWER`, `CONTACT_UPPER`: the contact pairs in pair order, pair k = the k-th
//!   node of each set. Because other tools may re-sort sets, [`import`] pairs by order only
//!   when every pair is geometrically consistent (the node-to-node vectors agree up to a
//!   tenth of the patch spacing in the contact plane) and otherwise pairs each lower node with
//!   the upper node at the same in-plane position.
//! - `SENSOR_<NAME>`: one node per sensor.
//!
//! Metadata that sets cannot carry goes into comment lines (ignored by ccx, all optional on
//! import):
//! - `** rigtwin clearance <m>` (default: the mean normal distance of the paired nodes),
//! - `** rigtwin pair <lower node> <upper node> area <m^2> n <x y z> t1 <x y z>` (default:
//!   n from the lower to the upper node, t1 along +x projected into the contact plane (+y
//!   when n is along x), t2 = n x t1, area = tributary area on the structured lower patch),
//! - `** rigtwin sensor <name> dir <x y z>` (default: the lower-cased set suffix, direction z).
//!
//! [`import`] reads `JOB.inp` (nodes, node and element sets, `*INCLUDE` relative to the
//! including file, then to the working directory) and `JOB.sti`, `JOB.mas`, `JOB.dof`.
//! Nodes of the set `LOWER` are [`DofGroup::Lower`](crate::fe::DofGroup), of `UPPER`
//! `Upper` (both required; a node set, or else the nodes of an element set of that name),
//! all other deck nodes `Clamp`. The matrices are checked as ccx writes them: three fields
//! per line, indices from 1, every diagonal present, an entry repeated (in either triangle)
//! only with the same value, `.sti`, `.mas` and `.dof` of one size. Contact and sensor nodes
//! must have free DOFs.
//!
//! [`run_ccx`] starts `$RIGTWIN_CCX` (default `ccx`) in the deck's directory.

mod condense;
mod deck;
mod export;
mod import;
mod matrix;
mod patch;
mod run;

use std::path::PathBuf;

pub use condense::{condense_internal_dofs, CondenseError};
pub use export::{export, ExportedFiles};
pub use import::{import, job_file};
pub use run::{
    ccx_available, ccx_command, ccx_required, read_dat_frequencies, run_ccx, CcxRun, CCX_ENV,
};

/// Errors of the CalculiX exchange. Every variant names the file (or job) and says what was
/// expected.
#[derive(Debug, thiserror::Error)]
pub enum CalculixError {
    /// A file could not be read, written or created.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A line does not have the expected form.
    #[error("{path}:{line}: expected {expected}, found `{found}`")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What the line should hold.
        expected: String,
        /// What it holds.
        found: String,
    },
    /// A matrix index points outside the matrix given by the `.dof` file.
    #[error(
        "{path}:{line}: index {index} is out of range: {dof} lists {dim} DOFs, expected 1..={dim}"
    )]
    IndexOutOfRange {
        /// The matrix file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The offending 1-based index.
        index: usize,
        /// The DOF file that fixes the dimension.
        dof: PathBuf,
        /// The matrix dimension.
        dim: usize,
    },
    /// Stiffness and mass files describe matrices of different size.
    #[error("{sti} is {n_sti}x{n_sti} but {mas} is {n_mas}x{n_mas}: expected one size (is one file truncated?)")]
    SizeMismatch {
        /// The stiffness file.
        sti: PathBuf,
        /// Its dimension (largest index).
        n_sti: usize,
        /// The mass file.
        mas: PathBuf,
        /// Its dimension.
        n_mas: usize,
    },
    /// The `.dof` file has a different number of DOFs than the matrices.
    #[error("{path} lists {lines} DOFs but {matrix} is {dim}x{dim}: expected one `node.dir` line per matrix row (is one file truncated?)")]
    DofCount {
        /// The `.dof` file.
        path: PathBuf,
        /// Its number of DOF lines.
        lines: usize,
        /// The matrix file.
        matrix: PathBuf,
        /// The matrix dimension.
        dim: usize,
    },
    /// A matrix file lacks the diagonal entry of a DOF (ccx writes all of them).
    #[error("{path}: no diagonal entry for DOF {dof}: expected one per DOF, as ccx writes them (is the file truncated?)")]
    MissingDiagonal {
        /// The matrix file.
        path: PathBuf,
        /// 1-based DOF index.
        dof: usize,
    },
    /// A matrix entry is given twice with different values (as `i j` and `j i`, or repeated).
    #[error("{path}:{line}: entry ({row}, {col}) = {value:e} contradicts line {first_line} ({first_value:e}): a symmetric matrix lists each entry once")]
    ConflictingEntry {
        /// The matrix file.
        path: PathBuf,
        /// Line of the second occurrence.
        line: usize,
        /// 1-based row.
        row: usize,
        /// 1-based column.
        col: usize,
        /// Value of the second occurrence.
        value: f64,
        /// Line of the first occurrence.
        first_line: usize,
        /// Value of the first occurrence.
        first_value: f64,
    },
    /// A set the import or the deck itself needs is not defined.
    #[error("{path}: set {name} is not defined; {needed_for}")]
    MissingSet {
        /// The deck.
        path: PathBuf,
        /// Set name (upper case).
        name: String,
        /// Why it is needed.
        needed_for: String,
    },
    /// A set or element refers to a node (or element) no keyword defines.
    #[error("{path}:{line}: {context} refers to {what} {id}, which is not defined")]
    UnknownNode {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The set or element that refers to it.
        context: String,
        /// "node" or "element".
        what: &'static str,
        /// The CalculiX number.
        id: usize,
    },
    /// The deck parses but does not describe a usable model (contact pairs, sensors).
    #[error("{path}: {what}")]
    Model {
        /// The deck.
        path: PathBuf,
        /// What is wrong and what was expected.
        what: String,
    },
    /// The mesh given to [`export`] is inconsistent.
    #[error("cannot export the mesh: {what}")]
    InvalidMesh {
        /// What is wrong.
        what: String,
    },
    /// The `ccx` executable was not found.
    #[error("`{command}` not found on PATH: install CalculiX (Debian: calculix-ccx) or set RIGTWIN_CCX to the executable")]
    CcxNotFound {
        /// The command that was tried.
        command: String,
    },
    /// `ccx` ran but reported a failure.
    #[error("ccx failed on job {job} in {dir}: {message}")]
    CcxFailed {
        /// Working directory.
        dir: PathBuf,
        /// Job name.
        job: String,
        /// Exit status and the `*ERROR` lines of its output.
        message: String,
    },
}

impl CalculixError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        CalculixError::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn parse(
        path: impl Into<PathBuf>,
        line: usize,
        expected: impl Into<String>,
        found: impl Into<String>,
    ) -> Self {
        CalculixError::Parse {
            path: path.into(),
            line,
            expected: expected.into(),
            found: found.into(),
        }
    }
}

/// Parses a CalculiX/Fortran real (`1.5`, `7850.`, `2.1e11`, `2.1D+11`).
pub(crate) fn parse_real(s: &str) -> Option<f64> {
    let s = s.trim();
    let v: f64 = if s.contains(['d', 'D']) {
        s.replace(['d', 'D'], "e").parse().ok()?
    } else {
        s.parse().ok()?
    };
    v.is_finite().then_some(v)
}
