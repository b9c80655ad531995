//! Bounding volume hierarchy built top down, with the lecture's three split rules.
//!
//! Every primitive goes to exactly one child, chosen by its box centre; a primitive that
//! straddles the split plane therefore lands on one side and grows that child's box (so
//! sibling boxes may overlap, which is what makes a BVH a BVH rather than a k-d tree).
//! Recursion stops at `max_leaf_prims` primitives or at depth `max_depth` (24 by default); the
//! SAH split also stops at up to `sah_leaf_max` (8) primitives where a leaf is cheaper than any
//! split. Leaf triangles are tested four at a time (see [`crate::shape::Tri4`]), so the SAH counts
//! a leaf's cost in blocks of four (`leaf_block`), which keeps the blocks full.
//!
//! Build layout ≠ traversal layout (as in tinybvh): the builder makes a binary tree of 32-byte
//! nodes, which is then collapsed into an 8-wide tree ([`WIDTH`]) whose nodes hold the boxes of
//! their eight children in structure-of-arrays form, so that one slab test checks all eight
//! (the AVX2 and AVX-512 walks in one instruction per plane, the portable walk in two
//! four-wide halves). Traversal visits the children nearest first and skips stacked nodes
//! that lie beyond the closest hit.

use super::{Accel, AccelParams, AccelStats, BvhParams, Counter};
use crate::geometry::{Aabb, Ray, EXIT_ROUNDING};
use glam::Vec3A;

/// How a node's primitives are divided between its two children.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SplitMethod {
    /// At the middle of the widest axis of the centroid bounds.
    Center,
    /// Equal counts on the widest axis of the centroid bounds.
    Median,
    /// Binned surface area heuristic (16 bins on each axis).
    Sah,
    /// SAH with spatial splits (Stich, Friedrich and Dietrich 2009): where the children of the
    /// best object split overlap, the node may instead be cut by a plane, with primitives that
    /// straddle it clipped into both children. Fewer overlapping boxes, some primitives
    /// referenced twice (the references may grow by at most `SBVH_BUDGET`, 30 %, of the count).
    Spatial,
    /// LBVH (Lauterbach et al. 2009, Karras 2012): primitives sorted once along a Morton
    /// (Z-order) curve of their centres; each node splits where the highest differing bit of
    /// the codes flips, so the hierarchy is the radix tree of the codes, built from the
    /// sorted leaves without any cost evaluation.
    Morton,
}

/// Spatial splits may add this fraction of the primitive count as extra references.
pub const SBVH_BUDGET: f32 = 0.3;
/// Spatial splits are tried where the object split's children overlap by more than this
/// fraction of the root's surface area (Stich et al.'s α).
const SBVH_ALPHA: f32 = 1e-5;
const SPATIAL_BINS: usize = 32;

/// A primitive reference of the spatial-split builder: the primitive and the box of its part.
#[derive(Clone, Copy)]
struct Ref {
    prim: u32,
    b: Aabb,
}

/// The spatial-split builder. Subtrees come back as (nodes, primitive references) with leaf
/// `first` relative to the subtree's references and interior `first` relative to its nodes.
struct SpatialBuilder<'a> {
    clip: &'a super::Clipper<'a>,
    params: AccelParams,
    root_area: f32,
    budget: std::sync::atomic::AtomicIsize,
}

