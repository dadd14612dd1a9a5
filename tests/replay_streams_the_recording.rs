//! Issue 15: the recording `replay` (and `diagnose`) works on keeps every channel's counts only
//! inside the steps' record windows and, for every block, the platform accelerometers' counts
//! (the twin's input), packed losslessly; it is read from the log in two streamed passes. Guards:
//! - the base blocks carry the platform counts as logged and zero elsewhere; every record
//!   window's counts are those cut from the logged blocks; the samples held for all channels
//!   are exactly the record windows', and the bytes held are below the raw size of what is
//!   kept (a size accounting: no channel's counts outside the windows but the platform's);
//! - the streamed replay of the file equals the replay of the log read whole, bit for bit
//!   (summary and recording), also on logs cut off at any point or with damaged chunks (the
//!   same salvage, or the same error).

mod cli_support;

use cli_support::{rigtwin, text, write_plan};
use rigtwin::control::StepInfo;
use rigtwin::log::{read_session, read_session_bytes};
use rigtwin::rig::channels::platform_accelerometers;
use rigtwin::rig::DaqBlock;
use rigtwin::session::replay::{replay, replay_read, window_counts, Replay};
use rigtwin::session::topics::TOPIC_DAQ;

/// Two short impact-free steps and one with impacts: a log of a few megabytes.
const PLAN: &str = r#"
name = "stream"
[defaults]
clearance = 2.78e-3
settle_periods = 20
record_periods = 20
steps_per_period = 1000

[[test]]
name = "low"
level = 0.2e-5
direction = "up"
steps = 2
omega_start = 0.99
omega_end = 1.0

[[test]]
name = "high"
level = 6.0e-5
steps = 1
direction = "down"
omega_start = 0.98
omega_end = 0.98
"#;

/// The counts of the window of `info` cut from whole blocks (channel-major).
fn cut(blocks: &[DaqBlock], nch: usize, info: &StepInfo) -> Vec<i32> {
    let n = info.record_samples;
    let (w0, w1) = (info.record_first_sample, info.record_end_sample());
    let mut out = vec![0; n * nch];
    for b in blocks {
        let (b0, b1) = (b.first_sample, b.first_sample + b.len as u64);
        let (s, e) = (b0.max(w0), b1.min(w1));
        if s >= e {
            continue;
        }
        for k in 0..nch {
            out[k * n + (s - w0) as usize..k * n + (e - w0) as usize]
                .copy_from_slice(&b.channel(k)[(s - b0) as usize..(e - b0) as usize]);
        }
    }
    out
}

/// A replay outcome as comparable text: the summary and recording, or the error.
fn outcome(
    r: Result<Replay, String>,
) -> Result<(String, rigtwin::session::replay::Recording), String> {
    r.map(|r| (serde_json::to_string(&r.summary).unwrap(), r.recording))
}

#[test]
fn the_recording_keeps_the_base_motion_and_the_record_windows_streamed() {
    let dir = tempfile::tempdir().unwrap();
    let plan = write_plan(dir.path(), PLAN);
    let mcap = dir.path().join("s.mcap");
    let o = rigtwin(&[
        "run",
        "--plan",
        &plan,
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));

    let whole = read_session(&mcap).unwrap();
    let blocks: Vec<DaqBlock> = whole
        .decode(TOPIC_DAQ)
        .unwrap()
        .into_iter()
        .map(|(_, _, b)| b)
        .collect();
    let r = replay(&mcap).unwrap();
    assert!(r.complete && r.matches_logged());
    let rec = &r.recording;
    let nch = rec.layout.channels.len();
    let platform: Vec<usize> = platform_accelerometers(&rec.layout)
        .into_iter()
        .map(|(k, _)| k)
        .collect();
    assert_eq!(rec.blocks.len(), blocks.len());
    for (i, b) in blocks.iter().enumerate() {
        let base = rec.base_block(i);
        assert_eq!(
            (base.seq, base.first_sample, base.time, base.len),
            (b.seq, b.first_sample, b.time, b.len)
        );
        for k in 0..nch {
            if platform.contains(&k) {
                assert_eq!(base.channel(k), b.channel(k), "block {i} channel {k}");
            } else {
                assert!(
                    base.channel(k).iter().all(|&c| c == 0),
                    "block {i} channel {k}"
                );
            }
        }
    }
    let windows: Vec<&StepInfo> = rec.record_windows().collect();
    assert_eq!(windows.len(), 3);
    for info in &windows {
        assert_eq!(window_counts(rec, info).unwrap(), cut(&blocks, nch, info));
    }
    // The accounting: all channels inside the windows only, the platform's everywhere.
    let in_windows: u64 = windows.iter().map(|w| w.record_samples as u64).sum();
    assert_eq!(rec.window_samples(), in_windows);
    let samples: u64 = blocks.iter().map(|b| b.len as u64).sum();
    let raw_kept = 4 * (platform.len() as u64 * samples + nch as u64 * in_windows);
    let raw_all = 4 * nch as u64 * samples;
    let held = rec.count_bytes() as u64;
    assert!(
        held < raw_kept / 2 && raw_kept < raw_all,
        "held {held} bytes, raw: kept {raw_kept}, all {raw_all}"
    );

    // The streamed replay is the whole-file one.
    let bytes = std::fs::read(&mcap).unwrap();
    let in_memory = replay_read(read_session_bytes(&mcap, &bytes).unwrap()).unwrap();
    assert_eq!(
        serde_json::to_string(&in_memory.summary).unwrap(),
        serde_json::to_string(&r.summary).unwrap()
    );
    assert!(in_memory.recording == r.recording);

    // Cut off and damaged logs: the same salvage or the same error, streamed or whole.
    let mutant = dir.path().join("m.mcap");
    let check = |b: &[u8], what: &str| {
        std::fs::write(&mutant, b).unwrap();
        let streamed = outcome(replay(&mutant).map_err(|e| e.to_string()));
        let whole = outcome(
            read_session_bytes(&mutant, b)
                .map_err(|e| e.to_string())
                .and_then(|s| replay_read(s).map_err(|e| e.to_string())),
        );
        match (&streamed, &whole) {
            (Ok((a, ra)), Ok((b, rb))) => {
                assert_eq!(a, b, "{what}: summaries differ");
                assert!(ra == rb, "{what}: recordings differ");
            }
            (Err(a), Err(b)) => assert_eq!(a, b, "{what}"),
            _ => panic!(
                "{what}: streamed {:?}, whole {:?}",
                streamed.err(),
                whole.err()
            ),
        }
        streamed.is_ok()
    };
    let len = bytes.len();
    let mut salvaged = 0;
    for i in 1..24 {
        let n = len * i / 24;
        salvaged += usize::from(check(&bytes[..n], &format!("cut at {n}")));
    }
    for i in 1..24 {
        let at = len * i / 24 + 17;
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        salvaged += usize::from(check(&b, &format!("flip at {at}")));
    }
    assert!(salvaged > 20, "{salvaged} of 46 mutants replayed");
}
