//! Estimation: compressed least squares, base parameters (QR with column pivoting), per-joint
//! noise weighting, statistics, and the physically consistent fit (log-Cholesky
//! parameterisation, Levenberg–Marquardt).

use crate::error::{Error, Result};
use crate::model::{LINK_PARAMS, params_from_pseudo_inertia, pseudo_inertia};
use faer::prelude::*;
use faer::{Mat, Side};
use nalgebra::Matrix4;

/// Row-wise compression of each joint's regressor rows: `[W_j τ_j] = Q_j·R_j`, kept only on the
/// columns the joint's rows can touch (the links it moves and its own friction terms), so the
/// cost per sample is small and memory does not grow with the log.
pub(crate) struct Accumulator {
    ncols: usize,
    blocks: Vec<JointBlock>,
}

struct JointBlock {
    cols: Vec<usize>,
    r: Mat<f64>,
    pending: Vec<f64>,
    pending_rows: usize,
    rows: usize,
}

impl JointBlock {
    fn width(&self) -> usize {
        self.cols.len() + 1
    }

    fn flush(&mut self) {
        if self.pending_rows == 0 {
            return;
        }
        let w = self.width();
        let rr = self.r.nrows();
        let stacked = Mat::from_fn(rr + self.pending_rows, w, |i, j| {
            if i < rr { self.r[(i, j)] } else { self.pending[(i - rr) * w + j] }
        });
        let qr = stacked.qr();
        let r = qr.thin_R();
        self.r = Mat::from_fn(r.nrows(), w, |i, j| if j >= i { r[(i, j)] } else { 0.0 });
        self.pending.clear();
        self.pending_rows = 0;
    }
}

impl Accumulator {
    /// `cols[j]`: the parameter columns joint `j`'s rows can be non-zero in.
    pub(crate) fn new(ncols: usize, cols: Vec<Vec<usize>>) -> Accumulator {
        Accumulator {
            ncols,
            blocks: cols
                .into_iter()
                .map(|cols| JointBlock {
                    r: Mat::zeros(0, cols.len() + 1),
                    cols,
                    pending: Vec::new(),
                    pending_rows: 0,
                    rows: 0,
                })
                .collect(),
        }
    }

    /// Adds the row `row` (all columns) with measured torque `tau` to joint `j`.
    pub(crate) fn push(&mut self, j: usize, row: &[f64], tau: f64) {
        let b = &mut self.blocks[j];
        b.pending.extend(b.cols.iter().map(|&c| row[c]));
        b.pending.push(tau);
        b.pending_rows += 1;
        b.rows += 1;
        let w = b.width();
        if b.pending_rows >= (4 * w).max(256) {
            b.flush();
        }
    }

    pub(crate) fn finish(&mut self) {
        for b in &mut self.blocks {
            b.flush();
        }
    }

    /// Rows of joint `j`.
    pub(crate) fn rows(&self, j: usize) -> usize {
        self.blocks[j].rows
    }

    /// Total rows.
    pub(crate) fn total_rows(&self) -> usize {
        self.blocks.iter().map(|b| b.rows).sum()
    }

    /// `‖W_j·π − τ_j‖²` for joint `j`.
    pub(crate) fn residual2(&self, j: usize, params: &[f64]) -> f64 {
        self.quadratic(j, params, -1.0)
    }

    /// `‖W_j·π + tau_coef·τ_j‖²` for joint `j`.
    pub(crate) fn quadratic(&self, j: usize, params: &[f64], tau_coef: f64) -> f64 {
        let b = &self.blocks[j];
        let w = b.width();
        let mut x: Vec<f64> = b.cols.iter().map(|&c| params[c]).collect();
        x.push(tau_coef);
        (0..b.r.nrows())
            .map(|i| {
                let v: f64 = (i..w).map(|k| b.r[(i, k)] * x[k]).sum();
                v * v
            })
            .sum()
    }

