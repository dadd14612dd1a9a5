//! The ROM build pipeline: the model sections of a rig description ([`RigModel`]) -> mesh ->
//! assembly (or CalculiX matrices) -> MacNeal reduction -> damping from the rig's table ->
//! provenance. Reports progress as [`BuildEvent`]s; the CLI renders them. The description's
//! `[reduction]` becomes a [`ModeSelection`] here (`ModeSelection::from(&ReductionSpec)`).

use std::path::Path;
use std::time::Instant;

use super::{ModeSelection, Rom};
use crate::config::{ReductionSpec, RigModel};

impl From<&ReductionSpec> for ModeSelection {
    /// The mode selection of a validated `[reduction]` (exactly one key set; none means the
    /// default 180 x f(1FU)).
    fn from(spec: &ReductionSpec) -> ModeSelection {
        match (spec.cutoff_ratio, spec.cutoff_hz, spec.modes) {
            (Some(ratio), _, _) => ModeSelection::CutoffRatio { ratio },
            (None, Some(hz), _) => ModeSelection::CutoffHz { hz },
            (None, None, Some(count)) => ModeSelection::Count { count },
            (None, None, None) => ModeSelection::default(),
        }
    }
}

/// Progress of a build.
#[derive(Clone, Debug)]
pub enum BuildEvent {
    /// A stage started.
    Stage {
        /// Stage name.
        name: &'static str,
        /// What it is doing.
        detail: String,
    },
    /// A stage finished.
    StageDone {
        /// Stage name.
        name: &'static str,
        /// Wall time, s.
        seconds: f64,
        /// Result summary.
        detail: String,
    },
    /// Eigen solve progress.
    Eigen {
        /// Converged modes so far.
        converged: usize,
        /// Modes wanted, when the selection is a count.
        target: Option<usize>,
        /// Cutoff frequency, Hz, when the selection is a frequency (known once f(1FU) is).
        target_hz: Option<f64>,
        /// Highest converged frequency, Hz.
        highest_hz: f64,
    },
}

