//! Contact activity (reference section 4.2, Fig. "contact activity"): intervals of contact from
//! per-sample flags, impacts per excitation period, and clusters of impacts with their size
//! histogram (the reference reports that "clusters of five impacts occur recurrently").
//!
//! Definitions used throughout (and by the step metrics, `metrics.rs`):
//! - a sample is *closed* when at least one contact pair is closed (simulation) or the contact
//!   resistance says so (measurement);
//! - an *interval* is a maximal run of closed samples `[start, end)`, after merging open gaps of
//!   at most `debounce` samples that have closed samples on both sides;
//! - an *impact* is an open->closed transition, i.e. an interval with `start > 0` (a record
//!   that begins closed did not see that contact start);
//! - a *cluster* is a group of consecutive intervals whose open gaps are at most
//!   `cluster_gap_periods` excitation periods long.

use super::error::{require_positive, SignalError};
use super::periods::PeriodGrid;

/// Number of open->closed transitions in `closed`, merging open gaps of at most `debounce`
/// samples between closed samples (0: every transition counts). No allocation.
pub fn count_impacts(closed: &[bool], debounce: usize) -> usize {
    let mut count = 0;
    let mut open_run = 0usize;
    let mut seen_closed = false;
    for &c in closed {
        if c {
            // An open run before the first closed sample is not bounded by contact on its left:
            // it is a real opening whatever its length.
            if open_run > 0 && (!seen_closed || open_run > debounce) {
                count += 1;
            }
            open_run = 0;
            seen_closed = true;
        } else {
            open_run += 1;
        }
    }
    count
}

/// Parameters of [`contact_activity`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ActivityParams {
    /// Open gaps of at most this many samples between closed samples are merged. Default 0.
    pub debounce: usize,
    /// Largest open gap inside a cluster, in excitation periods. Default 1.5.
    ///
    /// NOTE: with one impact per period the open gap between impacts is one period minus the
    /// contact duration, so a threshold of half a period would split every modulation burst
    /// into single impacts; 1.5 periods keeps impacts of consecutive periods together and
    /// starts a new cluster after at least one impact-free period. Use 0.5 to isolate the
    /// rebounds (chatter) within one period instead.
    pub cluster_gap_periods: f64,
}

impl Default for ActivityParams {
    fn default() -> Self {
        ActivityParams {
            debounce: 0,
            cluster_gap_periods: 1.5,
        }
    }
}

/// A maximal run of closed samples, `[start, end)` in sample indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ContactInterval {
    /// First closed sample.
    pub start: usize,
    /// One past the last closed sample.
    pub end: usize,
}

impl ContactInterval {
    /// True when the interval starts with an observed open->closed transition.
    pub fn is_impact(&self) -> bool {
        self.start > 0
    }
}

/// A group of contact intervals separated by short open gaps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ImpactCluster {
    /// Index of the cluster's first interval in [`ContactActivity::intervals`].
    pub first_interval: usize,
    /// Number of intervals in the cluster.
    pub intervals: usize,
    /// Number of impacts (intervals with an observed start) in the cluster.
    pub impacts: usize,
    /// First closed sample of the cluster.
    pub start: usize,
    /// One past the last closed sample of the cluster.
    pub end: usize,
    /// False when the record starts or ends within one cluster gap of the cluster, so that it
    /// may continue outside the record; such clusters are left out of the histogram.
    pub complete: bool,
}

/// Contact activity of a record.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactActivity {
    /// Contact intervals in time order.
    pub intervals: Vec<ContactInterval>,
    /// Clusters of intervals in time order.
    pub clusters: Vec<ImpactCluster>,
    /// Impacts starting in each whole excitation period (periods counted from sample 0).
    pub impacts_per_period: Vec<usize>,
    /// `cluster_size_histogram[m]` = number of complete clusters with `m` impacts
    /// (index 0 is always 0; length = largest size + 1, or 0 when there is none).
    pub cluster_size_histogram: Vec<usize>,
}

impl ContactActivity {
    /// The most frequent size among complete clusters (smallest size on ties), if any.
    pub fn most_frequent_cluster_size(&self) -> Option<usize> {
        let mut best: Option<(usize, usize)> = None;
        for (size, &count) in self.cluster_size_histogram.iter().enumerate() {
            if count > 0 && best.is_none_or(|(_, c)| count > c) {
                best = Some((size, count));
            }
        }
        best.map(|(size, _)| size)
    }

