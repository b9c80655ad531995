//! The scene (what is in the world) and the [`World`] (the scene plus an acceleration
//! structure built over it). The scene never knows which accelerator it is held in.

use glam::{Vec2, Vec3};

use crate::accel::{Accel, BuildParams, Counter, NoCount};
use crate::camera::Camera;
use crate::geometry::{spawn_ray, spawn_ray_to, Aabb, Ray, Transform};
use crate::light::{AreaLight, AreaShape, Light, LightSample};
use crate::material::Material;
use crate::sampling::build_cdf;
use crate::shape::{
    intersect_sphere, intersect_triangle, BlockHit, Corners, Mesh, Ray4, Reentry, Sphere, Tri4, TriHit,
};
use crate::Rgb;

/// Shared geometry: an object refers to it by index, so many objects (instances) can share
/// one mesh and its acceleration structure without copying triangles.
#[derive(Clone, Debug)]
pub enum Geometry {
    Mesh(Mesh),
    Sphere(Sphere),
}

impl Geometry {
    pub fn aabb(&self) -> Aabb {
        match self {
            Geometry::Mesh(m) => m.aabb(),
            Geometry::Sphere(s) => s.aabb(),
        }
    }
}

/// A thing in the scene: geometry, placed by an optional transform, with a material, and
/// emitting `emission` (an area light) if that is not black.
#[derive(Clone, Debug)]
pub struct Object {
    pub geometry: usize,
    pub transform: Option<Transform>,
    pub material: usize,
    pub emission: Rgb,
    /// Shadow rays per shading point when this object is a light.
    pub light_samples: u32,
}

impl Object {
    /// World-space box of this object given its geometry's box `b`.
    pub fn place_aabb(&self, b: Aabb) -> Aabb {
        match &self.transform {
            Some(t) => t.aabb(&b),
            None => b,
        }
    }
}

/// Everything that is rendered.
#[derive(Clone, Debug)]
pub struct Scene {
    pub geometries: Vec<Geometry>,
    pub objects: Vec<Object>,
    pub materials: Vec<Material>,
    /// Point, spot and directional lights. Area lights come from emissive objects.
    pub lights: Vec<Light>,
    pub camera: Camera,
    /// Radiance of rays that leave the scene.
    pub background: Rgb,
    /// Whitted's ambient term: constant radiance that reaches every diffuse surface unshadowed.
    pub ambient: Rgb,
    /// How the path tracer picks the light to sample at each vertex.
    pub light_selection: LightSelection,
}

/// How a light is chosen for next-event estimation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LightSelection {
    /// In proportion to emitted power (pbrt-v4's power light sampler).
    #[default]
    Power,
    /// Every light equally often (Mitsuba 3's default).
    Uniform,
}

impl Scene {
    /// Checks that every index refers to something and that emissive objects can be sampled.
    pub fn check(&self) -> Result<(), String> {
        for (i, o) in self.objects.iter().enumerate() {
            if o.geometry >= self.geometries.len() {
                return Err(format!("object {i} refers to geometry {} of {}", o.geometry, self.geometries.len()));
            }
            if o.material >= self.materials.len() {
                return Err(format!("object {i} refers to material {} of {}", o.material, self.materials.len()));
            }
            if o.emission != Rgb::ZERO {
                if let (Geometry::Sphere(_), Some(t)) = (&self.geometries[o.geometry], &o.transform) {
                    if t.uniform_scale().is_none() {
                        return Err(format!("object {i}: an emissive sphere may only be scaled uniformly"));
                    }
                }
            }
        }
        Ok(())
    }

    /// World-space bounds of everything.
    pub fn aabb(&self) -> Aabb {
        self.objects.iter().fold(Aabb::EMPTY, |b, o| b.union(self.object_aabb(o)))
    }

    /// World-space box of an object: for a transformed object, the box of the 8 transformed
    /// corners of its geometry's box.
    pub fn object_aabb(&self, o: &Object) -> Aabb {
        o.place_aabb(self.geometries[o.geometry].aabb())
    }

    /// Total triangle count as rendered (instances counted once per instance).
    pub fn triangle_count(&self) -> usize {
        self.objects
            .iter()
            .map(|o| match &self.geometries[o.geometry] {
                Geometry::Mesh(m) => m.indices.len(),
                Geometry::Sphere(_) => 0,
            })
            .sum()
    }

    fn area_light(&self, index: usize, o: &Object) -> AreaLight {
        let shape = match &self.geometries[o.geometry] {
            Geometry::Sphere(s) => {
                let (center, radius) = match &o.transform {
                    Some(t) => (t.point(s.center), s.radius * t.uniform_scale().unwrap_or(1.0)),
                    None => (s.center, s.radius),
                };
                AreaShape::Sphere(Sphere { center, radius })
            }
            Geometry::Mesh(m) => {
                let tris: Vec<[Vec3; 3]> = (0..m.indices.len())
                    .map(|i| {
                        let t = m.triangle(i);
                        match &o.transform {
                            Some(x) => t.map(|p| x.point(p)),
                            None => t,
                        }
                    })
                    .collect();
                match rectangle(m, &tris) {
                    Some(r) => r,
                    None => {
                        let cdf = build_cdf(tris.iter().map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()));
                        AreaShape::Triangles { tris, cdf }
                    }
                }
            }
        };
        AreaLight { object: index as u32, emission: o.emission, samples: o.light_samples.max(1), shape }
    }
}

/// A two-triangle mesh that is a rectangle split along a diagonal (Mitsuba's `rectangle`, an
/// OBJ quad), as an area light shape that is sampled by solid angle; `tris` are its world-space
/// triangles. `None` for anything else.
fn rectangle(m: &Mesh, tris: &[[Vec3; 3]]) -> Option<AreaShape> {
    let ([i0, i1], [t0, t1]) =
        (<[[u32; 3]; 2]>::try_from(m.indices.as_slice()).ok()?, <[[Vec3; 3]; 2]>::try_from(tris).ok()?);
    // The diagonal is the edge both share; the other two corners are opposite each other.
    let shared: Vec<usize> = (0..3).filter(|&k| i1.contains(&i0[k])).collect();
    let [a, b] = <[usize; 2]>::try_from(shared).ok()?;
    let c = 3 - a - b;
    let d = (0..3).find(|&k| !i0.contains(&i1[k]))?;
    let (corner, opposite) = (t0[c], t1[d]);
    let (ex, ey) = (t0[a] - corner, t0[b] - corner);
    let size = ex.length() + ey.length();
    let n0 = (t0[1] - t0[0]).cross(t0[2] - t0[0]);
    let n1 = (t1[1] - t1[0]).cross(t1[2] - t1[0]);
    let rect = ex.dot(ey).abs() <= 1e-5 * ex.length() * ey.length()
        && (corner + ex + ey - opposite).length() <= 1e-5 * size
        && n0.normalize_or_zero().dot(n1.normalize_or_zero()) > 0.9999;
    let normal = n0.normalize_or_zero();
    (rect && normal != Vec3::ZERO && size.is_finite()).then(|| AreaShape::rectangle(corner, ex, ey, normal))
}

/// The boxes of the parts of triangle `t` inside `part` below and above the plane
/// `x[axis] = pos` (the vertices on each side plus the points where edges cross the plane).
pub fn clip_triangle(t: [Vec3; 3], part: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let (mut lo, mut hi) = (Aabb::EMPTY, Aabb::EMPTY);
    for i in 0..3 {
        let (a, b) = (t[i], t[(i + 1) % 3]);
        if a[axis] <= pos {
            lo = lo.grow(a);
        }
        if a[axis] >= pos {
            hi = hi.grow(a);
        }
        if (a[axis] < pos && b[axis] > pos) || (a[axis] > pos && b[axis] < pos) {
            let f = (pos - a[axis]) / (b[axis] - a[axis]);
            let mut x = a + (b - a) * f;
            x[axis] = pos;
            lo = lo.grow(x);
            hi = hi.grow(x);
        }
    }
    let cut = |b: Aabb| {
        let c = Aabb { min: b.min.max(part.min), max: b.max.min(part.max) };
        if c.is_empty() {
            Aabb::EMPTY
        } else {
            c
        }
    };
    (cut(lo), cut(hi))
}

/// A closest hit before shading: the object, the primitive (triangle index, 0 for spheres) and
/// the barycentrics of vertices 1 and 2 on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawHit {
    pub t: f32,
    pub object: u32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
}

/// Objects a query passes over (up to two): those its ray starts or ends on and cannot meet
/// anywhere else, as [`World::leaving`] finds them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Skip([u32; 2]);

/// An object's surface as a path vertex first reads it: one record, where the object, its
/// material (behind a box where one-sided) and the material's texture were three or four
/// dependent loads and matches at every vertex.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Surface {
    /// The object's emission (black: none).
    pub emission: Rgb,
    /// Whether its material reflects from behind ([`Material::two_sided`]).
    pub two_sided: bool,
    /// Where the material is Lambertian with one albedo everywhere, that albedo: the BSDF
    /// [`Material::bsdf`] gives at every point.
    pub diffuse: Option<Rgb>,
    /// The material's index in the scene, for every other material.
    pub material: usize,
}

impl Surface {
    fn new(o: &Object, material: &Material) -> Surface {
        Surface {
            emission: o.emission,
            two_sided: material.two_sided(),
            diffuse: material.uniform_diffuse(),
            material: o.material,
        }
    }
}

/// No object (in [`Skip`]).
const NO_OBJECT: u32 = u32::MAX;

impl Skip {
    /// Passes over nothing.
    pub const NONE: Skip = Skip([NO_OBJECT; 2]);

    /// Passes over what `self` and `other` pass over (the first object of each).
    #[inline]
    pub fn and(self, other: Skip) -> Skip {
        Skip([self.0[0], other.0[0]])
    }

    #[inline(always)]
    fn has(self, obj: u32) -> bool {
        obj == self.0[0] || obj == self.0[1]
    }
}

