//! Sensor sensitivity errors: a channel records `gain` times its physical value. Applied to
//! the sensors' output before the anti-alias filter, the noise and the ADC, while the DAQ
//! layout keeps the nominal scale, as with a mis-calibrated sensor (or a wrong sensitivity in
//! the DAQ setup): the recorded data are off by the factor, the truth is not.

use crate::rig::daq::DaqLayout;

use super::super::SimRigError;
use super::SensorGainSpec;

/// `(channel index in layout order, gain)` for each entry of `gains`, or an error naming the
/// entry and the channel when the layout has no such channel.
pub fn resolve(
    gains: &[SensorGainSpec],
    layout: &DaqLayout,
) -> Result<Vec<(usize, f64)>, SimRigError> {
    gains
        .iter()
        .enumerate()
        .map(|(i, g)| {
            layout
                .index(&g.channel)
                .map(|k| (k, g.gain))
                .ok_or_else(|| {
                    SimRigError::Spec(format!(
                        "truth.variants.sensor_gains[{i}].channel = {:?}: no such channel \
                         (channels: {})",
                        g.channel,
                        layout
                            .channels
                            .iter()
                            .map(|c| c.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })
        })
        .collect()
}

/// Applies the resolved gains to one truth step's channel values (layout order).
#[inline]
pub fn apply(gains: &[(usize, f64)], values: &mut [f64]) {
    for &(k, g) in gains {
        values[k] *= g;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::sim::DaqSpec;

    #[test]
    fn resolves_names_and_scales_only_those_channels() {
        let layout = crate::rig::channels::layout(&DaqSpec::default());
        let gains = resolve(
            &[
                SensorGainSpec {
                    channel: "upper_tip".into(),
                    gain: 1.03,
                },
                SensorGainSpec {
                    channel: "platform_2".into(),
                    gain: 0.5,
                },
            ],
            &layout,
        )
        .unwrap();
        assert_eq!(gains, [(5, 1.03), (1, 0.5)]);
        let mut v: Vec<f64> = (0..layout.channels.len()).map(|k| k as f64 + 1.0).collect();
        apply(&gains, &mut v);
        assert_eq!(v[5], 6.0 * 1.03);
        assert_eq!(v[1], 1.0);
        assert_eq!(v[0], 1.0);
        assert_eq!(v[2..5], [3.0, 4.0, 5.0]);

        let msg = resolve(
            &[SensorGainSpec {
                channel: "tip".into(),
                gain: 1.0,
            }],
            &layout,
        )
        .unwrap_err()
        .to_string();
        assert!(
            msg.contains("truth.variants.sensor_gains[0].channel = \"tip\"")
                && msg.contains("upper_tip"),
            "{msg}"
        );
    }
}
