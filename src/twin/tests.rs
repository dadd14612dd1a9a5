//! Unit tests of the twin on small synthetic ROMs (fast): the response to a sine base
//! acceleration against the single-mode FRF, the static contact force, the time base, gaps,
//! determinism, bad input, and the task's queue, throttle, skipping and shutdown. The default
//! rig against the simulated rig is in `tests/twin_reproduces_sim_rig.rs`.

use std::f64::consts::PI;
use std::time::{Duration, Instant};

use faer::Mat;

use super::*;
use crate::rig::daq::{ChannelKind, ChannelSpec, DaqBlock, DaqLayout};
use crate::rom::{Rom, RomMeta, RomOutput};
use crate::signal::demodulate;

const FS: f64 = 10240.0;
const BLOCK: usize = 256;

/// Modes at `f_hz` with damping `zeta` and participation `beta`; one contact pair whose normal
/// gap closes as mode 0 moves up (`g_n = clearance - eta_0 + 1e-6 lambda_n`); all four beam
/// sensors read mode 0 with unit weight.
fn stub_rom(f_hz: &[f64], zeta: f64, beta: f64, clearance: f64) -> Rom {
    let m = f_hz.len();
    let outputs = TWIN_SENSORS
        .iter()
        .map(|n| RomOutput {
            name: (*n).into(),
            c_eta: (0..m).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect(),
            c_lambda: vec![0.0; 3],
        })
        .collect();
    Rom {
        meta: RomMeta::default(),
        omega: f_hz.iter().map(|f| 2.0 * PI * f).collect(),
        damping_ratio: vec![zeta; m],
        labels: (0..m).map(|i| format!("m{i}")).collect(),
        phi_g: Mat::from_fn(3, m, |r, i| if r == 0 && i == 0 { -1.0 } else { 0.0 }),
        g_res: Mat::from_fn(3, 3, |i, j| if i == j { 1e-6 } else { 0.0 }),
        k_gg: Mat::from_fn(3, 3, |i, j| if i == j { 1e6 } else { 0.0 }),
        beta: vec![beta; m],
        pair_area: vec![1e-6],
        pair_position: vec![[0.3, 0.0, 0.0]],
        clearance,
        friction: 0.4,
        outputs,
    }
}

/// Two platform accelerometers (24 bit, 100 m/s^2 full scale) and a vibrometer.
fn layout() -> DaqLayout {
    let half = 2f64.powi(23);
    let ch = |name: &str, kind, range: f64| ChannelSpec {
        name: name.into(),
        kind,
        scale: range / half,
        full_scale_counts: (half - 1.0) as i32,
    };
    DaqLayout {
        sample_rate: FS,
        block_size: BLOCK,
        channels: vec![
            ch("vibrometer", ChannelKind::Vibrometer, 2.0),
            ch("platform_1", ChannelKind::PlatformAcceleration, 100.0),
            ch("platform_2", ChannelKind::PlatformAcceleration, 100.0),
        ],
    }
}

/// Block `seq` of a stream whose base acceleration is `accel(t)` (m/s^2), the two platform
/// channels reading it with opposite rounding offsets.
fn block(layout: &DaqLayout, seq: u64, accel: &dyn Fn(f64) -> f64) -> DaqBlock {
    let first = seq * BLOCK as u64;
    let mut counts = vec![0; 3 * BLOCK];
    for i in 0..BLOCK {
        let t = (first + i as u64) as f64 / FS;
        let a = accel(t);
        for k in 1..3 {
            let s = layout.channels[k].scale;
            counts[k * BLOCK + i] = (a / s + if k == 1 { 0.25 } else { -0.25 }).round() as i32;
        }
    }
    DaqBlock {
        seq,
        first_sample: first,
        time: first as f64 / FS,
        len: BLOCK,
        counts,
    }
}

fn sine(amplitude: f64, f_hz: f64) -> impl Fn(f64) -> f64 {
    move |t| amplitude * (2.0 * PI * f_hz * t).sin()
}

fn upper_tip(blocks: &[TwinBlock]) -> Vec<f64> {
    blocks.iter().flat_map(|b| b.upper_tip().to_vec()).collect()
}

#[test]
fn sine_response_matches_the_single_mode_frf() {
    let (f0, zeta, beta) = (50.0, 0.01, 0.5);
    let rom = stub_rom(&[f0], zeta, beta, 1.0);
    let lay = layout();
    let spec = TwinSpec::default();
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap();
    // 1000 x 50 / 10240 = 4.88 -> 5 steps per sample.
    assert_eq!(twin.steps_per_sample(), 5);
    for f in [35.0, 50.0, 80.0] {
        twin.reset();
        let a = sine(2.0, f);
        // 4 s: ten decay times 1 / (zeta w0) of the transient, then the last second.
        let n_blocks = (4.0 * FS / BLOCK as f64) as u64;
        let out: Vec<TwinBlock> = (0..n_blocks)
            .map(|s| twin.push_block(&block(&lay, s, &a)).unwrap())
            .collect();
        let v = upper_tip(&out);
        let keep = FS as usize;
        let t0 = (v.len() - keep) as f64 / FS;
        let (w, w0) = (2.0 * PI * f, 2.0 * PI * f0);
        let h = demodulate(&v[v.len() - keep..], 1.0 / FS, w, t0).unwrap();
        // eta'' + 2 zeta w0 eta' + w0^2 eta = -beta a: |eta'| = w beta A / |w0^2 - w^2 + 2i zeta w0 w|.
        let expected =
            w * beta * 2.0 / ((w0 * w0 - w * w).powi(2) + (2.0 * zeta * w0 * w).powi(2)).sqrt();
        let e = h.magnitude / expected - 1.0;
        println!(
            "{f} Hz: {:.6e} m/s vs FRF {expected:.6e} ({e:+.2e})",
            h.magnitude
        );
        assert!(e.abs() < 1e-3, "{f} Hz: {} vs {expected}", h.magnitude);
        assert!(out.iter().all(|b| !b.contact.iter().any(|&c| c)));
    }
}

