//! Merging `[defaults]` into each test and checking every value. Each rule is a small
//! function shared by parsing ([`build`]) and by [`Plan::validate`](super::Plan::validate)
//! ([`check_plan`]), so a plan built in code obeys the same rules as one read from a file.

use std::collections::HashMap;

use super::error::{PlanError, PlanLocation};
use super::raw::{RawPlan, RawTest};
use super::{Direction, Plan, TestSpec, DEFAULT_STEPS_PER_PERIOD};

/// Largest accepted base level / l: a typo guard (1e-2 l is 3 mm on a 300 mm beam, far
/// beyond any base excitation of this rig).
const LEVEL_MAX: f64 = 1e-2;
/// Largest accepted clearance / l (typo guard).
const CLEARANCE_MAX: f64 = 0.1;
/// Largest accepted pre-load, i.e. the most negative clearance is `-CLEARANCE_PRELOAD_MAX`
/// (/ l): 1e-4 l is 30 um on a 300 mm beam, about twice the highest excitation level of the
/// reference's tests (6e-5 l).
// NOTE: a negative clearance makes the probe faces start overlapping by |clearance|. The
// contact law keeps an existing overlap (velocity-level Signorini for closed pairs, never
// pushed out, so no energy is injected): every pair is closed from the first step and
// carries force whenever the motion presses it further, i.e. held contact for the whole
// test. The static force an interference fit would set up is not modelled (the ROM has no
// initial stress), hence a small bound rather than an arbitrary one.
pub const CLEARANCE_PRELOAD_MAX: f64 = 1e-4;
/// Exclusive upper bound of Omega / omega_2.
const OMEGA_MAX: f64 = 10.0;

/// Largest accepted number of frequency steps per test (a typo guard: the paper's tests
/// have 20-40).
pub const MAX_STEPS: u32 = 10_000;
/// Largest accepted settle time, excitation periods (a typo guard: hours at the rig's
/// frequencies).
pub const MAX_SETTLE_PERIODS: u32 = 1_000_000;
/// Largest accepted record window, excitation periods: the rig keeps the window in memory
/// (about 9 kB per period at 51 Hz, 10,240 Hz and 11 channels), so this bounds it to about
/// 1 GB at the rig's first bending frequency.
pub const MAX_RECORD_PERIODS: u32 = 100_000;
/// Largest accepted number of time steps per excitation period of a simulation.
pub const MAX_STEPS_PER_PERIOD: u32 = 10_000_000;
/// Largest accepted simulated record window, time steps (`record_periods x
/// steps_per_period`): the virtual stepped sine keeps about 40 bytes per step of it, so this
/// bounds it to about 4 GB.
pub const MAX_RECORD_STEPS: u64 = 100_000_000;

/// The largest accepted value of a count key.
fn count_max(key: &str) -> u32 {
    match key {
        "steps" => MAX_STEPS,
        "settle_periods" => MAX_SETTLE_PERIODS,
        "record_periods" => MAX_RECORD_PERIODS,
        "steps_per_period" => MAX_STEPS_PER_PERIOD,
        _ => u32::MAX,
    }
}

/// The simulated record window's size rule (on `record_periods`).
fn check_record_steps(record_periods: u32, steps_per_period: u32) -> Result<(), String> {
    let n = u64::from(record_periods) * u64::from(steps_per_period);
    if n <= MAX_RECORD_STEPS {
        Ok(())
    } else {
        Err(format!(
            "record_periods x steps_per_period <= {MAX_RECORD_STEPS:e} time steps (the \
             simulated record window is kept in memory, about 40 bytes per step), got \
             {record_periods} x {steps_per_period} = {n:e}"
        ))
    }
}

/// A value rule: `Err` carries the expectation.
type Rule = fn(f64) -> Result<(), String>;

fn check_level(v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 && v <= LEVEL_MAX {
        Ok(())
    } else {
        Err(format!(
            "a base displacement amplitude / l in (0, {LEVEL_MAX:e}] (e.g. 6e-5)"
        ))
    }
}

pub(super) fn check_clearance(v: f64) -> Result<(), String> {
    if v.is_finite() && (-CLEARANCE_PRELOAD_MAX..=CLEARANCE_MAX).contains(&v) {
        Ok(())
    } else {
        Err(format!(
            "a clearance / l in [-{CLEARANCE_PRELOAD_MAX:e}, {CLEARANCE_MAX}] (e.g. 2.33e-3; 0: \
             the probes touch; negative: a pre-load, the faces overlapping)"
        ))
    }
}

fn check_omega(v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 && v < OMEGA_MAX {
        Ok(())
    } else {
        Err(format!(
            "Omega / omega_2 in (0, {OMEGA_MAX}) (omega_2: the 1FU circular frequency)"
        ))
    }
}

fn check_count(v: i64, what: &str, max: u32) -> Result<u32, String> {
    match u32::try_from(v) {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ if max == u32::MAX => Err(format!("an integer number of {what}, >= 1")),
        _ => Err(format!("an integer number of {what}, >= 1 and <= {max}")),
    }
}

