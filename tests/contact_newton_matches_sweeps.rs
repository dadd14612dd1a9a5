//! Guards the semismooth Newton (Alart–Curnier) contact solve against the projected sweeps on
//! coupled multi-pair problems: physically shaped patches from impacts to held contact (every
//! pair pressed closed, the complement form with `W^-1`), random frictional and frictionless
//! problems; the same solution within the tolerance, the law satisfied, the path reported,
//! the factorisation reused when the states repeat, and the automatic choice.

mod contact_support;

use contact_support::{law_violation, physical_problem, random_spd_problem};
use rigtwin::contact::{
    solve_problem, ContactParameters, ContactProblem, ContactSolver, NewtonUse, SolvePath,
    SweepMethod,
};

fn params(newton: NewtonUse) -> ContactParameters {
    ContactParameters {
        method: SweepMethod::GaussSeidel,
        tolerance: 1e-12,
        max_iterations: 200_000,
        newton,
        ..ContactParameters::default()
    }
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let s: f64 = a
        .iter()
        .map(|x| x * x)
        .sum::<f64>()
        .max(b.iter().map(|x| x * x).sum());
    if d == 0.0 {
        0.0
    } else {
        (d / s).sqrt()
    }
}

/// The problem pressed into held contact: the free gap velocity of every normal row made
/// negative (closing), so most pairs close at once.
fn held(mut p: ContactProblem, closing: f64) -> ContactProblem {
    let scale = p.c.iter().map(|x| x.abs()).fold(0.0, f64::max);
    for k in 0..p.n_pairs() {
        p.c[3 * k] = -closing * scale - p.c[3 * k].abs() * 0.1;
    }
    p.label = format!("{} (held)", p.label);
    p
}

fn check_agree(problem: &ContactProblem) -> (rigtwin::contact::SolveStats, usize) {
    let (sweeps, s0) = solve_problem(problem, &params(NewtonUse::Never), None).unwrap();
    assert!(s0.converged, "{}: sweeps {s0:?}", problem.label);
    let (newton, s1) = solve_problem(problem, &params(NewtonUse::Always), None).unwrap();
    assert!(s1.converged, "{}: newton {s1:?}", problem.label);
    assert_eq!(s1.path, SolvePath::Newton, "{}", problem.label);
    assert!(s1.newton_iterations >= 1 && s1.newton_iterations <= 30);
    let e = rel_diff(&newton.lambda, &sweeps.lambda);
    assert!(e < 1e-8, "{}: Newton vs sweeps {e:e}", problem.label);
    let v = law_violation(problem, &newton.lambda);
    assert!(v < 1e-9, "{}: law violation {v:e}", problem.label);
    (s1, s0.iterations)
}

#[test]
fn newton_matches_the_sweeps_on_impact_and_held_problems() {
    for (seed, n) in [(1u64, 12usize), (2, 30), (3, 60), (4, 120), (7, 192)] {
        let impact = physical_problem(seed, n);
        check_agree(&impact);
        for closing in [0.2, 1.0] {
            let (stats, sweeps) = check_agree(&held(impact.clone(), closing));
            println!(
                "{n:>3} pairs, held {closing}: Newton {} iterations ({} LU), sweeps {sweeps}; \
                 stick {} slip {} open {}",
                stats.newton_iterations, stats.factorisations, stats.stick, stats.slip, stats.open
            );
        }
    }
}

#[test]
fn newton_matches_the_sweeps_on_random_and_frictionless_problems() {
    for (seed, n, mu) in [
        (11u64, 20usize, 0.4),
        (12, 40, 0.8),
        (13, 30, 0.0),
        (14, 64, 0.1),
    ] {
        let p = random_spd_problem(seed, n, mu, 0.3);
        check_agree(&p);
        check_agree(&held(p, 0.5));
    }
}

#[test]
fn a_held_contact_that_sticks_reuses_its_factorisation() {
    // Every pair closed and sticking: c = -W lambda* for a purely normal lambda* > 0 (its
    // own solution, gamma = 0); scaled copies keep the states, so the second and later solves
    // need no new LU.
    let mut p = physical_problem(21, 96);
    let d = 3 * p.n_pairs();
    let target: Vec<f64> = (0..d)
        .map(|i| {
            if i % 3 == 0 {
                1.0 + 0.01 * (i % 7) as f64
            } else {
                0.0
            }
        })
        .collect();
    for i in 0..d {
        p.c[i] = -(0..d).map(|j| p.w[i * d + j] * target[j]).sum::<f64>();
    }
    let n = p.n_pairs();
    let mut solver = ContactSolver::new(&p.w, &p.mu, params(NewtonUse::Always)).unwrap();
    let (mut lambda, mut gamma) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    let first = solver.solve(&p.c, None, &mut lambda, &mut gamma).unwrap();
    assert!(first.converged && first.stick == n, "{first:?}");
    assert!(first.factorisations >= 1);
    for step in 1..5 {
        let c: Vec<f64> = p.c.iter().map(|x| x * (1.0 + 0.01 * step as f64)).collect();
        let s = solver.solve(&c, None, &mut lambda, &mut gamma).unwrap();
        assert!(s.converged && s.stick == n, "{s:?}");
        assert_eq!(s.factorisations, 0, "step {step}: {s:?}");
        assert!(s.newton_iterations <= 2, "{s:?}");
    }
}

