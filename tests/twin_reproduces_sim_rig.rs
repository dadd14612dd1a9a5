//! The twin on the default ROM, fed with the DAQ blocks of the simulated rig whose truth is
//! the same ROM (no hidden physics): in the linear regime it reproduces the measured
//! upper-tip velocity relative to the base (vibrometer minus the integrated platform
//! acceleration) within a fraction of a percent in RMS and waveform; in sustained impacts it
//! shows the same contact activity and response level; in held contact the twin on the
//! coarser patch a session of such tests gives it does as well; it gives the same bits for
//! the same blocks, on its thread as in the sync core.
//!
//! Both the rig and the twin start at rest, so the comparison needs no settling: the twin
//! follows the measured transient too. What differs: the twin sees the base acceleration
//! after the DAQ (anti-alias filter, noise, 24-bit counts, mean of three channels) and
//! interpolated to its own step (5 per sample against the truth's 6), and no shaker.

mod default_rom;

use std::f64::consts::PI;

use rigtwin::config::RigConfig;
use rigtwin::rig::daq::{ChannelKind, DaqBlock, DriveCommand};
use rigtwin::rig::sim::{base_acceleration_frf, SimRig, SimRigSpec, TruthTrace};
use rigtwin::rom::Rom;
use rigtwin::twin::{Pushed, Twin, TwinBlock, TwinEvent, TwinModel, TwinSpec, TwinTask};

use default_rom::{default_rom, rom_of};

/// Beam length of the default rig, m.
const L: f64 = 0.3;
/// A clearance at which nothing touches, m.
const APART: f64 = 0.1;

/// Runs the simulated rig for `seconds` at `f_hz` with drive amplitude `amp_v` (ramped in
/// over 0.2 s) and returns its blocks and truth trace.
fn record(
    clearance: f64,
    f_hz: f64,
    amp_v: f64,
    seconds: f64,
) -> (SimRig, Vec<DaqBlock>, TruthTrace) {
    let mut rig = SimRig::new(default_rom(), &SimRigSpec::default(), clearance).unwrap();
    rig.set_drive(DriveCommand {
        frequency_hz: f_hz,
        amplitude_v: amp_v,
        ramp_s: 0.2,
    })
    .unwrap();
    let n = (seconds * rig.layout().sample_rate / rig.layout().block_size as f64).ceil() as usize;
    let mut trace = TruthTrace::default();
    let blocks = (0..n).map(|_| rig.next_block_traced(&mut trace)).collect();
    (rig, blocks, trace)
}

fn run_twin(rig: &SimRig, blocks: &[DaqBlock], clearance: f64) -> Vec<TwinBlock> {
    run_twin_on(default_rom(), rig, blocks, clearance)
}

fn run_twin_on(rom: &Rom, rig: &SimRig, blocks: &[DaqBlock], clearance: f64) -> Vec<TwinBlock> {
    let mut twin = Twin::new(
        &TwinModel::nominal(rom),
        &TwinSpec::default(),
        rig.layout(),
        clearance,
    )
    .unwrap();
    assert_eq!(twin.steps_per_sample(), 5);
    blocks.iter().map(|b| twin.push_block(b).unwrap()).collect()
}