fn check_direction(v: &str) -> Result<Direction, String> {
    match v {
        "up" => Ok(Direction::Up),
        "down" => Ok(Direction::Down),
        _ => Err("\"up\" (increasing frequency) or \"down\" (decreasing frequency)".to_string()),
    }
}

/// The direction/frequency consistency rule. `Err` carries the expectation.
fn check_sweep(direction: Direction, start: f64, end: f64, steps: u32) -> Result<(), String> {
    if steps == 1 {
        return if start == end {
            Ok(())
        } else {
            Err(format!(
                "omega_start = omega_end for a single step (a dwell), got omega_start = \
                 {start}, omega_end = {end}; or steps >= 2"
            ))
        };
    }
    match direction {
        Direction::Up if start < end => Ok(()),
        Direction::Down if start > end => Ok(()),
        Direction::Up => Err(format!(
            "omega_start < omega_end when stepping up, got omega_start = {start}, \
             omega_end = {end} (swap them or use direction = \"down\")"
        )),
        Direction::Down => Err(format!(
            "omega_start > omega_end when stepping down, got omega_start = {start}, \
             omega_end = {end} (swap them or use direction = \"up\")"
        )),
    }
}

/// One test with `[defaults]` behind it: each key comes from the test or the defaults, and
/// an error names where it came from.
struct Merged<'a> {
    file: &'a str,
    test: &'a RawTest,
    defaults: &'a RawTest,
    location: PlanLocation,
}

impl Merged<'_> {
    /// The value of a key and the table it came from.
    fn get<T: Clone>(
        &self,
        key: &str,
        expected: &str,
        pick: impl Fn(&RawTest) -> &Option<T>,
    ) -> Result<(T, PlanLocation), PlanError> {
        if let Some(v) = pick(self.test) {
            return Ok((v.clone(), self.location.clone()));
        }
        if let Some(v) = pick(self.defaults) {
            return Ok((v.clone(), PlanLocation::Defaults));
        }
        Err(PlanError::Missing {
            file: self.file.into(),
            location: self.location.clone(),
            key: key.to_string(),
            expected: expected.to_string(),
        })
    }

    /// Like [`Merged::get`] for a key with a built-in default.
    fn get_or<T: Clone>(
        &self,
        default: T,
        pick: impl Fn(&RawTest) -> &Option<T>,
    ) -> (T, PlanLocation) {
        pick(self.test)
            .clone()
            .map(|v| (v, self.location.clone()))
            .or_else(|| {
                pick(self.defaults)
                    .clone()
                    .map(|v| (v, PlanLocation::Defaults))
            })
            .unwrap_or((default, self.location.clone()))
    }

    fn invalid(
        &self,
        location: PlanLocation,
        key: &'static str,
        value: String,
        expected: String,
    ) -> PlanError {
        PlanError::Invalid {
            file: self.file.into(),
            location,
            key,
            value,
            expected,
        }
    }

    fn float(
        &self,
        key: &'static str,
        pick: impl Fn(&RawTest) -> &Option<f64>,
        rule: Rule,
    ) -> Result<f64, PlanError> {
        // The rule's own wording is the expectation of a missing key too.
        let expected = rule(f64::NAN).err().unwrap_or_default();
        let (v, at) = self.get(key, &expected, pick)?;
        rule(v).map_err(|e| self.invalid(at, key, format!("{v}"), e))?;
        Ok(v)
    }

    fn count(
        &self,
        key: &'static str,
        what: &str,
        pick: impl Fn(&RawTest) -> &Option<i64>,
    ) -> Result<u32, PlanError> {
        let max = count_max(key);
        let expected = format!("an integer number of {what}, >= 1 and <= {max}");
        let (v, at) = self.get(key, &expected, pick)?;
        check_count(v, what, max).map_err(|e| self.invalid(at, key, v.to_string(), e))
    }

    fn build(&self) -> Result<TestSpec, PlanError> {
        let name = match &self.test.name {
            Some(n) if !n.trim().is_empty() => n.clone(),
            Some(n) => {
                return Err(self.invalid(
                    self.location.clone(),
                    "name",
                    format!("{n:?}"),
                    "a non-empty test name".into(),
                ))
            }
            None => {
                return Err(PlanError::Missing {
                    file: self.file.into(),
                    location: self.location.clone(),
                    key: "name".into(),
                    expected: "a unique test name, e.g. \"high-down\"; names have no default"
                        .into(),
                })
            }
        };
        let level = self.float("level", |t| &t.level, check_level)?;
        let clearance = self.float("clearance", |t| &t.clearance, check_clearance)?;
        let omega_start = self.float("omega_start", |t| &t.omega_start, check_omega)?;
        let omega_end = self.float("omega_end", |t| &t.omega_end, check_omega)?;
        let (dir, dir_at) = self.get("direction", "\"up\" or \"down\"", |t: &RawTest| {
            &t.direction
        })?;
        let direction = check_direction(&dir)
            .map_err(|e| self.invalid(dir_at.clone(), "direction", format!("{dir:?}"), e))?;
        let steps = self.count("steps", "frequency steps", |t| &t.steps)?;
        let settle_periods = self.count("settle_periods", "excitation periods", |t| {
            &t.settle_periods
        })?;
        let record_periods = self.count("record_periods", "excitation periods", |t| {
            &t.record_periods
        })?;
        let (spp, spp_at) =
            self.get_or(i64::from(DEFAULT_STEPS_PER_PERIOD), |t| &t.steps_per_period);
        let steps_per_period = check_count(
            spp,
            "time steps per excitation period",
            count_max("steps_per_period"),
        )
        .map_err(|e| self.invalid(spp_at.clone(), "steps_per_period", spp.to_string(), e))?;
        check_record_steps(record_periods, steps_per_period).map_err(|e| {
            self.invalid(spp_at, "steps_per_period", steps_per_period.to_string(), e)
        })?;
        check_sweep(direction, omega_start, omega_end, steps)
            .map_err(|e| self.invalid(dir_at, "direction", format!("{dir:?}"), e))?;
        Ok(TestSpec {
            name,
            level,
            direction,
            clearance,
            omega_start,
            omega_end,
            steps,
            settle_periods,
            record_periods,
            steps_per_period,
        })
    }
}

