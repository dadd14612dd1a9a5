//! What a diagnosis returns ([`Diagnosis`]): where the model and the recording differ, the
//! effects tried in the order in which they confound each other, each with its parameters,
//! evidence and its error on the tests it was fitted on and on the tests it was validated on,
//! and what the session cannot decide. Serialised as `rigtwin diagnose --json`.

use serde::{Deserialize, Serialize};

use crate::config::{PhysicsSpec, ReductionSpec};
use crate::twin::FeatureComparison;

use super::clearance::ClearanceEvidence;
use super::linear::LinearEvidence;
use super::sensors::SensorEvidence;

/// The verdict of a diagnosis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The model misses physics the session shows (an effect was accepted, or mismatches
    /// beyond the null spread remain: in a regime of impact-free steps, or in the impact band
    /// with the comparison's spread, [`BandSpread`]).
    Mismatch,
    /// Model and recording agree within the comparison's spread.
    NoSignificantMismatch,
}

/// The regime of a step, from the measurement.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// No contact in the record window, at the session's lowest level.
    ImpactFreeLow,
    /// No contact in the record window, at a higher level.
    ImpactFreeHigh,
    /// Contact in the record window (the impact band: non-periodic, compared as
    /// distributions).
    Impacts,
}

/// One compared feature of one step whose score exceeds the threshold.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Located {
    /// Test name.
    pub test: String,
    /// Step, counted from 0.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The regime of the step.
    pub regime: Regime,
    /// Channel.
    pub channel: String,
    /// Feature (`rms`, `amp_p10`, ...).
    pub feature: String,
    /// `|model - measured| / combined spread`.
    pub score: f64,
    /// Measured value (velocities normalised by `Omega q`).
    pub measured: f64,
    /// Model value.
    pub model: f64,
}

/// One step compared: every feature of every compared channel, measured and model with their
/// spreads and scores (the map of the mismatch, the before/after figures).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepScores {
    /// Test name.
    pub test: String,
    /// Index of the test in the session, from 0.
    pub test_index: usize,
    /// Step, counted from 0.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The regime of the step.
    pub regime: Regime,
    /// Base level of the test / l.
    pub level: f64,
    /// The compared features (none when the model missed part of the window).
    pub features: Vec<FeatureComparison>,
}

impl StepScores {
    /// The largest score of channel `channel`'s features (None: not compared).
    pub fn channel_score(&self, channel: &str) -> Option<f64> {
        self.features
            .iter()
            .filter(|f| f.channel == channel)
            .map(|f| f.score)
            .reduce(f64::max)
    }

    /// The largest score of the step (None: nothing compared).
    pub fn max_score(&self) -> Option<f64> {
        self.features.iter().map(|f| f.score).reduce(f64::max)
    }

    /// The comparison of feature `feature` of channel `channel` (None: not compared).
    pub fn feature(&self, channel: &str, feature: &str) -> Option<&FeatureComparison> {
        (self.features.iter()).find(|f| f.channel == channel && f.feature == feature)
    }

    /// The RMS of the step's feature scores, its share of the judge's error (None: nothing
    /// compared).
    pub fn rms_score(&self) -> Option<f64> {
        let n = self.features.len();
        let sum: f64 = self.features.iter().map(|f| f.score * f.score).sum();
        (n > 0).then(|| (sum / n as f64).sqrt())
    }
}

/// Scores per regime: how much of the session mismatches and where.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegimeScores {
    /// The regime.
    pub regime: Regime,
    /// Steps in the regime.
    pub steps: usize,
    /// Steps with a feature above the threshold.
    pub steps_above: usize,
    /// Median over the steps of the step's largest score.
    pub median_max_score: f64,
}

/// The impact band of a model compared with the comparison's own spread (the verdict on the
/// band): every window with contact gets an ensemble of runs from perturbed states and
/// a finer model's difference beside the twin's own sub-windows
/// ([`crate::session::twin_replay::EnsembleOptions`]), as `rigtwin replay --twin` compares.
/// The band is non-periodic: a step scores above the threshold pointwise where the model is
/// right (chaos, the twin's own step); with this spread the typical step of a right model
/// does not.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandSpread {
    /// Ensemble members per window.
    pub members: usize,
    /// Modes of the finer model whose difference joins the spread (None: ensemble only).
    pub finer_modes: Option<usize>,
    /// The band's steps, those above the threshold and the median largest score.
    pub scores: RegimeScores,
    /// Per band step, its largest score with the spread, in session order.
    pub steps: Vec<BandStep>,
    /// Whether the typical band step lies beyond the spread (the median largest score above
    /// the threshold): the band is a mismatch.
    pub beyond: bool,
}

