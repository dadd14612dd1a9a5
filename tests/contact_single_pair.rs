//! Guards the contact solver on single pairs with answers known in closed form: separation,
//! sticking (the tangential force balances the load exactly, gamma = 0) and sliding
//! (|lambda_t| = mu lambda_n, gamma_t antiparallel to lambda_t), for every sweep method.

mod contact_support;

use contact_support::{dense_solve, law_violation};
use rigtwin::contact::{solve_problem, ContactParameters, ContactProblem, NewtonUse, SweepMethod};

const ALL_METHODS: [SweepMethod; 3] = [
    SweepMethod::Jacobi,
    SweepMethod::AcceleratedJacobi,
    SweepMethod::GaussSeidel,
];

fn params(method: SweepMethod) -> ContactParameters {
    ContactParameters {
        method,
        tolerance: 1e-14,
        max_iterations: 100_000,
        newton: NewtonUse::Never,
        ..ContactParameters::default()
    }
}

/// A coupled single-pair Delassus block (m/s/N), SPD, not diagonally dominant in the n-t rows.
fn coupled_w() -> Vec<f64> {
    vec![
        2.0e-3, 0.3e-3, -0.2e-3, //
        0.3e-3, 1.5e-3, 0.1e-3, //
        -0.2e-3, 0.1e-3, 1.2e-3,
    ]
}

fn assert_close(a: f64, b: f64, rel: f64, what: &str) {
    assert!(
        (a - b).abs() <= rel * b.abs().max(a.abs()).max(1e-300),
        "{what}: {a} vs {b}"
    );
}

#[test]
fn separating_pair_carries_no_force() {
    for method in ALL_METHODS {
        let problem = ContactProblem {
            w: coupled_w(),
            c: vec![0.05, -0.3, 0.2],
            mu: vec![0.4],
            label: String::new(),
        };
        // Warm start from a wrong, compressive force: the solver must release it.
        let (sol, stats) =
            solve_problem(&problem, &params(method), Some(&[100.0, 10.0, 0.0])).unwrap();
        assert!(stats.converged, "{stats:?}");
        assert_eq!(sol.lambda, vec![0.0; 3]);
        assert_eq!(sol.gamma, problem.c);
        assert_eq!((stats.open, stats.stick, stats.slip), (1, 0, 0));
        assert_eq!(stats.residual, 0.0);
    }
}

#[test]
fn sticking_pair_balances_the_load_exactly() {
    for method in ALL_METHODS {
        let w = coupled_w();
        let c = vec![-0.1, -0.01, 0.005];
        // Sticking: gamma = 0, so lambda = -W^-1 c, which must lie inside the friction disk.
        let minus_c: Vec<f64> = c.iter().map(|x| -x).collect();
        let exact = dense_solve(&w, &minus_c).unwrap();
        assert!(exact[0] > 0.0 && exact[1].hypot(exact[2]) < 0.4 * exact[0]);
        let problem = ContactProblem {
            w,
            c,
            mu: vec![0.4],
            label: String::new(),
        };
        let (sol, stats) = solve_problem(&problem, &params(method), None).unwrap();
        assert!(stats.converged, "{stats:?}");
        for (l, e) in sol.lambda.iter().zip(&exact) {
            assert_close(*l, *e, 1e-12, "lambda");
        }
        assert!(
            sol.gamma.iter().all(|g| g.abs() < 1e-14),
            "gamma {:?}",
            sol.gamma
        );
        assert_eq!((stats.open, stats.stick, stats.slip), (0, 1, 0));
    }
}

#[test]
fn sliding_pair_with_decoupled_block_matches_closed_form() {
    // W = diag(a, b, b): lambda_n = -c_n / a, lambda_t = -mu lambda_n c_t / |c_t| as long as
    // |c_t| > b mu lambda_n, and gamma_t = c_t + b lambda_t keeps the direction of c_t.
    let (a, b, mu) = (2.0e-3, 1.5e-3, 0.4);
    let c: [f64; 3] = [-0.1, 0.08, -0.06];
    let ln = -c[0] / a;
    let ct = c[1].hypot(c[2]);
    assert!(ct > b * mu * ln);
    let exact = [ln, -mu * ln * c[1] / ct, -mu * ln * c[2] / ct];
    let problem = ContactProblem {
        w: vec![a, 0.0, 0.0, 0.0, b, 0.0, 0.0, 0.0, b],
        c: c.to_vec(),
        mu: vec![mu],
        label: String::new(),
    };
    for method in ALL_METHODS {
        let (sol, stats) = solve_problem(&problem, &params(method), None).unwrap();
        assert!(stats.converged, "{stats:?}");
        for (l, e) in sol.lambda.iter().zip(&exact) {
            assert_close(*l, *e, 1e-12, "lambda");
        }
        assert!(sol.gamma[0].abs() < 1e-15);
        let gt = [c[1] + b * exact[1], c[2] + b * exact[2]];
        assert_close(sol.gamma[1], gt[0], 1e-10, "gamma_t1");
        assert_close(sol.gamma[2], gt[1], 1e-10, "gamma_t2");
        assert_eq!((stats.open, stats.stick, stats.slip), (0, 0, 1));
    }
}

#[test]
fn sliding_pair_with_coupled_block_obeys_coulomb() {
    let problem = ContactProblem {
        w: coupled_w(),
        c: vec![-0.1, 0.2, -0.15],
        mu: vec![0.4],
        label: String::new(),
    };
    for method in ALL_METHODS {
        let (sol, stats) = solve_problem(&problem, &params(method), None).unwrap();
        assert!(stats.converged, "{stats:?}");
        let l = &sol.lambda;
        let g = &sol.gamma;
        assert!(l[0] > 0.0);
        assert_close(
            l[1].hypot(l[2]),
            0.4 * l[0],
            1e-12,
            "|lambda_t| = mu lambda_n",
        );
        assert!(g[0].abs() < 1e-14 * 0.2, "gamma_n {}", g[0]);
        // Antiparallel: gamma_t = -alpha lambda_t with alpha > 0.
        let cos = (l[1] * g[1] + l[2] * g[2]) / (l[1].hypot(l[2]) * g[1].hypot(g[2]));
        assert!((cos + 1.0).abs() < 1e-12, "cos {cos}");
        assert!(law_violation(&problem, l) < 1e-12);
        assert_eq!(stats.slip, 1);
    }
}

#[test]
fn frictionless_pair_slides_freely() {
    let problem = ContactProblem {
        w: coupled_w(),
        c: vec![-0.1, 0.2, -0.15],
        mu: vec![0.0],
        label: String::new(),
    };
    let (sol, stats) = solve_problem(&problem, &params(SweepMethod::Jacobi), None).unwrap();
    assert!(stats.converged);
    assert_eq!(&sol.lambda[1..], &[0.0, 0.0]);
    assert_close(sol.lambda[0], 0.1 / 2.0e-3, 1e-12, "lambda_n = -c_n / W_nn");
}
