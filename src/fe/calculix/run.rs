//! Running `ccx` on a job and reading the eigenfrequencies from its `.dat` file. The only
//! part of the exchange that starts a process.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::matrix::read_text;
use super::{parse_real, CalculixError};

/// Environment variable naming the CalculiX executable (default `ccx`).
pub const CCX_ENV: &str = "RIGTWIN_CCX";

/// What a successful [`run_ccx`] left behind.
#[derive(Clone, Debug)]
pub struct CcxRun {
    /// ccx's standard output followed by its standard error.
    pub log: String,
    /// `dir/JOB.dat` (eigenvalues of a `*FREQUENCY` step).
    pub dat: PathBuf,
    /// `dir/JOB` (append `.sti`, `.mas`, `.dof` for a matrix-storage job).
    pub job_path: PathBuf,
}

/// The CalculiX command: `$RIGTWIN_CCX` if set, else `ccx`.
pub fn ccx_command() -> String {
    std::env::var(CCX_ENV).unwrap_or_else(|_| "ccx".to_string())
}

/// Whether the CalculiX command can be started (for tests that need it).
/// Whether the environment demands CalculiX (`RIGTWIN_REQUIRE_CCX` set, as CI does): tests
/// that would otherwise skip without ccx fail instead.
pub fn ccx_required() -> bool {
    std::env::var_os("RIGTWIN_REQUIRE_CCX").is_some()
}

/// Whether the CalculiX executable can be started.
pub fn ccx_available() -> bool {
    Command::new(ccx_command()).arg("-v").output().is_ok()
}

/// Runs `ccx -i JOB` in `dir` (the deck is `dir/JOB.inp`). Stale `.dat`, `.sti`, `.mas`
/// and `.dof` files of the job are removed first. Since ccx exits with status 0 on most
/// failures, its output is searched for `*ERROR` lines; any makes this an error that quotes
/// them.
pub fn run_ccx(dir: &Path, job: &str) -> Result<CcxRun, CalculixError> {
    let deck = dir.join(format!("{job}.inp"));
    if !deck.is_file() {
        return Err(CalculixError::io(
            deck,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such deck"),
        ));
    }
    for ext in ["dat", "sti", "mas", "dof"] {
        let stale = dir.join(format!("{job}.{ext}"));
        if stale.exists() {
            std::fs::remove_file(&stale).map_err(|e| CalculixError::io(&stale, e))?;
        }
    }
    let command = ccx_command();
    let output = Command::new(&command)
        .arg("-i")
        .arg(job)
        .current_dir(dir)
        .output()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => CalculixError::CcxNotFound {
                command: command.clone(),
            },
            _ => CalculixError::io(PathBuf::from(&command), e),
        })?;
    let mut log = String::from_utf8_lossy(&output.stdout).into_owned();
    log.push_str(&String::from_utf8_lossy(&output.stderr));
    let errors: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("*ERROR"))
        .map(str::trim)
        .take(5)
        .collect();
    if !output.status.success() || !errors.is_empty() {
        let message = if errors.is_empty() {
            format!(
                "{}; last output: {}",
                output.status,
                log.lines().rev().take(3).collect::<Vec<_>>().join(" | ")
            )
        } else {
            format!("{}; {}", output.status, errors.join(" | "))
        };
        return Err(CalculixError::CcxFailed {
            dir: dir.to_path_buf(),
            job: job.to_string(),
            message,
        });
    }
    Ok(CcxRun {
        log,
        dat: dir.join(format!("{job}.dat")),
        job_path: dir.join(job),
    })
}

/// The eigenfrequencies, Hz (column `CYCLES/TIME`), of the first `E I G E N V A L U E
/// O U T P U T` block of a ccx `.dat` file, in mode order.
pub fn read_dat_frequencies(path: &Path) -> Result<Vec<f64>, CalculixError> {
    let text = read_text(path)?;
    let squeeze = |s: &str| s.split_whitespace().collect::<String>();
    let mut lines = text.lines().enumerate();
    if !lines
        .by_ref()
        .any(|(_, l)| squeeze(l) == "EIGENVALUEOUTPUT")
    {
        return Err(CalculixError::parse(
            path,
            text.lines().count().max(1),
            "an `E I G E N V A L U E   O U T P U T` block (the .dat of a *FREQUENCY step)",
            "none in the file",
        ));
    }
    let mut freqs = Vec::new();
    for (k, l) in lines {
        let fields: Vec<&str> = l.split_whitespace().collect();
        let is_row = fields.first().is_some_and(|f| f.parse::<usize>().is_ok());
        if !is_row {
            if freqs.is_empty() {
                continue; // header lines
            }
            break; // end of the block
        }
        let expected = "`mode eigenvalue rad/time cycles/time imaginary` (5 numbers)";
        if fields.len() != 5 {
            return Err(CalculixError::parse(path, k + 1, expected, l.trim()));
        }
        let mode: usize = fields[0].parse().unwrap_or(0);
        if mode != freqs.len() + 1 {
            return Err(CalculixError::parse(
                path,
                k + 1,
                format!("mode number {}", freqs.len() + 1),
                l.trim(),
            ));
        }
        let f = parse_real(fields[3])
            .ok_or_else(|| CalculixError::parse(path, k + 1, expected, l.trim()))?;
        freqs.push(f);
    }
    if freqs.is_empty() {
        return Err(CalculixError::parse(
            path,
            text.lines().count().max(1),
            "at least one mode line after the eigenvalue header",
            "the end of the block",
        ));
    }
    Ok(freqs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_cycles_column_of_the_first_block() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.dat");
        std::fs::write(
            &p,
            "\n     E I G E N V A L U E   O U T P U T\n\n MODE NO    EIGENVALUE                       FREQUENCY   \n                                     REAL PART            IMAGINARY PART\n                           (RAD/TIME)      (CYCLES/TIME     (RAD/TIME)\n\n      1   0.1984539E+09   0.1408737E+05   0.2242074E+04   0.0000000E+00\n      2   0.3833192E+09   0.1957854E+05   0.3116021E+04   0.0000000E+00\n\n     P A R T I C I P A T I O N   F A C T O R S\n\nMODE NO.   X-COMPONENT\n\n      1   0.7097984E-01  -0.2133349E-02  -0.1896594E-02   0.2308004E-05   0.7398207E-03  -0.7444837E-03\n",
        )
        .unwrap();
        assert_eq!(read_dat_frequencies(&p).unwrap(), vec![2242.074, 3116.021]);
    }

    #[test]
    fn dat_without_eigenvalues_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.dat");
        std::fs::write(&p, "\n S T R E S S E S\n").unwrap();
        let err = read_dat_frequencies(&p).unwrap_err().to_string();
        assert!(
            err.contains("b.dat") && err.contains("E I G E N V A L U E"),
            "{err}"
        );
    }
}
