//! Gait metrics, measured from the simulation (model + data) alone, whatever the controller:
//! steps, distance, falls, speed, velocity tracking, foot slip, step length/width error,
//! CoM-over-support margin and cost of transport. [`GaitMetrics`] is an observer of the rollout
//! engine ([`twin_core::engine::Metric`]): [`GaitMetrics::update`] takes in each step's state after
//! the physics step (contacts, body poses and actuator forces of that step).

use super::kin::{Body, BodyNames, Tree};
use super::plan::wrap;
use super::steer;
use twin_core::control::nominal_pose;
use twin_core::engine::{Flow, Measurement, Metric, Observer, StepView};
use twin_core::error::Result;
use twin_core::mj::{Data, Model};

/// What the gait should be (from the command and the gait's options): errors are measured
/// against it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GaitTargets {
    /// Forward velocity command, m/s.
    pub vx: f64,
    /// Leftward velocity command, m/s.
    pub vy: f64,
    /// Yaw-rate command, rad/s.
    pub yaw_rate: f64,
    /// Expected advance of a landing foot past the stance foot, m (`vx · step_period`).
    pub step_length: f64,
    /// Expected lateral distance between the feet, m.
    pub step_width: f64,
}

/// The metrics of a run (see [`GaitMetrics`]).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct GaitSummary {
    /// Simulated time measured, s.
    pub duration_secs: f64,
    /// Touchdowns (a foot landing after at least 0.05 s in the air).
    pub steps: u64,
    /// Net horizontal displacement of the pelvis, m.
    pub distance_m: f64,
    /// Displacement along the initial heading, m.
    pub forward_m: f64,
    /// Displacement across the initial heading (drift), m; signed, left positive.
    pub lateral_m: f64,
    /// Total heading change, rad (unwrapped).
    pub yaw_change_rad: f64,
    /// Whether the robot fell (pelvis below half its initial height, torso tilted over 60°, or
    /// a body other than the feet touching the ground).
    pub fell: bool,
    /// When it fell, s.
    pub fall_time_secs: Option<f64>,
    /// `distance_m` over the time until the fall or the end, m/s.
    pub average_speed_mps: f64,
    /// RMS over 1-s windows of the velocity error (heading frame) against the command, m/s.
    pub velocity_rms_error_mps: f64,
    /// Largest horizontal slide of a foot during one stance (its material point at the
    /// contacts, so rolling on an edge is not slip), m.
    pub slip_max_m: f64,
    /// Mean slide per stance, m.
    pub slip_mean_m: f64,
    /// RMS error of the step length (landing foot's advance past the stance foot), m.
    pub step_length_rms_error_m: f64,
    /// RMS error of the step width, m.
    pub step_width_rms_error_m: f64,
    /// Smallest signed distance of the CoM's ground projection inside the support polygon
    /// (convex hull of the foot contacts), m; negative: outside.
    pub support_margin_min_m: f64,
    /// Mean of that margin, m.
    pub support_margin_mean_m: f64,
    /// Cost of transport: Σ|τ·q̇|·dt / (m·g·distance).
    pub cost_of_transport: f64,
    /// RMS over 1-s windows of the forward velocity's error (heading frame at the window's
    /// start) against the command's mean over the window, m/s.
    pub vx_rms_error_mps: f64,
    /// The same for the leftward velocity, m/s.
    pub vy_rms_error_mps: f64,
    /// The same for the yaw rate, rad/s.
    pub yaw_rate_rms_error_radps: f64,
    /// Per command segment (the whole run for a constant command; each schedule entry, and
    /// the constant command before the first), what was asked and what was done. The body
    /// lags the command by a step or two, so a segment followed by a stop shows the rest of
    /// its motion in the stop's segment: compare a move and the stop after it together.
    pub segments: Vec<SegmentTracking>,
}

