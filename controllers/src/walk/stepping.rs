//! Where and when the feet go: the support region, the footstep plan and its corrections
//! (first step, recovery landings, the DCM-corrected step, steering), touchdown timing and the
//! ground reads that place each landing.

use super::*;

impl Walker {
    /// The feet's support region: the segment between the sole centres swept by a sole (in
    /// the feet's mean heading frame): start, segment, heading, sole half sizes.
    pub(super) fn support_region(&self, feet: &[Foothold; 2]) -> (Vector2<f64>, Vector2<f64>, f64, Vector2<f64>) {
        let heading = feet[1].yaw + wrap(feet[0].yaw - feet[1].yaw) / 2.0;
        let sole = |k: usize| self.body.legs[0].sole_half[k].min(self.body.legs[1].sole_half[k]);
        let segment = rotation(-heading) * (feet[1].pos - feet[0].pos);
        (feet[0].pos, segment, heading, Vector2::new(sole(0), sole(1)))
    }

    /// Whether `p` lies inside the feet's support region, at least `margin` from its edge.
    pub(super) fn inside_support(&self, p: Vector2<f64>, feet: &[Foothold; 2], margin: f64) -> bool {
        let (a, d, heading, half) = self.support_region(feet);
        let q = rotation(-heading) * (p - a);
        // Some s in [0, 1] with |q − s·d| ≤ half − margin on both axes.
        let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
        for k in 0..2 {
            let h = half[k] - margin;
            if h <= 0.0 {
                return false;
            }
            if d[k].abs() < 1e-9 {
                if q[k].abs() > h {
                    return false;
                }
            } else {
                let (s0, s1) = ((q[k] - h) / d[k], (q[k] + h) / d[k]);
                lo = lo.max(s0.min(s1));
                hi = hi.min(s0.max(s1));
            }
        }
        lo <= hi
    }

    /// `p` moved into the feet's support region (its soles shrunk to 80 %): onto the segment
    /// between the soles, then within a sole around that point.
    pub(super) fn clamp_to_support(&self, p: Vector2<f64>, feet: &[Foothold; 2]) -> Vector2<f64> {
        let (a, d, heading, half) = self.support_region(feet);
        let rot = rotation(heading);
        let q = rot.inverse() * (p - a);
        let s = (q.dot(&d) / d.norm_squared().max(1e-12)).clamp(0.0, 1.0);
        let r = q - d * s;
        let r = Vector2::new(r.x.clamp(-0.8 * half.x, 0.8 * half.x), r.y.clamp(-0.8 * half.y, 0.8 * half.y));
        a + rot * (d * s + r)
    }

    /// `p` moved into the sole of `foot` (shrunk to 80 %).
    pub(super) fn clamp_to_sole(&self, foot: &Foothold, p: Vector2<f64>) -> Vector2<f64> {
        let half = self.body.legs[foot.side.index()].sole_half;
        // One `sin_cos`: the inverse is the transpose, `Rotation2::new(-yaw)` bit for bit.
        let r = rotation(foot.yaw);
        let rel = r.inverse() * (p - foot.pos);
        let rel = Vector2::new(rel.x.clamp(-half[0] * 0.8, half[0] * 0.8), rel.y.clamp(-half[1] * 0.8, half[1] * 0.8));
        foot.pos + r * rel
    }

    /// Restarts the preview control's state at the measured CoM `com` and its velocity.
    pub(super) fn restart_preview(&mut self, com: Vector3<f64>) {
        self.axes = [
            PreviewAxis::restart(&self.preview, com.x, self.com_vel.x),
            PreviewAxis::restart(&self.preview, com.y, self.com_vel.y),
        ];
    }

    /// World sole centre of leg `leg` at `frames`.
    pub(super) fn sole_world(&self, frames: &Frames, leg: usize) -> Vector3<f64> {
        let l = &self.body.legs[leg];
        frames.xpos[l.foot] + frames.xrot[l.foot] * l.sole_in_foot
    }

    /// Foothold (sole centre x y, heading) of leg `leg` at `frames`.
    pub(super) fn foothold_of(&self, frames: &Frames, leg: usize) -> Foothold {
        let l = &self.body.legs[leg];
        let p = self.sole_world(frames, leg);
        let heading = frames.xrot[l.foot] * l.foot_rot_home.inverse();
        Foothold { side: l.side, pos: Vector2::new(p.x, p.y), yaw: kin::yaw_of(&heading) }
    }

