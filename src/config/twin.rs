//! The twin's settings: the `[twin]` table of a rig description. Every field has a default,
//! so the table may be omitted. Not part of the model: not hashed (changing the twin's step
//! or queue does not rebuild the ROM).
//!
//! The ROM- and DAQ-dependent checks (the twin step against the ROM's stability limit, the
//! platform accelerometers in the layout) are done by `twin::Twin::new`, whose errors name
//! the key as well.

use serde::{Deserialize, Serialize};

use super::error::SpecError;

/// What the twin does with its state when its input jumps (blocks skipped because it fell
/// behind, or blocks lost by the DAQ).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AfterGap {
    /// Keep the modal state and continue from the first sample after the gap (default). The
    /// excitation jumps in phase at the gap, so the twin shows a transient there, but its
    /// response level carries over: the 1FU mode (0.2 % damping) would need several seconds
    /// to build up again from rest.
    #[default]
    KeepState,
    /// Restart at rest at the first sample after the gap: the transient is the build-up from
    /// rest, the same as at the start of a session.
    RestartAtRest,
}

/// `[twin]`: time step, input queue and gap handling of the live twin.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TwinSpec {
    /// Twin steps per DAQ sample (>= 1), overriding the automatic choice; the twin step is
    /// `dt = 1 / (sample_rate * steps_per_sample)` and must stay below the open stability
    /// limit of the twin ROM (`2 / max(Omega)`; the end-of-step contact coupling needs no
    /// closed bound). Default: none (automatic, see `steps_per_reference_period`).
    pub steps_per_sample: Option<u32>,
    /// Automatic choice: the number of twin steps per DAQ sample is the integer nearest to
    /// `steps_per_reference_period * f(1FU) / sample_rate` (at least 1), i.e. about this many
    /// steps per 1FU period (> 0). Default 1000 (the reference's resolution): 5 steps per
    /// sample at 10240 Hz for the default rig (f(1FU) = 51.3 Hz, 999 steps per period).
    pub steps_per_reference_period: f64,
    /// Capacity of the input queue of the twin task, in DAQ blocks (>= 1). When it is full
    /// the task skips blocks (counted and reported) until the twin has drained it. Default
    /// 160: 4 s of data with the default DAQ (256 samples per block at 10240 Hz).
    pub queue_blocks: usize,
    /// What the twin does with its state after a gap in its input. Default `keep_state`.
    pub after_gap: AfterGap,
    /// For tests only: the twin task spends at least `throttle` wall seconds per second of
    /// data (it sleeps after each block), so a test can make it fall behind; 0 = off (>= 0).
    /// Default 0.
    pub throttle: f64,
    /// Runs of the model from perturbed initial states besides the twin's own, per step, for
    /// the model spread of the comparison (`rigtwin replay --twin`; `--ensemble` overrides it;
    /// the live twin runs none). 0 = the model spread is the twin's own sub-windows'. At most
    /// 64. Default 4.
    pub ensemble_members: usize,
    /// Size of an ensemble member's perturbation: its modal velocities at the step's start
    /// get a random change of this norm relative to theirs (in (0, 0.1]). Default 1e-3.
    pub ensemble_perturbation: f64,
    /// Resolution of the comparison's scores: the floor of the combined spread.
    pub tolerance: ComparisonTolerance,
    /// The comparison's discretisation member (`[twin.discretisation]`).
    pub discretisation: DiscretisationSpec,
    /// The twin's contact patch in a session that holds the probes in contact
    /// (`[twin.held_contact]`).
    pub held_contact: HeldContactSpec,
}