impl SpatialBuilder<'_> {
    fn build(&self, refs: Vec<Ref>, depth: usize) -> (Vec<Node>, Vec<u32>) {
        let bounds = refs.iter().fold(Aabb::EMPTY, |a, r| a.union(r.b));
        let n = refs.len();
        let leaf = |refs: &[Ref]| {
            (
                vec![Node { min: bounds.min.into(), first: 0, max: bounds.max.into(), count: refs.len() as u32 }],
                refs.iter().map(|r| r.prim).collect::<Vec<u32>>(),
            )
        };
        if n <= self.params.max_leaf_prims || depth >= self.params.max_depth {
            return leaf(&refs);
        }
        let (left, right) = self.split(refs, &bounds);
        let ((ln, lp), (rn, rp)) = if n >= PARALLEL_BUILD_MIN {
            rayon::join(|| self.build(left, depth + 1), || self.build(right, depth + 1))
        } else {
            (self.build(left, depth + 1), self.build(right, depth + 1))
        };
        let mut nodes = Vec::with_capacity(1 + ln.len() + rn.len());
        nodes.push(Node { min: bounds.min.into(), first: (1 + ln.len()) as u32, max: bounds.max.into(), count: 0 });
        let reloc = |n: &Node, node_off: usize, prim_off: usize| {
            if n.count == 0 {
                Node { first: n.first + node_off as u32, ..*n }
            } else {
                Node { first: n.first + prim_off as u32, ..*n }
            }
        };
        nodes.extend(ln.iter().map(|n| reloc(n, 1, 0)));
        let (roff, poff) = (1 + ln.len(), lp.len());
        nodes.extend(rn.iter().map(|n| reloc(n, roff, poff)));
        let mut prims = lp;
        prims.extend(rp);
        (nodes, prims)
    }

    /// The better of the best binned object split and the best spatial split.
    #[allow(clippy::needless_range_loop)]
    fn split(&self, mut refs: Vec<Ref>, bounds: &Aabb) -> (Vec<Ref>, Vec<Ref>) {
        let n = refs.len();
        let cb = refs.iter().fold(Aabb::EMPTY, |a, r| a.grow(r.b.center()));
        // Object split: binned SAH on the centres (16 bins per axis).
        let mut best_o = (f32::INFINITY, 0usize, 0usize, Aabb::EMPTY, Aabb::EMPTY);
        for axis in 0..3 {
            let ext = cb.extent()[axis];
            if ext <= 0.0 {
                continue;
            }
            let scale = BINS as f32 / ext;
            let bin = |r: &Ref| (((r.b.center()[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
            let mut bb = Bins::<BINS>::new();
            let mut bn = [0usize; BINS];
            for r in &refs {
                let k = bin(r);
                bb.grow_box(k, r.b);
                bn[k] += 1;
            }
            if let Some((cost, k)) = sah_sweep(&bb, &bn, &bn, self.params.leaf_block) {
                if cost < best_o.0 {
                    best_o = (cost, axis, k, bb.union(0..k), bb.union(k..BINS));
                }
            }
        }
        // Spatial split, where the object split's children overlap enough and budget remains.
        let overlap = Aabb { min: best_o.3.min.max(best_o.4.min), max: best_o.3.max.min(best_o.4.max) };
        let try_spatial =
            best_o.0.is_infinite() || (!overlap.is_empty() && overlap.half_area() > SBVH_ALPHA * self.root_area);
        let mut best_s = (f32::INFINITY, 0usize, 0.0f32);
        if try_spatial && self.budget.load(std::sync::atomic::Ordering::Relaxed) > 0 {
            for axis in 0..3 {
                let (lo, ext) = (bounds.min[axis], bounds.extent()[axis]);
                if ext <= 0.0 {
                    continue;
                }
                let w = ext / SPATIAL_BINS as f32;
                let bin = |x: f32| (((x - lo) / w) as usize).min(SPATIAL_BINS - 1);
                let mut bb = Bins::<SPATIAL_BINS>::new();
                let mut enter = [0usize; SPATIAL_BINS];
                let mut exit = [0usize; SPATIAL_BINS];
                for r in &refs {
                    let (b0, b1) = (bin(r.b.min[axis]), bin(r.b.max[axis]));
                    enter[b0] += 1;
                    exit[b1] += 1;
                    let mut part = r.b;
                    for k in b0..b1 {
                        let (l, rest) = (self.clip)(r.prim, &part, axis, lo + (k + 1) as f32 * w);
                        bb.grow_box(k, l);
                        part = rest;
                    }
                    bb.grow_box(b1, part);
                }
                if let Some((cost, k)) = sah_sweep(&bb, &enter, &exit, self.params.leaf_block) {
                    if cost < best_s.0 {
                        best_s = (cost, axis, lo + k as f32 * w);
                    }
                }
            }
        }
        if best_s.0 < best_o.0 {
            let (_, axis, pos) = best_s;
            let (mut left, mut right) = (Vec::with_capacity(n), Vec::with_capacity(n));
            let mut added = 0isize;
            for r in refs {
                if r.b.max[axis] <= pos {
                    left.push(r);
                } else if r.b.min[axis] >= pos {
                    right.push(r);
                } else {
                    let (l, h) = (self.clip)(r.prim, &r.b, axis, pos);
                    match (l.is_empty(), h.is_empty()) {
                        (false, false) => {
                            left.push(Ref { prim: r.prim, b: l });
                            right.push(Ref { prim: r.prim, b: h });
                            added += 1;
                        }
                        (false, true) => left.push(Ref { prim: r.prim, b: l }),
                        (true, false) => right.push(Ref { prim: r.prim, b: h }),
                        (true, true) => left.push(r),
                    }
                }
            }
            self.budget.fetch_sub(added, std::sync::atomic::Ordering::Relaxed);
            if !left.is_empty() && !right.is_empty() {
                return (left, right);
            }
            refs = left.into_iter().chain(right).collect();
        }
        if best_o.0.is_finite() {
            let (_, axis, split_bin, _, _) = best_o;
            let scale = BINS as f32 / cb.extent()[axis];
            let (left, right): (Vec<Ref>, Vec<Ref>) = refs
                .into_iter()
                .partition(|r| ((((r.b.center()[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1)) < split_bin);
            if !left.is_empty() && !right.is_empty() {
                return (left, right);
            }
            let mut all = left;
            all.extend(right);
            refs = all;
        }
        let right = refs.split_off(refs.len() / 2);
        (refs, right)
    }
}

/// Spreads the low 10 bits of `v` to every third bit.
fn spread_bits(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// 30-bit Morton code of `p` inside `b` (10 bits per axis).
fn morton(p: glam::Vec3, b: &Aabb) -> u32 {
    let e = b.extent().max(glam::Vec3::splat(f32::MIN_POSITIVE));
    let q = ((p - b.min) / e * 1023.0).clamp(glam::Vec3::ZERO, glam::Vec3::splat(1023.0));
    (spread_bits(q.x as u32) << 2) | (spread_bits(q.y as u32) << 1) | spread_bits(q.z as u32)
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
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// Children per node of the traversed tree.
pub const WIDTH: usize = 8;
const _: () = assert!(WIDTH.is_multiple_of(4), "the slab test takes the children four at a time");
const _: () = assert!(std::mem::size_of::<Wide>() == 28 * WIDTH, "no padding in a node");

/// A wide node: the boxes of up to [`WIDTH`] children, structure of arrays. 224 bytes, aligned
/// to 32: four cache lines at most wherever it starts, as with 64-byte alignment, without
/// padding it to 256.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Wide {
    /// min x, min y, min z, max x, max y, max z, each for the children.
    bounds: [[f32; WIDTH]; 6],
    /// Child references: an interior node's reference ([`node_ref`]), or `LEAF | index into
    /// leaves`, or `EMPTY`.
    child: [u32; WIDTH],
}

impl Wide {
    const EMPTY: Wide = Wide {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [EMPTY; WIDTH],
    };
}

const LEAF: u32 = 1 << 31;
const EMPTY: u32 = u32::MAX;

/// Interior references count in 8-byte units: node `i` is `i · NODE_UNITS`, its byte offset
/// over 8. The traversal reads a row of a node's bounds at `row of node 0 + reference · 8`
/// ([`Rows`]), a single x86 address (base plus index times 8): no instruction stands between a
/// child's reference, just loaded, and the loads of its bounds. (In 32-byte units a shift and an
/// add stood there, and before that a multiply by 224.)
const UNIT_BYTES: usize = 8;
const NODE_UNITS: usize = std::mem::size_of::<Wide>() / UNIT_BYTES;
const _: () = assert!(std::mem::size_of::<Wide>() == NODE_UNITS * UNIT_BYTES && std::mem::align_of::<Wide>() == 32);

/// Where the AVX slab test reads one node's six rows of bounds: the rows of a ray's near planes
/// (x, y, z) and then of its far planes ([`RayPre::near`], [`RayPre::far`]) in node 0 of an array
/// of nodes, and the node's reference, so that row `k` is at `base[k] + unit · UNIT_BYTES`.
///
/// A walk makes `base` once per ray ([`Rows::tree`]) and reads each row with one load whose
/// address is that sum ([`Rows::load`], written in `asm`). Written as pointer arithmetic, the
/// compiler computed the node's address (or `unit · 8`) into a register first and added each
/// row's offset in the load, even from six opaque row pointers: one more instruction on the
/// chain from a child's reference to its bounds, which is most of what a node visit waits on. Single rays 1–5 % faster on an AMD Zen 3 (the
/// bench's meshes, paired; MEASUREMENTS.md, sixty-ninth session), renders unchanged.
#[derive(Clone, Copy)]
struct Rows {
    base: [*const u8; 6],
    unit: usize,
}

impl Rows {
    /// The six rows' offsets into a node for `r`, near planes first.
    #[inline(always)]
    fn offsets(r: &RayPre) -> [usize; 6] {
        [r.near[0], r.near[1], r.near[2], r.far[0], r.far[1], r.far[2]]
    }

    /// The rows of node `n` itself.
    #[inline(always)]
    fn of(n: &Wide, r: &RayPre) -> Rows {
        let b = (n as *const Wide).cast::<u8>();
        Rows { base: Rows::offsets(r).map(|o| b.wrapping_add(o)), unit: 0 }
    }

    /// The rows of node 0 of `nodes` for the ray `r`, for [`Rows::at`].
    #[inline(always)]
    fn tree(nodes: &[Wide], r: &RayPre) -> [*const u8; 6] {
        let b = nodes.as_ptr().cast::<u8>();
        Rows::offsets(r).map(|o| b.wrapping_add(o))
    }

    /// The rows of the node with interior reference `r` (of the array `base` was made for).
    ///
    /// # Safety
    /// `r` must be an interior reference of that array (the rows then lie in its node).
    #[inline(always)]
    unsafe fn at(base: &[*const u8; 6], r: u32) -> Rows {
        Rows { base: *base, unit: r as usize }
    }

    /// Row `k` (0–2 the near planes' x, y, z, 3–5 the far planes'): one unaligned 32-byte
    /// load addressing `base[k] + unit · 8`.
    ///
    /// # Safety
    /// The CPU must support AVX. (The row lies in a node: a `Rows` is made only by
    /// [`Rows::of`], or by [`Rows::at`] for a reference its caller vouches for.)
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn load(self, k: usize) -> std::arch::x86_64::__m256 {
        const { assert!(UNIT_BYTES == 8, "the load's index scale") };
        let v: std::arch::x86_64::__m256;
        // SAFETY: 32 bytes of a node's bounds (see above), read without side effects.
        unsafe {
            std::arch::asm!(
                "vmovups {v}, ymmword ptr [{b} + {i}*8]",
                v = out(ymm_reg) v,
                b = in(reg) self.base[k],
                i = in(reg) self.unit,
                options(pure, readonly, nostack, preserves_flags)
            )
        };
        v
    }
}

/// The reference of interior node `index`.
fn node_ref(index: usize) -> u32 {
    assert!(index < (LEAF as usize) / NODE_UNITS, "more BVH nodes than references can address");
    (index * NODE_UNITS) as u32
}

/// The index of the node an interior reference names.
fn node_index(r: u32) -> usize {
    r as usize / NODE_UNITS
}

/// A BVH over primitive boxes (built binary, traversed 8-wide).
pub struct Bvh {
    nodes: Vec<Wide>,
    /// `(first, count)` ranges of `prims`.
    leaves: Vec<(u32, u32)>,
    prims: Vec<u32>,
    /// Whether the root is itself a leaf (then `leaves[0]` holds everything).
    root_leaf: bool,
    /// The reference the traversals start from when the root is a leaf: `LEAF` and its label.
    root_ref: u32,
    /// Whether the leaf references in the nodes carry the caller's labels
    /// ([`Accel::relabel_leaves`]) rather than indices into `leaves`.
    relabeled: bool,
    /// Bounds of everything: tested first where the root is a leaf, so that a ray that misses
    /// a small mesh entirely costs one box test (a 2-triangle quad has no node of its own to
    /// cull with). A root node's own test of its children's boxes culls the same rays.
    root_box: Aabb,
    stats: AccelStats,
    /// Whether this CPU has AVX2: single rays then test a node's eight boxes in one register,
    /// and packets run in AVX2 lanes.
    avx: bool,
    /// Whether it has AVX-512 as well ([`has_avx512`]): [`Accel::closest_leaf_inlined`] and
    /// [`Accel::any_leaf_inlined`] then run the walks compiled for it.
    avx512: bool,
}

/// Whether the CPU running this has AVX2, FMA and POPCNT (checked once per build; every CPU
/// with AVX2 so far has the other two as well, which the single-ray walks use).
pub(crate) fn has_avx2_fma_popcnt() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether the CPU running this has AVX-512 (F, VL, BW and DQ) besides AVX2, FMA and POPCNT:
/// the walks then have 32 vector registers, enough to keep the ray's constants in registers
/// across a leaf test inlined into the walk ([`Accel::closest_leaf_inlined`]).
pub(crate) fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        has_avx2_fma_popcnt()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512dq")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Deepest tree traversal supports (the build clamps `max_depth` to it).
const MAX_STACK: usize = 64;
const BINS: usize = 16;

/// The binary builder. It only reads shared data, so subtrees build in parallel.
///
/// Binary layout: depth first. An interior node's left child is the next node; `first` holds
/// the index of its right child.
struct Builder {
    params: AccelParams,
    split: SplitMethod,
    /// Subtrees with at least this many primitives are built as separate tasks
    /// ([`Builder::parallel_min`]).
    parallel_min: usize,
}

/// A primitive reference of the builder: its box, id and Morton code in one 32-byte record,
/// so that binning and partitioning stream through memory instead of gathering by index.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct PRef {
    min: [f32; 3],
    id: u32,
    max: [f32; 3],
    /// Morton code of the centre (only for [`SplitMethod::Morton`]).
    code: u32,
}

impl PRef {
    /// Centre on `axis` (the same arithmetic as [`Aabb::center`]).
    #[inline(always)]
    fn c(&self, axis: usize) -> f32 {
        (self.min[axis] + self.max[axis]) * 0.5
    }

    #[inline(always)]
    fn aabb(&self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }

    /// `(min, max, centre)` as SIMD vectors (the centre with [`PRef::c`]'s arithmetic).
    #[inline(always)]
    fn simd(&self) -> (Vec3A, Vec3A, Vec3A) {
        let (lo, hi) = (Vec3A::from_array(self.min), Vec3A::from_array(self.max));
        (lo, hi, (lo + hi) * 0.5)
    }
}

/// Subtrees with more primitives than this are always built as separate tasks.
const PARALLEL_BUILD_MIN: usize = 16 * 1024;

impl Builder {
    /// The smallest subtree built as a task of its own, for `n` primitives in all: about a
    /// sixteenth of them, between 4096 and [`PARALLEL_BUILD_MIN`]. A small mesh then still
    /// makes enough tasks for the threads to share the work evenly at the end (the bunny's
    /// 69,451 triangles made four of 16384 or more), and a large one no more than it needs.
    fn parallel_min(n: usize) -> usize {
        (n / 16).clamp(4096, PARALLEL_BUILD_MIN)
    }

    /// Bounds of the boxes and of their centres.
    fn bounds(&self, prims: &[PRef]) -> (Aabb, Aabb) {
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let (mut clo, mut chi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for p in prims {
            let (pmin, pmax, c) = p.simd();
            lo = lo.min(pmin);
            hi = hi.max(pmax);
            clo = clo.min(c);
            chi = chi.max(c);
        }
        if prims.is_empty() {
            return (Aabb::EMPTY, Aabb::EMPTY);
        }
        (Aabb { min: lo.into(), max: hi.into() }, Aabb { min: clo.into(), max: chi.into() })
    }

    /// Appends the subtree over `prims` (which sit at `offset` in the final primitive array)
    /// to `out`, depth first, with node indices relative to `base + out.len()`.
    fn build_into(&self, out: &mut Vec<Node>, base: usize, prims: &mut [PRef], offset: usize, depth: usize) {
        let (bounds, cbounds) = self.bounds(prims);
        let n = prims.len();
        let me = out.len();
        out.push(Node { min: bounds.min.into(), first: offset as u32, max: bounds.max.into(), count: n as u32 });
        if n <= self.params.max_leaf_prims || depth >= self.params.max_depth {
            return;
        }
        let mid = self.partition(prims, &bounds, &cbounds);
        if mid == 0 {
            return; // the SAH prefers a leaf
        }
        let (l, r) = prims.split_at_mut(mid);
        if n >= self.parallel_min {
            let (ln, rn) =
                rayon::join(|| self.subtree(l, offset, depth + 1), || self.subtree(r, offset + mid, depth + 1));
            let left_at = base + out.len();
            append_relocated(out, &ln, left_at);
            let right_at = base + out.len();
            append_relocated(out, &rn, right_at);
            out[me].first = right_at as u32;
        } else {
            self.build_into(out, base, l, offset, depth + 1);
            out[me].first = (base + out.len()) as u32;
            self.build_into(out, base, r, offset + mid, depth + 1);
        }
        out[me].count = 0;
    }

    /// A subtree in its own vector, indices relative to its start.
    fn subtree(&self, prims: &mut [PRef], offset: usize, depth: usize) -> Vec<Node> {
        let mut v = Vec::with_capacity(2 * prims.len() / self.params.max_leaf_prims + 1);
        self.build_into(&mut v, 0, prims, offset, depth);
        v
    }

    /// Reorders `prims` and returns the split index, in `1..n`, or 0 for "make a leaf".
    fn partition(&self, prims: &mut [PRef], bounds: &Aabb, cbounds: &Aabb) -> usize {
        let n = prims.len();
        if self.split == SplitMethod::Morton {
            return self.morton_partition(prims);
        }
        let axis = cbounds.largest_axis();
        if cbounds.extent()[axis] <= 0.0 {
            // All centroids coincide: no plane separates them; split the list in half.
            return n / 2;
        }
        let mid = match self.split {
            SplitMethod::Center => {
                let plane = cbounds.center()[axis];
                partition_in_place(prims, |p| p.c(axis) < plane)
            }
            SplitMethod::Median => n / 2,
            SplitMethod::Sah => return self.sah_partition(prims, bounds, cbounds),
            SplitMethod::Morton | SplitMethod::Spatial => unreachable!("handled elsewhere"),
        };
        if mid == 0 || mid == n || self.split == SplitMethod::Median {
            prims.select_nth_unstable_by(n / 2, |a, b| a.c(axis).total_cmp(&b.c(axis)));
            return n / 2;
        }
        mid
    }

    /// `prims` is sorted by Morton code: split where the highest bit in which the first and
    /// last codes differ turns from 0 to 1 (in the middle if all codes are equal).
    fn morton_partition(&self, prims: &[PRef]) -> usize {
        let n = prims.len();
        let (first, last) = (prims[0].code, prims[n - 1].code);
        if first == last {
            return n / 2;
        }
        let bit = 31 - (first ^ last).leading_zeros();
        let mid = prims.partition_point(|p| p.code & (1 << bit) == 0);
        mid.clamp(1, n - 1)
    }

    /// The binned SAH split: [`SMALL_BINS`] bins per axis for a node of at most
    /// [`SMALL_NODE`] references, [`BINS`] otherwise.
    fn sah_partition(&self, prims: &mut [PRef], bounds: &Aabb, cbounds: &Aabb) -> usize {
        if prims.len() <= SMALL_NODE {
            self.sah_partition_in::<SMALL_BINS>(prims, bounds, cbounds)
        } else {
            self.sah_partition_in::<BINS>(prims, bounds, cbounds)
        }
    }

    #[allow(clippy::needless_range_loop)]
    fn sah_partition_in<const NB: usize>(&self, prims: &mut [PRef], bounds: &Aabb, cbounds: &Aabb) -> usize {
        // (cost, axis, bins on the left). One pass over the primitives bins all three axes.
        let mut best = (f32::INFINITY, 0usize, 0usize);
        let lo = cbounds.min.to_array();
        let ext = cbounds.extent().to_array();
        let scale = ext.map(|e| if e > 0.0 { NB as f32 / e } else { 0.0 });
        let (lo_v, scale_v) = (Vec3A::from_array(lo), Vec3A::from_array(scale));
        let bin = |prims: &[PRef]| bin_refs::<NB>(prims, lo_v, scale_v);
        // A large node (the root and the first levels, where the other threads would wait)
        // is binned in parallel pieces, then merged: unions and sums, the same bins.
        let (bins, bin_n) = if prims.len() >= PARALLEL_BIN_MIN {
            use rayon::prelude::*;
            prims.par_chunks(PARALLEL_BIN_MIN / 4).map(bin).reduce(|| bin(&[]), merge_bins)
        } else {
            bin(prims)
        };
        let block = self.params.leaf_block;
        let one_by_one = || std::array::from_fn(|axis| sah_sweep(&bins[axis], &bin_n[axis], &bin_n[axis], block));
        #[cfg(target_arch = "x86_64")]
        let swept = if block.is_power_of_two() { sah_sweep3(&bins, &bin_n, block) } else { one_by_one() };
        #[cfg(not(target_arch = "x86_64"))]
        let swept: [_; 3] = one_by_one();
        for axis in 0..3 {
            if ext[axis] <= 0.0 {
                continue;
            }
            if let Some((cost, k)) = swept[axis] {
                if cost < best.0 {
                    best = (cost, axis, k);
                }
            }
        }
        let n = prims.len();
        if !best.0.is_finite() {
            return n / 2;
        }
        let (cost, axis, split_bin) = best;
        // SAH termination for small nodes: a leaf when testing its primitives costs less than
        // a split (traversal step plus the children's expected tests), both counted in blocks.
        // The step is discounted by `WIDE_SPLIT_COST`: see there.
        if n <= self.params.sah_leaf_max {
            let (ct, ci) = (self.params.traversal_cost * WIDE_SPLIT_COST, self.params.intersect_cost);
            let area = bounds.half_area();
            if ci * blocks(n, self.params.leaf_block) as f32 * area <= ct * area + ci * cost {
                return 0;
            }
        }
        let lo = cbounds.min[axis];
        let scale = NB as f32 / cbounds.extent()[axis];
        let mid = partition_in_place(prims, |p| (p.c(axis) - lo) * scale < split_bin as f32);
        if mid == 0 || mid == n {
            n / 2
        } else {
            mid
        }
    }
}

/// Nodes with at least this many primitives are binned in parallel.
const PARALLEL_BIN_MIN: usize = 128 * 1024;

/// Nodes of at most this many references are binned into [`SMALL_BINS`] bins per axis, not
/// [`BINS`]: filling, clearing and sweeping sixteen bins on three axes is most of what a small
/// node's split costs, and eight are as good for a few dozen references (the trees trace as
/// fast). The dragon builds about 9 % faster (two threads: 126–130 → 114–118 ms).
const SMALL_NODE: usize = 32;
const SMALL_BINS: usize = 8;

/// The share of `traversal_cost` that the SAH's leaf-or-split test charges for a split.
/// The binary tree is collapsed into eight-wide nodes ([`collapse`]), so a split near the
/// leaves mostly costs a ray one more slot of a wide node it visits anyway, not a node visit
/// of its own; and a block of four watertight triangle tests costs more than a wide node's
/// slab test. At 0.8 nodes of five to eight references split into leaves of one block more
/// often than at 1.0: in one run of `bench/vs_embree.sh` (with [`SMALL_BINS`] as well), bunny
/// bounce rays 0.85× → 0.89× of Embree's, any-hit 0.92× → 0.95×, packets 1.10× → 1.14×; the
/// icosphere's packets 1.16× → 1.21×; the dragon within ±1 %; 5–7 % more memory (still under
/// 60 bytes per triangle).
const WIDE_SPLIT_COST: f32 = 0.8;

/// Per axis, the SAH bins of `prims` (box and count) by their centres, for centre bounds
/// starting at `lo` with `scale` bins per unit.
fn bin_refs<const N: usize>(prims: &[PRef], lo: Vec3A, scale: Vec3A) -> ([Bins<N>; 3], [[usize; N]; 3]) {
    let mut bins = [Bins::<N>::new(), Bins::new(), Bins::new()];
    let mut bin_n = [[0usize; N]; 3];
    for p in prims {
        let (pmin, pmax, c) = p.simd();
        let f = ((c - lo) * scale).max(Vec3A::ZERO).min(Vec3A::splat((N - 1) as f32));
        let f = bin_indices::<N>(f);
        for axis in 0..3 {
            let b = f[axis];
            bin_n[axis][b] += 1;
            bins[axis].grow(b, pmin, pmax);
        }
    }
    (bins, bin_n)
}

/// The bins of two sets of references: per axis and bin, the union of the boxes and the sum
/// of the counts.
fn merge_bins<const N: usize>(
    (mut a, mut an): ([Bins<N>; 3], [[usize; N]; 3]),
    (b, bn): ([Bins<N>; 3], [[usize; N]; 3]),
) -> ([Bins<N>; 3], [[usize; N]; 3]) {
    for axis in 0..3 {
        for k in 0..N {
            a[axis].grow(k, b[axis].min[k], b[axis].max[k]);
            an[axis][k] += bn[axis][k];
        }
    }
    (a, an)
}

/// Bin boxes for the SAH sweeps, as SIMD vectors (a union is one `min` and one `max`).
struct Bins<const N: usize> {
    min: [Vec3A; N],
    max: [Vec3A; N],
}

impl<const N: usize> Bins<N> {
    fn new() -> Self {
        Bins { min: [Vec3A::INFINITY; N], max: [Vec3A::NEG_INFINITY; N] }
    }

    #[inline(always)]
    fn grow(&mut self, k: usize, min: Vec3A, max: Vec3A) {
        self.min[k] = self.min[k].min(min);
        self.max[k] = self.max[k].max(max);
    }

    #[inline(always)]
    fn grow_box(&mut self, k: usize, b: Aabb) {
        self.grow(k, b.min.into(), b.max.into());
    }

    /// Union of bins `range`, as an [`Aabb`].
    fn union(&self, range: std::ops::Range<usize>) -> Aabb {
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        for k in range {
            lo = lo.min(self.min[k]);
            hi = hi.max(self.max[k]);
        }
        if lo.cmpgt(hi).any() {
            Aabb::EMPTY
        } else {
            Aabb { min: lo.into(), max: hi.into() }
        }
    }
}

/// Truncates three bin positions, already clamped to `[0, N - 1]`, to indices.
#[inline(always)]
fn bin_indices<const N: usize>(f: Vec3A) -> [usize; 3] {
    const { assert!(N.is_power_of_two(), "bin_indices masks with N - 1") };
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE2 is part of the x86_64 baseline; the store goes to a local array.
    unsafe {
        use std::arch::x86_64::*;
        let mut out = [0i32; 4];
        _mm_storeu_si128(out.as_mut_ptr().cast(), _mm_cvttps_epi32(f.into()));
        [out[0] as usize & (N - 1), out[1] as usize & (N - 1), out[2] as usize & (N - 1)]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [f.x as usize, f.y as usize, f.z as usize]
    }
}

/// Half surface area of the box `(lo, hi)`; 0 if it is empty.
#[inline(always)]
fn half_area(lo: Vec3A, hi: Vec3A) -> f32 {
    let e = hi - lo;
    if e.x < 0.0 {
        return 0.0;
    }
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// Leaf tests for `n` primitives tested `block` at a time: `⌈n / block⌉`, by a shift for the
/// usual power-of-two block (a division per SAH plane showed in profiles).
#[inline(always)]
fn blocks(n: usize, block: usize) -> usize {
    if block.is_power_of_two() {
        (n + block - 1) >> block.trailing_zeros()
    } else {
        n.div_ceil(block.max(1))
    }
}

/// The SAH sweep over `N` bins: the best plane between two bins, as the index `k` of the first
/// bin on its right. Each bin has the box of what lies in it, the number of references that
/// start in it (`starts`, counted on the left of planes after it) and that end in it (`ends`,
/// counted on the right of planes before it); for object splits both are the bin counts.
/// Returns `(cost, k)` with cost `A(L)·⌈nL/block⌉ + A(R)·⌈nR/block⌉` (half
/// areas; leaves test `block` primitives at a time), or `None` if no plane has references on
/// both sides.
fn sah_sweep<const N: usize>(
    bins: &Bins<N>,
    starts: &[usize; N],
    ends: &[usize; N],
    block: usize,
) -> Option<(f32, usize)> {
    // Only planes right after an occupied bin need a look: a plane between two occupied bins
    // splits the same way wherever it lies (most bins of a small node are empty).
    let mut occupied = [0usize; N];
    let mut m = 0;
    for k in 0..N {
        // Without a branch: whether a bin is occupied is close to random.
        occupied[m] = k;
        m += (((starts[k] | ends[k]) != 0) | bins.min[k].cmple(bins.max[k]).all()) as usize;
    }
    // Right-hand sides as areas and counts only (a caller that needs the boxes rebuilds them).
    let mut right_area = [0.0f32; N];
    let mut right_n = [0usize; N];
    let (mut lo, mut hi, mut cnt) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY, 0);
    for j in (1..m).rev() {
        let k = occupied[j];
        lo = lo.min(bins.min[k]);
        hi = hi.max(bins.max[k]);
        cnt += ends[k];
        right_area[j] = half_area(lo, hi);
        right_n[j] = cnt;
    }
    let mut best: Option<(f32, usize)> = None;
    let (mut lo, mut hi, mut cnt) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY, 0);
    for j in 0..m.saturating_sub(1) {
        let k = occupied[j];
        lo = lo.min(bins.min[k]);
        hi = hi.max(bins.max[k]);
        cnt += starts[k];
        let rn = right_n[j + 1];
        if cnt == 0 || rn == 0 {
            continue;
        }
        let cost = half_area(lo, hi) * blocks(cnt, block) as f32 + right_area[j + 1] * blocks(rn, block) as f32;
        if best.is_none_or(|b| cost < b.0) {
            best = Some((cost, k + 1));
        }
    }
    best
}

/// [`sah_sweep`] of the three axes' object-split bins at once, an axis in each SSE lane: the
/// same planes at bitwise the same costs, per axis (`None` where no plane has references on
/// both sides). Every plane is evaluated, empty bins included: a plane after an empty bin
/// repeats the cost of the one before it, so the first of equals, which the sweep keeps, is
/// the plane right after an occupied bin, as there. `block` must be a power of two.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::needless_range_loop)]
fn sah_sweep3<const N: usize>(bins: &[Bins<N>; 3], n: &[[usize; N]; 3], block: usize) -> [Option<(f32, usize)>; 3] {
    use std::arch::x86_64::*;
    debug_assert!(block.is_power_of_two() && N < 1 << 16);
    // SAFETY: SSE2 is part of the x86_64 baseline; no memory is accessed through pointers.
    unsafe {
        // Bin k's boxes transposed: per bound, the x, y and z vectors whose lane a is the box of
        // axis a's bin k (lane 3 an empty box).
        let transpose = |r: [__m128; 3], pad: f32| {
            let r3 = _mm_set1_ps(pad);
            let (a, b) = (_mm_unpacklo_ps(r[0], r[1]), _mm_unpacklo_ps(r[2], r3));
            let c = _mm_movelh_ps(_mm_unpackhi_ps(r[0], r[1]), _mm_unpackhi_ps(r[2], r3));
            [_mm_movelh_ps(a, b), _mm_movehl_ps(b, a), c]
        };
        let mut lo = [[_mm_setzero_ps(); 3]; N];
        let mut hi = [[_mm_setzero_ps(); 3]; N];
        let mut cnt = [_mm_setzero_si128(); N];
        for k in 0..N {
            lo[k] = transpose([0, 1, 2].map(|a| bins[a].min[k].into()), f32::INFINITY);
            hi[k] = transpose([0, 1, 2].map(|a| bins[a].max[k].into()), f32::NEG_INFINITY);
            cnt[k] = _mm_setr_epi32(n[0][k] as i32, n[1][k] as i32, n[2][k] as i32, 0);
        }
        let zero = _mm_setzero_ps();
        // The arithmetic of `half_area`, lane by lane.
        let area = |l: &[__m128; 3], h: &[__m128; 3]| {
            let (ex, ey, ez) = (_mm_sub_ps(h[0], l[0]), _mm_sub_ps(h[1], l[1]), _mm_sub_ps(h[2], l[2]));
            let a = _mm_add_ps(_mm_add_ps(_mm_mul_ps(ex, ey), _mm_mul_ps(ey, ez)), _mm_mul_ps(ez, ex));
            _mm_andnot_ps(_mm_cmplt_ps(ex, zero), a)
        };
        let add = _mm_set1_epi32(block as i32 - 1);
        let shift = _mm_cvtsi32_si128(block.trailing_zeros() as i32);
        // Counts stay far below 2^31: the conversion to float is exact where `as f32` is.
        let blocks = |c: __m128i| _mm_cvtepi32_ps(_mm_srl_epi32(_mm_add_epi32(c, add), shift));
        let mut right_area = [zero; N];
        let mut right_n = [_mm_setzero_si128(); N];
        let (mut l, mut h, mut c) =
            ([_mm_set1_ps(f32::INFINITY); 3], [_mm_set1_ps(f32::NEG_INFINITY); 3], _mm_setzero_si128());
        for k in (1..N).rev() {
            for i in 0..3 {
                l[i] = _mm_min_ps(l[i], lo[k][i]);
                h[i] = _mm_max_ps(h[i], hi[k][i]);
            }
            c = _mm_add_epi32(c, cnt[k]);
            right_area[k] = area(&l, &h);
            right_n[k] = c;
        }
        let (mut best_cost, mut best_k, mut found) = (zero, _mm_setzero_si128(), _mm_setzero_si128());
        let (mut l, mut h, mut c) =
            ([_mm_set1_ps(f32::INFINITY); 3], [_mm_set1_ps(f32::NEG_INFINITY); 3], _mm_setzero_si128());
        let izero = _mm_setzero_si128();
        for k in 1..N {
            for i in 0..3 {
                l[i] = _mm_min_ps(l[i], lo[k - 1][i]);
                h[i] = _mm_max_ps(h[i], hi[k - 1][i]);
            }
            c = _mm_add_epi32(c, cnt[k - 1]);
            let rn = right_n[k];
            let empty = _mm_or_si128(_mm_cmpeq_epi32(c, izero), _mm_cmpeq_epi32(rn, izero));
            let cost = _mm_add_ps(_mm_mul_ps(area(&l, &h), blocks(c)), _mm_mul_ps(right_area[k], blocks(rn)));
            // Taken where valid and either the first valid plane or strictly cheaper.
            let better = _mm_or_si128(_mm_cmpeq_epi32(found, izero), _mm_castps_si128(_mm_cmplt_ps(cost, best_cost)));
            let take = _mm_andnot_si128(empty, better);
            let takef = _mm_castsi128_ps(take);
            best_cost = _mm_or_ps(_mm_and_ps(takef, cost), _mm_andnot_ps(takef, best_cost));
            best_k = _mm_or_si128(_mm_and_si128(take, _mm_set1_epi32(k as i32)), _mm_andnot_si128(take, best_k));
            found = _mm_or_si128(found, take);
        }
        let mut costs = [0.0f32; 4];
        let mut ks = [0i32; 4];
        let mut f = [0i32; 4];
        _mm_storeu_ps(costs.as_mut_ptr(), best_cost);
        _mm_storeu_si128(ks.as_mut_ptr().cast(), best_k);
        _mm_storeu_si128(f.as_mut_ptr().cast(), found);
        std::array::from_fn(|a| (f[a] != 0).then(|| (costs[a], ks[a] as usize)))
    }
}

/// Appends `sub` (indices relative to its start) to `out`, moving it to start at `at`.
fn append_relocated(out: &mut Vec<Node>, sub: &[Node], at: usize) {
    out.extend(sub.iter().map(|n| if n.count == 0 { Node { first: n.first + at as u32, ..*n } } else { *n }));
}

/// Moves the elements satisfying `pred` to the front; returns how many there are. Without a
/// branch on `pred` (which side an element goes to is close to random, and that branch was
/// mispredicted about every other time): every element is swapped into the next place on the
/// left, which is taken for good only where `pred` holds. Otherwise the swap exchanges two
/// elements of the right side: the order there is not the input's.
fn partition_in_place<T>(v: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        let left = pred(&v[j]);
        v.swap(i, j);
        i += left as usize;
    }
    i
}

/// Collapses the binary tree into `WIDTH`-wide nodes: each node adopts the children of its largest
/// interior children until it has `WIDTH` (eight).
fn collapse(bin: &[Node]) -> (Vec<Wide>, Vec<(u32, u32)>, usize) {
    let mut nodes: Vec<Wide> = Vec::with_capacity(bin.len() / 2 + 1);
    let mut leaves: Vec<(u32, u32)> = Vec::new();
    let mut max_depth = 0;
    // (binary node to expand, wide slot to fill, depth)
    let mut todo = vec![(0usize, 0usize, 0usize)];
    nodes.push(Wide::EMPTY);
    while let Some((b, slot, depth)) = todo.pop() {
        max_depth = max_depth.max(depth);
        // The children, and the half area of each interior one (-1 for leaves), in a fixed
        // array: no allocation per node.
        let area = |k: usize| if bin[k].count == 0 { bin[k].aabb().half_area() } else { -1.0 };
        let mut kids = [0usize; WIDTH];
        let mut areas = [0.0f32; WIDTH];
        let mut len = 0;
        for k in [b + 1, bin[b].first as usize] {
            (kids[len], areas[len]) = (k, area(k));
            len += 1;
        }
        while len < WIDTH {
            // Open the interior child with the largest surface area (the last of equals, as
            // `max_by` picks).
            let mut best = None;
            for i in 0..len {
                if areas[i] >= 0.0 && best.is_none_or(|j: usize| areas[i].total_cmp(&areas[j]).is_ge()) {
                    best = Some(i);
                }
            }
            let Some(i) = best else { break };
            let k = kids[i];
            // `swap_remove`, then two pushes.
            len -= 1;
            (kids[i], areas[i]) = (kids[len], areas[len]);
            for c in [k + 1, bin[k].first as usize] {
                (kids[len], areas[len]) = (c, area(c));
                len += 1;
            }
        }
        let mut n = Wide::EMPTY;
        for (j, &k) in kids[..len].iter().enumerate() {
            let c = &bin[k];
            for a in 0..3 {
                n.bounds[a][j] = c.min[a];
                n.bounds[3 + a][j] = c.max[a];
            }
            if c.count > 0 {
                n.child[j] = LEAF | leaves.len() as u32;
                leaves.push((c.first, c.count));
            } else {
                let idx = nodes.len();
                nodes.push(Wide::EMPTY);
                n.child[j] = node_ref(idx);
                todo.push((k, idx, depth + 1));
            }
        }
        nodes[slot] = n;
    }
    (nodes, leaves, max_depth)
}

/// Bytes in one row of a node's bounds (eight floats).
const ROW_BYTES: usize = std::mem::size_of::<[f32; WIDTH]>();

/// Per-ray data for the wide slab test: origin, inverse direction, the inverse direction
/// rounded up for exit distances, and for each axis which of the `bounds` rows holds the near
/// plane (min for a positive direction, max otherwise).
#[derive(Clone, Copy)]
struct RayPre {
    o: [f32; 3],
    inv: [f32; 3],
    /// `inv · EXIT_ROUNDING`: the exit distances come out rounded up without a multiply of
    /// their own.
    inv_exit: [f32; 3],
    /// Every `inv` and `inv_exit` is finite, so that no slab distance is NaN (the ray has no
    /// zero direction component): the test may then take minima and maxima as integers.
    finite: bool,
    /// The rows of the near and far planes as byte offsets into a node's bounds (read through
    /// [`RayPre::row`]: base plus offset, no index scaled per node).
    near: [usize; 3],
    far: [usize; 3],
    /// `-o · inv` rounded down and `-o · inv_exit` rounded up ([`outward_products`]): with them
    /// one fused multiply-add per plane gives a slab distance below the entry's exact value
    /// and above the exit's ([`slab_avx`]).
    c_near: [f32; 3],
    c_far: [f32; 3],
}

impl RayPre {
    /// The ray's constants for [`slab`].
    #[inline(always)]
    fn new(ray: &Ray, inv: glam::Vec3) -> RayPre {
        RayPre::with(ray, inv, None)
    }

    /// The ray's constants for the fused [`slab_avx`], with [`RayPre::c_near`] and `c_far`.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn new_fused(ray: &Ray, inv: glam::Vec3) -> RayPre {
        let (o, inv3) = (glam::Vec3A::from(ray.o), glam::Vec3A::from(inv));
        RayPre::with(ray, inv, Some(outward_products(o, inv3, inv3 * EXIT_ROUNDING)))
    }

    /// [`RayPre::new`] or, with the constants `c`, [`RayPre::new_fused`].
    #[inline(always)]
    fn with(ray: &Ray, inv: glam::Vec3, c: Option<(glam::Vec3A, glam::Vec3A)>) -> RayPre {
        let (nx, ny, nz) = ((inv.x < 0.0) as usize * 3, (inv.y < 0.0) as usize * 3, (inv.z < 0.0) as usize * 3);
        // In 16-byte lanes: each value stored whole, and read back by the lane.
        let (o, inv) = (glam::Vec3A::from(ray.o), glam::Vec3A::from(inv));
        let inv_exit = inv * EXIT_ROUNDING;
        // Finite constants imply a finite `inv_exit` (0 · inf is NaN); a sum that overflows
        // only sends the ray to the float test, which is conservative as well.
        let finite = c.map_or(inv_exit.is_finite(), |(c_near, c_far)| (c_near + c_far).is_finite());
        let (c_near, c_far) = c.unwrap_or((glam::Vec3A::ZERO, glam::Vec3A::ZERO));
        RayPre {
            o: o.to_array(),
            inv: inv.to_array(),
            inv_exit: inv_exit.to_array(),
            finite,
            c_near: c_near.to_array(),
            c_far: c_far.to_array(),
            near: [nx, 1 + ny, 2 + nz].map(|row| row * ROW_BYTES),
            far: [3 - nx, 4 - ny, 5 - nz].map(|row| row * ROW_BYTES),
        }
    }

    /// The row of `b` at byte offset `offset`, one of `near` or `far`.
    #[inline(always)]
    fn row(b: &[[f32; WIDTH]; 6], offset: usize) -> &[f32; WIDTH] {
        debug_assert!(offset.is_multiple_of(ROW_BYTES) && offset < 6 * ROW_BYTES);
        // SAFETY: `near` and `far` hold row indices below 6 times the row size (`new`), so the
        // offset starts a whole row inside `b`.
        unsafe { &*b.as_ptr().cast::<u8>().add(offset).cast::<[f32; WIDTH]>() }
    }
}

/// `-o · inv` rounded down and `-o · inv_exit` rounded up ([`RayPre::c_near`]): each product
/// moved outward by 4 ulps of itself in one fused multiply-add, more than the product's
/// rounding (half an ulp) and the multiply-add's own (half an ulp) together.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn outward_products(o: glam::Vec3A, inv: glam::Vec3A, inv_exit: glam::Vec3A) -> (glam::Vec3A, glam::Vec3A) {
    use std::arch::x86_64::*;
    let k = _mm_set1_ps(4.0 * f32::EPSILON);
    let abs = |v: __m128| _mm_andnot_ps(_mm_set1_ps(-0.0), v);
    let p = _mm_mul_ps(o.into(), inv.into());
    let q = _mm_mul_ps(o.into(), inv_exit.into());
    // -(|p| k) - p and |q| k - q.
    (_mm_fnmsub_ps(abs(p), k, p).into(), _mm_fmsub_ps(abs(q), k, q).into())
}

/// The ray's constants for a walk, `FUSED` as in [`Bvh::closest_walk`].
#[inline(always)]
fn ray_pre<const FUSED: bool>(ray: &Ray, inv: glam::Vec3) -> RayPre {
    #[cfg(target_arch = "x86_64")]
    if FUSED {
        // SAFETY: `FUSED` is true only in traversals that run after AVX2 and FMA were detected.
        return unsafe { RayPre::new_fused(ray, inv) };
    }
    RayPre::new(ray, inv)
}

/// The float `x` as an integer key. Keys of non-negative floats order as the floats do, and
/// the keys of negative floats (`-0.0` included) are below all of those.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn key(x: f32) -> i32 {
    x.to_bits() as i32
}

/// Slab test of one ray against the boxes of `n` within `[0, t_max]`: entry distances and a
/// bit mask of the boxes hit. Conservative like [`Aabb::slab`]: NaN from `0 · inf` is ignored,
/// empty boxes never hit, and the exit distance is rounded up by a few ulps.
///
/// The entry distance is the maximum of the three near-plane distances and 0, the exit
/// distance the minimum of the far-plane distances (rounded up through `inv_exit`) and
/// `t_max · EXIT_ROUNDING`. For a ray without a zero direction component (`finite`) they are
/// taken as integer maxima and minima of the floats' bits, which cost a cycle where float ones
/// cost several on the path from one node to the next: the entry maximum includes 0, so it is
/// exact (a negative distance never wins, as with floats), and an exit minimum below zero
/// keeps a negative key and rejects the box, as it must (an exit of exactly `-0.0` with entry
/// `+0.0` touches the box only at `t = 0`, where no hit counts). Rays with a zero component
/// take float maxima and minima, which ignore the NaN of an origin on a plane.
#[inline(always)]
fn slab(n: &Wide, r: &RayPre, t_max: f32) -> ([f32; WIDTH], u32) {
    let mut out = [0.0f32; WIDTH];
    let mut mask = 0;
    let t_exit = t_max * EXIT_ROUNDING;
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE2 is part of the x86_64 baseline; loads are unaligned-safe (`loadu`) from
    // 16-byte runs inside `n`'s rows, and stores go to 16-byte runs of a local array.
    unsafe {
        use std::arch::x86_64::*;
        let b = &n.bounds;
        let (i, f) = (_mm_castps_si128, _mm_castsi128_ps);
        // Integer max and min in SSE2 (which lacks pmaxsd): select by a comparison.
        let imax = |a: __m128, c: __m128| {
            let gt = _mm_cmpgt_epi32(i(a), i(c));
            f(_mm_or_si128(_mm_and_si128(gt, i(a)), _mm_andnot_si128(gt, i(c))))
        };
        let imin = |a: __m128, c: __m128| {
            let gt = _mm_cmpgt_epi32(i(a), i(c));
            f(_mm_or_si128(_mm_and_si128(gt, i(c)), _mm_andnot_si128(gt, i(a))))
        };
        // Four children at a time.
        for h in (0..WIDTH).step_by(4) {
            let mut tn = _mm_setzero_ps();
            let mut tf = _mm_set1_ps(t_exit);
            for a in 0..3 {
                let o = _mm_set1_ps(r.o[a]);
                let t0 = _mm_mul_ps(
                    _mm_sub_ps(_mm_loadu_ps(RayPre::row(b, r.near[a])[h..].as_ptr()), o),
                    _mm_set1_ps(r.inv[a]),
                );
                let t1 = _mm_mul_ps(
                    _mm_sub_ps(_mm_loadu_ps(RayPre::row(b, r.far[a])[h..].as_ptr()), o),
                    _mm_set1_ps(r.inv_exit[a]),
                );
                if r.finite {
                    tn = imax(t0, tn);
                    tf = imin(t1, tf);
                } else {
                    // maxps/minps return the second operand when either is NaN: keep the
                    // running value second so that NaN slab distances are ignored.
                    tn = _mm_max_ps(t0, tn);
                    tf = _mm_min_ps(t1, tf);
                }
            }
            let hit = if r.finite {
                _mm_movemask_ps(f(_mm_cmpgt_epi32(i(tn), i(tf)))) ^ 0xf
            } else {
                _mm_movemask_ps(_mm_cmple_ps(tn, tf))
            };
            mask |= (hit as u32) << h;
            _mm_storeu_ps(out[h..].as_mut_ptr(), tn);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let b = &n.bounds;
        for j in 0..WIDTH {
            let mut tn = 0.0f32;
            let mut tf = t_exit;
            for a in 0..3 {
                let t0 = (RayPre::row(b, r.near[a])[j] - r.o[a]) * r.inv[a];
                let t1 = (RayPre::row(b, r.far[a])[j] - r.o[a]) * r.inv_exit[a];
                if r.finite {
                    tn = if key(t0) > key(tn) { t0 } else { tn };
                    tf = if key(t1) < key(tf) { t1 } else { tf };
                } else {
                    tn = if t0 > tn { t0 } else { tn };
                    tf = if t1 < tf { t1 } else { tf };
                }
            }
            if if r.finite { key(tn) <= key(tf) } else { tn <= tf } {
                mask |= 1 << j;
            }
            out[j] = tn;
        }
    }
    (out, mask)
}

/// [`slab`] with the eight children in one AVX register. For rays without a zero direction
/// component each plane's distance is one fused multiply-add, `b · inv + c` with `c` the
/// product `-o · inv` rounded outward ([`RayPre::c_near`]): one rounding where `slab` has
/// two, on the path from one node to the next (bounce rays 3-5 % faster, any-hit 2-4 %,
/// primary 1-4 %: the bench, one thread, pinned A/B). Still conservative:
/// the entry distance is at most the exact one rounded to nearest and the exit distance at
/// least the exact one (times `EXIT_ROUNDING`), so it enters every box `slab` enters, at
/// distances at most a few ulps of `|o · inv|` apart. Rays with a zero component take
/// `slab`'s arithmetic.
///
/// The entry distances go straight into the caller's `out` (the traversal's own array) and the
/// hit mask is returned: returned as an array with the mask, they were stored once and copied,
/// a second store-to-load round trip before the children's order is known (single rays 2-3 %
/// faster, the bench's instructions 1.6 % fewer).
///
/// `finite` is `r.finite`, read by the walk as the ray's constants are made and handed down
/// in a register: read from `r` in the walk, it came from a 16-byte load over the last of the
/// constants' stores and the flag's (a store-forwarding stall at the start of every query,
/// 6-7 % of the walk's samples; without it primary rays are about 3 % faster, bounce rays
/// unchanged).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn slab_avx<const FUSED: bool>(
    n: &Wide,
    at: Rows,
    r: &RayPre,
    finite: bool,
    t_max: f32,
    out: &mut [f32; WIDTH],
) -> u32 {
    debug_assert_eq!(finite, r.finite);
    if finite {
        slab_avx_with::<true, FUSED>(at, r, t_max, out)
    } else {
        slab_avx_float(n, *r, t_max, out)
    }
}

/// [`slab_avx`] for rays with a zero direction component (kept out of the hot path). It takes
/// the ray's constants by value: by reference, every query laid them out in memory for this
/// call, which almost never happens (the Cornell box 1.4 % more instructions). For the same
/// reason it takes the node, not its [`Rows`]: those 56 bytes, passed by value, were stored to
/// memory at every node visit of some walks.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[cold]
#[inline(never)]
fn slab_avx_float(n: &Wide, r: RayPre, t_max: f32, out: &mut [f32; WIDTH]) -> u32 {
    slab_avx_with::<false, false>(Rows::of(n, &r), &r, t_max, out)
}

/// [`slab_avx`]'s arithmetic: maxima and minima on the floats' bits where `INT`, float ones
/// otherwise (the running value second, so that NaN distances are ignored, as in `slab`);
/// with `INT` and `FUSED`, the distances by fused multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn slab_avx_with<const INT: bool, const FUSED: bool>(at: Rows, r: &RayPre, t_max: f32, out: &mut [f32; WIDTH]) -> u32 {
    use std::arch::x86_64::*;
    let (tn, tf) = slab_avx_dists::<INT, FUSED>(at, r, t_max);
    let mask = if INT {
        _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_castps_si256(tn), _mm256_castps_si256(tf))))
            as u32
            ^ 0xff
    } else {
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32
    };
    // SAFETY: an unaligned store into an array of eight floats.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), tn) };
    mask
}

