//! Bounding volume hierarchy built top down, with the lecture's three split rules.
//!
//! Every primitive goes to exactly one child, chosen by its box centre; a primitive that
//! straddles the split plane therefore lands on one side and grows that child's box (so
//! sibling boxes may overlap, which is what makes a BVH a BVH rather than a k-d tree).
//! Recursion stops at `max_leaf_prims` primitives or at depth `max_depth` (24 by default).
//!
//! Layout: 32-byte nodes in one array; the two children of an interior node are adjacent
//! (`first`, `first + 1`), so traversal tests both boxes and descends into the nearer first.

use super::{Accel, AccelParams, AccelStats, BvhParams};
use crate::geometry::{Aabb, Ray};

/// How a node's primitives are divided between its two children.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SplitMethod {
    /// At the middle of the widest axis of the centroid bounds.
    Center,
    /// Equal counts on the widest axis of the centroid bounds.
    Median,
    /// Binned surface area heuristic (16 bins on each axis).
    Sah,
}

#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Node {
    min: [f32; 3],
    /// Leaf: index of the first primitive in `prims`; interior: index of the left child.
    first: u32,
    max: [f32; 3],
    /// Leaf: number of primitives (> 0); interior: 0.
    count: u32,
}

impl Node {
    #[inline]
    fn aabb(&self) -> Aabb {
        Aabb {
            min: self.min.into(),
            max: self.max.into(),
        }
    }
}

/// A binary BVH over primitive boxes.
pub struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<u32>,
    stats: AccelStats,
}

/// Deepest tree traversal supports (the build clamps `max_depth` to it).
const MAX_STACK: usize = 64;
const BINS: usize = 16;

struct Builder<'a> {
    boxes: &'a [Aabb],
    centroids: Vec<glam::Vec3>,
    params: AccelParams,
    split: SplitMethod,
    nodes: Vec<Node>,
    max_depth_seen: usize,
    leaves: usize,
}

impl Builder<'_> {
    fn bounds(&self, prims: &[u32]) -> (Aabb, Aabb) {
        prims.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), &p| {
            (
                b.union(self.boxes[p as usize]),
                c.grow(self.centroids[p as usize]),
            )
        })
    }

    fn make_leaf(&mut self, node: usize, offset: usize, n: usize) {
        self.nodes[node].first = offset as u32;
        self.nodes[node].count = n as u32;
        self.leaves += 1;
    }

    /// Builds node `node` over `prims`, which sit at `offset` in the final primitive array.
    fn build(&mut self, node: usize, prims: &mut [u32], offset: usize, depth: usize) {
        let (bounds, cbounds) = self.bounds(prims);
        self.nodes[node].min = bounds.min.into();
        self.nodes[node].max = bounds.max.into();
        self.max_depth_seen = self.max_depth_seen.max(depth);
        let n = prims.len();
        if n <= self.params.max_leaf_prims || depth >= self.params.max_depth {
            return self.make_leaf(node, offset, n);
        }
        let mid = self.partition(prims, &bounds, &cbounds);
        let left = self.nodes.len();
        let empty = Node {
            min: [0.0; 3],
            first: 0,
            max: [0.0; 3],
            count: 0,
        };
        self.nodes.push(empty);
        self.nodes.push(empty);
        self.nodes[node].first = left as u32;
        self.nodes[node].count = 0;
        let (l, r) = prims.split_at_mut(mid);
        self.build(left, l, offset, depth + 1);
        self.build(left + 1, r, offset + mid, depth + 1);
    }

    /// Reorders `prims` and returns the split index, always in `1..n`.
    fn partition(&self, prims: &mut [u32], bounds: &Aabb, cbounds: &Aabb) -> usize {
        let n = prims.len();
        let axis = cbounds.largest_axis();
        let c = &self.centroids;
        if cbounds.extent()[axis] <= 0.0 {
            // All centroids coincide: no plane separates them; split the list in half.
            return n / 2;
        }
        let mid = match self.split {
            SplitMethod::Center => {
                let plane = cbounds.center()[axis];
                partition_in_place(prims, |p| c[p as usize][axis] < plane)
            }
            SplitMethod::Median => n / 2,
            SplitMethod::Sah => return self.sah_partition(prims, bounds, cbounds),
        };
        if mid == 0 || mid == n || self.split == SplitMethod::Median {
            prims.select_nth_unstable_by(n / 2, |&a, &b| {
                c[a as usize][axis].total_cmp(&c[b as usize][axis])
            });
            return n / 2;
        }
        mid
    }

    #[allow(clippy::needless_range_loop)]
    fn sah_partition(&self, prims: &mut [u32], bounds: &Aabb, cbounds: &Aabb) -> usize {
        let c = &self.centroids;
        let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, bins on the left
        for axis in 0..3 {
            let lo = cbounds.min[axis];
            let ext = cbounds.extent()[axis];
            if ext <= 0.0 {
                continue;
            }
            let scale = BINS as f32 / ext;
            let mut bin_box = [Aabb::EMPTY; BINS];
            let mut bin_n = [0usize; BINS];
            for &p in prims.iter() {
                let b = (((c[p as usize][axis] - lo) * scale) as usize).min(BINS - 1);
                bin_n[b] += 1;
                bin_box[b] = bin_box[b].union(self.boxes[p as usize]);
            }
            // Sweep from the right, then from the left.
            let mut right_area = [0.0f32; BINS];
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
            let mut right_n = [0usize; BINS];
            for i in (1..BINS).rev() {
                acc = acc.union(bin_box[i]);
                cnt += bin_n[i];
                right_area[i] = acc.half_area();
                right_n[i] = cnt;
            }
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
            for i in 0..BINS - 1 {
                acc = acc.union(bin_box[i]);
                cnt += bin_n[i];
                let (nl, nr) = (cnt, right_n[i + 1]);
                if nl == 0 || nr == 0 {
                    continue;
                }
                let cost = acc.half_area() * nl as f32 + right_area[i + 1] * nr as f32;
                if cost < best.0 {
                    best = (cost, axis, i + 1);
                }
            }
        }
        let n = prims.len();
        if !best.0.is_finite() {
            return n / 2;
        }
        let (_, axis, split_bin) = best;
        let lo = cbounds.min[axis];
        let scale = BINS as f32 / cbounds.extent()[axis];
        let _ = bounds;
        let mid = partition_in_place(prims, |p| {
            (((c[p as usize][axis] - lo) * scale) as usize).min(BINS - 1) < split_bin
        });
        if mid == 0 || mid == n {
            n / 2
        } else {
            mid
        }
    }
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
fn partition_in_place(v: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        if pred(v[j]) {
            v.swap(i, j);
            i += 1;
        }
    }
    i
}

