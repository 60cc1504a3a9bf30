//! Shape generators shared by the integration tests: PoNQs of analytic surfaces with their
//! true normals and quadrics.
#![allow(dead_code)]

use ponq_mesh::{Ponq, Quadric};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Oriented samples of a surface.
pub struct Samples {
    pub points: Vec<[f64; 3]>,
    pub normals: Vec<[f64; 3]>,
}

/// Area-uniform samples of the union-free surface of an axis-aligned box.
pub fn box_samples(lo: [f64; 3], hi: [f64; 3], n: usize, rng: &mut ChaCha8Rng) -> Samples {
    let e = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let areas = [e[1] * e[2], e[0] * e[2], e[0] * e[1]];
    let total = 2.0 * (areas[0] + areas[1] + areas[2]);
    let mut s = Samples {
        points: Vec::new(),
        normals: Vec::new(),
    };
    for _ in 0..n {
        let mut r = rng.random_range(0.0..total);
        let mut axis = 0;
        while axis < 2 && r >= 2.0 * areas[axis] {
            r -= 2.0 * areas[axis];
            axis += 1;
        }
        let side = if r < areas[axis] { 0 } else { 1 };
        let mut p = [0.0; 3];
        for k in 0..3 {
            p[k] = rng.random_range(lo[k]..hi[k]);
        }
        p[axis] = if side == 0 { lo[axis] } else { hi[axis] };
        let mut nrm = [0.0; 3];
        nrm[axis] = if side == 0 { -1.0 } else { 1.0 };
        s.points.push(p);
        s.normals.push(nrm);
    }
    s
}

/// Samples of a sphere.
pub fn sphere_samples(c: [f64; 3], r: f64, n: usize, rng: &mut ChaCha8Rng) -> Samples {
    let mut s = Samples {
        points: Vec::new(),
        normals: Vec::new(),
    };
    while s.points.len() < n {
        let d: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !(0.1..=1.0).contains(&l) {
            continue;
        }
        let u = d.map(|x| x / l);
        s.points
            .push([c[0] + r * u[0], c[1] + r * u[1], c[2] + r * u[2]]);
        s.normals.push(u);
    }
    s
}

/// Samples of a finite closed cylinder along z.
pub fn cylinder_samples(r: f64, z0: f64, z1: f64, n: usize, rng: &mut ChaCha8Rng) -> Samples {
    let side = 2.0 * std::f64::consts::PI * r * (z1 - z0);
    let cap = std::f64::consts::PI * r * r;
    let mut s = Samples {
        points: Vec::new(),
        normals: Vec::new(),
    };
    for _ in 0..n {
        let t = rng.random_range(0.0..side + 2.0 * cap);
        let a = rng.random_range(0.0..std::f64::consts::TAU);
        if t < side {
            s.points
                .push([r * a.cos(), r * a.sin(), rng.random_range(z0..z1)]);
            s.normals.push([a.cos(), a.sin(), 0.0]);
        } else {
            let rr = r * rng.random_range(0.0f64..1.0).sqrt();
            let top = t >= side + cap;
            s.points
                .push([rr * a.cos(), rr * a.sin(), if top { z1 } else { z0 }]);
            s.normals.push([0.0, 0.0, if top { 1.0 } else { -1.0 }]);
        }
    }
    s
}

/// PoNQ of samples clustered by the cells of an `n^3` grid over `[-1,1]^3` (like the
/// authors' optimisation without the point fit).
pub fn ponq_by_grid(s: &Samples, n: usize) -> Ponq {
    let cell = |p: &[f64; 3]| {
        let c = |x: f64| (((x + 1.0) / 2.0 * n as f64).floor().max(0.0) as usize).min(n - 1);
        (c(p[0]) * n + c(p[1])) * n + c(p[2])
    };
    let ids: Vec<u32> = s.points.iter().map(|p| cell(p) as u32).collect();
    Ponq::from_clusters(&s.points, &s.normals, &ids, n * n * n)
        .expect("valid clusters")
        .0
}

/// A PoNQ with one point per sample: v* = the sample, a plane quadric, the true normal.
pub fn ponq_per_sample(s: &Samples) -> Ponq {
    let q = s
        .points
        .iter()
        .zip(&s.normals)
        .map(|(p, n)| Quadric::from_plane(*p, *n))
        .collect();
    Ponq::new(
        s.points.clone(),
        s.normals.clone(),
        q,
        Some(s.points.clone()),
    )
    .expect("finite")
}

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A CAD-like closed surface: the boundary of the union of a box, a sphere and a cylinder
/// (samples of each part kept where they are outside the other two): the benches' input.
pub fn cad_union_samples(n_samples: usize) -> Samples {
    let mut r = rng(42);
    let (blo, bhi) = ([-0.7, -0.5, -0.3], [0.6, 0.5, 0.35]);
    let (sc, sr) = ([0.3, 0.1, 0.2], 0.45);
    let (cr, cz0, cz1) = (0.3, -0.8, 0.8);
    let in_box = |p: &[f64; 3]| (0..3).all(|k| p[k] > blo[k] && p[k] < bhi[k]);
    let in_sphere = |p: &[f64; 3]| {
        (p[0] - sc[0]).powi(2) + (p[1] - sc[1]).powi(2) + (p[2] - sc[2]).powi(2) < sr * sr
    };
    let in_cyl = |p: &[f64; 3]| p[0] * p[0] + p[1] * p[1] < cr * cr && p[2] > cz0 && p[2] < cz1;
    let parts = [
        box_samples(blo, bhi, n_samples / 2, &mut r),
        sphere_samples(sc, sr, n_samples / 4, &mut r),
        cylinder_samples(cr, cz0, cz1, n_samples / 4, &mut r),
    ];
    let mut s = Samples {
        points: Vec::new(),
        normals: Vec::new(),
    };
    for (i, part) in parts.into_iter().enumerate() {
        for (p, n) in part.points.into_iter().zip(part.normals) {
            let covered =
                (i != 0 && in_box(&p)) || (i != 1 && in_sphere(&p)) || (i != 2 && in_cyl(&p));
            if !covered {
                s.points.push(p);
                s.normals.push(n);
            }
        }
    }
    s
}