#[test]
fn held_contact_carries_the_static_force() {
    // A constant base acceleration pushes mode 0 up against the stop at 1 mm:
    // w0^2 eta = -lambda_n - beta a, eta = clearance + 1e-6 lambda_n.
    let (f0, beta, clearance, a) = (50.0, 0.5, 1e-3, -400.0);
    let rom = stub_rom(&[f0], 0.02, beta, clearance);
    let lay = layout();
    let mut twin = Twin::new(
        &TwinModel::nominal(&rom),
        &TwinSpec::default(),
        &lay,
        clearance,
    )
    .unwrap();
    let n_blocks = (2.0 * FS / BLOCK as f64) as u64;
    let out: Vec<TwinBlock> = (0..n_blocks)
        .map(|s| twin.push_block(&block(&lay, s, &|_| a)).unwrap())
        .collect();
    let w2 = (2.0 * PI * f0).powi(2);
    let expected = (-beta * a - w2 * clearance) / (1.0 + w2 * 1e-6);
    let last = out.last().unwrap();
    let f = last.normal_force[BLOCK - 1];
    println!("static normal force {f:.6} N, expected {expected:.6} N");
    assert!(last.contact.iter().all(|&c| c));
    assert!((f / expected - 1.0).abs() < 1e-6, "{f} vs {expected}");
    assert!(last
        .tangential_force
        .iter()
        .all(|&t| t.abs() < 1e-9 * expected));
    assert!(last.upper_tip().iter().all(|v| v.abs() < 1e-6));
    assert_eq!(twin.counters().solver_failures, 0);
}

#[test]
fn output_sample_i_belongs_to_input_sample_i() {
    // A base acceleration step at sample 300 (inside block 1): the twin is at rest up to
    // sample 300 exactly, and starts moving at it (the steps before it ramp in).
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 1.0).unwrap();
    let step = |t: f64| if t >= 300.0 / FS - 1e-12 { 10.0 } else { 0.0 };
    let b0 = twin.push_block(&block(&lay, 0, &step)).unwrap();
    let b1 = twin.push_block(&block(&lay, 1, &step)).unwrap();
    assert_eq!((b1.seq, b1.first_sample, b1.len), (1, 256, 256));
    assert_eq!(b1.time, 256.0 / FS);
    assert!(b0.upper_tip().iter().all(|&v| v == 0.0));
    let v = b1.upper_tip();
    let i = 300 - 256;
    assert!(v[..i].iter().all(|&x| x == 0.0));
    // Sample 300 already moves (ramp from a_299 = 0 to a_300 = 10 over its steps); the
    // velocity is negative (-beta a pushes mode 0 down).
    assert!(v[i] < 0.0 && v[i + 1] < v[i], "{:?}", &v[i - 1..i + 3]);
    assert_eq!(twin.time(), Some(512.0 / FS));
    assert_eq!(twin.next_sample(), Some(512));
}

/// The bits of the blocks' velocities and contact forces, for bit-for-bit comparisons.
fn bits(blocks: &[TwinBlock]) -> Vec<u64> {
    blocks
        .iter()
        .flat_map(|b| {
            b.velocity
                .iter()
                .chain(&b.normal_force)
                .chain(&b.tangential_force)
        })
        .map(|x| x.to_bits())
        .collect()
}

#[test]
fn same_blocks_give_the_same_bits_with_impacts() {
    let rom = stub_rom(&[50.0, 400.0], 0.01, 0.5, 2e-4);
    let lay = layout();
    let a = sine(5.0, 50.0);
    let blocks: Vec<DaqBlock> = (0..80).map(|s| block(&lay, s, &a)).collect();
    let run = || {
        let mut twin =
            Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 2e-4).unwrap();
        let out: Vec<TwinBlock> = blocks.iter().map(|b| twin.push_block(b).unwrap()).collect();
        (out, twin.counters())
    };
    let (a1, c1) = run();
    let (a2, c2) = run();
    let contact = a1.iter().flat_map(|b| &b.contact).filter(|&&c| c).count();
    println!("{contact} samples with contact, {c1:?}");
    assert!(
        contact > 100,
        "no impacts: the check would miss the contact solver"
    );
    assert!(a1.iter().any(|b| b.normal_force.iter().any(|&f| f > 0.0)));
    assert_eq!(c1, c2);
    assert_eq!(bits(&a1), bits(&a2));
    assert_eq!(a1, a2);
}

