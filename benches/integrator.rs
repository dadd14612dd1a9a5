//! Integrator benchmark on the default ROM (modes to 180 x f(1FU), 192 pairs), one core:
//! steps per second with all contacts open, in sustained impacts (Omega = omega_2, high level
//! 6e-5 l, clearance 2.78e-3 l) and in held contact (issue 16: the probes touching, clearance 0,
//! at three levels; clearance 1e-5 l at 0.5e-5 l; a pre-load, clearance -1e-5 l; a tilted contact face, 1e-3 rad about y at
//! clearance 0), each with the default contact solve (Gauss-Seidel with the automatic
//! semismooth Newton) and with Gauss-Seidel sweeps only (the solve before issue 16; impacts
//! also with the Jacobi sweeps). Prints one JSON line per case, solver and run, then the
//! medians.
//!
//! ```text
//! cargo bench --bench integrator                      # 5 runs per case
//! cargo bench --bench integrator -- --repeat 9 --periods 100
//! cargo bench --bench integrator -- --case touching   # only the cases starting with it
//! ```
//! NOTE: with clearance 0 the model is positively homogeneous (no length scale: the response
//! to k times the base level is k times the response), so the touching cases at different
//! levels make the same contact pattern and cost the same up to round-off; the clearance
//! 1e-5 l case (the issue's recorded session) and the pre-load vary the contact pattern.
//! The ROM is taken from (or built into) the cache folder `$RIGTWIN_CACHE`, default
//! `target/rom-cache`.

use std::path::PathBuf;
use std::time::Instant;

use rigtwin::config::RigConfig;
use rigtwin::contact::{NewtonUse, SweepMethod};
use rigtwin::physics::{tilt, TiltSpec};
use rigtwin::rom::build::BuildOptions;
use rigtwin::sim::{Excitation, Integrator, IntegratorParameters, NullSink, State, TimeStep};

struct Args {
    repeat: usize,
    periods: u64,
    settle: u64,
    /// Only the cases whose name starts with this.
    case: Option<String>,
}

