//! A folder of built ROMs keyed by build hash, so that commands, tests and benches that need
//! the ROM of a rig description build it once ([`load_or_build`]).

use std::path::{Path, PathBuf};

use super::build::{build_hash, build_native, BuildError, BuildEvent, BuildOptions};
use super::file::RomFileError;
use super::Rom;
use crate::config::RigModel;

/// Errors of [`load_or_build`].
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// Building the ROM failed.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// Writing the built ROM into the cache failed.
    #[error("caching the ROM: {0}")]
    Write(#[from] RomFileError),
}

/// Where a ROM came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheOutcome {
    /// Read from the cache.
    Reused,
    /// Built (and written to the cache).
    Built,
}

/// The cache file of the native ROM of `cfg` (the model sections of a rig description) with
/// the options' mode selection in `dir`: `<rig name>-<first 16 hex digits of the build
/// hash>.rom`.
pub fn cache_path(dir: &Path, cfg: RigModel<'_>, opts: &BuildOptions) -> PathBuf {
    let hash = build_hash(cfg, &opts.selection_for(cfg), "native");
    dir.join(format!("{}-{}.rom", cfg.rig.name, &hash[..16]))
}

/// Returns the native ROM of `cfg` (the model sections of a rig description: `cfg.model()` of
/// a [`crate::config::RigConfig`]) from the cache folder `dir`, building and caching it when
/// the folder has none with the right build hash, or when `rebuild` is set. An unreadable or
/// stale cache file is rebuilt (with a warning), never used. Writing is atomic, so concurrent
/// builders of the same ROM leave one complete file.
pub fn load_or_build(
    cfg: RigModel<'_>,
    opts: &BuildOptions,
    dir: &Path,
    rebuild: bool,
    on_event: &mut dyn FnMut(BuildEvent),
) -> Result<(Rom, PathBuf, CacheOutcome), CacheError> {
    let hash = build_hash(cfg, &opts.selection_for(cfg), "native");
    let path = cache_path(dir, cfg, opts);
    if !rebuild && path.exists() {
        match super::file::read(&path) {
            Ok(rom) if rom.meta.config_hash == hash => {
                return Ok((rom, path, CacheOutcome::Reused))
            }
            Ok(_) => tracing::warn!("cached ROM {} has another hash; rebuilding", path.display()),
            Err(e) => tracing::warn!("cached ROM unreadable ({e}); rebuilding"),
        }
    }
    let rom = build_native(cfg, opts, on_event)?;
    super::file::write(&rom, &path)?;
    Ok((rom, path, CacheOutcome::Built))
}