/// What one command segment asked and what the robot did over it (the last one until the
/// end or the fall).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct SegmentTracking {
    /// When the segment starts, s from the start.
    pub start_secs: f64,
    /// When it ends (the next command, the fall or the end), s from the start.
    pub end_secs: f64,
    /// Its command: vx, vy (m/s), yaw rate (rad/s).
    pub command: [f64; 3],
    /// `|(vx, vy)|` times the segment's duration, m.
    pub commanded_distance_m: f64,
    /// Net horizontal displacement of the pelvis over the segment, m.
    pub distance_m: f64,
    /// That displacement along the heading at the segment's start, m.
    pub forward_m: f64,
    /// That displacement across the heading at the segment's start (left positive), m.
    pub lateral_m: f64,
    /// `yaw_rate` times the segment's duration, rad.
    pub commanded_angle_rad: f64,
    /// Heading change over the segment (unwrapped), rad.
    pub angle_rad: f64,
}

#[derive(Debug, Clone, Default)]
struct FootTrack {
    in_contact: bool,
    off_secs: f64,
    slip_m: f64,
    /// The foot's pose at the previous step (position, row-major rotation).
    prev_pose: Option<([f64; 3], [f64; 9])>,
    /// Mean contact point of the foot this step, world.
    contact_sum: [f64; 3],
    contact_n: u32,
    stances: u64,
}

/// What a contact with one geom means to the metrics, found once per rollout from the model
/// (the per-step loop over contacts then walks no body tree).
#[derive(Debug, Clone, Copy, PartialEq)]
struct GeomPart {
    /// The geom belongs to the world body (the floor).
    world: bool,
    /// What its body is, when the other geom is the world's.
    body: BodyPart,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum BodyPart {
    /// Not in the robot's subtree (a cup on a table).
    Scene,
    /// Foot `k` (0 left, 1 right).
    Foot(usize),
    /// Any other robot body: its ground contact is a fall.
    Body,
}

/// Each geom's [`GeomPart`] for the robot rooted at `base` with feet `feet`, in `data`'s pose
/// (the start, standing): a foot is its body's subtree (toes) and the bodies of its own leg
/// above it (an ankle link between two ankle joints) whose collision geoms reach within
/// [`FOOT_BAND_M`] of the feet's lowest point, so that a foot of several bodies and collision
/// shapes, named anything, stands on all of them.
fn geom_parts(data: &Data, base: usize, feet: [usize; 2]) -> Vec<GeomPart> {
    let model = data.model();
    let leg_of = |b: usize| -> Option<usize> {
        (0..2).find(|&k| model.in_subtree(feet[k], b)).or_else(|| {
            (0..2).find(|&k| model.in_subtree(b, feet[k]) && !model.in_subtree(b, feet[1 - k]) && b != base)
        })
    };
    let lowest = |g: usize| twin_core::robot::geom_lowest_z(model, data, g);
    let ground = (0..model.ngeom())
        .filter(|&g| feet.contains(&(model.geom_bodyid()[g] as usize)))
        .filter_map(lowest)
        .fold(f64::INFINITY, f64::min);
    (0..model.ngeom())
        .map(|g| {
            let b = model.geom_bodyid()[g] as usize;
            let body = if !model.in_subtree(base, b) {
                BodyPart::Scene
            } else {
                match leg_of(b) {
                    Some(k) if model.in_subtree(feet[k], b) => BodyPart::Foot(k),
                    Some(k) if lowest(g).is_some_and(|z| z <= ground + FOOT_BAND_M) => BodyPart::Foot(k),
                    _ => BodyPart::Body,
                }
            };
            GeomPart { world: b == 0, body }
        })
        .collect()
}

/// A body above a foot in its leg whose collision geoms reach within this of the feet's lowest
/// point when standing is part of that foot ([`geom_parts`]), m.
pub const FOOT_BAND_M: f64 = 0.02;

/// Where the open command segment started: (time s, base position, unwrapped yaw rad, its
/// command, the schedule entries begun).
type OpenSegment = (f64, [f64; 3], f64, [f64; 3], usize);

/// Accumulates [`GaitSummary`] step by step.
#[derive(Debug, Clone)]
pub struct GaitMetrics {
    targets: GaitTargets,
    feet: [usize; 2],
    base: usize,
    mass_kg: f64,
    gravity: f64,
    dt: f64,
    start: Option<([f64; 3], f64, f64)>,
    /// The base's axes that point up and forward at the start, in the base's frame (the
    /// robot's own frames: the base may be turned any way in its model).
    base_up: [f64; 3],
    base_forward: [f64; 3],
    last_yaw: f64,
    yaw_total: f64,
    last_base: [f64; 3],
    time: f64,
    fell_at: Option<f64>,
    foot: [FootTrack; 2],
    slips: Vec<f64>,
    step_len_sq: f64,
    step_width_sq: f64,
    step_samples: u64,
    steps: u64,
    margin_min: f64,
    margin_sum: f64,
    margin_n: u64,
    work_j: f64,
    window: Option<(f64, [f64; 2], f64)>,
    vel_err_sq: f64,
    vel_windows: u64,
    /// The command schedule ([`steer`]); empty: the constant `targets`.
    commands: Vec<[f64; 4]>,
    /// Σ of the command × dt over the current window (vx, vy, yaw rate).
    window_cmd: [f64; 3],
    /// Σ of the squared per-axis window errors (vx, vy, yaw rate).
    axis_err_sq: [f64; 3],
    /// Closed segments, and the open one's start: (time, base, unwrapped yaw, command, the
    /// schedule entries begun so far).
    segments: Vec<SegmentTracking>,
    segment: Option<OpenSegment>,
    hull: Vec<[f64; 2]>,
    /// Scratch of [`support_margin_into`], kept to spare an allocation per step.
    hull_scratch: Vec<[f64; 2]>,
    /// Per geom, found at the first update (see [`GeomPart`]).
    geoms: Vec<GeomPart>,
}

impl GaitMetrics {
    /// Metrics of the robot whose feet and pelvis are those [`Body::find`] finds in `model`
    /// (with `names` overriding).
    ///
    /// # Errors
    /// As [`Body::find`].
    pub fn for_model(model: &Model, names: &BodyNames, targets: GaitTargets) -> Result<GaitMetrics> {
        let tree = Tree::new(model);
        let body = Body::find(model, &tree, &nominal_pose(model), names)?;
        Ok(GaitMetrics::new(model, [body.legs[0].foot, body.legs[1].foot], body.pelvis, targets))
    }