#[test]
fn auto_uses_sweeps_for_small_impacts_and_newton_for_large_held_contact() {
    let small = physical_problem(1, 12);
    let (_, s) = solve_problem(&small, &params(NewtonUse::Auto), None).unwrap();
    assert_eq!(s.path, SolvePath::Sweeps, "{s:?}");
    assert_eq!(s.newton_iterations, 0);
    // Large: a few sweeps first (`newton_after_sweeps_large`), then Newton; or Newton from
    // the warm start when that is set to 0.
    let large = held(physical_problem(7, 192), 1.0);
    let (_, s) = solve_problem(&large, &params(NewtonUse::Auto), None).unwrap();
    let first = ContactParameters::default().newton_after_sweeps_large;
    assert!(first > 0);
    assert_eq!(s.path, SolvePath::SweepsThenNewton, "{s:?}");
    assert_eq!(s.iterations, first, "{s:?}");
    let p = ContactParameters {
        newton_after_sweeps_large: 0,
        ..params(NewtonUse::Auto)
    };
    let (_, s) = solve_problem(&large, &p, None).unwrap();
    assert_eq!(s.path, SolvePath::Newton, "{s:?}");
    assert_eq!(s.iterations, 0, "no sweep needed: {s:?}");
    // Below the pair threshold but slow to sweep: sweeps first, then Newton.
    let medium = held(physical_problem(3, 60), 1.0);
    let p = ContactParameters {
        newton_after_sweeps: 5,
        ..params(NewtonUse::Auto)
    };
    let (_, s) = solve_problem(&medium, &p, None).unwrap();
    assert!(s.converged, "{s:?}");
    assert!(
        matches!(s.path, SolvePath::SweepsThenNewton | SolvePath::Sweeps),
        "{s:?}"
    );
}

#[test]
fn a_sliding_held_contact_takes_chord_steps_and_matches_the_sweeps() {
    // Every pair pressed closed and driven tangentially (most pairs slip), the drive turning a
    // little from step to step: the states repeat while the slip directions move, so the
    // kept factorisation serves as a chord step (fewer LUs than Newton iterations), and each
    // step's forces still match the sweeps' within the tolerance.
    let base = held(physical_problem(7, 192), 1.0);
    let n = base.n_pairs();
    let scale = base.c.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let mut solver = ContactSolver::new(&base.w, &base.mu, params(NewtonUse::Always)).unwrap();
    let (mut lambda, mut gamma) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    let (mut iterations, mut factorisations, mut slipping) = (0, 0, 0);
    for step in 0..6 {
        let angle = 0.02 * step as f64;
        let mut p = base.clone();
        for k in 0..n {
            p.c[3 * k + 1] = 0.8 * scale * angle.cos();
            p.c[3 * k + 2] = 0.8 * scale * angle.sin();
        }
        let s = solver.solve(&p.c, None, &mut lambda, &mut gamma).unwrap();
        assert!(
            s.converged && s.path == SolvePath::Newton,
            "step {step}: {s:?}"
        );
        let (sweeps, s0) = solve_problem(&p, &params(NewtonUse::Never), None).unwrap();
        assert!(s0.converged, "step {step}: sweeps {s0:?}");
        let e = rel_diff(&lambda, &sweeps.lambda);
        assert!(e < 1e-8, "step {step}: Newton vs sweeps {e:e}");
        let v = law_violation(&p, &lambda);
        assert!(v < 1e-9, "step {step}: law violation {v:e}");
        iterations += s.newton_iterations;
        factorisations += s.factorisations;
        slipping += s.slip;
    }
    println!(
        "{iterations} Newton iterations, {factorisations} LUs, {slipping} slipping pair-steps"
    );
    assert!(
        slipping > 6 * n / 2,
        "mostly slipping: {slipping} of {}",
        6 * n
    );
    assert!(
        factorisations < iterations,
        "no chord step: {factorisations} LUs in {iterations} iterations"
    );
}
