//! An ONNX MLP actor as a policy file for the hand, or a refusal that names the node.
//!
//! The graph must be one chain from its single input to its single output:
//!
//! ```text
//! [Sub mean] [Div std] [Clip -c..c]          observation normalisation (optional)
//! (Gemm | MatMul [Add bias]) [Relu | Tanh]   one to `max_layers` dense layers
//! [Mul scale] [Add offset] [Clip]            action scaling (optional; a Clip only where it
//!                                            cannot bind, e.g. [-1, 1] after a final Tanh)
//! ```
//!
//! with `Identity`, `Flatten` (axis 1), `Cast` to float32 and `Expand` to a computed value's
//! `Shape` anywhere as no-ops (torch's exporter writes `Flatten` for Stable-Baselines3's
//! feature extractor, and the Expand in front of its actor's Tanh). Nodes the action's values
//! do not depend on (dead ones, or SB3's log_std head, which only gives that Expand its shape)
//! are left out and listed. Every weight must be a constant (an initializer or a `Constant`
//! node), float32, finite.

use std::collections::HashMap;

use onnx_protobuf::tensor_proto::DataType;
use onnx_protobuf::tensor_shape_proto::dimension;
use onnx_protobuf::type_proto;
use onnx_protobuf::{GraphProto, Message, ModelProto, NodeProto, TensorProto};
use vge_runtime::format::{ACT_IDENTITY, ACT_RELU, ACT_TANH};

use super::tensor::{Floats, read_floats};
use super::{OnnxError, keys};
use crate::{LayerRecord, ObsNorm, ObsSlice, PolicyFile, PolicyTask, Provenance};

/// What an imported policy must fit: the hand's observation and actions, and the runtime's
/// capacity (`vge_runtime::HandPolicy`: 4 layers of width 256).
#[derive(Debug, Clone, PartialEq)]
pub struct ImportTarget {
    /// The hand's observation slices, covering `0..obs_dim`.
    pub obs_layout: Vec<ObsSlice>,
    /// The hand's action names, one per action.
    pub action_names: Vec<String>,
    /// Control rate the policy gets when the file claims none.
    pub control_hz: f32,
    /// Most layers the runtime holds.
    pub max_layers: usize,
    /// Widest layer input or output the runtime holds.
    pub max_width: usize,
    /// The task the policy is imported for (its hand, observation set, object): recorded in
    /// the file when the model names none, and a model that names another hand is refused.
    pub task: Option<PolicyTask>,
}

impl ImportTarget {
    /// Width of the hand's observation.
    pub fn obs_dim(&self) -> usize {
        self.obs_layout.last().map_or(0, |s| s.end as usize)
    }

    /// Number of the hand's actions.
    pub fn act_dim(&self) -> usize {
        self.action_names.len()
    }
}

/// What the graph's output means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ActionScale {
    /// The graph's output (after its own `Mul`/`Add`, if any) is the action the bridge sends.
    Graph,
    /// Multiply the graph's output by this factor (e.g. the hand's largest joint-target step
    /// for an actor that outputs Stable-Baselines3's normalised actions in [-1, 1]).
    Times(f32),
}

/// Choices the graph cannot carry.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImportOptions {
    /// Observation normalisation applied outside the graph (e.g. a `VecNormalize`'s mean and
    /// `sqrt(var + eps)`); refused when the graph normalises too.
    pub obs_norm: Option<ObsNorm>,
    /// The observation layout the user says the actor was trained on; checked against the
    /// hand's.
    pub obs_layout: Option<Vec<ObsSlice>>,
    /// What the output means; required when the graph does not scale its output.
    pub action_scale: Option<ActionScale>,
    /// Where the model came from (a file name), recorded in the provenance.
    pub source: String,
}

/// An imported policy, and what the importer decided on the way (for the user to read).
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    pub policy: PolicyFile,
    pub notes: Vec<String>,
}

