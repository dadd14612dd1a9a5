//! Linear modal corrections (reference section 3.2's updating, done on the ROM instead of the
//! parent model): per mode label, a natural frequency and/or a damping ratio.
//!
// NOTE (MacNeal consistency): a corrected frequency `omega_i -> omega_i'` is read as the
// rank-one stiffness change of the parent model that moves mode i alone,
// `Delta K = (omega_i'^2 - omega_i^2) M phi_i phi_i^T M` (M-orthonormal modes): every other
// mode, the base participation `beta` and all mode shapes stay as they are. Its static
// flexibility follows from Sherman-Morrison, with `K^-1 M phi_i = phi_i / omega_i^2`:
// `(K + Delta K)^-1 = K^-1 + phi_i phi_i^T (1 / omega_i'^2 - 1 / omega_i^2)`. The ROM's static
// boundary flexibility is `G = G_res + Phi_g Omega^-2 Phi_g^T`, and the residual `G_res` is
// `G` minus the retained modes' part, i.e. the part of the modes left out, which do not
// change: so `G_res` (and `K_gg`, the output rows' residual part `c_lambda`) stays as it is
// and only `omega_i` changes. The ROM's static boundary flexibility then becomes exactly the
// corrected parent's (tested against a ROM rebuilt from `K + Delta K`). Keeping `G` instead
// (`G_res' = G_res + phi_g phi_g^T (1 / omega_i^2 - 1 / omega_i'^2)`) would make `G_res'`
// indefinite when a mode is softened and ascribe the change to the modes left out.
//
// NOTE (reference frequency): the ROM's reference mode (1FU, `omega_2`) may be corrected like
// any other; the frequency unit of plans (`Omega / omega_2`) is the nominal ROM's `omega_2`
// (a plan means the same frequencies in Hz whatever the model), which callers keep from the
// nominal ROM.

use crate::rom::Rom;

use super::{ModalCorrectionSpec, PhysicsError, MODAL_FREQUENCY_RANGE};

/// Index of the mode labelled `label` in `rom`, or an error naming `key`.
pub fn mode_index(rom: &Rom, label: &str, key: &str) -> Result<usize, PhysicsError> {
    rom.labels
        .iter()
        .position(|l| l == label)
        .ok_or_else(|| PhysicsError::UnknownMode {
            key: key.to_owned(),
            label: label.to_owned(),
            labels: rom.labels.clone(),
        })
}

/// Applies the corrections `modes` (valid, see [`crate::config::physics`]) to `rom` in place
/// (see the module docs). Keys in errors are `<prefix>.modes[i].<field>`. Nothing changes
/// when an entry fails.
pub fn apply(
    rom: &mut Rom,
    modes: &[ModalCorrectionSpec],
    prefix: &str,
) -> Result<(), PhysicsError> {
    let mut changes = Vec::with_capacity(modes.len());
    for (k, m) in modes.iter().enumerate() {
        let i = mode_index(rom, &m.mode, &format!("{prefix}.modes[{k}].mode"))?;
        let omega = match m.frequency_hz {
            Some(f) => {
                let (low, high) = MODAL_FREQUENCY_RANGE;
                let rom_hz = rom.omega[i] / (2.0 * std::f64::consts::PI);
                if !(f >= low * rom_hz && f <= high * rom_hz) {
                    return Err(PhysicsError::FrequencyRange {
                        key: format!("{prefix}.modes[{k}].frequency_hz"),
                        label: m.mode.clone(),
                        frequency_hz: f,
                        rom_hz,
                        low,
                        high,
                    });
                }
                2.0 * std::f64::consts::PI * f
            }
            None => rom.omega[i],
        };
        changes.push((i, omega, m.damping_ratio.unwrap_or(rom.damping_ratio[i])));
    }
    for (i, omega, zeta) in changes {
        rom.omega[i] = omega;
        rom.damping_ratio[i] = zeta;
    }
    Ok(())
}

