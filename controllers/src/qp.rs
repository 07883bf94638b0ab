//! The contact-force QP of IGM's stability term (paper Sec. "In-grasp manipulation"):
//!
//! ```text
//! unknowns  c_1..c_k >= 0            (normal force magnitudes, k >= 3)
//! minimise  ||w||^2,  w = G [c_1 n_1; ...; c_k n_k] = M c,  M = G N (6 x k)
//! subject   c_j = 1 for one j        (rules out the trivial c = 0)
//! ```
//!
//! G is the 6 x 3k grasp map of [`crate::grasp_map`] (`w = G f`), `n_i` the unit normals
//! pointing *into* the object (the direction a fingertip pushes), N = blockdiag(n_i).
//!
//! **Which j.** The paper only asks that some c_j = 1. We solve the QP once for each j
//! and keep the one with the smallest ||w||; on a tie (within 1e-9, e.g. every j reaches
//! equilibrium) the one with the smallest max(c), which is the j carrying the largest
//! optimal force, so the result is normalised to max(c*) = 1 whenever equilibrium exists.
//!
//! **Clarabel form** for a given j: `min 1/2 c^T P c + q^T c` with `P = 2 M^T M` (upper
//! triangle, CSC), `q = 0`, and `A c + s = b`: row 0 is `e_j^T` with `b_0 = 1` in a
//! `ZeroConeT(1)` (c_j = 1), rows 1..=k are `-I` with `b = 0` in a
//! `NonnegativeConeT(k)` (c >= 0). The interior-point answer is then *polished*: on its
//! support (c_i > 1e-7) the equality-constrained least-squares problem is solved exactly,
//! and kept when it is feasible and no worse, so symmetric grasps reach ||w|| ~ 1e-15
//! rather than the interior-point tolerance.
//!
//! **Degenerate contact sets** are typed errors, checked before solving: fewer than 3
//! contacts, a non-finite or zero normal, all normals parallel (same direction: the net
//! force is then `(sum c) n != 0` for every feasible c). Normals that lie in an open
//! half-space without being parallel still solve; `residual` then stays well above zero
//! and the caller can decide (IGM uses the best-effort c* as the paper does).

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::{DMatrix, DVector, Vector3};
use thiserror::Error;

/// Fewest contacts the QP accepts (the paper's k >= 3).
pub const MIN_CONTACTS: usize = 3;

/// Why the QP gave no answer.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum QpError {
    /// Fewer than [`MIN_CONTACTS`] contacts.
    #[error("{got} contacts, the contact-force QP needs at least {MIN_CONTACTS}")]
    TooFewContacts {
        /// Contacts given.
        got: usize,
    },
    /// G is not 6 x 3k for the k normals given.
    #[error("grasp map is {rows} x {cols}, expected 6 x {expected_cols}")]
    DimensionMismatch {
        /// Rows of G.
        rows: usize,
        /// Columns of G.
        cols: usize,
        /// 3k.
        expected_cols: usize,
    },
    /// A NaN or infinite entry in G or a normal.
    #[error("non-finite {0}")]
    NonFinite(&'static str),
    /// A normal of (near) zero length.
    #[error("normal {index} has (near) zero length")]
    ZeroNormal {
        /// Which contact.
        index: usize,
    },
    /// All normals point the same way: no non-zero c >= 0 balances the net force.
    #[error("all {count} contact normals are parallel: no equilibrium exists")]
    ParallelNormals {
        /// Contacts given.
        count: usize,
    },
    /// Clarabel rejected the problem data or settings.
    #[error("clarabel setup: {0}")]
    Setup(String),
    /// Clarabel ran but solved none of the k problems.
    #[error("clarabel did not solve any of the {count} problems (last status {status})")]
    Solver {
        /// How many problems (one per j) were tried.
        count: usize,
        /// Status of the last one, e.g. "NumericalError".
        status: String,
    },
}

