//! The two serial protocols on top of [`super::line`]: the laser vibrometer controller and the
//! power amplifier. Request bodies are `TAG VERB [ARG]`, answers `TAG OK VERB [VALUES]` or
//! `TAG ERR CODE TEXT`; TAG is a decimal 0..=999 the host chooses per request so that a late
//! answer is never taken for the current one. Both sides parse and format here.
//!
//! Vibrometer (115200 Bd 8N1): `IDN`, `RANGE MM_S` (full-scale velocity of the analog
//! output, mm/s), `FILTER HZ` (output low-pass), `STATUS` -> `OK STATUS RANGE=.. FILTER=..
//! LEVEL=0..100 OVR=0|1` (OVR: over-range latched since the last `CLEAR`), `CLEAR`.
//! Amplifier (9600 Bd 8N1): `IDN`, `GAIN` -> `OK GAIN V_PER_V`, `ENABLE 0|1`, `STATUS` ->
//! `OK STATUS EN=0|1 OVL=0|1 ILK=0|1 GAIN=.. LIM=..` (OVL: overload latched since `CLEAR`;
//! ILK=1: interlock open, output off; LIM: output limit, V), `CLEAR`.
//! Error codes: 1 unknown command, 2 bad argument, 3 refused (interlock open, overload latched).

/// A request, an answer or a STATUS answer's values that do not follow the protocol. The
/// messages quote what arrived.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    /// The body does not start with a tag 0..=999.
    #[error("{what} {body:?}: expected a tag 0..=999 first")]
    Tag {
        /// "request" or "answer".
        what: &'static str,
        /// The body.
        body: String,
    },
    /// A request without a verb.
    #[error("request {body:?}: no command")]
    NoCommand {
        /// The body.
        body: String,
    },
    /// A request with more than one argument.
    #[error("request {body:?}: more than one argument")]
    ExtraArgument {
        /// The body.
        body: String,
    },
    /// `OK` without the verb answered.
    #[error("answer {body:?}: OK without a command")]
    OkWithoutCommand {
        /// The body.
        body: String,
    },
    /// `ERR` without a numeric code.
    #[error("answer {body:?}: ERR without a numeric code")]
    ErrWithoutCode {
        /// The body.
        body: String,
    },
    /// Neither `OK` nor `ERR` after the tag.
    #[error("answer {body:?}: expected OK or ERR after the tag")]
    NoOutcome {
        /// The body.
        body: String,
    },
    /// A STATUS answer without one of its keys.
    #[error("{device} STATUS {values:?}: no {key}=")]
    MissingKey {
        /// "vibrometer" or "amplifier".
        device: &'static str,
        /// The answer's values.
        values: Vec<String>,
        /// The key missing.
        key: &'static str,
    },
    /// A STATUS flag that is not 0 or 1.
    #[error("{device} STATUS {key}={value}: expected 0 or 1")]
    NotAFlag {
        /// "vibrometer" or "amplifier".
        device: &'static str,
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
    },
    /// A STATUS value that is not a number.
    #[error("{device} STATUS {key}={value}: not a number")]
    NotANumber {
        /// "vibrometer" or "amplifier".
        device: &'static str,
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
    },
    /// The vibrometer's signal level beyond 100 %.
    #[error("{device} STATUS LEVEL={level}: expected 0..=100")]
    Level {
        /// "vibrometer".
        device: &'static str,
        /// The level, %.
        level: u8,
    },
    /// The amplifier's gain or limit is not finite.
    #[error("{device} STATUS GAIN={gain} LIM={limit_v}: not finite")]
    NotFinite {
        /// "amplifier".
        device: &'static str,
        /// Gain, V/V.
        gain: f64,
        /// Output limit, V.
        limit_v: f64,
    },
}

/// A parsed request: tag, verb, optional argument.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// Tag.
    pub tag: u16,
    /// Verb (upper case).
    pub verb: String,
    /// Argument.
    pub arg: Option<String>,
}

