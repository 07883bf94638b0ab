//! The MJCF reader: vge's subset of MuJoCo's XML, read with MuJoCo's semantics (default
//! classes, `childclass`, `autolimits`, degrees, the five orientation forms), everything outside
//! the subset refused with its element and line. The crate docs list the subset.

use std::collections::HashMap;

use nalgebra::{Matrix3, Unit, UnitQuaternion, Vector3};
use roxmltree::{Document, Node, ParsingOptions};

use crate::error::{HandError, Location};
use crate::geometry::{MassPart, Orientation, Solid, pose_f32, z_to};
use crate::model::{
    Body, ContactExclude, Geom, GeomMass, GeomShape, Inertial, Joint, JointLimit, Keyframe, PhysicsOptions,
    PositionServo, Site,
};

/// More XML nodes than any hand needs (Menagerie's largest hands have a few thousand).
const MAX_NODES: u32 = 200_000;

/// What the XML describes, before the fingers are resolved.
#[derive(Debug)]
pub(crate) struct Parsed {
    pub(crate) model_name: Option<String>,
    pub(crate) bodies: Vec<Body>,
    pub(crate) joints: Vec<Joint>,
    pub(crate) sites: Vec<Site>,
    pub(crate) excludes: Vec<ContactExclude>,
    pub(crate) keyframes: Vec<Keyframe>,
    pub(crate) options: PhysicsOptions,
    /// Where each body, joint and site is written (for the finger errors).
    pub(crate) body_at: Vec<Location>,
    pub(crate) joint_at: Vec<Location>,
    pub(crate) site_at: Vec<Location>,
    /// Where the keyframes are written.
    pub(crate) key_at: Vec<Location>,
}

// Attributes each element may have. An attribute not listed is refused: it may change the
// physics, and the reader never ignores what it does not read. Listed and not carried (the crate
// docs say why): names of assets, drawing (`material`, `rgba`, `group` of sites), `user` data,
// and MuJoCo's contact-solver parameters (`solref`, `solimp`, `margin`, ...).
const MUJOCO_ATTRS: &[&str] = &["model"];
const COMPILER_ATTRS: &[&str] = &[
    "angle",
    "eulerseq",
    "autolimits",
    "inertiafromgeom",
    "meshdir",
    "texturedir",
    "assetdir",
    "discardvisual",
    "strippath",
    "usethread",
    "saveinertial",
    "alignfree",
];
const OPTION_ATTRS: &[&str] = &[
    "timestep",
    "gravity",
    "integrator",
    "cone",
    "impratio",
    "iterations",
    "ls_iterations",
    "noslip_iterations",
    "ccd_iterations",
    "sdf_iterations",
    "sdf_initpoints",
    "tolerance",
    "ls_tolerance",
    "noslip_tolerance",
    "ccd_tolerance",
    "solver",
    "jacobian",
    "apirate",
    "magnetic",
];
const BODY_ATTRS: &[&str] = &[
    "name",
    "childclass",
    "pos",
    "quat",
    "euler",
    "axisangle",
    "xyaxes",
    "zaxis",
    "mocap",
    "gravcomp",
    "user",
];
const INERTIAL_ATTRS: &[&str] =
    &["pos", "quat", "euler", "axisangle", "xyaxes", "zaxis", "mass", "diaginertia", "fullinertia"];
const JOINT_ATTRS: &[&str] = &[
    "name",
    "class",
    "type",
    "pos",
    "axis",
    "range",
    "limited",
    "damping",
    "armature",
    "frictionloss",
    "stiffness",
    "springref",
    "ref",
    "group",
    "user",
    "solreflimit",
    "solimplimit",
    "solreffriction",
    "solimpfriction",
    "margin",
];
const GEOM_ATTRS: &[&str] = &[
    "name",
    "class",
    "type",
    "size",
    "fromto",
    "pos",
    "quat",
    "euler",
    "axisangle",
    "xyaxes",
    "zaxis",
    "contype",
    "conaffinity",
    "condim",
    "friction",
    "density",
    "mass",
    "group",
    "mesh",
    "material",
    "rgba",
    "priority",
    "solmix",
    "solref",
    "solimp",
    "margin",
    "gap",
    "user",
];
const SITE_ATTRS: &[&str] = &[
    "name",
    "class",
    "type",
    "size",
    "pos",
    "quat",
    "euler",
    "axisangle",
    "xyaxes",
    "zaxis",
    "material",
    "rgba",
    "group",
    "user",
];
const POSITION_ATTRS: &[&str] = &[
    "name",
    "class",
    "joint",
    "kp",
    "kv",
    "dampratio",
    "timeconst",
    "inheritrange",
    "ctrlrange",
    "ctrllimited",
    "forcerange",
    "forcelimited",
    "gear",
    "group",
    "user",
];
const GENERAL_ATTRS: &[&str] = &[
    "name",
    "class",
    "joint",
    "ctrlrange",
    "ctrllimited",
    "forcerange",
    "forcelimited",
    "gear",
    "group",
    "user",
    "dyntype",
    "gaintype",
    "biastype",
    "gainprm",
    "biasprm",
    "dynprm",
];
const KEY_ATTRS: &[&str] = &["name", "time", "qpos", "qvel", "ctrl"];
const EXCLUDE_ATTRS: &[&str] = &["name", "body1", "body2"];
const ORIENTATIONS: [&str; 5] = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];

/// Sections and elements that do not change the physics: skipped with all they contain.
const SKIPPED_SECTIONS: &[&str] = &["size", "visual", "statistic", "asset", "sensor", "custom"];
const SKIPPED_IN_BODY: &[&str] = &["camera", "light"];
/// Defaults of elements the subset either draws only or refuses where they are used.
const SKIPPED_IN_DEFAULT: &[&str] = &[
    "mesh",
    "material",
    "texture",
    "camera",
    "light",
    "pair",
    "equality",
    "tendon",
    "motor",
    "velocity",
    "intvelocity",
    "damper",
    "cylinder",
    "muscle",
    "adhesion",
];
/// Element types a default class holds values for.
const DEFAULTED: [&str; 5] = ["joint", "geom", "site", "position", "general"];

const UNKNOWN_WHY: &str = "vge does not know this element, and never ignores what it does not read";

/// Byte offsets of line starts, to name lines in errors.
struct Lines(Vec<usize>);

impl Lines {
    fn new(text: &str) -> Self {
        Self(std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect())
    }

    fn line(&self, pos: usize) -> u32 {
        let line = self.0.partition_point(|&start| start <= pos);
        u32::try_from(line).unwrap_or(u32::MAX)
    }
}