/// The QP's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactForces {
    /// c* (dimensionless: normalised by `c*_j = 1`), all >= 0, in contact order.
    pub magnitudes: Vec<f64>,
    /// The index j with `c*_j = 1`.
    pub fixed_index: usize,
    /// ||w|| = ||G N c*|| (force and torque entries mixed, as in the paper).
    pub residual: f64,
}

impl ContactForces {
    /// Whether the contacts can hold the object without friction: `residual <= tol`.
    #[must_use]
    pub fn in_equilibrium(&self, tol: f64) -> bool {
        self.residual <= tol
    }
}

/// M = G N (6 x k): column i is `G_i n_i` = [n_i; r_i x n_i], the wrench of a unit push.
fn wrench_basis(grasp: &DMatrix<f64>, normals: &[Vector3<f64>]) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(6, normals.len());
    for (i, n) in normals.iter().enumerate() {
        let col = grasp.view((0, 3 * i), (6, 3)) * n;
        m.set_column(i, &col);
    }
    m
}

fn validate(grasp: &DMatrix<f64>, normals: &[Vector3<f64>]) -> Result<Vec<Vector3<f64>>, QpError> {
    let k = normals.len();
    if k < MIN_CONTACTS {
        return Err(QpError::TooFewContacts { got: k });
    }
    if grasp.nrows() != 6 || grasp.ncols() != 3 * k {
        return Err(QpError::DimensionMismatch {
            rows: grasp.nrows(),
            cols: grasp.ncols(),
            expected_cols: 3 * k,
        });
    }
    if grasp.iter().any(|v| !v.is_finite()) {
        return Err(QpError::NonFinite("grasp map entry"));
    }
    let mut units = Vec::with_capacity(k);
    for (index, n) in normals.iter().enumerate() {
        if n.iter().any(|v| !v.is_finite()) {
            return Err(QpError::NonFinite("contact normal"));
        }
        let norm = n.norm();
        if norm < 1e-9 {
            return Err(QpError::ZeroNormal { index });
        }
        units.push(n / norm);
    }
    if units.iter().all(|n| n.dot(&units[0]) > 1.0 - 1e-9) {
        return Err(QpError::ParallelNormals { count: k });
    }
    Ok(units)
}