fn parse_args() -> Args {
    let mut a = Args {
        repeat: 5,
        periods: 50,
        settle: 100,
        case: None,
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
            "--case" => a.case = it.next(),
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
    /// Tilt of the contact face about y, rad (0: none): per-pair gap offsets as the simulated
    /// rig's tilt variant sets them.
    tilt: f64,
    /// Fraction of `--periods` and `--settle` the case runs (held contact is slower).
    share: f64,
}

/// A solver configuration of the bench: sweep method and Newton use.
struct Solver {
    name: &'static str,
    method: SweepMethod,
    newton: NewtonUse,
}

const GS_AUTO: Solver = Solver {
    name: "gauss_seidel+newton (default)",
    method: SweepMethod::GaussSeidel,
    newton: NewtonUse::Auto,
};
const GS_ONLY: Solver = Solver {
    name: "gauss_seidel only (before issue 16)",
    method: SweepMethod::GaussSeidel,
    newton: NewtonUse::Never,
};

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
    let case = |name, omega_ratio, level, clearance, tilt, share| Case {
        name,
        omega_ratio,
        level,
        clearance,
        tilt,
        share,
    };
    let cases = [
        case("open", 0.90, 2e-5, 2.78e-3, 0.0, 1.0),
        case("impacts", 1.0, 6e-5, 2.78e-3, 0.0, 1.0),
        case("touching 0.5e-5", 1.0, 0.5e-5, 0.0, 0.0, 0.2),
        case("touching 2e-5", 1.0, 2e-5, 0.0, 0.0, 0.2),
        case("touching 6e-5", 1.0, 6e-5, 0.0, 0.0, 0.2),
        case("clearance 1e-5", 1.0, 0.5e-5, 1e-5, 0.0, 0.2),
        case("preload -1e-5", 1.0, 0.5e-5, -1e-5, 0.0, 0.05),
        case("tilted 1e-3 rad", 1.0, 2e-5, 0.0, 1e-3, 0.2),
    ];
    let accel = Solver {
        name: "accelerated_jacobi only",
        method: SweepMethod::AcceleratedJacobi,
        newton: NewtonUse::Never,
    };
    let jacobi = Solver {
        name: "jacobi only",
        method: SweepMethod::Jacobi,
        newton: NewtonUse::Never,
    };
    let mut summary = Vec::new();
    for case in cases
        .iter()
        .filter(|c| args.case.as_deref().is_none_or(|n| c.name.starts_with(n)))
    {
        let solvers: Vec<&Solver> = match case.name {
            "open" => vec![&GS_AUTO], // no contact solve: the method does not matter
            "impacts" => vec![&GS_AUTO, &GS_ONLY, &accel, &jacobi],
            _ => vec![&GS_AUTO, &GS_ONLY],
        };
        let omega = case.omega_ratio * w2;
        let exc = Excitation::Sine {
            amplitude_m: case.level * l,
            omega,
            phase: 0.0,
        };
        let offsets = (case.tilt != 0.0).then(|| {
            tilt::gap_offsets(
                &rom.pair_position,
                &rom.pair_area,
                &TiltSpec {
                    angle: case.tilt,
                    axis: [0.0, 1.0],
                },
            )
        });
        let periods = ((args.periods as f64 * case.share).ceil() as u64).max(1);
        let settle = (args.settle as f64 * case.share).ceil() as u64;
        let mut settled: Option<State> = None;
        for solver in solvers {
            let mut params = IntegratorParameters {
                time_step: TimeStep::StepsPerPeriod {
                    steps: 1000.0,
                    omega,
                },
                ..Default::default()
            };
            params.contact.method = solver.method;
            params.contact.newton = solver.newton;
            let mut integ = Integrator::new(&rom, params).expect("integrator");
            integ.set_clearance(case.clearance * l).expect("clearance");
            integ.set_gap_offsets(offsets.as_deref()).expect("tilt");
            // Settled once per case (with the first solver); every solver runs from that state.
            let start = settled.get_or_insert_with(|| {
                let mut st = integ.state_at_rest();
                integ
                    .run(&mut st, &exc, settle * 1000, &mut NullSink)
                    .expect("settle");
                st
            });
            let mut rates = Vec::new();
            for run in 0..args.repeat {
                let mut st = start.clone();
                let n = periods * 1000;
                let t = Instant::now();
                let rep = integ.run(&mut st, &exc, n, &mut NullSink).expect("run");
                let secs = t.elapsed().as_secs_f64();
                let rate = n as f64 / secs;
                rates.push(rate);
                let c = rep.counters;
                println!(
                    "{{\"case\":\"{}\",\"solver\":\"{}\",\"run\":{run},\"steps\":{n},\"seconds\":{secs:.4},\"steps_per_second\":{rate:.0},\"realtime_factor\":{:.3},\"closed_steps\":{},\"solves\":{},\"sweeps_per_solve\":{:.2},\"newton_solves\":{},\"newton_iterations_per_newton_solve\":{:.2},\"newton_fallbacks\":{},\"failures\":{}}}",
                    case.name,
                    solver.name,
                    rate / (1000.0 * omega / (2.0 * std::f64::consts::PI)),
                    c.closed_steps,
                    c.solves,
                    c.iterations as f64 / c.solves.max(1) as f64,
                    c.newton_solves,
                    c.newton_iterations as f64 / c.newton_solves.max(1) as f64,
                    c.newton_fallbacks,
                    c.max_iterations + c.diverged,
                );
            }
            let rate = median(&mut rates);
            summary.push((
                case.name,
                solver.name,
                rate,
                rate / (1000.0 * omega / (2.0 * std::f64::consts::PI)),
            ));
        }
    }
    eprintln!(
        "median steps/s ({} runs of {} periods x 1000 steps; held-contact cases run the \
         fraction of the periods given in the source); real-time factor = steps/s over the \
         1000 steps per excitation period:",
        args.repeat, args.periods
    );
    for (c, m, r, f) in summary {
        eprintln!("  {c:>16} {m:>36} {r:>12.0} steps/s {f:>8.2} x real time");
    }
}
