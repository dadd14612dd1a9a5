//! The clearance the twin runs with, test by test: each test's clearance (its `test_start`
//! event's, in units of l, or what the model's `[model.clearance]` makes of it) applies from the first DAQ block that starts at or after the
//! event's sample. In the live session the event is logged after the block that ended the
//! previous test, and the simulated rig changes its clearance from the next block, so the live
//! twin and a replay cut at the same place: both use this one schedule.

use std::collections::VecDeque;

use crate::config::physics::test_clearance;
use crate::config::ClearanceSpec;
use crate::control::{EventKind, SessionEvent};
use crate::plan::per_l_to_metres;

/// Test clearances waiting for their first block (see the module documentation).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClearanceSchedule {
    /// Beam length l, m (the unit of the events' clearances).
    beam_length: f64,
    /// The model's clearance per test (`[model.clearance]`), if declared.
    model: Option<ClearanceSpec>,
    /// (sample of the `test_start` event, clearance in metres), in event order.
    pending: VecDeque<(u64, f64)>,
}

impl ClearanceSchedule {
    /// An empty schedule for a rig of beam length `beam_length` m and the model's clearance
    /// per test `model` (`[model.clearance]`; `None`: the plan's).
    pub fn new(beam_length: f64, model: Option<&ClearanceSpec>) -> ClearanceSchedule {
        ClearanceSchedule {
            beam_length,
            model: model.cloned(),
            pending: VecDeque::new(),
        }
    }

    /// The schedule of a recorded session's events.
    pub fn of_events<'a>(
        beam_length: f64,
        model: Option<&ClearanceSpec>,
        events: impl IntoIterator<Item = &'a SessionEvent>,
    ) -> ClearanceSchedule {
        let mut s = ClearanceSchedule::new(beam_length, model);
        for e in events {
            s.on_event(e);
        }
        s
    }

    /// Takes a session event: a `test_start` schedules its test's clearance.
    pub fn on_event(&mut self, event: &SessionEvent) {
        if let EventKind::TestStart {
            test, clearance, ..
        } = &event.kind
        {
            let plan_m = per_l_to_metres(*clearance, self.beam_length);
            let c = test_clearance(self.model.as_ref(), test, plan_m);
            self.pending.push_back((event.sample, c));
        }
    }

    /// The first scheduled clearance, m (the twin's clearance before the first block).
    pub fn first(&self) -> Option<f64> {
        self.pending.front().map(|&(_, c)| c)
    }

    /// The clearance in force for the block starting at `first_sample`, m: the last of those
    /// due by then (removed from the schedule), or the first scheduled one when none is due
    /// yet (0 with none at all).
    pub fn in_force_at(&mut self, first_sample: u64) -> f64 {
        let mut c = self.first().unwrap_or(0.0);
        while let Some(x) = self.next_due(first_sample) {
            c = x;
        }
        c
    }

    /// The next clearance due before the block starting at `first_sample`, m, removed from
    /// the schedule; call until `None` and apply each in order.
    pub fn next_due(&mut self, first_sample: u64) -> Option<f64> {
        match self.pending.front() {
            Some(&(sample, c)) if sample <= first_sample => {
                self.pending.pop_front();
                Some(c)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_start(sample: u64, clearance: f64) -> SessionEvent {
        SessionEvent {
            time: 0.0,
            sample,
            kind: EventKind::TestStart {
                test: "t".into(),
                level: 1e-5,
                direction: "up".into(),
                clearance,
            },
        }
    }

    #[test]
    fn clearances_apply_from_the_first_block_at_or_after_their_event() {
        let events = [test_start(0, 2e-3), test_start(100, 3e-3)];
        let mut s = ClearanceSchedule::of_events(0.5, None, &events);
        assert_eq!(s.first(), Some(1e-3));
        assert_eq!(s.next_due(0), Some(1e-3));
        assert_eq!(s.next_due(0), None);
        assert_eq!(s.next_due(99), None);
        assert_eq!(s.next_due(128), Some(1.5e-3));
        assert_eq!(s.next_due(256), None);
        // The model's clearance per test.
        let model = ClearanceSpec {
            offset: 1e-4,
            tests: vec![crate::config::TestClearanceSpec {
                test: "other".into(),
                clearance: 5e-3,
            }],
        };
        let mut s = ClearanceSchedule::of_events(0.5, Some(&model), &events);
        assert_eq!(s.next_due(0), Some(1e-3 + 1e-4));
        let mut events = events;
        if let EventKind::TestStart { test, .. } = &mut events[1].kind {
            *test = "other".into();
        }
        let mut s = ClearanceSchedule::of_events(0.5, Some(&model), &events);
        assert_eq!(s.next_due(0), Some(1e-3 + 1e-4));
        assert_eq!(s.next_due(100), Some(5e-3));
    }
}
