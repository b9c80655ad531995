//! SAH k-d tree (after pbrt-v3's `KdTreeAccel`, with binned split evaluation).
//!
//! Each interior node splits its box by an axis-aligned plane. Unlike a BVH, a primitive
//! whose box straddles the plane goes to *both* children, so sibling cells never overlap and
//! traversal can stop at the first leaf that holds a hit. The plane is chosen by the surface
//! area heuristic over 32 bins per axis, with pbrt's bonus for cutting off empty space
//! (`empty_bonus`, 0.5: a split with one empty side costs half as much); a node becomes a leaf
//! at `max_leaf_prims` primitives, at the depth limit (`8 + 1.3 log2 N` unless set), or after
//! three splits in a row that did not pay for themselves.
//!
//! Primitives listed in several leaves are tested once per ray (64-entry mailbox, as in
//! [`super::Grid`]).

use super::{Accel, AccelParams, AccelStats, BuildParams, Counter, OrderedWalk};
use crate::geometry::{Aabb, Ray};

/// k-d tree build settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KdParams {
    pub base: AccelParams,
    /// Cost reduction for splits with an empty side (pbrt's `emptyBonus`).
    pub empty_bonus: f32,
    /// Depth limit; 0 means pbrt's `8 + 1.3 log2 N`. (A k-d tree needs more depth than a BVH:
    /// `base.max_depth`, the lecture's 24, applies to the BVH's top-down splits.)
    pub max_depth: usize,
}

impl KdParams {
    pub fn new(base: AccelParams) -> KdParams {
        KdParams { base, empty_bonus: 0.5, max_depth: 0 }
    }
}

impl BuildParams for KdParams {
    fn base(&self) -> &AccelParams {
        &self.base
    }
    fn base_mut(&mut self) -> &mut AccelParams {
        &mut self.base
    }
}

#[derive(Clone, Copy, Debug)]
struct KdNode {
    /// Split position (interior) or unused (leaf).
    split: f32,
    /// 0, 1, 2: interior node splitting that axis; 3: leaf.
    axis: u32,
    /// Interior: index of the child above the plane (the one below is the next node).
    /// Leaf: first index into `refs`.
    a: u32,
    /// Leaf: number of primitives.
    b: u32,
}

const LEAF: u32 = 3;
const BINS: usize = 32;
const MAX_STACK: usize = 64;

/// A k-d tree over primitive boxes.
pub struct KdTree {
    bounds: Aabb,
    nodes: Vec<KdNode>,
    refs: Vec<u32>,
    stats: AccelStats,
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    p: KdParams,
    nodes: Vec<KdNode>,
    refs: Vec<u32>,
    depth: usize,
}