/// [`slab_avx_with`]'s entry and exit distances of the eight children, before they are
/// compared.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn slab_avx_dists<const INT: bool, const FUSED: bool>(
    at: Rows,
    r: &RayPre,
    t_max: f32,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    const { assert!(WIDTH == 8, "one AVX register holds eight children") };
    let mut tn = _mm256_setzero_ps();
    let mut tf = _mm256_set1_ps(t_max * EXIT_ROUNDING);
    for a in 0..3 {
        let o = _mm256_set1_ps(r.o[a]);
        // SAFETY: this function is compiled for AVX2 (`Rows` only names rows of a node).
        let (lo, hi) = unsafe { (at.load(a), at.load(3 + a)) };
        let (t0, t1) = if INT && FUSED {
            (
                _mm256_fmadd_ps(lo, _mm256_set1_ps(r.inv[a]), _mm256_set1_ps(r.c_near[a])),
                _mm256_fmadd_ps(hi, _mm256_set1_ps(r.inv_exit[a]), _mm256_set1_ps(r.c_far[a])),
            )
        } else {
            (
                _mm256_mul_ps(_mm256_sub_ps(lo, o), _mm256_set1_ps(r.inv[a])),
                _mm256_mul_ps(_mm256_sub_ps(hi, o), _mm256_set1_ps(r.inv_exit[a])),
            )
        };
        (tn, tf) = if INT { (imax8(t0, tn), imin8(t1, tf)) } else { (_mm256_max_ps(t0, tn), _mm256_min_ps(t1, tf)) };
    }
    (tn, tf)
}

