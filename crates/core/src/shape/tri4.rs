//! Four triangles tested at once: the watertight test of [`super::triangle`] in SSE lanes.
//!
//! A BVH leaf's triangles are stored together in blocks of four in structure-of-arrays form
//! (Embree's `triangle4v` idea), so a leaf costs one cache-friendly block read and one SIMD
//! test instead of four gathers and four scalar tests. Every lane does exactly the
//! arithmetic of [`intersect_triangle`], in the same order, so the results are the same bit
//! for bit; a block in which some edge function comes out exactly zero is handed to the
//! scalar test (which recomputes such edges in `f64`).

use glam::Vec3;

use super::triangle::{intersect_triangle, TriHit, WatertightRay};

/// Up to four triangles: `v[vertex][axis][lane]`, and the triangle index of each lane
/// ([`Tri4::NONE`] and NaN corners in unused lanes, which therefore never hit).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub struct Tri4 {
    pub v: [[[f32; 4]; 3]; 3],
    pub id: [u32; 4],
}

/// Per-ray data of the 4-wide test: the watertight ray and, where the test runs in SSE lanes,
/// its origin in sheared-axis order and its shear constants, each broadcast to four lanes once
/// per ray (a ray that reaches several leaves or objects shares them, where each run of blocks
/// broadcast them again), with its axes as indices.
#[derive(Clone, Copy, Debug)]
pub struct Ray4 {
    pub ray: WatertightRay,
    #[cfg(target_arch = "x86_64")]
    lanes: Lanes4,
}

impl Ray4 {
    /// The watertight set-up of `ray` and its lanes, its origin and direction read by axis where
    /// they lie (see [`WatertightRay::of`]).
    #[inline(always)]
    pub fn of(ray: &crate::geometry::Ray) -> Ray4 {
        let w = WatertightRay::of(&ray.o, &ray.d);
        Ray4 {
            ray: w,
            #[cfg(target_arch = "x86_64")]
            lanes: Lanes4::new(&w, &ray.o),
        }
    }
}

/// A hit found among blocks: the triangle, where on it, and where its corners are.
#[derive(Clone, Copy, Debug)]
pub struct BlockHit<'a> {
    pub tri: u32,
    pub hit: TriHit,
    pub corners: Corners<'a>,
}

/// Where a hit triangle's corners are: its block and lane. The hit's surface point is made
/// from them ([`Corners::get`]: read from the block the test has just read, rather than
/// through the mesh's index and position arrays, two dependent loads that miss the caches on
/// a large mesh); kept as a reference until then, so that a query whose caller wants no
/// surface reads nothing more.
#[derive(Clone, Copy, Debug)]
pub struct Corners<'a> {
    block: &'a Tri4,
    lane: usize,
}

impl Corners<'_> {
    /// The triangle's corners, as [`Tri4::pack`] was given them.
    #[inline(always)]
    pub fn get(&self) -> [Vec3; 3] {
        self.block.corners(self.lane)
    }
}

impl Tri4 {
    pub const NONE: u32 = u32::MAX;

    /// Packs up to four triangles `(index, corners)`.
    pub fn pack(tris: impl IntoIterator<Item = (u32, [Vec3; 3])>) -> Tri4 {
        let mut b = Tri4 { v: [[[f32::NAN; 4]; 3]; 3], id: [Tri4::NONE; 4] };
        for (lane, (id, p)) in tris.into_iter().enumerate() {
            assert!(lane < 4, "a block holds at most four triangles");
            b.id[lane] = id;
            for (vtx, c) in p.iter().enumerate() {
                for axis in 0..3 {
                    b.v[vtx][axis][lane] = c[axis];
                }
            }
        }
        b
    }

    /// Number of triangles in the block.
    #[inline]
    pub fn len(&self) -> usize {
        self.id.iter().filter(|&&i| i != Tri4::NONE).count()
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.id[0] == Tri4::NONE
    }

