//! In-grasp manipulation (IGM), the paper's Alg. 1, as a pure function over plain inputs
//! ([`igm_step`]) and as a [`Controller`] ([`IgmController`]).
//!
//! For the k >= 3 fingertips in contact (points p_i, normals n_i into the object, measured
//! normal forces c_i in N), at the measured joints q:
//! 1. J_S (3k x n for a hand of n joints: row block i is the Jacobian of the contact point
//!    as a point of finger i's tip body, [`Hand::fingertip_jacobian_at_point`], zero outside
//!    that finger's joints) and G (6 x 3k, [`crate::grasp_map`] about the object centre),
//!    both in f64.
//! 2. c* from the contact-force QP ([`contact_force_qp`]), normalised so that one
//!    `c*_j = 1`. **Which minimiser**: the QP's optimum is often not unique (on the cube
//!    two opposing fingers alone balance it, and so does every mix with the other opposing
//!    sets), and the solver's pick then has zeros that tell IGM to pull fingers off the
//!    object. By default ([`ForceSelection::NearestMeasured`]) c* is the distribution
//!    that balances as well as the QP's optimum and lies nearest the measured forces
//!    ([`nearest_balanced_forces`]); [`ForceSelection::QpOptimum`] uses the QP's answer
//!    as is. **Force scaling**: the paper's `c*_i - c_i` mixes that unitless c* with
//!    forces in newtons, so c* is first scaled to desired forces `f*_i = s c*_i`:
//!    by default ([`ForceScaling::MatchMeanMeasured`]) `s = max(mean_i c_i, min_mean_n) /
//!    mean_i c*_i`, i.e. the stability term *redistributes* the grip the hand already
//!    applies (keeping its total), and squeezes to a floor of `min_mean_n` per contact when
//!    the measured grip is lighter; [`ForceScaling::MaxEquals`] instead asks for a fixed
//!    grip `max_i f*_i = grip_n`.
//! 3. `dp_i = alpha (f*_i - c_i) n_i` (m; alpha in m/N), and `J_S dq_stable = [dp]` solved
//!    by damped least squares `dq = J^T (J J^T + lambda^2 I)^-1 dp`, lambda = `damping_m`
//!    (default 5 mm: the fingertip Jacobians' singular values are ~0.02-0.1 m/rad, so
//!    this biases the weakest direction by ~6 % and keeps dq bounded near singularities).
//! 4. `J_S dq_rot = G^T do`, same solver; `do` = [dx, dy, dz, rx, ry, rz] is a small
//!    object twist per step, by default a 0.0225 rad turn about +z (the paper's value;
//!    [`IgmConfig::reversed`] turns the other way).
//! 5. `psi = dq_stable + dq_rot`, scaled down uniformly (direction kept) so that no joint
//!    moves more than `max_delta_rad`; the controller then also keeps the targets inside
//!    the joint limits ([`limit_to_joint_range`]).
//!
//! J_S has zero columns for fingers not in the contact set, so psi is exactly zero on
//! them: FG can add a switching finger's trajectory on top without interference.

use std::sync::Arc;

use nalgebra::{DMatrix, DVector, Vector3};
use vge_hand::Hand;

use super::qp::{ContactForces, MIN_CONTACTS, contact_force_qp, nearest_balanced_forces};
use super::{Controller, ControllerError, ControllerInput, grasp_map, limit_to_joint_range};

/// One fingertip contact for [`igm_step`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipContact {
    /// Which finger touches (an index into the hand's fingers).
    pub finger: usize,
    /// Contact point, world frame (m).
    pub point_m: Vector3<f32>,
    /// Contact normal, either orientation (it is turned to point into the object).
    pub normal: Vector3<f32>,
    /// Measured normal force magnitude (N).
    pub force_n: f32,
}

/// How the unitless c* becomes desired forces in newtons (module docs, step 2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceScaling {
    /// Same mean as the measured forces, but at least `min_mean_n` per contact.
    MatchMeanMeasured {
        /// Floor of the mean desired force (N).
        min_mean_n: f32,
    },
    /// The largest desired force is `grip_n`.
    MaxEquals {
        /// Largest desired force (N).
        grip_n: f32,
    },
}