/// A surface hit with everything shading needs, in world space.
#[derive(Clone, Copy, Debug)]
pub struct Intersection {
    pub t: f32,
    pub p: Vec3,
    /// Unit geometric normal: the winding normal for meshes without normals, otherwise on the
    /// side of the shading normals; outward for spheres. Not flipped towards the ray.
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normals where the mesh has them), in the same
    /// hemisphere as `ng`.
    pub ns: Vec3,
    pub uv: Vec2,
    pub object: u32,
}

/// The closest hit among `blocks` with `t < t_max`, with the block that holds its corners.
#[inline(always)]
fn closest_in_blocks<'a>(blocks: &'a [Tri4], r4: &Ray4, t_max: f32, counter: &impl Counter) -> Option<BlockHit<'a>> {
    for block in blocks {
        for _ in 0..block.len() {
            counter.prim();
        }
    }
    Tri4::closest_at(blocks, r4, t_max)
}

/// What a mesh's closest-hit query keeps of its best hit so far, written by the leaf test at
/// every nearer hit: `(triangle, hit)`, or that and where the triangle's corners are (a
/// block's; `None` where triangles are stored singly), for a query whose caller makes the
/// hit's surface from them ([`World::interaction_at`]). The smaller record for every other
/// query: with the larger one, `World::hit` ran 0.6 % more instructions on the bunny.
trait HitRecord<'a>: Copy {
    /// What the record says of the corners (nothing, or where they are if anywhere).
    type Corners: Copy;
    /// The corners of a hit found without them (on a top level's object).
    const NO_CORNERS: Self::Corners;
    /// What the world's query returns: the hit, with the corners where the record has them.
    type Hit;
    fn hit(h: RawHit, corners: Self::Corners) -> Self::Hit;
    fn in_block(h: BlockHit<'a>) -> Self;
    fn single(tri: u32, h: TriHit) -> Self;
    fn parts(self) -> (u32, TriHit, Self::Corners);
}

impl<'a> HitRecord<'a> for (u32, TriHit) {
    type Corners = ();
    const NO_CORNERS: () = ();
    type Hit = RawHit;
    #[inline(always)]
    fn hit(h: RawHit, (): ()) -> RawHit {
        h
    }
    #[inline(always)]
    fn in_block(h: BlockHit<'a>) -> Self {
        (h.tri, h.hit)
    }
    #[inline(always)]
    fn single(tri: u32, h: TriHit) -> Self {
        (tri, h)
    }
    #[inline(always)]
    fn parts(self) -> (u32, TriHit, ()) {
        (self.0, self.1, ())
    }
}

impl<'a> HitRecord<'a> for (u32, TriHit, Option<Corners<'a>>) {
    type Corners = Option<Corners<'a>>;
    const NO_CORNERS: Self::Corners = None;
    type Hit = (RawHit, Option<Corners<'a>>);
    #[inline(always)]
    fn hit(h: RawHit, corners: Self::Corners) -> Self::Hit {
        (h, corners)
    }
    #[inline(always)]
    fn in_block(h: BlockHit<'a>) -> Self {
        (h.tri, h.hit, Some(h.corners))
    }
    #[inline(always)]
    fn single(tri: u32, h: TriHit) -> Self {
        (tri, h, None)
    }
    #[inline(always)]
    fn parts(self) -> Self {
        self
    }
}

/// The ray prepared for the triangle tests, made in `shared` when a test first needs it and
/// reused after: by every untransformed object a ray meets, and by every leaf of one object's
/// tree (a transformed object's own slot holds its local ray's).
#[inline(always)]
fn shared_ray4<'a>(shared: &'a mut Option<Ray4>, ray: &Ray) -> &'a Ray4 {
    shared.get_or_insert_with(|| Ray4::of(ray))
}

/// A leaf's block range `a..b` as a leaf label (see [`Accel::relabel_leaves`]): the first
/// block above three bits of count (1 to 8 blocks), or `None` where it does not fit.
fn label_of_range(a: u32, b: u32) -> Option<u32> {
    (b > a && b - a <= 8 && b < 1 << 27).then(|| a << 3 | (b - a - 1))
}

/// The block range a leaf label encodes.
#[inline(always)]
fn block_range(label: u32) -> (u32, u32) {
    let a = label >> 3;
    (a, a + (label & 7) + 1)
}

/// The bound a packet's ray gets once something blocks it ([`World::occluded_packet8`]):
/// below every box's entry distance, so that the walk leaves the ray out from then on.
const BLOCKED: f32 = -1.0;

/// Drops the rays of `hit` from a packet walk (their bound set to [`BLOCKED`]) and adds them
/// to `blocked`; returns `hit`, as the walk's leaf test does.
#[inline(always)]
fn drop_blocked(hit: u8, t_max: &mut [f32; 8], blocked: &mut u8) -> u8 {
    for lane in crate::accel::lanes(hit.into()) {
        t_max[lane] = BLOCKED;
    }
    *blocked |= hit;
    hit
}

/// `World::object_blocks`: the object is not an untransformed mesh of one block range.
const NOT_DIRECT: u32 = u32::MAX;

/// Meshes of at most this many triangles (four blocks) are tested block by block, without
/// their tree.
const SMALL_MESH: usize = 16;

/// A packet's rays prepared for triangle tests: each ray's watertight set-up, made when it
/// first reaches a leaf, and (AVX2) the rays in AVX lanes for the eight-ray test, made at the
/// first leaf that several of them reach.
#[derive(Default)]
struct PacketRays {
    r4: [Option<Ray4>; 8],
    /// None until made; `Some(None)` where the rays permute their axes differently.
    #[cfg(target_arch = "x86_64")]
    wide: Option<Option<crate::shape::Rays8>>,
}

