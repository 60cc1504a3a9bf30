//! Data parallelism: one batch split into shards, each shard's loss weighted by its share of
//! the batch, the gradients summed — over the micro-batches of one device
//! ([`Parallel::MicroBatches`], `train.micro_batches`) or over several GPUs at once
//! ([`Parallel::Devices`], `ponq-train --devices 0,1,2,3`).
//!
//! Every loss term is a mean per shape averaged over the batch ([`crate::loss`]), so the
//! gradient of the whole batch is `sum_k (n_k / N) grad(loss of shard k)`: both modes give one
//! device's step on the whole batch up to float rounding, with the same learning rate (the
//! global batch is `train.batch_size` whatever the number of devices or micro-batches).
//!
//! Several devices use Burn's own distributed training (`burn::tensor::distributed`): the
//! parameters of each device's replica are marked with `set_distributed`, and `backward`
//! all-reduces (sums) their gradients across the devices (NCCL on CUDA). One thread per
//! extra device runs its shard; the main thread runs shard 0, clips the summed gradient and
//! takes the single optimizer step; the next step sends the updated weights to the replicas.
//! Checkpoints are written from the main device only, so a run may resume with any device
//! count. Only Burn's CUDA backend implements the collective operations (its CPU and wgpu
//! backends do not), so several devices need `--backend cuda`.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

use anyhow::{Context, Result, anyhow, bail};
use burn::module::{Module, ModuleMapper, Param};
use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::prelude::*;
use burn::tensor::distributed::{DistributedConfig, DistributedContext, ReduceOperation};
use ponq_model::GridFrame;
use ponq_model::PonqNet;

use crate::config::LossWeights;
use crate::data::{Batcher, Item};
use crate::loss::{self, LossTerms};

/// Sizes of `k` contiguous shards of `n` items: as equal as possible (they differ by at
/// most one, the larger first) and summing to `n`. Shards may be empty when `n < k`.
pub fn shard_sizes(n: usize, k: usize) -> Vec<usize> {
    let k = k.max(1);
    (0..k).map(|i| n / k + usize::from(i < n % k)).collect()
}

/// The weight of a shard of `n_k` items in a batch of `n`: its share of the batch.
pub fn shard_weight(n_k: usize, n: usize) -> f32 {
    if n == 0 { 0.0 } else { n_k as f32 / n as f32 }
}

/// Parses a `--devices` list (`0,1,2,3`): device indices, at least one, no repeats.
pub fn parse_devices(list: &str) -> Result<Vec<usize>> {
    let mut out = Vec::new();
    for part in list.split(',').map(str::trim) {
        let i: usize = part.parse().map_err(|_| {
            anyhow!("invalid device index '{part}' in '{list}' (expected e.g. 0,1,2,3)")
        })?;
        if out.contains(&i) {
            bail!("device {i} is listed twice in '{list}'");
        }
        out.push(i);
    }
    Ok(out)
}

/// Checks device indices against the backend and the batch: the CPU backend is one device
/// (it uses every core), several devices need collective operations (CUDA only), and each
/// device needs at least one shape of a batch.
pub fn check_devices(
    backend: ponq_model::backend::BackendKind,
    indices: &[usize],
    batch_size: usize,
) -> Result<()> {
    use ponq_model::backend::BackendKind;
    if indices.is_empty() {
        bail!("no device given");
    }
    match backend {
        BackendKind::Flex if indices != [0] => bail!(
            "the flex backend is one device (it uses all CPU cores); --devices {indices:?} needs \
             --backend cuda"
        ),
        BackendKind::Wgpu if indices.len() > 1 => bail!(
            "training on several devices needs --backend cuda: Burn's wgpu backend has no \
             collective operations (all-reduce) to sum the gradients"
        ),
        _ => {}
    }
    if indices.len() > batch_size {
        bail!(
            "{} devices for a batch of {batch_size} shapes: each device needs at least one \
             shape (raise train.batch_size or use fewer devices)",
            indices.len()
        );
    }
    Ok(())
}

/// How the gradient of a batch is computed.
pub enum Parallel {
    /// On one device, over this many micro-batches in turn (1: the whole batch at once).
    /// Lowers peak memory; the gradient is the whole batch's.
    MicroBatches(usize),
    /// On several devices at once (Burn's distributed data parallelism).
    Devices(DeviceGroup),
}

/// The gradient and loss values of one batch.
pub struct BatchGradients {
    /// Gradients of the batch loss (summed over the shards).
    pub grads: GradientsParams,
    /// Loss terms of the batch (weighted mean over the shards).
    pub terms: LossTerms,
}