    /// Metrics of feet `feet` (bodies: left, right) and pelvis `base`.
    pub fn new(model: &Model, feet: [usize; 2], base: usize, targets: GaitTargets) -> GaitMetrics {
        GaitMetrics {
            targets,
            feet,
            base,
            mass_kg: model.total_mass_kg(),
            gravity: -model.gravity()[2],
            dt: model.timestep_secs(),
            start: None,
            base_up: [0.0, 0.0, 1.0],
            base_forward: [1.0, 0.0, 0.0],
            last_yaw: 0.0,
            yaw_total: 0.0,
            last_base: [0.0; 3],
            time: 0.0,
            fell_at: None,
            foot: Default::default(),
            slips: Vec::new(),
            step_len_sq: 0.0,
            step_width_sq: 0.0,
            step_samples: 0,
            steps: 0,
            margin_min: f64::INFINITY,
            margin_sum: 0.0,
            margin_n: 0,
            work_j: 0.0,
            window: None,
            vel_err_sq: 0.0,
            vel_windows: 0,
            commands: Vec::new(),
            window_cmd: [0.0; 3],
            axis_err_sq: [0.0; 3],
            segments: Vec::new(),
            segment: None,
            hull: Vec::new(),
            hull_scratch: Vec::new(),
            geoms: Vec::new(),
        }
    }

    /// The same metrics measuring tracking against the command schedule `commands`
    /// (`[t_secs, vx, vy, yaw_rate]`, [`steer`]; before its first time, the targets' command).
    pub fn with_commands(mut self, commands: Vec<[f64; 4]>) -> GaitMetrics {
        self.commands = commands;
        self
    }

    /// The command in force `t_secs` from the start.
    fn command_at(&self, t_secs: f64) -> [f64; 3] {
        match steer::scheduled(&self.commands, t_secs) {
            Some(c) => [c.vx, c.vy, c.yaw_rate],
            None => [self.targets.vx, self.targets.vy, self.targets.yaw_rate],
        }
    }

