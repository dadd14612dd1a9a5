//! The checksums of the rig links: CRC-32 (IEEE 802.3, reflected, as zlib; the catalogue's
//! CRC-32/ISO-HDLC) over a DAQ block's sample payload on CAN, CRC-16/CCITT-FALSE (the
//! catalogue's CRC-16/IBM-3740) over a serial line's body. Both are documented in
//! `firmware-interfaces/README.md`; computed by the `crc` crate from its catalogue, check
//! values below.

use crc::{Crc, Digest, CRC_16_IBM_3740, CRC_32_ISO_HDLC};

/// CRC-32/ISO-HDLC (poly 0x04C11DB7 reflected, init and final xor 0xFFFFFFFF).
static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
/// CRC-16/IBM-3740, a.k.a. CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor).
static CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// A running CRC-32 (IEEE): `Crc32::new()`, `update` any number of times, `finish`.
#[derive(Clone)]
pub struct Crc32(Digest<'static, u32>);

impl std::fmt::Debug for Crc32 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("Crc32").finish_non_exhaustive()
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Crc32::new()
    }
}

impl Crc32 {
    /// A fresh CRC.
    pub fn new() -> Crc32 {
        Crc32(CRC32.digest())
    }

    /// Adds bytes.
    pub fn update(&mut self, bytes: &[u8]) {
        self.0.update(bytes);
    }

    /// The checksum of everything added.
    pub fn finish(self) -> u32 {
        self.0.finalize()
    }
}

/// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).
pub fn crc16_ccitt(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_values() {
        // The catalogue's check values for "123456789".
        let mut c = Crc32::new();
        c.update(b"1234");
        c.update(b"56789");
        assert_eq!(c.finish(), 0xCBF4_3926);
        assert_eq!(crc16_ccitt(b"123456789"), 0x29B1);
    }

    /// The values the hand-written tables gave before the `crc` crate computed them (issue
    /// 18, item 8): empty input, one byte, and a DAQ-like payload of 24-bit samples.
    #[test]
    fn values_of_the_former_tables() {
        let crc32 = |b: &[u8]| {
            let mut c = Crc32::new();
            c.update(b);
            c.finish()
        };
        assert_eq!(crc32(b""), 0);
        assert_eq!(crc32(b"a"), 0xE8B7_BE43);
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
        assert_eq!(crc16_ccitt(b""), 0xFFFF);
        assert_eq!(crc16_ccitt(b"A"), 0xB915);
        assert_eq!(crc16_ccitt(b"AMP ENABLE 1"), legacy_crc16(b"AMP ENABLE 1"));
        let payload: Vec<u8> = (0..300i32)
            .flat_map(|k| ((k * 7919 - 40_000) & 0xFF_FFFF).to_le_bytes()[..3].to_vec())
            .collect();
        assert_eq!(crc32(&payload), legacy_crc32(&payload));
    }

    /// The former bitwise definitions, kept as the reference of the test above.
    fn legacy_crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    fn legacy_crc16(bytes: &[u8]) -> u16 {
        let mut c: u16 = 0xFFFF;
        for &b in bytes {
            c ^= u16::from(b) << 8;
            for _ in 0..8 {
                c = if c & 0x8000 != 0 {
                    (c << 1) ^ 0x1021
                } else {
                    c << 1
                };
            }
        }
        c
    }
}
