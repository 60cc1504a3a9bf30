//! `ponq_mesh::maxflow` (Boykov-Kolmogorov) against a plain Edmonds-Karp reference.
//!
//! For every graph: the flow values agree (1e-9 relative), and the cut given by
//! `Graph::segment` is a minimum cut: the capacity of the edges from `Source` nodes to `Sink`
//! nodes (terminal edges included) equals the flow.

use ponq_mesh::maxflow::{Graph, Segment};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const INF: f64 = f64::INFINITY;

/// A max-flow problem as a list of API calls.
#[derive(Debug, Clone, Default)]
struct Problem {
    n: usize,
    /// `add_tweights(node, cap_source, cap_sink)` calls.
    tweights: Vec<(usize, f64, f64)>,
    /// `add_edge(i, j, cap, rev_cap)` calls.
    edges: Vec<(usize, usize, f64, f64)>,
}

/// What the solver is documented to do with bad capacities.
fn clean(c: f64) -> f64 {
    if c > 0.0 { c } else { 0.0 }
}

/// Edmonds-Karp (BFS augmenting paths) on residual arcs; `+inf` capacities allowed.
fn reference_maxflow(p: &Problem) -> f64 {
    let s = p.n;
    let t = p.n + 1;
    let mut head = Vec::new();
    let mut cap = Vec::new();
    let mut adj = vec![Vec::new(); p.n + 2];
    let mut add = |i: usize, j: usize, c: f64, r: f64| {
        if i == j {
            return;
        }
        adj[i].push(head.len());
        head.push(j);
        cap.push(c);
        adj[j].push(head.len());
        head.push(i);
        cap.push(r);
    };
    for &(v, cs, ct) in &p.tweights {
        add(s, v, clean(cs), 0.0);
        add(v, t, clean(ct), 0.0);
    }
    for &(i, j, c, r) in &p.edges {
        add(i, j, clean(c), clean(r));
    }
    let mut flow = 0.0;
    let mut pred = vec![usize::MAX; p.n + 2];
    loop {
        pred.fill(usize::MAX);
        let mut queue = std::collections::VecDeque::from([s]);
        while let Some(v) = queue.pop_front() {
            for &a in &adj[v] {
                let w = head[a];
                if cap[a] > 0.0 && w != s && pred[w] == usize::MAX {
                    pred[w] = a;
                    queue.push_back(w);
                }
            }
        }
        if pred[t] == usize::MAX {
            return flow;
        }
        let mut b = INF;
        let mut v = t;
        while v != s {
            let a = pred[v];
            b = b.min(cap[a]);
            v = head[a ^ 1];
        }
        if b == INF {
            return INF;
        }
        let mut v = t;
        while v != s {
            let a = pred[v];
            cap[a] -= b;
            cap[a ^ 1] += b;
            v = head[a ^ 1];
        }
        flow += b;
    }
}

fn solve(p: &Problem) -> (f64, Vec<Segment>) {
    let mut g = Graph::new(p.n, p.edges.len());
    for &(v, cs, ct) in &p.tweights {
        g.add_tweights(v, cs, ct);
    }
    for &(i, j, c, r) in &p.edges {
        g.add_edge(i, j, c, r);
    }
    let f = g.maxflow();
    let seg = (0..p.n).map(|v| g.segment(v)).collect();
    (f, seg)
}

