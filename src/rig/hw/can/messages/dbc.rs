//! The DBC text of the message table: `firmware-interfaces/rig.dbc` is exactly this (CAN FD
//! frame format via the `VFrameFormat` attribute, value tables for the enumerated signals).

use super::table::{id, Node, MESSAGES};

/// The DBC text of [`MESSAGES`]: `firmware-interfaces/rig.dbc` is exactly this.
pub fn dbc() -> String {
    use std::fmt::Write;
    let mut s = String::new();
    s.push_str("VERSION \"rigtwin rig bus 1\"\n\n\nNS_ :\n\tCM_\n\tBA_DEF_\n\tBA_\n\tVAL_\n\tBA_DEF_DEF_\n\nBS_:\n\n");
    s.push_str("BU_: HOST RIG_DAQ\n\n");
    for m in &MESSAGES {
        let _ = writeln!(
            s,
            "BO_ {} {}: {} {}",
            m.id,
            m.name,
            m.len,
            m.sender.dbc_name()
        );
        let receiver = match m.sender {
            Node::Host => Node::Daq,
            Node::Daq => Node::Host,
        }
        .dbc_name();
        for g in m.signals {
            let (min, max) = if g.signed {
                (-(1i128 << (g.bits - 1)), (1i128 << (g.bits - 1)) - 1)
            } else {
                (0, (1i128 << g.bits) - 1)
            };
            let (min, max) = if g.factor == 1.0 {
                (min.to_string(), max.to_string())
            } else {
                (
                    format!("{}", min as f64 * g.factor),
                    format!("{}", max as f64 * g.factor),
                )
            };
            let _ = writeln!(
                s,
                " SG_ {} : {}|{}@1{} ({},0) [{}|{}] \"{}\" {}",
                g.name,
                g.byte * 8,
                g.bits,
                if g.signed { '-' } else { '+' },
                g.factor,
                min,
                max,
                g.unit,
                receiver
            );
        }
        s.push('\n');
    }
    s.push('\n');
    s.push_str("CM_ \"rigtwin rig bus: CAN FD, 1 Mbit/s arbitration, 8 Mbit/s data phase, 11-bit identifiers. See README.md.\";\n");
    s.push_str("CM_ BU_ HOST \"rigtwin (rigtwin run --backend hw)\";\n");
    s.push_str("CM_ BU_ RIG_DAQ \"DAQ front-end and signal generator (rigtwin firmware-sim stands in)\";\n");
    for m in &MESSAGES {
        let _ = writeln!(s, "CM_ BO_ {} \"{}\";", m.id, m.comment);
        for g in m.signals {
            let _ = writeln!(s, "CM_ SG_ {} {} \"{}\";", m.id, g.name, g.comment);
        }
    }
    s.push_str("BA_DEF_  \"BusType\" STRING ;\n");
    s.push_str("BA_DEF_ BO_  \"VFrameFormat\" ENUM  \"StandardCAN\",\"ExtendedCAN\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\",\"ExtendedCAN_FD\";\n");
    s.push_str("BA_DEF_ BO_  \"CANFD_BRS\" ENUM  \"0\",\"1\";\n");
    s.push_str("BA_DEF_DEF_  \"BusType\" \"CAN FD\";\n");
    s.push_str("BA_DEF_DEF_  \"VFrameFormat\" \"StandardCAN_FD\";\n");
    s.push_str("BA_DEF_DEF_  \"CANFD_BRS\" \"1\";\n");
    s.push_str("BA_ \"BusType\" \"CAN FD\";\n");
    for m in &MESSAGES {
        let _ = writeln!(s, "BA_ \"VFrameFormat\" BO_ {} 14;", m.id);
        let _ = writeln!(s, "BA_ \"CANFD_BRS\" BO_ {} 1;", m.id);
    }
    let _ = writeln!(s, "VAL_ {} FaultCode 1 \"HEARTBEAT_LOST\" 2 \"INTERLOCK\" 3 \"AMPLIFIER_OVERLOAD\" 4 \"OVER_RANGE\" 5 \"DRIVE_SATURATED\" 6 \"DEVICE_ERROR\" ;", id::FAULT);
    let _ = writeln!(
        s,
        "VAL_ {} StreamCommand 1 \"START\" 2 \"STOP\" ;",
        id::STREAM_CONTROL
    );
    let _ = writeln!(s, "VAL_ {} DriveState 0 \"IDLE\" 1 \"RUNNING\" 2 \"SAFETY_RAMP_DOWN\" 3 \"OFF_AFTER_FAULT\" ;", id::DRIVE_STATUS);
    let _ = writeln!(
        s,
        "VAL_ {} DeviceState 0 \"IDLE\" 1 \"STREAMING\" 2 \"SAFETY_RAMP_DOWN\" 3 \"FAULTED\" ;",
        id::DEVICE_HEARTBEAT
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dbc_file_is_the_table() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware-interfaces/rig.dbc");
        let file = std::fs::read_to_string(path).unwrap();
        assert!(
            file == dbc(),
            "{path} differs from messages::dbc(): regenerate it with \
             `cargo test --lib rig::hw::can::messages -- --ignored write_dbc`"
        );
    }

    #[test]
    #[ignore]
    fn write_dbc() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware-interfaces/rig.dbc");
        std::fs::write(path, dbc()).unwrap();
    }
}
