//! Readers for the matrix files of `*FREQUENCY,SOLVER=MATRIXSTORAGE`: `.sti`/`.mas` (one
//! triangle of a symmetric matrix, `i j value`, 1-based) and `.dof` (`node.dir` per row).

use std::path::{Path, PathBuf};

use faer::sparse::{SparseColMat, Triplet};

use super::{parse_real, CalculixError};

/// One entry of a symmetric matrix file, normalised to `row <= col`, 1-based.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Entry {
    pub row: usize,
    pub col: usize,
    pub value: f64,
    /// 1-based line number in the file.
    pub line: usize,
}

/// The deduplicated entries of one symmetric matrix file.
#[derive(Debug)]
pub(crate) struct SymEntries {
    pub path: PathBuf,
    /// Largest index (CalculiX writes every diagonal, so this is the dimension).
    pub dim: usize,
    /// Upper-triangle entries, sorted by column then row.
    pub entries: Vec<Entry>,
}

/// One `.dof` line: CalculiX node number and direction 1..=3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct DofLine {
    pub node: usize,
    pub dir: u8,
}

pub(crate) fn read_text(path: &Path) -> Result<String, CalculixError> {
    std::fs::read_to_string(path).map_err(|e| CalculixError::io(path, e))
}

/// Reads a `.sti` or `.mas` file. Entries may be in either triangle; an entry given twice
/// (repeated, or as both `i j` and `j i`) must carry the same value.
pub(crate) fn read_sym_matrix(path: &Path) -> Result<SymEntries, CalculixError> {
    let text = read_text(path)?;
    let mut entries = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() {
            continue;
        }
        let fields: Vec<&str> = trimmed.split_whitespace().collect();
        if fields.len() != 3 {
            return Err(CalculixError::parse(
                path,
                line,
                format!(
                    "`row column value` (3 fields), {} field(s) here",
                    fields.len()
                ),
                trimmed,
            ));
        }
        let index = |s: &str, what: &str| -> Result<usize, CalculixError> {
            match s.parse::<usize>() {
                Ok(i) if i >= 1 => Ok(i),
                _ => Err(CalculixError::parse(
                    path,
                    line,
                    format!("a 1-based {what} index"),
                    s,
                )),
            }
        };
        let i = index(fields[0], "row")?;
        let j = index(fields[1], "column")?;
        let value = parse_real(fields[2]).ok_or_else(|| {
            CalculixError::parse(path, line, "a finite real matrix value", fields[2])
        })?;
        entries.push(Entry {
            row: i.min(j),
            col: i.max(j),
            value,
            line,
        });
    }
    if entries.is_empty() {
        return Err(CalculixError::parse(
            path,
            1,
            "at least one `row column value` line",
            "an empty file",
        ));
    }
    entries.sort_by_key(|e| (e.col, e.row, e.line));
    let mut unique: Vec<Entry> = Vec::with_capacity(entries.len());
    for e in entries {
        if let Some(prev) = unique.last() {
            if prev.row == e.row && prev.col == e.col {
                if prev.value != e.value {
                    return Err(CalculixError::ConflictingEntry {
                        path: path.to_path_buf(),
                        line: e.line,
                        row: e.row,
                        col: e.col,
                        value: e.value,
                        first_line: prev.line,
                        first_value: prev.value,
                    });
                }
                continue;
            }
        }
        unique.push(e);
    }
    let dim = unique.iter().map(|e| e.col).max().unwrap_or(0);
    Ok(SymEntries {
        path: path.to_path_buf(),
        dim,
        entries: unique,
    })
}

/// Reads a `.dof` file: one `node.dir` per line (blank lines ignored), each DOF once.
pub(crate) fn read_dof(path: &Path) -> Result<Vec<DofLine>, CalculixError> {
    let text = read_text(path)?;
    let mut dofs = Vec::new();
    let mut seen = std::collections::HashMap::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() {
            continue;
        }
        let bad = || {
            CalculixError::parse(
                path,
                line,
                "`node.direction` with node >= 1 and direction 1, 2 or 3",
                trimmed,
            )
        };
        let (node, dir) = trimmed.split_once('.').ok_or_else(bad)?;
        let node: usize = node.parse().map_err(|_| bad())?;
        let dir: u8 = dir.parse().map_err(|_| bad())?;
        if node == 0 || !(1..=3).contains(&dir) {
            return Err(bad());
        }
        if let Some(first) = seen.insert((node, dir), line) {
            return Err(CalculixError::parse(
                path,
                line,
                format!("each DOF once, but {trimmed} is already on line {first}"),
                trimmed,
            ));
        }
        dofs.push(DofLine { node, dir });
    }
    Ok(dofs)
}