impl Builder<'_> {
    fn leaf(&mut self, prims: &[u32]) {
        self.nodes.push(KdNode { split: 0.0, axis: LEAF, a: self.refs.len() as u32, b: prims.len() as u32 });
        self.refs.extend_from_slice(prims);
    }

    fn build(&mut self, bounds: Aabb, prims: Vec<u32>, depth: usize, max_depth: usize, bad: u32) {
        self.depth = self.depth.max(depth);
        let n = prims.len();
        if n <= self.p.base.max_leaf_prims || depth >= max_depth {
            return self.leaf(&prims);
        }
        let (ct, ci) = (self.p.base.traversal_cost, self.p.base.intersect_cost);
        let area = bounds.half_area().max(f32::MIN_POSITIVE);
        let e = bounds.extent();
        let mut best: Option<(f32, usize, f32)> = None; // cost, axis, split
        for axis in 0..3 {
            if e[axis] <= 0.0 {
                continue;
            }
            let lo = bounds.min[axis];
            let scale = BINS as f32 / e[axis];
            let bin = |x: f32| (((x - lo) * scale).max(0.0) as usize).min(BINS - 1);
            let mut starts = [0u32; BINS];
            let mut ends = [0u32; BINS];
            for &p in &prims {
                let b = &self.boxes[p as usize];
                starts[bin(b.min[axis])] += 1;
                ends[bin(b.max[axis])] += 1;
            }
            // Plane k (1..BINS) lies between bins k-1 and k. Below: primitives starting before
            // it; above: primitives ending after it.
            let (o1, o2) = ((axis + 1) % 3, (axis + 2) % 3);
            let (mut below, mut above) = (0u32, n as u32);
            for k in 1..BINS {
                below += starts[k - 1];
                above -= ends[k - 1];
                let x = lo + k as f32 / scale;
                let (db, da) = (x - lo, bounds.max[axis] - x);
                let ab = db * (e[o1] + e[o2]) + e[o1] * e[o2];
                let aa = da * (e[o1] + e[o2]) + e[o1] * e[o2];
                let bonus = if below == 0 || above == 0 { self.p.empty_bonus } else { 0.0 };
                let cost = ct + ci * (1.0 - bonus) * (ab * below as f32 + aa * above as f32) / area;
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, axis, x));
                }
            }
        }
        let leaf_cost = ci * n as f32;
        let Some((cost, axis, split)) = best else { return self.leaf(&prims) };
        let bad = if cost >= leaf_cost { bad + 1 } else { bad };
        if (cost > 4.0 * leaf_cost && n < 16) || bad > 3 {
            return self.leaf(&prims);
        }
        let (mut below, mut above) = (Vec::new(), Vec::new());
        for &p in &prims {
            let b = &self.boxes[p as usize];
            if b.min[axis] <= split {
                below.push(p);
            }
            if b.max[axis] >= split {
                above.push(p);
            }
        }
        if below.len() == n && above.len() == n {
            // Every primitive straddles the plane: splitting cannot help.
            return self.leaf(&prims);
        }
        drop(prims);
        let me = self.nodes.len();
        self.nodes.push(KdNode { split, axis: axis as u32, a: 0, b: 0 });
        let (mut bb, mut ba) = (bounds, bounds);
        bb.max[axis] = split;
        ba.min[axis] = split;
        self.build(bb, below, depth + 1, max_depth, bad);
        self.nodes[me].a = self.nodes.len() as u32;
        self.build(ba, above, depth + 1, max_depth, bad);
    }
}

impl OrderedWalk for KdTree {
    /// Visits leaves in front-to-back order; `visit(prims, t_exit)` returns false to stop.
    #[inline]
    fn walk(&self, ray: &Ray, t_max: f32, counter: &impl Counter, mut visit: impl FnMut(&[u32], f32) -> bool) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = ray.d.recip();
        let Some(t0) = self.bounds.slab(ray.o, inv, 0.0, t_max) else { return };
        let t1 = exit_distance(&self.bounds, ray, inv, t_max);
        let mut stack = [(0u32, 0.0f32, 0.0f32); MAX_STACK];
        let mut sp = 0;
        let (mut node, mut tmin, mut tmax) = (0usize, t0, t1);
        loop {
            counter.node();
            let n = &self.nodes[node];
            if n.axis == LEAF {
                let prims = &self.refs[n.a as usize..(n.a + n.b) as usize];
                if !visit(prims, tmax) {
                    return;
                }
                if sp == 0 {
                    return;
                }
                sp -= 1;
                (node, tmin, tmax) = (stack[sp].0 as usize, stack[sp].1, stack[sp].2);
                continue;
            }
            let a = n.axis as usize;
            let (o, d) = (ray.o[a], ray.d[a]);
            // The child on the origin's side comes first (the lower one if the origin lies on
            // the plane and the ray goes down).
            let below_first = o < n.split || (o == n.split && d <= 0.0);
            let (first, second) = if below_first { (node + 1, n.a as usize) } else { (n.a as usize, node + 1) };
            if d == 0.0 {
                node = first;
                continue;
            }
            let t_plane = (n.split - o) * inv[a];
            if t_plane > tmax || t_plane <= 0.0 {
                node = first;
            } else if t_plane < tmin {
                node = second;
            } else {
                if sp < MAX_STACK {
                    stack[sp] = (second as u32, t_plane, tmax);
                    sp += 1;
                }
                node = first;
                tmax = t_plane;
            }
        }
    }
}

