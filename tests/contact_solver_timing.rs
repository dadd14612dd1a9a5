//! Measures the contact solver's speed (ignored by default; a measurement, not a check of
//! numbers): CPU time and solves per second for 20, 60 and 192 active pairs of physically
//! shaped problems, cold (from zero) and warm-started along sequences of steps whose free
//! velocities oscillate by 10 % with a period of 20 or 200 steps, for every sweep method. Run
//! with `cargo test --release --test contact_solver_timing -- --ignored --nocapture`.

mod contact_support;

use std::time::Instant;

use contact_support::{physical_problem, rng, thread_cpu_seconds};
use rand::Rng;
use rigtwin::contact::{ContactParameters, ContactSolver, NewtonUse, StepRule, SweepMethod};

const METHODS: [(&str, SweepMethod, StepRule); 4] = [
    ("Jacobi/auto", SweepMethod::Jacobi, StepRule::Auto),
    (
        "accel. Jacobi/auto",
        SweepMethod::AcceleratedJacobi,
        StepRule::Auto,
    ),
    (
        "accel. Jacobi/spectral",
        SweepMethod::AcceleratedJacobi,
        StepRule::Spectral,
    ),
    ("Gauss-Seidel", SweepMethod::GaussSeidel, StepRule::Auto),
];

/// CPU time of the calling thread (Linux: `CLOCK_THREAD_CPUTIME_ID`), so that the numbers
/// hold on a machine shared with other jobs; wall time elsewhere.
struct Clock {
    wall: Instant,
    cpu: Option<f64>,
}

impl Clock {
    fn now() -> Clock {
        Clock {
            wall: Instant::now(),
            cpu: thread_cpu_seconds(),
        }
    }

    fn elapsed(&self) -> f64 {
        match (self.cpu, thread_cpu_seconds()) {
            (Some(a), Some(b)) => b - a,
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

/// A sequence of free velocities: every component oscillates by 10 % of the largest |c| with
/// the given period in steps (random phases), around the problem's c.
fn sequence(
    problem: &rigtwin::contact::ContactProblem,
    period: f64,
    steps: usize,
) -> Vec<Vec<f64>> {
    let d = problem.c.len();
    let mut r = rng(77);
    let cmax = problem.c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let phases: Vec<f64> = (0..d)
        .map(|_| r.gen_range(0.0..std::f64::consts::TAU))
        .collect();
    (0..steps)
        .map(|j| {
            (0..d)
                .map(|i| {
                    problem.c[i]
                        + 0.1 * cmax * (std::f64::consts::TAU * j as f64 / period + phases[i]).sin()
                })
                .collect()
        })
        .collect()
}

/// Mean iterations and CPU time per solve along a warm-started sequence.
fn run_sequence(
    problem: &rigtwin::contact::ContactProblem,
    params: &ContactParameters,
    seq: &[Vec<f64>],
) -> (f64, f64, usize) {
    let d = problem.c.len();
    let mut solver = ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
    let mut lambda = vec![0.0; d];
    let mut gamma = vec![0.0; d];
    solver
        .solve(&seq[0], None, &mut lambda, &mut gamma)
        .unwrap();
    let mut iterations = 0;
    let mut not_converged = 0;
    let clock = Clock::now();
    for c in &seq[1..] {
        let stats = solver.solve(c, None, &mut lambda, &mut gamma).unwrap();
        iterations += stats.iterations;
        not_converged += (!stats.converged) as usize;
    }
    let k = (seq.len() - 1) as f64;
    (iterations as f64 / k, clock.elapsed() / k, not_converged)
}

#[test]
#[ignore = "timing measurement; run explicitly with --ignored --nocapture"]
fn contact_solver_timing() {
    println!(
        "CPU time per solve (us), default tolerance {:e}",
        ContactParameters::default().tolerance
    );
    println!(
        "{:>5} {:>24} | {:>6} {:>9} {:>8} | {:>6} {:>9} {:>8} | {:>6} {:>9} {:>8} | {:>6}",
        "pairs",
        "method",
        "cold it",
        "us",
        "solv/s",
        "w20 it",
        "us",
        "solv/s",
        "w200 it",
        "us",
        "solv/s",
        "nconv"
    );
    for n in [20usize, 60, 192] {
        let problem = physical_problem(900 + n as u64, n);
        let d = 3 * n;
        let steps = if n > 100 { 100 } else { 400 };
        let fast = sequence(&problem, 20.0, steps);
        let slow = sequence(&problem, 200.0, steps);
        for (name, method, step_rule) in METHODS {
            let params = ContactParameters {
                method,
                step_rule,
                newton: NewtonUse::Never,
                ..ContactParameters::default()
            };
            // Cold: fresh solver each time (includes gathering W and step sizes), best of 5.
            let mut cold = f64::INFINITY;
            let mut cold_it = 0;
            for _ in 0..5 {
                let mut solver =
                    ContactSolver::new(&problem.w, &problem.mu, params.clone()).unwrap();
                let mut lambda = vec![0.0; d];
                let mut gamma = vec![0.0; d];
                let clock = Clock::now();
                let stats = solver
                    .solve(&problem.c, None, &mut lambda, &mut gamma)
                    .unwrap();
                cold = cold.min(clock.elapsed());
                cold_it = stats.iterations;
            }
            let (it20, t20, nc20) = run_sequence(&problem, &params, &fast);
            let (it200, t200, nc200) = run_sequence(&problem, &params, &slow);
            println!(
                "{:>5} {:>24} | {:>6} {:>9.1} {:>8.0} | {:>6.1} {:>9.1} {:>8.0} | {:>6.1} {:>9.1} {:>8.0} | {:>6}",
                n,
                name,
                cold_it,
                1e6 * cold,
                1.0 / cold,
                it20,
                1e6 * t20,
                1.0 / t20,
                it200,
                1e6 * t200,
                1.0 / t200,
                nc20 + nc200
            );
        }
    }
}