    /// `[R z; 0 ρ]` ((n+1) × (n+1), upper triangular) of all joints stacked, each joint's rows
    /// scaled by `weights[j]`: `Σ_j w_j²‖W_j·π − τ_j‖² = ‖R·π − z‖² + ρ²`.
    pub(crate) fn compressed(&self, weights: &[f64]) -> Mat<f64> {
        let n = self.ncols;
        let total: usize = self.blocks.iter().map(|b| b.r.nrows()).sum();
        let mut stacked = Mat::<f64>::zeros(total.max(n + 1), n + 1);
        let mut row = 0;
        for (b, &w) in self.blocks.iter().zip(weights) {
            for i in 0..b.r.nrows() {
                for (k, &c) in b.cols.iter().enumerate() {
                    stacked[(row, c)] = w * b.r[(i, k)];
                }
                stacked[(row, n)] = w * b.r[(i, b.cols.len())];
                row += 1;
            }
        }
        let qr = stacked.qr();
        let r = qr.thin_R();
        Mat::from_fn(n + 1, n + 1, |i, j| if j >= i { r[(i, j)] } else { 0.0 })
    }
}

/// Identifiability of one standard parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Identifiability {
    /// Determined by the log on its own.
    Identifiable,
    /// Determined only in combination with other parameters (part of a base parameter); its
    /// share comes from the CAD prior.
    Combination,
    /// Has no effect on the logged torques; stays at the CAD value.
    NotIdentifiable,
}

/// One base parameter: `β = π_lead + Σ coef·π_other`.
#[derive(Debug, Clone)]
pub(crate) struct BaseParam {
    pub lead: usize,
    pub terms: Vec<(usize, f64)>,
    pub value: f64,
    pub std: f64,
}

/// Result of the base-parameter analysis of a compressed problem.
pub(crate) struct BaseAnalysis {
    pub rank: usize,
    pub condition: f64,
    /// Least-squares solution with the dependent parameters at 0 (all columns).
    pub ols: Vec<f64>,
    pub base: Vec<BaseParam>,
    pub identifiability: Vec<Identifiability>,
    /// Residual variance of the weighted least squares (≈ 1 with correct weights).
    pub sigma2: f64,
}

/// Relative tolerance on `|R_ii|` of the column-pivoted QR (columns scaled to unit norm).
const RANK_TOL: f64 = 1e-8;

fn upper_solve(r: &Mat<f64>, n: usize, b: &mut [f64]) {
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= r[(i, k)] * b[k];
        }
        b[i] = s / r[(i, i)];
    }
}

