//! Guards rigtwin's frictional contact solutions against an independent solver: Siconos'
//! fc3d nonsmooth Gauss-Seidel (python3-siconos, run by `tests/siconos/solve_fc3d.py` through
//! `/usr/bin/python3`, or `$RIGTWIN_SICONOS_PYTHON`). Physically shaped problems (Delassus
//! matrices built like `G_res / dt` over parts of the 12 x 16 contact patch, impact-like free
//! velocities) are solved by rigtwin, exported in the `.rtcp` exchange format, solved again by
//! Siconos, and the forces and gap velocities must agree to 1e-6 relative.
//!
//! Without siconos the test prints why and passes, unless `RIGTWIN_REQUIRE_SICONOS` is set
//! (CI sets it), in which case the missing oracle is a failure. With `--nocapture` it prints
//! the solve times of both solvers (solve only, best of several runs).

mod contact_support;

use std::process::Command;
use std::time::Instant;

use contact_support::{law_violation, physical_problem, siconos_or_skip, siconos_script};
use rigtwin::contact::{
    write_problem, ContactParameters, ContactProblem, ContactSolution, ContactSolver, NewtonUse,
    SolveStats, StepRule, SweepMethod,
};

const SIZES: [usize; 24] = [
    1, 2, 3, 4, 6, 8, 10, 12, 16, 20, 24, 30, 36, 42, 48, 60, 72, 90, 100, 120, 144, 160, 180, 192,
];
const REPEAT: usize = 3;

/// Solves with a fresh solver (so the timed solve includes gathering W and the step sizes),
/// best wall time of `REPEAT` cold solves.
fn solve_timed(
    problem: &ContactProblem,
    params: &ContactParameters,
) -> (ContactSolution, SolveStats, f64) {
    let d = problem.c.len();
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..REPEAT {
        let mut solver = ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
        let mut lambda = vec![0.0; d];
        let mut gamma = vec![0.0; d];
        let t0 = Instant::now();
        let stats = solver
            .solve(&problem.c, None, &mut lambda, &mut gamma)
            .unwrap();
        best = best.min(t0.elapsed().as_secs_f64());
        out = Some((ContactSolution { lambda, gamma }, stats));
    }
    let (sol, stats) = out.unwrap();
    (sol, stats, best)
}

#[test]
fn contact_solutions_match_siconos_fc3d() {
    let params = ContactParameters {
        method: SweepMethod::Jacobi,
        step_rule: StepRule::Auto,
        tolerance: 1e-11,
        max_iterations: 1_000_000,
        // The sweep methods themselves are under test here.
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    };
    let variants = [
        (
            "accelerated/spectral",
            SweepMethod::AcceleratedJacobi,
            StepRule::Spectral,
        ),
        ("gauss-seidel", SweepMethod::GaussSeidel, StepRule::Auto),
    ];
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("problems.rtcp");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&file).unwrap());
    let mut ours = Vec::new();
    for (i, &n) in SIZES.iter().enumerate() {
        let mut problem = physical_problem(500 + i as u64, n);
        if i % 5 == 4 {
            problem.mu = vec![0.15; n];
        }
        let (sol, stats, time) = solve_timed(&problem, &params);
        assert!(stats.converged, "{}: {stats:?}", problem.label);
        assert!(
            law_violation(&problem, &sol.lambda) < 1e-9,
            "{}",
            problem.label
        );
        let mut other_times = Vec::new();
        for (_, method, step_rule) in variants {
            let p = ContactParameters {
                method,
                step_rule,
                ..params.clone()
            };
            let (_, s, t) = solve_timed(&problem, &p);
            assert!(
                s.converged,
                "{}: {method:?} {step_rule:?} {s:?}",
                problem.label
            );
            other_times.push((s.iterations, t));
        }
        write_problem(&mut out, &problem, Some(&sol)).unwrap();
        ours.push((problem, stats, time, other_times));
    }
    drop(out);

    let Some(python) = siconos_or_skip("contact_solutions_match_siconos_fc3d") else {
        return;
    };
    let json = dir.path().join("siconos.json");
    let run = Command::new(&python)
        .arg(siconos_script())
        .arg(&file)
        .arg("--json")
        .arg(&json)
        .args(["--tol", "1e-12", "--max-iter", "100000", "--repeat"])
        .arg(REPEAT.to_string())
        .output()
        .unwrap();
    println!("{}", String::from_utf8_lossy(&run.stdout));
    assert!(
        run.status.success(),
        "solve_fc3d.py failed ({}): {}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let problems = report["problems"].as_array().unwrap();
    assert_eq!(problems.len(), ours.len());

    println!(
        "{:>5} {:>14} | {:>6} {:>9} | {:>6} {:>9} | {:>6} {:>9} | {:>9} {:>9} {:>9} | {:>8} {:>8}",
        "pairs",
        "open/stck/slip",
        "it J",
        "J ms",
        "it AJ",
        "AJ ms",
        "it GS",
        "GS ms",
        "NSGS it",
        "NSGS ms",
        "NSGS/AJ",
        "d lambda",
        "d gamma"
    );
    let mut sums = [0.0f64; 4];
    let mut worst = 0.0f64;
    for ((problem, stats, time, others), entry) in ours.iter().zip(problems) {
        let d_lambda = entry["rel_diff_lambda"].as_f64().unwrap();
        let d_gamma = entry["rel_diff_gamma"].as_f64().unwrap();
        let t_sic = entry["siconos_time_s"].as_f64().unwrap();
        assert_eq!(entry["siconos_info"].as_i64(), Some(0), "{}", problem.label);
        assert!(
            d_lambda < 1e-6 && d_gamma < 1e-6,
            "{}: rigtwin and Siconos differ: lambda {d_lambda:e}, gamma {d_gamma:e}",
            problem.label
        );
        worst = worst.max(d_lambda).max(d_gamma);
        for (sum, t) in sums
            .iter_mut()
            .zip([*time, others[0].1, others[1].1, t_sic])
        {
            *sum += t;
        }
        println!(
            "{:>5} {:>4}/{:>4}/{:>4} | {:>6} {:>9.4} | {:>6} {:>9.4} | {:>6} {:>9.4} | {:>9} {:>9.4} {:>9.2} | {:>8.1e} {:>8.1e}",
            problem.n_pairs(),
            stats.open,
            stats.stick,
            stats.slip,
            stats.iterations,
            1e3 * time,
            others[0].0,
            1e3 * others[0].1,
            others[1].0,
            1e3 * others[1].1,
            entry["siconos_iterations"].as_i64().unwrap(),
            1e3 * t_sic,
            t_sic / others[0].1,
            d_lambda,
            d_gamma
        );
    }
    println!(
        "total solve time (ms): Jacobi/auto {:.3}, accelerated Jacobi/spectral {:.3}, \
         Gauss-Seidel {:.3}, Siconos NSGS {:.3}; worst relative difference {worst:.1e}",
        1e3 * sums[0],
        1e3 * sums[1],
        1e3 * sums[2],
        1e3 * sums[3]
    );
}
