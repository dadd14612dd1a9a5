//! Guards the reason the end-of-step coupling exists: two Euler-Bernoulli cantilevers
//! (9 modes each, open limit ~640, closed limit ~1230 steps per 1FU period) pressed together
//! at the tips by a slowly ramped, then constant base acceleration and held closed and stuck
//! for 100 periods at 1000 steps per period. With the end-of-step coupling the contact stays
//! closed and stuck, the normal force settles at the static value and the energy (including
//! the potential of the constant base load) never grows. The explicit coupling on the same
//! case, beyond its closed bound, diverges; building it with the bound enforced is refused.

mod sim_support;

use rigtwin::contact::PairState;
use rigtwin::rom::Rom;
use rigtwin::sim::{
    Coupling, Excitation, Integrator, IntegratorParameters, SimError, StepOutput, TimeStep,
};

const A0: f64 = -50.0; // m/s^2; pushes the (thinner, softer) lower beam up onto the upper one
const RAMP_PERIODS: f64 = 20.0;
const HOLD_PERIODS: f64 = 100.0;

fn rom() -> Rom {
    sim_support::two_cantilevers(9, 0.0, 0.4, 0.0)
}

/// Smooth ramp (1 - cos) / 2 over the ramp, then constant, sampled at the step.
fn excitation(period: f64, dt: f64) -> Excitation {
    let t_ramp = RAMP_PERIODS * period;
    let n = ((RAMP_PERIODS + HOLD_PERIODS + 1.0) * period / dt).ceil() as usize;
    let accel = (0..n)
        .map(|i| {
            let t = i as f64 * dt;
            if t < t_ramp {
                A0 * 0.5 * (1.0 - (std::f64::consts::PI * t / t_ramp).cos())
            } else {
                A0
            }
        })
        .collect();
    Excitation::Sampled {
        accel,
        dt_sample: dt,
    }
}

/// Static normal force for the constant load: the free static gap closure divided by the
/// static gap flexibility `G_nn + sum_i Phi_n,i^2 / w_i^2`.
fn static_force(rom: &Rom) -> f64 {
    let m = rom.omega.len();
    let (mut gap, mut flex) = (rom.clearance, rom.g_res[(0, 0)]);
    for i in 0..m {
        let w2 = rom.omega[i] * rom.omega[i];
        gap += rom.phi_g[(0, i)] * (-rom.beta[i] * A0) / w2;
        flex += rom.phi_g[(0, i)] * rom.phi_g[(0, i)] / w2;
    }
    assert!(gap < 0.0, "the load must press the tips together");
    -gap / flex
}

struct Summary {
    /// Steps after the ramp with the contact open or not stuck.
    not_stuck_after_ramp: u64,
    mean_force_hold: f64,
    max_force_hold: f64,
    /// Energy including the potential of the base load at the end of the ramp, and its
    /// largest value afterwards, J.
    energy_at_hold: f64,
    max_energy_hold: f64,
    /// Largest total energy (modes and boundary) during the hold, J: the scale.
    energy_scale: f64,
    finite: bool,
}

fn run(coupling: Coupling) -> Summary {
    let rom = rom();
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps: 1000.0 },
        coupling,
        enforce_closed_bound: false,
        ..IntegratorParameters::default()
    };
    let mut integ = Integrator::new(&rom, params).unwrap();
    let dt = integ.dt();
    let period = 2.0 * std::f64::consts::PI / sim_support::omega_ref(&rom);
    let hold_start = (RAMP_PERIODS * 1000.0) as u64;
    let total = ((RAMP_PERIODS + HOLD_PERIODS) * 1000.0) as u64;
    let mut s = Summary {
        not_stuck_after_ramp: 0,
        mean_force_hold: 0.0,
        max_force_hold: 0.0,
        energy_at_hold: f64::NAN,
        max_energy_hold: f64::MIN,
        energy_scale: 0.0,
        finite: true,
    };
    let mut sum_force = 0.0;
    let mut sink = |o: &StepOutput<'_>| {
        if o.step < hold_start {
            return;
        }
        // During the hold the base load is constant, so the total energy minus the work
        // of the base load is conserved by the exact model.
        let e = o.energy.total() - o.energy.accounts.base_work;
        if o.step == hold_start {
            s.energy_at_hold = e;
        }
        s.max_energy_hold = s.max_energy_hold.max(e);
        s.energy_scale = s.energy_scale.max(o.energy.total().abs());
        if !(o.contact.any_closed && o.pair_states[0] == PairState::Stick) {
            s.not_stuck_after_ramp += 1;
        }
        sum_force += o.contact.normal_force;
        s.max_force_hold = s.max_force_hold.max(o.contact.normal_force);
    };
    let mut state = integ.state_at_rest();
    let report = integ
        .run(&mut state, &excitation(period, dt), total, &mut sink)
        .unwrap();
    s.finite = report.stop.is_none();
    s.mean_force_hold = sum_force / (total - hold_start) as f64;
    s
}

#[test]
fn end_of_step_coupling_holds_a_pressed_contact_closed_stuck_and_bounded() {
    let limits = rigtwin::sim::stability_limits(&rom()).unwrap();
    assert!(limits.steps_per_period_open() < 1000.0 && limits.steps_per_period_closed() > 1000.0);
    let s = run(Coupling::EndOfStep);
    let f_static = static_force(&rom());
    println!(
        "end of step: mean force {:.5e} N (static {f_static:.5e}), max {:.5e} N; energy \
         (total - base work) at hold {:.5e} J, max {:.5e} J, total energy scale {:.5e} J",
        s.mean_force_hold, s.max_force_hold, s.energy_at_hold, s.max_energy_hold, s.energy_scale
    );
    assert!(s.finite);
    assert_eq!(s.not_stuck_after_ramp, 0);
    assert!((s.mean_force_hold - f_static).abs() < 0.02 * f_static);
    assert!(s.max_force_hold < 1.2 * f_static);
    assert!(
        s.max_energy_hold <= s.energy_at_hold + 1e-9 * s.energy_scale,
        "energy grew from {:e} to {:e} J",
        s.energy_at_hold,
        s.max_energy_hold
    );
}

#[test]
fn explicit_coupling_diverges_on_the_same_case_beyond_its_closed_bound() {
    let s = run(Coupling::Explicit);
    println!(
        "explicit: finite {}, energy at hold {:.3e} J, max {:.3e} J",
        s.finite, s.energy_at_hold, s.max_energy_hold
    );
    let end_of_step = run(Coupling::EndOfStep);
    assert!(
        !s.finite
            || !s.max_energy_hold.is_finite()
            || s.max_energy_hold > 1e6 * end_of_step.energy_scale,
        "the explicit coupling stayed bounded ({:e} J)",
        s.max_energy_hold
    );
}

#[test]
fn explicit_coupling_beyond_its_closed_bound_is_refused() {
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps: 1000.0 },
        coupling: Coupling::Explicit,
        ..IntegratorParameters::default()
    };
    let err = Integrator::new(&rom(), params).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, SimError::TimeStepTooLarge { steps_needed, .. } if steps_needed > 1000.0)
    );
    assert!(msg.contains("closed") && msg.contains("EndOfStep"), "{msg}");
    println!("{msg}");
}