    /// Lane `lane`'s `hit` as a [`BlockHit`]: its triangle and where its corners are.
    #[inline(always)]
    fn hit_at(&self, lane: usize, hit: TriHit) -> BlockHit<'_> {
        BlockHit { tri: self.id[lane], hit, corners: Corners { block: self, lane } }
    }

    #[inline(always)]
    fn corners(&self, lane: usize) -> [Vec3; 3] {
        self.v.map(|p| Vec3::new(p[0][lane], p[1][lane], p[2][lane]))
    }

    /// The scalar test, lane by lane, in lane order: the reference the SIMD path reproduces.
    #[cold]
    #[inline(never)]
    fn closest_scalar(&self, r: &Ray4, t_max: f32) -> Option<(usize, TriHit)> {
        let mut best: Option<(usize, TriHit)> = None;
        let mut tm = t_max;
        for lane in 0..4 {
            if self.id[lane] == Tri4::NONE {
                continue;
            }
            let [a, b, c] = self.corners(lane);
            if let Some(h) = intersect_triangle(&r.ray, a, b, c, tm) {
                tm = h.t;
                best = Some((lane, h));
            }
        }
        best
    }

    /// The closest hit with `0 < t < t_max` among the four: `(triangle index, hit)`. Ties go
    /// to the lower lane, as a test of the lanes in order would give.
    #[inline(always)]
    pub fn closest(&self, r: &Ray4, t_max: f32) -> Option<(u32, TriHit)> {
        Tri4::closest_at(std::slice::from_ref(self), r, t_max).map(|h| (h.tri, h.hit))
    }

    /// Whether any of the four is hit with `0 < t < t_max`.
    #[inline(always)]
    pub fn any(&self, r: &Ray4, t_max: f32) -> bool {
        Tri4::any_in(std::slice::from_ref(self), r, t_max)
    }

    /// The closest hit with `0 < t < t_max` among the triangles of `blocks`, tested in order,
    /// with where its corners are; the ray's constants are made ready once for all of them.
    #[inline(always)]
    pub fn closest_at<'a>(blocks: &'a [Tri4], r: &Ray4, mut t_max: f32) -> Option<BlockHit<'a>> {
        #[cfg(target_arch = "x86_64")]
        let l = &r.lanes;
        let mut rec = None;
        for block in blocks {
            // The lanes' hit stays in registers: had the two ways joined into one `found`, the
            // lanes' would have been stored field by field, where the scalar call returns it, and
            // read back in wider pieces (a store-forwarding stall on every block that hit).
            #[cfg(target_arch = "x86_64")]
            let found = match block.lanes(l, t_max) {
                Some((mask, t, inv, v, w)) => block.nearest(mask, t, inv, v, w),
                None => {
                    if let Some((lane, hit)) = block.closest_scalar(r, t_max) {
                        t_max = hit.t;
                        rec = Some(block.hit_at(lane, hit));
                    }
                    continue;
                }
            };
            #[cfg(not(target_arch = "x86_64"))]
            let found = block.closest_scalar(r, t_max);
            if let Some((lane, hit)) = found {
                t_max = hit.t;
                rec = Some(block.hit_at(lane, hit));
            }
        }
        rec
    }

    /// Whether any triangle of `blocks` is hit with `0 < t < t_max`.
    #[inline(always)]
    pub fn any_in(blocks: &[Tri4], r: &Ray4, t_max: f32) -> bool {
        #[cfg(target_arch = "x86_64")]
        let l = &r.lanes;
        blocks.iter().any(|block| {
            #[cfg(target_arch = "x86_64")]
            if let Some((mask, ..)) = block.lanes(l, t_max) {
                return mask != 0;
            }
            block.closest_scalar(r, t_max).is_some()
        })
    }

    /// The nearest of the lanes in `mask` (the lower lane among equal distances) and its hit;
    /// `inv` holds each lane's `1 / det`, as the lane test worked it out.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn nearest(&self, mask: u32, t: [f32; 4], inv: [f32; 4], v: [f32; 4], w: [f32; 4]) -> Option<(usize, TriHit)> {
        if mask == 0 {
            return None;
        }
        let mut lane = mask.trailing_zeros() as usize;
        let mut rest = mask & (mask - 1);
        while rest != 0 {
            let j = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if t[j] < t[lane] {
                lane = j;
            }
        }
        // The scalar test's `1.0 / det`: a lane of the SIMD quotient is the same IEEE quotient,
        // taken from there rather than divided again at the end of the query's critical path.
        let inv = inv[lane];
        Some((lane, TriHit { t: t[lane], b1: v[lane] * inv, b2: w[lane] * inv }))
    }

    /// The four tests in SSE lanes: `(hit mask, t, 1 / det, v, w)`, or `None` when an edge function
    /// of a lane not already rejected is exactly zero (the scalar test must decide those).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn lanes(&self, l: &Lanes4, t_max: f32) -> Option<(u32, [f32; 4], [f32; 4], [f32; 4], [f32; 4])> {
        use std::arch::x86_64::*;
        // SAFETY: SSE and SSE2 are part of the x86_64 baseline. All loads read 16-byte arrays
        // inside `self` (16-byte aligned), and all stores go to local four-float arrays.
        unsafe {
            let [kx, ky, kz] = l.k;
            let ([ox, oy, oz], [sx, sy, sz]) = (l.o, l.s);
            // Per vertex: projected x, y and the scaled z, exactly as the scalar test.
            let project = |p: &[[f32; 4]; 3]| {
                let x = _mm_sub_ps(_mm_load_ps(p[kx].as_ptr()), ox);
                let y = _mm_sub_ps(_mm_load_ps(p[ky].as_ptr()), oy);
                let z = _mm_sub_ps(_mm_load_ps(p[kz].as_ptr()), oz);
                (_mm_sub_ps(x, _mm_mul_ps(sx, z)), _mm_sub_ps(y, _mm_mul_ps(sy, z)), _mm_mul_ps(sz, z))
            };
            let (ax, ay, az) = project(&self.v[0]);
            let (bx, by, bz) = project(&self.v[1]);
            let (cx, cy, cz) = project(&self.v[2]);
            let u = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
            let v = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
            let w = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
            let zero = _mm_setzero_ps();
            // Unused lanes hold NaN corners: their edge functions are NaN, which no comparison
            // below lets through (NaN is never zero, and its det is not finite).
            let neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(u, zero), _mm_cmplt_ps(v, zero)), _mm_cmplt_ps(w, zero));
            let pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(u, zero), _mm_cmpgt_ps(v, zero)), _mm_cmpgt_ps(w, zero));
            // Rejected: both signs among the edge functions (most blocks a ray meets end here).
            // The scalar test rejects these lanes too, whatever their third edge (it recomputes
            // only edges that are exactly zero), so they are decided before zero edges are
            // looked for.
            let mut ok = _mm_andnot_ps(_mm_and_ps(neg, pos), _mm_cmpord_ps(u, u));
            if _mm_movemask_ps(ok) == 0 {
                return Some((0, [0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]));
            }
            let any_zero = _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)), _mm_cmpeq_ps(w, zero));
            if _mm_movemask_ps(_mm_and_ps(any_zero, ok)) != 0 {
                return None;
            }
            let det = _mm_add_ps(_mm_add_ps(u, v), w);
            let sign = _mm_and_ps(det, _mm_set1_ps(-0.0));
            let abs_det = _mm_andnot_ps(_mm_set1_ps(-0.0), det);
            // Rejected: det zero or not finite.
            ok = _mm_and_ps(ok, _mm_cmpneq_ps(det, zero));
            ok = _mm_and_ps(ok, _mm_cmplt_ps(abs_det, _mm_set1_ps(f32::INFINITY)));
            let ts = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u, az), _mm_mul_ps(v, bz)), _mm_mul_ps(w, cz));
            let ts_abs = _mm_xor_ps(ts, sign);
            let tmax = _mm_set1_ps(t_max);
            ok = _mm_andnot_ps(_mm_cmple_ps(ts_abs, zero), ok);
            ok = _mm_andnot_ps(_mm_cmpgt_ps(ts_abs, _mm_mul_ps(tmax, abs_det)), ok);
            if _mm_movemask_ps(ok) == 0 {
                return Some((0, [0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]));
            }
            let inv = _mm_div_ps(_mm_set1_ps(1.0), det);
            let t = _mm_mul_ps(ts, inv);
            ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpgt_ps(t, zero), _mm_cmplt_ps(t, tmax)));
            let mut out = [[0.0f32; 4]; 4];
            _mm_storeu_ps(out[0].as_mut_ptr(), t);
            _mm_storeu_ps(out[1].as_mut_ptr(), inv);
            _mm_storeu_ps(out[2].as_mut_ptr(), v);
            _mm_storeu_ps(out[3].as_mut_ptr(), w);
            Some((_mm_movemask_ps(ok) as u32, out[0], out[1], out[2], out[3]))
        }
    }
}

