//! Inertias as ROS and Gazebo take them: floating-point noise tolerated, mass on fixed-joint
//! links lumped into the moving ancestor (parallel-axis theorem, as Gazebo and MuJoCo's
//! `fusestatic` do), real violations repaired by the smallest change of principal moments.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Relative size (to the largest principal moment) below which a negative moment or a
/// triangle-inequality deficit is floating-point noise, not a modelling error.
pub(crate) const NOISE_REL: f64 = 1e-9;

/// A rigid body's mass properties in some frame: mass (kg), centre of mass (m) and inertia
/// about the centre of mass (kg·m²), both in that frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MassProps {
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
}

impl MassProps {
    /// The union of `self` and `other` (both in the same frame): parallel-axis theorem.
    pub fn lump(&self, other: &MassProps) -> MassProps {
        let mass = self.mass + other.mass;
        if mass <= 0.0 {
            return MassProps { mass: 0.0, com: self.com, inertia: self.inertia + other.inertia };
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shift = |p: &MassProps| {
            let d = p.com - com;
            p.inertia + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * p.mass
        };
        MassProps { mass, com, inertia: shift(self) + shift(other) }
    }
}

/// `[ixx, ixy, ixz, iyy, iyz, izz]` as a symmetric matrix.
pub(crate) fn tensor(v: [f64; 6]) -> Matrix3<f64> {
    let [ixx, ixy, ixz, iyy, iyz, izz] = v;
    Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz)
}

/// Principal moments, ascending.
fn moments(t: &Matrix3<f64>) -> [f64; 3] {
    let mut p: Vec<f64> = SymmetricEigen::new(*t).eigenvalues.iter().copied().collect();
    p.sort_by(f64::total_cmp);
    [p[0], p[1], p[2]]
}

/// Whether an inertia tensor is one a rigid body can have, up to floating-point noise:
/// positive semi-definite and its principal moments satisfy the triangle inequality. The
/// message says why not and names the moments.
pub fn check(t: &Matrix3<f64>) -> std::result::Result<(), String> {
    let p = moments(t);
    let tol = NOISE_REL * p[2].abs().max(f64::MIN_POSITIVE);
    if p[0] < -tol {
        return Err(format!(
            "inertia is not positive definite (principal moments {:.6e}, {:.6e}, {:.6e} kg·m²); \
             fix ixx..izz (check units and signs of the products of inertia)",
            p[0], p[1], p[2]
        ));
    }
    if p[0] + p[1] < p[2] - tol {
        return Err(format!(
            "principal moments {:.6e}, {:.6e}, {:.6e} kg·m² violate the triangle inequality \
             ({:.6e} + {:.6e} < {:.6e}): no rigid body has this inertia; fix ixx..izz",
            p[0], p[1], p[2], p[0], p[1], p[2]
        ));
    }
    Ok(())
}

/// What [`admissible`] did to a tensor.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Fix {
    /// Used as is.
    None,
    /// Moments at zero or within noise of a violation, moved to the nearest tensor MuJoCo
    /// accepts; not a modelling error.
    Noise(String),
    /// A real violation, repaired by the smallest change of principal moments.
    Repaired(String),
}