    pub(super) fn build_loops(&mut self, model: &Model) {
        let o = &self.options;
        let gains = |saturation_error: f64| {
            let options = PdHoldOptions { saturation_error, damping_ratio: o.damping_ratio, ..Default::default() };
            PdHold::new(model, options).gains()
        };
        let pd_legs = gains(o.leg_saturation_error);
        let pd_rest = gains(o.saturation_error);
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let actuation = Actuation::of(model);
        let limits = actuation.limits(model);
        self.loops.clear();
        // The same loops, in the same order, as PdHold builds (joint transmissions on hinges).
        let mut k = 0;
        let mut push = |command: usize,
                        joint: usize,
                        gear: f64,
                        limits: [f64; 2],
                        drive: (Option<AffineServo>, [f64; 2]),
                        loops: &mut Vec<JointLoop>| {
            let leg = self
                .ik
                .iter()
                .enumerate()
                .find_map(|(li, _)| self.body.legs[li].joints.iter().position(|&j| j == joint).map(|ci| (li, ci)));
            let (kp, kd) = if leg.is_some() { pd_legs[k] } else { pd_rest[k] };
            k += 1;
            // Joint-space gains (PdHold's are per unit of command).
            let (kp, kd) = (kp * gear, kd * gear);
            let inertia = self.tree.subtree_axis_inertia(model, &frames, joint)
                + model.dof_armature()[model.jnt_dofadr()[joint] as usize];
            let kp_cap = (o.swing_stiffness / self.physics_dt).powi(2) * inertia;
            let kp_swing = kp.min(kp_cap);
            let kd_swing = (2.0 * o.damping_ratio * (kp_swing * inertia).sqrt())
                .min(kd.max(0.0) + 2.0 * (kp_swing * inertia).sqrt());
            loops.push(JointLoop {
                command,
                joint,
                qpos_adr: model.jnt_qposadr()[joint] as usize,
                dof: model.jnt_dofadr()[joint] as usize,
                gear,
                limits,
                torque_limits: drive.1,
                servo: drive.0,
                kp,
                kd,
                kp_swing,
                kd_swing,
                leg,
            });
        };
        let mut loops = Vec::new();
        match actuation {
            Actuation::Ctrl => {
                // The one actuator finder (joint transmissions on hinges and slides).
                for a in twin_core::robot::actuators_of(model, &[]) {
                    let Some(joint) = a.joint.filter(|_| a.gear != 0.0) else { continue };
                    push(a.id, joint, a.gear, limits[a.id], drive_of(model, &a), &mut loops);
                }
            }
            Actuation::Qfrc => {
                for joint in 0..model.njnt() {
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    push(dof, joint, 1.0, limits[dof], (None, limits[dof]), &mut loops);
                }
            }
        }
        self.held = Held {
            ff: vec![0.0; loops.len()],
            dq: vec![0.0; loops.len()],
            q_prev: vec![f64::NAN; loops.len()],
            qd_des: vec![0.0; loops.len()],
            ..Held::default()
        };
        self.loops = loops;
    }

    /// Torso roll, pitch (heading frame) and their rates, from the IMU or the base.
    pub(super) fn tilt(&self, observation: &Observation<'_>) -> ([f64; 2], [f64; 2]) {
        let base = self.body.base_qpos;
        let q = observation.qpos;
        let (rot, gyro_world) = match &self.body.imu {
            Some(imu) if imu.quat_adr.is_some() => {
                let a = imu.quat_adr.unwrap_or(0);
                let s = observation.sensordata;
                let site = kin::quat([s[a], s[a + 1], s[a + 2], s[a + 3]]);
                let g = &s[imu.gyro_adr..imu.gyro_adr + 3];
                let gyro = site * Vector3::new(g[0], g[1], g[2]);
                (site * imu.site_rot.inverse(), gyro)
            }
            _ => {
                let r = kin::quat([q[base + 3], q[base + 4], q[base + 5], q[base + 6]]);
                let d = self.body.base_dof;
                let w = observation.qvel;
                (r, r * Vector3::new(w[d + 3], w[d + 4], w[d + 5]))
            }
        };
        let (roll, pitch, yaw) = rot.euler_angles();
        let rate = rotation(-yaw) * Vector2::new(gyro_world.x, gyro_world.y);
        ([roll, pitch], [rate.x, rate.y])
    }

