//! Real contact problems of the default rig, cross-checked against Siconos: the ROM is run at
//! Omega = omega_2 at the high level (6e-5 l, clearance 2.78e-3 l) into sustained impacts, at
//! least 20 contact problems with several active pairs are captured from the integrator's steps
//! (the sub-problem on the pairs in the sweep, exactly as solved), exported in the `.rtcp`
//! format (`src/contact/problem_io.rs`), solved by Siconos' fc3d NSGS
//! (`tests/siconos/solve_fc3d.py` under `/usr/bin/python3` or `$RIGTWIN_SICONOS_PYTHON`), and
//! forces and gap velocities must agree with rigtwin's to 1e-6 relative.
//!
//! Without siconos the test says why and passes, unless `RIGTWIN_REQUIRE_SICONOS` is set (CI).
//! With `--nocapture` it prints the sizes and the solve times of both solvers.
//!
//! The second test does the same for held contact (issue 16: the probes touching, clearance
//! 0), with Siconos' nonsmooth Newton (`FC3D_NSN_AC`) timed beside NSGS and ours.

mod contact_support;
mod default_rom;

use std::process::Command;
use std::time::Instant;

use rigtwin::contact::{
    write_problem, ContactParameters, ContactSolver, NewtonUse, SolvePath, SweepMethod,
};
use rigtwin::plan::Plan;
use rigtwin::sim::stepped::{run_plan, CaptureOptions, SteppedSineOptions};

#[test]
fn captured_impact_problems_match_siconos() {
    let rom = default_rom::default_rom();
    let plan = Plan::from_str(
        r#"
        [[test]]
        name = "capture"
        level = 6.0e-5
        clearance = 2.78e-3
        direction = "down"
        omega_start = 1.0
        omega_end = 1.0
        steps = 1
        settle_periods = 100
        record_periods = 20
        "#,
        "capture plan",
    )
    .unwrap();
    let mut opts = SteppedSineOptions {
        capture: Some(CaptureOptions {
            max_problems: 24,
            min_active_pairs: 4,
            stride: 3,
            max_periods: 20,
        }),
        ..Default::default()
    };
    // Tight tolerance so that the stored solutions are rigtwin's converged answers.
    opts.integrator.contact.tolerance = 1e-12;
    opts.integrator.contact.max_iterations = 100_000;
    let results = run_plan(rom, &plan, &opts, 1, &|_| {}).unwrap();
    let captured = &results[0].captured;
    assert!(
        captured.len() >= 20,
        "only {} problems with >= 4 active pairs captured in 20 periods",
        captured.len()
    );

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("captured.rtcp");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&file).unwrap());
    let mut rigtwin_times = Vec::new();
    for (problem, solution) in captured {
        problem.validate().unwrap();
        write_problem(&mut out, problem, Some(solution)).unwrap();
        // Time rigtwin's Gauss-Seidel on the same problem from a cold start (best of 3).
        let d = problem.c.len();
        let params = ContactParameters {
            method: SweepMethod::GaussSeidel,
            tolerance: 1e-12,
            max_iterations: 100_000,
            newton: NewtonUse::Never,
            ..Default::default()
        };
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            let mut solver = ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
            let (mut lambda, mut gamma) = (vec![0.0; d], vec![0.0; d]);
            let t0 = Instant::now();
            let stats = solver
                .solve(&problem.c, None, &mut lambda, &mut gamma)
                .unwrap();
            best = best.min(t0.elapsed().as_secs_f64());
            assert!(stats.converged, "{}: {stats:?}", problem.label);
        }
        rigtwin_times.push(best);
    }
    drop(out);

    let Some(python) = contact_support::siconos_or_skip("captured_impact_problems_match_siconos")
    else {
        return;
    };
    let json = dir.path().join("siconos.json");
    let run = Command::new(&python)
        .arg(contact_support::siconos_script())
        .arg(&file)
        .arg("--json")
        .arg(&json)
        .args(["--tol", "1e-12", "--max-iter", "100000", "--repeat", "3"])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "solve_fc3d.py failed ({}): {}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let problems = report["problems"].as_array().unwrap();
    assert_eq!(problems.len(), captured.len());
    let (mut t_ours, mut t_sic, mut worst) = (0.0, 0.0, 0.0f64);
    for (((problem, _), entry), t) in captured.iter().zip(problems).zip(&rigtwin_times) {
        let d_lambda = entry["rel_diff_lambda"].as_f64().unwrap();
        let d_gamma = entry["rel_diff_gamma"].as_f64().unwrap();
        assert_eq!(entry["siconos_info"].as_i64(), Some(0), "{}", problem.label);
        assert!(
            d_lambda < 1e-6 && d_gamma < 1e-6,
            "{}: rigtwin and Siconos differ: lambda {d_lambda:e}, gamma {d_gamma:e}",
            problem.label
        );
        worst = worst.max(d_lambda).max(d_gamma);
        let ts = entry["siconos_time_s"].as_f64().unwrap();
        t_ours += t;
        t_sic += ts;
        println!(
            "{:>3} pairs  rigtwin GS {:8.3} ms  Siconos NSGS {:8.3} ms  d lambda {d_lambda:.1e}  d gamma {d_gamma:.1e}  ({})",
            problem.n_pairs(),
            1e3 * t,
            1e3 * ts,
            problem.label
        );
    }
    println!(
        "{} captured problems: worst relative difference {worst:.1e}; total solve time rigtwin \
         Gauss-Seidel {:.3} ms, Siconos NSGS {:.3} ms (ratio Siconos/rigtwin {:.2})",
        captured.len(),
        1e3 * t_ours,
        1e3 * t_sic,
        t_sic / t_ours
    );
}

