//! The regressor: joint torques linear in the standard parameters, built from MuJoCo's
//! kinematics of the twin.
//!
//! For each moving link `b`, MuJoCo gives the Jacobian `J_b` of the link frame's origin and its
//! time derivative (`mj_jacBody`, `mj_jacDot`), hence the link's angular velocity `ω`, angular
//! acceleration `α` and the classical acceleration `a` of its origin (gravity subtracted), all
//! rotated into the link frame. The Newton–Euler wrench about the origin is linear in the
//! link's standard parameters `π_b = [m, h, Ī]`:
//!
//! ```text
//! f = m·a + α×h + ω×(ω×h)
//! n = Ī·α + ω×(Ī·ω) + h×a
//! ```
//!
//! and the joint torques are `τ = Σ_b J_bᵀ·[f; n] = Σ_b J_bᵀ·Y_b(ω, α, a)·π_b`, plus per joint
//! viscous `q̇`, Coulomb `sign(q̇)` (or `tanh(q̇/ε)`), armature `q̈` and an optional constant
//! offset.

use crate::error::Result;
use crate::model::{LINK_PARAMS, RobotModel};
use nalgebra::Vector3;
use twin_core::mj::Data;

/// Friction columns of each joint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrictionModel {
    /// Smooth the Coulomb term as `tanh(q̇/ε)` with this `ε` (rad/s or m/s); `None` uses
    /// `sign(q̇)` (default: `None`; samples inside the velocity dead zone are dropped instead).
    pub coulomb_smoothing: Option<f64>,
    /// Add a constant torque offset per joint (sensor bias) (default: `false`).
    pub offset: bool,
    /// Add an asymmetry column `sech²(q̇/ε)` per joint (needs `coulomb_smoothing`): the first
    /// order of a Coulomb sigmoid shifted in velocity, `c·tanh((q̇ + φ)/ε) ≈ c·tanh(q̇/ε) +
    /// (c·φ/ε)·sech²(q̇/ε)`, which with the offset makes the friction differ between the two
    /// directions of motion near rest (default: `false`).
    pub asymmetry: bool,
}

impl FrictionModel {
    /// Columns per joint: viscous, Coulomb, armature (, offset) (, asymmetry).
    pub fn columns_per_joint(&self) -> usize {
        3 + usize::from(self.offset) + usize::from(self.asymmetry)
    }

    /// Names of the per-joint columns.
    pub fn column_names(&self) -> &'static [&'static str] {
        match (self.offset, self.asymmetry) {
            (false, false) => &["viscous", "coulomb", "armature"],
            (true, false) => &["viscous", "coulomb", "armature", "offset"],
            (false, true) => &["viscous", "coulomb", "armature", "asymmetry"],
            (true, true) => &["viscous", "coulomb", "armature", "offset", "asymmetry"],
        }
    }

    /// Column of the asymmetry term within a joint's block, when there is one.
    pub fn asymmetry_col(&self) -> Option<usize> {
        self.asymmetry.then_some(3 + usize::from(self.offset))
    }

    /// Asymmetry regressor value `sech²(q̇/ε)` at velocity `qd` (0 without smoothing).
    pub fn asymmetry_value(&self, qd: f64) -> f64 {
        match self.coulomb_smoothing {
            Some(eps) => 1.0 / (qd / eps).cosh().powi(2),
            None => 0.0,
        }
    }

    /// A short description, e.g. `"tanh(q̇/0.05) + offset + asymmetry"`.
    pub fn describe(&self) -> String {
        let mut s = match self.coulomb_smoothing {
            Some(eps) => format!("viscous + Coulomb tanh(q̇/{eps})"),
            None => "viscous + Coulomb sign(q̇)".to_string(),
        };
        if self.offset {
            s.push_str(" + offset");
        }
        if self.asymmetry {
            s.push_str(" + asymmetry");
        }
        s
    }

    /// Coulomb regressor value at velocity `qd`.
    pub fn coulomb(&self, qd: f64) -> f64 {
        match self.coulomb_smoothing {
            Some(eps) => (qd / eps).tanh(),
            None => {
                if qd > 0.0 {
                    1.0
                } else if qd < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
        }
    }
}

