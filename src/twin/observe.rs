//! How the model's prediction becomes what the rig's channels would record ([`Observation`]),
//! so that the twin is compared with the measurement like with like:
//!
//! - Sensor sensitivities (`[model] sensor_gains`, true over nominal): a platform
//!   accelerometer's gain is divided out of the measured base acceleration the twin consumes
//!   (the twin is driven by the true base motion); the tip channels' gains are applied to the
//!   predicted tip velocities as the summary derives them from the channels
//!   ([`TipObservation`]).
//! - Contact detection: the twin's contact state passes through the contact-resistance circuit
//!   (`[daq.contact_circuit]`), a minimum-hold per DAQ sample and the threshold
//!   (`[control] contact_threshold_v`), as the measured contact does
//!   ([`crate::physics::contact_detection`]).
//!
// NOTE (tip channels): the measured relative velocities are built by the step summary
// (`control::summary`): upper = vibrometer - base velocity (or the integrated upper-tip
// acceleration minus the base's without a vibrometer), lower = integral of (lower-tip
// acceleration - base acceleration), the base being the mean of the platform accelerometers.
// With sensitivities `g` (channel) and `g_p` (the platform mean), the channels record `g` times
// the absolute motion and the base channel `g_p a_b`, so what the summary makes of a true
// relative velocity `v` and base velocity `v_b` is `g v + (g - g_p) v_b`. The twin knows `v`
// and the true base acceleration; `v_b` is its drift-free periodic integral over the record
// window (the summary's own integration). With every gain 1 the observation is the identity
// and is skipped (the nominal twin's bits do not change).

use crate::config::{ContactCircuitSpec, PhysicsSpec};
use crate::physics::sensor_gain::{self, gain_of};
use crate::rig::channels::ChannelMap;
use crate::rig::daq::DaqLayout;

use super::error::TwinError;

/// How the tip relative velocities of the summary see a true relative velocity `v` and base
/// velocity `v_b`: `gain v + base_weight v_b` (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipObservation {
    /// Sensitivity of the tip's channel.
    pub gain: f64,
    /// `gain - g_p`, the weight of the base velocity.
    pub base_weight: f64,
}

impl TipObservation {
    /// The identity (nominal sensors).
    pub const IDENTITY: TipObservation = TipObservation {
        gain: 1.0,
        base_weight: 0.0,
    };

    /// Whether it is the identity.
    pub fn is_identity(&self) -> bool {
        *self == TipObservation::IDENTITY
    }
}

/// The model's observation of the rig's channels (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// The contact-resistance circuit.
    pub circuit: ContactCircuitSpec,
    /// Contact-voltage threshold, V.
    pub contact_threshold_v: f64,
    /// Per platform accelerometer of the layout (layout order), its sensitivity.
    pub platform_gains: Vec<(usize, f64)>,
    /// The upper and lower tip as the summary derives them.
    pub upper: TipObservation,
    /// See `upper`.
    pub lower: TipObservation,
    /// Every compared beam channel as the comparison derives it
    /// ([`crate::control::summary::COMPARED_CHANNELS`] order; the identity for a channel the
    /// layout lacks).
    pub beams: [TipObservation; 5],
}

impl Observation {
    /// The observation of the channels of `layout` with the sensitivities of `model`
    /// (`[model]`), the circuit `circuit` and the threshold `contact_threshold_v` (V). Fails
    /// on a gain for a channel the layout does not have (naming `model.sensor_gains[i]`).
    pub fn new(
        layout: &DaqLayout,
        model: &PhysicsSpec,
        circuit: &ContactCircuitSpec,
        contact_threshold_v: f64,
    ) -> Result<Observation, TwinError> {
        let gains = sensor_gain::resolve(
            &model.sensor_gains,
            layout.channels.iter().map(|c| c.name.as_str()),
            "model",
        )?;
        let map = ChannelMap::of(layout);
        let platform_gains: Vec<(usize, f64)> = map
            .platform
            .iter()
            .map(|&(k, _)| (k, gain_of(&gains, k)))
            .collect();
        let g_p = if platform_gains.is_empty() {
            1.0
        } else {
            platform_gains.iter().map(|&(_, g)| g).sum::<f64>() / platform_gains.len() as f64
        };
        let tip = |channel: Option<usize>| match channel {
            Some(k) => {
                let gain = gain_of(&gains, k);
                TipObservation {
                    gain,
                    base_weight: gain - g_p,
                }
            }
            None => TipObservation::IDENTITY,
        };
        let upper = tip(map.vibrometer.or(map.upper_tip));
        let lower = tip(map.lower_tip);
        let beams = [
            tip(map.vibrometer),
            tip(map.upper_tip),
            tip(map.upper_mid),
            tip(map.lower_tip),
            tip(map.lower_mid),
        ];
        // The identity exactly when every gain involved is 1 (the subtraction above is exact).
        Ok(Observation {
            circuit: circuit.clone(),
            contact_threshold_v,
            platform_gains,
            upper,
            lower,
            beams,
        })
    }

    /// The nominal observation (every sensitivity 1) with the circuit and threshold.
    pub fn nominal(circuit: &ContactCircuitSpec, contact_threshold_v: f64) -> Observation {
        Observation {
            circuit: circuit.clone(),
            contact_threshold_v,
            platform_gains: Vec::new(),
            upper: TipObservation::IDENTITY,
            lower: TipObservation::IDENTITY,
            beams: [TipObservation::IDENTITY; 5],
        }
    }
}
