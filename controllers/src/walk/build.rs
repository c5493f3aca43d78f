//! Making a [`Walker`] for a robot: finding its legs, feet and joint loops, the gains, and the
//! checks that refuse options the robot can't hold (torque actuators, strength in the crouch,
//! reach of the longest step) before it walks; the walker's public accessors.

use super::*;

impl Walker {
    /// A walker for `model` with `options`.
    ///
    /// # Errors
    /// [`Error::Walk`] when an option is out of range, the model has no legs the walker can
    /// find, or the legs can't reach `max_step_length` at `com_height`.
    pub fn new(model: &Model, options: WalkOptions) -> Result<Walker> {
        Walker::build(model, options, true)
    }

    /// [`Walker::new`]; with `check_fit` false, without refusing the legs' reach and the
    /// actuators' strength: those check the options against the robot, once, when its walker is
    /// made; an episode's copy of the robot (`Controller::reset`: randomized masses move the
    /// CoM a few millimetres) walks with the options its nominal robot was checked for, and how
    /// it walks is the episode's result. Romeo's derived crouch is the one that reaches with its
    /// knees bent enough (`derive`), at the edge of reach: re-checked per episode, one of its
    /// first five randomized copies was refused and the whole batch with it.
    pub(super) fn build(model: &Model, options: WalkOptions, check_fit: bool) -> Result<Walker> {
        options.validate().map_err(|(key, m)| Error::Walk { message: format!("option `{key}` {m}") })?;
        let tree = Tree::new(model);
        let home = nominal_pose(model);
        let body = Body::find(model, &tree, &home, &options.bodies)?;
        let ik = [LegIk::new(model, &body.legs[0]), LegIk::new(model, &body.legs[1])];
        let g = -model.gravity()[2];
        if g.is_nan() || g <= 0.0 {
            return Err(Error::Walk {
                message: format!("gravity must point down (−z); the model's is {:?}", model.gravity()),
            });
        }
        let physics_dt = model.timestep_secs();
        let dt = physics_dt * options.plan_every_ticks as f64;
        // In solves: the preview (and the commanded CoM offset) no more often than at
        // every-step solving, about 5 ms apart in physics steps.
        let preview_ratio = ((0.005 / physics_dt).round() as u64).max(1).div_ceil(options.plan_every_ticks);
        let preview_dt = dt * preview_ratio as f64;
        let horizon = (options.preview_horizon / preview_dt).ceil() as usize;
        let preview =
            PreviewGains::new(preview_dt, options.com_height, g, options.preview_qe, options.preview_r, horizon);
        let contact = ContactSensing::new(model, [body.legs[0].foot, body.legs[1].foot], tree.total_mass_kg * g);
        let mut walker = Walker {
            tree: tree.clone(),
            frames: tree.frames(),
            desired: tree.frames(),
            ik,
            loops: Vec::new(),
            nominal: home.clone(),
            q_des: home,
            gravity: Vector3::new(0.0, 0.0, -g),
            omega: (g / options.com_height).sqrt(),
            dt,
            physics_dt,
            physics_tick: 0,
            preview,
            preview_ratio,
            tilt_map_every: ((TILT_MAP_SECS / dt).round() as u64).max(1),
            axes: [PreviewAxis::default(); 2],
            zmp_buf: [vec![0.0; horizon + 1], vec![0.0; horizon + 1]],
            schedule: Schedule::default(),
            mode: Mode::Standing,
            command: options.command(),
            steer_target: None,
            step_zero: false,
            asked: None,
            hold: (Vector2::zeros(), 0.0),
            hold_secs: 0.0,
            t0: 0.0,
            tick: 0,
            com_prev: None,
            com_vel: Vector3::zeros(),
            pelvis_from_com: Vector3::zeros(),
            pelvis_z0: 0.0,
            pelvis_z: 0.0,
            sole_z: 0.0,
            ground_z: [0.0; 2],
            ground_ref: 0.0,
            ground_pitch: 0.0,
            ground_reads: [None; 3],
            ground_read_done: false,
            sole_prev_z: [0.0; 2],
            sole_still_secs: [0.0; 2],
            ground_pending: [false; 2],
            swing_contact_z: [None; 2],
            stride_add_m: 0.0,
            contact,
            target_z: [0.0; 2],
            touchdown_planned: None,
            search: [None; 2],
            landing: [None; 2],
            state: WalkerState::default(),
            planted: [Foothold { side: Side::Left, pos: Vector2::zeros(), yaw: 0.0 }; 2],
            recovering: false,
            line: None,
            track: Track::default(),
            swing_s: 0.0,
            swing_t: 0.0,
            measured_frame: [0.0; 2],
            track_swing_velocity: false,
            first_step: false,
            first_swing_off_m: 0.0,
            diagnostics: Diagnostics::default(),
            hip: hip::HipStrategy::default(),
            held: Held::default(),
            tilt_rate_gains: [options.tilt_rate_gain; 2],
            body,
            options: Arc::new(options),
        };
        walker.hip = walker.new_hip(model);
        walker.check_torque_actuators(model)?;
        if check_fit {
            walker.check_reach()?;
        }
        walker.build_loops(model);
        if check_fit {
            walker.check_strength(model)?;
        }
        walker.cap_pelvis_damping(model);
        walker.tilt_rate_gains = walker.stable_tilt_rate_gains(model);
        Ok(walker)
    }