/// Which of the QP's minimisers becomes c* (module docs, step 2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceSelection {
    /// The QP's own answer ([`contact_force_qp`]: best j, ties to the smallest max c).
    QpOptimum,
    /// Among the distributions balancing as well as the QP's answer, the one nearest the
    /// measured forces ([`nearest_balanced_forces`]).
    NearestMeasured {
        /// Relative slack on the balance (residual per unit of total force).
        slack: f32,
    },
}

/// Parameters of IGM.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IgmConfig {
    /// Stability gain alpha (m of fingertip motion per N of force error).
    pub alpha_m_per_n: f32,
    /// Damping lambda of the least-squares solves (m).
    pub damping_m: f32,
    /// Desired object twist per step do = [dx, dy, dz, rx, ry, rz] (m, rad), world frame,
    /// about the object centre.
    pub object_delta: [f32; 6],
    /// Largest change of any joint target per step (rad).
    pub max_delta_rad: f32,
    /// c* to newtons.
    pub force_scaling: ForceScaling,
    /// Which minimiser of the QP is c*.
    pub selection: ForceSelection,
    /// The controller stops turning when a joint target would come this close to its
    /// limit ([`fit_to_joint_limits`]); rad.
    pub limit_margin_rad: f32,
}

impl Default for IgmConfig {
    /// alpha 1 mm/N, lambda 5 mm, do = 0.0225 rad about +z, at most 0.05 rad per joint per
    /// step, desired mean force = measured mean but at least 2.5 N, c* nearest the measured
    /// forces, stop turning 0.02 rad before a joint limit. Tuned on the env (vge15, cube,
    /// 20 Hz, 12 seeds x both directions x 5 s): with a 0.5 N floor the grip decays while
    /// turning and a finger slips off (8 drops in 24); 1.5 N holds 4.7 contacts on average,
    /// 2.5 N all five (no drops); alpha 2 mm/N overshoots (4-11 drops of 24 at 1.5-2.5 N).
    /// The same values turn the Allegro's cube 0.5-0.85 rad either way in 2 s without a
    /// drop, until its ring finger's spread joint reaches its limit (with the start grasp
    /// pressed per kg: 0.51-0.58 rad in 5 s, no drop in 20 noisy episodes; in 30 s 16 of 20
    /// still within 0.44-0.62 rad, one dropped: docs/results/allegro/controllers.md).
    fn default() -> Self {
        Self {
            alpha_m_per_n: 1e-3,
            damping_m: 5e-3,
            object_delta: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0225],
            max_delta_rad: 0.05,
            force_scaling: ForceScaling::MatchMeanMeasured { min_mean_n: 2.5 },
            selection: ForceSelection::NearestMeasured { slack: 1e-3 },
            limit_margin_rad: 0.02,
        }
    }
}

impl IgmConfig {
    /// The same configuration turning the object the other way (do negated).
    #[must_use]
    pub fn reversed(mut self) -> Self {
        self.object_delta = self.object_delta.map(|v| -v);
        self
    }
}

/// Everything one IGM step computed.
#[derive(Debug, Clone, PartialEq)]
pub struct IgmOutput {
    /// psi = dq_stable + dq_rot after the per-step clip (rad, one entry per joint).
    pub delta_rad: Vec<f32>,
    /// dq_stable before the clip.
    pub dq_stable_rad: Vec<f32>,
    /// dq_rot before the clip.
    pub dq_rot_rad: Vec<f32>,
    /// The QP's answer, in the order of the contacts given.
    pub forces: ContactForces,
    /// Desired forces f*_i = s c*_i (N), same order.
    pub target_forces_n: Vec<f32>,
    /// Factor (<= 1) applied to psi by the clip.
    pub clip_scale: f32,
}

/// `J^T (J J^T + lambda^2 I)^-1 rhs`.
#[must_use]
pub fn damped_least_squares(jacobian: &DMatrix<f64>, rhs: &DVector<f64>, lambda: f64) -> DVector<f64> {
    let rows = jacobian.nrows();
    let gram = jacobian * jacobian.transpose() + DMatrix::identity(rows, rows) * (lambda * lambda);
    // SPD for lambda > 0; fall back to a pseudo-inverse solve when lambda = 0 and J is rank
    // deficient.
    let y = match gram.clone().cholesky() {
        Some(chol) => chol.solve(rhs),
        None => gram.svd(true, true).solve(rhs, 1e-12).unwrap_or_else(|_| DVector::zeros(rows)),
    };
    jacobian.transpose() * y
}

