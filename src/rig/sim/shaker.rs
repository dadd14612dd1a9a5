//! The electrodynamic shaker: voltage amplifier with an output limit, coil (R, L, Bl) and the
//! moving mass on its suspension, stepped on the truth model's time grid; and the analytic
//! frequency response of the same system with the beams' modes attached (the reference for
//! tests and for a feed-forward drive estimate).
//!
//! Equations (base displacement `x_b`, velocity `v_b`, coil current `i`, amplifier output `u`):
//! `u = clip(G d, +-u_max)`, `L di/dt = u - R i - Bl v_b`,
//! `F = Bl i - k x_b - c v_b`, and the base equation with the beams' modal reaction
//! `M a_b + sum_i beta_i eta_i'' = F` (solved together with the modes in `truth.rs`).

/// The shaker's state and step coefficients for a fixed truth step `dt`.
///
/// Time levels as in the leapfrog of the modes: `x_b^j`, `i^j` at `t^j`; `v_b^{j-1/2}` at the
/// half step before. [`Shaker::advance`] moves them to `j + 1` given the base acceleration of
/// the step.
#[derive(Clone, Debug, PartialEq)]
pub struct Shaker {
    dt: f64,
    stiffness: f64,
    damping: f64,
    force_constant: f64,
    resistance: f64,
    /// `exp(-R dt / L)`: the exact decay of the RL circuit over one step.
    decay: f64,
    gain: f64,
    limit_v: f64,
    x: f64,
    v_half: f64,
    current: f64,
}

impl Shaker {
    /// A shaker at rest for a valid spec and a truth step `dt` (s).
    pub fn new(spec: &super::ShakerSpec, dt: f64) -> Shaker {
        Shaker {
            dt,
            stiffness: spec.suspension_stiffness,
            damping: spec.suspension_damping(),
            force_constant: spec.force_constant,
            resistance: spec.coil_resistance,
            decay: (-spec.coil_resistance * dt / spec.coil_inductance).exp(),
            gain: spec.amplifier_gain,
            limit_v: spec.amplifier_limit_v,
            x: 0.0,
            v_half: 0.0,
            current: 0.0,
        }
    }

    /// The amplifier output for input `drive_v` (V): `(u, clipped)`.
    #[inline]
    pub fn amplifier(&self, drive_v: f64) -> (f64, bool) {
        let u = self.gain * drive_v;
        if u > self.limit_v {
            (self.limit_v, true)
        } else if u < -self.limit_v {
            (-self.limit_v, true)
        } else {
            (u, false)
        }
    }

    /// The amplifier's output limit, V.
    pub fn limit_v(&self) -> f64 {
        self.limit_v
    }

    /// Lowers (or raises) the amplifier's output limit, V (>= 0).
    pub fn set_limit_v(&mut self, limit_v: f64) {
        self.limit_v = limit_v;
    }

    /// The force on the moving mass at the start of the step without the velocity-dependent
    /// suspension damping, `Bl i^j - k x_b^j`, N, and the damping coefficient `c` (N s/m). The
    /// damping acts with the velocity averaged over the half steps,
    /// `c (v^{j-1/2} + v^{j+1/2}) / 2 = c v^{j-1/2} + c dt a_b / 2`, as the modal damping does.
    #[inline]
    pub fn elastic_and_coil_force(&self) -> f64 {
        self.force_constant * self.current - self.stiffness * self.x
    }

    /// Suspension damping coefficient c, N s/m.
    pub fn damping(&self) -> f64 {
        self.damping
    }

    /// Advances one step with base acceleration `a_b` (m/s^2, at `t^j`) and amplifier output
    /// `u` (V, held over the step): leapfrog for the base, exact exponential for the coil with
    /// the back-EMF of the step's (half-step) velocity.
    #[inline]
    pub fn advance(&mut self, a_b: f64, u: f64) {
        self.v_half += self.dt * a_b;
        self.x += self.dt * self.v_half;
        // NOTE: L di/dt = u - R i - Bl v with u and v constant over the step has the exact
        // solution i(t + dt) = i_inf + (i(t) - i_inf) exp(-R dt / L), i_inf = (u - Bl v) / R:
        // unconditionally stable whatever L / R is against dt.
        let i_inf = (u - self.force_constant * self.v_half) / self.resistance;
        self.current = i_inf + (self.current - i_inf) * self.decay;
    }

    /// Base displacement `x_b^j`, m.
    pub fn displacement(&self) -> f64 {
        self.x
    }

    /// Base velocity of the last step `v_b^{j-1/2}`, m/s.
    pub fn velocity_half(&self) -> f64 {
        self.v_half
    }

    /// Coil current `i^j`, A.
    pub fn current(&self) -> f64 {
        self.current
    }

