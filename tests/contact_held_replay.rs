//! Measures the contact solve on held contact (ignored by default; a measurement, not a check
//! of speed): the solves of the touching probes (default ROM, clearance 0, Omega = omega_2)
//! are captured from the integrator (the solver's input of every step with a solve, and the
//! warm start), then replayed through clones of the integrator's warmed solver with each
//! variant of the contact parameters, alternately, thread CPU time per variant (best and
//! median of the rounds), Newton iterations, factorisations, failures and the largest
//! relative difference of the forces to the captured ones. It does check that every variant
//! with Newton converges every solve (no failure) to within 1e-6 of the captured forces (the
//! sweeps alone may run out of sweeps on held contact).
//!
//! ```text
//! cargo test --release --test contact_held_replay -- --ignored --nocapture
//! HELD_LEVEL=6e-5 HELD_CLEARANCE=1e-5 HELD_PERIODS=10 ...   # other cases
//! HELD_VARIANTS="newton_min_pairs=96,newton_after_sweeps_large=0;newton_after_sweeps_large=8" ...
//! ```
//! `HELD_VARIANTS`: `;`-separated variants, each `,`-separated `key=value` TOML fields of
//! `ContactParameters` over the integrator's defaults (replacing the built-in variants).

mod contact_support;
mod default_rom;

use contact_support::thread_cpu_seconds;
use rigtwin::contact::{ContactParameters, ContactSolver, NewtonUse, SolveStatus};
use rigtwin::sim::{Excitation, Integrator, IntegratorParameters, NullSink, TimeStep};

/// CPU time of the calling thread, s (Linux; this measurement runs there).
fn cpu_seconds() -> f64 {
    thread_cpu_seconds().expect("thread CPU time (Linux)")
}