/// A [`Ray4`]'s constants in SSE lanes, with its axes as indices below 3.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
struct Lanes4 {
    o: [std::arch::x86_64::__m128; 3],
    s: [std::arch::x86_64::__m128; 3],
    k: [usize; 3],
}

#[cfg(target_arch = "x86_64")]
impl Lanes4 {
    /// The lanes of `ray`, whose origin `o` is read by axis where it lies.
    #[inline(always)]
    fn new(ray: &WatertightRay, o: &Vec3) -> Lanes4 {
        use std::arch::x86_64::_mm_set1_ps;
        let k = ray.axes();
        let o: &[f32; 3] = o.as_ref();
        // SAFETY: SSE is part of the x86_64 baseline.
        unsafe {
            Lanes4 {
                o: [o[k[0]], o[k[1]], o[k[2]]].map(|x| _mm_set1_ps(x)),
                s: ray.shear().map(|x| _mm_set1_ps(x)),
                // Axes are below 3 (a permutation of 0, 1, 2); saying so here spares the
                // blocks' loads their bounds checks.
                k: k.map(|a| a.min(2)),
            }
        }
    }
}

/// Eight rays that share their watertight permutation (camera rays of one packet do), in AVX
/// lanes: their origins in sheared-axis order and their shear constants.
#[cfg(target_arch = "x86_64")]
pub struct Rays8 {
    o: [std::arch::x86_64::__m256; 3],
    s: [std::arch::x86_64::__m256; 3],
    k: [usize; 3],
}

