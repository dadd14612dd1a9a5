//! ROM build benchmark: times each stage (assembly, factorisation, eigen solve, attachment
//! modes) of the reduction of a rig description, optionally on a refined mesh or with another
//! mode cutoff, and prints one JSON line per run plus the medians.
//!
//! ```text
//! cargo bench --bench rom_build                              # default rig, 3 runs
//! cargo bench --bench rom_build -- --cutoff-ratio 800 --repeat 1
//! cargo bench --bench rom_build -- --refine 2 --repeat 1    # element sizes / 2
//! ```
//! Peak memory is the process's VmHWM from /proc (run one refinement per process).

use std::time::Instant;

use rigtwin::config::RigConfig;
use rigtwin::rom::build::{build_native, BuildOptions};
use rigtwin::rom::ModeSelection;

struct Args {
    refine: f64,
    cutoff_ratio: Option<f64>,
    repeat: usize,
    config: Option<String>,
}

fn parse_args() -> Args {
    let mut a = Args {
        refine: 1.0,
        cutoff_ratio: None,
        repeat: 3,
        config: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = |name: &str| it.next().unwrap_or_else(|| panic!("{name} needs a value"));
        match arg.as_str() {
            "--refine" => a.refine = val("--refine").parse().expect("--refine: a number"),
            "--cutoff-ratio" => {
                a.cutoff_ratio = Some(
                    val("--cutoff-ratio")
                        .parse()
                        .expect("--cutoff-ratio: a number"),
                )
            }
            "--repeat" => a.repeat = val("--repeat").parse().expect("--repeat: an integer"),
            "--config" => a.config = Some(val("--config")),
            "--bench" => {}
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

/// Divides every element size by `r` (and multiplies the cells through the thickness); the
/// contact patch keeps its node counts.
fn refine(cfg: &mut RigConfig, r: f64) {
    let b = &mut cfg.mesh.beams;
    b.free_element /= r;
    b.clamp_exit_element /= r;
    b.clamp_element /= r;
    b.seat_element /= r;
    b.width_element /= r;
    b.thickness_cells = ((b.thickness_cells as f64) * r).round().max(1.0) as usize;
    cfg.mesh.blocks.element /= r;
    cfg.mesh.probes.element /= r;
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| {
                l.split_whitespace()
                    .nth(1)
                    .unwrap_or("0")
                    .parse::<f64>()
                    .unwrap_or(0.0)
            })
        })
        .unwrap_or(f64::NAN)
        / 1024.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let a = parse_args();
    let mut cfg = match &a.config {
        Some(p) => RigConfig::from_path(std::path::Path::new(p)).expect("rig description"),
        None => RigConfig::default_rig(),
    };
    refine(&mut cfg, a.refine);
    cfg.validate().expect("refined description is valid");
    let opts = BuildOptions {
        selection: a
            .cutoff_ratio
            .map(|ratio| ModeSelection::CutoffRatio { ratio }),
    };
    let mut rows = Vec::new();
    for run in 0..a.repeat {
        let t = Instant::now();
        let rom = build_native(cfg.model(), &opts, &mut |_| {}).expect("ROM builds");
        let total = t.elapsed().as_secs_f64();
        let tm = &rom.meta.timings;
        let f = rom.frequencies_hz();
        let row = serde_json::json!({
            "run": run, "refine": a.refine, "n_dof": rom.meta.n_dof, "n_elements": rom.meta.n_elements,
            "n_modes": rom.n_modes(), "highest_over_1fu": f.last().unwrap() / rom.frequencies_hz()[rom.meta.reference_mode],
            "total_s": total, "assembly_s": tm.assembly, "factorisation_s": tm.factorisation,
            "eigen_s": tm.eigen, "attachment_s": tm.attachment, "peak_rss_mib": peak_rss_mib(),
        });
        println!("{row}");
        rows.push((
            total,
            tm.assembly,
            tm.factorisation,
            tm.eigen,
            tm.attachment,
        ));
    }
    println!(
        "median of {}: total {:.2} s, assembly {:.2} s, factorisation {:.2} s, eigen {:.2} s, attachment {:.2} s; peak RSS {:.0} MiB",
        rows.len(),
        median(rows.iter().map(|r| r.0).collect()),
        median(rows.iter().map(|r| r.1).collect()),
        median(rows.iter().map(|r| r.2).collect()),
        median(rows.iter().map(|r| r.3).collect()),
        median(rows.iter().map(|r| r.4).collect()),
        peak_rss_mib()
    );
}
