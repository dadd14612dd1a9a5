//! The simulated rig's truth variants (`[truth.variants]`, physics the twin does not know) on
//! the default ROM as truth. Guards, per variant, the effect on what the rig records:
//! - all off, or on with neutral parameters (no joint stiffness, no wear, zero tilt, unit
//!   gains): the same blocks and truth, bit for bit, as the plain rig (with impacts);
//! - clamp friction: in a free decay from resonance the 1FU frequency measured on the upper
//!   tip accelerometer drops and its damping rises at large amplitude, and both return to the
//!   linear values at small amplitude; without the variant they do not depend on amplitude;
//! - wear: the clearance grows monotonically, only in sample periods with contact, up to its
//!   cap, and the beams' response in the impact regime grows with it;
//! - tilt: the pairs' initial gaps are the clearance plus the rotated face's offsets, the
//!   tilted edge closes first, and contact starts at a drive where the aligned probes stay
//!   apart;
//! - sensor gain: the mis-calibrated channel records gain x the value within one ADC count,
//!   every other channel and the truth are unchanged bit for bit.

mod default_rom;

use std::f64::consts::PI;

use rigtwin::rig::daq::{DaqBlock, DriveCommand};
use rigtwin::rig::sim::truth::Truth;
use rigtwin::rig::sim::{
    base_acceleration_frf, Beam, ClampFrictionSpec, SensorGainSpec, SimRig, SimRigSpec, TiltSpec,
    TruthSnapshot, TruthTrace, TruthVariants, WearSpec,
};
use rigtwin::rom::Rom;

use default_rom::default_rom;

/// Beam length of the default rig, m.
const L: f64 = 0.3;
/// The paper's clearance, m.
const CLEARANCE: f64 = 2.78e-3 * L;

fn drive(f_hz: f64, amplitude_v: f64, ramp_s: f64) -> DriveCommand {
    DriveCommand {
        frequency_hz: f_hz,
        amplitude_v,
        ramp_s,
    }
}

fn blocks_for(rig: &SimRig, seconds: f64) -> usize {
    (seconds * rig.layout().sample_rate / rig.layout().block_size as f64).ceil() as usize
}

fn run(rig: &mut SimRig, seconds: f64, trace: &mut TruthTrace) -> Vec<DaqBlock> {
    (0..blocks_for(rig, seconds))
        .map(|_| rig.next_block_traced(trace))
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

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Drive amplitude (V) for a base displacement `level` (m) at `omega` (rad/s) with the beams
/// as a rigid mass (as in the impact regime).
fn drive_for_level(rom: &Rom, level: f64) -> f64 {
    let w1 = rom.omega_ref();
    level * w1 * w1 / base_acceleration_frf(&SimRigSpec::default().shaker, &[], w1).abs()
}

/// The truth's state without the variant bookkeeping, as bits.
fn truth_bits(t: &TruthSnapshot) -> Vec<u64> {
    vec![
        t.time.to_bits(),
        t.truth_steps,
        t.base_displacement.to_bits(),
        t.base_velocity.to_bits(),
        t.base_acceleration.to_bits(),
        t.coil_current.to_bits(),
        t.amplifier_output.to_bits(),
        t.clearance.to_bits(),
        t.closed_pairs as u64,
        t.solver_failures,
    ]
}

/// A free decay `x` (sampled at `fs`), cut into groups of `cycles` cycles between upward zero
/// crossings: (tip displacement amplitude `a / w^2`, frequency Hz, damping ratio from the
/// logarithmic decrement of the cycle peaks), in time order.
fn free_decay(x: &[f64], fs: f64, cycles: usize) -> Vec<(f64, f64, f64)> {
    let mut up = Vec::new();
    for k in 1..x.len() {
        if x[k - 1] < 0.0 && x[k] >= 0.0 {
            up.push((k - 1) as f64 + x[k - 1] / (x[k - 1] - x[k]));
        }
    }
    let peaks: Vec<f64> = up
        .windows(2)
        .map(|w| {
            x[w[0].ceil() as usize..w[1].ceil() as usize]
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()))
        })
        .collect();
    (0..peaks.len().saturating_sub(cycles))
        .step_by(cycles)
        .map(|i| {
            let f = cycles as f64 * fs / (up[i + cycles] - up[i]);
            let zeta = (peaks[i] / peaks[i + cycles]).ln() / (2.0 * PI * cycles as f64);
            let a = (peaks[i] * peaks[i + cycles]).sqrt() / (2.0 * PI * f).powi(2);
            (a, f, zeta)
        })
        .collect()
}