impl PacketRays {
    /// The closest hits among `blocks` of the rays of `lanes` (of the packet's `active` ones),
    /// each with `t < t_max[lane]`: lowers `t_max` and records `(triangle, hit)` in `rec` for
    /// the lanes that hit, and returns them. The same hits as [`closest_in_blocks`] gives each
    /// ray alone. `avx2`: the CPU has AVX2.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn closest_in_blocks(
        &mut self,
        rays: &[Ray; 8],
        active: u8,
        avx2: bool,
        blocks: &[Tri4],
        lanes: u8,
        t_max: &mut [f32; 8],
        rec: &mut [Option<(u32, TriHit)>; 8],
    ) -> u8 {
        let mut hit = 0;
        #[cfg(target_arch = "x86_64")]
        if avx2 && lanes.count_ones() >= 2 {
            let r4 = &mut self.r4;
            // SAFETY: `avx2` says the CPU has AVX2.
            let wide = self.wide.get_or_insert_with(|| unsafe { crate::shape::Rays8::from_rays(rays, active) });
            if let Some(w) = wide {
                for block in blocks {
                    // SAFETY: `avx2` says the CPU has AVX2.
                    let (found, undecided) = unsafe { block.closest8(w, lanes, t_max, rec) };
                    hit |= found;
                    // Rays with an edge function exactly zero: the single-ray test decides.
                    for lane in crate::accel::lanes(undecided.into()) {
                        if let Some(f) = block.closest(shared_ray4(&mut r4[lane], &rays[lane]), t_max[lane]) {
                            (t_max[lane], rec[lane]) = (f.1.t, Some(f));
                            hit |= 1 << lane;
                        }
                    }
                }
                return hit;
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (active, avx2);
        for lane in crate::accel::lanes(lanes.into()) {
            let r4 = shared_ray4(&mut self.r4[lane], &rays[lane]);
            if let Some(BlockHit { tri, hit: h, .. }) = closest_in_blocks(blocks, r4, t_max[lane], &NoCount) {
                (t_max[lane], rec[lane]) = (h.t, Some((tri, h)));
                hit |= 1 << lane;
            }
        }
        hit
    }
}

/// The triangles of one mesh, laid out for its bottom-level structure: in blocks of four per
/// leaf ([`Tri4`], tested four at a time) when the structure tests whole leaves, otherwise one
/// 36-byte record of corners per triangle (no gather through the index buffer either way).
enum TriData {
    /// `blocks[ranges[leaf].0 .. ranges[leaf].1]` hold the triangles of each leaf. Where
    /// `labelled`, the structure hands each leaf's range itself to the leaf test instead of its
    /// index ([`Accel::relabel_leaves`], decoded by [`block_range`]).
    Leaves {
        blocks: Vec<Tri4>,
        ranges: Vec<(u32, u32)>,
        labelled: bool,
    },
    Single(Vec<[Vec3; 3]>),
}

impl TriData {
    fn new<A: Accel>(m: &Mesh, accel: &mut A) -> TriData {
        let Some(mut leaves) = accel.leaves() else {
            return TriData::Single((0..m.indices.len()).map(|i| m.triangle(i)).collect());
        };
        // A small mesh (a box, a few quads) is one leaf: its few blocks are tested straight
        // away, which costs less than entering a tree over them.
        let all: Vec<u32>;
        if m.indices.len() <= SMALL_MESH && leaves.len() > 1 {
            all = leaves.concat();
            leaves = vec![&all];
        }
        use rayon::prelude::*;
        let mut start = 0u32;
        let ranges: Vec<(u32, u32)> = leaves
            .iter()
            .map(|prims| {
                let r = (start, start + prims.len().div_ceil(4) as u32);
                start = r.1;
                r
            })
            .collect();
        // Per block, its leaf and first triangle there; then every block is packed in parallel
        // straight into place (an indexed parallel collect; nothing is initialised twice).
        let firsts: Vec<(u32, u32)> = leaves
            .iter()
            .enumerate()
            .flat_map(|(l, prims)| (0..prims.len()).step_by(4).map(move |f| (l as u32, f as u32)))
            .collect();
        let blocks = firsts
            .into_par_iter()
            .map(|(l, f)| {
                let prims = leaves[l as usize];
                let c = &prims[f as usize..(f as usize + 4).min(prims.len())];
                Tri4::pack(c.iter().map(|&p| (p, m.triangle(p as usize))))
            })
            .collect();
        // Each leaf's range rides in the structure's leaf reference where it fits.
        let labels: Option<Vec<u32>> =
            if ranges.len() > 1 { ranges.iter().map(|&(a, b)| label_of_range(a, b)).collect() } else { None };
        let labelled = labels.is_some_and(|l| accel.relabel_leaves(&l));
        // Labelled leaves carry their ranges themselves.
        let ranges = if labelled { Vec::new() } else { ranges };
        TriData::Leaves { blocks, ranges, labelled }
    }

    /// All the blocks (none where triangles are stored singly).
    #[inline(always)]
    fn blocks(&self) -> &[Tri4] {
        match self {
            TriData::Leaves { blocks, .. } => blocks,
            TriData::Single(_) => &[],
        }
    }

    /// The block range of a mesh tested as one leaf (a small mesh, or a tree that is one
    /// leaf): its blocks are tested straight away, without the structure.
    #[inline(always)]
    fn whole_range(&self) -> Option<(u32, u32)> {
        match self {
            TriData::Leaves { ranges, .. } => TriData::one_range(ranges),
            TriData::Single(_) => None,
        }
    }

    /// [`TriData::whole_range`] from the leaves' ranges.
    #[inline(always)]
    fn one_range(ranges: &[(u32, u32)]) -> Option<(u32, u32)> {
        match ranges {
            [range] => Some(*range),
            _ => None,
        }
    }

    /// The blocks of leaf `leaf` (an index, or the label that encodes the range).
    #[inline(always)]
    fn leaf_blocks<'a>(blocks: &'a [Tri4], ranges: &[(u32, u32)], labelled: bool, leaf: u32) -> &'a [Tri4] {
        let (a, b) = if labelled { block_range(leaf) } else { ranges[leaf as usize] };
        &blocks[a as usize..b as usize]
    }

    /// Closest triangle hit with `t < t_max` (updated), as the record `R` keeps it (with or
    /// without where its corners are: see [`HitRecord`]). `r4` is the ray
    /// prepared for the triangle tests, made from `ray` when the first leaf is reached if it
    /// is not made yet (shared by every untransformed object a ray meets; a ray that reaches
    /// no leaf, as most camera rays beside a mesh, never pays for it).
    #[inline(always)]
    fn closest<'a, A: Accel, R: HitRecord<'a>>(
        &'a self,
        accel: &A,
        ray: &Ray,
        r4: &mut Option<Ray4>,
        t_max: &mut f32,
        counter: &impl Counter,
    ) -> Option<R> {
        match self {
            TriData::Leaves { blocks, ranges, labelled } => {
                let mut rec = None;
                // A run of blocks tested, its hit kept in `rec`: the hit's distance. A function
                // inlined at both places, not a closure they share, which was a call per leaf.
                #[inline(always)]
                fn leaf<'a, R: HitRecord<'a>>(
                    blocks: &'a [Tri4],
                    r4: &mut Option<Ray4>,
                    ray: &Ray,
                    tm: f32,
                    counter: &impl Counter,
                    rec: &mut Option<R>,
                ) -> Option<f32> {
                    let found = closest_in_blocks(blocks, shared_ray4(r4, ray), tm, counter)?;
                    *rec = Some(R::in_block(found));
                    Some(found.hit.t)
                }
                if let Some((a, b)) = TriData::one_range(ranges) {
                    // The top level has tested the object's box already (a one-object scene
                    // has none; the exact block tests decide alone there).
                    if let Some(t) = leaf(&blocks[a as usize..b as usize], r4, ray, *t_max, counter, &mut rec) {
                        *t_max = t;
                    }
                } else {
                    // Inlined into the walk where it has the registers for it (AVX-512's 32:
                    // bounce rays 2-5 % faster, any-hit 1-8 %, forty-eighth session); a call
                    // from the AVX2 walk (see `World::hit_skipping`).
                    let test = {
                        #[inline(always)]
                        |l, tm| leaf(TriData::leaf_blocks(blocks, ranges, *labelled, l), r4, ray, tm, counter, &mut rec)
                    };
                    accel.closest_leaf_inlined(ray, t_max, test, counter);
                }
                rec
            }
            TriData::Single(tris) => {
                let mut rec = None;
                accel.closest_counted(
                    ray,
                    t_max,
                    |tri, tm| {
                        counter.prim();
                        let [a, b, c] = tris[tri as usize];
                        intersect_triangle(&shared_ray4(r4, ray).ray, a, b, c, tm).map(|h| {
                            rec = Some((tri, h));
                            h.t
                        })
                    },
                    counter,
                );
                rec.map(|(tri, h)| R::single(tri, h))
            }
        }
    }

    /// Whether any triangle is hit with `t < t_max`; `r4` as in [`TriData::closest`].
    #[inline(always)]
    fn any<A: Accel>(&self, accel: &A, ray: &Ray, r4: &mut Option<Ray4>, t_max: f32) -> bool {
        match self {
            TriData::Leaves { blocks, ranges, labelled } => {
                if let Some((a, b)) = TriData::one_range(ranges) {
                    Tri4::any_in(&blocks[a as usize..b as usize], shared_ray4(r4, ray), t_max)
                } else {
                    // As in `TriData::closest`.
                    let test = {
                        #[inline(always)]
                        |l, tm| {
                            Tri4::any_in(TriData::leaf_blocks(blocks, ranges, *labelled, l), shared_ray4(r4, ray), tm)
                        }
                    };
                    accel.any_leaf_inlined(ray, t_max, test, &NoCount)
                }
            }
            TriData::Single(tris) => accel.any(ray, t_max, |tri, tm| {
                let [a, b, c] = tris[tri as usize];
                intersect_triangle(&shared_ray4(r4, ray).ray, a, b, c, tm).is_some()
            }),
        }
    }
}

/// Calls `f` with the ray in `o`'s space and the slot of its preparation for the triangle
/// tests ([`TriData::closest`] fills it when a leaf is reached). Untransformed objects share
/// one preparation per ray (`shared`, made when the first of them needs it).
#[inline(always)]
fn with_mesh_ray<R>(
    o: &Object,
    ray: &Ray,
    shared: &mut Option<Ray4>,
    f: impl FnOnce(&Ray, &mut Option<Ray4>) -> R,
) -> R {
    match &o.transform {
        Some(x) => f(&x.ray_to_object(ray), &mut None),
        None => f(ray, shared),
    }
}

/// A triangle's unit normal by its winding (zero for a degenerate triangle): the one formula
/// for [`World`]'s `face_normals` and for a normal made from a hit's corners, so both are the
/// same bits.
#[inline(always)]
fn winding_normal([p0, p1, p2]: [Vec3; 3]) -> Vec3 {
    (p1 - p0).cross(p2 - p0).normalize_or_zero()
}

/// Each triangle's box, their union, and each triangle's unit normal by its winding (zero for
/// a degenerate triangle: [`World::interaction_into`] then falls back to the ray), in one
/// parallel pass over the triangles (a second pass to unite the boxes cost 3 ms of the
/// dragon's build).
fn triangle_boxes(m: &Mesh) -> (Vec<Aabb>, Aabb, Vec<Vec3>) {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    let n = m.indices.len();
    let mut boxes: Vec<Aabb> = Vec::with_capacity(n);
    let mut normals: Vec<Vec3> = Vec::with_capacity(n);
    let bound = boxes.spare_capacity_mut()[..n]
        .par_chunks_mut(CHUNK)
        .zip(normals.spare_capacity_mut()[..n].par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, (chunk, nchunk))| {
            let mut u = Aabb::EMPTY;
            for (k, (slot, nslot)) in chunk.iter_mut().zip(nchunk).enumerate() {
                let [p0, p1, p2] = m.triangle(c * CHUNK + k);
                let b = Aabb::from_points([p0, p1, p2]);
                u = u.union(b);
                slot.write(b);
                nslot.write(winding_normal([p0, p1, p2]));
            }
            u
        })
        .reduce(|| Aabb::EMPTY, Aabb::union);
    // SAFETY: the chunks cover the first `n` slots of both, and each slot was written above.
    unsafe {
        boxes.set_len(n);
        normals.set_len(n);
    }
    (boxes, bound, normals)
}

/// A scene with its acceleration structures: one per mesh (bottom level) and one over the
/// objects (top level). Also the list of all lights, area lights included.
pub struct World<'s, A: Accel> {
    pub scene: &'s Scene,
    top: A,
    blas: Vec<Option<A>>,
    /// Per geometry, the triangles laid out for its bottom-level structure.
    tris: Vec<TriData>,
    /// Per mesh, each triangle's unit geometric normal ([`winding_normal`]; empty for spheres):
    /// worked out once, not at every hit, where its square root and division sat on the path
    /// of every shading point. (Not read where the query hands over the hit's corners, which
    /// give it without a load that misses the caches on a large mesh: [`World::interaction_at`].)
    face_normals: Vec<Vec<Vec3>>,
    /// Per object, an untransformed mesh's arrays straight from the scene (`None` for spheres
    /// and transformed meshes): [`World::interaction_into`] reaches a hit's vertices from here in
    /// one load instead of through the object, the geometry and the mesh in turn.
    object_meshes: Vec<Option<MeshRef<'s>>>,
    /// Per object, `(geometry, first block, end)` where the object is an untransformed mesh
    /// tested as one range of blocks: the top level's leaf test goes straight to them.
    /// `NOT_DIRECT` in the first field otherwise.
    object_blocks: Vec<(u32, u32, u32)>,
    /// Per object, whether a ray leaving its surface can meet it again (see [`World::leaving`]).
    reentry: Vec<Reentry>,
    /// Per object, what a path vertex on it reads first (see [`Surface`]).
    pub(crate) surfaces: Vec<Surface>,
    /// Whether the top level's leaf references are the objects themselves
    /// ([`Accel::relabel_leaves`]; every leaf holds one object), so that its leaf-level query
    /// hands the object straight to the test.
    top_by_object: bool,
    pub lights: Vec<Light>,
    /// Running sum of the lights' powers, for choosing one in proportion to its power.
    light_cdf: Vec<f32>,
    /// Per light, the probability of choosing it (worked out once: a division that sat on
    /// every light sample's path).
    light_pmf: Vec<f32>,
    /// Per object, the index of its area light in `lights` (`u32::MAX`: not emissive).
    object_light: Vec<u32>,
    /// Per light, the object a shadow ray ending on it may pass over (`NO_OBJECT` where that
    /// cannot pay: a point light, or an object whose `reentry` is `Possible`).
    light_object: Vec<u32>,
    /// The index of the environment light in `lights`, if there is one.
    environment: Option<usize>,
    /// Whether this CPU has AVX2, for the packets' eight-ray triangle test and the path
    /// tracer's eight-lane vertices.
    pub(crate) avx2: bool,
    /// Whether [`World::hit_packet8`] traces its rays together (worked out once, when the
    /// world is built); otherwise it traces them one by one.
    packets: bool,
}

