//! The design problem of [`super::design`]: a trajectory's variables to its Fourier joints, the
//! criterion (condition number or log-determinant of the scaled base regressor) with its
//! semi-analytic gradient, the limit checks on the fine grid (position, velocity, acceleration,
//! torque, self-collision) and the shrinking that makes a trajectory meet them.

use super::*;

/// The worst limit violation found on a grid.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Violation {
    pub(super) what: String,
    pub(super) excess: f64,
}

/// Evaluation of a trajectory on a grid.
pub(super) struct Eval {
    pub(super) cost: f64,
    pub(super) condition: f64,
    pub(super) scaled_condition: f64,
    pub(super) penalty: f64,
}

/// A trajectory fitted to the limits (with the violation that bound it, if any), or the
/// violation that remains even at rest.
type Fitted = std::result::Result<(Vec<FourierJoint>, Option<Violation>), Violation>;

/// The design problem: model, limits, grid and the fixed base columns.
pub(super) struct Problem<'a> {
    pub(super) robot: &'a RobotModel,
    pub(super) reg: Regressor<'a>,
    pub(super) collide: Option<(Data, Vec<[usize; 2]>)>,
    pub(super) limits: Vec<JointLimits>,
    pub(super) selected: Vec<usize>,
    pub(super) cad: Vec<f64>,
    pub(super) cols: Vec<Vec<usize>>,
    pub(super) ncols: usize,
    pub(super) base_cols: Vec<usize>,
    pub(super) opts: ExciteOptions,
    pub(super) hold: Vec<f64>,
    pub(super) evaluations: usize,
    /// Per body, the excited joints (indices into `selected`) that move it.
    pub(super) body_joints: Vec<Vec<usize>>,
    /// Per excited joint: involved in a violation of the last [`Problem::assess`].
    pub(super) involved: Vec<bool>,
    /// Smoothing of the condition criterion (soft max/min of ln σ with this sharpness), or
    /// `None` for the condition number itself.
    pub(super) beta: Option<f64>,
    /// Inside the search: [`Eval::scaled_condition`] is not computed.
    pub(super) searching: bool,
    /// Where a joint touches its box, differentiate the scaled branch of
    /// [`Problem::box_fit`] (else the unscaled one, which asks for more motion).
    pub(super) touching_scaled: bool,
}

/// Weight of the squared limit violations against the criterion in the search's cost.
pub(super) const PENALTY_WEIGHT: f64 = 100.0;

/// A self-collision's depth that counts as much as a 100 % limit excess, m.
pub(super) const COLLISION_DEPTH_SCALE_M: f64 = 0.01;

/// Free variables per joint: `c`, `a₂…a_H`, `b₂…b_H`.
pub(super) fn vars_per_joint(h: usize) -> usize {
    2 * h - 1
}

pub(super) fn joints_from_vars(x: &[f64], h: usize, template: &[FourierJoint]) -> Vec<FourierJoint> {
    let nv = vars_per_joint(h);
    template.iter().enumerate().map(|(i, t)| joint_from_vars(&x[i * nv..(i + 1) * nv], h, t)).collect()
}

/// One joint's series from its variables `c, a₂…a_H, b₂…b_H` (`a₁`, `b₁` give rest at the ends).
pub(super) fn joint_from_vars(v: &[f64], h: usize, template: &FourierJoint) -> FourierJoint {
    let mut a = vec![0.0; h];
    let mut b = vec![0.0; h];
    for l in 1..h {
        a[l] = v[l];
        b[l] = v[h - 1 + l];
    }
    a[0] = -a[1..].iter().sum::<f64>();
    b[0] = -(1..h).map(|l| (l + 1) as f64 * b[l]).sum::<f64>();
    FourierJoint { name: template.name.clone(), index: template.index, rest: v[0], a, b }
}

pub(super) fn vars_from_joints(joints: &[FourierJoint], h: usize) -> Vec<f64> {
    let mut x = Vec::with_capacity(joints.len() * vars_per_joint(h));
    for f in joints {
        x.push(f.rest);
        x.extend_from_slice(&f.a[1..]);
        x.extend_from_slice(&f.b[1..]);
    }
    x
}

