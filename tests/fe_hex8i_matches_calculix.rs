//! Guards that the native element matrices reproduce CalculiX (`ccx`, *FREQUENCY):
//! - C3D8 on a small box and a tapered cantilever: eigenvalues equal to ccx's printed
//!   precision (same element, same integration);
//! - C3D8I on the project's 300 x 20 x 6 mm beam (60 x 4 x 2 elements), uniform and tapered
//!   27 -> 20 mm like the upper beam: the lowest 18 frequencies (to about 180 f1) within
//!   0.15 %. CalculiX keeps the 9 bubble DOFs per element as dynamic DOFs with bubble mass;
//!   the native element condenses them (stiffness exactly, the bubble inertia with the static
//!   bubble response) and adds Taylor's detJ0/detJ correction, hence a small, mode-dependent
//!   difference instead of round-off.
//!
//! Skips with a message when `ccx` is not on PATH.

mod support;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use rigtwin::fe::{assemble, ElementKind, Material, Mesh};
use support::{box_cantilever, linspace, lowest_modes};

fn steel() -> Material {
    Material {
        name: "steel".into(),
        youngs_modulus: 210e9,
        poisson_ratio: 0.3,
        density: 7850.0,
    }
}

fn ccx_available() -> bool {
    Command::new("ccx")
        .arg("-v")
        .output()
        .map(|o| o.status.success() || !o.stdout.is_empty())
        .unwrap_or(false)
}

/// A minimal CalculiX deck: nodes, one element set, the fixed nodes, *FREQUENCY.
fn deck(mesh: &Mesh, kind: ElementKind, n_modes: usize) -> String {
    let mut s = String::from("*NODE, NSET=NALL\n");
    for (i, p) in mesh.nodes.iter().enumerate() {
        writeln!(s, "{}, {:.12e}, {:.12e}, {:.12e}", i + 1, p[0], p[1], p[2]).unwrap();
    }
    writeln!(s, "*ELEMENT, TYPE={}, ELSET=EALL", kind.calculix_name()).unwrap();
    for (e, el) in mesh.elements.iter().enumerate() {
        let nodes: Vec<String> = el.nodes.iter().map(|n| (n + 1).to_string()).collect();
        writeln!(s, "{}, {}", e + 1, nodes.join(", ")).unwrap();
    }
    s.push_str("*NSET, NSET=FIX\n");
    for n in &mesh.fixed_nodes {
        writeln!(s, "{},", n + 1).unwrap();
    }
    let m = &mesh.materials[0];
    write!(
        s,
        "*BOUNDARY\nFIX, 1, 3\n*MATERIAL, NAME=STEEL\n*ELASTIC\n{:e}, {}\n*DENSITY\n{}\n\
         *SOLID SECTION, ELSET=EALL, MATERIAL=STEEL\n*STEP\n*FREQUENCY\n{}\n*END STEP\n",
        m.youngs_modulus, m.poisson_ratio, m.density, n_modes
    )
    .unwrap();
    s
}

/// Eigenvalues (rad/s)^2 from the EIGENVALUE OUTPUT table of a ccx .dat file.
fn parse_eigenvalues(dat: &str) -> Vec<f64> {
    let mut out = Vec::new();
    let mut inside = false;
    for line in dat.lines() {
        if line.contains("E I G E N V A L U E   O U T P U T") {
            inside = true;
            continue;
        }
        if inside {
            if line.contains("P A R T I C I P A T I O N") {
                break;
            }
            let cols: Vec<&str> = line.split_whitespace().collect();
            if cols.len() == 5 && cols[0].parse::<usize>().is_ok() {
                out.push(cols[1].parse::<f64>().expect("eigenvalue column"));
            }
        }
    }
    out
}