    /// How many schedule entries have begun by `t_secs`.
    fn entries_begun(&self, t_secs: f64) -> usize {
        self.commands.iter().take_while(|e| e[0] <= t_secs).count()
    }

    /// The open segment's tracking until `t_secs`, the base at `base` and the heading at
    /// `yaw_total`.
    fn segment_until(&self, t_secs: f64, base: [f64; 3], yaw_total: f64) -> Option<SegmentTracking> {
        let (t0, p0, y0, command, _) = self.segment?;
        let start_yaw = self.start.map_or(0.0, |s| s.1) + y0;
        let (s, c) = start_yaw.sin_cos();
        let d = [base[0] - p0[0], base[1] - p0[1]];
        let span = t_secs - t0;
        Some(SegmentTracking {
            start_secs: t0,
            end_secs: t_secs,
            command,
            commanded_distance_m: command[0].hypot(command[1]) * span,
            distance_m: d[0].hypot(d[1]),
            forward_m: c * d[0] + s * d[1],
            lateral_m: -s * d[0] + c * d[1],
            commanded_angle_rad: command[2] * span,
            angle_rad: yaw_total - y0,
        })
    }

    /// Whether a fall was detected.
    pub fn fell(&self) -> bool {
        self.fell_at.is_some()
    }

    /// The heading of the base's forward axis ([`GaitMetrics::base_forward`]), rad.
    fn yaw_of(&self, data: &Data) -> f64 {
        let (m, f) = (data.xmat()[self.base], self.base_forward);
        let x = m[0] * f[0] + m[1] * f[1] + m[2] * f[2];
        let y = m[3] * f[0] + m[4] * f[1] + m[5] * f[2];
        y.atan2(x)
    }

    /// At the start (standing): the base's axis nearest the world's up, and its horizontal axis
    /// nearest the robot's forward (the right foot to the left one, turned a quarter turn
    /// clockwise about up), both in the base's frame. A base frame turned about z (forward its
    /// −x) or lying (up its y) reads as one whose x is forward and z up.
    fn base_axes(&mut self, data: &Data) {
        let m = data.xmat()[self.base];
        // Column j of the row-major rotation: the base's axis j in the world.
        let axis = |j: usize| [m[j], m[3 + j], m[6 + j]];
        let nearest = |dir: [f64; 3], skip: Option<usize>| -> [f64; 3] {
            let mut best = (f64::NEG_INFINITY, [0.0; 3]);
            for j in (0..3).filter(|&j| Some(j) != skip) {
                let a = axis(j);
                let dot = a[0] * dir[0] + a[1] * dir[1] + a[2] * dir[2];
                let mut unit = [0.0; 3];
                unit[j] = dot.signum();
                if dot.abs() > best.0 {
                    best = (dot.abs(), unit);
                }
            }
            best.1
        };
        self.base_up = nearest([0.0, 0.0, 1.0], None);
        let up_index = self.base_up.iter().position(|&u| u != 0.0);
        let (l, r) = (data.xpos()[self.feet[0]], data.xpos()[self.feet[1]]);
        let left = [l[0] - r[0], l[1] - r[1]];
        let n = left[0].hypot(left[1]);
        let forward = if n > 1e-9 { [left[1] / n, -left[0] / n, 0.0] } else { [axis(0)[0], axis(0)[1], 0.0] };
        self.base_forward = nearest(forward, up_index);
    }

    /// How much the base's up axis ([`GaitMetrics::base_up`]) still points up: the cosine of its
    /// tilt from upright.
    fn uprightness(&self, data: &Data) -> f64 {
        let (m, u) = (data.xmat()[self.base], self.base_up);
        m[6] * u[0] + m[7] * u[1] + m[8] * u[2]
    }

