//! The channel map: which DAQ channel plays which role. Built from the rig description's
//! `[daq]` table ([`layout`]: the platform accelerometers, then [`FIXED_CHANNELS`]) or read
//! from any [`DaqLayout`] ([`ChannelMap::of`]), so the simulated rig, the hardware backend, the
//! session and the twin all use the same map.
//!
//! It also computes THE base acceleration: the mean of the platform accelerometers
//! ([`base_acceleration`]), the one function every consumer (control, the session summary,
//! the twin) calls, so a live session and its replay agree bit for bit.

use crate::config::{DaqSpec, FIXED_CHANNEL_NAMES};
use crate::rig::daq::{ChannelKind, ChannelSpec, DaqLayout};

/// Accelerometer at the lower beam's tip.
pub const LOWER_TIP: &str = FIXED_CHANNEL_NAMES[0];
/// Accelerometer at the lower beam's middle.
pub const LOWER_MID: &str = FIXED_CHANNEL_NAMES[1];
/// Accelerometer at the upper beam's tip (the vibrometer's spot).
pub const UPPER_TIP: &str = FIXED_CHANNEL_NAMES[2];
/// Accelerometer at the upper beam's middle.
pub const UPPER_MID: &str = FIXED_CHANNEL_NAMES[3];
/// Laser vibrometer velocity at the upper tip.
pub const VIBROMETER: &str = FIXED_CHANNEL_NAMES[4];
/// Contact-resistance circuit voltage.
pub const CONTACT_VOLTAGE: &str = FIXED_CHANNEL_NAMES[5];
/// Amplifier output voltage at the shaker coil.
pub const DRIVE_VOLTAGE: &str = FIXED_CHANNEL_NAMES[6];
/// Shaker coil current.
pub const DRIVE_CURRENT: &str = FIXED_CHANNEL_NAMES[7];

/// The channels after the platform accelerometers, in layout order.
pub const FIXED_CHANNELS: [(&str, ChannelKind); 8] = [
    (LOWER_TIP, ChannelKind::BeamAcceleration),
    (LOWER_MID, ChannelKind::BeamAcceleration),
    (UPPER_TIP, ChannelKind::BeamAcceleration),
    (UPPER_MID, ChannelKind::BeamAcceleration),
    (VIBROMETER, ChannelKind::Vibrometer),
    (CONTACT_VOLTAGE, ChannelKind::ContactVoltage),
    (DRIVE_VOLTAGE, ChannelKind::DriveVoltage),
    (DRIVE_CURRENT, ChannelKind::DriveCurrent),
];

/// The layout of a (valid) `[daq]` table: the platform accelerometers, then
/// [`FIXED_CHANNELS`]; every channel's scale is its kind's full scale / 2^(bits-1).
pub fn layout(spec: &DaqSpec) -> DaqLayout {
    let half = 2f64.powi(spec.adc_bits as i32 - 1);
    let full_scale_counts = (half - 1.0) as i32;
    let channel = |name: &str, kind: ChannelKind| {
        let r = &spec.full_scale;
        let range = match kind {
            ChannelKind::PlatformAcceleration => r.platform_acceleration,
            ChannelKind::BeamAcceleration => r.beam_acceleration,
            ChannelKind::Vibrometer => r.vibrometer,
            ChannelKind::ContactVoltage => r.contact_voltage,
            ChannelKind::DriveVoltage => r.drive_voltage,
            ChannelKind::DriveCurrent => r.drive_current,
        };
        ChannelSpec {
            name: name.to_string(),
            kind,
            scale: range / half,
            full_scale_counts,
        }
    };
    let channels = spec
        .platform_accelerometers
        .iter()
        .map(|n| channel(n, ChannelKind::PlatformAcceleration))
        .chain(FIXED_CHANNELS.iter().map(|&(n, k)| channel(n, k)))
        .collect();
    DaqLayout {
        sample_rate: spec.sample_rate,
        block_size: spec.block_size,
        channels,
    }
}

/// (channel index, scale in m/s^2 per count) of every platform accelerometer of a layout, in
/// layout order (the order [`base_acceleration`] sums them in).
pub fn platform_accelerometers(layout: &DaqLayout) -> Vec<(usize, f64)> {
    layout
        .indices_of(ChannelKind::PlatformAcceleration)
        .into_iter()
        .map(|k| (k, layout.channels[k].scale))
        .collect()
}

/// THE base acceleration, m/s^2: the mean of the platform accelerometers at sample `i` of
/// channel-major `counts` with `len` samples per channel (`counts[k * len + i]`).
/// `platform` is [`platform_accelerometers`] of the layout (not empty).
///
/// NOTE: the operation order is pinned (session summaries and replays are bit for bit): each
/// value is `count * scale` (as [`ChannelSpec::value`]), summed in layout order from the first
/// channel with `Iterator::sum`, then multiplied by `1 / n`. Do not reorder or divide.
#[inline]
pub fn base_acceleration(platform: &[(usize, f64)], counts: &[i32], len: usize, i: usize) -> f64 {
    let inv_n = 1.0 / platform.len() as f64;
    let sum: f64 = platform
        .iter()
        .map(|&(k, scale)| f64::from(counts[k * len + i]) * scale)
        .sum();
    sum * inv_n
}