    /// The torso-tilt feedback's rate gains (roll, pitch), s: `tilt_rate_gain`, lowered where
    /// the loop it closes would be unstable under the explicit physics step.
    ///
    /// The feedback turns the commanded pelvis against the measured tilt rate; each leg's hip
    /// joint about that axis takes the turn, so the legs' PD acts on the pelvis as a damping
    /// `S · tilt_rate_gain`, `S` the sum of those joints' `kp`. Within one step the pelvis turns
    /// on the inertia `I` that turns rigidly with it ([`Tree::rigid_axis_inertia`]); when the
    /// tilt is measured on a body that turns with it (the IMU's body, or the floating base when
    /// there is no IMU), that damping is stable under the step while `D·dt/(2I)`, with the
    /// joint loops' own margin on that turn, stays below [`TILT_LOOP_MARGIN`] (the Jury bound of [`PdHoldOptions::max_loop_margin`]). A tilt
    /// measured beyond a joint's spring (the shipped humanoid's IMU on its torso, over a waist
    /// pitch joint) closes no loop within a step, and keeps the option's gain.
    ///
    /// Example-robot-data's Unitree G1 (no IMU sensors: the base's orientation; a 3.8-kg pelvis
    /// under a torso on waist roll and pitch joints) at the default 0.05 s chattered at its hips'
    /// effort limits from the first step and fell within 0.7 s, standing; 0.03 s fell in 1.1 s,
    /// 0.02 s stood; this bound alone gave it 0.018 s (pitch) and 0.011 s (roll). The joint
    /// loops on the same turn use their share of the margin first
    /// ([`Walker::cap_pelvis_damping`]): the G1's use all of it, and its rate gains are 0.
    pub(super) fn stable_tilt_rate_gains(&self, model: &Model) -> [f64; 2] {
        let wanted = self.options.tilt_rate_gain;
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let measured = self.tilt_body(model);
        let mut gains = [wanted; 2];
        for (k, gain) in gains.iter_mut().enumerate() {
            let mode = self.pelvis_mode(model, &frames, k);
            if !mode.rigid[measured] || mode.inertia <= 0.0 {
                continue;
            }
            // Per leg, the hip joint (of its first three) most nearly about this axis.
            let axis = mode.axis;
            let stiffness: f64 =
                self.body
                    .legs
                    .iter()
                    .filter_map(|leg| {
                        let hip = leg.joints.iter().take(3).copied().max_by(|&a, &b| {
                            frames.axis[a].dot(&axis).abs().total_cmp(&frames.axis[b].dot(&axis).abs())
                        })?;
                        self.loops.iter().find(|l| l.joint == hip).map(|l| l.kp.max(0.0))
                    })
                    .sum();
            if stiffness > 0.0 {
                // What the joint loops leave of the margin on this mode.
                let left = (TILT_LOOP_MARGIN - mode.loops_margin(&self.loops, self.physics_dt)).max(0.0);
                *gain = wanted.min(left * 2.0 * mode.inertia / (stiffness * self.physics_dt));
            }
        }
        gains
    }

