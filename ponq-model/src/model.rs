//! The PoNQ network (SPEC section 3): a 3D CNN encoder over the SDF grid and five
//! per-cell decoders (points, normals, Cholesky factors, v* offsets, occupancy).
//!
//! Built from a [`PonqNetConfig`]; the default config is the paper's network
//! (2,716,861 parameters). A narrow CPU variant is the same code with a smaller `width`.

use burn::nn::PaddingConfig3d;
use burn::nn::conv::{Conv3d, Conv3dConfig};
use burn::prelude::*;
use burn::tensor::activation::{leaky_relu, sigmoid};

use crate::fast::{self, Kernels};

pub use crate::activation::LEAKY_SLOPE;

/// Hyper-parameters of [`PonqNet`].
#[derive(Config, Debug, PartialEq)]
pub struct PonqNetConfig {
    /// Feature channels of the encoder and decoders (paper: 128).
    #[config(default = 128)]
    pub width: usize,
    /// Points per cell `P` (paper: 4).
    #[config(default = 4)]
    pub points_per_cell: usize,
    /// Kernel-3 convolutions after the kernel-2 input convolution (paper: 5). The receptive
    /// field of a cell is `2 + 2 * encoder_layers` nodes per side.
    #[config(default = 5)]
    pub encoder_layers: usize,
    /// Residual blocks per decoder (paper: 3).
    #[config(default = 3)]
    pub decoder_blocks: usize,
}

/// A residual block of two 1x1x1 convolutions: `lrelu(x + conv_2(lrelu(conv_1(x))))`.
#[derive(Module, Debug)]
pub struct ResBlock {
    conv_1: Conv3d,
    conv_2: Conv3d,
}

impl ResBlock {
    fn new(width: usize, device: &Device) -> Self {
        let c = || Conv3dConfig::new([width, width], [1, 1, 1]).init(device);
        Self {
            conv_1: c(),
            conv_2: c(),
        }
    }

    fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let y = leaky_relu(self.conv_1.forward(x.clone()), LEAKY_SLOPE);
        leaky_relu(self.conv_2.forward(y) + x, LEAKY_SLOPE)
    }
}

/// One decoder: residual blocks then a 1x1x1 head with `outputs` channels.
#[derive(Module, Debug)]
pub struct Decoder {
    blocks: Vec<ResBlock>,
    head: Conv3d,
}

impl Decoder {
    fn new(width: usize, blocks: usize, outputs: usize, device: &Device) -> Self {
        Self {
            blocks: (0..blocks).map(|_| ResBlock::new(width, device)).collect(),
            head: Conv3dConfig::new([width, outputs], [1, 1, 1]).init(device),
        }
    }

    /// `[B, W, n, n, n]` features -> `[B, n^3, outputs / dim, dim]` (channel `c` is point
    /// `c / dim`, component `c % dim`).
    fn forward(&self, features: Tensor<5>, dim: usize) -> Tensor<4> {
        let mut x = features;
        for b in &self.blocks {
            x = b.forward(x);
        }
        let y = self.head.forward(x);
        let [batch, channels, d1, d2, d3] = y.dims();
        y.reshape([batch, channels, d1 * d2 * d3])
            .swap_dims(1, 2)
            .reshape([batch, d1 * d2 * d3, channels / dim, dim])
    }

    /// Its layers in the order of [`fast::decoders::DecoderShape`]'s flat parameters.
    fn layers(&self) -> Vec<&Conv3d> {
        let mut l: Vec<&Conv3d> = self
            .blocks
            .iter()
            .flat_map(|b| [&b.conv_1, &b.conv_2])
            .collect();
        l.push(&self.head);
        l
    }
}

/// Where the cells of an input grid lie, so that the point offsets can be made absolute.
///
/// Invariant: `cell > 0`, `offset_scale > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridFrame {
    /// Position of node `(0,0,0)` of the input grid.
    pub origin: [f64; 3],
    /// Cell size (node spacing); `2 / N` for the whole `[-1,1]^3` grid of `N` cells.
    pub cell: f64,
    /// Head outputs are multiplied by this to give offsets: `1 / (N + 1)` as in the authors'
    /// code, where `N` is the resolution of the whole grid (not of a crop).
    pub offset_scale: f64,
    /// Use the authors' slightly shifted cell bases `(2i/(N-1) - 1) * N/(N+1)` instead of the
    /// true cell centres (only for the authors' pretrained weights, whole grids only).
    pub authors_cell_base: bool,
}

