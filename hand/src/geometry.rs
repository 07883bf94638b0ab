//! MJCF's frame and mass conventions, in `f64` as MuJoCo's compiler computes them (the model
//! is stored in `f32` afterwards): the five ways to write an orientation, `fromto`, and the
//! mass properties of the primitive geoms and of a body made of them.

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};

/// An orientation as written in MJCF, already in radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Orientation {
    /// `quat`: w x y z, normalised by the compiler.
    Quat([f64; 4]),
    /// `axisangle`: axis (normalised) and angle.
    AxisAngle([f64; 3], f64),
    /// `euler`: three angles about the axes of `eulerseq`.
    Euler([f64; 3], [u8; 3]),
    /// `xyaxes`: the frame's x axis and (orthogonalised) y axis.
    XyAxes([f64; 6]),
    /// `zaxis`: the frame's z axis, by the smallest rotation from +z.
    ZAxis([f64; 3]),
}

/// Why an orientation has no rotation (a zero axis or quaternion).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Degenerate;

const EPS: f64 = 1e-14;

fn normalized(v: Vector3<f64>) -> Result<Vector3<f64>, Degenerate> {
    let n = v.norm();
    if n < EPS { Err(Degenerate) } else { Ok(v / n) }
}

/// The rotation taking +z onto `v` by the smallest angle (MuJoCo's `mjuu_z2quat`): about x by
/// pi when `v` points along -z.
pub(crate) fn z_to(v: &Vector3<f64>) -> Result<UnitQuaternion<f64>, Degenerate> {
    if v.norm() < EPS {
        return Err(Degenerate);
    }
    let cross = Vector3::z().cross(v);
    let s = cross.norm();
    let axis = if s < 1e-10 { Vector3::x() } else { cross / s };
    let angle = s.atan2(v.z);
    let (sin, cos) = (0.5 * angle).sin_cos();
    Ok(UnitQuaternion::new_unchecked(Quaternion::new(cos, sin * axis.x, sin * axis.y, sin * axis.z)))
}

impl Orientation {
    /// The rotation it describes, as MuJoCo's compiler resolves it.
    pub(crate) fn rotation(&self) -> Result<UnitQuaternion<f64>, Degenerate> {
        match *self {
            Self::Quat([w, x, y, z]) => {
                let q = Quaternion::new(w, x, y, z);
                if q.norm() < EPS {
                    return Err(Degenerate);
                }
                // Unit to float32 precision: kept as written, so that a file of float32 frames
                // reads back bit for bit (MuJoCo's normalisation would move it by < 1e-7).
                if (q.norm() - 1.0).abs() < UNIT_TOLERANCE {
                    return Ok(UnitQuaternion::new_unchecked(q));
                }
                Ok(UnitQuaternion::from_quaternion(q))
            }
            Self::AxisAngle(axis, angle) => {
                let axis = normalized(Vector3::from(axis))?;
                Ok(UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(axis), angle))
            }
            Self::Euler(angles, seq) => {
                // Lowercase: about the axes of the frame as rotated so far (post-multiply);
                // uppercase: about the parent's fixed axes (pre-multiply).
                let mut q = UnitQuaternion::identity();
                for (angle, axis) in angles.iter().zip(seq) {
                    let unit = match axis.to_ascii_lowercase() {
                        b'x' => Vector3::x_axis(),
                        b'y' => Vector3::y_axis(),
                        _ => Vector3::z_axis(),
                    };
                    let step = UnitQuaternion::from_axis_angle(&unit, *angle);
                    q = if axis.is_ascii_lowercase() { q * step } else { step * q };
                }
                Ok(q)
            }
            Self::XyAxes(v) => {
                let x = normalized(Vector3::new(v[0], v[1], v[2]))?;
                let y = Vector3::new(v[3], v[4], v[5]);
                let y = normalized(y - x * x.dot(&y))?;
                let z = normalized(x.cross(&y))?;
                let m = Matrix3::from_columns(&[x, y, z]);
                Ok(UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)))
            }
            Self::ZAxis(v) => z_to(&Vector3::from(v)),
        }
    }
}

/// How far from 1 a quaternion's norm may be to count as unit: a few float32 roundings.
const UNIT_TOLERANCE: f64 = 4.0 * f32::EPSILON as f64;

/// A pose from a position and a rotation, stored in `f32`.
pub(crate) fn pose_f32(pos: &Vector3<f64>, rot: &UnitQuaternion<f64>) -> Isometry3<f32> {
    let q = rot.quaternion();
    let q32 = Quaternion::new(q.w as f32, q.i as f32, q.j as f32, q.k as f32);
    // Renormalised only where the cast left it off unit: a float32 frame stays as written.
    let rotation = if (f64::from(q32.norm()) - 1.0).abs() < UNIT_TOLERANCE {
        UnitQuaternion::new_unchecked(q32)
    } else {
        UnitQuaternion::new_normalize(q32)
    };
    Isometry3::from_parts(Translation3::new(pos.x as f32, pos.y as f32, pos.z as f32), rotation)
}

/// A primitive's shape for its mass properties (half sizes, m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Solid {
    Sphere { r: f64 },
    Capsule { r: f64, half: f64 },
    Cylinder { r: f64, half: f64 },
    Box { half: Vector3<f64> },
}