/// The measured upper-tip velocity relative to the base: the vibrometer minus the base
/// velocity integrated (trapezoidal, from rest at t = 0) from the mean platform acceleration.
/// Both went through the same anti-alias filter as the twin's input.
fn measured_upper_tip(rig: &SimRig, blocks: &[DaqBlock]) -> Vec<f64> {
    let lay = rig.layout();
    let platform = lay.indices_of(ChannelKind::PlatformAcceleration);
    let vib = lay.index("vibrometer").unwrap();
    let dt = lay.dt();
    let mut v_base = 0.0;
    let mut a_last: Option<f64> = None;
    let mut out = Vec::new();
    for b in blocks {
        for i in 0..b.len {
            let a = platform
                .iter()
                .map(|&k| lay.channels[k].value(b.channel(k)[i]))
                .sum::<f64>()
                / platform.len() as f64;
            if let Some(p) = a_last {
                v_base += 0.5 * dt * (p + a);
            }
            a_last = Some(a);
            out.push(lay.channels[vib].value(b.channel(vib)[i]) - v_base);
        }
    }
    out
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

fn twin_upper_tip(out: &[TwinBlock]) -> Vec<f64> {
    out.iter().flat_map(|b| b.upper_tip().to_vec()).collect()
}

#[test]
fn upper_tip_velocity_matches_the_measurement_in_the_linear_regime() {
    let w1 = default_rom().omega_ref();
    let f1 = w1 / (2.0 * PI);
    let mut worst: f64 = 0.0;
    for ratio in [0.8, 1.0, 1.25] {
        let (rig, blocks, _) = record(APART, ratio * f1, 0.1, 3.0);
        let twin = run_twin(&rig, &blocks, APART);
        let measured = measured_upper_tip(&rig, &blocks);
        let predicted = twin_upper_tip(&twin);
        assert_eq!(measured.len(), predicted.len());
        // From 1 s on (the drive ramp and the first build-up are behind).
        let from = (1.0 * rig.layout().sample_rate) as usize;
        let (m, p) = (&measured[from..], &predicted[from..]);
        let diff: Vec<f64> = m.iter().zip(p).map(|(a, b)| a - b).collect();
        let rms_error = rms(p) / rms(m) - 1.0;
        let waveform_error = rms(&diff) / rms(m);
        println!(
            "Omega/omega_1FU = {ratio}: RMS measured {:.5e} m/s, twin {:.5e} m/s ({rms_error:+.2e}); \
             waveform error {waveform_error:.2e}",
            rms(m),
            rms(p)
        );
        assert!(twin.iter().all(|b| !b.contact.contains(&true)));
        if ratio != 1.0 {
            worst = worst.max(rms_error.abs());
            // Measured (2026-11): 4e-5 and 7.5e-5 RMS, 1.6e-3 waveform.
            assert!(rms_error.abs() < 0.005, "{ratio}: RMS error {rms_error}");
            assert!(
                waveform_error < 0.01,
                "{ratio}: waveform error {waveform_error}"
            );
        } else {
            // At resonance the response hangs on the damping of a 0.2 % mode; measured
            // 5.6e-5 RMS, 1.5e-4 waveform.
            assert!(rms_error.abs() < 0.01, "{ratio}: RMS error {rms_error}");
            assert!(
                waveform_error < 0.02,
                "{ratio}: waveform error {waveform_error}"
            );
        }
    }
    println!("worst off-resonance RMS error {worst:.2e}");
}

/// The drive amplitude (V) for the paper's high level (base displacement 6e-5 l at
/// omega_1FU) under impacts (the shaker carrying the beams as a rigid mass).
fn high_level_drive() -> f64 {
    let w1 = default_rom().omega_ref();
    let frf = base_acceleration_frf(&SimRigSpec::default().shaker, &[], w1).abs();
    6e-5 * L * w1 * w1 / frf
}

#[test]
fn contact_activity_matches_the_measurement_in_sustained_impacts() {
    let w1 = default_rom().omega_ref();
    let clearance = 2.78e-3 * L;
    let (rig, blocks, trace) = record(clearance, w1 / (2.0 * PI), high_level_drive(), 4.0);
    let twin = run_twin(&rig, &blocks, clearance);
    let fs = rig.layout().sample_rate;
    let from = (1.0 * fs) as usize;
    let truth_contact: Vec<bool> = trace.closed_steps[from..].iter().map(|&c| c > 0).collect();
    let measured_contact = measured_contact(&rig, &blocks)[from..].to_vec();
    let twin_contact: Vec<bool> = twin
        .iter()
        .flat_map(|b| b.contact.clone())
        .collect::<Vec<_>>()[from..]
        .to_vec();
    let fraction = |c: &[bool]| c.iter().filter(|&&x| x).count() as f64 / c.len() as f64;
    let onsets = |c: &[bool]| c.windows(2).filter(|w| !w[0] && w[1]).count();
    let (ft, fw) = (fraction(&truth_contact), fraction(&twin_contact));
    let (it, iw) = (onsets(&truth_contact), onsets(&twin_contact));
    let (fm, im) = (fraction(&measured_contact), onsets(&measured_contact));
    let measured = measured_upper_tip(&rig, &blocks);
    let predicted = twin_upper_tip(&twin);
    let (rm, rp) = (rms(&measured[from..]), rms(&predicted[from..]));
    let impulse: f64 = twin.iter().flat_map(|b| &b.normal_force).sum::<f64>() / fs;
    let failures: u32 = twin.iter().flat_map(|b| &b.solver_failures).sum();
    println!(
        "contact fraction: truth {ft:.4}, measured {fm:.4}, twin {fw:.4}; contact onsets: truth \
         {it}, measured {im}, twin {iw}; \
         upper-tip RMS: measured {rm:.4e} m/s, twin {rp:.4e} m/s ({:+.2e}); twin normal impulse \
         {impulse:.4e} N s over 4 s; twin solver failures {failures}, truth {}",
        rp / rm - 1.0,
        rig.truth().solver_failures
    );
    // Sustained: a contact onset in at least every other period of the 3 s compared (100
    // measured, 2026-11-26).
    let periods = 3.0 * w1 / (2.0 * PI);
    assert!(
        it as f64 > 0.5 * periods,
        "no sustained impacts in the rig: {it} onsets in {periods:.0} periods"
    );
    // The twin's contact is observed through the contact channel (circuit, minimum-hold,
    // threshold), so it compares with the measured channel. Measured (2026-11-24): fraction
    // 0.0068 (truth, any pair closed in a sample) / 0.0066 (channel) / 0.0079 (twin,
    // observed). The impacts are sensitive to the last bit of the input (the twin's step, the
    // DAQ's noise), so only the statistics compare.
    assert!(
        (fw - fm).abs() < 0.005,
        "contact fraction {fw} vs measured {fm}"
    );
    assert!(
        (iw as f64 / im as f64 - 1.0).abs() < 0.25,
        "onsets {iw} vs measured {im}"
    );
    assert!((rp / rm - 1.0).abs() < 0.1, "RMS {rp} vs {rm}");
    assert!(impulse > 0.0);
    // A sample the channel sees in contact had contact forces in it or in the sample before
    // (the circuit recovers within a sample: tau ln 2 = 35 us < 98 us).
    let forces: Vec<bool> = twin
        .iter()
        .flat_map(|b| b.normal_force.iter().map(|&f| f > 0.0).collect::<Vec<_>>())
        .collect();
    let contact: Vec<bool> = twin.iter().flat_map(|b| b.contact.clone()).collect();
    for i in 1..contact.len() {
        assert!(!contact[i] || forces[i] || forces[i - 1], "sample {i}");
    }
}

#[test]
fn same_blocks_give_the_same_bits_on_the_thread_and_in_the_sync_core() {
    let w1 = default_rom().omega_ref();
    let clearance = 2.78e-3 * L;
    let (rig, blocks, _) = record(clearance, w1 / (2.0 * PI), high_level_drive(), 1.5);
    let a = run_twin(&rig, &blocks, clearance);
    let b = run_twin(&rig, &blocks, clearance);
    let contact = a.iter().flat_map(|b| &b.contact).filter(|&&c| c).count();
    println!("{contact} samples with contact");
    assert!(
        contact > 0,
        "no contact: the check would miss the contact solver"
    );
    let bits = |v: &[TwinBlock]| -> Vec<u64> {
        v.iter()
            .flat_map(|b| {
                b.velocity
                    .iter()
                    .chain(&b.normal_force)
                    .chain(&b.tangential_force)
            })
            .map(|x| x.to_bits())
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(a, b);

    let spec = TwinSpec {
        queue_blocks: blocks.len(),
        ..TwinSpec::default()
    };
    let twin = Twin::new(
        &TwinModel::nominal(default_rom()),
        &spec,
        rig.layout(),
        clearance,
    )
    .unwrap();
    let (mut task, mut rx) = TwinTask::spawn(twin, &spec).unwrap();
    for blk in &blocks {
        assert_eq!(task.push(blk).unwrap(), Pushed::Queued);
    }
    let status = task.finish().unwrap();
    println!("task: {status:?}");
    let mut threaded = Vec::new();
    while let Ok(ev) = rx.try_recv() {
        match ev {
            TwinEvent::Block(b) => threaded.push(b),
            TwinEvent::Error { seq, message } => panic!("block {seq}: {message}"),
            TwinEvent::State { test, step, .. } => panic!("no state asked for ({test} {step})"),
        }
    }
    assert_eq!(bits(&threaded), bits(&a));
    assert_eq!(threaded, a);
}

/// The contact channel as the step summary reads it (below the default threshold), per sample.
fn measured_contact(rig: &SimRig, blocks: &[DaqBlock]) -> Vec<bool> {
    let lay = rig.layout();
    let kc = lay.index("contact_voltage").unwrap();
    let threshold = rigtwin::config::ControlSpec::default().contact_threshold_v;
    blocks
        .iter()
        .flat_map(|b| {
            b.channel(kc)
                .iter()
                .map(|&c| lay.channels[kc].value(c) < threshold)
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Held contact (issue 16): at a clearance of 1e-5 l and a base level of 0.5e-5 l at
/// omega_1FU, the twin on `[twin.held_contact]`'s coarser patch (8 x 11, the patch a session
/// of such tests gives the twin) follows the simulated rig (its truth on the default 12 x 16
/// patch) about as closely as the twin on the default patch: contact fraction, contact onsets
/// and upper-tip RMS; no solver failures.
#[test]
fn the_held_contact_twin_keeps_to_the_measurement_on_its_coarser_patch() {
    let w1 = default_rom().omega_ref();
    let clearance = 1e-5 * L;
    let drive = high_level_drive() * 0.5e-5 / 6e-5;
    let (rig, blocks, _) = record(clearance, w1 / (2.0 * PI), drive, 3.0);
    let coarse_cfg = RigConfig::default_rig()
        .held_contact_twin(&[1e-5])
        .expect("a held-contact patch for the default rig");
    let coarse = rom_of(&coarse_cfg);
    assert_eq!(coarse.n_pairs(), 88);
    let fine = run_twin(&rig, &blocks, clearance);
    let held = run_twin_on(&coarse, &rig, &blocks, clearance);
    let from = rig.layout().sample_rate as usize;
    let measured = measured_contact(&rig, &blocks)[from..].to_vec();
    let contact = |out: &[TwinBlock]| -> Vec<bool> {
        out.iter()
            .flat_map(|b| b.contact.clone())
            .collect::<Vec<_>>()[from..]
            .to_vec()
    };
    let fraction = |c: &[bool]| c.iter().filter(|&&x| x).count() as f64 / c.len() as f64;
    let onsets = |c: &[bool]| c.windows(2).filter(|w| !w[0] && w[1]).count();
    let failures = |out: &[TwinBlock]| out.iter().flat_map(|b| &b.solver_failures).sum::<u32>();
    let rm = rms(&measured_upper_tip(&rig, &blocks)[from..]);
    let (rf, rh) = (
        rms(&twin_upper_tip(&fine)[from..]),
        rms(&twin_upper_tip(&held)[from..]),
    );
    let (fine_contact, held_contact) = (contact(&fine), contact(&held));
    let (fm, cf, ch) = (
        fraction(&measured),
        fraction(&fine_contact),
        fraction(&held_contact),
    );
    let (om, of, oh) = (
        onsets(&measured),
        onsets(&fine_contact),
        onsets(&held_contact),
    );
    println!(
        "contact fraction: measured {fm:.4}, twin 12 x 16 {cf:.4}, twin 8 x 11 {ch:.4}; onsets: \
         measured {om}, 12 x 16 {of}, 8 x 11 {oh}; upper-tip RMS: measured {rm:.4e} m/s, \
         12 x 16 {:+.2e}, 8 x 11 {:+.2e}; solver failures {} / {}",
        rf / rm - 1.0,
        rh / rm - 1.0,
        failures(&fine),
        failures(&held)
    );
    // Measured (2026-11-29): contact fraction 0.0491 (channel) / 0.0577 (12 x 16) / 0.0575
    // (8 x 11); onsets 339 / 343 / 322; upper-tip RMS -0.19 % / -0.36 %; 0 failures.
    assert!(
        fm > 0.01,
        "no held contact in the rig: contact fraction {fm}"
    );
    assert_eq!(failures(&held), 0);
    assert!(
        (ch - fm).abs() < 0.02,
        "contact fraction {ch} vs measured {fm}"
    );
    assert!(
        (ch - cf).abs() < 0.01,
        "contact fraction {ch} vs the fine patch's {cf}"
    );
    assert!(
        (oh as f64 / om as f64 - 1.0).abs() < 0.15,
        "onsets {oh} vs measured {om}"
    );
    assert!((rh / rm - 1.0).abs() < 0.02, "RMS {rh} vs {rm}");
}
