//! Lossless compact storage of DAQ counts for a recording held in memory
//! (`replay::Recording`): a channel's samples in frames of [`FRAME`] samples, each
//! frame its first value and the differences between neighbouring samples, zigzag-coded and
//! bit-packed at the frame's widest difference. A 24-bit channel whose noise spans a few hundred
//! counts takes 11-13 bits a sample instead of 32. Only data this module packed are unpacked.

/// Samples per frame (one bit width each).
pub(crate) const FRAME: usize = 256;

fn zigzag(d: i64) -> u64 {
    ((d << 1) ^ (d >> 63)) as u64
}

fn unzigzag(z: u64) -> i64 {
    ((z >> 1) as i64) ^ -((z & 1) as i64)
}

/// Appends the samples `x` to `out`, packed.
pub(crate) fn pack(x: &[i32], out: &mut Vec<u8>) {
    for frame in x.chunks(FRAME) {
        let first = frame[0];
        out.extend_from_slice(&first.to_le_bytes());
        let deltas: Vec<u64> = frame
            .windows(2)
            .map(|w| zigzag(i64::from(w[1]) - i64::from(w[0])))
            .collect();
        let width = deltas
            .iter()
            .map(|&z| 64 - z.leading_zeros())
            .max()
            .unwrap_or(0);
        out.push(width as u8);
        if width == 0 {
            continue;
        }
        let mut acc: u128 = 0;
        let mut bits = 0u32;
        for &z in &deltas {
            acc |= u128::from(z) << bits;
            bits += width;
            while bits >= 8 {
                out.push(acc as u8);
                acc >>= 8;
                bits -= 8;
            }
        }
        if bits > 0 {
            out.push(acc as u8);
        }
    }
}

/// Unpacks `n` samples packed by [`pack`] from `bytes` at `*pos` onto `out`; `*pos` moves past
/// them.
pub(crate) fn unpack(bytes: &[u8], pos: &mut usize, n: usize, out: &mut Vec<i32>) {
    let mut left = n;
    while left > 0 {
        let len = left.min(FRAME);
        let first = i32::from_le_bytes(bytes[*pos..*pos + 4].try_into().expect("4 bytes"));
        let width = u32::from(bytes[*pos + 4]);
        *pos += 5;
        out.push(first);
        let mut value = i64::from(first);
        if width == 0 {
            out.extend(std::iter::repeat_n(first, len - 1));
        } else {
            let mask: u128 = (1u128 << width) - 1;
            let mut acc: u128 = 0;
            let mut bits = 0u32;
            for _ in 1..len {
                while bits < width {
                    acc |= u128::from(bytes[*pos]) << bits;
                    *pos += 1;
                    bits += 8;
                }
                let z = (acc & mask) as u64;
                acc >>= width;
                bits -= width;
                value += unzigzag(z);
                // NOTE: the differences of i32 samples sum back to i32 samples.
                out.push(value as i32);
            }
        }
        left -= len;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(x: &[i32]) -> usize {
        let mut bytes = Vec::new();
        pack(x, &mut bytes);
        let mut pos = 0;
        let mut out = Vec::new();
        unpack(&bytes, &mut pos, x.len(), &mut out);
        assert_eq!(out, x);
        assert_eq!(pos, bytes.len());
        bytes.len()
    }

    #[test]
    fn packs_losslessly_at_any_length_and_range() {
        assert_eq!(roundtrip(&[]), 0);
        roundtrip(&[7]);
        roundtrip(&[i32::MIN, i32::MAX, i32::MIN, 0, -1, 1]);
        let constant = vec![-42; 1000];
        // A constant frame is its first value and a zero width.
        assert_eq!(roundtrip(&constant), 4 * 5);
        let mut state = 1u64;
        let noisy: Vec<i32> = (0..5000)
            .map(|i| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let noise = ((state >> 33) % 1001) as i32 - 500;
                (3.0e5 * (i as f64 * 0.03).sin()) as i32 + noise
            })
            .collect();
        let bytes = roundtrip(&noisy);
        // About 12 bits a sample (differences within +-2^11), not 32.
        assert!(bytes < noisy.len() * 2, "{bytes} bytes");
    }

    #[test]
    fn frames_follow_each_other() {
        let a: Vec<i32> = (0..300).map(|i| i * 3).collect();
        let b: Vec<i32> = (0..10).map(|i| -i).collect();
        let mut bytes = Vec::new();
        pack(&a, &mut bytes);
        pack(&b, &mut bytes);
        let (mut pos, mut out) = (0, Vec::new());
        unpack(&bytes, &mut pos, a.len(), &mut out);
        unpack(&bytes, &mut pos, b.len(), &mut out);
        assert_eq!(out, [a, b].concat());
    }
}
