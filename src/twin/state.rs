//! Warm starts ([`TwinState`]): everything a [`super::Twin`] carries from one DAQ block to the
//! next — the ROM's state (modal coordinates, contact forces, energy accounts), the
//! extensions' state (clamp joints' sliders, wear), the contact circuit's voltage, the base
//! acceleration of the last sample and the stream position — captured between two blocks and
//! restored into a twin of the same model, which then continues bit for bit as the captured
//! one did. The session log keeps one at the start of every step (`/twin/state`), so
//! `rigtwin replay --twin --steps` can re-run a subset of steps from there instead of from
//! rest.
//!
//! A state names the model it belongs to ([`TwinState::model`]: ROM identity, extensions,
//! twin step); restoring it into another model is refused, since its numbers would mean
//! something else there.

use serde::{Deserialize, Serialize};

use crate::sim::effects::EffectsState;
use crate::sim::State;

/// A twin's state between two blocks (see the module docs). Serialises to JSON exactly (every
/// number round-trips), the contact vectors by their non-zero entries only.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TwinState {
    /// The model the state belongs to (ROM hash and size, extensions, twin step).
    pub model: String,
    /// The DAQ sample the next block starts with.
    pub next_sample: u64,
    /// The last block's sequence number.
    pub last_seq: u64,
    /// Base acceleration of the last sample processed, m/s^2 (`None` after a gap or reset).
    pub last_accel: Option<f64>,
    /// The ROM's state.
    pub rom: State,
    /// Relative velocities of the beam sensors at the last step ([`super::TWIN_SENSORS`]),
    /// m/s.
    pub last_velocity: [f64; 4],
    /// The `[model]` extensions' state and the clearance.
    pub effects: EffectsState,
    /// Voltage of the contact-resistance circuit, V.
    pub contact_voltage: f64,
}

impl TwinState {
    /// The state of ensemble member `member` (1, 2, ...) of the step of `test` / `step`
    /// (`record_attempt`, counted from 1): this state with its modal velocities perturbed by
    /// `relative` of their norm ([`crate::sim::State::perturb_velocities`]), from a seed of the
    /// step and the member only, so every run of the same session (and every hypothesis a
    /// diagnosis tries) draws the same perturbations.
    pub fn perturbed(
        &self,
        test: &str,
        step: usize,
        record_attempt: u32,
        member: usize,
        relative: f64,
    ) -> TwinState {
        let mut s = self.clone();
        s.rom
            .perturb_velocities(member_seed(test, step, record_attempt, member), relative);
        s
    }
}

/// FNV-1a over the step's name and numbers: a seed that depends on nothing else.
fn member_seed(test: &str, step: usize, record_attempt: u32, member: usize) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let bytes = test
        .bytes()
        .chain([0xff])
        .chain((step as u64).to_le_bytes())
        .chain(u64::from(record_attempt).to_le_bytes())
        .chain((member as u64).to_le_bytes());
    for b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Why a [`TwinState`] cannot be restored.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StateError {
    /// The state belongs to another model.
    #[error(
        "twin state: it belongs to another model ({state}); this twin is {twin}: re-run the \
         whole session, or re-run with the model the state was logged with"
    )]
    Model {
        /// The state's model.
        state: String,
        /// The twin's.
        twin: String,
    },
    /// The ROM's part does not fit.
    #[error("twin state: {0}")]
    Rom(#[from] crate::sim::StateMismatch),
    /// The extensions' part does not fit.
    #[error("twin state: {0}")]
    Effects(#[from] crate::sim::effects::EffectsStateMismatch),
    /// A scalar is not finite.
    #[error("twin state: {0} is not finite")]
    NonFinite(&'static str),
    /// A state restored into a model of another contact geometry
    /// ([`super::Twin::set_open_state`]) was not captured with the contact open.
    #[error(
        "twin state: not a state of open contact ({0}): it can be restored only into its own model"
    )]
    Open(&'static str),
}

/// Where warm-start states are captured: at the start of every step, i.e. before the first
/// DAQ block that starts at or after the sample of the step's `step_start` event (the step's
/// drive frequency applies from that block). The live twin and the twin replay use this one
/// rule, so they capture at the same samples.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepStarts {
    /// (sample of the `step_start` event, test, step), in event order.
    pending: std::collections::VecDeque<(u64, String, usize)>,
}

impl StepStarts {
    /// The step starts of a recorded session's events.
    pub fn of_events<'a>(
        events: impl IntoIterator<Item = &'a crate::control::SessionEvent>,
    ) -> StepStarts {
        let mut s = StepStarts::default();
        for e in events {
            s.on_event(e);
        }
        s
    }

    /// Takes a session event: a `step_start` schedules a capture.
    pub fn on_event(&mut self, event: &crate::control::SessionEvent) {
        if let crate::control::EventKind::StepStart { test, step, .. } = &event.kind {
            self.pending.push_back((event.sample, test.clone(), *step));
        }
    }

    /// The step whose state is due before the block starting at `first_sample` (test, step),
    /// removed from the schedule; of several due, the last (the earlier ones had no block of
    /// their own).
    pub fn next_due(&mut self, first_sample: u64) -> Option<(String, usize)> {
        let mut due = None;
        while let Some((sample, _, _)) = self.pending.front() {
            if *sample > first_sample {
                break;
            }
            let (_, test, step) = self.pending.pop_front().expect("front");
            due = Some((test, step));
        }
        due
    }
}