    /// Replans the future steps from the current one (or the rest point when standing).
    pub(super) fn replan(&mut self, t: f64, feet: &[Foothold; 2]) {
        let gait = self.options.gait();
        let horizon = self.preview.horizon() as f64 * self.dt * self.preview_ratio as f64;
        self.schedule.steps.clear();
        self.schedule.settle_secs = gait.ds_secs().max(0.1);
        match self.mode {
            Mode::Standing => {
                self.schedule.rest = (feet[0].pos + feet[1].pos) / 2.0;
                if !self.command.is_zero() {
                    // The first step, where `compute` will start it, so that the preview sees it.
                    let start = t.max(self.options.settle_secs);
                    let swing = self.first_swing(None, feet);
                    let first =
                        self.first_step(start, feet, swing, self.options.start_double_support, self.schedule.rest);
                    self.extend(first, t, horizon);
                }
            }
            Mode::Walking(step) => self.extend(step, t, horizon),
        }
    }

    /// The schedule from `step` on, covering the preview horizon.
    pub(super) fn extend(&mut self, step: Step, t: f64, horizon: f64) {
        let gait = self.options.gait();
        self.schedule.steps.push(step);
        if !self.command.is_zero() {
            let mut prev = step;
            let mut center = gait.center_of(&step.swing_to);
            let mut yaw = step.swing_to.yaw;
            while prev.end() < t + horizon + gait.period {
                let (c, y) = self.next_center(center, yaw);
                let next = Step {
                    start: prev.end(),
                    ds: gait.ds_secs(),
                    ss: gait.period - gait.ds_secs(),
                    zmp_from: prev.zmp_point(),
                    stance: prev.swing_to,
                    swing_from: prev.stance,
                    swing_to: gait.foothold(prev.stance.side, c, y),
                    zmp_inward: gait.zmp_inward,
                };
                (center, yaw) = (c, y);
                self.schedule.steps.push(next);
                prev = next;
            }
        }
        let last = self.schedule.steps.last().copied().unwrap_or(step);
        self.schedule.rest = (last.stance.pos + last.swing_to.pos) / 2.0;
    }

    /// Whether the command walks straight ahead or back (the only one with a line to hold).
    pub(super) fn straight(&self) -> bool {
        self.command.vy == 0.0 && self.command.yaw_rate == 0.0
    }

    /// The next step's centre and heading after `(center, yaw)`: the command's advance plus,
    /// walking straight, a sideways move toward the held line (`line_hold_gain`) and the
    /// held pace's added length (`stride_hold_gain`).
    pub(super) fn next_center(&self, center: Vector2<f64>, yaw: f64) -> (Vector2<f64>, f64) {
        let (mut c, y) = self.options.gait().next_center(center, yaw, &self.command);
        if let (Some((origin, heading)), true) = (self.line, self.straight()) {
            let off_m = (rotation(-heading) * (center - origin)).y;
            let reach = self.options.line_hold_step;
            let dy_m = (-self.options.line_hold_gain * off_m).clamp(-reach, reach);
            c += rotation(heading) * Vector2::new(0.0, dy_m);
        }
        if self.stride_add_m != 0.0 && self.straight() {
            c += rotation(yaw) * Vector2::new(self.stride_add_m, 0.0);
        }
        (c, y)
    }

    /// After the walking step `step` landed its foot at `landed` (`stride_hold_gain`): adds
    /// the gain times its advance's shortfall against the command's to the length every
    /// straight step gets, within ±`stride_hold_step`; other commands (turning, sideways,
    /// standing) start it over.
    pub(super) fn hold_stride(&mut self, step: &Step, landed: &Foothold) {
        let o = &self.options;
        if !self.straight() || self.command.is_zero() {
            self.stride_add_m = 0.0;
            return;
        }
        let advance_m = (rotation(-step.stance.yaw) * (landed.pos - step.stance.pos)).x;
        let asked_m = (self.command.vx * o.step_period).clamp(-o.max_step_length, o.max_step_length);
        let reach = o.stride_hold_step.min((o.max_step_length - asked_m.abs()).max(0.0));
        self.stride_add_m = (self.stride_add_m + o.stride_hold_gain * (asked_m - advance_m)).clamp(-reach, reach);
    }