/// The lane-wise maximum of the floats' bits as integers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn imax8(a: std::arch::x86_64::__m256, b: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_castsi256_ps(_mm256_max_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b)))
}

/// The lane-wise minimum of the floats' bits as integers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn imin8(a: std::arch::x86_64::__m256, b: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_castsi256_ps(_mm256_min_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b)))
}

/// The slab test of node `n`'s children: [`slab_avx`] where `AVX` (reading the node's rows
/// through `at`), [`slab`] otherwise; the entry distances go to `t`, the hit mask is returned.
/// `finite` is `r.finite`, as the walk read it (see [`slab_avx`]).
#[inline(always)]
fn node_slab<const AVX: bool, const FUSED: bool>(
    n: &Wide,
    at: Rows,
    r: &RayPre,
    finite: bool,
    t_max: f32,
    t: &mut [f32; WIDTH],
) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is true only in traversals that run after AVX2 and FMA were detected.
        return unsafe { slab_avx::<FUSED>(n, at, r, finite, t_max, t) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = at;
    let mask;
    (*t, mask) = slab(n, r, t_max);
    mask
}

/// Visits interior node `n`: pushes the children hit within `t_max` onto the stack, farthest
/// deepest, except the nearest, which is returned (`None`: no child is hit). The one- and
/// two-child cases, by far the most common, take no loop. With `ANY` (the any-hit walk) the
/// children are not ordered: the first hit is returned, the others pushed in slot order.
/// `finite` as in [`node_slab`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn visit<const AVX: bool, const FUSED: bool, const ANY: bool>(
    nodes: &[Wide],
    n: &Wide,
    at: Rows,
    r: &RayPre,
    finite: bool,
    t_max: f32,
    stack: &mut [std::mem::MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> Option<u32> {
    // The child references sit after the bounds, in a cache line the slab test does not read:
    // ask for it now, so that where the node is not cached it arrives with the bounds rather
    // than after the hit mask is known.
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint with no memory effect.
    unsafe {
        std::arch::x86_64::_mm_prefetch(n.child.as_ptr().cast::<i8>(), std::arch::x86_64::_MM_HINT_T0)
    };
    let mut t = [0.0f32; WIDTH];
    let mask = node_slab::<AVX, FUSED>(n, at, r, finite, t_max, &mut t);
    if mask == 0 {
        return None;
    }
    let j0 = mask.trailing_zeros() as usize;
    let rest = mask & (mask - 1);
    if rest == 0 {
        return Some(n.child[j0]);
    }
    if ANY {
        // Any hit ends the walk, so the order does not matter: the first child hit is taken
        // next and the others pushed as they come, without the distances' compare (a branch
        // that incoherent rays mispredict) or sort. As Embree's occlusion walk does; any-hit
        // rays +2-17 % (bunny, icosphere, dragon; bounce rays and the mostly blocked camera
        // rays alike).
        let mut m = rest;
        while m != 0 {
            let j = m.trailing_zeros() as usize;
            m &= m - 1;
            push_child(nodes, n.child[j], 0.0, stack, sp);
        }
        return Some(n.child[j0]);
    }
    let j1 = rest.trailing_zeros() as usize;
    let rest = rest & (rest - 1);
    if rest == 0 {
        // A branch, not a select: where it is predicted (coherent rays meet the same order
        // node after node) the next node's address does not wait for the distances, which
        // arrive through a store to memory. Primary rays +2-4 %, bounce rays unchanged.
        if t[j0] < t[j1] {
            push_child(nodes, n.child[j1], t[j1], stack, sp);
            return Some(n.child[j0]);
        }
        push_child(nodes, n.child[j0], t[j0], stack, sp);
        return Some(n.child[j1]);
    }
    // Three or more: by descending distance (ties: later child nearer).
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is true only in traversals that run after AVX2 and POPCNT were detected.
        return Some(unsafe { push_by_rank(nodes, n, &t, mask, stack, sp) });
    }
    Some(push_by_insertion(nodes, n, &t, mask, stack, sp))
}

/// [`visit`] for the closest-hit walk compiled with AVX-512 ([`Bvh::closest_avx512`]): the
/// same children in the same order, but the next child's reference is taken from the slab
/// test's mask register by `vpcompressd` (the hit children's references packed into the low
/// lanes, the first one moved to a general register), where [`visit`] moves the mask to a
/// general register, counts its trailing zeros and loads the reference at that slot: a shorter
/// chain from one node's bounds to the next node's address (bounce rays 3–7 % faster on the
/// bunny, the small icosphere and the dragon, primary rays 0–4 %: the fifty-third session). Two hit children are ordered from their
/// distances packed the same way. Rays with a zero direction component, and three or more hit
/// children, take [`visit`]'s ways.
///
/// # Safety
/// The CPU must support what [`has_avx512`] checks (only the AVX-512 walk calls it).
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn visit_avx512<const FUSED: bool>(
    nodes: &[Wide],
    n: &Wide,
    at: Rows,
    r: &RayPre,
    finite: bool,
    t_max: f32,
    stack: &mut [std::mem::MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> Option<u32> {
    use std::arch::x86_64::*;
    if !finite {
        return visit::<true, FUSED, false>(nodes, n, at, r, finite, t_max, stack, sp);
    }
    // SAFETY (of the intrinsics below): the caller's CPU has AVX2, FMA and AVX-512 F/VL; the
    // loads read `n`'s references, eight `u32`s.
    unsafe {
        // Not redundant with the load below: the compiler places that load after the branch on
        // an empty mask, and the prefetch asks for the references' line as the bounds are
        // asked for, as `visit` does.
        _mm_prefetch(n.child.as_ptr().cast::<i8>(), _MM_HINT_T0);
        let kids = _mm256_loadu_si256(n.child.as_ptr().cast());
        let (tn, tf) = slab_avx_dists::<true, FUSED>(at, r, t_max);
        // Entry at or before exit, on the floats' bits as integers (as `slab_avx_with`).
        let k = _mm256_cmple_epi32_mask(_mm256_castps_si256(tn), _mm256_castps_si256(tf));
        let mask = k as u32;
        if mask == 0 {
            return None;
        }
        let hit = _mm256_maskz_compress_epi32(k, kids);
        let c0 = _mm256_cvtsi256_si32(hit) as u32;
        let rest = mask & (mask - 1);
        if rest == 0 {
            return Some(c0);
        }
        if rest & (rest - 1) == 0 {
            let t = _mm256_castps256_ps128(_mm256_maskz_compress_ps(k, tn));
            let (c1, t0, t1) =
                (_mm256_extract_epi32::<1>(hit) as u32, _mm_cvtss_f32(t), _mm_cvtss_f32(_mm_movehdup_ps(t)));
            // As `visit`: a branch, not a select; the lower slot first where strictly nearer.
            if t0 < t1 {
                push_child(nodes, c1, t1, stack, sp);
                return Some(c0);
            }
            push_child(nodes, c0, t0, stack, sp);
            return Some(c1);
        }
        let mut t = [0.0f32; WIDTH];
        _mm256_storeu_ps(t.as_mut_ptr(), tn);
        Some(push_by_rank(nodes, n, &t, mask, stack, sp))
    }
}

/// Pushes child `c`, entered at distance `t`, on the stack, and asks the cache for it.
#[inline(always)]
fn push_child(nodes: &[Wide], c: u32, t: f32, stack: &mut [std::mem::MaybeUninit<(u32, f32)>], sp: &mut usize) {
    prefetch_node(nodes, c);
    stack[*sp].write((c, t));
    *sp += 1;
}

/// [`push_by_rank`] without AVX2: the hit children sorted by insertion, then pushed.
#[inline(always)]
fn push_by_insertion(
    nodes: &[Wide],
    n: &Wide,
    t: &[f32; WIDTH],
    mask: u32,
    stack: &mut [std::mem::MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> u32 {
    let mut refs = [0u32; WIDTH];
    let mut ts = [0.0f32; WIDTH];
    let mut k = 0;
    let mut m = mask;
    while m != 0 {
        let j = m.trailing_zeros() as usize;
        m &= m - 1;
        let mut p = k;
        while p > 0 && ts[p - 1] < t[j] {
            ts[p] = ts[p - 1];
            refs[p] = refs[p - 1];
            p -= 1;
        }
        ts[p] = t[j];
        refs[p] = n.child[j];
        k += 1;
    }
    for j in 0..k - 1 {
        push_child(nodes, refs[j], ts[j], stack, sp);
    }
    refs[k - 1]
}

/// [`visit`]'s three or more hit children (`mask`, distances `t`) put straight into their
/// places on the stack, farthest deepest, and the nearest returned, where it is popped at
/// once: each child's place is the number of hit children before it in that order (farther,
/// or as far and in a lower slot), counted by two comparisons of all eight distances at once.
/// No branch on the distances, where the insertion sort had one per step (7.5 % of the bunny's
/// node visits have three or more hit children). The distances of hit children are not
/// negative and not NaN, so their bits compare as integers as the floats do.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
#[inline]
fn push_by_rank(
    nodes: &[Wide],
    n: &Wide,
    t: &[f32; WIDTH],
    mask: u32,
    stack: &mut [std::mem::MaybeUninit<(u32, f32)>],
    sp: &mut usize,
) -> u32 {
    use std::arch::x86_64::*;
    const { assert!(WIDTH == 8, "one AVX register holds eight children") };
    // SAFETY: an unaligned load of eight floats.
    let tv = unsafe { _mm256_loadu_si256(t.as_ptr().cast()) };
    let base = *sp;
    let mut m = mask;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        let ti = _mm256_set1_epi32(t[i].to_bits() as i32);
        let farther = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(tv, ti))) as u32;
        let equal = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(tv, ti))) as u32;
        let place = ((farther | (equal & ((1 << i) - 1))) & mask).count_ones() as usize;
        prefetch_node(nodes, n.child[i]);
        stack[base + place].write((n.child[i], t[i]));
    }
    // The nearest took the place above the others: it is taken now, not pushed. (The stack
    // has room for it: seven places for each level of the deepest tree, and a node's
    // children are written above the places of the levels above it only.)
    let top = base + mask.count_ones() as usize - 1;
    *sp = top;
    // SAFETY: every place below `base + count` was written above.
    unsafe { stack[top].assume_init() }.0
}

/// The lane of `mask` (not empty) with the smallest `t`, the highest lane among equal ones:
/// the child [`visit`]'s order takes next ("later child nearer" on ties).
#[inline(always)]
fn nearest_lane(t: &[f32; WIDTH], mask: u32) -> usize {
    let mut j = 31 - mask.leading_zeros() as usize;
    let mut m = mask & !(1 << j);
    while m != 0 {
        let k = 31 - m.leading_zeros() as usize;
        m &= !(1 << k);
        if t[k] < t[j] {
            j = k;
        }
    }
    j
}