impl Parallel {
    /// Forward and backward of `items` through `model` (on the main device).
    pub fn gradients(
        &mut self,
        model: &PonqNet,
        items: &[Item],
        frame: &GridFrame,
        weights: &LossWeights,
    ) -> Result<BatchGradients> {
        match self {
            Self::MicroBatches(k) => micro_batch_gradients(model, items, frame, weights, *k),
            Self::Devices(group) => group.gradients(model, items, frame, weights),
        }
    }

    /// The model to optimise: replicas of several devices have their parameters marked for
    /// gradient all-reduce.
    pub fn prepare(&self, model: PonqNet) -> PonqNet {
        match self {
            Self::MicroBatches(_) => model,
            Self::Devices(_) => model.map(&mut MarkDistributed),
        }
    }
}

/// Loss of one shard, scaled by its weight, and its backward.
fn shard_backward(
    model: &PonqNet,
    items: &[Item],
    weight: f32,
    frame: &GridFrame,
    weights: &LossWeights,
) -> Result<(GradientsParams, LossTerms)> {
    let device = model_device(model)?;
    let batcher = Batcher { device };
    let out = model.forward(batcher.batch(items)?, frame);
    let l = loss::compute(&out, items, weights)?;
    let grads = GradientsParams::from_grads((l.total * weight).backward(), model);
    Ok((grads, l.terms))
}

fn model_device(model: &PonqNet) -> Result<Device> {
    model
        .devices()
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("the model has no parameters"))
}

/// One device, `k` micro-batches accumulated.
fn micro_batch_gradients(
    model: &PonqNet,
    items: &[Item],
    frame: &GridFrame,
    weights: &LossWeights,
    k: usize,
) -> Result<BatchGradients> {
    if items.is_empty() {
        bail!("empty batch");
    }
    let n = items.len();
    if k <= 1 {
        let (grads, terms) = shard_backward(model, items, 1.0, frame, weights)?;
        return Ok(BatchGradients { grads, terms });
    }
    let mut acc = GradientsAccumulator::<PonqNet>::new();
    let mut terms = LossTerms::default();
    let mut start = 0;
    for size in shard_sizes(n, k).into_iter().filter(|&s| s > 0) {
        let w = shard_weight(size, n);
        let (g, t) = shard_backward(model, &items[start..start + size], w, frame, weights)?;
        acc.accumulate(model, g);
        terms.add(&t, f64::from(w));
        start += size;
    }
    Ok(BatchGradients {
        grads: acc.grads(),
        terms,
    })
}

/// Marks every parameter for gradient all-reduce during `backward`.
struct MarkDistributed;

impl ModuleMapper for MarkDistributed {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let (id, tensor, mapper) = param.consume();
        let tensor = if tensor.is_distributed() {
            tensor
        } else {
            tensor.set_distributed(id)
        };
        Param::from_mapped_value(id, tensor, mapper)
    }
}

/// One shard's work for a peer device.
struct Job {
    model: PonqNet,
    items: Vec<Item>,
    weight: f32,
    frame: GridFrame,
    weights: LossWeights,
}

/// A worker thread of one peer device: its job queue and its answers.
struct Peer {
    jobs: Sender<Job>,
    results: Receiver<Result<LossTerms>>,
    thread: JoinHandle<()>,
}

/// Devices training one model together: the main device (index 0, in the caller's thread)
/// and one thread per peer.
pub struct DeviceGroup {
    devices: Vec<Device>,
    peers: Vec<Peer>,
    // Dropped last: closes the communication server once the peers are gone.
    _context: DistributedContext,
}

impl DeviceGroup {
    /// Starts the communication between `devices` (at least two, autodiff enabled) and one
    /// worker thread per device after the first.
    pub fn new(devices: Vec<Device>) -> Result<Self> {
        if devices.len() < 2 {
            bail!("a device group needs at least two devices");
        }
        let context = DistributedContext::init(
            devices.clone(),
            DistributedConfig {
                all_reduce_op: ReduceOperation::Sum,
            },
        );
        let mut peers = Vec::new();
        for (i, device) in devices.iter().enumerate().skip(1) {
            let (job_tx, job_rx) = channel::<Job>();
            let (res_tx, res_rx) = channel::<Result<LossTerms>>();
            let device = device.clone();
            let handle = std::thread::Builder::new()
                .name(format!("ponq-device-{i}"))
                .spawn(move || {
                    for job in job_rx {
                        let model = job.model.fork(&device).map(&mut MarkDistributed);
                        let r = shard_backward(
                            &model,
                            &job.items,
                            job.weight,
                            &job.frame,
                            &job.weights,
                        )
                        .map(|(_, t)| t);
                        if res_tx.send(r).is_err() {
                            break;
                        }
                    }
                })
                .context("cannot start a device thread")?;
            peers.push(Peer {
                jobs: job_tx,
                results: res_rx,
                thread: handle,
            });
        }
        Ok(Self {
            devices,
            peers,
            _context: context,
        })
    }

