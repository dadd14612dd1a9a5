//! Unit tests of the assembled core on small synthetic ROMs (fast): the shaker against its
//! analytic response, alone and with one beam mode, and the bookkeeping of blocks, drive and
//! faults. The default-ROM behaviour is in `tests/sim_rig_core.rs`.

use faer::Mat;

use super::*;
use crate::rig::daq::ChannelKind;
use crate::rig::sim::variants::{Beam, ClampFrictionSpec, SensorGainSpec, TiltSpec, WearSpec};
use crate::rom::{RomMeta, RomOutput};
use crate::signal::demodulate;

/// One mode at `f_hz` with participation `beta`, one contact pair far apart, the four beam
/// sensors reading the mode with unit participation.
fn stub_rom(f_hz: f64, zeta: f64, beta: f64) -> Rom {
    let outputs = truth::BEAM_SENSORS
        .iter()
        .map(|n| RomOutput {
            name: (*n).into(),
            c_eta: vec![1.0],
            c_lambda: vec![0.0; 3],
        })
        .collect();
    Rom {
        meta: RomMeta::default(),
        omega: vec![2.0 * std::f64::consts::PI * f_hz],
        damping_ratio: vec![zeta],
        labels: vec!["1FU".into()],
        phi_g: Mat::zeros(3, 1),
        g_res: Mat::from_fn(3, 3, |i, j| if i == j { 1e-6 } else { 0.0 }),
        k_gg: Mat::from_fn(3, 3, |i, j| if i == j { 1e6 } else { 0.0 }),
        beta: vec![beta],
        pair_area: vec![1e-6],
        pair_position: vec![[0.3, 0.0, 0.0]],
        clearance: 1.0,
        friction: 0.4,
        outputs,
    }
}

fn spec(oversampling: u32) -> SimRigSpec {
    let mut s = SimRigSpec::default();
    s.truth.oversampling = Some(oversampling);
    s
}

/// Drives at `f_hz` with amplitude `amp` (V) and returns the base-acceleration amplitude
/// from the truth trace and from the first platform channel over the last `record_s`.
fn measure(rig: &mut SimRig, f_hz: f64, amp: f64, settle_s: f64, record_s: f64) -> (f64, f64) {
    rig.set_drive(DriveCommand {
        frequency_hz: f_hz,
        amplitude_v: amp,
        ramp_s: 0.2,
    })
    .unwrap();
    let fs = rig.layout().sample_rate;
    let bs = rig.layout().block_size;
    let blocks = |s: f64| (s * fs / bs as f64).ceil() as usize;
    for _ in 0..blocks(settle_s) {
        rig.next_block();
    }
    let mut trace = TruthTrace::default();
    let mut platform = Vec::new();
    for _ in 0..blocks(record_s) {
        let b = rig.next_block_traced(&mut trace);
        platform.extend(
            b.channel(0)
                .iter()
                .map(|&c| rig.layout().channels[0].value(c)),
        );
    }
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let t0 = trace.time[0];
    let truth = demodulate(&trace.base_acceleration, 1.0 / fs, w, t0).unwrap();
    let daq = demodulate(&platform, 1.0 / fs, w, t0).unwrap();
    (truth.magnitude, daq.magnitude)
}

#[test]
fn shaker_alone_matches_the_electromechanical_frf() {
    // beta = 0: the mode is not attached; the base is the 1-DOF shaker on its coil.
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let spec = spec(4);
    for f in [20.0, 55.0, 300.0] {
        let mut rig = SimRig::new(&rom, &spec, 1.0).unwrap();
        let amp = 0.05;
        let (truth, daq) = measure(&mut rig, f, amp, 1.5, 0.5);
        let expected =
            amp * base_acceleration_frf(&spec.shaker, &[], 2.0 * std::f64::consts::PI * f).abs();
        let (et, ed) = (truth / expected - 1.0, daq / expected - 1.0);
        assert!(
            et.abs() < 0.01,
            "{f} Hz: truth {truth} vs {expected} ({et:e})"
        );
        // The platform channel: filter gain (flat here), noise and quantisation on top.
        assert!(ed.abs() < 0.01, "{f} Hz: DAQ {daq} vs {expected} ({ed:e})");
        assert!(rig.faults().is_empty(), "{:?}", rig.faults());
    }
}

