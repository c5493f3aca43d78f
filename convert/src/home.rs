//! The home pose a converted robot holds (an SRDF's named pose, [`crate::srdf`], or the zero pose
//! clamped into the joint ranges) and the contacts of the feet that carry it: MuJoCo's contact
//! stiffness is an acceleration, so a light foot under a heavy robot sinks in proportion unless
//! stiffened.

use crate::error::{Error, Result};
use crate::ir::JointKind;
use crate::{Converter, srdf};
use std::path::Path;

/// Deepest a contact may sink with the robot's whole weight on its link before the converter
/// stiffens it ([`Converter::weight_solref`]), metres.
pub(crate) const MAX_SINK_M: f64 = 0.005;

/// A link is a foot (may carry the robot, [`Converter::weight_solref`]) when its collision
/// geoms reach within this of the robot's lowest point in the home pose, metres.
pub(crate) const FOOT_BAND_M: f64 = 0.02;

/// Standard gravity, m/s² (the converter's floor and worlds use 9.81).
pub(crate) const GRAVITY_M_S2: f64 = 9.81;

impl Converter<'_> {
    /// The joint values of the home pose (an SRDF's named pose, [`srdf`]) by MJCF joint name;
    /// empty for the zero pose clamped into the joint ranges. Sets [`RobotMeta::home_pose`] and
    /// notes what was used.
    ///
    /// # Errors
    /// An SRDF named by [`ConvertOptions::srdf`] that can't be read or lacks the pose asked for,
    /// or a pose asked for that no SRDF beside the URDF has.
    pub(crate) fn named_pose(&mut self, urdf: &Path) -> Result<Vec<(String, f64)>> {
        let movable: Vec<&str> = self
            .robot
            .joints
            .iter()
            .filter(|j| matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic))
            .map(|j| j.name.as_str())
            .collect();
        let wanted = self.opts.pose.as_deref();
        let found = match &self.opts.srdf {
            Some(file) => srdf::read(file, wanted, &movable)?,
            None => srdf::find(urdf, &self.robot.name, wanted, &movable),
        };
        let Some(pose) = found else {
            if let Some(name) = wanted {
                return Err(Error::Urdf {
                    path: urdf.to_path_buf(),
                    line: 1,
                    element: "robot".into(),
                    name: Some(self.robot.name.clone()),
                    message: format!(
                        "pose \"{name}\" asked for, but no SRDF beside the URDF (its folder, srdf/ there or srdf/ one folder up) has a group state of that name for this robot: name the file with --srdf"
                    ),
                });
            }
            self.home_pose =
                "zero pose clamped into every joint's range (no SRDF with a standing or home pose beside the URDF)"
                    .into();
            return Ok(Vec::new());
        };
        let mut joints = Vec::with_capacity(pose.joints.len());
        for (name, value) in &pose.joints {
            let limit = self.robot.joints.iter().find(|j| &j.name == name).and_then(|j| match j.kind {
                JointKind::Continuous => None,
                _ => j.limit.as_ref().map(|l| (l.lower, l.upper)),
            });
            if let Some((lo, hi)) = limit.filter(|&(lo, hi)| lo < hi && !(lo..=hi).contains(value)) {
                self.notes.push(format!(
                    "SRDF pose \"{}\": joint \"{name}\" at {value} is outside its range [{lo}, {hi}]: clamped",
                    pose.name
                ));
            }
            joints.push((name.clone(), *value));
        }
        if !pose.unknown_joints.is_empty() {
            self.notes.push(format!(
                "SRDF pose \"{}\" ({}): joints not in this robot skipped: {}",
                pose.name,
                pose.file.display(),
                pose.unknown_joints.join(", ")
            ));
        }
        self.home_pose = format!(
            "SRDF pose \"{}\" of {} ({} of {} joints; the others at zero clamped into their ranges)",
            pose.name,
            pose.file.display(),
            joints.len(),
            movable.len()
        );
        Ok(joints)
    }

    /// A stiffer contact for a light link that may carry a heavy robot (a quadruped's foot):
    /// MuJoCo's contact stiffness is an acceleration, so under MuJoCo's default (`solref 0.02 1`,
    /// `solimp 0.9 0.95 0.001`) a contact of effective mass `mass` carrying force `f` settles
    /// `(1 − d)/d · f/(mass·k)` deep, k = 1/(0.95·0.02)²: ANYmal C's 0.09 kg feet under its 52 kg
    /// sank 3.7 cm. Where that depth, with the robot's whole weight (`total_kg`) on the link,
    /// exceeds [`MAX_SINK_M`], the direct-form `solref` of [`Converter::direct_solref`] whose
    /// depth at that weight is [`MAX_SINK_M`] (critically damped); `None` (the default) elsewhere.
    pub(crate) fn weight_solref(&mut self, link: &str, mass: f64, total_kg: f64) -> Option<[f64; 2]> {
        const DEFAULT_DMAX: f64 = 0.95;
        let k_default = 1.0 / (DEFAULT_DMAX * 0.02).powi(2);
        let accel = total_kg * GRAVITY_M_S2 / mass;
        let sink_default = (1.0 - DEFAULT_DMAX) / DEFAULT_DMAX * accel / k_default;
        if sink_default <= MAX_SINK_M {
            return None;
        }
        // Gazebo's form: depth (1 − d)·f/(mass·K) = MAX_SINK_M at f = total·g, as kp = f/depth.
        let kp = total_kg * GRAVITY_M_S2 / MAX_SINK_M;
        let solref = self.direct_solref(link, 0, kp, 0.0, mass);
        self.notes.push(format!(
            "link \"{link}\": contact stiffened (solref {:.4e} {:.4e}): its effective mass {mass:.3} kg under the robot's {total_kg:.1} kg would sink {:.1} mm with MuJoCo's default contact, at most {:.0} mm now",
            solref[0],
            solref[1],
            sink_default * 1e3,
            MAX_SINK_M * 1e3
        ));
        Some(solref)
    }
}
