//! Acceleration structures, kept apart from the scene.
//!
//! An accelerator is built over a list of primitive bounding boxes and knows nothing else
//! about the primitives: traversal hands candidate primitive indices to a closure that does
//! the exact test (the design of the `obvhs` crate). The same structure therefore serves as
//! the bottom level (triangles of one mesh) and as the top level (objects, which may be
//! transformed instances of shared meshes). Closest hit and any hit are separate queries.
//!
//! The kind is chosen at run time ([`AccelKind`]) but only once per render:
//! [`AccelKind::build_world`] returns an [`AnyWorld`], an enum over `World<A>` for each
//! implementation, and the render loop is generic over `A`, so traversal has no dynamic
//! dispatch.

mod brute;
mod bvh;
mod grid;
mod kdtree;

use std::fmt;
use std::str::FromStr;

pub use brute::Brute;
pub(crate) use bvh::has_avx2_fma_popcnt;
pub use bvh::{Bvh, SplitMethod, WIDTH as BVH_WIDTH};
pub use grid::{Grid, GridParams};
pub use kdtree::{KdParams, KdTree};

use crate::geometry::{Aabb, Ray};
use crate::scene::{Scene, World};

/// A closure of its own around `test`, which may be marked `#[inline(always)]`: a walk given
/// it keeps the choice of inlining it (see [`Accel::closest_leaf_inlined`]).
#[inline(always)]
pub(crate) fn called<R>(test: &mut impl FnMut(u32, f32) -> R) -> impl FnMut(u32, f32) -> R + '_ {
    move |leaf, t_max| test(leaf, t_max)
}

/// The interface every acceleration structure implements.
pub trait Accel: Send + Sync + Sized {
    /// Build settings: [`AccelParams`] or a superset of them.
    type Params: BuildParams;

    /// Builds over the primitives' boxes; primitive `i` has box `boxes[i]`. Empty boxes are
    /// allowed (such primitives are never reported).
    fn build(boxes: &[Aabb], params: &Self::Params) -> Self;

    /// Builds with a primitive clipper, for structures that split primitives (spatial splits):
    /// `clip(prim, part, axis, pos)` returns the boxes of the pieces of primitive `prim` that
    /// lie within the box `part` below and above the plane `x[axis] = pos`. By default the
    /// clipper is ignored.
    fn build_clipped(boxes: &[Aabb], params: &Self::Params, clip: &Clipper<'_>) -> Self {
        let _ = clip;
        Self::build(boxes, params)
    }

    /// Closest-hit query. Calls `test(prim, t_max)` for candidate primitives; `test` returns
    /// `Some(t)` for a hit with `t < t_max` (and records what it needs), after which only
    /// closer hits are sought. `t_max` is updated in place; returns whether anything was hit.
    #[inline]
    fn closest(&self, ray: &Ray, t_max: &mut f32, test: impl FnMut(u32, f32) -> Option<f32>) -> bool {
        self.closest_counted(ray, t_max, test, &NoCount)
    }

    /// Any-hit query: stops at the first primitive for which `test(prim, t_max)` is true.
    #[inline]
    fn any(&self, ray: &Ray, t_max: f32, test: impl FnMut(u32, f32) -> bool) -> bool {
        self.any_counted(ray, t_max, test, &NoCount)
    }

