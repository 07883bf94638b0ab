//! A count of what an ONNX model holds, read off its protobuf wire format without building
//! it, so that a model far beyond any MLP actor is refused before protobuf allocates a
//! message per node (850,000 nodes took 2.45 GB and 9 s to parse and walk).
//!
//! The scan follows the message fields of `onnx.proto` that protobuf would build (graphs,
//! nodes, attributes, tensors, value infos, types, shapes, entries, functions, training
//! info, subgraphs in attributes) and counts every node, every node whose op is a layer
//! (`Gemm`, `MatMul`), and every other field occurrence that becomes an allocation (a
//! message, a string, an unknown field), all bounded. Repeated numbers (a tensor's
//! `float_data`, `dims`, an attribute's `ints`) are arrays, not counted per number.

use super::OnnxError;

/// Most nodes an importable model may hold: a hand's MLP actor has a few per layer (and a
/// dead head or two), far below this.
pub const MAX_NODES: usize = 1024;
/// Most other allocations (messages, strings, unknown fields) protobuf would make for it.
pub const MAX_ELEMENTS: usize = 1 << 16;
/// Deepest nesting of messages followed (a subgraph in an attribute of a node of a graph...).
const MAX_DEPTH: usize = 32;

/// What the scan found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Census {
    pub nodes: usize,
    /// Nodes whose op is `Gemm` or `MatMul`, live or dead.
    pub layer_ops: usize,
    pub elements: usize,
    /// The whole model was scanned (else its bytes stopped being protobuf's wire format).
    pub complete: bool,
}

/// The message types of `onnx.proto` the scan follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Msg {
    Model,
    Graph,
    Node,
    Attribute,
    Tensor,
    SparseTensor,
    ValueInfo,
    Type,
    TypeTensor,
    TypeNested,
    TypeMap,
    Shape,
    Dimension,
    Entry,
    OpsetId,
    Annotation,
    Segment,
    TrainingInfo,
    Function,
}

impl Msg {
    /// The message type of field `field` of this message, when it is a message.
    fn child(self, field: u64) -> Option<Msg> {
        use Msg::*;
        Some(match (self, field) {
            (Model, 7) => Graph,
            (Model, 8) => OpsetId,
            (Model, 14) => Entry,
            (Model, 20) => TrainingInfo,
            (Model, 25) => Function,
            (Graph, 1) => Node,
            (Graph, 5) => Tensor,
            (Graph, 15) => SparseTensor,
            (Graph, 11..=13) => ValueInfo,
            (Graph, 14) => Annotation,
            (Graph, 16) => Entry,
            (Node, 5) => Attribute,
            (Node, 9) => Entry,
            (Attribute, 5 | 10) => Tensor,
            (Attribute, 6 | 11) => Graph,
            (Attribute, 22 | 23) => SparseTensor,
            (Attribute, 14 | 15) => Type,
            (Tensor, 3) => Segment,
            (Tensor, 13 | 16) => Entry,
            (SparseTensor, 1 | 2) => Tensor,
            (ValueInfo, 2) => Type,
            (ValueInfo, 4) => Entry,
            (Type, 1 | 8) => TypeTensor,
            (Type, 4 | 9) => TypeNested,
            (Type, 5) => TypeMap,
            (TypeTensor, 2) => Shape,
            (TypeNested, 1) | (TypeMap, 2) => Type,
            (Shape, 1) => Dimension,
            (Annotation, 2) => Entry,
            (TrainingInfo, 1 | 2) => Graph,
            (TrainingInfo, 3 | 4) => Entry,
            (Function, 11) => Attribute,
            (Function, 7) => Node,
            (Function, 9) => OpsetId,
            (Function, 12) => ValueInfo,
            (Function, 14) => Entry,
            _ => return None,
        })
    }

    /// Field `field` is a repeated number, stored as an array (packed or not).
    fn number_array(self, field: u64) -> bool {
        matches!(
            (self, field),
            (Msg::Tensor, 1 | 4 | 5 | 7 | 10 | 11) | (Msg::Attribute, 7 | 8) | (Msg::SparseTensor, 3)
        )
    }
}