#[test]
fn variants_off_or_neutral_give_the_same_bits() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let make = |variants: TruthVariants| {
        let mut spec = SimRigSpec::default();
        spec.truth.variants = variants;
        // A clearance the tips reach within the run: the contact solver and wear are exercised.
        let mut rig = SimRig::new(rom, &spec, 3e-4).unwrap();
        rig.set_drive(drive(f1, 0.08, 0.05)).unwrap();
        let mut trace = TruthTrace::default();
        let blocks = run(&mut rig, 0.5, &mut trace);
        (blocks, rig.truth(), trace)
    };
    let (a, ta, trace) = make(TruthVariants::default());
    let contact = trace.closed_steps.iter().filter(|&&c| c > 0).count();
    assert!(
        contact > 0,
        "no contact: the check would miss the contact solver"
    );
    let neutral = TruthVariants {
        // A neutral modal correction is not bit-neutral (Hz -> rad/s); the unit tests of
        // physics::modal cover it.
        modes: Vec::new(),
        clearance: Some(Default::default()),
        clamp_friction: Some(ClampFrictionSpec {
            stiffness_fraction: 0.0,
            half_slip_tip_amplitude: 1e-5,
            sliders: 16,
            beams: vec![Beam::Lower, Beam::Upper],
        }),
        wear: Some(WearSpec {
            coefficient: 0.0,
            max_growth: None,
        }),
        tilt: Some(TiltSpec {
            angle: 0.0,
            axis: [0.3, 1.0],
        }),
        sensor_gains: ["platform_1", "upper_tip", "vibrometer", "drive_current"]
            .iter()
            .map(|c| SensorGainSpec {
                channel: (*c).into(),
                gain: 1.0,
            })
            .collect(),
    };
    let (b, tb, _) = make(neutral);
    assert!(a == b, "neutral variants changed the blocks");
    assert_eq!(truth_bits(&ta), truth_bits(&tb));
    // The neutral run did run the variants: wear saw the contact's normal impulse.
    println!(
        "{contact} samples with contact; normal contact impulse {:.3e} N s",
        tb.wear_impulse
    );
    assert!(
        tb.wear_impulse > 0.0 && tb.clearance_growth == 0.0,
        "{tb:?}"
    );
    assert_eq!((ta.wear_impulse, ta.joint_dissipation), (0.0, 0.0));
}