impl<'s, A: Accel> World<'s, A> {
    pub fn build(scene: &'s Scene, params: &A::Params) -> World<'s, A> {
        use rayon::prelude::*;
        // Each geometry's structure and box. A mesh's box is the union of its triangles' boxes
        // (the box of the vertices its triangles use, as `Mesh::aabb` computes it, without a
        // second pass over the indices). The same pass keeps each triangle's unit normal for
        // shading.
        let (mut blas, (geometry_boxes, face_normals)): (Vec<_>, (Vec<_>, Vec<_>)) = scene
            .geometries
            .par_iter()
            .map(|g| match g {
                Geometry::Mesh(m) => {
                    let (boxes, bound, normals) = triangle_boxes(m);
                    let clip = |prim: u32, part: &Aabb, axis: usize, pos: f32| {
                        clip_triangle(m.triangle(prim as usize), part, axis, pos)
                    };
                    (Some(A::build_clipped(&boxes, params, &clip)), (bound, normals))
                }
                Geometry::Sphere(s) => (None, (s.aabb(), Vec::new())),
            })
            .unzip();
        let tris: Vec<TriData> = scene
            .geometries
            .iter()
            .zip(&mut blas)
            .map(|(g, accel)| match (g, accel) {
                (Geometry::Mesh(m), Some(accel)) => TriData::new(m, accel),
                _ => TriData::Single(Vec::new()),
            })
            .collect();
        let boxes: Vec<Aabb> = scene.objects.iter().map(|o| o.place_aabb(geometry_boxes[o.geometry])).collect();
        // One object per top-level leaf: each object's box is tested before its own structure
        // is entered (objects are few; a wasted bottom-level entry costs far more).
        let mut top_params = *params;
        top_params.base_mut().max_leaf_prims = 1;
        top_params.base_mut().sah_leaf_max = 1;
        top_params.base_mut().leaf_block = 1;
        let mut top = A::build(&boxes, &top_params);
        let labels: Option<Vec<u32>> =
            top.leaves().and_then(|l| l.iter().map(|objs| if let [o] = objs[..] { Some(o) } else { None }).collect());
        let top_by_object = labels.is_some_and(|l| top.relabel_leaves(&l));
        let object_blocks = scene
            .objects
            .iter()
            .map(|o| match (tris[o.geometry].whole_range(), &o.transform) {
                (Some((a, b)), None) => (o.geometry as u32, a, b),
                _ => (NOT_DIRECT, 0, 0),
            })
            .collect();
        let object_meshes = scene
            .objects
            .iter()
            .map(|o| match (&scene.geometries[o.geometry], &o.transform) {
                (Geometry::Mesh(m), None) => Some(MeshRef::new(m, o.geometry)),
                _ => None,
            })
            .collect();
        // Worked out in world space: a mesh's as it stands (meshes under a transform are left
        // `Possible`), a sphere's about its placed centre (an ellipsoid is as convex). Where
        // every triangle lies on a face of the mesh's box (the walls of an axis-aligned room, an
        // axis-aligned box) the box test already turns away every ray leaving outwards, so
        // that passing over the mesh would cost without saving: it is left `Possible` too.
        let reentry = scene
            .objects
            .iter()
            .map(|o| match (&scene.geometries[o.geometry], &o.transform) {
                (Geometry::Mesh(m), None) => match m.reentry() {
                    // (Large meshes are `Possible` at once, without a pass over them.)
                    Reentry::Possible => Reentry::Possible,
                    _ if m.on_box_faces() => Reentry::Possible,
                    r => r,
                },
                (Geometry::Mesh(_), Some(_)) => Reentry::Possible,
                (Geometry::Sphere(s), x) => {
                    Reentry::Inward { centre: x.as_ref().map_or(s.center, |x| x.point(s.center)) }
                }
            })
            .collect::<Vec<_>>();
        let surfaces = scene.objects.iter().map(|o| Surface::new(o, &scene.materials[o.material])).collect();
        let mut lights = scene.lights.clone();
        let mut object_light = vec![u32::MAX; scene.objects.len()];
        for (i, o) in scene.objects.iter().enumerate() {
            if o.emission != Rgb::ZERO && o.emission.is_finite() {
                object_light[i] = lights.len() as u32;
                lights.push(Light::Area(scene.area_light(i, o)));
            }
        }
        let radius = 0.5 * boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(*b)).extent().length();
        let radius = if radius.is_finite() { radius } else { 1.0 };
        let light_cdf = crate::sampling::build_cdf(lights.iter().map(|l| {
            let p = match scene.light_selection {
                LightSelection::Power => l.power(radius),
                LightSelection::Uniform => 1.0,
            };
            if p.is_finite() && p > 0.0 {
                p
            } else {
                0.0
            }
        }));
        let light_pmf = crate::sampling::cdf_probabilities(&light_cdf);
        let light_object = lights
            .iter()
            .map(|l| match l {
                Light::Area(a) if reentry[a.object as usize] != Reentry::Possible => a.object,
                _ => NO_OBJECT,
            })
            .collect();
        let environment = lights.iter().position(|l| matches!(l, Light::Environment(_)));
        let avx2 = crate::accel::has_avx2_fma_popcnt();
        let mut world = World {
            scene,
            top,
            blas,
            tris,
            face_normals,
            object_meshes,
            object_blocks,
            reentry,
            surfaces,
            top_by_object,
            lights,
            light_cdf,
            light_pmf,
            object_light,
            light_object,
            environment,
            avx2,
            packets: false,
        };
        world.packets = world.packet_tree().is_some() || world.top_packets();
        world
    }

    /// The environment light and its index in `lights`, if the scene has one.
    pub fn environment(&self) -> Option<(usize, &crate::light::Environment)> {
        let i = self.environment?;
        match &self.lights[i] {
            Light::Environment(e) => Some((i, e)),
            _ => None,
        }
    }

    /// Radiance of a ray that leaves the scene along `d`: the background plus the environment.
    pub fn escaped(&self, d: Vec3) -> Rgb {
        self.scene.background + self.environment().map_or(Rgb::ZERO, |(_, e)| e.eval(d))
    }

    /// Chooses a light in proportion to its power: its index and the probability of the choice.
    pub fn choose_light(&self, u: f32) -> Option<(usize, f32)> {
        let total = *self.light_cdf.last()?;
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        let (i, _) = crate::sampling::sample_cdf(&self.light_cdf, u);
        Some((i, self.light_probability(i)))
    }

    /// The probability that [`World::choose_light`] picks light `i`.
    #[inline]
    pub fn light_probability(&self, i: usize) -> f32 {
        self.light_pmf[i]
    }

    /// What a query for a ray from `p`, a point on object `obj`'s surface whose geometric normal
    /// is `ng` (either way round), along `d` may pass over: the object itself where the ray
    /// cannot meet it again (a flat object, or a convex one left outwards; see [`Reentry`]).
    /// The same holds backwards, for a shadow ray's end on a light: `p` that end, `d` pointing
    /// back along the ray. A query passing over such an object finds what it would find
    /// testing it, without the test (rays off a rotated box or a tilted wall no longer pay
    /// for it), but for rounding: a shadow ray that grazes a sphere light's outline on its way to
    /// a point the light's sampling chose as visible could be found blocked by the light
    /// itself, and no longer is.
    #[inline]
    pub fn leaving(&self, obj: u32, p: Vec3, ng: Vec3, d: Vec3) -> Skip {
        let clear = match self.reentry[obj as usize] {
            Reentry::Never => true,
            Reentry::Inward { centre } => ng.dot(d) * ng.dot(p - centre) > 0.0,
            Reentry::Possible => false,
        };
        Skip([if clear { obj } else { NO_OBJECT }, NO_OBJECT])
    }

    /// Whether light sample `ls` of light `light` is blocked from the surface point `hit`,
    /// whose geometric normal is `ng` (either way round). The shadow ray leaves `hit` offset to
    /// the light's side and ends short of the light's point, offset to `hit`'s side (or runs to
    /// infinity); it passes over the surface it leaves and the light it ends on where it cannot
    /// meet them ([`World::leaving`]).
    #[inline(always)]
    pub fn shadowed(&self, hit: &Intersection, ng: Vec3, light: usize, ls: &LightSample) -> bool {
        let (r, t_max, skip) = self.shadow_ray(hit, ng, light, ls);
        self.occluded_skipping(&r, t_max, skip)
    }

    /// The shadow ray [`World::shadowed`] traces: the ray, its `t_max` and what it passes over.
    #[inline(always)]
    pub fn shadow_ray(&self, hit: &Intersection, ng: Vec3, light: usize, ls: &LightSample) -> (Ray, f32, Skip) {
        if ls.infinite {
            let r = spawn_ray(hit.p, ng, Vec3::from(ls.wi));
            return (r, f32::INFINITY, self.shadow_skip(hit.object, hit.p, ng, light, None, r.d));
        }
        let (q, nq) = (Vec3::from(ls.p), Vec3::from(ls.n));
        let (r, t_max) = spawn_ray_to(hit.p, ng, q, nq);
        (r, t_max, self.shadow_skip(hit.object, hit.p, ng, light, Some((q, nq)), r.d))
    }

    /// What the shadow ray `d` from `p` on object `obj` (geometric normal `ng`) to light
    /// `light` passes over: see [`World::shadowed`]. `end`: the point the ray ends on and its
    /// normal (`None` for a light at infinity).
    #[inline(always)]
    pub(crate) fn shadow_skip(
        &self,
        obj: u32,
        p: Vec3,
        ng: Vec3,
        light: usize,
        end: Option<(Vec3, Vec3)>,
        d: Vec3,
    ) -> Skip {
        let mut skip = self.leaving(obj, p, ng, d);
        let at = self.light_object[light];
        if let (Some((q, nq)), true) = (end, at != NO_OBJECT) {
            skip = skip.and(self.leaving(at, q, nq, -d));
        }
        skip
    }