/// Counts the model `bytes` (module docs), refusing it as soon as a count passes its bound:
/// nodes past [`MAX_NODES`], layer ops past `max_layer_ops`, elements past [`MAX_ELEMENTS`],
/// nesting past 32. Bytes that are not protobuf's wire format end the count where they
/// start (`complete` false): protobuf's parser then refuses them, having built no more than
/// what was counted.
pub fn count(bytes: &[u8], max_layer_ops: usize) -> Result<Census, OnnxError> {
    let mut census = Census { complete: true, ..Census::default() };
    match scan(bytes, Msg::Model, 0, max_layer_ops, &mut census) {
        Ok(()) => Ok(census),
        Err(Stop::Malformed) => Ok(Census { complete: false, ..census }),
        Err(Stop::Refused(e)) => Err(e),
    }
}

/// Why a scan stopped early.
enum Stop {
    /// Past a bound.
    Refused(OnnxError),
    /// Not protobuf's wire format from here on.
    Malformed,
}

impl From<OnnxError> for Stop {
    fn from(e: OnnxError) -> Self {
        Self::Refused(e)
    }
}

fn scan(bytes: &[u8], msg: Msg, depth: usize, max_layer_ops: usize, c: &mut Census) -> Result<(), Stop> {
    if depth > MAX_DEPTH {
        let e = OnnxError::Graph(format!("messages nested deeper than {MAX_DEPTH}: not an MLP actor"));
        return Err(e.into());
    }
    let mut at = 0;
    while at < bytes.len() {
        let key = varint(bytes, &mut at)?;
        let (field, wire) = (key >> 3, key & 7);
        let value = match wire {
            0 => {
                varint(bytes, &mut at)?;
                None
            }
            1 => Some(take(bytes, &mut at, 8)?),
            2 => {
                let len = usize::try_from(varint(bytes, &mut at)?).map_err(|_| Stop::Malformed)?;
                Some(take(bytes, &mut at, len)?)
            }
            5 => Some(take(bytes, &mut at, 4)?),
            _ => return Err(Stop::Malformed),
        };
        if field == 0 {
            return Err(Stop::Malformed);
        }
        if msg.number_array(field) {
            // Numbers land in an array: no allocation of their own.
            continue;
        }
        c.elements += 1;
        if c.elements > MAX_ELEMENTS {
            return Err(Stop::Refused(OnnxError::Graph(format!(
                "more than {MAX_ELEMENTS} messages, names and fields: far more than an MLP actor holds; not read further"
            ))));
        }
        let (Some(child), Some(payload), 2) = (msg.child(field), value, wire) else { continue };
        if child == Msg::Node {
            c.nodes += 1;
            if c.nodes > MAX_NODES {
                return Err(Stop::Refused(OnnxError::Graph(format!(
                    "more than {MAX_NODES} nodes: far more than an MLP actor holds; not read further"
                ))));
            }
            if is_layer_op(payload)? {
                c.layer_ops += 1;
                if c.layer_ops > max_layer_ops {
                    return Err(Stop::Refused(OnnxError::Graph(format!(
                        "more than {max_layer_ops} Gemm and MatMul nodes: more layers than the runtime \
                         holds, even with a dead head beside each; not read further"
                    ))));
                }
            }
        }
        scan(payload, child, depth + 1, max_layer_ops, c)?;
    }
    Ok(())
}

/// Whether the `NodeProto` `node`'s op (`op_type`, field 4) is a layer's: `Gemm` or `MatMul`.
fn is_layer_op(node: &[u8]) -> Result<bool, Stop> {
    let mut at = 0;
    let mut op: &[u8] = &[];
    while at < node.len() {
        let key = varint(node, &mut at)?;
        match key & 7 {
            0 => {
                varint(node, &mut at)?;
            }
            1 => {
                take(node, &mut at, 8)?;
            }
            2 => {
                let len = usize::try_from(varint(node, &mut at)?).map_err(|_| Stop::Malformed)?;
                let value = take(node, &mut at, len)?;
                if key >> 3 == 4 {
                    // The last occurrence wins, as protobuf reads a repeated singular field.
                    op = value;
                }
            }
            5 => {
                take(node, &mut at, 4)?;
            }
            _ => return Err(Stop::Malformed),
        }
    }
    Ok(op == b"Gemm" || op == b"MatMul")
}