impl GridFrame {
    /// The whole `[-1,1]^3` grid of `n` cells per side.
    pub fn whole(n: usize) -> Self {
        Self {
            origin: [-1.0; 3],
            cell: 2.0 / n as f64,
            offset_scale: 1.0 / (n as f64 + 1.0),
            authors_cell_base: false,
        }
    }

    /// A crop of the `[-1,1]^3` grid of `n` cells starting at node `start`.
    pub fn crop(n: usize, start: [usize; 3]) -> Self {
        let cell = 2.0 / n as f64;
        Self {
            origin: start.map(|s| -1.0 + s as f64 * cell),
            cell,
            offset_scale: 1.0 / (n as f64 + 1.0),
            authors_cell_base: false,
        }
    }

    /// Base position of cell `i` along `axis` of a grid with `cells` cells.
    pub fn cell_base(&self, axis: usize, i: usize, cells: usize) -> f64 {
        if self.authors_cell_base {
            let n = cells as f64;
            if cells < 2 {
                return 0.0;
            }
            (2.0 * i as f64 / (n - 1.0) - 1.0) * n / (n + 1.0)
        } else {
            self.origin[axis] + (i as f64 + 0.5) * self.cell
        }
    }

    /// `[cells^3 * 3]` cell bases in C order.
    pub fn cell_bases(&self, cells: [usize; 3]) -> Vec<f32> {
        let mut out = Vec::with_capacity(cells.iter().product::<usize>() * 3);
        for i in 0..cells[0] {
            for j in 0..cells[1] {
                for k in 0..cells[2] {
                    out.push(self.cell_base(0, i, cells[0]) as f32);
                    out.push(self.cell_base(1, j, cells[1]) as f32);
                    out.push(self.cell_base(2, k, cells[2]) as f32);
                }
            }
        }
        out
    }
}

/// Network output for a batch of `B` grids of `C = n1 n2 n3` cells and `P` points per cell.
#[derive(Debug, Clone)]
pub struct PonqOutput {
    /// `[B, C, P, 3]` absolute point positions.
    pub points: Tensor<4>,
    /// `[B, C, P, 3]` absolute v* (offset added to the detached points).
    pub vstars: Tensor<4>,
    /// `[B, C, P, 3]` raw (unnormalised) normals.
    pub normals: Tensor<4>,
    /// `[B, C, P, 6]` upper-triangular entries of `U` ((0,0),(0,1),(0,2),(1,1),(1,2),(2,2));
    /// `A = U U^T`.
    pub cholesky: Tensor<4>,
    /// `[B, C]` occupancy probability (sigmoid).
    pub occupancy: Tensor<2>,
    /// Cells per axis.
    pub cells: [usize; 3],
}

/// The PoNQ network.
#[derive(Module, Debug)]
pub struct PonqNet {
    input: Conv3d,
    encoder: Vec<Conv3d>,
    decoder_points: Decoder,
    decoder_normals: Decoder,
    decoder_cholesky: Decoder,
    decoder_vstars: Decoder,
    decoder_occupancy: Decoder,
    #[module(skip)]
    points_per_cell: usize,
    #[module(skip)]
    kernels: Kernels,
}

impl PonqNetConfig {
    /// Builds the network with freshly initialised weights on `device`.
    pub fn init(&self, device: &Device) -> PonqNet {
        let w = self.width;
        let p = self.points_per_cell;
        let dec = |outputs| Decoder::new(w, self.decoder_blocks, outputs, device);
        PonqNet {
            input: Conv3dConfig::new([1, w], [2, 2, 2]).init(device),
            encoder: (0..self.encoder_layers)
                .map(|_| {
                    Conv3dConfig::new([w, w], [3, 3, 3])
                        .with_padding(PaddingConfig3d::Explicit(1, 1, 1))
                        .init(device)
                })
                .collect(),
            decoder_points: dec(3 * p),
            decoder_normals: dec(3 * p),
            decoder_cholesky: dec(6 * p),
            decoder_vstars: dec(3 * p),
            decoder_occupancy: dec(1),
            points_per_cell: p,
            kernels: Kernels::default(),
        }
    }
}

impl PonqNet {
    /// Points per cell `P`.
    pub fn points_per_cell(&self) -> usize {
        self.points_per_cell
    }

    /// The device the weights are on.
    pub(crate) fn device(&self) -> Device {
        self.input.weight.device()
    }

    fn decoders_ref(&self) -> [&Decoder; 5] {
        [
            &self.decoder_points,
            &self.decoder_normals,
            &self.decoder_cholesky,
            &self.decoder_vstars,
            &self.decoder_occupancy,
        ]
    }

