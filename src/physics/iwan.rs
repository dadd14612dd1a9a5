//! Friction in the clamping joint: an Iwan element ([`Iwan`]) on the first bending mode of each
//! beam ([`ClampJoint`]).
//!
//! Iwan element on a coordinate `q`: N Jenkins elements in parallel, element j a spring
//! `k = k_J / N` in series with a Coulomb slider at position `s_j` that slips at the spring
//! force `k delta_j` (slip deflection `delta_j`). Joint force `F_J(q) = k sum_j (q - s_j)`,
//! `F_J = k_J q` while every slider sticks. Slip deflections are spread uniformly (slip
//! forces uniform between 0 and `k delta_max`) at the midpoints
//! `delta_j = delta_max (j - 1/2) / N`, j = 1..N. Update at a new `q` (return mapping, exact
//! for a piecewise-linear path between updates): `s_j <- q - delta_j` if `q - s_j > delta_j`,
//! `s_j <- q + delta_j` if `q - s_j < -delta_j`, else unchanged; the slider dissipates
//! `k delta_j |Delta s_j|`.
//!
//! On the truth ROM the joint's stuck stiffness is already in `Omega^2`; the slipped sliders
//! remove `k_J q - F_J(q) = k sum_j s_j`, which enters the modal equation as the extra force
//! `f_load = k sum_j s_j` (zero until the first slider slips), evaluated at the step's
//! displacement `eta^j` (explicit, like the rest of the leapfrog step). Steady cycling at
//! amplitude `A <= delta_max` (continuous distribution) dissipates
//! `E(A) = integral_0^A (k_J / delta_max) 4 delta (A - delta) d delta = (2/3) k_J A^3 / delta_max`
//! per cycle, and the secant stiffness at full slip is `(1 - k_J / omega^2) omega^2`.
//!
// NOTE (stability): the slipped sliders' force only lowers the tangent stiffness of the mode
// (between `omega^2` and `omega^2 - k_J > 0`), so the explicit step stays within the ROM's own
// open stability bound.
//
// NOTE (units): the modal coordinate is mass-normalised (m kg^0.5); the configured slip
// amplitude is a tip displacement and is converted with the tip output's participation
// `c_tip,i` of the mode: `delta_max = 2 half_slip_tip_amplitude / |c_tip,i|`, `k_J =
// stiffness_fraction omega_i^2`. A mode shape with `c_tip,i = 0` is rejected.

use crate::rom::Rom;

use super::{ClampFrictionSpec, PhysicsError};

/// An Iwan element with uniformly distributed slip deflections (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Iwan {
    /// Stiffness per slider, `k_J / N`.
    k: f64,
    /// Slip deflection per slider, ascending.
    delta: Vec<f64>,
    /// Slider positions.
    s: Vec<f64>,
    /// `sum_j s_j` after the last update.
    sum_s: f64,
    /// Energy dissipated by the sliders since creation (force x slip), force x coordinate.
    dissipated: f64,
}

impl Iwan {
    /// `n >= 1` sliders of total stiffness `total_stiffness` (>= 0) with slip deflections
    /// uniform in (0, `max_slip`] (midpoints), all stuck at `q = 0`.
    pub fn uniform(total_stiffness: f64, max_slip: f64, n: usize) -> Iwan {
        let n = n.max(1);
        Iwan {
            k: total_stiffness / n as f64,
            delta: (0..n)
                .map(|j| max_slip * (j as f64 + 0.5) / n as f64)
                .collect(),
            s: vec![0.0; n],
            sum_s: 0.0,
            dissipated: 0.0,
        }
    }

    /// Moves the sliders to displacement `q` and returns the force the slipped sliders take
    /// away from the stuck joint, `k_J q - F_J(q) = k sum_j s_j`.
    #[inline]
    pub fn update(&mut self, q: f64) -> f64 {
        let mut sum = 0.0;
        let mut slip_work = 0.0;
        for (s, &d) in self.s.iter_mut().zip(&self.delta) {
            let p = q - *s;
            if p > d {
                let new = q - d;
                slip_work += d * (new - *s).abs();
                *s = new;
            } else if p < -d {
                let new = q + d;
                slip_work += d * (new - *s).abs();
                *s = new;
            }
            sum += *s;
        }
        self.sum_s = sum;
        self.dissipated += self.k * slip_work;
        self.k * sum
    }

