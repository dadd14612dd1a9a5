//! Guards the energy behaviour of the leapfrog step: with contact open and no damping the
//! leapfrog ("shadow") energy is conserved to round-off over 1,000 periods and the plain
//! mechanical energy oscillates in a band that does not grow (no drift); with damping,
//! excitation, impacts and friction the reported energy accounts (base work, damping loss,
//! contact work) explain the change of the leapfrog energy exactly, for both couplings.

mod sim_support;

use rigtwin::sim::{
    Coupling, Excitation, Integrator, IntegratorParameters, State, StepOutput, TimeStep,
};

#[test]
fn open_contact_energy_does_not_drift_over_1000_periods() {
    // Clearance 1 m: the tips never meet.
    let rom = sim_support::two_cantilevers(8, 1.0, 0.4, 0.0);
    let m = rom.omega.len();
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    // Several modes excited, the highest included.
    let eta: Vec<f64> = (0..m).map(|i| 1e-4 / (1.0 + i as f64)).collect();
    let v: Vec<f64> = (0..m)
        .map(|i| 0.02 * if i % 3 == 0 { 1.0 } else { -0.5 })
        .collect();
    let mut state = State::from_modal(eta, v, 1, 0.0);
    let steps_per_period = 1000u64;
    let periods = 1000u64;
    let window = 10 * steps_per_period;
    let total = periods * steps_per_period;
    let mut e0 = None;
    let (mut lf_dev, mut band_first, mut band_last) = (0.0f64, 0.0f64, 0.0f64);
    let mut closed = 0u64;
    let mut sink = |o: &StepOutput<'_>| {
        let lf = o.energy.leapfrog();
        let e_ref = *e0.get_or_insert(lf);
        lf_dev = lf_dev.max((lf - e_ref).abs() / e_ref);
        let band = (o.energy.mechanical() - e_ref).abs() / e_ref;
        if o.step < window {
            band_first = band_first.max(band);
        }
        if o.step >= total - window {
            band_last = band_last.max(band);
        }
        closed += o.contact.any_closed as u64;
    };
    let excitation = Excitation::Sampled {
        accel: vec![0.0; 2],
        dt_sample: 1e4,
    };
    let report = integ
        .run(&mut state, &excitation, total, &mut sink)
        .unwrap();
    assert_eq!(report.steps, total);
    assert_eq!(closed, 0, "the contact must stay open in this test");
    println!(
        "leapfrog energy: max relative deviation {lf_dev:.3e}; mechanical energy band: first 10 \
         periods {band_first:.3e}, last 10 periods {band_last:.3e}"
    );
    assert!(lf_dev < 1e-10, "leapfrog energy drifts by {lf_dev:e}");
    assert!(
        band_first > 1e-6,
        "the plain energy should oscillate (O((w dt)^2))"
    );
    assert!(
        band_last <= 1.05 * band_first,
        "mechanical energy band grew from {band_first:e} to {band_last:e}"
    );
}

fn balance_residual(coupling: Coupling, steps: f64) -> (f64, u64) {
    let rom = sim_support::two_cantilevers(6, 3e-4, 0.4, 0.01);
    let w = sim_support::omega_ref(&rom);
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerPeriod { steps, omega: w },
        coupling,
        ..IntegratorParameters::default()
    };
    let mut integ = Integrator::new(&rom, params).unwrap();
    let mut state = integ.state_at_rest();
    let excitation = Excitation::Sine {
        amplitude_m: 2e-5,
        omega: w,
        phase: 0.0,
    };
    let mut first: Option<(f64, f64)> = None;
    let (mut worst, mut scale, mut closed) = (0.0f64, 0.0f64, 0u64);
    let mut sink = |o: &StepOutput<'_>| {
        // E^{j+1/2} - E^{-1/2} = net work; compare differences from the first step.
        let (lf, net) = (o.energy.leapfrog(), o.energy.accounts.net());
        let (lf0, net0) = *first.get_or_insert((lf, net));
        worst = worst.max(((lf - lf0) - (net - net0)).abs());
        scale = scale.max(lf.abs()).max(o.energy.accounts.base_work.abs());
        closed += o.contact.any_closed as u64;
    };
    integ
        .run(&mut state, &excitation, (60.0 * steps) as u64, &mut sink)
        .unwrap();
    (worst / scale, closed)
}

#[test]
fn energy_accounts_explain_the_leapfrog_energy_with_damping_excitation_and_impacts() {
    for (coupling, steps) in [(Coupling::EndOfStep, 1000.0), (Coupling::Explicit, 2000.0)] {
        let (residual, closed) = balance_residual(coupling, steps);
        println!("{coupling:?}: relative balance residual {residual:.3e}, {closed} closed steps");
        assert!(closed > 100, "{coupling:?}: the test needs impacts");
        assert!(
            residual < 1e-10,
            "{coupling:?}: energy balance residual {residual:e}"
        );
    }
}
