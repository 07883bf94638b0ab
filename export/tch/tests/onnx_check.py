"""ONNX side of vge's ONNX tests (export/tch/tests/onnx.rs) and of docs/results/onnx-import/.

Uses the real `onnx` and `onnxruntime` packages (from .deps/py); no fallbacks.

  check MODEL                 onnx.checker.check_model(full_check=True), then print a JSON
                              summary (opset, metadata_props, input/output shapes, ops)
  run MODEL OBS OUT           onnxruntime on the float32 little-endian observations in OBS
                              (rows of the model's input width); writes the actions to OUT
  build OUT [options]         an MLP actor in the layout torch.onnx.export writes for a
                              Stable-Baselines3 SAC actor (Flatten, Gemm + Relu per hidden layer,
                              Gemm, Tanh), with torch's default Linear initialisation drawn from
                              a seeded generator; --variant makes the broken graphs the importer
                              must refuse
"""

import argparse
import json
import sys

import numpy as np
import onnx
import onnxruntime
from onnx import TensorProto, helper, numpy_helper


def check(path):
    model = onnx.load(path)
    onnx.checker.check_model(model, full_check=True)

    def shape(v):
        return [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]

    summary = {
        "ir_version": model.ir_version,
        "opset": {o.domain or "ai.onnx": o.version for o in model.opset_import},
        "producer": f"{model.producer_name} {model.producer_version}",
        "inputs": {i.name: shape(i) for i in model.graph.input},
        "outputs": {o.name: shape(o) for o in model.graph.output},
        "ops": [n.op_type for n in model.graph.node],
        "metadata_props": {p.key: p.value for p in model.metadata_props},
    }
    print(json.dumps(summary, indent=1))


def run(path, obs_path, out_path):
    session = onnxruntime.InferenceSession(path, providers=["CPUExecutionProvider"])
    (inp,) = session.get_inputs()
    width = inp.shape[-1]
    obs = np.fromfile(obs_path, dtype="<f4").reshape(-1, width)
    if inp.shape[0] == 1:
        # A batch fixed at 1 (torch.onnx.export without dynamic_axes, as SB3's docs export).
        actions = np.concatenate([session.run(None, {inp.name: obs[k:k + 1]})[0] for k in range(len(obs))])
    else:
        (actions,) = session.run(None, {inp.name: obs})
    np.asarray(actions, dtype="<f4").tofile(out_path)
    print(f"onnxruntime {onnxruntime.__version__}: {obs.shape[0]} observations -> actions {actions.shape}")


def linear(rng, n_in, n_out):
    # torch.nn.Linear's default: U(-1/sqrt(in), 1/sqrt(in)) for weight and bias.
    bound = 1.0 / np.sqrt(n_in)
    w = rng.uniform(-bound, bound, size=(n_out, n_in)).astype(np.float32)
    b = rng.uniform(-bound, bound, size=(n_out,)).astype(np.float32)
    return w, b