#[test]
fn clamp_friction_softens_and_damps_the_1fu_mode_at_large_amplitude() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let half_slip = 1e-4;
    let decay = |variants: TruthVariants| {
        let mut spec = SimRigSpec::default();
        spec.daq.noise_rms.beam_acceleration = 0.0;
        spec.truth.variants = variants;
        // Probes far apart: the beams ring freely.
        let mut rig = SimRig::new(rom, &spec, 0.1).unwrap();
        rig.set_drive(drive(f1, 0.25, 0.2)).unwrap();
        let mut trace = TruthTrace::default();
        run(&mut rig, 4.0, &mut trace);
        rig.set_drive(drive(f1, 0.0, 0.0)).unwrap();
        let blocks = run(&mut rig, 4.0, &mut trace);
        let x = values(&rig, &blocks, "upper_tip");
        // Skip the first 30 ms (the drive's end and the anti-alias filter).
        (
            free_decay(&x[300..], rig.layout().sample_rate, 10),
            rig.truth(),
        )
    };
    let (linear, t_off) = decay(TruthVariants::default());
    let (joint, t_on) = decay(TruthVariants {
        clamp_friction: Some(ClampFrictionSpec {
            stiffness_fraction: 0.2,
            half_slip_tip_amplitude: half_slip,
            sliders: 64,
            beams: vec![Beam::Lower, Beam::Upper],
        }),
        ..TruthVariants::default()
    });
    let show = |name: &str, d: &[(f64, f64, f64)]| {
        println!("{name}: tip amplitude (m), 1FU frequency (Hz), damping ratio per 10 cycles");
        for (a, f, z) in d {
            println!("  {a:.3e}  {f:.3}  {z:.5}");
        }
    };
    show("linear", &linear);
    show("clamp friction", &joint);
    println!(
        "joint dissipation {:.3e} J (off: {})",
        t_on.joint_dissipation, t_off.joint_dissipation
    );

    // Without the variant: frequency and damping independent of the amplitude.
    let (f_lin, z_lin) = (linear[0].1, linear[0].2);
    for &(a, f, z) in &linear {
        assert!((f / f_lin - 1.0).abs() < 2e-4, "linear: {f} Hz at {a:e} m");
        assert!(
            (z / z_lin - 1.0).abs() < 0.05,
            "linear: zeta {z} at {a:e} m"
        );
    }
    // With it: at large amplitude (beyond the half-slip amplitude) softer and more damped ...
    let (a0, f0, z0) = joint[0];
    assert!(a0 > half_slip, "the decay starts at {a0:e} m only");
    assert!(
        f0 < 0.985 * f_lin,
        "1FU at {a0:e} m: {f0} Hz vs linear {f_lin} Hz"
    );
    assert!(
        z0 > 3.0 * z_lin,
        "1FU at {a0:e} m: zeta {z0} vs linear {z_lin}"
    );
    // ... and both fall back monotonically (within the estimate's scatter) ...
    for w in joint.windows(2) {
        assert!(w[1].1 > w[0].1 - 0.02, "frequency {:?} -> {:?}", w[0], w[1]);
    }
    // ... to the linear values once hardly any slider slips (first slip at half_slip / 64).
    let &(a_end, f_end, z_end) = joint.last().unwrap();
    assert!(a_end < 1.5 * half_slip / 64.0, "decay ends at {a_end:e} m");
    assert!((f_end / f_lin - 1.0).abs() < 5e-4, "{f_end} vs {f_lin}");
    assert!((z_end / z_lin - 1.0).abs() < 0.25, "{z_end} vs {z_lin}");
    assert!(t_on.joint_dissipation > 0.0 && t_off.joint_dissipation == 0.0);
}

#[test]
fn wear_grows_the_clearance_under_contact_and_the_response_with_it() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let amp = drive_for_level(rom, 6e-5 * L);
    let cap = 3e-4;
    let session = |variants: TruthVariants| {
        let mut spec = SimRigSpec::default();
        spec.truth.variants = variants;
        let mut rig = SimRig::new(rom, &spec, CLEARANCE).unwrap();
        rig.set_drive(drive(f1, amp, 0.2)).unwrap();
        let mut trace = TruthTrace::default();
        let blocks = run(&mut rig, 4.5, &mut trace);
        let vib = values(&rig, &blocks, "vibrometer");
        (trace, rig.truth(), vib)
    };
    let (plain, t_plain, vib_plain) = session(TruthVariants::default());
    // An exaggerated wear rate so that the cap is reached within the run.
    let (worn, t_worn, vib_worn) = session(TruthVariants {
        wear: Some(WearSpec {
            coefficient: 1e-3,
            max_growth: Some(cap),
        }),
        ..TruthVariants::default()
    });
    println!(
        "normal contact impulse {:.4e} N s, clearance {:.4e} -> {:.4e} m",
        t_worn.wear_impulse, CLEARANCE, t_worn.clearance
    );
    assert!(plain.clearance.iter().all(|&c| c == CLEARANCE));
    assert_eq!(t_plain.clearance_growth, 0.0);

    // Monotonic, only while pairs carry force, up to the cap.
    let c = &worn.clearance;
    let closed = &worn.closed_steps;
    let mut grew = 0;
    for k in 1..c.len() {
        assert!(c[k] >= c[k - 1], "clearance shrank at sample {k}");
        if c[k] > c[k - 1] {
            grew += 1;
            assert!(
                closed[k] > 0 || closed[k - 1] > 0,
                "clearance grew at sample {k} without contact"
            );
        }
    }
    let first_contact = closed.iter().position(|&n| n > 0).unwrap();
    assert!(c[..first_contact].iter().all(|&x| x == CLEARANCE));
    assert_eq!(t_worn.clearance_growth, cap);
    assert_eq!(t_worn.clearance, CLEARANCE + cap);
    assert!(t_worn.wear_impulse * 1e-3 > cap);
    let capped_at = c.iter().position(|&x| x == CLEARANCE + cap).unwrap();
    println!(
        "grew in {grew} of {} samples; cap reached at {:.2} s",
        c.len(),
        worn.time[capped_at]
    );

    // The rig output: in the impact regime the tips travel further before they hit, so the
    // vibrometer's RMS over the last 1.5 s rises with the clearance.
    let n = vib_plain.len();
    let tail = 2 * n / 3;
    let (r_plain, r_worn) = (rms(&vib_plain[tail..]), rms(&vib_worn[tail..]));
    println!("vibrometer RMS over the last 1.5 s: {r_plain:.4} m/s plain, {r_worn:.4} m/s worn");
    assert!(worn.time[capped_at] < worn.time[tail]);
    assert!(r_worn > 1.15 * r_plain, "{r_worn} vs {r_plain}");
}