fn to_f32(v: &DVector<f64>) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// One IGM step (module docs) for `contacts` (k >= 3, at most one per finger for a
/// meaningful J_S) on an object centred at `object_position_m`, at joints `q_rad` (one per
/// joint of `hand`).
pub fn igm_step(
    hand: &Hand,
    q_rad: &[f32],
    contacts: &[TipContact],
    object_position_m: Vector3<f32>,
    config: &IgmConfig,
) -> Result<IgmOutput, ControllerError> {
    if contacts.len() < MIN_CONTACTS {
        return Err(ControllerError::TooFewContacts { got: contacts.len(), need: MIN_CONTACTS });
    }
    let q: Vec<f64> = q_rad.iter().map(|&v| f64::from(v)).collect();
    let mut jacobian = DMatrix::zeros(3 * contacts.len(), hand.num_joints());
    let mut points = Vec::with_capacity(contacts.len());
    let mut normals = Vec::with_capacity(contacts.len());
    let mut measured = Vec::with_capacity(contacts.len());
    for (i, c) in contacts.iter().enumerate() {
        if !c.force_n.is_finite() {
            return Err(ControllerError::NonFinite(format!("force of contact {i}")));
        }
        let point = c.point_m.cast::<f64>();
        let block = hand.fingertip_jacobian_at_point(c.finger, &q, &point)?;
        jacobian.view_mut((3 * i, 0), (3, block.ncols())).copy_from(&block);
        points.push(point);
        let inward = object_position_m - c.point_m;
        let n = if c.normal.dot(&inward) < 0.0 { -c.normal } else { c.normal };
        normals.push(n.cast::<f64>());
        measured.push(f64::from(c.force_n.max(0.0)));
    }
    let grasp = grasp_map(&points, object_position_m.cast::<f64>())?;

    let forces = contact_force_qp(&grasp, &normals)?;
    let k = contacts.len() as f64;
    let star = match config.selection {
        ForceSelection::QpOptimum => forces.magnitudes.clone(),
        ForceSelection::NearestMeasured { slack } => {
            let reference: Vec<f64> = if measured.iter().sum::<f64>() > 1e-6 {
                measured.clone()
            } else {
                vec![1.0; contacts.len()]
            };
            nearest_balanced_forces(&grasp, &normals, &forces, &reference, f64::from(slack))?
        }
    };
    let mean_star = star.iter().sum::<f64>() / k;
    let scale = match config.force_scaling {
        ForceScaling::MatchMeanMeasured { min_mean_n } => {
            (measured.iter().sum::<f64>() / k).max(f64::from(min_mean_n)) / mean_star
        }
        ForceScaling::MaxEquals { grip_n } => f64::from(grip_n) / star.iter().copied().fold(0.0, f64::max),
    };
    let targets: Vec<f64> = star.iter().map(|c| scale * c).collect();

    let alpha = f64::from(config.alpha_m_per_n);
    let lambda = f64::from(config.damping_m);
    let mut dp = DVector::zeros(3 * contacts.len());
    for i in 0..contacts.len() {
        let n = normals[i].normalize();
        dp.fixed_rows_mut::<3>(3 * i).copy_from(&(n * (alpha * (targets[i] - measured[i]))));
    }
    let dq_stable = damped_least_squares(&jacobian, &dp, lambda);
    let twist = DVector::from_iterator(6, config.object_delta.iter().map(|&v| f64::from(v)));
    let dq_rot = damped_least_squares(&jacobian, &(grasp.transpose() * twist), lambda);

    let psi = &dq_stable + &dq_rot;
    let largest = psi.amax();
    let max_delta = f64::from(config.max_delta_rad);
    let clip_scale = if largest > max_delta { max_delta / largest } else { 1.0 };
    if !psi.iter().all(|v| v.is_finite()) {
        return Err(ControllerError::NonFinite("IGM joint step".to_owned()));
    }
    Ok(IgmOutput {
        delta_rad: to_f32(&(psi * clip_scale)),
        dq_stable_rad: to_f32(&dq_stable),
        dq_rot_rad: to_f32(&dq_rot),
        target_forces_n: targets.iter().map(|&t| t as f32).collect(),
        forces,
        clip_scale: clip_scale as f32,
    })
}

