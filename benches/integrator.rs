//! Integrator benchmark on the default ROM (modes to 180 x f(1FU), 192 pairs), one core:
//! steps per second with all contacts open and in sustained impacts (Omega = omega_2, high
//! level 6e-5 l, clearance 2.78e-3 l), for each contact sweep method. Prints one JSON line per
//! case and run, then the medians.
//!
//! ```text
//! cargo bench --bench integrator                      # 5 runs per case
//! cargo bench --bench integrator -- --repeat 9 --periods 100
//! ```
//! The ROM is taken from (or built into) the cache folder `$RIGTWIN_CACHE`, default
//! `target/rom-cache`.

use std::path::PathBuf;
use std::time::Instant;

use rigtwin::config::RigConfig;
use rigtwin::contact::SweepMethod;
use rigtwin::rom::build::BuildOptions;
use rigtwin::sim::{Excitation, Integrator, IntegratorParameters, NullSink, State, TimeStep};

struct Args {
    repeat: usize,
    periods: u64,
    settle: u64,
}

fn parse_args() -> Args {
    let mut a = Args {
        repeat: 5,
        periods: 50,
        settle: 100,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = |name: &str| -> u64 {
            it.next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{name} needs an integer"))
        };
        match arg.as_str() {
            "--repeat" => a.repeat = val("--repeat") as usize,
            "--periods" => a.periods = val("--periods"),
            "--settle" => a.settle = val("--settle"),
            "--bench" => {}
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Case {
    name: &'static str,
    omega_ratio: f64,
    level: f64,
    clearance: f64,
}

fn main() {
    let args = parse_args();
    let cfg = RigConfig::default_rig();
    let dir = std::env::var_os("RIGTWIN_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/rom-cache"));
    let (rom, _, _) = rigtwin::rom::cache::load_or_build(
        cfg.model(),
        &BuildOptions::default(),
        &dir,
        false,
        &mut |_| {},
    )
    .expect("default ROM");
    let l = rom.meta.beam_length;
    let w2 = rom.omega_ref();
    eprintln!(
        "default ROM: {} modes, {} pairs, f(1FU) = {:.2} Hz",
        rom.n_modes(),
        rom.n_pairs(),
        w2 / (2.0 * std::f64::consts::PI)
    );
    let cases = [
        Case {
            name: "open",
            omega_ratio: 0.90,
            level: 2e-5,
            clearance: 2.78e-3,
        },
        Case {
            name: "impacts",
            omega_ratio: 1.0,
            level: 6e-5,
            clearance: 2.78e-3,
        },
    ];
    let methods = [
        ("jacobi", SweepMethod::Jacobi),
        ("accelerated_jacobi", SweepMethod::AcceleratedJacobi),
        ("gauss_seidel", SweepMethod::GaussSeidel),
    ];
    let mut summary = Vec::new();
    for case in &cases {
        for (mname, method) in methods {
            if case.name == "open" && method != SweepMethod::GaussSeidel {
                continue; // no contact solve: the method does not matter
            }
            let omega = case.omega_ratio * w2;
            let mut params = IntegratorParameters {
                time_step: TimeStep::StepsPerPeriod {
                    steps: 1000.0,
                    omega,
                },
                ..Default::default()
            };
            params.contact.method = method;
            let mut integ = Integrator::new(&rom, params).expect("integrator");
            integ.set_clearance(case.clearance * l).expect("clearance");
            let exc = Excitation::Sine {
                amplitude_m: case.level * l,
                omega,
                phase: 0.0,
            };
            let mut settled: State = integ.state_at_rest();
            integ
                .run(&mut settled, &exc, args.settle * 1000, &mut NullSink)
                .expect("settle");
            let mut rates = Vec::new();
            for run in 0..args.repeat {
                let mut st = settled.clone();
                let n = args.periods * 1000;
                let t = Instant::now();
                let rep = integ.run(&mut st, &exc, n, &mut NullSink).expect("run");
                let secs = t.elapsed().as_secs_f64();
                let rate = n as f64 / secs;
                rates.push(rate);
                println!(
                    "{{\"case\":\"{}\",\"method\":\"{mname}\",\"run\":{run},\"steps\":{n},\"seconds\":{secs:.4},\"steps_per_second\":{rate:.0},\"closed_steps\":{},\"solves\":{},\"mean_iterations\":{:.2},\"failures\":{}}}",
                    case.name,
                    rep.counters.closed_steps,
                    rep.counters.solves,
                    rep.counters.iterations as f64 / rep.counters.solves.max(1) as f64,
                    rep.counters.max_iterations + rep.counters.diverged,
                );
            }
            summary.push((case.name, mname, median(&mut rates)));
        }
    }
    eprintln!(
        "median steps/s ({} runs of {} periods x 1000 steps):",
        args.repeat, args.periods
    );
    for (c, m, r) in summary {
        eprintln!("  {c:>8} {m:>20} {r:>12.0}");
    }
}
