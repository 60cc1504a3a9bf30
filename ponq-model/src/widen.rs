//! A wider network that computes the same function (Net2Wider, Chen, Goodfellow and Shlens,
//! "Net2Net", ICLR 2016): the warm start of a wider model from a trained narrower one.
//!
//! Every hidden channel `j` of the wider network copies a channel `g(j)` of the narrower one
//! (`g(j) = j` for the old channels, a random old channel for the new ones): its incoming
//! weights and bias are that channel's, and each layer that reads the copies gets the
//! original's outgoing weights split among them (random positive shares summing to one), so
//! every layer's input is the same sum as before. The activations are elementwise (LeakyReLU)
//! and the residual adds pair equal channels, so the wider network's outputs equal the
//! narrower one's up to float rounding (tested). The unequal shares make the copies' gradients
//! differ, so training can pull them apart (equal halves would keep them identical forever).
//!
//! ```no_run
//! # fn main() -> ponq_model::Result<()> {
//! use ponq_model::backend;
//! let device = backend::cpu();
//! let (net, config) = ponq_model::weights::load("models/ponq-cpu.bpk".as_ref(), &device)?;
//! let (wide, wide_config) = ponq_model::widen::widen(&net, &config, 64, 7)?;
//! assert_eq!(wide_config.width, 64);
//! # let _ = wide;
//! # Ok(())
//! # }
//! ```

use burn::module::Param;
use burn::nn::conv::Conv3d;
use burn::prelude::*;

use crate::error::{ModelError, Result};
use crate::model::{PonqNet, PonqNetConfig};

/// Which of a layer's two channel axes are hidden (widened) ones.
#[derive(Clone, Copy)]
struct Axes {
    input: bool,
    output: bool,
}

/// The channel map of a widening: `g[j]` is the old channel new channel `j` copies; `share[j]`
/// is the part of `g[j]`'s outgoing weights channel `j` carries (the shares of one old
/// channel's copies are positive and sum to one).
struct ChannelMap {
    g: Vec<usize>,
    share: Vec<f32>,
}

impl ChannelMap {
    fn new(old: usize, new: usize, seed: u64) -> Self {
        let mut s = seed ^ 0x9E37_79B9_7F4A_7C15;
        let mut next = move || {
            // splitmix64: deterministic, no dependency for a handful of numbers.
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        let g: Vec<usize> = (0..new)
            .map(|j| {
                if j < old {
                    j
                } else {
                    (next() % old as u64) as usize
                }
            })
            .collect();
        // Raw shares in [0.5, 1.5), normalised per old channel.
        let raw: Vec<f64> = (0..new)
            .map(|_| 0.5 + (next() >> 11) as f64 / (1u64 << 53) as f64)
            .collect();
        let mut total = vec![0.0f64; old];
        for j in 0..new {
            total[g[j]] += raw[j];
        }
        let share = (0..new).map(|j| (raw[j] / total[g[j]]) as f32).collect();
        Self { g, share }
    }
}

fn values(t: TensorData) -> Result<Vec<f32>> {
    t.convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| ModelError::Tensor(format!("{e:?}")))
}

/// `wide`'s weight and bias set from `narrow`'s through `map` on the hidden axes.
fn widen_conv(narrow: &Conv3d, wide: &mut Conv3d, axes: Axes, map: &ChannelMap) -> Result<()> {
    let [co, ci, k0, k1, k2] = narrow.weight.dims();
    let [nco, nci, ..] = wide.weight.dims();
    let kk = k0 * k1 * k2;
    let w = values(narrow.weight.val().into_data())?;
    let b = match &narrow.bias {
        Some(b) => values(b.val().into_data())?,
        None => vec![0.0; co],
    };
    let src_out = |o: usize| if axes.output { map.g[o] } else { o };
    // Input channel j reads old channel src_in(j) with its share of the outgoing weights.
    let src_in = |j: usize| {
        if axes.input {
            (map.g[j], map.share[j])
        } else {
            (j, 1.0)
        }
    };
    let mut nw = vec![0.0f32; nco * nci * kk];
    for o in 0..nco {
        let so = src_out(o);
        for j in 0..nci {
            let (sj, f) = src_in(j);
            let src = &w[(so * ci + sj) * kk..(so * ci + sj + 1) * kk];
            for (d, s) in nw[(o * nci + j) * kk..(o * nci + j + 1) * kk]
                .iter_mut()
                .zip(src)
            {
                *d = s * f;
            }
        }
    }
    let nb: Vec<f32> = (0..nco).map(|o| b[src_out(o)]).collect();
    let device = wide.weight.device();
    wide.weight = Param::from_tensor(Tensor::from_data(
        TensorData::new(nw, [nco, nci, k0, k1, k2]),
        &device,
    ));
    if wide.bias.is_some() {
        wide.bias = Some(Param::from_tensor(Tensor::from_data(
            TensorData::new(nb, [nco]),
            &device,
        )));
    }
    Ok(())
}

/// `net` (built from `config`) widened to `width` channels (Net2Wider, see the module docs),
/// on `net`'s device, with its kernels; `seed` picks which channels the new ones copy and
/// the shares. `width == config.width` gives the same network.
///
/// # Errors
/// `width` below the network's width.
pub fn widen(
    net: &PonqNet,
    config: &PonqNetConfig,
    width: usize,
    seed: u64,
) -> Result<(PonqNet, PonqNetConfig)> {
    if width < config.width {
        return Err(ModelError::Invalid(format!(
            "cannot widen a width-{} network to {width}",
            config.width
        )));
    }
    let wide_config = PonqNetConfig {
        width,
        ..config.clone()
    };
    let mut wide = wide_config.init(&net.device()).with_kernels(net.kernels());
    let map = ChannelMap::new(config.width, width, seed);
    let narrow = net.convs();
    let wide_convs = wide.convs_mut();
    assert_eq!(narrow.len(), wide_convs.len(), "same architecture");
    for ((n, [input, output]), w) in narrow.into_iter().zip(wide_convs) {
        widen_conv(n, w, Axes { input, output }, &map)?;
    }
    Ok((wide, wide_config))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_are_positive_and_sum_to_one_per_channel() {
        let m = ChannelMap::new(5, 13, 3);
        assert_eq!(&m.g[..5], &[0, 1, 2, 3, 4]);
        for i in 0..5 {
            let s: f32 = (0..13).filter(|&j| m.g[j] == i).map(|j| m.share[j]).sum();
            assert!((s - 1.0).abs() < 1e-6, "channel {i}: {s}");
        }
        assert!(m.share.iter().all(|&s| s > 0.0));
        assert!(m.g.iter().all(|&g| g < 5));
    }
}