    /// Every convolution in a fixed order (input layer, encoder, each decoder's blocks and
    /// head), with whether its input and its output channels are the hidden width (the
    /// input layer reads the SDF, the heads write the outputs).
    pub(crate) fn convs(&self) -> Vec<(&Conv3d, [bool; 2])> {
        let mut v = vec![(&self.input, [false, true])];
        v.extend(self.encoder.iter().map(|c| (c, [true, true])));
        for d in self.decoders_ref() {
            let layers = d.layers();
            let n = layers.len();
            v.extend(
                layers
                    .into_iter()
                    .enumerate()
                    .map(|(i, c)| (c, [true, i + 1 < n])),
            );
        }
        v
    }

    /// The convolutions of [`PonqNet::convs`], mutable, in the same order.
    pub(crate) fn convs_mut(&mut self) -> Vec<&mut Conv3d> {
        let mut v = vec![&mut self.input];
        v.extend(self.encoder.iter_mut());
        for d in [
            &mut self.decoder_points,
            &mut self.decoder_normals,
            &mut self.decoder_cholesky,
            &mut self.decoder_vstars,
            &mut self.decoder_occupancy,
        ] {
            for b in d.blocks.iter_mut() {
                v.push(&mut b.conv_1);
                v.push(&mut b.conv_2);
            }
            v.push(&mut d.head);
        }
        v
    }

    /// The layer implementation this network runs on the CPU (default [`Kernels::Fast`]).
    pub fn kernels(&self) -> Kernels {
        self.kernels
    }

    /// Selects the layer implementation on the CPU; the weights are the same for both.
    pub fn with_kernels(mut self, kernels: Kernels) -> Self {
        self.kernels = kernels;
        self
    }

    /// Whether a forward on `device` takes the fast CPU kernels.
    pub fn uses_fast_kernels(&self, device: &Device) -> bool {
        self.kernels.is_fast() && fast::supports(device)
    }

    /// Whether [`PonqNet::forward_cells`] on `device` runs the encoder at the listed cells'
    /// neighbourhoods only ([`fast::sparse`]): the fast kernels without autodiff.
    pub fn uses_sparse_encoder(&self, device: &Device) -> bool {
        self.uses_fast_kernels(device) && !device.is_autodiff()
    }

    /// Encoder features `[B, W, n1, n2, n3]` of input grids `[B, 1, n1+1, n2+1, n3+1]`.
    pub fn encode(&self, sdf: Tensor<5>) -> Tensor<5> {
        if self.uses_fast_kernels(&sdf.device()) {
            return self.encode_fast(sdf).permute([0, 4, 1, 2, 3]);
        }
        let mut x = leaky_relu(self.input.forward(sdf), LEAKY_SLOPE);
        for c in &self.encoder {
            x = leaky_relu(c.forward(x), LEAKY_SLOPE);
        }
        x
    }

    /// Channels-last encoder features `[B, n1, n2, n3, W]` with the fast kernels (the input
    /// has one channel, so `[B, 1, D1, D2, D3]` is already channels-last).
    fn encode_fast(&self, sdf: Tensor<5>) -> Tensor<5> {
        let [b, c, d1, d2, d3] = sdf.dims();
        debug_assert_eq!(c, 1);
        let s = Some(LEAKY_SLOPE as f32);
        let p = self.kernels.precision();
        // The input convolution is unpadded, the encoder's keep the size (see `init`).
        let mut x = fast::ops::conv3d(sdf.reshape([b, d1, d2, d3, c]), &self.input, 0, s, p);
        for conv in &self.encoder {
            x = fast::ops::conv3d(x, conv, 1, s, p);
        }
        x
    }

    /// The five decoders' outputs `(points, vstar offsets, normals, cholesky, occupancy
    /// logits)` as `[B, cells, P or 1, dim]`, and the cells per axis.
    fn decode(&self, sdf: Tensor<5>) -> ([Tensor<4>; 5], [usize; 3]) {
        if self.uses_fast_kernels(&sdf.device()) {
            let f = self.encode_fast(sdf);
            let [batch, n1, n2, n3, w] = f.dims();
            let rows = f.reshape([batch * n1 * n2 * n3, w]);
            return (self.decode_rows(rows, batch), [n1, n2, n3]);
        }
        let f = self.encode(sdf);
        let [_, _, n1, n2, n3] = f.dims();
        let d = |dec: &Decoder, dim| dec.forward(f.clone(), dim);
        (
            [
                d(&self.decoder_points, 3),
                d(&self.decoder_vstars, 3),
                d(&self.decoder_normals, 3),
                d(&self.decoder_cholesky, 6),
                d(&self.decoder_occupancy, 1),
            ],
            [n1, n2, n3],
        )
    }

