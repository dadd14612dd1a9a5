//! DAQ blocks on the bus: the device side splits a block into DAQ_BLOCK_HEADER + DAQ_SAMPLES
//! frames ([`split_block`]); the host side puts them back together ([`Reassembler`]), detects
//! loss, reordering, duplicates and payload corruption, checks the header against the rig's
//! channel map and delivers complete blocks in sequence order.
//!
//! Delivery rule: block `s` is delivered once all its frames arrived and its CRC matches; it
//! is declared lost (a sequence gap) when its CRC fails, or when a header of block `s + 2` or
//! later arrives while `s` is incomplete (at most two blocks are assembled at a time).
//! Blocks after a lost one are still delivered, with their own sequence numbers, so the
//! session sees the gap.

use std::collections::{BTreeMap, BTreeSet};

use crate::rig::{DaqBlock, DaqLayout};

use super::messages::{
    BlockHeader, Message, SampleFrame, INT24_MAX, INT24_MIN, SAMPLES_PER_FRAME, SAMPLE_RATE_RES,
};
use crate::rig::hw::crc::Crc32;

/// What the rig's channel map says a block header must carry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockFormat {
    /// Channel mask (the layout's channels: bits 0..n).
    pub channel_mask: u16,
    /// Samples per channel.
    pub block_size: u16,
    /// Sample rate / SAMPLE_RATE_RES.
    pub sample_rate: u32,
}

/// A channel map that cannot travel on the bus.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BlockFormatError {
    /// No channel, or more than the 16 bits of ChannelMask.
    #[error("{channels} DAQ channels: the CAN block header's ChannelMask holds 1..=16")]
    Channels {
        /// Channels in the layout.
        channels: usize,
    },
    /// No sample, or more than BlockSize holds.
    #[error("block size {block_size}: the CAN block header's BlockSize holds 1..=65535")]
    BlockSize {
        /// Samples per channel per block.
        block_size: usize,
    },
    /// A sample rate the SampleRate field cannot carry.
    #[error("sample rate {sample_rate} Hz does not fit the header's SampleRate field")]
    SampleRate {
        /// The layout's sample rate, Hz.
        sample_rate: f64,
    },
}

/// A block that cannot be split into frames of its format.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SplitError {
    /// The block's shape is not the format's.
    #[error(
        "block {seq}: {counts} counts of {len} samples, the format wants {channels} channels x \
         {block_size}"
    )]
    Shape {
        /// Block.
        seq: u64,
        /// Counts in the block.
        counts: usize,
        /// Samples per channel in the block.
        len: usize,
        /// Channels of the format.
        channels: usize,
        /// Samples per channel of the format.
        block_size: usize,
    },
    /// A sequence number beyond the header's 32 bits.
    #[error("block {seq} beyond u32")]
    Seq {
        /// Block.
        seq: u64,
    },
    /// A count beyond the 24 bits of a sample.
    #[error("block {seq}, channel {channel}, sample {sample}: count {count} does not fit 24 bits")]
    Count {
        /// Block.
        seq: u64,
        /// Channel index.
        channel: usize,
        /// Sample index.
        sample: usize,
        /// The count.
        count: i32,
    },
    /// More sample frames than their 8-bit index holds.
    #[error("block {seq}: more than 256 sample frames")]
    Frames {
        /// Block.
        seq: u64,
    },
}

impl BlockFormat {
    /// The format of a layout; `Err` when it cannot travel on the bus (more than 16
    /// channels, blocks beyond 65535 samples, a sample rate beyond the field).
    pub fn of(layout: &DaqLayout) -> Result<BlockFormat, BlockFormatError> {
        let n = layout.channels.len();
        if n == 0 || n > 16 {
            return Err(BlockFormatError::Channels { channels: n });
        }
        if layout.block_size == 0 || layout.block_size > usize::from(u16::MAX) {
            return Err(BlockFormatError::BlockSize {
                block_size: layout.block_size,
            });
        }
        let rate = (layout.sample_rate / SAMPLE_RATE_RES).round();
        if !(rate >= 1.0 && rate <= f64::from(u32::MAX)) {
            return Err(BlockFormatError::SampleRate {
                sample_rate: layout.sample_rate,
            });
        }
        Ok(BlockFormat {
            channel_mask: ((1u32 << n) - 1) as u16,
            block_size: layout.block_size as u16,
            sample_rate: rate as u32,
        })
    }

