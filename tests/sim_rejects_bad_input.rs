//! Guards that the integrator refuses bad input with an error that names what is wrong
//! instead of panicking or running: a time step beyond the open stability limit, non-finite
//! excitation or parameters, excitation samples that do not cover the run, ROMs whose arrays
//! do not fit together or whose residual flexibility is not symmetric positive definite, and
//! states that belong to another ROM.

mod sim_support;

use faer::Mat;
use rigtwin::contact::ContactError;
use rigtwin::sim::{
    Excitation, Integrator, IntegratorParameters, NullSink, SimError, State, TimeStep,
};

fn rom() -> rigtwin::rom::Rom {
    sim_support::two_cantilevers(6, 1e-3, 0.4, 0.01)
}

#[test]
fn time_step_beyond_the_open_limit_is_refused_with_the_needed_steps_per_period() {
    let rom = rom();
    let limits = rigtwin::sim::stability_limits(&rom).unwrap();
    let steps = 0.9 * limits.steps_per_period_open();
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod { steps },
        ..IntegratorParameters::default()
    };
    let err = Integrator::new(&rom, params).unwrap_err();
    let msg = err.to_string();
    println!("{msg}");
    match err {
        SimError::TimeStepTooLarge {
            steps_needed,
            steps_given,
            limit,
            ..
        } => {
            assert!((steps_needed - limits.steps_per_period_open()).abs() < 1e-9);
            assert!((steps_given - steps).abs() < 1e-6 * steps);
            assert!(limit.contains("open"));
        }
        other => panic!("unexpected error {other:?}"),
    }
    assert!(msg.contains(&format!("{:.1}", limits.steps_per_period_open())));
    // Just inside the limit is accepted, for both couplings where the closed bound allows.
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerReferencePeriod {
            steps: 1.01 * limits.steps_per_period_open(),
        },
        ..IntegratorParameters::default()
    };
    assert!(Integrator::new(&rom, params).is_ok());
}

#[test]
fn invalid_parameters_are_refused() {
    let rom = rom();
    for params in [
        IntegratorParameters {
            time_step: TimeStep::Dt { dt: f64::NAN },
            ..IntegratorParameters::default()
        },
        IntegratorParameters {
            time_step: TimeStep::StepsPerPeriod {
                steps: 1000.0,
                omega: 0.0,
            },
            ..IntegratorParameters::default()
        },
        IntegratorParameters {
            open_margin_steps: -1.0,
            ..IntegratorParameters::default()
        },
    ] {
        assert!(matches!(
            Integrator::new(&rom, params),
            Err(SimError::InvalidParameter { .. })
        ));
    }
    let mut params = IntegratorParameters::default();
    params.contact.relaxation = 3.0;
    assert!(matches!(
        Integrator::new(&rom, params),
        Err(SimError::Contact(ContactError::InvalidParameter { .. }))
    ));
}

#[test]
fn non_finite_excitation_is_refused() {
    let rom = rom();
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    let mut state = integ.state_at_rest();
    let mut accel = vec![1.0; 100];
    accel[42] = f64::NAN;
    let err = integ
        .run(
            &mut state,
            &Excitation::Sampled {
                accel,
                dt_sample: 1e-4,
            },
            10,
            &mut NullSink,
        )
        .unwrap_err();
    assert!(
        matches!(err, SimError::ExcitationSample { index: 42, .. }),
        "{err}"
    );
    let err = integ
        .run(
            &mut state,
            &Excitation::Sine {
                amplitude_m: f64::INFINITY,
                omega: 300.0,
                phase: 0.0,
            },
            10,
            &mut NullSink,
        )
        .unwrap_err();
    assert!(matches!(err, SimError::InvalidParameter { .. }), "{err}");
    let err = integ.step(&mut state, f64::NAN, &mut NullSink).unwrap_err();
    assert!(matches!(err, SimError::BaseAcceleration { .. }), "{err}");
    // Nothing ran.
    assert_eq!(state.step(), 0);
}

#[test]
fn excitation_that_does_not_cover_the_run_is_refused() {
    let rom = rom();
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    let mut state = integ.state_at_rest();
    let dt = integ.dt();
    let excitation = Excitation::Sampled {
        accel: vec![0.0; 11],
        dt_sample: 10.0 * dt,
    };
    // 100 dt of samples: 101 steps (t = 0 ..= 100 dt) fit, 102 do not.
    assert!(integ
        .run(&mut state, &excitation, 101, &mut NullSink)
        .is_ok());
    let mut state = integ.state_at_rest();
    let err = integ
        .run(&mut state, &excitation, 102, &mut NullSink)
        .unwrap_err();
    assert!(matches!(err, SimError::ExcitationSpan { .. }), "{err}");
}