/// Where the ray leaves the box (the box is known to be hit).
fn exit_distance(b: &Aabb, ray: &Ray, inv: glam::Vec3, t_max: f32) -> f32 {
    let mut t = t_max;
    for a in 0..3 {
        let far = if inv[a] < 0.0 { b.min[a] } else { b.max[a] };
        let tf = (far - ray.o[a]) * inv[a];
        if tf < t {
            t = tf;
        }
    }
    t * crate::geometry::EXIT_ROUNDING
}

impl Accel for KdTree {
    type Params = KdParams;

    fn build(boxes: &[Aabb], params: &KdParams) -> Self {
        let prims: Vec<u32> = (0..boxes.len() as u32).filter(|&i| !boxes[i as usize].is_empty()).collect();
        let bounds = prims.iter().fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]));
        let n = prims.len().max(1) as f32;
        let auto_depth = (8.0 + 1.3 * n.log2()).round() as usize;
        let max_depth = if params.max_depth == 0 { auto_depth } else { params.max_depth }.min(MAX_STACK - 1);
        let mut b = Builder { boxes, p: *params, nodes: Vec::new(), refs: Vec::new(), depth: 0 };
        if !prims.is_empty() {
            b.build(bounds, prims, 0, max_depth, 0);
        }
        let leaves = b.nodes.iter().filter(|n| n.axis == LEAF).count();
        let stats = AccelStats {
            nodes: b.nodes.len(),
            leaves,
            max_depth: b.depth,
            prim_refs: b.refs.len(),
            bytes: b.nodes.len() * std::mem::size_of::<KdNode>() + b.refs.len() * 4,
            sah_cost: kd_sah_cost(&b.nodes, bounds, &params.base),
        };
        KdTree { bounds, nodes: b.nodes, refs: b.refs, stats }
    }

    fn closest_counted(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.walk_closest(ray, t_max, test, counter)
    }

    fn any_counted(&self, ray: &Ray, t_max: f32, test: impl FnMut(u32, f32) -> bool, counter: &impl Counter) -> bool {
        self.walk_any(ray, t_max, test, counter)
    }

    fn boxes_at_depth(&self, depth: usize) -> Vec<Aabb> {
        let mut out = Vec::new();
        let mut todo = if self.nodes.is_empty() { Vec::new() } else { vec![(0usize, self.bounds, 0usize)] };
        while let Some((i, b, d)) = todo.pop() {
            if d == depth {
                out.push(b);
                continue;
            }
            let n = &self.nodes[i];
            if n.axis != LEAF {
                let a = n.axis as usize;
                let (mut lo, mut hi) = (b, b);
                lo.max[a] = n.split;
                hi.min[a] = n.split;
                todo.push((i + 1, lo, d + 1));
                todo.push((n.a as usize, hi, d + 1));
            }
        }
        out
    }

    fn stats(&self) -> AccelStats {
        self.stats
    }
}

/// SAH cost of the tree relative to the root box's area.
fn kd_sah_cost(nodes: &[KdNode], bounds: Aabb, p: &AccelParams) -> f32 {
    if nodes.is_empty() {
        return 0.0;
    }
    let root = bounds.half_area().max(f32::MIN_POSITIVE);
    let mut cost = 0.0f64;
    let mut stack = vec![(0usize, bounds)];
    while let Some((i, b)) = stack.pop() {
        let n = &nodes[i];
        let a = (b.half_area() / root) as f64;
        if n.axis == LEAF {
            cost += a * (p.intersect_cost * n.b as f32) as f64;
        } else {
            cost += a * p.traversal_cost as f64;
            let ax = n.axis as usize;
            let (mut lo, mut hi) = (b, b);
            lo.max[ax] = n.split;
            hi.min[ax] = n.split;
            stack.push((i + 1, lo));
            stack.push((n.a as usize, hi));
        }
    }
    cost as f32
}