    fn channels(&self) -> usize {
        self.channel_mask.count_ones() as usize
    }
}

/// The frames of one block: header, then the sample frames in order. `Err` when a count does
/// not fit 24 bits or the block does not match the format.
pub fn split_block(
    block: &DaqBlock,
    format: &BlockFormat,
    timestamp_us: u64,
) -> Result<Vec<Message>, SplitError> {
    let n_ch = format.channels();
    let len = usize::from(format.block_size);
    if block.len != len || block.counts.len() != n_ch * len {
        return Err(SplitError::Shape {
            seq: block.seq,
            counts: block.counts.len(),
            len: block.len,
            channels: n_ch,
            block_size: len,
        });
    }
    let seq = u32::try_from(block.seq).map_err(|_| SplitError::Seq { seq: block.seq })?;
    let total = n_ch * len;
    let mut stream = Vec::with_capacity(total);
    let mut crc = Crc32::new();
    for i in 0..len {
        for k in 0..n_ch {
            let c = block.counts[k * len + i];
            if !(INT24_MIN..=INT24_MAX).contains(&c) {
                return Err(SplitError::Count {
                    seq: block.seq,
                    channel: k,
                    sample: i,
                    count: c,
                });
            }
            crc.update(&c.to_le_bytes()[..3]);
            stream.push(c);
        }
    }
    let mut out = Vec::with_capacity(1 + total.div_ceil(SAMPLES_PER_FRAME));
    out.push(Message::BlockHeader(BlockHeader {
        seq,
        first_sample: block.first_sample,
        timestamp_us,
        channel_mask: format.channel_mask,
        block_size: format.block_size,
        sample_rate: format.sample_rate,
        crc: crc.finish(),
    }));
    for (f, chunk) in stream.chunks(SAMPLES_PER_FRAME).enumerate() {
        let mut samples = [0; SAMPLES_PER_FRAME];
        samples[..chunk.len()].copy_from_slice(chunk);
        out.push(Message::Samples(SampleFrame {
            block_seq: seq as u16,
            index: u8::try_from(f).map_err(|_| SplitError::Frames { seq: block.seq })?,
            count: chunk.len() as u8,
            samples,
        }));
    }
    Ok(out)
}

/// What the reassembler counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReassemblyCounters {
    /// Blocks lost.
    pub sequence_gaps: u64,
    /// Frames that came after a later one.
    pub reordered: u64,
    /// Frames received twice.
    pub duplicates: u64,
    /// Blocks with a payload CRC mismatch.
    pub crc_errors: u64,
    /// Sample frames that do not fit (no header, bad index or count).
    pub malformed: u64,
}

/// A header that does not match the rig's channel map: the session cannot go on.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "DAQ_BLOCK_HEADER (0x100) of block {seq}: {field} = {got}, the rig description's channel map \
     wants {expected}"
)]
pub struct FormatMismatch {
    /// Block.
    pub seq: u32,
    /// Signal.
    pub field: &'static str,
    /// Received.
    pub got: String,
    /// Expected.
    pub expected: String,
}

#[derive(Debug)]
struct Assembly {
    header: BlockHeader,
    stream: Vec<i32>,
    have: Vec<bool>,
    received: usize,
    highest: Option<u8>,
}

/// Puts blocks back together. See the module docs.
#[derive(Debug)]
pub struct Reassembler {
    format: BlockFormat,
    sample_rate_hz: f64,
    open: BTreeMap<u32, Assembly>,
    /// The next sequence number to deliver.
    next: u32,
    /// Highest header seen.
    newest: Option<u32>,
    ready: BTreeMap<u32, DaqBlock>,
    /// Blocks given up (CRC failure, incomplete when too old) not yet passed by `next`.
    dropped: BTreeSet<u32>,
    counters: ReassemblyCounters,
    /// Sample frames seen for blocks already delivered or dropped (recent block seqs, mod
    /// 65536), to tell late frames from orphans.
    done_recent: Vec<u16>,
}