#[cfg(target_arch = "x86_64")]
impl Rays8 {
    /// The rays of the `lanes` mask (other lanes copy the first) made straight from the rays,
    /// eight at a time: the same axes and shear as [`WatertightRay::new`] gives each (the same
    /// comparisons, and divisions in AVX lanes, which round as scalar ones do), or None where
    /// two of them permute the axes differently.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub unsafe fn from_rays(rays: &[crate::geometry::Ray; 8], lanes: u8) -> Option<Rays8> {
        use std::arch::x86_64::*;
        let first = &rays[lanes.trailing_zeros() as usize & 7];
        let row = |f: &dyn Fn(&crate::geometry::Ray) -> f32| {
            let v: [f32; 8] = std::array::from_fn(|i| f(if lanes & (1 << i) != 0 { &rays[i] } else { first }));
            // SAFETY: an unaligned load of a local array of eight floats.
            unsafe { _mm256_loadu_ps(v.as_ptr()) }
        };
        let d = [row(&|r| r.d.x), row(&|r| r.d.y), row(&|r| r.d.z)];
        let sign = _mm256_set1_ps(-0.0);
        let [ax, ay, az] = d.map(|v| _mm256_andnot_ps(sign, v));
        // A mask's lanes all agree: every bit of the eight set, or none.
        let uniform = |m: __m256| -> Option<bool> {
            match _mm256_movemask_ps(m) as u8 {
                0 => Some(false),
                0xff => Some(true),
                _ => None,
            }
        };
        let x_max = uniform(_mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(ax, ay), _mm256_cmp_ps::<_CMP_GE_OQ>(ax, az)))?;
        // As `WatertightRay::new` chooses them (y against z matters only where x is not the
        // largest).
        let kz = if x_max { 0 } else { 2 - uniform(_mm256_cmp_ps::<_CMP_GE_OQ>(ay, az))? as usize };
        let (kx, ky) = ([1, 2, 0][kz], [2, 0, 1][kz]);
        let negative = uniform(_mm256_cmp_ps::<_CMP_LT_OQ>(d[kz], _mm256_setzero_ps()))?;
        let swap = (kx ^ ky) * negative as usize;
        let (kx, ky) = (kx ^ swap, ky ^ swap);
        let o = [row(&|r| r.o.x), row(&|r| r.o.y), row(&|r| r.o.z)];
        Some(Rays8 {
            o: [o[kx], o[ky], o[kz]],
            s: [_mm256_div_ps(d[kx], d[kz]), _mm256_div_ps(d[ky], d[kz]), _mm256_div_ps(_mm256_set1_ps(1.0), d[kz])],
            k: [kx, ky, kz],
        })
    }
}

