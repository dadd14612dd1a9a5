//! Twin benchmark on the default rig's twin (modes to 180 x f(1FU); 192 pairs, 88 in held
//! contact), one core: the twin's real-time factor (seconds of data per wall second) and steps
//! per second, fed with DAQ blocks of the default simulated DAQ layout (10240 Hz, 256-sample
//! blocks, three 24-bit platform accelerometers) carrying a synthesised sine base
//! acceleration, at the twin's default step (5 steps per sample, about 1000 per 1FU period):
//! - `open`: Omega = 0.90 omega_2, base level 2e-5 l, clearance 2.78e-3 l (no contact);
//! - `impacts`: Omega = omega_2, high level 6e-5 l, clearance 2.78e-3 l (sustained impacts);
//! - `touching L`: Omega = omega_2, clearance 0 (the probes touch at rest: most pairs closed
//!   at once in the contact phases) at the levels L = 0.5e-5, 2e-5 and 6e-5 l (held contact,
//!   issue 16; a fifth of the data of the others);
//! - `small clearance`: Omega = omega_2, 0.5e-5 l, clearance 1e-5 l (the issue's recorded
//!   session: contact a few per cent of the time);
//! - `preload -1e-5`: Omega = omega_2, 0.5e-5 l, clearance -1e-5 l (the faces overlap: every
//!   pair a candidate in every step; a twentieth of the data).
//!
//! - `impacts + EXT`: the `impacts` case with one `[model]` extension on (issue 14): `modes`
//!   (1FU and 1FL frequency and damping corrected), `clamp friction` (Iwan, 64 sliders, both
//!   beams), `wear`, `tilt` (2e-3 rad), `sensor gains` (a platform accelerometer and a tip),
//!   and `all` of them at once: the cost of each extension against `impacts`.
//!
//! Each case's twin runs on the ROM a session of that case gives it: the held-contact cases
//! (touching, small clearance, pre-load) on the coarser patch of `[twin.held_contact]` (8 x 11,
//! 88 pairs; `RigConfig::held_contact_twin`), the others on the default patch.
//!
//! `--case TEXT` runs only the cases whose name contains TEXT. `--contact-nodes AxB` gives
//! every case's twin that contact patch instead (`[reduction] contact_nodes`, e.g. `12x16` for
//! the default patch in held contact).
//!
//! Each case settles for `--settle` periods, then runs `--seconds` of data `--repeat` times
//! from the settled twin (sync core, `Twin::push_block`, one JSON line per run), then once
//! through the threaded `TwinTask` (all blocks queued at once). Prints the medians.
//!
//! ```text
//! cargo bench --bench twin                            # 5 runs of 10 s of data per case
//! cargo bench --bench twin -- --repeat 9 --seconds 20
//! ```
//! The ROM is taken from (or built into) the cache folder `$RIGTWIN_CACHE`, default
//! `target/rom-cache`.

use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

use rigtwin::config::{PhysicsSpec, RigConfig};
use rigtwin::rig::daq::{ChannelKind, DaqBlock, DaqLayout};
use rigtwin::rig::sim::DaqSpec;
use rigtwin::rom::build::BuildOptions;
use rigtwin::twin::{Twin, TwinEvent, TwinModel, TwinSpec, TwinTask};

struct Args {
    repeat: usize,
    seconds: f64,
    settle: f64,
    case: Option<String>,
    contact_nodes: Option<[usize; 2]>,
}

