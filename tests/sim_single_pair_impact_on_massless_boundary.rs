//! Guards the impact behaviour of the massless boundary on the simplest case with a known
//! answer: one mode (a mass on a spring) hitting a wall through a massless spring of
//! flexibility G (the residual flexibility). While closed the mode oscillates about a shifted
//! equilibrium at `w_c = sqrt(w^2 + 1/G)`, the force is a piece of a sine, the contact opens
//! when the force returns to zero, and the exact restitution is 1. Checked for both
//! couplings: one closing and one opening per impact (no chattering), contact duration and
//! peak force against the piecewise-linear solution, a unimodal force history, and a
//! restitution that is at most 1 and close to it.

mod sim_support;

use rigtwin::sim::{Coupling, Excitation, Integrator, IntegratorParameters, State, TimeStep};

struct Record {
    closed: bool,
    lambda_n: f64,
    leapfrog: f64,
    boundary: f64,
}

struct Impact {
    /// Steps with the contact closed.
    steps: usize,
    /// Peak normal force, N.
    peak: f64,
    /// Whether the force rises and then falls with no other extremum.
    unimodal: bool,
    /// Leapfrog energy of the flight before and after, J.
    energy_before: f64,
    energy_after: f64,
}

fn impacts(records: &[Record]) -> Vec<Impact> {
    let mut out = vec![];
    let mut j = 0;
    while j < records.len() {
        if !records[j].closed {
            j += 1;
            continue;
        }
        let start = j;
        while j < records.len() && records[j].closed {
            j += 1;
        }
        if start == 0 || j == records.len() {
            continue;
        }
        let forces: Vec<f64> = records[start..j].iter().map(|r| r.lambda_n).collect();
        let peak = forces.iter().copied().fold(0.0, f64::max);
        let turns = forces
            .windows(3)
            .filter(|w| (w[1] - w[0]) * (w[2] - w[1]) < 0.0)
            .count();
        out.push(Impact {
            steps: j - start,
            peak,
            unimodal: turns <= 1,
            energy_before: records[start - 1].leapfrog + records[start - 1].boundary,
            energy_after: records[j].leapfrog + records[j].boundary,
        });
    }
    out
}

/// The piecewise-linear solution: contact duration (s) and peak force (N) for a mode hitting
/// the wall with speed `u0 < 0` at eta = -clearance.
fn exact_contact(omega: f64, g: f64, clearance: f64, u0: f64) -> (f64, f64) {
    let wc = (omega * omega + 1.0 / g).sqrt();
    let eta_eq = -clearance / (g * wc * wc);
    let x0 = -clearance - eta_eq;
    let theta = (u0 / wc).atan2(x0);
    let two_pi = 2.0 * std::f64::consts::PI;
    let duration = (2.0 * theta).rem_euclid(two_pi) / wc;
    let r = x0.hypot(u0 / wc);
    (duration, (x0 + r) / g)
}