pub(crate) fn base_analysis(rz: &Mat<f64>, rows: usize) -> Result<BaseAnalysis> {
    let n = rz.ncols() - 1;
    let norms: Vec<f64> = (0..n).map(|c| (0..n).map(|i| rz[(i, c)] * rz[(i, c)]).sum::<f64>().sqrt()).collect();
    let max_norm = norms.iter().copied().fold(0.0, f64::max);
    if max_norm <= 0.0 || !max_norm.is_finite() {
        return Err(Error::Numerical("the regressor is zero or not finite".into()));
    }
    let active: Vec<usize> = (0..n).filter(|&c| norms[c] > 1e-10 * max_norm).collect();
    let na = active.len();
    let scaled = Mat::from_fn(n, na, |i, k| rz[(i, active[k])] / norms[active[k]]);
    let cp = scaled.col_piv_qr();
    let r = cp.thin_R();
    let perm: Vec<usize> = cp.P().arrays().0.to_vec();
    let r00 = r[(0, 0)].abs();
    let kmax = r.nrows().min(na);
    let rank = (0..kmax).take_while(|&i| r[(i, i)].abs() > RANK_TOL * r00).count();
    let q = cp.compute_thin_Q();
    let y: Vec<f64> = (0..kmax).map(|i| (0..n).map(|k| q[(k, i)] * rz[(k, n)]).sum()).collect();
    let r11 = Mat::from_fn(rank, rank, |i, j| if j >= i { r[(i, j)] } else { 0.0 });
    let mut beta: Vec<f64> = y[..rank].to_vec();
    upper_solve(&r11, rank, &mut beta);
    let mut ols = vec![0.0; n];
    for k in 0..rank {
        let c = active[perm[k]];
        ols[c] = beta[k] / norms[c];
    }
    // K = R11⁻¹·R12, the dependent parameters' coefficients in each base parameter.
    let nd = na - rank;
    let mut kmat = vec![vec![0.0; nd]; rank];
    for d in 0..nd {
        let mut col: Vec<f64> = (0..rank).map(|i| r[(i, rank + d)]).collect();
        upper_solve(&r11, rank, &mut col);
        for i in 0..rank {
            kmat[i][d] = col[i];
        }
    }
    // Residual of the scaled problem: ‖z‖² + ρ² − ‖y_b‖².
    let z2: f64 = (0..=n).map(|i| rz[(i, n)] * rz[(i, n)]).sum();
    let y2: f64 = beta_norm2(&y[..rank]);
    let resid2 = (z2 - y2).max(0.0);
    let dof = rows.saturating_sub(rank).max(1);
    let sigma2 = resid2 / dof as f64;
    // Covariance of the scaled base parameters: σ²·R11⁻¹·R11⁻ᵀ.
    let mut rinv = Mat::<f64>::zeros(rank, rank);
    for c in 0..rank {
        let mut e = vec![0.0; rank];
        e[c] = 1.0;
        upper_solve(&r11, rank, &mut e);
        for i in 0..rank {
            rinv[(i, c)] = e[i];
        }
    }
    let base = (0..rank)
        .map(|k| {
            let lead = active[perm[k]];
            let var: f64 = (0..rank).map(|c| rinv[(k, c)] * rinv[(k, c)]).sum::<f64>() * sigma2;
            let terms = (0..nd)
                .filter_map(|d| {
                    let other = active[perm[rank + d]];
                    let coef = kmat[k][d] * norms[other] / norms[lead];
                    (coef.abs() > 1e-9).then_some((other, coef))
                })
                .collect();
            BaseParam { lead, terms, value: beta[k] / norms[lead], std: var.sqrt() / norms[lead] }
        })
        .collect();
    let condition = if rank == 0 {
        f64::INFINITY
    } else {
        let sv = r11.singular_values().map_err(|e| Error::Numerical(format!("SVD failed: {e:?}")))?;
        let (hi, lo) = sv.iter().fold((0.0f64, f64::INFINITY), |(h, l), &s| (h.max(s), l.min(s)));
        hi / lo
    };
    // Identifiable alone: the parameter's unit vector is orthogonal to the null space.
    let mut identifiability = vec![Identifiability::NotIdentifiable; n];
    for &c in &active {
        identifiability[c] = Identifiability::Identifiable;
    }
    if nd > 0 {
        let null = Mat::from_fn(na, nd, |i, d| {
            // Row i of P·[−K; I] in the active (scaled) space.
            let k = perm.iter().position(|&p| p == i).unwrap_or(0);
            if k < rank {
                -kmat[k][d]
            } else if k - rank == d {
                1.0
            } else {
                0.0
            }
        });
        let qn = null.qr().compute_thin_Q();
        for (i, &c) in active.iter().enumerate() {
            let row2: f64 = (0..nd).map(|d| qn[(i, d)] * qn[(i, d)]).sum();
            if row2.sqrt() > 1e-6 {
                identifiability[c] = Identifiability::Combination;
            }
        }
    }
    Ok(BaseAnalysis { rank, condition, ols, base, identifiability, sigma2 })
}

fn beta_norm2(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum()
}

/// Kind of each parameter in the consistent fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ParamKind {
    /// Start of a link's 10 standard parameters (its pseudo-inertia must stay ⪰ 0).
    Link,
    /// Inside a link block.
    LinkRest,
    /// Constrained to ≥ 0 (viscous, Coulomb, armature).
    NonNegative,
    /// Free (offset).
    Free,
}

/// `∂J/∂π_k` of the pseudo-inertia, for the 10 standard parameters.
fn pseudo_inertia_basis() -> [Matrix4<f64>; LINK_PARAMS] {
    std::array::from_fn(|k| {
        let mut e = [0.0; LINK_PARAMS];
        e[k] = 1.0;
        pseudo_inertia(&e)
    })
}