/// Singular values of the columns `cols` of the compressed `rz`, each column scaled to unit
/// norm when `scaled`.
pub(super) fn singular_values(rz: &Mat<f64>, cols: &[usize], scaled: bool) -> Option<Vec<f64>> {
    let n = rz.nrows();
    let norms: Vec<f64> = cols.iter().map(|&c| (0..n).map(|i| rz[(i, c)] * rz[(i, c)]).sum::<f64>().sqrt()).collect();
    if norms.iter().any(|&x| !(x > 0.0 && x.is_finite())) {
        return None;
    }
    let m = Mat::from_fn(n, cols.len(), |i, k| rz[(i, cols[k])] / if scaled { norms[k] } else { 1.0 });
    m.singular_values().ok().filter(|sv| sv.iter().all(|&s| s > 0.0 && s.is_finite()))
}

/// Largest over smallest of `sv`.
pub(super) fn ratio(sv: &[f64]) -> f64 {
    sv.iter().copied().fold(0.0, f64::max) / sv.iter().copied().fold(f64::INFINITY, f64::min)
}

impl<'a> Problem<'a> {
    pub(super) fn omega(&self) -> f64 {
        2.0 * PI * self.opts.base_frequency_hz
    }

    pub(super) fn excitation(&self, joints: Vec<FourierJoint>) -> Excitation {
        Excitation {
            base_frequency_hz: self.opts.base_frequency_hz,
            joints,
            hold: self.hold.clone(),
            joint_names: self.robot.joints.iter().map(|j| j.name.clone()).collect(),
        }
    }

    /// The compressed regressor along `joints` on an `n`-point grid, the squared penalty
    /// and the worst violation.
    pub(super) fn assess(
        &mut self,
        joints: &[FourierJoint],
        n: usize,
        collisions: bool,
    ) -> Result<(Mat<f64>, f64, Option<Violation>)> {
        let nj = self.robot.joints.len();
        let omega = self.omega();
        let period = 1.0 / self.opts.base_frequency_hz;
        let mut acc = Accumulator::new(self.ncols, self.cols.clone());
        let (mut q, mut qd, mut qdd) = (self.hold.clone(), vec![0.0; nj], vec![0.0; nj]);
        let mut rows = Vec::new();
        let mut penalty = 0.0;
        let mut worst: Option<Violation> = None;
        let mut involved = vec![false; self.selected.len()];
        let mut note = |what: String, excess: f64, penalty: &mut f64| {
            *penalty += excess * excess;
            if worst.as_ref().is_none_or(|w| excess > w.excess) {
                worst = Some(Violation { what, excess });
            }
        };
        for k in 0..n {
            let t = k as f64 * period / n as f64;
            for f in joints {
                let (a, b, c) = f.sample(omega, t);
                q[f.index] = a;
                qd[f.index] = b;
                qdd[f.index] = c;
            }
            let tau = self.reg.torques(None, &q, &qd, &qdd, &self.cad, &mut rows)?;
            for (s, &j) in self.selected.iter().enumerate() {
                let lim = &self.limits[s];
                let name = &lim.name;
                if q[j] > lim.upper || q[j] < lim.lower || qd[j].abs() > lim.velocity || qdd[j].abs() > lim.acceleration
                {
                    involved[s] = true;
                }
                if let Some(tmax) = lim.torque
                    && tau[j].abs() > tmax
                {
                    // A joint's torque comes from the motion of every joint: all are shrunk.
                    involved.iter_mut().for_each(|x| *x = true);
                }
                if q[j] > lim.upper {
                    note(
                        format!("joint \"{name}\" position {:.3} above {:.3} at t = {t:.2} s", q[j], lim.upper),
                        (q[j] - lim.upper) / (lim.upper - lim.lower).max(1e-6),
                        &mut penalty,
                    );
                }
                if q[j] < lim.lower {
                    note(
                        format!("joint \"{name}\" position {:.3} below {:.3} at t = {t:.2} s", q[j], lim.lower),
                        (lim.lower - q[j]) / (lim.upper - lim.lower).max(1e-6),
                        &mut penalty,
                    );
                }
                // Velocity, acceleration and torque: how far beyond its limit, as a fraction of it.
                for (what, value, limit, digits) in [
                    ("velocity", qd[j], Some(lim.velocity), 3),
                    ("acceleration", qdd[j], Some(lim.acceleration), 3),
                    ("torque", tau[j], lim.torque, 2),
                ] {
                    if let Some(max) = limit
                        && value.abs() > max
                    {
                        note(
                            format!(
                                "joint \"{name}\" {what} {value:.digits$} beyond its limit {max:.digits$} at t = {t:.2} s"
                            ),
                            value.abs() / max - 1.0,
                            &mut penalty,
                        );
                    }
                }
            }
            let ncols = self.ncols;
            for (s, &j) in self.selected.iter().enumerate() {
                acc.push(s, &rows[j * ncols..(j + 1) * ncols], tau[j]);
            }
            if collisions {
                for (bodies, depth) in self.penetrations(&q)? {
                    // The joints that move one link and not the other.
                    let (a, b) = (&self.body_joints[bodies[0]], &self.body_joints[bodies[1]]);
                    for &x in a.iter().filter(|x| !b.contains(x)).chain(b.iter().filter(|x| !a.contains(x))) {
                        involved[x] = true;
                    }
                    let model = &self.robot.model;
                    note(
                        format!(
                            "links \"{}\" and \"{}\" collide ({:.1} mm deep) at t = {t:.2} s",
                            model.name(ObjType::Body, bodies[0]),
                            model.name(ObjType::Body, bodies[1]),
                            depth * 1e3
                        ),
                        depth / COLLISION_DEPTH_SCALE_M,
                        &mut penalty,
                    );
                }
            }
        }
        acc.finish();
        self.involved = involved;
        let weights = vec![1.0; self.selected.len()];
        Ok((acc.compressed(&weights), penalty, worst))
    }