/// `[twin.held_contact]`: a coarser contact patch for the twin in a session whose every test
/// holds the probes in contact (touching, pre-loaded, or a gap of a few micrometres).
///
/// There most pairs close at once, step after step, and the contact solve on the model's own
/// patch (`[contact] nodes`: 192 pairs on the default rig) keeps the twin at about 2x real
/// time; on 8 x 11 (88 pairs) it runs at 6.5-7.3x, its response within the fine patch's own
/// spread in held contact and as close to the simulated rig's (BENCHMARKS.md, "Held contact:
/// the twin's patch chosen by the plan"). In impacts the coarse patch rings differently
/// (more, shorter contacts), so a session with any test at a larger clearance keeps the
/// model's patch, and so does a description that sets its own `[reduction] contact_nodes`.
/// The simulated rig's truth is not affected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeldContactSpec {
    /// Whether the twin takes `contact_nodes` in such a session. Default true.
    pub enabled: bool,
    /// The twin's patch `[across y, along x]` there (at least 2 nodes per edge; used only
    /// when it has fewer pairs than `[contact] nodes`). Default [8, 11].
    pub contact_nodes: [usize; 2],
    /// A test holds contact when its clearance / l is at most this (in [-1e-4, 0.1]).
    /// Default 2e-5 (6 um on the default rig's 300 mm beams, whose planned gap is 2.33e-3 l):
    /// at 1e-5 l and a base level of 0.5e-5 l the probes are in contact 7 % of the time, with
    /// 100-192 pairs in each solve.
    pub max_clearance: f64,
}

impl Default for HeldContactSpec {
    fn default() -> Self {
        HeldContactSpec {
            enabled: true,
            contact_nodes: [8, 11],
            max_clearance: 2e-5,
        }
    }
}

impl HeldContactSpec {
    /// The twin's patch for a session whose tests have the clearances `clearances` (/ l):
    /// `contact_nodes` when enabled and every test holds contact; none otherwise (no tests
    /// included).
    pub fn patch_for(&self, clearances: &[f64]) -> Option<[usize; 2]> {
        let held = !clearances.is_empty() && clearances.iter().all(|&c| c <= self.max_clearance);
        (self.enabled && held).then_some(self.contact_nodes)
    }
}

/// `[twin.discretisation]`: a run of a finer model beside the ensemble (`rigtwin replay
/// --twin` with an ensemble; the live twin runs none) in every record window with contact,
/// measured or modelled: the rig description's structure with more modes and a finer step
/// than the twin's, on the `[contact] nodes` patch, from rest at the start of the step before
/// (its lead-in), with the clearance and wear the twin had there. Each feature's model spread
/// gains `|twin - member|` in quadrature: in the impact band the twin's own modal truncation
/// and step move its response more than chaos does (BENCHMARKS.md, "The comparison's
/// spread"), and a right model must not score as a mismatch there. Off contact the two agree
/// and nothing is run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiscretisationSpec {
    /// Whether the member runs. Default true.
    pub enabled: bool,
    /// The member's ROM keeps the modes up to this multiple of f(1FU) (> 0). Default 400 (the
    /// simulated rig's own resolution, `[truth] cutoff_ratio`'s default; its ROM is then the
    /// same cache entry).
    pub cutoff_ratio: f64,
    /// The member's steps per DAQ sample (>= 1; below the open stability limit of its ROM).
    /// Default 13 (7.5 us at 10240 Hz).
    pub steps_per_sample: u32,
}

impl Default for DiscretisationSpec {
    fn default() -> Self {
        DiscretisationSpec {
            enabled: true,
            cutoff_ratio: 400.0,
            steps_per_sample: 13,
        }
    }
}

/// `[twin.tolerance]`: the resolution below which measurement and model are not told apart,
/// whatever their spreads (the floor of a score's combined spread).
///
// NOTE: the spreads of a steady, periodic response are tiny (sensor noise averaged over
// hundreds of periods; the model has none), so without a floor a difference far below what
// matters to the analyst — and below the twin's own discretisation error (BENCHMARKS.md,
// "The comparison's spread") — would score as a mismatch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ComparisonTolerance {
    /// For the velocity features, relative to the larger of the two values (>= 0). Default
    /// 0.01.
    pub relative: f64,
    /// For `contact_fraction`, absolute (>= 0). Default 0.005.
    pub contact_fraction: f64,
    /// For `impacts_per_period`, absolute (>= 0). Default 0.02.
    pub impacts_per_period: f64,
}