/// Imports the ONNX model `bytes` as a policy for `target`; see the module docs for the
/// graphs accepted. The result has passed the policy file's validation. A model with more
/// nodes, layers or fields than any MLP actor is refused from its wire format before it is
/// parsed ([`super::census`]): at most [`super::census::MAX_NODES`] nodes, and twice
/// `target.max_layers` `Gemm` and `MatMul` nodes (room for a dead head beside each layer).
pub fn import(bytes: &[u8], target: &ImportTarget, options: &ImportOptions) -> Result<Imported, OnnxError> {
    super::census::count(bytes, 2 * target.max_layers)?;
    let model = ModelProto::parse_from_bytes(bytes).map_err(OnnxError::Parse)?;
    let graph = model.graph.as_ref().ok_or_else(|| OnnxError::Graph("the model has no graph".to_owned()))?;
    check_opset(&model)?;
    let mut notes = Vec::new();
    let walked = Walk::new(graph, target).run(&mut notes)?;
    let meta = Metadata::of(&model);
    meta.check(target)?;
    if let Some(layout) = &options.obs_layout
        && !same_layout(layout, &target.obs_layout)
    {
        return Err(OnnxError::Option(format!(
            "the observation layout given ({}) is not the hand's ({})",
            show_layout(layout),
            show_layout(&target.obs_layout)
        )));
    }

    let obs_dim = target.obs_dim();
    let act_dim = target.act_dim();
    let obs_norm = match (&options.obs_norm, walked.norm) {
        (Some(_), Some((node, _))) => {
            return Err(OnnxError::Option(format!(
                "the graph normalises the observation itself (node `{node}`): do not also give a mean or std"
            )));
        }
        (Some(given), None) => {
            if given.mean.len() != obs_dim || given.std.len() != obs_dim {
                return Err(OnnxError::Option(format!(
                    "the observation mean and std given hold {} and {} values, the hand observes {obs_dim}",
                    given.mean.len(),
                    given.std.len()
                )));
            }
            given.clone()
        }
        (None, Some((_, norm))) => norm,
        (None, None) => ObsNorm::identity(obs_dim),
    };

    let ones = vec![1.0; act_dim];
    let (mut scale, mut offset) =
        (walked.scale.clone().unwrap_or_else(|| ones.clone()), walked.offset.unwrap_or(vec![0.0; act_dim]));
    match (options.action_scale, &walked.scale) {
        (None, None) => {
            return Err(OnnxError::Option(
                "the graph does not scale its output (no Mul after the last layer): say what its output \
                 is, `graph` (already the action the bridge sends) or a factor to multiply it by \
                 (vge import --action-scale graph|hand|FACTOR)"
                    .to_owned(),
            ));
        }
        (None | Some(ActionScale::Graph), _) => {}
        (Some(ActionScale::Times(f)), _) => {
            if !(f.is_finite() && f > 0.0) {
                return Err(OnnxError::Option(format!("action scale factor {f}: must be finite and > 0")));
            }
            scale.iter_mut().chain(offset.iter_mut()).for_each(|v| *v *= f);
            notes.push(format!("the graph's output is multiplied by {f} (action scale and offset)"));
        }
    }

    let control_hz = match meta.control_hz()? {
        Some(hz) => hz,
        None => {
            notes.push(format!(
                "the file claims no control rate: the policy runs at the hand's {} Hz",
                target.control_hz
            ));
            target.control_hz
        }
    };
    let producer = format!("{} {}", model.producer_name, model.producer_version);
    let provenance = match meta.provenance()? {
        Some(p) => p,
        None => Provenance {
            vge_version: env!("CARGO_PKG_VERSION").to_owned(),
            config_hash: format!(
                "onnx:{} (producer {}, crc32 {:08x})",
                options.source,
                if producer.trim().is_empty() { "unnamed" } else { producer.trim() },
                vge_runtime::format::crc32(bytes)
            ),
            seed: 0,
            steps: 0,
        },
    };
    let policy = PolicyFile {
        provenance,
        control_hz,
        obs_dim: obs_dim as u32,
        act_dim: act_dim as u32,
        obs_layout: target.obs_layout.clone(),
        obs_mean: obs_norm.mean,
        obs_std: obs_norm.std,
        obs_clip: obs_norm.clip,
        layers: walked.layers,
        action_names: target.action_names.clone(),
        action_scale: scale,
        action_offset: offset,
        task: imported_task(meta.task()?, target.task.as_ref())?,
    };
    policy.to_bytes()?;
    Ok(Imported { policy, notes })
}

/// The task a model names, checked against the one it is imported for, else that one.
fn imported_task(
    named: Option<PolicyTask>,
    target: Option<&PolicyTask>,
) -> Result<Option<PolicyTask>, OnnxError> {
    match (named, target) {
        (Some(named), Some(target))
            if named.hand != target.hand || named.hand_sha256 != target.hand_sha256 =>
        {
            Err(OnnxError::Graph(format!(
                "the model was exported for the hand {} ({}), not {} ({})",
                named.hand,
                named.hand_sha256_hex(),
                target.hand,
                target.hand_sha256_hex()
            )))
        }
        (Some(named), _) => Ok(Some(named)),
        (None, target) => Ok(target.cloned()),
    }
}

fn check_opset(model: &ModelProto) -> Result<(), OnnxError> {
    let version = model
        .opset_import
        .iter()
        .find(|o| o.domain.is_empty() || o.domain == "ai.onnx")
        .map(|o| o.version)
        .ok_or_else(|| OnnxError::Graph("the model imports no default-domain (ai.onnx) opset".to_owned()))?;
    // Opset 7 is the first with today's broadcasting Gemm, Add and Mul.
    if version < 7 {
        return Err(OnnxError::Graph(format!("opset {version}: vge imports opset 7 and newer")));
    }
    Ok(())
}

/// A value's constant source.
#[derive(Clone, Copy)]
enum Const<'a> {
    Initializer(&'a TensorProto),
    /// A `Constant` node's `value` tensor, or its `value_float` / `value_floats`.
    Node(&'a NodeProto),
}

/// What the chain turned into.
struct Walked {
    /// The node that normalises, and the normalisation.
    norm: Option<(String, ObsNorm)>,
    layers: Vec<LayerRecord>,
    scale: Option<Vec<f32>>,
    offset: Option<Vec<f32>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Before the first layer: Sub, Div, Clip.
    Normalise,
    /// From the first layer on.
    Layers,
    /// After the last layer's output went through a Mul, an Add (not its bias) or a Clip.
    Output,
}

/// A layer whose activation (and, for MatMul, bias) may still follow.
struct Pending {
    node: String,
    layer: LayerRecord,
    activation: Option<u8>,
    /// MatMul, or Gemm without C: an `Add` right after it is its bias.
    takes_bias: bool,
}

struct Walk<'a> {
    graph: &'a GraphProto,
    target: &'a ImportTarget,
    consts: HashMap<&'a str, Const<'a>>,
    /// The node writing each value.
    producers: HashMap<&'a str, &'a NodeProto>,
    stage: Stage,
    mean: Option<Vec<f32>>,
    std: Option<Vec<f32>>,
    clip: Option<f32>,
    norm_node: Option<String>,
    layers: Vec<LayerRecord>,
    layer_nodes: Vec<String>,
    pending: Option<Pending>,
    scale: Option<Vec<f32>>,
    offset: Option<Vec<f32>>,
    /// Per action: the interval the output can take so far (for a Clip behind the layers).
    range: Vec<(f32, f32)>,
}