#[test]
fn gaps_are_reported_and_out_of_order_blocks_rejected() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let a = sine(2.0, 50.0);
    for after_gap in [AfterGap::KeepState, AfterGap::RestartAtRest] {
        let spec = TwinSpec {
            after_gap,
            ..TwinSpec::default()
        };
        let mut twin = Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap();
        for s in 0..20 {
            assert_eq!(twin.push_block(&block(&lay, s, &a)).unwrap().gap, None);
        }
        // Blocks 20..=22 lost.
        let b = twin.push_block(&block(&lay, 23, &a)).unwrap();
        let gap = b.gap.expect("gap reported");
        assert_eq!(gap.from_sample, 20 * 256);
        assert_eq!(gap.samples, 3 * 256);
        assert_eq!(gap.blocks, 3);
        assert_eq!(gap.from_time, 20.0 * 256.0 / FS);
        assert_eq!(gap.restarted, after_gap == AfterGap::RestartAtRest);
        // Peak over the first 60 samples (more than a quarter period).
        let peak = b.upper_tip()[..60]
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        match after_gap {
            // Still swinging at the level built up over 20 blocks (about 0.12 m/s).
            AfterGap::KeepState => assert!(peak > 0.05, "{peak}"),
            // From rest: 6 ms of a 2 m/s^2 drive reach at most beta a t = 6e-3 m/s.
            AfterGap::RestartAtRest => assert!(peak < 0.01, "{peak}"),
        }
        assert_eq!(twin.counters().gaps, 1);
        // A repeated block is rejected and changes nothing.
        let before = twin.clone();
        let err = twin.push_block(&block(&lay, 23, &a)).unwrap_err();
        assert!(err.to_string().contains("out of order"), "{err}");
        assert_eq!(twin.counters(), before.counters());
        let x = twin.push_block(&block(&lay, 24, &a)).unwrap();
        let mut y = before.clone();
        assert_eq!(x, y.push_block(&block(&lay, 24, &a)).unwrap());
    }
}

#[test]
fn bad_input_gives_clear_errors() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let spec = TwinSpec::default();

    // No platform accelerometers.
    let mut no_platform = lay.clone();
    no_platform
        .channels
        .retain(|c| c.kind != ChannelKind::PlatformAcceleration);
    let msg = Twin::new(&TwinModel::nominal(&rom), &spec, &no_platform, 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("no platform accelerometer") && msg.contains("vibrometer"),
        "{msg}"
    );

    // A block of the wrong shape.
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap();
    let mut b = block(&lay, 0, &|_| 0.0);
    b.counts.pop();
    let msg = twin.push_block(&b).unwrap_err().to_string();
    assert!(
        msg.contains("block 0: 767 counts, expected 3 channels x 256 samples"),
        "{msg}"
    );
    let empty = DaqBlock {
        len: 0,
        counts: vec![],
        ..b.clone()
    };
    assert!(twin
        .push_block(&empty)
        .unwrap_err()
        .to_string()
        .contains("no samples"));
    assert_eq!(twin.next_sample(), None);

    // A twin step beyond the open stability limit: a mode at 5 kHz needs
    // dt < 2 / (2 pi 5000) = 6.4e-5 s, one step per sample is 9.8e-5 s.
    let stiff = stub_rom(&[50.0, 5000.0], 0.01, 0.5, 1.0);
    let one = TwinSpec {
        steps_per_sample: Some(1),
        ..TwinSpec::default()
    };
    let msg = Twin::new(&TwinModel::nominal(&stiff), &one, &lay, 1.0)
        .unwrap_err()
        .to_string();
    println!("{msg}");
    assert!(
        msg.contains("twin.steps_per_sample = 1")
            && msg.contains("open stability limit")
            && msg.contains("use twin.steps_per_sample >= 2"),
        "{msg}"
    );
    let coarse = TwinSpec {
        steps_per_reference_period: 100.0,
        ..TwinSpec::default()
    };
    let msg = Twin::new(&TwinModel::nominal(&stiff), &coarse, &lay, 1.0)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("twin.steps_per_reference_period = 100 (-> 1 steps per sample)"),
        "{msg}"
    );
    let two = TwinSpec {
        steps_per_sample: Some(2),
        ..TwinSpec::default()
    };
    assert!(Twin::new(&TwinModel::nominal(&stiff), &two, &lay, 1.0).is_ok());

    // A ROM without the beam sensors, a bad clearance.
    let mut blind = rom.clone();
    blind.outputs.retain(|o| o.name != "upper_tip");
    let msg = Twin::new(&TwinModel::nominal(&blind), &spec, &lay, 1.0)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("no output \"upper_tip\""), "{msg}");
    assert!(Twin::new(&TwinModel::nominal(&rom), &spec, &lay, f64::NAN).is_err());
    assert!(twin.set_clearance(f64::INFINITY).is_err());
}

/// Polls the receiver until the task has processed everything and returns the blocks.
fn collect(rx: &mut TwinReceiver) -> Vec<TwinBlock> {
    let mut out = Vec::new();
    while let Ok(ev) = rx.try_recv() {
        match ev {
            TwinEvent::Block(b) => out.push(b),
            TwinEvent::Error { seq, message } => panic!("block {seq}: {message}"),
            TwinEvent::State { .. } => {}
        }
    }
    out
}