    /// The first step from standing at `t` with `swing` swinging.
    pub(super) fn first_step(
        &self,
        t: f64,
        feet: &[Foothold; 2],
        swing: Side,
        ds: f64,
        zmp_from: Vector2<f64>,
    ) -> Step {
        let gait = self.options.gait();
        let stance = feet[swing.other().index()];
        let (c, y) = self.next_center(gait.center_of(&stance), stance.yaw);
        Step {
            start: t,
            ds,
            ss: gait.period - gait.ds_secs(),
            zmp_from,
            stance,
            swing_from: feet[swing.index()],
            swing_to: gait.foothold(swing, c, y),
            zmp_inward: gait.zmp_inward,
        }
    }

    /// Where a recovery step of `swing` lands, `secs` before touchdown, with the measured DCM
    /// `dcm`: under the capture point predicted at touchdown (the ZMP held at the `stance`
    /// sole meanwhile), within `max_step_adjust` fore-aft and at least 2/3 of a step width
    /// beside the stance foot (the feet must not cross). Also that predicted capture point.
    pub(super) fn recovery_landing(
        &self,
        stance: &Foothold,
        swing: Side,
        dcm: Vector2<f64>,
        secs: f64,
    ) -> (Vector2<f64>, Vector2<f64>) {
        let o = &self.options;
        let p = self.clamp_to_sole(stance, dcm);
        let xi_td = p + (dcm - p) * (self.omega * secs.max(0.0)).exp();
        let rel = rotation(-stance.yaw) * (xi_td - stance.pos);
        let side = swing.sign();
        let reach = o.max_step_adjust;
        let x = (rel.x * o.step_adjust_gain).clamp(-reach, reach);
        let y = (side * rel.y * o.step_adjust_gain).clamp(o.step_width * 2.0 / 3.0, o.step_width + reach);
        (stance.pos + rotation(stance.yaw) * Vector2::new(x, side * y), xi_td)
    }

    /// How far the capture point predicted at a recovery step's touchdown stays outside the
    /// feet's support once `swing` has landed where [`Walker::recovery_landing`] puts it, m:
    /// 0 when that one step captures the push.
    pub(super) fn recovery_miss(&self, feet: &[Foothold; 2], swing: Side, dcm: Vector2<f64>) -> f64 {
        let o = &self.options;
        let stance = feet[swing.other().index()];
        let secs = o.recovery_double_support_secs + o.recovery_swing_secs;
        let (landing, xi_td) = self.recovery_landing(&stance, swing, dcm, secs);
        let mut landed = [stance; 2];
        landed[swing.index()] = Foothold { side: swing, pos: landing, yaw: stance.yaw };
        (xi_td - self.clamp_to_support(xi_td, &landed)).norm()
    }

    /// Which foot swings first: after a push (`push`: the measured DCM) the one whose step
    /// leaves the capture point predicted at touchdown least outside the feet
    /// ([`Walker::recovery_miss`]): a foot that would have to cross the other to get under it
    /// (a sideways push toward the stance foot) can't, and stepping it in place again and
    /// again lets the DCM run away. When both do equally well, the foot farther from the DCM,
    /// so that the stance foot's ankle holds what it can while the swing foot catches the
    /// rest (stepping with the nearer foot puts the ZMP on the far one, and the DCM runs away
    /// faster than a step can follow); else toward the commanded side or turn.
    pub(super) fn first_swing(&self, push: Option<Vector2<f64>>, feet: &[Foothold; 2]) -> Side {
        match push {
            Some(dcm) => {
                let (ml, mr) = (self.recovery_miss(feet, Side::Left, dcm), self.recovery_miss(feet, Side::Right, dcm));
                if (ml - mr).abs() > RECOVERY_MISS_TIE_M {
                    return if ml < mr { Side::Left } else { Side::Right };
                }
                let gap = |f: &Foothold| (self.clamp_to_sole(f, dcm) - dcm).norm();
                let (gl, gr) = (gap(&feet[0]), gap(&feet[1]));
                if (gl - gr).abs() > 1e-3 {
                    return if gl < gr { Side::Right } else { Side::Left };
                }
                // Equally near (a push straight ahead or back): the foot away from the
                // DCM's sideways offset swings.
                let mid = (feet[0].pos + feet[1].pos) / 2.0;
                let lateral = rotation(-(feet[0].yaw + feet[1].yaw) / 2.0) * (dcm - mid);
                if lateral.y >= 0.0 { Side::Right } else { Side::Left }
            }
            None if self.command.vy < 0.0 || self.command.yaw_rate < 0.0 => Side::Right,
            None => Side::Left,
        }
    }