/// The node as errors name it: its name, or its position and output when it has none.
fn label(index: usize, node: &NodeProto) -> String {
    if node.name.is_empty() {
        format!("#{index} -> {}", node.output.first().map_or("?", String::as_str))
    } else {
        node.name.clone()
    }
}

/// The refusal of `node` (at `index`) for `reason`.
fn refusal(index: usize, node: &NodeProto, reason: String) -> OnnxError {
    OnnxError::Node { node: label(index, node), op: node.op_type.clone(), reason }
}

/// Activations the runtime does not compute (it has identity, ReLU and tanh layers).
const OTHER_ACTIVATIONS: [&str; 14] = [
    "Elu",
    "LeakyRelu",
    "Selu",
    "Celu",
    "PRelu",
    "ThresholdedRelu",
    "Sigmoid",
    "HardSigmoid",
    "HardSwish",
    "Softplus",
    "Softsign",
    "Gelu",
    "Mish",
    "Swish",
];

impl<'a> Walk<'a> {
    fn new(graph: &'a GraphProto, target: &'a ImportTarget) -> Self {
        let mut consts: HashMap<&str, Const<'_>> =
            graph.initializer.iter().map(|t| (t.name.as_str(), Const::Initializer(t))).collect();
        for n in graph.node.iter().filter(|n| n.op_type == "Constant") {
            if let Some(out) = n.output.first() {
                consts.insert(out.as_str(), Const::Node(n));
            }
        }
        let producers =
            graph.node.iter().flat_map(|n| n.output.iter().map(move |o| (o.as_str(), n))).collect();
        Self {
            graph,
            target,
            consts,
            producers,
            stage: Stage::Normalise,
            mean: None,
            std: None,
            clip: None,
            norm_node: None,
            layers: Vec::new(),
            layer_nodes: Vec::new(),
            pending: None,
            scale: None,
            offset: None,
            range: Vec::new(),
        }
    }

    fn run(mut self, notes: &mut Vec<String>) -> Result<Walked, OnnxError> {
        let g = self.graph;
        let inputs: Vec<_> = g.input.iter().filter(|i| !self.consts.contains_key(i.name.as_str())).collect();
        let [input] = inputs.as_slice() else {
            let names: Vec<_> = inputs.iter().map(|i| i.name.as_str()).collect();
            return Err(OnnxError::Graph(format!(
                "{} inputs ({names:?}) besides the weights: an actor takes one, the observation",
                names.len()
            )));
        };
        let [output] = g.output.as_slice() else {
            let names: Vec<_> = g.output.iter().map(|o| o.name.as_str()).collect();
            return Err(OnnxError::Graph(format!(
                "{} outputs ({names:?}): vge imports an actor with one, the action (export the actor \
                 alone, e.g. Stable-Baselines3's policy.actor, not a policy that also returns values)",
                names.len()
            )));
        };

        // Non-Constant nodes reading each value.
        let live = live_nodes(g, &output.name);
        let left_out: Vec<String> = g
            .node
            .iter()
            .enumerate()
            .filter(|(i, n)| n.op_type != "Constant" && !live.get(*i).copied().unwrap_or(false))
            .map(|(i, n)| format!("{} ({})", label(i, n), n.op_type))
            .collect();
        if !left_out.is_empty() {
            notes.push(format!(
                "{} nodes that the action's values do not depend on (dead, or only the shape an Expand \
                 takes, as torch writes SB3's log_std head) were left out: {}",
                left_out.len(),
                left_out.join(", ")
            ));
        }
        let mut readers: HashMap<&str, Vec<usize>> = HashMap::new();
        let is_live = |i: &usize| live.get(*i).copied().unwrap_or(false);
        for (i, n) in g.node.iter().enumerate().filter(|(i, n)| n.op_type != "Constant" && is_live(i)) {
            for name in n.input.iter().filter(|s| !s.is_empty()) {
                readers.entry(name.as_str()).or_default().push(i);
            }
        }
        let mut visited = vec![false; g.node.len()];
        let mut cur = input.name.clone();
        while let Some(next) = readers.get(cur.as_str()) {
            let (&i, rest) = next.split_first().unwrap_or((&usize::MAX, &[]));
            let node =
                g.node.get(i).ok_or_else(|| OnnxError::Graph(format!("`{cur}` is read by no node")))?;
            if let Some(&j) = rest.first()
                && let Some(other) = g.node.get(j)
            {
                return Err(refusal(
                    j,
                    other,
                    format!(
                        "reads `{cur}`, which node `{}` reads too: vge imports one chain of layers, not a \
                         branching graph",
                        label(i, node)
                    ),
                ));
            }
            if visited.get(i).copied().unwrap_or(true) {
                return Err(refusal(i, node, "is reached twice: the graph has a cycle".to_owned()));
            }
            if let Some(v) = visited.get_mut(i) {
                *v = true;
            }
            cur = self.step(i, node, &cur, notes)?;
        }
        if cur != output.name {
            return Err(OnnxError::Graph(format!(
                "the chain from input `{}` ends at `{cur}`, not at the graph's output `{}`",
                input.name, output.name
            )));
        }
        for (i, n) in g.node.iter().enumerate() {
            if n.op_type != "Constant" && is_live(&i) && !visited.get(i).copied().unwrap_or(false) {
                return Err(refusal(
                    i,
                    n,
                    format!(
                        "is not on the chain from `{}` to `{}`: vge imports one chain",
                        input.name, output.name
                    ),
                ));
            }
        }
        self.finish_layer();
        let (Some(last), Some(last_node)) = (self.layers.last(), self.layer_nodes.last()) else {
            return Err(OnnxError::Graph(format!(
                "no Gemm or MatMul layer between `{}` and `{}`",
                input.name, output.name
            )));
        };
        let act_dim = self.target.act_dim();
        if last.out_dim as usize != act_dim {
            return Err(OnnxError::Node {
                node: last_node.clone(),
                op: "last layer".to_owned(),
                reason: format!(
                    "gives {} outputs, the hand has {act_dim} actions ({})",
                    last.out_dim,
                    self.target.action_names.join(", ")
                ),
            });
        }
        // After the walk, so that a layer of the wrong width is named by its node.
        check_io_type(input, "input", self.target.obs_dim(), "the hand observes")?;
        check_io_type(output, "output", act_dim, "the hand has actions:")?;
        let norm = self.norm_node.map(|node| {
            let obs_dim = self.target.obs_dim();
            let norm = ObsNorm {
                mean: self.mean.unwrap_or(vec![0.0; obs_dim]),
                std: self.std.unwrap_or(vec![1.0; obs_dim]),
                clip: self.clip,
            };
            (node, norm)
        });
        Ok(Walked { norm, layers: self.layers, scale: self.scale, offset: self.offset })
    }

