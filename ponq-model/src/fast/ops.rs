//! The fast CPU kernels as Burn operations: a backend extension ([`PonqCpuOps`]) implemented
//! for the `flex` CPU backend (forward only) and for `Autodiff<Flex>` (forward, and a
//! hand-written backward registered in the autodiff graph), plus the `Tensor` wrappers the
//! network calls ([`conv3d`], [`decoders()`]).
//!
//! The tensors are channels-last: a grid batch is `[B, D1, D2, D3, C]`, a row block
//! `[rows, C]`. Weights and biases are the `Conv3d` parameters as they are (`[Cout, Cin, k, k,
//! k]`, `[Cout]`), so their gradients land on the same parameters as the stock layers'.

use std::borrow::Cow;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Dispatch, Flex, backend_extension};
use burn::nn::conv::Conv3d;
use burn::prelude::*;
use burn::tensor::DType;

use super::decoders::{self, DecoderShape};
use super::kernels::{self, Act, ConvShape, Precision};
use super::winograd;

/// The fused layers of the PoNQ network on the CPU.
///
/// `act` selects LeakyReLU with negative slope `slope` after the bias; without
/// it the layer is affine. `bf16` runs the GEMMs (forward and backward) with bf16 inputs and
/// f32 sums ([`Precision::Bf16`]).
#[backend_extension(Flex, Autodiff)]
pub trait PonqCpuOps: burn::backend::Backend {
    /// `act(conv3d(x, w) + b)`, stride 1, zero padding `pad`: `x: [B, D1, D2, D3, Cin]`,
    /// `w: [Cout, Cin, k, k, k]`, `b: [Cout]` -> `[B, O1, O2, O3, Cout]`.
    fn conv3d_cl(
        x: FloatTensor<Self>,
        w: FloatTensor<Self>,
        b: FloatTensor<Self>,
        pad: usize,
        act: bool,
        slope: f32,
        bf16: bool,
    ) -> FloatTensor<Self>;

    /// The five decoders fused ([`mod@decoders`]): `x: [rows, W]`, `theta: [shape.params()]` ->
    /// `[rows, shape.total_outputs()]`.
    fn decoders_cl(
        x: FloatTensor<Self>,
        theta: FloatTensor<Self>,
        shape: DecoderShape,
        bf16: bool,
    ) -> FloatTensor<Self>;
}

fn precision(bf16: bool) -> Precision {
    if bf16 {
        Precision::Bf16
    } else {
        Precision::F32
    }
}

fn activation(act: bool, slope: f32) -> Act {
    if act {
        Act::Leaky(slope)
    } else {
        Act::Identity
    }
}

/// The values of an `f32` tensor in C order (borrowed when it is contiguous).
fn values(t: &FlexTensor) -> Cow<'_, [f32]> {
    assert_eq!(
        t.dtype(),
        DType::F32,
        "the fast CPU kernels take f32 tensors (got {:?}); use the stock layers for other types",
        t.dtype()
    );
    let n = t.layout().num_elements();
    if t.is_contiguous() {
        let off = t.layout().start_offset();
        Cow::Borrowed(&t.storage::<f32>()[off..off + n])
    } else {
        let c = t.to_contiguous();
        let off = c.layout().start_offset();
        Cow::Owned(c.storage::<f32>()[off..off + n].to_vec())
    }
}

fn dims(t: &FlexTensor) -> Vec<usize> {
    t.layout().shape().iter().copied().collect()
}

fn tensor(v: Vec<f32>, shape: Vec<usize>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(v, shape))
}

fn conv_shape(x: &FlexTensor, w: &FlexTensor, pad: usize) -> ConvShape {
    let xd = dims(x);
    let wd = dims(w);
    assert!(
        xd.len() == 5 && wd.len() == 5,
        "conv3d_cl: x {xd:?}, w {wd:?}"
    );
    assert!(
        wd[2] == wd[3] && wd[3] == wd[4] && wd[1] == xd[4],
        "conv3d_cl: x {xd:?}, w {wd:?}"
    );
    ConvShape {
        batch: xd[0],
        dims: [xd[1], xd[2], xd[3]],
        cin: xd[4],
        cout: wd[0],
        k: wd[2],
        pad,
    }
}

