//! The simulated rig's shaker and amplifier (`[shaker]`). Every field states its unit and
//! default; [`ShakerSpec::validate`] names the key of a bad value. Not part of the model: not
//! hashed. The shaker model itself lives in `rig::sim::shaker`.
//!
//! The defaults model a large electrodynamic shaker carrying the small two-beam rig
//! (reference section 5: the total moving mass is large compared with the beams' modal mass,
//! so exciter-structure interaction is weak, yet the resonant force drop is visible): 50 kg
//! moving on a soft suspension (5.7 Hz), a low-impedance coil (0.8 ohm, 1 mH, 40 N/A) behind a
//! voltage amplifier. With the default ROM (sum(beta_i^2) = 0.74 kg, 1FU: beta^2 = 0.21 kg at
//! 0.18 % damping) the linear base acceleration at a constant drive dips to about 0.6 of its
//! value at 0.9 / 1.1 omega_1FU (30 kg: 0.39, 100 kg: 0.84); under impacts the tips cannot
//! build up the resonance and the dip mostly disappears.

use serde::{Deserialize, Serialize};

use super::error::{non_negative, positive, SpecError};

/// An electrodynamic shaker driven by a voltage amplifier: moving mass on a suspension, coil
/// with resistance, inductance and force constant (TOML `[shaker]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShakerSpec {
    /// Everything that moves with the table, kg: armature, table, clamping blocks and the
    /// beams themselves (the beams' modal reaction is subtracted from it, so it must exceed
    /// `sum_i beta_i^2` of the truth ROM). Default 50 (a large shaker: armature about 25 kg,
    /// table/head expander 15 kg, clamping blocks 9 kg, beams with probes 0.74 kg).
    pub moving_mass: f64,
    /// Axial stiffness of the armature suspension, N/m (>= 0). Default 6.5e4 (suspension
    /// frequency 5.7 Hz with the default mass, well below the test band).
    pub suspension_stiffness: f64,
    /// Damping ratio of the suspension alone, - (>= 0; the coil adds electrical damping
    /// `Bl^2 / R` under voltage drive). Default 0.05.
    pub suspension_damping_ratio: f64,
    /// Coil resistance R, ohm (> 0). Default 0.8.
    pub coil_resistance: f64,
    /// Coil inductance L, H (> 0). Default 1.0e-3 (electrical corner R / (2 pi L) = 127 Hz).
    pub coil_inductance: f64,
    /// Force constant Bl, N/A (= back-EMF constant, V s/m) (> 0). Default 40.
    pub force_constant: f64,
    /// Voltage gain of the power amplifier, V/V (> 0). Default 20.
    pub amplifier_gain: f64,
    /// Largest output voltage magnitude of the amplifier, V (> 0); beyond it the output clips
    /// and the rig reports drive saturation. Default 60.
    pub amplifier_limit_v: f64,
}

impl Default for ShakerSpec {
    fn default() -> Self {
        ShakerSpec {
            moving_mass: 50.0,
            suspension_stiffness: 6.5e4,
            suspension_damping_ratio: 0.05,
            coil_resistance: 0.8,
            coil_inductance: 1.0e-3,
            force_constant: 40.0,
            amplifier_gain: 20.0,
            amplifier_limit_v: 60.0,
        }
    }
}

impl ShakerSpec {
    /// Suspension damping coefficient `c = 2 zeta sqrt(k M)`, N s/m.
    pub fn suspension_damping(&self) -> f64 {
        2.0 * self.suspension_damping_ratio * (self.suspension_stiffness * self.moving_mass).sqrt()
    }

    /// Checks every field against the range in its documentation. The ROM-dependent check
    /// (moving mass against the beams' modal mass) is done by `rig::sim::SimRig::new`.
    pub fn validate(&self) -> Result<(), SpecError> {
        let s = self;
        positive("shaker.moving_mass", s.moving_mass)?;
        non_negative("shaker.suspension_stiffness", s.suspension_stiffness)?;
        non_negative(
            "shaker.suspension_damping_ratio",
            s.suspension_damping_ratio,
        )?;
        positive("shaker.coil_resistance", s.coil_resistance)?;
        positive("shaker.coil_inductance", s.coil_inductance)?;
        positive("shaker.force_constant", s.force_constant)?;
        positive("shaker.amplifier_gain", s.amplifier_gain)?;
        positive("shaker.amplifier_limit_v", s.amplifier_limit_v)
    }
}