#[test]
fn task_output_equals_the_sync_core() {
    let rom = stub_rom(&[50.0, 400.0], 0.01, 0.5, 2e-4);
    let lay = layout();
    let a = sine(5.0, 50.0);
    let blocks: Vec<DaqBlock> = (0..40).map(|s| block(&lay, s, &a)).collect();
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 2e-4).unwrap();
    let sync: Vec<TwinBlock> = blocks.iter().map(|b| twin.push_block(b).unwrap()).collect();

    let spec = TwinSpec::default();
    let (mut task, mut rx) = TwinTask::spawn(
        Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 2e-4).unwrap(),
        &spec,
    )
    .unwrap();
    for b in &blocks {
        assert_eq!(task.push(b).unwrap(), Pushed::Queued);
    }
    let status = task.finish().unwrap();
    assert!(!status.running);
    assert_eq!(status.blocks_processed, 40);
    assert_eq!(status.blocks_skipped, 0);
    assert_eq!(status.lag_s, 0.0);
    assert_eq!(status.steps, 40 * 256 * 5);
    assert!(status.steps_per_s > 0.0 && status.realtime_factor > 0.0);
    assert_eq!(collect(&mut rx), sync);
    assert!(task.push(&blocks[0]).is_err());
}

#[test]
fn task_clearance_applies_from_the_next_block() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let a = sine(5.0, 50.0);
    let blocks: Vec<DaqBlock> = (0..30).map(|s| block(&lay, s, &a)).collect();
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 1.0).unwrap();
    let mut sync = Vec::new();
    let spec = TwinSpec::default();
    let (mut task, mut rx) = TwinTask::spawn(twin.clone(), &spec).unwrap();
    for (s, b) in blocks.iter().enumerate() {
        if s == 20 {
            twin.set_clearance(2e-4).unwrap();
            task.set_clearance(2e-4).unwrap();
        }
        sync.push(twin.push_block(b).unwrap());
        task.push(b).unwrap();
    }
    task.finish().unwrap();
    let out = collect(&mut rx);
    assert!(out[..20].iter().all(|b| !b.contact.contains(&true)));
    assert!(out[20..].iter().any(|b| b.contact.contains(&true)));
    assert_eq!(out, sync);
    assert!(task.set_clearance(f64::NAN).is_err());
}

#[test]
fn throttled_task_falls_behind_without_blocking_the_producer() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let a = sine(2.0, 50.0);
    // 4 wall seconds per data second: 100 ms per 25 ms block; a queue of 2 blocks.
    let spec = TwinSpec {
        queue_blocks: 2,
        throttle: 4.0,
        ..TwinSpec::default()
    };
    let (mut task, mut rx) = TwinTask::spawn(
        Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap(),
        &spec,
    )
    .unwrap();
    let blocks: Vec<DaqBlock> = (0..60).map(|s| block(&lay, s, &a)).collect();

    // A burst of 40 blocks (1 s of data): a blocking producer would wait about 4 s.
    let t = Instant::now();
    let mut worst = Duration::ZERO;
    let mut outcomes = Vec::new();
    for b in &blocks[..40] {
        let t1 = Instant::now();
        outcomes.push(task.push(b).unwrap());
        worst = worst.max(t1.elapsed());
    }
    let producer = t.elapsed();
    let status = task.status();
    println!("40 pushes in {producer:?} (worst {worst:?}); {status:?}");
    assert!(producer < Duration::from_millis(500), "{producer:?}");
    let queued = outcomes.iter().filter(|o| **o == Pushed::Queued).count();
    assert!((2..=4).contains(&queued), "{queued} queued");
    let first_skip = outcomes
        .iter()
        .position(|o| matches!(o, Pushed::Skipped { first: true, .. }))
        .unwrap();
    assert_eq!(first_skip, queued);
    assert!(status.behind);
    assert_eq!(status.blocks_skipped, (40 - queued) as u64);
    assert_eq!(status.samples_skipped, 256 * (40 - queued) as u64);
    assert_eq!(status.last_skipped_seq, Some(39));
    assert_eq!(status.input_time, 40.0 * 256.0 / FS);
    assert!(status.lag_s > 0.8, "lag {}", status.lag_s);
    assert!(status.queue_depth <= 2);

    // Once the queue has drained the task takes blocks again, and the twin reports the gap.
    let t = Instant::now();
    while task.status().queue_depth > 0 || task.status().blocks_processed < queued as u64 {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the twin never drained its queue"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(task.push(&blocks[40]).unwrap(), Pushed::Queued);
    assert!(!task.status().behind);
    let status = task.finish().unwrap();
    println!("final: {status:?}");
    assert_eq!(status.blocks_processed, queued as u64 + 1);
    assert_eq!(status.gaps, 1);
    assert_eq!(status.lag_s, 0.0);
    assert!(status.realtime_factor < 0.3, "{}", status.realtime_factor);
    let out = collect(&mut rx);
    let resumed = out.last().unwrap();
    assert_eq!(resumed.seq, 40);
    assert_eq!(
        resumed.gap,
        Some(TwinGap {
            from_sample: queued as u64 * 256,
            samples: (40 - queued) as u64 * 256,
            blocks: (40 - queued) as u64,
            from_time: queued as f64 * 256.0 / FS,
            restarted: false,
        })
    );
}