/// Column layout of the parameter vector: links first (10 each, Pinocchio order), then joints
/// (viscous, Coulomb, armature, optional offset).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layout {
    /// Number of moving links.
    pub links: usize,
    /// Number of identified joints.
    pub joints: usize,
    /// Friction columns.
    pub friction: FrictionModel,
}

impl Layout {
    /// Total number of parameters.
    pub fn ncols(&self) -> usize {
        self.links * LINK_PARAMS + self.joints * self.friction.columns_per_joint()
    }
    /// First column of link `l`.
    pub fn link_col(&self, l: usize) -> usize {
        l * LINK_PARAMS
    }
    /// First column of joint `j`'s friction block.
    pub fn joint_col(&self, j: usize) -> usize {
        self.links * LINK_PARAMS + j * self.friction.columns_per_joint()
    }
}

/// State of a floating base at one sample, in MuJoCo's free-joint convention.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseSample {
    /// Position of the base origin (world, m), then orientation `w x y z` (world_from_base).
    pub qpos: [f64; 7],
    /// Linear velocity of the base origin (world frame, m/s), then angular velocity (base
    /// frame, rad/s).
    pub qvel: [f64; 6],
    /// Time derivative of `qvel` (m/s², rad/s²).
    pub qacc: [f64; 6],
}

/// Computes regressor rows sample by sample.
pub struct Regressor<'a> {
    robot: &'a RobotModel,
    data: Data,
    layout: Layout,
    jacp: Vec<f64>,
    jacr: Vec<f64>,
    jacp_dot: Vec<f64>,
    jacr_dot: Vec<f64>,
    qpos0: Vec<f64>,
}

/// `L(v)ᵀ·w` for the inertia columns `[Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`, where `Ī·v = L(v)·π_I`.
fn inertia_cols(v: &Vector3<f64>, w: &Vector3<f64>) -> [f64; 6] {
    [
        v[0] * w[0],
        v[1] * w[0] + v[0] * w[1],
        v[1] * w[1],
        v[2] * w[0] + v[0] * w[2],
        v[2] * w[1] + v[1] * w[2],
        v[2] * w[2],
    ]
}