    /// Adds a touchdown's step length and width errors: the landed foot at `p` against the
    /// other at `o`, in the heading frame of `yaw`. Out of line: inlined, the compiler took the
    /// heading's `sin_cos` on every step, not only at touchdowns.
    #[inline(never)]
    fn step_geometry(len_sq: &mut f64, width_sq: &mut f64, targets: &GaitTargets, p: [f64; 3], o: [f64; 3], yaw: f64) {
        let (s, c) = yaw.sin_cos();
        let d = [p[0] - o[0], p[1] - o[1]];
        let along = c * d[0] + s * d[1];
        let across = -s * d[0] + c * d[1];
        *len_sq += (along - targets.step_length).powi(2);
        *width_sq += (across.abs() - targets.step_width).powi(2);
    }

    /// Takes in one simulation step (call after `mj_step2`, or after `mj_step`/`forward`).
    pub fn update(&mut self, data: &Data) {
        if self.fell_at.is_some() {
            return;
        }
        let t = data.time_secs();
        let base = data.xpos()[self.base];
        if self.start.is_none() {
            self.base_axes(data);
        }
        let yaw = self.yaw_of(data);
        let Some((origin, _, t0)) = self.start else {
            self.start = Some((base, yaw, t));
            self.last_yaw = yaw;
            self.last_base = base;
            self.window = Some((t, [base[0], base[1]], yaw));
            self.geoms = geom_parts(data, self.base, self.feet);
            self.segment = Some((0.0, base, 0.0, self.command_at(0.0), self.entries_begun(0.0)));
            return;
        };
        self.time = t - t0;
        // Command segments: one closes where the next schedule entry begins.
        let command = self.command_at(self.time);
        let begun = self.entries_begun(self.time);
        if self.segment.is_some_and(|s| s.4 != begun) {
            // At the entry's own time (the pose of the step that reached it).
            let at = self.commands[begun - 1][0];
            self.segments.extend(self.segment_until(at, self.last_base, self.yaw_total));
            self.segment = Some((at, self.last_base, self.yaw_total, command, begun));
        }
        for (sum, c) in self.window_cmd.iter_mut().zip(command) {
            *sum += c * self.dt;
        }
        self.yaw_total += wrap(yaw - self.last_yaw);
        self.last_yaw = yaw;
        self.last_base = base;

        // Falls: low pelvis, tilted torso, or ground contact of another body.
        let up = self.uprightness(data);
        let mut body_on_ground = false;
        let mut foot_contact = [false; 2];
        self.hull.clear();
        // Only where the contacts are matters here, not their forces.
        for (g, position) in data.contact_points() {
            if g[0] < 0 || g[1] < 0 {
                continue;
            }
            let part = [self.geoms[g[0] as usize], self.geoms[g[1] as usize]];
            let robot = if part[0].world {
                part[1].body
            } else if part[1].world {
                part[0].body
            } else {
                continue;
            };
            match robot {
                // Scene objects (a cup on a table) are not the robot.
                BodyPart::Scene => {}
                BodyPart::Foot(k) => {
                    foot_contact[k] = true;
                    self.hull.push([position[0], position[1]]);
                    let track = &mut self.foot[k];
                    for (sum, x) in track.contact_sum.iter_mut().zip(position) {
                        *sum += x;
                    }
                    track.contact_n += 1;
                }
                BodyPart::Body => body_on_ground = true,
            }
        }
        if base[2] < 0.5 * origin[2] || up < 0.5 || body_on_ground {
            self.fell_at = Some(self.time);
            return;
        }

        // Feet: touchdowns, slip, step geometry.
        #[allow(clippy::needless_range_loop)] // k indexes feet, tracks and contacts alike
        for k in 0..2 {
            let p = data.xpos()[self.feet[k]];
            let rot = data.xmat()[self.feet[k]];
            let track = &mut self.foot[k];
            // Slide of the foot's material point at its contacts since the previous step.
            let slide = match (track.prev_pose, track.contact_n) {
                (Some((pp, pr)), n) if n > 0 => {
                    let c = track.contact_sum.map(|v| v / f64::from(n));
                    let d = [c[0] - p[0], c[1] - p[1], c[2] - p[2]];
                    // Body-frame coordinates of the contact point, then where it was before.
                    let local: [f64; 3] =
                        std::array::from_fn(|j| rot[j] * d[0] + rot[3 + j] * d[1] + rot[6 + j] * d[2]);
                    let was: [f64; 3] = std::array::from_fn(|i| {
                        pp[i] + pr[3 * i] * local[0] + pr[3 * i + 1] * local[1] + pr[3 * i + 2] * local[2]
                    });
                    (c[0] - was[0]).hypot(c[1] - was[1])
                }
                _ => 0.0,
            };
            track.prev_pose = Some((p, rot));
            track.contact_sum = [0.0; 3];
            track.contact_n = 0;
            if foot_contact[k] {
                if !track.in_contact {
                    if track.off_secs >= twin_core::engine::observers::TOUCHDOWN_MIN_AIR_SECS {
                        self.steps += 1;
                        let o = data.xpos()[self.feet[1 - k]];
                        Self::step_geometry(&mut self.step_len_sq, &mut self.step_width_sq, &self.targets, p, o, yaw);
                        self.step_samples += 1;
                    }
                    track.in_contact = true;
                    track.slip_m = 0.0;
                } else {
                    track.slip_m += slide;
                }
                track.off_secs = 0.0;
            } else {
                track.off_secs += self.dt;
                if track.in_contact && track.off_secs >= 0.02 {
                    track.in_contact = false;
                    track.stances += 1;
                    self.slips.push(track.slip_m);
                }
            }
        }

        // CoM over the support polygon.
        if !self.hull.is_empty() {
            let com = data.subtree_com()[self.base];
            let margin = support_margin_into(&mut self.hull, [com[0], com[1]], &mut self.hull_scratch);
            self.margin_min = self.margin_min.min(margin);
            self.margin_sum += margin;
            self.margin_n += 1;
        }

        // Mechanical work of the actuators.
        let qvel = data.qvel();
        self.work_j += data.qfrc_actuator().iter().zip(qvel).map(|(f, v)| (f * v).abs()).sum::<f64>() * self.dt;

        // Velocity tracking over 1-s windows.
        if let Some((tw, pw, yw)) = self.window
            && t - tw >= 1.0 - 1e-9
        {
            let span = t - tw;
            let (s, c) = yw.sin_cos();
            let d = [base[0] - pw[0], base[1] - pw[1]];
            let v = [(c * d[0] + s * d[1]) / span, (-s * d[0] + c * d[1]) / span];
            // The command's mean over the window (the constant one exactly, without a schedule).
            let mean = if self.commands.is_empty() {
                [self.targets.vx, self.targets.vy, self.targets.yaw_rate]
            } else {
                self.window_cmd.map(|sum| sum / span)
            };
            let yaw_rate = wrap(yaw - yw) / span;
            self.vel_err_sq += (v[0] - mean[0]).powi(2) + (v[1] - mean[1]).powi(2);
            for (sq, e) in self.axis_err_sq.iter_mut().zip([v[0] - mean[0], v[1] - mean[1], yaw_rate - mean[2]]) {
                *sq += e * e;
            }
            self.window_cmd = [0.0; 3];
            self.vel_windows += 1;
            self.window = Some((t, [base[0], base[1]], yaw));
        }
    }

