//! A small interpreter for the two MediaPipe networks, in candle on the CPU.
//!
//! `tools/landmarker/convert_mediapipe.py` turns each TFLite file into a safetensors file:
//! the constant tensors (as MediaPipe ships them, laid out for NCHW) and, in the metadata, the
//! operator list in execution order with TFLite's options. [`Graph`] runs exactly that list:
//! the convolutional networks (detector, Face Mesh v1 and v2) and the blendshape head (an
//! MLP-Mixer of 1x1 convolutions, transposes and layer norms built from reductions). Tensors
//! of rank 4 are NCHW here while the graph's shapes and axes are TFLite's NHWC;
//! [`Graph::forward`] maps between the two where an operator needs it (padding, reshape,
//! concatenation, reductions, transposes, slices, broadcasting against lower-rank operands)
//! and checks every operator's output shape against the one the file records.

use std::collections::BTreeMap;

use candle_core::{DType, Device, Tensor};
use serde::Deserialize;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum GraphError {
    #[error("{name}: {cause}")]
    Candle {
        name: String,
        cause: candle_core::Error,
    },
    #[error("{name}: {message}")]
    Format { name: String, message: String },
}

#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
enum Activation {
    None,
    Relu,
    Relu6,
}

#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(rename_all = "lowercase")]
enum Padding {
    Same,
    Valid,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case")]
enum Kind {
    Conv2d {
        stride: [usize; 2],
        padding: Padding,
        activation: Activation,
    },
    DepthwiseConv2d {
        stride: [usize; 2],
        padding: Padding,
        activation: Activation,
    },
    MaxPool2d {
        stride: [usize; 2],
        filter: [usize; 2],
        padding: Padding,
        activation: Activation,
    },
    Add {
        activation: Activation,
    },
    Concat {
        axis: i64,
        activation: Activation,
    },
    Pad {
        paddings: Vec<[usize; 2]>,
    },
    Reshape,
    Relu,
    Prelu,
    Logistic,
    Neg,
    Sqrt,
    Rsqrt,
    Sub {
        activation: Activation,
    },
    Mul {
        activation: Activation,
    },
    Div {
        activation: Activation,
    },
    SquaredDifference {
        activation: Activation,
    },
    /// Reductions over TFLite axes.
    Mean {
        axes: Vec<usize>,
        keep_dims: bool,
    },
    Sum {
        axes: Vec<usize>,
        keep_dims: bool,
    },
    /// A permutation of TFLite axes.
    Transpose {
        perm: Vec<usize>,
    },
    /// Per TFLite axis `[start, stop, step]` (masks and negative bounds already resolved by
    /// the converter), then the `squeeze`d axes removed.
    StridedSlice {
        ranges: Vec<[usize; 3]>,
        squeeze: Vec<usize>,
    },
}

#[derive(Clone, Debug, Deserialize)]
struct Op {
    inputs: Vec<String>,
    output: String,
    output_shape: Vec<usize>,
    #[serde(flatten)]
    kind: Kind,
}

/// One network: its constants and operators.
pub struct Graph {
    name: String,
    ops: Vec<Op>,
    constants: BTreeMap<String, Tensor>,
    input: String,
    /// As TFLite gives it (NHWC for an image).
    pub input_shape: Vec<usize>,
    outputs: Vec<String>,
}

impl Graph {
    /// Reads a network from the bytes of a converted safetensors file; `name` is used in errors.
    pub fn from_bytes(name: &str, bytes: &[u8]) -> Result<Graph, GraphError> {
        let format = |message: String| GraphError::Format {
            name: name.to_string(),
            message,
        };
        let (_, header) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| format(format!("not a safetensors file: {e}")))?;
        let meta = header
            .metadata()
            .clone()
            .ok_or_else(|| format("no metadata (not made by convert_mediapipe.py)".into()))?;
        let field = |key: &str| {
            meta.get(key)
                .cloned()
                .ok_or_else(|| format(format!("metadata has no `{key}`")))
        };
        fn json<T: serde::de::DeserializeOwned>(key: &str, text: &str) -> Result<T, String> {
            serde_json::from_str(text).map_err(|e| format!("metadata `{key}`: {e}"))
        }
        let ops: Vec<Op> = json("graph", &field("graph")?).map_err(format)?;
        let input_shape: Vec<usize> =
            json("input_shape", &field("input_shape")?).map_err(format)?;
        if input_shape.len() < 2 {
            return Err(format(format!("input_shape {input_shape:?} has no size")));
        }
        let outputs: Vec<String> = json("outputs", &field("outputs")?).map_err(format)?;
        let candle = |source| GraphError::Candle {
            name: name.to_string(),
            cause: source,
        };
        let mut constants = BTreeMap::new();
        for (key, t) in
            candle_core::safetensors::load_buffer(bytes, &Device::Cpu).map_err(candle)?
        {
            constants.insert(key, t.to_dtype(DType::F32).map_err(candle)?);
        }
        Ok(Graph {
            name: name.to_string(),
            ops,
            constants,
            input: field("input")?,
            input_shape,
            outputs,
        })
    }