impl Reassembler {
    /// A reassembler expecting `format` (sample rate `sample_rate_hz` for block times).
    pub fn new(format: BlockFormat, sample_rate_hz: f64) -> Reassembler {
        Reassembler {
            format,
            sample_rate_hz,
            open: BTreeMap::new(),
            next: 0,
            newest: None,
            ready: BTreeMap::new(),
            dropped: BTreeSet::new(),
            counters: ReassemblyCounters::default(),
            done_recent: Vec::new(),
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> ReassemblyCounters {
        self.counters
    }

    fn mark_done(&mut self, seq: u32) {
        self.done_recent.push(seq as u16);
        if self.done_recent.len() > 8 {
            self.done_recent.remove(0);
        }
    }

    /// A block header. `Err` when it does not match the channel map.
    pub fn header(&mut self, h: BlockHeader) -> Result<(), FormatMismatch> {
        let f = &self.format;
        let mismatch = |field, got: String, expected: String| FormatMismatch {
            seq: h.seq,
            field,
            got,
            expected,
        };
        if h.channel_mask != f.channel_mask {
            return Err(mismatch(
                "ChannelMask",
                format!(
                    "{:#06x} ({} channels)",
                    h.channel_mask,
                    h.channel_mask.count_ones()
                ),
                format!("{:#06x} ({} channels)", f.channel_mask, f.channels()),
            ));
        }
        if h.block_size != f.block_size {
            return Err(mismatch(
                "BlockSize",
                h.block_size.to_string(),
                f.block_size.to_string(),
            ));
        }
        if h.sample_rate != f.sample_rate {
            return Err(mismatch(
                "SampleRate",
                format!("{} Hz", f64::from(h.sample_rate) * SAMPLE_RATE_RES),
                format!("{} Hz", f64::from(f.sample_rate) * SAMPLE_RATE_RES),
            ));
        }
        if h.seq < self.next
            || self.open.contains_key(&h.seq)
            || self.ready.contains_key(&h.seq)
            || self.dropped.contains(&h.seq)
        {
            // Already delivered, declared lost or being assembled.
            self.counters.duplicates += 1;
            return Ok(());
        }
        if self.newest.is_some_and(|n| h.seq < n) {
            self.counters.reordered += 1;
        }
        self.newest = Some(self.newest.map_or(h.seq, |n| n.max(h.seq)));
        let total = f.channels() * usize::from(f.block_size);
        self.open.insert(
            h.seq,
            Assembly {
                header: h,
                stream: vec![0; total],
                have: vec![false; h.frame_count()],
                received: 0,
                highest: None,
            },
        );
        // Blocks two or more behind the newest header that are still incomplete are lost.
        let newest = self.newest.unwrap_or(0);
        let stale: Vec<u32> = self
            .open
            .keys()
            .copied()
            .filter(|&s| s.saturating_add(2) <= newest)
            .collect();
        for s in stale {
            self.open.remove(&s);
            self.mark_done(s);
            self.dropped.insert(s);
        }
        self.advance();
        Ok(())
    }

    /// A sample frame.
    pub fn samples(&mut self, f: SampleFrame) {
        let Some((&seq, _)) = self.open.iter().find(|(s, _)| **s as u16 == f.block_seq) else {
            if self.done_recent.contains(&f.block_seq) {
                self.counters.reordered += 1;
            } else {
                self.counters.malformed += 1;
            }
            return;
        };
        let total = self.format.channels() * usize::from(self.format.block_size);
        let newer_started = self.open.range(seq + 1..).any(|(_, a)| a.received > 0);
        let a = self.open.get_mut(&seq).expect("found above");
        let i = usize::from(f.index);
        let expected_count = total
            .saturating_sub(i * SAMPLES_PER_FRAME)
            .min(SAMPLES_PER_FRAME);
        if i >= a.have.len() || usize::from(f.count) != expected_count {
            self.counters.malformed += 1;
            return;
        }
        if a.have[i] {
            self.counters.duplicates += 1;
            return;
        }
        if a.highest.is_some_and(|h| f.index < h) || newer_started {
            self.counters.reordered += 1;
        }
        a.highest = Some(a.highest.map_or(f.index, |h| h.max(f.index)));
        a.have[i] = true;
        a.received += 1;
        let start = i * SAMPLES_PER_FRAME;
        a.stream[start..start + expected_count].copy_from_slice(&f.samples[..expected_count]);
        if a.received == a.have.len() {
            let a = self.open.remove(&seq).expect("present");
            self.finish(seq, a);
        }
    }

    fn finish(&mut self, seq: u32, a: Assembly) {
        self.mark_done(seq);
        let mut crc = Crc32::new();
        for c in &a.stream {
            crc.update(&c.to_le_bytes()[..3]);
        }
        if crc.finish() != a.header.crc {
            self.counters.crc_errors += 1;
            self.dropped.insert(seq);
            self.advance();
            return;
        }
        let n_ch = self.format.channels();
        let len = usize::from(self.format.block_size);
        let mut counts = vec![0; n_ch * len];
        for i in 0..len {
            for k in 0..n_ch {
                counts[k * len + i] = a.stream[i * n_ch + k];
            }
        }
        self.ready.insert(
            seq,
            DaqBlock {
                seq: u64::from(seq),
                first_sample: a.header.first_sample,
                time: a.header.first_sample as f64 / self.sample_rate_hz,
                len,
                counts,
            },
        );
        self.advance();
    }

    /// Moves `next` past blocks that can no longer arrive: dropped ones, and missing ones
    /// two or more behind the newest header.
    fn advance(&mut self) {
        loop {
            let next = self.next;
            if self.ready.contains_key(&next) || self.open.contains_key(&next) {
                return;
            }
            if self.dropped.remove(&next) {
                self.counters.sequence_gaps += 1;
                self.next += 1;
                continue;
            }
            let Some(newest) = self.newest else { return };
            if newest < next.saturating_add(2) {
                return;
            }
            let first_known = [
                self.ready.keys().next(),
                self.open.keys().next(),
                self.dropped.iter().next(),
            ]
            .into_iter()
            .flatten()
            .copied()
            .filter(|&k| k > next)
            .min();
            let resume = first_known.map_or(newest - 1, |k| k.min(newest - 1));
            self.counters.sequence_gaps += u64::from(resume - next);
            self.next = resume;
        }
    }

    /// The next block in sequence order, if complete.
    pub fn pop(&mut self) -> Option<DaqBlock> {
        let b = self.ready.remove(&self.next)?;
        self.next += 1;
        self.advance();
        Some(b)
    }
}

/// Decodes a frame into the reassembler when it is a DAQ frame; returns whether it was one.
pub fn feed(r: &mut Reassembler, m: &Message) -> Result<bool, FormatMismatch> {
    match *m {
        Message::BlockHeader(h) => r.header(h).map(|_| true),
        Message::Samples(s) => {
            r.samples(s);
            Ok(true)
        }
        _ => Ok(false),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::{ChannelKind, ChannelSpec};
    use proptest::prelude::*;

    fn layout(n_ch: usize, len: usize) -> DaqLayout {
        DaqLayout {
            sample_rate: 10240.0,
            block_size: len,
            channels: (0..n_ch)
                .map(|k| ChannelSpec {
                    name: format!("c{k}"),
                    kind: ChannelKind::BeamAcceleration,
                    scale: 1.0,
                    full_scale_counts: INT24_MAX,
                })
                .collect(),
        }
    }

    fn block(seq: u64, n_ch: usize, len: usize) -> DaqBlock {
        DaqBlock {
            seq,
            first_sample: seq * len as u64,
            time: (seq * len as u64) as f64 / 10240.0,
            len,
            counts: (0..n_ch * len)
                .map(|j| ((j as i64 * 7919 + seq as i64 * 104729) % (1 << 23)) as i32 - (1 << 22))
                .collect(),
        }
    }

    fn frames(seq: u64, n_ch: usize, len: usize) -> Vec<Message> {
        let f = BlockFormat::of(&layout(n_ch, len)).unwrap();
        split_block(&block(seq, n_ch, len), &f, seq * 1000).unwrap()
    }

    fn feed_all(r: &mut Reassembler, ms: &[Message]) -> Vec<DaqBlock> {
        let mut out = Vec::new();
        for m in ms {
            feed(r, m).unwrap();
            while let Some(b) = r.pop() {
                out.push(b);
            }
        }
        out
    }

    fn reassembler(n_ch: usize, len: usize) -> Reassembler {
        Reassembler::new(BlockFormat::of(&layout(n_ch, len)).unwrap(), 10240.0)
    }

    #[test]
    fn blocks_survive_the_round_trip() {
        let (n_ch, len) = (11, 256);
        let ms: Vec<Message> = (0..3).flat_map(|s| frames(s, n_ch, len)).collect();
        // 11 x 256 = 2816 samples: 141 frames per block, the last with 16.
        assert_eq!(ms.len(), 3 * 142);
        let mut r = reassembler(n_ch, len);
        let got = feed_all(&mut r, &ms);
        assert_eq!(got, (0..3).map(|s| block(s, n_ch, len)).collect::<Vec<_>>());
        assert_eq!(r.counters(), ReassemblyCounters::default());
    }

    #[test]
    fn a_lost_frame_is_a_gap_and_later_blocks_still_arrive() {
        let mut ms: Vec<Message> = (0..4).flat_map(|s| frames(s, 3, 40)).collect();
        ms.remove(8); // a sample frame of block 1 (7 frames per block)
        let mut r = reassembler(3, 40);
        let got: Vec<u64> = feed_all(&mut r, &ms).iter().map(|b| b.seq).collect();
        // Block 1 is declared lost when block 3's header arrives.
        assert_eq!(got, vec![0, 2, 3]);
        assert_eq!(r.counters().sequence_gaps, 1);
    }

    #[test]
    fn reordered_frames_within_two_blocks_are_put_back_and_counted() {
        let mut ms: Vec<Message> = (0..3).flat_map(|s| frames(s, 3, 40)).collect();
        ms.swap(3, 5); // within block 0
        let last0 = ms.remove(6); // block 0's last frame after block 1's first sample frame
        ms.insert(8, last0);
        let mut r = reassembler(3, 40);
        let got = feed_all(&mut r, &ms);
        assert_eq!(got, (0..3).map(|s| block(s, 3, 40)).collect::<Vec<_>>());
        assert!(r.counters().reordered >= 2, "{:?}", r.counters());
        assert_eq!(r.counters().sequence_gaps, 0);
    }

    #[test]
    fn corrupt_payload_duplicates_and_orphans_are_counted() {
        let mut ms = frames(0, 3, 40);
        if let Message::Samples(s) = &mut ms[2] {
            s.samples[0] ^= 1;
        }
        let dup = ms[3];
        ms.insert(4, dup);
        ms.extend(frames(1, 3, 40));
        let mut orphan = frames(9, 3, 40)[1];
        if let Message::Samples(s) = &mut orphan {
            s.block_seq = 77;
        }
        ms.push(orphan);
        let mut r = reassembler(3, 40);
        let got: Vec<u64> = feed_all(&mut r, &ms).iter().map(|b| b.seq).collect();
        assert_eq!(got, vec![1]);
        let c = r.counters();
        assert_eq!(
            (c.crc_errors, c.duplicates, c.malformed, c.sequence_gaps),
            (1, 1, 1, 1)
        );
    }

    #[test]
    fn a_header_off_the_channel_map_is_an_error_naming_the_field() {
        let mut r = reassembler(11, 256);
        let Message::BlockHeader(mut h) = frames(0, 11, 256)[0] else {
            panic!()
        };
        h.channel_mask = 0x3FF;
        let e = r.header(h).unwrap_err().to_string();
        assert!(
            e.contains("ChannelMask") && e.contains("0x03ff") && e.contains("0x07ff"),
            "{e}"
        );
        h.channel_mask = 0x7FF;
        h.sample_rate = 10_000_000;
        let e = r.header(h).unwrap_err().to_string();
        assert!(
            e.contains("SampleRate = 10000 Hz") && e.contains("10240 Hz"),
            "{e}"
        );
    }

    proptest! {
        /// Any loss, duplication and reordering of the frames of a few blocks: no panic,
        /// delivered blocks are exact copies and in increasing order.
        #[test]
        fn arbitrary_frame_streams_never_corrupt_or_panic(
            ops in prop::collection::vec((0usize..40, 0u8..4), 0..60),
        ) {
            let mut ms: Vec<Message> = (0..5).flat_map(|s| frames(s, 3, 40)).collect();
            for (i, op) in ops {
                let i = i % ms.len().max(1);
                if ms.is_empty() { break; }
                match op {
                    0 => { ms.remove(i); }
                    1 => { let m = ms[i]; ms.insert(i, m); }
                    2 => { let j = (i + 3) % ms.len(); ms.swap(i, j); }
                    _ => if let Message::Samples(s) = &mut ms[i] { s.samples[0] = s.samples[0].wrapping_add(1) % (1 << 23); },
                }
            }
            let mut r = reassembler(3, 40);
            let got = feed_all(&mut r, &ms);
            let mut last = None;
            for b in got {
                prop_assert_eq!(&b, &block(b.seq, 3, 40));
                prop_assert!(last.is_none_or(|l| b.seq > l));
                last = Some(b.seq);
            }
        }
    }
}
