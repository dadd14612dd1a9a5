//! Safety limits checked on every DAQ block and control update, and the reasons a session
//! aborts. Every abort ramps the drive down and is logged with its reason.
//!
//! Checks: backend faults (amplifier clipping, ADC over-range, device errors), block sequence
//! and shape, acceleration magnitude, contact duty over a sliding window, dead sensor channels
//! (counts constant while the drive is on), and drive saturation (the controller at its limit
//! with the base amplitude short of the target for `saturation_periods` periods). The DAQ
//! watchdog (no block within `daq_timeout_s`) and the operator stop are raised by the session.

use std::collections::VecDeque;

use crate::rig::{ChannelKind, DaqBlock, DaqLayout, RigFault};

use super::amplitude::ControlUpdate;
use super::spec::SafetySpec;

/// Why a session stopped early.
#[derive(
    Clone,
    Debug,
    PartialEq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
    thiserror::Error,
)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AbortReason {
    /// The operator stopped the session (Ctrl-C / SIGINT, or SIGTERM).
    #[error("operator stop (SIGINT or SIGTERM)")]
    Operator,
    /// No DAQ block arrived in time.
    #[error("DAQ silent for {seconds} s (watchdog, safety.daq_timeout_s) after block {last_seq}")]
    DaqTimeout {
        /// The timeout, s.
        seconds: f64,
        /// Sequence number of the last block received (-1: none).
        last_seq: i64,
    },
    /// The DAQ stream ended.
    #[error("DAQ stream ended after block {last_seq}")]
    StreamEnded {
        /// Sequence number of the last block received (-1: none).
        last_seq: i64,
    },
    /// Blocks were lost or arrived out of order.
    #[error("DAQ block {got} arrived where {expected} was due (lost or reordered data)")]
    SequenceGap {
        /// The sequence number due.
        expected: u64,
        /// The one that came.
        got: u64,
    },
    /// A block did not fit the layout.
    #[error("malformed DAQ block: {message}")]
    BadBlock {
        /// What is wrong.
        message: String,
    },
    /// The backend raised a fault.
    #[error("rig fault: {fault}")]
    Rig {
        /// The fault.
        fault: RigFault,
    },
    /// An acceleration channel exceeded its limit.
    #[error("channel {channel}: |a| = {value:.1} m/s^2 at t = {time:.4} s exceeds safety.max_acceleration = {limit} m/s^2")]
    Acceleration {
        /// Channel name.
        channel: String,
        /// The value, m/s^2.
        value: f64,
        /// The limit, m/s^2.
        limit: f64,
        /// Rig time, s.
        time: f64,
    },
    /// The beams were in contact for too large a share of the window.
    #[error("contact duty {duty:.2} over the last {window_s} s exceeds safety.max_contact_duty = {limit} (t = {time:.3} s)")]
    ContactDuty {
        /// Share of samples in contact.
        duty: f64,
        /// The limit.
        limit: f64,
        /// Window, s.
        window_s: f64,
        /// Rig time, s.
        time: f64,
    },
    /// A sensor channel stopped changing while the drive was on.
    #[error("channel {channel}: dead (counts constant for {seconds:.2} s with the drive on, t = {time:.3} s)")]
    DeadChannel {
        /// Channel name.
        channel: String,
        /// How long it was constant, s.
        seconds: f64,
        /// Rig time, s.
        time: f64,
    },
    /// The controller cannot reach the target amplitude within the drive limit.
    #[error("drive saturated: {periods} periods at safety.max_drive_v = {limit_v} V with the base amplitude {measured_m:.3e} m short of the target {target_m:.3e} m")]
    DriveSaturation {
        /// Periods at the limit.
        periods: u32,
        /// The drive limit, V.
        limit_v: f64,
        /// Last measured base amplitude, m.
        measured_m: f64,
        /// Target, m.
        target_m: f64,
    },
    /// The session log could not keep up or failed.
    #[error("{message}")]
    Log {
        /// What failed (the log's error, which names the log file: "session log PATH: ...").
        message: String,
    },
    /// The backend failed.
    #[error("rig backend: {message}")]
    Backend {
        /// What failed.
        message: String,
    },
}

