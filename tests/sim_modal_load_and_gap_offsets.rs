//! Guards the integrator's two hooks for physics outside the ROM (used by the simulated rig's
//! truth variants):
//! - an extra modal load (`Integrator::step_loaded`): an empty or all-zero load gives the bits
//!   of `Integrator::step`; a constant force on one mode settles at the static displacement
//!   `f / omega^2` and leaves the other modes alone; a load on a mode the ROM does not have is
//!   an error;
//! - per-pair gap offsets (`Integrator::set_gap_offsets`): zero offsets give the bits of none,
//!   a uniform offset the bits of the clearance moved by it, the bound-based open prediction
//!   the exact prediction's trajectory with offsets too, the gaps at rest are the clearance
//!   plus the offsets, and offsets of the wrong length or non-finite are rejected.

mod sim_support;

use rigtwin::rom::Rom;
use rigtwin::sim::{Excitation, Integrator, IntegratorParameters, SimError, StepOutput};

/// Velocities, forces and energies of every step, as bits.
fn push_bits(words: &mut Vec<u64>, o: &StepOutput<'_>) {
    words.extend(o.velocity.iter().map(|x| x.to_bits()));
    words.extend(o.displacement.iter().map(|x| x.to_bits()));
    words.extend(o.lambda.iter().map(|x| x.to_bits()));
    words.push(o.energy.kinetic.to_bits());
    words.push(o.energy.accounts.contact_work.to_bits());
    words.push(o.contact.candidates as u64);
}

fn patch() -> Rom {
    sim_support::synthetic_patch(40, 6, 8, 4e-6, 3)
}

fn excitation(rom: &Rom) -> Excitation {
    Excitation::Sine {
        amplitude_m: 2e-5,
        omega: sim_support::omega_ref(rom),
        phase: 0.3,
    }
}

/// `steps` steps of the patch under the sine, after `setup`; (bits, closed steps).
fn patch_run(
    params: IntegratorParameters,
    steps: u64,
    setup: impl FnOnce(&mut Integrator),
) -> (Vec<u64>, u64) {
    let rom = patch();
    let mut integ = Integrator::new(&rom, params).unwrap();
    setup(&mut integ);
    let mut state = integ.state_at_rest();
    let mut words = Vec::new();
    let mut closed = 0;
    let mut sink = |o: &StepOutput<'_>| {
        push_bits(&mut words, o);
        closed += u64::from(o.contact.any_closed);
    };
    integ
        .run(&mut state, &excitation(&rom), steps, &mut sink)
        .unwrap();
    (words, closed)
}

#[test]
fn an_empty_or_zero_load_is_the_plain_step() {
    let rom = patch();
    let a_base = |j: u64| 40.0 * (0.02 * j as f64).sin();
    let once = |load: &[(usize, f64)]| {
        let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
        let mut state = integ.state_at_rest();
        let mut words = Vec::new();
        let mut sink = |o: &StepOutput<'_>| push_bits(&mut words, o);
        for j in 0..5000 {
            if load.is_empty() {
                integ.step(&mut state, a_base(j), &mut sink).unwrap();
            } else {
                integ
                    .step_loaded(&mut state, a_base(j), load, &mut sink)
                    .unwrap();
            }
        }
        (words, state.counters().closed_steps)
    };
    let (plain, closed) = once(&[]);
    assert!(
        closed > 100,
        "the check needs contact: {closed} closed steps"
    );
    assert!(once(&[(0, 0.0), (3, 0.0)]).0 == plain);
}

