//! Sensor sensitivities from redundant channels. Two channels that see the same motion have
//! fundamental complex amplitudes in a constant ratio, the ratio of their sensitivities
//! (true over nominal): flat in frequency and the same with and without impacts.
//! - The platform accelerometers all see the base: each channel's ratio to the mean of the
//!   others. With three or more, the channels that agree decide: when all but one agree, the
//!   odd one is off by its ratio to the mean of the others (2 of 3 agree).
//! - The vibrometer and the upper-tip accelerometer see one spot: the accelerometer's
//!   fundamental over `i Omega` times the vibrometer's is `g_upper_tip / g_vibrometer`. No
//!   third channel sees that spot, so a ratio off 1 says that one of the two is off, not which.
//! - `lower_tip`, `lower_mid` and `upper_mid` have no redundant partner: they are decided
//!   against the model later, never here.
//!
//! A ratio is the least-squares ratio over every record window (`r = sum conj(x) y / sum
//! |x|^2`, dominated by the windows with the most signal); its spread is the `|x|^2`-weighted
//! standard deviation of the per-window ratios and its standard error the spread over the
//! square root of the windows' effective number. Two channels agree when their ratio is
//! within [`SensorOptions::significance`] standard errors of 1, or within
//! [`SensorOptions::min_deviation`] (a deviation too small to matter).

use rustfft::num_complex::Complex64;
use serde::Serialize;

use crate::rig::channels::{LOWER_MID, LOWER_TIP, UPPER_MID, UPPER_TIP, VIBROMETER};
use crate::session::replay::Recording;

use super::error::EvidenceError;
use super::evidence::{session_evidence, SessionEvidence};

/// Settings of the sensitivity estimates.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct SensorOptions {
    /// Standard errors within which a ratio counts as 1, -. Default 4.
    pub significance: f64,
    /// Relative deviation of a ratio from 1 below which two channels agree whatever the
    /// standard error, -. Default 0.002 (0.2 %).
    pub min_deviation: f64,
}

impl Default for SensorOptions {
    fn default() -> Self {
        SensorOptions {
            significance: 4.0,
            min_deviation: 0.002,
        }
    }
}

/// A ratio of two channels' fundamentals over the record windows.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ChannelRatio {
    /// The numerator channel (or channels, joined by `+`, for a mean).
    pub numerator: String,
    /// The denominator channel (or channels, joined by `+`, for a mean).
    pub denominator: String,
    /// Magnitude of the least-squares complex ratio, - (the sensitivity ratio).
    pub ratio: f64,
    /// Phase of the least-squares complex ratio, rad (0 for two channels of one motion).
    pub phase_rad: f64,
    /// Weighted standard deviation of the per-window ratio magnitudes, -.
    pub spread: f64,
    /// Standard error of `ratio`, -.
    pub standard_error: f64,
    /// Record windows used.
    pub windows: usize,
    /// The ratio over the impact-free windows only (none without such windows), -.
    pub impact_free: Option<f64>,
    /// The ratio over the windows with contact only (none without such windows), -.
    pub with_contact: Option<f64>,
    /// Slope of the per-window ratio against Omega / omega_2 (weighted least squares), -;
    /// zero for a sensitivity error (flat in frequency). None with a single frequency.
    pub slope_per_omega_ratio: Option<f64>,
    /// Standard error of the slope, -.
    pub slope_standard_error: Option<f64>,
}

impl ChannelRatio {
    /// Whether the ratio is 1 within the options' tolerance.
    pub fn is_one(&self, opts: &SensorOptions) -> bool {
        let dev = (self.ratio - 1.0).abs();
        dev <= opts.min_deviation || dev <= opts.significance * self.standard_error
    }
}

/// What the session says about one channel's sensitivity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SensitivityStatus {
    /// Agrees with its redundant partners: nominal within the spread.
    Nominal,
    /// Off: its partners agree among themselves and not with it.
    Off,
    /// The session cannot say (no redundant partner, or partners that cannot decide which
    /// channel is off).
    Undecided,
}