    /// The body the torso tilt is measured on: the IMU's, or the floating base without one.
    pub(super) fn tilt_body(&self, model: &Model) -> usize {
        let pelvis = self.body.pelvis;
        match &self.body.imu {
            Some(imu) if imu.quat_adr.is_some() => model
                .id(ObjType::Sensor, &imu.name)
                .map_or(pelvis, |s| model.site_bodyid()[model.sensor_objid()[s] as usize] as usize),
            _ => pelvis,
        }
    }

    /// The pelvis's turn about its roll (`k` 0) or pitch (1) axis at `frames`, within one
    /// physics step: what turns rigidly with it ([`Tree::rigid_axis_inertia`], the legs
    /// excluded) and each joint loop's share of the turn, the square of its axis's part along
    /// this one for the loops that join the rigid set to what lies beyond a spring (each leg's
    /// three hip joints, a waist joint), 0 for the others.
    pub(super) fn pelvis_mode(&self, model: &Model, frames: &Frames, k: usize) -> PelvisMode {
        let pelvis = self.body.pelvis;
        let axis = frames.xrot[pelvis] * Vector3::ith(k, 1.0);
        let legs: Vec<usize> = self.body.legs.iter().filter_map(|l| l.bodies.first().copied()).collect();
        let (rigid, _) = self.tree.rigid_axis_inertia(model, frames, pelvis, (frames.xpos[pelvis], axis), &legs);
        // Their moment about the axis, each body's own inertia along it (not its mean).
        let (mass, ipos, iquat, principal) =
            (model.body_mass(), model.body_ipos(), model.body_iquat(), model.body_inertia());
        let inertia: f64 = (0..rigid.len())
            .filter(|&b| rigid[b])
            .map(|b| {
                let c = frames.xpos[b] + frames.xrot[b] * Vector3::from(ipos[b]);
                let r = c - frames.xpos[pelvis];
                let perp = r - axis * axis.dot(&r);
                let local = (frames.xrot[b] * kin::quat(iquat[b])).inverse() * axis;
                let own: f64 = (0..3).map(|i| principal[b][i] * local[i] * local[i]).sum();
                mass[b] * perp.norm_squared() + own
            })
            .sum();
        let parent = model.body_parentid();
        let share = self
            .loops
            .iter()
            .map(|l| {
                let b = self.tree.joint_body(l.joint);
                let joins = match l.leg {
                    Some((_, in_chain)) => in_chain < 3,
                    None => !rigid[b] && rigid[parent[b] as usize],
                };
                if joins { frames.axis[l.joint].dot(&axis).powi(2) } else { 0.0 }
            })
            .collect();
        PelvisMode { axis, rigid, inertia, share }
    }