impl Solid {
    pub(crate) fn volume_m3(&self) -> f64 {
        use std::f64::consts::PI;
        match *self {
            Self::Sphere { r } => 4.0 / 3.0 * PI * r.powi(3),
            Self::Capsule { r, half } => PI * r * r * 2.0 * half + 4.0 / 3.0 * PI * r.powi(3),
            Self::Cylinder { r, half } => PI * r * r * 2.0 * half,
            Self::Box { half } => 8.0 * half.x * half.y * half.z,
        }
    }

    /// Principal moments about its centre, in its own frame, for mass `m` (MuJoCo's formulas:
    /// a capsule is a cylinder plus two hemispheres displaced along z).
    pub(crate) fn inertia_diag(&self, m: f64) -> Vector3<f64> {
        match *self {
            Self::Sphere { r } => Vector3::repeat(0.4 * m * r * r),
            Self::Capsule { r, half } => {
                let h = 2.0 * half;
                let sphere_m = m * 4.0 * r / (4.0 * r + 3.0 * h);
                let cyl_m = m - sphere_m;
                let sphere_i = 0.4 * sphere_m * r * r;
                let side = cyl_m * (3.0 * r * r + h * h) / 12.0
                    + sphere_i
                    + sphere_m * h * (3.0 * r + 2.0 * h) / 8.0;
                Vector3::new(side, side, cyl_m * r * r / 2.0 + sphere_i)
            }
            Self::Cylinder { r, half } => {
                let h = 2.0 * half;
                let side = m * (3.0 * r * r + h * h) / 12.0;
                Vector3::new(side, side, m * r * r / 2.0)
            }
            Self::Box { half } => {
                let s = half.component_mul(&half);
                Vector3::new(m * (s.y + s.z) / 3.0, m * (s.x + s.z) / 3.0, m * (s.x + s.y) / 3.0)
            }
        }
    }
}

/// One part of a body's mass: mass, centre and inertia tensor about that centre, in the body
/// frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MassPart {
    pub(crate) mass: f64,
    pub(crate) com: Vector3<f64>,
    pub(crate) inertia: Matrix3<f64>,
}

impl MassPart {
    /// A solid of mass `mass` whose frame is at `pos`, turned by `rot`, in the body frame.
    pub(crate) fn of_solid(solid: &Solid, mass: f64, pos: Vector3<f64>, rot: &UnitQuaternion<f64>) -> Self {
        let r = rot.to_rotation_matrix();
        let inertia = r.matrix() * Matrix3::from_diagonal(&solid.inertia_diag(mass)) * r.matrix().transpose();
        Self { mass, com: pos, inertia }
    }

    /// The parts as one: total mass, common centre, inertia about it (parallel axes).
    pub(crate) fn combine(parts: &[Self]) -> Self {
        let mass: f64 = parts.iter().map(|p| p.mass).sum();
        if mass <= 0.0 {
            return Self { mass: 0.0, com: Vector3::zeros(), inertia: Matrix3::zeros() };
        }
        let com = parts.iter().fold(Vector3::zeros(), |acc, p| acc + p.com * p.mass) / mass;
        let inertia = parts.iter().fold(Matrix3::zeros(), |acc, p| {
            let d = p.com - com;
            acc + p.inertia + (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * p.mass
        });
        Self { mass, com, inertia }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn close(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> bool {
        a.angle_to(b) < 1e-12
    }

    #[test]
    fn euler_lowercase_turns_about_moving_axes_and_uppercase_about_fixed_ones() {
        let (a, b) = (0.3, 0.7);
        let rx = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a);
        let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), b);
        let moving = Orientation::Euler([a, b, 0.0], *b"xyz").rotation().unwrap();
        let fixed = Orientation::Euler([a, b, 0.0], *b"XYZ").rotation().unwrap();
        assert!(close(&moving, &(rx * ry)));
        assert!(close(&fixed, &(ry * rx)));
        assert!(!close(&moving, &fixed));
    }

    #[test]
    fn zaxis_down_is_a_half_turn_about_x_and_xyaxes_orthogonalises_y() {
        let down = Orientation::ZAxis([0.0, 0.0, -2.0]).rotation().unwrap();
        assert!(close(&down, &UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)));
        let q = Orientation::XyAxes([0.0, 2.0, 0.0, -1.0, 1.0, 0.0]).rotation().unwrap();
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
        assert!((q * Vector3::y() + Vector3::x()).norm() < 1e-12);
        assert_eq!(Orientation::ZAxis([0.0; 3]).rotation(), Err(Degenerate));
    }

    #[test]
    fn a_capsule_weighs_its_cylinder_and_its_two_hemispheres() {
        let (r, half) = (0.01, 0.02);
        let capsule = Solid::Capsule { r, half }.volume_m3();
        let parts = Solid::Cylinder { r, half }.volume_m3() + Solid::Sphere { r }.volume_m3();
        assert!((capsule - parts).abs() < 1e-18);
        // Two unit point-like spheres at +-1 on x: inertia 2 about y and z, 0 about x.
        let tiny = Solid::Sphere { r: 1e-9 };
        let rot = UnitQuaternion::identity();
        let a = MassPart::of_solid(&tiny, 1.0, Vector3::x(), &rot);
        let b = MassPart::of_solid(&tiny, 1.0, -Vector3::x(), &rot);
        let both = MassPart::combine(&[a, b]);
        assert!((both.inertia - Matrix3::from_diagonal(&Vector3::new(0.0, 2.0, 2.0))).norm() < 1e-12);
        assert_eq!(both.com, Vector3::zeros());
    }
}
