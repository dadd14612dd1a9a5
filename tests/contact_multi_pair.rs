//! Guards the contact solver on coupled multi-pair problems: frictionless problems against
//! the exact LCP solution found by enumerating all active sets, frictional problems (random
//! SPD and physically shaped Delassus matrices) against the contact law to 1e-10, agreement
//! of sweep methods and step rules, the active-set prediction, warm starts, and non-convergence
//! and bad input reported as data or errors.

mod contact_support;

use contact_support::{apply, dense_solve, law_violation, physical_problem, random_spd_problem};
use rigtwin::contact::{
    solve_problem, ContactError, ContactParameters, ContactProblem, ContactSolver, NewtonUse,
    PairState, SolveStatus, StepRule, SweepMethod,
};

fn tight(method: SweepMethod, step_rule: StepRule) -> ContactParameters {
    ContactParameters {
        method,
        step_rule,
        tolerance: 1e-14,
        max_iterations: 200_000,
        // The sweep methods themselves are under test here (Newton: contact_newton_*.rs).
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    }
}

const METHODS: [(SweepMethod, StepRule); 6] = [
    (SweepMethod::Jacobi, StepRule::Auto),
    (SweepMethod::Jacobi, StepRule::RowSum),
    (SweepMethod::Jacobi, StepRule::Spectral),
    (SweepMethod::AcceleratedJacobi, StepRule::Auto),
    (SweepMethod::AcceleratedJacobi, StepRule::Spectral),
    (SweepMethod::GaussSeidel, StepRule::Auto),
];

/// The exact solution of the frictionless problem (normal LCP
/// `gamma_n = W_nn lambda_n + c_n`, `0 <= lambda_n _|_ gamma_n >= 0`) by trying every active
/// set; W SPD makes it unique.
fn enumerate_lcp(problem: &ContactProblem) -> Vec<f64> {
    let n = problem.n_pairs();
    let d = 3 * n;
    let mut found = None;
    for mask in 0u32..(1 << n) {
        let set: Vec<usize> = (0..n).filter(|k| mask & (1 << k) != 0).collect();
        let a: Vec<f64> = set
            .iter()
            .flat_map(|&p| set.iter().map(move |&q| (p, q)))
            .map(|(p, q)| problem.w[3 * p * d + 3 * q])
            .collect();
        let b: Vec<f64> = set.iter().map(|&p| -problem.c[3 * p]).collect();
        let Some(x) = dense_solve(&a, &b) else {
            continue;
        };
        let mut lambda = vec![0.0; d];
        for (i, &p) in set.iter().enumerate() {
            lambda[3 * p] = x[i];
        }
        let gamma = apply(&problem.w, &lambda, &problem.c);
        let scale = problem.c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let ok = (0..n).all(|k| lambda[3 * k] >= 0.0 && gamma[3 * k] >= -1e-12 * scale);
        if ok {
            assert!(found.is_none(), "two LCP solutions: W not SPD?");
            found = Some(lambda);
        }
    }
    found.expect("an SPD LCP has a solution")
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let num = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    let den = b.iter().map(|y| y * y).sum::<f64>().sqrt().max(1e-300);
    num / den
}

#[test]
fn frictionless_problems_match_the_enumerated_lcp_solution() {
    let mut cases = Vec::new();
    for seed in 0..12 {
        let n = 2 + (seed as usize % 6);
        let mut p = random_spd_problem(seed, n, 0.0, 0.05);
        p.label = format!("random {seed}");
        cases.push(p);
        let mut p = physical_problem(100 + seed, n);
        p.mu = vec![0.0; n];
        cases.push(p);
    }
    let mut worst = 0.0f64;
    let mut mixed = 0;
    for problem in &cases {
        let exact = enumerate_lcp(problem);
        let n_active = (0..problem.n_pairs())
            .filter(|&k| exact[3 * k] > 0.0)
            .count();
        if n_active > 0 && n_active < problem.n_pairs() {
            mixed += 1;
        }
        for (method, rule) in METHODS {
            let (sol, stats) = solve_problem(problem, &tight(method, rule), None).unwrap();
            assert!(
                stats.converged,
                "{}: {method:?} {rule:?} {stats:?}",
                problem.label
            );
            let e = rel_diff(&sol.lambda, &exact);
            worst = worst.max(e);
            assert!(
                e < 1e-10,
                "{}: {method:?} {rule:?}: rel. error {e:e}",
                problem.label
            );
            assert!(sol.lambda.iter().skip(1).step_by(3).all(|&x| x == 0.0));
        }
    }
    // The cases must exercise partial contact, not only all-open or all-closed.
    assert!(
        mixed >= cases.len() / 3,
        "only {mixed} cases with partial contact"
    );
    println!(
        "frictionless LCP: worst relative error {worst:e} over {} cases",
        cases.len()
    );
}

