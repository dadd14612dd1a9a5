//! Issue 14, "What must hold", first point, for the contact effects: a session of the simulated
//! rig with a clearance offset, wear or a tilted protrusion hidden in `[truth.variants]`, and a
//! twin that declares the same physics with the same parameters in `[model]`, tracks the rig as
//! closely as the nominal twin tracks the nominal rig on the same plan (the null case, on
//! three noise seeds: its spread), while the nominal twin on the same recording does not (it
//! scores above the twin with the physics by more than one over the plan). Two parameter
//! values per effect. The test fails if the twin ignores the declared physics (tried: then the "twin with
//! the physics" is the nominal twin, whose scores fail the null comparison).
//!
//! The impact band is chaotic and the twin's own discretisation scores there (BENCHMARKS.md,
//! "Why the nominal twin over-counts contact", "The comparison's spread"): on this plan a right
//! model scores 3-10 on a grazing step and up to ~56 on a step right after contact, where the
//! lower beam's free response from the last impacts has not died out. So the comparison is with
//! the null case on the same plan: per step against the null's largest score, and over the plan
//! in the median of the per-step scores (one chaotic step must not decide it), each bound the
//! largest of the null case's three noise seeds (one seed is one draw of a chaotic band: the
//! medians of two seeds differ by up to 2-3, BENCHMARKS.md). Both
//! twins run at 13 steps per DAQ sample (the simulated rig's own step) instead of the default
//! 5, which cuts the twin's contact fraction in the band from about 2x the measured one to
//! about 1.3x. Scores and margins: BENCHMARKS.md, "The contact effects tracked (issue 14)".

mod cli_support;
mod twin_support;

use twin_support::{hidden_and_declared, max_scores, on_every_core, Case};

/// One high-level step in sustained impacts (the wear-in: wear opens the gap here), then the
/// low level up through the top of 1FU, where the beams graze the protrusion at 1.00-1.01
/// omega_2 and the clearance (and a tilted face's lower edge) sets how far the upper beam's
/// resonance is clipped. 200 settle periods let most of the previous step's transient decay.
const PLAN: &str = r#"
name = "contact-track"
[defaults]
level = 2.0e-5
clearance = 2.78e-3
settle_periods = 200
record_periods = 50
steps_per_period = 1000
[[test]]
name = "wear-in"
level = 6.0e-5
steps = 1
settle_periods = 100
direction = "down"
omega_start = 0.98
omega_end = 0.98
[[test]]
name = "graze-up"
direction = "up"
steps = 5
omega_start = 0.99
omega_end = 1.03
"#;

/// Settings every rig description of the test shares: the twins at the simulated rig's own
/// step (13 per DAQ sample), and a DAQ watchdog of 30 s instead of 2 (the simulated rig computes
/// its blocks on a CPU shared with the rest of the suite: under load a block in the impact band
/// took longer than 2 s of wall time once and aborted the session).
const COMMON: &str = "[twin]\nsteps_per_sample = 13\n[safety]\ndaq_timeout_s = 30.0\n";

/// The null case's noise seeds (`[daq] noise_seed`; 1 is the default, which the effect cases
/// use).
const NULL_SEEDS: [u64; 3] = [1, 2, 3];

/// The median of the per-step largest scores.
fn median(scores: &[f64]) -> f64 {
    let mut s = scores.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

#[test]
fn a_twin_with_the_hidden_contact_physics_tracks_the_rig_and_the_nominal_twin_does_not() {
    let dir = tempfile::tempdir().unwrap();
    // The null case's spread: nothing hidden, the nominal twin, three noise seeds (the effect
    // cases below run on the default seed, 1). The bounds are the largest score and the largest
    // median over the seeds.
    let nulls = on_every_core(&NULL_SEEDS, |_, &seed| {
        let null_case = Case::new(
            dir.path(),
            &format!("null-seed{seed}"),
            COMMON,
            &format!("[daq]\nnoise_seed = {seed}\n"),
        );
        null_case.record(PLAN, false);
        max_scores(&null_case.replay(&null_case.nominal, "nominal-twin"))
    });
    let (mut null_max, mut null_median) = (0.0f64, 0.0f64);
    for (seed, null) in NULL_SEEDS.iter().zip(&nulls) {
        let m = median(null);
        println!("null case, noise seed {seed}: {null:.2?}, median {m:.2}");
        null_max = null.iter().copied().fold(null_max, f64::max);
        null_median = null_median.max(m);
    }
    println!("null case bounds: largest score {null_max:.2}, largest median {null_median:.2}");

    let cases: [(&str, &str); 6] = [
        ("clearance +2e-4 m", "[{t}.clearance]\noffset = 2.0e-4\n"),
        ("clearance -1.5e-4 m", "[{t}.clearance]\noffset = -1.5e-4\n"),
        ("tilt 0.1 rad", "[{t}.tilt]\nangle = 0.1\n"),
        ("tilt -0.09 rad", "[{t}.tilt]\nangle = -0.09\n"),
        (
            "wear 1.2e-3 m/(N s), cap 2e-4 m",
            "[{t}.wear]\ncoefficient = 1.2e-3\nmax_growth = 2.0e-4\n",
        ),
        (
            "wear 1.2e-4 m/(N s), cap 3e-4 m",
            "[{t}.wear]\ncoefficient = 1.2e-4\nmax_growth = 3.0e-4\n",
        ),
    ];
    let runs = on_every_core(&cases, |i, &(_, physics)| {
        let case = Case::new(
            dir.path(),
            &format!("case{i}"),
            COMMON,
            &hidden_and_declared(physics),
        );
        case.record(PLAN, false);
        (
            max_scores(&case.replay(&case.rig, "twin-with-physics")),
            max_scores(&case.replay(&case.nominal, "nominal-twin")),
        )
    });
    let mut failures = Vec::new();
    for ((name, _), (matched, nominal)) in cases.iter().zip(&runs) {
        let (m, n) = (median(matched), median(nominal));
        println!(
            "{name}: twin with the physics {matched:.2?} (median {m:.2}), nominal twin \
             {nominal:.2?} ({n:.2})"
        );
        // As close as the null case: no step above the null's largest score on this plan plus
        // one spread, and over the plan within the null's largest median plus one.
        for (k, &s) in matched.iter().enumerate() {
            if s > null_max + 1.0 {
                failures.push(format!(
                    "{name}: step {k}: the twin with the physics scores {s:.2}, the null case at \
                     most {null_max:.2}"
                ));
            }
        }
        if m > null_median + 1.0 {
            failures.push(format!(
                "{name}: the twin with the physics scores {m:.2} over the plan, the null case \
                 at most {null_median:.2}"
            ));
        }
        // The nominal twin does not: on the same recording it is further from the rig than the
        // twin with the physics by more than one over the plan, and some step misses by more
        // than the threshold of a mismatch (3).
        // NOTE: a paired comparison (one recording, two twins). The null case is another
        // recording, and its median is one draw of a chaotic band: it moved from 5.49 to 8.10
        // when the contact solve's path changed (Newton from 48 pairs, issue 16), while every
        // nominal twin stayed 2.8-8.7 above its twin with the physics.
        let worst = nominal.iter().copied().fold(0.0, f64::max);
        if n <= m + 1.0 || worst <= 3.0 {
            failures.push(format!(
                "{name}: the nominal twin should not track the rig: {n:.2} over the plan (null \
                 case {null_median:.2}, twin with the physics {m:.2}), worst step {worst:.2}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
