//! The simulated rig's synchronous core ([`rigtwin::rig::sim::SimRig`]) with the default ROM
//! as truth guards: the base response against the analytic shaker-plus-modes FRF off
//! resonance; the resonant force drop at omega_1FU; impacts at the paper's high level with the
//! contact-voltage channel following the truth's closed pairs; every injected fault; block
//! bookkeeping; bit-for-bit determinism and noise seeding. `speed` (ignored) prints virtual
//! seconds per wall second.

mod default_rom;

use std::f64::consts::PI;

use rigtwin::rig::daq::{DaqBlock, DriveCommand, RigFault};
use rigtwin::rig::sim::{
    base_acceleration_frf, BaseMode, InjectedFault, SimRig, SimRigSpec, TruthTrace,
};
use rigtwin::rom::Rom;
use rigtwin::signal::demodulate;

use default_rom::default_rom;

/// Beam length of the default rig, m (levels and clearances are fractions of it).
const L: f64 = 0.3;
/// A clearance at which nothing touches, m.
const APART: f64 = 0.1;

fn modes(rom: &Rom) -> Vec<BaseMode> {
    (0..rom.n_modes())
        .map(|i| BaseMode {
            omega: rom.omega[i],
            zeta: rom.damping_ratio[i],
            beta: rom.beta[i],
        })
        .collect()
}

fn blocks_for(rig: &SimRig, seconds: f64) -> usize {
    (seconds * rig.layout().sample_rate / rig.layout().block_size as f64).ceil() as usize
}

fn run(rig: &mut SimRig, seconds: f64) -> Vec<DaqBlock> {
    (0..blocks_for(rig, seconds))
        .map(|_| rig.next_block())
        .collect()
}

/// Physical values of channel `name` over the blocks.
fn values(rig: &SimRig, blocks: &[DaqBlock], name: &str) -> Vec<f64> {
    let k = rig.layout().index(name).unwrap();
    let ch = &rig.layout().channels[k];
    blocks
        .iter()
        .flat_map(|b| b.channel(k).iter().map(|&c| ch.value(c)))
        .collect()
}

/// Base-acceleration amplitude (truth) at `f_hz` over `record_s` after `settle_s`.
fn base_amplitude(rig: &mut SimRig, f_hz: f64, settle_s: f64, record_s: f64) -> f64 {
    run(rig, settle_s);
    let mut trace = TruthTrace::default();
    for _ in 0..blocks_for(rig, record_s) {
        rig.next_block_traced(&mut trace);
    }
    let fs = rig.layout().sample_rate;
    demodulate(
        &trace.base_acceleration,
        1.0 / fs,
        2.0 * PI * f_hz,
        trace.time[0],
    )
    .unwrap()
    .magnitude
}

fn drive(f_hz: f64, amplitude_v: f64, ramp_s: f64) -> DriveCommand {
    DriveCommand {
        frequency_hz: f_hz,
        amplitude_v,
        ramp_s,
    }
}

#[test]
fn base_response_matches_the_frf_off_resonance() {
    let rom = default_rom();
    let spec = SimRigSpec::default();
    let modes = modes(rom);
    for f in [20.0, 120.0] {
        let mut rig = SimRig::new(rom, &spec, APART).unwrap();
        rig.set_drive(drive(f, 0.05, 0.3)).unwrap();
        let a = base_amplitude(&mut rig, f, 2.0, 1.0);
        let expected = 0.05 * base_acceleration_frf(&spec.shaker, &modes, 2.0 * PI * f).abs();
        let e = a / expected - 1.0;
        println!("{f} Hz: base acceleration {a:.5e} m/s^2, FRF {expected:.5e} ({e:+.2e})");
        assert!(e.abs() < 0.01, "{f} Hz: {a} vs {expected}");
        assert!(rig.faults().is_empty(), "{:?}", rig.faults());
    }
}