    /// Runs the network on an NCHW input; returns the graph's outputs in order, each in
    /// TFLite's own shape (NHWC for rank 4).
    pub fn forward(&self, input: &Tensor) -> Result<Vec<Tensor>, GraphError> {
        let mut values: BTreeMap<&str, Tensor> = BTreeMap::new();
        values.insert(&self.input, input.clone());
        for op in &self.ops {
            let out = self
                .apply(op, &values)
                .map_err(|source| GraphError::Candle {
                    name: format!("{} operator `{}`", self.name, op.output),
                    cause: source,
                })?;
            let got = nhwc_dims(&out);
            if got != op.output_shape {
                return Err(GraphError::Format {
                    name: self.name.clone(),
                    message: format!(
                        "operator `{}` gave shape {got:?}, the file says {:?}",
                        op.output, op.output_shape
                    ),
                });
            }
            values.insert(&op.output, out);
        }
        self.outputs
            .iter()
            .map(|name| {
                let t = values
                    .get(name.as_str())
                    .ok_or_else(|| GraphError::Format {
                        name: self.name.clone(),
                        message: format!("output `{name}` is never computed"),
                    })?;
                if t.rank() == 4 {
                    t.permute((0, 2, 3, 1))
                        .map_err(|source| GraphError::Candle {
                            name: self.name.clone(),
                            cause: source,
                        })
                } else {
                    Ok(t.clone())
                }
            })
            .collect()
    }

