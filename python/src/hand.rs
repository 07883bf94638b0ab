//! A hand read from its MJCF description ([`vge_hand::Hand`]), behind `vge.Hand`: names,
//! limits, masses, and the kinematics in float64 (as MuJoCo computes them, so that the two
//! can be compared entry by entry).

use std::sync::Arc;

use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use vge_hand::Hand;

use crate::errors;

/// A loaded hand (behind `vge.Hand`).
#[pyclass(module = "vge._vge", frozen)]
#[derive(Debug)]
pub struct HandCore {
    hand: Arc<Hand>,
}

impl HandCore {
    /// The hand an env simulates, shared with it.
    pub fn from_arc(hand: Arc<Hand>) -> Self {
        Self { hand }
    }

    fn joints<'a>(&self, q: &'a PyReadonlyArray1<'_, f64>) -> PyResult<&'a [f64]> {
        q.as_slice().map_err(|e| errors::value(format!("joint angles: {e}")))
    }
}

#[pymethods]
impl HandCore {
    /// Reads the MJCF file at `path` and the TOML beside it (same stem), if there is one.
    #[staticmethod]
    fn load(path: &str) -> PyResult<Self> {
        Ok(Self { hand: Arc::new(Hand::load(path).map_err(errors::hand)?) })
    }

    /// A hand that ships with vge (`vge15`, `allegro`), or the MJCF file at `spec` when it is
    /// a path (it has a `/` or ends in .xml): the reader of the `[env]` key `hand`.
    #[staticmethod]
    fn named(spec: &str) -> PyResult<Self> {
        Ok(Self { hand: vge_sim::hands::load(spec).map_err(errors::sim)? })
    }

    /// The names of the hands that ship with vge.
    #[staticmethod]
    fn shipped_names() -> Vec<&'static str> {
        vge_sim::hands::shipped_names()
    }

    #[getter]
    fn name(&self) -> &str {
        self.hand.name()
    }

    #[getter]
    fn num_joints(&self) -> usize {
        self.hand.num_joints()
    }

    #[getter]
    fn num_fingers(&self) -> usize {
        self.hand.num_fingers()
    }

    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.hand.joints().iter().map(|j| j.name.clone()).collect()
    }

    #[getter]
    fn finger_names(&self) -> Vec<String> {
        self.hand.fingers().iter().map(|f| f.name.clone()).collect()
    }

    #[getter]
    fn fingertip_names(&self) -> Vec<String> {
        self.hand.fingers().iter().map(|f| f.tip_name.clone()).collect()
    }

    /// `(first, end)` joint indices of each finger.
    #[getter]
    fn finger_joints(&self) -> Vec<(usize, usize)> {
        self.hand.fingers().iter().map(|f| (f.joints.start, f.joints.end)).collect()
    }

    /// `num_joints x 2` (lower, upper) in radians; -inf, inf for an unlimited joint.
    fn joint_limits<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .hand
            .joints()
            .iter()
            .flat_map(|j| match j.limit {
                Some(l) => [f64::from(l.lower_rad), f64::from(l.upper_rad)],
                None => [f64::NEG_INFINITY, f64::INFINITY],
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.hand.num_joints(), 2])
    }

    #[getter]
    fn body_names(&self) -> Vec<Option<String>> {
        self.hand.bodies().iter().map(|b| b.name.clone()).collect()
    }

    #[getter]
    fn description_sha256(&self) -> String {
        self.hand.description_sha256().iter().map(|b| format!("{b:02x}")).collect()
    }

    #[getter]
    fn start_grasp(&self) -> Option<Vec<f32>> {
        self.hand.start_grasp_rad()
    }

    /// `num_fingers x 3` fingertip positions (m, world frame) at joint angles `q`.
    fn fingertip_positions<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let tips = self.hand.fingertip_positions_m(self.joints(&q)?).map_err(errors::hand)?;
        let flat: Vec<f64> = tips.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        PyArray1::from_vec(py, flat).reshape([tips.len(), 3])
    }

    /// `num_fingers x 3 x num_joints` fingertip Jacobians (world frame) at joint angles `q`.
    fn fingertip_jacobians<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let jacobians = self.hand.fingertip_jacobians(self.joints(&q)?).map_err(errors::hand)?;
        let n = self.hand.num_joints();
        // nalgebra is column-major; numpy's rows are the position components.
        let flat: Vec<f64> =
            jacobians.iter().flat_map(|j| (0..3).flat_map(move |r| (0..n).map(move |c| j[(r, c)]))).collect();
        PyArray1::from_vec(py, flat).reshape([jacobians.len(), 3, n])
    }

    /// `num_bodies x 7` world poses at joint angles `q`: position (m), then the quaternion
    /// w x y z (MuJoCo's `xpos`, `xquat`; body 0 is the world).
    fn body_poses<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let poses = self.hand.body_poses_world(self.joints(&q)?).map_err(errors::hand)?;
        let flat: Vec<f64> = poses
            .iter()
            .flat_map(|p| {
                let (t, r) = (p.translation.vector, p.rotation.quaternion());
                [t.x, t.y, t.z, r.w, r.i, r.j, r.k]
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape([poses.len(), 7])
    }

    /// Each body's mass (kg), centre of mass (m) and inertia about it (kg m^2), in its frame,
    /// as MuJoCo compiles them: `(num_bodies,)`, `(num_bodies, 3)`, `(num_bodies, 3, 3)`.
    #[allow(clippy::type_complexity)]
    fn body_mass_properties<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray3<f64>>)> {
        let bodies = self.hand.bodies();
        let props: Vec<_> = bodies.iter().map(|b| b.mass_properties).collect();
        let masses = props.iter().map(|p| f64::from(p.mass_kg)).collect();
        let coms: Vec<f64> = props
            .iter()
            .flat_map(|p| p.com_in_body_m.iter().map(|v| f64::from(*v)).collect::<Vec<_>>())
            .collect();
        let inertias: Vec<f64> = props
            .iter()
            .flat_map(|p| (0..3).flat_map(move |r| (0..3).map(move |c| f64::from(p.inertia_kg_m2[(r, c)]))))
            .collect();
        Ok((
            PyArray1::from_vec(py, masses),
            PyArray1::from_vec(py, coms).reshape([bodies.len(), 3])?,
            PyArray1::from_vec(py, inertias).reshape([bodies.len(), 3, 3])?,
        ))
    }
}