impl Tri4 {
    /// [`Tri4::closest`] for the rays of the `lanes` mask at once, one triangle at a time with
    /// the rays in AVX lanes: each lane does the 4-wide test's arithmetic in the same order and
    /// picks the same triangle (nearest, ties to the lower lane, against the block's incoming
    /// `t_max`). Lanes that hit lower their `t_max` and take their hit into `best`. Returns the
    /// lanes that hit and the lanes not decided: where an edge function is exactly zero, which
    /// the caller must test with [`Tri4::closest`] (as each ray alone would be), from their
    /// unchanged `t_max` and `best`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    pub unsafe fn closest8(
        &self,
        r: &Rays8,
        lanes: u8,
        t_max: &mut [f32; 8],
        best: &mut [Option<(u32, TriHit)>; 8],
    ) -> (u8, u8) {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = r.k;
        let zero = _mm256_setzero_ps();
        let sign_bit = _mm256_set1_ps(-0.0);
        // SAFETY: an unaligned load of eight floats.
        let tmax = unsafe { _mm256_loadu_ps(t_max.as_ptr()) };
        let (mut bt, mut binv, mut bv, mut bw, mut bj) =
            (_mm256_set1_ps(f32::INFINITY), zero, zero, zero, _mm256_setzero_si256());
        let (mut undecided, mut found) = (0u32, 0u32);
        for j in 0..4 {
            if self.id[j] == Tri4::NONE {
                continue;
            }
            let project = |p: &[[f32; 4]; 3]| {
                let x = _mm256_sub_ps(_mm256_set1_ps(p[kx][j]), r.o[0]);
                let y = _mm256_sub_ps(_mm256_set1_ps(p[ky][j]), r.o[1]);
                let z = _mm256_sub_ps(_mm256_set1_ps(p[kz][j]), r.o[2]);
                (
                    _mm256_sub_ps(x, _mm256_mul_ps(r.s[0], z)),
                    _mm256_sub_ps(y, _mm256_mul_ps(r.s[1], z)),
                    _mm256_mul_ps(r.s[2], z),
                )
            };
            let (ax, ay, az) = project(&self.v[0]);
            let (bx, by, bz) = project(&self.v[1]);
            let (cx, cy, cz) = project(&self.v[2]);
            let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
            let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
            let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
            let any_zero = _mm256_or_ps(
                _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)),
                _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
            );
            undecided |= _mm256_movemask_ps(any_zero) as u32;
            let neg = _mm256_or_ps(
                _mm256_or_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(u, zero), _mm256_cmp_ps::<_CMP_LT_OQ>(v, zero)),
                _mm256_cmp_ps::<_CMP_LT_OQ>(w, zero),
            );
            let pos = _mm256_or_ps(
                _mm256_or_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(u, zero), _mm256_cmp_ps::<_CMP_GT_OQ>(v, zero)),
                _mm256_cmp_ps::<_CMP_GT_OQ>(w, zero),
            );
            let mut ok = _mm256_andnot_ps(_mm256_and_ps(neg, pos), _mm256_cmp_ps::<_CMP_ORD_Q>(u, u));
            if _mm256_movemask_ps(ok) as u32 & lanes as u32 == 0 {
                continue;
            }
            let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
            let sign = _mm256_and_ps(det, sign_bit);
            let abs_det = _mm256_andnot_ps(sign_bit, det);
            ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_NEQ_UQ>(det, zero));
            ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LT_OQ>(abs_det, _mm256_set1_ps(f32::INFINITY)));
            let ts = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(v, bz)), _mm256_mul_ps(w, cz));
            let ts_abs = _mm256_xor_ps(ts, sign);
            ok = _mm256_andnot_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(ts_abs, zero), ok);
            ok = _mm256_andnot_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(ts_abs, _mm256_mul_ps(tmax, abs_det)), ok);
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
            let t = _mm256_mul_ps(ts, inv);
            ok = _mm256_and_ps(
                ok,
                _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(t, zero), _mm256_cmp_ps::<_CMP_LT_OQ>(t, tmax)),
            );
            // Nearest so far; a tie keeps the lower triangle, as the 4-wide test's choice does.
            let take = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LT_OQ>(t, bt));
            found |= _mm256_movemask_ps(take) as u32;
            bt = _mm256_blendv_ps(bt, t, take);
            binv = _mm256_blendv_ps(binv, inv, take);
            bv = _mm256_blendv_ps(bv, v, take);
            bw = _mm256_blendv_ps(bw, w, take);
            bj = _mm256_blendv_epi8(bj, _mm256_set1_epi32(j as i32), _mm256_castps_si256(take));
        }
        let (undecided, found) = (undecided as u8 & lanes, found as u8 & lanes & !(undecided as u8));
        if found != 0 {
            let mut out = [[0.0f32; 8]; 4];
            let mut js = [0i32; 8];
            // SAFETY: unaligned stores into local arrays of eight elements.
            unsafe {
                _mm256_storeu_ps(out[0].as_mut_ptr(), bt);
                _mm256_storeu_ps(out[1].as_mut_ptr(), binv);
                _mm256_storeu_ps(out[2].as_mut_ptr(), bv);
                _mm256_storeu_ps(out[3].as_mut_ptr(), bw);
                _mm256_storeu_si256(js.as_mut_ptr().cast(), bj);
            }
            for lane in crate::accel::lanes(found.into()) {
                let inv = out[1][lane];
                t_max[lane] = out[0][lane];
                best[lane] = Some((
                    self.id[js[lane] as usize],
                    TriHit { t: out[0][lane], b1: out[2][lane] * inv, b2: out[3][lane] * inv },
                ));
            }
        }
        (found, undecided)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    fn random_point(rng: &mut Pcg32, scale: f32) -> Vec3 {
        Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5) * scale
    }

    /// Ray 881,244 of Embree's primary rays on the displaced icosphere at subdivision 8
    /// (`bench/vs_embree.sh`, mesh `ico8`), with the two faces of a fold it meets: it passes
    /// within 10⁻¹⁰ of the edge they share and, in exact arithmetic (`bench/exact_hit.py`),
    /// crosses both, the nearer at t = 4.221347000670272 and the other at 4.221356588824753.
    /// Embree 3's test misses both faces. A watertight test cannot: the shared edge's function
    /// has opposite signs on the two faces however it rounds, so one of them is hit (here the
    /// nearer, as exact arithmetic has it), and the block agrees with the scalar test.
    #[test]
    fn a_ray_grazing_a_fold_hits_it() {
        let o = Vec3::new(1.1225147, 1.5668054, 3.7778432);
        let d = Vec3::new(-0.1742432, -0.5706661, -0.8024834);
        let [a, b, c, e] = [
            Vec3::new(0.39181644, -0.8411553, 0.38955078),
            Vec3::new(0.38694927, -0.84215903, 0.39031667),
            Vec3::new(0.38927653, -0.84375507, 0.38682297),
            Vec3::new(0.38436863, -0.844665, 0.3875487),
        ];
        let (near, far) = ([a, b, c], [c, b, e]);
        let ray = WatertightRay::new(o, d);
        let scalar = [near, far].map(|[p, q, r]| intersect_triangle(&ray, p, q, r, f32::INFINITY));
        let exact = [4.221347000670272f64, 4.221356588824753];
        assert!(scalar.iter().any(Option::is_some), "the ray slipped between the fold's faces");
        for (h, t) in scalar.iter().zip(exact) {
            if let Some(h) = h {
                assert!((h.t as f64 - t).abs() < 2e-5, "t = {} where exact arithmetic gives {t}", h.t);
            }
        }
        assert!(scalar[0].is_some(), "the nearer face, which exact arithmetic says the ray crosses, was missed");
        let block = Tri4::pack([(0, near), (1, far)]);
        let (id, h) = block
            .closest(&Ray4::of(&crate::geometry::Ray::new(o, d)), f32::INFINITY)
            .expect("the block test missed the fold");
        assert_eq!(id, 0);
        assert_eq!(h.t.to_bits(), scalar[0].unwrap().t.to_bits());
    }

    /// The block gives exactly what the scalar test gives lane by lane, on random triangles
    /// (some degenerate, some sharing edges with their neighbours) and random rays, including
    /// rays aimed exactly at shared vertices.
    #[test]
    fn block_matches_scalar_test_bit_for_bit() {
        let mut rng = Pcg32::new(7, 1);
        let mut hits = 0;
        for case in 0..20_000 {
            let n = 1 + case % 4;
            let shared = random_point(&mut rng, 2.0);
            let tris: Vec<(u32, [Vec3; 3])> = (0..n)
                .map(|i| {
                    let mut p = [shared, random_point(&mut rng, 2.0), random_point(&mut rng, 2.0)];
                    if case % 17 == 0 {
                        p[2] = p[1]; // degenerate
                    }
                    (i as u32 * 3 + 1, p)
                })
                .collect();
            let block = Tri4::pack(tris.iter().copied());
            assert_eq!(block.len(), n);
            let o = random_point(&mut rng, 6.0);
            let target = if case % 5 == 0 { shared } else { random_point(&mut rng, 1.0) };
            let d = (target - o).normalize();
            let t_max = if case % 3 == 0 { rng.next_f32() * 4.0 } else { f32::INFINITY };
            let r = Ray4::of(&crate::geometry::Ray::new(o, d));
            let mut want = None;
            let mut tm = t_max;
            for (id, [a, b, c]) in &tris {
                if let Some(h) = intersect_triangle(&r.ray, *a, *b, *c, tm) {
                    tm = h.t;
                    want = Some((*id, h));
                }
            }
            let got = block.closest(&r, t_max);
            assert_eq!(
                got.map(|(i, h)| (i, h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits())),
                want.map(|(i, h)| (i, h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits())),
                "case {case}"
            );
            assert_eq!(block.any(&r, t_max), want.is_some(), "case {case}");
            hits += want.is_some() as usize;
        }
        assert!(hits > 2_000, "too few hits to mean anything: {hits}");
    }

    /// The eight-ray test, its rays made by [`Rays8::from_rays`], gives each ray exactly what
    /// the block's own test gives it with the ray's own set-up (the undecided rays finished by
    /// that test, as the caller does): random blocks, packets of rays from one point towards
    /// the block (some aimed exactly at a shared vertex, which makes edge functions zero),
    /// random lanes and bounds, the scene turned so that every axis dominates with either
    /// sign.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_ray_test_matches_the_block_test_bit_for_bit() {
        if !crate::accel::has_avx2_fma_popcnt() {
            eprintln!("no AVX2: the eight-ray test is not used on this CPU");
            return;
        }
        let mut rng = Pcg32::new(9, 3);
        let (mut hits, mut undecided, mut packets) = (0, 0, 0);
        for case in 0..5_000 {
            let n = 1 + case % 4;
            // Axes rotated by case % 3, and mirrored every other case.
            let turn = |p: Vec3| {
                let p = match case % 3 {
                    0 => p,
                    1 => Vec3::new(p.z, p.x, p.y),
                    _ => Vec3::new(p.y, p.z, p.x),
                };
                if case % 2 == 1 {
                    -p
                } else {
                    p
                }
            };
            let shared = turn(random_point(&mut rng, 2.0));
            let tris: Vec<(u32, [Vec3; 3])> = (0..n)
                .map(|i| {
                    let (b, c) = (turn(random_point(&mut rng, 2.0)), turn(random_point(&mut rng, 2.0)));
                    (i as u32 * 5 + 2, [shared, b, c])
                })
                .collect();
            let block = Tri4::pack(tris.iter().copied());
            let o = turn(random_point(&mut rng, 6.0) + Vec3::new(0.0, 0.0, 8.0));
            let plain: [crate::geometry::Ray; 8] = std::array::from_fn(|i| {
                let target = if (case + i) % 7 == 0 { shared } else { turn(random_point(&mut rng, 1.5)) };
                crate::geometry::Ray::new(o, (target - o).normalize())
            });
            let rays: [Ray4; 8] = plain.map(|r| Ray4::of(&r));
            let lanes = (rng.next_u32() & 0xff) as u8 | 1;
            let t0: [f32; 8] =
                std::array::from_fn(|_| if rng.next_f32() < 0.3 { rng.next_f32() * 12.0 } else { f32::INFINITY });
            // SAFETY: AVX2 was detected above.
            let Some(r8) = (unsafe { Rays8::from_rays(&plain, lanes) }) else {
                // Only where the lanes' axes differ.
                let k = rays[lanes.trailing_zeros() as usize].ray.axes();
                assert!((0..8).any(|l| lanes & (1 << l) != 0 && rays[l].ray.axes() != k), "case {case}");
                continue;
            };
            packets += 1;
            let (mut tm, mut best) = (t0, [None; 8]);
            // SAFETY: AVX2 was detected above.
            let (found, und) = unsafe { block.closest8(&r8, lanes, &mut tm, &mut best) };
            assert_eq!(found & und, 0);
            undecided += und.count_ones();
            for lane in (0..8).filter(|l| und & (1 << l) != 0) {
                if let Some(f) = block.closest(&rays[lane], tm[lane]) {
                    (tm[lane], best[lane]) = (f.1.t, Some(f));
                }
            }
            let bits = |h: Option<(u32, TriHit)>| h.map(|(i, h)| (i, h.t.to_bits(), h.b1.to_bits(), h.b2.to_bits()));
            for lane in 0..8 {
                let want = if lanes & (1 << lane) != 0 { block.closest(&rays[lane], t0[lane]) } else { None };
                assert_eq!(bits(best[lane]), bits(want), "case {case}, lane {lane}");
                assert_eq!(tm[lane].to_bits(), want.map_or(t0[lane], |w| w.1.t).to_bits(), "case {case}, lane {lane}");
                hits += usize::from(want.is_some());
            }
        }
        assert!(
            packets > 2_000 && hits > 2_000 && undecided > 20,
            "{packets} packets, {hits} hits, {undecided} undecided"
        );
    }

    /// [`Rays8::from_rays`] makes the axes, origin and shear [`Ray4::of`] makes, bit for bit,
    /// on the directions where the choice is delicate: ties between components, signed zeros,
    /// infinities and NaN; and it declines lanes that permute the axes differently.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_ray_setup_is_the_single_ray_setup() {
        use std::arch::x86_64::{_mm256_storeu_ps, _mm_storeu_ps};
        if !crate::accel::has_avx2_fma_popcnt() {
            eprintln!("no AVX2: the eight-ray set-up is not used on this CPU");
            return;
        }
        let values = [0.0f32, -0.0, 1.0, -1.0, 0.5, -2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN];
        let o = Vec3::new(0.3, -0.2, 0.7);
        let lanes = |v: std::arch::x86_64::__m256| {
            let mut out = [0.0f32; 8];
            // SAFETY: an unaligned store into a local array of eight floats.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
            out.map(f32::to_bits)
        };
        let four = |v: std::arch::x86_64::__m128| {
            let mut out = [0.0f32; 4];
            // SAFETY: SSE is part of the x86_64 baseline; an unaligned store into a local array.
            unsafe { _mm_storeu_ps(out.as_mut_ptr(), v) };
            out.map(f32::to_bits)
        };
        for x in values {
            for y in values {
                for z in values {
                    let d = Vec3::new(x, y, z);
                    let want = Ray4::of(&crate::geometry::Ray::new(o, d));
                    // SAFETY: AVX2 was detected above.
                    let got = unsafe { Rays8::from_rays(&[crate::geometry::Ray::new(o, d); 8], 0xff) }
                        .expect("eight copies of one ray share their axes");
                    assert_eq!(got.k, want.ray.axes(), "direction {d}");
                    for a in 0..3 {
                        let (o8, s8) = (lanes(got.o[a]), lanes(got.s[a]));
                        assert_eq!(four(want.lanes.o[a]), [o8[0]; 4], "direction {d}, origin {a}");
                        assert_eq!(o8, [o8[0]; 8], "direction {d}, origin {a}");
                        assert_eq!(four(want.lanes.s[a]), [s8[0]; 4], "direction {d}, shear {a}");
                        assert_eq!(s8, [s8[0]; 8], "direction {d}, shear {a}");
                    }
                }
            }
        }
        let mut rays = [crate::geometry::Ray::new(o, Vec3::new(0.1, 0.2, 1.0)); 8];
        rays[5].d = Vec3::new(1.0, 0.2, 0.1);
        // SAFETY: AVX2 was detected above.
        assert!(unsafe { Rays8::from_rays(&rays, 0xff) }.is_none(), "lane 5 has another dominant axis");
        // SAFETY: AVX2 was detected above.
        assert!(unsafe { Rays8::from_rays(&rays, 0xdf) }.is_some(), "lane 5 is not active");
        rays[5].d = Vec3::new(0.1, 0.2, -1.0);
        // SAFETY: AVX2 was detected above.
        assert!(unsafe { Rays8::from_rays(&rays, 0xff) }.is_none(), "lane 5 swaps x and y");
    }

    #[test]
    fn unused_lanes_never_hit() {
        let block = Tri4::pack([]);
        assert!(block.is_empty());
        let r = Ray4::of(&crate::geometry::Ray::new(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z));
        assert!(block.closest(&r, f32::INFINITY).is_none());
        assert!(!block.any(&r, f32::INFINITY));
    }
}