    /// The walking step `step` with its landing spot, and when the spot alone can't absorb
    /// it its touchdown time, corrected for the measured DCM `dcm` at `t` (Khadiv et al. 2016):
    /// the DCM error against the step's reference as planned ([`Track`]), carried to touchdown
    /// under the stance ankle's ZMP feedback ([`dcm_error_ahead`], stance-foot frame), gives the
    /// DCM at touchdown `ξ_T`; the foot lands at `ξ_T − b`, `b` the plan's offset of the DCM from
    /// the landing foot, within `max_step_adjust` of the planned spot and without crossing the
    /// stance foot. When that bound cuts the correction, an earlier touchdown (down to a
    /// `min_single_support_secs` swing) that leaves less of it uncorrected is taken: the error
    /// grows as `e^(ω·t)` while the foot swings.
    pub(super) fn corrected_step(&self, step: &Step, t: f64, dcm: Vector2<f64>) -> Step {
        let o = &self.options;
        let tr = &self.track;
        let omega = self.omega;
        let planned = Step { ss: tr.end_secs - step.start - step.ds, ..*step };
        let (xi_ref, _) = planned.dcm(t, tr.end_dcm, omega);
        let to_world = rotation(step.stance.yaw);
        let err = to_world.inverse() * (dcm - xi_ref);
        let half = self.body.legs[step.stance.side.index()].sole_half;
        let gain = 1.0 + o.dcm_zmp_gain / omega;
        let reach = 0.8 * o.step_adjust_ankle;
        let u = step.stance.pos;
        let zmp = step.zmp_point();
        let side = step.swing_to.side.sign();
        let ss_start = step.start + step.ds;
        let earliest = (ss_start + o.min_single_support_secs)
            .max(t + (1.0 - self.swing_s) * o.min_single_support_secs)
            .min(step.end());
        // (uncorrected part, touchdown time, landing spot), from the current touchdown on.
        let mut best = (f64::INFINITY, step.end(), step.swing_to.pos);
        const CANDIDATES: usize = 6;
        for k in 0..CANDIDATES {
            let end = step.end() - (step.end() - earliest) * k as f64 / (CANDIDATES - 1) as f64;
            let tau = (end - t).max(0.0);
            let ahead = Vector2::new(
                dcm_error_ahead(err.x, reach * half[0], gain, omega, tau),
                dcm_error_ahead(err.y, reach * half[1], gain, omega, tau),
            );
            let xi_td = zmp + (tr.end_dcm - zmp) * (omega * (end - tr.end_secs)).exp() + to_world * ahead;
            let wanted = (xi_td - tr.end_dcm) * o.step_adjust_gain;
            let mut adjust = wanted;
            if adjust.norm() > o.max_step_adjust {
                adjust *= o.max_step_adjust / adjust.norm();
            }
            // Keep the feet from crossing: at least 2/3 of the step width apart sideways.
            let rel = to_world.inverse() * (tr.landing + adjust - u);
            let lateral = side * (side * rel.y).max(o.step_width * 2.0 / 3.0);
            let target = u + to_world * Vector2::new(rel.x, lateral);
            let left = (tr.landing + wanted - target).norm();
            // A later touchdown unless an earlier one leaves at least 1 mm less.
            if left < best.0 - 1e-3 {
                best = (left, end, target);
            }
            if left < 1e-3 || end <= earliest {
                break;
            }
        }
        Step { ss: best.1 - ss_start, swing_to: Foothold { pos: best.2, ..step.swing_to }, ..*step }
    }

    /// The walking step `step` with its landing spot moved fore-aft by `progress_hold_gain` of
    /// the gap between its stance foot as aimed (`aimed`, the previous step's corrected landing
    /// spot) and as landed, at most `max_step_adjust`: the advance the command asks for then
    /// counts from the aim, so a foot that lands past its spot doesn't lengthen every step.
    pub(super) fn progress_held(&self, step: Step, aimed: &Foothold) -> Step {
        let o = &self.options;
        if aimed.side != step.stance.side {
            return step;
        }
        let to_world = rotation(step.stance.yaw);
        let past_m = (to_world.inverse() * (step.stance.pos - aimed.pos)).x;
        let back_m = (-o.progress_hold_gain * past_m).clamp(-o.max_step_adjust, o.max_step_adjust);
        let pos = step.swing_to.pos + to_world * Vector2::new(back_m, 0.0);
        Step { swing_to: Foothold { pos, ..step.swing_to }, ..step }
    }