/// A link's constrained share: its 10 parameters from `s` less `shift`'s.
fn own_share(p: &[f64], shift: &[f64], s: usize) -> [f64; LINK_PARAMS] {
    std::array::from_fn(|k| p[s + k] - shift[s + k])
}

/// Strictly feasible point near `p`: each link's pseudo-inertia (of its share less `shift`)
/// with its eigenvalues raised to `floor × the largest`, non-negative terms raised to a small
/// positive value.
fn interior_point(p: &[f64], kinds: &[ParamKind], scales: &[f64], shift: &[f64], floor: f64) -> Vec<f64> {
    let mut p = p.to_vec();
    for i in 0..p.len() {
        match kinds[i] {
            ParamKind::Link => {
                let lp = own_share(&p, shift, i);
                let eig = pseudo_inertia(&lp).symmetric_eigen();
                let top = eig.eigenvalues.abs().max().max(1e-12);
                let clipped = eig.eigenvalues.map(|l| l.max(floor * top));
                let j = eig.eigenvectors * Matrix4::from_diagonal(&clipped) * eig.eigenvectors.transpose();
                let own = params_from_pseudo_inertia(&j);
                for k in 0..LINK_PARAMS {
                    p[i + k] = own[k] + shift[i + k];
                }
            }
            ParamKind::NonNegative => p[i] = p[i].max(1e-3 * scales[i]),
            _ => {}
        }
    }
    p
}

/// What constrains each parameter of [`consistent_fit`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bounds<'a> {
    /// Each parameter's kind (a link's first parameter, the rest of a link's, non-negative, free).
    pub kinds: &'a [ParamKind],
    /// Each parameter's typical size.
    pub scales: &'a [f64],
    /// The share of each link's parameters left out of its physical constraint (zero where none).
    pub shift: &'a [f64],
}

