//! Finding a cup on a table from a point cloud alone (no ground truth): RANSAC for the table
//! plane (seeded), the points above it clustered, the cup's axis and radius from a circle fit
//! to its side wall.
//!
//! 1. Table: among horizontal planes (normal within [`CupDetectOptions::max_tilt_rad`] of
//!    world z) holding at least [`CupDetectOptions::min_plane_fraction`] of the points, the
//!    highest (a floor in view is lower); its inliers refit by least squares.
//! 2. Objects: the points between [`CupDetectOptions::min_height_m`] and
//!    [`CupDetectOptions::max_height_m`] above the plane and over the table's extent,
//!    clustered by distance ([`CupDetectOptions::cluster_gap_m`]); the biggest cluster is the
//!    cup.
//! 3. Cup: its height is the cluster's highest point above the plane; the points of its side
//!    wall (below the rim band) projected on the plane give centre and radius by a geometric
//!    circle fit (Gauss–Newton from the algebraic fit), which works on the visible half arc.

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector2, Vector3};
use rand::{Rng, SeedableRng};

/// What [`detect_cup`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CupEstimate {
    /// The cup's centre: on its axis, half its height above the table, world frame, metres.
    pub centre_world: Point3<f64>,
    /// Outer radius of the side wall, metres.
    pub radius_m: f64,
    /// Height of the rim above the table, metres.
    pub height_m: f64,
    /// World z of the table surface under the cup's axis, metres.
    pub table_height_m: f64,
    /// Points of the cup's cluster.
    pub n_points: usize,
}

/// How [`detect_cup`] searches.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct CupDetectOptions {
    /// RANSAC draws per plane. (default: 300)
    #[default(300)]
    pub ransac_iterations: usize,
    /// Distance from the plane within which a point belongs to it, metres. (default: 0.004)
    #[default(0.004)]
    pub plane_inlier_m: f64,
    /// Largest angle between a table's normal and world z, radians. (default: 0.17, ≈ 10°)
    #[default(0.17)]
    pub max_tilt_rad: f64,
    /// Smallest share of all points a plane must hold to count as a table (or floor).
    /// (default: 0.05)
    #[default(0.05)]
    pub min_plane_fraction: f64,
    /// Points at least this high above the table belong to objects, metres (default: 0.008)
    #[default(0.008)]
    pub min_height_m: f64,
    /// Points higher than this above the table are ignored (not a cup), metres.
    /// (default: 0.4)
    #[default(0.4)]
    pub max_height_m: f64,
    /// Largest gap between neighbouring points of one object, metres. (default: 0.015)
    #[default(0.015)]
    pub cluster_gap_m: f64,
    /// Fewest points of a cup. (default: 30)
    #[default(30)]
    pub min_cluster_points: usize,
    /// Seed of RANSAC's draws. (default: 0)
    pub seed: u64,
}

/// A plane `n · p = d` with unit normal `n` pointing up (n.z > 0).
#[derive(Debug, Clone, Copy)]
struct Plane {
    n: Vector3<f64>,
    d: f64,
}

impl Plane {
    fn height(&self, p: &Point3<f64>) -> f64 {
        self.n.dot(&p.coords) - self.d
    }
}

fn fail(message: String) -> Error {
    Error::Perception { what: "cup detection".into(), message }
}

/// Least-squares plane through `points` (centroid and the covariance's smallest axis), normal
/// pointing up.
fn fit_plane(points: &[Point3<f64>]) -> Plane {
    let n_pts = points.len().max(1) as f64;
    let c = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n_pts;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p.coords - c;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let i = eig.eigenvalues.imin();
    let mut n = eig.eigenvectors.column(i).into_owned();
    if n.z < 0.0 {
        n = -n;
    }
    Plane { n, d: n.dot(&c) }
}