    /// Total number of impacts.
    pub fn impacts(&self) -> usize {
        self.intervals.iter().filter(|i| i.is_impact()).count()
    }
}

/// Contact intervals of `closed` (module docs), with open gaps of at most `debounce` samples
/// between closed samples merged.
pub fn contact_intervals(closed: &[bool], debounce: usize) -> Vec<ContactInterval> {
    let mut out: Vec<ContactInterval> = Vec::new();
    let mut k = 0;
    while k < closed.len() {
        if !closed[k] {
            k += 1;
            continue;
        }
        let start = k;
        while k < closed.len() && closed[k] {
            k += 1;
        }
        match out.last_mut() {
            Some(last) if start - last.end <= debounce => last.end = k,
            _ => out.push(ContactInterval { start, end: k }),
        }
    }
    out
}

/// Contact activity of a record sampled at `dt` (s) under excitation `omega` (rad/s).
///
/// Intervals and clusters cover the whole record; `impacts_per_period` covers its whole
/// periods. Errors: `dt`/`omega` invalid, less than one whole period, bad `params`.
pub fn contact_activity(
    closed: &[bool],
    dt: f64,
    omega: f64,
    params: &ActivityParams,
) -> Result<ContactActivity, SignalError> {
    if closed.is_empty() {
        return Err(SignalError::Empty {
            channel: "contact_closed",
        });
    }
    let grid = PeriodGrid::new(closed.len(), dt, omega)?;
    require_positive("cluster_gap_periods", params.cluster_gap_periods)?;
    let intervals = contact_intervals(closed, params.debounce);

    let mut impacts_per_period = vec![0usize; grid.periods()];
    let mut p = 0;
    for iv in intervals.iter().filter(|i| i.is_impact()) {
        while p < grid.periods() && iv.start >= grid.members(p).end {
            p += 1;
        }
        if p == grid.periods() {
            break;
        }
        impacts_per_period[p] += 1;
    }

    let gap = params.cluster_gap_periods * grid.samples_per_period();
    let n = closed.len();
    let mut clusters: Vec<ImpactCluster> = Vec::new();
    for (i, iv) in intervals.iter().enumerate() {
        match clusters.last_mut() {
            Some(c) if (iv.start - c.end) as f64 <= gap => {
                c.intervals += 1;
                c.impacts += usize::from(iv.is_impact());
                c.end = iv.end;
            }
            _ => clusters.push(ImpactCluster {
                first_interval: i,
                intervals: 1,
                impacts: usize::from(iv.is_impact()),
                start: iv.start,
                end: iv.end,
                complete: false,
            }),
        }
    }
    let mut cluster_size_histogram = Vec::new();
    for c in &mut clusters {
        // Open time seen before and after the cluster must exceed the gap.
        c.complete = c.start as f64 > gap && (n - c.end) as f64 > gap;
        if c.complete {
            if cluster_size_histogram.len() <= c.impacts {
                cluster_size_histogram.resize(c.impacts + 1, 0);
            }
            cluster_size_histogram[c.impacts] += 1;
        }
    }
    Ok(ContactActivity {
        intervals,
        clusters,
        impacts_per_period,
        cluster_size_histogram,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn flags(n: usize, closed_runs: &[(usize, usize)]) -> Vec<bool> {
        let mut f = vec![false; n];
        for &(a, b) in closed_runs {
            f[a..b].iter_mut().for_each(|c| *c = true);
        }
        f
    }

    #[test]
    fn intervals_and_impact_counts_agree() {
        let f = flags(50, &[(0, 3), (10, 12), (13, 15), (20, 21), (49, 50)]);
        let iv = contact_intervals(&f, 0);
        assert_eq!(
            iv,
            vec![
                ContactInterval { start: 0, end: 3 },
                ContactInterval { start: 10, end: 12 },
                ContactInterval { start: 13, end: 15 },
                ContactInterval { start: 20, end: 21 },
                ContactInterval { start: 49, end: 50 },
            ]
        );
        assert_eq!(count_impacts(&f, 0), 4);
        assert_eq!(iv.iter().filter(|i| i.is_impact()).count(), 4);
        // Debounce 1 merges 10..12 and 13..15.
        assert_eq!(contact_intervals(&f, 1).len(), 4);
        assert_eq!(count_impacts(&f, 1), 3);
        // Debounce 5 also merges 20..21 into it; the 7-sample gap after the clipped first
        // interval stays open.
        let iv5 = contact_intervals(&f, 5);
        assert_eq!(iv5[1], ContactInterval { start: 10, end: 21 });
        assert_eq!(count_impacts(&f, 5), 2);
        assert_eq!(iv5.iter().filter(|i| i.is_impact()).count(), 2);
    }

    #[test]
    fn leading_open_run_shorter_than_debounce_still_counts() {
        let f = flags(10, &[(1, 4)]);
        assert_eq!(count_impacts(&f, 5), 1);
        assert_eq!(
            contact_intervals(&f, 5),
            vec![ContactInterval { start: 1, end: 4 }]
        );
    }

    #[test]
    fn counts_of_random_flags_agree_between_counter_and_intervals() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let n = rng.gen_range(1..80);
            let f: Vec<bool> = (0..n).map(|_| rng.gen_bool(0.4)).collect();
            for d in 0..4 {
                let by_intervals = contact_intervals(&f, d)
                    .iter()
                    .filter(|i| i.is_impact())
                    .count();
                assert_eq!(count_impacts(&f, d), by_intervals, "{f:?} debounce {d}");
            }
        }
    }

    /// Bursts of `size` impacts in consecutive periods separated by `quiet` impact-free periods;
    /// 100 samples per period, each contact lasts 5 samples at sample 30 of its period.
    fn bursts(sizes: &[usize], quiet: usize) -> Vec<bool> {
        let mut runs = Vec::new();
        let mut p = quiet;
        for &s in sizes {
            for _ in 0..s {
                runs.push((p * 100 + 30, p * 100 + 35));
                p += 1;
            }
            p += quiet;
        }
        flags(p * 100, &runs)
    }

    #[test]
    fn clusters_of_five_are_found_and_histogrammed() {
        let f = bursts(&[5, 5, 3, 5, 5, 2], 3);
        let omega = TAU * 10.0;
        let dt = 1.0 / 1000.0; // 100 samples per period
        let a = contact_activity(&f, dt, omega, &ActivityParams::default()).unwrap();
        assert_eq!(a.intervals.len(), 25);
        assert_eq!(a.impacts(), 25);
        let sizes: Vec<usize> = a.clusters.iter().map(|c| c.impacts).collect();
        assert_eq!(sizes, vec![5, 5, 3, 5, 5, 2]);
        assert!(a.clusters.iter().all(|c| c.complete));
        assert_eq!(a.cluster_size_histogram, vec![0, 0, 1, 1, 0, 4]);
        assert_eq!(a.most_frequent_cluster_size(), Some(5));
        assert_eq!(a.impacts_per_period.len(), f.len() / 100);
        assert_eq!(a.impacts_per_period.iter().sum::<usize>(), 25);
        assert!(a.impacts_per_period.iter().all(|&c| c <= 1));
        assert_eq!(a.impacts_per_period[3..9], [1, 1, 1, 1, 1, 0]);

        // Half-period gaps isolate every impact.
        let p = ActivityParams {
            cluster_gap_periods: 0.5,
            ..Default::default()
        };
        let a = contact_activity(&f, dt, omega, &p).unwrap();
        assert_eq!(a.clusters.len(), 25);
        assert_eq!(a.most_frequent_cluster_size(), Some(1));
    }

    #[test]
    fn clusters_touching_the_record_ends_are_incomplete() {
        // A burst right at the start (sample 30 of period 0) and one running into the end.
        let mut f = bursts(&[4, 5], 3);
        f.drain(..300); // first burst now starts at sample 30
        f.truncate(f.len() - 250); // the last burst ends 115 samples before the record end
        let a = contact_activity(&f, 1e-3, TAU * 10.0, &ActivityParams::default()).unwrap();
        assert_eq!(a.clusters.len(), 2);
        assert!(!a.clusters[0].complete && !a.clusters[1].complete);
        assert!(a.cluster_size_histogram.is_empty());
        assert_eq!(a.most_frequent_cluster_size(), None);
    }

    #[test]
    fn rejects_bad_parameters() {
        let f = vec![false; 100];
        assert!(matches!(
            contact_activity(&[], 1e-3, 1.0, &ActivityParams::default()),
            Err(SignalError::Empty { .. })
        ));
        assert!(matches!(
            contact_activity(&f, 1e-3, TAU * 5.0, &ActivityParams::default()),
            Err(SignalError::TooShort { .. })
        ));
        let p = ActivityParams {
            cluster_gap_periods: f64::NAN,
            ..Default::default()
        };
        assert!(matches!(
            contact_activity(&f, 1e-3, TAU * 10.0, &p),
            Err(SignalError::InvalidParameter { .. })
        ));
    }
}