    /// The metrics so far.
    pub fn summary(&self) -> GaitSummary {
        let Some((origin, heading0, _)) = self.start else { return GaitSummary::default() };
        let d = [self.last_base[0] - origin[0], self.last_base[1] - origin[1]];
        let (s, c) = heading0.sin_cos();
        let distance = d[0].hypot(d[1]);
        let mut slips = self.slips.clone();
        for f in &self.foot {
            if f.in_contact && f.stances > 0 {
                slips.push(f.slip_m);
            }
        }
        let rms = |sq: f64, n: u64| if n > 0 { (sq / n as f64).sqrt() } else { 0.0 };
        GaitSummary {
            duration_secs: self.time,
            steps: self.steps,
            distance_m: distance,
            forward_m: c * d[0] + s * d[1],
            lateral_m: -s * d[0] + c * d[1],
            yaw_change_rad: self.yaw_total,
            fell: self.fell_at.is_some(),
            fall_time_secs: self.fell_at,
            average_speed_mps: if self.time > 0.0 { distance / self.time } else { 0.0 },
            velocity_rms_error_mps: rms(self.vel_err_sq, self.vel_windows),
            slip_max_m: slips.iter().copied().fold(0.0, f64::max),
            slip_mean_m: if slips.is_empty() { 0.0 } else { slips.iter().sum::<f64>() / slips.len() as f64 },
            step_length_rms_error_m: rms(self.step_len_sq, self.step_samples),
            step_width_rms_error_m: rms(self.step_width_sq, self.step_samples),
            support_margin_min_m: if self.margin_n > 0 { self.margin_min } else { 0.0 },
            support_margin_mean_m: if self.margin_n > 0 { self.margin_sum / self.margin_n as f64 } else { 0.0 },
            cost_of_transport: if distance > 1e-3 {
                self.work_j / (self.mass_kg * self.gravity * distance)
            } else {
                f64::INFINITY
            },
            vx_rms_error_mps: rms(self.axis_err_sq[0], self.vel_windows),
            vy_rms_error_mps: rms(self.axis_err_sq[1], self.vel_windows),
            yaw_rate_rms_error_radps: rms(self.axis_err_sq[2], self.vel_windows),
            segments: self
                .segments
                .iter()
                .cloned()
                .chain(self.segment_until(self.time, self.last_base, self.yaw_total))
                .collect(),
        }
    }
}

impl Observer for GaitMetrics {
    /// Starts over on this rollout's model (its mass and timestep may be randomized).
    fn start(&mut self, model: &Model, _data: &Data) -> Result<()> {
        let commands = std::mem::take(&mut self.commands);
        *self = GaitMetrics::new(model, self.feet, self.base, self.targets).with_commands(commands);
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        self.update(step.data);
        Ok(Flow::Continue)
    }
}

impl Metric for GaitMetrics {
    fn measurements(&self) -> Vec<Measurement> {
        self.summary().measurements()
    }
}

impl GaitSummary {
    /// The summary as named measurements (the fall as 0/1).
    pub fn measurements(&self) -> Vec<Measurement> {
        vec![
            Measurement::new("fell", f64::from(u8::from(self.fell)), ""),
            Measurement::new("steps", self.steps as f64, ""),
            Measurement::new("distance", self.distance_m, "m"),
            Measurement::new("forward", self.forward_m, "m"),
            Measurement::new("lateral_drift", self.lateral_m, "m"),
            Measurement::new("heading_change", self.yaw_change_rad, "rad"),
            Measurement::new("average_speed", self.average_speed_mps, "m/s"),
            Measurement::new("velocity_rms_error", self.velocity_rms_error_mps, "m/s"),
            Measurement::new("slip_max", self.slip_max_m, "m"),
            Measurement::new("slip_mean", self.slip_mean_m, "m"),
            Measurement::new("step_length_rms_error", self.step_length_rms_error_m, "m"),
            Measurement::new("step_width_rms_error", self.step_width_rms_error_m, "m"),
            Measurement::new("support_margin_min", self.support_margin_min_m, "m"),
            Measurement::new("cost_of_transport", self.cost_of_transport, ""),
            Measurement::new("vx_rms_error", self.vx_rms_error_mps, "m/s"),
            Measurement::new("vy_rms_error", self.vy_rms_error_mps, "m/s"),
            Measurement::new("yaw_rate_rms_error", self.yaw_rate_rms_error_radps, "rad/s"),
        ]
    }
}

impl std::fmt::Display for GaitSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "gait metrics over {:.2} s:", self.duration_secs)?;
        match self.fall_time_secs {
            Some(t) => writeln!(f, "  fell                    yes, at {t:.2} s")?,
            None => writeln!(f, "  fell                    no")?,
        }
        writeln!(f, "  steps                   {}", self.steps)?;
        writeln!(
            f,
            "  distance                {:.3} m (forward {:.3} m, lateral drift {:.3} m)",
            self.distance_m, self.forward_m, self.lateral_m
        )?;
        writeln!(f, "  heading change          {:.1}°", self.yaw_change_rad.to_degrees())?;
        writeln!(f, "  average speed           {:.3} m/s", self.average_speed_mps)?;
        writeln!(f, "  velocity error (RMS)    {:.3} m/s", self.velocity_rms_error_mps)?;
        writeln!(f, "  foot slip per stance    max {:.4} m, mean {:.4} m", self.slip_max_m, self.slip_mean_m)?;
        writeln!(
            f,
            "  step length/width error {:.3} m / {:.3} m (RMS)",
            self.step_length_rms_error_m, self.step_width_rms_error_m
        )?;
        writeln!(
            f,
            "  CoM support margin      min {:.3} m, mean {:.3} m",
            self.support_margin_min_m, self.support_margin_mean_m
        )?;
        write!(f, "  cost of transport       {:.3}", self.cost_of_transport)?;
        write!(
            f,
            "\n  command tracking (RMS)  vx {:.3} m/s, vy {:.3} m/s, yaw rate {:.3} rad/s",
            self.vx_rms_error_mps, self.vy_rms_error_mps, self.yaw_rate_rms_error_radps
        )?;
        if self.segments.len() > 1 {
            for s in &self.segments {
                write!(
                    f,
                    "\n  {:6.2}–{:6.2} s  cmd ({:.2}, {:.2}, {:.2}): {:.3} of {:.3} m, {:.1}° of {:.1}°",
                    s.start_secs,
                    s.end_secs,
                    s.command[0],
                    s.command[1],
                    s.command[2],
                    s.distance_m,
                    s.commanded_distance_m,
                    s.angle_rad.to_degrees(),
                    s.commanded_angle_rad.to_degrees()
                )?;
            }
        }
        Ok(())
    }
}