#[test]
fn one_attached_mode_gives_the_resonant_force_drop_of_the_frf() {
    // A heavy, lightly damped mode at 55 Hz: the base sees its apparent mass.
    let (f1, zeta, beta) = (55.0, 0.01, 0.5);
    let rom = stub_rom(f1, zeta, beta);
    // A light table, so the mode's apparent mass (beta^2 / (2 zeta) = 12.5 kg at resonance)
    // shows clearly.
    let mut spec = spec(4);
    spec.shaker.moving_mass = 5.0;
    let mode = BaseMode {
        omega: 2.0 * std::f64::consts::PI * f1,
        zeta,
        beta,
    };
    let mut measured = Vec::new();
    for ratio in [0.9, 1.0, 1.1] {
        let f = ratio * f1;
        let mut rig = SimRig::new(&rom, &spec, 1.0).unwrap();
        let amp = 0.05;
        let (truth, _) = measure(&mut rig, f, amp, 2.5, 0.5);
        let expected = amp
            * base_acceleration_frf(&spec.shaker, &[mode], 2.0 * std::f64::consts::PI * f).abs();
        let e = truth / expected - 1.0;
        assert!(e.abs() < 0.01, "{f} Hz: {truth} vs {expected} ({e:e})");
        measured.push(truth);
    }
    assert!(
        measured[1] < measured[0] && measured[1] < measured[2],
        "{measured:?}"
    );
}

#[test]
fn rejects_bad_setup_and_commands() {
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let mut s = spec(4);
    s.shaker.moving_mass = 0.1;
    let heavy = stub_rom(55.0, 0.01, 0.5); // beta^2 = 0.25 kg > 0.1 kg
    let msg = SimRig::new(&heavy, &s, 1.0).unwrap_err().to_string();
    assert!(msg.contains("shaker.moving_mass = 0.1"), "{msg}");

    let mut s = spec(4);
    s.truth.oversampling = Some(1);
    // dt = 1/10240 s against the 2000 Hz mode's limit 2 / w = 1.6e-4 s: fine; a 20 kHz mode
    // (limit 1.6e-5 s) is not.
    let stiff = stub_rom(20_000.0, 0.01, 0.0);
    let msg = SimRig::new(&stiff, &s, 1.0).unwrap_err().to_string();
    assert!(msg.contains("truth.oversampling = 1"), "{msg}");
    assert!(SimRig::new(&rom, &s, 1.0).is_ok());

    let mut no_sensor = rom.clone();
    no_sensor.outputs.remove(1);
    let msg = SimRig::new(&no_sensor, &spec(4), 1.0)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("lower_mid"), "{msg}");
    assert!(SimRig::new(&rom, &spec(4), f64::NAN).is_err());

    let mut rig = SimRig::new(&rom, &spec(4), 1.0).unwrap();
    let bad = DriveCommand {
        frequency_hz: -1.0,
        amplitude_v: 0.1,
        ramp_s: 0.0,
    };
    assert!(matches!(rig.set_drive(bad), Err(SimRigError::Command(_))));
    let msg = rig
        .schedule(InjectedFault::DeadChannel {
            at_s: 0.0,
            channel: "platform_9".into(),
        })
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("platform_9") && msg.contains("platform_1"),
        "{msg}"
    );
    assert!(rig
        .schedule(InjectedFault::DaqStall { at_s: f64::NAN })
        .is_err());
    assert!(rig
        .schedule(InjectedFault::DriveSaturation {
            at_s: 0.0,
            limit_v: -1.0
        })
        .is_err());
}

#[test]
fn blocks_are_contiguous_and_valid() {
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let mut rig = SimRig::new(&rom, &spec(4), 1.0).unwrap();
    rig.set_drive(DriveCommand {
        frequency_hz: 40.0,
        amplitude_v: 0.1,
        ramp_s: 0.0,
    })
    .unwrap();
    for k in 0..8u64 {
        let b = rig.next_block();
        assert_eq!(b.seq, k);
        assert_eq!(b.first_sample, k * 256);
        assert_eq!(b.time, (k * 256) as f64 / 10240.0);
        b.check(rig.layout()).unwrap();
    }
    let snap = rig.truth();
    assert_eq!(snap.truth_steps, 8 * 256 * 4);
    assert_eq!(snap.time, 8.0 * 256.0 / 10240.0);
    assert!(!snap.failed);
    // At rest the contact channel sits at the open voltage from the first sample on (the
    // filter starts settled).
    let mut rig = SimRig::new(&rom, &spec(4), 1.0).unwrap();
    let b = rig.next_block();
    let k = rig.layout().index("contact_voltage").unwrap();
    let ch = &rig.layout().channels[k];
    assert_eq!(ch.kind, ChannelKind::ContactVoltage);
    for &c in b.channel(k) {
        assert!((ch.value(c) - 5.0).abs() < 0.02, "{}", ch.value(c));
    }
}