/// The estimate of one channel's sensitivity.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct ChannelSensitivity {
    /// Channel name.
    pub channel: String,
    /// Nominal, off or undecided.
    pub status: SensitivityStatus,
    /// True over nominal sensitivity (the `[model]` `sensor_gains` `gain`), -, when the
    /// channel is decided: its ratio to the channels it agrees with. None when undecided.
    pub gain: Option<f64>,
    /// Spread of the gain over the record windows, -.
    pub spread: Option<f64>,
    /// Standard error of the gain, -.
    pub standard_error: Option<f64>,
    /// Why, in words (which channels decided, or why nothing can).
    pub reason: String,
}

/// The sensitivity evidence of a session.
#[derive(Clone, Debug, PartialEq, Serialize, schemars::JsonSchema)]
pub struct SensorEvidence {
    /// Record windows used.
    pub windows: usize,
    /// The options used.
    pub options: SensorOptions,
    /// Each platform accelerometer against the mean of the others (empty with fewer than two).
    pub platform_ratios: Vec<ChannelRatio>,
    /// Upper-tip accelerometer over the vibrometer's derivative (`g_upper_tip /
    /// g_vibrometer`), when the layout has both.
    pub upper_tip_over_vibrometer: Option<ChannelRatio>,
    /// Every motion sensor's verdict, layout order.
    pub channels: Vec<ChannelSensitivity>,
}

impl SensorEvidence {
    /// The verdict on channel `name`.
    pub fn channel(&self, name: &str) -> Option<&ChannelSensitivity> {
        self.channels.iter().find(|c| c.channel == name)
    }
}

/// Weighted least-squares statistics of `y_k / x_k` over windows (see the module docs).
fn ratio_of(
    numerator: String,
    denominator: String,
    pairs: &[(Complex64, Complex64, f64, bool)],
) -> ChannelRatio {
    // (x, y, omega_ratio, impact_free)
    let ls = |sel: &dyn Fn(bool) -> bool| -> Option<Complex64> {
        let (mut num, mut den) = (Complex64::new(0.0, 0.0), 0.0);
        for (x, y, _, _) in pairs.iter().filter(|p| sel(p.3)) {
            num += x.conj() * y;
            den += x.norm_sqr();
        }
        (den > 0.0).then(|| num / den)
    };
    let r = ls(&|_| true).unwrap_or(Complex64::new(f64::NAN, f64::NAN));
    let mag = r.norm();
    let (mut sw, mut sw2, mut s) = (0.0, 0.0, 0.0);
    for (x, y, _, _) in pairs {
        let w = x.norm_sqr();
        if w > 0.0 {
            let d = (y / x).norm() - mag;
            sw += w;
            sw2 += w * w;
            s += w * d * d;
        }
    }
    let spread = if sw > 0.0 { (s / sw).sqrt() } else { f64::NAN };
    let n_eff = if sw2 > 0.0 { sw * sw / sw2 } else { 0.0 };
    let standard_error = if n_eff > 1.0 {
        spread / (n_eff - 1.0).sqrt()
    } else {
        f64::INFINITY
    };
    // Weighted line of |y/x| against Omega / omega_2.
    let (mut a, mut b, mut c, mut d, mut e) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (x, y, o, _) in pairs {
        let w = x.norm_sqr();
        if w > 0.0 {
            let q = (y / x).norm();
            a += w;
            b += w * o;
            c += w * o * o;
            d += w * q;
            e += w * o * q;
        }
    }
    let det = a * c - b * b;
    let (slope, slope_se) = if det > 1e-12 * a * c && n_eff > 2.0 {
        let slope = (a * e - b * d) / det;
        let icpt = (d - slope * b) / a;
        let mut res = 0.0;
        for (x, y, o, _) in pairs {
            let w = x.norm_sqr();
            if w > 0.0 {
                let q = (y / x).norm() - icpt - slope * o;
                res += w * q * q;
            }
        }
        let s2 = res / a * n_eff / (n_eff - 2.0);
        // Var(slope) = s2 * a / det, with the weights normalised to the effective count.
        (Some(slope), Some((s2 * a / det * a / n_eff).sqrt()))
    } else {
        (None, None)
    };
    ChannelRatio {
        numerator,
        denominator,
        ratio: mag,
        phase_rad: r.arg(),
        spread,
        standard_error,
        windows: pairs.len(),
        impact_free: ls(&|free| free).map(|z| z.norm()),
        with_contact: ls(&|free| !free).map(|z| z.norm()),
        slope_per_omega_ratio: slope,
        slope_standard_error: slope_se,
    }
}