fn conv_forward(
    x: &FlexTensor,
    w: &FlexTensor,
    b: &FlexTensor,
    s: &ConvShape,
    act: Act,
    prec: Precision,
) -> FlexTensor {
    let y = if winograd::applies(s, prec) {
        winograd::conv_forward(&values(x), s, &values(w), Some(&values(b)), act)
    } else {
        let packed = kernels::pack_weight(&values(w), s, false);
        kernels::conv_forward(&values(x), s, &packed, Some(&values(b)), act, prec)
    };
    let o = s.out_dims();
    tensor(y, vec![s.batch, o[0], o[1], o[2], s.cout])
}

fn decoders_forward(
    x: &FlexTensor,
    theta: &FlexTensor,
    shape: &DecoderShape,
    prec: Precision,
) -> FlexTensor {
    let xd = dims(x);
    assert!(
        xd.len() == 2 && xd[1] == shape.width && dims(theta) == [shape.params()],
        "decoders_cl: x {xd:?}, theta {:?}, {shape:?}",
        dims(theta)
    );
    let y = decoders::forward(&values(x), shape, &values(theta), prec);
    tensor(y, vec![xd[0], shape.total_outputs()])
}

impl PonqCpuOps for Flex {
    fn decoders_cl(
        x: FlexTensor,
        theta: FlexTensor,
        shape: DecoderShape,
        bf16: bool,
    ) -> FlexTensor {
        decoders_forward(&x, &theta, &shape, precision(bf16))
    }

    fn conv3d_cl(
        x: FlexTensor,
        w: FlexTensor,
        b: FlexTensor,
        pad: usize,
        act: bool,
        slope: f32,
        bf16: bool,
    ) -> FlexTensor {
        let s = conv_shape(&x, &w, pad);
        conv_forward(&x, &w, &b, &s, activation(act, slope), precision(bf16))
    }
}

/// Backward of [`PonqCpuOps::conv3d_cl`]; parents `[x, w, b]`.
#[derive(Debug)]
struct ConvBackward;

impl Backward<Flex, 3> for ConvBackward {
    /// `(x, w, y, shape, activation, precision)`.
    type State = (
        FlexTensor,
        FlexTensor,
        FlexTensor,
        ConvShape,
        Act,
        Precision,
    );

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_w, node_b] = ops.parents;
        let gy = grads.consume::<Flex>(&ops.node);
        let (x, w, y, s, act, prec) = ops.state;
        let gz = kernels::activation_grad(&values(&y), &values(&gy), act);
        if let Some(node) = node_b {
            grads.register::<Flex>(
                node.id,
                tensor(kernels::column_sums(&gz, s.cout), vec![s.cout]),
            );
        }
        if let Some(node) = node_w {
            let gw = if winograd::applies(&s, prec) {
                winograd::conv_weight_grad(&values(&x), &s, &gz)
            } else {
                kernels::conv_weight_grad(&values(&x), &s, &gz, prec)
            };
            grads.register::<Flex>(node.id, tensor(gw, dims(&w)));
        }
        if let Some(node) = node_x {
            let gx = if winograd::applies(&s, prec) {
                winograd::conv_input_grad(&s, &values(&w), &gz)
            } else {
                kernels::conv_input_grad(&s, &values(&w), &gz, prec)
            };
            grads.register::<Flex>(node.id, tensor(gx, dims(&x)));
        }
    }
}

/// Backward of [`PonqCpuOps::decoders_cl`]; parents `[x, theta]`.
#[derive(Debug)]
struct DecodersBackward;

impl Backward<Flex, 2> for DecodersBackward {
    /// `(x, theta, shape, precision)`.
    type State = (FlexTensor, FlexTensor, DecoderShape, Precision);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_theta] = ops.parents;
        let gy = grads.consume::<Flex>(&ops.node);
        let (x, theta, shape, prec) = ops.state;
        let g = decoders::backward(
            &values(&x),
            &shape,
            &values(&theta),
            &values(&gy),
            node_x.is_some(),
            node_theta.is_some(),
            prec,
        );
        register(grads, node_x.map(|n| n.id), g.x, dims(&x));
        register(grads, node_theta.map(|n| n.id), g.theta, dims(&theta));
    }
}