    /// [`Accel::closest`], reporting every node (or cell) visited to `counter`.
    fn closest_counted(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool;

    /// [`Accel::any`], reporting every node (or cell) visited to `counter`.
    fn any_counted(&self, ray: &Ray, t_max: f32, test: impl FnMut(u32, f32) -> bool, counter: &impl Counter) -> bool;

    /// The primitives of each leaf, indexed by leaf id, for structures that test a leaf's
    /// primitives together (the BVHs). Callers may then lay out primitive data leaf by leaf and
    /// use [`Accel::closest_leaf_counted`] / [`Accel::any_leaf_counted`]. `None` (the default) means
    /// each primitive is its own leaf: leaf id = primitive id.
    fn leaves(&self) -> Option<Vec<&[u32]>> {
        None
    }

    /// Replaces the leaf ids that the leaf-level queries ([`Accel::closest_leaf_counted`],
    /// [`Accel::any_leaf_counted`], [`Accel::closest_leaf_packet8`]) hand to `test` by
    /// `labels[leaf]`: a caller can put there what it would otherwise look up per leaf (the
    /// triangle blocks' range, say), which saves a dependent memory access on every leaf a ray
    /// reaches. Labels must be below `2^31 - 1`. Returns false, changing nothing, where the
    /// structure has no leaves of its own (the default) or a label does not fit. The caller
    /// has laid out what the leaves hold by then: a structure may free its own lists of the
    /// leaves' primitives, after which [`Accel::leaves`] gives none (and primitive-level
    /// queries are not available).
    fn relabel_leaves(&mut self, _labels: &[u32]) -> bool {
        false
    }

    /// Closest hit, leaf at a time: `test(leaf, t_max)` tests all of a leaf's primitives and
    /// returns the closest `t < t_max` among them. Leaf ids are those of [`Accel::leaves`].
    fn closest_leaf_counted(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_counted(ray, t_max, test, counter)
    }

    /// Any hit, leaf at a time (see [`Accel::closest_leaf_counted`]).
    fn any_leaf_counted(
        &self,
        ray: &Ray,
        t_max: f32,
        test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_counted(ray, t_max, test, counter)
    }

    /// [`Accel::closest_leaf_counted`] for a leaf test marked `#[inline(always)]`: a structure
    /// whose walk has the registers to take it inlined runs that walk (the BVH's copy compiled
    /// with AVX-512's 32 vector registers); the others get a closure of their own around it and
    /// call it as before. The same leaves in the same order.
    fn closest_leaf_inlined(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        self.closest_leaf_counted(ray, t_max, called(&mut test), counter)
    }

    /// [`Accel::any_leaf_counted`] for a leaf test marked `#[inline(always)]` (see
    /// [`Accel::closest_leaf_inlined`]).
    fn any_leaf_inlined(
        &self,
        ray: &Ray,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        self.any_leaf_counted(ray, t_max, called(&mut test), counter)
    }

    /// Closest hits of a packet of up to eight rays traced together (for coherent rays such
    /// as camera rays): `active` selects the lanes, `t_max` is each lane's bound (updated),
    /// and `test(leaf, lanes, t_max)` tests the rays of the `lanes` mask against a leaf,
    /// lowering the `t_max` of those that hit, and returns their mask. Returns the mask of
    /// lanes that hit. The default traces the lanes one by one.
    fn closest_leaf_packet8(
        &self,
        rays: &[Ray; 8],
        active: u8,
        t_max: &mut [f32; 8],
        test: impl FnMut(u32, u8, &mut [f32; 8]) -> u8,
    ) -> u8 {
        lane_by_lane(self, rays, active, t_max, test)
    }

    /// [`Accel::closest_leaf_packet8`] for `P` groups of eight rays traced together (a 4×4
    /// pixel tile as two groups, group 0 its top two rows; or one pixel's camera samples):
    /// `test(group, leaf, lanes, t_max)` tests the rays of a group's `lanes` against a leaf.
    /// Returns each group's mask of lanes that hit. `P` is at most 4. The default traces the
    /// groups one after the other.
    fn closest_leaf_packets<const P: usize>(
        &self,
        rays: &[[Ray; 8]; P],
        active: [u8; P],
        t_max: &mut [[f32; 8]; P],
        test: impl FnMut(usize, u32, u8, &mut [f32; 8]) -> u8,
    ) -> [u8; P] {
        groups_one_by_one(self, rays, active, t_max, test)
    }

    /// Size and shape of the structure.
    fn stats(&self) -> AccelStats;

    /// The boxes of the structure's nodes at `depth` (0 = the root), for pictures of it.
    fn boxes_at_depth(&self, depth: usize) -> Vec<Aabb>;
}

/// The set bits of a lane mask, lowest first.
#[inline(always)]
pub(crate) fn lanes(mask: u32) -> impl Iterator<Item = usize> {
    let mut m = mask;
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            lane
        })
    })
}

