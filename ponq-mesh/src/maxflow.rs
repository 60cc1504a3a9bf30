//! Maximum flow / minimum s-t cut (Boykov-Kolmogorov).
//!
//! PoNQ labels the tetrahedra of a 3D Delaunay tetrahedralisation inside / outside with a
//! minimum s-t cut of its dual graph: one node per tetrahedron (degree <= 4), one edge per
//! interior triangle, and terminal edges of infinite capacity for the tetrahedra that are
//! already known to be inside (source) or outside (sink). [`Graph`] computes that cut.
//!
//! # Why a hand-written solver
//!
//! No suitable crate exists: `rs-graph` is GPL (this project is MIT OR Apache-2.0), and the
//! permissively licensed max-flow crates the project measured were 30-100x slower than the
//! Boykov-Kolmogorov algorithm on this kind of graph (~1M nodes, ~2M edges).
//!
//! # Algorithm
//!
//! This is the algorithm of Y. Boykov and V. Kolmogorov, "An Experimental Comparison of
//! Min-Cut/Max-Flow Algorithms for Energy Minimization in Vision" (PAMI 2004), following the
//! structure of Kolmogorov's `maxflow-v3` implementation:
//!
//! * two search trees, `S` rooted at the source and `T` rooted at the sink, grow from their
//!   *active* nodes (FIFO queue) until they touch;
//! * the path found is augmented by its bottleneck capacity; the nodes whose parent arc (or
//!   terminal arc) got saturated become *orphans*;
//! * orphans look for a new parent in their own tree, preferring the one closest to the
//!   terminal; the distance / timestamp heuristics of `maxflow-v3` (`TS`, `DIST`) avoid
//!   re-walking the same paths to the root; orphans without a valid parent become free and
//!   their children become orphans in turn.
//!
//! Terminal capacities are stored as one signed number per node (`cap_source - cap_sink`,
//! the common part `min(cap_source, cap_sink)` is pushed as flow immediately), exactly like
//! `maxflow-v3`. Arcs live in compact CSR arrays (each node's outgoing arcs contiguous, every
//! arc knows its reverse "sister" arc) built once, on the first [`Graph::maxflow`] call, from
//! the edge list. Nothing is recursive: tree walks are loops, the active set and the orphan
//! sets are explicit queues. Memory: 32 bytes per node, 32 bytes per edge (plus 24 bytes per
//! edge, released by `maxflow`, for the edges added but not yet built into the arrays).
//!
//! # Numerical invariants
//!
//! * All capacities are `f64` and are kept `>= 0` (residual arc capacities) or in
//!   `[-inf, +inf]` (signed terminal capacities). Negative and NaN capacities given to
//!   [`Graph::add_edge`] / [`Graph::add_tweights`] are treated as 0 (they never panic).
//! * A residual capacity `<= 0` is "saturated". The bottleneck of a path is the minimum of its
//!   residuals, so the arc that attains it becomes exactly `0.0` and every other residual stays
//!   `>= 0` (IEEE subtraction `c - b` with `b <= c` is never negative): there is no drift
//!   towards negative capacities, and every augmentation saturates at least one arc.
//! * `+inf` capacities are allowed (terminal capacities and, although PoNQ does not need it,
//!   edge capacities). `inf - finite` stays `inf`; `inf - inf` is never computed:
//!   - a node with infinite capacity to *both* terminals carries infinite flow; it is recorded
//!     (the flow becomes infinite) and its terminal edges are then ignored, i.e. the node is
//!     treated as having no terminal edge;
//!   - if an augmenting path of infinite bottleneck is found, the search stops at once.
//!
//!   In both cases [`Graph::maxflow`] returns `f64::INFINITY` (it never hangs and never
//!   produces NaN), and the labels of [`Graph::segment`] are valid `Source`/`Sink` values but
//!   do not form a minimum cut (no cut of finite capacity exists).
//!
//! # Example
//!
//! ```
//! use ponq_mesh::maxflow::{Graph, Segment};
//! let mut g = Graph::new(2, 1); // nodes 0 and 1
//! g.add_tweights(0, 5.0, 1.0); // source -> 0: 5, 0 -> sink: 1
//! g.add_tweights(1, 2.0, 6.0);
//! g.add_edge(0, 1, 3.0, 4.0); // 0 -> 1: 3, 1 -> 0: 4
//! assert_eq!(g.maxflow(), 6.0);
//! assert_eq!(g.segment(0), Segment::Source);
//! assert_eq!(g.segment(1), Segment::Sink);
//! ```

