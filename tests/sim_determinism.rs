//! Guards bit-for-bit determinism of the integrator (rapier-style determinism test): the same
//! ROM, parameters, state and excitation give identical outputs, bit for bit, run after run;
//! the portable and the AVX2 build of the step agree bit for bit; the bound-based open
//! prediction gives the same trajectory as computing every gap exactly; and a state carried
//! across a change of time step (stepped sine) continues deterministically. The case is a
//! synthetic multi-pair contact patch with impacts, friction and solver warm starts.

mod sim_support;

use rigtwin::rom::Rom;
use rigtwin::sim::{Excitation, Integrator, IntegratorParameters, StepOutput, TimeStep};

fn rom() -> Rom {
    sim_support::synthetic_patch(40, 6, 8, 4e-6, 3)
}

fn excitation(rom: &Rom) -> Excitation {
    Excitation::Sine {
        amplitude_m: 2e-5,
        omega: sim_support::omega_ref(rom),
        phase: 0.3,
    }
}

/// Every number of every step output, as bits.
#[derive(Default)]
struct Bits {
    words: Vec<u64>,
    closed_steps: u64,
}

impl Bits {
    fn push(&mut self, o: &StepOutput<'_>) {
        let w = &mut self.words;
        w.push(o.step);
        w.push(o.time.to_bits());
        w.extend(o.displacement.iter().map(|x| x.to_bits()));
        w.extend(o.velocity.iter().map(|x| x.to_bits()));
        w.extend(o.lambda.iter().map(|x| x.to_bits()));
        w.extend(o.pair_states.iter().map(|s| *s as u64));
        let e = o.energy;
        for x in [
            e.kinetic,
            e.potential,
            e.potential_mid,
            e.boundary,
            e.accounts.base_work,
            e.accounts.damping_dissipated,
            e.accounts.contact_work,
            o.contact.normal_force,
            o.contact.tangential_force,
        ] {
            w.push(x.to_bits());
        }
        w.push(o.contact.candidates as u64);
        w.push(o.solve.map_or(0, |s| s.iterations as u64));
        self.closed_steps += o.contact.any_closed as u64;
    }
}

fn run(params: IntegratorParameters, portable: bool, steps: u64) -> Bits {
    let rom = rom();
    let mut integ = Integrator::new(&rom, params).unwrap();
    if portable {
        integ.force_portable_kernels();
    }
    let mut state = integ.state_at_rest();
    let mut bits = Bits::default();
    let mut sink = |o: &StepOutput<'_>| bits.push(o);
    integ
        .run(&mut state, &excitation(&rom), steps, &mut sink)
        .unwrap();
    bits
}

const STEPS: u64 = 30_000;

#[test]
fn same_inputs_give_bit_identical_outputs() {
    let a = run(IntegratorParameters::default(), false, STEPS);
    let b = run(IntegratorParameters::default(), false, STEPS);
    assert!(
        a.closed_steps > 100,
        "the test needs contact ({} closed steps)",
        a.closed_steps
    );
    assert_eq!(a.words.len(), b.words.len());
    assert!(a.words == b.words, "two runs differ");
    println!(
        "{} words compared, {} closed steps",
        a.words.len(),
        a.closed_steps
    );
}

#[test]
fn portable_and_simd_builds_agree_bit_for_bit() {
    let a = run(IntegratorParameters::default(), false, STEPS);
    let b = run(IntegratorParameters::default(), true, STEPS);
    assert!(a.closed_steps > 100);
    assert!(a.words == b.words, "portable and SIMD builds differ");
}

#[test]
fn bounded_open_prediction_gives_the_exact_prediction_trajectory() {
    let exact = IntegratorParameters {
        report_gaps: true,
        ..IntegratorParameters::default()
    };
    let a = run(IntegratorParameters::default(), false, STEPS);
    let b = run(exact, false, STEPS);
    assert!(a.closed_steps > 100);
    assert!(
        a.words == b.words,
        "bound-based and exact prediction differ"
    );
}

#[test]
fn stepped_sine_with_a_carried_state_is_deterministic() {
    let once = || {
        let rom = rom();
        let w = sim_support::omega_ref(&rom);
        let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
        let mut state = integ.state_at_rest();
        let mut bits = Bits::default();
        let mut phase = 0.0;
        let mut omega_old = w;
        for k in 0..4 {
            let omega = w * (0.98 + 0.01 * k as f64);
            integ
                .set_time_step(TimeStep::StepsPerPeriod {
                    steps: 1000.0,
                    omega,
                })
                .unwrap();
            phase = rigtwin::sim::continuous_phase(omega_old, phase, omega, state.time());
            omega_old = omega;
            let excitation = Excitation::Sine {
                amplitude_m: 2e-5,
                omega,
                phase,
            };
            let mut sink = |o: &StepOutput<'_>| bits.push(o);
            integ
                .run(&mut state, &excitation, 8_000, &mut sink)
                .unwrap();
        }
        (bits, state)
    };
    let (a, sa) = once();
    let (b, sb) = once();
    assert!(a.closed_steps > 100);
    assert!(a.words == b.words);
    assert_eq!(sa, sb);
    assert_eq!(sa.step(), 32_000);
}
