//! Guards that repeated frictionless impacts without damping or excitation never add energy
//! with the end-of-step coupling (two Euler-Bernoulli cantilevers hitting at the tips, free
//! vibration over 300 periods, hundreds of impacts): the total energy (leapfrog plus
//! boundary) before every impact is at most the one before the previous impact. The
//! end-of-step coupling loses energy at impacts (first order in dt); the explicit coupling at
//! a step inside its stability limit shows that the model itself is elastic.

mod sim_support;

use rigtwin::sim::{
    Coupling, Excitation, Integrator, IntegratorParameters, State, StepOutput, TimeStep,
};

/// Total energy before each impact over `periods` free periods.
fn energies_before_impacts(coupling: Coupling, steps: f64, periods: f64) -> Vec<f64> {
    let rom = sim_support::two_cantilevers(8, 1e-4, 0.0, 0.0);
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps },
        coupling,
        ..IntegratorParameters::default()
    };
    let mut integ = Integrator::new(&rom, params).unwrap();
    let m = rom.omega.len();
    let mut v = vec![0.0; m];
    v[rom.meta.reference_mode] = -0.05; // the upper beam moves down onto the lower one
    let mut state = State::from_modal(vec![0.0; m], v, 1, 0.0);
    let mut before = vec![];
    let (mut was_closed, mut last_open) = (false, 0.0);
    let mut sink = |o: &StepOutput<'_>| {
        if o.contact.any_closed && !was_closed {
            before.push(last_open);
        }
        if !o.contact.any_closed {
            last_open = o.energy.total();
        }
        was_closed = o.contact.any_closed;
    };
    let excitation = Excitation::Sampled {
        accel: vec![0.0; 2],
        dt_sample: 1e3,
    };
    let report = integ
        .run(&mut state, &excitation, (steps * periods) as u64, &mut sink)
        .unwrap();
    assert!(report.stop.is_none());
    assert_eq!(report.counters.max_iterations + report.counters.diverged, 0);
    before
}

#[test]
fn end_of_step_impacts_never_add_energy() {
    let e = energies_before_impacts(Coupling::EndOfStep, 1000.0, 300.0);
    assert!(e.len() > 200, "{} impacts", e.len());
    for (i, w) in e.windows(2).enumerate() {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-12),
            "impact {}: energy grew from {:e} to {:e} J",
            i + 1,
            w[0],
            w[1]
        );
    }
    println!(
        "end of step, 1000 steps per period: {} impacts, energy {:.4e} -> {:.4e} J (first impact keeps {:.4})",
        e.len(),
        e[0],
        e[e.len() - 1],
        e[1] / e[0]
    );
}

#[test]
fn explicit_coupling_inside_its_limit_keeps_the_impact_energy() {
    let e = energies_before_impacts(Coupling::Explicit, 4000.0, 100.0);
    assert!(e.len() > 50, "{} impacts", e.len());
    let (lo, hi) = e
        .iter()
        .fold((f64::MAX, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
    println!(
        "explicit, 4000 steps per period: {} impacts, energy within [{:.4}, {:.4}] of the first",
        e.len(),
        lo / e[0],
        hi / e[0]
    );
    assert!(lo > 0.95 * e[0] && hi < 1.05 * e[0]);
}
