//! Differential and half-differential transmissions → MuJoCo fixed tendons, one actuator per
//! tendon, with the coefficients of ros_control's effort mapping: a tendon's length is
//! `Σ coef_j · q_j`, so an actuator force `τa` on it applies `coef_j · τa` to joint `j`.

use super::ir::{Interface, JointKind};
use super::{Converter, DifferentialMeta, esc, f};

impl Converter<'_> {
    /// Tendons and actuators of every differential transmission whose joints are 1-DOF and
    /// not mimics.
    pub(super) fn differentials(&mut self) -> crate::error::Result<()> {
        let robot = self.robot;
        for d in &robot.differentials {
            let bad = d.joints.iter().find(|(name, ..)| {
                !robot.joints.iter().any(|j| {
                    &j.name == name
                        && j.mimic.is_none()
                        && matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
                })
            });
            if let Some((name, ..)) = bad {
                self.notes.push(format!(
                    "differential transmission \"{}\" (line {}): joint \"{name}\" is not a free 1-DOF joint; transmission not converted",
                    d.name, d.line
                ));
                continue;
            }
            let coef = d.coefficients();
            // Effort each actuator may give so that no joint exceeds its effort limit with both
            // actuators at full effort.
            let mut act_effort: Option<f64> = None;
            for (k, (jname, ..)) in d.joints.iter().enumerate() {
                let effort = robot
                    .joints
                    .iter()
                    .find(|j| &j.name == jname)
                    .and_then(|j| j.limit.as_ref())
                    .map(|l| l.effort)
                    .filter(|e| *e > 0.0);
                let sum = coef[0][k].abs() + coef[1][k].abs();
                if let (Some(e), true) = (effort, sum > 0.0) {
                    let a = e / sum;
                    act_effort = Some(act_effort.map_or(a, |b: f64| b.min(a)));
                }
            }
            if d.joints.iter().any(|j| j.2 != 0.0) {
                self.notes.push(format!(
                    "differential transmission \"{}\" (line {}): joint offsets only shift actuator positions (ros_control's position mapping); torques are exact",
                    d.name, d.line
                ));
            }
            let mut names = [String::new(), String::new()];
            for (a, (aname, _)) in d.actuators.iter().enumerate() {
                let clash = robot.joints.iter().any(|j| &j.name == aname);
                let name = if clash { format!("{aname}_tendon") } else { aname.clone() };
                let mut tendon = format!("<fixed name=\"{}\">", esc(&name));
                for (k, (jname, ..)) in d.joints.iter().enumerate() {
                    if coef[a][k] != 0.0 {
                        tendon.push_str(&format!("<joint joint=\"{}\" coef=\"{}\"/>", esc(jname), f(coef[a][k])));
                    }
                }
                tendon.push_str("</fixed>");
                self.tendon_xml.push(tendon);
                let fr = act_effort.map(|e| format!(" forcerange=\"{} {}\"", f(-e), f(e))).unwrap_or_default();
                let line = match d.interface {
                    Interface::Effort => {
                        let cr = act_effort.map(|e| format!(" ctrlrange=\"{} {}\"", f(-e), f(e))).unwrap_or_default();
                        format!("<motor name=\"{}\" tendon=\"{}\"{cr}{fr}/>", esc(&name), esc(&name))
                    }
                    Interface::Position => {
                        let kp = act_effort.map_or(100.0, |e| self.opts.position_kp_per_effort * e);
                        format!(
                            "<position name=\"{}\" tendon=\"{}\" kp=\"{}\" kv=\"{}\"{fr}/>",
                            esc(&name),
                            esc(&name),
                            f(kp),
                            f(kp * self.opts.position_kv_per_kp)
                        )
                    }
                    Interface::Velocity => {
                        let kv = act_effort.map_or(10.0, |e| self.opts.velocity_kv_per_effort * e);
                        format!("<velocity name=\"{}\" tendon=\"{}\" kv=\"{}\"{fr}/>", esc(&name), esc(&name), f(kv))
                    }
                };
                self.tendon_act_xml.push(line);
                names[a] = name;
            }
            self.differential_meta.push(DifferentialMeta {
                name: d.name.clone(),
                half: d.half,
                actuators: names,
                joints: [d.joints[0].0.clone(), d.joints[1].0.clone()],
                coefficients: coef,
                interface: d.interface,
            });
        }
        Ok(())
    }
}
