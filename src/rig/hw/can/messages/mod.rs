//! The rig's CAN FD messages, exactly as `firmware-interfaces/rig.dbc` defines them: one table
//! ([`MESSAGES`]) of identifiers, lengths, senders and byte-aligned little-endian integer
//! signals with their scale factors, from which the frames are packed and unpacked and the DBC
//! file is written ([`dbc`]; a test keeps the file and the table identical). Typed messages
//! ([`Message`]) hold raw signal values; physical values are `raw * factor`.
//!
//! Decoding is strict: an unknown identifier, a classic or extended frame, a wrong length or a
//! field out of its documented set is a [`DecodeError`] naming the frame id, the byte and the
//! signal. Reserved bytes are sent as zero and ignored on receipt.

use super::frame::CanFrame;

mod dbc;
mod table;
mod types;

pub use dbc::dbc;
pub use table::*;
pub use types::*;

/// Why a frame does not decode.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// No message has this identifier.
    #[error("CAN frame {id:#05x}: unknown identifier (rig.dbc has none)")]
    UnknownId {
        /// The identifier.
        id: u32,
    },
    /// Not a standard-identifier CAN FD frame.
    #[error("CAN frame {id:#05x} ({name}): {what}")]
    Format {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// What is wrong.
        what: &'static str,
    },
    /// Wrong data length.
    #[error("CAN frame {id:#05x} ({name}): {len} data bytes, expected {expected}")]
    Length {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// Bytes received.
        len: usize,
        /// Bytes defined.
        expected: usize,
    },
    /// A field outside its documented values.
    #[error("CAN frame {id:#05x} ({name}), byte {byte}, {signal} = {value}: {what}")]
    Field {
        /// Identifier.
        id: u32,
        /// Message name.
        name: &'static str,
        /// First byte of the signal.
        byte: usize,
        /// Signal name.
        signal: &'static str,
        /// Raw value.
        value: i128,
        /// What was expected.
        what: &'static str,
    },
}

/// Raw value of `s` in `data` (which has the message's length).
pub fn raw(data: &[u8], s: &SignalDef) -> i128 {
    let n = (s.bits / 8) as usize;
    let mut v: u64 = 0;
    for (i, b) in data[s.byte..s.byte + n].iter().enumerate() {
        v |= u64::from(*b) << (8 * i);
    }
    if s.signed && s.bits < 64 && v & (1 << (s.bits - 1)) != 0 {
        i128::from(v) - (1i128 << s.bits)
    } else if s.signed {
        i128::from(v as i64)
    } else {
        i128::from(v)
    }
}

fn put(data: &mut [u8], s: &SignalDef, value: i128) {
    let n = (s.bits / 8) as usize;
    let v = value as u64; // two's complement, truncated to the signal's width below
    for (i, b) in data[s.byte..s.byte + n].iter_mut().enumerate() {
        *b = (v >> (8 * i)) as u8;
    }
}

/// A decoded signal value as the DBC defines it: integers where the factor is 1, `raw *
/// factor` otherwise.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum SignalValue {
    /// Unscaled integer.
    Int(i128),
    /// Scaled value.
    Float(f64),
}

/// Every signal of a well-formed frame of a known message, with its physical value. Used for
/// the decoded-values log that the `cantools` cross-check compares.
pub fn signal_values(frame: &CanFrame) -> Result<Vec<(&'static str, SignalValue)>, DecodeError> {
    let d = checked_def(frame)?;
    Ok(d.signals
        .iter()
        .map(|s| {
            let r = raw(frame.data(), s);
            let v = if s.factor == 1.0 {
                SignalValue::Int(r)
            } else {
                SignalValue::Float(r as f64 * s.factor)
            };
            (s.name, v)
        })
        .collect())
}

fn checked_def(frame: &CanFrame) -> Result<&'static MessageDef, DecodeError> {
    let d = def(frame.id)
        .filter(|_| !frame.extended)
        .ok_or(DecodeError::UnknownId { id: frame.id })?;
    if !frame.fd {
        return Err(DecodeError::Format {
            id: d.id,
            name: d.name,
            what: "a classic CAN frame: every rig message is CAN FD",
        });
    }
    if frame.len() != d.len {
        return Err(DecodeError::Length {
            id: d.id,
            name: d.name,
            len: frame.len(),
            expected: d.len,
        });
    }
    Ok(d)
}