/// Horizontal planes holding at least `min_inliers` points, each found by RANSAC among the
/// points not yet taken (at most 4).
fn horizontal_planes(points: &[Point3<f64>], opts: &CupDetectOptions) -> Vec<(Plane, Vec<usize>)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(opts.seed);
    let min_inliers = ((points.len() as f64 * opts.min_plane_fraction).ceil() as usize).max(3);
    let cos_tilt = opts.max_tilt_rad.cos();
    let mut left: Vec<usize> = (0..points.len()).collect();
    let mut planes = Vec::new();
    for _ in 0..4 {
        if left.len() < min_inliers {
            break;
        }
        // Candidates are scored on an evenly strided sample of at most 4000 points: the ranking
        // of planes holding ≥ 5 % of the points is the same, at a fraction of the cost.
        let stride = left.len().div_ceil(4000);
        let sample: Vec<usize> = left.iter().copied().step_by(stride).collect();
        let mut best: Option<(usize, Plane)> = None;
        for _ in 0..opts.ransac_iterations {
            let pick = |rng: &mut rand_chacha::ChaCha8Rng| points[left[rng.random_range(0..left.len())]];
            let (a, b, c) = (pick(&mut rng), pick(&mut rng), pick(&mut rng));
            let n = (b - a).cross(&(c - a));
            let norm = n.norm();
            if norm < 1e-9 {
                continue;
            }
            let mut n = n / norm;
            if n.z < 0.0 {
                n = -n;
            }
            if n.z < cos_tilt {
                continue;
            }
            let plane = Plane { n, d: n.dot(&a.coords) };
            let count = sample.iter().filter(|&&i| plane.height(&points[i]).abs() <= opts.plane_inlier_m).count();
            if best.is_none_or(|(c, _)| count > c) {
                best = Some((count, plane));
            }
        }
        let Some((_, plane)) = best else { break };
        let count = left.iter().filter(|&&i| plane.height(&points[i]).abs() <= opts.plane_inlier_m).count();
        if count < min_inliers {
            break;
        }
        let inliers: Vec<usize> =
            left.iter().copied().filter(|&i| plane.height(&points[i]).abs() <= opts.plane_inlier_m).collect();
        let refined = fit_plane(&inliers.iter().map(|&i| points[i]).collect::<Vec<_>>());
        let inliers: Vec<usize> =
            left.iter().copied().filter(|&i| refined.height(&points[i]).abs() <= opts.plane_inlier_m).collect();
        left.retain(|i| inliers.binary_search(i).is_err());
        planes.push((refined, inliers));
    }
    planes
}

/// Clusters of `points` (indices) whose members are chained by gaps of at most `gap`.
fn clusters(points: &[Point3<f64>], gap: f64) -> Vec<Vec<usize>> {
    use std::collections::HashMap;
    let cell = |p: &Point3<f64>| -> [i64; 3] { [0, 1, 2].map(|i| (p[i] / gap).floor() as i64) };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(i);
    }
    let mut label = vec![usize::MAX; points.len()];
    let mut out = Vec::new();
    for start in 0..points.len() {
        if label[start] != usize::MAX {
            continue;
        }
        let id = out.len();
        label[start] = id;
        let mut members = vec![start];
        let mut k = 0;
        while k < members.len() {
            let p = points[members[k]];
            let c = cell(&p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else { continue };
                        for &j in list {
                            if label[j] == usize::MAX && (points[j] - p).norm() <= gap {
                                label[j] = id;
                                members.push(j);
                            }
                        }
                    }
                }
            }
            k += 1;
        }
        out.push(members);
    }
    out
}

/// Circle through 2-D points: algebraic (Kåsa) fit, then Gauss–Newton on the geometric
/// distances. `None` when the points are degenerate (collinear, too few).
fn fit_circle(points: &[Vector2<f64>]) -> Option<(Vector2<f64>, f64)> {
    if points.len() < 3 {
        return None;
    }
    // Kåsa: x² + y² + D x + E y + F = 0, least squares, centred for conditioning.
    let mean = points.iter().fold(Vector2::zeros(), |a, p| a + p) / points.len() as f64;
    let mut ata = Matrix3::<f64>::zeros();
    let mut atb = Vector3::<f64>::zeros();
    for p in points {
        let q = p - mean;
        let row = Vector3::new(q.x, q.y, 1.0);
        ata += row * row.transpose();
        atb += row * -(q.x * q.x + q.y * q.y);
    }
    let sol = ata.lu().solve(&atb)?;
    let mut c = Vector2::new(-sol.x / 2.0, -sol.y / 2.0);
    let r2 = c.norm_squared() - sol.z;
    if r2.is_nan() || r2 <= 0.0 {
        return None;
    }
    let mut r = r2.sqrt();
    c += mean;
    for _ in 0..50 {
        let mut jtj = Matrix3::<f64>::zeros();
        let mut jtr = Vector3::<f64>::zeros();
        for p in points {
            let v = p - c;
            let d = v.norm().max(1e-12);
            let res = d - r;
            let j = Vector3::new(-v.x / d, -v.y / d, -1.0);
            jtj += j * j.transpose();
            jtr += j * res;
        }
        let step = jtj.lu().solve(&(-jtr))?;
        c += Vector2::new(step.x, step.y);
        r += step.z;
        if step.norm() < 1e-10 {
            break;
        }
    }
    (r > 0.0 && r.is_finite()).then_some((c, r))
}

