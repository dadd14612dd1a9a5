//! Truth variants: physics of the simulated rig that the twin does not know, each off by
//! default and switched on in `[truth.variants]`. The parameters and their checks are
//! [`crate::config::physics`] (the same schema as the model's `[model]`), the physics
//! [`crate::physics`]: one implementation for the truth and the model.
//!
//! - `modes`: the truth ROM's natural frequencies and damping ratios differ from the nominal.
//! - `clamp_friction`: an Iwan element on the first bending mode of each beam.
//! - `clearance`: each test's clearance differs from the plan's.
//! - `wear`: the clearance grows with the accumulated normal contact impulse.
//! - `tilt`: every pair gets its own initial gap.
//! - `sensor_gains`: per-channel sensitivity errors applied before the ADC while the DAQ
//!   layout keeps the nominal sensitivity.

pub use crate::physics::{
    Beam, ClampFrictionSpec, ClearanceSpec, ModalCorrectionSpec, SensorGainSpec, TiltSpec,
    TruthVariants, WearSpec, MAX_SLIDERS, MAX_TILT,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::sim::SimRigSpec;

    fn parse(text: &str) -> Result<SimRigSpec, String> {
        let spec: SimRigSpec = toml::from_str(text).map_err(|e| e.to_string())?;
        spec.validate().map_err(|e| e.to_string())?;
        Ok(spec)
    }

    #[test]
    fn off_by_default_and_parsed_with_defaults() {
        let spec = parse("").unwrap();
        assert!(!spec.truth.variants.any());
        assert_eq!(spec.truth.variants.to_json(), "{}");
        let spec = parse(
            "[truth.variants]\n\
             sensor_gains = [{ channel = \"upper_tip\", gain = 1.03 }]\n\
             [truth.variants.clamp_friction]\n\
             stiffness_fraction = 0.2\n\
             half_slip_tip_amplitude = 1e-4\n\
             [truth.variants.wear]\n\
             coefficient = 1e-6\n\
             [truth.variants.tilt]\n\
             angle = 1e-3\n",
        )
        .unwrap();
        let v = &spec.truth.variants;
        assert!(v.any());
        let c = v.clamp_friction.as_ref().unwrap();
        assert_eq!(
            (c.sliders, c.beams.as_slice()),
            (64, &[Beam::Lower, Beam::Upper][..])
        );
        assert_eq!(v.wear.as_ref().unwrap().max_growth, None);
        assert_eq!(v.tilt.as_ref().unwrap().axis, [0.0, 1.0]);
        assert_eq!(v.sensor_gains[0].gain, 1.03);
        // The other [truth] keys keep their defaults.
        assert_eq!(spec.truth.cutoff_ratio, 400.0);
        // Round trip through TOML and JSON.
        let back: SimRigSpec = toml::from_str(&toml::to_string(&spec).unwrap()).unwrap();
        assert_eq!(back, spec);
        let json = v.to_json();
        assert!(json.contains("\"clamp_friction\"") && json.contains("\"upper_tip\""));
        let back: TruthVariants = serde_json::from_str(&json).unwrap();
        assert_eq!(&back, v);
    }

    #[test]
    fn misspelled_keys_are_rejected_by_name() {
        for (text, key) in [
            ("[truth.variants]\nwaer = 1\n", "waer"),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = 1e-4\nslider = 3\n",
                "slider",
            ),
            ("[truth.variants.wear]\ncoeficient = 1e-6\n", "coeficient"),
            (
                "[truth.variants.tilt]\nangle = 0.0\naxes = [1.0, 0.0]\n",
                "axes",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"upper_tip\", gian = 1.0 }]\n",
                "gian",
            ),
        ] {
            let msg = parse(text).unwrap_err();
            assert!(msg.contains(&format!("unknown field `{key}`")), "{msg}");
        }
        let msg = parse(
            "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
             half_slip_tip_amplitude = 1e-4\nbeams = [\"middle\"]\n",
        )
        .unwrap_err();
        assert!(msg.contains("middle") && msg.contains("lower"), "{msg}");
        let msg = parse("[truth.variants.wear]\n").unwrap_err();
        assert!(msg.contains("missing field `coefficient`"), "{msg}");
    }

    #[test]
    fn bad_values_name_the_key() {
        let clamp = |body: &str| {
            format!(
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = 1e-4\n{body}"
            )
        };
        for (text, expect) in [
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = -0.1\n\
                 half_slip_tip_amplitude = 1e-4\n"
                    .to_string(),
                "truth.variants.clamp_friction.stiffness_fraction = -0.1: expected",
            ),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 1.0\n\
                 half_slip_tip_amplitude = 1e-4\n"
                    .to_string(),
                "truth.variants.clamp_friction.stiffness_fraction = 1: expected",
            ),
            (
                "[truth.variants.clamp_friction]\nstiffness_fraction = 0.1\n\
                 half_slip_tip_amplitude = nan\n"
                    .to_string(),
                "truth.variants.clamp_friction.half_slip_tip_amplitude = NaN: expected",
            ),
            (
                clamp("sliders = 0\n"),
                "truth.variants.clamp_friction.sliders = 0: expected 1 to 10000",
            ),
            (
                clamp("beams = []\n"),
                "truth.variants.clamp_friction.beams = []",
            ),
            (
                clamp("beams = [\"upper\", \"upper\"]\n"),
                "truth.variants.clamp_friction.beams[1] = upper: expected each beam listed once",
            ),
            (
                "[truth.variants.wear]\ncoefficient = -1e-6\n".to_string(),
                "truth.variants.wear.coefficient = -0.000001: expected",
            ),
            (
                "[truth.variants.wear]\ncoefficient = 1e-6\nmax_growth = 0.0\n".to_string(),
                "truth.variants.wear.max_growth = 0: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = 0.5\n".to_string(),
                "truth.variants.tilt.angle = 0.5: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = inf\n".to_string(),
                "truth.variants.tilt.angle = inf: expected",
            ),
            (
                "[truth.variants.tilt]\nangle = 0.01\naxis = [0.0, 0.0]\n".to_string(),
                "truth.variants.tilt.axis = [0.0, 0.0]: expected",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"upper_tipp\", gain = 1.1 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].channel = \"upper_tipp\": expected a DAQ \
                 channel name (channels: platform_1, platform_2, platform_3, lower_tip",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"vibrometer\", gain = 1.1 }, \
                 { channel = \"vibrometer\", gain = 1.2 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[1].channel = \"vibrometer\": expected each channel",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"lower_mid\", gain = -1.0 }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].gain = -1: expected",
            ),
            (
                "[truth.variants]\nsensor_gains = [{ channel = \"lower_mid\", gain = nan }]\n"
                    .to_string(),
                "truth.variants.sensor_gains[0].gain = NaN: expected",
            ),
        ] {
            let msg = parse(&text).unwrap_err();
            assert!(msg.contains(expect), "{text}\n-> {msg}");
        }
        // A renamed platform accelerometer is a valid channel.
        parse(
            "[daq]\nplatform_accelerometers = [\"table\"]\n[truth.variants]\n\
             sensor_gains = [{ channel = \"table\", gain = 0.98 }]\n",
        )
        .unwrap();
    }
}
