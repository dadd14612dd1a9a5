//! Why an effect could not be applied to a ROM or a DAQ layout ([`PhysicsError`]): every
//! variant names the key (`model.modes[0].mode`, `truth.variants.sensor_gains[1].channel`,
//! ...) and what was found instead.

/// An effect that does not fit the ROM or the channels it is applied to.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A mode label the ROM does not have.
    #[error("{key} = {label:?}: the ROM has no mode with that label (labels: {})", labels.join(", "))]
    UnknownMode {
        /// Key of the label.
        key: String,
        /// The label given.
        label: String,
        /// The ROM's labels.
        labels: Vec<String>,
    },
    /// A corrected frequency too far from the ROM's.
    #[error(
        "{key} = {frequency_hz}: expected a natural frequency within {low} to {high} times the \
         ROM's {rom_hz:.4} Hz for mode {label}"
    )]
    FrequencyRange {
        /// Key of the frequency.
        key: String,
        /// Mode label.
        label: String,
        /// The frequency given, Hz.
        frequency_hz: f64,
        /// The ROM's frequency of the mode, Hz.
        rom_hz: f64,
        /// The accepted factor range.
        low: f64,
        /// The accepted factor range.
        high: f64,
    },
    /// A mode that does not move the output an effect needs (the clamp's tip).
    #[error(
        "{key}: mode {label} does not move the output {output:?} (participation \
         {participation}): cannot convert the slip amplitude"
    )]
    NoParticipation {
        /// Key of the effect.
        key: String,
        /// Mode label.
        label: String,
        /// Output name.
        output: String,
        /// Its participation in the mode.
        participation: f64,
    },
    /// A channel name that is not among the channels.
    #[error("{key} = {channel:?}: no such channel (channels: {})", channels.join(", "))]
    UnknownChannel {
        /// Key of the channel.
        key: String,
        /// The channel given.
        channel: String,
        /// The channels there are.
        channels: Vec<String>,
    },
}