/// [`Accel::closest_leaf_packets`] as packets of eight, one after the other.
pub(crate) fn groups_one_by_one<A: Accel, const P: usize>(
    accel: &A,
    rays: &[[Ray; 8]; P],
    active: [u8; P],
    t_max: &mut [[f32; 8]; P],
    mut test: impl FnMut(usize, u32, u8, &mut [f32; 8]) -> u8,
) -> [u8; P] {
    let mut hits = [0u8; P];
    for (g, (t, h)) in t_max.iter_mut().zip(hits.iter_mut()).enumerate() {
        if active[g] != 0 {
            *h = accel.closest_leaf_packet8(&rays[g], active[g], t, |leaf, lanes, t| test(g, leaf, lanes, t));
        }
    }
    hits
}

/// [`Accel::closest_leaf_packet8`] one lane at a time.
pub(crate) fn lane_by_lane<A: Accel>(
    accel: &A,
    rays: &[Ray; 8],
    active: u8,
    t_max: &mut [f32; 8],
    mut test: impl FnMut(u32, u8, &mut [f32; 8]) -> u8,
) -> u8 {
    let mut hits = 0;
    for (lane, ray) in rays.iter().enumerate() {
        if active & (1 << lane) == 0 {
            continue;
        }
        let mut bound = t_max[lane];
        let hit = accel.closest_leaf_counted(
            ray,
            &mut bound,
            |leaf, tm| {
                t_max[lane] = tm;
                (test(leaf, 1 << lane, t_max) != 0).then_some(t_max[lane])
            },
            &NoCount,
        );
        t_max[lane] = bound;
        if hit {
            hits |= 1 << lane;
        }
    }
    hits
}

/// Closest and any hit over leaves that a traversal visits front to back and that do not
/// overlap along the ray (grid cells, k-d tree leaves), with a per-ray mailbox: a primitive
/// listed in several leaves is tested once. The mailbox is a 64-entry direct-mapped cache of
/// primitive ids; a collision only means a repeated test, never a wrong answer.
struct OrderedLeaves {
    mailbox: [u32; 64],
    pub best: f32,
    pub hit: bool,
}

impl OrderedLeaves {
    #[inline]
    pub fn new(t_max: f32) -> OrderedLeaves {
        OrderedLeaves { mailbox: [u32::MAX; 64], best: t_max, hit: false }
    }

    /// True the first time this ray meets `p`.
    #[inline]
    fn fresh(&mut self, p: u32) -> bool {
        let slot = &mut self.mailbox[p as usize % 64];
        let fresh = *slot != p;
        *slot = p;
        fresh
    }

    /// Tests a leaf for the closest hit; returns whether to go on to the next leaf (no hit
    /// found yet within this leaf's exit distance `t_exit`).
    #[inline]
    pub fn closest(&mut self, prims: &[u32], t_exit: f32, test: &mut impl FnMut(u32, f32) -> Option<f32>) -> bool {
        for &p in prims {
            if self.fresh(p) {
                if let Some(t) = test(p, self.best) {
                    self.best = t;
                    self.hit = true;
                }
            }
        }
        self.best > t_exit
    }

    /// Tests a leaf for any hit within `t_max`; returns whether to go on.
    #[inline]
    pub fn any(&mut self, prims: &[u32], t_max: f32, test: &mut impl FnMut(u32, f32) -> bool) -> bool {
        for &p in prims {
            if self.fresh(p) && test(p, t_max) {
                self.hit = true;
                return false;
            }
        }
        true
    }
}

/// Structures whose traversal hands out leaves front to back, not overlapping along the ray
/// (grid cells, k-d tree leaves). Closest and any hit follow from `walk` with a mailbox
/// ([`OrderedLeaves`]).
pub(crate) trait OrderedWalk {
    /// Calls `visit(prims, t_exit)` for each leaf the ray meets within `[0, t_max]`, nearest
    /// first, until `visit` returns false.
    fn walk(&self, ray: &Ray, t_max: f32, counter: &impl Counter, visit: impl FnMut(&[u32], f32) -> bool);

    /// [`Accel::closest_counted`] over the walk.
    #[inline]
    fn walk_closest(
        &self,
        ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        let mut leaves = OrderedLeaves::new(*t_max);
        self.walk(ray, *t_max, counter, |prims, t_exit| leaves.closest(prims, t_exit, &mut test));
        *t_max = leaves.best;
        leaves.hit
    }

