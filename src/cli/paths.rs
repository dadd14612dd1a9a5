//! The files a command reads and writes, checked before it starts (issue 17, cases 2 and 8):
//! no output may land on one of the command's inputs or on another of its outputs — compared
//! by path and by file identity (device and inode, so a hard link or a symbolic link to an
//! input counts as the input) — and every output's folder must exist or be creatable and be
//! writable. A command builds one [`Files`] from its flags and calls [`Files::ready`] before it
//! reads, builds or runs anything, so a bad path costs nothing and destroys nothing; `ready`
//! then creates the missing folders of every output (issue 18, item 3: every `--out`, `--json`
//! and `--figures` behaves the same).

use anyhow::bail;
use std::os::unix::fs::MetadataExt;
use std::path::{Component, Path, PathBuf};

/// One file (or folder) a command names on its command line.
#[derive(Clone, Debug)]
struct Named {
    /// The flag that names it, e.g. `--out`, or a description of a positional argument.
    flag: String,
    /// The path as given.
    path: PathBuf,
    /// What the command keeps there (`the session log`, `the plan`, ...).
    what: String,
}

/// An output: a file, or a folder the command fills with files ending in one of `extensions`.
#[derive(Clone, Debug)]
struct Output {
    named: Named,
    /// `None`: a file. `Some(exts)`: a folder into which files with these extensions (and no
    /// others) are written.
    folder: Option<Vec<&'static str>>,
}

/// The inputs and outputs of one command.
#[derive(Clone, Debug, Default)]
pub(crate) struct Files {
    inputs: Vec<Named>,
    outputs: Vec<Output>,
}

/// The identity of an existing file: device and inode (symbolic links followed).
fn identity(path: &Path) -> Option<(u64, u64)> {
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// `path` made absolute and lexically clean, its folder resolved when it exists (so `a/../b`,
/// `./b` and a symlinked folder compare equal to `b`).
fn normalized(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    if let Ok(p) = absolute.canonicalize() {
        return p;
    }
    if let (Some(dir), Some(name)) = (absolute.parent(), absolute.file_name()) {
        if let Ok(d) = dir.canonicalize() {
            return d.join(name);
        }
    }
    let mut clean = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                clean.pop();
            }
            other => clean.push(other),
        }
    }
    clean
}

/// Whether `a` and `b` name the same file: the same path once normalised, or, when both
/// exist, the same device and inode.
fn same_file(a: &Path, b: &Path) -> bool {
    if normalized(a) == normalized(b) {
        return true;
    }
    matches!((identity(a), identity(b)), (Some(x), Some(y)) if x == y)
}

/// Whether `file` would be written by an output folder `dir` that writes files with
/// `extensions`: `file` sits directly in `dir` and ends with one of them.
fn written_into(dir: &Path, extensions: &[&str], file: &Path) -> bool {
    let in_dir = normalized(file)
        .parent()
        .is_some_and(|parent| same_file(parent, dir));
    let ext = file
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    in_dir && ext.is_some_and(|e| extensions.contains(&e.as_str()))
}

impl Files {
    /// No files yet.
    pub(crate) fn new() -> Files {
        Files::default()
    }

    /// An input file named by `flag` (e.g. `--plan`, `the session log FILE`).
    pub(crate) fn input(mut self, flag: &str, path: &Path, what: &str) -> Files {
        self.inputs.push(Named {
            flag: flag.to_string(),
            path: path.to_path_buf(),
            what: what.to_string(),
        });
        self
    }

    /// An optional input.
    pub(crate) fn input_opt(self, flag: &str, path: Option<&Path>, what: &str) -> Files {
        match path {
            Some(p) => self.input(flag, p, what),
            None => self,
        }
    }

    /// An output file named by `flag`.
    pub(crate) fn output(mut self, flag: &str, path: &Path, what: &str) -> Files {
        self.outputs.push(Output {
            named: Named {
                flag: flag.to_string(),
                path: path.to_path_buf(),
                what: what.to_string(),
            },
            folder: None,
        });
        self
    }

    /// An optional output file.
    pub(crate) fn output_opt(self, flag: &str, path: Option<&Path>, what: &str) -> Files {
        match path {
            Some(p) => self.output(flag, p, what),
            None => self,
        }
    }