/// Capacity of the cut `Source` | `Sink` in the original graph.
fn cut_value(p: &Problem, seg: &[Segment]) -> f64 {
    let mut c = 0.0;
    for &(v, cs, ct) in &p.tweights {
        match seg[v] {
            Segment::Sink => c += clean(cs),
            Segment::Source => c += clean(ct),
        }
    }
    for &(i, j, cap, rev) in &p.edges {
        if i == j {
            continue;
        }
        match (seg[i], seg[j]) {
            (Segment::Source, Segment::Sink) => c += clean(cap),
            (Segment::Sink, Segment::Source) => c += clean(rev),
            _ => {}
        }
    }
    c
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// Checks the solver against the reference; returns the flow.
fn check(p: &Problem) -> f64 {
    let expected = reference_maxflow(p);
    let (f, seg) = solve(p);
    if expected == INF {
        assert_eq!(f, INF, "infinite flow not reported: {p:?}");
        return f;
    }
    assert!(
        close(f, expected),
        "flow {f} != reference {expected}: {p:?}"
    );
    let c = cut_value(p, &seg);
    assert!(close(c, expected), "cut {c} != flow {expected}: {p:?}");
    f
}

// ---------------------------------------------------------------------------------------
// Hand-made graphs.

/// CLRS (3rd ed.) figure 26.1: s=-, v1..v4 = 0..3, t=-; maximum flow 23, unique minimum cut
/// {s, v1, v2, v4} | {v3, t}.
fn clrs() -> Problem {
    Problem {
        n: 4,
        tweights: vec![
            (0, 16.0, 0.0),
            (1, 13.0, 0.0),
            (2, 0.0, 20.0),
            (3, 0.0, 4.0),
        ],
        edges: vec![
            (0, 2, 12.0, 0.0),
            (1, 0, 4.0, 0.0),
            (1, 3, 14.0, 0.0),
            (2, 1, 9.0, 0.0),
            (3, 2, 7.0, 0.0),
        ],
    }
}

#[test]
fn textbook_clrs() {
    let p = clrs();
    assert_eq!(check(&p), 23.0);
    let (_, seg) = solve(&p);
    use Segment::*;
    assert_eq!(seg, vec![Source, Source, Sink, Source]);
}

#[test]
fn textbook_clrs_with_antiparallel_edge() {
    // 2nd edition: also v1 -> v2 with capacity 10 (same answer).
    let mut p = clrs();
    p.edges[1] = (1, 0, 4.0, 10.0);
    assert_eq!(check(&p), 23.0);
}

#[test]
fn single_node_and_chain() {
    let p = Problem {
        n: 1,
        tweights: vec![(0, 3.0, 5.0)],
        edges: vec![],
    };
    assert_eq!(check(&p), 3.0);
    // s -5-> 0 -2-> 1 -7-> 2 -4-> t: bottleneck 2, cut between 0 and 1.
    let p = Problem {
        n: 3,
        tweights: vec![(0, 5.0, 0.0), (2, 0.0, 4.0)],
        edges: vec![(0, 1, 2.0, 9.0), (1, 2, 7.0, 0.0)],
    };
    assert_eq!(check(&p), 2.0);
    let (_, seg) = solve(&p);
    assert_eq!(seg, vec![Segment::Source, Segment::Sink, Segment::Sink]);
}

#[test]
fn no_terminal_edges_gives_zero_and_all_sink() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut p = random_problem(&mut rng, 40, 0.2);
    p.tweights.clear();
    let (f, seg) = solve(&p);
    assert_eq!(f, 0.0);
    assert!(seg.iter().all(|&s| s == Segment::Sink));
    // Not even nodes.
    let mut g = Graph::new(0, 0);
    assert_eq!(g.maxflow(), 0.0);
}

#[test]
fn segment_before_maxflow_is_sink() {
    let p = clrs();
    let mut g = Graph::new(p.n, 0);
    for &(v, cs, ct) in &p.tweights {
        g.add_tweights(v, cs, ct);
    }
    assert!((0..p.n).all(|v| g.segment(v) == Segment::Sink));
}

#[test]
fn infinite_terminals_force_sides() {
    // Infinite source / sink seeds, finite edges: finite flow, seeds on their side.
    let p = Problem {
        n: 4,
        tweights: vec![(0, INF, 0.0), (3, 0.0, INF), (1, 1.0, 0.5), (2, INF, 2.0)],
        edges: vec![(0, 1, 3.0, 3.0), (1, 3, 1.5, 0.0), (2, 3, 0.25, 8.0)],
    };
    // Node 1 passes 0.5 + 1.5 (fed by s and node 0), node 2 passes 2 + 0.25.
    assert_eq!(check(&p), 4.25);
    let (_, seg) = solve(&p);
    assert_eq!(seg[0], Segment::Source);
    assert_eq!(seg[2], Segment::Source);
    assert_eq!(seg[3], Segment::Sink);
}