/// Parses a request body.
pub fn parse_request(body: &str) -> Result<Request, ProtocolError> {
    let body_ = || body.to_string();
    let mut it = body.split(' ');
    let tag = it
        .next()
        .and_then(|t| t.parse::<u16>().ok())
        .filter(|t| *t <= 999)
        .ok_or_else(|| ProtocolError::Tag {
            what: "request",
            body: body_(),
        })?;
    let verb = it
        .next()
        .filter(|v| !v.is_empty())
        .ok_or_else(|| ProtocolError::NoCommand { body: body_() })?
        .to_string();
    let arg = it.next().map(str::to_string);
    if it.next().is_some() {
        return Err(ProtocolError::ExtraArgument { body: body_() });
    }
    Ok(Request { tag, verb, arg })
}

/// An answer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Reply {
    /// `OK VERB VALUES...`
    Ok {
        /// Verb answered.
        verb: String,
        /// Values (words).
        values: Vec<String>,
    },
    /// `ERR CODE TEXT`
    Err {
        /// Error code.
        code: u8,
        /// Text.
        text: String,
    },
}

/// Parses an answer body into (tag, reply).
pub fn parse_reply(body: &str) -> Result<(u16, Reply), ProtocolError> {
    let body_ = || body.to_string();
    let mut it = body.split(' ');
    let tag = it
        .next()
        .and_then(|t| t.parse::<u16>().ok())
        .filter(|t| *t <= 999)
        .ok_or_else(|| ProtocolError::Tag {
            what: "answer",
            body: body_(),
        })?;
    match it.next() {
        Some("OK") => {
            let verb = it
                .next()
                .ok_or_else(|| ProtocolError::OkWithoutCommand { body: body_() })?
                .to_string();
            Ok((
                tag,
                Reply::Ok {
                    verb,
                    values: it.map(str::to_string).collect(),
                },
            ))
        }
        Some("ERR") => {
            let code = it
                .next()
                .and_then(|c| c.parse().ok())
                .ok_or_else(|| ProtocolError::ErrWithoutCode { body: body_() })?;
            Ok((
                tag,
                Reply::Err {
                    code,
                    text: it.collect::<Vec<_>>().join(" "),
                },
            ))
        }
        _ => Err(ProtocolError::NoOutcome { body: body_() }),
    }
}

/// Formats an answer body.
pub fn format_reply(tag: u16, reply: &Reply) -> String {
    match reply {
        Reply::Ok { verb, values } if values.is_empty() => format!("{tag} OK {verb}"),
        Reply::Ok { verb, values } => format!("{tag} OK {verb} {}", values.join(" ")),
        Reply::Err { code, text } => format!("{tag} ERR {code} {text}"),
    }
}

fn fields(
    values: &[String],
    keys: &[&'static str],
    device: &'static str,
) -> Result<Vec<String>, ProtocolError> {
    keys.iter()
        .map(|&key| {
            values
                .iter()
                .find_map(|v| v.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
                .map(str::to_string)
                .ok_or_else(|| ProtocolError::MissingKey {
                    device,
                    values: values.to_vec(),
                    key,
                })
        })
        .collect()
}

fn flag(v: &str, key: &'static str, device: &'static str) -> Result<bool, ProtocolError> {
    match v {
        "0" => Ok(false),
        "1" => Ok(true),
        _ => Err(ProtocolError::NotAFlag {
            device,
            key,
            value: v.to_string(),
        }),
    }
}

fn number<T: std::str::FromStr>(
    v: &str,
    key: &'static str,
    device: &'static str,
) -> Result<T, ProtocolError> {
    v.parse().map_err(|_| ProtocolError::NotANumber {
        device,
        key,
        value: v.to_string(),
    })
}

/// The vibrometer controller's status.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VibrometerStatus {
    /// Full-scale velocity, mm/s.
    pub range_mm_s: u32,
    /// Output low-pass, Hz.
    pub filter_hz: u32,
    /// Signal level, 0..=100 %.
    pub level: u8,
    /// Over-range latched.
    pub over_range: bool,
}

impl VibrometerStatus {
    /// The STATUS answer's values.
    pub fn values(&self) -> Vec<String> {
        vec![
            format!("RANGE={}", self.range_mm_s),
            format!("FILTER={}", self.filter_hz),
            format!("LEVEL={}", self.level),
            format!("OVR={}", u8::from(self.over_range)),
        ]
    }

    /// Parses the STATUS answer's values.
    pub fn parse(values: &[String]) -> Result<VibrometerStatus, ProtocolError> {
        const W: &str = "vibrometer";
        let f = fields(values, &["RANGE", "FILTER", "LEVEL", "OVR"], W)?;
        let level: u8 = number(&f[2], "LEVEL", W)?;
        if level > 100 {
            return Err(ProtocolError::Level { device: W, level });
        }
        Ok(VibrometerStatus {
            range_mm_s: number(&f[0], "RANGE", W)?,
            filter_hz: number(&f[1], "FILTER", W)?,
            level,
            over_range: flag(&f[3], "OVR", W)?,
        })
    }
}

/// The power amplifier's status.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmplifierStatus {
    /// Output enabled.
    pub enabled: bool,
    /// Overload latched.
    pub overload: bool,
    /// Interlock open (output off).
    pub interlock_open: bool,
    /// Voltage gain, V/V.
    pub gain: f64,
    /// Output limit, V.
    pub limit_v: f64,
}