    /// The area light of an object, if it emits.
    pub fn light_of(&self, object: u32) -> Option<usize> {
        self.object_light.get(object as usize).filter(|&&l| l != u32::MAX).map(|&l| l as usize)
    }

    /// Bytes of triangle data laid out for the bottom-level structures (blocks of four, or one
    /// record per triangle), which traversal reads besides the structures themselves.
    fn triangle_bytes(&self) -> usize {
        self.tris
            .iter()
            .map(|t| match t {
                TriData::Leaves { blocks, ranges, .. } => {
                    blocks.len() * std::mem::size_of::<Tri4>() + ranges.len() * std::mem::size_of::<(u32, u32)>()
                }
                TriData::Single(t) => t.len() * std::mem::size_of::<[Vec3; 3]>(),
            })
            .sum()
    }

    /// Blocks of four triangles in the leaves (0 for structures that test triangles singly).
    pub fn triangle_blocks(&self) -> usize {
        self.tris.iter().map(|t| if let TriData::Leaves { blocks, .. } = t { blocks.len() } else { 0 }).sum()
    }

    /// Bytes of all the structures and the triangle data their leaves hold (what Embree reports
    /// as the size of its BVH).
    pub fn bytes(&self) -> usize {
        let bottoms: usize = self.blas.iter().flatten().map(|b| b.stats().bytes).sum();
        self.top.stats().bytes + bottoms + self.triangle_bytes()
    }

    /// The top-level structure and the bottom-level one of each geometry (None for spheres).
    pub fn structures(&self) -> (&A, &[Option<A>]) {
        (&self.top, &self.blas)
    }

    /// The blocks of object `obj` where the top level's leaf test goes straight to them (an
    /// untransformed mesh tested as one range of blocks).
    #[inline(always)]
    fn direct_blocks(&self, obj: u32) -> Option<&[Tri4]> {
        let (g, a, b) = self.object_blocks[obj as usize];
        (g != NOT_DIRECT).then(|| &self.tris[g as usize].blocks()[a as usize..b as usize])
    }

