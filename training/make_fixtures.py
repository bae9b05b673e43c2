#!/usr/bin/env python3
"""ONNX models with fixed (seeded random) weights: test fixtures and latency-benchmark networks.

These are NOT trained policies. They follow the policy model I/O contract of
sim/src/observation.rs (input "obs" float32 [1, 2, 224, 224], output "action" float32 [1, 3],
tanh) so that the loading, contract check and inference paths can be tested and timed before
the trained SAC policy exists.

    pip install onnx==1.23.2 numpy
    python3 training/make_fixtures.py                # models/fixtures/*.onnx (committed, small)
    python3 training/make_fixtures.py --bench DIR    # benchmark networks into DIR (large, not committed)

Deterministic: the same command writes byte-identical files.
"""

import argparse
import json
import os

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

import herb_sim  # the contract's names and shapes (the Rust side's, through the bindings)

OPSET = 17  # tract 0.23 is tested against opsets 9..18
IR_VERSION = 8
SHAPE = list(herb_sim.MODEL_INPUT_SHAPE)  # [1, 2, 224, 224]
S = herb_sim.OBS_SIZE


def build(name, pool, convs, fcs, seed=0, in_name=herb_sim.INPUT_NAME, in_shape=SHAPE,
          out_name=herb_sim.OUTPUT_NAME, n_out=herb_sim.MODEL_OUTPUT_SHAPE[1], global_pool=False):
    """A NatureCNN-style actor: optional AvgPool(pool), convs [(out_ch, kernel, stride)],
    optional global average pool, flatten, ReLU MLP `fcs`, a linear layer to `n_out`, tanh."""
    rng = np.random.default_rng(seed)
    inits, nodes = [], []

    def param(pname, shape, fan_in):
        a = (rng.uniform(-1.0, 1.0, size=shape) * np.sqrt(6.0 / fan_in)).astype(np.float32)
        inits.append(numpy_helper.from_array(a, name=pname))
        return pname

    def bias(pname, n):
        inits.append(numpy_helper.from_array(
            rng.uniform(-0.1, 0.1, n).astype(np.float32), name=pname))
        return pname

    x, ch, side = in_name, in_shape[1], in_shape[2]
    if pool > 1:
        nodes.append(helper.make_node("AveragePool", [x], ["pooled"], name="pool",
                                      kernel_shape=[pool, pool], strides=[pool, pool]))
        x, side = "pooled", side // pool
    for i, (oc, k, s) in enumerate(convs):
        w = param(f"conv{i}.w", (oc, ch, k, k), ch * k * k)
        b = bias(f"conv{i}.b", oc)
        nodes.append(helper.make_node("Conv", [x, w, b], [f"conv{i}"], name=f"conv{i}",
                                      kernel_shape=[k, k], strides=[s, s], pads=[0, 0, 0, 0]))
        nodes.append(helper.make_node("Relu", [f"conv{i}"], [f"relu{i}"], name=f"relu{i}"))
        x, ch, side = f"relu{i}", oc, (side - k) // s + 1
    if global_pool:
        nodes.append(helper.make_node("GlobalAveragePool", [x], ["gap"], name="gap"))
        x, side = "gap", 1
    nodes.append(helper.make_node("Flatten", [x], ["flat"], name="flatten", axis=1))
    x, fan = "flat", ch * side * side
    for i, out in enumerate(list(fcs) + [n_out]):
        w = param(f"fc{i}.w", (out, fan), fan)
        b = bias(f"fc{i}.b", out)
        last = i == len(fcs)
        y = f"fc{i}"
        nodes.append(helper.make_node("Gemm", [x, w, b], [y], name=y, transB=1))
        z = out_name if last else f"fcrelu{i}"
        nodes.append(helper.make_node("Tanh" if last else "Relu", [y], [z], name=f"act{i}"))
        x, fan = z, out
    graph = helper.make_graph(
        nodes, name,
        inputs=[helper.make_tensor_value_info(in_name, TensorProto.FLOAT, in_shape)],
        outputs=[helper.make_tensor_value_info(out_name, TensorProto.FLOAT, [1, n_out])],
        initializer=inits)
    # The producer name keeps the script's first path so the committed fixtures stay byte-identical.
    model = helper.make_model(graph, producer_name="herb models/make_fixtures.py",
                              opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = IR_VERSION
    onnx.checker.check_model(model, full_check=True)
    return model


# The benchmark networks: the paper's NatureCNN on the full 224 x 224 observation (SB3 SAC:
# NatureCNN features 512, actor MLP 256-256), and lighter candidates for deployment that
# downsample inside the network (the I/O contract is unchanged).
BENCH = {
    "naturecnn224": dict(pool=1, convs=[(32, 8, 4), (64, 4, 2), (64, 3, 1)], fcs=[512, 256, 256]),
    "naturecnn112": dict(pool=2, convs=[(32, 8, 4), (64, 4, 2), (64, 3, 1)], fcs=[512, 256, 256]),
    "herbnet112": dict(pool=2, convs=[(16, 8, 4), (32, 4, 2), (32, 3, 1)], fcs=[256, 256, 256]),
    "herbnet56": dict(pool=4, convs=[(32, 8, 4), (64, 4, 2), (64, 3, 1)], fcs=[512, 256, 256]),
}

# Test fixtures (small): a tiny valid policy and models that break the contract one way each.
TINY = dict(pool=8, convs=[(4, 3, 2)], fcs=[], global_pool=True)
FIXTURES = {
    "tiny_policy": dict(TINY),
    "bad_input_name": dict(TINY, in_name="x"),
    "bad_input_shape": dict(TINY, in_shape=[1, 1, S, S]),
    "bad_output_shape": dict(TINY, n_out=2),
}


def reference_outputs(model):
    """Outputs of the ONNX reference evaluator for two fixed observations."""
    from onnx.reference import ReferenceEvaluator
    ev = ReferenceEvaluator(model)
    zeros = np.zeros(SHAPE, dtype=np.float32)
    ramp = ((np.arange(np.prod(SHAPE)) % 255) / 255.0).astype(np.float32).reshape(SHAPE)
    return {name: [float(v) for v in ev.run(None, {herb_sim.INPUT_NAME: obs})[0].ravel()]
            for name, obs in [("zeros", zeros), ("ramp", ramp)]}


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bench", metavar="DIR", help="write the benchmark networks into DIR")
    args = ap.parse_args()
    if args.bench:
        os.makedirs(args.bench, exist_ok=True)
        for name, spec in BENCH.items():
            path = os.path.join(args.bench, name + ".onnx")
            onnx.save(build(name, **spec), path)
            print(f"wrote {path} ({os.path.getsize(path) / 1e6:.1f} MB)")
        return
    out = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models", "fixtures")
    os.makedirs(out, exist_ok=True)
    expected = {}
    for name, spec in FIXTURES.items():
        model = build(name, **spec)
        path = os.path.join(out, name + ".onnx")
        onnx.save(model, path)
        print(f"wrote {path} ({os.path.getsize(path)} bytes)")
        if name == "tiny_policy":
            expected = reference_outputs(model)
    with open(os.path.join(out, "tiny_policy_expected.json"), "w") as f:
        json.dump({"source": "onnx.reference.ReferenceEvaluator on tiny_policy.onnx",
                   "zeros": expected["zeros"], "ramp": expected["ramp"],
                   "ramp_definition": f"((i mod 255) / 255) for i in 0..{SHAPE[1]}*{S}*{S}, row-major"},
                  f, indent=2)
        f.write("\n")


if __name__ == "__main__":
    main()
