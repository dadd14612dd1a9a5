//! Guards that the two contact couplings are two discretisations of the same model: two
//! Euler-Bernoulli cantilevers (6 modes each, both couplings stable from ~550 steps per
//! period) start in free vibration towards each other and hit at the tips several times in
//! three periods. The sensor histories of the explicit (reference) and the end-of-step
//! coupling approach each other as dt shrinks, at first order (the end-of-step coupling's
//! lag), and differ by less than 0.6 % at the smallest step. Each on its own converges at its
//! order: second for the explicit coupling (leapfrog), first for the end-of-step coupling.

mod sim_support;

use rigtwin::sim::{
    Coupling, Excitation, Integrator, IntegratorParameters, State, StepOutput, TimeStep,
};

const PERIODS: f64 = 3.0;
const STEPS: [f64; 5] = [4000.0, 8000.0, 16000.0, 32000.0, 64000.0];
/// Elastic layer between the tips, m/N: a contact softer than the bare residual flexibility,
/// so that each impact is one smooth contact (the bare tips micro-bounce, a sensitive regime
/// in which neither coupling converges trajectory-wise over several impacts).
const LAYER: f64 = 1e-6;

/// Upper-tip displacement at the times k dt (k = 1 ..= n - 1) and the number of impacts.
fn history(coupling: Coupling, steps: f64) -> (Vec<f64>, u64) {
    let rom = sim_support::two_cantilevers_with_layer(6, 1e-4, 0.4, 0.0, LAYER);
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps },
        coupling,
        ..IntegratorParameters::default()
    };
    let mut integ = Integrator::new(&rom, params).unwrap();
    let dt = integ.dt();
    let m = rom.omega.len();
    let mut v = vec![0.0; m];
    v[rom.meta.reference_mode] = -0.05;
    let mut state = State::from_modal(vec![0.0; m], v, 1, 0.0);
    let n = (PERIODS * steps) as u64;
    let mut y = vec![0.0; n as usize + 1];
    let (mut impacts, mut was_closed) = (0, false);
    let mut sink = |o: &StepOutput<'_>| {
        // Explicit outputs are at t^j, end-of-step outputs at t^{j+1}: index by time.
        let k = (o.time / dt).round() as usize;
        y[k] = o.displacement[1];
        impacts += (o.contact.any_closed && !was_closed) as u64;
        was_closed = o.contact.any_closed;
    };
    let excitation = Excitation::Sampled {
        accel: vec![0.0; 2],
        dt_sample: 1.0,
    };
    integ.run(&mut state, &excitation, n, &mut sink).unwrap();
    (y[1..n as usize].to_vec(), impacts)
}

/// RMS difference relative to the RMS of the explicit history.
fn difference(steps: f64) -> f64 {
    let (a, impacts_a) = history(Coupling::Explicit, steps);
    let (b, impacts_b) = history(Coupling::EndOfStep, steps);
    assert!(impacts_a >= 3 && impacts_b >= 3, "the test needs impacts");
    let (mut d2, mut r2) = (0.0, 0.0);
    for (x, y) in a.iter().zip(&b) {
        d2 += (x - y) * (x - y);
        r2 += x * x;
    }
    (d2 / r2).sqrt()
}

#[test]
fn explicit_and_end_of_step_couplings_converge_to_the_same_response() {
    let rom = sim_support::two_cantilevers_with_layer(6, 1e-4, 0.4, 0.0, LAYER);
    let limits = rigtwin::sim::stability_limits(&rom).unwrap();
    assert!(limits.steps_per_period_closed() < 1000.0);
    let d: Vec<f64> = STEPS.iter().map(|&s| difference(s)).collect();
    println!(
        "explicit vs end of step, relative RMS difference at {STEPS:?} steps per period: {d:?}"
    );
    for w in d.windows(2) {
        let ratio = w[0] / w[1];
        assert!((1.5..3.0).contains(&ratio), "not first order: {d:?}");
    }
    assert!(
        d[4] < 0.006,
        "couplings differ by {} at the smallest step",
        d[4]
    );
}

/// Relative RMS change of one coupling's history when dt halves, for each step of `STEPS`
/// except the first.
fn self_convergence(coupling: Coupling) -> Vec<f64> {
    let mut prev: Option<Vec<f64>> = None;
    let mut out = vec![];
    for &s in STEPS.iter() {
        let (y, _) = history(coupling, s);
        if let Some(p) = prev {
            // p[k] is at time (k + 1) 2 dt = y[2 k + 1].
            let (mut d2, mut r2) = (0.0, 0.0);
            for (k, x) in p.iter().enumerate() {
                d2 += (x - y[2 * k + 1]).powi(2);
                r2 += x * x;
            }
            out.push((d2 / r2).sqrt());
        }
        prev = Some(y);
    }
    out
}

#[test]
fn explicit_coupling_is_second_order_and_end_of_step_first_order() {
    for (coupling, order) in [(Coupling::Explicit, 2), (Coupling::EndOfStep, 1)] {
        let d = self_convergence(coupling);
        println!("{coupling:?}: change when dt halves: {d:?}");
        let expected = (1 << order) as f64;
        for w in d.windows(2) {
            let ratio = w[0] / w[1];
            assert!(
                ratio > 0.75 * expected && ratio < 1.3 * expected,
                "{coupling:?}: ratio {ratio}, expected ~{expected}: {d:?}"
            );
        }
    }
}