    /// The five decoders on channels-last feature rows `[batch * cells, W]` (fast kernels):
    /// one fused operation ([`fast::decoders`]); the rows of a batch item are its cells in C
    /// order, so each head's columns are already `[B, cells, outputs / dim, dim]`.
    fn decode_rows(&self, rows: Tensor<2>, batch: usize) -> [Tensor<4>; 5] {
        let decoders = [
            (&self.decoder_points, 3),
            (&self.decoder_vstars, 3),
            (&self.decoder_normals, 3),
            (&self.decoder_cholesky, 6),
            (&self.decoder_occupancy, 1),
        ];
        let shape = fast::decoders::DecoderShape {
            width: rows.dims()[1],
            blocks: self.decoder_points.blocks.len(),
            outputs: decoders.map(|(d, _)| d.head.weight.dims()[0]),
        };
        let layers: Vec<&Conv3d> = decoders.iter().flat_map(|(d, _)| d.layers()).collect();
        let theta = fast::ops::decoder_params(&layers);
        let y = fast::ops::decoders(rows, theta, shape, self.kernels.precision());
        let n = y.dims()[0];
        let mut d = 0;
        decoders.map(|(_, dim)| {
            let (off, od) = (shape.output_offset(d), shape.outputs[d]);
            d += 1;
            y.clone()
                .narrow(1, off, od)
                .reshape([batch, n / batch, od / dim, dim])
        })
    }

    /// [`PonqNet::forward`] on one grid `[1, 1, n1+1, n2+1, n3+1]`, at the listed cells only
    /// (C-order indices into its `n1 x n2 x n3` cells, any order, repeats allowed): the five
    /// decoders run only on the listed cells' features, and on the CPU without autodiff (the
    /// fast kernels at inference) the encoder too runs only where those features depend on
    /// ([`fast::sparse`]: the listed cells dilated by one cell per layer); elsewhere the
    /// encoder runs on the whole grid. Inference keeps only the cells near the surface, a
    /// small part of a grid, so this skips most of the network's work. The values are those
    /// of [`PonqNet::forward`] at the same cells (up to float rounding: the same kernels on
    /// fewer rows).
    ///
    /// The output's cell axis runs over the listed cells in order: its tensors are
    /// `[1, k, P, dim]` and `[1, k]` for `k = cells.len()`, and its `cells` field is
    /// `[k, 1, 1]`.
    ///
    /// # Errors
    /// A batch other than 1, an empty list or a cell index outside the grid.
    pub fn forward_cells(
        &self,
        sdf: Tensor<5>,
        frame: &GridFrame,
        cells: &[usize],
    ) -> crate::Result<PonqOutput> {
        let device = sdf.device();
        let [batch, _, d1, d2, d3] = sdf.dims();
        if batch != 1 {
            return Err(crate::ModelError::Invalid(format!(
                "forward_cells takes one grid, got a batch of {batch}"
            )));
        }
        let dims = [d1, d2, d3].map(|d| d.saturating_sub(1));
        let total: usize = dims.iter().product();
        if cells.is_empty() {
            return Err(crate::ModelError::Invalid(
                "forward_cells: no cell listed".into(),
            ));
        }
        if let Some(&c) = cells.iter().find(|&&c| c >= total) {
            return Err(crate::ModelError::Invalid(format!(
                "cell {c} is outside the grid of {dims:?} cells"
            )));
        }
        let k = cells.len();
        let idx = Tensor::<1, Int>::from_data(
            TensorData::new(cells.iter().map(|&c| c as i64).collect::<Vec<_>>(), [k]),
            &device,
        );
        let [points, vstars, normals, cholesky, occupancy] = if self.uses_sparse_encoder(&device) {
            // Inference: the encoder at the listed cells' neighbourhoods only.
            let rows = self.encode_cells_sparse(sdf, dims, cells)?;
            self.decode_rows(rows, 1)
        } else if self.uses_fast_kernels(&device) {
            let f = self.encode_fast(sdf);
            let [_, n1, n2, n3, w] = f.dims();
            let rows = f.reshape([n1 * n2 * n3, w]).select(0, idx.clone());
            self.decode_rows(rows, 1)
        } else {
            let (out, _) = self.decode(sdf);
            out.map(|t| t.select(1, idx.clone()))
        };
        // The bases of the listed cells only (what `GridFrame::cell_bases` gives for all).
        let bases: Vec<f32> = cells
            .iter()
            .flat_map(|&c| {
                let ijk = [
                    c / (dims[1] * dims[2]),
                    (c / dims[2]) % dims[1],
                    c % dims[2],
                ];
                (0..3).map(move |a| frame.cell_base(a, ijk[a], dims[a]) as f32)
            })
            .collect();
        let bases =
            Tensor::<1>::from_data(TensorData::new(bases, [k * 3]), &device).reshape([1, k, 1, 3]);
        let scale = frame.offset_scale as f32;
        let points = points.mul_scalar(scale) + bases;
        let vstars = vstars.mul_scalar(scale) + points.clone().detach();
        let occupancy = sigmoid(occupancy).reshape([1, k]);
        Ok(PonqOutput {
            points,
            vstars,
            normals,
            cholesky,
            occupancy,
            cells: [k, 1, 1],
        })
    }