#[test]
fn resonant_force_drop_at_omega_1fu() {
    let rom = default_rom();
    let spec = SimRigSpec::default();
    let modes = modes(rom);
    let f1 = rom.omega_ref() / (2.0 * PI);
    let amp = 0.05;
    let mut measured = Vec::new();
    for ratio in [0.9, 1.0, 1.1] {
        let f = ratio * f1;
        let mut rig = SimRig::new(rom, &spec, APART).unwrap();
        rig.set_drive(drive(f, amp, 0.3)).unwrap();
        let a = base_amplitude(&mut rig, f, 6.0, 1.0);
        let expected = amp * base_acceleration_frf(&spec.shaker, &modes, 2.0 * PI * f).abs();
        println!(
            "Omega/omega_1FU = {ratio}: base acceleration {a:.5e} m/s^2 (FRF {expected:.5e}, {:+.2e})",
            a / expected - 1.0
        );
        measured.push((a, expected));
    }
    let (dip, dip_frf) = (
        measured[1].0 / measured[0].0.max(measured[2].0),
        measured[1].1 / measured[0].1.max(measured[2].1),
    );
    println!("force drop: a(omega_1FU) / max(a(0.9), a(1.1)) = {dip:.4} (FRF {dip_frf:.4})");
    assert!(dip < 0.95, "no resonant force drop: {dip}");
    // After 6 s of settling (about 4 decay times of 1FU) the dip is within a few % of the
    // steady state's.
    assert!((dip / dip_frf - 1.0).abs() < 0.05, "{dip} vs {dip_frf}");
}

#[test]
fn impacts_at_the_high_level_drive_the_contact_voltage() {
    let rom = default_rom();
    let spec = SimRigSpec::default();
    let w1 = rom.omega_ref();
    let f1 = w1 / (2.0 * PI);
    // The paper's high level: base displacement 6e-5 l at omega_1FU, clearance 2.78e-3 l.
    // Under impacts the tips cannot build up the resonant response, so the beams' modal
    // reaction (the resonant force drop) largely disappears: the drive amplitude comes from the
    // FRF of the shaker carrying the beams as a rigid mass (no modes).
    let level = 6e-5 * L;
    let frf = base_acceleration_frf(&spec.shaker, &[], w1).abs();
    let amp = level * w1 * w1 / frf;
    println!("drive amplitude for {level:.3e} m at {f1:.2} Hz: {amp:.4} V");
    let mut rig = SimRig::new(rom, &spec, 2.78e-3 * L).unwrap();
    rig.set_drive(drive(f1, amp, 0.2)).unwrap();
    let mut trace = TruthTrace::default();
    let blocks: Vec<DaqBlock> = (0..blocks_for(&rig, 3.0))
        .map(|_| rig.next_block_traced(&mut trace))
        .collect();
    let contact = values(&rig, &blocks, "contact_voltage");
    let closed = &trace.closed_steps;
    let first = closed
        .iter()
        .position(|&c| c > 0)
        .expect("no impact in 3 s");
    let impacts = closed.windows(2).filter(|w| w[0] == 0 && w[1] > 0).count();
    let closed_samples = closed.iter().filter(|&&c| c > 0).count();
    println!(
        "first impact at {:.3} s, {impacts} impacts, {closed_samples} samples with contact, \
         solver failures {}",
        trace.time[first],
        rig.truth().solver_failures
    );
    assert!(impacts > 20, "{impacts}");
    let base = &trace.base_displacement[trace.base_displacement.len() - 10240..];
    let q = demodulate(
        base,
        1.0 / 10240.0,
        w1,
        trace.time[trace.time.len() - 10240],
    )
    .unwrap();
    println!(
        "base displacement amplitude in the last second: {:.3e} m",
        q.magnitude
    );
    assert!(
        q.magnitude > 0.7 * level && q.magnitude < 1.3 * level,
        "base displacement {} m for a level of {level} m",
        q.magnitude
    );

    // The contact voltage: at the open level (5 V) until the first impact, low (below the
    // midpoint) only within a short lag (RC 50 us, anti-alias filter ~0.2 ms) after truth
    // steps with closed pairs, and low after every contact closed for at least 3 samples' worth
    // of truth steps (0.29 ms, about 6 RC time constants).
    let os = rig.oversampling();
    let mid = 2.5;
    assert!(contact[..first].iter().all(|&v| (v - 5.0).abs() < 0.05));
    let lag = 6;
    for (n, &v) in contact.iter().enumerate() {
        if v < mid {
            let from = n.saturating_sub(lag);
            assert!(
                closed[from..=n].iter().any(|&c| c > 0),
                "sample {n}: contact voltage {v} V with no contact in the {lag} samples before"
            );
        }
    }
    let mut n = 0;
    let mut long_contacts = 0;
    while n < closed.len() {
        if closed[n] > 0 {
            let end = (n..closed.len())
                .find(|&k| closed[k] == 0)
                .unwrap_or(closed.len());
            let closed_time = closed[n..end].iter().sum::<u32>();
            if closed_time >= 3 * os {
                long_contacts += 1;
                let to = (end + lag).min(contact.len());
                assert!(
                    contact[n..to].iter().any(|&v| v < mid),
                    "contact over samples {n}..{end} (closed truth steps {:?}) not seen on the \
                     contact voltage {:?}",
                    &closed[n..end],
                    &contact[n..to]
                );
            }
            n = end;
        } else {
            n += 1;
        }
    }
    println!("{long_contacts} contacts closed for >= 3 samples");

    // Impacts load the beam accelerometers hard, but within their range by default.
    for name in ["lower_tip", "upper_tip", "lower_mid", "upper_mid"] {
        let peak = values(&rig, &blocks, name)
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        println!("{name}: peak {peak:.1} m/s^2");
    }
    let vib = values(&rig, &blocks, "vibrometer")
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    println!("vibrometer: peak {vib:.3} m/s");
    assert!(rig.faults().is_empty(), "{:?}", rig.faults());
}