/// One step of the impact band with the comparison's spread ([`BandSpread`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandStep {
    /// Test name.
    pub test: String,
    /// Step, counted from 0.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// The step's largest score.
    pub max_score: f64,
}

/// The validation error of the whole diagnosis with the comparison's spread: the RMS score
/// of every compared feature of the accepted effects' validation tests, the impact band's
/// windows compared with the ensemble and the finer model ([`BandSpread`]), the others
/// pointwise. The judge's own errors ([`EffectResult::error_before`]) are pointwise at the
/// twin's step, where the band's chaos and the twin's own step (it over-counts contact)
/// leave a floor that a right model does not go below (BENCHMARKS.md, "The validation error
/// with the comparison's spread"); a lone accepted band effect reports these instead, each
/// step the median over its draws: the locate or show run and the judge's runs of the same
/// model, scored against the locate or show run's spreads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationWithSpread {
    /// The tests.
    pub tests: Vec<String>,
    /// The model as given, -.
    pub before: f64,
    /// The fixed model, -.
    pub after: f64,
}

/// An error on a set of steps: the RMS of the compared features' scores (for a candidate
/// judged on the impact band, each step's median over the runs of each model).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetError {
    /// Error on the steps the effect was fitted on, -.
    pub train: f64,
    /// Error on the steps it was validated on, -.
    pub validation: f64,
}

/// One effect tried.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectResult {
    /// `linear_frequency`, `linear_damping`, `clamp_friction`, `clearance`, `wear`, `tilt`,
    /// `sensor_gain` or `discretisation`.
    pub effect: String,
    /// Rank among the effects (1: the first named), in the order of identification; accepted
    /// effects rank before rejected ones.
    pub rank: usize,
    /// Whether the effect is in the fixed model.
    pub accepted: bool,
    /// The fitted parameters, with the `[model]` key names.
    pub parameters: serde_json::Value,
    /// Other effects that explain the evidence as well (the channels cannot tell them apart),
    /// with why.
    pub alternatives: Vec<String>,
    /// The evidence, in words and numbers.
    pub evidence: serde_json::Value,
    /// Why accepted or rejected.
    pub reason: String,
    /// Tests fitted on.
    pub train_tests: Vec<String>,
    /// Tests validated on.
    pub validation_tests: Vec<String>,
    /// Error of the model without the effect (with the effects accepted before it): the
    /// judge's, pointwise at the twin's step; for the one accepted effect when it is a band
    /// effect, with the comparison's spread (the locate and show runs; the pointwise ones in
    /// `evidence.pointwise`), where both runs had the band's spread.
    pub error_before: Option<SetError>,
    /// Error of the model with the effect.
    pub error_after: Option<SetError>,
}

impl EffectResult {
    /// Effect `effect` rejected before any fit (not indicated by the evidence, or no trend),
    /// with its `evidence` and the `reason`; no tests, alternatives or errors.
    pub fn unfitted(effect: &str, evidence: serde_json::Value, reason: String) -> EffectResult {
        EffectResult {
            effect: effect.into(),
            rank: 0,
            accepted: false,
            parameters: serde_json::json!({}),
            alternatives: Vec::new(),
            evidence,
            reason,
            train_tests: Vec::new(),
            validation_tests: Vec::new(),
            error_before: None,
            error_after: None,
        }
    }
}

/// The twin's discretisation of the fixed model where the `discretisation` effect was
/// accepted: what `--write-config` puts into `[reduction]` and `[twin]`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Refinement {
    /// `[reduction]` of the fixed model (None: the given one).
    pub reduction: Option<ReductionSpec>,
    /// `[twin] steps_per_reference_period` of the fixed model, its `steps_per_sample` removed
    /// (None: the given step).
    pub steps_per_reference_period: Option<f64>,
}

/// The discretisation stage's evidence (`evidence-discretisation`): the twin as given and
/// each refinement tried, step by step over the session's tests with contact.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DiscretisationEvidence {
    /// The tests the refinements were compared on (the best on these is judged).
    pub train_tests: Vec<String>,
    /// The tests the best refinement was judged on.
    pub validation_tests: Vec<String>,
    /// The twin as given.
    pub given: DiscretisedTwin,
    /// Each refinement tried, in the order tried.
    pub options: Vec<DiscretisedTwin>,
}

/// One discretisation of the twin and how it scores.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DiscretisedTwin {
    /// What is refined against the twin as given, in words (None: the twin as given).
    pub refined: Option<String>,
    /// Retained modes.
    pub modes: usize,
    /// The highest retained mode over f(1FU).
    pub highest_mode_over_1fu: f64,
    /// Contact pairs of its patch.
    pub contact_pairs: usize,
    /// Twin steps per sample.
    pub steps_per_sample: u32,
    /// Twin steps per 1FU period.
    pub steps_per_1fu_period: f64,
    /// Its error on the train and validation tests (None: not run, or nothing compared).
    pub error: Option<SetError>,
    /// Why it could not run (a step beyond the ROM's stability limit, a model error).
    pub failure: Option<String>,
    /// Its steps (empty where it could not run).
    pub steps: Vec<DiscretisedStep>,
}