#[test]
fn random_frictional_problems_satisfy_the_contact_law() {
    let mut worst = 0.0f64;
    let (mut stick, mut slip, mut open) = (0, 0, 0);
    for seed in 0..30 {
        let n = 2 + (seed as usize % 9);
        let problem = random_spd_problem(1000 + seed, n, 0.4, 0.2);
        for (method, rule) in METHODS {
            let (sol, stats) = solve_problem(&problem, &tight(method, rule), None).unwrap();
            assert!(
                stats.converged,
                "seed {seed}: {method:?} {rule:?} {stats:?}"
            );
            let v = law_violation(&problem, &sol.lambda);
            worst = worst.max(v);
            assert!(
                v < 1e-10,
                "seed {seed}: {method:?} {rule:?}: violation {v:e}"
            );
            // The returned gamma is W lambda + c.
            let gamma = apply(&problem.w, &sol.lambda, &problem.c);
            assert!(rel_diff(&sol.gamma, &gamma) < 1e-12);
            if method == SweepMethod::Jacobi && rule == StepRule::Auto {
                stick += stats.stick;
                slip += stats.slip;
                open += stats.open;
            }
        }
    }
    assert!(stick > 0 && slip > 0 && open > 0, "{stick} {slip} {open}");
    println!(
        "random frictional: worst violation {worst:e}; pairs open {open} stick {stick} slip {slip}"
    );
}

#[test]
fn physical_problems_agree_across_methods_and_satisfy_the_law() {
    for (seed, n) in [(1u64, 12usize), (2, 30), (3, 60)] {
        let problem = physical_problem(seed, n);
        let (reference, stats) =
            solve_problem(&problem, &tight(SweepMethod::Jacobi, StepRule::Auto), None).unwrap();
        assert!(stats.converged, "{stats:?}");
        assert!(
            stats.stick + stats.slip > 0 && stats.open + stats.slip > 0,
            "{stats:?}"
        );
        let v = law_violation(&problem, &reference.lambda);
        assert!(v < 1e-10, "{}: violation {v:e}", problem.label);
        for (method, rule) in METHODS {
            let (sol, stats) = solve_problem(&problem, &tight(method, rule), None).unwrap();
            assert!(stats.converged, "{method:?} {rule:?} {stats:?}");
            let e = rel_diff(&sol.lambda, &reference.lambda);
            assert!(e < 1e-9, "{}: {method:?} {rule:?}: {e:e}", problem.label);
        }
    }
}

#[test]
fn predicted_open_pairs_are_left_out_and_the_rest_solved_exactly() {
    let problem = physical_problem(7, 24);
    let n = problem.n_pairs();
    let gaps: Vec<f64> = (0..n)
        .map(|k| if k % 3 == 0 { 1e-4 } else { -1e-6 })
        .collect();
    let params = tight(SweepMethod::Jacobi, StepRule::Auto);
    let mut solver = ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
    let mut lambda = vec![0.0; 3 * n];
    let mut gamma = vec![0.0; 3 * n];
    let stats = solver
        .solve(&problem.c, Some(&gaps), &mut lambda, &mut gamma)
        .unwrap();
    assert!(stats.converged);
    assert_eq!(stats.predicted_open, n.div_ceil(3));
    assert_eq!(stats.active_pairs, n - n.div_ceil(3));
    let active: Vec<usize> = (0..n).filter(|k| k % 3 != 0).collect();
    assert_eq!(solver.active_pairs(), &active[..]);
    // Same forces as the restricted problem solved alone.
    let sub = problem.restrict(&active).unwrap();
    let (sub_sol, _) = solve_problem(&sub, &params, None).unwrap();
    for (i, &p) in active.iter().enumerate() {
        for a in 0..3 {
            let (x, y) = (lambda[3 * p + a], sub_sol.lambda[3 * i + a]);
            assert!(
                (x - y).abs() <= 1e-12 * y.abs().max(1.0),
                "pair {p}: {x} vs {y}"
            );
        }
    }
    for k in (0..n).step_by(3) {
        assert_eq!(&lambda[3 * k..3 * k + 3], &[0.0; 3]);
        assert_eq!(solver.pair_states()[k], PairState::Open);
    }
    // gamma of every pair, open ones included, is W lambda + c.
    let expect = apply(&problem.w, &lambda, &problem.c);
    assert!(rel_diff(&gamma, &expect) < 1e-12);
    // The captured active sub-problem is the restricted problem with the solver's solution.
    let (captured, captured_sol) = solver.last_active_problem("capture");
    assert_eq!(captured.w, sub.w);
    assert_eq!(captured.c, sub.c);
    assert!(law_violation(&captured, &captured_sol.lambda) < 1e-10);
}