    /// Advances the steering target's integral (`command_hold_gain`) to `t` with the target
    /// `goal` while walking (not recovering from a push); standing, or with no target (a
    /// constant command), restarts it at the feet `feet` (their midpoint and mean heading).
    pub(super) fn integrate_hold(&mut self, goal: Option<Command>, t: f64, feet: &[Foothold; 2]) {
        if let (Some(asked), Mode::Walking(_), false) = (goal, self.mode, self.recovering) {
            let dt = t - self.hold_secs;
            let mid_yaw = self.hold.1 + asked.yaw_rate * dt / 2.0;
            self.hold.0 += rotation(mid_yaw) * Vector2::new(asked.vx, asked.vy) * dt;
            self.hold.1 += asked.yaw_rate * dt;
        } else {
            let heading = feet[0].yaw + wrap(feet[1].yaw - feet[0].yaw) / 2.0;
            self.hold = ((feet[0].pos + feet[1].pos) / 2.0, heading);
        }
        self.asked = goal;
        self.hold_secs = t;
    }

    /// The walking step `step` with its landing moved toward where the asked command's
    /// integral will be at its touchdown (`command_hold_gain` of the gap, in position and
    /// heading; the heading measured at the stance foot): a step with a command puts the feet's
    /// centre path there (as the plan's own steps do, a step's advance after the last); a step
    /// with none, which brings the feet side by side to stand, puts their midpoint there, so
    /// that the walker stands where the integral stopped (from the centre path it would stand
    /// half the last step's overshoot past it: the last step is planned before the command
    /// stops). The step's advance stays within the step limits (or within the planned advance,
    /// when it is beyond).
    pub(super) fn command_held(&self, step: Step, a: Command) -> Step {
        let o = &self.options;
        let gait = o.gait();
        let ahead = step.end() - self.hold_secs;
        let ref_yaw = self.hold.1 + a.yaw_rate * ahead;
        let ref_pos = self.hold.0 + rotation(self.hold.1 + a.yaw_rate * ahead / 2.0) * Vector2::new(a.vx, a.vy) * ahead;
        let stance_center = gait.center_of(&step.stance);
        let center = gait.center_of(&step.swing_to);
        // The feet's headings as the stance foot stands, not as planned: feet turn on the ground.
        let stance_yaw = self.foothold_of(&self.frames, step.stance.side.index()).yaw;
        let yaw = step.swing_to.yaw + wrap(stance_yaw - step.stance.yaw);
        let (gap_m, gap_rad) = if self.command.is_zero() {
            let mid_yaw = stance_yaw + wrap(yaw - stance_yaw) / 2.0;
            ((ref_pos - (stance_center + center) / 2.0) * 2.0, 2.0 * wrap(ref_yaw - mid_yaw))
        } else {
            (ref_pos - center, wrap(ref_yaw - yaw))
        };
        let k = o.command_hold_gain;
        let to_stance = rotation(-step.stance.yaw);
        let planned = to_stance * (center - stance_center);
        let held = planned + to_stance * gap_m * k;
        let within = |v: f64, planned: f64, limit: f64| v.clamp((-limit).min(planned), limit.max(planned));
        let advance =
            Vector2::new(within(held.x, planned.x, o.max_step_length), within(held.y, planned.y, o.max_step_lateral));
        let turn_planned = wrap(step.swing_to.yaw - step.stance.yaw);
        let turn = within(turn_planned + k * gap_rad, turn_planned, o.max_step_yaw);
        let swing_to = gait.foothold(
            step.swing_to.side,
            stance_center + rotation(step.stance.yaw) * advance,
            step.stance.yaw + turn,
        );
        Step { swing_to, ..step }
    }

    /// The command of the step about to be planned, moved toward the steering `goal` by at most
    /// the acceleration limits over one step period ([`steer::ramp`]): the steps' advance is
    /// what the command sets, and it changes once per step.
    pub(super) fn steer_step(&mut self, goal: Command) {
        let o = &self.options;
        let next = steer::ramp(self.command, goal, o.step_period, o.max_accel_mps2, o.max_yaw_accel_radps2);
        if next != self.command {
            self.set_command(next);
        }
    }