/// Per-block and per-update safety checks of a session.
#[derive(Debug)]
pub struct SafetyMonitor {
    spec: SafetySpec,
    dt: f64,
    accel: Vec<usize>,
    names: Vec<String>,
    contact: Option<usize>,
    contact_threshold_counts: f64,
    /// Channels checked for flat lines (sensors; not the contact channel, which is constant
    /// while open).
    watched: Vec<usize>,
    /// Per watched channel: last count and the sample from which it has been constant with
    /// the drive on (None while the drive is off).
    flat_since: Vec<(i32, Option<u64>)>,
    /// Closed samples and samples per block over the duty window.
    duty: VecDeque<(u32, u32)>,
    duty_sum: (u64, u64),
    duty_blocks: usize,
    saturated_periods: u32,
    next_seq: u64,
}

impl SafetyMonitor {
    /// Monitor for a stream with `layout`; `contact_threshold_v` separates open (above) from
    /// closed (below) on the contact-voltage channel.
    pub fn new(spec: &SafetySpec, layout: &DaqLayout, contact_threshold_v: f64) -> SafetyMonitor {
        let accel: Vec<usize> = layout
            .channels
            .iter()
            .enumerate()
            .filter(|(_, c)| {
                matches!(
                    c.kind,
                    ChannelKind::PlatformAcceleration | ChannelKind::BeamAcceleration
                )
            })
            .map(|(i, _)| i)
            .collect();
        let contact = layout
            .indices_of(ChannelKind::ContactVoltage)
            .first()
            .copied();
        let watched: Vec<usize> = layout
            .channels
            .iter()
            .enumerate()
            .filter(|(_, c)| c.kind != ChannelKind::ContactVoltage)
            .map(|(i, _)| i)
            .collect();
        let block_s = layout.block_size as f64 / layout.sample_rate;
        let duty_blocks = ((spec.contact_window_s / block_s).round() as usize).max(1);
        SafetyMonitor {
            spec: spec.clone(),
            dt: layout.dt(),
            names: layout.channels.iter().map(|c| c.name.clone()).collect(),
            contact_threshold_counts: contact
                .map_or(0.0, |k| contact_threshold_v / layout.channels[k].scale),
            accel,
            contact,
            flat_since: vec![(0, None); watched.len()],
            watched,
            duty: VecDeque::with_capacity(duty_blocks + 1),
            duty_sum: (0, 0),
            duty_blocks,
            saturated_periods: 0,
            next_seq: 0,
        }
    }

    /// Checks a block: sequence, shape, acceleration limits, contact duty, dead channels.
    /// `drive_on`: the drive amplitude is non-zero (a dead channel shows only then).
    pub fn check_block(
        &mut self,
        block: &DaqBlock,
        layout: &DaqLayout,
        drive_on: bool,
    ) -> Result<(), AbortReason> {
        if block.seq != self.next_seq {
            return Err(AbortReason::SequenceGap {
                expected: self.next_seq,
                got: block.seq,
            });
        }
        self.next_seq += 1;
        block.check(layout).map_err(|e| AbortReason::BadBlock {
            message: e.to_string(),
        })?;
        let n = block.len;
        for &k in &self.accel {
            let scale = layout.channels[k].scale;
            let limit_counts = self.spec.max_acceleration / scale;
            if let Some((i, &c)) = block
                .channel(k)
                .iter()
                .enumerate()
                .find(|(_, c)| f64::from(c.unsigned_abs()) > limit_counts)
            {
                return Err(AbortReason::Acceleration {
                    channel: self.names[k].clone(),
                    value: f64::from(c) * scale,
                    limit: self.spec.max_acceleration,
                    time: block.time + i as f64 * self.dt,
                });
            }
        }
        if let Some(k) = self.contact {
            let closed = block
                .channel(k)
                .iter()
                .filter(|&&c| f64::from(c) < self.contact_threshold_counts)
                .count() as u32;
            self.duty.push_back((closed, n as u32));
            self.duty_sum.0 += u64::from(closed);
            self.duty_sum.1 += n as u64;
            while self.duty.len() > self.duty_blocks {
                let (c, m) = self.duty.pop_front().expect("non-empty");
                self.duty_sum.0 -= u64::from(c);
                self.duty_sum.1 -= u64::from(m);
            }
            if self.duty.len() == self.duty_blocks {
                let duty = self.duty_sum.0 as f64 / self.duty_sum.1 as f64;
                if duty > self.spec.max_contact_duty {
                    return Err(AbortReason::ContactDuty {
                        duty,
                        limit: self.spec.max_contact_duty,
                        window_s: self.spec.contact_window_s,
                        time: block.time + n as f64 * self.dt,
                    });
                }
            }
        }
        let limit_samples = (self.spec.dead_channel_s / self.dt).ceil() as u64;
        for (w, &k) in self.watched.iter().enumerate() {
            let counts = block.channel(k);
            let (last, since) = &mut self.flat_since[w];
            for (i, &c) in counts.iter().enumerate() {
                let sample = block.first_sample + i as u64;
                if !drive_on {
                    *since = None;
                } else if since.is_none() || c != *last {
                    *since = Some(sample);
                }
                *last = c;
            }
            if let Some(s) = *since {
                let end = block.first_sample + n as u64;
                if end - s >= limit_samples {
                    return Err(AbortReason::DeadChannel {
                        channel: self.names[k].clone(),
                        seconds: (end - s) as f64 * self.dt,
                        time: end as f64 * self.dt,
                    });
                }
            }
        }
        Ok(())
    }

