//! The summary of a ROM that `rigtwin rom info` prints and writes as JSON.

use super::{BuildTimings, ModeSelection, Rom};

/// Summary of a ROM (the JSON of `rigtwin rom info --json`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RomInfo {
    /// ROM file format version.
    pub format_version: u32,
    /// Rig name.
    pub rig_name: String,
    /// Where K and M came from ("native" or "calculix:JOB").
    pub source: String,
    /// SHA-256 of the rig description and reduction settings.
    pub config_hash: String,
    /// Free DOFs of the parent FE model.
    pub n_dof: usize,
    /// Mesh nodes of the parent model.
    pub n_nodes: usize,
    /// Solid elements of the parent model.
    pub n_elements: usize,
    /// Retained free-interface modes.
    pub n_modes: usize,
    /// Contact node pairs (the boundary has 3 x this many coordinates).
    pub n_contact_pairs: usize,
    /// Mode selection used.
    pub selection: ModeSelection,
    /// Natural frequencies of the retained modes, Hz, ascending.
    pub frequencies_hz: Vec<f64>,
    /// Best-effort labels (1FL, 1FU, 1EL, ...).
    pub labels: Vec<String>,
    /// Modal damping ratios.
    pub damping_ratios: Vec<f64>,
    /// The 1FU frequency (omega_2 / 2 pi), Hz.
    pub f_1fu_hz: f64,
    /// f(1FL) / f(1FU), if a 1FL mode was found.
    pub ratio_1fl_1fu: Option<f64>,
    /// f(2FU) / f(1FU), if a 2FU mode was found.
    pub ratio_2fu_1fu: Option<f64>,
    /// Highest retained frequency relative to f(1FU).
    pub highest_mode_over_1fu: f64,
    /// Total build time, s.
    pub build_seconds: f64,
    /// Build stage timings, s.
    pub timings: BuildTimings,
    /// Largest relative eigen residual of the retained modes.
    pub max_eigen_residual: f64,
    /// Relative error of the ROM's static boundary flexibility vs the parent model.
    pub static_flexibility_error: f64,
    /// Stability limit of the explicit step with all pairs open, steps per 1FU period.
    pub stable_steps_per_period_open: f64,
    /// Same with all pairs closed.
    pub stable_steps_per_period_closed: f64,
    /// Nominal clearance, m.
    pub clearance: f64,
    /// Friction coefficient.
    pub friction: f64,
    /// Output channel names.
    pub outputs: Vec<String>,
}

/// Below this highest retained mode (x f(1FU)) impacts are slow: see
/// [`RomInfo::few_modes_warning`].
// NOTE: measured on the default rig (a dwell at omega_2 at 6e-5 l, 10 + 10 periods, 1000
// steps per period): with modes up to 1.0 or 3.6 x f(1FU) (2 or 4 modes, no second bending
// mode) every impact stays closed for about 62 time steps; with modes up to 17, 44, 82 and
// 179 x f(1FU) (8, 16, 24, 40 modes) for 7.4, 6.8, 6.1 and 4.8. The impact's time scale is
// set by the highest retained mode.
pub const FEW_MODES_CUTOFF_RATIO: f64 = 10.0;

/// Where the ROM a summary describes came from this time, for the first line of
/// [`RomInfo::text`]: only a ROM built now says how long its build took as news.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RomOrigin {
    /// Built by this command.
    Built,
    /// Taken from the ROM cache.
    Cache,
    /// Read from a ROM file.
    File,
}