def build(out, obs_dim, act_dim, hidden, seed, variant, matmul, weights_npz, sb3_head):
    rng = np.random.default_rng(seed)
    dims = [obs_dim] + hidden + [act_dim]
    names = [f"latent_pi.{2 * k}" for k in range(len(hidden))] + ["mu"]
    params = [linear(rng, a, b) for a, b in zip(dims[:-1], dims[1:])]
    if weights_npz:
        # Fitted weights (the results loop): w0, b0, w1, b1, ... as numpy arrays.
        saved = np.load(weights_npz)
        params = [(saved[f"w{k}"].astype(np.float32), saved[f"b{k}"].astype(np.float32)) for k in range(len(params))]
    if variant == "nan":
        params[-1][0][3, 7] = np.nan

    nodes, inits = [], []
    x = "input"
    nodes.append(helper.make_node("Flatten", [x], ["/features_extractor/flatten/Flatten_output_0"],
                                  name="/features_extractor/flatten/Flatten", axis=1))
    x = "/features_extractor/flatten/Flatten_output_0"
    for k, ((w, b), name) in enumerate(zip(params, names)):
        scope = f"/latent_pi/{name}" if name != "mu" else "/mu"
        y = f"{scope}/Gemm_output_0"
        if matmul:
            # torch's dynamo exporter: MatMul with the transposed weight, then Add.
            wt = f"{name}.weight_t"
            inits.append(numpy_helper.from_array(np.ascontiguousarray(w.T), wt))
            inits.append(numpy_helper.from_array(b, f"{name}.bias"))
            nodes.append(helper.make_node("MatMul", [x, wt], [f"{scope}/MatMul_output_0"], name=f"{scope}/MatMul"))
            nodes.append(helper.make_node("Add", [f"{scope}/MatMul_output_0", f"{name}.bias"], [y], name=f"{scope}/Add"))
        else:
            inits.append(numpy_helper.from_array(w, f"{name}.weight"))
            inits.append(numpy_helper.from_array(b, f"{name}.bias"))
            nodes.append(helper.make_node("Gemm", [x, f"{name}.weight", f"{name}.bias"], [y], name=f"{scope}/Gemm",
                                          alpha=1.0, beta=1.0, transB=1))
        x = y
        if name != "mu":
            act = "Relu"
            if k == 0 and variant == "unsupported":
                act = "Sigmoid"
            if k == 0 and variant == "elu":
                act = "Elu"
            act_name = f"/latent_pi/latent_pi.{2 * k + 1}/{act}"
            nodes.append(helper.make_node(act, [x], [f"{act_name}_output_0"], name=act_name))
            x = f"{act_name}_output_0"
    if sb3_head:
        # What torch.onnx.export really writes for SB3's SAC actor: the log_std head, used only
        # for the shape of an Expand in front of the Tanh (sb3_actor.py in
        # docs/results/onnx-import exported it so).
        w, b = linear(rng, hidden[-1], act_dim)
        inits += [numpy_helper.from_array(w, "log_std.weight"), numpy_helper.from_array(b, "log_std.bias"),
                  numpy_helper.from_array(np.array(-20, np.float32), "min"),
                  numpy_helper.from_array(np.array(2, np.float32), "max"),
                  numpy_helper.from_array(np.array(0, np.float32), "zero")]
        latent = nodes[-2].output[0]
        nodes += [
            helper.make_node("Gemm", [latent, "log_std.weight", "log_std.bias"], ["ls"], name="/log_std/Gemm", transB=1),
            helper.make_node("Clip", ["ls", "min", "max"], ["ls_c"], name="/Clip"),
            helper.make_node("Exp", ["ls_c"], ["std"], name="/Exp"),
            helper.make_node("Mul", ["zero", "std"], ["std0"], name="/Mul"),
            helper.make_node("Shape", [x], ["mu_shape"], name="/Shape"),
            helper.make_node("ConstantOfShape", ["mu_shape"], ["zeros"], name="/ConstantOfShape"),
            helper.make_node("Add", ["zeros", x], ["a0"], name="/Add"),
            helper.make_node("Add", ["a0", "std0"], ["a1"], name="/Add_1"),
            helper.make_node("Shape", ["a1"], ["a1_shape"], name="/Shape_1"),
            helper.make_node("Expand", [x, "a1_shape"], ["expanded"], name="/Expand"),
        ]
        x = "expanded"
    nodes.append(helper.make_node("Tanh", [x], ["output"], name="/Tanh"))

    graph = helper.make_graph(
        nodes, "main_graph",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["batch_size", obs_dim])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["batch_size", act_dim])],
        inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name="onnx.helper (torch.onnx.export layout)")
    model.ir_version = 8
    # The broken variants are still well-formed ONNX: only vge's limits refuse them.
    onnx.checker.check_model(model, full_check=True)
    onnx.save(model, out)
    print(f"wrote {out}: {' -> '.join(map(str, dims))}, {variant}{', MatMul + Add' if matmul else ''}")


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("check")
    c.add_argument("model")
    r = sub.add_parser("run")
    r.add_argument("model")
    r.add_argument("obs")
    r.add_argument("out")
    b = sub.add_parser("build")
    b.add_argument("out")
    b.add_argument("--obs", type=int, default=65)
    b.add_argument("--act", type=int, default=15)
    b.add_argument("--hidden", default="256,256")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--variant", choices=["ok", "unsupported", "elu", "nan"], default="ok")
    b.add_argument("--matmul", action="store_true")
    b.add_argument("--sb3-head", action="store_true", help="add the log_std head torch writes for SB3's actor")
    b.add_argument("--weights", help="npz of fitted w0, b0, w1, b1, ... instead of random ones")
    a = p.parse_args()
    if a.cmd == "check":
        check(a.model)
    elif a.cmd == "run":
        run(a.model, a.obs, a.out)
    else:
        hidden = [int(h) for h in a.hidden.split(",") if h]
        build(a.out, a.obs, a.act, hidden, a.seed, a.variant, a.matmul, a.weights, a.sb3_head)
    return 0


if __name__ == "__main__":
    sys.exit(main())