    /// [`Accel::any_counted`] over the walk.
    #[inline]
    fn walk_any(&self, ray: &Ray, t_max: f32, mut test: impl FnMut(u32, f32) -> bool, counter: &impl Counter) -> bool {
        let mut leaves = OrderedLeaves::new(t_max);
        self.walk(ray, t_max, counter, |prims, _| leaves.any(prims, t_max, &mut test));
        leaves.hit
    }
}

/// Splits a primitive's box by an axis-aligned plane: `(prim, part, axis, pos) → (below, above)`.
pub type Clipper<'a> = dyn Fn(u32, &Aabb, usize, f32) -> (Aabb, Aabb) + Sync + 'a;

/// The clipper that knows only boxes: the box itself, cut by the plane.
pub fn clip_box(_prim: u32, part: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let (mut lo, mut hi) = (*part, *part);
    lo.max[axis] = lo.max[axis].min(pos);
    hi.min[axis] = hi.min[axis].max(pos);
    let fix = |b: Aabb| if b.min[axis] > b.max[axis] { Aabb::EMPTY } else { b };
    (fix(lo), fix(hi))
}

/// Receives traversal events. [`NoCount`] compiles to nothing; [`Counts`] tallies them (for
/// the heat-map images and statistics).
/// Shared (`&self`) so that one counter can follow a query into the bottom level from inside
/// the top level's primitive test.
pub trait Counter {
    /// A node (or grid cell) was visited.
    fn node(&self);
    /// A primitive was tested.
    fn prim(&self);
}

/// The counter of the normal render path: does nothing.
pub struct NoCount;

impl Counter for NoCount {
    #[inline(always)]
    fn node(&self) {}
    #[inline(always)]
    fn prim(&self) {}
}

/// Counts of traversal work for one query or many.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Nodes (or grid cells) visited.
    pub nodes: std::cell::Cell<u64>,
    /// Primitives tested (objects in the top level, triangles and spheres below).
    pub prims: std::cell::Cell<u64>,
}

impl Counter for Counts {
    #[inline]
    fn node(&self) {
        self.nodes.set(self.nodes.get() + 1);
    }
    #[inline]
    fn prim(&self) {
        self.prims.set(self.prims.get() + 1);
    }
}

/// Build settings shared by the accelerators (each uses those that apply to it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelParams {
    /// A node with this many primitives or fewer becomes a leaf.
    pub max_leaf_prims: usize,
    /// Depth limit of top-down builds; the lecture's 24. A node at this depth becomes a leaf
    /// whatever its size.
    pub max_depth: usize,
    /// SAH cost of traversing one node, relative to `intersect_cost`.
    pub traversal_cost: f32,
    /// SAH cost of one primitive test.
    pub intersect_cost: f32,
    /// The SAH BVH may also make a leaf of up to this many primitives where that is cheaper
    /// than any split (both costed in blocks of `leaf_block`). 8 by default; at most
    /// `max_leaf_prims` turns this off.
    pub sah_leaf_max: usize,
    /// Leaf primitives are tested this many at a time (triangles in blocks of four, see
    /// [`crate::shape::Tri4`]), so the SAH counts a leaf of `n` primitives as `⌈n / leaf_block⌉`
    /// tests, as Embree's builders do. That fills the blocks: fewer, fuller leaves. 4 by
    /// default; 1 where primitives are tested one by one (the objects of the top level).
    pub leaf_block: usize,
}

impl Default for AccelParams {
    fn default() -> Self {
        AccelParams {
            max_leaf_prims: 4,
            max_depth: 24,
            traversal_cost: 1.0,
            intersect_cost: 1.0,
            sah_leaf_max: 8,
            leaf_block: 4,
        }
    }
}

/// What a built structure looks like.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AccelStats {
    pub nodes: usize,
    pub leaves: usize,
    pub max_depth: usize,
    /// Primitive references in leaves (more than the primitive count where they are duplicated).
    pub prim_refs: usize,
    /// Bytes of the structure itself (nodes and index arrays).
    pub bytes: usize,
    /// SAH cost of the tree with the build's costs, relative to the root box.
    pub sah_cost: f32,
}