use std::collections::VecDeque;

/// `parent` / `next` / arc index meaning "none".
const NONE: u32 = u32::MAX;
/// `parent` of a node attached directly to its terminal.
const TERMINAL: u32 = u32::MAX - 1;
/// `parent` of an orphan (only during adoption).
const ORPHAN: u32 = u32::MAX - 2;
/// Bit of [`Node::dist_tag`] telling that the node belongs to the sink tree.
const SINK_BIT: u32 = 1 << 31;
/// Largest stored distance estimate (the estimate is a heuristic, clamping is harmless).
const DIST_MAX: u32 = SINK_BIT - 1;
/// "Infinite" distance during orphan adoption.
const INF_D: u32 = u32::MAX;
/// Maximum number of nodes.
const MAX_NODES: usize = (1 << 31) - 2;
/// Maximum number of arcs (twice the number of stored edges); indices stay below `ORPHAN`.
const MAX_ARCS: usize = ORPHAN as usize;

/// Which side of the minimum cut a node lies on (see [`Graph::segment`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Segment {
    /// Reachable from the source in the residual graph.
    Source,
    /// Not reachable from the source in the residual graph.
    Sink,
}

/// One node (32 bytes).
#[derive(Debug, Clone, Copy)]
struct Node {
    /// Residual terminal capacity: `> 0` towards the source, `< 0` towards the sink.
    tr_cap: f64,
    /// Outgoing arcs are `arcs[first..end]`.
    first: u32,
    end: u32,
    /// Arc to the parent (its `head` is the parent), or `TERMINAL`, `ORPHAN`, `NONE` (free).
    parent: u32,
    /// Next node in the active queue; `NONE` if not queued, the node itself if last.
    next: u32,
    /// Timestamp of the distance estimate.
    ts: u32,
    /// Distance estimate to the terminal (low 31 bits) and the sink-tree flag (`SINK_BIT`).
    dist_tag: u32,
}

impl Node {
    const EMPTY: Node = Node {
        tr_cap: 0.0,
        first: 0,
        end: 0,
        parent: NONE,
        next: NONE,
        ts: 0,
        dist_tag: 0,
    };

    #[inline]
    fn is_sink(&self) -> bool {
        self.dist_tag & SINK_BIT != 0
    }

    #[inline]
    fn dist(&self) -> u32 {
        self.dist_tag & DIST_MAX
    }

    #[inline]
    fn set_dist(&mut self, d: u32) {
        self.dist_tag = (self.dist_tag & SINK_BIT) | d.min(DIST_MAX);
    }

    #[inline]
    fn set_tree(&mut self, sink: bool, d: u32) {
        self.dist_tag = if sink { SINK_BIT } else { 0 } | d.min(DIST_MAX);
    }
}

/// One directed residual arc (16 bytes).
#[derive(Debug, Clone, Copy)]
struct Arc {
    /// Node the arc points to.
    head: u32,
    /// The reverse arc.
    sister: u32,
    /// Residual capacity, `>= 0` (`+inf` allowed).
    r_cap: f64,
}

/// An edge given to [`Graph::add_edge`], not yet in the CSR arrays.
#[derive(Debug, Clone, Copy)]
struct Edge {
    i: u32,
    j: u32,
    cap: f64,
    rev_cap: f64,
}

/// Capacities are clamped to `[0, +inf]`; NaN becomes 0.
#[inline]
fn sanitize(c: f64) -> f64 {
    if c > 0.0 { c } else { 0.0 }
}

/// A directed graph with a source and a sink terminal, and its maximum flow / minimum cut.
///
/// Nodes are numbered `0..num_nodes()`. Usage: create it with [`Graph::new`] (and
/// [`Graph::add_node`] for more nodes), give capacities with [`Graph::add_tweights`] and
/// [`Graph::add_edge`], call [`Graph::maxflow`], then read the cut with [`Graph::segment`].
///
/// Capacities may keep being added after `maxflow`: the flow already found stays feasible (all
/// additions only increase capacities), and the next `maxflow` call continues from the
/// residual graph and returns the total maximum flow of the modified graph.
///
/// Limits: at most `2^31 - 2` nodes and `~2^31` edges (more panics).
#[derive(Debug, Clone)]
pub struct Graph {
    nodes: Vec<Node>,
    arcs: Vec<Arc>,
    /// Edges added since the CSR arrays were built.
    pending: Vec<Edge>,
    /// Finite part of the flow pushed so far.
    flow: f64,
    /// An infinite flow was found.
    infinite: bool,
    /// Active FIFO queue (intrusive list through `Node::next`).
    queue_first: u32,
    queue_last: u32,
    /// Orphans created by an augmentation (processed last-in first-out, i.e. from the
    /// terminal side of the path first, like `maxflow-v3`'s `set_orphan_front`).
    orphans_front: Vec<u32>,
    /// Orphans created during adoption (first-in first-out).
    orphans_rear: VecDeque<u32>,
    /// Current timestamp.
    time: u32,
}