#[test]
fn warm_start_from_the_solution_converges_in_one_sweep_and_reuses_the_block() {
    let problem = physical_problem(11, 40);
    let n = problem.n_pairs();
    let params = ContactParameters {
        tolerance: 1e-12,
        max_iterations: 100_000,
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    };
    let mut solver = ContactSolver::new(&problem.w, &problem.mu, params).unwrap();
    let mut lambda = vec![0.0; 3 * n];
    let mut gamma = vec![0.0; 3 * n];
    let cold = solver
        .solve(&problem.c, None, &mut lambda, &mut gamma)
        .unwrap();
    assert!(cold.converged && cold.active_set_changed && cold.iterations > 10);
    let first = lambda.clone();
    let warm = solver
        .solve(&problem.c, None, &mut lambda, &mut gamma)
        .unwrap();
    assert!(warm.converged && !warm.active_set_changed, "{warm:?}");
    assert!(warm.iterations <= 2, "{warm:?}");
    assert!(rel_diff(&lambda, &first) < 1e-10);
}

#[test]
fn solves_are_deterministic() {
    let problem = physical_problem(5, 50);
    let run = || solve_problem(&problem, &ContactParameters::default(), None).unwrap();
    let (a, sa) = run();
    let (b, sb) = run();
    assert_eq!(a, b);
    assert_eq!(sa, sb);
}

#[test]
fn non_convergence_is_reported_not_hidden() {
    let problem = physical_problem(3, 60);
    let params = ContactParameters {
        max_iterations: 3,
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    };
    let (sol, stats) = solve_problem(&problem, &params, None).unwrap();
    assert_eq!(stats.status, SolveStatus::MaxIterations);
    assert!(!stats.converged);
    assert_eq!(stats.iterations, 3);
    assert!(stats.relative_residual > 1e-6, "{stats:?}");
    assert!(sol.lambda.iter().all(|x| x.is_finite()));
}

#[test]
fn unstable_step_rule_is_reported_as_data() {
    // The diagonal rule on a strongly coupled (not diagonally dominant) W does not converge:
    // the iterate oscillates or blows up. Either way the solve returns, flagged.
    let problem = physical_problem(3, 60);
    let params = ContactParameters {
        step_rule: StepRule::Diagonal,
        max_iterations: 20_000,
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    };
    let (sol, stats) = solve_problem(&problem, &params, None).unwrap();
    assert!(!stats.converged, "{stats:?}");
    assert_ne!(stats.status, SolveStatus::Converged);
    assert!(sol.lambda.iter().all(|x| x.is_finite()));
    assert!(stats.relative_residual > 1e-3, "{stats:?}");
}

#[test]
fn bad_input_is_an_error_value() {
    let problem = physical_problem(1, 4);
    let mut solver =
        ContactSolver::new(&problem.w, &problem.mu, ContactParameters::default()).unwrap();
    let mut lambda = vec![0.0; 12];
    let mut gamma = vec![0.0; 12];
    let mut c = problem.c.clone();
    c[5] = f64::NAN;
    let err = solver.solve(&c, None, &mut lambda, &mut gamma).unwrap_err();
    assert!(matches!(
        err,
        ContactError::NonFinite {
            what: "c",
            index: 5,
            ..
        }
    ));
    assert!(err.to_string().contains("c[5]"), "{err}");
    let err = solver
        .solve(
            &problem.c,
            Some(&[0.0, f64::INFINITY, 0.0, 0.0]),
            &mut lambda,
            &mut gamma,
        )
        .unwrap_err();
    assert!(err.to_string().contains("predicted_gap_n[1]"), "{err}");
    let err = solver
        .solve(&problem.c[..9], None, &mut lambda, &mut gamma)
        .unwrap_err();
    assert!(matches!(
        err,
        ContactError::Dimension {
            what: "c",
            found: 9,
            expected: 12,
            ..
        }
    ));
    lambda[0] = f64::NAN;
    assert!(solver
        .solve(&problem.c, None, &mut lambda, &mut gamma)
        .is_err());

    let mut w = problem.w.clone();
    w[1] += 1e-3 * w[0];
    assert!(matches!(
        ContactSolver::new(&w, &problem.mu, ContactParameters::default()),
        Err(ContactError::NotSymmetric { row: 0, col: 1, .. })
    ));
    assert!(matches!(
        ContactSolver::new(
            &problem.w,
            &[0.4, -0.1, 0.4, 0.4],
            ContactParameters::default()
        ),
        Err(ContactError::InvalidFriction { pair: 1, .. })
    ));
    let bad = ContactParameters {
        relaxation: 2.5,
        ..ContactParameters::default()
    };
    assert!(matches!(
        ContactSolver::new(&problem.w, &problem.mu, bad),
        Err(ContactError::InvalidParameter {
            field: "relaxation",
            ..
        })
    ));
}