/// Runs 20 free periods at `steps` per period and checks every impact; returns the mean
/// restitution.
fn check(coupling: Coupling, steps: f64) -> f64 {
    let omega = 2.0 * std::f64::consts::PI * 10.0;
    let g = 1.0 / (99.0 * omega * omega); // w_c = 10 w
    let clearance = 1e-3;
    let rom = sim_support::bar_one_mode(omega, g, clearance, 0.0);
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps },
        coupling,
        ..IntegratorParameters::default()
    };
    let mut integ = Integrator::new(&rom, params).unwrap();
    let h = integ.dt();
    // Free amplitude 2 x clearance: one impact per period.
    let v0 = -2.0 * clearance * omega;
    let mut state = State::from_modal(vec![0.0], vec![v0], 1, 0.0);
    let mut records = vec![];
    let mut sink = |o: &rigtwin::sim::StepOutput<'_>| {
        records.push(Record {
            closed: o.contact.any_closed,
            lambda_n: o.lambda[0],
            leapfrog: o.energy.leapfrog(),
            boundary: o.energy.boundary,
        })
    };
    let periods = 20;
    let excitation = Excitation::Sampled {
        accel: vec![0.0; 2],
        dt_sample: 1e3,
    };
    let report = integ
        .run(&mut state, &excitation, periods * steps as u64, &mut sink)
        .unwrap();
    assert!(report.stop.is_none());
    assert_eq!(report.counters.max_iterations + report.counters.diverged, 0);

    let closings = records
        .windows(2)
        .filter(|w| !w[0].closed && w[1].closed)
        .count();
    let found = impacts(&records);
    // At least one impact per free period, and every closing starts one impact phase of the
    // exact duration (checked below): a phase split by chattering would be too short.
    assert!(
        closings >= periods as usize,
        "{coupling:?}: {closings} closings in {periods} periods"
    );
    assert!(found.len() + 1 >= closings);
    let mut restitutions = vec![];
    for (i, imp) in found.iter().enumerate() {
        // Speed at the wall from the flight energy before the impact.
        let e = imp.energy_before;
        let u0 = -(2.0 * e - omega * omega * clearance * clearance).sqrt();
        let (duration, peak) = exact_contact(omega, g, clearance, u0);
        let steps_exact = duration / h;
        assert!(
            (imp.steps as f64 - steps_exact).abs() <= 2.0,
            "{coupling:?} impact {i}: {} steps closed, exact {steps_exact:.2}",
            imp.steps
        );
        // The end-of-step coupling loses energy during the contact (first order in dt), so
        // its peak force is low by a few per cent at 1000 steps per period.
        let tolerance = match coupling {
            Coupling::Explicit => 0.01,
            Coupling::EndOfStep => 0.06 * 1000.0 / steps,
        };
        assert!(
            (imp.peak - peak).abs() <= tolerance * peak,
            "{coupling:?} impact {i}: peak force {} N, exact {peak} N",
            imp.peak
        );
        assert!(imp.unimodal, "{coupling:?} impact {i}: force oscillates");
        // Restitution from the flight energies: e^2 = (2E_after - w^2 d^2) / (2E_before - w^2 d^2).
        let w2d2 = omega * omega * clearance * clearance;
        let restitution =
            ((2.0 * imp.energy_after - w2d2) / (2.0 * imp.energy_before - w2d2)).sqrt();
        match coupling {
            // Symplectic while closed: elastic up to O(dt^2).
            Coupling::Explicit => assert!(
                (restitution - 1.0).abs() < 1e-3,
                "{coupling:?} impact {i}: restitution {restitution}"
            ),
            // Implicit in the closed stiffness: dissipative, never above 1.
            Coupling::EndOfStep => assert!(
                restitution <= 1.0 + 1e-12 && restitution > 0.9,
                "{coupling:?} impact {i}: restitution {restitution}"
            ),
        }
        restitutions.push(restitution);
        if i == 0 {
            println!(
                "{coupling:?}: {} steps closed (exact {steps_exact:.2}), peak {:.6e} N (exact {peak:.6e}), restitution {restitution:.6}",
                imp.steps, imp.peak
            );
        }
    }
    restitutions.iter().sum::<f64>() / restitutions.len() as f64
}

#[test]
fn end_of_step_impact_closes_once_with_a_smooth_force_and_restitution_below_one() {
    let e = check(Coupling::EndOfStep, 1000.0);
    println!("end of step, 1000 steps per period: mean restitution {e:.5}");
}

#[test]
fn explicit_impact_closes_once_with_a_smooth_force_and_restitution_near_one() {
    let e = check(Coupling::Explicit, 1000.0);
    println!("explicit, 1000 steps per period: mean restitution {e:.7}");
}

/// The end-of-step coupling's loss of restitution is a first-order time discretisation
/// error: halving dt halves it.
#[test]
fn end_of_step_restitution_converges_to_one_at_first_order() {
    let d1 = 1.0 - check(Coupling::EndOfStep, 1000.0);
    let d2 = 1.0 - check(Coupling::EndOfStep, 2000.0);
    let d4 = 1.0 - check(Coupling::EndOfStep, 4000.0);
    println!("restitution deficit at 1000/2000/4000 steps per period: {d1:.5} {d2:.5} {d4:.5}");
    for (a, b) in [(d1, d2), (d2, d4)] {
        assert!(a > 0.0 && b > 0.0);
        assert!((1.6..2.4).contains(&(a / b)), "deficit ratio {}", a / b);
    }
}