fn register(
    grads: &mut Gradients,
    id: Option<burn::backend::autodiff::NodeId>,
    g: Option<Vec<f32>>,
    shape: Vec<usize>,
) {
    if let (Some(id), Some(g)) = (id, g) {
        grads.register::<Flex>(id, tensor(g, shape));
    }
}

impl<C: CheckpointStrategy> PonqCpuOps for Autodiff<Flex, C> {
    fn decoders_cl(
        x: FloatTensor<Self>,
        theta: FloatTensor<Self>,
        shape: DecoderShape,
        bf16: bool,
    ) -> FloatTensor<Self> {
        let prec = precision(bf16);
        match DecodersBackward
            .prepare::<C>([x.node(), theta.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (xp, tp) = (x.primitive().clone(), theta.primitive().clone());
                let y = decoders_forward(&xp, &tp, &shape, prec);
                prep.finish((xp, tp, shape, prec), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(decoders_forward(
                x.primitive(),
                theta.primitive(),
                &shape,
                prec,
            )),
        }
    }

    fn conv3d_cl(
        x: FloatTensor<Self>,
        w: FloatTensor<Self>,
        b: FloatTensor<Self>,
        pad: usize,
        act: bool,
        slope: f32,
        bf16: bool,
    ) -> FloatTensor<Self> {
        let act = activation(act, slope);
        let prec = precision(bf16);
        let s = conv_shape(x.primitive(), w.primitive(), pad);
        match ConvBackward
            .prepare::<C>([x.node(), w.node(), b.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (xp, wp) = (x.primitive().clone(), w.primitive().clone());
                let y = conv_forward(&xp, &wp, b.primitive(), &s, act, prec);
                prep.finish((xp, wp, y.clone(), s, act, prec), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(conv_forward(
                x.primitive(),
                w.primitive(),
                b.primitive(),
                &s,
                act,
                prec,
            )),
        }
    }
}

/// Weight and bias of a `Conv3d` (a zero bias when it has none).
fn params(conv: &Conv3d) -> (Tensor<5>, Tensor<1>) {
    let w = conv.weight.val();
    let b = match &conv.bias {
        Some(b) => b.val(),
        None => Tensor::<1>::zeros([w.dims()[0]], &w.device()),
    };
    (w, b)
}

/// `conv`'s weights on a channels-last grid batch `[B, D1, D2, D3, Cin]`, stride 1, zero
/// padding `pad`, then LeakyReLU with slope `leaky` when given; GEMMs in `prec`.
pub fn conv3d(
    x: Tensor<5>,
    conv: &Conv3d,
    pad: usize,
    leaky: Option<f32>,
    prec: Precision,
) -> Tensor<5> {
    let (w, b) = params(conv);
    Tensor::from_dispatch(<Dispatch as PonqCpuOps>::conv3d_cl(
        x.into_dispatch(),
        w.into_dispatch(),
        b.into_dispatch(),
        pad,
        leaky.is_some(),
        leaky.unwrap_or(0.0),
        prec == Precision::Bf16,
    ))
}

/// The five decoders fused ([`mod@decoders`]) on feature rows `[rows, W]` with the flat
/// parameters `theta` (layout in [`DecoderShape`]): `[rows, T]`; GEMMs in `prec`.
pub fn decoders(x: Tensor<2>, theta: Tensor<1>, shape: DecoderShape, prec: Precision) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as PonqCpuOps>::decoders_cl(
        x.into_dispatch(),
        theta.into_dispatch(),
        shape,
        prec == Precision::Bf16,
    ))
}

/// `theta` for [`decoders()`]: the decoders' parameters flattened in [`DecoderShape`]'s order
/// (the concatenation carries the gradient back to each layer's parameters).
pub fn decoder_params(layers: &[&Conv3d]) -> Tensor<1> {
    let parts: Vec<Tensor<1>> = layers
        .iter()
        .flat_map(|c| {
            let (w, b) = params(c);
            let n: usize = w.dims().iter().product();
            [w.reshape([n]), b]
        })
        .collect();
    Tensor::cat(parts, 0)
}
