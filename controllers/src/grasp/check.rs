//! The checks of a grasp, measured from the simulation (not from the controller's beliefs):
//! reach without collision, grip force within bounds, no slip in the hand, balance, lifted and
//! held.

use crate::checks::{Checks, Threshold, Thresholds};
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use twin_core::engine::{Check, Flow, Measurement, Observer, StepView, Verdict};
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, Model, ObjType};

/// What a grasp check measured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GraspMeasure {
    /// Least arm clearance, m (negative: penetration); −1 after a forbidden contact.
    pub min_clearance_m: f64,
    /// The first forbidden contact or arm collision, if any.
    pub collision: Option<String>,
    /// Largest normal force of one finger on the cup, N.
    pub max_grip_force_n: f64,
    /// Smaller of the two fingers' mean normal force while lifted, N (NaN: never lifted).
    pub hold_grip_force_n: f64,
    /// Largest cup displacement in the grasp frame since the lift started, m (NaN: no lift).
    pub slip_m: f64,
    /// Largest cup tilt in the grasp frame since the lift started, degrees (NaN: no lift).
    pub tilt_deg: f64,
    /// Least CoM margin inside the support polygon, m.
    pub min_com_margin_m: f64,
    /// When the CoM margin was least, s.
    pub min_com_margin_secs: f64,
    /// Largest cup height above its start, m.
    pub max_lift_m: f64,
    /// Cup height above its start at the end, m.
    pub final_lift_m: f64,
    /// Time the cup has been continuously at least `min_lift_m` up at the end, s.
    pub held_secs: f64,
}

#[derive(Debug, Clone)]
struct GripperSet {
    grasp_body: usize,
    fingers: [usize; 2],
    gripper_bodies: Vec<usize>,
    arm_bodies: Vec<usize>,
}

/// Observes a rollout and checks the grasp against the grasp thresholds of a scenario's
/// [`Checks`] (`Check` name `grasp`).
#[derive(Debug, Clone)]
pub struct GraspCheck {
    checks: Checks,
    cup_name: String,
    grasp_names: [String; 2],
    cup_body: usize,
    robot_root: usize,
    feet: Vec<usize>,
    grippers: Vec<GripperSet>,
    /// Geom pairs (arm geom, other robot geom) whose distance is watched.
    pairs: Vec<(usize, usize)>,
    cup_z0: f64,
    /// Per gripper: lowest grasp-frame z while the grasp point was at the cup (within 2 cm of
    /// its centre).
    grasp_z_at_cup: Vec<Option<f64>>,
    /// Cup pose in the grasp frame when the lift started: (gripper, position, rotation).
    lift_ref: Option<(usize, Vector3<f64>, Matrix3<f64>)>,
    hold_force_sum: [f64; 2],
    hold_steps: u64,
    lifted_since: Option<f64>,
    scratch: Option<Data>,
    m: GraspMeasure,
}

fn geoms_of(model: &Model, bodies: &[usize]) -> Vec<usize> {
    (0..model.ngeom())
        .filter(|&g| bodies.contains(&(model.geom_bodyid()[g] as usize)))
        .filter(|&g| model.geom_contype()[g] != 0 || model.geom_conaffinity()[g] != 0)
        .collect()
}

impl GraspCheck {
    /// A check of the grasp of body `cup` by the grippers whose grasp frames are
    /// `grasp_bodies`.
    pub fn new(checks: Checks, cup: &str, grasp_bodies: [String; 2]) -> GraspCheck {
        GraspCheck {
            checks,
            cup_name: cup.to_string(),
            grasp_names: grasp_bodies,
            cup_body: 0,
            robot_root: 0,
            feet: Vec::new(),
            grippers: Vec::new(),
            pairs: Vec::new(),
            cup_z0: 0.0,
            grasp_z_at_cup: Vec::new(),
            lift_ref: None,
            hold_force_sum: [0.0; 2],
            hold_steps: 0,
            lifted_since: None,
            scratch: None,
            m: GraspMeasure::default(),
        }
    }

    /// What was measured so far.
    pub fn measure(&self) -> &GraspMeasure {
        &self.m
    }

    /// One scenario verdict per threshold.
    pub fn verdicts(&self) -> Vec<Threshold> {
        let c = &self.checks;
        let m = &self.m;
        let mut out = Thresholds::default();
        out.at_most("max_grip_force_n", m.max_grip_force_n, c.max_grip_force_n);
        out.at_most("max_slip_m", m.slip_m, c.max_slip_m);
        out.at_most("max_tilt_deg", m.tilt_deg, c.max_tilt_deg);
        out.at_least("min_clearance_m", m.min_clearance_m, c.min_clearance_m);
        out.at_least("min_grip_force_n", m.hold_grip_force_n, c.min_grip_force_n);
        out.at_least("min_com_margin_m", m.min_com_margin_m, c.min_com_margin_m);
        if c.min_lift_m.is_some() || c.min_hold_secs.is_some() {
            out.at_least("min_lift_m", m.final_lift_m, c.min_lift_m);
            out.at_least("min_hold_secs", m.held_secs, Some(c.min_hold_secs.unwrap_or(2.0)));
        }
        out.0
    }