    /// Closest hit with `0 < t < t_max`, with everything shading needs.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Intersection> {
        self.intersect_skipping(ray, t_max, Skip::NONE)
    }

    /// [`World::intersect`] passing over the objects of `skip`, which the ray cannot meet.
    pub fn intersect_skipping(&self, ray: &Ray, t_max: f32, skip: Skip) -> Option<Intersection> {
        let mut out = None;
        self.intersect_skipping_into(ray, t_max, skip, &mut out);
        out
    }

    /// [`World::intersect_skipping`] written into `out`, where the caller keeps it (see
    /// [`World::interaction_into`]).
    #[inline(always)]
    pub fn intersect_skipping_into(&self, ray: &Ray, t_max: f32, skip: Skip, out: &mut Option<Intersection>) {
        match self.hit_skipping::<(u32, TriHit, Option<Corners>)>(ray, t_max, skip, &NoCount) {
            Some((h, corners)) => self.interaction_at(ray, &h, corners, out),
            None => *out = None,
        }
    }

    /// Closest hit with `0 < t < t_max`: only which primitive and where on it.
    #[inline]
    pub fn hit(&self, ray: &Ray, t_max: f32) -> Option<RawHit> {
        self.hit_counted(ray, t_max, &NoCount)
    }

    /// [`World::hit`], reporting the nodes visited and primitives tested at both levels.
    pub fn hit_counted(&self, ray: &Ray, t_max: f32, counter: &impl Counter) -> Option<RawHit> {
        self.hit_skipping::<(u32, TriHit)>(ray, t_max, Skip::NONE, counter)
    }

    /// [`World::hit_counted`] passing over the objects of `skip`, with what the record `R` says
    /// of the hit triangle's corners: where they are, for a record that asks, where the query
    /// has them at hand (a scene that is one untransformed mesh in a tree; see
    /// [`World::interaction_at`]).
    fn hit_skipping<'w, R: HitRecord<'w>>(
        &'w self,
        ray: &Ray,
        t_max: f32,
        skip: Skip,
        counter: &impl Counter,
    ) -> Option<R::Hit> {
        // (object and primitive as one word, b1, b2). The object test below writes it and the
        // end of this function reads it back: kept as one word, its store and its load have the
        // same width, so the load is forwarded from the store (two 4-byte stores read as one
        // 8-byte load would stall it).
        let mut best: Option<(u64, f32, f32)> = None;
        let mut t = t_max;
        let mut shared = None;
        if let Some((accel, tris)) = self.one_tree() {
            // One untransformed mesh: its tree is entered straight from here.
            counter.prim();
            let mut t = t_max;
            let found: R = tris.closest(accel, ray, &mut None, &mut t, counter)?;
            let (prim, h, at) = found.parts();
            return Some(R::hit(RawHit { t, object: 0, prim, b1: h.b1, b2: h.b2 }, at));
        }
        // Inlined into the top level's walks (inside a block, where a closure may carry the
        // attribute): as a call, every object test made the walk store and reload its AVX
        // registers, and its triangle blocks ran in SSE encodings (the Cornell box 2.8 % fewer
        // instructions inlined, the same image). A mesh's own leaf test stays a call from its
        // tree's AVX2 walk (`TriData::closest`): inlined there, the walk's ray constants were
        // read from memory at every node (the bench's loads +63 %), for no gain in time; the
        // walk's AVX-512 copy, with registers enough, takes it inlined
        // (`Accel::closest_leaf_inlined`).
        let mut test = {
            #[inline(always)]
            |obj: u32, tmax: f32| {
                if skip.has(obj) {
                    return None;
                }
                counter.prim();
                let (prim, h) = self.closest_in_object(obj, ray, &mut shared, tmax, counter)?;
                best = Some((obj as u64 | (prim as u64) << 32, h.b1, h.b2));
                Some(h.t)
            }
        };
        if self.scene.objects.len() == 1 {
            // One object: its own structure culls as well as a top level would.
            if let Some(hit_t) = test(0, t) {
                t = hit_t;
            }
        } else if self.top_by_object {
            self.top.closest_leaf_counted(ray, &mut t, test, counter);
        } else {
            self.top.closest_counted(ray, &mut t, test, counter);
        }
        let (key, b1, b2) = best?;
        Some(R::hit(RawHit { t, object: key as u32, prim: (key >> 32) as u32, b1, b2 }, R::NO_CORNERS))
    }

    /// The closest hit on object `obj` with `t < tmax`: `(primitive, hit)` (a sphere is
    /// primitive 0, barycentrics 0). `shared` holds the ray's watertight set-up once made, for
    /// every untransformed object it meets.
    #[inline(always)]
    fn closest_in_object(
        &self,
        obj: u32,
        ray: &Ray,
        shared: &mut Option<Ray4>,
        tmax: f32,
        counter: &impl Counter,
    ) -> Option<(u32, TriHit)> {
        if let Some(blocks) = self.direct_blocks(obj) {
            return closest_in_blocks(blocks, shared_ray4(shared, ray), tmax, counter).map(|h| (h.tri, h.hit));
        }
        let o = &self.scene.objects[obj as usize];
        match &self.scene.geometries[o.geometry] {
            Geometry::Sphere(s) => {
                let local = o.transform.as_ref().map_or(*ray, |x| x.ray_to_object(ray));
                intersect_sphere(s, local.o, local.d, tmax).map(|t| (0, TriHit { t, b1: 0.0, b2: 0.0 }))
            }
            Geometry::Mesh(_) => {
                let accel = self.blas[o.geometry].as_ref()?;
                let mut tm = tmax;
                let (tri, h) = with_mesh_ray(o, ray, shared, |local, r4| {
                    self.tris[o.geometry].closest::<A, (u32, TriHit)>(accel, local, r4, &mut tm, counter)
                })?;
                // The distance the query lowered `tm` to, as this query always reported it.
                Some((tri, TriHit { t: tm, ..h }))
            }
        }
    }

    /// The tree packets share, with its triangle blocks and leaf ranges: a single untransformed
    /// mesh whose blocks sit in leaves. Anything else (a small mesh tested as one range
    /// included) traces packets ray by ray.
    #[allow(clippy::type_complexity)]
    fn packet_tree(&self) -> Option<(&A, &[Tri4], &[(u32, u32)], bool)> {
        match self.scene.objects.as_slice() {
            [o] if o.transform.is_none() && self.tris[o.geometry].whole_range().is_none() => {
                match (&self.tris[o.geometry], &self.blas[o.geometry]) {
                    (TriData::Leaves { blocks, ranges, labelled }, Some(accel)) => {
                        Some((accel, blocks, ranges, *labelled))
                    }
                    _ => None,
                }
            }
            _ => None,
        }
    }

    /// The tree and triangles of a scene that is one untransformed mesh in leaves (as
    /// [`World::packet_tree`] finds it): single-ray queries enter its tree straight away,
    /// past the layers that test objects (`World::closest_in_object` and the like).
    #[inline(always)]
    fn one_tree(&self) -> Option<(&A, &TriData)> {
        if !self.packets || self.scene.objects.len() != 1 {
            return None;
        }
        // With one object, `packets` says `packet_tree` found it such a mesh.
        let g = self.scene.objects[0].geometry;
        Some((self.blas[g].as_ref()?, &self.tris[g]))
    }

    /// Whether packets traverse the top level together: several objects, each leaf of the top
    /// level one of them.
    fn top_packets(&self) -> bool {
        self.top_by_object && self.scene.objects.len() > 1
    }

    /// Closest hits of the `active` ones of eight rays traced as a packet (coherent rays such
    /// as camera rays): the same hits as [`World::hit`] gives each ray (None for lanes not
    /// active), but for exact ties: where a ray meets triangles in different leaves at one
    /// distance (through a vertex or an edge they share), the first found wins, and a packet
    /// may visit those leaves in another order than the ray alone. Packets pay for a single
    /// untransformed mesh, whose leaves are blocks of four triangles, and for a top level
    /// whose leaves are objects (each ray then tests the objects it reaches alone); other
    /// scenes trace the rays one by one.
    pub fn hit_packet8(&self, rays: &[Ray; 8], active: u8) -> [Option<RawHit>; 8] {
        if !self.packets {
            return std::array::from_fn(|i| {
                (active & (1 << i) != 0).then(|| self.hit(&rays[i], f32::INFINITY)).flatten()
            });
        }
        let mut packet = PacketRays::default();
        let mut t = [f32::INFINITY; 8];
        // Per lane: the hit triangle (primitive) and its object.
        let mut rec: [Option<(u32, TriHit)>; 8] = [None; 8];
        let mut objs = [0u32; 8];
        if let Some((accel, blocks, ranges, labelled)) = self.packet_tree() {
            accel.closest_leaf_packet8(rays, active, &mut t, |leaf, lanes, tm| {
                let blocks = TriData::leaf_blocks(blocks, ranges, labelled, leaf);
                packet.closest_in_blocks(rays, active, self.avx2, blocks, lanes, tm, &mut rec)
            });
        } else if self.top_packets() {
            // The packet traverses the top level together; the rays that reach an object's leaf
            // test the object (its blocks together, other objects ray by ray).
            self.top.closest_leaf_packet8(rays, active, &mut t, |obj, lanes, tm| {
                let hit = match self.direct_blocks(obj) {
                    Some(blocks) => packet.closest_in_blocks(rays, active, self.avx2, blocks, lanes, tm, &mut rec),
                    None => {
                        let mut hit = 0;
                        for lane in crate::accel::lanes(lanes.into()) {
                            let found =
                                self.closest_in_object(obj, &rays[lane], &mut packet.r4[lane], tm[lane], &NoCount);
                            if let Some(f) = found {
                                (tm[lane], rec[lane]) = (f.1.t, Some(f));
                                hit |= 1 << lane;
                            }
                        }
                        hit
                    }
                };
                for lane in crate::accel::lanes(hit.into()) {
                    objs[lane] = obj;
                }
                hit
            });
        }
        std::array::from_fn(|i| rec[i].map(|(prim, h)| RawHit { t: t[i], object: objs[i], prim, b1: h.b1, b2: h.b2 }))
    }

    /// [`World::hit_packet8`] for `P` groups of eight rays (at most 4: a 4×4 pixel tile as two
    /// groups, group 0 its top two rows, or one pixel's camera samples), with `active` lanes per
    /// group, the hits written into `out` (None where a lane is not active or misses). A single
    /// mesh's tree is traversed by all the groups together ([`Accel::closest_leaf_packets`]),
    /// each interior node tested once for all of them; other scenes trace the groups as
    /// [`World::hit_packet8`] does.
    pub fn hit_packets<const P: usize>(
        &self,
        rays: &[[Ray; 8]; P],
        active: [u8; P],
        out: &mut [[Option<RawHit>; 8]; P],
    ) {
        let tree = self.packet_tree().filter(|_| self.packets);
        let Some((accel, blocks, ranges, labelled)) = tree else {
            for (g, out) in out.iter_mut().enumerate() {
                *out = if active[g] != 0 { self.hit_packet8(&rays[g], active[g]) } else { [None; 8] };
            }
            return;
        };
        let mut packet: [PacketRays; P] = std::array::from_fn(|_| PacketRays::default());
        let mut t = [[f32::INFINITY; 8]; P];
        let mut rec: [[Option<(u32, TriHit)>; 8]; P] = [[None; 8]; P];
        accel.closest_leaf_packets(rays, active, &mut t, |g, leaf, lanes, tm| {
            let blocks = TriData::leaf_blocks(blocks, ranges, labelled, leaf);
            packet[g].closest_in_blocks(&rays[g], active[g], self.avx2, blocks, lanes, tm, &mut rec[g])
        });
        // The packet tree is the one object's.
        for ((out, rec), t) in out.iter_mut().zip(&rec).zip(&t) {
            *out = std::array::from_fn(|i| {
                rec[i].map(|(prim, h)| RawHit { t: t[i], object: 0, prim, b1: h.b1, b2: h.b2 })
            });
        }
    }

    /// [`World::occluded`]'s walk alone, a diagnostic for `snell bench --walk-only`: in a world
    /// that is one untransformed mesh in leaves (as `World::one_tree` finds it), its tree
    /// walked for the ray as an any-hit query walks it, but every leaf answering "not blocked"
    /// at once, without its triangle tests. So the walk visits every node whose box the ray
    /// enters, and reaches every leaf, as a ray that nothing blocks does; its time is the
    /// walk's own, with the leaf test's call where the AVX2 walk calls it (the AVX-512 walk
    /// inlines it, as it does the real test). `None` in any other world.
    pub fn occluded_walk_only(&self, ray: &Ray, t_max: f32) -> Option<bool> {
        let (accel, _) = self.one_tree()?;
        // Never true (leaf labels are below 2^31); opaque to the compiler, which would
        // otherwise drop the calls.
        let test = {
            #[inline(always)]
            |leaf: u32, _: f32| std::hint::black_box(leaf) == u32::MAX
        };
        Some(accel.any_leaf_inlined(ray, t_max, test, &NoCount))
    }

    /// Whether anything blocks the ray within `0 < t < t_max` (any-hit query).
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.occluded_skipping(ray, t_max, Skip::NONE)
    }

    /// [`World::occluded`] passing over the objects of `skip`, which the ray cannot meet.
    pub fn occluded_skipping(&self, ray: &Ray, t_max: f32, skip: Skip) -> bool {
        if let Some((accel, tris)) = self.one_tree() {
            return tris.any(accel, ray, &mut None, t_max);
        }
        let mut shared = None;
        // Inlined, as in `hit_skipping`.
        let mut test = {
            #[inline(always)]
            |obj: u32, tmax: f32| !skip.has(obj) && self.any_in_object(obj, ray, &mut shared, tmax)
        };
        if self.scene.objects.len() == 1 {
            test(0, t_max)
        } else if self.top_by_object {
            self.top.any_leaf_counted(ray, t_max, test, &NoCount)
        } else {
            self.top.any(ray, t_max, test)
        }
    }

    /// Whether object `obj` blocks `ray` within `0 < t < tmax`; `shared` as in
    /// [`World::closest_in_object`].
    #[inline(always)]
    fn any_in_object(&self, obj: u32, ray: &Ray, shared: &mut Option<Ray4>, tmax: f32) -> bool {
        if let Some(blocks) = self.direct_blocks(obj) {
            return Tri4::any_in(blocks, shared_ray4(shared, ray), tmax);
        }
        let o = &self.scene.objects[obj as usize];
        match &self.scene.geometries[o.geometry] {
            Geometry::Sphere(s) => {
                let local = o.transform.as_ref().map_or(*ray, |x| x.ray_to_object(ray));
                intersect_sphere(s, local.o, local.d, tmax).is_some()
            }
            Geometry::Mesh(_) => {
                let Some(accel) = self.blas[o.geometry].as_ref() else { return false };
                with_mesh_ray(o, ray, shared, |local, r4| self.tris[o.geometry].any(accel, local, r4, tmax))
            }
        }
    }

    /// [`World::occluded_skipping`] for the `active` ones of eight rays, each with its own
    /// `t_max` and `skip`: the mask of those blocked. Coherent rays (a point's shadow rays to
    /// the samples of one area light) traverse a single mesh's tree or a top level of objects
    /// together, as [`World::hit_packet8`]'s do; a ray stops taking part once something blocks
    /// it. Every ray gets the answer it gets alone: the same objects passed over, the same
    /// triangle arithmetic, and boxes that never cut off a hit either way.
    pub fn occluded_packet8(&self, rays: &[Ray; 8], active: u8, t_max: &[f32; 8], skip: &[Skip; 8]) -> u8 {
        let one_by_one = || {
            crate::accel::lanes(active.into())
                .filter(|&i| self.occluded_skipping(&rays[i], t_max[i], skip[i]))
                .fold(0u8, |m, i| m | 1 << i)
        };
        if !self.packets {
            return one_by_one();
        }
        let mut packet = PacketRays::default();
        let mut t = *t_max;
        if self.packet_tree().is_some() {
            // As `occluded_skipping` for this scene, nothing is passed over.
            let g = self.scene.objects[0].geometry;
            return self.any_packet_in_mesh(g, rays, active, &mut t, &mut packet).unwrap_or_else(one_by_one);
        }
        if !self.top_packets() {
            return one_by_one();
        }
        let mut rec = [None; 8];
        let mut blocked = 0u8;
        self.top.closest_leaf_packet8(rays, active, &mut t, |obj, lanes, tm| {
            let passed = (0..8).fold(0u8, |m, i| m | (skip[i].has(obj) as u8) << i);
            let lanes = lanes & !blocked & !passed;
            if lanes == 0 {
                return 0;
            }
            // The rays of `lanes` against the object one at a time, as `occluded_skipping` tests it.
            let each = |r4: &mut [Option<Ray4>; 8], tm: &[f32; 8]| {
                crate::accel::lanes(lanes.into())
                    .filter(|&i| self.any_in_object(obj, &rays[i], &mut r4[i], tm[i]))
                    .fold(0u8, |m, i| m | 1 << i)
            };
            let o = &self.scene.objects[obj as usize];
            let hit = match (self.direct_blocks(obj), &o.transform, &self.scene.geometries[o.geometry]) {
                (Some(blocks), _, _) => packet.closest_in_blocks(rays, active, self.avx2, blocks, lanes, tm, &mut rec),
                // A transformed mesh: its rays taken into its space and tested together there
                // (one at a time where its triangles are not in blocks).
                (None, Some(x), Geometry::Mesh(_)) if lanes.count_ones() >= 2 => {
                    let local = rays.map(|r| x.ray_to_object(&r));
                    let mut local_t = *tm;
                    self.any_packet_in_mesh(o.geometry, &local, lanes, &mut local_t, &mut PacketRays::default())
                        .unwrap_or_else(|| each(&mut packet.r4, tm))
                }
                _ => each(&mut packet.r4, tm),
            };
            drop_blocked(hit, tm, &mut blocked)
        });
        blocked
    }

    /// The `active` ones of eight rays (in its own space) that the triangles of mesh geometry
    /// `g` block within their bound `t` (a blocked ray's bound dropped to [`BLOCKED`]): its
    /// blocks tested together, under its structure where it has one. None where its
    /// triangles are not in blocks (a structure without leaves of blocks).
    fn any_packet_in_mesh(
        &self,
        g: usize,
        rays: &[Ray; 8],
        active: u8,
        t: &mut [f32; 8],
        packet: &mut PacketRays,
    ) -> Option<u8> {
        let TriData::Leaves { blocks, ranges, labelled } = &self.tris[g] else { return None };
        let mut rec = [None; 8];
        if let Some((a, b)) = TriData::one_range(ranges) {
            let blocks = &blocks[a as usize..b as usize];
            return Some(packet.closest_in_blocks(rays, active, self.avx2, blocks, active, t, &mut rec));
        }
        let accel = self.blas[g].as_ref()?;
        let mut blocked = 0u8;
        accel.closest_leaf_packet8(rays, active, t, |leaf, lanes, tm| {
            let lanes = lanes & !blocked;
            let blocks = TriData::leaf_blocks(blocks, ranges, *labelled, leaf);
            let hit = packet.closest_in_blocks(rays, active, self.avx2, blocks, lanes, tm, &mut rec);
            drop_blocked(hit, tm, &mut blocked)
        });
        Some(blocked)
    }

    /// Everything shading needs about the hit `h` of `ray` (as [`World::hit`] or a packet query
    /// finds it), written into `out`, where the caller keeps it. An untransformed mesh's hit
    /// (most hits) is worked out inline and written there field by field. (Returned from a
    /// call, or from the two ways joined, it was built in a temporary and copied over in
    /// 16-byte pieces, whose loads waited for the temporary's narrower stores: a
    /// store-forwarding stall on every hit.)
    #[inline(always)]
    pub fn interaction_into(&self, ray: &Ray, h: &RawHit, out: &mut Option<Intersection>) {
        self.interaction_at(ray, h, None, out)
    }

    /// [`World::interaction_into`] given the hit triangle's `corners` where the query had them
    /// (those of an untransformed mesh, which are the mesh's positions): its point and its
    /// normal are made from them rather than from the mesh's index and position arrays (two
    /// dependent loads) and `face_normals` (a third), each a likely cache miss on a large mesh
    /// (the dragon's renders 1.05–1.08× as fast, the bunny's 1.01–1.02×). The same bits.
    #[inline(always)]
    fn interaction_at(&self, ray: &Ray, h: &RawHit, corners: Option<Corners>, out: &mut Option<Intersection>) {
        let Some(m) = &self.object_meshes[h.object as usize] else {
            return self.interaction_other_into(ray, h, out);
        };
        let RawHit { t, object, prim, b1, b2 } = *h;
        let corners = corners.map(|c| c.get());
        let face_normal = match corners {
            Some(c) => winding_normal(c),
            None => self.face_normals[m.geometry][prim as usize],
        };
        let (p, ng, ns, uv) = m.surface(face_normal, prim, b1, b2, corners);
        *out = Some(Intersection::new(ray, t, p, ng, ns, uv, object));
    }

    /// [`World::interaction_into`] of a hit on a sphere or a transformed mesh.
    #[inline(never)]
    fn interaction_other_into(&self, ray: &Ray, h: &RawHit, out: &mut Option<Intersection>) {
        let RawHit { t, object: obj, prim, b1, b2 } = *h;
        let o = &self.scene.objects[obj as usize];
        let (p, mut ng, mut ns, uv) = match &self.scene.geometries[o.geometry] {
            Geometry::Sphere(s) => {
                let local = match &o.transform {
                    Some(x) => x.ray_to_object(ray),
                    None => *ray,
                };
                // Re-project onto the surface to remove the error of o + t·d.
                let n = (local.at(t) - s.center).normalize_or_zero();
                let p = s.center + n * s.radius;
                let uv = Vec2::new(
                    0.5 + crate::sampling::atan2(n.z, n.x) / std::f32::consts::TAU,
                    n.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI,
                );
                (p, n, n, uv)
            }
            Geometry::Mesh(m) => {
                MeshRef::new(m, o.geometry).surface(self.face_normals[o.geometry][prim as usize], prim, b1, b2, None)
            }
        };
        let p = match &o.transform {
            Some(x) => {
                ng = x.normal(ng).normalize_or_zero();
                ns = x.normal(ns).normalize_or_zero();
                x.point(p)
            }
            None => p,
        };
        *out = Some(Intersection::new(ray, t, p, ng, ns, uv, obj));
    }
}

