//! Issue 17, cases 5 and 8: bit flips in a session log or a ROM file never abort, panic or hang
//! the reader. Every mutation of a real session log (single-bit flips spread over chunk
//! payloads, record lengths, chunk CRCs and sizes, the summary section and the footer) is read
//! and replayed in-process: it reads as intact, is salvaged (the summary says what is missing),
//! or is refused with an error; every mutation of a ROM file is read or refused. The normal test
//! runs a few thousand mutations; `cargo test --test bit_flips_never_abort -- --ignored
//! --nocapture` runs at least 10,000 of each and prints the counts recorded in BENCHMARKS.md.

mod cli_support;

use std::ops::Range;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use cli_support::{rigtwin, text, write_plan};
use rigtwin::log::read_session_bytes;
use rigtwin::session::replay::replay_read;

/// One short step at the high level: a session log of a few hundred kilobytes.
const PLAN: &str = r#"
name = "fuzz"
[defaults]
level = 6.0e-5
clearance = 2.78e-3
steps = 2
settle_periods = 20
record_periods = 20
steps_per_period = 1000

[[test]]
name = "t"
direction = "down"
omega_start = 1.0
omega_end = 0.99
"#;

/// Where a mutation lands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Target {
    ChunkPayload,
    RecordLength,
    ChunkCrcOrSize,
    Summary,
    Footer,
    Anywhere,
}

const TARGETS: [Target; 6] = [
    Target::ChunkPayload,
    Target::RecordLength,
    Target::ChunkCrcOrSize,
    Target::Summary,
    Target::Footer,
    Target::Anywhere,
];

/// The byte ranges of a session log each target covers.
struct Regions {
    payloads: Vec<Range<usize>>,
    lengths: Vec<Range<usize>>,
    crcs_and_sizes: Vec<Range<usize>>,
    summary: Range<usize>,
    footer: Range<usize>,
    all: Range<usize>,
}

/// Walks the top-level records of a closed MCAP file.
fn regions(bytes: &[u8]) -> Regions {
    let mut r = Regions {
        payloads: Vec::new(),
        lengths: Vec::new(),
        crcs_and_sizes: Vec::new(),
        summary: 0..0,
        footer: 0..0,
        all: 0..bytes.len(),
    };
    let mut pos = 8;
    while pos + 9 <= bytes.len() - 8 {
        let op = bytes[pos];
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        let body = pos + 9;
        r.lengths.push(pos + 1..pos + 9);
        match op {
            0x06 => {
                // start, end, uncompressed size, CRC, compression (u32 length + text),
                // compressed size, records.
                r.crcs_and_sizes.push(body + 16..body + 28);
                let clen = u32::from_le_bytes(bytes[body + 28..body + 32].try_into().unwrap());
                let records = body + 32 + clen as usize + 8;
                r.crcs_and_sizes.push(records - 8..records);
                r.payloads.push(records..body + len);
            }
            0x0F => r.summary = body + len..0,
            0x02 => {
                r.summary.end = pos;
                r.footer = pos..bytes.len();
            }
            _ => {}
        }
        pos = body + len;
    }
    assert!(!r.payloads.is_empty() && !r.summary.is_empty() && !r.footer.is_empty());
    r
}

/// How the mutations went.
#[derive(Debug, Default)]
struct Counts {
    mutations: usize,
    /// Read and replayed with nothing missing.
    intact: usize,
    /// Read and replayed with `complete: false` (what is missing said).
    salvaged: usize,
    /// Refused with an error.
    refused: usize,
    /// Panics (must stay 0), with the target and offset.
    panics: Vec<String>,
    slowest: Duration,
}

/// Flips one bit of `bytes` in a range of `target`.
fn mutate(bytes: &mut [u8], regions: &Regions, target: Target, rng: &mut ChaCha8Rng) -> usize {
    let pick = |rs: &[Range<usize>], rng: &mut ChaCha8Rng| rs[rng.gen_range(0..rs.len())].clone();
    let range = match target {
        Target::ChunkPayload => pick(&regions.payloads, rng),
        Target::RecordLength => pick(&regions.lengths, rng),
        Target::ChunkCrcOrSize => pick(&regions.crcs_and_sizes, rng),
        Target::Summary => regions.summary.clone(),
        Target::Footer => regions.footer.clone(),
        Target::Anywhere => regions.all.clone(),
    };
    let at = rng.gen_range(range);
    bytes[at] ^= 1 << rng.gen_range(0..8);
    at
}

