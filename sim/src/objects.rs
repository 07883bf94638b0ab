//! The objects the hand turns: a cube (default), a sphere, a cylinder (axis along z) and
//! two convex polyhedra (dodecahedron, icosahedron) whose vertices are generated here: the
//! paper's five ([`ObjectShape::PAPER`]). A sixth, the hexagonal prism (axis along z), is
//! no object of the paper's: it tests a policy on a shape it never trained on.
//!
//! Every shape is scaled so that its *width* (twice the distance from its centre to its
//! closest surface point, i.e. twice the inradius) equals [`ObjectConfig::width_m`]: the
//! fingers then meet every object at about the same flexion as the 10 cm cube.

use rapier3d::geometry::{ColliderBuilder, SharedShape};
use rapier3d::math::{Pose, Rotation, Vector};

use crate::error::SimError;

/// Which object is grasped. Configs spell it as [`ObjectShape::name`] does (`"cube"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectShape {
    /// A cube (the paper's default).
    #[default]
    Cube,
    /// A sphere.
    Sphere,
    /// A cylinder standing on its axis (axis along world z).
    Cylinder,
    /// A regular dodecahedron (convex hull of its 20 vertices).
    Dodecahedron,
    /// A regular icosahedron (convex hull of its 12 vertices).
    Icosahedron,
    /// A regular hexagonal prism standing on a hexagon (axis along world z, convex hull of
    /// its 12 vertices), as tall as it is wide across its flats: the unseen object.
    HexagonalPrism,
}

impl ObjectShape {
    /// All shapes, in a fixed order.
    pub const ALL: [Self; 6] = [
        Self::Cube,
        Self::Sphere,
        Self::Cylinder,
        Self::Dodecahedron,
        Self::Icosahedron,
        Self::HexagonalPrism,
    ];

    /// The paper's five objects (its multi-object experiment), in a fixed order.
    pub const PAPER: [Self; 5] =
        [Self::Cube, Self::Sphere, Self::Cylinder, Self::Dodecahedron, Self::Icosahedron];

    /// Lower-case name, e.g. "cube".
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Cube => "cube",
            Self::Sphere => "sphere",
            Self::Cylinder => "cylinder",
            Self::Dodecahedron => "dodecahedron",
            Self::Icosahedron => "icosahedron",
            Self::HexagonalPrism => "hexagonal-prism",
        }
    }
}

impl std::str::FromStr for ObjectShape {
    type Err = String;

    /// Parses a lower-case name as [`ObjectShape::name`] gives it.
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|o| o.name() == s).ok_or_else(|| {
            let names: Vec<_> = Self::ALL.iter().map(|o| o.name()).collect();
            format!("unknown object `{s}` (one of: {})", names.join(", "))
        })
    }
}

impl std::fmt::Display for ObjectShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Object parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectConfig {
    /// Shape.
    pub shape: ObjectShape,
    /// Width: twice the inradius (a cube's side, a sphere's or cylinder's diameter).
    pub width_m: f32,
    /// Mass.
    pub mass_kg: f32,
    /// Coulomb friction coefficient of the object (combined with the fingers' by average).
    pub friction: f32,
}

impl Default for ObjectConfig {
    /// 10 cm cube, 0.15 kg, friction 0.8 (the notes: 0.5-1.0 behaves like Coulomb).
    fn default() -> Self {
        Self { shape: ObjectShape::Cube, width_m: 0.10, mass_kg: 0.15, friction: 0.8 }
    }
}

impl ObjectConfig {
    /// A default-sized object of `shape`.
    #[must_use]
    pub fn of(shape: ObjectShape) -> Self {
        Self { shape, ..Self::default() }
    }

    pub(crate) fn validate(&self) -> Result<(), SimError> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        if !ok(self.width_m) || self.width_m > 0.3 {
            return Err(SimError::InvalidConfig(format!("object width {} m", self.width_m)));
        }
        if !ok(self.mass_kg) {
            return Err(SimError::InvalidConfig(format!("object mass {} kg", self.mass_kg)));
        }
        if !self.friction.is_finite() || self.friction < 0.0 {
            return Err(SimError::InvalidConfig(format!("object friction {}", self.friction)));
        }
        Ok(())
    }

    /// The collision shape, centred on the body origin.
    pub fn shape(&self) -> Result<SharedShape, SimError> {
        let half = 0.5 * self.width_m;
        let hull = |unit: Vec<Vector>, inradius: f32| -> Result<SharedShape, SimError> {
            let scaled: Vec<Vector> = unit.iter().map(|v| *v * (half / inradius)).collect();
            SharedShape::convex_hull(&scaled)
                .ok_or_else(|| SimError::InvalidConfig("degenerate convex hull".to_owned()))
        };
        Ok(match self.shape {
            ObjectShape::Cube => SharedShape::cuboid(half, half, half),
            ObjectShape::Sphere => SharedShape::ball(half),
            ObjectShape::Cylinder => SharedShape::cylinder(half, half),
            ObjectShape::Dodecahedron => hull(dodecahedron_vertices(), DODECAHEDRON_INRADIUS)?,
            ObjectShape::Icosahedron => hull(icosahedron_vertices(), ICOSAHEDRON_INRADIUS)?,
            ObjectShape::HexagonalPrism => hull(hexagonal_prism_vertices(), HEXAGONAL_PRISM_INRADIUS)?,
        })
    }

    /// Collider (shape, mass, friction); a cylinder is turned so that its axis is z.
    pub(crate) fn collider(&self) -> Result<ColliderBuilder, SimError> {
        let pose = match self.shape {
            ObjectShape::Cylinder => {
                Pose::from_rotation(Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2))
            }
            _ => Pose::IDENTITY,
        };
        Ok(ColliderBuilder::new(self.shape()?).position(pose).mass(self.mass_kg).friction(self.friction))
    }
}