/// Errors of a build, each naming its stage.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// The rig description is invalid.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// Meshing or assembly failed.
    #[error("assembling the FE model: {0}")]
    Fe(#[from] crate::fe::FeError),
    /// Reading CalculiX files failed.
    #[error(transparent)]
    Calculix(#[from] crate::fe::calculix::CalculixError),
    /// Condensing CalculiX's incompatible-mode DOFs failed.
    #[error("condensing CalculiX's internal DOFs: {0}")]
    Condense(#[from] crate::fe::calculix::CondenseError),
    /// The reduction failed.
    #[error("reducing the model: {0}")]
    Rom(#[from] super::RomError),
}

/// Options of a build beyond the rig description.
#[derive(Clone, Debug, Default)]
pub struct BuildOptions {
    /// Overrides the description's mode selection.
    pub selection: Option<ModeSelection>,
}

impl BuildOptions {
    /// The mode selection of a build of `cfg`: the override, else the description's
    /// `[reduction]`.
    pub fn selection_for(&self, cfg: RigModel<'_>) -> ModeSelection {
        self.selection
            .unwrap_or_else(|| ModeSelection::from(cfg.reduction))
    }
}

/// Hash identifying a ROM: the rig description's canonical hash and the mode selection.
pub fn build_hash(cfg: RigModel<'_>, selection: &ModeSelection, source: &str) -> String {
    use sha2::{Digest, Sha256};
    let text = format!(
        "{}|{}|{}|format{}",
        cfg.canonical_hash(),
        serde_json::to_string(selection).expect("selection serialises"),
        source,
        super::file::FORMAT_VERSION
    );
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Builds the ROM of a rig description (its model sections: `cfg.model()` of a
/// [`crate::config::RigConfig`]) from its native FE model.
pub fn build_native(
    cfg: RigModel<'_>,
    opts: &BuildOptions,
    on_event: &mut dyn FnMut(BuildEvent),
) -> Result<Rom, BuildError> {
    let t0 = Instant::now();
    let selection = opts.selection_for(cfg);
    on_event(BuildEvent::Stage {
        name: "mesh",
        detail: "structured hex mesh of the rig".into(),
    });
    let t = Instant::now();
    let mesh = crate::fe::rig::mesh_rig(cfg)?;
    let model = crate::fe::assembly::assemble(&mesh, cfg.contact.clearance)?;
    let assembly = t.elapsed().as_secs_f64();
    on_event(BuildEvent::StageDone {
        name: "assembly",
        seconds: assembly,
        detail: format!(
            "{} nodes, {} elements, {} springs, {} free DOFs",
            mesh.n_nodes(),
            mesh.elements.len(),
            mesh.springs.len(),
            model.n_dof()
        ),
    });
    finish(
        cfg,
        model,
        selection,
        "native".to_string(),
        assembly,
        t0,
        on_event,
    )
}

/// Builds the ROM from CalculiX matrices (`JOB.inp`, `JOB.sti`, `JOB.mas`, `JOB.dof`); the rig
/// description's model sections supply damping, friction and the default mode selection.
pub fn build_calculix(
    job: &Path,
    cfg: RigModel<'_>,
    opts: &BuildOptions,
    on_event: &mut dyn FnMut(BuildEvent),
) -> Result<Rom, BuildError> {
    let t0 = Instant::now();
    let selection = opts.selection_for(cfg);
    on_event(BuildEvent::Stage {
        name: "read",
        detail: format!("CalculiX job {}", job.display()),
    });
    let t = Instant::now();
    let imported = crate::fe::calculix::import(job)?;
    let n_internal = imported
        .dofs
        .iter()
        .filter(|d| d.group == crate::fe::DofGroup::Internal)
        .count();
    // NOTE: ccx keeps the 9 bubble DOFs of every C3D8I element as global DOFs with a mass that
    // is only semidefinite; they are condensed with their static response, exactly as the
    // native element does per element, so the reduction sees the same kind of model.
    let model = if n_internal > 0 {
        crate::fe::calculix::condense_internal_dofs(&imported)?
    } else {
        imported
    };
    let assembly = t.elapsed().as_secs_f64();
    on_event(BuildEvent::StageDone {
        name: "read",
        seconds: assembly,
        detail: format!(
            "{} nodes, {} free DOFs ({} internal DOFs condensed), {} contact pairs",
            model.n_nodes(),
            model.n_dof(),
            n_internal,
            model.pairs.len()
        ),
    });
    let name = job
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    finish(
        cfg,
        model,
        selection,
        format!("calculix:{name}"),
        assembly,
        t0,
        on_event,
    )
}

fn finish(
    cfg: RigModel<'_>,
    model: crate::fe::FeModel,
    selection: ModeSelection,
    source: String,
    assembly: f64,
    t0: Instant,
    on_event: &mut dyn FnMut(BuildEvent),
) -> Result<Rom, BuildError> {
    on_event(BuildEvent::Stage {
        name: "reduce",
        detail: format!("{} DOFs", model.n_dof()),
    });
    let mut rom = super::macneal::reduce(&model, selection, &mut |p| {
        on_event(BuildEvent::Eigen {
            converged: p.converged,
            target: p.wanted,
            target_hz: p.target_hz,
            highest_hz: p.ritz_max_hz,
        })
    })?;
    let tm = &rom.meta.timings;
    on_event(BuildEvent::StageDone {
        name: "factorise",
        seconds: tm.factorisation,
        detail: "sparse Cholesky of K".into(),
    });
    on_event(BuildEvent::StageDone {
        name: "eigen",
        seconds: tm.eigen,
        detail: format!(
            "{} modes up to {:.0} Hz",
            rom.n_modes(),
            rom.frequencies_hz().last().copied().unwrap_or(0.0)
        ),
    });
    on_event(BuildEvent::StageDone {
        name: "attachment",
        seconds: tm.attachment,
        detail: format!("{} boundary coordinates", 3 * rom.n_pairs()),
    });
    let freqs = rom.frequencies_hz();
    rom.damping_ratio = cfg.damping.damping_ratios(&rom.labels, &freqs);
    rom.friction = cfg.contact.friction;
    rom.meta.timings.assembly = assembly;
    rom.meta.config_hash = build_hash(cfg, &selection, &source);
    rom.meta.source = source;
    rom.meta.rig_name = cfg.rig.name.clone();
    rom.meta.beam_length = cfg.rig.beam_length;
    rom.meta.build_seconds = t0.elapsed().as_secs_f64();
    Ok(rom)
}
