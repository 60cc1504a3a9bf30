//! The six losses against hand-computed values, and gradients reaching every parameter.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::prelude::*;
use ponq_model::{GridFrame, PonqNetConfig, PonqOutput, backend};
use ponq_train::config::LossWeights;
use ponq_train::data::{Batcher, Item, ItemOptions, make_item, sphere_shape};
use ponq_train::loss;

fn t4(v: Vec<f32>, shape: [usize; 4], d: &Device) -> Tensor<4> {
    let n = v.len();
    Tensor::<1>::from_data(TensorData::new(v, [n]), d).reshape(shape)
}

/// Two cells, one point each; only cell 0 is occupied.
/// p0 = (0,0,0), v*0 = (0.05,0.05,0), n0 = (1,0,0), U0 = I; p1 far away (excluded).
/// Samples s1 = (0.1,0,0) n=(1,0,0), s2 = (0,0.2,0) n=(0,1,0).
/// Occupancy predictions (0.8, 0.3) vs ground truth (1, 0), both cells close.
#[test]
fn losses_match_hand_computed_values() {
    let d = backend::cpu();
    let out = PonqOutput {
        points: t4(vec![0.0, 0.0, 0.0, 5.0, 5.0, 5.0], [1, 2, 1, 3], &d),
        vstars: t4(vec![0.05, 0.05, 0.0, 5.0, 5.0, 5.0], [1, 2, 1, 3], &d),
        normals: t4(vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0], [1, 2, 1, 3], &d),
        cholesky: t4(
            vec![1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [1, 2, 1, 6],
            &d,
        ),
        occupancy: Tensor::<1>::from_data(TensorData::new(vec![0.8f32, 0.3], [2]), &d)
            .reshape([1, 2]),
        cells: [2, 1, 1],
    };
    let item = Item {
        cells: 2,
        sdf: vec![],
        samples: vec![[0.1, 0.0, 0.0], [0.0, 0.2, 0.0]],
        normals: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        occupied: vec![true, false],
        close: vec![true, true],
    };
    let w = LossWeights {
        cd: 100.0,
        normals: 0.1,
        a: 0.1,
        vstar: 100.0,
        reg: 100.0,
        occ: 0.1,
        occ_margin: 0.01,
    };
    let l = loss::compute(&out, &[item], &w).expect("loss");
    let t = l.terms;
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6 * (1.0 + b.abs());
    // CD: samples -> p0: (0.01 + 0.04) / 2; p0 -> nearest sample s1: 0.01.
    assert!(close(t.cd, 0.035), "cd {}", t.cd);
    // Normals: s1 0, s2 |(1,0,0) - (0,1,0)|^2 = 2 -> mean 1.
    assert!(close(t.normals, 1.0), "normals {}", t.normals);
    // A = I vs n n^T: ||I - e_i e_i^T||_F^2 = 2 for both samples.
    assert!(close(t.a, 2.0), "a {}", t.a);
    // v*: (n1 . (v - s1))^2 = 0.05^2, (n2 . (v - s2))^2 = 0.15^2 -> mean 0.0125.
    assert!(close(t.vstar, 0.0125), "vstar {}", t.vstar);
    // reg: |v* - p|^2 = 0.005 over the one point of the occupied cell.
    assert!(close(t.reg, 0.005), "reg {}", t.reg);
    // occ: relu(0.04 - 0.01) and relu(0.09 - 0.01), mean 0.055.
    assert!(close(t.occ, 0.055), "occ {}", t.occ);
    let total =
        100.0 * 0.035 + 0.1 * 1.0 + 0.1 * 2.0 + 100.0 * 0.0125 + 100.0 * 0.005 + 0.1 * 0.055;
    assert!(close(t.total, total), "total {} vs {total}", t.total);
    assert!(close(f64::from(l.total.into_scalar::<f32>()), total));
}

#[test]
fn occupancy_loss_ignores_far_cells_and_the_margin() {
    let d = backend::cpu();
    let out = PonqOutput {
        points: t4(vec![0.0; 6], [1, 2, 1, 3], &d),
        vstars: t4(vec![0.0; 6], [1, 2, 1, 3], &d),
        normals: t4(vec![0.0; 6], [1, 2, 1, 3], &d),
        cholesky: t4(vec![0.0; 12], [1, 2, 1, 6], &d),
        occupancy: Tensor::<1>::from_data(TensorData::new(vec![0.95f32, 0.0], [2]), &d)
            .reshape([1, 2]),
        cells: [2, 1, 1],
    };
    // Cell 1 is wrong (0 vs 1) but not close; cell 0 is within the margin.
    let item = Item {
        cells: 2,
        sdf: vec![],
        samples: vec![],
        normals: vec![],
        occupied: vec![true, true],
        close: vec![true, false],
    };
    let l = loss::compute(&out, &[item], &LossWeights::default()).unwrap();
    assert!(l.terms.occ.abs() < 1e-9, "{}", l.terms.occ);
    assert_eq!(l.terms.cd, 0.0);
}

struct GradCheck<'a> {
    grads: &'a GradientsParams,
    params: usize,
    missing: Vec<String>,
}

impl ModuleVisitor for GradCheck<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.params += 1;
        let ok = self
            .grads
            .get::<D>(param.id)
            .map(|g| (g.clone() * g).sum().into_scalar::<f32>() > 0.0)
            .unwrap_or(false);
        if !ok {
            self.missing.push(format!("{:?} (rank {D})", param.id));
        }
    }
}

#[test]
fn gradients_reach_every_parameter() {
    let d = backend::cpu().autodiff();
    let net = PonqNetConfig::new()
        .with_width(8)
        .with_points_per_cell(2)
        .with_encoder_layers(1)
        .with_decoder_blocks(1)
        .init(&d);
    let shape = sphere_shape("s", 8, [0.05, -0.02, 0.03], 0.55, 3000);
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
    let items = vec![make_item(
        &shape,
        &ItemOptions {
            crop: 0,
            samples: 800,
            augment: true,
        },
        &mut rng,
    )];
    let x = Batcher { device: d.clone() }.batch(&items).unwrap();
    let out = net.forward(x, &GridFrame::whole(8));
    let l = loss::compute(&out, &items, &LossWeights::default()).unwrap();
    assert!(l.terms.cd > 0.0 && l.terms.normals > 0.0 && l.terms.a > 0.0 && l.terms.occ >= 0.0);
    let grads = GradientsParams::from_grads(l.total.backward(), &net);
    let mut c = GradCheck {
        grads: &grads,
        params: 0,
        missing: vec![],
    };
    net.visit(&mut c);
    // input conv, 1 encoder conv, 5 decoders x (1 block x 2 convs + head): weights + biases.
    assert_eq!(c.params, 2 * (1 + 1 + 5 * 3));
    assert!(c.missing.is_empty(), "no gradient for {:?}", c.missing);
}