    /// Folds `node` (which reads `cur`) into the policy; returns the value it writes.
    fn step(
        &mut self,
        i: usize,
        node: &NodeProto,
        cur: &str,
        notes: &mut Vec<String>,
    ) -> Result<String, OnnxError> {
        let refuse = |reason: String| refusal(i, node, reason);
        if !(node.domain.is_empty() || node.domain == "ai.onnx") {
            return Err(refuse(format!(
                "op of domain `{}`: vge imports standard ONNX ops only",
                node.domain
            )));
        }
        let [out] = node.output.as_slice() else {
            return Err(refuse(format!("has {} outputs; vge imports ops with one", node.output.len())));
        };
        let op = node.op_type.as_str();
        let first_is_cur = node.input.first().is_some_and(|s| s == cur);
        match op {
            "Identity" => {}
            "Expand" => {
                // torch writes SB3's squashed mode as Expand(mean, Shape(mean + 0 * std)): to the
                // shape of a value computed from the same batch, a no-op; the output's declared
                // width is checked after the walk.
                let to_shape = node.input.get(1).and_then(|s| self.producers.get(s.as_str()));
                if to_shape.is_none_or(|p| p.op_type != "Shape") {
                    return Err(refuse(
                        "expands to a shape that is not the Shape of a computed value".to_owned(),
                    ));
                }
                notes.push(format!(
                    "node `{}`: Expand to a computed value's shape taken as a no-op",
                    label(i, node)
                ));
            }
            "Flatten" => {
                let axis = attr_i(node, "axis").unwrap_or(1);
                if axis != 1 {
                    return Err(refuse(format!(
                        "axis {axis}: only Flatten(axis=1), a no-op on [batch, obs]"
                    )));
                }
            }
            "Cast" => {
                if attr_i(node, "to") != Some(DataType::FLOAT as i64) {
                    return Err(refuse("casts to another type than float32".to_owned()));
                }
            }
            "Sub" | "Div" => self.normalise(i, node, first_is_cur)?,
            "Gemm" | "MatMul" => {
                if !first_is_cur {
                    return Err(refuse(format!("`{cur}` must be its first input (A)")));
                }
                self.layer(i, node, notes)?;
            }
            "Relu" | "Tanh" => match &mut self.pending {
                Some(p) if p.activation.is_none() && self.stage == Stage::Layers => {
                    p.activation = Some(if op == "Relu" { ACT_RELU } else { ACT_TANH });
                }
                _ => {
                    return Err(refuse(
                        "is not right after a layer (Gemm, or MatMul and its bias Add): the runtime applies \
                         an activation to a layer's output only"
                            .to_owned(),
                    ));
                }
            },
            "Add" => self.add(i, node, cur)?,
            "Mul" => self.mul(i, node, cur)?,
            "Clip" => self.clip(i, node, first_is_cur, notes)?,
            _ if OTHER_ACTIVATIONS.contains(&op) => {
                return Err(refuse(
                    "unsupported op: vge's runtime has no such activation (its layers apply identity, ReLU \
                     or tanh)"
                        .to_owned(),
                ));
            }
            _ => {
                return Err(refuse(
                    "unsupported op: vge imports MLP actors (Gemm, or MatMul + Add; Relu, Tanh; Sub/Div \
                     before the first layer; Mul, Add, Clip after the last)"
                        .to_owned(),
                ));
            }
        }
        Ok(out.clone())
    }

    /// The float constant feeding `node` as `name`, finite.
    fn constant(&self, i: usize, node: &NodeProto, name: &str) -> Result<Floats, OnnxError> {
        let refuse = |reason: String| refusal(i, node, reason);
        let floats = match self.consts.get(name) {
            Some(Const::Initializer(t)) => read_floats(t),
            Some(Const::Node(c)) => constant_node(c),
            None => {
                return Err(refuse(format!(
                    "input `{name}` is not a constant (an initializer or a Constant node): vge imports fixed \
                     weights"
                )));
            }
        }
        .map_err(|why| refuse(format!("tensor `{name}`: {why}")))?;
        if let Some(at) = floats.first_non_finite() {
            let v = floats.values.get(at).copied().unwrap_or(f32::NAN);
            return Err(refuse(format!(
                "tensor `{name}` holds {v} at flat index {at}: the runtime refuses non-finite weights"
            )));
        }
        Ok(floats)
    }