#[test]
fn injected_faults_do_what_they_say() {
    let rom = default_rom();
    let spec = SimRigSpec::default();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let mut rig = SimRig::new(rom, &spec, APART).unwrap();
    rig.set_drive(drive(f1, 0.08, 0.0)).unwrap();
    rig.schedule(InjectedFault::DeadChannel {
        at_s: 0.1,
        channel: "upper_tip".into(),
    })
    .unwrap();
    rig.schedule(InjectedFault::ClearanceChange {
        at_s: 0.2,
        clearance_m: 3e-4,
    })
    .unwrap();
    rig.schedule(InjectedFault::DriveSaturation {
        at_s: 0.3,
        limit_v: 0.5,
    })
    .unwrap();
    rig.schedule(InjectedFault::DaqStall { at_s: 0.4 }).unwrap();
    assert!(rig
        .schedule(InjectedFault::DeadChannel {
            at_s: 0.0,
            channel: "upper_tip_2".into(),
        })
        .is_err());

    let mut blocks = Vec::new();
    let mut trace = TruthTrace::default();
    while !rig.stalled() {
        let b = rig.next_block_traced(&mut trace);
        b.check(rig.layout()).unwrap();
        blocks.push(b);
        assert!(blocks.len() < 100, "the stall never came");
    }
    let fs = rig.layout().sample_rate;
    // Stalled exactly once the next sample's time reached 0.4 s.
    let next = blocks.len() as f64 * 256.0 / fs;
    assert!(next >= 0.4 && next - 256.0 / fs < 0.4, "{next}");
    for (k, b) in blocks.iter().enumerate() {
        assert_eq!(b.seq, k as u64);
        assert_eq!(b.first_sample, k as u64 * 256);
    }

    let time: Vec<f64> = (0..trace.time.len()).map(|n| n as f64 / fs).collect();
    assert_eq!(time, trace.time);
    let tip = values(&rig, &blocks, "upper_tip");
    let on = |t0: f64, t1: f64| {
        time.iter()
            .zip(&tip)
            .filter(move |(t, _)| **t >= t0 && **t < t1)
            .map(|(_, v)| *v)
    };
    assert!(on(0.0, 0.1).any(|v| v != 0.0));
    assert!(on(0.1, 0.4).all(|v| v == 0.0));

    // The clearance shrank below the tips' relative amplitude: impacts from 0.2 s on, none
    // before.
    let closed_before = trace.closed_steps[..(0.2 * fs) as usize]
        .iter()
        .any(|&c| c > 0);
    let closed_after = trace.closed_steps[(0.2 * fs) as usize..]
        .iter()
        .any(|&c| c > 0);
    assert!(!closed_before && closed_after);
    assert_eq!(rig.truth().clearance, 3e-4);

    // The amplifier limit: 0.08 V x 20 = 1.6 V of output clipped at 0.5 V from 0.3 s on.
    let u = &trace.amplifier_output;
    let n3 = (0.3 * fs) as usize;
    assert!(u[..n3].iter().fold(0.0f64, |m, v| m.max(v.abs())) > 1.5);
    assert!(u[n3..].iter().all(|v| v.abs() <= 0.5));
    assert!(rig
        .faults()
        .contains(&RigFault::DriveSaturated { limit_v: 0.5 }));
    assert!(rig.truth().amplifier_limit_v == 0.5);
}

