//! The default rig's ROM for integration tests, built once per test binary and cached across
//! test binaries in `CARGO_TARGET_TMPDIR/rom-cache` (keyed by build hash, written atomically).

#![allow(dead_code)]

use std::sync::OnceLock;

use rigtwin::config::RigConfig;
use rigtwin::rom::build::BuildOptions;
use rigtwin::rom::Rom;

/// The native ROM of the embedded default rig (modes to 180 x f(1FU), 192 pairs).
pub fn default_rom() -> &'static Rom {
    static ROM: OnceLock<Rom> = OnceLock::new();
    ROM.get_or_init(|| rom_of(&RigConfig::default_rig()))
}

/// The native ROM of `cfg`, built or taken from the same cache.
pub fn rom_of(cfg: &RigConfig) -> Rom {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rom-cache");
    let (rom, _, _) = rigtwin::rom::cache::load_or_build(
        cfg.model(),
        &BuildOptions::default(),
        &dir,
        false,
        &mut |_| {},
    )
    .expect("ROM");
    rom
}