    /// `node`'s constant `name` as `len` values (a scalar, `[len]` or `[1, len]`).
    fn vector(
        &self,
        i: usize,
        node: &NodeProto,
        name: &str,
        len: usize,
        what: &str,
    ) -> Result<Vec<f32>, OnnxError> {
        let f = self.constant(i, node, name)?;
        let leading_ones = f.dims.iter().rev().skip(1).all(|&d| d == 1);
        match f.values.len() {
            n if n == len && leading_ones => Ok(f.values),
            1 => Ok(vec![f.values.first().copied().unwrap_or(0.0); len]),
            _ => {
                Err(refusal(i, node, format!("tensor `{name}` has shape {:?}, {what} {len} values", f.dims)))
            }
        }
    }

    /// The constant input of a binary op that reads `cur` (either side for Add and Mul).
    fn other_input<'n>(&self, i: usize, node: &'n NodeProto, cur: &str) -> Result<&'n str, OnnxError> {
        match node.input.as_slice() {
            [a, b] if a == cur => Ok(b),
            [a, b] if b == cur => Ok(a),
            _ => Err(refusal(i, node, format!("expected two inputs, `{cur}` and a constant"))),
        }
    }

    fn normalise(&mut self, i: usize, node: &NodeProto, first_is_cur: bool) -> Result<(), OnnxError> {
        let op = node.op_type.as_str();
        let refuse = |reason: &str| refusal(i, node, reason.to_owned());
        if self.stage != Stage::Normalise {
            return Err(refuse(
                "after a layer: the runtime normalises the observation only (Sub, Div before the first layer)",
            ));
        }
        let [_, c] = node.input.as_slice() else {
            return Err(refuse("expected two inputs"));
        };
        if !first_is_cur {
            return Err(refuse("the observation must be its first input"));
        }
        if self.clip.is_some() {
            return Err(refuse("after the Clip: the runtime clips the normalised observation last"));
        }
        let obs_dim = self.target.obs_dim();
        let v = self.vector(i, node, c, obs_dim, "the hand observes")?;
        if op == "Sub" {
            if self.mean.is_some() || self.std.is_some() {
                return Err(refuse("a Sub after a Sub or Div: the runtime subtracts one mean, then divides"));
            }
            self.mean = Some(v);
        } else {
            if self.std.is_some() {
                return Err(refuse("a second Div: the runtime divides by one std"));
            }
            if let Some((at, s)) = v.iter().enumerate().find(|(_, s)| **s <= 0.0) {
                return Err(refuse(&format!("divides by {s} at index {at}: a std must be > 0")));
            }
            self.std = Some(v);
        }
        self.norm_node.get_or_insert_with(|| label(i, node));
        Ok(())
    }

    fn layer(&mut self, i: usize, node: &NodeProto, notes: &mut Vec<String>) -> Result<(), OnnxError> {
        let refuse = |reason: String| refusal(i, node, reason);
        if self.stage == Stage::Output {
            return Err(refuse(
                "a layer after the action's Mul, Add or Clip: the runtime scales the last layer's output only"
                    .to_owned(),
            ));
        }
        self.finish_layer();
        let is_gemm = node.op_type == "Gemm";
        let (b_name, c_name) = match node.input.as_slice() {
            [_, b] => (b.as_str(), None),
            [_, b, c] if is_gemm => (b.as_str(), Some(c.as_str()).filter(|c| !c.is_empty())),
            _ => return Err(refuse("expected inputs (x, W) or, for Gemm, (x, W, bias)".to_owned())),
        };
        let trans_b = if is_gemm {
            if attr_i(node, "transA").unwrap_or(0) != 0 {
                return Err(refuse("transA = 1: the observation must not be transposed".to_owned()));
            }
            attr_i(node, "transB").unwrap_or(0) != 0
        } else {
            false
        };
        let (alpha, beta) = if is_gemm {
            (attr_f(node, "alpha").unwrap_or(1.0), attr_f(node, "beta").unwrap_or(1.0))
        } else {
            (1.0, 1.0)
        };
        let w = self.constant(i, node, b_name)?;
        let &[rows, cols] = w.dims.as_slice() else {
            return Err(refuse(format!("weight `{b_name}` has shape {:?}, not a matrix", w.dims)));
        };
        // Stored row-major: `[out, in]` with transB (torch's Linear), else `[in, out]`.
        let (in_dim, out_dim) = if trans_b { (cols, rows) } else { (rows, cols) };
        let index = self.layers.len();
        let max = (self.target.max_layers, self.target.max_width);
        if index >= max.0 {
            return Err(refuse(format!("layer {}: the runtime holds at most {} layers", index + 1, max.0)));
        }
        match self.layers.last() {
            None if in_dim != self.target.obs_dim() => {
                return Err(refuse(format!(
                    "weight `{b_name}` takes {in_dim} inputs, the hand observes {} ({})",
                    self.target.obs_dim(),
                    show_layout(&self.target.obs_layout)
                )));
            }
            Some(prev) if prev.out_dim as usize != in_dim => {
                return Err(refuse(format!(
                    "weight `{b_name}` takes {in_dim} inputs, the layer before gives {}",
                    prev.out_dim
                )));
            }
            _ => {}
        }
        if let Some(w) = [in_dim, out_dim].into_iter().find(|&w| w > max.1 || w == 0) {
            return Err(refuse(format!(
                "width {w}: the runtime's layers are 1 to {} wide (vge_runtime::HandPolicy)",
                max.1
            )));
        }
        let mut weights = if trans_b {
            w.values
        } else {
            (0..out_dim)
                .flat_map(|o| (0..in_dim).map(move |k| (k, o)))
                .map(|(k, o)| w.values[k * out_dim + o])
                .collect()
        };
        let mut bias = match c_name {
            Some(c) => self.vector(i, node, c, out_dim, "the layer has")?,
            None => vec![0.0; out_dim],
        };
        if alpha != 1.0 || (beta != 1.0 && c_name.is_some()) {
            weights.iter_mut().for_each(|v| *v *= alpha);
            bias.iter_mut().for_each(|v| *v *= beta);
            notes.push(format!(
                "node `{}`: alpha {alpha} and beta {beta} folded into the weights and bias",
                label(i, node)
            ));
        }
        let layer = LayerRecord {
            in_dim: in_dim as u32,
            out_dim: out_dim as u32,
            activation: ACT_IDENTITY,
            weights,
            bias,
        };
        self.pending =
            Some(Pending { node: label(i, node), layer, activation: None, takes_bias: c_name.is_none() });
        self.stage = Stage::Layers;
        Ok(())
    }

    /// Moves the pending layer (with its activation, identity if none came) into the layers.
    fn finish_layer(&mut self) {
        if let Some(p) = self.pending.take() {
            let activation = p.activation.unwrap_or(ACT_IDENTITY);
            let bound = match activation {
                ACT_TANH => (-1.0, 1.0),
                ACT_RELU => (0.0, f32::INFINITY),
                _ => (f32::NEG_INFINITY, f32::INFINITY),
            };
            self.range = vec![bound; p.layer.out_dim as usize];
            self.layers.push(LayerRecord { activation, ..p.layer });
            self.layer_nodes.push(p.node);
        }
    }

    /// Width of the last layer's output.
    fn action_width(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out_dim as usize)
    }

    fn add(&mut self, i: usize, node: &NodeProto, cur: &str) -> Result<(), OnnxError> {
        let c = self.other_input(i, node, cur)?;
        if let Some(p) = &self.pending
            && p.takes_bias
            && p.activation.is_none()
        {
            let bias = self.vector(i, node, c, p.layer.out_dim as usize, "the layer has")?;
            if let Some(p) = &mut self.pending {
                p.layer.bias = bias;
                p.takes_bias = false;
            }
            return Ok(());
        }
        if self.stage == Stage::Normalise {
            return Err(refusal(
                i,
                node,
                "before any layer: write the normalisation as Sub (mean), then Div (std)".to_owned(),
            ));
        }
        self.finish_layer();
        if self.offset.is_some() {
            return Err(refusal(
                i,
                node,
                "a second Add after the last layer: the runtime adds one offset".to_owned(),
            ));
        }
        let v = self.vector(i, node, c, self.action_width(), "the action has")?;
        self.range.iter_mut().zip(&v).for_each(|(r, o)| *r = (r.0 + o, r.1 + o));
        self.offset = Some(v);
        self.stage = Stage::Output;
        Ok(())
    }

    fn mul(&mut self, i: usize, node: &NodeProto, cur: &str) -> Result<(), OnnxError> {
        let c = self.other_input(i, node, cur)?;
        let refuse = |reason: &str| refusal(i, node, reason.to_owned());
        if self.stage == Stage::Normalise {
            return Err(refuse("before any layer: write the normalisation as Sub (mean), then Div (std)"));
        }
        if self.offset.is_some() {
            return Err(refuse("a Mul after the action's Add: the runtime scales, then adds the offset"));
        }
        if self.scale.is_some() {
            return Err(refuse("a second Mul after the last layer: the runtime scales once"));
        }
        self.finish_layer();
        let v = self.vector(i, node, c, self.action_width(), "the action has")?;
        self.range.iter_mut().zip(&v).for_each(|(r, s)| {
            *r = if *s == 0.0 {
                (0.0, 0.0)
            } else {
                let (a, b) = (s * r.0, s * r.1);
                (a.min(b), a.max(b))
            }
        });
        self.scale = Some(v);
        self.stage = Stage::Output;
        Ok(())
    }

    fn clip(
        &mut self,
        i: usize,
        node: &NodeProto,
        first_is_cur: bool,
        notes: &mut Vec<String>,
    ) -> Result<(), OnnxError> {
        if !first_is_cur {
            return Err(refusal(i, node, "the value clipped must be its first input".to_owned()));
        }
        let bound = |k: usize, attr: &str, default: f32| -> Result<f32, OnnxError> {
            match node.input.get(k).filter(|s| !s.is_empty()) {
                Some(name) => {
                    let f = self.constant(i, node, name)?;
                    match f.values.as_slice() {
                        [v] => Ok(*v),
                        _ => Err(refusal(i, node, format!("bound `{name}` is not a scalar"))),
                    }
                }
                // Before opset 11 the bounds are attributes.
                None => Ok(attr_f(node, attr).unwrap_or(default)),
            }
        };
        let (lo, hi) = (bound(1, "min", f32::NEG_INFINITY)?, bound(2, "max", f32::INFINITY)?);
        if self.stage == Stage::Normalise {
            if self.clip.is_some() || !(hi > 0.0 && lo == -hi && hi.is_finite()) {
                return Err(refusal(
                    i,
                    node,
                    format!(
                        "clips the observation to [{lo}, {hi}]: the runtime clips once, to [-c, c] with c > 0"
                    ),
                ));
            }
            self.clip = Some(hi);
            self.norm_node.get_or_insert_with(|| label(i, node));
            return Ok(());
        }
        self.finish_layer();
        self.stage = Stage::Output;
        if let Some((k, r)) = self.range.iter().enumerate().find(|(_, r)| !(lo <= r.0 && r.1 <= hi)) {
            return Err(refusal(
                i,
                node,
                format!(
                    "clips the action to [{lo}, {hi}], but action {k} reaches [{}, {}]: the runtime does not clip \
                     actions (the hand clips each step to its largest joint-target change)",
                    r.0, r.1
                ),
            ));
        }
        notes.push(format!(
            "node `{}`: Clip to [{lo}, {hi}] cannot bind here and was left out",
            label(i, node)
        ));
        Ok(())
    }
}

