//! A CAN (FD) frame as it travels on any transport: identifier, FD/BRS/ESI flags and up to 64
//! data bytes, without allocation.

use std::fmt;

/// Data lengths a CAN FD frame can have (DLC 0..15).
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// Whether `len` is a valid CAN FD data length.
pub fn valid_fd_len(len: usize) -> bool {
    FD_LENGTHS.contains(&len)
}

/// One CAN or CAN FD data frame.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct CanFrame {
    /// Identifier: 11 bits (standard) or 29 bits (`extended`).
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// CAN FD frame (FDF); classic CAN otherwise (at most 8 bytes).
    pub fd: bool,
    /// Bit-rate switch in the data phase (FD only).
    pub brs: bool,
    /// Error state indicator (FD only).
    pub esi: bool,
    len: u8,
    data: [u8; 64],
}

impl CanFrame {
    /// A CAN FD frame with bit-rate switch and a standard identifier, as every rig message is.
    /// `None` when the length is not a CAN FD length or the id exceeds 11 bits.
    pub fn fd(id: u32, data: &[u8]) -> Option<CanFrame> {
        CanFrame::new(id, false, true, true, false, data)
    }

    /// Any frame; `None` when id or length do not fit the flags.
    pub fn new(
        id: u32,
        extended: bool,
        fd: bool,
        brs: bool,
        esi: bool,
        data: &[u8],
    ) -> Option<CanFrame> {
        let id_ok = if extended {
            id < (1 << 29)
        } else {
            id < (1 << 11)
        };
        let len_ok = if fd {
            valid_fd_len(data.len())
        } else {
            data.len() <= 8
        };
        if !id_ok || !len_ok || (!fd && (brs || esi)) {
            return None;
        }
        let mut d = [0u8; 64];
        d[..data.len()].copy_from_slice(data);
        Some(CanFrame {
            id,
            extended,
            fd,
            brs,
            esi,
            len: data.len() as u8,
            data: d,
        })
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    /// Data length, bytes.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the frame carries no data.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "CanFrame({:#05x}{}{} [{}] ",
            self.id,
            if self.extended { " ext" } else { "" },
            if self.fd { " fd" } else { "" },
            self.len
        )?;
        for b in self.data() {
            write!(f, "{b:02x}")?;
        }
        write!(f, ")")
    }
}