/// Asks the cache for node `c`, a child that waits on the stack while a nearer one is
/// traversed, so that it has arrived when it is popped. Without a branch: a leaf or empty
/// reference (at least 2^31, beyond any node index) prefetches the first node instead, which
/// costs nothing (whether a child is a leaf is close to random, and the branch on it was
/// mispredicted often).
#[inline(always)]
fn prefetch_node(nodes: &[Wide], c: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        let i = if (c as usize) < nodes.len() * NODE_UNITS { c as usize } else { 0 };
        let p = nodes.as_ptr().cast::<i8>().wrapping_add(i * UNIT_BYTES);
        // SAFETY: prefetching is a hint with no memory effect, valid for any address.
        unsafe {
            use std::arch::x86_64::*;
            for line in (0..std::mem::size_of::<Wide>()).step_by(64) {
                _mm_prefetch(p.wrapping_add(line), _MM_HINT_T0);
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (nodes, c);
}

impl Bvh {
    /// The node of interior reference `r`, found without a multiply or a bounds check.
    #[inline(always)]
    fn node(&self, r: u32) -> &Wide {
        debug_assert!((r as usize).is_multiple_of(NODE_UNITS) && node_index(r) < self.nodes.len());
        // SAFETY: interior references are written only by `collapse`, as `node_ref` of an
        // index into `nodes` (the root, 0, where `nodes` is not empty), and nothing changes
        // them afterwards (`relabel_leaves` rewrites leaf references only); the traversals
        // call this only for references without the `LEAF` bit, which are never `EMPTY`
        // (empty slots are never entered). So `r · UNIT_BYTES` is the byte offset of a node of `nodes`.
        unsafe { &*self.nodes.as_ptr().cast::<u8>().add((r as usize) * UNIT_BYTES).cast::<Wide>() }
    }

    fn leaf(&self, leaf: u32) -> &[u32] {
        assert!(!self.relabeled, "primitive-level queries on a relabelled BVH");
        let (first, count) = self.leaves[leaf as usize];
        &self.prims[first as usize..(first + count) as usize]
    }

    /// Whether the AVX2 walks use the fused slab test: in trees of more than one node. A tree
    /// of one node (the Cornell box's top level) keeps the unfused test, as the fused test's
    /// two constants per ray cost more than one node's shorter chain gives.
    #[inline(always)]
    fn fused(&self) -> bool {
        self.nodes.len() > 1
    }

    /// The closest-hit traversal; `AVX`: with [`slab_avx`] (only after AVX2 and FMA were
    /// detected), `FUSED` (only with `AVX`): its fused multiply-adds, `AVX512` (only in
    /// [`Bvh::closest_avx512`]): nodes visited by [`visit_avx512`].
    #[inline(always)]
    fn closest_walk<const AVX: bool, const FUSED: bool, const AVX512: bool>(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        let inv = ray.d.recip();
        if self.nodes.len() == 1 && !self.root_leaf {
            // The ray's constants made here apart from the walk's, so that they stay in
            // registers rather than being laid out in memory for a walk that never runs.
            return self.closest_in_root::<AVX, FUSED>(&ray_pre::<FUSED>(ray, inv), t_max, test, counter);
        }
        // A tree that is a single leaf starts at that leaf (one call site of `test`, so that
        // it is inlined), once its box is hit; otherwise the root node's test of its children's
        // boxes culls.
        let root = if self.root_leaf {
            if self.root_box.slab(ray.o, inv, 0.0, *t_max).is_none() {
                return false;
            }
            self.root_ref
        } else if self.nodes.is_empty() {
            return false;
        } else {
            0
        };
        let mut hit = false;
        let r = ray_pre::<FUSED>(ray, inv);
        let finite = r.finite;
        let rows = Rows::tree(&self.nodes, &r);
        // Uninitialised: zeroing it (3.5 KiB) per ray showed up in profiles. Only entries below `sp`
        // are read, and each was written first.
        let mut stack = [std::mem::MaybeUninit::<(u32, f32)>::uninit(); (WIDTH - 1) * MAX_STACK];
        stack[0].write((root, 0.0));
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            // SAFETY: stack[sp] was written before sp was raised past it.
            let (mut cur, t_enter) = unsafe { stack[sp].assume_init() };
            if t_enter > *t_max {
                continue;
            }
            loop {
                if cur & LEAF != 0 {
                    if let Some(t) = test(cur & !LEAF, *t_max) {
                        *t_max = t;
                        hit = true;
                    }
                    break;
                }
                counter.node();
                let n = self.node(cur);
                // SAFETY: `cur` is an interior reference (not a leaf's) of `self.nodes`.
                let at = unsafe { Rows::at(&rows, cur) };
                #[cfg(target_arch = "x86_64")]
                let next = if AVX512 {
                    // SAFETY: `AVX512` is true only in the walk compiled with AVX-512.
                    unsafe { visit_avx512::<FUSED>(&self.nodes, n, at, &r, finite, *t_max, &mut stack, &mut sp) }
                } else {
                    visit::<AVX, FUSED, false>(&self.nodes, n, at, &r, finite, *t_max, &mut stack, &mut sp)
                };
                #[cfg(not(target_arch = "x86_64"))]
                let next = visit::<AVX, FUSED, false>(&self.nodes, n, at, &r, finite, *t_max, &mut stack, &mut sp);
                match next {
                    Some(next) => cur = next,
                    None => break,
                }
            }
        }
        hit
    }

    /// [`Bvh::closest_walk`] in a tree of one node (a top level of at most eight objects, such
    /// as the Cornell box's, or a mesh of at most eight leaves), whose children are all leaves:
    /// the hit children are taken nearest first straight from the slab test's distances, and
    /// those beyond a hit dropped, without a stack. The same leaves in the same order as the
    /// walk (ties: the later child first), so the same hits: the Cornell box's closest-hit
    /// queries 9 % fewer instructions, the same image.
    #[inline(always)]
    fn closest_in_root<const AVX: bool, const FUSED: bool>(
        &self,
        r: &RayPre,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        let n = &self.nodes[0];
        counter.node();
        let mut t = [0.0f32; WIDTH];
        let mut mask = node_slab::<AVX, FUSED>(n, Rows::of(n, r), r, r.finite, *t_max, &mut t);
        let mut hit = false;
        while mask != 0 {
            let j = nearest_lane(&t, mask);
            mask &= !(1 << j);
            if let Some(th) = test(n.child[j] & !LEAF, *t_max) {
                (*t_max, hit) = (th, true);
                for k in super::lanes(mask) {
                    if t[k] > th {
                        mask &= !(1 << k);
                    }
                }
            }
        }
        hit
    }

    /// [`Bvh::any_walk`] in a tree of one node: the hit children in the walk's order, without
    /// a stack.
    #[inline(always)]
    fn any_in_root<const AVX: bool, const FUSED: bool>(
        &self,
        r: &RayPre,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        let n = &self.nodes[0];
        counter.node();
        let mut mask = node_slab::<AVX, FUSED>(n, Rows::of(n, r), r, r.finite, t_max, &mut [0.0; WIDTH]);
        // The lowest slot first, then the others from the highest down: the walk's order
        // (the first child hit taken, the others pushed in slot order and popped).
        let mut j = mask.trailing_zeros() as usize;
        while mask != 0 {
            mask &= !(1 << j);
            if test(n.child[j] & !LEAF, t_max) {
                return true;
            }
            j = 31usize.wrapping_sub(mask.leading_zeros() as usize);
        }
        false
    }

    /// The any-hit traversal; `AVX` and `FUSED` as in [`Bvh::closest_walk`].
    #[inline(always)]
    fn any_walk<const AVX: bool, const FUSED: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        let inv = ray.d.recip();
        if self.nodes.len() == 1 && !self.root_leaf {
            // As in `closest_walk`.
            return self.any_in_root::<AVX, FUSED>(&ray_pre::<FUSED>(ray, inv), t_max, test, counter);
        }
        let root = if self.root_leaf {
            if self.root_box.slab(ray.o, inv, 0.0, t_max).is_none() {
                return false;
            }
            self.root_ref
        } else if self.nodes.is_empty() {
            return false;
        } else {
            0
        };
        let r = ray_pre::<FUSED>(ray, inv);
        let finite = r.finite;
        let rows = Rows::tree(&self.nodes, &r);
        let mut stack = [std::mem::MaybeUninit::<(u32, f32)>::uninit(); (WIDTH - 1) * MAX_STACK];
        stack[0].write((root, 0.0));
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            // SAFETY: stack[sp] was written before sp was raised past it.
            let (mut cur, _) = unsafe { stack[sp].assume_init() };
            loop {
                if cur & LEAF != 0 {
                    if test(cur & !LEAF, t_max) {
                        return true;
                    }
                    break;
                }
                counter.node();
                // SAFETY: `cur` is an interior reference (not a leaf's) of `self.nodes`.
                let at = unsafe { Rows::at(&rows, cur) };
                match visit::<AVX, FUSED, true>(&self.nodes, self.node(cur), at, &r, finite, t_max, &mut stack, &mut sp)
                {
                    Some(next) => cur = next,
                    None => break,
                }
            }
        }
        false
    }

    /// [`Bvh::closest_walk`] compiled for AVX2, FMA and POPCNT; `FUSED` as there. The leaf test
    /// is inlined where the caller's closure asks for it (the top level's object test) and is
    /// a call otherwise (a mesh's triangle blocks, `TriData::closest`).
    ///
    /// # Safety
    /// The CPU must support AVX2, FMA and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt")]
    unsafe fn closest_avx<const FUSED: bool>(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_walk::<true, FUSED, false>(ray, t_max, test, counter)
    }

    /// [`Bvh::any_walk`] compiled for AVX2, FMA and POPCNT.
    ///
    /// # Safety
    /// The CPU must support AVX2, FMA and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt")]
    unsafe fn any_avx<const FUSED: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_walk::<true, FUSED>(ray, t_max, test, counter)
    }

    /// [`Bvh::closest_walk`] compiled with AVX-512 as well, for a leaf test inlined into it
    /// ([`Accel::closest_leaf_inlined`]): the walk is [`Bvh::closest_avx`]'s (the same 256-bit
    /// slab test, so the same leaves in the same order), but with 32 vector registers the
    /// ray's constants stay in them across the leaf test, where with AVX2's 16 an inlined leaf
    /// test pushed them to memory (the fortieth session) and a called one reloads them after
    /// every leaf.
    ///
    /// # Safety
    /// The CPU must support what [`has_avx512`] checks.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt,avx512f,avx512vl,avx512bw,avx512dq")]
    unsafe fn closest_avx512<const FUSED: bool>(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_walk::<true, FUSED, true>(ray, t_max, test, counter)
    }

    /// [`Bvh::any_walk`] compiled with AVX-512 as well, as [`Bvh::closest_avx512`].
    ///
    /// # Safety
    /// The CPU must support what [`has_avx512`] checks.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt,avx512f,avx512vl,avx512bw,avx512dq")]
    unsafe fn any_avx512<const FUSED: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_walk::<true, FUSED>(ray, t_max, test, counter)
    }

    /// The closest-hit walk for this CPU: with `INLINED` (a leaf test meant to be inlined,
    /// [`Accel::closest_leaf_inlined`]) the AVX-512 copy where the CPU has it; otherwise the
    /// AVX2 walk where it has that; otherwise the portable one.
    #[inline(always)]
    fn closest_on_cpu<const INLINED: bool>(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `avx512` and `avx` are set only where `has_avx512` and `has_avx2_fma_popcnt`
        // found what those walks are compiled for.
        unsafe {
            match (INLINED && self.avx512, self.avx, self.fused()) {
                (true, _, true) => return self.closest_avx512::<true>(ray, t_max, test, counter),
                (true, _, false) => return self.closest_avx512::<false>(ray, t_max, test, counter),
                (false, true, true) => return self.closest_avx::<true>(ray, t_max, test, counter),
                (false, true, false) => return self.closest_avx::<false>(ray, t_max, test, counter),
                (false, false, _) => {}
            }
        }
        self.closest_walk::<false, false, false>(ray, t_max, test, counter)
    }

    /// The any-hit walk for this CPU, chosen as in [`Bvh::closest_on_cpu`].
    #[inline(always)]
    fn any_on_cpu<const INLINED: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `closest_on_cpu`.
        unsafe {
            match (INLINED && self.avx512, self.avx, self.fused()) {
                (true, _, true) => return self.any_avx512::<true>(ray, t_max, test, counter),
                (true, _, false) => return self.any_avx512::<false>(ray, t_max, test, counter),
                (false, true, true) => return self.any_avx::<true>(ray, t_max, test, counter),
                (false, true, false) => return self.any_avx::<false>(ray, t_max, test, counter),
                (false, false, _) => {}
            }
        }
        self.any_walk::<false, false>(ray, t_max, test, counter)
    }
}

/// Packet traversal: eight rays against a node's four boxes at once in AVX2 lanes, the node
/// fetched once for all of them.
#[cfg(target_arch = "x86_64")]
mod packet {
    use super::{imax8, imin8, Bvh, EMPTY, EXIT_ROUNDING, LEAF, MAX_STACK, WIDTH};
    use crate::geometry::Ray;
    use std::arch::x86_64::*;

    /// The eight rays in structure-of-arrays form.
    struct Rays8 {
        o: [__m256; 3],
        inv: [__m256; 3],
        /// Per axis, lanes whose direction is negative (the near plane is the max).
        neg: [__m256; 3],
    }

    impl Rays8 {
        /// The rays of a group with no active lane: never tested.
        // SAFETY: an all-zero __m256 is a valid value (eight zero floats).
        const IDLE: Rays8 = unsafe { std::mem::zeroed() };
    }

    #[target_feature(enable = "avx2")]
    fn load(rays: &[Ray; 8]) -> Rays8 {
        let lane = |f: &dyn Fn(&Ray) -> f32| {
            let v: [f32; 8] = std::array::from_fn(|i| f(&rays[i]));
            // SAFETY: an unaligned load of a local array of eight floats.
            unsafe { _mm256_loadu_ps(v.as_ptr()) }
        };
        let inv = [lane(&|r| 1.0 / r.d.x), lane(&|r| 1.0 / r.d.y), lane(&|r| 1.0 / r.d.z)];
        let zero = _mm256_setzero_ps();
        Rays8 {
            o: [lane(&|r| r.o.x), lane(&|r| r.o.y), lane(&|r| r.o.z)],
            neg: [
                _mm256_cmp_ps::<_CMP_LT_OQ>(inv[0], zero),
                _mm256_cmp_ps::<_CMP_LT_OQ>(inv[1], zero),
                _mm256_cmp_ps::<_CMP_LT_OQ>(inv[2], zero),
            ],
            inv,
        }
    }

    /// The lanes of `r` whose ray meets child `j` of `bounds` within `[0, t_max]`, with their
    /// entry distances; the single-ray test's arithmetic (near plane by the direction's sign,
    /// NaN ignored, exit rounded up).
    #[target_feature(enable = "avx2")]
    fn slab8(bounds: &[[f32; WIDTH]; 6], j: usize, r: &Rays8, t_max: __m256) -> (__m256, u32) {
        let (lo, hi) = (std::array::from_fn(|a| bounds[a][j]), std::array::from_fn(|a| bounds[3 + a][j]));
        let (tn, tf) = entry_exit(lo, hi, r, t_max);
        let tf = _mm256_mul_ps(tf, _mm256_set1_ps(EXIT_ROUNDING));
        (tn, _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32)
    }