/// Upper triangle of the symmetric k x k matrix `s`, in clarabel's CSC.
fn upper_csc(s: &DMatrix<f64>) -> CscMatrix<f64> {
    let n = s.ncols();
    let mut colptr = Vec::with_capacity(n + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for c in 0..n {
        for r in 0..=c {
            rowval.push(r);
            nzval.push(s[(r, c)]);
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(n, n, colptr, rowval, nzval)
}

/// A = [e_j^T; -I] ((k+1) x k) in CSC.
fn constraint_csc(k: usize, j: usize) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(k + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for c in 0..k {
        if c == j {
            rowval.push(0);
            nzval.push(1.0);
        }
        rowval.push(1 + c);
        nzval.push(-1.0);
        colptr.push(rowval.len());
    }
    CscMatrix::new(k + 1, k, colptr, rowval, nzval)
}

fn settings() -> DefaultSettings<f64> {
    DefaultSettings {
        verbose: false,
        tol_gap_abs: 1e-10,
        tol_gap_rel: 1e-10,
        tol_feas: 1e-10,
        max_iter: 100,
        ..DefaultSettings::default()
    }
}

/// Exact minimiser of ||M c|| with c_j = 1 and c_i = 0 off `support`; `None` when it has a
/// clearly negative entry.
fn polish(m: &DMatrix<f64>, j: usize, support: &[usize]) -> Option<Vec<f64>> {
    let free: Vec<usize> = support.iter().copied().filter(|&i| i != j).collect();
    let mut c = vec![0.0; m.ncols()];
    c[j] = 1.0;
    if !free.is_empty() {
        let a = DMatrix::from_fn(6, free.len(), |r, col| m[(r, free[col])]);
        let rhs: DVector<f64> = -m.column(j);
        let x = a.svd(true, true).solve(&rhs, 1e-12).ok()?;
        for (slot, &i) in free.iter().enumerate() {
            if !x[slot].is_finite() || x[slot] < -1e-9 {
                return None;
            }
            c[i] = x[slot].max(0.0);
        }
    }
    Some(c)
}

fn residual_of(m: &DMatrix<f64>, c: &[f64]) -> f64 {
    (m * DVector::from_column_slice(c)).norm()
}

/// Solve the contact-force QP (module docs) for grasp map `grasp` (6 x 3k) and normals
/// `normals` (k, pointing into the object; normalised here).
pub fn contact_force_qp(grasp: &DMatrix<f64>, normals: &[Vector3<f64>]) -> Result<ContactForces, QpError> {
    let units = validate(grasp, normals)?;
    let k = units.len();
    let m = wrench_basis(grasp, &units);
    let p = upper_csc(&(m.transpose() * &m * 2.0));
    let q = vec![0.0; k];
    let mut b = vec![0.0; k + 1];
    b[0] = 1.0;
    let cones = [SupportedConeT::ZeroConeT(1), SupportedConeT::NonnegativeConeT(k)];

    let mut best: Option<ContactForces> = None;
    let mut last_status = SolverStatus::Unsolved;
    for j in 0..k {
        let a = constraint_csc(k, j);
        let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings())
            .map_err(|e| QpError::Setup(e.to_string()))?;
        solver.solve();
        last_status = solver.solution.status;
        if !matches!(last_status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
            continue;
        }
        let raw: Vec<f64> = solver.solution.x.iter().map(|&v| v.max(0.0)).collect();
        if raw.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let mut c = raw;
        c[j] = 1.0;
        let mut residual = residual_of(&m, &c);
        let support: Vec<usize> = (0..k).filter(|&i| c[i] > 1e-7 || i == j).collect();
        if let Some(polished) = polish(&m, j, &support) {
            let r = residual_of(&m, &polished);
            if r <= residual {
                c = polished;
                residual = r;
            }
        }
        let candidate = ContactForces { magnitudes: c, fixed_index: j, residual };
        best = match best {
            None => Some(candidate),
            Some(current) => Some(if better(&candidate, &current) { candidate } else { current }),
        };
    }
    best.ok_or_else(|| QpError::Solver { count: k, status: format!("{last_status:?}") })
}

fn max_of(c: &[f64]) -> f64 {
    c.iter().copied().fold(0.0, f64::max)
}

fn better(a: &ContactForces, b: &ContactForces) -> bool {
    const TIE: f64 = 1e-9;
    if a.residual < b.residual - TIE {
        true
    } else if a.residual > b.residual + TIE {
        false
    } else {
        max_of(&a.magnitudes) < max_of(&b.magnitudes)
    }
}

/// Among the force distributions that balance the object as well as the QP's optimum
/// does, the one nearest `reference` (IGM's choice of c*: the measured forces).
///
/// The QP's minimiser is often not unique: on the cube, two opposing fingers alone reach
/// ||w|| = 0, and so does every mix of that pair with the other opposing sets. Which
/// minimiser [`contact_force_qp`] returns is then an accident of the solver and the
/// tie-break, and one with zeros tells IGM to pull those fingers off the object (measured
/// on the env: a five-finger grasp shrank to three within 0.3 s). This second stage keeps
/// the QP's balance and picks the minimiser closest to what the hand already applies:
///
/// ```text
/// minimise ||c - r||^2   subject to   ||M c|| <= rho sum(c),   c >= 0
/// rho = residual / sum(c*) + slack
/// ```
///
/// (a second-order cone program, solved with clarabel), i.e. at most the QP's residual
/// per unit of total force, plus `slack` for the solver's tolerance. The feasible set is a
/// cone, so a reference that already balances is returned unchanged, at any scale. The
/// answer is in the units of `reference`. Returns `forces`' magnitudes, rescaled to the
/// sum of `reference`, when the problem fails to solve.
pub fn nearest_balanced_forces(
    grasp: &DMatrix<f64>,
    normals: &[Vector3<f64>],
    forces: &ContactForces,
    reference: &[f64],
    slack: f64,
) -> Result<Vec<f64>, QpError> {
    let units = validate(grasp, normals)?;
    let k = units.len();
    if reference.len() != k || reference.iter().any(|v| !v.is_finite() || *v < 0.0) {
        return Err(QpError::NonFinite("reference force"));
    }
    let ref_sum: f64 = reference.iter().sum();
    let star_sum: f64 = forces.magnitudes.iter().sum();
    let fallback = || forces.magnitudes.iter().map(|c| c * ref_sum / star_sum.max(1e-12)).collect();
    if ref_sum <= 0.0 || star_sum <= 0.0 {
        return Ok(fallback());
    }
    let m = wrench_basis(grasp, &units);
    let rho = forces.residual / star_sum + slack;
    let p = upper_csc(&(DMatrix::identity(k, k) * 2.0));
    let q: Vec<f64> = reference.iter().map(|r| -2.0 * r).collect();
    // Rows 0..7: the cone (rho 1^T c; M c) via s = b - A c with A = [-rho 1^T; -M], b = 0.
    // Rows 7..7+k: s = -(-I) c = c >= 0.
    let mut a = DMatrix::zeros(7 + k, k);
    a.row_mut(0).fill(-rho);
    a.view_mut((1, 0), (6, k)).copy_from(&(-&m));
    a.view_mut((7, 0), (k, k)).copy_from(&(-DMatrix::identity(k, k)));
    let a = dense_csc(&a);
    let b = vec![0.0; 7 + k];
    let cones = [SupportedConeT::SecondOrderConeT(7), SupportedConeT::NonnegativeConeT(k)];
    let mut solver =
        DefaultSolver::new(&p, &q, &a, &b, &cones, settings()).map_err(|e| QpError::Setup(e.to_string()))?;
    solver.solve();
    if !matches!(solver.solution.status, SolverStatus::Solved | SolverStatus::AlmostSolved)
        || solver.solution.x.iter().any(|v| !v.is_finite())
    {
        return Ok(fallback());
    }
    Ok(solver.solution.x.iter().map(|&v| v.max(0.0)).collect())
}

/// A dense matrix in clarabel's CSC, exact zeros left out.
fn dense_csc(a: &DMatrix<f64>) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(a.ncols() + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for c in 0..a.ncols() {
        for r in 0..a.nrows() {
            if a[(r, c)] != 0.0 {
                rowval.push(r);
                nzval.push(a[(r, c)]);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(a.nrows(), a.ncols(), colptr, rowval, nzval)
}

/// Mean wall time of one [`contact_force_qp`] call (microseconds) for `k` contacts spread
/// evenly round the equator of a 5 cm sphere, tilted so they are not coplanar with the
/// centre's horizontal plane, over `iterations` calls; for `vge bench`.
pub fn bench_contact_force_qp(k: usize, iterations: usize) -> Result<f64, QpError> {
    let centre = Vector3::zeros();
    let mut points = Vec::with_capacity(k);
    let mut normals = Vec::with_capacity(k);
    for i in 0..k {
        let angle = std::f64::consts::TAU * (i as f64) / (k as f64) + 0.1 * (i as f64);
        let z = if i % 2 == 0 { 0.01 } else { -0.01 };
        let p = Vector3::new(0.05 * angle.cos(), 0.05 * angle.sin(), z);
        normals.push(-(p - centre).normalize());
        points.push(p);
    }
    let grasp = grasp_map_f64(&points, centre);
    let iterations = iterations.max(1);
    contact_force_qp(&grasp, &normals)?;
    let start = Instant::now();
    for _ in 0..iterations {
        std::hint::black_box(contact_force_qp(std::hint::black_box(&grasp), &normals)?);
    }
    Ok(start.elapsed().as_secs_f64() * 1e6 / iterations as f64)
}

/// G (6 x 3k) in f64 with the convention of [`crate::grasp_map`] (`w = G f`), without its
/// finiteness check (the QP checks G itself).
#[must_use]
pub fn grasp_map_f64(points: &[Vector3<f64>], object_position: Vector3<f64>) -> DMatrix<f64> {
    crate::grasp::grasp_map_unchecked(points, &object_position)
}