#[test]
fn drive_saturation_clips_and_latches() {
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let mut rig = SimRig::new(&rom, &spec(4), 1.0).unwrap();
    rig.set_drive(DriveCommand {
        frequency_hz: 40.0,
        amplitude_v: 0.5, // 10 V at the coil
        ramp_s: 0.0,
    })
    .unwrap();
    rig.schedule(InjectedFault::DriveSaturation {
        at_s: 0.1,
        limit_v: 4.0,
    })
    .unwrap();
    let k = rig.layout().index("drive_voltage").unwrap();
    let mut peak_before: f64 = 0.0;
    let mut peak_after: f64 = 0.0;
    for _ in 0..12 {
        let b = rig.next_block();
        let ch = &rig.layout().channels[k];
        for (i, &c) in b.channel(k).iter().enumerate() {
            let t = b.time + i as f64 / 10240.0;
            let v = ch.value(c).abs();
            if t < 0.1 {
                peak_before = peak_before.max(v);
            } else if t > 0.11 {
                peak_after = peak_after.max(v);
            }
        }
    }
    assert!((peak_before - 10.0).abs() < 0.2, "{peak_before}");
    // Clipped at 4 V (the anti-alias filter overshoots the clipped edges slightly).
    assert!(peak_after < 4.5 && peak_after > 3.9, "{peak_after}");
    assert_eq!(rig.faults(), &[RigFault::DriveSaturated { limit_v: 4.0 }]);
    assert_eq!(rig.truth().amplifier_limit_v, 4.0);
}

