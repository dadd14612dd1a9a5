//! Modal damping of the rig description: identified damping ratios by mode label and the
//! fill rule of reference section 3.2 for modes that were not identified.
//!
//! Mode labels follow `<order><F|E|T|A><L|U|C>`: order >= 1; flap-wise, edge-wise, torsion,
//! axial; lower beam, upper beam, clamp. Examples: 1FL, 1FU, 1EL, 2FU, 1TU, 1FC.

use serde::{Deserialize, Serialize};

/// One identified modal damping ratio.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModalDamping {
    /// Mode label, e.g. "1FU". Required.
    pub label: String,
    /// Damping ratio (fraction of critical, not percent), -. Required, in [0, 1).
    pub ratio: f64,
}

/// `[damping]`: identified modal damping ratios, listed in ascending frequency of the
/// identified modes (the order only matters when no computed mode carries a listed label).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DampingSpec {
    /// Identified ratios by label. Required, at least one.
    pub ratios: Vec<ModalDamping>,
}

impl DampingSpec {
    /// The listed ratio of a label, if any.
    pub fn listed(&self, label: &str) -> Option<f64> {
        self.ratios
            .iter()
            .find(|m| m.label == label)
            .map(|m| m.ratio)
    }

    /// Damping ratio of each computed mode (one per entry of `freqs_hz`; `labels[i]` labels
    /// mode i, a missing label counts as not listed).
    ///
    /// Fill rule (reference section 3.2: D3 = D4, D>7 = D7): a mode whose label is listed
    /// takes its listed ratio; an unlisted mode takes the ratio of the lowest listed mode at
    /// or above its frequency; an unlisted mode above every listed mode takes the ratio of
    /// the highest listed mode. "Listed mode" means a computed mode carrying a listed label.
    /// When no computed mode carries a listed label, every mode takes the ratio of the last
    /// listed entry (the highest identified mode).
    pub fn damping_ratios(&self, labels: &[String], freqs_hz: &[f64]) -> Vec<f64> {
        let ratio_of = |i: usize| labels.get(i).and_then(|l| self.listed(l));
        // (frequency, ratio) of the computed modes that carry a listed label.
        let anchors: Vec<(f64, f64)> = freqs_hz
            .iter()
            .enumerate()
            .filter_map(|(i, &f)| ratio_of(i).map(|r| (f, r)))
            .collect();
        let fallback = self.ratios.last().map_or(0.0, |m| m.ratio);
        let top = anchors
            .iter()
            .copied()
            .reduce(|a, b| if b.0 >= a.0 { b } else { a })
            .map_or(fallback, |a| a.1);
        freqs_hz
            .iter()
            .enumerate()
            .map(|(i, &f)| {
                ratio_of(i).unwrap_or_else(|| {
                    anchors
                        .iter()
                        .filter(|a| a.0 >= f)
                        .copied()
                        .reduce(|a, b| if b.0 < a.0 { b } else { a })
                        .map_or(top, |a| a.1)
                })
            })
            .collect()
    }
}

/// Whether `label` follows the grammar `<order><F|E|T|A><L|U|C>` with order >= 1.
pub fn is_valid_label(label: &str) -> bool {
    let digits = label.chars().take_while(|c| c.is_ascii_digit()).count();
    let rest: Vec<char> = label[digits..].chars().collect();
    digits > 0
        && label[..digits].parse::<u32>().is_ok_and(|n| n >= 1)
        && rest.len() == 2
        && matches!(rest[0], 'F' | 'E' | 'T' | 'A')
        && matches!(rest[1], 'L' | 'U' | 'C')
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference Table 1 ratios.
    fn table1() -> DampingSpec {
        let r = |label: &str, ratio: f64| ModalDamping {
            label: label.into(),
            ratio,
        };
        DampingSpec {
            ratios: vec![
                r("1FL", 0.00153),
                r("1FU", 0.00183),
                r("1EU", 0.00236),
                r("1FC", 0.00748),
                r("2FL", 0.00186),
                r("2FU", 0.00143),
            ],
        }
    }

    fn labels(l: &[&str]) -> Vec<String> {
        l.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn reference_modes_get_reference_fill() {
        // The reference's seven modes (frequencies as ratios to f2) plus two above.
        let l = labels(&[
            "1FL", "1FU", "1EL", "1EU", "1FC", "2FL", "2FU", "1TU", "3FL",
        ]);
        let f = [0.918, 1.0, 2.006, 2.4, 3.509, 5.763, 5.95, 7.1, 16.0];
        let d = table1().damping_ratios(&l, &f);
        assert_eq!(
            d[..7],
            [0.00153, 0.00183, 0.00236, 0.00236, 0.00748, 0.00186, 0.00143]
        );
        // D>7 = D7.
        assert_eq!(d[7..], [0.00143, 0.00143]);
    }

    #[test]
    fn unlisted_mode_takes_next_listed_above_not_list_order() {
        // 2FU computed below 2FL: an unlisted mode between them takes 2FL's ratio, and a
        // mode above both takes the ratio of the highest-frequency listed mode (2FL here).
        let l = labels(&["1FL", "2FU", "1TL", "2FL", "3FU"]);
        let f = [50.0, 300.0, 310.0, 320.0, 900.0];
        let d = table1().damping_ratios(&l, &f);
        assert_eq!(d, vec![0.00153, 0.00143, 0.00186, 0.00186, 0.00186]);
    }

    #[test]
    fn missing_labels_and_no_anchor_fall_back_to_last_listed() {
        let d = table1().damping_ratios(&labels(&["9TL"]), &[10.0, 20.0]);
        assert_eq!(d, vec![0.00143, 0.00143]);
    }

    #[test]
    fn label_grammar() {
        for ok in ["1FL", "1FU", "1EL", "2FU", "1TU", "1FC", "12AL"] {
            assert!(is_valid_label(ok), "{ok}");
        }
        for bad in ["", "FL", "0FL", "1XL", "1FX", "1F", "1FLU", "-1FL", "1fl"] {
            assert!(!is_valid_label(bad), "{bad}");
        }
    }
}