fn varint(bytes: &[u8], at: &mut usize) -> Result<u64, Stop> {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*at).ok_or(Stop::Malformed)?;
        *at += 1;
        value |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Ok(value);
        }
    }
    Err(Stop::Malformed)
}

fn take<'a>(bytes: &'a [u8], at: &mut usize, len: usize) -> Result<&'a [u8], Stop> {
    let end = at.checked_add(len).filter(|&e| e <= bytes.len()).ok_or(Stop::Malformed)?;
    let s = &bytes[*at..end];
    *at = end;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use onnx_protobuf::{GraphProto, Message, ModelProto, NodeProto, TensorProto};

    use super::*;

    fn node(op: &str, i: usize) -> NodeProto {
        let mut n = NodeProto::new();
        n.op_type = op.to_owned();
        n.input = vec![format!("v{i}"), "w".to_owned()];
        n.output = vec![format!("v{}", i + 1)];
        n
    }

    fn model(nodes: Vec<NodeProto>) -> Vec<u8> {
        let mut g = GraphProto::new();
        g.node = nodes;
        let mut t = TensorProto::new();
        t.float_data = vec![0.5; 1000];
        t.dims = vec![10, 100];
        g.initializer = vec![t];
        let mut m = ModelProto::new();
        m.graph = Some(g).into();
        m.write_to_bytes().expect("encodes")
    }

    #[test]
    fn nodes_and_layers_are_counted_and_number_arrays_are_not() {
        let nodes = vec![node("Gemm", 0), node("Relu", 1), node("MatMul", 2), node("Add", 3)];
        let c = count(&model(nodes), 8).expect("counts");
        assert_eq!((c.nodes, c.layer_ops), (4, 2));
        // Model.graph, Graph.node x4 with 3 strings each, Graph.initializer: its 1000 floats
        // and 2 dims are arrays.
        assert!(c.elements < 30, "{c:?}");
    }

    #[test]
    fn too_many_nodes_or_layers_are_refused_before_a_model_is_built() {
        let chain: Vec<NodeProto> = (0..MAX_NODES + 1).map(|i| node("Identity", i)).collect();
        let e = count(&model(chain), 8).expect_err("nodes").to_string();
        assert!(e.contains(&format!("more than {MAX_NODES} nodes")), "{e}");
        let layers: Vec<NodeProto> = (0..9).map(|i| node("Gemm", i)).collect();
        let e = count(&model(layers), 8).expect_err("layers").to_string();
        assert!(e.contains("more than 8 Gemm and MatMul nodes"), "{e}");
        // Nodes inside a subgraph of an attribute count too.
        let mut inner = GraphProto::new();
        inner.node = (0..MAX_NODES + 1).map(|i| node("Identity", i)).collect();
        let mut attr = onnx_protobuf::AttributeProto::new();
        attr.g = Some(inner).into();
        let mut n = node("If", 0);
        n.attribute = vec![attr];
        assert!(count(&model(vec![n]), 8).is_err(), "a subgraph's nodes are nodes");
    }

    #[test]
    fn bytes_that_are_not_protobuf_end_the_count_for_the_parser_to_refuse() {
        let bytes = model(vec![node("Gemm", 0)]);
        assert!(count(&bytes, 8).expect("counts").complete);
        for junk in [&bytes[..bytes.len() - 3], &[0x0b], &[0xff; 11]] {
            let c = count(junk, 8).expect("not refused here");
            assert!(!c.complete, "{junk:?}");
            assert!(ModelProto::parse_from_bytes(junk).is_err(), "protobuf refuses {junk:?}");
        }
    }
}