fn env_f64(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// One captured solve: free gap velocity (zero outside the active pairs), the solver mask
/// (`-1` active, `1` left out), the warm start and the forces the integrator got.
struct Captured {
    c: Vec<f64>,
    mask: Vec<f64>,
    warm: Vec<f64>,
    lambda: Vec<f64>,
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let s: f64 = b.iter().map(|x| x * x).sum::<f64>().max(1e-300);
    (d / s).sqrt()
}

#[test]
#[ignore = "measurement: run with --ignored --nocapture"]
fn contact_held_replay() {
    let rom = default_rom::default_rom();
    let l = rom.meta.beam_length;
    let omega = rom.omega_ref() * env_f64("HELD_OMEGA", 1.0);
    let level = env_f64("HELD_LEVEL", 0.5e-5);
    let clearance = env_f64("HELD_CLEARANCE", 0.0);
    let settle = env_f64("HELD_SETTLE", 40.0) as u64;
    let periods = env_f64("HELD_PERIODS", 10.0) as u64;
    let rounds = env_f64("HELD_ROUNDS", 5.0) as usize;
    let exc = Excitation::Sine {
        amplitude_m: level * l,
        omega,
        phase: 0.0,
    };
    let params = IntegratorParameters {
        time_step: TimeStep::StepsPerPeriod {
            steps: 1000.0,
            omega,
        },
        ..Default::default()
    };
    let mut integ = Integrator::new(rom, params).expect("integrator");
    integ.set_clearance(clearance * l).expect("clearance");
    let mut st = integ.state_at_rest();
    integ
        .run(&mut st, &exc, settle * 1000, &mut NullSink)
        .expect("settle");
    let base: ContactSolver = integ.contact_solver().clone();
    let n = base.n_pairs();
    let mut captured = Vec::new();
    let t0 = cpu_seconds();
    for _ in 0..periods * 1000 {
        let warm = st.lambda().to_vec();
        let before = st.counters().solves;
        integ.run(&mut st, &exc, 1, &mut NullSink).expect("step");
        if st.counters().solves == before {
            continue;
        }
        let solver = integ.contact_solver();
        let (problem, solution) = solver.last_active_problem("capture");
        let mut c = vec![0.0; 3 * n];
        let mut mask = vec![1.0; n];
        let mut lambda = vec![0.0; 3 * n];
        for (slot, &p) in solver.active_pairs().iter().enumerate() {
            c[3 * p..3 * p + 3].copy_from_slice(&problem.c[3 * slot..3 * slot + 3]);
            lambda[3 * p..3 * p + 3].copy_from_slice(&solution.lambda[3 * slot..3 * slot + 3]);
            mask[p] = -1.0;
        }
        captured.push(Captured {
            c,
            mask,
            warm,
            lambda,
        });
    }
    let sim_cpu = cpu_seconds() - t0;
    let sizes: Vec<usize> = captured
        .iter()
        .map(|c| c.mask.iter().filter(|&&m| m < 0.0).count())
        .collect();
    let large = sizes.iter().filter(|&&s| s >= 96).count();
    let mut histogram = [0usize; 5];
    for &s in &sizes {
        histogram[[24, 48, 96, 144, usize::MAX]
            .iter()
            .position(|&b| s < b)
            .unwrap()] += 1;
    }
    eprintln!("active pairs per solve: <24 / <48 / <96 / <144 / >=144: {histogram:?}");
    eprintln!(
        "captured {} solves in {periods} periods ({large} with >= 96 pairs; sim CPU {sim_cpu:.3} s, \
         level {level:e} l, clearance {clearance:e} l)",
        captured.len()
    );

    let dp = base.parameters().clone();
    let mut variants: Vec<(String, ContactParameters)> = vec![("default".into(), dp.clone())];
    if let Ok(spec) = std::env::var("HELD_VARIANTS") {
        for v in spec.split(';').filter(|s| !s.is_empty()) {
            let table: toml::Table = toml::from_str(&v.replace(',', "\n")).expect("variant TOML");
            let mut merged = toml::Table::try_from(&dp).expect("params to TOML");
            merged.extend(table);
            let p: ContactParameters = merged.try_into().expect("variant parameters");
            variants.push((v.to_string(), p));
        }
    } else {
        // The second pass's choice (Newton from the warm start from 96 pairs on), Newton for
        // every solve, and the sweeps only.
        variants.push((
            "second pass (96 pairs, no sweeps first)".into(),
            ContactParameters {
                newton_min_pairs: 96,
                newton_after_sweeps_large: 0,
                ..dp.clone()
            },
        ));
        for newton in [NewtonUse::Always, NewtonUse::Never] {
            variants.push((
                format!("{newton:?}"),
                ContactParameters {
                    newton,
                    ..dp.clone()
                },
            ));
        }
    }
    let mut times = vec![Vec::new(); variants.len()];
    let mut report = vec![(0usize, 0usize, 0usize, 0usize, 0.0f64); variants.len()];
    // CPU time of the last round per variant: solves with and without Newton iterations, and
    // their counts.
    let mut split = vec![[0.0f64; 4]; variants.len()];
    let (mut lambda, mut gamma) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
    for _ in 0..rounds {
        for (v, (_, p)) in variants.iter().enumerate() {
            let mut solver = base.clone();
            solver.set_parameters(p.clone()).expect("parameters");
            let (mut newton, mut lus, mut sweeps, mut failures, mut worst) = (0, 0, 0, 0, 0.0f64);
            let t = cpu_seconds();
            split[v] = [0.0; 4];
            for cap in &captured {
                lambda.copy_from_slice(&cap.warm);
                let ts = cpu_seconds();
                let s = solver
                    .solve(&cap.c, Some(&cap.mask), &mut lambda, &mut gamma)
                    .expect("solve");
                let k = if s.newton_iterations > 0 { 0 } else { 2 };
                split[v][k] += cpu_seconds() - ts;
                split[v][k + 1] += 1.0;
                newton += s.newton_iterations;
                lus += s.factorisations;
                sweeps += s.iterations;
                if s.status != SolveStatus::Converged {
                    failures += 1;
                }
                worst = worst.max(rel_diff(&lambda, &cap.lambda));
            }
            times[v].push(cpu_seconds() - t);
            report[v] = (newton, lus, sweeps, failures, worst);
        }
    }
    eprintln!(
        "variant: best / median CPU s over {rounds} rounds; Newton iterations / LUs / sweeps, \
         failures, worst relative difference to the captured forces; last round's split"
    );
    for (v, (name, _)) in variants.iter().enumerate() {
        let t = &mut times[v];
        t.sort_by(f64::total_cmp);
        let (newton, lus, sweeps, failures, worst) = report[v];
        eprintln!(
            "  {name:>40}: {:.4} / {:.4} s; {newton} / {lus} / {sweeps}, {failures}, {worst:.1e}; \
             newton solves {:.0}: {:.4} s, sweep solves {:.0}: {:.4} s",
            t[0],
            t[t.len() / 2],
            split[v][1],
            split[v][0],
            split[v][3],
            split[v][2]
        );
    }
    // The sweeps alone may run out of sweeps on held contact (why Newton is there).
    for (v, (name, p)) in variants.iter().enumerate() {
        if p.newton != NewtonUse::Never {
            assert_eq!(report[v].3, 0, "{name}: solver failures");
            assert!(
                report[v].4 < 1e-6,
                "{name}: forces differ by {:e}",
                report[v].4
            );
        }
    }
}