#[test]
fn abort_discards_the_queue_and_drop_joins() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let spec = TwinSpec {
        queue_blocks: 8,
        throttle: 2.0,
        ..TwinSpec::default()
    };
    let (mut task, _rx) = TwinTask::spawn(
        Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap(),
        &spec,
    )
    .unwrap();
    for s in 0..8 {
        task.push(&block(&lay, s, &|_| 0.0)).unwrap();
    }
    let t = Instant::now();
    let status = task.abort().unwrap();
    println!("abort after {:?}: {status:?}", t.elapsed());
    assert!(status.blocks_discarded >= 6, "{status:?}");
    assert_eq!(status.blocks_processed + status.blocks_discarded, 8);
    assert!(!status.running);

    // Wrong shapes and order are refused on the producer side.
    let (mut task, _rx) = TwinTask::spawn(
        Twin::new(&TwinModel::nominal(&rom), &spec, &lay, 1.0).unwrap(),
        &spec,
    )
    .unwrap();
    let mut b = block(&lay, 0, &|_| 0.0);
    task.push(&b).unwrap();
    let msg = task.push(&b).unwrap_err().to_string();
    assert!(msg.contains("out of order"), "{msg}");
    b.seq = 1;
    b.first_sample = 256;
    b.counts.truncate(10);
    assert!(task.push(&b).unwrap_err().to_string().contains("10 counts"));
    drop(task);
}

#[test]
fn task_status_counts_only_its_own_work() {
    // A twin that ran (settled) before it was handed to the task.
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let a = sine(2.0, 50.0);
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 1.0).unwrap();
    for s in 0..5 {
        twin.push_block(&block(&lay, s, &a)).unwrap();
    }
    let spec = TwinSpec::default();
    let (mut task, mut rx) = TwinTask::spawn(twin, &spec).unwrap();
    for s in 5..8 {
        task.push(&block(&lay, s, &a)).unwrap();
    }
    let status = task.finish().unwrap();
    assert_eq!(status.blocks_processed, 3);
    assert_eq!(status.steps, 3 * 256 * 5);
    assert_eq!(status.gaps, 0);
    assert_eq!(status.twin_time, 8.0 * 256.0 / FS);
    assert_eq!(status.input_time, 8.0 * 256.0 / FS);
    assert_eq!(collect(&mut rx).len(), 3);
}

#[test]
fn outputs_round_trip_through_json_and_have_schemas() {
    let rom = stub_rom(&[50.0], 0.01, 0.5, 1.0);
    let lay = layout();
    let a = sine(2.0, 50.0);
    let mut twin = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 1.0).unwrap();
    twin.push_block(&block(&lay, 0, &a)).unwrap();
    let b = twin.push_block(&block(&lay, 2, &a)).unwrap();
    assert!(b.gap.is_some());
    for ev in [
        TwinEvent::Block(b),
        TwinEvent::Error {
            seq: 3,
            message: "bad".into(),
        },
    ] {
        let json = serde_json::to_string(&ev).unwrap();
        assert_eq!(serde_json::from_str::<TwinEvent>(&json).unwrap(), ev);
    }
    let status = TwinStatus {
        lag_s: 0.5,
        last_skipped_seq: Some(7),
        ..TwinStatus::default()
    };
    let json = serde_json::to_string(&status).unwrap();
    assert_eq!(serde_json::from_str::<TwinStatus>(&json).unwrap(), status);

    let block_schema = serde_json::to_string(&schemars::schema_for!(TwinBlock)).unwrap();
    for key in [
        "velocity",
        "contact",
        "normal_force",
        "solver_failures",
        "gap",
        "from_sample",
    ] {
        assert!(
            block_schema.contains(&format!("\"{key}\"")),
            "{key}: {block_schema}"
        );
    }
    let status_schema = serde_json::to_string(&schemars::schema_for!(TwinStatus)).unwrap();
    for key in ["lag_s", "queue_depth", "blocks_skipped", "steps_per_s"] {
        assert!(status_schema.contains(&format!("\"{key}\"")), "{key}");
    }
    let event_schema = serde_json::to_string(&schemars::schema_for!(TwinEvent)).unwrap();
    assert!(event_schema.contains("\"kind\""), "{event_schema}");
}

/// A twin block whose channel `k` at sample `s` is `k + s / 1000` (contact on odd samples).
fn marked_block(first_sample: u64, len: usize) -> TwinBlock {
    let v = |k: usize, i: usize| k as f64 + (first_sample + i as u64) as f64 / 1000.0;
    TwinBlock {
        seq: first_sample / len as u64,
        first_sample,
        time: first_sample as f64 / FS,
        len,
        velocity: (0..4)
            .flat_map(|k| (0..len).map(move |i| v(k, i)))
            .collect(),
        base_acceleration: (0..len).map(|i| v(30, i)).collect(),
        contact: (0..len)
            .map(|i| (first_sample + i as u64) % 2 == 1)
            .collect(),
        normal_force: (0..len).map(|i| v(10, i)).collect(),
        tangential_force: (0..len).map(|i| v(20, i)).collect(),
        solver_failures: vec![1; len],
        gap: None,
        restarts: Vec::new(),
    }
}