/// The accelerators that can be chosen by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AccelKind {
    /// Tests every primitive: the correctness oracle.
    Brute,
    /// BVH with the given split method.
    Bvh(SplitMethod),
    /// SAH k-d tree.
    KdTree,
    /// Uniform grid.
    Grid,
}

impl AccelKind {
    /// Every kind, in the order tables list them.
    pub const ALL: [AccelKind; 8] = [
        AccelKind::Brute,
        AccelKind::Bvh(SplitMethod::Center),
        AccelKind::Bvh(SplitMethod::Median),
        AccelKind::Bvh(SplitMethod::Sah),
        AccelKind::Bvh(SplitMethod::Spatial),
        AccelKind::Bvh(SplitMethod::Morton),
        AccelKind::KdTree,
        AccelKind::Grid,
    ];

    /// What `default` means: the fastest implementation.
    pub const DEFAULT: AccelKind = AccelKind::Bvh(SplitMethod::Sah);

    pub fn name(self) -> &'static str {
        match self {
            AccelKind::Brute => "brute",
            AccelKind::Bvh(SplitMethod::Center) => "bvh-center",
            AccelKind::Bvh(SplitMethod::Median) => "bvh-median",
            AccelKind::Bvh(SplitMethod::Sah) => "bvh-sah",
            AccelKind::Bvh(SplitMethod::Spatial) => "bvh-sbvh",
            AccelKind::Bvh(SplitMethod::Morton) => "bvh-bottomup",
            AccelKind::KdTree => "kdtree",
            AccelKind::Grid => "grid",
        }
    }

    /// Builds the acceleration structure over `scene` (one per mesh and one over the objects).
    pub fn build_world<'s>(self, scene: &'s Scene, params: &AccelParams) -> AnyWorld<'s> {
        match self {
            AccelKind::Brute => AnyWorld::Brute(World::build(scene, params)),
            AccelKind::Bvh(split) => {
                let p = BvhParams { split, base: *params };
                AnyWorld::Bvh(World::build(scene, &p))
            }
            AccelKind::KdTree => AnyWorld::KdTree(World::build(scene, &KdParams::new(*params))),
            AccelKind::Grid => AnyWorld::Grid(World::build(scene, &GridParams { base: *params, lambda: 3.0 })),
        }
    }
}

impl fmt::Display for AccelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for AccelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "default" || s == "bvh" {
            return Ok(AccelKind::DEFAULT);
        }
        AccelKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<_> = AccelKind::ALL.iter().map(|k| k.name()).collect();
            format!("unknown accelerator '{s}' (expected default, {})", names.join(", "))
        })
    }
}

/// Parameters as the BVH sees them: the split method plus the shared settings.
#[derive(Clone, Copy, Debug)]
pub struct BvhParams {
    pub split: SplitMethod,
    pub base: AccelParams,
}

/// Build parameters that an accelerator type accepts.
pub trait BuildParams: Sync + Send + Copy {
    fn base(&self) -> &AccelParams;
    fn base_mut(&mut self) -> &mut AccelParams;
}
impl BuildParams for AccelParams {
    fn base(&self) -> &AccelParams {
        self
    }
    fn base_mut(&mut self) -> &mut AccelParams {
        self
    }
}
impl BuildParams for BvhParams {
    fn base(&self) -> &AccelParams {
        &self.base
    }
    fn base_mut(&mut self) -> &mut AccelParams {
        &mut self.base
    }
}

/// A world built with one of the accelerators; `match` on it once, then work generically.
pub enum AnyWorld<'s> {
    Brute(World<'s, Brute>),
    Bvh(World<'s, Bvh>),
    KdTree(World<'s, KdTree>),
    Grid(World<'s, Grid>),
}

/// Runs `$body` with `$w` bound to the concrete `World<A>` inside an [`AnyWorld`].
#[macro_export]
macro_rules! with_world {
    ($any:expr, $w:ident => $body:expr) => {
        match $any {
            $crate::accel::AnyWorld::Brute($w) => $body,
            $crate::accel::AnyWorld::Bvh($w) => $body,
            $crate::accel::AnyWorld::KdTree($w) => $body,
            $crate::accel::AnyWorld::Grid($w) => $body,
        }
    };
}