    /// Self-contacts between links not excepted, at joint positions `q` (every robot joint, rad
    /// or m): the two bodies (sorted) and the penetration depth, m (> 0). None without the
    /// collision check.
    pub(super) fn penetrations(&mut self, q: &[f64]) -> Result<Vec<([usize; 2], f64)>> {
        let Some((data, allowed)) = &mut self.collide else {
            return Ok(Vec::new());
        };
        for (j, joint) in self.robot.joints.iter().enumerate() {
            data.qpos_mut()[joint.qpos_adr] = q[j];
        }
        data.kinematics_collision()?;
        let model = data.model().clone();
        Ok(data
            .contacts()
            .into_iter()
            .filter_map(|(dist, geoms)| {
                let bodies = sorted([
                    model.geom_bodyid()[geoms[0] as usize] as usize,
                    model.geom_bodyid()[geoms[1] as usize] as usize,
                ]);
                (dist < 0.0 && !allowed.contains(&bodies)).then_some((bodies, -dist))
            })
            .collect())
    }

    pub(super) fn evaluate(&mut self, joints: &[FourierJoint]) -> Result<Eval> {
        Ok(self.evaluate_with_matrix(joints)?.0)
    }

    /// [`Problem::evaluate`], and the compressed regressor it was computed from.
    pub(super) fn evaluate_with_matrix(&mut self, joints: &[FourierJoint]) -> Result<(Eval, Mat<f64>)> {
        self.evaluations += 1;
        let (rz, penalty, _) = self.assess(joints, self.opts.samples, self.opts.self_collision)?;
        // The column-scaled figure is only reported (and the log-determinant's): the search
        // under the condition criterion skips its SVD.
        let want_scaled = self.opts.criterion == Criterion::LogDet || !self.searching;
        let scaled = if want_scaled { singular_values(&rz, &self.base_cols, true) } else { Some(Vec::new()) };
        let (condition, scaled_condition, crit) = match (singular_values(&rz, &self.base_cols, false), scaled) {
            (Some(sv), Some(scaled)) => {
                let crit = match self.opts.criterion {
                    Criterion::Condition => match self.beta {
                        // Soft maximum of ln σ minus soft minimum: smooth where singular
                        // values cross, an upper bound on ln cond.
                        Some(beta) => {
                            let lse = |sign: f64| {
                                let m = sv.iter().map(|s| sign * s.ln()).fold(f64::NEG_INFINITY, f64::max);
                                m + sv.iter().map(|s| (beta * (sign * s.ln() - m)).exp()).sum::<f64>().ln() / beta
                            };
                            lse(1.0) + lse(-1.0)
                        }
                        None => ratio(&sv).ln(),
                    },
                    // Log-determinant of the column-scaled matrix: invariant to units.
                    Criterion::LogDet => -2.0 * scaled.iter().map(|s| s.ln()).sum::<f64>() / scaled.len() as f64,
                };
                (ratio(&sv), if want_scaled { ratio(&scaled) } else { f64::NAN }, crit)
            }
            _ => (f64::INFINITY, f64::INFINITY, 100.0),
        };
        Ok((Eval { cost: crit + PENALTY_WEIGHT * penalty, condition, scaled_condition, penalty }, rz))
    }