#[test]
fn same_spec_and_commands_give_identical_blocks() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let make = |seed: u64| {
        let mut spec = SimRigSpec::default();
        spec.daq.noise_seed = seed;
        // A clearance the tips reach within the run, so the contact solver is exercised.
        let mut rig = SimRig::new(rom, &spec, 3e-4).unwrap();
        let mut trace = TruthTrace::default();
        rig.set_drive(drive(f1, 0.08, 0.05)).unwrap();
        let mut blocks: Vec<DaqBlock> = (0..blocks_for(&rig, 0.3))
            .map(|_| rig.next_block_traced(&mut trace))
            .collect();
        rig.set_drive(drive(1.02 * f1, 0.08, 0.1)).unwrap();
        blocks.extend((0..blocks_for(&rig, 0.2)).map(|_| rig.next_block_traced(&mut trace)));
        (blocks, rig.truth(), trace)
    };
    let (a, ta, trace) = make(11);
    let impacts = trace.closed_steps.iter().filter(|&&c| c > 0).count();
    println!("{impacts} samples with contact");
    assert!(
        impacts > 0,
        "no contact: the determinism check would miss the contact solver"
    );
    let (b, tb, _) = make(11);
    assert!(a == b, "same seed and commands: blocks differ");
    assert_eq!(ta, tb);
    let (c, tc, _) = make(12);
    assert!(a != c, "different noise seeds gave identical blocks");
    // The truth does not depend on the noise.
    assert_eq!(ta, tc);
}

/// Prints virtual seconds simulated per wall second. The truth is the default ROM, or the ROM
/// file named by `RIGTWIN_TRUTH_ROM` (e.g. one built with `rigtwin rom build --cutoff-ratio
/// 400`, the truth spec's default).
#[test]
#[ignore = "speed figure: cargo test --test sim_rig_core speed -- --ignored --nocapture"]
fn speed() {
    let loaded;
    let rom = match std::env::var_os("RIGTWIN_TRUTH_ROM") {
        Some(path) => {
            loaded = rigtwin::rom::file::read(std::path::Path::new(&path)).unwrap();
            &loaded
        }
        None => default_rom(),
    };
    println!(
        "truth ROM: {} modes to {:.1} x f(1FU), {} pairs",
        rom.n_modes(),
        rom.omega.iter().fold(0.0f64, |m, w| m.max(*w)) / rom.omega_ref(),
        rom.n_pairs()
    );
    let spec = SimRigSpec::default();
    let w1 = rom.omega_ref();
    let f1 = w1 / (2.0 * PI);
    let frf = base_acceleration_frf(&spec.shaker, &[], w1).abs();
    let high = 6e-5 * L * w1 * w1 / frf;
    for (name, clearance, amp, virtual_s) in [
        ("open (no contact)", APART, 0.05, 5.0),
        ("high level, impacts", 2.78e-3 * L, high, 5.0),
        (
            "clearance 0 (probes touching at rest), 0.05 V",
            0.0,
            0.05,
            0.5,
        ),
    ] {
        let mut rig = SimRig::new(rom, &spec, clearance).unwrap();
        rig.set_drive(drive(f1, amp, 0.2)).unwrap();
        run(&mut rig, 1.0);
        let mut trace = TruthTrace::default();
        let t = std::time::Instant::now();
        for _ in 0..blocks_for(&rig, virtual_s) {
            rig.next_block_traced(&mut trace);
        }
        let wall = t.elapsed().as_secs_f64();
        let contact = trace
            .closed_steps
            .iter()
            .map(|&c| u64::from(c))
            .sum::<u64>() as f64
            / (trace.closed_steps.len() as f64 * f64::from(rig.oversampling()));
        println!(
            "{name}: {:.2} virtual s per wall s ({} truth steps per sample, {:.0} truth steps/s, \
             {:.1} % of the steps with contact, {} solver failures)",
            virtual_s / wall,
            rig.oversampling(),
            virtual_s * 10240.0 * f64::from(rig.oversampling()) / wall,
            100.0 * contact,
            rig.truth().solver_failures
        );
    }
}