    /// The eight rays' entry and exit distances of the box `lo`..`hi` within `[0, t_max]`, the
    /// exit not yet rounded up: near plane by the direction's sign, NaN distances ignored.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn entry_exit(lo: [f32; 3], hi: [f32; 3], r: &Rays8, t_max: __m256) -> (__m256, __m256) {
        let mut tn = _mm256_setzero_ps();
        let mut tf = t_max;
        for a in 0..3 {
            let t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(lo[a]), r.o[a]), r.inv[a]);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(hi[a]), r.o[a]), r.inv[a]);
            tn = _mm256_max_ps(_mm256_blendv_ps(t0, t1, r.neg[a]), tn);
            tf = _mm256_min_ps(_mm256_blendv_ps(t1, t0, r.neg[a]), tf);
        }
        (tn, tf)
    }

    /// Whether every ray of `active` misses the whole tree's box, so that no node need be
    /// looked at (a packet of camera rays beside the mesh). Conservative: the exit distance is
    /// rounded up twice over, beyond any rounding of the nodes' own tests of the boxes inside
    /// it, and the rays' `t_max` is left out.
    #[target_feature(enable = "avx2")]
    fn misses_tree(bvh: &Bvh, r: &Rays8, active: u8) -> bool {
        let b = &bvh.root_box;
        let (tn, tf) = entry_exit(b.min.to_array(), b.max.to_array(), r, _mm256_set1_ps(f32::INFINITY));
        let tf = _mm256_mul_ps(tf, _mm256_set1_ps(EXIT_ROUNDING * EXIT_ROUNDING));
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u8 & active == 0
    }

    /// A child a packet enters: its reference and lanes in one word (low and high half), so
    /// that the pair is written and read back whole (two 4-byte writes read as one 8-byte
    /// word would stall the read on store forwarding), and its entry distance.
    #[derive(Clone, Copy)]
    struct Kid {
        refs: u64,
        t: f32,
    }

    impl Kid {
        #[inline(always)]
        fn new(node: u32, lanes: u32, t: f32) -> Kid {
            Kid { refs: node as u64 | (lanes as u64) << 32, t }
        }

        #[inline(always)]
        fn node(self) -> u32 {
            self.refs as u32
        }

        #[inline(always)]
        fn lanes(self) -> u32 {
            (self.refs >> 32) as u32
        }
    }

    /// Pushes a child onto the stack, whose entries from `base` up to `*sp` (the node's
    /// children pushed so far) are kept in order of decreasing entry distance, so that the
    /// nearest is popped first; among equal distances the later one counts as nearer.
    #[inline(always)]
    fn push_sorted(stack: &mut [std::mem::MaybeUninit<Kid>], base: usize, sp: &mut usize, kid: Kid) {
        let mut p = *sp;
        // SAFETY: entries base..sp were written by this function.
        while p > base && unsafe { stack[p - 1].assume_init() }.t < kid.t {
            stack[p] = stack[p - 1];
            p -= 1;
        }
        stack[p].write(kid);
        *sp += 1;
    }

    /// A packet as one frustum: per axis, the range of the rays' origins and of their inverse
    /// directions, which must all have one sign. The box test on these ranges (interval
    /// arithmetic) is conservative: a box that any of the rays enters, the frustum enters.
    /// Camera rays through neighbouring pixels make a narrow frustum, tested at the cost of
    /// one ray instead of eight.
    struct Frustum {
        /// Per axis, the bound rows of the near and the far planes (min or max by the sign).
        near_row: [usize; 3],
        far_row: [usize; 3],
        /// The origin coordinate that brings each plane nearest (for the near plane) or
        /// farthest (for the far plane).
        near_o: [__m256; 3],
        far_o: [__m256; 3],
        /// The inverse directions' range.
        inv_lo: [__m256; 3],
        inv_hi: [__m256; 3],
    }

    /// Per axis, the range of a group of rays' origins and inverse directions, and the sign
    /// all their directions share.
    #[derive(Clone, Copy)]
    struct Ranges {
        neg: [bool; 3],
        o_lo: [f32; 3],
        o_hi: [f32; 3],
        inv_lo: [f32; 3],
        inv_hi: [f32; 3],
    }

    impl Ranges {
        /// The ranges of the `active` rays, or None where there are none or a direction
        /// component changes sign across them or is zero in one (its inverse is infinite).
        ///
        /// Always inlined into its callers, which are compiled for AVX2 (an out-of-line call
        /// cost the bench's packets 4 %); it carries no target feature of its own, which
        /// `#[inline(always)]` does not allow.
        ///
        /// # Safety
        /// The CPU must support AVX2.
        #[inline(always)]
        unsafe fn new(r: &Rays8, active: u8) -> Option<Ranges> {
            let active = active as i32;
            if active == 0 {
                return None;
            }
            // Lanes left out of the ranges are replaced by the identity of min or max.
            let lanes = lane_mask(active as u8);
            let (inf, ninf) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
            let lo = |v: __m256| hmin(_mm256_blendv_ps(inf, v, lanes));
            let hi = |v: __m256| hmax(_mm256_blendv_ps(ninf, v, lanes));
            let abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
            let mut neg = [false; 3];
            for (a, neg) in neg.iter_mut().enumerate() {
                let m = _mm256_movemask_ps(r.neg[a]) & active;
                let abs = _mm256_and_ps(r.inv[a], abs_mask);
                let ok = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_LT_OQ>(abs, inf),
                    _mm256_cmp_ps::<_CMP_GT_OQ>(abs, _mm256_setzero_ps()),
                );
                if (m != 0 && m != active) || _mm256_movemask_ps(ok) & active != active {
                    return None;
                }
                *neg = m != 0;
            }
            Some(Ranges { neg, o_lo: r.o.map(lo), o_hi: r.o.map(hi), inv_lo: r.inv.map(lo), inv_hi: r.inv.map(hi) })
        }

        /// The ranges of both groups, or None where their directions' signs differ.
        fn union(self, o: Ranges) -> Option<Ranges> {
            let lo = |a: [f32; 3], b: [f32; 3]| std::array::from_fn(|i| a[i].min(b[i]));
            let hi = |a: [f32; 3], b: [f32; 3]| std::array::from_fn(|i| a[i].max(b[i]));
            (self.neg == o.neg).then(|| Ranges {
                neg: self.neg,
                o_lo: lo(self.o_lo, o.o_lo),
                o_hi: hi(self.o_hi, o.o_hi),
                inv_lo: lo(self.inv_lo, o.inv_lo),
                inv_hi: hi(self.inv_hi, o.inv_hi),
            })
        }
    }

    impl Frustum {
        /// The frustum of the `active` rays, or None where [`Ranges::new`] finds none or the
        /// rays share neither their origin nor their direction.
        #[target_feature(enable = "avx2")]
        fn new(r: &Rays8, active: u8) -> Option<Frustum> {
            // SAFETY: this function is compiled for AVX2, which its callers guarantee.
            Frustum::of(unsafe { Ranges::new(r, active) }?)
        }

        /// The frustum of rays with ranges `g`, or None where the rays share neither their
        /// origin nor their direction.
        #[target_feature(enable = "avx2")]
        fn of(g: Ranges) -> Option<Frustum> {
            let Ranges { neg, o_lo, o_hi, inv_lo, inv_hi } = g;
            // Intervals of origins times intervals of directions make a tight frustum where one
            // of them is a point: one origin (a pinhole camera) or one direction (an
            // orthographic one). Rays from across a lens aimed at one focus point would make a
            // frustum far wider than the rays, which then enters most of the tree.
            if o_lo != o_hi && inv_lo != inv_hi {
                return None;
            }
            // A positive direction meets a plane nearest from the largest origin and farthest
            // from the smallest; a negative one the other way round.
            let pick = |a: usize, nearest: bool| _mm256_set1_ps(if neg[a] == nearest { o_lo[a] } else { o_hi[a] });
            Some(Frustum {
                near_row: std::array::from_fn(|a| if neg[a] { 3 + a } else { a }),
                far_row: std::array::from_fn(|a| if neg[a] { a } else { 3 + a }),
                near_o: std::array::from_fn(|a| pick(a, true)),
                far_o: std::array::from_fn(|a| pick(a, false)),
                inv_lo: inv_lo.map(|v| _mm256_set1_ps(v)),
                inv_hi: inv_hi.map(|v| _mm256_set1_ps(v)),
            })
        }

        /// Entry distances (lower bounds over the rays) of the node's eight boxes and the mask
        /// of those the frustum meets within `[0, t_max]`. Rounding is monotonic, so each
        /// bound is at most (entry) or at least (exit) what any ray's own slab test computes;
        /// the exit is rounded up as there.
        #[target_feature(enable = "avx2")]
        fn test(&self, bounds: &[[f32; WIDTH]; 6], t_max: f32) -> (__m256, u32) {
            let mut tn = _mm256_setzero_ps();
            let mut tf = _mm256_set1_ps(t_max);
            for a in 0..3 {
                // SAFETY: unaligned loads of eight floats.
                let (near, far) = unsafe {
                    (
                        _mm256_loadu_ps(bounds[self.near_row[a]].as_ptr()),
                        _mm256_loadu_ps(bounds[self.far_row[a]].as_ptr()),
                    )
                };
                let near = _mm256_sub_ps(near, self.near_o[a]);
                let far = _mm256_sub_ps(far, self.far_o[a]);
                // The inverse directions are finite (`Frustum::new`), so no distance is NaN,
                // and maxima and minima are taken on the floats' bits as in the single-ray
                // `slab_avx`: the entry's includes 0, and an extreme below zero stays below
                // zero and rejects the box.
                let near = imin8(_mm256_mul_ps(near, self.inv_lo[a]), _mm256_mul_ps(near, self.inv_hi[a]));
                let far = imax8(_mm256_mul_ps(far, self.inv_lo[a]), _mm256_mul_ps(far, self.inv_hi[a]));
                tn = imax8(tn, near);
                tf = imin8(tf, far);
            }
            let tf = _mm256_mul_ps(tf, _mm256_set1_ps(EXIT_ROUNDING));
            let outside = _mm256_cmpgt_epi32(_mm256_castps_si256(tn), _mm256_castps_si256(tf));
            (tn, _mm256_movemask_ps(_mm256_castsi256_ps(outside)) as u32 ^ 0xff)
        }
    }

    /// The smallest of the eight lanes.
    #[target_feature(enable = "avx2")]
    fn hmin(v: __m256) -> f32 {
        let m = _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let m = _mm_min_ps(m, _mm_movehl_ps(m, m));
        _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps::<1>(m, m)))
    }

    /// The largest of the eight lanes.
    #[target_feature(enable = "avx2")]
    fn hmax(v: __m256) -> f32 {
        let m = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let m = _mm_max_ps(m, _mm_movehl_ps(m, m));
        _mm_cvtss_f32(_mm_max_ss(m, _mm_shuffle_ps::<1>(m, m)))
    }

    /// All bits set in the lanes of the `active` mask, none in the others.
    #[target_feature(enable = "avx2")]
    fn lane_mask(active: u8) -> __m256 {
        let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(active as i32), bits), bits))
    }

    /// The largest `t_max` of the `active` lanes (−∞ for none; the bounds are never NaN).
    #[target_feature(enable = "avx2")]
    fn farthest(t_max: &[f32; 8], active: u8) -> f32 {
        // SAFETY: an unaligned load of eight floats.
        let t = unsafe { _mm256_loadu_ps(t_max.as_ptr()) };
        hmax(_mm256_blendv_ps(_mm256_set1_ps(f32::NEG_INFINITY), t, lane_mask(active)))
    }

    /// Packet traversal with the frustum: interior nodes are entered by the frustum test, and
    /// only a leaf's own box is tested ray by ray (with the single-ray arithmetic), so every
    /// ray tests the leaves its own traversal would, and perhaps a few more. The packet is `P`
    /// groups of eight rays under one frustum; lane masks hold eight bits per group, group
    /// `g`'s at bit `8g`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    unsafe fn frustum_walk<const P: usize>(
        bvh: &Bvh,
        r: &[Rays8; P],
        f: &Frustum,
        active: [u8; P],
        t_max: &mut [[f32; 8]; P],
        leaf: &mut impl FnMut(u32, u32, &mut [[f32; 8]; P]),
    ) {
        let farthest_all =
            |t_max: &[[f32; 8]; P]| (0..P).map(|g| farthest(&t_max[g], active[g])).fold(f32::NEG_INFINITY, f32::max);
        let all = (0..P).fold(0u32, |m, g| m | (active[g] as u32) << (8 * g));
        let mut far = farthest_all(t_max);
        // Only entries below `sp` are read.
        let mut stack = [std::mem::MaybeUninit::<Kid>::uninit(); (WIDTH - 1) * MAX_STACK];
        stack[0].write(Kid::new(0, all, 0.0));
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            // SAFETY: stack[sp] was written before sp was raised past it.
            let kid = unsafe { stack[sp].assume_init() };
            let (cur, mask) = (kid.node(), kid.lanes());
            if kid.t > far {
                continue;
            }
            if cur & LEAF != 0 {
                leaf(cur & !LEAF, mask, t_max);
                far = farthest_all(t_max);
                continue;
            }
            let n = bvh.node(cur);
            let (tn, hit) = f.test(&n.bounds, far);
            if hit == 0 {
                continue;
            }
            let mut t = [0.0f32; 8];
            // SAFETY: an unaligned store into a local array of eight floats.
            unsafe { _mm256_storeu_ps(t.as_mut_ptr(), tn) };
            // SAFETY: unaligned loads of each group's eight t_max.
            let tm: [__m256; P] = std::array::from_fn(|g| unsafe { _mm256_loadu_ps(t_max[g].as_ptr()) });
            // Children ordered far to near, so that the nearest is popped first.
            let base = sp;
            for j in crate::accel::lanes(hit) {
                let c = n.child[j];
                if c == EMPTY {
                    continue;
                }
                let lanes = if c & LEAF != 0 {
                    (0..P).fold(0u32, |m, g| m | (slab8(&n.bounds, j, &r[g], tm[g]).1 & active[g] as u32) << (8 * g))
                } else {
                    all
                };
                if lanes != 0 {
                    push_sorted(&mut stack, base, &mut sp, Kid::new(c, lanes, t[j]));
                }
            }
        }
    }

    /// [`closest8`] for `P` groups of eight rays under one frustum (each interior node is
    /// tested once for all of them); `test(group, leaf, lanes, t_max)` tests a group's rays.
    /// Where the groups make no frustum, each is traced as [`closest8`] traces it. Returns
    /// each group's mask of lanes that hit. `P` is at most 4 (lane masks of 32 bits).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest_groups<const P: usize>(
        bvh: &Bvh,
        rays: &[[Ray; 8]; P],
        active: [u8; P],
        t_max: &mut [[f32; 8]; P],
        test: &mut impl FnMut(usize, u32, u8, &mut [f32; 8]) -> u8,
    ) -> [u8; P] {
        const { assert!(P <= 4, "lane masks hold four groups of eight") };
        let mut hits = [0u8; P];
        if bvh.root_leaf || bvh.nodes.is_empty() {
            for (g, (t, h)) in t_max.iter_mut().zip(hits.iter_mut()).enumerate() {
                // SAFETY: the caller guarantees AVX2.
                *h = unsafe { closest8(bvh, &rays[g], active[g], t, &mut |leaf, lanes, t| test(g, leaf, lanes, t)) };
            }
            return hits;
        }
        // Idle groups (no active lane) are neither loaded nor tested.
        let r: [Rays8; P] = std::array::from_fn(|g| if active[g] != 0 { load(&rays[g]) } else { Rays8::IDLE });
        // Groups none of whose rays meet the tree's box take no further part.
        let live: [u8; P] = std::array::from_fn(|g| if misses_tree(bvh, &r[g], active[g]) { 0 } else { active[g] });
        if live.iter().all(|&a| a == 0) {
            return hits;
        }
        // One frustum for the groups that go on, where each makes one and their signs agree.
        // SAFETY: the caller guarantees AVX2.
        let each: [Option<Ranges>; P] = std::array::from_fn(|g| unsafe { Ranges::new(&r[g], live[g]) });
        let mut ranges = None;
        let mut frustum = true;
        for (g, m) in each.into_iter().enumerate() {
            if live[g] == 0 {
                continue;
            }
            ranges = match (m, ranges) {
                (Some(m), None) => Some(m),
                (Some(m), Some(all)) => m.union(all),
                (None, _) => None,
            };
            frustum &= ranges.is_some();
        }
        if let Some(f) = ranges.filter(|_| frustum).and_then(|g| Frustum::of(g)) {
            let mut leaf = |leaf: u32, mask: u32, t_max: &mut [[f32; 8]; P]| {
                for (g, (t, h)) in t_max.iter_mut().zip(hits.iter_mut()).enumerate() {
                    let lanes = (mask >> (8 * g)) as u8;
                    if lanes != 0 {
                        *h |= test(g, leaf, lanes, t);
                    }
                }
            };
            // SAFETY: the caller guarantees AVX2.
            unsafe { frustum_walk(bvh, &r, &f, live, t_max, &mut leaf) };
            return hits;
        }
        // Each group as `closest8` traces it, with its rays loaded and its box test made above.
        for (g, (t, h)) in t_max.iter_mut().zip(hits.iter_mut()).enumerate() {
            if live[g] != 0 {
                // SAFETY: the caller guarantees AVX2.
                *h = unsafe { walk8(bvh, &r[g], live[g], t, &mut |leaf, lanes, t| test(g, leaf, lanes, t)) };
            }
        }
        hits
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn closest8(
        bvh: &Bvh,
        rays: &[Ray; 8],
        active: u8,
        t_max: &mut [f32; 8],
        test: &mut impl FnMut(u32, u8, &mut [f32; 8]) -> u8,
    ) -> u8 {
        if bvh.root_leaf {
            return test(bvh.root_ref & !LEAF, active, t_max);
        }
        if bvh.nodes.is_empty() {
            return 0;
        }
        let r = load(rays);
        if misses_tree(bvh, &r, active) {
            return 0;
        }
        // SAFETY: the caller guarantees AVX2.
        unsafe { walk8(bvh, &r, active, t_max, test) }
    }

    /// [`closest8`]'s traversal of a tree of nodes, for rays already loaded (`r`) of which
    /// some `active` one meets the tree's box.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    unsafe fn walk8(
        bvh: &Bvh,
        r: &Rays8,
        active: u8,
        t_max: &mut [f32; 8],
        test: &mut impl FnMut(u32, u8, &mut [f32; 8]) -> u8,
    ) -> u8 {
        let mut hits = 0u8;
        if let Some(f) = Frustum::new(r, active) {
            let mut leaf =
                |leaf: u32, mask: u32, t_max: &mut [[f32; 8]; 1]| hits |= test(leaf, mask as u8, &mut t_max[0]);
            // SAFETY: the caller guarantees AVX2.
            unsafe { frustum_walk(bvh, std::array::from_ref(r), &f, [active], std::array::from_mut(t_max), &mut leaf) };
            return hits;
        }
        // Uninitialised, as in the single-ray traversal: only entries below `sp` are read.
        let mut stack = [std::mem::MaybeUninit::<Kid>::uninit(); (WIDTH - 1) * MAX_STACK];
        stack[0].write(Kid::new(0, active as u32, 0.0));
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            // SAFETY: stack[sp] was written before sp was raised past it.
            let kid = unsafe { stack[sp].assume_init() };
            let (cur, mask) = (kid.node(), kid.lanes());
            if cur & LEAF != 0 {
                hits |= test(cur & !LEAF, mask as u8, t_max);
                continue;
            }
            let n = bvh.node(cur);
            // SAFETY: an unaligned load of the eight bounds.
            let tm = unsafe { _mm256_loadu_ps(t_max.as_ptr()) };
            // Children hit by any lane still active, ordered far to near by the entry distance
            // of their first lane, so that the nearest is popped first.
            let base = sp;
            for j in 0..WIDTH {
                let c = n.child[j];
                if c == EMPTY {
                    continue;
                }
                let (tn, hit) = slab8(&n.bounds, j, r, tm);
                let m = hit & mask;
                if m == 0 {
                    continue;
                }
                let mut t = [0.0f32; 8];
                // SAFETY: an unaligned store into a local array of eight floats.
                unsafe { _mm256_storeu_ps(t.as_mut_ptr(), tn) };
                push_sorted(&mut stack, base, &mut sp, Kid::new(c, m, t[m.trailing_zeros() as usize]));
            }
        }
        hits
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use crate::sampling::Pcg32;
        use glam::Vec3;

        /// Wherever one of a packet's rays enters a box (its own slab test), the frustum test
        /// enters it too, no later: random packets (one origin, or one direction from origins
        /// spread as an orthographic camera's), random active lanes and `t_max`, random boxes.
        #[test]
        fn frustum_enters_every_box_a_ray_enters() {
            if !crate::accel::has_avx2_fma_popcnt() {
                eprintln!("no AVX2: the frustum traversal is not used on this CPU");
                return;
            }
            let mut rng = Pcg32::new(5, 6);
            let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
            let (mut frusta, mut entered) = (0, 0);
            for case in 0..6000 {
                // One origin (a pinhole camera), one direction (an orthographic one), or neither
                // (rays from across a lens), which gets no frustum.
                let (o_spread, d_spread) = [(0.0, 0.05), (u(0.0, 0.5), 0.0), (u(0.01, 0.5), 0.05)][case % 3];
                let centre = Vec3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)).normalize();
                let o0 = Vec3::new(u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0));
                let rays: [Ray; 8] = std::array::from_fn(|_| {
                    let d = centre + d_spread * Vec3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
                    let o = o0 + o_spread * Vec3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
                    Ray::new(o, d.normalize())
                });
                let active = (u(1.0, 256.0) as u32).min(255) as u8;
                let t_max: [f32; 8] =
                    std::array::from_fn(|_| if u(0.0, 1.0) < 0.3 { u(0.1, 5.0) } else { f32::INFINITY });
                // SAFETY: AVX2 was detected above.
                let (r, f) = unsafe {
                    let r = load(&rays);
                    let f = Frustum::new(&r, active);
                    (r, f)
                };
                if case % 3 == 2 && active.count_ones() > 1 {
                    assert!(f.is_none(), "case {case}: rays with neither one origin nor one direction");
                }
                let Some(f) = f else { continue };
                frusta += 1;
                let mut bounds = [[0.0f32; WIDTH]; 6];
                let (mins, maxs) = bounds.split_at_mut(3);
                for (lo, hi) in mins.iter_mut().flatten().zip(maxs.iter_mut().flatten()) {
                    let (c, h) = (u(-3.0, 3.0), u(0.0, 1.5));
                    (*lo, *hi) = (c - h, c + h);
                }
                // SAFETY: AVX2 was detected above; the load reads eight floats.
                let (ft, fmask, per_ray) = unsafe {
                    let (ft, fmask) = f.test(&bounds, farthest(&t_max, active));
                    let tm = _mm256_loadu_ps(t_max.as_ptr());
                    let per_ray: [(__m256, u32); WIDTH] = std::array::from_fn(|j| slab8(&bounds, j, &r, tm));
                    (ft, fmask, per_ray)
                };
                let mut fte = [0.0f32; 8];
                // SAFETY: a store into a local array of eight floats.
                unsafe { _mm256_storeu_ps(fte.as_mut_ptr(), ft) };
                for (j, (tn, m)) in per_ray.iter().enumerate() {
                    let m = m & active as u32;
                    if m == 0 {
                        continue;
                    }
                    entered += 1;
                    assert!(fmask & (1 << j) != 0, "case {case}: a ray enters box {j}, the frustum does not");
                    let mut t = [0.0f32; 8];
                    // SAFETY: a store into a local array of eight floats.
                    unsafe { _mm256_storeu_ps(t.as_mut_ptr(), *tn) };
                    for lane in crate::accel::lanes(m) {
                        assert!(fte[j] <= t[lane], "case {case}: the frustum enters box {j} after ray {lane}");
                    }
                }
            }
            assert!(frusta > 3000 && entered > 1000, "{frusta} frusta, {entered} boxes entered");
        }
    }
}