impl RomInfo {
    /// Summarises a ROM.
    pub fn new(rom: &Rom) -> Self {
        let f = rom.frequencies_hz();
        let f_ref = f.get(rom.meta.reference_mode).copied().unwrap_or(f64::NAN);
        let by_label = |l: &str| rom.labels.iter().position(|x| x == l).map(|i| f[i] / f_ref);
        RomInfo {
            format_version: super::file::FORMAT_VERSION,
            rig_name: rom.meta.rig_name.clone(),
            source: rom.meta.source.clone(),
            config_hash: rom.meta.config_hash.clone(),
            n_dof: rom.meta.n_dof,
            n_nodes: rom.meta.n_nodes,
            n_elements: rom.meta.n_elements,
            n_modes: rom.n_modes(),
            n_contact_pairs: rom.n_pairs(),
            selection: rom.meta.selection,
            highest_mode_over_1fu: f.last().copied().unwrap_or(f64::NAN) / f_ref,
            f_1fu_hz: f_ref,
            ratio_1fl_1fu: by_label("1FL"),
            ratio_2fu_1fu: by_label("2FU"),
            frequencies_hz: f,
            labels: rom.labels.clone(),
            damping_ratios: rom.damping_ratio.clone(),
            build_seconds: rom.meta.build_seconds,
            timings: rom.meta.timings.clone(),
            max_eigen_residual: rom.meta.max_eigen_residual,
            static_flexibility_error: rom.meta.static_flexibility_error,
            stable_steps_per_period_open: rom.meta.stable_steps_per_period_open,
            stable_steps_per_period_closed: rom.meta.stable_steps_per_period_closed,
            clearance: rom.clearance,
            friction: rom.friction,
            outputs: rom.outputs.iter().map(|o| o.name.clone()).collect(),
        }
    }

    /// A warning for a ROM whose highest retained mode is below [`FEW_MODES_CUTOFF_RATIO`] x
    /// f(1FU): impacts excite the beams far above it, so every contact lasts about ten times
    /// longer than with the default modes (slow, soft impacts). `None` for a ROM with enough
    /// modes.
    pub fn few_modes_warning(&self) -> Option<String> {
        // NaN (no reference mode) is not "few".
        let few = self.highest_mode_over_1fu < FEW_MODES_CUTOFF_RATIO;
        if !few {
            return None;
        }
        Some(format!(
            "the ROM keeps {} modes, up to {:.1} x f(1FU): impacts excite the beams far above \
             that, so each contact lasts about ten times longer than with modes past \
             {FEW_MODES_CUTOFF_RATIO} x f(1FU) (slow, soft impacts); rebuild it with more modes \
             (`rom build --cutoff-ratio`, default 180)",
            self.n_modes, self.highest_mode_over_1fu
        ))
    }

    /// A short human-readable summary (a few lines); the first says where the ROM came from.
    pub fn text(&self, origin: RomOrigin) -> String {
        let origin = match origin {
            RomOrigin::Built => format!("built in {:.1} s", self.build_seconds),
            RomOrigin::Cache => format!(
                "loaded from the cache (its build took {:.1} s)",
                self.build_seconds
            ),
            RomOrigin::File => format!(
                "read from the file (its build took {:.1} s)",
                self.build_seconds
            ),
        };
        let mut s = format!(
            "{} ({}): {} DOFs -> {} modes + {} contact pairs, {origin}\n",
            self.rig_name, self.source, self.n_dof, self.n_modes, self.n_contact_pairs,
        );
        s += &format!(
            "f(1FU) = {:.2} Hz; f(1FL)/f(1FU) = {}; f(2FU)/f(1FU) = {}; highest mode = {:.1} x f(1FU)\n",
            self.f_1fu_hz,
            self.ratio_1fl_1fu.map_or("-".into(), |r| format!("{r:.4}")),
            self.ratio_2fu_1fu.map_or("-".into(), |r| format!("{r:.3}")),
            self.highest_mode_over_1fu
        );
        s += &format!(
            "explicit step limit: {:.0} steps per 1FU period open, {:.0} closed; eigen residual {:.1e}; static flexibility error {:.1e}\n",
            self.stable_steps_per_period_open, self.stable_steps_per_period_closed, self.max_eigen_residual, self.static_flexibility_error
        );
        s += "lowest modes:";
        for (f, l) in self.frequencies_hz.iter().zip(&self.labels).take(10) {
            s += &format!(" {l} {f:.1} Hz,");
        }
        s.pop();
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rom_without_modes_past_ten_times_f1_warns_of_slow_impacts() {
        let mut rom = crate::rom::file::tests::sample_rom();
        // Modes at 10, 20, 30, 40 rad/s, the reference mode the second: up to 2 x f(1FU).
        rom.meta.reference_mode = 1;
        let w = RomInfo::new(&rom).few_modes_warning().expect("a warning");
        assert!(
            w.contains("4 modes, up to 2.0 x f(1FU)") && w.contains("slow"),
            "{w}"
        );
        rom.omega[3] = 20.0 * 11.0;
        assert_eq!(RomInfo::new(&rom).few_modes_warning(), None);
    }
}