/// Which channel of a layout plays which role. A role the layout lacks is `None` (the
/// platform list empty); layouts built by [`layout`] have every role.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelMap {
    /// (channel index, scale in m/s^2 per count) of the platform accelerometers, layout order.
    pub platform: Vec<(usize, f64)>,
    /// Lower beam's tip accelerometer.
    pub lower_tip: Option<usize>,
    /// Lower beam's mid accelerometer.
    pub lower_mid: Option<usize>,
    /// Upper beam's tip accelerometer.
    pub upper_tip: Option<usize>,
    /// Upper beam's mid accelerometer.
    pub upper_mid: Option<usize>,
    /// The (first) vibrometer channel.
    pub vibrometer: Option<usize>,
    /// The (first) contact-voltage channel.
    pub contact_voltage: Option<usize>,
    /// The (first) drive-voltage channel.
    pub drive_voltage: Option<usize>,
    /// The (first) drive-current channel.
    pub drive_current: Option<usize>,
}

impl ChannelMap {
    /// The roles of a layout's channels: the platform accelerometers and the other kinds by
    /// kind, the beam accelerometers by name ([`LOWER_TIP`], ...).
    pub fn of(layout: &DaqLayout) -> ChannelMap {
        let first = |kind| layout.indices_of(kind).first().copied();
        let beam = |name| {
            layout
                .index(name)
                .filter(|&k| layout.channels[k].kind == ChannelKind::BeamAcceleration)
        };
        ChannelMap {
            platform: platform_accelerometers(layout),
            lower_tip: beam(LOWER_TIP),
            lower_mid: beam(LOWER_MID),
            upper_tip: beam(UPPER_TIP),
            upper_mid: beam(UPPER_MID),
            vibrometer: first(ChannelKind::Vibrometer),
            contact_voltage: first(ChannelKind::ContactVoltage),
            drive_voltage: first(ChannelKind::DriveVoltage),
            drive_current: first(ChannelKind::DriveCurrent),
        }
    }

    /// [`base_acceleration`] of sample `i` of channel-major `counts` with `len` samples per
    /// channel (the map must have a platform accelerometer).
    #[inline]
    pub fn base_acceleration(&self, counts: &[i32], len: usize, i: usize) -> f64 {
        base_acceleration(&self.platform, counts, len, i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_names_kinds_and_scales() {
        let spec = DaqSpec::default();
        let l = layout(&spec);
        let names: Vec<&str> = l.channels.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "platform_1",
                "platform_2",
                "platform_3",
                "lower_tip",
                "lower_mid",
                "upper_tip",
                "upper_mid",
                "vibrometer",
                "contact_voltage",
                "drive_voltage",
                "drive_current"
            ]
        );
        assert_eq!(l.indices_of(ChannelKind::PlatformAcceleration), [0, 1, 2]);
        assert_eq!(l.indices_of(ChannelKind::BeamAcceleration), [3, 4, 5, 6]);
        let c = &l.channels[0];
        assert_eq!(c.full_scale_counts, (1 << 23) - 1);
        assert_eq!(c.scale, 100.0 / f64::from(1 << 23));
        assert_eq!(l.block_size, 256);
        assert_eq!(l.sample_rate, 10240.0);
    }

    #[test]
    fn map_of_the_default_layout_has_every_role() {
        let m = ChannelMap::of(&layout(&DaqSpec::default()));
        let s = 100.0 / f64::from(1 << 23);
        assert_eq!(m.platform, [(0, s), (1, s), (2, s)]);
        assert_eq!(
            [
                m.lower_tip,
                m.lower_mid,
                m.upper_tip,
                m.upper_mid,
                m.vibrometer,
                m.contact_voltage,
                m.drive_voltage,
                m.drive_current
            ],
            [3, 4, 5, 6, 7, 8, 9, 10].map(Some)
        );
    }

    #[test]
    fn base_acceleration_is_the_mean_in_layout_order() {
        let m = ChannelMap::of(&layout(&DaqSpec::default()));
        let s = m.platform[0].1;
        let len = 2;
        let mut counts = vec![0; 11 * len];
        // Sample 1: counts 1, 2, 4 on the platform channels.
        counts[1] = 1;
        counts[len + 1] = 2;
        counts[2 * len + 1] = 4;
        assert_eq!(m.base_acceleration(&counts, len, 0), 0.0);
        let want = (((f64::from(1) * s) + f64::from(2) * s) + f64::from(4) * s) * (1.0 / 3.0);
        assert_eq!(
            m.base_acceleration(&counts, len, 1).to_bits(),
            want.to_bits()
        );
    }
}
