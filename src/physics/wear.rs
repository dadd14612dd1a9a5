//! Clearance growth from wear: `clearance = nominal + min(coefficient P, max_growth)`, `P` the
//! accumulated normal contact impulse since the rig started (N s): the sum over steps and
//! closed pairs of the normal impulse `dt lambda_n`, i.e. the time integral of the total normal
//! contact force, the momentum the beams have exchanged through the contact.
//!
//! `P` comes from the contact solve each step already makes: the step's integrated normal force
//! `sum_k lambda_n,k` (N) times the step. It only grows, so the clearance never shrinks.
//!
// NOTE (why the impulse and not the dissipated work): the first version drove wear with the work
// the contact dissipated, `-(W_c + E_b)` (contact work on the modes plus the energy held in the
// boundary's residual flexibility). With the massless contact boundary that work is mostly the
// end-of-step impact law's numerical loss (a closing velocity removed each closed step): it
// falls about as dt^0.55 and had not converged at any step tried (twin at 19.5 us 2.6-2.7x the
// same model at 3.3 us; the simulated rig's truth at 7.5 us about 0.53x the twin's), so a
// coefficient in m/J was a property of the integrator's step and a diagnosis could not find
// the rig's value. The normal impulse is momentum exchanged between the beams: measured on the
// same session (the wear proofs' plan) the twin's at 19.5 us is 0.94-0.95x the same model's at
// 3.3 us and 0.98-0.99x the truth's at the same clearance (BENCHMARKS.md, "Wear driven by the
// normal contact impulse").

/// The wear state (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Wear {
    coefficient: f64,
    max_growth: f64,
    /// `P`: the accumulated normal contact impulse, N s.
    impulse: f64,
    /// Current clearance growth, m.
    growth: f64,
}

impl Wear {
    /// Wear with `coefficient` (m/(N s), >= 0) and an optional cap `max_growth` (m, > 0).
    pub fn new(coefficient: f64, max_growth: Option<f64>) -> Wear {
        Wear {
            coefficient,
            max_growth: max_growth.unwrap_or(f64::INFINITY),
            impulse: 0.0,
            growth: 0.0,
        }
    }

    /// Takes one step's normal contact impulse `impulse` (N s, the step times the sum of the
    /// closed pairs' normal forces); returns the new growth (m) if it changed. A step without
    /// force (or a non-finite or negative impulse, from a failing solve) changes nothing.
    #[inline]
    pub fn update(&mut self, impulse: f64) -> Option<f64> {
        if !impulse.is_finite() || impulse <= 0.0 {
            return None;
        }
        self.impulse += impulse;
        let growth = (self.coefficient * self.impulse).min(self.max_growth);
        if growth > self.growth {
            self.growth = growth;
            Some(growth)
        } else {
            None
        }
    }

    /// Restores `P` (N s) and the growth (m) of an earlier [`Wear::impulse`] and
    /// [`Wear::growth`]; `false` (nothing changed) when either is negative or not finite.
    pub fn set_state(&mut self, impulse: f64, growth: f64) -> bool {
        let fits = impulse.is_finite() && growth.is_finite() && impulse >= 0.0 && growth >= 0.0;
        if fits {
            self.impulse = impulse;
            self.growth = growth;
        }
        fits
    }

    /// `P`, N s.
    pub fn impulse(&self) -> f64 {
        self.impulse
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
    fn growth_follows_the_accumulated_impulse_and_stops_at_the_cap() {
        let mut w = Wear::new(1e-4, Some(2.5e-6));
        // Open: no force, no growth.
        assert_eq!(w.update(0.0), None);
        // Two closed steps of 4e-3 and 6e-3 N s ...
        close(w.update(4e-3), 4e-7);
        close(w.update(6e-3), 1e-6);
        assert!((w.impulse() - 1e-2).abs() < 1e-15);
        // ... open again: nothing moves.
        assert_eq!(w.update(0.0), None);
        assert!((w.growth() - 1e-6).abs() < 1e-18);
        // Far beyond the cap: the impulse still counts, the growth stops.
        assert_eq!(w.update(1.0), Some(2.5e-6));
        assert_eq!(w.update(2.0), None);
        assert_eq!(w.growth(), 2.5e-6);
        assert!((w.impulse() - 3.01).abs() < 1e-12);
        // Non-finite or negative impulses (a failing truth) change nothing.
        assert_eq!(w.update(f64::NAN), None);
        assert_eq!(w.update(f64::INFINITY), None);
        assert_eq!(w.update(-1.0), None);
        assert!((w.impulse() - 3.01).abs() < 1e-12);
    }

    #[test]
    fn zero_coefficient_never_grows_but_counts() {
        let mut w = Wear::new(0.0, None);
        assert_eq!(w.update(5.0), None);
        assert_eq!(w.growth(), 0.0);
        assert_eq!(w.impulse(), 5.0);
    }

    #[test]
    fn a_restored_state_continues_where_it_was_captured() {
        let mut a = Wear::new(2e-4, None);
        a.update(3e-3);
        let mut b = Wear::new(2e-4, None);
        assert!(b.set_state(a.impulse(), a.growth()));
        assert_eq!(a.update(1e-3), b.update(1e-3));
        assert_eq!(a, b);
        assert!(!b.set_state(-1.0, 0.0));
        assert!(!b.set_state(1.0, f64::NAN));
        assert_eq!(a, b);
    }
}
