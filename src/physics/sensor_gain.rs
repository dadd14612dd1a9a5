//! Sensor sensitivities: a channel records `gain` times its physical value (true sensitivity
//! over nominal). In the simulated rig's truth they are applied to the sensors' output before
//! the anti-alias filter, the noise and the ADC, while the DAQ layout keeps the nominal scale,
//! as with a mis-calibrated sensor (or a wrong sensitivity in the DAQ setup): the recorded data
//! are off by the factor, the truth is not. In the model they are the observation of the
//! predicted channels, and a platform accelerometer's gain is divided out of the measured base
//! acceleration the twin consumes.

use super::{PhysicsError, SensorGainSpec};

/// `(channel index, gain)` for each entry of `gains`, the index into `channels` (the channel
/// names in layout order), or an error naming the key `<prefix>.sensor_gains[i].channel`.
pub fn resolve<'a>(
    gains: &[SensorGainSpec],
    channels: impl Iterator<Item = &'a str> + Clone,
    prefix: &str,
) -> Result<Vec<(usize, f64)>, PhysicsError> {
    gains
        .iter()
        .enumerate()
        .map(|(i, g)| {
            channels
                .clone()
                .position(|c| c == g.channel)
                .map(|k| (k, g.gain))
                .ok_or_else(|| PhysicsError::UnknownChannel {
                    key: format!("{prefix}.sensor_gains[{i}].channel"),
                    channel: g.channel.clone(),
                    channels: channels.clone().map(str::to_owned).collect(),
                })
        })
        .collect()
}

/// The gain of channel `k` among resolved gains (1 when not listed).
pub fn gain_of(gains: &[(usize, f64)], k: usize) -> f64 {
    gains
        .iter()
        .find(|&&(c, _)| c == k)
        .map_or(1.0, |&(_, g)| g)
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

    #[test]
    fn resolves_names_and_scales_only_those_channels() {
        // The default rig's channels, in layout order.
        let daq = crate::config::DaqSpec::default();
        let names: Vec<&str> = daq.channel_names().collect();
        let channels = || names.iter().copied();
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
            channels(),
            "truth.variants",
        )
        .unwrap();
        assert_eq!(gains, [(5, 1.03), (1, 0.5)]);
        let mut v: Vec<f64> = (0..names.len()).map(|k| k as f64 + 1.0).collect();
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
            channels(),
            "truth.variants",
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
