//! A policy file as one ONNX graph, raw observation to action.

use onnx_protobuf::attribute_proto::AttributeType;
use onnx_protobuf::tensor_proto::DataType;
use onnx_protobuf::tensor_shape_proto::{Dimension, dimension};
use onnx_protobuf::type_proto::{self, Tensor};
use onnx_protobuf::{
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto, StringStringEntryProto,
    TensorShapeProto, TypeProto, ValueInfoProto,
};
use protobuf::{EnumOrUnknown, MessageField};
use vge_runtime::WeightType;
use vge_runtime::format::{ACT_IDENTITY, ACT_RELU, ACT_TANH};

use super::tensor::float_tensor;
use super::{INPUT_NAME, IR_VERSION, OPSET_VERSION, OUTPUT_NAME, OnnxError, keys};
use crate::PolicyFile;

/// The ONNX model of `policy`: `action = offset + scale * mlp(clip((obs - mean) / std))` with
/// the same `f32` operations in the same order as `vge_runtime::Policy::forward`, so that
/// onnxruntime's actions differ from the runtime's only by the rounding of the matrix
/// products' summation order.
///
/// Graph: input [`INPUT_NAME`] `float32 [batch, obs_dim]`; nodes `normalise/sub_mean`,
/// `normalise/div_std`, `normalise/clip` (when the file clips), `layer{k}/gemm` and
/// `layer{k}/relu` or `layer{k}/tanh`, `action/mul_scale`, `action/add_offset`; output
/// [`OUTPUT_NAME`] `float32 [batch, act_dim]`. Initializers `obs_mean`, `obs_std`,
/// `obs_clip_min`/`obs_clip_max`, `layer{k}.weight` (`out × in`, `Gemm` with `transB = 1`, as
/// torch writes `Linear`), `layer{k}.bias`, `action_scale`, `action_offset`.
pub fn export(policy: &PolicyFile) -> Result<ModelProto, OnnxError> {
    let obs_dim = policy.obs_dim as usize;
    let act_dim = policy.act_dim as usize;
    let mut g = GraphProto::new();
    g.name = "vge_policy".to_owned();
    g.input.push(value_info(INPUT_NAME, batch_shape(obs_dim)));
    g.output.push(value_info(OUTPUT_NAME, batch_shape(act_dim)));

    g.initializer.push(float_tensor("obs_mean", &[obs_dim], &policy.obs_mean));
    g.initializer.push(float_tensor("obs_std", &[obs_dim], &policy.obs_std));
    g.node.push(node("normalise/sub_mean", "Sub", &[INPUT_NAME, "obs_mean"], "obs_centred"));
    g.node.push(node("normalise/div_std", "Div", &["obs_centred", "obs_std"], "obs_normalised"));
    let mut x = "obs_normalised".to_owned();
    if let Some(clip) = policy.obs_clip {
        g.initializer.push(float_tensor("obs_clip_min", &[], &[-clip]));
        g.initializer.push(float_tensor("obs_clip_max", &[], &[clip]));
        g.node.push(node("normalise/clip", "Clip", &[&x, "obs_clip_min", "obs_clip_max"], "obs_clipped"));
        x = "obs_clipped".to_owned();
    }

    for (k, layer) in policy.layers.iter().enumerate() {
        let (w, b) = (format!("layer{k}.weight"), format!("layer{k}.bias"));
        g.initializer.push(float_tensor(
            &w,
            &[layer.out_dim as usize, layer.in_dim as usize],
            &layer.weights,
        ));
        g.initializer.push(float_tensor(&b, &[layer.out_dim as usize], &layer.bias));
        let linear = format!("layer{k}.linear");
        let mut gemm = node(&format!("layer{k}/gemm"), "Gemm", &[&x, &w, &b], &linear);
        gemm.attribute.push(int_attribute("transB", 1));
        g.node.push(gemm);
        x = match layer.activation {
            ACT_IDENTITY => linear,
            ACT_RELU | ACT_TANH => {
                let (op, short) =
                    if layer.activation == ACT_RELU { ("Relu", "relu") } else { ("Tanh", "tanh") };
                let out = format!("layer{k}.out");
                g.node.push(node(&format!("layer{k}/{short}"), op, &[&linear], &out));
                out
            }
            code => {
                return Err(OnnxError::Graph(format!("layer {k} has activation code {code}, not 0, 1 or 2")));
            }
        };
    }

    g.initializer.push(float_tensor("action_scale", &[act_dim], &policy.action_scale));
    g.initializer.push(float_tensor("action_offset", &[act_dim], &policy.action_offset));
    g.node.push(node("action/mul_scale", "Mul", &[&x, "action_scale"], "action_scaled"));
    g.node.push(node("action/add_offset", "Add", &["action_scaled", "action_offset"], OUTPUT_NAME));

    let mut model = ModelProto::new();
    model.ir_version = IR_VERSION;
    let mut opset = OperatorSetIdProto::new();
    opset.domain = String::new();
    opset.version = OPSET_VERSION;
    model.opset_import.push(opset);
    model.producer_name = "vge".to_owned();
    model.producer_version = env!("CARGO_PKG_VERSION").to_owned();
    model.doc_string = "vge policy: action = action_offset + action_scale * mlp(clip((obs - obs_mean) / \
                        obs_std)); see metadata_props for the observation layout and action names"
        .to_owned();
    model.graph = MessageField::some(g);
    model.metadata_props = metadata(policy);
    Ok(model)
}