/// Mutates a session log `n` times and replays every mutant.
fn fuzz_session_log(original: &[u8], n: usize, seed: u64) -> Counts {
    let regions = regions(original);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut counts = Counts::default();
    let path = Path::new("fuzzed.mcap");
    let mut bytes = original.to_vec();
    for i in 0..n {
        let target = TARGETS[i % TARGETS.len()];
        bytes.copy_from_slice(original);
        let at = mutate(&mut bytes, &regions, target, &mut rng);
        let t0 = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| {
            read_session_bytes(path, &bytes)
                .map_err(|e| e.to_string())
                .and_then(|s| replay_read(s).map_err(|e| e.to_string()))
        }));
        counts.slowest = counts.slowest.max(t0.elapsed());
        counts.mutations += 1;
        match outcome {
            Ok(Ok(r)) if r.summary.complete => counts.intact += 1,
            Ok(Ok(r)) => {
                assert!(r.summary.missing.is_some());
                counts.salvaged += 1;
            }
            Ok(Err(_)) => counts.refused += 1,
            Err(_) => counts.panics.push(format!("{target:?} at byte {at}")),
        }
    }
    counts
}

/// Mutates a ROM file `n` times (single-bit flips, half in its header) and reads every mutant.
fn fuzz_rom(original: &[u8], n: usize, seed: u64) -> Counts {
    // Magic, version, header length (u64 at 16..24), JSON header, payload.
    let header_len = u64::from_le_bytes(original[16..24].try_into().unwrap()) as usize;
    let header_end = (24 + header_len).min(original.len());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut counts = Counts::default();
    let mut bytes = original.to_vec();
    for i in 0..n {
        bytes.copy_from_slice(original);
        let at = if i % 2 == 0 {
            rng.gen_range(0..header_end)
        } else {
            rng.gen_range(0..original.len())
        };
        bytes[at] ^= 1 << rng.gen_range(0..8);
        let t0 = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| {
            rigtwin::rom::file::from_bytes(&bytes, Path::new("fuzzed.rom")).is_ok()
        }));
        counts.slowest = counts.slowest.max(t0.elapsed());
        counts.mutations += 1;
        match outcome {
            Ok(true) => counts.intact += 1,
            Ok(false) => counts.refused += 1,
            Err(_) => counts.panics.push(format!("byte {at}")),
        }
    }
    counts
}

/// A short session log and a small ROM, made by the binary.
fn files(dir: &Path) -> (Vec<u8>, Vec<u8>) {
    let plan = write_plan(dir, PLAN);
    let mcap = dir.join("s.mcap");
    let o = rigtwin(&[
        "run",
        "--plan",
        &plan,
        "--quiet",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rom = dir.join("small.rom");
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/sim-fixtures/small-rig.toml");
    let o = rigtwin(&[
        "rom",
        "build",
        config,
        "--quiet",
        "--out",
        rom.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    (std::fs::read(&mcap).unwrap(), std::fs::read(&rom).unwrap())
}

fn run(log_mutations: usize, rom_mutations: usize) {
    let dir = tempfile::tempdir().unwrap();
    let (log, rom) = files(dir.path());
    let t0 = Instant::now();
    let l = fuzz_session_log(&log, log_mutations, 17);
    let log_wall = t0.elapsed();
    let t0 = Instant::now();
    let r = fuzz_rom(&rom, rom_mutations, 17);
    let rom_wall = t0.elapsed();
    println!(
        "session log ({} bytes): {} mutations: {} intact, {} salvaged, {} refused, {} panics; \
         slowest {:.3} s, {:.1} s in all",
        log.len(),
        l.mutations,
        l.intact,
        l.salvaged,
        l.refused,
        l.panics.len(),
        l.slowest.as_secs_f64(),
        log_wall.as_secs_f64()
    );
    println!(
        "ROM ({} bytes): {} mutations: {} read, {} refused, {} panics; slowest {:.3} s, {:.1} s \
         in all",
        rom.len(),
        r.mutations,
        r.intact,
        r.refused,
        r.panics.len(),
        r.slowest.as_secs_f64(),
        rom_wall.as_secs_f64()
    );
    assert!(l.panics.is_empty(), "session log panics: {:?}", l.panics);
    assert!(r.panics.is_empty(), "ROM panics: {:?}", r.panics);
    assert!(l.salvaged > 0, "no mutation was salvaged: {l:?}");
}

#[test]
fn bit_flips_in_logs_and_roms_are_read_salvaged_or_refused() {
    run(600, 600);
}

#[test]
#[ignore = "about 4 minutes: the fuzz run recorded in BENCHMARKS.md"]
fn ten_thousand_bit_flips() {
    run(10_200, 10_000);
}