#[test]
fn infinite_path_terminates() {
    // s -inf-> 0 -inf-> 1 -inf-> 2 -inf-> t, plus finite clutter.
    let p = Problem {
        n: 5,
        tweights: vec![(0, INF, 0.0), (2, 0.0, INF), (3, 4.0, 0.0), (4, 0.0, 1.0)],
        edges: vec![
            (0, 1, INF, 0.0),
            (1, 2, INF, 1.0),
            (3, 4, 2.0, 0.0),
            (3, 1, 1.0, 1.0),
        ],
    };
    assert_eq!(check(&p), INF);
    // Same, but one finite link: finite flow.
    let mut q = p.clone();
    q.edges[1] = (1, 2, 6.0, 1.0);
    assert_eq!(check(&q), 6.0 + 1.0);
    // A node tied to both terminals with infinite capacity.
    let p = Problem {
        n: 3,
        tweights: vec![(1, INF, 2.0), (1, 1.0, INF), (0, 3.0, 0.0), (2, 0.0, 3.0)],
        edges: vec![(0, 2, 1.0, 0.0)],
    };
    assert_eq!(check(&p), INF);
    let (f, seg) = solve(&p);
    assert_eq!(f, INF);
    assert_eq!(seg.len(), 3);
}

#[test]
fn bad_capacities_are_zero() {
    let p = Problem {
        n: 4,
        tweights: vec![
            (0, 5.0, f64::NAN),
            (1, -2.0, 3.0),
            (3, 0.0, 4.0),
            (2, f64::NAN, -INF),
        ],
        edges: vec![
            (0, 1, -1.0, 2.0),
            (0, 2, f64::NAN, 1.0),
            (0, 3, 2.5, -0.0),
            (1, 3, 7.0, f64::NAN),
            (2, 2, 1.0, 1.0),
        ],
    };
    assert_eq!(check(&p), 2.5);
}

// ---------------------------------------------------------------------------------------
// Random graphs.

/// A random capacity: zeros, small integers (many ties), reals over a wide range.
fn random_cap(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..10) {
        0 | 1 => 0.0,
        2..=4 => rng.random_range(1..5) as f64,
        5 => 10f64.powf(rng.random_range(-6.0..6.0)),
        _ => rng.random_range(0.0..10.0),
    }
}

fn random_terminal(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..10) {
        0 => INF,
        1..=4 => 0.0,
        _ => random_cap(rng),
    }
}

fn random_problem(rng: &mut ChaCha8Rng, n: usize, density: f64) -> Problem {
    let mut p = Problem {
        n,
        ..Default::default()
    };
    for v in 0..n {
        let cs = random_terminal(rng);
        let mut ct = random_terminal(rng);
        if cs == INF && ct == INF {
            ct = 1.0;
        }
        p.tweights.push((v, cs, ct));
        // Sometimes a second call (must accumulate).
        if rng.random_bool(0.1) {
            p.tweights.push((v, random_cap(rng), random_cap(rng)));
        }
    }
    for i in 0..n {
        for j in 0..n {
            if i != j && rng.random_bool(density) {
                p.edges.push((i, j, random_cap(rng), random_cap(rng)));
            }
        }
    }
    p
}

#[test]
fn random_graphs_seeded() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed);
    for _ in 0..2000 {
        let n = rng.random_range(2..60);
        let density = [0.01, 0.05, 0.15, 0.4, 0.9][rng.random_range(0..5)];
        let p = random_problem(&mut rng, n, density);
        check(&p);
    }
}

#[test]
fn random_graphs_with_infinite_flow() {
    // Infinite edges and doubly-infinite nodes: infinite or finite, must agree and terminate.
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let mut n_inf = 0;
    for _ in 0..500 {
        let n = rng.random_range(2..30);
        let mut p = random_problem(&mut rng, n, 0.15);
        for e in p.edges.iter_mut() {
            if rng.random_bool(0.3) {
                e.2 = INF;
            }
        }
        if rng.random_bool(0.1) {
            let v = rng.random_range(0..n);
            p.tweights.push((v, INF, INF));
        }
        if check(&p) == INF {
            n_inf += 1;
        }
    }
    assert!(n_inf > 50, "too few infinite cases: {n_inf}");
}