/// Held contact (issue 16): problems captured from the default ROM with the probes touching
/// (clearance 0, Omega = omega_2, 0.5e-5 l), at least 96 pairs in the solve, as solved by the
/// default solve (a few sweeps, then Newton, for these sizes). Siconos NSGS must agree to 1e-6; Siconos'
/// nonsmooth Newton (`FC3D_NSN_AC`) is timed beside it at the same tolerance, as are ours
/// (default: sweeps then Newton; Gauss-Seidel only). Times: cold solves, fresh solver each (ours include
/// the one-time `W^-1` where the complement form is used), best of 3.
#[test]
fn captured_held_contact_problems_match_siconos() {
    let rom = default_rom::default_rom();
    let plan = Plan::from_str(
        r#"
        [[test]]
        name = "capture held"
        level = 0.5e-5
        clearance = 0.0
        direction = "down"
        omega_start = 1.0
        omega_end = 1.0
        steps = 1
        settle_periods = 20
        record_periods = 20
        "#,
        "capture plan",
    )
    .unwrap();
    let mut opts = SteppedSineOptions {
        capture: Some(CaptureOptions {
            max_problems: 12,
            min_active_pairs: 96,
            stride: 4,
            max_periods: 20,
        }),
        ..Default::default()
    };
    opts.integrator.contact.tolerance = 1e-12;
    opts.integrator.contact.max_iterations = 100_000;
    let results = run_plan(rom, &plan, &opts, 1, &|_| {}).unwrap();
    let captured = &results[0].captured;
    assert!(
        captured.len() >= 8,
        "only {} held-contact problems with >= 96 active pairs captured in 20 periods",
        captured.len()
    );

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("held.rtcp");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&file).unwrap());
    let mut times = Vec::new();
    for (problem, solution) in captured {
        problem.validate().unwrap();
        write_problem(&mut out, problem, Some(solution)).unwrap();
        let d = problem.c.len();
        let time = |newton: NewtonUse| {
            let params = ContactParameters {
                method: SweepMethod::GaussSeidel,
                tolerance: 1e-12,
                max_iterations: 100_000,
                newton,
                ..Default::default()
            };
            let mut best = f64::INFINITY;
            let mut last = None;
            for _ in 0..3 {
                let mut solver =
                    ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
                let (mut lambda, mut gamma) = (vec![0.0; d], vec![0.0; d]);
                let t0 = Instant::now();
                let stats = solver
                    .solve(&problem.c, None, &mut lambda, &mut gamma)
                    .unwrap();
                best = best.min(t0.elapsed().as_secs_f64());
                assert!(stats.converged, "{}: {newton:?} {stats:?}", problem.label);
                last = Some((stats, lambda));
            }
            let (stats, lambda) = last.unwrap();
            (best, stats, lambda)
        };
        let (t_auto, s_auto, l_auto) = time(NewtonUse::Auto);
        let (t_gs, _, l_gs) = time(NewtonUse::Never);
        // A few sweeps first, then Newton; a small held problem may already converge in the
        // sweeps. A Newton attempt never fails here.
        assert_ne!(s_auto.path, SolvePath::NewtonFallback, "{}", problem.label);
        // Newton against the stored (captured, default-solve) answer and against sweeps.
        let diff = |a: &[f64], b: &[f64]| {
            let n: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
            let s: f64 = b.iter().map(|x| x * x).sum();
            if n == 0.0 {
                0.0
            } else {
                (n / s).sqrt()
            }
        };
        assert!(diff(&l_auto, &solution.lambda) < 1e-8, "{}", problem.label);
        assert!(diff(&l_gs, &l_auto) < 1e-6, "{}", problem.label);
        times.push((t_auto, t_gs, s_auto.newton_iterations));
    }
    drop(out);

    let Some(python) =
        contact_support::siconos_or_skip("captured_held_contact_problems_match_siconos")
    else {
        return;
    };
    let json = dir.path().join("siconos.json");
    let run = Command::new(&python)
        .arg(contact_support::siconos_script())
        .arg(&file)
        .arg("--json")
        .arg(&json)
        .args(["--tol", "1e-12", "--max-iter", "100000", "--repeat", "3"])
        .args(["--solvers", "nsgs,nsn_ac"])
        .output()
        .unwrap();
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap_or_else(|e| {
            panic!(
                "solve_fc3d.py wrote no report ({e}; status {}): {}",
                run.status,
                String::from_utf8_lossy(&run.stderr)
            )
        }))
        .unwrap();
    let problems = report["problems"].as_array().unwrap();
    assert_eq!(problems.len(), captured.len());
    let (mut t_ours, mut t_gs, mut t_nsgs, mut t_nsn) = (0.0, 0.0, 0.0, 0.0);
    let (mut worst, mut nsn_failed) = (0.0f64, 0);
    for (((problem, _), entry), (ta, tg, its)) in captured.iter().zip(problems).zip(&times) {
        let nsgs = &entry["solvers"]["nsgs"];
        let nsn = &entry["solvers"]["nsn_ac"];
        assert_eq!(nsgs["info"].as_i64(), Some(0), "{}", problem.label);
        let d_lambda = nsgs["rel_diff_lambda"].as_f64().unwrap();
        let d_gamma = nsgs["rel_diff_gamma"].as_f64().unwrap();
        assert!(
            d_lambda < 1e-6 && d_gamma < 1e-6,
            "{}: rigtwin and Siconos NSGS differ: lambda {d_lambda:e}, gamma {d_gamma:e}",
            problem.label
        );
        worst = worst.max(d_lambda).max(d_gamma);
        let nsn_ok = nsn["info"].as_i64() == Some(0);
        if nsn_ok {
            let d = nsn["rel_diff_lambda"].as_f64().unwrap();
            assert!(
                d < 1e-6,
                "{}: Siconos NSN_AC differs by {d:e}",
                problem.label
            );
        } else {
            nsn_failed += 1;
        }
        let (ts, tn) = (
            nsgs["time_s"].as_f64().unwrap(),
            nsn["time_s"].as_f64().unwrap(),
        );
        t_ours += ta;
        t_gs += tg;
        t_nsgs += ts;
        t_nsn += tn;
        println!(
            "{:>3} pairs  rigtwin Newton {:8.3} ms ({its} it)  GS {:8.3} ms  Siconos NSGS {:8.3} ms  NSN_AC {:8.3} ms{}  d lambda {d_lambda:.1e}  ({})",
            problem.n_pairs(),
            1e3 * ta,
            1e3 * tg,
            1e3 * ts,
            1e3 * tn,
            if nsn_ok { "" } else { " (info != 0)" },
            problem.label
        );
    }
    let best_siconos = t_nsgs.min(t_nsn);
    println!(
        "{} held-contact problems: worst relative difference to NSGS {worst:.1e}; total solve \
         time rigtwin (default, Newton) {:.3} ms, rigtwin Gauss-Seidel only {:.3} ms, Siconos \
         NSGS {:.3} ms, Siconos NSN_AC {:.3} ms ({nsn_failed} without convergence); ratio \
         Siconos' best / rigtwin {:.2}",
        captured.len(),
        1e3 * t_ours,
        1e3 * t_gs,
        1e3 * t_nsgs,
        1e3 * t_nsn,
        best_siconos / t_ours
    );
}