    fn tensor<'a>(
        &'a self,
        values: &'a BTreeMap<&str, Tensor>,
        name: &str,
    ) -> candle_core::Result<&'a Tensor> {
        values
            .get(name)
            .or_else(|| self.constants.get(name))
            .ok_or_else(|| candle_core::Error::Msg(format!("unknown tensor `{name}`")))
    }

    fn apply(&self, op: &Op, values: &BTreeMap<&str, Tensor>) -> candle_core::Result<Tensor> {
        let arg = |i: usize| self.tensor(values, &op.inputs[i]);
        match &op.kind {
            Kind::Conv2d {
                stride,
                padding,
                activation,
            } => {
                let (x, w) = (arg(0)?, arg(1)?);
                activate(conv(x, w, arg(2)?, *padding, *stride)?, *activation)
            }
            Kind::DepthwiseConv2d {
                stride,
                padding,
                activation,
            } => {
                let (x, w) = (arg(0)?, arg(1)?);
                activate(depthwise(x, w, arg(2)?, *padding, *stride)?, *activation)
            }
            Kind::MaxPool2d {
                stride,
                filter,
                padding,
                activation,
            } => {
                if *padding == Padding::Same && !divides(arg(0)?, *filter, *stride)? {
                    candle_core::bail!("SAME max pooling that needs padding is not supported");
                }
                let y = arg(0)?
                    .max_pool2d_with_stride((filter[0], filter[1]), (stride[0], stride[1]))?;
                activate(y, *activation)
            }
            Kind::Add { activation } => activate(arg(0)?.broadcast_add(arg(1)?)?, *activation),
            Kind::Concat { axis, activation } => {
                let parts = (0..op.inputs.len())
                    .map(arg)
                    .collect::<candle_core::Result<Vec<_>>>()?;
                let rank = parts[0].rank();
                let axis = if *axis < 0 { rank as i64 + axis } else { *axis } as usize;
                activate(Tensor::cat(&parts, nchw_axis(rank, axis))?, *activation)
            }
            Kind::Pad { paddings } => {
                let mut x = arg(0)?.clone();
                let rank = x.rank();
                for (axis, [before, after]) in paddings.iter().enumerate() {
                    if before + after > 0 {
                        x = x.pad_with_zeros(nchw_axis(rank, axis), *before, *after)?;
                    }
                }
                Ok(x)
            }
            Kind::Reshape => {
                let x = arg(0)?;
                let x = if x.rank() == 4 {
                    x.permute((0, 2, 3, 1))?.contiguous()?
                } else {
                    x.clone()
                };
                let y = x.reshape(op.output_shape.clone())?;
                if y.rank() == 4 {
                    y.permute((0, 3, 1, 2))?.contiguous()
                } else {
                    Ok(y)
                }
            }
            Kind::Relu => arg(0)?.relu(),
            Kind::Prelu => prelu(arg(0)?, arg(1)?),
            Kind::Logistic => (arg(0)?.neg()?.exp()? + 1.0)?.recip(),
            Kind::Neg => arg(0)?.neg(),
            Kind::Sqrt => arg(0)?.sqrt(),
            Kind::Rsqrt => arg(0)?.sqrt()?.recip(),
            Kind::Sub { activation } => {
                let (a, b) = aligned(arg(0)?, arg(1)?)?;
                activate(a.broadcast_sub(&b)?, *activation)
            }
            Kind::Mul { activation } => {
                let (a, b) = aligned(arg(0)?, arg(1)?)?;
                activate(a.broadcast_mul(&b)?, *activation)
            }
            Kind::Div { activation } => {
                let (a, b) = aligned(arg(0)?, arg(1)?)?;
                activate(a.broadcast_div(&b)?, *activation)
            }
            Kind::SquaredDifference { activation } => {
                let (a, b) = aligned(arg(0)?, arg(1)?)?;
                activate(a.broadcast_sub(&b)?.sqr()?, *activation)
            }
            Kind::Mean { axes, keep_dims } => in_tflite_layout(arg(0)?, |x| {
                let y = x.mean_keepdim(axes.as_slice())?;
                squeezed(y, axes, *keep_dims)
            }),
            Kind::Sum { axes, keep_dims } => in_tflite_layout(arg(0)?, |x| {
                let y = x.sum_keepdim(axes.as_slice())?;
                squeezed(y, axes, *keep_dims)
            }),
            Kind::Transpose { perm } => {
                in_tflite_layout(arg(0)?, |x| x.permute(perm.as_slice())?.contiguous())
            }
            Kind::StridedSlice { ranges, squeeze } => in_tflite_layout(arg(0)?, |x| {
                let mut y = x.clone();
                for (axis, &[start, stop, step]) in ranges.iter().enumerate() {
                    let len = stop.saturating_sub(start);
                    if step == 1 {
                        y = y.narrow(axis, start, len)?;
                    } else {
                        let picks: Vec<u32> =
                            (start..stop).step_by(step).map(|i| i as u32).collect();
                        let n = picks.len();
                        y = y.index_select(&Tensor::from_vec(picks, n, y.device())?, axis)?;
                    }
                }
                squeezed(y.contiguous()?, squeeze, false)
            }),
        }
    }
}

