//! Guards that `ContactSolver::solve` does not allocate: a counting global allocator watches
//! the solving thread over many solves with changing active sets, every sweep method and step
//! rule, and warm starts.

mod contact_support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use contact_support::physical_problem;
use rigtwin::contact::{ContactParameters, ContactSolver, NewtonUse, StepRule, SweepMethod};

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; the bookkeeping touches only const-initialised
// thread-locals, which never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ARMED.with(|a| a.get()) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if ARMED.with(|a| a.get()) {
            COUNT.with(|c| c.set(c.get() + 1));
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// One solve of every kind the loop below meets (cold, all pairs, and held: every pair
/// pressed closed so the complement form with W^-1 is used).
fn warm_up(solver: &mut ContactSolver, problem: &rigtwin::contact::ContactProblem) {
    let n = problem.n_pairs();
    let (mut lambda, mut gamma) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    solver
        .solve(&problem.c, None, &mut lambda, &mut gamma)
        .unwrap();
    let held: Vec<f64> = (0..3 * n)
        .map(|i| if i % 3 == 0 { -1.0 } else { 0.0 })
        .collect();
    let held: Vec<f64> = (0..3 * n)
        .map(|i| {
            -(0..3 * n)
                .map(|j| problem.w[i * 3 * n + j] * -held[j])
                .sum::<f64>()
        })
        .collect();
    lambda.fill(0.0);
    solver.solve(&held, None, &mut lambda, &mut gamma).unwrap();
}

#[test]
fn solve_does_not_allocate() {
    let problem = physical_problem(21, 48);
    let n = problem.n_pairs();
    let mut total_iterations = 0;
    for (method, step_rule, newton) in [
        (SweepMethod::Jacobi, StepRule::Auto, NewtonUse::Never),
        (SweepMethod::Jacobi, StepRule::Spectral, NewtonUse::Never),
        (
            SweepMethod::AcceleratedJacobi,
            StepRule::Auto,
            NewtonUse::Never,
        ),
        (SweepMethod::GaussSeidel, StepRule::Auto, NewtonUse::Never),
        (SweepMethod::Jacobi, StepRule::Auto, NewtonUse::Auto),
        (SweepMethod::GaussSeidel, StepRule::Auto, NewtonUse::Always),
    ] {
        let params = ContactParameters {
            method,
            step_rule,
            newton,
            ..ContactParameters::default()
        };
        let mut solver = ContactSolver::new(&problem.w, &problem.mu, params).unwrap();
        if newton != NewtonUse::Never {
            // NOTE: the Newton workspace's matrix and, for the complement form, W^-1 are
            // allocated once, at the first solve that needs them (most solvers never do).
            warm_up(&mut solver, &problem);
        }
        let mut lambda = vec![0.0; 3 * n];
        let mut gamma = vec![0.0; 3 * n];
        let mut c = problem.c.clone();
        let mut gaps = vec![0.0; n];
        let mut changes = 0;
        ARMED.with(|a| a.set(true));
        for step in 0..60 {
            // Active sets of varying size and membership, including empty and full.
            for (k, g) in gaps.iter_mut().enumerate() {
                *g = if (k + step) % 7 < step % 8 {
                    1e-3
                } else {
                    -1e-6
                };
            }
            for (i, x) in c.iter_mut().enumerate() {
                *x = problem.c[i] * (1.0 + 0.05 * ((step + i) as f64).sin());
            }
            let stats = solver
                .solve(&c, Some(&gaps), &mut lambda, &mut gamma)
                .unwrap();
            total_iterations += stats.iterations;
            changes += stats.active_set_changed as usize;
        }
        ARMED.with(|a| a.set(false));
        assert!(
            changes > 10,
            "{method:?}: only {changes} active-set changes"
        );
        let count = COUNT.with(|c| c.get());
        assert_eq!(
            count, 0,
            "{method:?} {step_rule:?} {newton:?}: {count} allocations during solves"
        );
    }
    assert!(total_iterations > 1000);
}