fn run_ccx(dir: &Path, mesh: &Mesh, kind: ElementKind, n_modes: usize) -> Vec<f64> {
    std::fs::write(dir.join("beam.inp"), deck(mesh, kind, n_modes)).unwrap();
    let out = Command::new("ccx")
        .arg("-i")
        .arg("beam")
        .current_dir(dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .expect("run ccx");
    let dat = std::fs::read_to_string(dir.join("beam.dat")).unwrap_or_default();
    let ev = parse_eigenvalues(&dat);
    assert_eq!(
        ev.len(),
        n_modes,
        "ccx failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    ev
}

/// Largest relative frequency difference native vs ccx over the lowest `n_modes`.
fn compare(label: &str, mesh: &Mesh, kind: ElementKind, n_modes: usize) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let ccx = run_ccx(dir.path(), mesh, kind, n_modes);
    let model = assemble(mesh, 0.0).unwrap();
    let native = lowest_modes(&model, n_modes);
    let mut worst = 0.0f64;
    for (i, (m, c)) in native.iter().zip(&ccx).enumerate() {
        let f_ccx = c.sqrt() / (2.0 * std::f64::consts::PI);
        let rel = m.freq / f_ccx - 1.0;
        worst = worst.max(rel.abs());
        println!(
            "{label} {kind:?} mode {:2}: native {:10.3} Hz, ccx {:10.3} Hz, rel {:+.2e}",
            i + 1,
            m.freq,
            f_ccx,
            rel
        );
    }
    worst
}

/// Cantilever along x with root-to-tip width and thickness factors (tapered cells).
fn cantilever(kind: ElementKind, size: [f64; 3], cells: [usize; 3], root_factor: [f64; 2]) -> Mesh {
    let [l, b, h] = size;
    box_cantilever(
        &linspace(0.0, l, cells[0]),
        &linspace(-b / 2.0, b / 2.0, cells[1]),
        &linspace(-h / 2.0, h / 2.0, cells[2]),
        kind,
        steel(),
        move |p| {
            let s = 1.0 - p[0] / l;
            let fy = 1.0 + (root_factor[0] - 1.0) * s;
            let fz = 1.0 + (root_factor[1] - 1.0) * s;
            [p[0], p[1] * fy, p[2] * fz]
        },
    )
}

#[test]
fn hex8_matches_calculix_to_printed_precision() {
    if !ccx_available() {
        assert!(
            !rigtwin::fe::calculix::ccx_required(),
            "RIGTWIN_REQUIRE_CCX is set but ccx cannot be started"
        );
        eprintln!("SKIPPED: `ccx` (CalculiX) is not on PATH; the C3D8 check did not run");
        return;
    }
    let (size, cells) = ([0.1, 0.01, 0.004], [20, 2, 2]);
    for (label, root) in [("box", [1.0, 1.0]), ("tapered", [1.35, 1.2])] {
        let mesh = cantilever(ElementKind::Hex8, size, cells, root);
        // ccx prints 7 significant digits of the eigenvalue.
        let err = compare(label, &mesh, ElementKind::Hex8, 6);
        assert!(err < 1e-6, "C3D8 {label}: native vs ccx differ by {err:e}");
    }
}

#[test]
fn hex8i_matches_calculix_on_the_project_beam() {
    if !ccx_available() {
        assert!(
            !rigtwin::fe::calculix::ccx_required(),
            "RIGTWIN_REQUIRE_CCX is set but ccx cannot be started"
        );
        eprintln!("SKIPPED: `ccx` (CalculiX) is not on PATH; the C3D8I check did not run");
        return;
    }
    let (size, cells) = ([0.3, 0.02, 0.006], [60, 4, 2]);
    for (label, root) in [("uniform", [1.0, 1.0]), ("tapered", [1.35, 1.0])] {
        let mesh = cantilever(ElementKind::Hex8I, size, cells, root);
        let err = compare(label, &mesh, ElementKind::Hex8I, 18);
        assert!(
            err < 1.5e-3,
            "C3D8I {label}: native vs ccx differ by {err:e}"
        );
    }
}