/// Runs `f` on the tensor in TFLite's layout (NHWC for rank 4) and brings a rank-4 result
/// back to NCHW: for operators whose axes or shapes are TFLite's.
fn in_tflite_layout(
    x: &Tensor,
    f: impl FnOnce(&Tensor) -> candle_core::Result<Tensor>,
) -> candle_core::Result<Tensor> {
    let x = if x.rank() == 4 {
        x.permute((0, 2, 3, 1))?.contiguous()?
    } else {
        x.clone()
    };
    let y = f(&x)?;
    if y.rank() == 4 {
        y.permute((0, 3, 1, 2))?.contiguous()
    } else {
        Ok(y)
    }
}

/// `y` with the (kept, size-1) `axes` removed unless `keep_dims`.
fn squeezed(y: Tensor, axes: &[usize], keep_dims: bool) -> candle_core::Result<Tensor> {
    if keep_dims {
        return Ok(y);
    }
    let mut y = y;
    let mut axes = axes.to_vec();
    axes.sort_unstable();
    for &a in axes.iter().rev() {
        y = y.squeeze(a)?;
    }
    Ok(y)
}

/// Two operands of an element-wise operator made ready for NCHW broadcasting: TFLite
/// broadcasts trailing NHWC axes, so a lower-rank operand beside a rank-4 one (a per-channel
/// scale of shape `[C]`, a scalar) is padded to NHWC rank 4 and turned to NCHW.
fn aligned(a: &Tensor, b: &Tensor) -> candle_core::Result<(Tensor, Tensor)> {
    let lift = |t: &Tensor| -> candle_core::Result<Tensor> {
        let mut dims = vec![1usize; 4 - t.rank()];
        dims.extend_from_slice(t.dims());
        t.reshape(dims)?.permute((0, 3, 1, 2))
    };
    match (a.rank(), b.rank()) {
        (4, r) if r < 4 => Ok((a.clone(), lift(b)?)),
        (r, 4) if r < 4 => Ok((lift(a)?, b.clone())),
        _ => Ok((a.clone(), b.clone())),
    }
}

/// The NCHW axis of a TFLite (NHWC) axis for rank-4 tensors; other ranks are unchanged.
fn nchw_axis(rank: usize, axis: usize) -> usize {
    if rank == 4 {
        [0, 2, 3, 1][axis]
    } else {
        axis
    }
}

fn nhwc_dims(t: &Tensor) -> Vec<usize> {
    let d = t.dims();
    if d.len() == 4 {
        vec![d[0], d[2], d[3], d[1]]
    } else {
        d.to_vec()
    }
}

fn divides(x: &Tensor, filter: [usize; 2], stride: [usize; 2]) -> candle_core::Result<bool> {
    let (h, w) = (x.dim(2)?, x.dim(3)?);
    Ok(filter == stride && h % stride[0] == 0 && w % stride[1] == 0)
}

/// The input padded with zeros by TFLite's rule ([`implicit_padding`]).
fn pad_for(
    x: &Tensor,
    padding: Padding,
    kernel: [usize; 2],
    stride: [usize; 2],
) -> candle_core::Result<Tensor> {
    let (pads, _) = implicit_padding([x.dim(2)?, x.dim(3)?], padding, kernel, stride);
    let mut x = x.clone();
    for (axis, [before, after]) in [(2, pads[0]), (3, pads[1])] {
        if before + after > 0 {
            x = x.pad_with_zeros(axis, before, after)?;
        }
    }
    Ok(x)
}

/// The input padded for a `kernel` at `stride` (TFLite's rule, `pad_for`), its NCHW dims, and
/// the output's height and width (0 where the kernel does not fit; callers check `hp >= kh`).
fn padded(
    x: &Tensor,
    padding: Padding,
    kernel: [usize; 2],
    stride: [usize; 2],
) -> candle_core::Result<(Tensor, [usize; 4], [usize; 2])> {
    let xp = pad_for(x, padding, kernel, stride)?;
    let (n, c, hp, wp) = xp.dims4()?;
    let out = |size: usize, k: usize, s: usize| size.checked_sub(k).map_or(0, |d| d / s + 1);
    let (oh, ow) = (out(hp, kernel[0], stride[0]), out(wp, kernel[1], stride[1]));
    Ok((xp, [n, c, hp, wp], [oh, ow]))
}