#[test]
fn logged_samples_keep_the_sensor_order_and_cut_record_windows() {
    assert_eq!(
        TWIN_SENSORS,
        ["lower_tip", "lower_mid", "upper_tip", "upper_mid"],
        "TwinSamples names its arrays in this order"
    );
    let blocks: Vec<TwinSamples> = [0u64, 8, 16]
        .iter()
        .map(|&f| TwinSamples::from(&marked_block(f, 8)))
        .collect();
    let s = &blocks[1];
    assert_eq!(s.lower_tip[2], 0.0 + 10.0 / 1000.0);
    assert_eq!(s.upper_tip[2], (2.0 + 10.0 / 1000.0) as f32);
    assert_eq!(s.upper_mid[0], (3.0 + 8.0 / 1000.0) as f32);
    assert_eq!(s.contact[..2], [0, 1]);
    assert_eq!(s.solver_failures, 8);

    // A window across block boundaries, blocks in any order.
    let shuffled = [blocks[2].clone(), blocks[0].clone(), blocks[1].clone()];
    let t = TwinTrace::cut(&shuffled, 5, 14).unwrap();
    assert_eq!(t.upper_tip.len(), 14);
    for (j, s) in (5..19).enumerate() {
        assert_eq!(t.upper_tip[j], f64::from((2.0 + s as f64 / 1000.0) as f32));
        assert_eq!(t.lower_tip[j], f64::from((s as f64 / 1000.0) as f32));
        assert_eq!(t.contact[j], s % 2 == 1);
        assert_eq!(
            t.normal_force[j],
            f64::from((10.0 + s as f64 / 1000.0) as f32)
        );
    }
    // A missing block (skipped by the twin) or a window past the end: no trace.
    assert!(TwinTrace::cut(&[blocks[0].clone(), blocks[2].clone()], 5, 14).is_none());
    assert!(TwinTrace::cut(&blocks, 20, 8).is_none());
    // A malformed logged block is not used.
    let mut bad = blocks[1].clone();
    bad.upper_tip.pop();
    assert!(TwinTrace::cut(&[blocks[0].clone(), bad, blocks[2].clone()], 5, 14).is_none());
}

#[test]
fn a_restored_state_continues_bit_for_bit_and_another_model_is_refused() {
    let rom = stub_rom(&[50.0, 400.0], 0.01, 0.5, 2e-4);
    let lay = layout();
    let a = sine(5.0, 50.0);
    let blocks: Vec<DaqBlock> = (0..80).map(|s| block(&lay, s, &a)).collect();
    // Wear acting: the clearance moves with the contact impulse, so the effects' state matters.
    let extensions = crate::config::PhysicsSpec {
        wear: Some(crate::config::physics::WearSpec {
            coefficient: 1e-3,
            max_growth: Some(2e-5),
        }),
        ..Default::default()
    };
    let model = TwinModel::nominal(&rom).with_extensions(extensions);
    let new = || Twin::new(&model, &TwinSpec::default(), &lay, 2e-4).unwrap();
    let mut full = new();
    assert_eq!(full.state(), None, "no state before the first block");
    let mut states = Vec::new();
    let mut out = Vec::new();
    for b in &blocks {
        states.push(full.state());
        out.push(full.push_block(b).unwrap());
    }
    assert!(out.iter().flat_map(|b| &b.contact).any(|&c| c));
    for k in [1, 23, 57] {
        let state = states[k].clone().unwrap();
        // Through JSON, as the log keeps it: every number round-trips.
        let text = serde_json::to_string(&state).unwrap();
        let back: TwinState = serde_json::from_str(&text).unwrap();
        assert_eq!(back, state);
        let mut warm = new();
        warm.set_state(&back).unwrap();
        for (b, expected) in blocks[k..].iter().zip(&out[k..]) {
            let got = warm.push_block(b).unwrap();
            assert_eq!(
                bits(std::slice::from_ref(&got)),
                bits(std::slice::from_ref(expected)),
                "block {} from state {k}",
                b.seq
            );
            assert_eq!(got.contact, expected.contact);
        }
        assert_eq!(warm.clearance().to_bits(), full.clearance().to_bits());
    }
    assert!(full.clearance() > 2e-4, "wear did not act");

    // Another model (no wear): refused, and the twin is unchanged.
    let state = states[23].clone().unwrap();
    let mut other = Twin::new(&TwinModel::nominal(&rom), &TwinSpec::default(), &lay, 2e-4).unwrap();
    let err = other.set_state(&state).unwrap_err().to_string();
    assert!(err.contains("another model"), "{err}");
    assert_eq!(other.next_sample(), None);
    // A state that does not fit: refused with the field named.
    let mut bad = state.clone();
    bad.rom = crate::sim::State::at_rest(3, 1, 0.0);
    let err = new().set_state(&bad).unwrap_err().to_string();
    assert!(err.contains("eta"), "{err}");
    let mut bad = state;
    bad.contact_voltage = f64::NAN;
    let err = new().set_state(&bad).unwrap_err().to_string();
    assert!(err.contains("contact_voltage"), "{err}");
}