impl Accel for Bvh {
    type Params = BvhParams;

    fn closest_leaf_packet8(
        &self,
        rays: &[Ray; 8],
        active: u8,
        t_max: &mut [f32; 8],
        mut test: impl FnMut(u32, u8, &mut [f32; 8]) -> u8,
    ) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where AVX2, FMA and POPCNT were detected (`has_avx2_fma_popcnt`).
            return unsafe { packet::closest8(self, rays, active, t_max, &mut test) };
        }
        super::lane_by_lane(self, rays, active, t_max, test)
    }

    fn closest_leaf_packets<const P: usize>(
        &self,
        rays: &[[Ray; 8]; P],
        active: [u8; P],
        t_max: &mut [[f32; 8]; P],
        mut test: impl FnMut(usize, u32, u8, &mut [f32; 8]) -> u8,
    ) -> [u8; P] {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where AVX2, FMA and POPCNT were detected (`has_avx2_fma_popcnt`).
            return unsafe { packet::closest_groups(self, rays, active, t_max, &mut test) };
        }
        super::groups_one_by_one(self, rays, active, t_max, test)
    }

    fn build(boxes: &[Aabb], params: &BvhParams) -> Self {
        Self::build_clipped(boxes, params, &super::clip_box)
    }

    fn build_clipped(boxes: &[Aabb], params: &BvhParams, clip: &super::Clipper<'_>) -> Self {
        use rayon::prelude::*;
        // Boxes that are empty (degenerate triangles) are left out. Usually there are none, and
        // then the list is an indexed collect, cheaper than a filtered one.
        let mut prims: Vec<u32> = if boxes.par_iter().any(|b| b.is_empty()) {
            (0..boxes.len() as u32).into_par_iter().filter(|&i| !boxes[i as usize].is_empty()).collect()
        } else {
            (0..boxes.len() as u32).into_par_iter().collect()
        };
        let mut base = params.base;
        base.max_depth = base.max_depth.min(MAX_STACK - 1);
        base.max_leaf_prims = base.max_leaf_prims.max(1);
        let b = Builder { params: base, split: params.split, parallel_min: Builder::parallel_min(prims.len()) };
        let bin = if prims.is_empty() {
            Vec::new()
        } else if params.split == SplitMethod::Spatial {
            let refs: Vec<Ref> = prims.iter().map(|&p| Ref { prim: p, b: boxes[p as usize] }).collect();
            let root_area = refs.iter().fold(Aabb::EMPTY, |a, r| a.union(r.b)).half_area();
            let sb = SpatialBuilder {
                clip,
                params: base,
                root_area,
                budget: std::sync::atomic::AtomicIsize::new((prims.len() as f32 * SBVH_BUDGET) as isize),
            };
            let (nodes, refs) = sb.build(refs, 0);
            prims = refs;
            nodes
        } else {
            let mut refs: Vec<PRef> = prims
                .par_iter()
                .map(|&p| {
                    let pb = boxes[p as usize];
                    PRef { min: pb.min.to_array(), id: p, max: pb.max.to_array(), code: 0 }
                })
                .collect();
            if params.split == SplitMethod::Morton {
                let cb = refs.iter().fold(Aabb::EMPTY, |b, r| b.grow(r.aabb().center()));
                for r in &mut refs {
                    r.code = morton(r.aabb().center(), &cb);
                }
                refs.sort_unstable_by_key(|r| (r.code, r.id));
            }
            let nodes = b.subtree(&mut refs, 0, 0);
            prims = refs.par_iter().map(|r| r.id).collect();
            nodes
        };
        // The statistics and the wide tree are independent walks of the binary tree.
        let ((max_depth_seen, sah_cost), (nodes, leaves, root_leaf)) = rayon::join(
            || (binary_depth(&bin), binary_sah_cost(&bin, &base)),
            || match bin.first() {
                None => (Vec::new(), Vec::new(), false),
                Some(root) if root.count > 0 => (Vec::new(), vec![(root.first, root.count)], true),
                Some(_) => {
                    let (n, l, _) = collapse(&bin);
                    (n, l, false)
                }
            },
        );
        let stats = AccelStats {
            nodes: nodes.len(),
            leaves: leaves.len(),
            max_depth: max_depth_seen,
            prim_refs: prims.len(),
            bytes: nodes.len() * std::mem::size_of::<Wide>() + leaves.len() * 8 + prims.len() * 4,
            sah_cost,
        };
        let root_box = bin.first().map_or(Aabb::EMPTY, |n| n.aabb());
        let (avx, avx512) = (has_avx2_fma_popcnt(), has_avx512());
        Bvh { nodes, leaves, prims, root_leaf, root_ref: LEAF, relabeled: false, root_box, stats, avx, avx512 }
    }

    fn closest_counted(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_leaf_counted(
            ray,
            t_max,
            |leaf, mut tm| {
                let mut best = None;
                for &p in self.leaf(leaf) {
                    if let Some(t) = test(p, tm) {
                        tm = t;
                        best = Some(t);
                    }
                }
                best
            },
            counter,
        )
    }

    fn any_counted(
        &self,
        ray: &Ray,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_leaf_counted(ray, t_max, |leaf, tm| self.leaf(leaf).iter().any(|&p| test(p, tm)), counter)
    }

    fn relabel_leaves(&mut self, labels: &[u32]) -> bool {
        if self.relabeled || labels.len() != self.leaves.len() || labels.iter().any(|&l| l >= LEAF - 1) {
            return false;
        }
        for n in &mut self.nodes {
            for c in &mut n.child {
                if *c != EMPTY && *c & LEAF != 0 {
                    *c = LEAF | labels[(*c & !LEAF) as usize];
                }
            }
        }
        if self.root_leaf {
            self.root_ref = LEAF | labels[0];
        }
        self.relabeled = true;
        // Nothing reads the leaves' primitive lists any more: the labels stand for them.
        (self.leaves, self.prims) = (Vec::new(), Vec::new());
        self.stats.bytes = self.nodes.len() * std::mem::size_of::<Wide>();
        true
    }

    fn leaves(&self) -> Option<Vec<&[u32]>> {
        Some(self.leaves.iter().map(|&(first, count)| &self.prims[first as usize..(first + count) as usize]).collect())
    }

    #[inline(always)]
    fn closest_leaf_counted(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_on_cpu::<false>(ray, t_max, test, counter)
    }

    #[inline(always)]
    fn any_leaf_counted(
        &self,
        ray: &Ray,
        t_max: f32,
        test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_on_cpu::<false>(ray, t_max, test, counter)
    }

    /// The AVX-512 walk with the test inlined where the CPU has it; elsewhere the AVX2 walk
    /// keeps its call to the test (inlined there, the ray's constants went to memory).
    #[inline(always)]
    fn closest_leaf_inlined(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        if self.avx512 {
            self.closest_on_cpu::<true>(ray, t_max, test, counter)
        } else {
            self.closest_on_cpu::<false>(ray, t_max, super::called(&mut test), counter)
        }
    }

    #[inline(always)]
    fn any_leaf_inlined(
        &self,
        ray: &Ray,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        if self.avx512 {
            self.any_on_cpu::<true>(ray, t_max, test, counter)
        } else {
            self.any_on_cpu::<false>(ray, t_max, super::called(&mut test), counter)
        }
    }

    fn boxes_at_depth(&self, depth: usize) -> Vec<Aabb> {
        // Depth 0 is the root box; depth d the children of the wide nodes at depth d - 1.
        if self.root_box.is_empty() {
            return Vec::new();
        }
        if depth == 0 {
            return vec![self.root_box];
        }
        let mut out = Vec::new();
        let mut todo = if self.nodes.is_empty() { Vec::new() } else { vec![(0usize, 1usize)] };
        while let Some((i, d)) = todo.pop() {
            let n = &self.nodes[i];
            for j in 0..WIDTH {
                if n.child[j] == EMPTY {
                    continue;
                }
                if d == depth {
                    let b = &n.bounds;
                    out.push(Aabb {
                        min: glam::Vec3::new(b[0][j], b[1][j], b[2][j]),
                        max: glam::Vec3::new(b[3][j], b[4][j], b[5][j]),
                    });
                } else if n.child[j] & LEAF == 0 {
                    todo.push((node_index(n.child[j]), d + 1));
                }
            }
        }
        out
    }

    fn stats(&self) -> AccelStats {
        self.stats
    }
}

/// Depth of the deepest leaf of the binary tree (the root has depth 0).
fn binary_depth(bin: &[Node]) -> usize {
    let mut max = 0;
    let mut stack = vec![(0usize, 0usize)];
    while let Some((i, d)) = stack.pop() {
        if i >= bin.len() {
            continue;
        }
        max = max.max(d);
        if bin[i].count == 0 {
            stack.push((i + 1, d + 1));
            stack.push((bin[i].first as usize, d + 1));
        }
    }
    max
}