impl Bvh {
    fn compute_stats(&mut self, params: &AccelParams) {
        let root_area = self.nodes.first().map_or(0.0, |n| n.aabb().half_area());
        let mut sah = 0.0f64;
        for n in &self.nodes {
            let a = if root_area > 0.0 {
                (n.aabb().half_area() / root_area) as f64
            } else {
                1.0
            };
            sah += if n.count > 0 {
                a * params.intersect_cost as f64 * n.count as f64
            } else {
                a * params.traversal_cost as f64
            };
        }
        self.stats.nodes = self.nodes.len();
        self.stats.prim_refs = self.prims.len();
        self.stats.bytes = self.nodes.len() * std::mem::size_of::<Node>() + self.prims.len() * 4;
        self.stats.sah_cost = sah as f32;
    }
}

impl Accel for Bvh {
    type Params = BvhParams;

    fn build(boxes: &[Aabb], params: &BvhParams) -> Self {
        let mut prims: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| !boxes[i as usize].is_empty())
            .collect();
        let mut base = params.base;
        base.max_depth = base.max_depth.min(MAX_STACK - 1);
        base.max_leaf_prims = base.max_leaf_prims.max(1);
        let mut b = Builder {
            boxes,
            centroids: boxes.iter().map(|b| b.center()).collect(),
            params: base,
            split: params.split,
            nodes: Vec::with_capacity(2 * prims.len() / base.max_leaf_prims.max(1) + 1),
            max_depth_seen: 0,
            leaves: 0,
        };
        if !prims.is_empty() {
            b.nodes.push(Node {
                min: [0.0; 3],
                first: 0,
                max: [0.0; 3],
                count: 0,
            });
            b.build(0, &mut prims, 0, 0);
        }
        let stats = AccelStats {
            max_depth: b.max_depth_seen,
            leaves: b.leaves,
            ..Default::default()
        };
        let mut bvh = Bvh {
            nodes: b.nodes,
            prims,
            stats,
        };
        bvh.compute_stats(&base);
        bvh
    }

    fn closest(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        let Some(root) = self.nodes.first() else {
            return false;
        };
        let inv_d = ray.d.recip();
        if root.aabb().slab(ray.o, inv_d, 0.0, *t_max).is_none() {
            return false;
        }
        let mut stack = [(0u32, 0.0f32); MAX_STACK];
        let mut sp = 0usize;
        let mut node = 0usize;
        let mut hit = false;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                let first = n.first as usize;
                for &p in &self.prims[first..first + n.count as usize] {
                    if let Some(t) = test(p, *t_max) {
                        *t_max = t;
                        hit = true;
                    }
                }
            } else {
                let l = n.first as usize;
                let dl = self.nodes[l].aabb().slab(ray.o, inv_d, 0.0, *t_max);
                let dr = self.nodes[l + 1].aabb().slab(ray.o, inv_d, 0.0, *t_max);
                match (dl, dr) {
                    (Some(a), Some(b)) => {
                        let (near, far, tfar) = if a <= b { (l, l + 1, b) } else { (l + 1, l, a) };
                        stack[sp] = (far as u32, tfar);
                        sp += 1;
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = l + 1;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next node that may still hold a closer hit.
            loop {
                if sp == 0 {
                    return hit;
                }
                sp -= 1;
                let (nd, t_enter) = stack[sp];
                if t_enter <= *t_max {
                    node = nd as usize;
                    break;
                }
            }
        }
    }

    fn any(&self, ray: &Ray, t_max: f32, mut test: impl FnMut(u32, f32) -> bool) -> bool {
        let Some(root) = self.nodes.first() else {
            return false;
        };
        let inv_d = ray.d.recip();
        if root.aabb().slab(ray.o, inv_d, 0.0, t_max).is_none() {
            return false;
        }
        let mut stack = [0u32; MAX_STACK];
        let mut sp = 0usize;
        let mut node = 0usize;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                let first = n.first as usize;
                if self.prims[first..first + n.count as usize]
                    .iter()
                    .any(|&p| test(p, t_max))
                {
                    return true;
                }
            } else {
                let l = n.first as usize;
                let hl = self.nodes[l]
                    .aabb()
                    .slab(ray.o, inv_d, 0.0, t_max)
                    .is_some();
                let hr = self.nodes[l + 1]
                    .aabb()
                    .slab(ray.o, inv_d, 0.0, t_max)
                    .is_some();
                if hl {
                    if hr {
                        stack[sp] = (l + 1) as u32;
                        sp += 1;
                    }
                    node = l;
                    continue;
                } else if hr {
                    node = l + 1;
                    continue;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node = stack[sp] as usize;
        }
    }

    fn stats(&self) -> AccelStats {
        self.stats
    }
}