/// A full convolution plus its bias as one matrix product, `W (out x in k k) . columns (in k k
/// x pixels)`, giving NCHW directly; a 1x1 convolution at stride 1 multiplies the input
/// itself. candle's `conv2d` costs several times more here (4 ms for the mesh's first,
/// strided layer of 3 input channels).
fn conv(
    x: &Tensor,
    w: &Tensor,
    bias: &Tensor,
    padding: Padding,
    stride: [usize; 2],
) -> candle_core::Result<Tensor> {
    let (co, ci, kh, kw) = w.dims4()?;
    let (xp, [n, c, hp, wp], [oh, ow]) = padded(x, padding, [kh, kw], stride)?;
    if n != 1 || c != ci || bias.elem_count() != co || hp < kh || wp < kw {
        candle_core::bail!(
            "kernel {:?} and bias of {} do not fit an input of shape {:?}",
            w.dims(),
            bias.elem_count(),
            xp.dims()
        );
    }
    let columns = if kh * kw == 1 && stride == [1, 1] {
        xp.reshape((ci, oh * ow))?
    } else {
        let xs = values(&xp)?;
        let mut cols: Vec<f32> = Vec::with_capacity(ci * kh * kw * oh * ow);
        for plane in xs.chunks_exact(hp * wp) {
            for i in 0..kh {
                for j in 0..kw {
                    for oy in 0..oh {
                        let row = &plane[(oy * stride[0] + i) * wp + j..];
                        cols.extend(row.iter().step_by(stride[1]).take(ow));
                    }
                }
            }
        }
        Tensor::from_vec(cols, (ci * kh * kw, oh * ow), x.device())?
    };
    let y = w.reshape((co, ci * kh * kw))?.matmul(&columns)?;
    y.broadcast_add(&bias.reshape(((), 1))?)?
        .reshape((1, co, oh, ow))
}

/// A depthwise convolution (one filter per channel) plus its bias, by direct loops over the
/// input with TFLite's padding applied implicitly (taps that fall outside add nothing).
/// Broadcast products of shifted views, or candle's grouped `conv2d` (one convolution per
/// channel), cost several times more on these thin, wide layers, and padding the input first
/// costs two copies of it.
fn depthwise(
    x: &Tensor,
    w: &Tensor,
    bias: &Tensor,
    padding: Padding,
    stride: [usize; 2],
) -> candle_core::Result<Tensor> {
    let (kh, kw) = (w.dim(2)?, w.dim(3)?);
    let (n, c, h, wd) = x.dims4()?;
    let (pads, [oh, ow]) = implicit_padding([h, wd], padding, [kh, kw], stride);
    let pad = [pads[0][0], pads[1][0]];
    if w.dims() != [c, 1, kh, kw] || bias.elem_count() != c || oh == 0 || ow == 0 {
        candle_core::bail!(
            "depthwise kernel {:?} and bias of {} do not fit an input of {c} channels, {h}x{wd}",
            w.dims(),
            bias.elem_count()
        );
    }
    let (ws, bs) = (values(w)?, values(bias)?);
    // Tap by tap in row order, then the bias: each output's sum in the order of the
    // broadcast formulation (-0.0 is the exact identity of f32 addition). The taps are the
    // outer loop so that the inner one runs along an output row, which the compiler
    // vectorizes at stride 1.
    let mut out = vec![-0.0f32; n * c * oh * ow];
    with_slice(x, |xs| {
        for ((plane, o), ch) in xs
            .chunks_exact(h * wd)
            .zip(out.chunks_exact_mut(oh * ow))
            .zip((0..c).cycle())
        {
            let taps = &ws[ch * kh * kw..(ch + 1) * kh * kw];
            for (t, &tap) in taps.iter().enumerate() {
                let (i, j) = (t / kw, t % kw);
                // Output columns whose input column `ox * s + j - pad_left` is inside.
                let first = pad[1].saturating_sub(j).div_ceil(stride[1]);
                let last = ((wd + pad[1]).saturating_sub(j))
                    .div_ceil(stride[1])
                    .min(ow);
                if first >= last {
                    continue;
                }
                for (oy, o_row) in o.chunks_exact_mut(ow).enumerate() {
                    let Some(iy) = (oy * stride[0] + i).checked_sub(pad[0]) else {
                        continue;
                    };
                    if iy >= h {
                        continue;
                    }
                    let row = &plane[iy * wd..(iy + 1) * wd];
                    let x0 = first * stride[1] + j - pad[1];
                    if stride[1] == 1 {
                        for (acc, a) in o_row[first..last].iter_mut().zip(&row[x0..]) {
                            *acc += a * tap;
                        }
                    } else {
                        for (acc, a) in o_row[first..last]
                            .iter_mut()
                            .zip(row[x0..].iter().step_by(stride[1]))
                        {
                            *acc += a * tap;
                        }
                    }
                }
            }
            let b = bs[ch];
            for acc in o.iter_mut() {
                *acc += b;
            }
        }
    })?;
    Tensor::from_vec(out, (n, c, oh, ow), x.device())
}