    /// Starts a step with `swing` swinging from the feet `feet` at `t`.
    pub(super) fn start_step(&mut self, t: f64, feet: &[Foothold; 2], swing: Side, ds: f64, zmp_from: Vector2<f64>) {
        let mut step = self.first_step(t, feet, swing, ds, zmp_from);
        if let (Mode::Walking(prev), false) = (self.mode, self.recovering) {
            step = self.progress_held(step, &prev.swing_to);
        }
        if let (Some(asked), false, true) = (self.asked, self.recovering, self.options.command_hold_gain > 0.0) {
            step = self.command_held(step, asked);
        }
        if self.recovering {
            // A recovery step: quick, since the DCM diverges meanwhile.
            step.ds = self.options.recovery_double_support_secs;
            step.ss = self.options.recovery_swing_secs;
            // Its ZMP goes where the DCM needs it, not to a planned point.
            step.zmp_inward = 0.0;
        }
        self.mode = Mode::Walking(step);
        self.step_zero = self.command.is_zero();
        self.swing_s = 0.0;
        self.swing_t = t;
        self.touchdown_planned = None;
        self.search[swing.index()] = None;
        self.landing[swing.index()] = None;
        self.state.steps += 1;
    }
}

impl Walker {
    /// Feet whose step ended before they landed (`touchdown_from_contact`): each one's target
    /// goes on down from where it was to land until it lands or has gone `touchdown_reach_m`
    /// down; then its sole's height is the ground under it. Updates `foot_ground` and the
    /// soles' motion state.
    pub(super) fn landing_feet(
        &mut self,
        sensordata: &[f64],
        t: f64,
        foot_ground: &mut [f64; 2],
        swinging: Option<usize>,
    ) {
        let z = [self.sole_world(&self.frames, 0).z, self.sole_world(&self.frames, 1).z];
        self.contact.update(z, self.dt);
        for leg in 0..2 {
            let (Some(planned), Some((_, base))) = (self.landing[leg], self.search[leg]) else { continue };
            if swinging == Some(leg) {
                continue;
            }
            let gap = z[leg] - self.target_z[leg];
            if self.contact.landed(leg, sensordata, 1.0, gap, true) {
                self.foot_landed(leg, t, planned, true);
            } else if self.search_depth(leg, t) >= self.options.touchdown_reach_m {
                self.foot_landed(leg, t, planned, false);
            } else {
                foot_ground[leg] = base - self.search_depth(leg, t);
            }
        }
    }

    /// The part of a step's swing in which its foot's profile comes down to where it is to
    /// land: all of it, or [`TOUCHDOWN_PROFILE_END`] with `touchdown_from_contact`.
    pub(super) fn profile_end(&self) -> f64 {
        if self.options.touchdown_from_contact { TOUCHDOWN_PROFILE_END } else { 1.0 }
    }

    /// The current step's end moved by its swing foot's contact (`touchdown_from_contact`):
    /// to now when the foot has landed, past now while a late foot goes on down looking for
    /// the ground (until it has gone `touchdown_reach_m` below its planned height).
    pub(super) fn touchdown_timing(&mut self, mut step: Step, t: f64, sensordata: &[f64]) -> Step {
        let leg = step.swing_to.side.index();
        let gap = self.sole_world(&self.frames, leg).z - self.target_z[leg];
        if self.contact.landed(leg, sensordata, self.swing_s, gap, self.search[leg].is_some()) {
            self.touchdown_planned.get_or_insert(step.end());
            step.ss = step.ss.min((t - step.start - step.ds).max(0.0));
        }
        step
    }

    /// A foot landed (`touchdown_from_contact`): its sole's height is the ground under it, and
    /// the touch-down is logged.
    pub(super) fn foot_landed(&mut self, leg: usize, t: f64, planned_secs: f64, from_contact: bool) {
        let sole = self.sole_world(&self.frames, leg);
        self.ground_z[leg] = self.ground_at(sole.z);
        self.search[leg] = None;
        self.landing[leg] = None;
        self.log_touchdown(TouchdownEvent {
            time_secs: t,
            planned_secs,
            leg,
            sole_world_m: [sole.x, sole.y, sole.z],
            from_contact,
            ground_m: self.ground_z[leg],
            ground_secs: t,
        });
    }