const PHI: f32 = 1.618_034;
/// Inradius of [`dodecahedron_vertices`]: edge 2/phi, r = (a/2) sqrt(5/2 + 11 sqrt(5)/10).
const DODECAHEDRON_INRADIUS: f32 = 1.376_382;
/// Inradius of [`icosahedron_vertices`]: edge 2, r = phi^2 a / (2 sqrt(3)).
const ICOSAHEDRON_INRADIUS: f32 = 1.511_523;

/// The 20 vertices of a regular dodecahedron (circumradius sqrt(3)).
#[must_use]
pub fn dodecahedron_vertices() -> Vec<Vector> {
    let mut v = Vec::with_capacity(20);
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0f32, 1.0] {
                v.push(Vector::new(sx, sy, sz));
            }
        }
    }
    let (a, b) = (1.0 / PHI, PHI);
    for s1 in [-1.0, 1.0] {
        for s2 in [-1.0f32, 1.0] {
            v.push(Vector::new(0.0, s1 * a, s2 * b));
            v.push(Vector::new(s1 * a, s2 * b, 0.0));
            v.push(Vector::new(s1 * b, 0.0, s2 * a));
        }
    }
    v
}

/// The 12 vertices of a regular icosahedron (edge 2).
#[must_use]
pub fn icosahedron_vertices() -> Vec<Vector> {
    let mut v = Vec::with_capacity(12);
    for s1 in [-1.0, 1.0] {
        for s2 in [-1.0f32, 1.0] {
            v.push(Vector::new(0.0, s1, s2 * PHI));
            v.push(Vector::new(s1, s2 * PHI, 0.0));
            v.push(Vector::new(s2 * PHI, 0.0, s1));
        }
    }
    v
}

/// Inradius of [`hexagonal_prism_vertices`]: the hexagon's apothem and the half height are
/// both 1.
const HEXAGONAL_PRISM_INRADIUS: f32 = 1.0;

/// The 12 vertices of a regular hexagonal prism with apothem 1 and height 2 (axis z), a
/// vertex of each hexagon on the x axis (so its flats face ±y).
#[must_use]
pub fn hexagonal_prism_vertices() -> Vec<Vector> {
    let circumradius = 1.0 / (std::f32::consts::PI / 6.0).cos();
    let mut v = Vec::with_capacity(12);
    for z in [-1.0f32, 1.0] {
        for k in 0..6 {
            let angle = k as f32 * std::f32::consts::PI / 3.0;
            v.push(Vector::new(circumradius * angle.cos(), circumradius * angle.sin(), z));
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shape_has_the_configured_width() {
        for shape in ObjectShape::ALL {
            let cfg = ObjectConfig::of(shape);
            let shape_ref = cfg.shape().expect("shape");
            let s = shape_ref.as_support_map().expect("convex");
            // The inradius is the smallest support distance over the face normals; those of
            // a dodecahedron point at an icosahedron's vertices (in one of two orientations)
            // and vice versa (duality),
            // and the axes cover the cube, sphere and cylinder.
            let axes = [Vector::X, Vector::Y, Vector::Z, -Vector::X, -Vector::Y, -Vector::Z];
            let inradius = axes
                .into_iter()
                .chain(dodecahedron_vertices())
                .chain(icosahedron_vertices())
                .chain(icosahedron_vertices().into_iter().map(|v| Vector::new(v.y, v.x, v.z)))
                .map(|d| {
                    let d = d.normalize();
                    s.local_support_point(d).dot(d)
                })
                .fold(f32::INFINITY, f32::min);
            assert!((inradius - 0.05).abs() < 1e-5, "{}: inradius {inradius}", shape.name());
        }
    }

    #[test]
    fn names_parse_back_to_their_shapes() {
        for shape in ObjectShape::ALL {
            assert_eq!(shape.name().parse::<ObjectShape>(), Ok(shape));
        }
        assert!(ObjectShape::PAPER.iter().all(|s| ObjectShape::ALL.contains(s)));
        assert!(!ObjectShape::PAPER.contains(&ObjectShape::HexagonalPrism), "the unseen object");
    }

    #[test]
    fn the_hexagonal_prism_stands_on_its_hexagon() {
        let cfg = ObjectConfig::of(ObjectShape::HexagonalPrism);
        let shape = cfg.shape().expect("shape");
        let s = shape.as_support_map().expect("convex");
        let support = |d: Vector| s.local_support_point(d).dot(d);
        // Flats face ±y, corners ±x (at the circumradius, 2/sqrt(3) times the apothem),
        // the hexagons ±z.
        assert!((support(Vector::Y) - 0.05).abs() < 1e-5);
        assert!((support(Vector::X) - 0.05 / (std::f32::consts::PI / 6.0).cos()).abs() < 1e-5);
        assert!((support(Vector::Z) - 0.05).abs() < 1e-5);
    }

    #[test]
    fn polyhedra_are_regular() {
        for (verts, n) in [(dodecahedron_vertices(), 20), (icosahedron_vertices(), 12)] {
            assert_eq!(verts.len(), n);
            let r0 = verts[0].length();
            assert!(verts.iter().all(|v| (v.length() - r0).abs() < 1e-5));
        }
    }

    #[test]
    fn bad_configs_are_rejected() {
        let c = ObjectConfig { mass_kg: f32::NAN, ..ObjectConfig::default() };
        assert!(c.validate().is_err());
        let c = ObjectConfig { friction: -1.0, ..ObjectConfig::default() };
        assert!(c.validate().is_err());
    }
}