#[test]
fn mismatched_rom_dimensions_are_refused() {
    let base = rom();
    let m = base.omega.len();
    let cases: Vec<(&str, rigtwin::rom::Rom)> = vec![
        ("damping", {
            let mut r = base.clone();
            r.damping_ratio.pop();
            r
        }),
        ("beta", {
            let mut r = base.clone();
            r.beta.push(0.0);
            r
        }),
        ("phi_g rows", {
            let mut r = base.clone();
            r.phi_g = Mat::zeros(6, m);
            r
        }),
        ("phi_g columns", {
            let mut r = base.clone();
            r.phi_g = Mat::zeros(3, m + 1);
            r
        }),
        ("g_res", {
            let mut r = base.clone();
            r.g_res = Mat::zeros(2, 2);
            r
        }),
        ("output c_eta", {
            let mut r = base.clone();
            r.outputs[1].c_eta.pop();
            r
        }),
        ("output c_lambda", {
            let mut r = base.clone();
            r.outputs[0].c_lambda.push(0.0);
            r
        }),
    ];
    for (what, r) in cases {
        let err = Integrator::new(&r, IntegratorParameters::default()).unwrap_err();
        assert!(
            matches!(err, SimError::RomDimension { .. }),
            "{what}: unexpected {err}"
        );
        println!("{what}: {err}");
    }
}

#[test]
fn invalid_rom_values_are_refused() {
    let base = rom();
    let mut r = base.clone();
    r.omega[3] = -1.0;
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomValue {
            what: "omega",
            index: 3,
            ..
        })
    ));
    let mut r = base.clone();
    r.phi_g[(0, 2)] = f64::NAN;
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomValue { what: "phi_g", .. })
    ));
    let mut r = base.clone();
    r.meta.reference_mode = r.omega.len();
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomValue {
            what: "meta.reference_mode",
            ..
        })
    ));
    let mut r = base.clone();
    r.friction = -0.1;
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomValue {
            what: "friction",
            ..
        })
    ));
    let mut r = base.clone();
    r.g_res[(0, 1)] = 1e-3;
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomFlexibility { .. })
    ));
    let mut r = base.clone();
    r.g_res[(1, 1)] = -1.0;
    assert!(matches!(
        Integrator::new(&r, IntegratorParameters::default()),
        Err(SimError::RomFlexibility { .. })
    ));
}

#[test]
fn state_of_another_rom_is_refused() {
    let rom = rom();
    let mut integ = Integrator::new(&rom, IntegratorParameters::default()).unwrap();
    let excitation = Excitation::Sine {
        amplitude_m: 1e-5,
        omega: 300.0,
        phase: 0.0,
    };
    let mut wrong = State::at_rest(rom.omega.len() + 1, 1, 0.0);
    assert!(matches!(
        integ.run(&mut wrong, &excitation, 1, &mut NullSink),
        Err(SimError::StateDimension { what: "eta", .. })
    ));
    let mut wrong = State::at_rest(rom.omega.len(), 2, 0.0);
    assert!(matches!(
        integ.run(&mut wrong, &excitation, 1, &mut NullSink),
        Err(SimError::StateDimension { what: "lambda", .. })
    ));
    let mut eta = vec![0.0; rom.omega.len()];
    eta[0] = f64::INFINITY;
    let mut bad = State::from_modal(eta, vec![0.0; rom.omega.len()], 1, 0.0);
    assert!(matches!(
        integ.run(&mut bad, &excitation, 1, &mut NullSink),
        Err(SimError::StateValue { what: "eta", .. })
    ));
    // A state (e.g. read back from a damaged log) with a normal force on a pair it does not
    // list as closed: the open prediction would not see that contact.
    let at_rest = State::at_rest(rom.omega.len(), 1, 0.0);
    let mut json = serde_json::to_value(&at_rest).unwrap();
    json["lambda"]["index"] = serde_json::json!([0]);
    json["lambda"]["value"] = serde_json::json!([1.0]);
    let mut forced: State = serde_json::from_value(json).unwrap();
    let err = integ
        .run(&mut forced, &excitation, 1, &mut NullSink)
        .unwrap_err();
    assert!(
        matches!(err, SimError::StateValue { index: 0, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("not list as closed"), "{err}");
}