    fn bind(&mut self, model: &Model) -> Result<()> {
        self.cup_body = model.id(ObjType::Body, &self.cup_name).ok_or_else(|| Error::Grasp {
            message: format!(
                "grasp checks: the model has no body \"{}\" (the cup): compose a world with it",
                self.cup_name
            ),
        })?;
        self.robot_root = model.free_joint().map_or(0, |f| f.body);
        self.feet = twin_core::robot::find_feet(model)?;
        let ids: Vec<usize> = self.grasp_names.iter().filter_map(|n| model.id(ObjType::Body, n)).collect();
        if ids.is_empty() {
            return Err(Error::Grasp {
                message: format!("grasp checks: the model has no grasp body {:?}", self.grasp_names),
            });
        }
        self.grippers.clear();
        let parent = model.body_parentid();
        for (k, &g) in ids.iter().enumerate() {
            let hand = parent[g] as usize;
            let gripper_bodies = model.subtree(hand);
            let mut fingers: Vec<usize> = (0..model.njnt())
                .filter(|&j| model.joint_type(j) == twin_core::mj::JointType::Slide)
                .map(|j| model.jnt_bodyid()[j] as usize)
                .filter(|b| gripper_bodies.contains(b))
                .collect();
            fingers.dedup();
            if fingers.len() != 2 {
                return Err(Error::Grasp {
                    message: format!(
                        "grasp checks: the gripper of \"{}\" has {} fingers, not 2",
                        model.name(ObjType::Body, g),
                        fingers.len()
                    ),
                });
            }
            // The arm: below the first ancestor shared with the other gripper.
            let mut up = vec![g];
            let mut b = g;
            while b != 0 {
                b = parent[b] as usize;
                up.push(b);
            }
            let trunk = ids
                .iter()
                .enumerate()
                .filter(|&(i, _)| i != k)
                .find_map(|(_, &o)| {
                    let mut theirs = vec![o];
                    let mut b = o;
                    while b != 0 {
                        b = parent[b] as usize;
                        theirs.push(b);
                    }
                    up.iter().copied().find(|x| theirs.contains(x))
                })
                .unwrap_or(self.robot_root);
            let top = up.iter().copied().take_while(|&x| x != trunk).last().unwrap_or(hand);
            let arm_bodies = model.subtree(top);
            self.grippers.push(GripperSet {
                grasp_body: g,
                fingers: [fingers[0], fingers[1]],
                gripper_bodies,
                arm_bodies,
            });
        }
        // Watched pairs: each arm's geoms against every other robot geom outside that arm,
        // except the trunk body the arm hangs from (its shoulder joint sits on it).
        let robot = model.subtree(self.robot_root);
        let mut pairs = Vec::new();
        for (k, gs) in self.grippers.iter().enumerate() {
            let top = *gs.arm_bodies.iter().min().unwrap_or(&0);
            let attach = parent[top] as usize;
            let others: Vec<usize> = robot
                .iter()
                .copied()
                .filter(|b| !gs.arm_bodies.contains(b) && *b != attach)
                // Each pair of arms once.
                .filter(|b| !self.grippers[..k].iter().any(|o| o.arm_bodies.contains(b)))
                .collect();
            for ga in geoms_of(model, &gs.arm_bodies) {
                for go in geoms_of(model, &others) {
                    pairs.push((ga, go));
                }
            }
        }
        self.pairs = pairs;
        Ok(())
    }

    /// Whether a contact between robot body `rb` and world body `wb` is allowed.
    fn allowed(&self, rb: usize, wb: usize) -> bool {
        self.feet.contains(&rb) && wb != self.cup_body
            || wb == self.cup_body && self.grippers.iter().any(|g| g.gripper_bodies.contains(&rb))
    }
}