/// Minimises `πᵀ·H·π − 2·bᵀ·π` subject to every link's pseudo-inertia `J(π − shift) ⪰ 0` and
/// the non-negative terms `≥ 0` (`shift`: the share of each body that is not identified, such
/// as the fixed-joint links lumped into it at their URDF values, so that the share written
/// back is the one constrained to be physical; zero elsewhere): a convex problem (quadratic objective, linear matrix
/// inequalities), solved by a primal log-barrier interior-point method (Newton steps on
/// `t·f(π) − Σ log det J_l(π) − Σ log π_i`, `t` raised ×10 per round until the duality gap
/// is below 1e-7 of the cost, faer Cholesky for each step). Every iterate, the answer included, is strictly physically consistent.
/// `cost_offset` makes `f + cost_offset` the χ²-like cost (data residual + prior), which sets
/// the accuracy. Returns the parameters, the number of Newton steps and the largest
/// regularisation a step needed ([`solve_spd`]): the method does not fail numerically; a step
/// that no regularisation can make is the end, at the last (feasible) iterate.
pub(crate) fn consistent_fit(
    h: &Mat<f64>,
    b: &[f64],
    cost_offset: f64,
    start: &[f64],
    bounds: &Bounds<'_>,
    max_iterations: usize,
) -> Result<FitOutcome> {
    let Bounds { kinds, scales, shift } = *bounds;
    let n = b.len();
    let basis = pseudo_inertia_basis();
    let link_starts: Vec<usize> = (0..n).filter(|&i| kinds[i] == ParamKind::Link).collect();
    let bounded: Vec<usize> = (0..n).filter(|&i| kinds[i] == ParamKind::NonNegative).collect();
    let barrier_terms = (4 * link_starts.len() + bounded.len()).max(1) as f64;
    let objective = |p: &[f64]| -> f64 {
        let mut f = 0.0;
        for i in 0..n {
            let mut hp = 0.0;
            for k in 0..n {
                hp += h[(i, k)] * p[k];
            }
            f += p[i] * hp - 2.0 * b[i] * p[i];
        }
        f
    };
    // Barrier value, or None outside the feasible set.
    let barrier = |p: &[f64]| -> Option<f64> {
        let mut phi = 0.0;
        for &s in &link_starts {
            let ch = pseudo_inertia(&own_share(p, shift, s)).cholesky()?;
            phi -= 2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
        }
        for &i in &bounded {
            if p[i] <= 0.0 {
                return None;
            }
            phi -= p[i].ln();
        }
        Some(phi)
    };
    // Start: the unconstrained minimiser H⁻¹·b pulled strictly inside, else the prior's point.
    let unconstrained = solve_spd(h, b).map(|s| s.solution).unwrap_or_else(|| start.to_vec());
    let mut p = interior_point(&unconstrained, kinds, scales, shift, 1e-3);
    if barrier(&p).is_none() || p.iter().any(|v| !v.is_finite()) {
        p = interior_point(start, kinds, scales, shift, 1e-3);
    }
    if barrier(&p).is_none() {
        return Err(Error::Numerical("no physically consistent starting point".into()));
    }
    let chi2 = |p: &[f64]| (objective(p) + cost_offset).max(1.0);
    // Barrier weight: duality gap m/t starts near 10 % of the cost, ends below 1e-7 of it.
    let mut t = barrier_terms / (0.1 * chi2(&p));
    let mut steps = 0;
    let mut max_ridge = 0.0f64;
    'outer: loop {
        for _ in 0..50 {
            if steps >= max_iterations {
                break 'outer;
            }
            steps += 1;
            // Gradient and Hessian of t·f + φ.
            let mut grad = vec![0.0; n];
            let mut hess = Mat::<f64>::zeros(n, n);
            for i in 0..n {
                let mut hp = 0.0;
                for k in 0..n {
                    hp += h[(i, k)] * p[k];
                    hess[(i, k)] = 2.0 * t * h[(i, k)];
                }
                grad[i] = 2.0 * t * (hp - b[i]);
            }
            for &s in &link_starts {
                let jinv = pseudo_inertia(&own_share(&p, shift, s))
                    .try_inverse()
                    .ok_or_else(|| Error::Numerical("pseudo-inertia became singular".into()))?;
                let g: Vec<Matrix4<f64>> = basis.iter().map(|a| jinv * a).collect();
                for k in 0..LINK_PARAMS {
                    grad[s + k] -= g[k].trace();
                    for m in 0..LINK_PARAMS {
                        // tr(G_k·G_m)
                        hess[(s + k, s + m)] += g[k].component_mul(&g[m].transpose()).sum();
                    }
                }
            }
            for &i in &bounded {
                grad[i] -= 1.0 / p[i];
                hess[(i, i)] += 1.0 / (p[i] * p[i]);
            }
            // The Hessian is positive definite in exact arithmetic (2t·H with the prior, plus
            // the barrier's); rounding can break that when the data leave a direction flat and
            // t is large. Scaled and, if need be, regularised (a Levenberg step), it always
            // gives a descent direction; if even that fails, the current iterate, strictly
            // feasible, is the answer.
            let neg: Vec<f64> = grad.iter().map(|g| -g).collect();
            let Some(solved) = solve_spd(&hess, &neg) else {
                break 'outer;
            };
            max_ridge = max_ridge.max(solved.ridge);
            let step = Mat::from_fn(n, 1, |i, _| solved.solution[i]);
            let decrement: f64 = -(0..n).map(|i| grad[i] * step[(i, 0)]).sum::<f64>();
            if decrement / 2.0 < 1e-7 {
                break;
            }
            // Backtracking line search that stays strictly feasible.
            let f0 = t * objective(&p) + barrier(&p).expect("feasible");
            let mut alpha = 1.0;
            let mut moved = false;
            for _ in 0..60 {
                let trial: Vec<f64> = (0..n).map(|i| p[i] + alpha * step[(i, 0)]).collect();
                if let Some(phi) = barrier(&trial)
                    && t * objective(&trial) + phi <= f0 - 0.25 * alpha * decrement
                {
                    p = trial;
                    moved = alpha > 1e-8;
                    break;
                }
                alpha *= 0.5;
            }
            if !moved {
                break;
            }
        }
        if barrier_terms / t < 1e-7 * chi2(&p) {
            break;
        }
        t *= 10.0;
    }
    if p.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical("the physically consistent fit did not converge to finite values".into()));
    }
    Ok(FitOutcome { params: p, steps, max_ridge })
}