/// The tensor MuJoCo will accept closest to `t`: principal moments raised to a floor
/// (positive definite) and projected onto `a + b ≥ c`, principal axes kept. `floor_abs` is the
/// smallest moment allowed (kg·m²), for bodies whose tensor is all zeros.
pub(crate) fn admissible(t: &Matrix3<f64>, floor_abs: f64) -> (Matrix3<f64>, Fix) {
    let violation = check(t).err();
    let eig = SymmetricEigen::new(*t);
    let before: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| before[a].total_cmp(&before[b]));
    let sorted = [before[order[0]], before[order[1]], before[order[2]]];
    let mut p = sorted;
    let floor = (p[2].abs() * 1e-6).max(floor_abs);
    for x in &mut p {
        *x = x.max(floor);
    }
    // MuJoCo checks a + b ≥ c without tolerance, on moments it recomputes: stay a hair inside.
    let margin = 1e-9;
    if p[0] + p[1] < p[2] * (1.0 + margin) {
        // Orthogonal projection onto the plane a + b = c (normal (1, 1, −1)).
        let d = (p[2] * (1.0 + margin) - p[0] - p[1]) / 3.0;
        p[0] += d;
        p[1] += d;
        p[2] -= d;
    }
    if p == sorted {
        return (*t, Fix::None);
    }
    let mut newp = before.clone();
    for (k, &i) in order.iter().enumerate() {
        newp[i] = p[k];
    }
    let q = eig.eigenvectors;
    let r = q * Matrix3::from_diagonal(&Vector3::new(newp[0], newp[1], newp[2])) * q.transpose();
    let r = (r + r.transpose()) * 0.5;
    let how = format!(
        "principal moments {:.6e}, {:.6e}, {:.6e} → {:.6e}, {:.6e}, {:.6e} kg·m²",
        sorted[0], sorted[1], sorted[2], p[0], p[1], p[2]
    );
    match violation {
        Some(problem) => (
            r,
            Fix::Repaired(format!(
                "{problem}; repaired: {how} (smallest change that makes the tensor positive definite and satisfy the triangle inequality; principal axes kept)"
            )),
        ),
        None => (r, Fix::Noise(how)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repair_is_the_smallest_change() {
        let bad = tensor([1.0, 0.0, 0.0, 1.0, 0.0, 3.0]);
        assert!(check(&bad).is_err());
        let (fixed, fix) = admissible(&bad, 1e-12);
        assert!(matches!(fix, Fix::Repaired(ref m) if m.contains("triangle")), "{fix:?}");
        assert!(check(&fixed).is_ok(), "{fixed:?}");
        // Projection onto a + b = c: each moment moves by (3 − 2)/3.
        assert!((fixed[(0, 0)] - (1.0 + 1.0 / 3.0)).abs() < 1e-6, "{fixed:?}");
        assert!((fixed[(2, 2)] - (3.0 - 1.0 / 3.0)).abs() < 1e-6, "{fixed:?}");
        let not_pd = tensor([1.0, 2.0, 0.0, 1.0, 0.0, 1.0]);
        let (fixed, fix) = admissible(&not_pd, 1e-12);
        assert!(matches!(fix, Fix::Repaired(_)));
        assert!(check(&fixed).is_ok(), "{fixed:?}");
    }

    #[test]
    fn noise_is_not_a_violation() {
        // Diagonal with zeros and a rounding-level negative moment (go1, b1, anymal…).
        let t = tensor([1e-3, 0.0, 0.0, 1e-3, 1e-19, -2.220446e-16]);
        assert!(check(&t).is_ok());
        let (fixed, fix) = admissible(&t, 1e-12);
        assert!(matches!(fix, Fix::Noise(_)), "{fix:?}");
        let p = moments(&fixed);
        assert!(p[0] > 0.0 && p[0] + p[1] >= p[2]);
        // A valid tensor is untouched.
        let ok = tensor([0.02, 0.001, 0.002, 0.03, 0.003, 0.04]);
        assert_eq!(admissible(&ok, 1e-12), (ok, Fix::None));
    }

    #[test]
    fn lumping_is_the_parallel_axis_theorem() {
        let a = MassProps { mass: 2.0, com: Vector3::new(0.0, 0.0, 0.0), inertia: Matrix3::identity() * 0.1 };
        let b = MassProps { mass: 1.0, com: Vector3::new(0.3, 0.0, 0.0), inertia: Matrix3::zeros() };
        let c = a.lump(&b);
        assert_eq!(c.mass, 3.0);
        assert!((c.com.x - 0.1).abs() < 1e-15);
        // About x: no change; about y and z: 0.1 + 2·0.1² + 1·0.2².
        assert!((c.inertia[(0, 0)] - 0.1).abs() < 1e-15);
        assert!((c.inertia[(1, 1)] - (0.1 + 0.02 + 0.04)).abs() < 1e-15);
        assert!((c.inertia[(2, 2)] - (0.1 + 0.02 + 0.04)).abs() < 1e-15);
    }
}