    /// Scales each joint's deviation from rest to use its position, velocity and acceleration
    /// room (on the fine grid), then shrinks all together until torques and collisions are
    /// within limits. Returns the feasible trajectory, or the violation at rest.
    /// With `per_joint` false, the trajectory is only shrunk as a whole (a random trajectory
    /// as drawn, made feasible).
    pub(super) fn fit_to_limits(&mut self, joints: &[FourierJoint], per_joint: bool) -> Result<Fitted> {
        let n = 4 * self.opts.samples;
        let mut scaled: Vec<FourierJoint> = Vec::with_capacity(joints.len());
        for (f, lim) in joints.iter().zip(&self.limits) {
            let (mut f, room) = self.room(f, lim);
            let s = if !room.is_finite() {
                0.0
            } else if per_joint {
                0.999 * room
            } else {
                room.min(1.0)
            };
            f.scale(s);
            scaled.push(f);
        }
        let shrink = |js: &[FourierJoint], s: f64| -> Vec<FourierJoint> {
            js.iter()
                .map(|f| {
                    let mut f = f.clone();
                    f.scale(s);
                    f
                })
                .collect()
        };
        let (_, pen, worst) = self.assess(&scaled, n, self.opts.self_collision)?;
        if pen == 0.0 {
            return Ok(Ok((scaled, None)));
        }
        let (_, pen0, worst0) = self.assess(&shrink(&scaled, 0.0), n, self.opts.self_collision)?;
        if pen0 > 0.0 {
            return Ok(Err(worst0.or(worst).expect("a penalty has a violation")));
        }
        // Alternatively shrink only the joints involved in a violation (a collision involves
        // the joints that move one link and not the other), so that one tight pair does not
        // stop the whole robot; the better of the two by the criterion is kept.
        let mut selective = None;
        if per_joint {
            let mut current = scaled.clone();
            for _ in 0..60 {
                let (_, p, _) = self.assess(&current, n, self.opts.self_collision)?;
                if p == 0.0 {
                    selective = Some(current);
                    break;
                }
                for (f, &inv) in current.iter_mut().zip(&self.involved) {
                    if inv {
                        f.scale(0.85);
                    }
                }
            }
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..12 {
            let mid = 0.5 * (lo + hi);
            let (_, p, _) = self.assess(&shrink(&scaled, mid), n, self.opts.self_collision)?;
            if p == 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let global = (lo >= 1e-3).then(|| shrink(&scaled, lo));
        let chosen = match (global, selective) {
            (Some(g), Some(sel)) => {
                if self.evaluate(&sel)?.cost < self.evaluate(&g)?.cost {
                    sel
                } else {
                    g
                }
            }
            (Some(g), None) => g,
            (None, Some(sel)) => sel,
            (None, None) => return Ok(Err(worst.expect("a penalty has a violation"))),
        };
        Ok(Ok((chosen, worst)))
    }

    /// Each joint's rest clamped into its range and its deviation from rest scaled to its
    /// position, velocity and acceleration room on the fine grid: to touch the binding one
    /// with `touch`, else only shrunk where it exceeds one.
    pub(super) fn box_fit(&self, joints: &[FourierJoint], touch: bool) -> Vec<FourierJoint> {
        joints
            .iter()
            .zip(&self.limits)
            .map(|(f, lim)| {
                let (mut f, room) = self.room(f, lim);
                let s = if !room.is_finite() {
                    1.0
                } else if touch {
                    0.999 * room
                } else {
                    (0.999 * room).min(1.0)
                };
                f.scale(s);
                f
            })
            .collect()
    }

    /// One joint with its rest clamped into its range, and by how much its deviation from rest
    /// can be scaled before it touches its binding position, velocity or acceleration limit on
    /// the fine grid (infinite for a joint that does not move).
    pub(super) fn room(&self, f: &FourierJoint, lim: &JointLimits) -> (FourierJoint, f64) {
        self.room_on(f, lim, 4 * self.opts.samples)
    }

    /// [`Problem::room`] on an `n`-point grid.
    pub(super) fn room_on(&self, f: &FourierJoint, lim: &JointLimits, n: usize) -> (FourierJoint, f64) {
        let omega = self.omega();
        let period = 1.0 / self.opts.base_frequency_hz;
        let mut f = f.clone();
        f.rest = f.rest.clamp(lim.lower, lim.upper);
        let (mut up, mut down, mut v, mut a) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for k in 0..n {
            let (q, qd, qdd) = f.sample(omega, k as f64 * period / n as f64);
            up = up.max(q - f.rest);
            down = down.max(f.rest - q);
            v = v.max(qd.abs());
            a = a.max(qdd.abs());
        }
        let mut room = f64::INFINITY;
        for (limit, need) in
            [(lim.upper - f.rest, up), (f.rest - lim.lower, down), (lim.velocity, v), (lim.acceleration, a)]
        {
            if need > 1e-12 {
                room = room.min(limit / need);
            }
        }
        (f, room)
    }

    /// `M` such that `d(criterion) = Σ_rows drᵀ·M·r` over the base columns of the regressor's
    /// rows `r` (the rows behind the compressed `rz`); `None` where the criterion is degenerate.
    /// With `W = U·Σ·Vᵀ`, `dσᵢ = Σ_rows (r·vᵢ)(dr·vᵢ)/σᵢ`; the log-determinant's column scaling
    /// adds `d ln‖w_c‖ = Σ_rows r_c·dr_c/‖w_c‖²`.
    pub(super) fn criterion_metric(&self, rz: &Mat<f64>) -> Option<Mat<f64>> {
        let cols = &self.base_cols;
        let nb = cols.len();
        let w = Mat::from_fn(rz.nrows(), nb, |i, k| rz[(i, cols[k])]);
        let svd = w.thin_svd().ok()?;
        let sv: Vec<f64> = (0..nb).map(|i| svd.S().column_vector()[i]).collect();
        if sv.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
            return None;
        }
        let ln_sv: Vec<f64> = sv.iter().map(|s| s.ln()).collect();
        // ∂ln σᵢ weights of the soft maximum (β > 0) or soft minimum (β < 0) of ln σ.
        let softmax = |beta: f64| -> Vec<f64> {
            let m = ln_sv.iter().map(|l| beta * l).fold(f64::NEG_INFINITY, f64::max);
            let e: Vec<f64> = ln_sv.iter().map(|l| (beta * l - m).exp()).collect();
            let total: f64 = e.iter().sum();
            e.iter().map(|x| x / total).collect()
        };
        let (d, e): (Vec<f64>, Vec<f64>) = match self.opts.criterion {
            Criterion::Condition => {
                // ∂criterion/∂ln σᵢ.
                let c: Vec<f64> = match self.beta {
                    Some(beta) => softmax(beta).iter().zip(softmax(-beta)).map(|(p, m)| p - m).collect(),
                    None => {
                        let arg = |better: fn(f64, f64) -> bool| {
                            (0..nb).fold(0, |best, i| if better(sv[i], sv[best]) { i } else { best })
                        };
                        let (imax, imin) = (arg(|a, b| a > b), arg(|a, b| a < b));
                        (0..nb).map(|i| f64::from(u8::from(i == imax)) - f64::from(u8::from(i == imin))).collect()
                    }
                };
                (c.iter().zip(&sv).map(|(c, s)| c / (s * s)).collect(), vec![0.0; nb])
            }
            Criterion::LogDet => {
                let k = 2.0 / nb as f64;
                let norms2 = (0..nb).map(|c| (0..w.nrows()).map(|i| w[(i, c)] * w[(i, c)]).sum::<f64>());
                (sv.iter().map(|s| -k / (s * s)).collect(), norms2.map(|n2| k / n2).collect())
            }
        };
        let v = svd.V();
        Some(Mat::from_fn(nb, nb, |i, j| {
            (0..nb).map(|k| v[(i, k)] * d[k] * v[(j, k)]).sum::<f64>() + if i == j { e[i] } else { 0.0 }
        }))
    }

    /// Squared self-collision excess at joint positions `q` (as in [`Problem::assess`]).
    pub(super) fn collision_penalty(&mut self, q: &[f64]) -> Result<f64> {
        Ok(self.penetrations(q)?.iter().map(|(_, depth)| (depth / COLLISION_DEPTH_SCALE_M).powi(2)).sum())
    }

    /// The search's cost at the variables `x` ([`Problem::evaluate`] of
    /// [`Problem::box_fit`]`(x)`) and its gradient. A sample's regressor rows depend only on
    /// that sample's `(q, q̇, q̈)`, which are linear in the Fourier coefficients: each sample's
    /// rows are differentiated in its own 3 values per excited joint (forward differences; the
    /// rows are linear in q̈), pushed through [`Problem::criterion_metric`] and the penalties,
    /// and chained through the Fourier series and each joint's scaling into its box. That is
    /// 3 regressor evaluations per joint and sample, against a full evaluation (regressor,
    /// collision check, QR and SVD) per variable (2H − 1 per joint) for finite differences.
    pub(super) fn cost_gradient(&mut self, x: &[f64], template: &[FourierJoint]) -> Result<(f64, Vec<f64>)> {
        let h = self.opts.harmonics;
        let nvj = vars_per_joint(h);
        let raw = joints_from_vars(x, h, template);
        let joints = self.box_fit(&raw, false);
        let (eval, rz) = self.evaluate_with_matrix(&joints)?;
        let mut grad = vec![0.0; x.len()];
        let Some(metric) = self.criterion_metric(&rz) else {
            return Ok((eval.cost, grad));
        };
        let nb = self.base_cols.len();
        let ncols = self.ncols;
        let nsel = self.selected.len();
        let selected = self.selected.clone();
        let base_cols = self.base_cols.clone();
        // Per excited joint, the base columns its rows keep (as the accumulator does).
        let masks: Vec<Vec<bool>> =
            self.cols.iter().map(|c| base_cols.iter().map(|b| c.contains(b)).collect()).collect();
        let n = self.opts.samples;
        let omega = self.omega();
        let period = 1.0 / self.opts.base_frequency_hz;
        let nj = self.robot.joints.len();
        let (mut q, mut qd, mut qdd) = (self.hold.clone(), vec![0.0; nj], vec![0.0; nj]);
        let (mut rows, mut rows1) = (Vec::new(), Vec::new());
        let mut z = vec![0.0; nsel * nb];
        let mut r = vec![0.0; nb];
        // ∂cost/∂(rest, a, b) of each excited joint's scaled series.
        let mut g_series: Vec<(f64, Vec<f64>, Vec<f64>)> = vec![(0.0, vec![0.0; h], vec![0.0; h]); nsel];
        // Per sample, every entry rewritten: ∂penalty/∂τ_j of the torque excesses, and
        // ∂cost/∂(q, q̇, q̈) of each excited joint.
        let mut torque_weight = vec![0.0; nsel];
        let mut g_sample = vec![[0.0; 3]; nsel];
        for k in 0..n {
            let t = k as f64 * period / n as f64;
            for f in &joints {
                (q[f.index], qd[f.index], qdd[f.index]) = f.sample(omega, t);
            }
            let tau0 = self.reg.torques(None, &q, &qd, &qdd, &self.cad, &mut rows)?;
            for (s, &j) in selected.iter().enumerate() {
                for (b, rb) in r.iter_mut().enumerate() {
                    *rb = if masks[s][b] { rows[j * ncols + base_cols[b]] } else { 0.0 };
                }
                for a in 0..nb {
                    z[s * nb + a] = (0..nb).map(|b| metric[(a, b)] * r[b]).sum();
                }
            }
            for ((w, &j), lim) in torque_weight.iter_mut().zip(&selected).zip(&self.limits) {
                *w = match lim.torque {
                    Some(tmax) if tau0[j].abs() > tmax => 2.0 * (tau0[j].abs() / tmax - 1.0) * tau0[j].signum() / tmax,
                    _ => 0.0,
                };
            }
            for (i, &ji) in selected.iter().enumerate() {
                for (kind, step) in [1e-6, 1e-6, 1e-3].into_iter().enumerate() {
                    let slot = match kind {
                        0 => &mut q[ji],
                        1 => &mut qd[ji],
                        _ => &mut qdd[ji],
                    };
                    let kept = *slot;
                    *slot += step;
                    let tau1 = self.reg.torques(None, &q, &qd, &qdd, &self.cad, &mut rows1)?;
                    match kind {
                        0 => q[ji] = kept,
                        1 => qd[ji] = kept,
                        _ => qdd[ji] = kept,
                    }
                    let mut d = 0.0;
                    for (s, &j) in selected.iter().enumerate() {
                        for (b, &c) in base_cols.iter().enumerate() {
                            if masks[s][b] {
                                d += (rows1[j * ncols + c] - rows[j * ncols + c]) * z[s * nb + b];
                            }
                        }
                        d += PENALTY_WEIGHT * torque_weight[s] * (tau1[j] - tau0[j]);
                    }
                    g_sample[i][kind] = d / step;
                }
                // The joint's own position, velocity and acceleration excesses.
                let lim = &self.limits[i];
                let range = (lim.upper - lim.lower).max(1e-6);
                let excess = |v: f64, limit: f64| 2.0 * (v.abs() / limit - 1.0).max(0.0) * v.signum() / limit;
                g_sample[i][0] += PENALTY_WEIGHT * 2.0 * ((q[ji] - lim.upper).max(0.0) - (lim.lower - q[ji]).max(0.0))
                    / (range * range);
                g_sample[i][1] += PENALTY_WEIGHT * excess(qd[ji], lim.velocity);
                g_sample[i][2] += PENALTY_WEIGHT * excess(qdd[ji], lim.acceleration);
            }
            if self.opts.self_collision {
                let p0 = self.collision_penalty(&q)?;
                if p0 > 0.0 {
                    for (i, &ji) in selected.iter().enumerate() {
                        let kept = q[ji];
                        q[ji] += 1e-6;
                        let p1 = self.collision_penalty(&q)?;
                        q[ji] = kept;
                        g_sample[i][0] += PENALTY_WEIGHT * (p1 - p0) / 1e-6;
                    }
                }
            }
            for ((rest, ga, gb), [gq, gv, gacc]) in g_series.iter_mut().zip(&g_sample) {
                *rest += gq;
                for l in 0..h {
                    let w = omega * (l + 1) as f64;
                    let (sn, cs) = (w * t).sin_cos();
                    ga[l] += gq * sn / w + gv * cs - gacc * w * sn;
                    gb[l] += -gq * (cs - 1.0) / w + gv * sn + gacc * w * cs;
                }
            }
        }
        // Through box_fit: rest clamped into the range, the motion scaled by s = min(1, room).
        // Uncapped scale 0.999·room (infinite for a joint that does not move).
        let uncapped = |room: f64| if room.is_finite() { 0.999 * room } else { f64::INFINITY };
        for (i, (f, (g_rest, ga, gb))) in raw.iter().zip(&g_series).enumerate() {
            let lim = &self.limits[i];
            let s_free = uncapped(self.room(f, lim).1);
            let s = s_free.min(1.0);
            let gx = &mut grad[i * nvj..(i + 1) * nvj];
            if f.rest > lim.lower && f.rest < lim.upper {
                gx[0] = *g_rest;
            }
            for l in 1..h {
                gx[l] = s * (ga[l] - ga[0]);
                gx[h - 1 + l] = s * (gb[l] - (l + 1) as f64 * gb[0]);
            }
            // Where the joint touches its box (the searches start there: each start is scaled
            // to touch), the cost has a kink: either branch's gradient may stall the line
            // search (the unscaled one asks for motion the box removes; on the leg no step is
            // accepted), so each start is searched with both (`touching_scaled`).
            if s_free < 1.0 || (self.touching_scaled && s_free <= 1.0 + 1e-6) {
                // ∂s/∂x by differences of the box fit alone (no regressor involved).
                let g_dev: f64 = ga.iter().zip(&f.a).chain(gb.iter().zip(&f.b)).map(|(g, c)| g * c).sum();
                let mut v = x[i * nvj..(i + 1) * nvj].to_vec();
                for p in 0..nvj {
                    let kept = v[p];
                    let step = 1e-7 * (1.0 + kept.abs());
                    v[p] += step;
                    let s1 = uncapped(self.room(&joint_from_vars(&v, h, &template[i]), lim).1);
                    v[p] = kept;
                    gx[p] += g_dev * (s1 - s_free) / step;
                }
            }
        }
        Ok((eval.cost, grad))
    }

    /// The search's cost at the variables `x`, with its gradient (else an empty one).
    pub(super) fn cost(
        &mut self,
        x: &[f64],
        template: &[FourierJoint],
        with_gradient: bool,
    ) -> Result<(f64, Vec<f64>)> {
        if with_gradient {
            self.cost_gradient(x, template)
        } else {
            let js = self.box_fit(&joints_from_vars(x, self.opts.harmonics, template), false);
            Ok((self.evaluate(&js)?.cost, Vec::new()))
        }
    }

    pub(super) fn usage(&mut self, joints: &[FourierJoint]) -> Result<Vec<JointUse>> {
        let n = 4 * self.opts.samples;
        let omega = self.omega();
        let period = 1.0 / self.opts.base_frequency_hz;
        let nj = self.robot.joints.len();
        let mut out: Vec<JointUse> = self
            .limits
            .iter()
            .map(|l| JointUse { name: l.name.clone(), span: 0.0, velocity: 0.0, acceleration: 0.0, torque: 0.0 })
            .collect();
        let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); joints.len()];
        let (mut q, mut qd, mut qdd) = (self.hold.clone(), vec![0.0; nj], vec![0.0; nj]);
        let mut rows = Vec::new();
        for k in 0..n {
            let t = k as f64 * period / n as f64;
            for f in joints {
                let (a, b, c) = f.sample(omega, t);
                (q[f.index], qd[f.index], qdd[f.index]) = (a, b, c);
            }
            let tau = self.reg.torques(None, &q, &qd, &qdd, &self.cad, &mut rows)?;
            for (s, &j) in self.selected.iter().enumerate() {
                let lim = &self.limits[s];
                let u = &mut out[s];
                range[s] = (range[s].0.min(q[j]), range[s].1.max(q[j]));
                u.velocity = u.velocity.max(qd[j].abs() / lim.velocity);
                u.acceleration = u.acceleration.max(qdd[j].abs() / lim.acceleration);
                if let Some(tm) = lim.torque {
                    u.torque = u.torque.max(tau[j].abs() / tm);
                }
            }
        }
        for (u, r) in out.iter_mut().zip(range) {
            u.span = r.1 - r.0;
        }
        Ok(out)
    }
}