/// IGM's step at the joint limits: the rotation term is scaled down (uniformly, by the
/// largest factor in [0, 1]) so that no joint target `q' + dq_stable + s dq_rot` passes
/// within `limit_margin_rad` of its limit, then the per-step clip is applied and the
/// targets are kept inside the limits ([`limit_to_joint_range`]). A joint without a range
/// does not restrict the rotation.
///
/// Clamping joint by joint instead bends the fingertip motion once the first joint (a
/// roll, on the cube) saturates: the other fingers keep turning, the grasp tears and the
/// object falls (measured: 2 of 16 seeded episodes within 2 s). Scaled this way IGM
/// turns the object until the first joint reaches its limit and then only holds it,
/// which is where the paper's IGM ends too ("before reaching joint limits").
#[must_use]
pub fn fit_to_joint_limits(
    hand: &Hand,
    q_target_rad: &[f32],
    out: &IgmOutput,
    config: &IgmConfig,
) -> Vec<f32> {
    let margin = config.limit_margin_rad.max(0.0);
    let mut s = 1.0f32;
    for (j, joint) in hand.joints().iter().enumerate() {
        let (Some(limit), Some(&target), Some(&stable), Some(&rot)) =
            (joint.limit, q_target_rad.get(j), out.dq_stable_rad.get(j), out.dq_rot_rad.get(j))
        else {
            continue;
        };
        let base = target + stable;
        // The bound the rotation moves towards; a target already past it may not go further.
        let room = if rot > 0.0 {
            (limit.upper_rad - margin - base).max(0.0)
        } else if rot < 0.0 {
            (base - limit.lower_rad - margin).max(0.0)
        } else {
            continue;
        };
        s = s.min(room / rot.abs());
    }
    let psi: Vec<f32> = out.dq_stable_rad.iter().zip(&out.dq_rot_rad).map(|(st, rot)| st + s * rot).collect();
    let largest = psi.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let clip = if largest > config.max_delta_rad { config.max_delta_rad / largest } else { 1.0 };
    let clipped: Vec<f32> = psi.iter().map(|v| v * clip).collect();
    limit_to_joint_range(hand, q_target_rad, &clipped)
}

/// The contacts of `input` as [`TipContact`]s, leaving out finger `exclude`.
#[must_use]
pub fn tip_contacts(input: &ControllerInput, exclude: Option<usize>) -> Vec<TipContact> {
    input
        .contacts
        .iter()
        .enumerate()
        .filter(|(f, _)| Some(*f) != exclude)
        .filter_map(|(finger, c)| {
            c.as_ref().map(|c| TipContact {
                finger,
                point_m: c.point_m,
                normal: c.normal,
                force_n: c.force_n,
            })
        })
        .collect()
}

/// IGM as a [`Controller`]: [`igm_step`] on every fingertip in contact, then kept inside
/// the joint limits. Stateless; the rng is unused.
#[derive(Debug, Clone)]
pub struct IgmController {
    /// The hand the kinematics are taken from (the env's).
    pub hand: Arc<Hand>,
    /// IGM parameters.
    pub config: IgmConfig,
}

impl IgmController {
    /// IGM on `hand` with `config`.
    #[must_use]
    pub fn new(hand: Arc<Hand>, config: IgmConfig) -> Self {
        Self { hand, config }
    }

    /// The step on the given contacts, kept inside the joint limits
    /// ([`fit_to_joint_limits`]).
    pub fn step_on(
        &self,
        input: &ControllerInput,
        contacts: &[TipContact],
    ) -> Result<Vec<f32>, ControllerError> {
        input.check_sizes(&self.hand)?;
        let out = igm_step(&self.hand, &input.q_rad, contacts, input.object_position_m, &self.config)?;
        Ok(fit_to_joint_limits(&self.hand, &input.q_target_rad, &out, &self.config))
    }
}

impl Controller for IgmController {
    fn name(&self) -> &'static str {
        "igm"
    }

    fn reset(&mut self, _rng: &mut dyn rand::Rng) {}

    fn act(
        &mut self,
        input: &ControllerInput,
        _rng: &mut dyn rand::Rng,
    ) -> Result<Vec<f32>, ControllerError> {
        self.step_on(input, &tip_contacts(input, None))
    }
}
