//! Clearance growth from wear: `clearance = nominal + min(coefficient W, max_growth)`, `W` the
//! work the contact has dissipated since the rig started (impacts and friction).
//!
//! `W` comes from the energy terms the integrator already computes each step: the cumulative
//! work of the contact forces on the modes `W_c = sum dt f_c . vbar` (negative when the contact
//! takes energy out) and the elastic energy held in the boundary's residual flexibility
//! `E_b = 1/2 lambda^T G_res lambda` (returned to the modes when the pairs open). What the
//! contact took and did not give back is `D = -(W_c + E_b)`: friction work plus the energy
//! the (end-of-step, implicit) impacts dissipate. `D` changes only while pairs carry force
//! (and once more in the step they open, when `E_b` drops to zero); `W` is its running
//! maximum, so the clearance never shrinks, even where `D` dips by a discretisation ripple
//! during a contact.

/// The wear state (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Wear {
    coefficient: f64,
    max_growth: f64,
    /// `W`: the running maximum of the dissipated contact work, J.
    work: f64,
    /// Current clearance growth, m.
    growth: f64,
}

impl Wear {
    /// Wear with `coefficient` (m/J, >= 0) and an optional cap `max_growth` (m, > 0).
    pub fn new(coefficient: f64, max_growth: Option<f64>) -> Wear {
        Wear {
            coefficient,
            max_growth: max_growth.unwrap_or(f64::INFINITY),
            work: 0.0,
            growth: 0.0,
        }
    }

    /// Takes the step's cumulative contact work on the modes `contact_work` (J) and boundary
    /// energy `boundary` (J); returns the new growth (m) if it changed.
    #[inline]
    pub fn update(&mut self, contact_work: f64, boundary: f64) -> Option<f64> {
        let d = -(contact_work + boundary);
        if !(d > self.work) {
            return None;
        }
        self.work = d;
        let growth = (self.coefficient * d).min(self.max_growth);
        if growth > self.growth {
            self.growth = growth;
            Some(growth)
        } else {
            None
        }
    }

    /// Restores `W` (J) and the growth (m) of an earlier [`Wear::work`] and [`Wear::growth`];
    /// `false` (nothing changed) when either is negative or not finite.
    pub fn set_state(&mut self, work: f64, growth: f64) -> bool {
        let fits = work.is_finite() && growth.is_finite() && work >= 0.0 && growth >= 0.0;
        if fits {
            self.work = work;
            self.growth = growth;
        }
        fits
    }

    /// `W`, J.
    pub fn work(&self) -> f64 {
        self.work
    }

    /// Clearance growth so far, m.
    pub fn growth(&self) -> f64 {
        self.growth
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(got: Option<f64>, expected: f64) {
        let g = got.unwrap_or_else(|| panic!("no growth, expected {expected:e}"));
        assert!(
            (g - expected).abs() <= 1e-12 * expected,
            "{g:e} vs {expected:e}"
        );
    }

    #[test]
    fn growth_follows_the_running_maximum_and_stops_at_the_cap() {
        let mut w = Wear::new(1e-3, Some(2.5e-6));
        // Open: no contact work, no boundary energy.
        assert_eq!(w.update(0.0, 0.0), None);
        // A contact takes 1 mJ and holds 0.4 mJ elastically ...
        close(w.update(-1e-3, 4e-4), 6e-7);
        close(w.update(-1.4e-3, 4e-4), 1e-6);
        // ... a ripple back: the clearance does not shrink ...
        assert_eq!(w.update(-1.3e-3, 4e-4), None);
        assert!((w.growth() - 1e-6).abs() < 1e-18);
        // ... open again: the boundary energy went back to the modes, the rest was lost.
        close(w.update(-1.05e-3, 0.0), 1.05e-6);
        assert_eq!(w.update(-1.05e-3, 0.0), None);
        // Far beyond the cap.
        assert_eq!(w.update(-1.0, 0.0), Some(2.5e-6));
        assert_eq!(w.update(-2.0, 0.0), None);
        assert_eq!(w.growth(), 2.5e-6);
        assert_eq!(w.work(), 2.0);
        // Non-finite energy (a failing truth) changes nothing.
        assert_eq!(w.update(f64::NAN, 0.0), None);
        assert_eq!(w.work(), 2.0);
    }

    #[test]
    fn zero_coefficient_never_grows() {
        let mut w = Wear::new(0.0, None);
        assert_eq!(w.update(-5.0, 1.0), None);
        assert_eq!(w.growth(), 0.0);
        assert_eq!(w.work(), 4.0);
    }
}