    /// Lowers the damping of the loops that turn the pelvis (hips, waist) where, together,
    /// they would turn it unstably under the explicit physics step, on the axes where the
    /// walker measures the tilt on a body that turns rigidly with the pelvis.
    ///
    /// The gain rule sizes each joint's `kd` on that joint's own inertia (the whole robot
    /// beyond it), but within one step the pelvis turns on what turns rigidly with it
    /// ([`Walker::pelvis_mode`]), and every hip and waist loop damps that turn at once: the
    /// margin `K·dt²/(4I) + D·dt/(2I)` (the Jury bound of [`PdHoldOptions::max_loop_margin`];
    /// `K`, `D` the loops' stiffness and damping on the turn) must stay below
    /// [`TILT_LOOP_MARGIN`]. Above it, the damping of the loops on that turn is scaled down by
    /// the one factor that meets it (the stiffness, which carries the robot, is kept); the
    /// torso-tilt rate loop gets what is left ([`Walker::stable_tilt_rate_gains`]).
    ///
    /// Example-robot-data's Unitree G1 (no IMU: the tilt is the pelvis's own; a 3.8-kg pelvis,
    /// 0.03 kg·m² about its roll and pitch axes, between two hips and a waist whose `kd` were
    /// sized on its 33 kg) had margins of 1.92 (roll) and 1.08 (pitch): its hip pitch, hip roll
    /// and waist torques flipped sign on most physics steps in single support, at the hips'
    /// effort limits (`saturated` 9.5 s of a 12-s turn, 23 s of a 30-s walk; none at a 1-ms
    /// timestep), it fell turning and at 0.2 and 0.3 m/s. Capped (kd × 0.49 on roll, × 0.90 on
    /// pitch) it saturates 0 s, turns 95° and walks at 0.2–0.3 m/s. The same estimate puts the
    /// shipped humanoid's pelvis pitch turn at 3.1 (0.014 kg·m² between hips and waist pitch),
    /// yet it walks (its tilt measured on the torso, beyond the waist's spring), and capping
    /// it there felled it at 1.0 s: the estimate overstates the margin where no feedback of
    /// the walker closes on the pelvis within a step, and the cap is kept to the axes where
    /// one does, as for the tilt-rate bound.
    pub(super) fn cap_pelvis_damping(&mut self, model: &Model) {
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        let dt = self.physics_dt;
        let measured = self.tilt_body(model);
        for k in 0..2 {
            let mode = self.pelvis_mode(model, &frames, k);
            if !mode.rigid[measured] || mode.inertia <= 0.0 {
                continue;
            }
            let (k_term, d_term) = mode.terms(&self.loops, dt);
            if k_term + d_term <= TILT_LOOP_MARGIN || d_term <= 0.0 {
                continue;
            }
            let factor = ((TILT_LOOP_MARGIN - k_term) / d_term).clamp(0.0, 1.0);
            for (l, &w) in self.loops.iter_mut().zip(&mode.share) {
                if w > 0.0 {
                    l.kd *= factor;
                    l.kd_swing = l.kd_swing.min(l.kd);
                }
            }
        }
    }

    /// The options.
    pub fn options(&self) -> &WalkOptions {
        &self.options
    }

    /// What it planned and measured at the last tick.
    pub fn state(&self) -> &WalkerState {
        &self.state
    }

    /// The foot bodies found (left, right) and the pelvis.
    pub fn feet(&self) -> ([usize; 2], usize) {
        ([self.body.legs[0].foot, self.body.legs[1].foot], self.body.pelvis)
    }

    /// Steers toward `target` from now on (a navigation stack's `/cmd_vel`, [`steer`]): the
    /// target is clamped to what the steps allow and reached at the acceleration limits; it
    /// overrides a schedule. A zero target stops the walker: it finishes its step, brings the
    /// feet side by side and stands. Returns whether the target was cut (counted in
    /// [`WalkerState::commands_clamped`]).
    pub fn steer(&mut self, target: Command) -> bool {
        let (target, cut) = steer::clamp(target, &self.options.command_bounds());
        self.state.commands_clamped += u64::from(cut);
        self.steer_target = Some(target);
        cut
    }

    /// The command the steps are planned with now.
    pub fn command(&self) -> Command {
        self.command
    }

    /// Sets a new velocity command (takes effect at the next step).
    pub fn set_command(&mut self, command: Command) {
        self.command = command;
        if !self.straight() {
            self.line = None;
        }
    }

    /// Refuses legs driven by servos the walker can't command a torque through: the walker
    /// computes joint torques (PD toward its IK targets plus the feed-forward that holds the
    /// weight) and sends a position or velocity servo the setpoint whose force is that torque
    /// ([`AffineServo`]), which needs the servo's force law to be affine in its setpoint with no
    /// activation dynamics, and a force limit for the gain rule to scale the loop by.
    pub(super) fn check_torque_actuators(&self, model: &Model) -> Result<()> {
        let legs: Vec<usize> = self.body.legs.iter().flat_map(|l| l.joints.iter().copied()).collect();
        for a in twin_core::robot::actuators_of(model, &[]) {
            let Some(joint) = a.joint.filter(|j| legs.contains(j)) else { continue };
            if a.interface == twin_core::convert::Interface::Effort {
                continue;
            }
            let affine = model.actuator_dyntype()[a.id] == 0
                && model.actuator_gaintype()[a.id] == 0
                && model.actuator_gainprm()[a.id][0] != 0.0;
            let force_limited = a.joint_effort(model).is_finite();
            let what = if !affine {
                "whose force is not an affine function of its setpoint (activation dynamics, or a \
                 gain that is not fixed)"
            } else if !force_limited {
                "with no force limit (`forcerange`), so the walker can't scale its joint loop to \
                 the actuator's strength"
            } else {
                continue;
            };
            return Err(Error::Walk {
                message: format!(
                    "the leg joint \"{}\" is driven by a {} servo (actuator \"{}\") {what}: give it \
                     a plain position servo with a force range (the URDF joint's effort limit), or \
                     convert the URDF with torque motors (`twin convert --actuators motor ROBOT.urdf`)",
                    model.name(ObjType::Joint, joint),
                    format!("{:?}", a.interface).to_lowercase(),
                    a.name
                ),
            });
        }
        Ok(())
    }