/// Any rig message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Message {
    /// FAULT.
    Fault(Fault),
    /// STREAM_CONTROL.
    StreamControl(StreamControl),
    /// DRIVE_SETPOINT.
    DriveSetpoint(DriveSetpoint),
    /// DRIVE_STATUS.
    DriveStatus(DriveStatus),
    /// HOST_HEARTBEAT.
    HostHeartbeat(HostHeartbeat),
    /// DEVICE_HEARTBEAT.
    DeviceHeartbeat(DeviceHeartbeat),
    /// TIME_SYNC_REQUEST.
    TimeSyncRequest(TimeSyncRequest),
    /// TIME_SYNC_RESPONSE.
    TimeSyncResponse(TimeSyncResponse),
    /// DAQ_BLOCK_HEADER.
    BlockHeader(BlockHeader),
    /// DAQ_SAMPLES.
    Samples(SampleFrame),
}

/// Largest int24 magnitude on the positive side.
pub const INT24_MAX: i32 = (1 << 23) - 1;
/// Smallest int24.
pub const INT24_MIN: i32 = -(1 << 23);

impl Message {
    /// The message's definition.
    pub fn def(&self) -> &'static MessageDef {
        let id = match self {
            Message::Fault(_) => id::FAULT,
            Message::StreamControl(_) => id::STREAM_CONTROL,
            Message::DriveSetpoint(_) => id::DRIVE_SETPOINT,
            Message::DriveStatus(_) => id::DRIVE_STATUS,
            Message::HostHeartbeat(_) => id::HOST_HEARTBEAT,
            Message::DeviceHeartbeat(_) => id::DEVICE_HEARTBEAT,
            Message::TimeSyncRequest(_) => id::TIME_SYNC_REQUEST,
            Message::TimeSyncResponse(_) => id::TIME_SYNC_RESPONSE,
            Message::BlockHeader(_) => id::DAQ_BLOCK_HEADER,
            Message::Samples(_) => id::DAQ_SAMPLES,
        };
        def(id).expect("every message is in the table")
    }

    /// Raw signal values in table order.
    fn raws(&self) -> Vec<i128> {
        use Message as M;
        match *self {
            M::Fault(f) => vec![
                f.code as i128,
                f.channel.into(),
                f.value.into(),
                f.count.into(),
            ],
            M::StreamControl(s) => vec![s.command as i128, s.session.into()],
            M::DriveSetpoint(s) => vec![
                s.seq.into(),
                i128::from(s.enable),
                s.frequency.into(),
                s.amplitude.into(),
                s.ramp.into(),
            ],
            M::DriveStatus(s) => vec![
                s.block_seq.into(),
                s.applied_seq.into(),
                s.state.into(),
                s.frequency.into(),
                s.amplitude.into(),
                s.target.into(),
                s.phase.into(),
            ],
            M::HostHeartbeat(h) => vec![h.counter.into(), h.consumed.into()],
            M::DeviceHeartbeat(h) => vec![
                h.counter.into(),
                h.state.into(),
                h.flags.into(),
                h.rx_errors.into(),
            ],
            M::TimeSyncRequest(t) => vec![t.seq.into(), t.host_time_us.into()],
            M::TimeSyncResponse(t) => {
                vec![t.seq.into(), t.host_time_us.into(), t.device_time_us.into()]
            }
            M::BlockHeader(h) => vec![
                h.seq.into(),
                h.first_sample.into(),
                h.timestamp_us.into(),
                h.channel_mask.into(),
                h.block_size.into(),
                h.sample_rate.into(),
                h.crc.into(),
            ],
            M::Samples(s) => {
                let mut v = vec![s.block_seq.into(), s.index.into(), s.count.into()];
                v.extend(s.samples.iter().map(|&x| i128::from(x)));
                v
            }
        }
    }

    /// The frame (CAN FD, BRS, standard id). Sample values are truncated to 24 bits: the
    /// block encoder checks their range first.
    pub fn encode(&self) -> CanFrame {
        let d = self.def();
        let mut data = [0u8; 64];
        for (s, v) in d.signals.iter().zip(self.raws()) {
            put(&mut data, s, v);
        }
        CanFrame::fd(d.id, &data[..d.len]).expect("table lengths are CAN FD lengths")
    }

    /// Decodes a frame; see the module docs for what is rejected.
    pub fn decode(frame: &CanFrame) -> Result<Message, DecodeError> {
        let d = checked_def(frame)?;
        let data = frame.data();
        let r: Vec<i128> = d.signals.iter().map(|s| raw(data, s)).collect();
        let bad = |i: usize, what: &'static str| DecodeError::Field {
            id: d.id,
            name: d.name,
            byte: d.signals[i].byte,
            signal: d.signals[i].name,
            value: r[i],
            what,
        };
        // Narrowing casts below are exact: each raw value has its signal's width.
        Ok(match d.id {
            id::FAULT => Message::Fault(Fault {
                code: FaultCode::from_raw(r[0])
                    .ok_or_else(|| bad(0, "expected a fault code 1..=6"))?,
                channel: r[1] as u8,
                value: r[2] as i32,
                count: r[3] as u16,
            }),
            id::STREAM_CONTROL => Message::StreamControl(StreamControl {
                command: match r[0] {
                    1 => StreamCommand::Start,
                    2 => StreamCommand::Stop,
                    _ => return Err(bad(0, "expected 1 (start) or 2 (stop)")),
                },
                session: r[1] as u32,
            }),
            id::DRIVE_SETPOINT => {
                if r[1] > 1 {
                    return Err(bad(1, "expected 0 or 1"));
                }
                if r[2] == 0 {
                    return Err(bad(2, "expected a frequency > 0"));
                }
                Message::DriveSetpoint(DriveSetpoint {
                    seq: r[0] as u16,
                    enable: r[1] == 1,
                    frequency: r[2] as u64,
                    amplitude: r[3] as u32,
                    ramp: r[4] as u32,
                })
            }
            id::DRIVE_STATUS => {
                if r[2] > 3 {
                    return Err(bad(2, "expected a drive state 0..=3"));
                }
                Message::DriveStatus(DriveStatus {
                    block_seq: r[0] as u32,
                    applied_seq: r[1] as u16,
                    state: r[2] as u8,
                    frequency: r[3] as u64,
                    amplitude: r[4] as u32,
                    target: r[5] as u32,
                    phase: r[6] as u16,
                })
            }
            id::HOST_HEARTBEAT => Message::HostHeartbeat(HostHeartbeat {
                counter: r[0] as u32,
                consumed: r[1] as u32,
            }),
            id::DEVICE_HEARTBEAT => {
                if r[1] > 3 {
                    return Err(bad(1, "expected a device state 0..=3"));
                }
                Message::DeviceHeartbeat(DeviceHeartbeat {
                    counter: r[0] as u32,
                    state: r[1] as u8,
                    flags: r[2] as u8,
                    rx_errors: r[3] as u16,
                })
            }
            id::TIME_SYNC_REQUEST => Message::TimeSyncRequest(TimeSyncRequest {
                seq: r[0] as u32,
                host_time_us: r[1] as u64,
            }),
            id::TIME_SYNC_RESPONSE => Message::TimeSyncResponse(TimeSyncResponse {
                seq: r[0] as u32,
                host_time_us: r[1] as u64,
                device_time_us: r[2] as u64,
            }),
            id::DAQ_BLOCK_HEADER => {
                if r[3] == 0 {
                    return Err(bad(3, "expected at least one channel"));
                }
                if r[4] == 0 {
                    return Err(bad(4, "expected at least one sample per channel"));
                }
                if r[5] == 0 {
                    return Err(bad(5, "expected a sample rate > 0"));
                }
                Message::BlockHeader(BlockHeader {
                    seq: r[0] as u32,
                    first_sample: r[1] as u64,
                    timestamp_us: r[2] as u64,
                    channel_mask: r[3] as u16,
                    block_size: r[4] as u16,
                    sample_rate: r[5] as u32,
                    crc: r[6] as u32,
                })
            }
            id::DAQ_SAMPLES => {
                if r[2] == 0 || r[2] > SAMPLES_PER_FRAME as i128 {
                    return Err(bad(2, "expected 1..=20 samples"));
                }
                let count = r[2] as usize;
                let mut samples = [0i32; SAMPLES_PER_FRAME];
                for (i, s) in samples.iter_mut().enumerate() {
                    *s = r[3 + i] as i32;
                    if i >= count && *s != 0 {
                        return Err(bad(3 + i, "expected 0 beyond SampleCount"));
                    }
                }
                Message::Samples(SampleFrame {
                    block_seq: r[0] as u16,
                    index: r[1] as u8,
                    count: count as u8,
                    samples,
                })
            }
            _ => unreachable!("checked_def returns table entries"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn table_is_consistent() {
        for m in &MESSAGES {
            assert!(super::super::frame::valid_fd_len(m.len), "{}", m.name);
            let mut used = vec![false; m.len];
            for s in m.signals {
                for b in &mut used[s.byte..s.byte + s.bits as usize / 8] {
                    assert!(!*b, "{}.{} overlaps", m.name, s.name);
                    *b = true;
                }
            }
        }
    }

    #[test]
    fn messages_round_trip_and_bad_fields_name_byte_and_signal() {
        let mut samples = [0; 20];
        samples[0] = INT24_MIN;
        samples[1] = INT24_MAX;
        samples[2] = -1;
        let all = [
            Message::Fault(Fault {
                code: FaultCode::DriveSaturated,
                channel: 255,
                value: -1234,
                count: 2,
            }),
            Message::DriveSetpoint(DriveSetpoint {
                seq: 7,
                enable: true,
                frequency: 55_000_000_000,
                amplitude: 123_456,
                ramp: 500_000,
            }),
            Message::BlockHeader(BlockHeader {
                seq: 3,
                first_sample: 768,
                timestamp_us: u64::MAX - 5,
                channel_mask: 0x7FF,
                block_size: 256,
                sample_rate: 10_240_000,
                crc: 0xDEAD_BEEF,
            }),
            Message::Samples(SampleFrame {
                block_seq: 3,
                index: 140,
                count: 3,
                samples,
            }),
        ];
        for m in all {
            assert_eq!(Message::decode(&m.encode()).unwrap(), m);
        }
        let mut f = Message::StreamControl(StreamControl {
            command: StreamCommand::Start,
            session: 1,
        })
        .encode();
        let mut d = f.data().to_vec();
        d[0] = 9;
        f = CanFrame::fd(id::STREAM_CONTROL, &d).unwrap();
        let e = Message::decode(&f).unwrap_err().to_string();
        assert!(
            e.contains("0x020") && e.contains("byte 0") && e.contains("StreamCommand"),
            "{e}"
        );
        let short = CanFrame::fd(id::DAQ_SAMPLES, &[0; 48]).unwrap();
        let e = Message::decode(&short).unwrap_err().to_string();
        assert!(e.contains("48 data bytes, expected 64"), "{e}");
        let e = Message::decode(&CanFrame::fd(0x7FF, &[]).unwrap()).unwrap_err();
        assert!(matches!(e, DecodeError::UnknownId { id: 0x7FF }));
    }

    proptest! {
        #[test]
        fn decoding_arbitrary_frames_never_panics(
            id in prop::sample::select(vec![0x010u32, 0x020, 0x030, 0x031, 0x040, 0x041, 0x050, 0x051, 0x100, 0x101, 0x7FF, 0]),
            fd in any::<bool>(),
            len_i in 0usize..16,
            bytes in prop::collection::vec(any::<u8>(), 64),
        ) {
            let len = if fd { super::super::frame::FD_LENGTHS[len_i] } else { len_i.min(8) };
            let f = CanFrame::new(id, false, fd, false, false, &bytes[..len]).unwrap();
            if let Ok(m) = Message::decode(&f) {
                // What decodes re-encodes to the same bytes except reserved ones.
                let again = Message::decode(&m.encode()).unwrap();
                prop_assert_eq!(again, m);
                prop_assert!(signal_values(&f).is_ok());
            }
        }
    }
}