/// A mesh's arrays as [`World::interaction_into`] reads them, and the index of its geometry.
#[derive(Clone, Copy)]
struct MeshRef<'s> {
    indices: &'s [[u32; 3]],
    positions: &'s [Vec3],
    normals: Option<&'s [Vec3]>,
    uvs: Option<&'s [Vec2]>,
    geometry: usize,
}

impl<'s> MeshRef<'s> {
    fn new(m: &'s Mesh, geometry: usize) -> MeshRef<'s> {
        MeshRef {
            indices: &m.indices,
            positions: &m.positions,
            normals: m.normals.as_deref(),
            uvs: m.uvs.as_deref(),
            geometry,
        }
    }

    /// The point, geometric normal (`face_normal`, turned to the shading normal's side),
    /// shading normal and texture coordinates at barycentrics `(b1, b2)` of triangle `prim`;
    /// its `corners` where the caller has them (else they are read through the index array,
    /// as the vertex normals and texture coordinates are).
    #[inline(always)]
    fn surface(
        &self,
        face_normal: Vec3,
        prim: u32,
        b1: f32,
        b2: f32,
        corners: Option<[Vec3; 3]>,
    ) -> (Vec3, Vec3, Vec3, Vec2) {
        let index = || self.indices[prim as usize].map(|i| i as usize);
        let b0 = 1.0 - b1 - b2;
        let [p0, p1, p2] = corners.unwrap_or_else(|| index().map(|i| self.positions[i]));
        // The hit point from barycentrics is far more accurate than o + t·d.
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let mut ng = face_normal;
        let ns = match self.normals {
            Some(n) => {
                let [i0, i1, i2] = index();
                let ns = (n[i0] * b0 + n[i1] * b1 + n[i2] * b2).normalize_or_zero();
                if ns == Vec3::ZERO {
                    ng
                } else {
                    if ng.dot(ns) < 0.0 {
                        ng = -ng;
                    }
                    ns
                }
            }
            None => ng,
        };
        let uv = match self.uvs {
            Some(u) => {
                let [i0, i1, i2] = index();
                u[i0] * b0 + u[i1] * b1 + u[i2] * b2
            }
            None => Vec2::new(b1, b2),
        };
        (p, ng, ns, uv)
    }
}

impl Intersection {
    /// The hit with its normals made usable: a zero geometric normal faces the ray, and a
    /// shading normal that is zero or on the other side is the geometric one.
    #[inline(always)]
    fn new(ray: &Ray, t: f32, p: Vec3, mut ng: Vec3, mut ns: Vec3, uv: Vec2, object: u32) -> Intersection {
        if ng == Vec3::ZERO {
            ng = -ray.d.normalize_or_zero();
        }
        if ns == Vec3::ZERO || ns.dot(ng) <= 0.0 {
            ns = ng;
        }
        Intersection { t, p, ng, ns, uv, object }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(corner: Vec3, e1: Vec3, e2: Vec3) -> Mesh {
        let mut m = Mesh::quad(corner, e1, e2);
        m.validate().unwrap();
        m
    }

    /// A scene of these geometries, objects and materials, with no other lights, seen by a
    /// camera at `+z` looking at the origin.
    fn scene_of(geometries: Vec<Geometry>, objects: Vec<Object>, materials: Vec<Material>) -> Scene {
        let camera = crate::camera::Camera::look_at(
            Vec3::Z,
            Vec3::ZERO,
            Vec3::Y,
            crate::camera::Projection::Perspective { fov_y: 40.0 },
        )
        .unwrap();
        Scene {
            geometries,
            objects,
            materials,
            lights: Vec::new(),
            camera,
            background: Rgb::ZERO,
            ambient: Rgb::ZERO,
            light_selection: LightSelection::Power,
        }
    }

    #[test]
    fn leaf_labels_give_back_their_block_ranges() {
        for (a, b) in [(0, 1), (0, 8), (5, 6), (123_456, 123_463), ((1 << 27) - 9, (1 << 27) - 1)] {
            let l = label_of_range(a, b).unwrap();
            assert!(l < (1 << 31) - 1);
            assert_eq!(block_range(l), (a, b));
        }
        // Nine blocks, an empty range, or a range past 2^27 blocks stay with the table.
        assert_eq!(label_of_range(0, 9), None);
        assert_eq!(label_of_range(3, 3), None);
        assert_eq!(label_of_range((1 << 27) - 1, 1 << 27), None);
    }

    /// Where a query hands over the hit triangle's corners (a scene of one untransformed mesh),
    /// they are the mesh's own corners of that triangle, and the surface made from them (with
    /// the normal worked out from them) is the one made through the mesh's arrays, bit for bit:
    /// every accelerator, a mesh with and without vertex normals and texture coordinates.
    #[test]
    fn corners_from_the_query_give_the_surface_the_mesh_gives() {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let plain = Mesh::icosphere(3);
        let mut smooth = plain.clone();
        smooth.normals =
            Some(smooth.positions.iter().map(|p| (*p + 0.1 * Vec3::new(p.y, p.z, p.x)).normalize()).collect());
        smooth.uvs = Some(smooth.positions.iter().map(|p| Vec2::new(p.x * 0.5 + 0.5, p.y * p.z)).collect());
        for mesh in [plain, smooth] {
            let white = Material::Diffuse { albedo: crate::material::Texture::Constant(Rgb::ONE) };
            let object = Object { geometry: 0, transform: None, material: 0, emission: Rgb::ZERO, light_samples: 1 };
            let scene = scene_of(vec![Geometry::Mesh(mesh.clone())], vec![object], vec![white]);
            for kind in crate::accel::AccelKind::ALL {
                let any = kind.build_world(&scene, &crate::accel::AccelParams::default());
                crate::with_world!(&any, world => {
                    let mut rng = crate::sampling::Pcg32::new(3, 5);
                    let mut handed = 0;
                    for _ in 0..2000 {
                        let from = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 6.0 - 3.0;
                        let to = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.6 - 0.8;
                        let ray = Ray::new(from, (to - from).normalize());
                        let Some((h, corners)) = world.hit_skipping::<(u32, TriHit, Option<Corners>)>(&ray, f32::INFINITY, Skip::NONE, &NoCount) else {
                            continue;
                        };
                        if let Some(c) = corners {
                            assert_eq!(c.get(), mesh.triangle(h.prim as usize), "{kind:?}: triangle {}", h.prim);
                            handed += 1;
                        }
                        let (mut through_arrays, mut from_query) = (None, None);
                        world.interaction_into(&ray, &h, &mut through_arrays);
                        world.intersect_skipping_into(&ray, f32::INFINITY, Skip::NONE, &mut from_query);
                        let (a, b) = (through_arrays.unwrap(), from_query.unwrap());
                        let flat = |i: &Intersection| {
                            [[i.t].as_slice(), &i.p.to_array(), &i.ng.to_array(), &i.ns.to_array(), &i.uv.to_array()].concat()
                        };
                        assert_eq!(bits(&flat(&a)), bits(&flat(&b)), "{kind:?}: ray {ray:?}");
                        assert_eq!(a.object, b.object);
                    }
                    // The trees of one mesh hand them over; the other structures need not.
                    if world.one_tree().is_some() {
                        assert!(handed > 500, "{kind:?}: {handed} hits with corners");
                    }
                });
            }
        }
    }

    /// The record a path vertex reads gives the BSDF, the sidedness and the emission that the
    /// object and its material give, and leaves every other material to `Material::bsdf`.
    #[test]
    fn surfaces_give_what_their_materials_give() {
        use crate::material::bsdf::Bsdf;
        use crate::material::microfacet::Distribution;
        use crate::material::Texture;
        let albedo = Rgb::new(0.5, 0.25, 0.125);
        let checker = Texture::Checker { a: Rgb::ONE, b: Rgb::ZERO, scale: 4.0 };
        let materials = vec![
            Material::Diffuse { albedo: Texture::Constant(albedo) },
            Material::OneSided(Box::new(Material::Diffuse { albedo: Texture::Constant(albedo) })),
            Material::Diffuse { albedo: checker.clone() },
            Material::OneSided(Box::new(Material::Diffuse { albedo: checker })),
            Material::plastic(Texture::Constant(albedo), Rgb::ONE, 1.5, 0.0, Distribution::Ggx),
            Material::Mirror { reflectance: Rgb::ONE },
        ];
        let objects: Vec<Object> = (0..materials.len())
            .map(|i| Object {
                geometry: 0,
                transform: None,
                material: i,
                emission: if i == 1 { Rgb::new(2.0, 3.0, 4.0) } else { Rgb::ZERO },
                light_samples: 1,
            })
            .collect();
        let scene = scene_of(vec![Geometry::Mesh(quad(Vec3::ZERO, Vec3::X, Vec3::Y))], objects, materials);
        let world: World<crate::accel::Brute> = World::build(&scene, &crate::accel::AccelParams::default());
        let diffuse = [Some(albedo), Some(albedo), None, None, None, None];
        for (i, (s, o)) in world.surfaces.iter().zip(&scene.objects).enumerate() {
            let m = &scene.materials[o.material];
            assert_eq!(s.emission, o.emission, "object {i}");
            assert_eq!(s.two_sided, m.two_sided(), "object {i}");
            assert_eq!(s.material, o.material, "object {i}");
            assert_eq!(s.diffuse, diffuse[i], "object {i}");
            if let Some(a) = s.diffuse {
                for uv in [Vec2::ZERO, Vec2::new(0.3, 0.7), Vec2::new(0.9, 0.1)] {
                    match m.bsdf(uv) {
                        Bsdf::Diffuse { albedo } => assert_eq!(albedo, a, "object {i} at {uv}"),
                        other => panic!("object {i}: {other:?}"),
                    }
                }
            }
        }
    }

    #[test]
    fn emitting_rectangles_are_sampled_as_rectangles() {
        let shape = |m: Mesh, transform: Option<Transform>| {
            let scene = scene_of(vec![Geometry::Mesh(m)], Vec::new(), Vec::new());
            let o = Object { geometry: 0, transform, material: 0, emission: Rgb::ONE, light_samples: 1 };
            scene.area_light(0, &o).shape
        };
        let r = shape(quad(Vec3::ZERO, Vec3::X * 2.0, Vec3::Y), None);
        match r {
            AreaShape::Rectangle { ex, ey, normal, .. } => {
                assert!((ex.length() * ey.length() - 2.0).abs() < 1e-6);
                assert!((normal - Vec3::Z).length() < 1e-6, "the winding's side: {normal:?}");
            }
            other => panic!("{other:?}"),
        }
        // Moved and turned, still a rectangle; a parallelogram and a single triangle are not.
        let t = Transform::try_new(glam::Affine3A::from_rotation_x(0.5) * glam::Affine3A::from_translation(Vec3::ONE));
        assert!(matches!(shape(quad(Vec3::ZERO, Vec3::X, Vec3::Y), t), AreaShape::Rectangle { .. }));
        assert!(matches!(
            shape(quad(Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1.0, 0.0)), None),
            AreaShape::Triangles { .. }
        ));
        let mut tri = quad(Vec3::ZERO, Vec3::X, Vec3::Y);
        tri.indices.truncate(1);
        assert!(matches!(shape(tri, None), AreaShape::Triangles { .. }));
    }