    /// Checks a control update for drive saturation.
    pub fn check_update(&mut self, u: &ControlUpdate, target_m: f64) -> Result<(), AbortReason> {
        if u.saturated {
            self.saturated_periods += 1;
        } else {
            self.saturated_periods = 0;
        }
        if self.saturated_periods >= self.spec.saturation_periods {
            return Err(AbortReason::DriveSaturation {
                periods: self.saturated_periods,
                limit_v: self.spec.max_drive_v,
                measured_m: u.measured_m,
                target_m,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::ChannelSpec;

    fn layout() -> DaqLayout {
        let ch = |name: &str, kind, scale| ChannelSpec {
            name: name.into(),
            kind,
            scale,
            full_scale_counts: 1 << 20,
        };
        DaqLayout {
            sample_rate: 1000.0,
            block_size: 100,
            channels: vec![
                ch("platform_1", ChannelKind::PlatformAcceleration, 0.01),
                ch("contact_voltage", ChannelKind::ContactVoltage, 0.001),
            ],
        }
    }

    fn block(seq: u64, accel: impl Fn(u64) -> i32, contact: i32) -> DaqBlock {
        let first = seq * 100;
        let mut counts: Vec<i32> = (0..100).map(|i| accel(first + i)).collect();
        counts.extend(std::iter::repeat_n(contact, 100));
        DaqBlock {
            seq,
            first_sample: first,
            time: first as f64 / 1000.0,
            len: 100,
            counts,
        }
    }

    #[test]
    fn each_limit_raises_its_reason() {
        let (spec, l) = (SafetySpec::default(), layout());
        let moving = |k: u64| ((k as f64 * 0.3).sin() * 1000.0) as i32;
        let mut m = SafetyMonitor::new(&spec, &l, 2.5);
        for s in 0..20 {
            m.check_block(&block(s, moving, 5000), &l, true).unwrap();
        }
        // Gap.
        assert!(matches!(
            m.check_block(&block(21, moving, 5000), &l, true),
            Err(AbortReason::SequenceGap {
                expected: 20,
                got: 21
            })
        ));
        // Acceleration: 3001 m/s^2 = 300100 counts.
        let mut m = SafetyMonitor::new(&spec, &l, 2.5);
        let e = m
            .check_block(&block(0, |_| 300_100, 5000), &l, true)
            .unwrap_err();
        assert!(e.to_string().contains("platform_1"), "{e}");
        // Contact duty: closed (1 V < 2.5 V) all the time.
        let mut m = SafetyMonitor::new(&spec, &l, 2.5);
        let mut r = Ok(());
        for s in 0..10 {
            r = m.check_block(&block(s, moving, 1000), &l, true);
            if r.is_err() {
                break;
            }
        }
        assert!(matches!(r, Err(AbortReason::ContactDuty { .. })), "{r:?}");
        // Dead channel: constant counts with the drive on for 0.5 s; fine with the drive off.
        let mut m = SafetyMonitor::new(&spec, &l, 2.5);
        for s in 0..10 {
            m.check_block(&block(s, |_| 7, 5000), &l, false).unwrap();
        }
        let mut r = Ok(());
        for s in 10..20 {
            r = m.check_block(&block(s, |_| 7, 5000), &l, true);
            if r.is_err() {
                break;
            }
        }
        let e = r.unwrap_err();
        assert!(
            matches!(e, AbortReason::DeadChannel { .. }) && e.to_string().contains("platform_1"),
            "{e}"
        );
    }
}