    /// Refuses a robot whose leg actuators can't hold its weight in the walking crouch: with
    /// the CoM at `com_height` over the middle of the feet where they stand in the home pose,
    /// each sole carrying half the weight at its centre, every leg joint's static torque
    /// ([`Tree::static_torque`]) must lie within what its actuator gives (its command range
    /// times its gear). Walking needs more (a whole leg's share in single support, the ankles'
    /// ZMP work); a robot that can't hold the crouch falls before its first step.
    pub(super) fn check_strength(&self, model: &Model) -> Result<()> {
        for (joint, needed, [lo, hi]) in self.crouch_torques() {
            if needed < lo - 1e-9 || needed > hi + 1e-9 {
                return Err(Error::Walk {
                    message: format!(
                        "the actuator of joint \"{}\" gives {:.1} N·m but holding the robot's {:.1} kg \
                         on both feet with the CoM at com_height {} m takes {:.1} N·m: raise com_height \
                         (a straighter leg needs less), or give the joint a stronger actuator (its \
                         effort limit in the URDF)",
                        model.name(ObjType::Joint, joint),
                        if needed > 0.0 { hi } else { lo },
                        self.tree.total_mass_kg,
                        self.options.com_height,
                        needed
                    ),
                });
            }
        }
        Ok(())
    }

    /// Each leg joint's static torque holding the robot in the walking crouch (as
    /// [`Walker::check_strength`] poses it), N·m, with what its actuator gives, N·m:
    /// (joint, torque, [least, most]).
    pub(super) fn crouch_torques(&self) -> Vec<(usize, f64, [f64; 2])> {
        let HomeCrouch { qpos: home, frames, pelvis_pos, pelvis_z, .. } = self.home_crouch();
        let mut q = home.clone();
        for (leg, ik) in self.ik.iter().enumerate() {
            let sole = self.sole_world(&frames, leg);
            let pelvis = Vector3::new(pelvis_pos.x, pelvis_pos.y, pelvis_z);
            let (ql, _) = self.crouched_leg(leg, &home, sole, pelvis);
            for (k, v) in ql.iter().enumerate() {
                q[ik.qpos_adr(k)] = *v;
            }
        }
        let b = self.body.base_qpos;
        q[b + 2] += pelvis_z - pelvis_pos.z;
        let mut crouched = self.tree.frames();
        self.tree.forward(&q, &mut crouched);
        let weight = -self.gravity * self.tree.total_mass_kg;
        let forces: Vec<(usize, Vector3<f64>, Vector3<f64>)> =
            (0..2).map(|leg| (self.body.legs[leg].foot, self.sole_world(&crouched, leg), weight / 2.0)).collect();
        self.loops
            .iter()
            .filter(|l| l.leg.is_some())
            .map(|l| {
                let needed = self.tree.static_torque(&crouched, l.joint, self.gravity, &forces);
                (l.joint, needed, l.torque_limits)
            })
            .collect()
    }

    /// The legs' static load in the walking crouch: the largest part of its actuator's torque
    /// that a leg joint spends holding the robot on both feet (as the strength check poses it; at
    /// most 1 once the walker is built).
    pub fn crouch_load(&self) -> f64 {
        self.crouch_torques()
            .iter()
            .map(|(_, needed, [lo, hi])| if *needed > 0.0 { needed / hi.max(1e-9) } else { needed / lo.min(-1e-9) })
            .fold(0.0, f64::max)
    }