/// Merges defaults, validates every test and builds the [`Plan`].
pub(super) fn build(raw: RawPlan, file: &str) -> Result<Plan, PlanError> {
    if raw.defaults.name.is_some() {
        return Err(PlanError::Invalid {
            file: file.into(),
            location: PlanLocation::Defaults,
            key: "name",
            value: format!("{:?}", raw.defaults.name.unwrap_or_default()),
            expected: "no default name: each [[test]] names itself".into(),
        });
    }
    if raw.tests.is_empty() {
        return Err(PlanError::NoTests { file: file.into() });
    }
    let mut tests = Vec::with_capacity(raw.tests.len());
    for (index, t) in raw.tests.iter().enumerate() {
        let merged = Merged {
            file,
            test: t,
            defaults: &raw.defaults,
            location: PlanLocation::Test {
                index,
                name: t.name.clone(),
            },
        };
        tests.push(merged.build()?);
    }
    let plan = Plan {
        source: file.to_string(),
        name: raw.name,
        description: raw.description,
        tests,
    };
    check_unique_names(&plan)?;
    Ok(plan)
}

fn check_unique_names(plan: &Plan) -> Result<(), PlanError> {
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (index, t) in plan.tests.iter().enumerate() {
        if let Some(first) = seen.insert(&t.name, index) {
            return Err(PlanError::Invalid {
                file: plan.source.as_str().into(),
                location: PlanLocation::Test {
                    index,
                    name: Some(t.name.clone()),
                },
                key: "name",
                value: format!("{:?}", t.name),
                expected: format!("a name not used by test {} already", first + 1),
            });
        }
    }
    Ok(())
}

/// Checks an already built plan against the same rules.
pub(super) fn check_plan(plan: &Plan) -> Result<(), PlanError> {
    if plan.tests.is_empty() {
        return Err(PlanError::NoTests {
            file: plan.source.as_str().into(),
        });
    }
    for (index, t) in plan.tests.iter().enumerate() {
        let invalid = |key: &'static str, value: String, expected: String| PlanError::Invalid {
            file: plan.source.as_str().into(),
            location: PlanLocation::Test {
                index,
                name: Some(t.name.clone()),
            },
            key,
            value,
            expected,
        };
        if t.name.trim().is_empty() {
            return Err(invalid(
                "name",
                format!("{:?}", t.name),
                "a non-empty test name".into(),
            ));
        }
        let floats: [(&'static str, f64, Rule); 4] = [
            ("level", t.level, check_level),
            ("clearance", t.clearance, check_clearance),
            ("omega_start", t.omega_start, check_omega),
            ("omega_end", t.omega_end, check_omega),
        ];
        for (key, v, rule) in floats {
            rule(v).map_err(|e| invalid(key, format!("{v}"), e))?;
        }
        let counts = [
            ("steps", t.steps, "frequency steps"),
            ("settle_periods", t.settle_periods, "excitation periods"),
            ("record_periods", t.record_periods, "excitation periods"),
            (
                "steps_per_period",
                t.steps_per_period,
                "time steps per excitation period",
            ),
        ];
        for (key, v, what) in counts {
            check_count(i64::from(v), what, count_max(key))
                .map_err(|e| invalid(key, v.to_string(), e))?;
        }
        check_record_steps(t.record_periods, t.steps_per_period)
            .map_err(|e| invalid("steps_per_period", t.steps_per_period.to_string(), e))?;
        check_sweep(t.direction, t.omega_start, t.omega_end, t.steps)
            .map_err(|e| invalid("direction", format!("{:?}", t.direction.as_str()), e))?;
    }
    check_unique_names(plan)
}