    /// The encoder's features `[cells.len(), W]` at `cells` of one grid `[1, 1, n1+1, n2+1,
    /// n3+1]` whose cells are `dims`, computed at those cells' neighbourhoods only
    /// ([`fast::sparse`]; the fast kernels' values, without gradients).
    fn encode_cells_sparse(
        &self,
        sdf: Tensor<5>,
        dims: [usize; 3],
        cells: &[usize],
    ) -> crate::Result<Tensor<2>> {
        let device = sdf.device();
        let values = |t: TensorData| {
            t.convert::<f32>()
                .try_into_vec::<f32>()
                .map_err(|e| crate::ModelError::Invalid(format!("tensor values: {e:?}")))
        };
        let nodes = values(sdf.into_data())?;
        let layer = |conv: &Conv3d, cin: usize, k: usize| -> crate::Result<(Vec<f32>, Vec<f32>)> {
            let w = values(conv.weight.val().into_data())?;
            let cout = conv.weight.dims()[0];
            let b = match &conv.bias {
                Some(b) => values(b.val().into_data())?,
                None => vec![0.0; cout],
            };
            let shape = fast::kernels::ConvShape {
                batch: 1,
                dims,
                cin,
                cout,
                k,
                pad: 0,
            };
            Ok((fast::kernels::pack_weight(&w, &shape, false), b))
        };
        let mut layers = vec![layer(&self.input, 1, 2)?];
        for conv in &self.encoder {
            let cin = conv.weight.dims()[1];
            layers.push(layer(conv, cin, 3)?);
        }
        let width = layers.last().map_or(0, |l| l.1.len());
        let sets = fast::sparse::ActiveSets::new(dims, cells, self.encoder.len());
        let features = fast::sparse::encode(
            &nodes,
            &sets,
            &layers,
            fast::kernels::Act::Leaky(LEAKY_SLOPE as f32),
            self.kernels.precision(),
        );
        let rows = sets.rows_of(cells).ok_or_else(|| {
            crate::ModelError::Invalid("sparse encoder: a listed cell was not computed".into())
        })?;
        let mut out = Vec::with_capacity(rows.len() * width);
        for r in rows {
            out.extend_from_slice(&features[r * width..(r + 1) * width]);
        }
        Ok(Tensor::<2>::from_data(
            TensorData::new(out, [cells.len(), width]),
            &device,
        ))
    }

    /// Runs the network on `[B, 1, n1+1, n2+1, n3+1]` SDF grids (already scaled, see
    /// [`crate::network_input_scale`]) whose node `(0,0,0)` and spacing are given by `frame`.
    pub fn forward(&self, sdf: Tensor<5>, frame: &GridFrame) -> PonqOutput {
        let device = sdf.device();
        let batch = sdf.dims()[0];
        let ([points, vstars, normals, cholesky, occupancy], [n1, n2, n3]) = self.decode(sdf);
        let cells = n1 * n2 * n3;
        let scale = frame.offset_scale as f32;
        let bases = Tensor::<1>::from_data(
            TensorData::new(frame.cell_bases([n1, n2, n3]), [cells * 3]),
            &device,
        )
        .reshape([1, cells, 1, 3]);
        let points = points.mul_scalar(scale) + bases;
        let vstars = vstars.mul_scalar(scale) + points.clone().detach();
        let occupancy = sigmoid(occupancy).reshape([batch, cells]);
        PonqOutput {
            points,
            vstars,
            normals,
            cholesky,
            occupancy,
            cells: [n1, n2, n3],
        }
    }
}
