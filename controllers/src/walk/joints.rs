//! From the walker's targets to joint commands: the hip strategy and lean, feed-forward
//! forces, joint torques through each drive, the torso-tilt loops and the diagnostics it
//! publishes.

use super::*;

impl Walker {
    /// The hip strategy for the model, in its home pose.
    pub(super) fn new_hip(&self, model: &Model) -> hip::HipStrategy {
        let mut frames = self.tree.frames();
        self.tree.forward(&self.nominal, &mut frames);
        hip::HipStrategy::new(model, &self.tree, &frames, &self.body, -self.gravity.z)
    }

    /// The hip strategy's lean of the upper body this tick (roll, pitch, heading frame, rad),
    /// and the torso tilt and rate the tilt feedback acts on: measured against the lean, so
    /// that the feedback holds the commanded lean instead of taking it back. `stance`: the
    /// foot that alone supports (else both do). Zero, and the tilt unchanged, when off.
    ///
    /// What drives it is the commanded ZMP's distance beyond the feet, except during a recovery
    /// step: there the ZMP is planned at the stance sole's edge and the landing spot is to
    /// catch the rest, so the lean acts on the DCM beyond the stance sole and slows it while
    /// the foot swings (the landing spot follows the slower DCM, and lands nearer).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn hip_lean(
        &mut self,
        zmp_cmd: Vector2<f64>,
        dcm: Vector2<f64>,
        feet: &[Foothold; 2],
        stance: Option<Side>,
        heading: f64,
        tilt: [f64; 2],
        rate: [f64; 2],
    ) -> ([f64; 2], [f64; 2], [f64; 2]) {
        let o = &self.options;
        if o.hip_gain == 0.0 {
            return ([0.0; 2], tilt, rate);
        }
        // What the feet give: the forces' points (step 7) are clamped the same way.
        let wanted = if self.recovering && stance.is_some() { dcm } else { zmp_cmd };
        let held = match stance {
            Some(side) => self.clamp_to_sole(&feet[side.index()], wanted),
            None => self.clamp_to_support(wanted, feet),
        };
        let excess = rotation(-heading) * (wanted - held);
        let params =
            hip::HipParams { gain: o.hip_gain, max_lean_rad: o.hip_max_lean_rad, return_secs: o.hip_return_secs };
        let (lean, lean_rate) = self.hip.update(excess, stance.is_some(), self.dt, &params);
        ([lean.x, lean.y], [tilt[0] - lean.x, tilt[1] - lean.y], [rate[0] - lean_rate.x, rate[1] - lean_rate.y])
    }

    /// Each joint loop's feed-forward torque (gravity and the planned contact `forces` at the
    /// observed configuration, `self.frames`) and the swinging leg, kept for the joint PD
    /// ([`Walker::joint_torques`]).
    pub(super) fn hold_feed_forward(
        &mut self,
        forces: &[(usize, Vector3<f64>, Vector3<f64>)],
        swinging: Option<usize>,
    ) {
        self.held.swinging = swinging;
        for (ff, l) in self.held.ff.iter_mut().zip(&self.loops) {
            *ff = self.tree.static_torque(&self.frames, l.joint, self.gravity, forces);
        }
        self.held.since = 0;
    }

    /// The joint PD toward the IK targets plus the held feed-forward, into `command`.
    pub(super) fn joint_torques(&self, observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
        for (i, ((l, &ff), &dq)) in self.loops.iter().zip(&self.held.ff).zip(&self.held.dq).enumerate() {
            let (kp, kd, track) = match (l.leg, self.held.swinging) {
                (Some((leg, _)), Some(s)) if leg == s => (l.kp_swing, l.kd_swing, self.track_swing_velocity),
                _ => (l.kp, l.kd, false),
            };
            // (`dq` is zero on a solve's step.)
            let q_target = self.q_des[l.qpos_adr] + dq;
            let qd_target = if track { self.held.qd_des[i] } else { 0.0 };
            let tau = kp * (q_target - observation.qpos[l.qpos_adr]) - kd * (observation.qvel[l.dof] - qd_target) + ff;
            let u = match &l.servo {
                None => tau / l.gear,
                Some(servo) => servo.command_for(
                    tau / l.gear,
                    l.gear * observation.qpos[l.qpos_adr],
                    l.gear * observation.qvel[l.dof],
                ),
            };
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }

    /// The pelvis's counter-rotation (roll, pitch, heading frame, rad) against the torso's
    /// `tilt` and its `rate` (rad, rad/s), within ±0.2 rad.
    pub(super) fn tilt_correction(&self, tilt: [f64; 2], rate: [f64; 2]) -> [f64; 2] {
        let (o, g) = (&self.options, &self.tilt_rate_gains);
        [
            (-(o.tilt_gain * tilt[0] + g[0] * rate[0])).clamp(-0.2, 0.2),
            (-(o.tilt_gain * tilt[1] + g[1] * rate[1])).clamp(-0.2, 0.2),
        ]
    }

    /// On a solve's step with steps held after it (`plan_every_ticks` > 1): what the steps
    /// until the next solve need to move each leg's targets, just solved, with the tilt
    /// feedback ([`Walker::hold_targets`]). The stance leg carries the pelvis, whose commanded
    /// roll and pitch counter-rotate against the torso's tilt rate, and that loop minds the
    /// delay: held for the steps between solves it lets the walk fall more
    /// (`plan_every_ticks` docs). Linear about the solve ([`LegIk::base_motion_map`], feet held
    /// where they are): the commanded pelvis's correction `correction` (its roll `roll`, lean
    /// included), the tilt and rate offsets it was measured against (`against`) and, for a leg
    /// placed from the measured pelvis (`swing_from_measured_pelvis`), that pose.
    pub(super) fn hold_tilt_map(
        &mut self,
        observation: &Observation<'_>,
        correction: [f64; 2],
        roll: f64,
        against: ([f64; 2], [f64; 2]),
    ) {
        let h = &mut self.held;
        h.correction = correction;
        (h.lean, h.lean_rate) = against;
        h.dq.fill(0.0);
        // Pelvis rotation (in its frame) per unit correction: roll about x; pitch about the
        // pitch axis, y turned by the roll (`euler_quat`: yaw · pitch · roll).
        let (sin_roll, cos_roll) = roll.sin_cos();
        h.pitch_axis = [cos_roll, -sin_roll];
        if self.tick.is_multiple_of(self.tilt_map_every) {
            for (ik, map) in self.ik.iter().zip(h.leg_maps.iter_mut()) {
                let n = ik.len().min(12);
                let mut q = [0.0; 12];
                for (k, qk) in q.iter_mut().enumerate().take(n) {
                    *qk = self.q_des[ik.qpos_adr(k)];
                }
                ik.base_motion_map(&q[..n], 1e-3, &mut map[..n]);
            }
        }
        h.measured = self.measured_frame;
        h.pelvis = h.measured.iter().any(|&w| w > 0.0).then(|| {
            let (q, b) = (observation.qpos, self.body.base_qpos);
            (Vector3::new(q[b], q[b + 1], q[b + 2]), kin::quat([q[b + 3], q[b + 4], q[b + 5], q[b + 6]]))
        });
    }

    /// On a step between solves: each leg's targets moved from the last solve's by the change
    /// of the tilt feedback's pelvis correction since (this step's IMU against the held lean),
    /// and of the measured pelvis pose for a leg placed from it, through the maps of
    /// [`Walker::hold_tilt_map`]; into `held.dq`.
    pub(super) fn hold_targets(&mut self, observation: &Observation<'_>) {
        let (tilt, rate) = self.tilt(observation);
        let h = &self.held;
        let c = self.tilt_correction(
            [tilt[0] - h.lean[0], tilt[1] - h.lean[1]],
            [rate[0] - h.lean_rate[0], rate[1] - h.lean_rate[1]],
        );
        let dc = [c[0] - h.correction[0], c[1] - h.correction[1]];
        // The commanded pelvis's rotation since the solve, in its frame (x, y, z).
        let turn = [dc[0], dc[1] * h.pitch_axis[0], dc[1] * h.pitch_axis[1]];
        // The measured pelvis's motion since the solve, in its frame at the solve: a few
        // milliseconds' rotation is twice the vector part of its quaternion.
        let moved = h.pelvis.map(|(pos0, rot0)| {
            let (q, b) = (observation.qpos, self.body.base_qpos);
            let inv = rot0.inverse();
            let dp = inv * (Vector3::new(q[b], q[b + 1], q[b + 2]) - pos0);
            let dr = (inv * kin::quat([q[b + 3], q[b + 4], q[b + 5], q[b + 6]])).into_inner();
            let s = 2.0f64.copysign(dr.w);
            [dp.x, dp.y, dp.z, s * dr.i, s * dr.j, s * dr.k]
        });
        let h = &mut self.held;
        for (i, l) in self.loops.iter().enumerate() {
            let Some((leg, k)) = l.leg.filter(|&(_, k)| k < 12) else { continue };
            let m = &h.leg_maps[leg][k];
            let w = h.measured[leg];
            let mut dq = (1.0 - w) * (m[3] * turn[0] + m[4] * turn[1] + m[5] * turn[2]);
            if let (Some(v), true) = (&moved, w > 0.0) {
                dq += w * m.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
            }
            h.dq[i] = dq;
        }
    }

    /// Refreshes the diagnostic messages from this tick's state at their rate.
    pub(super) fn publish_diagnostics(&mut self, time_secs: f64) {
        // Counted in physics steps: their rate whatever `plan_every_ticks` (between solves they
        // repeat the last one's state).
        let every = ((1.0 / DIAGNOSTICS_RATE_HZ) / self.physics_dt).round().max(1.0) as u64;
        let d = &mut self.diagnostics;
        d.fresh = self.physics_tick.is_multiple_of(every);
        if !d.fresh {
            return;
        }
        let stamp = (time_secs.max(0.0) * 1e9).round();
        d.stamp_nanos = stamp as u64;
        let s = &self.state;
        let z = self.sole_z;
        let values = [
            s.com,
            s.com_ref,
            [s.zmp_cmd[0], s.zmp_cmd[1], z],
            [s.zmp_ref[0], s.zmp_ref[1], z],
            [s.dcm[0], s.dcm[1], z],
            [s.dcm_ref[0], s.dcm_ref[1], z],
        ];
        for (p, v) in d.points.iter_mut().zip(values) {
            p.header.stamp_nanos = stamp as i64;
            if p.header.frame_id.is_empty() {
                p.header.frame_id = "odom".into();
            }
            p.point = v;
        }
        d.footsteps.header.stamp_nanos = stamp as i64;
        if d.footsteps.header.frame_id.is_empty() {
            d.footsteps.header.frame_id = "odom".into();
        }
        d.footsteps.poses.resize(s.footholds.len(), twin_core::log::typed::Pose::default());
        for (pose, (_, xy, yaw)) in d.footsteps.poses.iter_mut().zip(&s.footholds) {
            pose.position = [xy[0], xy[1], z];
            // (The planned yaws repeat from tick to tick: their sines are kept.)
            let (sin, cos) = kin::kept_sin_cos(yaw / 2.0);
            pose.orientation_xyzw = [0.0, 0.0, sin, cos];
        }
    }
}