/// One attribute value and the element that wrote it (the element itself or a default).
#[derive(Clone, Copy)]
struct Src<'a, 'i> {
    value: &'a str,
    node: Node<'a, 'i>,
}

type Table<'a, 'i> = HashMap<&'a str, Src<'a, 'i>>;

/// A default class: attribute values per element type, its parent's merged in.
#[derive(Clone, Default)]
struct Class<'a, 'i> {
    tables: HashMap<&'static str, Table<'a, 'i>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InertiaFromGeom {
    False,
    True,
    Auto,
}

#[derive(Debug, Clone, Copy)]
struct Compiler {
    degrees: bool,
    eulerseq: [u8; 3],
    autolimits: bool,
    inertia_from_geom: InertiaFromGeom,
}

impl Default for Compiler {
    /// MuJoCo's defaults: degrees, "xyz", autolimits on, inertia from geoms when no `<inertial>`.
    fn default() -> Self {
        Self { degrees: true, eulerseq: *b"xyz", autolimits: true, inertia_from_geom: InertiaFromGeom::Auto }
    }
}

/// `limited`, `ctrllimited`, `forcelimited`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Limited {
    True,
    False,
    Auto,
}

/// Reads the document into a [`Parsed`].
pub(crate) fn parse(xml: &str, file: &str) -> Result<Parsed, HandError> {
    let options = ParsingOptions { allow_dtd: false, nodes_limit: MAX_NODES, ..ParsingOptions::default() };
    let doc = Document::parse_with_options(xml, options).map_err(|e| HandError::Xml {
        file: file.to_owned(),
        line: e.pos().row,
        message: e.to_string(),
    })?;
    let mut reader = Reader {
        file,
        lines: Lines::new(xml),
        compiler: Compiler::default(),
        classes: HashMap::new(),
        body_names: HashMap::new(),
        joint_names: HashMap::new(),
        num_actuators: 0,
        out: Parsed {
            model_name: None,
            bodies: Vec::new(),
            joints: Vec::new(),
            sites: Vec::new(),
            excludes: Vec::new(),
            keyframes: Vec::new(),
            options: PhysicsOptions::default(),
            body_at: Vec::new(),
            joint_at: Vec::new(),
            site_at: Vec::new(),
            key_at: Vec::new(),
        },
    };
    reader.document(doc.root_element())?;
    Ok(reader.out)
}

struct Reader<'a, 'i> {
    file: &'a str,
    lines: Lines,
    compiler: Compiler,
    classes: HashMap<&'a str, Class<'a, 'i>>,
    body_names: HashMap<String, usize>,
    joint_names: HashMap<String, usize>,
    num_actuators: usize,
    out: Parsed,
}

/// The attributes an element has: its own, then its class's.
struct Attrs<'r, 'a, 'i> {
    node: Node<'a, 'i>,
    own: Table<'a, 'i>,
    inherited: Option<&'r Table<'a, 'i>>,
}

impl<'a, 'i> Attrs<'_, 'a, 'i> {
    fn get(&self, name: &str) -> Option<Src<'a, 'i>> {
        self.own.get(name).or_else(|| self.inherited.and_then(|t| t.get(name))).copied()
    }

    fn own_str(&self, name: &str) -> Option<&'a str> {
        self.own.get(name).map(|s| s.value)
    }
}

fn tag<'a>(node: Node<'a, '_>) -> &'a str {
    node.tag_name().name()
}

fn elements<'a, 'i>(node: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(Node::is_element)
}

impl<'a, 'i> Reader<'a, 'i> {
    fn at(&self, node: Node<'_, '_>) -> Location {
        Location {
            file: self.file.to_owned(),
            line: self.lines.line(node.range().start),
            element: tag(node).to_owned(),
        }
    }

    fn unsupported(&self, node: Node<'_, '_>, what: impl Into<String>, why: impl Into<String>) -> HandError {
        HandError::Unsupported { at: self.at(node), what: what.into(), why: why.into() }
    }

    fn invalid(&self, node: Node<'_, '_>, message: impl Into<String>) -> HandError {
        HandError::Invalid { at: self.at(node), message: message.into() }
    }

    fn unknown(&self, node: Node<'_, '_>) -> HandError {
        self.unsupported(node, format!("element <{}>", tag(node)), UNKNOWN_WHY)
    }

    fn check_attrs(&self, node: Node<'_, '_>, allowed: &[&str]) -> Result<(), HandError> {
        match node.attributes().find(|a| !allowed.contains(&a.name())) {
            None => Ok(()),
            Some(a) => Err(self.unsupported(
                node,
                format!("attribute `{}` of <{}>", a.name(), tag(node)),
                "vge does not read it; it may change the physics, and vge never ignores what it does not read",
            )),
        }
    }

    fn own_table(node: Node<'a, 'i>) -> Table<'a, 'i> {
        node.attributes().map(|a| (a.name(), Src { value: a.value(), node })).collect()
    }

    // ---- values ----