    /// Makes the state non-finite (tests of the failure path).
    #[cfg(test)]
    pub(crate) fn poison(&mut self) {
        self.x = f64::NAN;
    }

    /// Whether the state is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.v_half.is_finite() && self.current.is_finite()
    }
}

/// A complex number (re, im) for the analytic response.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Complex {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Complex {
        Complex { re, im }
    }

    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }

    fn mul(self, o: Complex) -> Complex {
        Complex::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }

    fn div(self, o: Complex) -> Complex {
        let d = o.re * o.re + o.im * o.im;
        Complex::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }

    /// Magnitude.
    pub fn abs(self) -> f64 {
        self.re.hypot(self.im)
    }

    /// Argument, rad.
    pub fn arg(self) -> f64 {
        self.im.atan2(self.re)
    }
}

/// One beam mode as seen by the base: circular frequency (rad/s), damping ratio and modal
/// participation `beta` (kg^0.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseMode {
    /// Natural circular frequency, rad/s.
    pub omega: f64,
    /// Modal damping ratio, -.
    pub zeta: f64,
    /// Participation of the base acceleration, kg^0.5.
    pub beta: f64,
}

/// Steady-state base acceleration per volt of amplifier input at circular frequency `omega`
/// (rad/s), (m/s^2)/V, of the linear system (no contact, no amplifier clipping): the shaker of
/// `spec` carrying beams with modes `modes`.
///
/// With `e^{i w t}`: the beams' apparent mass `M_app = M + sum_i beta_i^2 w^2 / (w_i^2 - w^2 +
/// 2 i zeta_i w_i w)` (-> M at w = 0, -> M - sum beta_i^2 far above the modes), the coil
/// `U = (R + i w L) I + Bl a / (i w)` and `M_app a = Bl I + (k + i w c) a / w^2` give
/// `a / U = Bl / ((R + i w L) (M_app - (k + i w c) / w^2) + Bl^2 / (i w))`, `U = G d`.
pub fn base_acceleration_frf(spec: &super::ShakerSpec, modes: &[BaseMode], omega: f64) -> Complex {
    let w = omega;
    let mut m_app = Complex::new(spec.moving_mass, 0.0);
    for md in modes {
        let den = Complex::new(md.omega * md.omega - w * w, 2.0 * md.zeta * md.omega * w);
        m_app = m_app.add(Complex::new(md.beta * md.beta * w * w, 0.0).div(den));
    }
    let suspension = Complex::new(
        -spec.suspension_stiffness / (w * w),
        -spec.suspension_damping() / w,
    );
    let z_e = Complex::new(spec.coil_resistance, w * spec.coil_inductance);
    let bl = spec.force_constant;
    // Bl^2 / (i w) = -i Bl^2 / w.
    let back_emf = Complex::new(0.0, -bl * bl / w);
    let den = z_e.mul(m_app.add(suspension)).add(back_emf);
    Complex::new(bl * spec.amplifier_gain, 0.0).div(den)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::sim::ShakerSpec;

    #[test]
    fn amplifier_clips_symmetrically() {
        let s = Shaker::new(&ShakerSpec::default(), 1e-5);
        assert_eq!(s.amplifier(1.0), (20.0, false));
        assert_eq!(s.amplifier(4.0), (60.0, true));
        assert_eq!(s.amplifier(-4.0), (-60.0, true));
    }

    #[test]
    fn coil_reaches_ohms_law_at_rest() {
        let spec = ShakerSpec {
            suspension_stiffness: 1e12,
            ..ShakerSpec::default()
        };
        let mut s = Shaker::new(&spec, 1e-5);
        for _ in 0..10_000 {
            s.advance(0.0, 8.0);
        }
        assert!((s.current() - 10.0).abs() < 1e-9, "{}", s.current());
    }

    #[test]
    fn frf_limits() {
        let spec = ShakerSpec::default();
        // Far above the suspension and the electrical corner the acceleration per volt tends
        // to Bl G / (i w L M): check the magnitude at a high frequency within 2 %.
        let w = 2.0 * std::f64::consts::PI * 5000.0;
        let a = base_acceleration_frf(&spec, &[], w).abs();
        let approx = spec.force_constant * spec.amplifier_gain
            / (w * spec.coil_inductance * spec.moving_mass);
        assert!((a / approx - 1.0).abs() < 0.02, "{a} vs {approx}");
        // A mode far above the band adds nothing; at its resonance it lowers the response.
        let mode = BaseMode {
            omega: 2.0 * std::f64::consts::PI * 55.0,
            zeta: 0.002,
            beta: 0.45,
        };
        let w1 = mode.omega;
        let with = base_acceleration_frf(&spec, &[mode], w1).abs();
        let without = base_acceleration_frf(&spec, &[], w1).abs();
        assert!(with < 0.9 * without, "{with} vs {without}");
    }
}