/// The discretisation member starts at rest with the clearance and wear the twin had
/// (`Twin::reset_keeping_geometry`), on a ROM of another size; a state of other extensions is
/// refused.
#[test]
fn a_finer_member_starts_at_rest_with_the_twins_clearance_and_wear() {
    let rom = stub_rom(&[50.0, 400.0], 0.01, 0.5, 2e-4);
    let finer = stub_rom(&[50.0, 400.0, 900.0], 0.01, 0.5, 2e-4);
    let lay = layout();
    let a = sine(5.0, 50.0);
    let blocks: Vec<DaqBlock> = (0..60).map(|s| block(&lay, s, &a)).collect();
    let extensions = crate::config::PhysicsSpec {
        wear: Some(crate::config::physics::WearSpec {
            coefficient: 1e-3,
            max_growth: Some(2e-5),
        }),
        ..Default::default()
    };
    let model = TwinModel::nominal(&rom).with_extensions(extensions.clone());
    let mut twin = Twin::new(&model, &TwinSpec::default(), &lay, 2e-4).unwrap();
    for b in &blocks {
        twin.push_block(b).unwrap();
    }
    twin.set_clearance(2.5e-4).unwrap();
    let state = twin.state().unwrap();
    assert!(twin.clearance() > 2.5e-4, "wear did not act");
    let fine_model = TwinModel::nominal(&finer).with_extensions(extensions);
    let fine_spec = TwinSpec {
        steps_per_sample: Some(13),
        ..TwinSpec::default()
    };
    let mut fine = Twin::new(&fine_model, &fine_spec, &lay, 2e-4).unwrap();
    fine.push_block(&blocks[0]).unwrap();
    fine.reset_keeping_geometry(&state).unwrap();
    assert_eq!(fine.clearance().to_bits(), twin.clearance().to_bits());
    assert_eq!(fine.next_sample(), None, "at rest, ready for any block");
    // At rest: its first block from there is a run from rest.
    let mut fresh = Twin::new(&fine_model, &fine_spec, &lay, 2e-4).unwrap();
    fresh.reset_keeping_geometry(&state).unwrap();
    let (x, y) = (
        fine.push_block(&blocks[7]).unwrap(),
        fresh.push_block(&blocks[7]).unwrap(),
    );
    assert_eq!(bits(&[x]), bits(&[y]));
    // Other extensions (no wear): refused.
    let mut other = Twin::new(&TwinModel::nominal(&finer), &fine_spec, &lay, 2e-4).unwrap();
    let err = other
        .reset_keeping_geometry(&state)
        .unwrap_err()
        .to_string();
    assert!(err.contains("wear"), "{err}");
}

/// The discretisation member's difference enters each model spread in quadrature and the
/// scores follow; a feature the member lacks keeps its spread.
#[test]
fn the_discretisation_member_widens_the_model_spread_in_quadrature() {
    use crate::signal::Feature;
    let tol = crate::twin::ComparisonTolerance {
        relative: 0.0,
        contact_fraction: 0.0,
        impacts_per_period: 0.0,
    };
    let f = |channel: &str, feature: &str, value: f64, spread: f64| Feature {
        channel: channel.into(),
        feature: feature.into(),
        value,
        spread: Some(spread),
    };
    let c = crate::twin::TwinComparison::synthetic(
        &[
            f("upper_tip", "rms", 10.0, 0.3),
            f("contact", "contact_fraction", 0.004, 0.0003),
        ],
        &[
            f("upper_tip", "rms", 12.0, 0.4),
            f("contact", "contact_fraction", 0.008, 0.0004),
        ],
        &tol,
    );
    assert!((c.features[0].score - 2.0 / 0.5).abs() < 1e-12);
    let d = c.with_discretisation(&[f("upper_tip", "rms", 10.8, 0.2)], &tol);
    assert!(d.discretisation_member);
    // |12 - 10.8| = 1.2 joins the model's 0.4: sqrt(0.16 + 1.44) = 1.265.
    let s = d.features[0].model_spread.unwrap();
    assert!((s - 1.6f64.sqrt()).abs() < 1e-12, "{s}");
    assert!((d.features[0].score - 2.0 / (0.09f64 + 1.6).sqrt()).abs() < 1e-12);
    assert_eq!(d.features[1].model_spread, Some(0.0004));
    assert_eq!(d.max_score, Some(d.features[1].score));
}

/// Another draw of the model scored against a comparison's spreads: its value replaces the
/// model's, both spreads and the tolerance's floor stay; the same value gives the same score.
#[test]
fn another_draw_is_scored_against_the_comparisons_spreads() {
    use crate::signal::Feature;
    let tol = crate::twin::ComparisonTolerance {
        relative: 0.1,
        contact_fraction: 0.0,
        impacts_per_period: 0.0,
    };
    let f = |value: f64, spread: f64| Feature {
        channel: "upper_tip".into(),
        feature: "rms".into(),
        value,
        spread: Some(spread),
    };
    let c = crate::twin::TwinComparison::synthetic(&[f(10.0, 0.3)], &[f(12.0, 0.4)], &tol);
    let same = c.features[0].with_model_value(12.0, &tol);
    assert_eq!(same, c.features[0]);
    let d = c.features[0].with_model_value(8.0, &tol);
    assert_eq!(
        (d.model, d.model_spread, d.measured_spread),
        (8.0, Some(0.4), Some(0.3))
    );
    // |8 - 10| against sqrt(0.3^2 + 0.4^2 + (0.1 x 10)^2).
    assert!(
        (d.score - 2.0 / 1.25f64.sqrt()).abs() < 1e-12,
        "{}",
        d.score
    );
}

