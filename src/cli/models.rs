//! The models the commands run: rig descriptions (a file, or the embedded default) and their
//! ROMs, built or taken from the cache with a progress display; the simulated rig's own truth
//! ROM beside the twin's.

use anyhow::Context;
use std::path::{Path, PathBuf};

use super::progress::BuildProgress;
use crate::config::RigConfig;
use crate::rom::build::BuildOptions;
use crate::rom::Rom;

/// The rig description at `path`, or the embedded default rig without one.
pub(crate) fn load_config(path: Option<&Path>) -> anyhow::Result<RigConfig> {
    Ok(match path {
        Some(p) => RigConfig::from_path(p)?,
        None => RigConfig::default_rig(),
    })
}

/// The rig description at `path` and its text (stored in session logs), or the embedded
/// default rig's.
pub(crate) fn load_config_text(path: Option<&Path>) -> anyhow::Result<(RigConfig, String)> {
    Ok(match path {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the rig description {}", p.display()))?;
            (RigConfig::from_str(&text, &p.display().to_string())?, text)
        }
        None => (
            RigConfig::default_rig(),
            crate::config::DEFAULT_RIG_TOML.to_string(),
        ),
    })
}

/// Returns the cached ROM of `cfg`, building it if the cache has none for the current rig
/// description (the cache key is the ROM's build hash); and whether it was reused.
pub(crate) fn cached_rom(
    cfg: &RigConfig,
    rebuild: bool,
    quiet: bool,
) -> anyhow::Result<(Rom, PathBuf, bool)> {
    let progress = BuildProgress::new(quiet);
    let (rom, path, outcome) = crate::rom::cache::load_or_build(
        cfg.model(),
        &BuildOptions::default(),
        &super::cache_dir(),
        rebuild,
        &mut |e| progress.event(&e),
    )?;
    progress.finish();
    warn_few_modes(&rom);
    Ok((
        rom,
        path,
        outcome == crate::rom::cache::CacheOutcome::Reused,
    ))
}

/// The twin's own ROM and its file where the session's tests, with the clearances
/// `clearances` (/ l), hold the probes in contact ([`RigConfig::held_contact_twin`]: a
/// coarser contact patch); says so on the terminal. None: the twin runs on `cfg`'s ROM.
pub(crate) fn held_contact_twin_rom(
    cfg: &RigConfig,
    clearances: &[f64],
    rebuild: bool,
    quiet: bool,
) -> anyhow::Result<Option<(Rom, PathBuf)>> {
    let Some(twin) = cfg.held_contact_twin(clearances) else {
        return Ok(None);
    };
    let (rom, path, _) = cached_rom(&twin, rebuild, quiet)?;
    let ([y, x], [fy, fx]) = (twin.twin.held_contact.contact_nodes, cfg.contact.nodes);
    println!(
        "twin: contact patch {y} x {x} ({} pairs) in place of the model's {fy} x {fx}: every test holds the probes in contact (clearance <= {:e} l, [twin.held_contact])",
        rom.n_pairs(),
        twin.twin.held_contact.max_clearance
    );
    Ok(Some((rom, path)))
}

/// The simulated rig's truth ROM: the rig description's structure with modes up to
/// `[truth] cutoff_ratio` x f(1FU) (more than the twin's), on the `[contact] nodes` patch
/// (the model's `[reduction] contact_nodes`, if any, is the twin's only).
pub(crate) fn truth_rom(cfg: &RigConfig, rebuild: bool, quiet: bool) -> anyhow::Result<Rom> {
    finer_rom(cfg, cfg.truth.cutoff_ratio, rebuild, quiet)
}

/// The rig description's structure with modes up to `cutoff_ratio` x f(1FU), on the
/// `[contact] nodes` patch: the simulated rig's truth ROM, and the twin comparison's
/// discretisation member's (`[twin.discretisation]`); one cache entry for equal ratios.
pub(crate) fn finer_rom(
    cfg: &RigConfig,
    cutoff_ratio: f64,
    rebuild: bool,
    quiet: bool,
) -> anyhow::Result<Rom> {
    let mut finer = cfg.clone();
    finer.reduction = crate::config::ReductionSpec {
        cutoff_ratio: Some(cutoff_ratio),
        cutoff_hz: None,
        modes: None,
        contact_nodes: None,
    };
    let (rom, _, _) = cached_rom(&finer, rebuild, quiet)?;
    Ok(rom)
}

/// Says before anything runs on `rom` that its impacts will be slow, when it keeps too few
/// modes ([`crate::rom::info::RomInfo::few_modes_warning`]).
pub(crate) fn warn_few_modes(rom: &Rom) {
    if let Some(w) = crate::rom::info::RomInfo::new(rom).few_modes_warning() {
        eprintln!("warning: {w}");
    }
}