/// Signed distance of `p` inside the convex hull of `points` (reordered in place), metres;
/// negative outside. For one or two points: minus the distance to the point / segment.
pub fn support_margin(points: &mut Vec<[f64; 2]>, p: [f64; 2]) -> f64 {
    support_margin_into(points, p, &mut Vec::new())
}

/// [`support_margin`] building the hull in `hull` (cleared first), so that a caller measuring
/// every step reuses one buffer.
fn support_margin_into(points: &mut Vec<[f64; 2]>, p: [f64; 2], hull: &mut Vec<[f64; 2]>) -> f64 {
    // Monotone chain hull.
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    points.dedup_by(|a, b| (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6);
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let seg_dist = |a: [f64; 2], b: [f64; 2]| {
        let ab = [b[0] - a[0], b[1] - a[1]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1];
        let s = if len2 > 0.0 { (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
        (p[0] - a[0] - s * ab[0]).hypot(p[1] - a[1] - s * ab[1])
    };
    if points.len() == 1 {
        return -seg_dist(points[0], points[0]);
    }
    hull.clear();
    for &pt in points.iter() {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], pt) <= 0.0 {
            hull.pop();
        }
        hull.push(pt);
    }
    let lower = hull.len() + 1;
    for &pt in points.iter().rev().skip(1) {
        while hull.len() >= lower && cross(hull[hull.len() - 2], hull[hull.len() - 1], pt) <= 0.0 {
            hull.pop();
        }
        hull.push(pt);
    }
    hull.pop();
    if hull.len() < 3 {
        return -seg_dist(points[0], points[points.len() - 1]);
    }
    let n = hull.len();
    let inside = (0..n).all(|i| cross(hull[i], hull[(i + 1) % n], p) >= 0.0);
    let dist = (0..n).map(|i| seg_dist(hull[i], hull[(i + 1) % n])).fold(f64::INFINITY, f64::min);
    if inside { dist } else { -dist }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn support_margin_is_signed_distance_to_the_hull() {
        let square = || vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]];
        assert!((support_margin(&mut square(), [0.5, 0.4]) - 0.4).abs() < 1e-12);
        assert!((support_margin(&mut square(), [1.5, 0.5]) + 0.5).abs() < 1e-12);
        assert!((support_margin(&mut vec![[0.0, 0.0], [1.0, 0.0]], [0.5, 0.2]) + 0.2).abs() < 1e-12);
    }
}