    fn gradients(
        &mut self,
        model: &PonqNet,
        items: &[Item],
        frame: &GridFrame,
        weights: &LossWeights,
    ) -> Result<BatchGradients> {
        let n = items.len();
        if n == 0 {
            bail!("empty batch");
        }
        let sizes = shard_sizes(n, self.devices.len());
        // A device without items (the last, short batch of an epoch) still joins the
        // all-reduce, with a copy of the first item at weight 0.
        let shard = |k: usize| -> (Vec<Item>, f32) {
            let start: usize = sizes[..k].iter().sum();
            if sizes[k] == 0 {
                (vec![items[0].clone()], 0.0)
            } else {
                (
                    items[start..start + sizes[k]].to_vec(),
                    shard_weight(sizes[k], n),
                )
            }
        };
        for (k, peer) in self.peers.iter().enumerate() {
            let (shard_items, weight) = shard(k + 1);
            peer.jobs
                .send(Job {
                    model: model.clone(),
                    items: shard_items,
                    weight,
                    frame: *frame,
                    weights: *weights,
                })
                .map_err(|_| anyhow!("device thread {} stopped", k + 1))?;
        }
        let (items0, w0) = shard(0);
        let (grads, t0) = shard_backward(model, &items0, w0, frame, weights)?;
        let mut terms = LossTerms::default();
        terms.add(&t0, f64::from(w0));
        for (k, peer) in self.peers.iter().enumerate() {
            let t = peer
                .results
                .recv()
                .map_err(|_| anyhow!("device thread {} stopped", k + 1))?
                .with_context(|| format!("on device {}", k + 1))?;
            let (_, w) = shard(k + 1);
            terms.add(&t, f64::from(w));
        }
        Ok(BatchGradients { grads, terms })
    }
}

impl Drop for DeviceGroup {
    fn drop(&mut self) {
        for peer in self.peers.drain(..) {
            drop(peer.jobs);
            drop(peer.results);
            let _ = peer.thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ponq_model::backend::BackendKind;

    #[test]
    fn device_lists_are_checked() {
        assert_eq!(parse_devices("0,1, 2,3").unwrap(), vec![0, 1, 2, 3]);
        assert!(
            parse_devices("0,x")
                .unwrap_err()
                .to_string()
                .contains("'x'")
        );
        assert!(
            parse_devices("1,1")
                .unwrap_err()
                .to_string()
                .contains("twice")
        );
        assert!(parse_devices("").is_err());
        assert!(check_devices(BackendKind::Flex, &[0], 8).is_ok());
        assert!(check_devices(BackendKind::Flex, &[0, 1], 8).is_err());
        assert!(check_devices(BackendKind::Flex, &[1], 8).is_err());
        let e = check_devices(BackendKind::Wgpu, &[0, 1], 8).unwrap_err();
        assert!(e.to_string().contains("--backend cuda"), "{e}");
        assert!(check_devices(BackendKind::Cuda, &[0, 1, 2, 3], 4).is_ok());
        let e = check_devices(BackendKind::Cuda, &[0, 1, 2, 3], 3).unwrap_err();
        assert!(e.to_string().contains("at least one"), "{e}");
    }

    #[test]
    fn shards_cover_the_batch_and_weights_sum_to_one() {
        for n in 1..20 {
            for k in 1..9 {
                let s = shard_sizes(n, k);
                assert_eq!(s.len(), k);
                assert_eq!(s.iter().sum::<usize>(), n);
                let (lo, hi) = (s.iter().min().unwrap(), s.iter().max().unwrap());
                assert!(hi - lo <= 1, "{s:?}");
                assert!(s.windows(2).all(|w| w[0] >= w[1]), "{s:?}");
                let w: f32 = s.iter().map(|&m| shard_weight(m, n)).sum();
                assert!((w - 1.0).abs() < 1e-6);
            }
        }
    }
}