impl Graph {
    /// Creates a graph with `nodes` nodes, numbered `0..nodes`, without any edge.
    ///
    /// `edge_hint` is the expected number of [`Graph::add_edge`] calls (memory is reserved for
    /// it; it is not a limit).
    ///
    /// # Panics
    /// If `nodes` exceeds `2^31 - 2`.
    pub fn new(nodes: usize, edge_hint: usize) -> Self {
        assert!(
            nodes <= MAX_NODES,
            "maxflow::Graph: too many nodes ({nodes})"
        );
        Graph {
            nodes: vec![Node::EMPTY; nodes],
            arcs: Vec::new(),
            pending: Vec::with_capacity(edge_hint),
            flow: 0.0,
            infinite: false,
            queue_first: NONE,
            queue_last: NONE,
            orphans_front: Vec::new(),
            orphans_rear: VecDeque::new(),
            time: 0,
        }
    }

    /// Appends one node without any edge and returns its index (the previous
    /// [`Graph::num_nodes`]).
    ///
    /// # Panics
    /// If the graph already has `2^31 - 2` nodes.
    pub fn add_node(&mut self) -> usize {
        let id = self.nodes.len();
        assert!(id < MAX_NODES, "maxflow::Graph: too many nodes");
        self.nodes.push(Node::EMPTY);
        id
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Adds the terminal capacities `source -> node` (`cap_source`) and `node -> sink`
    /// (`cap_sink`).
    ///
    /// Calls accumulate. `f64::INFINITY` is allowed (hard constraint: an infinite source
    /// capacity forces the node into [`Segment::Source`] unless the flow is infinite).
    /// Negative and NaN capacities are treated as 0. A node with infinite capacity to both
    /// terminals makes the maximum flow infinite (see the module documentation).
    ///
    /// # Panics
    /// If `node` is out of range.
    pub fn add_tweights(&mut self, node: usize, cap_source: f64, cap_sink: f64) {
        let nd = &mut self.nodes[node];
        let mut cs = sanitize(cap_source);
        let mut ct = sanitize(cap_sink);
        let delta = nd.tr_cap;
        if delta > 0.0 {
            cs += delta;
        } else {
            ct -= delta;
        }
        if cs == f64::INFINITY && ct == f64::INFINITY {
            self.infinite = true;
            nd.tr_cap = 0.0;
        } else {
            self.flow += cs.min(ct);
            nd.tr_cap = cs - ct;
        }
    }

    /// Adds the edge `i -> j` with capacity `cap` and the edge `j -> i` with capacity
    /// `rev_cap`.
    ///
    /// Capacities are expected to be finite and `>= 0`; negative and NaN capacities are
    /// treated as 0, `+inf` is accepted. Parallel edges add up. Self-loops (`i == j`) and edges
    /// with both capacities 0 are ignored (they cannot carry flow).
    ///
    /// # Panics
    /// If `i` or `j` is out of range.
    pub fn add_edge(&mut self, i: usize, j: usize, cap: f64, rev_cap: f64) {
        let n = self.nodes.len();
        assert!(
            i < n && j < n,
            "maxflow::Graph::add_edge: node out of range ({i}, {j}; {n} nodes)"
        );
        let cap = sanitize(cap);
        let rev_cap = sanitize(rev_cap);
        if i == j || (cap == 0.0 && rev_cap == 0.0) {
            return;
        }
        self.pending.push(Edge {
            i: i as u32,
            j: j as u32,
            cap,
            rev_cap,
        });
    }

    /// Computes the maximum flow from the source to the sink and returns its value.
    ///
    /// The value includes the flow of earlier calls (capacities added after a call are taken
    /// into account by continuing from the residual graph). If an infinite flow exists (a path
    /// of infinite capacities from the source to the sink, e.g. a node with infinite capacity
    /// to both terminals), returns `f64::INFINITY` (the search stops as soon as it is detected;
    /// see the module documentation for the labels in that case).
    pub fn maxflow(&mut self) -> f64 {
        if !self.pending.is_empty() {
            self.build_arcs();
        }
        if !self.infinite {
            self.init_trees();
            self.run();
        }
        if self.infinite {
            f64::INFINITY
        } else {
            self.flow
        }
    }

    /// Side of the minimum cut of `node`, as computed by the last [`Graph::maxflow`] call.
    ///
    /// [`Segment::Source`] if `node` is reachable from the source in the residual graph, else
    /// [`Segment::Sink`]: nodes in no search tree (e.g. nodes without any terminal edge
    /// connected to them) are `Sink`. Before any `maxflow` call every node is `Sink`. The
    /// labels are those of the last `maxflow` call (not updated by later additions).
    ///
    /// With these labels, the sum of the capacities of the edges from `Source` nodes to `Sink`
    /// nodes (terminal edges included) equals the maximum flow (unless it is infinite).
    ///
    /// # Panics
    /// If `node` is out of range.
    pub fn segment(&self, node: usize) -> Segment {
        let nd = &self.nodes[node];
        if nd.parent != NONE && !nd.is_sink() {
            Segment::Source
        } else {
            Segment::Sink
        }
    }

    /// Moves the pending edges (and the residual arcs already built) into the CSR arrays.
    fn build_arcs(&mut self) {
        let mut edges = std::mem::take(&mut self.pending);
        // Arcs already built (residual capacities), back to an edge list.
        if !self.arcs.is_empty() {
            for (v, nd) in self.nodes.iter().enumerate() {
                for a in nd.first..nd.end {
                    let arc = self.arcs[a as usize];
                    let r_rev = self.arcs[arc.sister as usize].r_cap;
                    if a < arc.sister && (arc.r_cap > 0.0 || r_rev > 0.0) {
                        edges.push(Edge {
                            i: v as u32,
                            j: arc.head,
                            cap: arc.r_cap,
                            rev_cap: r_rev,
                        });
                    }
                }
            }
        }
        let n_arcs = 2 * edges.len();
        assert!(
            n_arcs <= MAX_ARCS,
            "maxflow::Graph: too many edges ({})",
            edges.len()
        );
        // Degrees, then offsets; `end` is used as the insertion cursor.
        for nd in self.nodes.iter_mut() {
            nd.first = 0;
            nd.end = 0;
        }
        for e in &edges {
            self.nodes[e.i as usize].end += 1;
            self.nodes[e.j as usize].end += 1;
        }
        let mut acc = 0u32;
        for nd in self.nodes.iter_mut() {
            let deg = nd.end;
            nd.first = acc;
            nd.end = acc;
            acc += deg;
        }
        self.arcs.clear();
        self.arcs.shrink_to_fit();
        self.arcs = vec![
            Arc {
                head: 0,
                sister: 0,
                r_cap: 0.0,
            };
            n_arcs
        ];
        for e in &edges {
            let ai = self.nodes[e.i as usize].end;
            self.nodes[e.i as usize].end += 1;
            let aj = self.nodes[e.j as usize].end;
            self.nodes[e.j as usize].end += 1;
            self.arcs[ai as usize] = Arc {
                head: e.j,
                sister: aj,
                r_cap: e.cap,
            };
            self.arcs[aj as usize] = Arc {
                head: e.i,
                sister: ai,
                r_cap: e.rev_cap,
            };
        }
    }

    /// Resets the search trees: every node with a terminal capacity is an active root.
    fn init_trees(&mut self) {
        self.queue_first = NONE;
        self.queue_last = NONE;
        self.orphans_front.clear();
        self.orphans_rear.clear();
        self.time = 0;
        for v in 0..self.nodes.len() {
            let nd = &mut self.nodes[v];
            nd.next = NONE;
            nd.ts = 0;
            if nd.tr_cap > 0.0 {
                nd.parent = TERMINAL;
                nd.set_tree(false, 1);
                self.set_active(v as u32);
            } else if nd.tr_cap < 0.0 {
                nd.parent = TERMINAL;
                nd.set_tree(true, 1);
                self.set_active(v as u32);
            } else {
                nd.parent = NONE;
                nd.set_tree(false, 0);
            }
        }
    }

    /// Appends `v` to the active queue unless it is already there.
    #[inline]
    fn set_active(&mut self, v: u32) {
        if self.nodes[v as usize].next == NONE {
            if self.queue_last != NONE {
                self.nodes[self.queue_last as usize].next = v;
            } else {
                self.queue_first = v;
            }
            self.queue_last = v;
            self.nodes[v as usize].next = v;
        }
    }

    /// Pops the next active node that still belongs to a tree, or `NONE`.
    #[inline]
    fn next_active(&mut self) -> u32 {
        loop {
            let v = self.queue_first;
            if v == NONE {
                return NONE;
            }
            let nd = &mut self.nodes[v as usize];
            if nd.next == v {
                self.queue_first = NONE;
                self.queue_last = NONE;
            } else {
                self.queue_first = nd.next;
            }
            nd.next = NONE;
            if nd.parent != NONE {
                return v;
            }
        }
    }

    /// Advances the timestamp (resetting all timestamps on the rare wrap-around: they only
    /// drive heuristics, and "older than now" is always a safe answer).
    #[inline]
    fn tick(&mut self) {
        if self.time == u32::MAX {
            for nd in self.nodes.iter_mut() {
                nd.ts = 0;
            }
            self.time = 0;
        }
        self.time += 1;
    }

    /// The main loop: grow, augment, adopt, until no active node is left or the flow is
    /// infinite.
    fn run(&mut self) {
        let mut current = NONE;
        loop {
            let mut i = current;
            if i != NONE {
                let nd = &mut self.nodes[i as usize];
                nd.next = NONE;
                if nd.parent == NONE {
                    i = NONE;
                }
            }
            if i == NONE {
                i = self.next_active();
                if i == NONE {
                    break;
                }
            }

            // Growth.
            let ni = self.nodes[i as usize];
            let mut middle = NONE;
            if !ni.is_sink() {
                for a in ni.first..ni.end {
                    let arc = self.arcs[a as usize];
                    if arc.r_cap > 0.0 {
                        let j = arc.head;
                        let nj = &mut self.nodes[j as usize];
                        if nj.parent == NONE {
                            nj.set_tree(false, ni.dist() + 1);
                            nj.parent = arc.sister;
                            nj.ts = ni.ts;
                            self.set_active(j);
                        } else if nj.is_sink() {
                            middle = a;
                            break;
                        } else if nj.ts <= ni.ts && nj.dist() > ni.dist() {
                            // Closer to the source through `i`.
                            nj.parent = arc.sister;
                            nj.ts = ni.ts;
                            nj.set_dist(ni.dist() + 1);
                        }
                    }
                }
            } else {
                for a in ni.first..ni.end {
                    let arc = self.arcs[a as usize];
                    if self.arcs[arc.sister as usize].r_cap > 0.0 {
                        let j = arc.head;
                        let nj = &mut self.nodes[j as usize];
                        if nj.parent == NONE {
                            nj.set_tree(true, ni.dist() + 1);
                            nj.parent = arc.sister;
                            nj.ts = ni.ts;
                            self.set_active(j);
                        } else if !nj.is_sink() {
                            middle = arc.sister;
                            break;
                        } else if nj.ts <= ni.ts && nj.dist() > ni.dist() {
                            nj.parent = arc.sister;
                            nj.ts = ni.ts;
                            nj.set_dist(ni.dist() + 1);
                        }
                    }
                }
            }

            self.tick();

            if middle != NONE {
                // Keep `i` out of the queue while it is the current node.
                self.nodes[i as usize].next = i;
                current = i;
                if !self.augment(middle) {
                    self.infinite = true;
                    self.nodes[i as usize].next = NONE;
                    break;
                }
                self.adopt();
            } else {
                current = NONE;
            }
        }
    }

    /// Pushes the bottleneck along the path source -> ... -> tail(middle) -> head(middle) ->
    /// ... -> sink. Returns `false` (and changes nothing) if the bottleneck is infinite.
    fn augment(&mut self, middle: u32) -> bool {
        let mid = self.arcs[middle as usize];
        let tail = self.arcs[mid.sister as usize].head;

        // Bottleneck.
        let mut bottleneck = mid.r_cap;
        let mut v = tail;
        loop {
            let a = self.nodes[v as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            let r = self.arcs[arc.sister as usize].r_cap;
            if bottleneck > r {
                bottleneck = r;
            }
            v = arc.head;
        }
        let r = self.nodes[v as usize].tr_cap;
        if bottleneck > r {
            bottleneck = r;
        }
        let mut v = mid.head;
        loop {
            let a = self.nodes[v as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            if bottleneck > arc.r_cap {
                bottleneck = arc.r_cap;
            }
            v = arc.head;
        }
        let r = -self.nodes[v as usize].tr_cap;
        if bottleneck > r {
            bottleneck = r;
        }
        if bottleneck == f64::INFINITY {
            return false;
        }

        // Augmentation.
        self.arcs[mid.sister as usize].r_cap += bottleneck;
        self.arcs[middle as usize].r_cap -= bottleneck;
        // Source tree: flow goes parent -> v, i.e. along the sister of v's parent arc.
        let mut v = tail;
        loop {
            let a = self.nodes[v as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            self.arcs[a as usize].r_cap += bottleneck;
            let s = &mut self.arcs[arc.sister as usize];
            s.r_cap -= bottleneck;
            if s.r_cap <= 0.0 {
                s.r_cap = 0.0;
                self.set_orphan_front(v);
            }
            v = arc.head;
        }
        let nd = &mut self.nodes[v as usize];
        nd.tr_cap -= bottleneck;
        if nd.tr_cap <= 0.0 {
            nd.tr_cap = 0.0;
            self.set_orphan_front(v);
        }
        // Sink tree: flow goes v -> parent, along v's parent arc.
        let mut v = mid.head;
        loop {
            let a = self.nodes[v as usize].parent;
            if a == TERMINAL {
                break;
            }
            let arc = self.arcs[a as usize];
            self.arcs[arc.sister as usize].r_cap += bottleneck;
            let p = &mut self.arcs[a as usize];
            p.r_cap -= bottleneck;
            if p.r_cap <= 0.0 {
                p.r_cap = 0.0;
                self.set_orphan_front(v);
            }
            v = arc.head;
        }
        let nd = &mut self.nodes[v as usize];
        nd.tr_cap += bottleneck;
        if nd.tr_cap >= 0.0 {
            nd.tr_cap = 0.0;
            self.set_orphan_front(v);
        }

        self.flow += bottleneck;
        true
    }

    #[inline]
    fn set_orphan_front(&mut self, v: u32) {
        self.nodes[v as usize].parent = ORPHAN;
        self.orphans_front.push(v);
    }

    #[inline]
    fn set_orphan_rear(&mut self, v: u32) {
        self.nodes[v as usize].parent = ORPHAN;
        self.orphans_rear.push_back(v);
    }

    /// Processes all orphans: each orphan of the augmentation, followed by the orphans it
    /// creates.
    fn adopt(&mut self) {
        while let Some(v) = self.orphans_front.pop() {
            self.process_orphan(v);
            while let Some(w) = self.orphans_rear.pop_front() {
                self.process_orphan(w);
            }
        }
    }

    /// Finds a new parent for the orphan `i` in its own tree, or frees it.
    fn process_orphan(&mut self, i: u32) {
        let ni = self.nodes[i as usize];
        let sink = ni.is_sink();
        let time = self.time;
        let mut a0_min = NONE;
        let mut d_min = INF_D;

        for a0 in ni.first..ni.end {
            let arc0 = self.arcs[a0 as usize];
            // Residual capacity of the arc the flow would use: parent -> i (source tree) or
            // i -> parent (sink tree).
            let r = if sink {
                arc0.r_cap
            } else {
                self.arcs[arc0.sister as usize].r_cap
            };
            if r <= 0.0 {
                continue;
            }
            let nj = &self.nodes[arc0.head as usize];
            if nj.is_sink() != sink || nj.parent == NONE {
                continue;
            }
            // Does `j` lead to the terminal (and how far)?
            let mut j = arc0.head;
            let mut d: u32 = 0;
            loop {
                let nj = &mut self.nodes[j as usize];
                if nj.ts == time {
                    d = d.saturating_add(nj.dist());
                    break;
                }
                let a = nj.parent;
                d = d.saturating_add(1);
                if a == TERMINAL {
                    nj.ts = time;
                    nj.set_dist(1);
                    break;
                }
                if a == ORPHAN {
                    d = INF_D;
                    break;
                }
                j = self.arcs[a as usize].head;
            }
            if d < INF_D {
                if d < d_min {
                    a0_min = a0;
                    d_min = d;
                }
                // Mark the path with exact distances.
                let mut j = arc0.head;
                while self.nodes[j as usize].ts != time {
                    let nj = &mut self.nodes[j as usize];
                    nj.ts = time;
                    nj.set_dist(d);
                    d = d.saturating_sub(1);
                    j = self.arcs[nj.parent as usize].head;
                }
            }
        }

        if a0_min != NONE {
            let nd = &mut self.nodes[i as usize];
            nd.parent = a0_min;
            nd.ts = time;
            nd.set_dist(d_min.saturating_add(1));
            return;
        }

        // No parent: `i` becomes free; its neighbours in the same tree may grow into it
        // again, its children become orphans.
        self.nodes[i as usize].parent = NONE;
        for a0 in ni.first..ni.end {
            let arc0 = self.arcs[a0 as usize];
            let j = arc0.head;
            let nj = self.nodes[j as usize];
            if nj.is_sink() != sink || nj.parent == NONE {
                continue;
            }
            let r = if sink {
                arc0.r_cap
            } else {
                self.arcs[arc0.sister as usize].r_cap
            };
            if r > 0.0 {
                self.set_active(j);
            }
            let a = nj.parent;
            if a != TERMINAL && a != ORPHAN && self.arcs[a as usize].head == i {
                self.set_orphan_rear(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Nodes reachable from the source in the residual graph.
    fn residual_reachable(g: &Graph) -> Vec<bool> {
        let n = g.nodes.len();
        let mut seen = vec![false; n];
        let mut stack: Vec<usize> = (0..n).filter(|&v| g.nodes[v].tr_cap > 0.0).collect();
        for &v in &stack {
            seen[v] = true;
        }
        while let Some(v) = stack.pop() {
            let nd = g.nodes[v];
            for a in nd.first..nd.end {
                let arc = g.arcs[a as usize];
                if arc.r_cap > 0.0 && !seen[arc.head as usize] {
                    seen[arc.head as usize] = true;
                    stack.push(arc.head as usize);
                }
            }
        }
        seen
    }

    /// Nodes that reach the sink in the residual graph.
    fn residual_coreachable(g: &Graph) -> Vec<bool> {
        let n = g.nodes.len();
        let mut seen = vec![false; n];
        let mut stack: Vec<usize> = (0..n).filter(|&v| g.nodes[v].tr_cap < 0.0).collect();
        for &v in &stack {
            seen[v] = true;
        }
        while let Some(v) = stack.pop() {
            let nd = g.nodes[v];
            for a in nd.first..nd.end {
                let arc = g.arcs[a as usize];
                if g.arcs[arc.sister as usize].r_cap > 0.0 && !seen[arc.head as usize] {
                    seen[arc.head as usize] = true;
                    stack.push(arc.head as usize);
                }
            }
        }
        seen
    }

    /// Small deterministic generator (no dev-dependency needed in unit tests).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> u64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            self.0 >> 33
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
        fn cap(&mut self) -> f64 {
            match self.below(4) {
                0 => 0.0,
                1 => (1 + self.below(4)) as f64,
                _ => self.below(1_000_000) as f64 / 100_000.0,
            }
        }
    }

    fn random_graph(rng: &mut Lcg) -> Graph {
        let n = 2 + rng.below(50) as usize;
        let m = rng.below((n * n) as u64 / 2 + 1) as usize;
        let mut g = Graph::new(n, m);
        for v in 0..n {
            let cs = match rng.below(8) {
                0 => f64::INFINITY,
                1..=3 => 0.0,
                _ => rng.cap(),
            };
            let ct = match rng.below(8) {
                0 if cs != f64::INFINITY => f64::INFINITY,
                0..=3 => 0.0,
                _ => rng.cap(),
            };
            g.add_tweights(v, cs, ct);
        }
        for _ in 0..m {
            let i = rng.below(n as u64) as usize;
            let j = rng.below(n as u64) as usize;
            let c = rng.cap();
            let r = rng.cap();
            g.add_edge(i, j, c, r);
        }
        g
    }

    #[test]
    fn segments_are_the_residual_reachable_set() {
        let mut rng = Lcg(7);
        for _ in 0..500 {
            let mut g = random_graph(&mut rng);
            let f = g.maxflow();
            assert!(f.is_finite() && f >= 0.0);
            let reach = residual_reachable(&g);
            let coreach = residual_coreachable(&g);
            for v in 0..g.num_nodes() {
                assert_eq!(g.segment(v) == Segment::Source, reach[v], "node {v}");
                // A maximum flow: no node is both reachable and co-reachable.
                assert!(
                    !(reach[v] && coreach[v]),
                    "augmenting path left through {v}"
                );
            }
            // Tree invariants after termination.
            assert!(g.orphans_front.is_empty() && g.orphans_rear.is_empty());
            for v in 0..g.num_nodes() {
                let nd = g.nodes[v];
                if nd.parent != NONE && nd.parent != TERMINAL {
                    let arc = g.arcs[nd.parent as usize];
                    let parent = g.nodes[arc.head as usize];
                    assert_eq!(parent.is_sink(), nd.is_sink());
                    assert_ne!(parent.parent, NONE);
                }
            }
        }
    }

    #[test]
    fn timestamp_wrap_around() {
        let mut rng = Lcg(5);
        for _ in 0..100 {
            let mut g = random_graph(&mut rng);
            let mut h = g.clone();
            let expected = h.maxflow();
            g.build_arcs();
            g.init_trees();
            g.time = u32::MAX - 3;
            g.run();
            assert!((g.flow - expected).abs() <= 1e-9 * expected.max(1.0));
            let reach = residual_reachable(&g);
            for (v, &r) in reach.iter().enumerate() {
                assert_eq!(g.segment(v) == Segment::Source, r);
            }
        }
    }

    #[test]
    fn residual_capacities_stay_nonnegative() {
        let mut rng = Lcg(11);
        for _ in 0..300 {
            let mut g = random_graph(&mut rng);
            g.maxflow();
            assert!(g.arcs.iter().all(|a| a.r_cap >= 0.0));
            assert!(g.nodes.iter().all(|n| !n.tr_cap.is_nan()));
        }
    }

    #[test]
    fn two_nodes_example() {
        let mut g = Graph::new(2, 1);
        g.add_tweights(0, 5.0, 1.0);
        g.add_tweights(1, 2.0, 6.0);
        g.add_edge(0, 1, 3.0, 4.0);
        assert_eq!(g.maxflow(), 6.0);
        assert_eq!(g.segment(0), Segment::Source);
        assert_eq!(g.segment(1), Segment::Sink);
    }

    #[test]
    fn tweights_accumulate() {
        let mut g = Graph::new(1, 0);
        g.add_tweights(0, 3.0, 1.0);
        g.add_tweights(0, 1.0, 5.0);
        // source 4, sink 6.
        assert_eq!(g.maxflow(), 4.0);
        assert_eq!(g.segment(0), Segment::Sink);
        g.add_tweights(0, 10.0, 0.0);
        // source 14, sink 6.
        assert_eq!(g.maxflow(), 6.0);
        assert_eq!(g.segment(0), Segment::Source);
    }

    #[test]
    fn bad_capacities_are_zero() {
        let mut g = Graph::new(3, 2);
        g.add_tweights(0, f64::NAN, -1.0);
        g.add_tweights(1, -f64::INFINITY, f64::NAN);
        g.add_edge(0, 1, -3.0, f64::NAN);
        g.add_edge(1, 2, f64::NAN, -0.0);
        g.add_edge(2, 2, 5.0, 5.0);
        assert_eq!(g.maxflow(), 0.0);
        assert!(g.pending.is_empty() && g.arcs.is_empty());
        for v in 0..3 {
            assert_eq!(g.segment(v), Segment::Sink);
        }
    }

    #[test]
    fn both_terminals_infinite() {
        let mut g = Graph::new(3, 2);
        g.add_tweights(0, f64::INFINITY, 0.0);
        g.add_tweights(0, 0.0, f64::INFINITY);
        g.add_tweights(1, 1.0, 0.0);
        g.add_tweights(2, 0.0, 1.0);
        g.add_edge(1, 2, 1.0, 0.0);
        assert_eq!(g.maxflow(), f64::INFINITY);
        assert!(g.nodes.iter().all(|n| !n.tr_cap.is_nan()));
    }

    #[test]
    fn adding_after_maxflow_continues() {
        let mut rng = Lcg(3);
        for _ in 0..200 {
            let mut g = random_graph(&mut rng);
            let n = g.num_nodes();
            let mut fresh = g.clone();
            g.maxflow();
            // Same additions to both.
            let extra = g.add_node();
            assert_eq!(fresh.add_node(), extra);
            for _ in 0..(1 + rng.below(10)) {
                let i = rng.below(n as u64 + 1) as usize;
                let j = rng.below(n as u64 + 1) as usize;
                let (c, r) = (rng.cap(), rng.cap());
                g.add_edge(i, j, c, r);
                fresh.add_edge(i, j, c, r);
                let (s, t) = (rng.cap(), rng.cap());
                g.add_tweights(i, s, t);
                fresh.add_tweights(i, s, t);
            }
            let f1 = g.maxflow();
            let f2 = fresh.maxflow();
            assert!((f1 - f2).abs() <= 1e-9 * f1.abs().max(1.0), "{f1} vs {f2}");
        }
    }
}