    fn numbers(&self, src: Src<'_, '_>, name: &str) -> Result<Vec<f64>, HandError> {
        src.value
            .split_whitespace()
            .map(|t| match t.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(self.invalid(src.node, format!("attribute `{name}`: `{t}` is not a finite number"))),
            })
            .collect()
    }

    fn fixed<const N: usize>(
        &self,
        attrs: &Attrs<'_, 'a, 'i>,
        name: &str,
    ) -> Result<Option<[f64; N]>, HandError> {
        let Some(src) = attrs.get(name) else { return Ok(None) };
        let v = self.numbers(src, name)?;
        <[f64; N]>::try_from(v.as_slice()).map(Some).map_err(|_| {
            self.invalid(src.node, format!("attribute `{name}` needs {N} numbers, has {}", v.len()))
        })
    }

    fn scalar(&self, attrs: &Attrs<'_, 'a, 'i>, name: &str, default: f64) -> Result<f64, HandError> {
        Ok(self.fixed::<1>(attrs, name)?.map_or(default, |[v]| v))
    }

    /// Up to N numbers over `base`, the class's first and then the element's own (MuJoCo reads
    /// `size` and `friction` partially: what is not written keeps its default).
    fn partial<const N: usize>(
        &self,
        attrs: &Attrs<'_, 'a, 'i>,
        name: &str,
        base: [f64; N],
    ) -> Result<[f64; N], HandError> {
        let mut out = base;
        let layers = [attrs.inherited.and_then(|t| t.get(name)).copied(), attrs.own.get(name).copied()];
        for src in layers.into_iter().flatten() {
            let v = self.numbers(src, name)?;
            if v.is_empty() || v.len() > N {
                return Err(self.invalid(
                    src.node,
                    format!("attribute `{name}` needs 1 to {N} numbers, has {}", v.len()),
                ));
            }
            out[..v.len()].copy_from_slice(&v);
        }
        Ok(out)
    }

    fn integer(&self, attrs: &Attrs<'_, 'a, 'i>, name: &str, default: i64) -> Result<i64, HandError> {
        let Some(src) = attrs.get(name) else { return Ok(default) };
        src.value.trim().parse().map_err(|_| {
            self.invalid(src.node, format!("attribute `{name}`: `{}` is not an integer", src.value))
        })
    }

    fn boolean(&self, src: Src<'_, '_>, name: &str) -> Result<bool, HandError> {
        match src.value.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            other => {
                Err(self.invalid(src.node, format!("attribute `{name}`: `{other}` is not true or false")))
            }
        }
    }

    fn limited(&self, attrs: &Attrs<'_, 'a, 'i>, name: &str) -> Result<Limited, HandError> {
        let Some(src) = attrs.get(name) else { return Ok(Limited::Auto) };
        match src.value.trim() {
            "true" => Ok(Limited::True),
            "false" => Ok(Limited::False),
            "auto" => Ok(Limited::Auto),
            other => {
                Err(self
                    .invalid(src.node, format!("attribute `{name}`: `{other}` is not true, false or auto")))
            }
        }
    }

    /// A `[lower, upper]` range and its `limited` flag with MuJoCo's rules: `auto` means limited
    /// when a range is written, provided `autolimits` is on (MuJoCo refuses it otherwise).
    fn range(
        &self,
        attrs: &Attrs<'_, 'a, 'i>,
        range_name: &str,
        limited_name: &str,
    ) -> Result<Option<[f64; 2]>, HandError> {
        let range = self.fixed::<2>(attrs, range_name)?;
        let limited = match self.limited(attrs, limited_name)? {
            Limited::True => true,
            Limited::False => false,
            Limited::Auto if range.is_none() => false,
            Limited::Auto if self.compiler.autolimits => true,
            Limited::Auto => {
                return Err(self.invalid(
                    attrs.node,
                    format!(
                        "`{range_name}` without `{limited_name}` while the compiler's autolimits is false"
                    ),
                ));
            }
        };
        if !limited {
            return Ok(None);
        }
        match range {
            Some([lo, hi]) if lo < hi => Ok(Some([lo, hi])),
            Some([lo, hi]) => {
                Err(self.invalid(attrs.node, format!("`{range_name}` {lo} {hi}: lower must be below upper")))
            }
            None => {
                Err(self
                    .invalid(attrs.node, format!("`{limited_name}` is true but there is no `{range_name}`")))
            }
        }
    }

    fn angle(&self, v: f64) -> f64 {
        if self.compiler.degrees { v.to_radians() } else { v }
    }

    /// The element's orientation: its own (at most one form), else its class's.
    fn orientation(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<UnitQuaternion<f64>, HandError> {
        let own: Vec<&str> = ORIENTATIONS.iter().copied().filter(|n| attrs.own.contains_key(n)).collect();
        let chosen: Vec<&str> = if own.is_empty() {
            ORIENTATIONS
                .iter()
                .copied()
                .filter(|n| attrs.inherited.is_some_and(|t| t.contains_key(n)))
                .collect()
        } else {
            own
        };
        let name = match chosen.as_slice() {
            [] => return Ok(UnitQuaternion::identity()),
            [one] => *one,
            more => {
                return Err(
                    self.invalid(attrs.node, format!("more than one orientation: {}", more.join(", ")))
                );
            }
        };
        let orientation = match name {
            "quat" => self.fixed::<4>(attrs, name)?.map(Orientation::Quat),
            "axisangle" => self
                .fixed::<4>(attrs, name)?
                .map(|[x, y, z, a]| Orientation::AxisAngle([x, y, z], self.angle(a))),
            "euler" => self
                .fixed::<3>(attrs, name)?
                .map(|e| Orientation::Euler(e.map(|v| self.angle(v)), self.compiler.eulerseq)),
            "xyaxes" => self.fixed::<6>(attrs, name)?.map(Orientation::XyAxes),
            _ => self.fixed::<3>(attrs, name)?.map(Orientation::ZAxis),
        };
        let src = attrs.get(name).map_or(attrs.node, |s| s.node);
        match orientation {
            Some(o) => {
                o.rotation().map_err(|_| self.invalid(src, format!("`{name}` has a zero axis or quaternion")))
            }
            None => Ok(UnitQuaternion::identity()),
        }
    }

    fn position(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<Vector3<f64>, HandError> {
        Ok(self.fixed::<3>(attrs, "pos")?.map_or_else(Vector3::zeros, Vector3::from))
    }

    // ---- classes ----

    fn class_of(&self, node: Node<'a, 'i>, childclass: &'a str) -> Result<&'a str, HandError> {
        match node.attribute("class") {
            None => Ok(childclass),
            Some(name) if self.classes.contains_key(name) => Ok(name),
            Some(name) => Err(self.invalid(node, format!("class `{name}` is not defined"))),
        }
    }

    fn attrs<'r>(&'r self, node: Node<'a, 'i>, class: &str, kind: &str) -> Attrs<'r, 'a, 'i> {
        let inherited = self.classes.get(class).and_then(|c| c.tables.get(kind));
        Attrs { node, own: Self::own_table(node), inherited }
    }

    fn default(&mut self, node: Node<'a, 'i>, parent: Option<&'a str>) -> Result<(), HandError> {
        self.check_attrs(node, &["class"])?;
        let name = match (node.attribute("class"), parent) {
            (None | Some("main"), None) => "main",
            (Some(other), None) => {
                return Err(
                    self.invalid(node, format!("the top-level default class is `main`, not `{other}`"))
                );
            }
            (None, Some(_)) => return Err(self.invalid(node, "a nested default needs a `class` name")),
            (Some(name), Some(_)) => {
                if self.classes.contains_key(name) {
                    return Err(self.invalid(node, format!("default class `{name}` is defined twice")));
                }
                name
            }
        };
        let mut class = match parent {
            Some(p) => self.classes.get(p).cloned().unwrap_or_default(),
            None => self.classes.get("main").cloned().unwrap_or_default(),
        };
        let mut nested = Vec::new();
        for child in elements(node) {
            let kind = tag(child);
            if let Some(kind) = DEFAULTED.iter().find(|k| **k == kind) {
                let allowed: Vec<&str> = allowed_attrs(kind)
                    .iter()
                    .copied()
                    .filter(|a| !matches!(*a, "name" | "class" | "joint"))
                    .collect();
                self.check_attrs(child, &allowed)?;
                class.tables.entry(*kind).or_default().extend(Self::own_table(child));
            } else if kind == "default" {
                nested.push(child);
            } else if !SKIPPED_IN_DEFAULT.contains(&kind) {
                return Err(self.unknown(child));
            }
        }
        let sets = |k: &str| class.tables.get(k).is_some_and(|t| !t.is_empty());
        if sets("position") && sets("general") {
            return Err(self.unsupported(
                node,
                format!("default class `{name}` with both <position> and <general> values"),
                "MuJoCo merges them into one actuator default; write one of the two",
            ));
        }
        self.classes.insert(name, class);
        for child in nested {
            self.default(child, Some(name))?;
        }
        Ok(())
    }

    // ---- document ----

    fn document(&mut self, root: Node<'a, 'i>) -> Result<(), HandError> {
        if tag(root) != "mujoco" {
            return Err(self.invalid(root, "the root element of an MJCF file is <mujoco>"));
        }
        self.check_attrs(root, MUJOCO_ATTRS)?;
        self.out.model_name = root.attribute("model").map(str::to_owned);
        let mut sections: HashMap<&str, Vec<Node<'a, 'i>>> = HashMap::new();
        for child in elements(root) {
            let kind = tag(child);
            match kind {
                "compiler" | "option" | "default" | "worldbody" | "contact" | "actuator" | "keyframe" => {
                    sections.entry(kind).or_default().push(child);
                }
                "tendon" | "equality" => {
                    // An empty section changes nothing; its first entry is what vge cannot carry.
                    if let Some(first) = elements(child).next() {
                        let why = if kind == "tendon" {
                            "vge's joints are driven one by one; a tendon couples them"
                        } else {
                            "an equality constraint (also how MJCF writes mimic joints) couples bodies or joints"
                        };
                        return Err(self.unsupported(first, format!("<{}> in <{kind}>", tag(first)), why));
                    }
                }
                "include" => {
                    return Err(self.unsupported(
                        child,
                        "<include>",
                        "write the included file's content into this one",
                    ));
                }
                "extension" | "deformable" => {
                    return Err(self.unsupported(
                        child,
                        format!("<{kind}>"),
                        "plugins and deformables are not rigid hands",
                    ));
                }
                _ if SKIPPED_SECTIONS.contains(&kind) => {}
                _ => return Err(self.unknown(child)),
            }
        }
        // MuJoCo reads the sections in this order whatever their order in the file.
        let section = |name: &str| sections.get(name).cloned().unwrap_or_default();
        for node in section("compiler") {
            self.compiler_section(node)?;
        }
        for node in section("option") {
            self.option_section(node)?;
        }
        self.classes.insert("main", Class::default());
        for node in section("default") {
            self.default(node, None)?;
        }
        self.world(root, &section("worldbody"))?;
        for node in section("contact") {
            self.contact_section(node)?;
        }
        for node in section("actuator") {
            self.actuator_section(node)?;
        }
        for node in section("keyframe") {
            self.keyframe_section(node)?;
        }
        Ok(())
    }

    fn compiler_section(&mut self, node: Node<'a, 'i>) -> Result<(), HandError> {
        self.check_attrs(node, COMPILER_ATTRS)?;
        if let Some(child) = elements(node).next() {
            return Err(self.unknown(child));
        }
        let attrs = Attrs { node, own: Self::own_table(node), inherited: None };
        if let Some(src) = attrs.get("angle") {
            self.compiler.degrees = match src.value {
                "degree" => true,
                "radian" => false,
                other => {
                    return Err(self.invalid(node, format!("angle `{other}` is neither degree nor radian")));
                }
            };
        }
        if let Some(src) = attrs.get("eulerseq") {
            let seq = src.value.as_bytes();
            match <[u8; 3]>::try_from(seq) {
                Ok(seq) if seq.iter().all(|c| b"xyzXYZ".contains(c)) => self.compiler.eulerseq = seq,
                _ => {
                    return Err(
                        self.invalid(node, format!("eulerseq `{}` is not 3 of x y z X Y Z", src.value))
                    );
                }
            }
        }
        if let Some(src) = attrs.get("autolimits") {
            self.compiler.autolimits = self.boolean(src, "autolimits")?;
        }
        if let Some(src) = attrs.get("inertiafromgeom") {
            self.compiler.inertia_from_geom = match src.value {
                "false" => InertiaFromGeom::False,
                "true" => InertiaFromGeom::True,
                "auto" => InertiaFromGeom::Auto,
                other => {
                    return Err(
                        self.invalid(node, format!("inertiafromgeom `{other}` is not false, true or auto"))
                    );
                }
            };
        }
        Ok(())
    }

    /// `<option>`: gravity and time step are carried; the rest are MuJoCo's solver settings
    /// (integrator, cone, iterations, tolerances), which describe MuJoCo, not the hand.
    fn option_section(&mut self, node: Node<'a, 'i>) -> Result<(), HandError> {
        self.check_attrs(node, OPTION_ATTRS)?;
        if let Some(child) = elements(node).next() {
            let why = "<flag> switches MuJoCo's physics terms on or off";
            return Err(self.unsupported(child, format!("<{}> in <option>", tag(child)), why));
        }
        let attrs = Attrs { node, own: Self::own_table(node), inherited: None };
        if let Some(g) = self.fixed::<3>(&attrs, "gravity")? {
            self.out.options.gravity_m_per_s2 = Some(Vector3::from(g).map(|v| v as f32));
        }
        if let Some([dt]) = self.fixed::<1>(&attrs, "timestep")? {
            if dt <= 0.0 {
                return Err(self.invalid(node, format!("timestep {dt} s is not positive")));
            }
            self.out.options.timestep_s = Some(dt as f32);
        }
        Ok(())
    }

    // ---- bodies ----

    fn world(&mut self, root: Node<'a, 'i>, sections: &[Node<'a, 'i>]) -> Result<(), HandError> {
        let world = Body {
            name: Some("world".to_owned()),
            parent: None,
            pose_in_parent: nalgebra::Isometry3::identity(),
            joints: 0..0,
            geoms: Vec::new(),
            inertial: None,
            mass_properties: zero_inertial(),
        };
        self.body_names.insert("world".to_owned(), 0);
        self.out.bodies.push(world);
        self.out.body_at.push(self.at(sections.first().copied().unwrap_or(root)));
        for &section in sections {
            self.check_attrs(section, &[])?;
            self.body_contents(section, 0, "main")?;
        }
        Ok(())
    }

    fn body(&mut self, node: Node<'a, 'i>, parent: usize, childclass: &'a str) -> Result<(), HandError> {
        self.check_attrs(node, BODY_ATTRS)?;
        let own = Attrs { node, own: Self::own_table(node), inherited: None };
        if let Some(src) = own.get("mocap")
            && self.boolean(src, "mocap")?
        {
            return Err(self.unsupported(
                node,
                "a mocap body",
                "a mocap body is moved by the user, not by the physics",
            ));
        }
        if self.scalar(&own, "gravcomp", 0.0)? != 0.0 {
            return Err(self.unsupported(node, "gravcomp", "gravity compensation forces are not carried"));
        }
        let childclass = match node.attribute("childclass") {
            None => childclass,
            Some(c) if self.classes.contains_key(c) => c,
            Some(c) => return Err(self.invalid(node, format!("childclass `{c}` is not defined"))),
        };
        let name = node.attribute("name").map(str::to_owned);
        let index = self.out.bodies.len();
        if let Some(name) = &name
            && self.body_names.insert(name.clone(), index).is_some()
        {
            return Err(self.invalid(node, format!("body name `{name}` is used twice")));
        }
        let pose = pose_f32(&self.position(&own)?, &self.orientation(&own)?);
        let start = self.out.joints.len();
        self.out.bodies.push(Body {
            name,
            parent: Some(parent),
            pose_in_parent: pose,
            joints: start..start,
            geoms: Vec::new(),
            inertial: None,
            mass_properties: zero_inertial(),
        });
        self.out.body_at.push(self.at(node));
        self.body_contents(node, index, childclass)
    }

    /// A body's (or the world's) elements: joints, geoms, sites and its inertial first, then its
    /// child bodies, so that bodies and joints are numbered as MuJoCo numbers them (depth first,
    /// a body's joints before its children's).
    fn body_contents(
        &mut self,
        node: Node<'a, 'i>,
        index: usize,
        childclass: &'a str,
    ) -> Result<(), HandError> {
        let is_world = index == 0;
        let mut inertial_node = None;
        let mut mass_parts = Vec::new();
        for child in elements(node) {
            match tag(child) {
                "body" => {}
                "inertial" if !is_world => {
                    if inertial_node.replace(child).is_some() {
                        return Err(self.invalid(child, "a body has at most one <inertial>"));
                    }
                }
                "joint" if !is_world => self.joint(child, index, childclass)?,
                "freejoint" => {
                    return Err(self.unsupported(
                        child,
                        "<freejoint>",
                        "a hand's bodies hang from fixed joints and hinges",
                    ));
                }
                "geom" => {
                    if let Some(part) = self.geom(child, index, childclass)? {
                        mass_parts.push((part, child));
                    }
                }
                "site" => self.site(child, index, childclass)?,
                "frame" | "replicate" | "attach" => {
                    let why = "write its contents out as bodies, geoms and sites";
                    return Err(self.unsupported(child, format!("<{}>", tag(child)), why));
                }
                "composite" | "flexcomp" | "plugin" => {
                    return Err(self.unsupported(child, format!("<{}>", tag(child)), "not a rigid body"));
                }
                kind if SKIPPED_IN_BODY.contains(&kind) => {}
                "joint" | "inertial" => {
                    return Err(self.invalid(child, "the world body has no joints or inertial"));
                }
                _ => return Err(self.unknown(child)),
            }
        }
        let end = self.out.joints.len();
        if let Some(body) = self.out.bodies.get_mut(index) {
            body.joints.end = end;
        }
        if !is_world {
            self.mass_properties(index, inertial_node, &mass_parts)?;
        }
        for child in elements(node).filter(|c| tag(*c) == "body") {
            self.body(child, index, childclass)?;
        }
        Ok(())
    }

    fn mass_properties(
        &mut self,
        index: usize,
        inertial_node: Option<Node<'a, 'i>>,
        parts: &[(Option<MassPart>, Node<'a, 'i>)],
    ) -> Result<(), HandError> {
        let inertial = inertial_node.map(|n| self.inertial(n)).transpose()?;
        let from_geoms = match self.compiler.inertia_from_geom {
            InertiaFromGeom::True => true,
            InertiaFromGeom::False => false,
            InertiaFromGeom::Auto => inertial.is_none(),
        };
        let mass_properties = if from_geoms {
            let mut solids = Vec::with_capacity(parts.len());
            for (part, node) in parts {
                match part {
                    Some(p) => solids.push(*p),
                    None => {
                        return Err(self.unsupported(
                            *node,
                            "the mass of a mesh geom",
                            "its body has no <inertial>, so MuJoCo takes its mass from the mesh, and vge never \
                             opens mesh files: give the body an <inertial> or the geom mass=\"0\"",
                        ));
                    }
                }
            }
            inertial_f32(&MassPart::combine(&solids))
        } else {
            inertial.unwrap_or_else(zero_inertial)
        };
        if let Some(body) = self.out.bodies.get_mut(index) {
            body.inertial = inertial;
            body.mass_properties = mass_properties;
        }
        Ok(())
    }

    fn inertial(&self, node: Node<'a, 'i>) -> Result<Inertial, HandError> {
        self.check_attrs(node, INERTIAL_ATTRS)?;
        if let Some(child) = elements(node).next() {
            return Err(self.unknown(child));
        }
        let attrs = Attrs { node, own: Self::own_table(node), inherited: None };
        let pos =
            self.fixed::<3>(&attrs, "pos")?.ok_or_else(|| self.invalid(node, "<inertial> needs `pos`"))?;
        let [mass] =
            self.fixed::<1>(&attrs, "mass")?.ok_or_else(|| self.invalid(node, "<inertial> needs `mass`"))?;
        if mass < 0.0 {
            return Err(self.invalid(node, format!("mass {mass} is negative")));
        }
        let inertia = match (self.fixed::<3>(&attrs, "diaginertia")?, self.fixed::<6>(&attrs, "fullinertia")?)
        {
            (Some(d), None) => {
                let r = self.orientation(&attrs)?.to_rotation_matrix();
                r.matrix() * Matrix3::from_diagonal(&Vector3::from(d)) * r.matrix().transpose()
            }
            (None, Some([xx, yy, zz, xy, xz, yz])) => {
                if ORIENTATIONS.iter().any(|o| attrs.own.contains_key(o)) {
                    return Err(self.invalid(
                        node,
                        "`fullinertia` with an orientation: MuJoCo derives it from the tensor",
                    ));
                }
                Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
            }
            _ => return Err(self.invalid(node, "<inertial> needs one of `diaginertia` and `fullinertia`")),
        };
        Ok(inertial_f32(&MassPart { mass, com: Vector3::from(pos), inertia }))
    }

    fn joint(&mut self, node: Node<'a, 'i>, body: usize, childclass: &'a str) -> Result<(), HandError> {
        self.check_attrs(node, JOINT_ATTRS)?;
        let class = self.class_of(node, childclass)?;
        let attrs = self.attrs(node, class, "joint");
        let kind = attrs.get("type").map_or("hinge", |s| s.value);
        let name = attrs.own_str("name");
        let label = name.map_or_else(|| "an unnamed joint".to_owned(), |n| format!("joint `{n}`"));
        if kind != "hinge" {
            let why = "vge's hands have hinge joints only (ball, slide and free joints are not carried)";
            return Err(self.unsupported(node, format!("{label} of type `{kind}`"), why));
        }
        let name = name.ok_or_else(|| {
            self.invalid(node, "a hinge joint needs a `name`: it names an entry of the joint vector")
        })?;
        for (attr, why) in [
            ("stiffness", "a joint spring is not carried"),
            ("springref", "a joint spring is not carried"),
            ("ref", "a reference angle shifts MuJoCo's qpos from the joint angle"),
        ] {
            if self.scalar(&attrs, attr, 0.0)? != 0.0 {
                return Err(self.unsupported(node, format!("`{attr}` of joint `{name}`"), why));
            }
        }
        let axis = self.fixed::<3>(&attrs, "axis")?.map_or_else(Vector3::z, Vector3::from);
        let axis = Unit::try_new(axis, 1e-12)
            .ok_or_else(|| self.invalid(node, format!("joint `{name}` has a zero axis")))?;
        let limit = self.range(&attrs, "range", "limited")?.map(|[lo, hi]| JointLimit {
            lower_rad: self.angle(lo) as f32,
            upper_rad: self.angle(hi) as f32,
        });
        let non_negative = |attr: &str| -> Result<f32, HandError> {
            let v = self.scalar(&attrs, attr, 0.0)?;
            if v < 0.0 {
                return Err(self.invalid(node, format!("`{attr}` {v} of joint `{name}` is negative")));
            }
            Ok(v as f32)
        };
        let joint = Joint {
            name: name.to_owned(),
            body,
            axis_in_body: Unit::new_normalize(axis.into_inner().map(|v| v as f32)),
            pos_in_body_m: self.position(&attrs)?.map(|v| v as f32),
            limit,
            damping_nms_per_rad: non_negative("damping")?,
            armature_kg_m2: non_negative("armature")?,
            frictionloss_nm: non_negative("frictionloss")?,
            servo: None,
        };
        let index = self.out.joints.len();
        if self.joint_names.insert(name.to_owned(), index).is_some() {
            return Err(self.invalid(node, format!("joint name `{name}` is used twice")));
        }
        self.out.joints.push(joint);
        self.out.joint_at.push(self.at(node));
        Ok(())
    }

    /// Reads a geom into its body; returns its mass part (`Some(None)` for a mesh, whose mass
    /// vge cannot know), or `None` when it adds no mass (a group outside 0..=5).
    fn geom(
        &mut self,
        node: Node<'a, 'i>,
        body: usize,
        childclass: &'a str,
    ) -> Result<Option<Option<MassPart>>, HandError> {
        self.check_attrs(node, GEOM_ATTRS)?;
        let class = self.class_of(node, childclass)?;
        let attrs = self.attrs(node, class, "geom");
        let kind = attrs.get("type").map_or("sphere", |s| s.value);
        let name = attrs.own_str("name").map(str::to_owned);
        let label = name.as_ref().map_or_else(|| "an unnamed geom".to_owned(), |n| format!("geom `{n}`"));
        let contype = self.bits(&attrs, "contype")?;
        let conaffinity = self.bits(&attrs, "conaffinity")?;
        let condim = self.integer(&attrs, "condim", 3)?;
        let condim = match u8::try_from(condim) {
            Ok(c @ (1 | 3 | 4 | 6)) => c,
            _ => return Err(self.invalid(node, format!("condim {condim} of {label} is not 1, 3, 4 or 6"))),
        };
        let friction = self.partial(&attrs, "friction", [1.0, 0.005, 0.0001])?;
        let group = self.integer(&attrs, "group", 0)?;
        let group =
            i32::try_from(group).map_err(|_| self.invalid(node, format!("group {group} of {label}")))?;
        let mass = match self.fixed::<1>(&attrs, "mass")? {
            Some([m]) if m >= 0.0 => GeomMass::Kg(m as f32),
            None => match self.scalar(&attrs, "density", 1000.0)? {
                d if d >= 0.0 => GeomMass::DensityKgPerM3(d as f32),
                d => return Err(self.invalid(node, format!("density {d} of {label} is negative"))),
            },
            Some([m]) => return Err(self.invalid(node, format!("mass {m} of {label} is negative"))),
        };
        let size = self.partial(&attrs, "size", [0.0; 3])?;
        let fromto = self.fixed::<6>(&attrs, "fromto")?;
        let (pos, rot, half_from_fromto) = match fromto {
            Some(f) => {
                if !matches!(kind, "capsule" | "cylinder" | "box") {
                    return Err(self.invalid(node, format!("`fromto` on {label} of type `{kind}`")));
                }
                let (a, b) = (Vector3::new(f[0], f[1], f[2]), Vector3::new(f[3], f[4], f[5]));
                let rot = z_to(&(b - a))
                    .map_err(|_| self.invalid(node, format!("`fromto` of {label} has zero length")))?;
                (0.5 * (a + b), rot, Some(0.5 * (b - a).norm()))
            }
            None => (self.position(&attrs)?, self.orientation(&attrs)?, None),
        };
        let positive = |v: f64, what: &str| -> Result<f64, HandError> {
            if v > 0.0 {
                Ok(v)
            } else {
                Err(self.invalid(node, format!("{what} {v} of {label} is not positive")))
            }
        };
        let solid = match kind {
            "sphere" => Solid::Sphere { r: positive(size[0], "radius")? },
            "capsule" | "cylinder" => {
                let r = positive(size[0], "radius")?;
                let half = positive(half_from_fromto.unwrap_or(size[1]), "half-length")?;
                if kind == "capsule" { Solid::Capsule { r, half } } else { Solid::Cylinder { r, half } }
            }
            "box" => {
                let z = half_from_fromto.unwrap_or(size[2]);
                let half = Vector3::new(
                    positive(size[0], "half-size x")?,
                    positive(size[1], "half-size y")?,
                    positive(z, "half-size z")?,
                );
                Solid::Box { half }
            }
            "mesh" => {
                let mesh = attrs
                    .get("mesh")
                    .ok_or_else(|| self.invalid(node, format!("{label} of type mesh names no `mesh`")))?;
                if contype != 0 || conaffinity != 0 {
                    return Err(self.unsupported(
                        node,
                        format!("{label}: a mesh that collides"),
                        "vge never opens mesh files: give it contype=\"0\" conaffinity=\"0\" and collide with primitives",
                    ));
                }
                let zero_mass = matches!(mass, GeomMass::Kg(0.0) | GeomMass::DensityKgPerM3(0.0));
                self.push_geom(
                    body,
                    Geom {
                        name,
                        shape: GeomShape::VisualMesh { mesh: mesh.value.to_owned() },
                        pose_in_body: pose_f32(&pos, &rot),
                        contype,
                        conaffinity,
                        condim,
                        friction: friction.map(|v| v as f32),
                        mass,
                        group,
                    },
                );
                return Ok(if zero_mass || !(0..=5).contains(&group) { None } else { Some(None) });
            }
            other => {
                let why = "vge's collision shapes are spheres, capsules, cylinders and boxes (and meshes that never collide)";
                return Err(self.unsupported(node, format!("{label} of type `{other}`"), why));
            }
        };
        let shape = match solid {
            Solid::Sphere { r } => GeomShape::Sphere { radius_m: r as f32 },
            Solid::Capsule { r, half } => {
                GeomShape::Capsule { radius_m: r as f32, half_length_m: half as f32 }
            }
            Solid::Cylinder { r, half } => {
                GeomShape::Cylinder { radius_m: r as f32, half_length_m: half as f32 }
            }
            Solid::Box { half } => GeomShape::Box { half_extents_m: half.map(|v| v as f32) },
        };
        let kg = match mass {
            GeomMass::Kg(m) => f64::from(m),
            GeomMass::DensityKgPerM3(d) => f64::from(d) * solid.volume_m3(),
        };
        let part = MassPart::of_solid(&solid, kg, pos, &rot);
        self.push_geom(
            body,
            Geom {
                name,
                shape,
                pose_in_body: pose_f32(&pos, &rot),
                contype,
                conaffinity,
                condim,
                friction: friction.map(|v| v as f32),
                mass,
                group,
            },
        );
        Ok((0..=5).contains(&group).then_some(Some(part)))
    }

    fn push_geom(&mut self, body: usize, geom: Geom) {
        if let Some(b) = self.out.bodies.get_mut(body) {
            b.geoms.push(geom);
        }
    }

    fn bits(&self, attrs: &Attrs<'_, 'a, 'i>, name: &str) -> Result<u32, HandError> {
        let v = self.integer(attrs, name, 1)?;
        u32::try_from(v).map_err(|_| self.invalid(attrs.node, format!("`{name}` {v} is not a 32-bit mask")))
    }

    fn site(&mut self, node: Node<'a, 'i>, body: usize, childclass: &'a str) -> Result<(), HandError> {
        self.check_attrs(node, SITE_ATTRS)?;
        let class = self.class_of(node, childclass)?;
        let attrs = self.attrs(node, class, "site");
        let name = attrs.own_str("name").map(str::to_owned);
        if let Some(n) = &name
            && self.out.sites.iter().any(|s| s.name.as_ref() == Some(n))
        {
            return Err(self.invalid(node, format!("site name `{n}` is used twice")));
        }
        let pose_in_body = pose_f32(&self.position(&attrs)?, &self.orientation(&attrs)?);
        self.out.sites.push(Site { name, body, pose_in_body });
        self.out.site_at.push(self.at(node));
        Ok(())
    }

    // ---- sections after the bodies ----

    fn contact_section(&mut self, node: Node<'a, 'i>) -> Result<(), HandError> {
        self.check_attrs(node, &[])?;
        for child in elements(node) {
            match tag(child) {
                "exclude" => {
                    self.check_attrs(child, EXCLUDE_ATTRS)?;
                    let body = |attr: &str| -> Result<usize, HandError> {
                        let name = child
                            .attribute(attr)
                            .ok_or_else(|| self.invalid(child, format!("<exclude> needs `{attr}`")))?;
                        self.body_names
                            .get(name)
                            .copied()
                            .ok_or_else(|| self.invalid(child, format!("`{attr}`: no body named `{name}`")))
                    };
                    let exclude = ContactExclude { body1: body("body1")?, body2: body("body2")? };
                    self.out.excludes.push(exclude);
                }
                "pair" => {
                    let why =
                        "an explicit contact pair sets its own contact parameters; use contype/conaffinity";
                    return Err(self.unsupported(child, "<pair>", why));
                }
                _ => return Err(self.unknown(child)),
            }
        }
        Ok(())
    }

    fn actuator_section(&mut self, node: Node<'a, 'i>) -> Result<(), HandError> {
        self.check_attrs(node, &[])?;
        for child in elements(node) {
            let kind = tag(child);
            let servo = match kind {
                "position" => {
                    self.check_attrs(child, POSITION_ATTRS)?;
                    let class = self.class_of(child, "main")?;
                    self.position_servo(&self.attrs(child, class, "position"))?
                }
                "general" => {
                    self.check_attrs(child, GENERAL_ATTRS)?;
                    let class = self.class_of(child, "main")?;
                    self.general_servo(&self.attrs(child, class, "general"))?
                }
                "motor" | "velocity" | "intvelocity" | "damper" | "cylinder" | "muscle" | "adhesion"
                | "plugin" => {
                    let why = "vge's joints are driven by position servos (<position>, or <general> written as one)";
                    return Err(self.unsupported(child, format!("<{kind}> actuator"), why));
                }
                _ => return Err(self.unknown(child)),
            };
            self.num_actuators += 1;
            let (joint, servo) = servo;
            let slot = self.out.joints.get_mut(joint).map(|j| &mut j.servo);
            match slot {
                Some(slot @ None) => *slot = Some(servo),
                _ => {
                    return Err(self.invalid(
                        child,
                        "a second actuator on one joint: vge drives a joint with one servo",
                    ));
                }
            }
        }
        Ok(())
    }

    /// The joint an actuator drives (it must drive a joint: tendons, sites and bodies as
    /// transmissions are outside the subset, and refused by the attribute check) and its gear,
    /// which must be 1 so that the target is the joint angle.
    fn transmission(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<usize, HandError> {
        let node = attrs.node;
        let name = attrs
            .get("joint")
            .ok_or_else(|| self.invalid(node, "an actuator needs the `joint` it drives"))?;
        let joint = self
            .joint_names
            .get(name.value)
            .copied()
            .ok_or_else(|| self.invalid(node, format!("no joint named `{}`", name.value)))?;
        let gear = self.partial(attrs, "gear", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])?;
        if gear[0] != 1.0 {
            let why = "the servo's target would be gear times the joint angle";
            return Err(self.unsupported(node, format!("gear {} on joint `{}`", gear[0], name.value), why));
        }
        Ok(joint)
    }

    /// The control and force ranges of a servo.
    fn servo_ranges(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<[Option<[f32; 2]>; 2], HandError> {
        let ctrl = self.range(attrs, "ctrlrange", "ctrllimited")?;
        let force = self.range(attrs, "forcerange", "forcelimited")?;
        Ok([ctrl, force].map(|range| range.map(|r| r.map(|v| v as f32))))
    }

    fn position_servo(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<(usize, PositionServo), HandError> {
        let node = attrs.node;
        let joint = self.transmission(attrs)?;
        for (attr, why) in [
            ("dampratio", "a damping ratio needs MuJoCo's joint-space inertia; write kv"),
            ("timeconst", "activation dynamics are not carried"),
        ] {
            if self.scalar(attrs, attr, 0.0)? != 0.0 {
                return Err(self.unsupported(node, format!("`{attr}` of a position actuator"), why));
            }
        }
        let kp = self.scalar(attrs, "kp", 1.0)?;
        let kv = self.scalar(attrs, "kv", 0.0)?;
        if kp < 0.0 || kv < 0.0 {
            return Err(self.invalid(node, format!("kp {kp} and kv {kv} must not be negative")));
        }
        let [mut ctrl, force] = self.servo_ranges(attrs)?;
        let inherit = self.scalar(attrs, "inheritrange", 0.0)?;
        if inherit > 0.0 {
            if attrs.get("ctrlrange").is_some() {
                return Err(self.invalid(node, "both `inheritrange` and `ctrlrange`"));
            }
            let limit = self.out.joints.get(joint).and_then(|j| j.limit);
            let limit =
                limit.ok_or_else(|| self.invalid(node, "`inheritrange` on a joint without a range"))?;
            let (mid, half) =
                (0.5 * (limit.lower_rad + limit.upper_rad), 0.5 * (limit.upper_rad - limit.lower_rad));
            ctrl = Some([mid - inherit as f32 * half, mid + inherit as f32 * half]);
        }
        let name = attrs.own_str("name").map(str::to_owned);
        let servo = PositionServo {
            name,
            kp_nm_per_rad: kp as f32,
            kv_nms_per_rad: kv as f32,
            force_range_nm: force,
            ctrl_range_rad: ctrl,
        };
        Ok((joint, servo))
    }

    /// A `<general>` actuator, accepted when it is exactly a position servo: no dynamics, a
    /// fixed gain kp, and an affine bias `0 -kp -kv`.
    fn general_servo(&self, attrs: &Attrs<'_, 'a, 'i>) -> Result<(usize, PositionServo), HandError> {
        let node = attrs.node;
        let joint = self.transmission(attrs)?;
        let text = |name: &str, default: &'static str| attrs.get(name).map_or(default, |s| s.value.trim());
        let (dyntype, gaintype, biastype) =
            (text("dyntype", "none"), text("gaintype", "fixed"), text("biastype", "none"));
        let mut gain = [0.0; 10];
        gain[0] = 1.0;
        let gain = self.partial(attrs, "gainprm", gain)?;
        let bias = self.partial(attrs, "biasprm", [0.0; 10])?;
        let (kp, kv) = (gain[0], -bias[2]);
        let servo = dyntype == "none"
            && gaintype == "fixed"
            && biastype == "affine"
            && bias[0] == 0.0
            && bias[1] == -kp
            && kp >= 0.0
            && kv >= 0.0;
        if !servo {
            let why = "a <general> actuator is carried only as a position servo: dyntype none, gaintype fixed, \
                       biastype affine, gainprm kp, biasprm 0 -kp -kv";
            return Err(self.unsupported(node, "a <general> actuator that is not a position servo", why));
        }
        let [ctrl, force] = self.servo_ranges(attrs)?;
        let name = attrs.own_str("name").map(str::to_owned);
        let servo = PositionServo {
            name,
            kp_nm_per_rad: kp as f32,
            kv_nms_per_rad: kv as f32,
            force_range_nm: force,
            ctrl_range_rad: ctrl,
        };
        Ok((joint, servo))
    }

    fn keyframe_section(&mut self, node: Node<'a, 'i>) -> Result<(), HandError> {
        self.check_attrs(node, &[])?;
        let nq = self.out.joints.len();
        for child in elements(node) {
            if tag(child) != "key" {
                return Err(self.unknown(child));
            }
            self.check_attrs(child, KEY_ATTRS)?;
            let attrs = Attrs { node: child, own: Self::own_table(child), inherited: None };
            let vector = |name: &str, len: usize| -> Result<Option<Vec<f64>>, HandError> {
                let Some(src) = attrs.get(name) else { return Ok(None) };
                let v = self.numbers(src, name)?;
                if v.len() != len {
                    return Err(
                        self.invalid(child, format!("`{name}` has {} numbers, the model has {len}", v.len()))
                    );
                }
                Ok(Some(v))
            };
            let qpos = vector("qpos", nq)?.unwrap_or_else(|| vec![0.0; nq]);
            if vector("qvel", nq)?.is_some_and(|v| v.iter().any(|x| *x != 0.0)) {
                let why = "a keyframe here is a configuration; it starts at rest";
                return Err(self.unsupported(child, "a keyframe with non-zero `qvel`", why));
            }
            vector("ctrl", self.num_actuators)?;
            self.out.keyframes.push(Keyframe {
                name: attrs.own_str("name").map(str::to_owned),
                qpos_rad: qpos.iter().map(|v| *v as f32).collect(),
            });
            self.out.key_at.push(self.at(child));
        }
        Ok(())
    }
}

fn allowed_attrs(kind: &str) -> &'static [&'static str] {
    match kind {
        "joint" => JOINT_ATTRS,
        "geom" => GEOM_ATTRS,
        "site" => SITE_ATTRS,
        "position" => POSITION_ATTRS,
        _ => GENERAL_ATTRS,
    }
}

fn zero_inertial() -> Inertial {
    Inertial { mass_kg: 0.0, com_in_body_m: Vector3::zeros(), inertia_kg_m2: Matrix3::zeros() }
}

fn inertial_f32(part: &MassPart) -> Inertial {
    Inertial {
        mass_kg: part.mass as f32,
        com_in_body_m: part.com.map(|v| v as f32),
        inertia_kg_m2: part.inertia.map(|v| v as f32),
    }
}
