//! The admissible set of one contact pair and the projection onto it.
//!
//! For a closed pair k the contact force `lambda_k = (lambda_n, lambda_t1, lambda_t2)` must lie
//! in `C_k = R+ x Disk(mu lambda_n)` (Signorini in the normal direction, Coulomb's disk in the
//! tangent plane, DESIGN.md "The model" step 4). The law is `-gamma_k in N_C(lambda_k)` with
//! the gap velocity `gamma_k`: an open pair (`lambda_n = 0`) separates (`gamma_n >= 0`) with any
//! tangential velocity, a sticking pair has `gamma = 0`, a slipping pair has `gamma_n = 0`,
//! `|lambda_t| = mu lambda_n` and `gamma_t` antiparallel to `lambda_t`.
//!
//! The augmented-Lagrangian fixed point uses [`project_pair`] on a trial point
//! `lambda - eps .* gamma`; its fixed points are exactly the solutions of the law as long as
//! the two tangential components share one `eps`.

/// Contact state of one pair after a solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PairState {
    /// No normal force (predicted open, or separating in the solution).
    Open,
    /// Normal force, tangential force strictly inside the friction disk: no relative motion.
    Stick,
    /// Normal force, tangential force on the rim of the friction disk: sliding.
    Slip,
}

/// Projects a trial force `x = (x_n, x_t1, x_t2)` (N) onto the admissible set of a pair with
/// friction coefficient `mu` (-), the way the augmented-Lagrangian iteration needs it: the normal
/// part onto `R+`, then the tangential part onto the disk of radius `mu` times the *projected*
/// normal force. Returns the projected force and which part of the set it landed on.
///
/// This is not the Euclidean projection onto the Coulomb cone: the disk radius follows the new
/// normal force, which is what makes the fixed points satisfy Coulomb's law with the
/// velocity-level Signorini condition (and coincide with Siconos' fc3d solutions).
#[inline(always)]
pub fn project_pair(mu: f64, x: [f64; 3]) -> ([f64; 3], PairState) {
    // Written as a comparison (not f64::max) so that a NaN trial point stays NaN and is
    // caught by the caller's finiteness check instead of being clamped to zero.
    let ln = if x[0] > 0.0 || x[0].is_nan() {
        x[0]
    } else {
        0.0
    };
    let radius = mu * ln;
    let t2 = x[1] * x[1] + x[2] * x[2];
    if t2 <= radius * radius {
        let state = if ln > 0.0 {
            PairState::Stick
        } else {
            PairState::Open
        };
        ([ln, x[1], x[2]], state)
    } else if radius > 0.0 {
        let s = radius / t2.sqrt();
        ([ln, s * x[1], s * x[2]], PairState::Slip)
    } else {
        // Zero normal force (or mu = 0): the disk is a point (or the tangent plane is free of
        // force for a frictionless pair with positive normal force).
        let state = if ln > 0.0 {
            PairState::Slip
        } else {
            PairState::Open
        };
        ([ln, 0.0, 0.0], state)
    }
}

/// Whether `lambda` (N) lies in the admissible set of a pair with friction coefficient `mu`,
/// up to an absolute tolerance `tol` (N).
pub fn is_admissible(mu: f64, lambda: [f64; 3], tol: f64) -> bool {
    lambda[0] >= -tol && lambda[1].hypot(lambda[2]) <= mu * lambda[0].max(0.0) + tol
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_normal_trial_gives_zero_force() {
        let (p, s) = project_pair(0.4, [-2.0, 1.0, -3.0]);
        assert_eq!(p, [0.0, 0.0, 0.0]);
        assert_eq!(s, PairState::Open);
    }

    #[test]
    fn point_inside_the_disk_is_unchanged() {
        let x = [10.0, 1.0, -2.0];
        let (p, s) = project_pair(0.4, x);
        assert_eq!(p, x);
        assert_eq!(s, PairState::Stick);
    }

    #[test]
    fn point_outside_the_disk_lands_on_the_rim_in_the_same_direction() {
        let x = [10.0, 30.0, -40.0];
        let (p, s) = project_pair(0.4, x);
        assert_eq!(s, PairState::Slip);
        assert_eq!(p[0], 10.0);
        assert!((p[1].hypot(p[2]) - 4.0).abs() < 1e-14);
        // Same direction: the cross product with the trial vanishes, the dot product is positive.
        assert!((p[1] * x[2] - p[2] * x[1]).abs() < 1e-12);
        assert!(p[1] * x[1] + p[2] * x[2] > 0.0);
    }

    #[test]
    fn projection_is_idempotent_and_admissible() {
        let trials = [
            [1.0, 0.0, 0.0],
            [1.0, 5.0, 5.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [3.0, -0.1, 0.2],
            [1e-300, 1.0, 1.0],
        ];
        for mu in [0.0, 0.4, 1.5] {
            for x in trials {
                let (p, _) = project_pair(mu, x);
                assert!(is_admissible(mu, p, 1e-14), "{p:?} for mu {mu}");
                let (q, _) = project_pair(mu, p);
                for i in 0..3 {
                    assert!(
                        (q[i] - p[i]).abs() <= 1e-15 * p[i].abs().max(1.0),
                        "{p:?} {q:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn frictionless_pair_has_no_tangential_force() {
        let (p, s) = project_pair(0.0, [2.0, 1.0, 1.0]);
        assert_eq!(p, [2.0, 0.0, 0.0]);
        assert_eq!(s, PairState::Slip);
    }

    #[test]
    fn nan_trial_is_not_hidden() {
        let (p, _) = project_pair(0.4, [f64::NAN, 0.0, 0.0]);
        assert!(p[0].is_nan());
    }
}