fn parse_args() -> Args {
    let mut a = Args {
        repeat: 5,
        seconds: 10.0,
        settle: 200.0,
        case: None,
        contact_nodes: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = |name: &str| -> f64 {
            it.next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{name} needs a number"))
        };
        match arg.as_str() {
            "--repeat" => a.repeat = val("--repeat") as usize,
            "--seconds" => a.seconds = val("--seconds"),
            "--settle" => a.settle = val("--settle"),
            "--case" => a.case = it.next(),
            "--contact-nodes" => {
                let v = it.next().expect("--contact-nodes needs AxB, e.g. 8x11");
                let (y, x) = v
                    .split_once('x')
                    .expect("--contact-nodes as AxB, e.g. 8x11");
                a.contact_nodes = Some([
                    y.parse().expect("--contact-nodes: a count"),
                    x.parse().expect("--contact-nodes: a count"),
                ]);
            }
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

/// Blocks `first_seq..first_seq + n` of a base acceleration `-amplitude omega^2 sin(omega t)`
/// quantised to the platform channels' counts (the other channels read 0).
fn blocks(layout: &DaqLayout, first_seq: u64, n: u64, amplitude: f64, omega: f64) -> Vec<DaqBlock> {
    let len = layout.block_size;
    let nc = layout.channels.len();
    let platform = layout.indices_of(ChannelKind::PlatformAcceleration);
    (first_seq..first_seq + n)
        .map(|seq| {
            let first = seq * len as u64;
            let mut counts = vec![0; nc * len];
            for i in 0..len {
                let t = (first + i as u64) as f64 / layout.sample_rate;
                let a = -amplitude * omega * omega * (omega * t).sin();
                for &k in &platform {
                    counts[k * len + i] = (a / layout.channels[k].scale).round() as i32;
                }
            }
            DaqBlock {
                seq,
                first_sample: first,
                time: first as f64 / layout.sample_rate,
                len,
                counts,
            }
        })
        .collect()
}

struct Case {
    name: &'static str,
    omega_ratio: f64,
    level: f64,
    clearance: f64,
    /// Fraction of `--seconds` and `--settle` the case runs (the slow case runs less).
    share: f64,
    /// The `[model]` extensions on.
    model: PhysicsSpec,
}

fn main() {
    let args = parse_args();
    let mut cfg = RigConfig::default_rig();
    cfg.reduction.contact_nodes = args.contact_nodes;
    cfg.validate().expect("--contact-nodes: a valid patch");
    let dir = std::env::var_os("RIGTWIN_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/rom-cache"));
    let build = |cfg: &RigConfig| {
        let (rom, _, _) = rigtwin::rom::cache::load_or_build(
            cfg.model(),
            &BuildOptions::default(),
            &dir,
            false,
            &mut |_| {},
        )
        .expect("ROM");
        rom
    };
    let rom = build(&cfg);
    let held = |clearance: f64| cfg.held_contact_twin(&[clearance]);
    let held_rom = held(0.0).map(|c| build(&c));
    let l = rom.meta.beam_length;
    let w2 = rom.omega_ref();
    let layout = rigtwin::rig::channels::layout(&DaqSpec::default());
    let fs = layout.sample_rate;
    let block_s = layout.block_size as f64 / fs;
    let spec = TwinSpec::default();
    eprintln!(
        "ROM: {} modes, {} pairs, f(1FU) = {:.2} Hz; DAQ {fs} Hz, {} samples per block",
        rom.n_modes(),
        rom.n_pairs(),
        w2 / (2.0 * PI),
        layout.block_size
    );
    let extensions = |toml: &str| -> PhysicsSpec {
        let t: toml::Table = toml::from_str(toml).expect("extension TOML");
        let spec: PhysicsSpec = t["model"].clone().try_into().expect("extension spec");
        spec.validate("model", &DaqSpec::default())
            .expect("valid extension");
        spec
    };
    let modes = r#"modes = [{ mode = "1FU", frequency_hz = 50.5, damping_ratio = 0.003 },
         { mode = "1FL", damping_ratio = 0.002 }]"#;
    let gains = r#"sensor_gains = [{ channel = "platform_1", gain = 1.02 }, { channel = "lower_tip", gain = 0.97 }]"#;
    let clamp = r#"[model.clamp_friction]
stiffness_fraction = 0.1
half_slip_tip_amplitude = 1.0e-4"#;
    let wear = r#"[model.wear]
coefficient = 1.0e-6
max_growth = 5.0e-5"#;
    let tilt = r#"[model.tilt]
angle = 2.0e-3
axis = [0.6, 0.8]"#;
    let all = format!("[model]\n{modes}\n{gains}\n{clamp}\n{wear}\n{tilt}");
    let impacts_with = |name: &'static str, ext: &str| Case {
        name,
        omega_ratio: 1.0,
        level: 6e-5,
        clearance: 2.78e-3,
        share: 1.0,
        model: extensions(ext),
    };
    let cases = [
        Case {
            name: "open",
            omega_ratio: 0.90,
            level: 2e-5,
            clearance: 2.78e-3,
            share: 1.0,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "impacts",
            omega_ratio: 1.0,
            level: 6e-5,
            clearance: 2.78e-3,
            share: 1.0,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "touching 0.5e-5",
            omega_ratio: 1.0,
            level: 0.5e-5,
            clearance: 0.0,
            share: 0.2,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "touching 2e-5",
            omega_ratio: 1.0,
            level: 2e-5,
            clearance: 0.0,
            share: 0.2,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "touching 6e-5",
            omega_ratio: 1.0,
            level: 6e-5,
            clearance: 0.0,
            share: 0.2,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "small clearance",
            omega_ratio: 1.0,
            level: 0.5e-5,
            clearance: 1e-5,
            share: 0.2,
            model: PhysicsSpec::default(),
        },
        Case {
            name: "preload -1e-5",
            omega_ratio: 1.0,
            level: 0.5e-5,
            clearance: -1e-5,
            share: 0.05,
            model: PhysicsSpec::default(),
        },
        impacts_with("impacts + modes", &format!("[model]\n{modes}")),
        impacts_with("impacts + clamp friction", &format!("[model]\n{clamp}")),
        impacts_with("impacts + wear", &format!("[model]\n{wear}")),
        impacts_with("impacts + tilt", &format!("[model]\n{tilt}")),
        impacts_with("impacts + sensor gains", &format!("[model]\n{gains}")),
        impacts_with("impacts + all", &all),
    ];
    let mut summary = Vec::new();
    for case in &cases {
        if args
            .case
            .as_ref()
            .is_some_and(|c| !case.name.contains(c.as_str()))
        {
            continue;
        }
        let omega = case.omega_ratio * w2;
        let clearance = case.clearance * l;
        let case_rom = match (held(case.clearance), &held_rom) {
            (Some(_), Some(coarse)) => coarse,
            _ => &rom,
        };
        let mut twin = Twin::new(
            &TwinModel::nominal(case_rom).with_extensions(case.model.clone()),
            &spec,
            &layout,
            clearance,
        )
        .expect("twin");
        let settle_blocks = (case.share * args.settle * 2.0 * PI / omega / block_s).ceil() as u64;
        let run_blocks = (case.share * args.seconds / block_s).ceil() as u64;
        for b in blocks(&layout, 0, settle_blocks, case.level * l, omega) {
            twin.push_block(&b).expect("settle");
        }
        let input = blocks(&layout, settle_blocks, run_blocks, case.level * l, omega);
        let data_s = run_blocks as f64 * block_s;
        let mut factors = Vec::new();
        let mut rates = Vec::new();
        for run in 0..args.repeat {
            let mut t = twin.clone();
            let before = t.counters();
            let solver_before = t.solver_counters();
            let start = Instant::now();
            let mut contact = 0usize;
            for b in &input {
                let out = t.push_block(b).expect("run");
                contact += out.contact.iter().filter(|&&c| c).count();
            }
            let secs = start.elapsed().as_secs_f64();
            let c = t.counters();
            let sc = t.solver_counters();
            let solves = sc.solves - solver_before.solves;
            let newton_solves = sc.newton_solves - solver_before.newton_solves;
            let newton_iterations = sc.newton_iterations - solver_before.newton_iterations;
            let sweeps = sc.iterations - solver_before.iterations;
            let closed_steps = sc.closed_steps - solver_before.closed_steps;
            let steps = c.steps - before.steps;
            factors.push(data_s / secs);
            rates.push(steps as f64 / secs);
            println!(
                "{{\"case\":\"{}\",\"pairs\":{},\"run\":{run},\"data_seconds\":{data_s:.3},\"wall_seconds\":{secs:.4},\"realtime_factor\":{:.2},\"steps_per_second\":{:.0},\"steps_per_sample\":{},\"contact_sample_fraction\":{:.4},\"solves_per_step\":{:.4},\"closed_step_fraction\":{:.4},\"sweeps_per_solve\":{:.1},\"newton_solve_fraction\":{:.3},\"newton_iterations_per_newton_solve\":{:.2},\"solver_failures\":{}}}",
                case.name,
                case_rom.n_pairs(),
                data_s / secs,
                steps as f64 / secs,
                t.steps_per_sample(),
                contact as f64 / (run_blocks as f64 * layout.block_size as f64),
                solves as f64 / steps as f64,
                closed_steps as f64 / steps as f64,
                sweeps as f64 / solves.max(1) as f64,
                newton_solves as f64 / solves.max(1) as f64,
                newton_iterations as f64 / newton_solves.max(1) as f64,
                c.solver_failures - before.solver_failures,
            );
        }
        // The same data through the threaded task (queue large enough for all of it).
        let task_spec = TwinSpec {
            queue_blocks: input.len(),
            ..spec.clone()
        };
        let (mut task, mut rx) = TwinTask::spawn(twin.clone(), &task_spec).expect("task");
        for b in &input {
            task.push(b).expect("push");
        }
        let status = task.finish().expect("finish");
        let mut outputs = 0;
        while let Ok(ev) = rx.try_recv() {
            assert!(matches!(ev, TwinEvent::Block(_)));
            outputs += 1;
        }
        assert_eq!(outputs, input.len());
        println!(
            "{{\"case\":\"{}\",\"run\":\"task\",\"realtime_factor\":{:.2},\"steps_per_second\":{:.0},\"blocks_skipped\":{}}}",
            case.name, status.realtime_factor, status.steps_per_s, status.blocks_skipped
        );
        summary.push((
            case.name,
            case_rom.n_pairs(),
            median(&mut factors),
            median(&mut rates),
            status.realtime_factor,
        ));
    }
    eprintln!(
        "median over {} runs of {} s of data (held-contact cases: the share in the source; sync \
         core; task: one run):",
        args.repeat, args.seconds
    );
    for (c, pairs, f, r, tf) in summary {
        eprintln!(
            "  {c:>16}: {f:>6.2} x real time, {r:>9.0} steps/s (task: {tf:.2} x real time; {pairs} pairs)"
        );
    }
}