/// Signed distance of `p` inside the convex polygon `hull` (counter-clockwise), m.
fn margin_inside(hull: &[Vector2<f64>], p: Vector2<f64>) -> f64 {
    if hull.len() < 3 {
        return if hull.is_empty() {
            f64::NEG_INFINITY
        } else {
            -hull.iter().map(|h| (h - p).norm()).fold(f64::INFINITY, f64::min)
        };
    }
    let mut m = f64::INFINITY;
    for i in 0..hull.len() {
        let a = hull[i];
        let b = hull[(i + 1) % hull.len()];
        let e = b - a;
        let len = e.norm();
        if len < 1e-12 {
            continue;
        }
        // Left of a→b is inside for a counter-clockwise hull.
        let d = (e.x * (p.y - a.y) - e.y * (p.x - a.x)) / len;
        m = m.min(d);
    }
    m
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
fn convex_hull(mut pts: Vec<Vector2<f64>>) -> Vec<Vector2<f64>> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup_by(|a, b| (*a - *b).norm() < 1e-9);
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| (a - o).perp(&(b - o));
    let mut lower: Vec<Vector2<f64>> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0.0 {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<Vector2<f64>> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0.0 {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

impl Observer for GraspCheck {
    fn start(&mut self, model: &Model, data: &Data) -> Result<()> {
        self.bind(model)?;
        self.cup_z0 = data.xpos()[self.cup_body][2];
        self.grasp_z_at_cup = vec![None; self.grippers.len()];
        self.lift_ref = None;
        self.hold_force_sum = [0.0; 2];
        self.hold_steps = 0;
        self.lifted_since = None;
        self.m = GraspMeasure {
            min_clearance_m: f64::INFINITY,
            hold_grip_force_n: f64::NAN,
            slip_m: f64::NAN,
            tilt_deg: f64::NAN,
            min_com_margin_m: f64::INFINITY,
            ..GraspMeasure::default()
        };
        self.scratch = None;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let data = step.data;
        let model = data.model().clone();
        let body_of = |g: i32| if g < 0 { 0 } else { model.geom_bodyid()[g as usize] as usize };
        let is_robot = |b: usize| b != 0 && model.in_subtree(self.robot_root, b);
        // Contacts: forbidden ones, finger forces, the support polygon.
        let mut finger_force = vec![[0.0f64; 2]; self.grippers.len()];
        let mut support = Vec::new();
        for i in 0..data.ncon() {
            let Some(w) = data.contact_wrench_world(i) else { continue };
            let (b1, b2) = (body_of(w.geoms[0]), body_of(w.geoms[1]));
            let (r1, r2) = (is_robot(b1), is_robot(b2));
            if r1 && r2 {
                if self.m.collision.is_none() {
                    self.m.collision = Some(format!(
                        "t = {:.3} s: \"{}\" touches \"{}\"",
                        step.time_secs,
                        model.name(ObjType::Body, b1),
                        model.name(ObjType::Body, b2)
                    ));
                }
                self.m.min_clearance_m = self.m.min_clearance_m.min(-1.0);
                continue;
            }
            let (rb, wb) = match (r1, r2) {
                (true, false) => (b1, b2),
                (false, true) => (b2, b1),
                _ => continue,
            };
            if !self.allowed(rb, wb) {
                if self.m.collision.is_none() {
                    self.m.collision = Some(format!(
                        "t = {:.3} s: robot \"{}\" touches \"{}\" at ({:.3}, {:.3}, {:.3}) m",
                        step.time_secs,
                        model.name(ObjType::Body, rb),
                        if wb == 0 {
                            "the world (floor or table)".to_string()
                        } else {
                            model.name(ObjType::Body, wb).to_string()
                        },
                        w.position[0],
                        w.position[1],
                        w.position[2]
                    ));
                }
                self.m.min_clearance_m = self.m.min_clearance_m.min(-1.0);
            }
            if self.feet.contains(&rb) && wb != self.cup_body {
                support.push(Vector2::new(w.position[0], w.position[1]));
            }
            if wb == self.cup_body {
                for (k, gs) in self.grippers.iter().enumerate() {
                    if let Some(f) = gs.fingers.iter().position(|&fb| fb == rb) {
                        let r = &data.xmat()[gs.grasp_body];
                        let jaw = Vector3::new(r[1], r[4], r[7]);
                        finger_force[k][f] += Vector3::from(w.force_n).dot(&jaw).abs();
                    }
                }
            }
        }
        for ff in &finger_force {
            self.m.max_grip_force_n = self.m.max_grip_force_n.max(ff[0]).max(ff[1]);
        }
        // Balance: the robot's CoM over the hull of the feet's contacts (after the first
        // 0.1 s, while the feet's contacts form).
        let com = data.subtree_com()[self.robot_root];
        let margin = margin_inside(&convex_hull(support), Vector2::new(com[0], com[1]));
        if step.time_secs >= 0.1 && margin < self.m.min_com_margin_m {
            self.m.min_com_margin_m = margin;
            self.m.min_com_margin_secs = step.time_secs;
        }
        // Arm clearance, every 10th step (50 Hz at 2 ms).
        if step.index.is_multiple_of(10) && !self.pairs.is_empty() {
            let scratch = match self.scratch.as_mut() {
                Some(s) => s,
                None => self.scratch.insert(data.try_clone()?),
            };
            scratch.qpos_mut().copy_from_slice(step.qpos);
            scratch.kinematics_with_velocity()?;
            for &(a, b) in &self.pairs {
                let d = scratch.geom_distance(a, b, 0.05)?;
                if d < self.m.min_clearance_m {
                    self.m.min_clearance_m = d;
                }
                if d < 0.0 && self.m.collision.is_none() {
                    self.m.collision = Some(format!(
                        "t = {:.3} s: arm geom \"{}\" penetrates \"{}\" by {:.4} m",
                        step.time_secs,
                        model.name(ObjType::Geom, a),
                        model.name(ObjType::Geom, b),
                        -d
                    ));
                }
            }
        }
        // Grasp, lift, slip.
        let cup_p = Vector3::from(data.xpos()[self.cup_body]);
        let cup_r = Matrix3::from_row_slice(&data.xmat()[self.cup_body]);
        // The lift starts when a grasp frame that was at the cup has risen 1 cm: from then on
        // the cup must move with it, whether the fingers hold it or not.
        for (k, gs) in self.grippers.iter().enumerate() {
            let gp = Vector3::from(data.xpos()[gs.grasp_body]);
            if (gp - cup_p).norm() < 0.02 {
                let z = self.grasp_z_at_cup[k].get_or_insert(gp.z);
                *z = z.min(gp.z);
            }
            if self.lift_ref.is_none()
                && let Some(z0) = self.grasp_z_at_cup[k]
                && gp.z > z0 + 0.01
            {
                let gr = Matrix3::from_row_slice(&data.xmat()[gs.grasp_body]);
                self.lift_ref = Some((k, gr.transpose() * (cup_p - gp), gr.transpose() * cup_r));
                self.m.slip_m = 0.0;
                self.m.tilt_deg = 0.0;
            }
        }
        if let Some((k, p0, r0)) = self.lift_ref {
            let gs = &self.grippers[k];
            let gp = Vector3::from(data.xpos()[gs.grasp_body]);
            let gr = Matrix3::from_row_slice(&data.xmat()[gs.grasp_body]);
            let p = gr.transpose() * (cup_p - gp);
            let r = gr.transpose() * cup_r;
            self.m.slip_m = self.m.slip_m.max((p - p0).norm());
            let rel = Rotation3::from_matrix_unchecked(r0.transpose() * r);
            self.m.tilt_deg = self.m.tilt_deg.max(rel.angle().to_degrees());
            if cup_p.z > self.cup_z0 + 0.01 {
                self.hold_force_sum[0] += finger_force[k][0];
                self.hold_force_sum[1] += finger_force[k][1];
                self.hold_steps += 1;
                let n = self.hold_steps as f64;
                self.m.hold_grip_force_n = (self.hold_force_sum[0] / n).min(self.hold_force_sum[1] / n);
            }
        }
        let lift = cup_p.z - self.cup_z0;
        self.m.max_lift_m = self.m.max_lift_m.max(lift);
        self.m.final_lift_m = lift;
        let needed = self.checks.min_lift_m.unwrap_or(0.1);
        if lift >= needed {
            let since = *self.lifted_since.get_or_insert(step.time_secs);
            self.m.held_secs = step.sim_secs - since;
        } else {
            self.lifted_since = None;
            self.m.held_secs = 0.0;
        }
        Ok(Flow::Continue)
    }
}

impl Check for GraspCheck {
    fn name(&self) -> &str {
        "grasp"
    }

    fn verdict(&self) -> Verdict {
        let verdicts = self.verdicts();
        let failed: Vec<&str> = verdicts.iter().filter(|v| !v.passed).map(|v| v.name).collect();
        let mut details: Vec<String> = verdicts.iter().map(ToString::to_string).collect();
        if let Some(c) = &self.m.collision {
            details.push(format!("collision: {c}"));
        }
        Verdict {
            name: "grasp".into(),
            passed: failed.is_empty(),
            metrics: verdicts.iter().map(|v| Measurement::new(v.name, v.value, "")).collect(),
            details,
            cause: (!failed.is_empty()).then(|| format!("failed: {}", failed.join(", "))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn com_margin_is_the_signed_distance_to_the_hull() {
        let pts = vec![
            Vector2::new(0.0, 0.0),
            Vector2::new(0.2, 0.0),
            Vector2::new(0.2, 0.1),
            Vector2::new(0.0, 0.1),
            Vector2::new(0.1, 0.05),
        ];
        let hull = convex_hull(pts);
        assert_eq!(hull.len(), 4);
        assert!((margin_inside(&hull, Vector2::new(0.1, 0.05)) - 0.05).abs() < 1e-12);
        assert!((margin_inside(&hull, Vector2::new(0.25, 0.05)) + 0.05).abs() < 1e-12);
    }
}