/// The ROM's static boundary flexibility `G = G_res + Phi_g Omega^-2 Phi_g^T`, 3C x 3C, m/N.
pub fn static_boundary_flexibility(rom: &Rom) -> faer::Mat<f64> {
    let nb = rom.g_res.nrows();
    faer::Mat::from_fn(nb, nb, |r, c| {
        rom.g_res[(r, c)]
            + (0..rom.n_modes())
                .map(|i| rom.phi_g[(r, i)] * rom.phi_g[(c, i)] / (rom.omega[i] * rom.omega[i]))
                .sum::<f64>()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rom::{RomMeta, RomOutput};
    use faer::Mat;

    fn rom() -> Rom {
        let w = |f: f64| 2.0 * std::f64::consts::PI * f;
        Rom {
            meta: RomMeta::default(),
            omega: vec![w(92.0), w(100.0), w(240.0)],
            damping_ratio: vec![0.0015, 0.0018, 0.0024],
            labels: vec!["1FL".into(), "1FU".into(), "1EU".into()],
            phi_g: Mat::from_fn(3, 3, |r, c| 0.1 * (r + 1) as f64 - 0.05 * c as f64),
            g_res: Mat::from_fn(3, 3, |i, j| if i == j { 1e-6 } else { 1e-8 }),
            k_gg: Mat::zeros(3, 3),
            beta: vec![0.5, 0.4, 0.1],
            pair_area: vec![1e-6],
            pair_position: vec![[0.3, 0.0, 0.0]],
            clearance: 1e-3,
            friction: 0.4,
            outputs: vec![RomOutput {
                name: "upper_tip".into(),
                c_eta: vec![0.1, 1.0, 0.0],
                c_lambda: vec![0.0; 3],
            }],
        }
    }

    #[test]
    fn only_the_named_mode_changes_and_the_flexibility_follows_sherman_morrison() {
        let nominal = rom();
        let mut r = rom();
        let spec = [ModalCorrectionSpec {
            mode: "1FU".into(),
            frequency_hz: Some(96.0),
            damping_ratio: Some(0.003),
        }];
        apply(&mut r, &spec, "model").unwrap();
        let w = 2.0 * std::f64::consts::PI * 96.0;
        assert_eq!(r.omega, [nominal.omega[0], w, nominal.omega[2]]);
        assert_eq!(r.damping_ratio, [0.0015, 0.003, 0.0024]);
        assert_eq!(r.g_res, nominal.g_res);
        let (g0, g1) = (
            static_boundary_flexibility(&nominal),
            static_boundary_flexibility(&r),
        );
        let d = 1.0 / (w * w) - 1.0 / (nominal.omega[1] * nominal.omega[1]);
        for a in 0..3 {
            for b in 0..3 {
                let expected = g0[(a, b)] + nominal.phi_g[(a, 1)] * nominal.phi_g[(b, 1)] * d;
                assert!((g1[(a, b)] - expected).abs() <= 1e-15 * expected.abs().max(1e-12));
            }
        }
        // Damping only.
        let mut r = rom();
        apply(
            &mut r,
            &[ModalCorrectionSpec {
                mode: "1FL".into(),
                frequency_hz: None,
                damping_ratio: Some(0.01),
            }],
            "model",
        )
        .unwrap();
        assert_eq!(r.omega, nominal.omega);
        assert_eq!(r.damping_ratio[0], 0.01);
    }

    #[test]
    fn unknown_labels_and_far_frequencies_name_the_key_and_change_nothing() {
        let mut r = rom();
        let e = apply(
            &mut r,
            &[
                ModalCorrectionSpec {
                    mode: "1FU".into(),
                    frequency_hz: Some(99.0),
                    damping_ratio: None,
                },
                ModalCorrectionSpec {
                    mode: "1FX".into(),
                    frequency_hz: Some(99.0),
                    damping_ratio: None,
                },
            ],
            "model",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("model.modes[1].mode = \"1FX\"") && e.contains("1FL, 1FU, 1EU"),
            "{e}"
        );
        assert_eq!(
            (&r.omega, &r.damping_ratio),
            (&rom().omega, &rom().damping_ratio)
        );
        let e = apply(
            &mut r,
            &[ModalCorrectionSpec {
                mode: "1EU".into(),
                frequency_hz: Some(1000.0),
                damping_ratio: None,
            }],
            "truth.variants",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("truth.variants.modes[0].frequency_hz = 1000"),
            "{e}"
        );
    }
}