    /// The home pose and the pelvis height that puts the CoM at `com_height` (what the
    /// strength and reach checks start from).
    pub(super) fn home_crouch(&self) -> HomeCrouch {
        let qpos = self.nominal.clone();
        let mut frames = self.tree.frames();
        self.tree.forward(&qpos, &mut frames);
        let com = frames.com();
        let pelvis_pos = frames.xpos[self.body.pelvis];
        let pelvis_z = self.options.com_height + (pelvis_pos.z - com.z);
        HomeCrouch { qpos, frames, com, pelvis_pos, pelvis_z }
    }

    /// Leg `leg`'s angles (from the home pose `home`, knee bent) that put its sole centre at
    /// `sole` (world, m) in the home foot orientation with the pelvis at `pelvis` (world, m,
    /// home orientation), and the IK's remaining error.
    pub(super) fn crouched_leg(
        &self,
        leg: usize,
        home: &[f64],
        sole: Vector3<f64>,
        pelvis: Vector3<f64>,
    ) -> (Vec<f64>, kin::IkResult) {
        let ik = &self.ik[leg];
        let rot = self.body.legs[leg].foot_rot_home;
        let foot = sole - rot * self.body.legs[leg].sole_in_foot;
        let mut q: Vec<f64> = (0..ik.len()).map(|k| home[ik.qpos_adr(k)]).collect();
        ik.bend_knee(&mut q, 0.5);
        let error = ik.solve((foot - pelvis, rot), &mut q, 200, 1e-3);
        (q, error)
    }

    /// The gait's extreme poses: with the CoM at `com_height` midway between a front and a back
    /// foot `max_step_length` apart (and `step_width` + `max_step_lateral` wide), soles flat in
    /// their home orientation, each leg's IK solution (within the joint ranges) and its
    /// remaining error: (leg, angles, error), each leg in front in turn.
    pub(super) fn extreme_poses(&self) -> Vec<(usize, Vec<f64>, kin::IkResult)> {
        let HomeCrouch { qpos: home, frames, com, pelvis_pos, pelvis_z } = self.home_crouch();
        let sole_z = self.sole_world(&frames, 0).z;
        let o = &self.options;
        let half_len = o.max_step_length / 2.0;
        let half_width = (o.step_width + o.max_step_lateral) / 2.0;
        let offset_x = pelvis_pos.x - com.x;
        let mut poses = Vec::with_capacity(4);
        for front in 0..2 {
            for leg in 0..2 {
                let x = if leg == front { half_len } else { -half_len };
                let y = self.body.legs[leg].side.sign() * half_width;
                let sole = Vector3::new(com.x + x, com.y + y, sole_z);
                let (q, r) = self.crouched_leg(leg, &home, sole, Vector3::new(com.x + offset_x, com.y, pelvis_z));
                poses.push((leg, q, r));
            }
        }
        poses
    }

    /// The least knee bend of the gait's extreme poses ([`LegIk::knee_bend_rad`]), rad: how far
    /// the longest step keeps the legs from the straight knee, where a leg's length stops
    /// following its knee (the crouch of [`derive`](mod@derive)).
    pub fn least_knee_bend_rad(&self) -> f64 {
        self.extreme_poses().iter().map(|(leg, q, _)| self.ik[*leg].knee_bend_rad(q)).fold(f64::INFINITY, f64::min)
    }

    /// Refuses steps the legs can't reach: in every extreme pose of the gait
    /// ([`Walker::extreme_poses`]) both legs' IK must converge.
    pub(super) fn check_reach(&self) -> Result<()> {
        let o = &self.options;
        for (leg, _, r) in self.extreme_poses() {
            if r.position_error_m > 0.005 || r.rotation_error_rad > 0.02 {
                return Err(Error::WalkReach {
                    message: format!(
                        "the {} leg can't reach a step of max_step_length {} m (width {} m) with the CoM at \
                         com_height {} m: its foot stays {:.3} m and {:.3} rad from the target; shorten \
                         max_step_length, or lower com_height",
                        match self.body.legs[leg].side {
                            Side::Left => "left",
                            Side::Right => "right",
                        },
                        o.max_step_length,
                        o.step_width,
                        o.com_height,
                        r.position_error_m,
                        r.rotation_error_rad
                    ),
                });
            }
        }
        Ok(())
    }
}
