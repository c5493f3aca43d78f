//! Exact ray–primitive intersections (plane, sphere, capsule, ellipsoid, cylinder, box) in
//! safe Rust, with the conventions of MuJoCo's `mju_rayGeom`: a plane is seen from its front
//! (+z) side only and within its half-sizes when they are positive; a ray starting inside a
//! solid hits it where it leaves; grazing rays (discriminant below `mjMINVAL`) miss. The ray
//! caster ([`super::RayScene`]) inlines these in its hot loop instead of calling MuJoCo once per
//! ray and geom, and maps the shared ray origin into each geom's frame once per cast.

/// MuJoCo's `mjMINVAL`: smaller denominators and discriminants count as zero.
const MINVAL: f64 = mujoco_sys::mjMINVAL;

/// A primitive in its own frame (centred at the origin, axes along its frame's axes), sizes
/// as MuJoCo's `geom_size` gives them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Shape {
    /// The plane z = 0 seen from +z, within `|x| ≤ half[0]`, `|y| ≤ half[1]` where positive.
    Plane { half: [f64; 2] },
    /// Radius.
    Sphere { radius: f64 },
    /// Radius and half-length of the segment along z.
    Capsule { radius: f64, half_len: f64 },
    /// 1 / semi-axis² along x, y, z.
    Ellipsoid { inv_sq: [f64; 3] },
    /// Radius and half-height along z.
    Cylinder { radius: f64, half_len: f64 },
    /// Half-sizes along x, y, z.
    Box { half: [f64; 3] },
}

impl Shape {
    /// The shape of MuJoCo geom type `ty` with sizes `size`, `None` for a type that is not one
    /// of these primitives.
    pub(crate) fn of(ty: u32, size: [f64; 3]) -> Option<Shape> {
        use mujoco_sys as sys;
        Some(match ty {
            sys::mjtGeom_mjGEOM_PLANE => Shape::Plane { half: [size[0], size[1]] },
            sys::mjtGeom_mjGEOM_SPHERE => Shape::Sphere { radius: size[0] },
            sys::mjtGeom_mjGEOM_CAPSULE => Shape::Capsule { radius: size[0], half_len: size[1] },
            sys::mjtGeom_mjGEOM_ELLIPSOID => Shape::Ellipsoid { inv_sq: size.map(|s| 1.0 / (s * s)) },
            sys::mjtGeom_mjGEOM_CYLINDER => Shape::Cylinder { radius: size[0], half_len: size[1] },
            sys::mjtGeom_mjGEOM_BOX => Shape::Box { half: size },
            _ => return None,
        })
    }