#[test]
fn tilt_offsets_the_gaps_by_the_geometry_and_closes_the_tilted_edge_first() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let spec = SimRigSpec::default();
    let tilted = |angle: f64| TruthVariants {
        tilt: Some(TiltSpec {
            angle,
            axis: [0.0, 1.0],
        }),
        ..TruthVariants::default()
    };
    let truth = |variants: &TruthVariants, clearance: f64| {
        Truth::new(rom, &spec.shaker, clearance, variants, |l| {
            Ok(0.5 * l.dt_max_open())
        })
        .unwrap()
    };

    // Geometry: at rest every pair's normal gap is the clearance plus -sin(angle) (x_k - x_c)
    // (about +y), x_c the area centroid of the patch.
    let angle = 0.02;
    let t = truth(&tilted(angle), CLEARANCE);
    let n = rom.n_pairs();
    let area: f64 = rom.pair_area.iter().sum();
    let xc = rom
        .pair_position
        .iter()
        .zip(&rom.pair_area)
        .map(|(p, a)| p[0] * a)
        .sum::<f64>()
        / area;
    let mut gaps = vec![0.0; 3 * n];
    t.integrator().gaps(t.state(), &mut gaps).unwrap();
    let (x_min, x_max) = rom
        .pair_position
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p[0]), b.max(p[0]))
        });
    for k in 0..n {
        let expected = CLEARANCE - angle.sin() * (rom.pair_position[k][0] - xc);
        assert!(
            (gaps[3 * k] - expected).abs() < 1e-15,
            "pair {k}: {} vs {expected}",
            gaps[3 * k]
        );
        assert_eq!((gaps[3 * k + 1], gaps[3 * k + 2]), (0.0, 0.0));
    }
    println!(
        "patch x in [{x_min}, {x_max}] m, centroid {xc} m: gaps {:.4e} .. {:.4e} m",
        CLEARANCE - angle.sin() * (x_max - xc),
        CLEARANCE - angle.sin() * (x_min - xc)
    );

    // The first pairs to close lie on the edge the tilt brought down: the tip side for a
    // positive angle, the root side for a negative one.
    for (angle, edge) in [(0.02, x_max), (-0.02, x_min)] {
        let mut t = truth(&tilted(angle), 3e-4);
        let w = 2.0 * PI * f1;
        let mut step = 0u64;
        while t.closed_pairs() == 0 {
            step += 1;
            assert!(step < 2_000_000, "no contact");
            let time = step as f64 * t.dt();
            t.step(0.08 * (w * time).sin() * (time / 0.05).min(1.0));
        }
        let first: Vec<f64> = t
            .state()
            .closed_pairs()
            .iter()
            .map(|&k| rom.pair_position[k][0])
            .collect();
        println!(
            "angle {angle}: first contact at {:.4} s on pairs at x = {first:?}",
            step as f64 * t.dt()
        );
        assert!(
            first.iter().all(|x| (x - edge).abs() < 1e-9),
            "angle {angle}: first closed pairs at x = {first:?}, edge {edge}"
        );
    }

    // On the rig: at a drive where the aligned probes stay apart for 3 s, the tilted ones
    // touch (the contact-resistance channel drops).
    let contact = |variants: TruthVariants| {
        let mut s = spec.clone();
        s.truth.variants = variants;
        let mut rig = SimRig::new(rom, &s, CLEARANCE).unwrap();
        rig.set_drive(drive(f1, 0.017, 0.2)).unwrap();
        let mut trace = TruthTrace::default();
        let blocks = run(&mut rig, 3.0, &mut trace);
        let v = values(&rig, &blocks, "contact_voltage");
        let closed = trace.closed_steps.iter().filter(|&&c| c > 0).count();
        (v.iter().fold(f64::INFINITY, |m, &x| m.min(x)), closed)
    };
    let (v_aligned, closed_aligned) = contact(TruthVariants::default());
    let (v_tilted, closed_tilted) = contact(tilted(0.02));
    println!(
        "0.017 V for 3 s: aligned {closed_aligned} samples with contact (lowest contact \
         voltage {v_aligned:.2} V), tilted 20 mrad {closed_tilted} (lowest {v_tilted:.2} V)"
    );
    assert_eq!(closed_aligned, 0);
    assert!(v_aligned > 4.9, "{v_aligned}");
    assert!(closed_tilted > 0 && v_tilted < 2.5, "{v_tilted}");
}