/// [`export`] encoded as protobuf bytes (an `.onnx` file).
pub fn to_bytes(policy: &PolicyFile) -> Result<Vec<u8>, OnnxError> {
    export(policy)?.write_to_bytes().map_err(OnnxError::Encode)
}

/// The ONNX bytes of the policy file `vgep` (any version; `f16` weights are exported as the
/// `f32` values the runtime widens them to). `i8` policies are refused
/// ([`OnnxError::Quantised`]).
pub fn policy_bytes_to_onnx(vgep: &[u8]) -> Result<Vec<u8>, OnnxError> {
    let (policy, weights) = PolicyFile::decode(vgep, true)?;
    if weights == WeightType::I8 {
        return Err(OnnxError::Quantised);
    }
    to_bytes(&policy)
}

fn metadata(policy: &PolicyFile) -> Vec<StringStringEntryProto> {
    let json = |v: serde_json::Value| v.to_string();
    let layout = policy
        .obs_layout
        .iter()
        .map(|s| serde_json::json!({ "name": s.name, "start": s.start, "end": s.end }))
        .collect::<Vec<_>>();
    let p = &policy.provenance;
    let mut entries = vec![
        (keys::OBS_LAYOUT, json(serde_json::Value::Array(layout))),
        (keys::ACTION_NAMES, json(serde_json::json!(policy.action_names))),
        (keys::OBS_DIM, policy.obs_dim.to_string()),
        (keys::ACT_DIM, policy.act_dim.to_string()),
        (keys::CONTROL_HZ, policy.control_hz.to_string()),
        (
            keys::ACTION_UNITS,
            "for vge's hand: the change of each joint's position target per control step (rad)".to_owned(),
        ),
        (keys::VGE_VERSION, p.vge_version.clone()),
        (keys::CONFIG_HASH, p.config_hash.clone()),
        (keys::SEED, p.seed.to_string()),
        (keys::STEPS, p.steps.to_string()),
    ];
    if let Some(t) = &policy.task {
        entries.extend([
            (keys::HAND, t.hand.clone()),
            (keys::HAND_SHA256, t.hand_sha256_hex()),
            (keys::OBSERVATION_SET, t.observation_set.clone()),
            (keys::OBJECT, t.object.clone()),
            (keys::ORIENTATION, t.orientation.clone()),
        ]);
    }
    entries
        .into_iter()
        .map(|(k, v)| {
            let mut e = StringStringEntryProto::new();
            e.key = k.to_owned();
            e.value = v;
            e
        })
        .collect()
}

/// `[batch, width]` with a symbolic batch dimension.
fn batch_shape(width: usize) -> TensorShapeProto {
    let mut batch = Dimension::new();
    batch.value = Some(dimension::Value::DimParam("batch".to_owned()));
    let mut w = Dimension::new();
    w.value = Some(dimension::Value::DimValue(width as i64));
    let mut shape = TensorShapeProto::new();
    shape.dim = vec![batch, w];
    shape
}

fn value_info(name: &str, shape: TensorShapeProto) -> ValueInfoProto {
    let mut tensor = Tensor::new();
    tensor.elem_type = DataType::FLOAT as i32;
    tensor.shape = MessageField::some(shape);
    let mut ty = TypeProto::new();
    ty.value = Some(type_proto::Value::TensorType(tensor));
    let mut v = ValueInfoProto::new();
    v.name = name.to_owned();
    v.type_ = MessageField::some(ty);
    v
}

fn node(name: &str, op: &str, inputs: &[&str], output: &str) -> NodeProto {
    let mut n = NodeProto::new();
    n.name = name.to_owned();
    n.op_type = op.to_owned();
    n.input = inputs.iter().map(|s| (*s).to_owned()).collect();
    n.output = vec![output.to_owned()];
    n
}

fn int_attribute(name: &str, value: i64) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.to_owned();
    a.type_ = EnumOrUnknown::new(AttributeType::INT);
    a.i = value;
    a
}