/// Checks an entry list against the DOF count (indices in range, every diagonal present) and builds the full (both triangles) sparse
/// matrix, 0-based.
pub(crate) fn to_sparse(
    m: &SymEntries,
    dof_path: &Path,
    n: usize,
) -> Result<SparseColMat<usize, f64>, CalculixError> {
    let mut triplets = Vec::with_capacity(2 * m.entries.len());
    let mut has_diagonal = vec![false; n + 1];
    for e in &m.entries {
        if e.col > n {
            return Err(CalculixError::IndexOutOfRange {
                path: m.path.clone(),
                line: e.line,
                index: e.col,
                dof: dof_path.to_path_buf(),
                dim: n,
            });
        }
        if e.row == e.col {
            has_diagonal[e.col] = true;
        }
        triplets.push(Triplet::new(e.row - 1, e.col - 1, e.value));
        if e.row != e.col {
            triplets.push(Triplet::new(e.col - 1, e.row - 1, e.value));
        }
    }
    // NOTE: ccx writes every column's diagonal (last in the column), zero or not: a missing
    // one means a file cut inside a column.
    if let Some(j) = (1..=n).find(|&j| !has_diagonal[j]) {
        return Err(CalculixError::MissingDiagonal {
            path: m.path.clone(),
            dof: j,
        });
    }
    SparseColMat::try_new_from_triplets(n, n, &triplets).map_err(|err| CalculixError::Model {
        path: m.path.clone(),
        what: format!("cannot build a {n}x{n} sparse matrix: {err:?}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn mirrors_one_triangle_and_accepts_both() {
        let dir = tempfile::tempdir().unwrap();
        // lower-triangle writer, with an exact mirrored duplicate
        let p = write(
            dir.path(),
            "a.sti",
            "1 1 2.0\n2 1 -1.0\n2 2 3.0\n1 2 -1.0\n\n",
        );
        let truncated = write(dir.path(), "b.sti", "1 1 2.0\n2 1 -1.0\n");
        let b = read_sym_matrix(&truncated).unwrap();
        let err = to_sparse(&b, Path::new("b.dof"), 2)
            .unwrap_err()
            .to_string();
        assert!(err.contains("b.sti") && err.contains("DOF 2"), "{err}");
        let m = read_sym_matrix(&p).unwrap();
        assert_eq!(m.dim, 2);
        assert_eq!(m.entries.len(), 3);
        let s = to_sparse(&m, Path::new("a.dof"), 2).unwrap();
        let d = s.to_dense();
        assert_eq!(d[(0, 1)], -1.0);
        assert_eq!(d[(1, 0)], -1.0);
        assert_eq!(d[(1, 1)], 3.0);
    }

    #[test]
    fn conflicting_mirror_is_an_error_naming_both_lines() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "a.sti",
            "1 1 2.0\n1 2 -1.0\n2 2 3.0\n2 1 -1.5\n",
        );
        let err = read_sym_matrix(&p).unwrap_err().to_string();
        assert!(err.contains("a.sti:4"), "{err}");
        assert!(err.contains("line 2"), "{err}");
    }

    #[test]
    fn dof_lines_parse_and_reject_bad_directions() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "a.dof", "2.1\n2.2\n\n13.3\n");
        let d = read_dof(&p).unwrap();
        assert_eq!(
            d,
            vec![
                DofLine { node: 2, dir: 1 },
                DofLine { node: 2, dir: 2 },
                DofLine { node: 13, dir: 3 },
            ]
        );
        let p = write(dir.path(), "b.dof", "2.1\n2.4\n");
        let err = read_dof(&p).unwrap_err().to_string();
        assert!(
            err.contains("b.dof:2") && err.contains("direction 1, 2 or 3"),
            "{err}"
        );
    }
}