#[test]
fn a_non_finite_truth_is_reported_not_a_panic() {
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let mut rig = SimRig::new(&rom, &spec(4), 1.0).unwrap();
    rig.set_drive(DriveCommand {
        frequency_hz: 40.0,
        amplitude_v: 0.1,
        ramp_s: 0.0,
    })
    .unwrap();
    rig.next_block();
    rig.truth.poison();
    for _ in 0..3 {
        let b = rig.next_block();
        b.check(rig.layout()).unwrap();
    }
    assert!(rig.truth().failed);
    assert_eq!(rig.faults().len(), 1, "{:?}", rig.faults());
    match &rig.faults()[0] {
        RigFault::Device { message: msg } => assert!(msg.contains("non-finite"), "{msg}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_stiff_base_coupling_gets_a_stable_step() {
    // Moving mass barely above the mode's beta^2 = 0.25 kg: the base's free mass is 0.01 kg,
    // and the coil's back-EMF damping and electrical stiffness on it are far stiffer than the
    // mode.
    let rom = stub_rom(55.0, 0.01, 0.5);
    let mut s = spec(1);
    s.shaker.moving_mass = 0.26;
    let msg = SimRig::new(&rom, &s, 1.0).unwrap_err().to_string();
    assert!(msg.contains("shaker attached"), "{msg}");
    s.truth.oversampling = None;
    let mut rig = SimRig::new(&rom, &s, 1.0).unwrap();
    assert!(rig.oversampling() > 1);
    rig.set_drive(DriveCommand {
        frequency_hz: 50.0,
        amplitude_v: 0.01,
        ramp_s: 0.0,
    })
    .unwrap();
    for _ in 0..40 {
        rig.next_block();
    }
    let t = rig.truth();
    assert!(!t.failed && t.base_acceleration.is_finite(), "{t:?}");
    assert!(rig.faults().is_empty(), "{:?}", rig.faults());
}

#[test]
fn adc_clipping_latches_over_range_once_per_channel() {
    let rom = stub_rom(2000.0, 0.01, 0.0);
    let mut s = spec(4);
    s.daq.full_scale.platform_acceleration = 0.05;
    let mut rig = SimRig::new(&rom, &s, 1.0).unwrap();
    rig.set_drive(DriveCommand {
        frequency_hz: 40.0,
        amplitude_v: 0.1,
        ramp_s: 0.0,
    })
    .unwrap();
    for _ in 0..20 {
        let b = rig.next_block();
        b.check(rig.layout()).unwrap();
    }
    let names: Vec<&str> = rig
        .faults()
        .iter()
        .map(|f| match f {
            RigFault::OverRange { channel } => channel.as_str(),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(names, ["platform_1", "platform_2", "platform_3"]);
}

#[test]
fn injected_faults_read_from_json() {
    let f: InjectedFault =
        serde_json::from_str(r#"{"kind": "dead_channel", "at_s": 1.5, "channel": "upper_tip"}"#)
            .unwrap();
    assert_eq!(
        f,
        InjectedFault::DeadChannel {
            at_s: 1.5,
            channel: "upper_tip".into()
        }
    );
    assert_eq!(f.at_s(), 1.5);
    assert!(serde_json::from_str::<InjectedFault>(
        r#"{"kind": "daq_stall", "at_s": 1.0, "extra": 1}"#
    )
    .is_err());
}

#[test]
fn truth_variants_check_the_rom_and_name_bad_input() {
    let rom = stub_rom(55.0, 0.01, 0.1);
    let clamp = |beams: Vec<Beam>| {
        let mut s = spec(4);
        s.truth.variants.clamp_friction = Some(ClampFrictionSpec {
            stiffness_fraction: 0.1,
            half_slip_tip_amplitude: 1e-4,
            sliders: 8,
            beams,
        });
        s
    };
    // The stub has a 1FU mode only.
    let msg = SimRig::new(&rom, &clamp(vec![Beam::Lower, Beam::Upper]), 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("truth.variants.clamp_friction.beams = \"1FL\"")
            && msg.contains("no mode with that label"),
        "{msg}"
    );
    let rig = SimRig::new(&rom, &clamp(vec![Beam::Upper]), 1.0).unwrap();
    assert!(rig.variants().clamp_friction.is_some());
    // A mode that does not move the tip cannot take a tip slip amplitude.
    let mut still = rom.clone();
    still.outputs[2].c_eta[0] = 0.0;
    let msg = SimRig::new(&still, &clamp(vec![Beam::Upper]), 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("does not move the output \"upper_tip\""),
        "{msg}"
    );

    let mut s = spec(4);
    s.truth.variants.sensor_gains = vec![SensorGainSpec {
        channel: "upper_tipp".into(),
        gain: 1.03,
    }];
    let msg = SimRig::new(&rom, &s, 1.0).unwrap_err().to_string();
    assert!(
        msg.contains("truth.variants.sensor_gains[0].channel = \"upper_tipp\"")
            && msg.contains("upper_tip,"),
        "{msg}"
    );
    let mut s = spec(4);
    s.truth.variants.tilt = Some(TiltSpec {
        angle: f64::NAN,
        axis: [0.0, 1.0],
    });
    let msg = SimRig::new(&rom, &s, 1.0).unwrap_err().to_string();
    assert!(msg.contains("truth.variants.tilt.angle = NaN"), "{msg}");
    let mut s = spec(4);
    s.truth.variants.wear = Some(WearSpec {
        coefficient: -1.0,
        max_growth: None,
    });
    let msg = SimRig::new(&rom, &s, 1.0).unwrap_err().to_string();
    assert!(
        msg.contains("truth.variants.wear.coefficient = -1"),
        "{msg}"
    );
}

#[test]
fn clamp_friction_on_one_mode_is_inert_below_the_first_slip_and_damps_above() {
    // One 1FU mode; the joint carries 30 % of its stiffness, half its 32 sliders slip at a tip
    // amplitude of 0.1 mm (the first at 3.1 um).
    let f1 = 55.0;
    let rom = stub_rom(f1, 0.002, 0.3);
    let mut with = spec(4);
    with.truth.variants.clamp_friction = Some(ClampFrictionSpec {
        stiffness_fraction: 0.3,
        half_slip_tip_amplitude: 1e-4,
        sliders: 32,
        beams: vec![Beam::Upper],
    });
    // Tip amplitude at resonance (the tip outputs read the mode with unit participation)
    // from the upper-tip accelerometer over the last second of a 3 s dwell.
    let tip = |s: &SimRigSpec, amp: f64| {
        let mut rig = SimRig::new(&rom, s, 1.0).unwrap();
        rig.set_drive(DriveCommand {
            frequency_hz: f1,
            amplitude_v: amp,
            ramp_s: 0.2,
        })
        .unwrap();
        let k = rig.layout().index("upper_tip").unwrap();
        let mut x = Vec::new();
        for b in 0..120 {
            let block = rig.next_block();
            if b >= 80 {
                let ch = &rig.layout().channels[k];
                x.extend(block.channel(k).iter().map(|&c| ch.value(c)));
            }
        }
        let w = 2.0 * std::f64::consts::PI * f1;
        let h = demodulate(&x, 1.0 / 10240.0, w, 80.0 * 256.0 / 10240.0).unwrap();
        (h.magnitude / (w * w), rig.truth().joint_dissipation)
    };
    // Low level: below the first slip the joint is stuck, the rig records what the plain rig
    // records.
    let (lin_low, _) = tip(&spec(4), 1e-4);
    let (joint_low, e_low) = tip(&with, 1e-4);
    println!("low level: plain {lin_low:.4e} m, joint {joint_low:.4e} m (dissipated {e_low:e} J)");
    assert!(lin_low < 3e-6, "{lin_low}");
    assert_eq!(e_low, 0.0);
    assert_eq!(joint_low, lin_low);
    // High level: the slipping joint dissipates and holds the resonance far down.
    let (lin_high, _) = tip(&spec(4), 0.02);
    let (joint_high, e_high) = tip(&with, 0.02);
    println!(
        "high level: plain {lin_high:.4e} m, joint {joint_high:.4e} m (dissipated {e_high:.3e} J)"
    );
    assert!(joint_high < 0.5 * lin_high, "{joint_high} vs {lin_high}");
    assert!(e_high > 0.0);
}