    /// The joint force `F_J(q) = k sum_j (q - s_j)` at the current slider positions.
    pub fn force(&self, q: f64) -> f64 {
        self.k * (self.s.len() as f64 * q - self.sum_s)
    }

    /// Energy dissipated by the sliders since creation (force x coordinate: J for a modal
    /// coordinate).
    pub fn dissipated(&self) -> f64 {
        self.dissipated
    }

    /// Back to rest: every slider stuck where it started (the dissipated energy is kept).
    pub fn reset(&mut self) {
        self.s.fill(0.0);
        self.sum_s = 0.0;
    }

    /// Number of sliders currently not at rest relative to where they started (slipped at
    /// least once).
    pub fn slipped(&self) -> usize {
        self.s.iter().filter(|&&s| s != 0.0).count()
    }

    /// The sliders' state (for a warm start).
    pub fn state(&self) -> IwanState {
        IwanState {
            slider: self.s.clone(),
            dissipated: self.dissipated,
        }
    }

    /// Restores a state of an element like this one; `false` (nothing changed) when the slider
    /// count differs or a value is not finite.
    pub fn set_state(&mut self, state: &IwanState) -> bool {
        let fits = state.slider.len() == self.s.len()
            && state.slider.iter().all(|s| s.is_finite())
            && state.dissipated.is_finite();
        if fits {
            self.s.copy_from_slice(&state.slider);
            // The same sum, in the same order, as `update` forms it.
            self.sum_s = self.s.iter().fold(0.0, |a, &s| a + s);
            self.dissipated = state.dissipated;
        }
        fits
    }
}

/// The state of an [`Iwan`] element: its sliders' positions and the energy dissipated so far.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct IwanState {
    /// Slider positions, in the element's coordinate.
    pub slider: Vec<f64>,
    /// Energy dissipated so far, J.
    pub dissipated: f64,
}

/// The clamping joints of the listed beams: one Iwan element per beam on the modal coordinate
/// of its first bending mode, and the modal load it produces.
#[derive(Clone, Debug, PartialEq)]
pub struct ClampJoint {
    /// Mode index per element.
    modes: Vec<usize>,
    elements: Vec<Iwan>,
    /// `(mode, f_load)` of the last update.
    load: Vec<(usize, f64)>,
}

impl ClampJoint {
    /// The joints of `spec` (valid) on `rom`: finds each beam's first bending mode by label
    /// (1FL, 1FU) and its tip output. Errors name the key `<prefix>.clamp_friction.beams`.
    pub fn new(
        rom: &Rom,
        spec: &ClampFrictionSpec,
        prefix: &str,
    ) -> Result<ClampJoint, PhysicsError> {
        let key = format!("{prefix}.clamp_friction.beams");
        let mut modes = Vec::new();
        let mut elements = Vec::new();
        for &beam in &spec.beams {
            let label = beam.first_bending_label();
            let i = super::modal::mode_index(rom, label, &key)?;
            let tip = beam.tip_output();
            let c = rom
                .outputs
                .iter()
                .find(|o| o.name == tip)
                .and_then(|o| o.c_eta.get(i).copied())
                .unwrap_or(0.0);
            if !(c.is_finite() && c != 0.0) {
                return Err(PhysicsError::NoParticipation {
                    key,
                    label: label.to_owned(),
                    output: tip.to_owned(),
                    participation: c,
                });
            }
            let max_slip = 2.0 * spec.half_slip_tip_amplitude / c.abs();
            let k_j = spec.stiffness_fraction * rom.omega[i] * rom.omega[i];
            modes.push(i);
            elements.push(Iwan::uniform(k_j, max_slip, spec.sliders));
        }
        let load = modes.iter().map(|&i| (i, 0.0)).collect();
        Ok(ClampJoint {
            modes,
            elements,
            load,
        })
    }