    /// Distance along `dir` (any length: the answer is in multiples of it) from `origin`, both
    /// in the shape's frame, to where the ray first meets the shape's surface, or a negative
    /// number when it does not.
    #[inline(always)]
    pub(crate) fn hit(&self, origin: [f64; 3], dir: [f64; 3]) -> f64 {
        let (p, v) = (origin, dir);
        match *self {
            Shape::Plane { half } => {
                // Front face only, as MuJoCo renders it.
                if v[2] > -MINVAL {
                    return -1.0;
                }
                let x = -p[2] / v[2];
                if x < 0.0 {
                    return -1.0;
                }
                let inside = |i: usize| half[i] <= 0.0 || (p[i] + x * v[i]).abs() <= half[i];
                if inside(0) && inside(1) { x } else { -1.0 }
            }
            Shape::Sphere { radius } => nearest_root(dot(v, v), dot(v, p), dot(p, p) - radius * radius),
            Shape::Ellipsoid { inv_sq: s } => nearest_root(
                s[0] * v[0] * v[0] + s[1] * v[1] * v[1] + s[2] * v[2] * v[2],
                s[0] * v[0] * p[0] + s[1] * v[1] * p[1] + s[2] * v[2] * p[2],
                s[0] * p[0] * p[0] + s[1] * p[1] * p[1] + s[2] * p[2] * p[2] - 1.0,
            ),
            Shape::Capsule { radius, half_len } => {
                let r2 = radius * radius;
                let mut best = -1.0;
                let mut take = |x: f64| {
                    if x >= 0.0 && (best < 0.0 || x < best) {
                        best = x;
                    }
                };
                // The round side, between the caps' centres.
                let side =
                    nearest_root(v[0] * v[0] + v[1] * v[1], v[0] * p[0] + v[1] * p[1], p[0] * p[0] + p[1] * p[1] - r2);
                if side >= 0.0 && (p[2] + side * v[2]).abs() <= half_len {
                    take(side);
                }
                // The caps: each sphere's roots on its own half.
                let a = dot(v, v);
                for sign in [1.0, -1.0] {
                    let q = [p[0], p[1], p[2] - sign * half_len];
                    if let Some((x0, x1)) = roots(a, dot(v, q), dot(q, q) - r2) {
                        for x in [x0, x1] {
                            if sign * (p[2] + x * v[2]) >= half_len {
                                take(x);
                            }
                        }
                    }
                }
                best
            }
            Shape::Cylinder { radius, half_len } => {
                let r2 = radius * radius;
                let mut best = -1.0;
                // The flat ends.
                if v[2].abs() > MINVAL {
                    for sign in [-1.0, 1.0] {
                        let x = (sign * half_len - p[2]) / v[2];
                        if x >= 0.0 {
                            let (a, b) = (p[0] + x * v[0], p[1] + x * v[1]);
                            if a * a + b * b <= r2 && (best < 0.0 || x < best) {
                                best = x;
                            }
                        }
                    }
                }
                let side =
                    nearest_root(v[0] * v[0] + v[1] * v[1], v[0] * p[0] + v[1] * p[1], p[0] * p[0] + p[1] * p[1] - r2);
                if side >= 0.0 && (p[2] + side * v[2]).abs() <= half_len && (best < 0.0 || side < best) {
                    best = side;
                }
                best
            }
            Shape::Box { half } => {
                // Slabs: the ray is inside the box between the largest entry and the smallest
                // exit over the three axes (the faces' rectangles, without testing each).
                let (mut enter, mut leave) = (f64::NEG_INFINITY, f64::INFINITY);
                if !slab(p[0], v[0], half[0], &mut enter, &mut leave)
                    || !slab(p[1], v[1], half[1], &mut enter, &mut leave)
                    || !slab(p[2], v[2], half[2], &mut enter, &mut leave)
                    || enter > leave
                    || leave < 0.0
                {
                    -1.0
                } else if enter >= 0.0 {
                    enter
                } else {
                    leave
                }
            }
        }
    }
}

/// Narrows `[enter, leave]` to where the ray `p + x v` (one coordinate) is within
/// `[−half, half]`; false when it never is.
#[inline(always)]
fn slab(p: f64, v: f64, half: f64, enter: &mut f64, leave: &mut f64) -> bool {
    if v.abs() <= MINVAL {
        // Parallel to the slab: inside it or never.
        return p.abs() <= half;
    }
    let inv = 1.0 / v;
    let (a, b) = ((-half - p) * inv, (half - p) * inv);
    let (near, far) = if a < b { (a, b) } else { (b, a) };
    *enter = enter.max(near);
    *leave = leave.min(far);
    true
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Both roots of `a x² + 2 b x + c = 0`, smaller first, `None` when the discriminant is below
/// `MINVAL` (no or a grazing intersection).
#[inline]
fn roots(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let det = b * b - a * c;
    if det < MINVAL {
        return None;
    }
    let det = det.sqrt();
    Some(((-b - det) / a, (-b + det) / a))
}

/// The smallest non-negative root of `a x² + 2 b x + c = 0`, or −1.
#[inline]
fn nearest_root(a: f64, b: f64, c: f64) -> f64 {
    match roots(a, b, c) {
        Some((x0, _)) if x0 >= 0.0 => x0,
        Some((_, x1)) if x1 >= 0.0 => x1,
        _ => -1.0,
    }
}