/// Finds a cup standing on a table in `points_world` (e.g. [`super::depth::DepthFrame::points_world`]),
/// from the points alone.
///
/// # Errors
/// [`Error::Perception`] saying which stage failed: no horizontal plane, nothing on it, a
/// cluster too small, or a side wall that fits no circle.
pub fn detect_cup(points_world: &[Point3<f64>], opts: &CupDetectOptions) -> Result<CupEstimate> {
    let finite: Vec<Point3<f64>> =
        points_world.iter().copied().filter(|p| p.coords.iter().all(|x| x.is_finite())).collect();
    let planes = horizontal_planes(&finite, opts);
    // The table: the highest plane (a floor in view is lower), by its inliers' mean height.
    let mean_z = |idx: &[usize]| idx.iter().map(|&i| finite[i].z).sum::<f64>() / idx.len().max(1) as f64;
    let Some((table, table_pts)) = planes.iter().max_by(|a, b| mean_z(&a.1).total_cmp(&mean_z(&b.1))) else {
        return Err(fail(format!(
            "no horizontal plane holds {:.0} % of the {} points (within {} m, tilt ≤ {:.0}°): is a table in view?",
            opts.min_plane_fraction * 100.0,
            finite.len(),
            opts.plane_inlier_m,
            opts.max_tilt_rad.to_degrees()
        )));
    };
    // The table's extent in its plane, to keep objects standing on it.
    let e1 =
        table.n.cross(&Vector3::x()).try_normalize(1e-9).unwrap_or_else(|| table.n.cross(&Vector3::y()).normalize());
    let e2 = table.n.cross(&e1);
    let in_plane = |p: &Point3<f64>| Vector2::new(e1.dot(&p.coords), e2.dot(&p.coords));
    let (mut lo, mut hi) = (Vector2::repeat(f64::INFINITY), Vector2::repeat(f64::NEG_INFINITY));
    for &i in table_pts {
        let q = in_plane(&finite[i]);
        lo = lo.inf(&q);
        hi = hi.sup(&q);
    }
    let above: Vec<Point3<f64>> = finite
        .iter()
        .filter(|p| {
            let h = table.height(p);
            let q = in_plane(p);
            h >= opts.min_height_m && h <= opts.max_height_m && q.x >= lo.x && q.x <= hi.x && q.y >= lo.y && q.y <= hi.y
        })
        .copied()
        .collect();
    let groups = clusters(&above, opts.cluster_gap_m);
    let Some(cup) = groups.iter().max_by_key(|g| g.len()) else {
        return Err(fail(format!(
            "nothing stands on the table (no points {} … {} m above it)",
            opts.min_height_m, opts.max_height_m
        )));
    };
    if cup.len() < opts.min_cluster_points {
        return Err(fail(format!(
            "the biggest object on the table has {} points, fewer than {}: too far or too small to fit",
            cup.len(),
            opts.min_cluster_points
        )));
    }
    let cup_pts: Vec<Point3<f64>> = cup.iter().map(|&i| above[i]).collect();
    let height = cup_pts.iter().map(|p| table.height(p)).fold(f64::NEG_INFINITY, f64::max);
    // Side wall: below the rim band (a closed top or the rim's inside would pull the circle in).
    let rim_band = (0.15 * height).max(2.0 * opts.plane_inlier_m);
    let side: Vec<Vector2<f64>> =
        cup_pts.iter().filter(|p| table.height(p) < height - rim_band).map(&in_plane).collect();
    let Some((c2, radius)) = fit_circle(&side) else {
        return Err(fail(format!(
            "the {} side-wall points of the object on the table fit no circle (is it round?)",
            side.len()
        )));
    };
    // Back to the world: the axis point on the table, then half the height up.
    let on_table = e1 * c2.x + e2 * c2.y + table.n * table.d;
    let centre = on_table + table.n * (height / 2.0);
    Ok(CupEstimate {
        centre_world: Point3::from(centre),
        radius_m: radius,
        height_m: height,
        table_height_m: on_table.z,
        n_points: cup.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_fit_on_a_half_arc_is_exact() {
        let pts: Vec<Vector2<f64>> = (0..40)
            .map(|k| {
                let a = std::f64::consts::PI * k as f64 / 39.0;
                Vector2::new(0.3 + 0.04 * a.cos(), -0.2 + 0.04 * a.sin())
            })
            .collect();
        let (c, r) = fit_circle(&pts).unwrap();
        assert!((c - Vector2::new(0.3, -0.2)).norm() < 1e-9 && (r - 0.04).abs() < 1e-9, "{c} {r}");
    }

    #[test]
    fn empty_cloud_says_what_is_missing() {
        let err = detect_cup(&[], &CupDetectOptions::default()).unwrap_err().to_string();
        assert!(err.contains("no horizontal plane"), "{err}");
    }
}