/// Which nodes the values of `output` depend on: backwards from it through every input,
/// except an Expand's shape and a Shape's input (a Shape reads only its input's shape).
fn live_nodes(g: &GraphProto, output: &str) -> Vec<bool> {
    let producer: HashMap<&str, usize> =
        g.node.iter().enumerate().flat_map(|(i, n)| n.output.iter().map(move |o| (o.as_str(), i))).collect();
    let mut live = vec![false; g.node.len()];
    let mut stack = vec![output];
    while let Some(v) = stack.pop() {
        let Some(&i) = producer.get(v) else { continue };
        let (Some(n), Some(seen)) = (g.node.get(i), live.get_mut(i)) else { continue };
        if *seen || n.op_type == "Shape" {
            continue;
        }
        *seen = true;
        let inputs = if n.op_type == "Expand" { &n.input[..n.input.len().min(1)] } else { &n.input[..] };
        stack.extend(inputs.iter().filter(|s| !s.is_empty()).map(String::as_str));
    }
    live
}

/// A `Constant` node's float value.
fn constant_node(node: &NodeProto) -> Result<Floats, String> {
    for a in &node.attribute {
        match a.name.as_str() {
            "value" => {
                return a
                    .t
                    .as_ref()
                    .ok_or_else(|| "Constant without its tensor".to_owned())
                    .and_then(read_floats);
            }
            "value_float" => return Ok(Floats { dims: Vec::new(), values: vec![a.f] }),
            "value_floats" => return Ok(Floats { dims: vec![a.floats.len()], values: a.floats.clone() }),
            _ => {}
        }
    }
    Err("a Constant that holds no float tensor".to_owned())
}