/// What [`consistent_fit`] returns.
#[derive(Debug, Clone)]
pub(crate) struct FitOutcome {
    /// The parameters (strictly physically consistent).
    pub params: Vec<f64>,
    /// Newton steps taken.
    pub steps: usize,
    /// Largest relative regularisation a Newton step needed (0: none).
    pub max_ridge: f64,
}

/// The solution of a symmetric positive (semi)definite system and the regularisation it took.
pub(crate) struct SpdSolution {
    /// `x` with `(D·A·D + ridge·1)·D⁻¹x = D·b`, `D = diag(A)^-1/2`.
    pub solution: Vec<f64>,
    /// Relative ridge added to the unit-diagonal scaled matrix (0: none).
    pub ridge: f64,
}

/// Solves `A·x = b` for symmetric `A` that should be positive definite: Jacobi-scaled to a unit
/// diagonal, Cholesky; where rounding makes it fail, a ridge `μ·1` (μ = 1e-14 … 1e-2) is added
/// to the scaled matrix. `None` only for a non-finite or non-positive diagonal, or a matrix
/// that no ridge up to 1e-2 makes factorizable.
pub(crate) fn solve_spd(a: &Mat<f64>, b: &[f64]) -> Option<SpdSolution> {
    let n = b.len();
    let d: Vec<f64> = (0..n).map(|i| a[(i, i)]).collect();
    if d.iter().any(|v| !(v.is_finite() && *v > 0.0)) || b.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let s: Vec<f64> = d.iter().map(|v| 1.0 / v.sqrt()).collect();
    let rhs = Mat::from_fn(n, 1, |i, _| s[i] * b[i]);
    let mut ridge = 0.0;
    loop {
        let scaled = Mat::from_fn(n, n, |i, j| s[i] * a[(i, j)] * s[j] + if i == j { ridge } else { 0.0 });
        if let Ok(llt) = scaled.llt(Side::Lower) {
            let y = llt.solve(&rhs);
            let x: Vec<f64> = (0..n).map(|i| s[i] * y[(i, 0)]).collect();
            if x.iter().all(|v| v.is_finite()) {
                return Some(SpdSolution { solution: x, ridge });
            }
        }
        ridge = if ridge == 0.0 { 1e-14 } else { ridge * 100.0 };
        if ridge > 1e-2 {
            return None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_pivoted_qr_finds_the_rank_and_base_parameters() {
        // τ = 2·x0 + 3·(x1 + x2): columns 1 and 2 equal, column 3 zero.
        let rows = 50;
        let mut acc = Accumulator::new(4, vec![vec![0, 1, 2, 3]]);
        for i in 0..rows {
            let a = (i as f64 * 0.37).sin();
            let b = (i as f64 * 0.11).cos();
            acc.push(0, &[a, b, b, 0.0], 2.0 * a + 3.0 * b);
        }
        acc.finish();
        let rz = acc.compressed(&[1.0]);
        let ba = base_analysis(&rz, rows).unwrap();
        assert_eq!(ba.rank, 2);
        assert_eq!(ba.identifiability[0], Identifiability::Identifiable);
        assert_eq!(ba.identifiability[1], Identifiability::Combination);
        assert_eq!(ba.identifiability[2], Identifiability::Combination);
        assert_eq!(ba.identifiability[3], Identifiability::NotIdentifiable);
        let combo = ba.base.iter().find(|b| b.lead == 1 || b.lead == 2).unwrap();
        assert!((combo.value - 3.0).abs() < 1e-9, "{}", combo.value);
        assert_eq!(combo.terms.len(), 1);
        assert!((combo.terms[0].1 - 1.0).abs() < 1e-9);
        assert!((ba.ols[0] - 2.0).abs() < 1e-9);
    }
}