impl AmplifierStatus {
    /// The STATUS answer's values.
    pub fn values(&self) -> Vec<String> {
        vec![
            format!("EN={}", u8::from(self.enabled)),
            format!("OVL={}", u8::from(self.overload)),
            format!("ILK={}", u8::from(self.interlock_open)),
            format!("GAIN={}", self.gain),
            format!("LIM={}", self.limit_v),
        ]
    }

    /// Parses the STATUS answer's values.
    pub fn parse(values: &[String]) -> Result<AmplifierStatus, ProtocolError> {
        const W: &str = "amplifier";
        let f = fields(values, &["EN", "OVL", "ILK", "GAIN", "LIM"], W)?;
        let gain: f64 = number(&f[3], "GAIN", W)?;
        let limit_v: f64 = number(&f[4], "LIM", W)?;
        if !(gain.is_finite() && limit_v.is_finite()) {
            return Err(ProtocolError::NotFinite {
                device: W,
                gain,
                limit_v,
            });
        }
        Ok(AmplifierStatus {
            enabled: flag(&f[0], "EN", W)?,
            overload: flag(&f[1], "OVL", W)?,
            interlock_open: flag(&f[2], "ILK", W)?,
            gain,
            limit_v,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn statuses_round_trip() {
        let v = VibrometerStatus {
            range_mm_s: 500,
            filter_hz: 5000,
            level: 87,
            over_range: true,
        };
        let body = format_reply(
            12,
            &Reply::Ok {
                verb: "STATUS".into(),
                values: v.values(),
            },
        );
        let (tag, r) = parse_reply(&body).unwrap();
        assert_eq!(tag, 12);
        let Reply::Ok { values, .. } = r else {
            panic!()
        };
        assert_eq!(VibrometerStatus::parse(&values).unwrap(), v);
        let a = AmplifierStatus {
            enabled: true,
            overload: false,
            interlock_open: true,
            gain: 4.5,
            limit_v: 20.0,
        };
        assert_eq!(AmplifierStatus::parse(&a.values()).unwrap(), a);
        assert!(AmplifierStatus::parse(&["EN=2".into()]).is_err());
        assert_eq!(
            parse_request("7 RANGE 500").unwrap(),
            Request {
                tag: 7,
                verb: "RANGE".into(),
                arg: Some("500".into())
            }
        );
        assert!(parse_request("1000 STATUS").is_err());
        assert_eq!(
            parse_reply("3 ERR 3 interlock open").unwrap(),
            (
                3,
                Reply::Err {
                    code: 3,
                    text: "interlock open".into()
                }
            )
        );
    }

    proptest! {
        #[test]
        fn parsers_never_panic(body in "[ -~]{0,120}") {
            let _ = parse_request(&body);
            if let Ok((_, Reply::Ok { values, .. })) = parse_reply(&body) {
                let _ = VibrometerStatus::parse(&values);
                let _ = AmplifierStatus::parse(&values);
            }
        }
    }
}