    /// Keeps `event` in [`WalkerState::touchdowns`] (the last [`MAX_TOUCHDOWN_LOG`]).
    pub(super) fn log_touchdown(&mut self, event: TouchdownEvent) {
        if self.state.touchdowns.len() >= MAX_TOUCHDOWN_LOG {
            self.state.touchdowns.remove(0);
        }
        self.state.touchdowns.push(event);
    }

    /// How far below where it was to land foot `leg`'s target has gone looking for the
    /// ground at `t`, m (0 when it is not looking).
    pub(super) fn search_depth(&self, leg: usize, t: f64) -> f64 {
        self.search[leg]
            .map_or(0.0, |(from, _)| (TOUCHDOWN_SEARCH_MPS * (t - from)).min(self.options.touchdown_reach_m))
    }

    /// The ground `step`'s swing foot is to land on (`follow_ground`): the stance foot's,
    /// going on rising or falling as under the last footholds (`ground_slope_gain`).
    pub(super) fn landing_ground(&self, step: &Step) -> f64 {
        let mut other = self.ground_z[step.stance.side.index()];
        if self.options.ground_slope_gain != 0.0 {
            let along = Vector2::new(step.stance.yaw.cos(), step.stance.yaw.sin());
            other += self.options.ground_slope_gain
                * self.ground_slope(along)
                * (step.swing_to.pos - step.stance.pos).dot(&along);
        }
        other
    }

    /// The ground a sole resting at height `z` (world, m) stands on: the starting soles' level
    /// within [`GROUND_DEADBAND_M`] of it (flat ground), else `z`.
    pub(super) fn ground_at(&self, z: f64) -> f64 {
        if (z - self.sole_z).abs() <= GROUND_DEADBAND_M { self.sole_z } else { z }
    }

    /// Whether foot `leg`'s sole rests on the ground (`follow_ground`): level within
    /// [`GROUND_READ_MAX_TILT_RAD`] (not on an edge, heel or toe) and still for
    /// [`GROUND_READ_STILL_SECS`].
    pub(super) fn sole_at_rest(&self, leg: usize) -> bool {
        let l = &self.body.legs[leg];
        let sole_up = self.frames.xrot[l.foot] * l.foot_rot_home.inverse() * Vector3::z();
        sole_up.z >= GROUND_READ_MAX_TILT_RAD.cos() && self.sole_still_secs[leg] >= GROUND_READ_STILL_SECS
    }

    /// Whether the ground under the footholds rises: the stance foot's last mid-stance read is
    /// more than [`GROUND_RISE_M`] above its previous one (false without reads).
    pub(super) fn ground_rising(&self) -> bool {
        matches!(self.ground_reads, [Some((_, z0)), _, Some((_, z2))] if z2 - z0 > GROUND_RISE_M)
    }

    /// The ground's slope along `along` (a unit vector) under the last three ground reads,
    /// rise per metre: the mean of the last two steps' slopes when they agree in sign and
    /// within [`GROUND_SLOPE_AGREEMENT`] of the steeper, each step at least
    /// [`GROUND_SLOPE_MIN_BASE_M`] long; 0 otherwise (a single step up, rough ground, flat).
    pub(super) fn ground_slope(&self, along: Vector2<f64>) -> f64 {
        let [Some((p0, z0)), Some((p1, z1)), Some((p2, z2))] = self.ground_reads else { return 0.0 };
        let (d0, d1) = ((p1 - p0).dot(&along), (p2 - p1).dot(&along));
        if d0.abs() < GROUND_SLOPE_MIN_BASE_M || d1.abs() < GROUND_SLOPE_MIN_BASE_M {
            return 0.0;
        }
        let (s0, s1) = ((z1 - z0) / d0, (z2 - z1) / d1);
        let steeper = s0.abs().max(s1.abs());
        if s0 * s1 <= 0.0 || (s1 - s0).abs() > GROUND_SLOPE_AGREEMENT * steeper {
            return 0.0;
        }
        ((s0 + s1) / 2.0).clamp(-MAX_GROUND_SLOPE, MAX_GROUND_SLOPE)
    }
}

/// Smoothstep on [0, 1].
pub(super) fn smooth(a: f64) -> f64 {
    let a = a.clamp(0.0, 1.0);
    a * a * (3.0 - 2.0 * a)
}