fn attr_i(node: &NodeProto, name: &str) -> Option<i64> {
    node.attribute.iter().find(|a| a.name == name).map(|a| a.i)
}

fn attr_f(node: &NodeProto, name: &str) -> Option<f32> {
    node.attribute.iter().find(|a| a.name == name).map(|a| a.f)
}

/// The graph input's or output's declared element type and width, where declared.
fn check_io_type(
    v: &onnx_protobuf::ValueInfoProto,
    what: &str,
    width: usize,
    hand: &str,
) -> Result<(), OnnxError> {
    let Some(type_proto::Value::TensorType(t)) = v.type_.as_ref().and_then(|t| t.value.as_ref()) else {
        return Ok(());
    };
    if t.elem_type != DataType::FLOAT as i32 {
        return Err(OnnxError::Graph(format!(
            "{what} `{}` is not float32 (elem_type {})",
            v.name, t.elem_type
        )));
    }
    let last = t.shape.as_ref().and_then(|s| s.dim.last()).and_then(|d| match d.value {
        Some(dimension::Value::DimValue(n)) => Some(n),
        _ => None,
    });
    match last {
        Some(n) if n != width as i64 => {
            Err(OnnxError::Graph(format!("{what} `{}` is declared {n} wide, {hand} {width}", v.name)))
        }
        _ => Ok(()),
    }
}

fn same_layout(a: &[ObsSlice], b: &[ObsSlice]) -> bool {
    a == b
}

fn show_layout(layout: &[ObsSlice]) -> String {
    layout.iter().map(|s| format!("{} {}..{}", s.name, s.start, s.end)).collect::<Vec<_>>().join(", ")
}

/// The file's `metadata_props`.
struct Metadata<'a> {
    props: HashMap<&'a str, &'a str>,
}

impl<'a> Metadata<'a> {
    fn of(model: &'a ModelProto) -> Self {
        Self { props: model.metadata_props.iter().map(|e| (e.key.as_str(), e.value.as_str())).collect() }
    }

    fn bad(key: &str, reason: String) -> OnnxError {
        OnnxError::Metadata { key: key.to_owned(), reason }
    }

    fn number<T: std::str::FromStr>(&self, key: &str) -> Result<Option<T>, OnnxError> {
        self.props
            .get(key)
            .map(|v| v.trim().parse::<T>().map_err(|_| Self::bad(key, format!("`{v}` is not a number"))))
            .transpose()
    }