    /// An output folder named by `flag`, into which the command writes files ending in one
    /// of `extensions` (lower case, without the dot).
    pub(crate) fn output_folder(
        mut self,
        flag: &str,
        path: &Path,
        what: &str,
        extensions: &[&'static str],
    ) -> Files {
        self.outputs.push(Output {
            named: Named {
                flag: flag.to_string(),
                path: path.to_path_buf(),
                what: what.to_string(),
            },
            folder: Some(extensions.to_vec()),
        });
        self
    }

    /// An optional output folder.
    pub(crate) fn output_folder_opt(
        self,
        flag: &str,
        path: Option<&Path>,
        what: &str,
        extensions: &[&'static str],
    ) -> Files {
        match path {
            Some(p) => self.output_folder(flag, p, what, extensions),
            None => self,
        }
    }

    /// Refuses an output on an input or on another output, and an output whose folder cannot
    /// be created or written. Touches nothing.
    pub(crate) fn check(&self) -> anyhow::Result<()> {
        for (i, out) in self.outputs.iter().enumerate() {
            for input in &self.inputs {
                if let Some(how) = clash(out, &input.path) {
                    bail!(
                        "{} {} {how} {} {} ({}, an input of this command): writing there would \
                         overwrite it; name another {}",
                        out.named.flag,
                        out.named.path.display(),
                        input.flag,
                        input.path.display(),
                        input.what,
                        if out.folder.is_some() {
                            "folder"
                        } else {
                            "file"
                        }
                    );
                }
            }
            for other in &self.outputs[..i] {
                let how = match (&out.folder, &other.folder) {
                    (None, None) => same_file(&out.named.path, &other.named.path)
                        .then(|| clash_words(&out.named.path, &other.named.path)),
                    (Some(_), None) => clash(out, &other.named.path),
                    (None, Some(_)) => clash(other, &out.named.path),
                    (Some(_), Some(_)) => same_file(&out.named.path, &other.named.path)
                        .then(|| clash_words(&out.named.path, &other.named.path)),
                };
                if let Some(how) = how {
                    bail!(
                        "{} {} {how} {} {} ({}): two outputs of one command cannot share a \
                         file; name another",
                        out.named.flag,
                        out.named.path.display(),
                        other.named.flag,
                        other.named.path.display(),
                        other.named.what
                    );
                }
            }
        }
        for out in &self.outputs {
            writable(out)?;
        }
        Ok(())
    }
}

impl Files {
    /// [`Files::check`], then creates every output's missing folders: an output file's parent
    /// folders, an output folder and its parents. (Only folders: no output file is touched.)
    pub(crate) fn ready(&self) -> anyhow::Result<()> {
        self.check()?;
        for out in &self.outputs {
            let path = &out.named.path;
            let dir = match out.folder {
                Some(_) => Some(path.as_path()),
                None => path.parent().filter(|d| !d.as_os_str().is_empty()),
            };
            if let Some(dir) = dir {
                std::fs::create_dir_all(dir).map_err(|e| {
                    anyhow::anyhow!(
                        "{} {}: creating the folder {}: {e}",
                        out.named.flag,
                        path.display(),
                        dir.display()
                    )
                })?;
            }
        }
        Ok(())
    }
}

/// How output `out` would overwrite `file`, in words, or `None`.
fn clash(out: &Output, file: &Path) -> Option<String> {
    if same_file(&out.named.path, file) {
        return Some(clash_words(&out.named.path, file));
    }
    match &out.folder {
        Some(exts) if written_into(&out.named.path, exts, file) => Some(format!(
            "would write {} files into the folder of",
            exts.join("/")
        )),
        _ => None,
    }
}

/// "is" for the same path, "is the same file as (a link)" for two paths of one file.
fn clash_words(a: &Path, b: &Path) -> String {
    if normalized(a) == normalized(b) {
        "is".to_string()
    } else {
        "is the same file (a hard or symbolic link) as".to_string()
    }
}

/// Checks that `out` can be written: an output file is not an existing folder (and an output
/// folder not an existing file), and the nearest existing folder above it is a writable folder.
fn writable(out: &Output) -> anyhow::Result<()> {
    let Output { named, folder } = out;
    let path = &named.path;
    if let Ok(m) = std::fs::metadata(path) {
        match folder {
            None if m.is_dir() => bail!(
                "{} {}: is a folder; {} needs a file name",
                named.flag,
                path.display(),
                named.what
            ),
            Some(_) if !m.is_dir() => bail!(
                "{} {}: is a file, not a folder (for {})",
                named.flag,
                path.display(),
                named.what
            ),
            _ => {}
        }
    }
    // The folder the output goes in (a folder output: itself when it exists), else the nearest
    // existing one above, in which the missing ones will be created.
    let start = match folder {
        Some(_) if path.is_dir() => path.clone(),
        _ => normalized(path)
            .parent()
            .map_or_else(|| PathBuf::from("/"), Path::to_path_buf),
    };
    let mut dir = start.as_path();
    while !dir.exists() {
        dir = match dir.parent() {
            Some(p) => p,
            None => break,
        };
    }
    let meta = std::fs::metadata(dir);
    if !meta.as_ref().is_ok_and(|m| m.is_dir()) {
        bail!(
            "{} {}: cannot be created: {} is not a folder",
            named.flag,
            path.display(),
            dir.display()
        );
    }
    if !access_writable(dir) {
        bail!(
            "{} {}: cannot be written: the folder {} is not writable",
            named.flag,
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// Whether this process may create files in the folder `dir` (access(2), W_OK and X_OK).
fn access_writable(dir: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(dir.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: access(2) reads the NUL-terminated path and nothing else.
    unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) == 0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_on_an_input_is_refused_by_path_and_by_hard_link() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.mcap");
        std::fs::write(&a, b"x").unwrap();
        let b = dir.path().join("b.mcap");
        std::fs::hard_link(&a, &b).unwrap();
        let by_path = Files::new().input("FILE", &a, "the session log").output(
            "--json",
            &dir.path().join(".").join("a.mcap"),
            "the summary",
        );
        let e = by_path.check().unwrap_err().to_string();
        assert!(
            e.contains("--json") && e.contains("FILE") && e.contains("a.mcap"),
            "{e}"
        );
        let by_link = Files::new()
            .input("FILE", &b, "the session log")
            .output("--out", &a, "the copy");
        let e = by_link.check().unwrap_err().to_string();
        assert!(e.contains("hard or symbolic link"), "{e}");
        let fine = Files::new().input("FILE", &a, "the session log").output(
            "--out",
            &dir.path().join("c.mcap"),
            "the copy",
        );
        fine.check().unwrap();
    }

    #[test]
    fn two_outputs_on_one_file_and_folders_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let s = dir.path().join("s.mcap");
        let e = Files::new()
            .output("--out", &s, "the session log")
            .output("--json", &s, "the summary")
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("--json") && e.contains("--out"), "{e}");
        let plan = dir.path().join("figs").join("plan.png");
        let e = Files::new()
            .input("--plan", &plan, "the plan")
            .output_folder(
                "--figures",
                &dir.path().join("figs"),
                "the figures",
                &["png"],
            )
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("--figures") && e.contains("--plan"), "{e}");
        let e = Files::new()
            .output("--json", dir.path(), "the summary")
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a folder"), "{e}");
        let file = dir.path().join("f");
        std::fs::write(&file, b"").unwrap();
        let e = Files::new()
            .output("--json", &file.join("x").join("s.json"), "the summary")
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a folder"), "{e}");
    }

    #[test]
    fn ready_creates_the_missing_folders_of_every_output() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("new").join("dir").join("s.mcap");
        let figs = dir.path().join("other").join("figs");
        Files::new()
            .output("--out", &log, "the session log")
            .output_folder("--figures", &figs, "the figures", &["png"])
            .ready()
            .unwrap();
        assert!(log.parent().unwrap().is_dir());
        assert!(!log.exists(), "no output file is created");
        assert!(figs.is_dir());
        // A refused output creates nothing.
        let s = dir.path().join("x").join("s.mcap");
        assert!(Files::new()
            .output("--out", &s, "the session log")
            .output("--json", &s, "the summary")
            .ready()
            .is_err());
        assert!(!dir.path().join("x").exists());
    }
}