impl<'a> Regressor<'a> {
    /// A regressor for `robot` with the given friction columns.
    ///
    /// # Errors
    /// [`crate::Error::Core`] if MuJoCo can't allocate its data.
    pub fn new(robot: &'a RobotModel, friction: FrictionModel) -> Result<Regressor<'a>> {
        let data = Data::new(robot.model.clone())?;
        let nv = robot.model.nv();
        Ok(Regressor {
            robot,
            data,
            layout: Layout { links: robot.links.len(), joints: robot.joints.len(), friction },
            jacp: vec![0.0; 3 * nv],
            jacr: vec![0.0; 3 * nv],
            jacp_dot: vec![0.0; 3 * nv],
            jacr_dot: vec![0.0; 3 * nv],
            qpos0: robot.model.qpos0().to_vec(),
        })
    }

    /// The column layout.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// Rows per sample: one per identified joint, then 6 for a floating base (the free
    /// joint's DOFs: force along the world axes, then torque about the base origin in base axes).
    pub fn nrows(&self) -> usize {
        self.robot.joints.len() + if self.robot.floating.is_some() { 6 } else { 0 }
    }

    /// Fills `rows` (row-major, [`Regressor::nrows`] rows, [`Layout::ncols`] columns) for
    /// joint positions `q`, velocities `qd`, accelerations `qdd` (one entry per identified
    /// joint). The base is at its default pose, at rest (a fixed base; a floating robot's free
    /// joint too: use [`Regressor::compute_floating`] for it).
    ///
    /// # Errors
    /// [`crate::Error::Core`] if MuJoCo raises.
    pub fn compute(&mut self, q: &[f64], qd: &[f64], qdd: &[f64], rows: &mut [f64]) -> Result<()> {
        self.compute_with(None, q, qd, qdd, rows)
    }

    /// As [`Regressor::compute`], the floating base in state `base`; the last 6 rows are the
    /// free joint's.
    ///
    /// # Errors
    /// As [`Regressor::compute`].
    pub fn compute_floating(
        &mut self,
        base: &BaseSample,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        rows: &mut [f64],
    ) -> Result<()> {
        self.compute_with(Some(base), q, qd, qdd, rows)
    }

    fn compute_with(
        &mut self,
        base: Option<&BaseSample>,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        rows: &mut [f64],
    ) -> Result<()> {
        let robot = self.robot;
        let nj = robot.joints.len();
        let ncols = self.layout.ncols();
        let nv = robot.model.nv();
        debug_assert_eq!(rows.len(), self.nrows() * ncols);
        rows.fill(0.0);
        self.data.qpos_mut().copy_from_slice(&self.qpos0);
        self.data.qvel_mut().fill(0.0);
        for (j, joint) in robot.joints.iter().enumerate() {
            self.data.qpos_mut()[joint.qpos_adr] = q[j];
            self.data.qvel_mut()[joint.dof] = qd[j];
        }
        if let (Some(fb), Some(b)) = (&robot.floating, base) {
            self.data.qpos_mut()[fb.qpos_adr..fb.qpos_adr + 7].copy_from_slice(&b.qpos);
            self.data.qvel_mut()[fb.dof..fb.dof + 6].copy_from_slice(&b.qvel);
        }
        self.data.kinematics_with_velocity()?;
        let g = robot.model.gravity();
        // (dof, row, velocity, acceleration) of each DOF that moves the current link.
        let mut dofs: Vec<(usize, usize, f64, f64)> = Vec::with_capacity(nj + 6);
        for (l, link) in robot.links.iter().enumerate() {
            dofs.clear();
            for &j in &link.ancestor_joints {
                dofs.push((robot.joints[j].dof, j, qd[j], qdd[j]));
            }
            if let (true, Some(fb)) = (link.floating, &robot.floating) {
                let (v, a) = base.map_or(([0.0; 6], [0.0; 6]), |b| (b.qvel, b.qacc));
                for k in 0..6 {
                    dofs.push((fb.dof + k, nj + k, v[k], a[k]));
                }
            }
            self.data.body_jacobian_dot(
                link.body,
                &mut self.jacp,
                &mut self.jacr,
                &mut self.jacp_dot,
                &mut self.jacr_dot,
            )?;
            let xmat = self.data.xmat()[link.body];
            // world_from_link is row-major; link-frame coordinates are its transpose times world.
            let to_link = |v: [f64; 3]| -> Vector3<f64> {
                Vector3::new(
                    xmat[0] * v[0] + xmat[3] * v[1] + xmat[6] * v[2],
                    xmat[1] * v[0] + xmat[4] * v[1] + xmat[7] * v[2],
                    xmat[2] * v[0] + xmat[5] * v[1] + xmat[8] * v[2],
                )
            };
            let (mut w, mut al, mut acc) = ([0.0; 3], [0.0; 3], [-g[0], -g[1], -g[2]]);
            for &(d, _, v, a) in &dofs {
                for r in 0..3 {
                    let (jp, jr) = (self.jacp[r * nv + d], self.jacr[r * nv + d]);
                    w[r] += jr * v;
                    al[r] += jr * a + self.jacr_dot[r * nv + d] * v;
                    acc[r] += jp * a + self.jacp_dot[r * nv + d] * v;
                }
            }
            let (w, al, acc) = (to_link(w), to_link(al), to_link(acc));
            let w2 = w.dot(&w);
            let col = self.layout.link_col(l);
            for &(d, row_idx, _, _) in &dofs {
                let u = to_link([self.jacp[d], self.jacp[nv + d], self.jacp[2 * nv + d]]);
                let v = to_link([self.jacr[d], self.jacr[nv + d], self.jacr[2 * nv + d]]);
                let row = &mut rows[row_idx * ncols + col..row_idx * ncols + col + LINK_PARAMS];
                row[0] += u.dot(&acc);
                // h columns: −α×u + ω(ω·u) − |ω|²u + a×v
                let au = al.cross(&u);
                let av = acc.cross(&v);
                let wu = w.dot(&u);
                for k in 0..3 {
                    row[1 + k] += -au[k] + w[k] * wu - w2 * u[k] + av[k];
                }
                // inertia columns: L(α)ᵀv − L(ω)ᵀ(ω×v)
                let a_cols = inertia_cols(&al, &v);
                let w_cols = inertia_cols(&w, &w.cross(&v));
                for k in 0..6 {
                    row[4 + k] += a_cols[k] - w_cols[k];
                }
            }
        }
        let fm = self.layout.friction;
        for j in 0..nj {
            let c = j * ncols + self.layout.joint_col(j);
            rows[c] = qd[j];
            rows[c + 1] = fm.coulomb(qd[j]);
            rows[c + 2] = qdd[j];
            if fm.offset {
                rows[c + 3] = 1.0;
            }
            if let Some(k) = fm.asymmetry_col() {
                rows[c + k] = fm.asymmetry_value(qd[j]);
            }
        }
        Ok(())
    }

    /// Generalized forces `Jᵀ·w` (one per row, as [`Regressor::nrows`]) of external wrenches
    /// at the pose of the last [`Regressor::compute`]/[`Regressor::compute_floating`] call.
    /// Each wrench is `(body, [fx, fy, fz, nx, ny, nz])`, force (N) and torque (N·m) expressed
    /// in the body's frame, the torque about the body frame's origin.
    ///
    /// # Errors
    /// [`crate::Error::Core`] for a bad body id.
    pub fn external_forces(&mut self, wrenches: &[(usize, [f64; 6])], out: &mut [f64]) -> Result<()> {
        let robot = self.robot;
        let nv = robot.model.nv();
        out.fill(0.0);
        for &(body, w) in wrenches {
            self.data.body_jacobian_dot(
                body,
                &mut self.jacp,
                &mut self.jacr,
                &mut self.jacp_dot,
                &mut self.jacr_dot,
            )?;
            let x = self.data.xmat()[body];
            let to_world = |v: [f64; 3]| -> [f64; 3] {
                [
                    x[0] * v[0] + x[1] * v[1] + x[2] * v[2],
                    x[3] * v[0] + x[4] * v[1] + x[5] * v[2],
                    x[6] * v[0] + x[7] * v[1] + x[8] * v[2],
                ]
            };
            let f = to_world([w[0], w[1], w[2]]);
            let n = to_world([w[3], w[4], w[5]]);
            let mut add = |d: usize, row: usize| {
                out[row] += (0..3).map(|r| self.jacp[r * nv + d] * f[r] + self.jacr[r * nv + d] * n[r]).sum::<f64>();
            };
            for (j, joint) in robot.joints.iter().enumerate() {
                add(joint.dof, j);
            }
            if let Some(fb) = &robot.floating {
                for k in 0..6 {
                    add(fb.dof + k, robot.joints.len() + k);
                }
            }
        }
        Ok(())
    }

    /// Generalized forces `Y·π` at one sample, for parameters `params` in [`Layout`] order: one
    /// per row, as [`Regressor::nrows`] (the joint torques first, in joint order, then a
    /// floating base's 6). `base`: a floating base's state, `None` for the base at its default
    /// pose, at rest (as [`Regressor::compute`]). `rows` is resized to hold the regressor.
    ///
    /// # Errors
    /// As [`Regressor::compute`].
    pub fn torques(
        &mut self,
        base: Option<&BaseSample>,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        params: &[f64],
        rows: &mut Vec<f64>,
    ) -> Result<Vec<f64>> {
        let nr = self.nrows();
        let ncols = self.layout.ncols();
        rows.resize(nr * ncols, 0.0);
        self.compute_with(base, q, qd, qdd, rows)?;
        Ok((0..nr).map(|j| rows[j * ncols..(j + 1) * ncols].iter().zip(params).map(|(a, b)| a * b).sum()).collect())
    }
}