/// A degree <= 4 graph like the dual of a tetrahedralisation: most nodes tied to a terminal
/// with infinite capacity, a band of free nodes between.
fn tet_dual_like(rng: &mut ChaCha8Rng, n: usize) -> Problem {
    let mut p = Problem {
        n,
        ..Default::default()
    };
    let mut deg = vec![0u8; n];
    for _ in 0..(2 * n) {
        // Mostly local edges (nodes ordered roughly along space).
        let i = rng.random_range(0..n);
        let j = (i + rng.random_range(1..20)).min(n - 1);
        if i != j && deg[i] < 4 && deg[j] < 4 {
            deg[i] += 1;
            deg[j] += 1;
            let c = rng.random_range(0.0..1.0);
            p.edges.push((i, j, c, c));
        }
    }
    for v in 0..n {
        let x = v as f64 / n as f64;
        if x < 0.4 {
            p.tweights.push((v, INF, 0.0));
        } else if x > 0.6 {
            p.tweights.push((v, 0.0, INF));
        } else if rng.random_bool(0.2) {
            p.tweights
                .push((v, rng.random_range(0.0..0.5), rng.random_range(0.0..0.5)));
        }
    }
    p
}

#[test]
fn tet_dual_like_graphs() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    for _ in 0..20 {
        let n = rng.random_range(50..3000);
        let p = tet_dual_like(&mut rng, n);
        check(&p);
    }
}

/// A 2D / 3D grid with vision-like costs: unary data terms, Potts-like pairwise terms.
fn grid(rng: &mut ChaCha8Rng, dims: &[usize], seeds: bool) -> Problem {
    let n: usize = dims.iter().product();
    let mut p = Problem {
        n,
        ..Default::default()
    };
    let mut stride = 1;
    for &d in dims {
        for v in 0..n {
            if (v / stride) % d + 1 < d {
                let c = rng.random_range(0.0..2.0);
                p.edges
                    .push((v, v + stride, c, c * rng.random_range(0.5..1.5)));
            }
        }
        stride *= d;
    }
    for v in 0..n {
        // A noisy "object" in the middle.
        let inside = (v % dims[0]) * 3 > dims[0] && (v % dims[0]) * 3 < 2 * dims[0];
        let (a, b) = if inside { (1.0, 0.3) } else { (0.3, 1.0) };
        p.tweights.push((
            v,
            a * rng.random_range(0.0..3.0),
            b * rng.random_range(0.0..3.0),
        ));
    }
    if seeds {
        p.tweights.push((n / 2, INF, 0.0));
        p.tweights.push((0, 0.0, INF));
    }
    p
}

#[test]
fn grid_graphs() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for dims in [
        &[2usize, 2][..],
        &[10, 7],
        &[32, 32],
        &[60, 20],
        &[8, 8, 8],
        &[12, 5, 9],
    ] {
        for seeds in [false, true] {
            let p = grid(&mut rng, dims, seeds);
            check(&p);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Property-based.

fn cap_strategy() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => Just(0.0),
        3 => (1u8..5).prop_map(f64::from),
        4 => 0.0f64..100.0,
        1 => Just(-1.0),
    ]
}

fn terminal_strategy() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => Just(0.0),
        5 => cap_strategy(),
        1 => Just(INF),
    ]
}

prop_compose! {
    fn problem_strategy()(n in 2usize..60)(
        n in Just(n),
        edges in prop::collection::vec(
            (0..n, 0..n, cap_strategy(), cap_strategy()), 0..(4 * n)),
        tweights in prop::collection::vec((0..n, terminal_strategy(), terminal_strategy()), 0..(2 * n)),
    ) -> Problem {
        Problem { n, tweights, edges }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn prop_matches_reference(p in problem_strategy()) {
        check(&p);
    }
}
