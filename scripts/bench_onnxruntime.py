#!/usr/bin/env python3
"""onnxruntime's batch-1 forward on a policy's ONNX export, to set beside vge's runtime
(`runtime/examples/forward_bench.rs`, run by scripts/bench-runtime-vs-onnxruntime.sh).

One intra-op and one inter-op thread, sequential execution, all graph optimisations; the same
observation stream as the runtime's bench (xorshift64* in [-1, 1) per entry). Timed per call
with perf_counter_ns, three ways:
- `run`: session.run with a numpy input (what a Python deployment calls);
- `iobinding`: run_with_iobinding on an input and output bound once (no per-call allocation:
  the least Python does per call);
- `floor`: the same iobinding call on a one-node graph (Identity) of the policy's input: what
  a call costs before any arithmetic, Python's share included.
Prints one JSON line with the medians and 99th percentiles in ns.
"""

import argparse
import json
import time

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper


def observations(n_obs, count=64):
    """The runtime bench's stream: xorshift64*, (x >> 40) / 2^23 - 1 per entry."""
    state = 0x9E3779B97F4A7C15
    mask = (1 << 64) - 1
    out = np.empty((count, n_obs), dtype=np.float32)
    for i in range(count):
        for j in range(n_obs):
            state ^= state >> 12
            state ^= (state << 25) & mask
            state ^= state >> 27
            out[i, j] = np.float32(((state * 0x2545F4914F6CDD1D) & mask) >> 40) / np.float32(1 << 23) - np.float32(1)
    return out


def session(model_bytes):
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(model_bytes, opts, providers=["CPUExecutionProvider"])


def timed(call, obs, iters):
    for k in range(iters // 10 + 100):
        call(obs[k % len(obs)])
    ns = np.empty(iters)
    for k in range(iters):
        o = obs[k % len(obs)]
        t = time.perf_counter_ns()
        call(o)
        ns[k] = time.perf_counter_ns() - t
    return float(np.median(ns)), float(np.percentile(ns, 99))


def bound_call(sess, n_obs, n_act, in_name, out_name):
    x = np.zeros((1, n_obs), dtype=np.float32)
    y = np.zeros((1, n_act), dtype=np.float32)
    binding = sess.io_binding()
    binding.bind_cpu_input(in_name, x)
    binding.bind_output(out_name, "cpu", 0, np.float32, [1, n_act], y.ctypes.data)

    def call(o):
        x[0] = o
        sess.run_with_iobinding(binding)

    return call


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("onnx", help="the policy as ONNX (vge export --format onnx)")
    p.add_argument("--iters", type=int, default=20000)
    args = p.parse_args()
    model = onnx.load(args.onnx)
    in_name, out_name = model.graph.input[0].name, model.graph.output[0].name
    n_obs = model.graph.input[0].type.tensor_type.shape.dim[1].dim_value
    n_act = model.graph.output[0].type.tensor_type.shape.dim[1].dim_value
    sess = session(model.SerializeToString())
    obs = observations(n_obs)
    run_ns, run_p99 = timed(lambda o: sess.run(None, {in_name: o[None, :]}), obs, args.iters)
    bind_ns, bind_p99 = timed(bound_call(sess, n_obs, n_act, in_name, out_name), obs, args.iters)
    # The floor: an Identity graph over an input of the policy's width.
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, n_obs])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, n_obs])
    identity = helper.make_model(helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "floor", [x], [y]),
                                 opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    floor = session(identity.SerializeToString())
    floor_ns, _ = timed(bound_call(floor, n_obs, n_obs, "x", "y"), obs, args.iters)
    print(json.dumps({
        "bench": "onnxruntime",
        "onnxruntime_version": ort.__version__,
        "iters": args.iters,
        "run_median_ns": run_ns, "run_p99_ns": run_p99,
        "iobinding_median_ns": bind_ns, "iobinding_p99_ns": bind_p99,
        "floor_median_ns": floor_ns,
    }))


if __name__ == "__main__":
    main()