/// A step of a test with contact under one discretisation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DiscretisedStep {
    /// Test name.
    pub test: String,
    /// Step, counted from 0.
    pub step: usize,
    /// Omega / omega_2.
    pub omega_ratio: f64,
    /// RMS of the step's feature scores, the quantity the judge sums (None: not compared).
    pub score: Option<f64>,
    /// Fraction of the record window in contact, measured (None: not compared).
    pub contact_measured: Option<f64>,
    /// The same by this twin.
    pub contact_model: Option<f64>,
}

/// What a session cannot decide, and why.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Undecided {
    /// The effect.
    pub effect: String,
    /// Why the session cannot tell.
    pub reason: String,
}

/// The work a diagnosis did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisCost {
    /// Model runs (whole or per test).
    pub model_runs: usize,
    /// Rig seconds the model re-ran, s.
    pub model_rig_seconds: f64,
    /// Wall seconds in model runs, s.
    pub model_wall_seconds: f64,
    /// The same per stage, in the order they ran.
    pub stages: Vec<StageCost>,
}

/// The model runs of one stage of a diagnosis.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageCost {
    /// The stage (`locate`, `sensor_gain`, `linear`, `clamp_friction`, `sensor_gain_again`,
    /// `clamp_friction_again`, `discretisation`, `wear`, `clearance`, `tilt`, `show`).
    pub stage: String,
    /// Model runs (whole or per test).
    pub model_runs: usize,
    /// Rig seconds the model re-ran, s.
    pub model_rig_seconds: f64,
    /// Wall seconds in model runs, s.
    pub model_wall_seconds: f64,
}

/// The result of a diagnosis (`rigtwin diagnose --json`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Diagnosis {
    /// The verdict.
    pub verdict: Verdict,
    /// Score above which a feature counts as a mismatch, -.
    pub threshold: f64,
    /// Features above the threshold with the model as given, largest first.
    pub located: Vec<Located>,
    /// Every step's largest score per channel, before (model as given).
    pub scores_before: Vec<StepScores>,
    /// The same with the accepted effects.
    pub scores_after: Vec<StepScores>,
    /// Per regime, before.
    pub regimes_before: Vec<RegimeScores>,
    /// Per regime, after.
    pub regimes_after: Vec<RegimeScores>,
    /// The impact band of the model as given with the comparison's spread (None: no step with
    /// contact, or no ensemble configured).
    pub band_before: Option<BandSpread>,
    /// The same with the accepted effects, where the model as given was beyond the spread
    /// (None as well when no effect was accepted).
    pub band_after: Option<BandSpread>,
    /// The effects tried, by rank.
    pub effects: Vec<EffectResult>,
    /// What the session cannot decide.
    pub undecided: Vec<Undecided>,
    /// The model's extensions as given (`[model]`).
    pub model_before: PhysicsSpec,
    /// The model's extensions with the accepted effects (`[model]` of the fixed model).
    pub model_after: PhysicsSpec,
    /// The twin's discretisation of the fixed model where the `discretisation` effect was
    /// accepted (`[reduction]` and `[twin]` of the written rig description); None: the given
    /// one.
    pub discretisation_after: Option<Refinement>,
    /// The discretisation stage's evidence (None: the twin is the reference's or finer, or
    /// the stage could not compare).
    pub discretisation: Option<DiscretisationEvidence>,
    /// Path of the written rig description (set by the caller).
    pub model: Option<String>,
    /// Tests any effect was validated on (the before/after figures' tests).
    pub validation_tests: Vec<String>,
    /// Their error with the comparison's spread, the model as given and the fixed one (None
    /// where the band was not run with the spread for both: no effect accepted, no
    /// ensemble, or the model as given within the spread; or where the twin's discretisation
    /// was refined: the model as given's spread then holds its own discretisation error).
    pub validation_with_spread: Option<ValidationWithSpread>,
    /// The sensor-sensitivity evidence (None: the session has no record window for it).
    pub sensors: Option<SensorEvidence>,
    /// The linear fits of 1FL and 1FU per test and their amplitude dependence.
    pub linear: Option<LinearEvidence>,
    /// The clearance per test and its trend.
    pub clearance: Option<ClearanceEvidence>,
    /// Model runs and their cost.
    pub cost: DiagnosisCost,
    /// Wall time, s (set by the caller).
    pub wall_seconds: f64,
}