/// TFLite's padding of an input of `size` (height, width): per axis the padding before and
/// after, and the output's height and width. SAME pads `max((out - 1) s + k - in, 0)` with
/// the odd pixel after; VALID pads nothing (output 0 where the kernel does not fit).
fn implicit_padding(
    size: [usize; 2],
    padding: Padding,
    kernel: [usize; 2],
    stride: [usize; 2],
) -> ([[usize; 2]; 2], [usize; 2]) {
    let mut pad = [[0; 2]; 2];
    let mut out = [0; 2];
    for a in 0..2 {
        let (n, k, s) = (size[a], kernel[a], stride[a]);
        match padding {
            Padding::Same => {
                out[a] = n.div_ceil(s);
                let total = ((out[a] - 1) * s + k).saturating_sub(n);
                pad[a] = [total / 2, total - total / 2];
            }
            Padding::Valid => out[a] = n.checked_sub(k).map_or(0, |d| d / s + 1),
        }
    }
    (pad, out)
}

/// Runs `f` on a tensor's f32 values in row-major order, borrowed from its storage where it
/// is contiguous on the CPU (copied otherwise).
fn with_slice<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    {
        let (storage, layout) = t.storage_and_layout();
        if let (candle_core::Storage::Cpu(cpu), Some((start, end))) =
            (&*storage, layout.contiguous_offsets())
        {
            let data = cpu.as_slice::<f32>()?;
            return Ok(f(&data[start..end]));
        }
    }
    Ok(f(&values(t)?))
}

/// PReLU with one slope per channel, in one pass: `x` where `x >= 0`, else `alpha x`; the
/// values of `relu(x) - alpha relu(-x)` bit for bit.
fn prelu(x: &Tensor, alpha: &Tensor) -> candle_core::Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    let alpha = values(alpha)?;
    if alpha.len() != c {
        candle_core::bail!("PReLU has {} slopes for {c} channels", alpha.len());
    }
    let mut out = Vec::with_capacity(n * c * h * w);
    with_slice(x, |xs| {
        for (plane, &a) in xs.chunks_exact(h * w).zip(alpha.iter().cycle()) {
            out.extend(plane.iter().map(|&v| v * if v < 0.0 { a } else { 1.0 }));
        }
    })?;
    Tensor::from_vec(out, (n, c, h, w), x.device())
}

fn activate(y: Tensor, activation: Activation) -> candle_core::Result<Tensor> {
    match activation {
        Activation::None => Ok(y),
        Activation::Relu => y.relu(),
        Activation::Relu6 => y.clamp(0f32, 6f32),
    }
}

/// A tensor's values, flattened, as f32.
pub fn values(t: &Tensor) -> candle_core::Result<Vec<f32>> {
    t.flatten_all()?.to_vec1::<f32>()
}