    /// `World::leaving` passes over only objects a ray cannot meet. From real hits on flat,
    /// convex and other meshes and on spheres (one stretched into an ellipsoid), rays leaving
    /// to either side find the same closest hit, and the same occlusion, with the skip as
    /// without; and the skip is taken for every ray off a flat object, for some off a convex
    /// one (those leaving outwards), and never off the others.
    #[test]
    fn rays_leaving_a_surface_pass_over_only_what_they_cannot_meet() {
        let mut geometries = Vec::new();
        let mut expect = Vec::new();
        for (k, (name, mut m, want)) in crate::shape::reentry_shapes().into_iter().enumerate() {
            if m.indices.is_empty() {
                continue;
            }
            // Side by side (in place: the objects stay untransformed).
            let shift = Vec3::new(6.0 * k as f32, 0.0, 0.0);
            m.positions.iter_mut().for_each(|p| *p += shift);
            // A mesh on its box's faces is never passed over: its box test turns away the
            // rays leaving it outwards already.
            let want = if m.on_box_faces() { None } else { want };
            geometries.push(Geometry::Mesh(m));
            expect.push((name, want, None));
        }
        geometries.push(Geometry::Sphere(Sphere { center: Vec3::new(-6.0, 0.5, 0.0), radius: 0.8 }));
        expect.push(("sphere", Some(false), None));
        geometries.push(Geometry::Sphere(Sphere { center: Vec3::ZERO, radius: 1.0 }));
        let stretch = glam::Affine3A::from_translation(Vec3::new(-12.0, 0.0, 1.0))
            * glam::Affine3A::from_scale(Vec3::new(2.0, 0.5, 1.0));
        expect.push(("ellipsoid", Some(false), Transform::try_new(stretch)));
        let objects = expect
            .iter()
            .enumerate()
            .map(|(g, e)| Object { geometry: g, transform: e.2, material: 0, emission: Rgb::ZERO, light_samples: 1 })
            .collect();
        let white = Material::Diffuse { albedo: crate::material::Texture::Constant(Rgb::ONE) };
        let scene = scene_of(geometries, objects, vec![white]);
        // Every accelerator: the skip is taken in the world's own object test.
        for kind in crate::accel::AccelKind::ALL {
            let any = kind.build_world(&scene, &crate::accel::AccelParams::default());
            crate::with_world!(&any, world => {
                let mut rng = crate::sampling::Pcg32::new(7, 11);
                let unit = |rng: &mut crate::sampling::Pcg32| loop {
                    let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
                    if (1e-3..1.0).contains(&v.length_squared()) {
                        break v.normalize();
                    }
                };
                // Per object: rays left from it, and how many of them passed over it.
                let mut counts = vec![(0u32, 0u32); expect.len()];
                for (i, o) in scene.objects.iter().enumerate() {
                    let b = o.place_aabb(scene.geometries[o.geometry].aabb());
                    for _ in 0..400 {
                        let target = b.min + (b.max - b.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                        let from = target + unit(&mut rng) * 5.0;
                        let Some(hit) = world.intersect(&Ray::new(from, target - from), f32::INFINITY) else { continue };
                        for _ in 0..4 {
                            let ray = crate::geometry::spawn_ray(hit.p, hit.ng, unit(&mut rng));
                            let skip = world.leaving(hit.object, hit.p, hit.ng, ray.d);
                            let c = &mut counts[hit.object as usize];
                            c.0 += 1;
                            c.1 += u32::from(skip != Skip::NONE);
                            let (want, got) = (world.hit(&ray, f32::INFINITY), world.hit_skipping::<(u32, TriHit)>(&ray, f32::INFINITY, skip, &NoCount));
                            assert_eq!(got, want, "object {i} ({}): ray {ray:?} from a hit on {}", expect[i].0, hit.object);
                            assert_eq!(world.occluded_skipping(&ray, f32::INFINITY, skip), want.is_some());
                        }
                    }
                }
                for ((name, want, _), &(rays, skipped)) in expect.iter().zip(&counts) {
                    assert!(rays >= 200, "{kind:?}, {name}: only {rays} rays");
                    match want {
                        Some(true) => assert_eq!(skipped, rays, "{kind:?}, {name}: flat"),
                        Some(false) => {
                            assert!(skipped > rays / 5 && skipped < rays, "{kind:?}, {name}: {skipped} of {rays} passed over")
                        }
                        None => assert_eq!(skipped, 0, "{kind:?}, {name}"),
                    }
                }
            });
        }
    }
}