#[test]
fn sensor_gain_scales_the_recorded_channel_and_nothing_else() {
    let rom = default_rom();
    let f1 = rom.omega_ref() / (2.0 * PI);
    let gains = [("upper_tip", 1.03), ("drive_current", 0.9)];
    let record = |variants: TruthVariants| {
        let mut spec = SimRigSpec::default();
        let n = &mut spec.daq.noise_rms;
        n.platform_acceleration = 0.0;
        n.beam_acceleration = 0.0;
        n.vibrometer = 0.0;
        n.contact_voltage = 0.0;
        n.drive_voltage = 0.0;
        n.drive_current = 0.0;
        spec.truth.variants = variants;
        let mut rig = SimRig::new(rom, &spec, 3e-4).unwrap();
        rig.set_drive(drive(f1, 0.08, 0.05)).unwrap();
        let mut trace = TruthTrace::default();
        let blocks = run(&mut rig, 0.5, &mut trace);
        (rig, blocks, trace)
    };
    let (rig, nominal, trace) = record(TruthVariants::default());
    assert!(trace.closed_steps.iter().any(|&c| c > 0), "no impacts");
    let (rig_g, off, _) = record(TruthVariants {
        sensor_gains: gains
            .iter()
            .map(|(c, g)| SensorGainSpec {
                channel: (*c).into(),
                gain: *g,
            })
            .collect(),
        ..TruthVariants::default()
    });
    // The layout (nominal sensitivity) is unchanged, and so is the truth.
    assert_eq!(rig.layout(), rig_g.layout());
    assert_eq!(truth_bits(&rig.truth()), truth_bits(&rig_g.truth()));
    for (k, ch) in rig.layout().channels.iter().enumerate() {
        let gain = gains.iter().find(|(c, _)| *c == ch.name).map(|(_, g)| *g);
        let a = values(&rig, &nominal, &ch.name);
        let b = values(&rig_g, &off, &ch.name);
        match gain {
            None => {
                let same = nominal
                    .iter()
                    .zip(&off)
                    .all(|(x, y)| x.channel(k) == y.channel(k));
                assert!(same, "{}: changed without a gain", ch.name);
            }
            Some(g) => {
                // Within one count (each run rounds to the nearest count).
                let worst = a
                    .iter()
                    .zip(&b)
                    .map(|(x, y)| (y - g * x).abs())
                    .fold(0.0f64, f64::max);
                let ratio = rms(&b) / rms(&a);
                println!(
                    "{}: recorded / nominal RMS {ratio:.9} (gain {g}), worst deviation from \
                     gain x nominal {:.3} counts",
                    ch.name,
                    worst / ch.scale
                );
                assert!(
                    worst <= (0.5 + 0.5 * g) * ch.scale * (1.0 + 1e-9),
                    "{}",
                    ch.name
                );
                assert!((ratio / g - 1.0).abs() < 1e-6, "{}: {ratio}", ch.name);
            }
        }
    }
}
