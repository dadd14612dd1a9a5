//! Output files written under a temporary name beside their destination and renamed into place
//! once they are worth keeping (issue 17, case 3): until then an existing file of that name is
//! left untouched, and a file that is never published is removed when its [`Staged`] is
//! dropped. The session log is published when the session starts (from then on it holds
//! samples worth keeping, and a crash leaves it at its own name); a copy or a JSON summary when
//! it is complete ([`write_atomically`]).
//!
//! A process killed with SIGKILL (or by a power cut) before it published its file leaves the
//! temporary `NAME.partial-PID-N` behind: no drop runs. For the session log that is a file
//! holding only its header and metadata (the log is published as soon as the backend starts),
//! so it holds no sample. [`stale_partials`] finds such files of a destination whose process
//! is gone; `rigtwin run` removes those of its outputs and says so.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// Tells staged files of one process apart.
static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A file being written under a temporary name in its destination's folder.
#[derive(Debug)]
pub struct Staged {
    /// Where it is written.
    temp: PathBuf,
    /// Where it goes when published.
    dest: PathBuf,
    /// Renamed into place.
    published: bool,
}

impl Staged {
    /// Creates a new, empty temporary file beside `dest` (`dest`'s folder must exist):
    /// `NAME.partial-PID-N` for the destination `NAME`.
    pub fn create(dest: &Path) -> std::io::Result<(File, Staged)> {
        let name = dest.file_name().ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the path names no file (it ends in .. or /)",
            )
        })?;
        let mut temp_name = name.to_os_string();
        temp_name.push(format!(
            ".partial-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let temp = dest.with_file_name(temp_name);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)?;
        Ok((
            file,
            Staged {
                temp,
                dest: dest.to_path_buf(),
                published: false,
            },
        ))
    }

    /// The temporary name (the file is written there until published).
    pub fn temp(&self) -> &Path {
        &self.temp
    }

    /// The destination.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// Whether the file is at its destination.
    pub fn is_published(&self) -> bool {
        self.published
    }

    /// Renames the file into place, replacing what was there (atomically: readers see the old
    /// file or the new one, never a mix). An open handle keeps writing to the file. Once done,
    /// later calls do nothing.
    pub fn publish(&mut self) -> std::io::Result<()> {
        if !self.published {
            std::fs::rename(&self.temp, &self.dest)?;
            self.published = true;
        }
        Ok(())
    }
}

impl Drop for Staged {
    /// A file that was never published is removed: the destination keeps what it had.
    fn drop(&mut self) {
        if !self.published {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// The temporary files `NAME.partial-PID-N` beside `dest` (named `NAME`) left by processes that
/// are no longer running (killed before they published them), in name order. Files of a
/// running process (this one, or another writing the same destination right now) are not
/// listed. A folder that cannot be read lists nothing.
pub fn stale_partials(dest: &Path) -> Vec<PathBuf> {
    let (Some(name), dir) = (dest.file_name(), dest.parent()) else {
        return Vec::new();
    };
    let dir = match dir {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut prefix = name.to_os_string();
    prefix.push(".partial-");
    let prefix = prefix.to_string_lossy().into_owned();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut stale: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .filter(|e| {
            let file_name = e.file_name();
            let file_name = file_name.to_string_lossy();
            let Some(rest) = file_name.strip_prefix(&prefix) else {
                return false;
            };
            let mut parts = rest.splitn(2, '-');
            let pid = parts.next().and_then(|p| p.parse::<u32>().ok());
            let n = parts.next().and_then(|n| n.parse::<u32>().ok());
            matches!((pid, n), (Some(pid), Some(_)) if !process_alive(pid))
        })
        .map(|e| e.path())
        .collect();
    stale.sort();
    stale
}

/// Whether a process with this id is running (kill(2) with signal 0: it exists, or exists
/// and belongs to another user).
fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    if pid <= 0 {
        return false;
    }
    // SAFETY: signal 0 sends nothing; kill(2) only checks that the process exists.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// Writes `data` to `dest` through a temporary file synced to disk and renamed into place, so
/// that `dest` is never left half written and keeps its old content if anything fails.
pub fn write_atomically(dest: &Path, data: &[u8]) -> std::io::Result<()> {
    let (mut file, mut staged) = Staged::create(dest)?;
    file.write_all(data)?;
    file.sync_all()?;
    drop(file);
    staged.publish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unpublished_file_leaves_the_destination_alone_and_disappears() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("s.mcap");
        std::fs::write(&dest, b"old").unwrap();
        let (mut f, staged) = Staged::create(&dest).unwrap();
        f.write_all(b"new").unwrap();
        let temp = staged.temp().to_path_buf();
        assert!(temp.exists());
        drop(staged);
        assert!(!temp.exists());
        assert_eq!(std::fs::read(&dest).unwrap(), b"old");
    }

    #[test]
    fn a_published_file_replaces_the_destination_and_stays_writable() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("s.json");
        std::fs::write(&dest, b"old").unwrap();
        let (mut f, mut staged) = Staged::create(&dest).unwrap();
        f.write_all(b"new").unwrap();
        staged.publish().unwrap();
        f.write_all(b" and more").unwrap();
        drop(staged);
        assert_eq!(std::fs::read(&dest).unwrap(), b"new and more");
        write_atomically(&dest, b"{}").unwrap();
        assert_eq!(std::fs::read(&dest).unwrap(), b"{}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn stale_partials_are_those_of_ended_processes() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("s.mcap");
        // A process that has ended: its id names no running process (until reused).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = dir.path().join(format!("s.mcap.partial-{dead}-0"));
        std::fs::write(&stale, b"x").unwrap();
        // This process's own staged file, another output's and a look-alike are not listed.
        let (_f, own) = Staged::create(&dest).unwrap();
        std::fs::write(dir.path().join(format!("t.mcap.partial-{dead}-0")), b"x").unwrap();
        std::fs::write(dir.path().join("s.mcap.partial-notes"), b"x").unwrap();
        assert!(own.temp().exists());
        assert_eq!(stale_partials(&dest), vec![stale]);
    }
}
