//! The ROM file: versioned and self-describing.
//!
//! Layout (all integers little-endian):
//! ```text
//! magic     12 bytes  "RIGTWIN-ROM\n"
//! version   u32       FORMAT_VERSION
//! hlen      u64       length of the JSON header in bytes
//! header    hlen      UTF-8 JSON: format_version, meta (RomMeta), labels, clearance, friction,
//!                     the output names, the payload's SHA-256, and one entry per array:
//!                     {name, rows, cols, offset, len} (offset/len in f64 values, column-major)
//! payload   8 x N     f64 little-endian values of all arrays, back to back
//! ```
//! Reading checks the magic, the version, the header, every array's declared shape against the
//! ROM's dimensions and the payload checksum, so a truncated or foreign file is reported as such
//! (naming the file) instead of being misread.

use super::{Rom, RomMeta, RomOutput};
use faer::Mat;
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Magic bytes at the start of every ROM file.
pub const MAGIC: &[u8; 12] = b"RIGTWIN-ROM\n";
/// Current format version. Bump on any incompatible change (2: `meta.beam_length`).
pub const FORMAT_VERSION: u32 = 2;

/// Errors reading or writing a ROM file.
#[derive(Debug, thiserror::Error)]
pub enum RomFileError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The file does not start with the ROM magic.
    #[error(
        "{path}: not a rigtwin ROM file (expected the magic bytes \"RIGTWIN-ROM\" at the start)"
    )]
    NotARom {
        /// File.
        path: PathBuf,
    },
    /// Written by another format version.
    #[error("{path}: ROM format version {found}, this rigtwin reads version {expected}; rebuild it with `rigtwin rom build`")]
    Version {
        /// File.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// Version this build reads.
        expected: u32,
    },
    /// The file ends before the header or payload it declares.
    #[error("{path}: truncated: {what}")]
    Truncated {
        /// File.
        path: PathBuf,
        /// What is missing.
        what: String,
    },
    /// The header or payload is inconsistent.
    #[error("{path}: corrupt ROM file: {what}")]
    Corrupt {
        /// File.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

#[derive(serde::Serialize, serde::Deserialize)]
struct ArrayEntry {
    name: String,
    rows: usize,
    cols: usize,
    offset: usize,
    len: usize,
}

#[derive(serde::Serialize, serde::Deserialize)]
struct Header {
    format_version: u32,
    meta: RomMeta,
    n_modes: usize,
    n_pairs: usize,
    labels: Vec<String>,
    clearance: f64,
    friction: f64,
    output_names: Vec<String>,
    payload_sha256: String,
    arrays: Vec<ArrayEntry>,
}

struct PayloadBuilder {
    values: Vec<f64>,
    arrays: Vec<ArrayEntry>,
}

impl PayloadBuilder {
    fn push(&mut self, name: &str, rows: usize, cols: usize, data: impl IntoIterator<Item = f64>) {
        let offset = self.values.len();
        self.values.extend(data);
        let len = self.values.len() - offset;
        debug_assert_eq!(len, rows * cols, "array {name}");
        self.arrays.push(ArrayEntry {
            name: name.to_string(),
            rows,
            cols,
            offset,
            len,
        });
    }

    fn push_mat(&mut self, name: &str, m: &Mat<f64>) {
        let (r, c) = (m.nrows(), m.ncols());
        self.push(
            name,
            r,
            c,
            (0..c).flat_map(|j| (0..r).map(move |i| m[(i, j)])),
        );
    }
}

fn payload_bytes(values: &[f64]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(values.len() * 8);
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Serialises a ROM to bytes (the file content).
pub fn to_bytes(rom: &Rom) -> Vec<u8> {
    let m = rom.n_modes();
    let c = rom.n_pairs();
    let mut p = PayloadBuilder {
        values: Vec::new(),
        arrays: Vec::new(),
    };
    p.push("omega", m, 1, rom.omega.iter().copied());
    p.push("damping_ratio", m, 1, rom.damping_ratio.iter().copied());
    p.push("beta", m, 1, rom.beta.iter().copied());
    p.push("pair_area", c, 1, rom.pair_area.iter().copied());
    p.push(
        "pair_position",
        c,
        3,
        (0..3).flat_map(|d| rom.pair_position.iter().map(move |x| x[d])),
    );
    p.push_mat("phi_g", &rom.phi_g);
    p.push_mat("g_res", &rom.g_res);
    p.push_mat("k_gg", &rom.k_gg);
    for o in &rom.outputs {
        p.push(&format!("c_eta/{}", o.name), m, 1, o.c_eta.iter().copied());
        p.push(
            &format!("c_lambda/{}", o.name),
            3 * c,
            1,
            o.c_lambda.iter().copied(),
        );
    }
    let payload = payload_bytes(&p.values);
    let header = Header {
        format_version: FORMAT_VERSION,
        meta: rom.meta.clone(),
        n_modes: m,
        n_pairs: c,
        labels: rom.labels.clone(),
        clearance: rom.clearance,
        friction: rom.friction,
        output_names: rom.outputs.iter().map(|o| o.name.clone()).collect(),
        payload_sha256: sha256_hex(&payload),
        arrays: p.arrays,
    };
    let header = serde_json::to_vec(&header).expect("ROM header serialises");
    let mut out = Vec::with_capacity(24 + header.len() + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(header.len() as u64).to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(&payload);
    out
}

/// Writes a ROM file (atomically: a temporary file renamed into place).
pub fn write(rom: &Rom, path: &Path) -> Result<(), RomFileError> {
    let io = |source| RomFileError::Io {
        path: path.to_path_buf(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    // NOTE: the temporary name is unique per process and thread, so concurrent writers of the
    // same ROM (test binaries sharing a cache) never interleave inside one file.
    static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("rom.{}-{seq}.partial", std::process::id()));
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(&to_bytes(rom)).map_err(io)?;
    f.sync_all().map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Reads a ROM file.
pub fn read(path: &Path) -> Result<Rom, RomFileError> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|source| RomFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    from_bytes(&bytes, path)
}

/// Reads only the header's metadata (fast: no payload decoding); used for cache checks.
pub fn read_meta(path: &Path) -> Result<RomMeta, RomFileError> {
    let bytes = std::fs::read(path).map_err(|source| RomFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (header, _) = parse_header(&bytes, path)?;
    Ok(header.meta)
}

fn parse_header<'a>(bytes: &'a [u8], path: &Path) -> Result<(Header, &'a [u8]), RomFileError> {
    let p = || path.to_path_buf();
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(RomFileError::NotARom { path: p() });
    }
    if bytes.len() < 24 {
        return Err(RomFileError::Truncated {
            path: p(),
            what: "file ends inside the fixed preamble (24 bytes)".into(),
        });
    }
    let version = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes"));
    if version != FORMAT_VERSION {
        return Err(RomFileError::Version {
            path: p(),
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let hlen = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes"));
    let rest = &bytes[24..];
    if (rest.len() as u64) < hlen {
        return Err(RomFileError::Truncated {
            path: p(),
            what: format!("header declares {hlen} bytes, {} remain", rest.len()),
        });
    }
    let hlen = hlen as usize;
    let header: Header =
        serde_json::from_slice(&rest[..hlen]).map_err(|e| RomFileError::Corrupt {
            path: p(),
            what: format!("header JSON: {e}"),
        })?;
    Ok((header, &rest[hlen..]))
}

/// Parses ROM bytes; `path` only names the source in errors.
pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Rom, RomFileError> {
    let corrupt = |what: String| RomFileError::Corrupt {
        path: path.to_path_buf(),
        what,
    };
    let (header, payload) = parse_header(bytes, path)?;
    // NOTE: the header's lengths come from the file (the checksum covers only the payload):
    // sums and products are checked so that a damaged or crafted header is an error, never
    // an overflow.
    let total_bytes = header
        .arrays
        .iter()
        .try_fold(0usize, |sum, a| sum.checked_add(a.len))
        .and_then(|n| n.checked_mul(8))
        .ok_or_else(|| {
            corrupt(format!(
                "the header's array lengths add up to more than {} bytes",
                usize::MAX
            ))
        })?;
    let total = total_bytes / 8;
    if payload.len() < total_bytes {
        return Err(RomFileError::Truncated {
            path: path.to_path_buf(),
            what: format!(
                "payload declares {total} values ({total_bytes} bytes), {} bytes remain",
                payload.len()
            ),
        });
    }
    if payload.len() > total_bytes {
        return Err(corrupt(format!(
            "{} trailing bytes after the payload",
            payload.len() - total_bytes
        )));
    }
    if sha256_hex(payload) != header.payload_sha256 {
        return Err(corrupt(
            "payload checksum mismatch (the file was modified or damaged)".into(),
        ));
    }
    let values: Vec<f64> = payload
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let (m, c) = (header.n_modes, header.n_pairs);
    let get = |name: &str, rows: usize, cols: usize| -> Result<&[f64], RomFileError> {
        let a = header
            .arrays
            .iter()
            .find(|a| a.name == name)
            .ok_or_else(|| corrupt(format!("array `{name}` missing")))?;
        if a.rows != rows
            || a.cols != cols
            || rows.checked_mul(cols) != Some(a.len)
            || a.offset
                .checked_add(a.len)
                .is_none_or(|end| end > values.len())
        {
            return Err(corrupt(format!(
                "array `{name}` is {}x{} (len {}, offset {}), expected {rows}x{cols}",
                a.rows, a.cols, a.len, a.offset
            )));
        }
        Ok(&values[a.offset..a.offset + a.len])
    };
    let mat = |name: &str, rows: usize, cols: usize| -> Result<Mat<f64>, RomFileError> {
        let d = get(name, rows, cols)?;
        Ok(Mat::from_fn(rows, cols, |i, j| d[i + rows * j]))
    };
    // Every mode and pair owns values of the payload: larger counts are damage (and would
    // overflow the sizes below).
    if m > values.len() || c > values.len() {
        return Err(corrupt(format!(
            "the header declares {m} modes and {c} pairs, more than the payload's {} values",
            values.len()
        )));
    }
    if header.labels.len() != m {
        return Err(corrupt(format!(
            "{} labels for {m} modes",
            header.labels.len()
        )));
    }
    let pos = get("pair_position", c, 3)?;
    let mut outputs = Vec::new();
    for name in &header.output_names {
        outputs.push(RomOutput {
            name: name.clone(),
            c_eta: get(&format!("c_eta/{name}"), m, 1)?.to_vec(),
            c_lambda: get(&format!("c_lambda/{name}"), 3 * c, 1)?.to_vec(),
        });
    }
    if header.meta.reference_mode >= m.max(1) {
        return Err(corrupt(format!(
            "reference mode {} out of range ({m} modes)",
            header.meta.reference_mode
        )));
    }
    Ok(Rom {
        meta: header.meta,
        omega: get("omega", m, 1)?.to_vec(),
        damping_ratio: get("damping_ratio", m, 1)?.to_vec(),
        labels: header.labels,
        phi_g: mat("phi_g", 3 * c, m)?,
        g_res: mat("g_res", 3 * c, 3 * c)?,
        k_gg: mat("k_gg", 3 * c, 3 * c)?,
        beta: get("beta", m, 1)?.to_vec(),
        pair_area: get("pair_area", c, 1)?.to_vec(),
        pair_position: (0..c)
            .map(|k| [pos[k], pos[c + k], pos[2 * c + k]])
            .collect(),
        clearance: header.clearance,
        friction: header.friction,
        outputs,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small synthetic ROM with distinct values in every array (for format tests only).
    pub(crate) fn sample_rom() -> Rom {
        let (m, c) = (4, 2);
        let n = 3 * c;
        Rom {
            meta: RomMeta {
                config_hash: "abc".into(),
                source: "native".into(),
                n_dof: 99,
                ..Default::default()
            },
            omega: vec![10.0, 20.0, 30.0, 40.0],
            damping_ratio: vec![0.001; m],
            labels: vec!["1FL".into(), "1FU".into(), "1EL".into(), "1EU".into()],
            phi_g: Mat::from_fn(n, m, |i, j| (i * 10 + j) as f64 * 0.1),
            g_res: Mat::from_fn(
                n,
                n,
                |i, j| if i == j { 1e-6 } else { 1e-8 * (i + j) as f64 },
            ),
            k_gg: Mat::from_fn(n, n, |i, j| (i + 2 * j) as f64),
            beta: vec![0.5, -0.25, 0.125, 1.0],
            pair_area: vec![1e-7, 2e-7],
            pair_position: vec![[0.29, 0.0, 0.01], [0.291, 0.001, 0.01]],
            clearance: 7e-4,
            friction: 0.4,
            outputs: vec![RomOutput {
                name: "upper_tip".into(),
                c_eta: vec![1.0, 2.0, 3.0, 4.0],
                c_lambda: vec![0.5; n],
            }],
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let rom = sample_rom();
        let bytes = to_bytes(&rom);
        let back = from_bytes(&bytes, Path::new("mem.rom")).unwrap();
        assert_eq!(back.omega, rom.omega);
        assert_eq!(back.phi_g, rom.phi_g);
        assert_eq!(back.g_res, rom.g_res);
        assert_eq!(back.k_gg, rom.k_gg);
        assert_eq!(back.pair_position, rom.pair_position);
        assert_eq!(back.outputs, rom.outputs);
        assert_eq!(back.meta, rom.meta);
        assert_eq!(back.labels, rom.labels);
    }

    #[test]
    fn damaged_files_are_reported() {
        let bytes = to_bytes(&sample_rom());
        let p = Path::new("x.rom");
        let msg = |b: &[u8]| from_bytes(b, p).unwrap_err().to_string();
        assert!(msg(b"PK\x03\x04 not a rom").contains("not a rigtwin ROM"));
        assert!(msg(&bytes[..bytes.len() - 9]).contains("truncated"));
        assert!(msg(&bytes[..30]).contains("truncated"));
        let mut flipped = bytes.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 0x40;
        assert!(msg(&flipped).contains("checksum"));
        let mut v1 = bytes.clone();
        v1[12] = 1;
        assert!(msg(&v1).contains("version 1"));
        let mut extra = bytes;
        extra.push(0);
        assert!(msg(&extra).contains("trailing"));
        assert!(msg(&[]).starts_with("x.rom"));
    }

    /// The header with `edit` applied (its length rewritten), the payload as it was.
    fn with_header(bytes: &[u8], edit: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
        let hlen = u64::from_le_bytes(bytes[16..24].try_into().unwrap()) as usize;
        let mut header: serde_json::Value = serde_json::from_slice(&bytes[24..24 + hlen]).unwrap();
        edit(&mut header);
        let text = serde_json::to_vec(&header).unwrap();
        let mut out = bytes[..16].to_vec();
        out.extend_from_slice(&(text.len() as u64).to_le_bytes());
        out.extend_from_slice(&text);
        out.extend_from_slice(&bytes[24 + hlen..]);
        out
    }

    /// Sizes in the header (which the payload checksum does not cover) that would overflow
    /// are errors, not panics or wrapped arithmetic.
    #[test]
    fn huge_sizes_in_the_header_are_errors() {
        let bytes = to_bytes(&sample_rom());
        let p = Path::new("x.rom");
        let msg = |b: &[u8]| from_bytes(b, p).unwrap_err().to_string();
        let huge_len = with_header(&bytes, |h| h["arrays"][0]["len"] = usize::MAX.into());
        assert!(
            msg(&huge_len).contains("add up to more than"),
            "{}",
            msg(&huge_len)
        );
        let times_eight = with_header(&bytes, |h| {
            h["arrays"][0]["len"] = (usize::MAX / 8 + 1).into()
        });
        assert!(msg(&times_eight).contains("add up to more than"));
        let huge_offset = with_header(&bytes, |h| {
            h["arrays"][0]["offset"] = (usize::MAX - 1).into()
        });
        assert!(
            msg(&huge_offset).contains("offset"),
            "{}",
            msg(&huge_offset)
        );
        let huge_pairs = with_header(&bytes, |h| h["n_pairs"] = (usize::MAX / 2).into());
        assert!(msg(&huge_pairs).contains("pairs"), "{}", msg(&huge_pairs));
        let huge_modes = with_header(&bytes, |h| h["n_modes"] = usize::MAX.into());
        assert!(msg(&huge_modes).contains("modes"), "{}", msg(&huge_modes));
    }
}