    /// The claims about the observation and actions, each checked against the hand.
    fn check(&self, target: &ImportTarget) -> Result<(), OnnxError> {
        if let Some(n) = self.number::<usize>(keys::OBS_DIM)?
            && n != target.obs_dim()
        {
            return Err(Self::bad(
                keys::OBS_DIM,
                format!("claims {n}, the hand observes {}", target.obs_dim()),
            ));
        }
        if let Some(n) = self.number::<usize>(keys::ACT_DIM)?
            && n != target.act_dim()
        {
            return Err(Self::bad(
                keys::ACT_DIM,
                format!("claims {n}, the hand has {} actions", target.act_dim()),
            ));
        }
        if let Some(text) = self.props.get(keys::OBS_LAYOUT) {
            let layout = parse_layout(text).map_err(|why| Self::bad(keys::OBS_LAYOUT, why))?;
            if !same_layout(&layout, &target.obs_layout) {
                return Err(Self::bad(
                    keys::OBS_LAYOUT,
                    format!(
                        "the file observes [{}], the hand provides [{}]",
                        show_layout(&layout),
                        show_layout(&target.obs_layout)
                    ),
                ));
            }
        }
        if let Some(text) = self.props.get(keys::ACTION_NAMES) {
            let names: Vec<String> = serde_json::from_str(text)
                .map_err(|e| Self::bad(keys::ACTION_NAMES, format!("not a JSON array of strings: {e}")))?;
            if names != target.action_names {
                return Err(Self::bad(
                    keys::ACTION_NAMES,
                    format!(
                        "the file acts on [{}], the hand on [{}]",
                        names.join(", "),
                        target.action_names.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    fn control_hz(&self) -> Result<Option<f32>, OnnxError> {
        let hz = self.number::<f32>(keys::CONTROL_HZ)?;
        match hz {
            Some(hz) if !(hz.is_finite() && hz > 0.0) => {
                Err(Self::bad(keys::CONTROL_HZ, format!("{hz}: must be finite and > 0")))
            }
            _ => Ok(hz),
        }
    }

    /// vge's provenance, when the file carries all of it (a file `vge export` wrote).
    fn provenance(&self) -> Result<Option<Provenance>, OnnxError> {
        let (Some(version), Some(hash)) =
            (self.props.get(keys::VGE_VERSION), self.props.get(keys::CONFIG_HASH))
        else {
            return Ok(None);
        };
        let (Some(seed), Some(steps)) = (self.number::<u64>(keys::SEED)?, self.number::<u64>(keys::STEPS)?)
        else {
            return Ok(None);
        };
        Ok(Some(Provenance {
            vge_version: (*version).to_owned(),
            config_hash: (*hash).to_owned(),
            seed,
            steps,
        }))
    }

    /// The task record, when the file names a hand (a file `vge export` wrote from a policy
    /// with one); each key checked as the policy file checks its field.
    fn task(&self) -> Result<Option<PolicyTask>, OnnxError> {
        use vge_runtime::policy::{check_task_name, is_observation_set};
        let Some(hand) = self.props.get(keys::HAND) else {
            return match keys::TASK.iter().find(|k| self.props.contains_key(**k)) {
                Some(key) => {
                    Err(Self::bad(key, format!("a task key without `{}`: name the hand", keys::HAND)))
                }
                None => Ok(None),
            };
        };
        let name = |key: &'static str, value: &str, required: bool| {
            check_task_name(key, value, required)
                .map(|()| value.to_owned())
                .map_err(|e| Self::bad(key, e.to_string()))
        };
        let hand = name(keys::HAND, hand, true)?;
        let missing =
            |key: &str| Self::bad(key, format!("missing: the file names its hand (`{}`)", keys::HAND));
        let sha = self.props.get(keys::HAND_SHA256).ok_or_else(|| missing(keys::HAND_SHA256))?;
        let hand_sha256 = parse_sha256(sha).ok_or_else(|| {
            let why = if sha.len() == 64 {
                format!("`{sha}` holds a character that is not a hex digit")
            } else {
                format!("{} bytes, not 64 hex digits", sha.len())
            };
            Self::bad(keys::HAND_SHA256, format!("{why} (the SHA-256 of the hand's MJCF description)"))
        })?;
        let set = self.props.get(keys::OBSERVATION_SET).ok_or_else(|| missing(keys::OBSERVATION_SET))?;
        if !is_observation_set(set) {
            return Err(Self::bad(
                keys::OBSERVATION_SET,
                format!("`{set:.72}` is not `full`, `proprio` or `proprio:K` (K 1 to 64)"),
            ));
        }
        Ok(Some(PolicyTask {
            hand,
            hand_sha256,
            observation_set: (*set).to_owned(),
            object: name(keys::OBJECT, self.props.get(keys::OBJECT).unwrap_or(&""), false)?,
            orientation: name(keys::ORIENTATION, self.props.get(keys::ORIENTATION).unwrap_or(&""), false)?,
        }))
    }
}

/// 64 hex digits (either case) as 32 bytes.
fn parse_sha256(text: &str) -> Option<[u8; 32]> {
    let digits = text.as_bytes();
    if digits.len() != 64 || !digits.iter().all(u8::is_ascii_hexdigit) {
        return None;
    }
    let mut sha = [0u8; 32];
    for (byte, pair) in sha.iter_mut().zip(digits.chunks_exact(2)) {
        *byte = u8::from_str_radix(std::str::from_utf8(pair).ok()?, 16).ok()?;
    }
    Some(sha)
}

fn parse_layout(text: &str) -> Result<Vec<ObsSlice>, String> {
    #[derive(serde::Deserialize)]
    struct Slice {
        name: String,
        start: u32,
        end: u32,
    }
    let slices: Vec<Slice> =
        serde_json::from_str(text).map_err(|e| format!("not a JSON array of {{name, start, end}}: {e}"))?;
    Ok(slices.into_iter().map(|s| ObsSlice::new(s.name, s.start..s.end)).collect())
}
