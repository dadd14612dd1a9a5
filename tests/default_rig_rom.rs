//! Guards the default rig's ROM (rig-config/two-beam.toml at its default resolution and mode
//! cutoff): the frequency targets of the reference rig (f(1FL)/f(1FU) = 0.918 +- 0.01,
//! 2FU/1FU in [5.5, 6.5]), the retained coverage at the 180 x f(1FU) cutoff, MacNeal's exact
//! static boundary flexibility, the ROM file round trip, and the independent check through
//! CalculiX: ccx's own first 10 eigenfrequencies of the exported mesh within 0.5 % of
//! rigtwin's, and a ROM built from ccx's matrices matching the native ROM within 0.5 %.

use std::sync::OnceLock;

use rigtwin::config::RigConfig;
use rigtwin::rom::build::{build_calculix, build_native, BuildOptions};
use rigtwin::rom::info::{RomInfo, RomOrigin};
use rigtwin::rom::Rom;

fn native() -> &'static Rom {
    static ROM: OnceLock<Rom> = OnceLock::new();
    ROM.get_or_init(|| {
        build_native(
            RigConfig::default_rig().model(),
            &BuildOptions::default(),
            &mut |_| {},
        )
        .expect("default ROM builds")
    })
}

fn label_freq(rom: &Rom, label: &str) -> f64 {
    let i = rom
        .labels
        .iter()
        .position(|l| l == label)
        .unwrap_or_else(|| {
            panic!(
                "no mode labelled {label}: {:?}",
                &rom.labels[..12.min(rom.labels.len())]
            )
        });
    rom.frequencies_hz()[i]
}

#[test]
fn default_rig_meets_the_reference_frequency_targets() {
    let rom = native();
    let info = RomInfo::new(rom);
    eprintln!("{}", info.text(RomOrigin::Built));
    let f1fu = label_freq(rom, "1FU");
    assert_eq!(rom.labels[rom.meta.reference_mode], "1FU");
    let r1 = label_freq(rom, "1FL") / f1fu;
    let r2 = label_freq(rom, "2FU") / f1fu;
    eprintln!("f(1FU) = {f1fu:.3} Hz, 1FL/1FU = {r1:.4}, 2FU/1FU = {r2:.3}, highest = {:.1} x f(1FU), {} modes", info.highest_mode_over_1fu, rom.n_modes());
    assert!((r1 - 0.918).abs() <= 0.01, "f(1FL)/f(1FU) = {r1}");
    assert!((5.5..=6.5).contains(&r2), "f(2FU)/f(1FU) = {r2}");
    assert!((45.0..60.0).contains(&f1fu), "f(1FU) = {f1fu} Hz");
    // The cutoff: every retained mode is below 180 f(1FU) and the highest is close to it
    // (the next mode would exceed it).
    assert!(
        info.highest_mode_over_1fu <= 180.0 && info.highest_mode_over_1fu > 150.0,
        "highest retained mode {} x f(1FU)",
        info.highest_mode_over_1fu
    );
    assert_eq!(rom.n_pairs(), 192);
    assert!(
        rom.meta.max_eigen_residual < 1e-6,
        "eigen residual {}",
        rom.meta.max_eigen_residual
    );
    assert!(
        rom.meta.static_flexibility_error < 1e-8,
        "static flexibility error {}",
        rom.meta.static_flexibility_error
    );
    assert!(
        rom.damping_ratio.iter().all(|&d| d > 0.0 && d < 0.01),
        "every mode has a damping ratio from the table"
    );
    assert!(rom.meta.stable_steps_per_period_closed > rom.meta.stable_steps_per_period_open);
}

#[test]
fn default_rom_file_round_trips_bit_for_bit() {
    let rom = native();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("default.rom");
    rigtwin::rom::file::write(rom, &p).unwrap();
    let back = rigtwin::rom::file::read(&p).unwrap();
    assert_eq!(
        rigtwin::rom::file::to_bytes(&back),
        rigtwin::rom::file::to_bytes(rom)
    );
    assert_eq!(back.meta.config_hash.len(), 64);
}

#[test]
fn calculix_agrees_with_the_native_model_of_the_default_rig() {
    use rigtwin::fe::calculix;
    if !calculix::ccx_available() {
        assert!(
            !calculix::ccx_required(),
            "RIGTWIN_REQUIRE_CCX is set but ccx cannot be started"
        );
        eprintln!(
            "SKIPPED: ccx not on PATH; the CalculiX comparison of the default rig did not run"
        );
        return;
    }
    let cfg = RigConfig::default_rig();
    let mesh = rigtwin::fe::rig::mesh_rig(cfg.model()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let files = calculix::export(&mesh, dir.path(), "rig", 10).unwrap();
    // ccx's own eigen solve (its C3D8I with dynamic bubble DOFs) on the same mesh.
    let run = calculix::run_ccx(dir.path(), &files.job).unwrap();
    let f_ccx = calculix::read_dat_frequencies(&run.dat).unwrap();
    let f_native = native().frequencies_hz();
    assert!(f_ccx.len() >= 10, "ccx printed {} frequencies", f_ccx.len());
    for (i, (a, b)) in f_ccx.iter().zip(&f_native).take(10).enumerate() {
        let rel = (a - b).abs() / b;
        eprintln!(
            "mode {:>2} {:>5}: ccx {a:10.3} Hz  rigtwin {b:10.3} Hz  {:+.4} %",
            i + 1,
            native().labels[i],
            100.0 * (a - b) / b
        );
        assert!(rel < 5e-3, "mode {} differs by {:.3} %", i + 1, 100.0 * rel);
    }
    // A ROM from ccx's matrices (MATRIXSTORAGE) against the native ROM.
    let run = calculix::run_ccx(dir.path(), &files.matrix_job).unwrap();
    let from_ccx = build_calculix(
        &run.job_path,
        cfg.model(),
        &BuildOptions::default(),
        &mut |_| {},
    )
    .unwrap();
    let f_rom = from_ccx.frequencies_hz();
    assert_eq!(from_ccx.n_pairs(), native().n_pairs());
    let n = f_rom.len().min(f_native.len());
    assert!(
        n + 2 >= f_native.len(),
        "ccx ROM keeps {} modes, native {}",
        f_rom.len(),
        f_native.len()
    );
    let worst = (0..n)
        .map(|i| (f_rom[i] - f_native[i]).abs() / f_native[i])
        .fold(0.0, f64::max);
    eprintln!(
        "ROM from ccx matrices: {} modes, worst frequency difference {:.2e}",
        f_rom.len(),
        worst
    );
    assert!(worst < 5e-3);
}