#[test]
fn a_constant_load_settles_at_the_static_displacement() {
    // Two cantilevers far apart, damped: a force on mode 1 only.
    let rom = sim_support::two_cantilevers(6, 1.0, 0.4, 0.05);
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    let mut state = integ.state_at_rest();
    let f = 3.0;
    let period = 2.0 * std::f64::consts::PI / rom.omega[0];
    let steps = (40.0 * period / integ.dt()) as u64;
    for _ in 0..steps {
        integ
            .step_loaded(&mut state, 0.0, &[(1, f)], &mut rigtwin::sim::NullSink)
            .unwrap();
    }
    let eta = state.eta();
    let expected = f / (rom.omega[1] * rom.omega[1]);
    println!("eta_1 = {:.6e}, f / omega_1^2 = {expected:.6e}", eta[1]);
    assert!(
        (eta[1] / expected - 1.0).abs() < 1e-6,
        "{} vs {expected}",
        eta[1]
    );
    for (i, e) in eta.iter().enumerate().filter(|(i, _)| *i != 1) {
        assert_eq!(*e, 0.0, "mode {i} moved");
    }

    let m = integ.n_modes();
    let err = integ
        .step_loaded(&mut state, 0.0, &[(m, 1.0)], &mut rigtwin::sim::NullSink)
        .unwrap_err();
    assert!(
        matches!(err, SimError::StateDimension { found, expected, .. } if found == m && expected == m),
        "{err}"
    );
    assert!(err.to_string().contains("modal load index"), "{err}");
}

#[test]
fn gap_offsets_shift_each_pairs_gap_and_nothing_else() {
    let rom = patch();
    let n = rom.n_pairs();
    const STEPS: u64 = 20_000;
    let (plain, closed) = patch_run(IntegratorParameters::default(), STEPS, |_| {});
    assert!(
        closed > 100,
        "the check needs contact: {closed} closed steps"
    );
    let zero = vec![0.0; n];
    let (with_zero, _) = patch_run(IntegratorParameters::default(), STEPS, |i| {
        i.set_gap_offsets(Some(&zero)).unwrap()
    });
    assert!(with_zero == plain, "zero offsets changed the run");

    // A uniform offset is a moved clearance, bit for bit.
    let delta = -1e-6;
    let (uniform, _) = patch_run(IntegratorParameters::default(), STEPS, |i| {
        i.set_gap_offsets(Some(&vec![delta; n])).unwrap()
    });
    let (moved, _) = patch_run(IntegratorParameters::default(), STEPS, |i| {
        let c = i.clearance();
        i.set_clearance(c + delta).unwrap()
    });
    assert!(
        uniform == moved,
        "a uniform offset differs from the moved clearance"
    );
    assert!(uniform != plain);

    // Uneven offsets: the bounded prediction still gives the exact prediction's trajectory.
    let offsets: Vec<f64> = (0..n).map(|k| 3e-6 * ((k as f64) * 0.7).sin()).collect();
    let exact = IntegratorParameters {
        report_gaps: true,
        ..IntegratorParameters::default()
    };
    let (bounded, closed_off) = patch_run(IntegratorParameters::default(), STEPS, |i| {
        i.set_gap_offsets(Some(&offsets)).unwrap()
    });
    let (exact, _) = patch_run(exact, STEPS, |i| i.set_gap_offsets(Some(&offsets)).unwrap());
    assert!(closed_off > 100);
    assert!(
        bounded == exact,
        "bounded and exact prediction differ with offsets"
    );

    // At rest the gaps are the clearance plus the offsets.
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    integ.set_gap_offsets(Some(&offsets)).unwrap();
    assert_eq!(integ.gap_offsets(), Some(&offsets[..]));
    let mut gaps = vec![0.0; 3 * n];
    integ.gaps(&integ.state_at_rest(), &mut gaps).unwrap();
    for k in 0..n {
        assert_eq!(gaps[3 * k], rom.clearance + offsets[k]);
        assert_eq!((gaps[3 * k + 1], gaps[3 * k + 2]), (0.0, 0.0));
    }

    // Bad offsets.
    let err = integ.set_gap_offsets(Some(&offsets[1..])).unwrap_err();
    assert!(err.to_string().contains("gap offsets"), "{err}");
    let mut nan = offsets.clone();
    nan[2] = f64::NAN;
    let err = integ.set_gap_offsets(Some(&nan)).unwrap_err();
    assert!(err.to_string().contains("gap offset (m) = NaN"), "{err}");
    integ.set_gap_offsets(None).unwrap();
    assert_eq!(integ.gap_offsets(), None);
}