/// The sensitivity evidence of the recording `rec` (as recorded, no corrections).
///
/// Errors: those of [`session_evidence`] (no record windows, ...).
pub fn sensor_sensitivities(
    rec: &Recording,
    opts: &SensorOptions,
) -> Result<SensorEvidence, EvidenceError> {
    Ok(sensor_sensitivities_of(&session_evidence(rec, &[])?, opts))
}

/// [`sensor_sensitivities`] of evidence already computed.
pub fn sensor_sensitivities_of(ev: &SessionEvidence, opts: &SensorOptions) -> SensorEvidence {
    let names = &ev.channel_names;
    let platform = ev.platform.clone();
    let mut channels: Vec<ChannelSensitivity> = Vec::new();

    // Platform accelerometers: each against the mean of the others, and pairwise.
    let against = |num: &[usize], den: &[usize]| -> ChannelRatio {
        let mean = |ks: &[usize], w: &super::evidence::WindowEvidence| -> Complex64 {
            ks.iter().map(|&k| w.channels[k]).sum::<Complex64>() / ks.len() as f64
        };
        let pairs: Vec<_> = ev
            .windows
            .iter()
            .map(|w| (mean(den, w), mean(num, w), w.omega_ratio, w.impact_free()))
            .collect();
        let join = |ks: &[usize]| {
            ks.iter()
                .map(|&k| names[k].as_str())
                .collect::<Vec<_>>()
                .join("+")
        };
        ratio_of(join(num), join(den), &pairs)
    };
    let mut platform_ratios = Vec::new();
    if platform.len() >= 2 {
        let others =
            |k: usize| -> Vec<usize> { platform.iter().copied().filter(|&j| j != k).collect() };
        for &k in &platform {
            platform_ratios.push(against(&[k], &others(k)));
        }
        // Which channels agree with which (pairwise ratios).
        let agree = |i: usize, j: usize| against(&[i], &[j]).is_one(opts);
        let n = platform.len();
        let all_agree = (0..n).all(|a| (a + 1..n).all(|b| agree(platform[a], platform[b])));
        // The odd one out: disagrees with every other, while the others all agree.
        let odd: Vec<usize> = (0..n)
            .filter(|&a| {
                let rest: Vec<usize> = (0..n).filter(|&b| b != a).collect();
                rest.iter().all(|&b| !agree(platform[a], platform[b]))
                    && rest.iter().all(|&b| {
                        rest.iter()
                            .all(|&c| b == c || agree(platform[b], platform[c]))
                    })
            })
            .collect();
        for (a, &k) in platform.iter().enumerate() {
            let r = &platform_ratios[a];
            let others_names = others(k)
                .iter()
                .map(|&j| names[j].clone())
                .collect::<Vec<_>>()
                .join(", ");
            let decided = |status, reason: String| ChannelSensitivity {
                channel: names[k].clone(),
                status,
                gain: Some(r.ratio),
                spread: Some(r.spread),
                standard_error: Some(r.standard_error),
                reason,
            };
            channels.push(if all_agree {
                decided(
                    SensitivityStatus::Nominal,
                    format!("agrees with {others_names} (one base)"),
                )
            } else if n >= 3 && odd.len() == 1 {
                if odd[0] == a {
                    decided(
                        SensitivityStatus::Off,
                        format!(
                            "disagrees with {others_names}, which agree with each other: its \
                             ratio to their mean is the gain"
                        ),
                    )
                } else {
                    let off = &names[platform[odd[0]]];
                    // Against the channels that agree (all but the odd one).
                    let good: Vec<usize> = platform
                        .iter()
                        .copied()
                        .filter(|&j| j != k && j != platform[odd[0]])
                        .collect();
                    let r = against(&[k], &good);
                    ChannelSensitivity {
                        channel: names[k].clone(),
                        status: SensitivityStatus::Nominal,
                        gain: Some(r.ratio),
                        spread: Some(r.spread),
                        standard_error: Some(r.standard_error),
                        reason: format!("agrees with the other platform channels; {off} is off"),
                    }
                }
            } else {
                ChannelSensitivity {
                    channel: names[k].clone(),
                    status: SensitivityStatus::Undecided,
                    gain: None,
                    spread: None,
                    standard_error: None,
                    reason: format!(
                        "the platform accelerometers disagree and no majority agrees (ratio to \
                         the mean of {others_names}: {:.4} +- {:.4}): which is off cannot be \
                         decided from them",
                        r.ratio, r.standard_error
                    ),
                }
            });
        }
    } else {
        for &k in &platform {
            channels.push(undecided(
                &names[k],
                "the only platform accelerometer: no redundant channel",
            ));
        }
    }

    // The vibrometer and the upper-tip accelerometer: one spot.
    let k_ut = ev.channel(UPPER_TIP);
    let k_vib = ev.channel(VIBROMETER);
    let upper_tip_over_vibrometer = match (k_ut, k_vib) {
        (Some(ut), Some(vib)) => {
            let pairs: Vec<_> = ev
                .windows
                .iter()
                .map(|w| {
                    (
                        w.channels[vib] * Complex64::new(0.0, w.omega),
                        w.channels[ut],
                        w.omega_ratio,
                        w.impact_free(),
                    )
                })
                .collect();
            Some(ratio_of(
                UPPER_TIP.to_string(),
                format!("d/dt {VIBROMETER}"),
                &pairs,
            ))
        }
        _ => None,
    };
    match &upper_tip_over_vibrometer {
        Some(r) if r.is_one(opts) => {
            for (name, gain) in [(UPPER_TIP, r.ratio), (VIBROMETER, 1.0 / r.ratio)] {
                channels.push(ChannelSensitivity {
                    channel: name.to_string(),
                    status: SensitivityStatus::Nominal,
                    gain: Some(gain),
                    spread: Some(r.spread),
                    standard_error: Some(r.standard_error),
                    reason: format!(
                        "{UPPER_TIP} and {VIBROMETER} agree (one spot): both nominal, unless both \
                         are off by the same factor"
                    ),
                });
            }
        }
        Some(r) => {
            for name in [UPPER_TIP, VIBROMETER] {
                channels.push(undecided(
                    name,
                    &format!(
                        "{UPPER_TIP} / {VIBROMETER} sensitivity ratio {:.4} +- {:.4} (one spot): one \
                         of the two is off by this factor, no third channel says which; decided \
                         against the model",
                        r.ratio, r.standard_error
                    ),
                ));
            }
        }
        None => {
            for k in [k_ut, k_vib].into_iter().flatten() {
                channels.push(undecided(
                    &names[k],
                    "its partner at the upper tip is not in the layout: no redundant channel",
                ));
            }
        }
    }
    for name in [LOWER_TIP, LOWER_MID, UPPER_MID] {
        if ev.channel(name).is_some() {
            channels.push(undecided(
                name,
                "no redundant channel sees its spot: decided against the model",
            ));
        }
    }
    channels.sort_by_key(|c| ev.channel(&c.channel));
    SensorEvidence {
        windows: ev.windows.len(),
        options: opts.clone(),
        platform_ratios,
        upper_tip_over_vibrometer,
        channels,
    }
}

fn undecided(channel: &str, reason: &str) -> ChannelSensitivity {
    ChannelSensitivity {
        channel: channel.to_string(),
        status: SensitivityStatus::Undecided,
        gain: None,
        spread: None,
        standard_error: None,
        reason: reason.to_string(),
    }
}