/// Like with like for noise: the vibrometer reads the upper tip with white noise 3 % of its
/// amplitude, which raises the measured per-period amplitudes by about 4 % (the module docs of
/// `crate::signal::noise`); a model that is the rig exactly scores that as a mismatch unless
/// the measurement's noise floor is laid on its channels, as the comparison does.
#[test]
fn the_measured_noise_floor_is_laid_on_the_model() {
    use crate::control::summary::summarize;
    use crate::control::StepInfo;
    let lay = crate::rig::channels::layout(&crate::config::DaqSpec::default());
    let dt = lay.dt();
    let (f, periods) = (40.0, 60); // 256 samples a period
    let n = periods * 256;
    let w = 2.0 * PI * f;
    let (a_b, v) = (2.0, 0.01); // base acceleration, relative tip velocity amplitudes
                                // Relative velocities of the twin's sensors (lower_tip, lower_mid, upper_tip, upper_mid).
    let phase = [0.5, 0.5, 0.0, 0.0];
    let scale = [1.0, 0.5, 1.0, 0.5];
    let rel = |k: usize, t: f64| scale[k] * v * (w * t + phase[k]).sin();
    let d_rel = |k: usize, t: f64| scale[k] * v * w * (w * t + phase[k]).cos();
    let mut noise = crate::signal::noise::Gaussian::new(9);
    let sigma = 0.03 * v;
    let mut counts = Vec::with_capacity(n * lay.channels.len());
    for ch in &lay.channels {
        counts.extend((0..n).map(|i| {
            let t = i as f64 * dt;
            let value = match ch.name.as_str() {
                "vibrometer" => -a_b / w * (w * t).cos() + rel(2, t) + sigma * noise.next(),
                "upper_tip" => a_b * (w * t).sin() + d_rel(2, t),
                "upper_mid" => a_b * (w * t).sin() + d_rel(3, t),
                "lower_tip" => a_b * (w * t).sin() + d_rel(0, t),
                "lower_mid" => a_b * (w * t).sin() + d_rel(1, t),
                "contact_voltage" => 5.0,
                _ => a_b * (w * t).sin(),
            };
            (value / ch.scale).round() as i32
        }));
    }
    let info = StepInfo::synthetic(w, a_b / (w * w), n);
    let measured = summarize(&lay, &info, &counts).unwrap();
    let vib_floor = measured
        .noise_floor
        .iter()
        .find(|f| f.channel == "vibrometer")
        .unwrap()
        .rms;
    assert!((vib_floor / sigma - 1.0).abs() < 0.05, "{vib_floor}");

    let o = Observation::nominal(&crate::config::ContactCircuitSpec::default(), 2.5);
    let mut out = TwinWindows::new(&o, crate::twin::ComparisonTolerance::default());
    for b in 0..n / BLOCK {
        let first = (b * BLOCK) as u64;
        let t = |i: usize| (first as usize + i) as f64 * dt;
        out.push(&TwinBlock {
            seq: b as u64,
            first_sample: first,
            time: t(0),
            len: BLOCK,
            velocity: (0..4)
                .flat_map(|k| (0..BLOCK).map(move |i| rel(k, t(i))))
                .collect(),
            base_acceleration: (0..BLOCK).map(|i| a_b * (w * t(i)).sin()).collect(),
            contact: vec![false; BLOCK],
            normal_force: vec![0.0; BLOCK],
            tangential_force: vec![0.0; BLOCK],
            solver_failures: vec![0; BLOCK],
            gap: None,
            restarts: Vec::new(),
        });
    }
    let score = |m: &crate::control::StepSummary, feature: &str| {
        let c = out.compare(&info, m, dt).unwrap().unwrap();
        c.features
            .iter()
            .find(|x| x.channel == "vibrometer" && x.feature == feature)
            .unwrap()
            .clone()
    };
    for feature in ["amp_p10", "amp_p50", "amp_p90"] {
        let with = score(&measured, feature);
        assert!(with.score < 1.0, "{with:?}");
        let bare = crate::control::StepSummary {
            noise_floor: Vec::new(),
            ..measured.clone()
        };
        let without = score(&bare, feature);
        assert!(
            without.score > 3.0 && without.measured / without.model > 1.03,
            "{without:?}"
        );
    }
    // The accelerometers' floor is their quantisation's; their features match either way.
    let c = out.compare(&info, &measured, dt).unwrap().unwrap();
    assert_eq!(c.observation_noise, measured.noise_floor);
    for x in c.features.iter().filter(|x| x.channel != "vibrometer") {
        assert!(x.score < 1.0, "{x:?}");
    }
}