/// SAH cost of the binary tree, relative to the root's area.
fn binary_sah_cost(nodes: &[Node], params: &AccelParams) -> f32 {
    let root_area = nodes.first().map_or(0.0, |n| n.aabb().half_area());
    let mut sah = 0.0f64;
    for n in nodes {
        let a = if root_area > 0.0 { (n.aabb().half_area() / root_area) as f64 } else { 1.0 };
        sah += if n.count > 0 {
            a * params.intersect_cost as f64 * n.count as f64
        } else {
            a * params.traversal_cost as f64
        };
    }
    sah as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::NoCount;
    use crate::sampling::Pcg32;

    /// [`slab_avx`] with its entry distances returned. The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    unsafe fn slab_avx_pair<const FUSED: bool>(n: &Wide, r: &RayPre, t_max: f32) -> ([f32; WIDTH], u32) {
        let mut t = [0.0f32; WIDTH];
        // SAFETY: the caller checked for AVX2 and FMA.
        let mask = unsafe { slab_avx::<FUSED>(n, Rows::of(n, r), r, r.finite, t_max, &mut t) };
        (t, mask)
    }

    /// Every plane, empty bins included, as the sweep looked before it skipped them.
    fn sweep_every_plane<const N: usize>(bins: &Bins<N>, n: &[usize; N], block: usize) -> Option<(f32, usize)> {
        let mut best: Option<(f32, usize)> = None;
        for k in 1..N {
            let (nl, nr): (usize, usize) = (n[..k].iter().sum(), n[k..].iter().sum());
            if nl == 0 || nr == 0 {
                continue;
            }
            let cost = bins.union(0..k).half_area() * nl.div_ceil(block) as f32
                + bins.union(k..N).half_area() * nr.div_ceil(block) as f32;
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, k));
            }
        }
        best
    }

    /// Skipping empty bins chooses the plane, at the cost, that trying every plane chooses.
    #[test]
    fn sweep_over_occupied_bins_matches_every_plane() {
        let mut rng = Pcg32::new(3, 5);
        for case in 0..2000 {
            let mut bins = Bins::<BINS>::new();
            let mut n = [0usize; BINS];
            for _ in 0..1 + case % 12 {
                let k = (rng.next_f32() * BINS as f32) as usize % BINS;
                let lo = Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0;
                bins.grow(k, lo, lo + Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()));
                n[k] += 1;
            }
            for block in [1, 4] {
                let got = sah_sweep(&bins, &n, &n, block);
                let want = sweep_every_plane(&bins, &n, block);
                match (got, want) {
                    (Some((c, k)), Some((cw, kw))) => {
                        assert_eq!(k, kw, "case {case}");
                        assert!((c - cw).abs() <= 1e-4 * cw.abs().max(1.0), "case {case}: {c} vs {cw}");
                    }
                    (g, w) => assert_eq!(g.is_none(), w.is_none(), "case {case}"),
                }
            }
        }
    }

    /// Binning in pieces and merging gives the bins of binning everything at once (as the
    /// parallel binning of large nodes does), whichever way the list is cut.
    #[test]
    fn merged_bins_match_binning_all_at_once() {
        let mut rng = Pcg32::new(13, 4);
        let mut v = || Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let refs: Vec<PRef> = (0..5000)
            .map(|i| {
                let lo = v() * 10.0;
                let hi = lo + v();
                PRef { min: lo.to_array(), id: i, max: hi.to_array(), code: 0 }
            })
            .collect();
        let (lo, scale) = (Vec3A::splat(0.5), Vec3A::splat(BINS as f32 / 10.0));
        let key = |(b, n): &([Bins<BINS>; 3], [[usize; BINS]; 3])| {
            let boxes: Vec<[u32; 6]> = b
                .iter()
                .flat_map(|b| (0..BINS).map(|k| [b.min[k].to_array(), b.max[k].to_array()]))
                .map(|[l, h]| [l[0], l[1], l[2], h[0], h[1], h[2]].map(f32::to_bits))
                .collect();
            (boxes, *n)
        };
        let whole = key(&bin_refs(&refs, lo, scale));
        for cut in [0, 1, 777, 2500, 4999, 5000] {
            let (a, b) = refs.split_at(cut);
            let merged = merge_bins(bin_refs(a, lo, scale), bin_refs(b, lo, scale));
            assert!(key(&merged) == whole, "cut at {cut}");
        }
        let pieces = refs.chunks(300).map(|c| bin_refs(c, lo, scale)).reduce(merge_bins).unwrap();
        assert!(key(&pieces) == whole, "in pieces of 300");
    }

    /// The branch-free partition splits as the predicate says, keeps every element once, and
    /// keeps the left side in input order.
    #[test]
    fn partition_in_place_splits_by_the_predicate() {
        let mut rng = Pcg32::new(5, 1);
        for len in 0..200 {
            let v: Vec<u32> = (0..len).map(|_| (rng.next_f32() * 1000.0) as u32).collect();
            let mut w = v.clone();
            let mid = partition_in_place(&mut w, |&x| x % 3 == 0);
            let left: Vec<u32> = v.iter().copied().filter(|x| x % 3 == 0).collect();
            assert_eq!(w[..mid], left[..], "len {len}");
            assert!(w[mid..].iter().all(|x| x % 3 != 0), "len {len}");
            let (mut a, mut b) = (v.clone(), w.clone());
            a.sort_unstable();
            b.sort_unstable();
            assert_eq!(a, b, "len {len}");
        }
    }

    /// The three-axis sweep finds, per axis, the plane and the bitwise cost of the sweep of
    /// that axis alone, with empty bins, lone occupied bins and empty axes among the cases.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn three_axis_sweep_matches_the_single_axis_sweeps() {
        let mut rng = Pcg32::new(7, 9);
        let mut with_plane = 0;
        for case in 0..3000 {
            let mut bins = [Bins::<BINS>::new(), Bins::new(), Bins::new()];
            let mut n = [[0usize; BINS]; 3];
            let prims = case % 23;
            for _ in 0..prims {
                let lo = Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0;
                let hi = lo + Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * (case % 3) as f32;
                for axis in 0..3 {
                    // Some cases crowd every reference into few bins of an axis.
                    let spread = if case % 5 == axis { 2 } else { BINS };
                    let k = (rng.next_f32() * spread as f32) as usize % BINS;
                    bins[axis].grow(k, lo, hi);
                    n[axis][k] += 1;
                }
            }
            for block in [1, 2, 4] {
                let got = sah_sweep3(&bins, &n, block);
                for axis in 0..3 {
                    let want = sah_sweep(&bins[axis], &n[axis], &n[axis], block);
                    let bits = |r: Option<(f32, usize)>| r.map(|(c, k)| (c.to_bits(), k));
                    assert_eq!(bits(got[axis]), bits(want), "case {case}, block {block}, axis {axis}");
                    with_plane += want.is_some() as usize;
                }
            }
        }
        assert!(with_plane > 10_000, "most cases have a plane ({with_plane})");
    }

    /// The wide slab test is conservative: every child box that `Aabb::slab` enters within
    /// `(0, t_max]` it enters too, at the same entry distance, and it never enters an empty
    /// slot; the AVX2 test gives the same distances and mask. Random boxes (some flat, some
    /// with a plane through the ray's origin), rays with and without a zero direction
    /// component (the integer and the float extremes), finite and infinite `t_max`.
    #[test]
    fn wide_slab_test_enters_every_box_the_exact_test_enters() {
        let mut rng = Pcg32::new(5, 9);
        let (mut entered, mut float_path) = (0, 0);
        for case in 0..40_000 {
            let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let kids = 1 + case % WIDTH;
            let mut boxes: Vec<Aabb> = (0..kids)
                .map(|_| {
                    let c = v() * 4.0 - glam::Vec3::splat(2.0);
                    Aabb::EMPTY.grow(c).grow(c + v())
                })
                .collect();
            if case % 3 == 0 {
                boxes[0].max.y = boxes[0].min.y; // flat
            }
            let mut o = v() * 6.0 - glam::Vec3::splat(3.0);
            // Mostly aimed at a box, so that many are entered.
            let aim = boxes[case % kids].center() + (v() - glam::Vec3::splat(0.5)) * 0.8;
            let mut d = if case % 4 == 3 { v() - glam::Vec3::splat(0.5) } else { aim - o };
            match case % 7 {
                0 => {
                    d.x = 0.0;
                    o.x = if case % 2 == 0 { boxes[0].min.x } else { boxes[0].max.x };
                }
                1 => o.z = boxes[case % kids].max.z,
                2 => d.y = -0.0,
                // Through a corner: entry and exit meet, and only the rounding keeps the box.
                3 => d = boxes[case % kids].max - o,
                // Leaving a box through its face: its exit distance is -0.0.
                4 => {
                    o.z = boxes[case % kids].min.z;
                    d.z = -d.z.abs();
                }
                _ => {}
            }
            let t_max = if case % 2 == 0 { f32::INFINITY } else { rng.next_f32() * 5.0 };
            let mut n = Wide::EMPTY;
            for (j, b) in boxes.iter().enumerate() {
                for a in 0..3 {
                    n.bounds[a][j] = b.min[a];
                    n.bounds[3 + a][j] = b.max[a];
                }
            }
            let inv = d.recip();
            let r = RayPre::new(&Ray::new(o, d), inv);
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX2 and FMA were detected.
            let r_fused = has_avx2_fma_popcnt().then(|| unsafe { RayPre::new_fused(&Ray::new(o, d), inv) });
            float_path += usize::from(!r.finite);
            let (t, mask) = slab(&n, &r, t_max);
            for (j, &tj) in t.iter().enumerate() {
                // Boxes the ray meets at some t > 0 (a box touched only at t = 0 can hold no
                // hit, and the integer test may leave it out).
                let exact = boxes
                    .get(j)
                    .filter(|b| b.slab(o, inv, f32::MIN_POSITIVE, t_max).is_some())
                    .and_then(|b| b.slab(o, inv, 0.0, t_max));
                if let Some(te) = exact {
                    assert!(mask & (1 << j) != 0, "case {case}: box {j} missed");
                    assert_eq!(tj, te, "case {case}: box {j}");
                    entered += 1;
                }
                if j >= kids {
                    assert_eq!(mask & (1 << j), 0, "case {case}: empty slot {j} entered");
                }
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(r_fused) = r_fused {
                // Unfused: `slab`'s arithmetic, so its distances and mask.
                // SAFETY: AVX2 and FMA were detected.
                let (tu, mu) = unsafe { slab_avx_pair::<false>(&n, &r, t_max) };
                assert_eq!((tu.map(f32::to_bits), mu), (t.map(f32::to_bits), mask), "case {case}");
                let r = r_fused;
                // SAFETY: AVX2 and FMA were detected.
                let (ta, ma) = unsafe { slab_avx_pair::<true>(&n, &r, t_max) };
                if !r.finite {
                    // `slab`'s arithmetic, so its distances and mask.
                    assert_eq!((ta.map(f32::to_bits), ma), (t.map(f32::to_bits), mask), "case {case}");
                }
                // Every box `slab` enters, no empty slot, and entry distances at or below the
                // exact one (in f64) rounded to nearest, less than a few ulps of `|o · inv|`
                // below it.
                assert_eq!(ma & mask, mask, "case {case}: the FMA test missed a box");
                assert_eq!(ma >> kids, 0, "case {case}: empty slot entered");
                let slack = (0..3).map(|a| (o[a] * inv[a]).abs()).filter(|x| x.is_finite()).fold(0.0f32, f32::max)
                    * 8.0
                    * f32::EPSILON;
                for j in (0..kids).filter(|j| r.finite && mask & (1 << j) != 0) {
                    let b = &boxes[j];
                    let exact = (0..3).fold(0.0f64, |e, a| {
                        let near = if inv[a] < 0.0 { b.max[a] } else { b.min[a] };
                        e.max((near as f64 - o[a] as f64) * inv[a] as f64)
                    }) as f32;
                    assert!(
                        ta[j] <= exact && exact - ta[j] <= slack + 2.0 * exact * f32::EPSILON,
                        "case {case}: box {j} at {} against {exact}",
                        ta[j]
                    );
                }
            }
        }
        assert!(entered > 8_000 && float_path > 4_000, "{entered} boxes entered, {float_path} float tests");
    }

    /// The fused slab test ([`slab_avx`]) enters every box `slab` enters, at every scale:
    /// scenes from 1e-15 to 1e15 across and far from the origin, rays grazing faces, edges and
    /// corners, direction components from 1e-9 to 1 of each other (where `|o · inv|` is far
    /// larger than the distances the planes are at).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn fused_slab_test_enters_every_box_slab_enters_at_every_scale() {
        if !has_avx2_fma_popcnt() {
            return;
        }
        let mut rng = Pcg32::new(21, 4);
        let (mut entered, mut fused_rays) = (0, 0);
        for case in 0..60_000 {
            let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let scale = 10f32.powi((case % 11) as i32 * 3 - 15);
            let offset = (v() - glam::Vec3::splat(0.5)) * scale * [0.0, 1.0, 1e3, 1e6][case % 4];
            let kids = 1 + case % WIDTH;
            let boxes: Vec<Aabb> = (0..kids)
                .map(|_| {
                    let c = offset + (v() * 4.0 - glam::Vec3::splat(2.0)) * scale;
                    Aabb::EMPTY.grow(c).grow(c + v() * scale)
                })
                .collect();
            let o = offset + (v() * 6.0 - glam::Vec3::splat(3.0)) * scale;
            let b = &boxes[case % kids];
            // A corner, an edge's midpoint or a face's centre of one box, or a point inside it.
            let target = match case % 4 {
                0 => b.max,
                1 => glam::Vec3::new(b.min.x, b.max.y, 0.5 * (b.min.z + b.max.z)),
                2 => glam::Vec3::new(b.min.x, 0.5 * (b.min.y + b.max.y), 0.5 * (b.min.z + b.max.z)),
                _ => b.min + v() * (b.max - b.min),
            };
            let squash = glam::Vec3::new(1.0, 10f32.powi(-((case / 4 % 10) as i32)), 1.0);
            let d = (target - o) * squash;
            let inv = d.recip();
            let ray = Ray::new(o, d);
            let (r, t_max) = (RayPre::new(&ray, inv), if case % 2 == 0 { f32::INFINITY } else { 1.0 });
            // SAFETY: AVX2 and FMA were detected.
            let rf = unsafe { RayPre::new_fused(&ray, inv) };
            let mut n = Wide::EMPTY;
            for (j, b) in boxes.iter().enumerate() {
                for a in 0..3 {
                    n.bounds[a][j] = b.min[a];
                    n.bounds[3 + a][j] = b.max[a];
                }
            }
            let (_, mask) = slab(&n, &r, t_max);
            // SAFETY: AVX2 and FMA were detected.
            let (_, ma) = unsafe { slab_avx_pair::<true>(&n, &rf, t_max) };
            assert_eq!(ma & mask, mask, "case {case}: the fused test missed a box slab enters");
            assert_eq!(ma >> kids, 0, "case {case}: empty slot entered");
            entered += mask.count_ones();
            fused_rays += usize::from(rf.finite);
        }
        assert!(entered > 10_000 && fused_rays > 50_000, "{entered} boxes entered, {fused_rays} fused rays");
    }

    /// The walk's AVX2 placement of three or more hit children gives the insertion sort's
    /// stack, ties included.
    #[test]
    fn children_placed_by_rank_as_the_insertion_sort_orders_them() {
        if !has_avx2_fma_popcnt() {
            return;
        }
        let mut rng = Pcg32::new(5, 9);
        let mut n = Wide::EMPTY;
        n.child = std::array::from_fn(|j| 100 + j as u32);
        let mut compared = 0;
        for _ in 0..20_000 {
            let mask = rng.next_u32() & 0xff;
            if mask.count_ones() < 3 {
                continue;
            }
            // Few distinct distances, so that ties (children entered at once, as from inside
            // their boxes) are common; zero and infinity among them.
            let t: [f32; WIDTH] = std::array::from_fn(|_| match rng.next_u32() % 6 {
                0 => 0.0,
                1 => f32::INFINITY,
                k => k as f32 * 0.25 + (rng.next_u32() % 2) as f32 * 1e-7,
            });
            let run = |rank: bool| {
                let mut stack = [std::mem::MaybeUninit::<(u32, f32)>::uninit(); 2 * WIDTH];
                stack[0].write((7, 7.0));
                let mut sp = 1;
                // SAFETY: AVX2, FMA and POPCNT were detected above.
                let next = if rank {
                    unsafe { push_by_rank(&[], &n, &t, mask, &mut stack, &mut sp) }
                } else {
                    push_by_insertion(&[], &n, &t, mask, &mut stack, &mut sp)
                };
                // SAFETY: the entries below `sp` were written.
                let pushed: Vec<(u32, u32)> =
                    (0..sp).map(|i| unsafe { stack[i].assume_init() }).map(|(r, d)| (r, d.to_bits())).collect();
                (next, pushed)
            };
            let (by_rank, sorted) = (run(true), run(false));
            assert_eq!(by_rank, sorted, "mask {mask:08b}, t {t:?}");
            assert_eq!(by_rank.1.len(), mask.count_ones() as usize, "the entry below and all but the nearest");
            compared += 1;
        }
        assert!(compared > 10_000);
    }

    /// Which compilation of the walks a test runs.
    #[derive(Clone, Copy, Debug)]
    enum Walk {
        Portable,
        /// The CPU must have AVX2, FMA and POPCNT.
        Avx2 {
            fused: bool,
        },
        /// The CPU must have what [`has_avx512`] checks.
        Avx512 {
            fused: bool,
        },
    }

    /// The closest-hit walk `walk`: whether it hit, and the bound it lowered `t` to.
    fn closest_walk_with(
        bvh: &Bvh,
        ray: &Ray,
        walk: Walk,
        t: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        // SAFETY: the callers ask for a compiled walk only where its features were detected.
        unsafe {
            match walk {
                Walk::Portable => bvh.closest_walk::<false, false, false>(ray, t, test, &NoCount),
                Walk::Avx2 { fused: true } => bvh.closest_avx::<true>(ray, t, test, &NoCount),
                Walk::Avx2 { fused: false } => bvh.closest_avx::<false>(ray, t, test, &NoCount),
                Walk::Avx512 { fused: true } => bvh.closest_avx512::<true>(ray, t, test, &NoCount),
                Walk::Avx512 { fused: false } => bvh.closest_avx512::<false>(ray, t, test, &NoCount),
            }
        }
    }

    /// The any-hit walk `walk`.
    fn any_walk_with(bvh: &Bvh, ray: &Ray, walk: Walk, t_max: f32, test: impl FnMut(u32, f32) -> bool) -> bool {
        // SAFETY: as in `closest_walk_with`.
        unsafe {
            match walk {
                Walk::Portable => bvh.any_walk::<false, false>(ray, t_max, test, &NoCount),
                Walk::Avx2 { fused: true } => bvh.any_avx::<true>(ray, t_max, test, &NoCount),
                Walk::Avx2 { fused: false } => bvh.any_avx::<false>(ray, t_max, test, &NoCount),
                Walk::Avx512 { fused: true } => bvh.any_avx512::<true>(ray, t_max, test, &NoCount),
                Walk::Avx512 { fused: false } => bvh.any_avx512::<false>(ray, t_max, test, &NoCount),
            }
        }
    }

    /// The AVX2 traversal finds what the portable one finds. Its slab test's distances differ
    /// from the portable one's by a few ulps ([`slab_avx`]), so children with almost the same
    /// entry distance may be visited in the other order and a leaf at the edge of a box may
    /// be tested by one and not the other; on these random boxes that hardly ever happens.
    /// Where the CPU has AVX-512, its copies of the AVX2 walks reach the same leaves in the
    /// same order.
    #[test]
    fn avx_traversal_matches_the_portable_one() {
        if !has_avx2_fma_popcnt() {
            return;
        }
        let avx512 = has_avx512();
        let mut rng = Pcg32::new(11, 2);
        let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let boxes: Vec<Aabb> = (0..3000)
            .map(|_| {
                let c = v() * 10.0;
                Aabb::EMPTY.grow(c).grow(c + v() * 0.5)
            })
            .collect();
        let bvh = Bvh::build(&boxes, &BvhParams { split: SplitMethod::Sah, base: AccelParams::default() });
        assert!(bvh.nodes.len() > 50, "a tree several levels deep");
        let (mut axis_aligned, mut differ, mut many_leaves) = (0, 0, 0);
        for i in 0..4000 {
            let mut o = v() * 14.0 - glam::Vec3::splat(2.0);
            let mut d = v() - glam::Vec3::splat(0.5);
            if i % 4 == 0 {
                // A zero direction component, the origin on a box's plane: the slab test's
                // infinities and its NaN (0 · inf).
                d.x = 0.0;
                o.x = boxes[(o.y.abs() * 100.0) as usize % boxes.len()].min.x;
                axis_aligned += 1;
            }
            let ray = Ray::new(o, d);
            let inv = d.recip();
            let walk = |walk: Walk| {
                let mut seen = Vec::new();
                let mut t = f32::INFINITY;
                let test = |leaf: u32, tm: f32| {
                    seen.push((leaf, tm.to_bits()));
                    let best =
                        bvh.leaf(leaf).iter().filter_map(|&p| boxes[p as usize].slab(o, inv, 0.0, tm)).reduce(f32::min);
                    best.filter(|&t| t < tm)
                };
                let hit = closest_walk_with(&bvh, &ray, walk, &mut t, test);
                (hit, t.to_bits(), seen)
            };
            let fused = walk(Walk::Avx2 { fused: true });
            let unfused = walk(Walk::Avx2 { fused: false });
            let portable = walk(Walk::Portable);
            assert_eq!(unfused, portable, "ray {i}: the unfused test is `slab`'s arithmetic");
            assert_eq!((fused.0, fused.1), (portable.0, portable.1), "ray {i}");
            differ += usize::from(fused.2 != portable.2);
            // Leaves reached, in order, and whether one blocks the ray within 5.
            let any = |walk: Walk| {
                let mut seen = Vec::new();
                let test = |leaf: u32, tm: f32| {
                    seen.push(leaf);
                    bvh.leaf(leaf).iter().any(|&p| boxes[p as usize].slab(o, inv, 0.0, tm).is_some())
                };
                (any_walk_with(&bvh, &ray, walk, 5.0, test), seen)
            };
            let blocked = any(Walk::Portable).0;
            assert_eq!(any(Walk::Avx2 { fused: true }).0, blocked, "ray {i}");
            assert_eq!(any(Walk::Avx2 { fused: false }).0, blocked, "ray {i}");
            if avx512 {
                // The AVX-512 copies are the AVX2 walks compiled with more registers (the
                // closest-hit one taking its next child by `visit_avx512`): the same leaves in
                // the same order, with the same bounds.
                for fused in [true, false] {
                    let (wide, avx2) = (Walk::Avx512 { fused }, Walk::Avx2 { fused });
                    assert_eq!(walk(wide), walk(avx2), "ray {i}: {wide:?}");
                    assert_eq!(any(wide), any(avx2), "ray {i}: {wide:?}");
                }
            }
            // Where nothing blocks the ray, the any-hit walk reaches every leaf it enters: the
            // AVX2 walk (the unfused test, `slab`'s arithmetic) in the portable walk's order,
            // so its pushes drop, repeat and reorder no child.
            let every_leaf = |walk: Walk| {
                let mut seen = Vec::new();
                let test = |leaf: u32, _| {
                    seen.push(leaf);
                    false
                };
                (any_walk_with(&bvh, &ray, walk, f32::INFINITY, test), seen)
            };
            let (avx_leaves, portable_leaves) = (every_leaf(Walk::Avx2 { fused: false }), every_leaf(Walk::Portable));
            assert_eq!(avx_leaves, portable_leaves, "ray {i}: the any-hit walks' leaves");
            many_leaves += usize::from(portable_leaves.1.len() >= 3);
        }
        assert!(axis_aligned > 0);
        assert!(many_leaves > 1000, "only {many_leaves} rays reach three leaves or more");
        assert!(differ <= 4, "{differ} of 4000 rays visit other leaves or in another order");
    }
}
