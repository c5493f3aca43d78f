//! The walker as a [`Controller`]: `reset` seats it on the observed pose, `compute` runs one
//! control tick (state, footsteps, swing and stance, balance, joint commands) and its topics
//! publish the diagnostics.

use super::*;

impl Controller for Walker {
    fn name(&self) -> &'static str {
        "walk"
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        // Masses, inertias and gains may differ per episode (randomization): rebuild for `model`.
        // A schedule starts over; a live target and a set command carry on.
        let command = if self.options.commands.is_empty() { self.command } else { self.options.command() };
        let (steer_target, clamped) = (self.steer_target, self.state.commands_clamped);
        *self = Walker::build(model, WalkOptions::clone(&self.options), false)?;
        self.command = command;
        self.steer_target = steer_target;
        self.t0 = observation.time_secs;
        self.tree.forward(observation.qpos, &mut self.frames);
        let com = self.frames.com();
        self.axes = [PreviewAxis::at(com.x), PreviewAxis::at(com.y)];
        self.com_prev = None;
        self.com_vel = Vector3::zeros();
        let pelvis = self.frames.xpos[self.body.pelvis];
        let yaw = self.frames.xrot[self.body.pelvis].euler_angles().2;
        let d = rotation(-yaw) * Vector2::new(pelvis.x - com.x, pelvis.y - com.y);
        self.pelvis_from_com = Vector3::new(d.x, d.y, pelvis.z - com.z);
        self.pelvis_z0 = pelvis.z;
        self.sole_z = (self.sole_world(&self.frames, 0).z + self.sole_world(&self.frames, 1).z) / 2.0;
        // `com_height` is above the ground under the feet at the start when following the
        // ground (a start on a step or a hill), above the floor (z = 0) otherwise.
        let start_ground = if self.options.follow_ground { self.sole_z } else { 0.0 };
        self.pelvis_z = start_ground + self.options.com_height + (pelvis.z - com.z);
        self.ground_z = [self.sole_z; 2];
        self.ground_ref = 0.0;
        self.ground_pitch = 0.0;
        self.ground_reads = [None; 3];
        self.ground_read_done = false;
        self.sole_still_secs = [0.0; 2];
        self.ground_pending = [false; 2];
        self.sole_prev_z = [self.sole_world(&self.frames, 0).z, self.sole_world(&self.frames, 1).z];
        for ik in &self.ik {
            for k in 0..ik.len() {
                let a = ik.qpos_adr(k);
                self.q_des[a] = observation.qpos[a];
            }
        }
        self.mode = Mode::Standing;
        let feet = [self.foothold_of(&self.frames, 0), self.foothold_of(&self.frames, 1)];
        self.planted = feet;
        self.schedule = Schedule::default();
        self.replan(0.0, &feet);
        self.schedule.rest_from = self.schedule.rest;
        self.tick = 0;
        self.state = WalkerState { commands_clamped: clamped, ..WalkerState::default() };
        Ok(())
    }

    fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        if self.tick > 0 && self.held.since + 1 < self.options.plan_every_ticks {
            // Between solves (`plan_every_ticks`): the joint PD, toward the last solve's
            // targets moved by the tilt feedback since.
            self.held.since += 1;
            self.hold_targets(observation);
            self.joint_torques(observation, command);
            self.publish_diagnostics(observation.time_secs);
            self.physics_tick += 1;
            return;
        }
        let t = observation.time_secs - self.t0;
        let o = Arc::clone(&self.options);
        let gait = o.gait();
        // 0. Steering: the live target or the schedule's, taken step by step (below).
        let goal = self.steer_target.or_else(|| steer::scheduled(&o.commands, t));
        // 1. State.
        self.tree.forward(observation.qpos, &mut self.frames);
        let com = self.frames.com();
        if let Some(prev) = self.com_prev {
            let raw = (com - prev) / self.dt;
            let alpha = self.dt / (self.dt + 0.01);
            self.com_vel += (raw - self.com_vel) * alpha;
        }
        self.com_prev = Some(com);
        let dcm = Vector2::new(com.x + self.com_vel.x / self.omega, com.y + self.com_vel.y / self.omega);
        let feet = [self.foothold_of(&self.frames, 0), self.foothold_of(&self.frames, 1)];
        if o.command_hold_gain > 0.0 {
            self.integrate_hold(goal, t, &feet);
        }

        // 3. Step timing: touchdown, start, stop.
        let mut replan = self.tick == 0;
        // A walking step (not a recovery one) started: its reference is set after the replan.
        let mut new_step = false;
        match self.mode {
            Mode::Standing => {
                let ready = t >= o.settle_secs;
                if let (Some(goal), true) = (goal, ready) {
                    self.steer_step(goal);
                }
                let push = ready && !self.inside_support(dcm, &feet, o.recovery_margin);
                if push {
                    self.recovering = true;
                    // Plan from where the push left the body: the reference restarts at the
                    // measured CoM state, so the feedback does not pull it back to a stale one.
                    self.restart_preview(com);
                }
                if ready && !push && !self.command.is_zero() && self.straight() && self.line.is_none() {
                    // The line to hold: through the feet's midpoint along their mean heading.
                    let heading = feet[0].yaw + wrap(feet[1].yaw - feet[0].yaw) / 2.0;
                    self.line = Some(((feet[0].pos + feet[1].pos) / 2.0, heading));
                }
                if ready && (!self.command.is_zero() || push) {
                    // Step toward where the body is falling, or as planned.
                    let swing = self.first_swing(push.then_some(dcm), &feet);
                    let ds = o.start_double_support;
                    let zmp_from = self.schedule.zmp(t, &mut 0);
                    self.start_step(t, &feet, swing, ds, zmp_from);
                    replan = true;
                    if !push {
                        (self.first_step, self.first_swing_off_m) = (true, 0.0);
                        // Walking takes over the preview's CoM reference where it is.
                        self.track.com = Vector2::new(self.axes[0].x[0], self.axes[1].x[0]);
                        new_step = true;
                    }
                }
            }
            Mode::Walking(mut step) => {
                if o.touchdown_from_contact {
                    step = self.touchdown_timing(step, t, observation.sensordata);
                    self.mode = Mode::Walking(step);
                }
                if t >= step.end() {
                    if std::mem::take(&mut self.first_step) && !self.recovering {
                        let sole_m = 2.0 * self.body.legs[step.swing_to.side.index()].sole_half[0];
                        self.track_swing_velocity |= self.first_swing_off_m > o.swing_miss_fraction * sole_m;
                    }
                    if let (Some(goal), false) = (goal, self.recovering) {
                        self.steer_step(goal);
                    }
                    // Touchdown: the landed foot is planted where it actually is.
                    let mut now = feet;
                    now[step.stance.side.index()] = step.stance;
                    // The landed foot's heading is the plan's: measured ones let it drift.
                    now[step.swing_to.side.index()].yaw = step.swing_to.yaw;
                    self.planted = now;
                    // Blind on uneven ground: the landed foot's ground is where its sole is.
                    let landed = step.swing_to.side.index();
                    if o.stride_hold_gain > 0.0 && !self.recovering {
                        self.hold_stride(&step, &feet[landed]);
                    }
                    if o.touchdown_from_contact {
                        // Landed (ended by contact), or still on its way down: its target goes on
                        // down into the next step until it lands.
                        match self.touchdown_planned {
                            Some(planned) => self.foot_landed(landed, t, planned, true),
                            None => {
                                self.landing[landed] = Some(step.end());
                                self.search[landed] = Some((t, self.target_z[landed]));
                            }
                        }
                    } else {
                        let sole = self.sole_world(&self.frames, landed);
                        // In the air: by the foot's sensors where it has them, else still coming down.
                        let airborne = match self.contact.on_ground(landed, observation.sensordata) {
                            Some(on) => !on,
                            None => sole.z - self.sole_prev_z[landed] < -GROUND_READ_MAX_SPEED_MPS * self.dt,
                        };
                        if o.follow_ground && o.landing_read_at_rest && airborne {
                            // In the air: the ground it aimed at, until it is down and still.
                            self.ground_z[landed] = self.landing_ground(&step);
                            self.ground_pending[landed] = true;
                        } else if o.follow_ground {
                            self.ground_z[landed] = self.ground_at(sole.z);
                        }
                        self.log_touchdown(TouchdownEvent {
                            time_secs: t,
                            planned_secs: step.end(),
                            leg: landed,
                            sole_world_m: [sole.x, sole.y, sole.z],
                            from_contact: false,
                            ground_m: if o.follow_ground { self.ground_z[landed] } else { sole.z },
                            ground_secs: t,
                        });
                    }
                    if self.recovering && self.inside_support(dcm, &now, o.recovery_margin) {
                        // Stop: the ZMP moves from under the DCM to between the feet, and the
                        // reference restarts at the measured state.
                        self.mode = Mode::Standing;
                        self.schedule.steps.clear();
                        self.schedule.rest_from = self.clamp_to_support(dcm, &now);
                        self.schedule.rest_start = t;
                        self.restart_preview(com);
                        self.recovering = false;
                    } else if !self.recovering
                        && self.step_zero
                        && self.command.is_zero()
                        && self.inside_support(dcm, &now, o.recovery_margin)
                    {
                        // Told to stop, and the feet are side by side: stand where they are.
                        self.mode = Mode::Standing;
                        self.schedule.steps.clear();
                        self.schedule.rest_from = self.clamp_to_support(dcm, &now);
                        self.schedule.rest_start = t;
                        self.restart_preview(com);
                    } else {
                        let swing = if self.recovering { self.first_swing(Some(dcm), &now) } else { step.stance.side };
                        self.start_step(t, &now, swing, gait.ds_secs(), step.zmp_point());
                        new_step = !self.recovering;
                    }
                    replan = true;
                } else if self.recovering
                    && step.swing_phase(t) > 0.0
                    && step.swing_phase(t) < o.recovery_reach_fraction * 2.0 / 3.0
                {
                    // Recovery step: land under the capture point predicted at touchdown, moved
                    // until the foot is 2/3 of the way there (later moves would jerk it).
                    let (landing, _) = self.recovery_landing(&step.stance, step.swing_to.side, dcm, step.end() - t);
                    let mut adjusted = step;
                    adjusted.swing_to.pos = landing;
                    self.mode = Mode::Walking(adjusted);
                    replan = true;
                } else if !self.recovering && self.swing_s < o.step_adjust_until * self.profile_end() {
                    let corrected = self.corrected_step(&step, t, dcm);
                    self.mode = Mode::Walking(corrected);
                    // While tracking a walking step only the step itself (the mode) steers; the
                    // schedule after it is telemetry (the planned footholds), rebuilt when the
                    // landing or touchdown has moved by a millimetre or millisecond since.
                    replan = self.schedule.steps.first().is_none_or(|p| {
                        (p.swing_to.pos - corrected.swing_to.pos).norm() > 1e-3
                            || (p.end() - corrected.end()).abs() > 1e-3
                    });
                }
            }
        }
        if replan {
            let rest_from = self.schedule.rest_from;
            let rest_start = self.schedule.rest_start;
            self.replan(t, &feet);
            self.schedule.rest_from = rest_from;
            self.schedule.rest_start = rest_start;
        }
        if new_step && let Mode::Walking(step) = self.mode {
            self.track.end_dcm = self.schedule.first_end_dcm(self.omega);
            self.track.end_secs = step.end();
            self.track.landing = step.swing_to.pos;
        }
        let tracking = matches!(self.mode, Mode::Walking(_)) && !self.recovering;

        // 4. Preview control at its own rate; the CoM reference in between is extrapolated.
        let ratio = self.preview_ratio;
        let pdt = self.dt * ratio as f64;
        if !tracking && self.tick.is_multiple_of(ratio) {
            let mut cursor = 0;
            for j in 0..self.zmp_buf[0].len() {
                let z = self.schedule.zmp(t + j as f64 * pdt, &mut cursor);
                self.zmp_buf[0][j] = z.x;
                self.zmp_buf[1][j] = z.y;
            }
            for a in 0..2 {
                self.axes[a].step(&self.preview, &self.zmp_buf[a]);
            }
        }
        let tau = (self.tick % ratio) as f64 * self.dt;
        let extrapolate = |a: &PreviewAxis| (a.x[0] + a.x[1] * tau + a.x[2] * tau * tau / 2.0, a.x[1] + a.x[2] * tau);
        let (cx, vx) = extrapolate(&self.axes[0]);
        let (cy, vy) = extrapolate(&self.axes[1]);
        let com_ref = Vector2::new(cx, cy);
        let dcm_ref = com_ref + Vector2::new(vx, vy) / self.omega;
        let dcm_err = dcm - dcm_ref;
        let (com_ref, dcm_ref, dcm_err, zmp_ref) = match self.mode {
            Mode::Walking(step) if self.recovering => {
                // Recovery step: no reference to return to. The DCM, with the ZMP on the
                // planned path, reaches `ξ_td` at touchdown; only the part of it outside the
                // support the landing foot will give is an error, corrected through the ZMP
                // (ankles) now.
                let decay = (-self.omega * (step.end() - t).max(0.0)).exp();
                let p = self.clamp_to_sole(&step.stance, dcm);
                let xi_td = p + (dcm - p) / decay;
                let mut landed = [step.stance; 2];
                landed[step.swing_to.side.index()] = step.swing_to;
                let err = (xi_td - self.clamp_to_support(xi_td, &landed)) * decay;
                (com.xy(), dcm - err, err, p)
            }
            Mode::Walking(step) => {
                let end = self.track.end_dcm + (step.swing_to.pos - self.track.landing);
                let (xi_ref, p_ref) = step.dcm(t, end, self.omega);
                let decay = (-self.omega * self.dt).exp();
                self.track.com = xi_ref + (self.track.com - xi_ref) * decay;
                (self.track.com, xi_ref, dcm - xi_ref, p_ref)
            }
            _ => (com_ref, dcm_ref, dcm_err, self.schedule.zmp(t, &mut 0)),
        };
        let zmp_cmd = zmp_ref + dcm_err * (1.0 + o.dcm_zmp_gain / self.omega);
        let com_cmd = com_ref - dcm_err * o.dcm_com_gain;

        // 5. Targets: feet, pelvis.
        let (stance_side, swing) = match self.mode {
            Mode::Walking(step) => (Some(step.stance.side), Some(step)),
            Mode::Standing => (None, None),
        };
        let mut foot_targets = [(self.planted[0], 0.0), (self.planted[1], 0.0)];
        // Ground under each foot target: a swinging foot goes from its own ground to the stance
        // foot's (the ground ahead taken as level with the stance foot's: blind).
        let mut foot_ground = self.ground_z;
        let mut swinging: Option<usize> = None;
        if let Some(step) = swing {
            foot_targets[step.stance.side.index()] = (step.stance, 0.0);
            let s_before = self.swing_s;
            let ss_start = step.start + step.ds;
            if t <= ss_start {
                self.swing_s = 0.0;
            } else {
                // (1 − s) shrinks with the time left, whatever the end is now.
                let (left, before) = (step.end() - t, step.end() - self.swing_t.max(ss_start));
                self.swing_s =
                    if left <= 0.0 || before <= 0.0 { 1.0 } else { 1.0 - (1.0 - self.swing_s) * left / before };
            }
            self.swing_t = t;
            let s = self.swing_s;
            if s_before < GROUND_READ_PHASE[0] {
                self.ground_read_done = false;
            }
            if o.follow_ground
                && o.stance_ground_read
                && !self.ground_read_done
                && (GROUND_READ_PHASE[0]..GROUND_READ_PHASE[1]).contains(&s)
            {
                // In single support the weight is on the stance foot, so it is on the ground:
                // its sole's height is the ground under it (read once a step, in mid stance, so
                // that a foot that landed in the air, or before its ground, is corrected once
                // loaded).
                // A sole tilted beyond any slope the walker follows stands on an edge or a heel:
                // its height is no ground (the landing's read stays).
                let stance = step.stance.side.index();
                let z = self.sole_world(&self.frames, stance).z;
                if self.sole_at_rest(stance) {
                    self.ground_read_done = true;
                    self.ground_pending[stance] = false;
                    self.ground_z[stance] = self.ground_at(z);
                    foot_ground[stance] = self.ground_z[stance];
                    self.ground_reads = [self.ground_reads[1], self.ground_reads[2], Some((feet[stance].pos, z))];
                }
            }
            // From contact, the swing's profile reaches the ground early and the target then goes on
            // down until the foot lands ([`contact::TOUCHDOWN_PROFILE_END`]).
            let s_profile = if o.touchdown_from_contact { s / TOUCHDOWN_PROFILE_END } else { s };
            let (mut blend, lift) = swing_profile(s_profile);
            if self.recovering {
                // A recovery step's foot gets over its landing spot early, then comes down.
                blend = swing_profile(s / o.recovery_reach_fraction).0;
            }
            let from = step.swing_from;
            let to = step.swing_to;
            let pos = from.pos + (to.pos - from.pos) * blend;
            let yaw = from.yaw + wrap(to.yaw - from.yaw) * blend;
            foot_targets[to.side.index()] = (Foothold { side: to.side, pos, yaw }, lift * o.foot_clearance);
            let (own, other) = (self.ground_z[to.side.index()], self.landing_ground(&step));
            foot_ground[to.side.index()] = own + (other - own) * blend;
            if o.step_down_reach > 0.0 && !self.ground_rising() {
                // Late in the swing the foot keeps going down past the stance foot's ground
                // (not on ground known to rise: there it would push the foot into the slope).
                foot_ground[to.side.index()] -= o.step_down_reach * blend;
            }
            if o.swing_holds_at_contact {
                let leg = to.side.index();
                if s < contact::TOUCHDOWN_ARM_PHASE {
                    self.swing_contact_z[leg] = None;
                } else if self.swing_contact_z[leg].is_none()
                    && self.contact.on_ground(leg, observation.sensordata) == Some(true)
                {
                    self.swing_contact_z[leg] = Some(self.sole_world(&self.frames, leg).z);
                }
                if let Some(z) = self.swing_contact_z[leg] {
                    let lift = foot_targets[leg].1;
                    foot_ground[leg] = foot_ground[leg].max(z - lift);
                }
            }
            if s > 0.0 && s < 1.0 {
                swinging = Some(to.side.index());
                if self.first_step {
                    // How far the foot is off its trajectory, along the swing.
                    let along = (to.pos - from.pos).try_normalize(1e-9).unwrap_or_default();
                    let off = (self.sole_world(&self.frames, to.side.index()).xy() - pos).dot(&along);
                    self.first_swing_off_m = self.first_swing_off_m.max(off.abs());
                }
            }
        }
        if o.touchdown_from_contact {
            self.landing_feet(observation.sensordata, t, &mut foot_ground, swinging);
        }
        if o.follow_ground {
            for (leg, ground) in foot_ground.iter_mut().enumerate() {
                let z = self.sole_world(&self.frames, leg).z;
                let moved = (z - self.sole_prev_z[leg]).abs() > GROUND_READ_MAX_SPEED_MPS * self.dt;
                self.sole_still_secs[leg] = if moved { 0.0 } else { self.sole_still_secs[leg] + self.dt };
                self.sole_prev_z[leg] = z;
                if self.ground_pending[leg] && swinging == Some(leg) {
                    self.ground_pending[leg] = false;
                } else if self.ground_pending[leg]
                    && !moved
                    && self.contact.on_ground(leg, observation.sensordata) != Some(false)
                {
                    // A foot that came down after its planned touchdown, now stopped on its ground
                    // (and, with foot sensors, carrying load).
                    self.ground_pending[leg] = false;
                    self.ground_z[leg] = self.ground_at(z);
                    *ground = self.ground_z[leg];
                    if let Some(e) = self.state.touchdowns.iter_mut().rev().find(|e| e.leg == leg) {
                        (e.ground_m, e.ground_secs) = (self.ground_z[leg], t);
                    }
                }
            }
        }
        let yaw_l = foot_targets[0].0.yaw;
        let yaw_r = foot_targets[1].0.yaw;
        let heading = yaw_r + wrap(yaw_l - yaw_r) / 2.0;
        let (tilt_raw, rate_raw) = self.tilt(observation);
        let (lean, tilt, rate) =
            self.hip_lean(zmp_cmd, dcm, &feet, swinging.and(stance_side), heading, tilt_raw, rate_raw);
        // (Without a lean the correction alone, bit for bit.)
        let lean_plus = |k: usize, c: f64| if lean[k] == 0.0 { c } else { lean[k] + c };
        let correction = self.tilt_correction(tilt, rate);
        let pelvis_rot = kin::euler_quat(0.0, 0.0, heading)
            * kin::euler_quat(lean_plus(0, correction[0]), lean_plus(1, correction[1]), 0.0);
        let off = rotation(heading) * self.pelvis_from_com.xy();
        let crouch = smooth(t / o.settle_secs.max(1e-9));
        let pelvis_z = self.pelvis_z0 + (self.pelvis_z - self.pelvis_z0) * crouch;
        // The body rises and sinks with the ground under the planted feet.
        let ground = (self.ground_z[0] + self.ground_z[1]) / 2.0 - self.sole_z;
        self.ground_ref += (ground - self.ground_ref) * (self.dt / (self.dt + GROUND_FOLLOW_SECS));
        let pelvis_pos = Vector3::new(com_cmd.x + off.x, com_cmd.y + off.y, pelvis_z + self.ground_ref);
        // The soles pitched with the ground's slope along the heading between the planted feet
        // (ankles that follow a slope, not stand on a heel), re-estimated only over a base long
        // enough to tell a slope from the reads' errors, and followed gradually.
        if o.ground_pitch_gain != 0.0 {
            let along = Vector2::new(heading.cos(), heading.sin());
            let (d, dz) =
                ((self.planted[0].pos - self.planted[1].pos).dot(&along), self.ground_z[0] - self.ground_z[1]);
            if d.abs() >= GROUND_PITCH_MIN_BASE_M || dz == 0.0 {
                let slope = if dz == 0.0 { 0.0 } else { (dz / d).clamp(-MAX_GROUND_SLOPE, MAX_GROUND_SLOPE) };
                let wanted = -o.ground_pitch_gain * slope.atan();
                self.ground_pitch += (wanted - self.ground_pitch) * (self.dt / (self.dt + GROUND_PITCH_FOLLOW_SECS));
            }
        }
        let ground_pitch = self.ground_pitch;

        // 6. Leg IK, both legs on every solve (the physics steps between solves,
        // `plan_every_ticks`, track the last solution). The measured-pelvis weights move on
        // each solve.
        for (leg, w) in self.measured_frame.iter_mut().enumerate() {
            *w = if o.swing_from_measured_pelvis && swinging == Some(leg) {
                1.0
            } else {
                (*w - self.dt / MEASURED_FRAME_RELEASE_SECS).max(0.0)
            };
        }
        let mut ik_error: f64 = 0.0;
        for (leg, &(f, lift)) in foot_targets.iter().enumerate() {
            let l = &self.body.legs[leg];
            let rot = if ground_pitch == 0.0 {
                kin::euler_quat(0.0, 0.0, f.yaw) * l.foot_rot_home
            } else {
                kin::euler_quat(0.0, 0.0, f.yaw) * kin::euler_quat(0.0, ground_pitch, 0.0) * l.foot_rot_home
            };
            let sole = Vector3::new(f.pos.x, f.pos.y, foot_ground[leg] + lift);
            self.target_z[leg] = sole.z;
            let foot = sole - rot * l.sole_in_foot;
            let w = self.measured_frame[leg];
            let (base_pos, base_rot) = if w > 0.0 {
                let (pos, rot) = (self.frames.xpos[self.body.pelvis], self.frames.xrot[self.body.pelvis]);
                // (Half a turn apart, e.g. fallen over, has no slerp: the measured pose then.)
                (pelvis_pos.lerp(&pos, w), pelvis_rot.try_slerp(&rot, w, 1e-9).unwrap_or(rot))
            } else {
                (pelvis_pos, pelvis_rot)
            };
            let inv = base_rot.inverse();
            let target = (inv * (foot - base_pos), inv * rot);
            let ik = &self.ik[leg];
            let mut q = [0.0; 12];
            let n = ik.len().min(12);
            for (k, qk) in q.iter_mut().enumerate().take(n) {
                *qk = self.q_des[ik.qpos_adr(k)];
            }
            ik.bend_knee(&mut q[..n], 0.05);
            let r = ik.solve(target, &mut q[..n], o.ik_iterations, 1e-3);
            ik_error = ik_error.max(r.position_error_m);
            for (k, qk) in q.iter().enumerate().take(n) {
                self.q_des[ik.qpos_adr(k)] = *qk;
            }
        }
        if o.plan_every_ticks > 1 {
            let against =
                ([tilt_raw[0] - tilt[0], tilt_raw[1] - tilt[1]], [rate_raw[0] - rate[0], rate_raw[1] - rate[1]]);
            self.hold_tilt_map(observation, correction, lean_plus(0, correction[0]), against);
        }
        // The commanded configuration's CoM offset, for the next ticks: refreshed at the
        // preview rate (it changes slowly with the legs' posture; a whole-tree pass per tick
        // was a third of the walker's cost).
        if self.tick.is_multiple_of(ratio) {
            let b = self.body.base_qpos;
            self.q_des[b..b + 3].copy_from_slice(pelvis_pos.as_slice());
            let qq = pelvis_rot.into_inner();
            self.q_des[b + 3..b + 7].copy_from_slice(&[qq.w, qq.i, qq.j, qq.k]);
            let c = self.tree.com(&self.q_des, &mut self.desired);
            let d = rotation(-heading) * Vector2::new(pelvis_pos.x - c.x, pelvis_pos.y - c.y);
            self.pelvis_from_com = Vector3::new(d.x, d.y, pelvis_pos.z - c.z);
        }

        // 7. Feed-forward: gravity and the planned contact forces at the commanded ZMP.
        let weight = -self.gravity * self.tree.total_mass_kg;
        let mut forces: [(usize, Vector3<f64>, Vector3<f64>); 2] = [(0, Vector3::zeros(), Vector3::zeros()); 2];
        let nforces;
        let clamp_to_sole = |leg: usize, p: Vector2<f64>| self.clamp_to_sole(&feet[leg], p);
        match (swinging, stance_side) {
            (Some(_), Some(stance)) => {
                let i = stance.index();
                let p = clamp_to_sole(i, zmp_cmd);
                forces[0] = (self.body.legs[i].foot, Vector3::new(p.x, p.y, self.sole_z), weight);
                nforces = 1;
            }
            _ => {
                let (a, b) = (feet[0].pos, feet[1].pos);
                let ab = b - a;
                let alpha = ((zmp_cmd - a).dot(&ab) / ab.norm_squared().max(1e-9)).clamp(0.0, 1.0);
                // What the weight split can't reach (fore-aft, or beyond a foot) the ankles
                // give: each foot's force moves by it within its sole.
                let residual = if o.double_support_ankle { zmp_cmd - (a + ab * alpha) } else { Vector2::zeros() };
                for (k, (leg, w)) in [(0usize, 1.0 - alpha), (1usize, alpha)].into_iter().enumerate() {
                    let p = clamp_to_sole(leg, feet[leg].pos + residual);
                    forces[k] = (self.body.legs[leg].foot, Vector3::new(p.x, p.y, self.sole_z), weight * w);
                }
                nforces = 2;
            }
        }

        self.track_swing_velocity |= o.swing_miss_fraction == 0.0;
        if self.track_swing_velocity {
            // The targets' rate between solves, filtered (the IK's one iteration a solve
            // moves them in small, uneven steps).
            let alpha = self.dt / (self.dt + SWING_VELOCITY_FILTER_SECS);
            let h = &mut self.held;
            for (i, l) in self.loops.iter().enumerate() {
                let q = self.q_des[l.qpos_adr];
                let v = if h.q_prev[i].is_finite() { (q - h.q_prev[i]) / self.dt } else { 0.0 };
                h.qd_des[i] += (v - h.qd_des[i]) * alpha;
                h.q_prev[i] = q;
            }
        }
        // 8. PD + feed-forward.
        self.hold_feed_forward(&forces[..nforces], swinging);
        self.joint_torques(observation, command);

        // Telemetry.
        self.state.com_ref = [com_ref.x, com_ref.y, self.options.com_height];
        self.state.com = [com.x, com.y, com.z];
        self.state.zmp_ref = [zmp_ref.x, zmp_ref.y];
        self.state.zmp_cmd = [zmp_cmd.x, zmp_cmd.y];
        self.state.dcm_ref = [dcm_ref.x, dcm_ref.y];
        self.state.dcm = [dcm.x, dcm.y];
        self.state.walking = matches!(self.mode, Mode::Walking(_));
        self.state.command = [self.command.vx, self.command.vy, self.command.yaw_rate];
        self.state.ik_error_m = ik_error;
        self.state.footholds.clear();
        for s in self.schedule.steps.iter().take(6) {
            self.state.footholds.push((s.swing_to.side, [s.swing_to.pos.x, s.swing_to.pos.y], s.swing_to.yaw));
        }
        self.publish_diagnostics(observation.time_secs);
        self.tick += 1;
        self.physics_tick += 1;
    }

    /// CoM, ZMP and DCM (reference and actual) as points, the planned footsteps as poses, all
    /// in the world (`odom`) frame at 100 Hz: Foxglove and PlotJuggler plot the points'
    /// coordinates, rerun draws them in 3-D with the robot.
    fn topics(&self) -> Vec<twin_core::topics::TopicInfo> {
        use twin_core::log::typed::{PointStamped, PoseArray, RosMessage};
        use twin_core::topics::{Qos, TopicInfo, TopicKind};
        let topic = |name: &str, type_name, k| TopicInfo {
            name: name.to_string(),
            type_name,
            rate_hz: Some(DIAGNOSTICS_RATE_HZ),
            frame_id: "odom".into(),
            qos: Qos::STREAM,
            kind: TopicKind::Controller(k),
        };
        let mut topics: Vec<TopicInfo> =
            DIAGNOSTIC_POINTS.iter().enumerate().map(|(k, n)| topic(n, PointStamped::TYPE_NAME, k)).collect();
        topics.push(topic("/walk/footsteps", PoseArray::TYPE_NAME, DIAGNOSTIC_POINTS.len()));
        topics
    }

    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, twin_core::topics::TypedMessage<'_>)) {
        let d = &self.diagnostics;
        if !d.fresh {
            return;
        }
        for (k, p) in d.points.iter().enumerate() {
            emit(k, d.stamp_nanos, twin_core::topics::TypedMessage::Point(p));
        }
        emit(DIAGNOSTIC_POINTS.len(), d.stamp_nanos, twin_core::topics::TypedMessage::Poses(&d.footsteps));
    }
}