    /// Updates every element at the modal displacements `eta` and returns the modal load
    /// `(mode, f_load)` for the step.
    #[inline]
    pub fn update(&mut self, eta: &[f64]) -> &[(usize, f64)] {
        for ((l, e), &i) in self
            .load
            .iter_mut()
            .zip(&mut self.elements)
            .zip(&self.modes)
        {
            l.1 = e.update(eta[i]);
        }
        &self.load
    }

    /// Back to rest: every slider of every joint stuck at zero displacement, no load.
    pub fn reset(&mut self) {
        self.elements.iter_mut().for_each(Iwan::reset);
        self.load.iter_mut().for_each(|l| l.1 = 0.0);
    }

    /// The load of the last update.
    pub fn load(&self) -> &[(usize, f64)] {
        &self.load
    }

    /// Energy dissipated in the joints since the start, J.
    pub fn dissipated(&self) -> f64 {
        self.elements.iter().map(Iwan::dissipated).sum()
    }

    /// The elements' states, one per beam in the order of the spec (for a warm start).
    pub fn state(&self) -> Vec<IwanState> {
        self.elements.iter().map(Iwan::state).collect()
    }

    /// Restores [`ClampJoint::state`] of a joint like this one; `false` (nothing changed) when
    /// it does not fit.
    pub fn set_state(&mut self, state: &[IwanState]) -> bool {
        let fits = state.len() == self.elements.len()
            && self
                .elements
                .iter()
                .zip(state)
                .all(|(e, s)| e.s.len() == s.slider.len())
            && state
                .iter()
                .all(|s| s.slider.iter().all(|x| x.is_finite()) && s.dissipated.is_finite());
        if fits {
            for (e, s) in self.elements.iter_mut().zip(state) {
                e.set_state(s);
            }
        }
        fits
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `cycles` cycles of `q = amp sin(theta)` with `per_cycle` updates each and returns
    /// the loop area `closed integral F_J dq` of the last cycle (trapezoidal in q, exact for
    /// the piecewise-linear path) and the dissipated energy of that cycle.
    fn cycle(iwan: &mut Iwan, amp: f64, cycles: usize, per_cycle: usize) -> (f64, f64) {
        let mut area = 0.0;
        let mut q_prev = 0.0;
        let mut f_prev = iwan.force(0.0);
        let mut e0 = 0.0;
        for n in 1..=cycles * per_cycle {
            if n == (cycles - 1) * per_cycle + 1 {
                area = 0.0;
                e0 = iwan.dissipated();
            }
            let q = amp * (std::f64::consts::TAU * n as f64 / per_cycle as f64).sin();
            iwan.update(q);
            let f = iwan.force(q);
            area += 0.5 * (f + f_prev) * (q - q_prev);
            q_prev = q;
            f_prev = f;
        }
        (area, iwan.dissipated() - e0)
    }

    /// Energy per cycle of the discrete element: `sum_{delta_j < A} 4 k delta_j (A - delta_j)`.
    fn discrete_loss(k_j: f64, max_slip: f64, n: usize, amp: f64) -> f64 {
        let k = k_j / n as f64;
        (0..n)
            .map(|j| max_slip * (j as f64 + 0.5) / n as f64)
            .filter(|&d| d < amp)
            .map(|d| 4.0 * k * d * (amp - d))
            .sum()
    }

    #[test]
    fn nothing_changes_below_the_first_slip() {
        let (k_j, max_slip, n) = (2.0e4, 1e-3, 10);
        let mut iwan = Iwan::uniform(k_j, max_slip, n);
        // First slip at delta_1 = max_slip / (2 n) = 5e-5.
        for i in 0..2000 {
            let q = 4.99e-5 * (i as f64 * 0.01).sin();
            assert_eq!(iwan.update(q), 0.0);
            assert!((iwan.force(q) - k_j * q).abs() <= 1e-14 * k_j * q.abs());
        }
        assert_eq!(iwan.dissipated(), 0.0);
        assert_eq!(iwan.slipped(), 0);
        // Just above: the first slider slips, nothing else.
        iwan.update(5.01e-5);
        assert_eq!(iwan.slipped(), 1);
        assert!(iwan.dissipated() > 0.0);
    }

    #[test]
    fn hysteresis_loop_area_is_the_dissipated_energy() {
        let (k_j, max_slip, n) = (2.0e4, 1e-3, 50);
        for amp in [2e-4, 6e-4, 1.5e-3] {
            let mut iwan = Iwan::uniform(k_j, max_slip, n);
            let (area, lost) = cycle(&mut iwan, amp, 3, 4000);
            let expected = discrete_loss(k_j, max_slip, n, amp);
            println!(
                "A = {amp:e}: loop area {area:.6e}, dissipated {lost:.6e}, expected {expected:.6e}"
            );
            assert!((area / expected - 1.0).abs() < 1e-3, "{area} vs {expected}");
            assert!((lost / expected - 1.0).abs() < 1e-9, "{lost} vs {expected}");
        }
    }

    #[test]
    fn loss_per_cycle_grows_with_the_cube_of_the_amplitude() {
        // Many sliders: close to the continuous distribution, E = (2/3) k_J A^3 / delta_max.
        let (k_j, max_slip, n) = (2.0e4, 1e-3, 2000);
        let mut losses = Vec::new();
        for amp in [5e-5, 1e-4, 2e-4, 4e-4] {
            let mut iwan = Iwan::uniform(k_j, max_slip, n);
            let (_, lost) = cycle(&mut iwan, amp, 2, 2000);
            let continuous = 2.0 / 3.0 * k_j * amp.powi(3) / max_slip;
            println!("A = {amp:e}: {lost:.5e} (continuous {continuous:.5e})");
            assert!(
                (lost / continuous - 1.0).abs() < 0.01,
                "{lost} vs {continuous}"
            );
            losses.push(lost);
        }
        for w in losses.windows(2) {
            let ratio = w[1] / w[0];
            assert!((ratio / 8.0 - 1.0).abs() < 0.01, "doubling A: x{ratio}");
        }
    }

    #[test]
    fn secant_stiffness_softens_to_the_unjointed_part() {
        let (k_j, max_slip, n) = (2.0e4, 1e-3, 100);
        let mut previous = f64::INFINITY;
        for amp in [1e-5, 2e-4, 5e-4, 9e-4, 2e-3, 1e-2] {
            let mut iwan = Iwan::uniform(k_j, max_slip, n);
            cycle(&mut iwan, amp, 2, 400);
            // At the turning point q = A (a quarter into the next cycle).
            let q = amp;
            iwan.update(q);
            let secant = iwan.force(q) / q;
            println!("A = {amp:e}: secant {secant:.2} of {k_j}");
            assert!(secant <= previous + 1e-9 * k_j, "{secant} after {previous}");
            previous = secant;
        }
        // Below the first slip the joint is fully stuck; far beyond delta_max it carries
        // (about) the slip forces only: sum k delta_j / A -> 0.
        let mut stuck = Iwan::uniform(k_j, max_slip, n);
        assert_eq!(stuck.update(1e-6), 0.0);
        assert!((stuck.force(1e-6) / (k_j * 1e-6) - 1.0).abs() < 1e-14);
        assert!(previous < 0.06 * k_j, "{previous}");
    }

    #[test]
    fn the_modal_load_is_what_the_slipped_sliders_take_away() {
        let (k_j, max_slip, n) = (3.0e4, 1e-3, 7);
        let mut iwan = Iwan::uniform(k_j, max_slip, n);
        for i in 0..500 {
            let q = 1.2e-3 * (i as f64 * 0.05).sin() * (1.0 + 0.001 * i as f64);
            let load = iwan.update(q);
            let expected = k_j * q - iwan.force(q);
            assert!(
                (load - expected).abs() <= 1e-12 * k_j * 1e-3,
                "{load} vs {expected}"
            );
        }
    }
}