impl Default for ComparisonTolerance {
    fn default() -> Self {
        ComparisonTolerance {
            relative: 0.01,
            contact_fraction: 0.005,
            impacts_per_period: 0.02,
        }
    }
}

impl ComparisonTolerance {
    /// The floor for `feature` between the values `measured` and `model`.
    pub fn of(&self, feature: &str, measured: f64, model: f64) -> f64 {
        match feature {
            "contact_fraction" => self.contact_fraction,
            "impacts_per_period" => self.impacts_per_period,
            _ => self.relative * measured.abs().max(model.abs()),
        }
    }
}

/// The largest ensemble (`[twin] ensemble_members`).
pub const MAX_ENSEMBLE_MEMBERS: usize = 64;

impl Default for TwinSpec {
    fn default() -> Self {
        TwinSpec {
            steps_per_sample: None,
            steps_per_reference_period: 1000.0,
            queue_blocks: 160,
            after_gap: AfterGap::KeepState,
            throttle: 0.0,
            ensemble_members: 4,
            ensemble_perturbation: 1e-3,
            tolerance: ComparisonTolerance::default(),
            discretisation: DiscretisationSpec::default(),
            held_contact: HeldContactSpec::default(),
        }
    }
}

impl TwinSpec {
    /// Checks the ranges documented on the fields; the error names the key.
    pub fn validate(&self) -> Result<(), SpecError> {
        if self.steps_per_sample == Some(0) {
            return Err(SpecError::new(
                "twin.steps_per_sample",
                0,
                "at least 1 twin step per DAQ sample",
            ));
        }
        let s = self.steps_per_reference_period;
        if !(s.is_finite() && s > 0.0) {
            return Err(SpecError::new(
                "twin.steps_per_reference_period",
                s,
                "a finite number of steps per 1FU period > 0",
            ));
        }
        if self.queue_blocks == 0 {
            return Err(SpecError::new(
                "twin.queue_blocks",
                0,
                "a queue of at least 1 block",
            ));
        }
        let t = self.throttle;
        if !(t.is_finite() && t >= 0.0) {
            return Err(SpecError::new(
                "twin.throttle",
                t,
                "a finite number of wall seconds per second of data >= 0 (0 = off)",
            ));
        }
        if self.ensemble_members > MAX_ENSEMBLE_MEMBERS {
            return Err(SpecError::new(
                "twin.ensemble_members",
                self.ensemble_members,
                "at most 64 ensemble members (0 = none)",
            ));
        }
        let e = self.ensemble_perturbation;
        if !(e.is_finite() && e > 0.0 && e <= 0.1) {
            return Err(SpecError::new(
                "twin.ensemble_perturbation",
                e,
                "a relative perturbation in (0, 0.1]",
            ));
        }
        let d = &self.discretisation;
        if !(d.cutoff_ratio.is_finite() && d.cutoff_ratio > 0.0) {
            return Err(SpecError::new(
                "twin.discretisation.cutoff_ratio",
                d.cutoff_ratio,
                "a finite multiple of f(1FU) > 0",
            ));
        }
        if d.steps_per_sample == 0 {
            return Err(SpecError::new(
                "twin.discretisation.steps_per_sample",
                0,
                "at least 1 step per DAQ sample",
            ));
        }
        let h = &self.held_contact;
        if let Some(expected) = super::validate::patch_nodes_problem(h.contact_nodes) {
            let [y, x] = h.contact_nodes;
            return Err(SpecError::new(
                "twin.held_contact.contact_nodes",
                format!("[{y}, {x}]"),
                expected,
            ));
        }
        let m = h.max_clearance;
        if !(m.is_finite() && (-1e-4..=0.1).contains(&m)) {
            return Err(SpecError::new(
                "twin.held_contact.max_clearance",
                m,
                "a clearance / l in [-1e-4, 0.1]",
            ));
        }
        let t = &self.tolerance;
        for (key, v) in [
            ("twin.tolerance.relative", t.relative),
            ("twin.tolerance.contact_fraction", t.contact_fraction),
            ("twin.tolerance.impacts_per_period", t.impacts_per_period),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SpecError::new(key, v, "a finite tolerance >= 0"));
            }
        }
        Ok(())
    }

    /// Twin steps per DAQ sample for a DAQ rate `sample_rate` (Hz) and a ROM whose 1FU mode
    /// is at `omega_ref` (rad/s): the override if given, else the integer nearest to
    /// `steps_per_reference_period * omega_ref / (2 pi sample_rate)`, at least 1. The spec
    /// must be valid.
    pub fn steps_per_sample_for(&self, sample_rate: f64, omega_ref: f64) -> u32 {
        if let Some(n) = self.steps_per_sample {
            return n;
        }
        let n = (self.steps_per_reference_period * omega_ref
            / (2.0 * std::f64::consts::PI * sample_rate))
            .round();
        if n.is_finite() && n >= 1.0 {
            n.min(f64::from(u32::MAX)) as u32
        } else {
            1
        }
    }

    /// Which key chose the number of steps per sample (for error messages).
    pub(crate) fn step_key(&self) -> &'static str {
        if self.steps_per_sample.is_some() {
            "twin.steps_per_sample"
        } else {
            "twin.steps_per_reference_period"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{RigConfig, DEFAULT_RIG_TOML};

    #[test]
    fn defaults_are_valid_and_round_trip_through_toml() {
        let spec = TwinSpec::default();
        spec.validate().unwrap();
        let text = toml::to_string(&spec).unwrap();
        let back: TwinSpec = toml::from_str(&text).unwrap();
        assert_eq!(back, spec);
        let empty: TwinSpec = toml::from_str("").unwrap();
        assert_eq!(empty, spec);
    }

    #[test]
    fn automatic_step_gives_about_1000_steps_per_1fu_period() {
        let spec = TwinSpec::default();
        let w1 = 2.0 * std::f64::consts::PI * 51.27;
        // 1000 x 51.27 / 10240 = 5.007 -> 5 steps per sample, 998.7 per period.
        assert_eq!(spec.steps_per_sample_for(10240.0, w1), 5);
        assert_eq!(spec.steps_per_sample_for(1.0e6, w1), 1);
        let fixed = TwinSpec {
            steps_per_sample: Some(3),
            ..TwinSpec::default()
        };
        assert_eq!(fixed.steps_per_sample_for(10240.0, w1), 3);
    }

    #[test]
    fn bad_values_name_the_key() {
        for (spec, key) in [
            (
                TwinSpec {
                    steps_per_sample: Some(0),
                    ..TwinSpec::default()
                },
                "twin.steps_per_sample = 0",
            ),
            (
                TwinSpec {
                    steps_per_reference_period: -1.0,
                    ..TwinSpec::default()
                },
                "twin.steps_per_reference_period = -1",
            ),
            (
                TwinSpec {
                    queue_blocks: 0,
                    ..TwinSpec::default()
                },
                "twin.queue_blocks = 0",
            ),
            (
                TwinSpec {
                    throttle: f64::NAN,
                    ..TwinSpec::default()
                },
                "twin.throttle = NaN",
            ),
            (
                TwinSpec {
                    discretisation: DiscretisationSpec {
                        cutoff_ratio: 0.0,
                        ..DiscretisationSpec::default()
                    },
                    ..TwinSpec::default()
                },
                "twin.discretisation.cutoff_ratio = 0",
            ),
            (
                TwinSpec {
                    discretisation: DiscretisationSpec {
                        steps_per_sample: 0,
                        ..DiscretisationSpec::default()
                    },
                    ..TwinSpec::default()
                },
                "twin.discretisation.steps_per_sample = 0",
            ),
            (
                TwinSpec {
                    held_contact: HeldContactSpec {
                        contact_nodes: [1, 11],
                        ..HeldContactSpec::default()
                    },
                    ..TwinSpec::default()
                },
                "twin.held_contact.contact_nodes = [1, 11]",
            ),
            (
                TwinSpec {
                    held_contact: HeldContactSpec {
                        max_clearance: 0.5,
                        ..HeldContactSpec::default()
                    },
                    ..TwinSpec::default()
                },
                "twin.held_contact.max_clearance = 0.5",
            ),
        ] {
            let msg = spec.validate().unwrap_err().to_string();
            assert!(msg.contains(key), "{msg}");
        }
    }

    #[test]
    fn the_held_contact_patch_only_where_every_test_holds_contact() {
        let h = HeldContactSpec::default();
        // `rig-config/plans/held-contact.toml`: touching, 1e-5 l, pre-load.
        assert_eq!(h.patch_for(&[0.0, 1e-5, -1e-5]), Some([8, 11]));
        assert_eq!(h.patch_for(&[2e-5]), Some([8, 11]));
        // One test at the reference's clearance: impacts, the model's patch.
        assert_eq!(h.patch_for(&[0.0, 2.33e-3]), None);
        assert_eq!(h.patch_for(&[]), None);
        let off = HeldContactSpec {
            enabled: false,
            ..h.clone()
        };
        assert_eq!(off.patch_for(&[0.0]), None);

        let rig = RigConfig::default_rig();
        let twin = rig.held_contact_twin(&[0.0, 1e-5]).unwrap();
        assert_eq!(twin.reduction.contact_nodes, Some([8, 11]));
        assert_eq!(twin.contact.nodes, rig.contact.nodes);
        assert_ne!(twin.canonical_hash(), rig.canonical_hash());
        assert!(rig.held_contact_twin(&[2.33e-3]).is_none());
        // A patch of the description's own wins; so does a model patch already as coarse.
        let mut own = rig.clone();
        own.reduction.contact_nodes = Some([10, 12]);
        assert!(own.held_contact_twin(&[0.0]).is_none());
        let mut coarse = rig.clone();
        coarse.contact.nodes = [6, 8];
        assert!(coarse.held_contact_twin(&[0.0]).is_none());
        // From TOML.
        let cfg = RigConfig::from_str(
            &format!(
                "{DEFAULT_RIG_TOML}\n[twin.held_contact]\ncontact_nodes = [6, 8]\nmax_clearance = 0.0\n"
            ),
            "test",
        )
        .unwrap();
        assert_eq!(cfg.twin.held_contact.patch_for(&[0.0]), Some([6, 8]));
        assert_eq!(cfg.twin.held_contact.patch_for(&[1e-5]), None);
    }

    #[test]
    fn rig_config_parses_the_twin_table_and_does_not_hash_it() {
        let base = RigConfig::from_str(DEFAULT_RIG_TOML, "default").unwrap();
        assert_eq!(base.twin, TwinSpec::default());
        let text = format!(
            "{DEFAULT_RIG_TOML}\n[twin]\nsteps_per_sample = 7\nqueue_blocks = 8\n\
             after_gap = \"restart_at_rest\"\n"
        );
        let cfg = RigConfig::from_str(&text, "twin.toml").unwrap();
        assert_eq!(cfg.twin.steps_per_sample, Some(7));
        assert_eq!(cfg.twin.queue_blocks, 8);
        assert_eq!(cfg.twin.after_gap, AfterGap::RestartAtRest);
        assert_eq!(cfg.canonical_hash(), base.canonical_hash());

        let unknown = format!("{DEFAULT_RIG_TOML}\n[twin]\nqueue_block = 8\n");
        let err = RigConfig::from_str(&unknown, "twin.toml").unwrap_err();
        assert_eq!(err.key(), Some("twin.queue_block"), "{err}");

        let bad = format!("{DEFAULT_RIG_TOML}\n[twin]\nqueue_blocks = 0\n");
        let msg = RigConfig::from_str(&bad, "twin.toml")
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("twin.toml") && msg.contains("twin.queue_blocks"),
            "{msg}"
        );
    }
}
