//! Uniform grid (Fujimoto et al. 1986; Amanatides & Woo 1987 for the traversal).
//!
//! The scene box is cut into `res.x × res.y × res.z` cells; with `N` primitives the longest
//! axis gets about `λ·N^(1/3)` cells (λ = [`GridParams::lambda`], 3 by default) and the other
//! axes as many as keep the cells close to cubes. Each primitive is listed in every cell its
//! box overlaps (conservative). A ray walks the cells it pierces in order with a 3D-DDA and
//! stops as soon as the closest hit found lies within the current cell.
//!
//! Mailboxing: a primitive listed in several cells would be tested again in each. Every ray
//! carries a small direct-mapped cache of the primitives it has tested (64 entries, indexed
//! by primitive id) and skips those; a collision only means a repeated test, never a wrong
//! answer.

use glam::Vec3;

use super::{Accel, AccelParams, AccelStats, BuildParams, Counter, OrderedWalk};
use crate::geometry::{Aabb, Ray};

/// Grid build settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridParams {
    pub base: AccelParams,
    /// Cells along the longest axis ≈ `lambda · N^(1/3)`.
    pub lambda: f32,
}

impl BuildParams for GridParams {
    fn base(&self) -> &AccelParams {
        &self.base
    }
    fn base_mut(&mut self) -> &mut AccelParams {
        &mut self.base
    }
}

/// Most cells along one axis.
const MAX_RES: u32 = 1024;
/// Most cells in all.
const MAX_CELLS: u64 = 1 << 26;

/// A uniform grid over primitive boxes.
pub struct Grid {
    bounds: Aabb,
    res: [u32; 3],
    cell_size: Vec3,
    inv_cell: Vec3,
    /// `cell_start[c]..cell_start[c + 1]` indexes `cell_prims` for cell `c`.
    cell_start: Vec<u32>,
    cell_prims: Vec<u32>,
    stats: AccelStats,
}

impl Grid {
    #[inline]
    fn cell_index(&self, c: [i32; 3]) -> usize {
        (c[0] as usize) + self.res[0] as usize * ((c[1] as usize) + self.res[1] as usize * (c[2] as usize))
    }

    fn cell_of(&self, p: Vec3) -> [i32; 3] {
        let q = (p - self.bounds.min) * self.inv_cell;
        [0, 1, 2].map(|a| (q[a].floor() as i64).clamp(0, self.res[a] as i64 - 1) as i32)
    }

    /// Indices of the cells that the box `b` overlaps.
    fn cells_of(&self, b: &Aabb) -> impl Iterator<Item = usize> + '_ {
        let (lo, hi) = (self.cell_of(b.min), self.cell_of(b.max));
        (lo[2]..=hi[2]).flat_map(move |z| {
            (lo[1]..=hi[1]).flat_map(move |y| (lo[0]..=hi[0]).map(move |x| self.cell_index([x, y, z])))
        })
    }

    fn prims_in(&self, cell: usize) -> &[u32] {
        &self.cell_prims[self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize]
    }
}

impl OrderedWalk for Grid {
    /// Walks the cells the ray pierces within `[0, t_max]`, nearest first. `visit(prims, t_exit)`
    /// returns false to stop.
    #[inline]
    fn walk(&self, ray: &Ray, t_max: f32, counter: &impl Counter, mut visit: impl FnMut(&[u32], f32) -> bool) {
        if self.cell_prims.is_empty() {
            return;
        }
        let inv = ray.d.recip();
        let Some(t_enter) = self.bounds.slab(ray.o, inv, 0.0, t_max) else { return };
        let mut cell = self.cell_of(ray.o + ray.d * t_enter);
        let mut step = [0i32; 3];
        let mut next = [f32::INFINITY; 3];
        let mut delta = [f32::INFINITY; 3];
        let mut stop = [0i32; 3];
        for a in 0..3 {
            let d = ray.d[a];
            if d > 0.0 {
                step[a] = 1;
                stop[a] = self.res[a] as i32;
                let plane = self.bounds.min[a] + (cell[a] + 1) as f32 * self.cell_size[a];
                next[a] = (plane - ray.o[a]) * inv[a];
                delta[a] = self.cell_size[a] * inv[a];
            } else if d < 0.0 {
                step[a] = -1;
                stop[a] = -1;
                let plane = self.bounds.min[a] + cell[a] as f32 * self.cell_size[a];
                next[a] = (plane - ray.o[a]) * inv[a];
                delta[a] = -self.cell_size[a] * inv[a];
            } else {
                stop[a] = i32::MIN;
            }
        }
        loop {
            let a = if next[0] < next[1] {
                if next[0] < next[2] {
                    0
                } else {
                    2
                }
            } else if next[1] < next[2] {
                1
            } else {
                2
            };
            let t_exit = next[a];
            counter.node();
            if !visit(self.prims_in(self.cell_index(cell)), t_exit) {
                return;
            }
            if t_exit > t_max || step[a] == 0 {
                return;
            }
            cell[a] += step[a];
            if cell[a] == stop[a] {
                return;
            }
            next[a] += delta[a];
        }
    }
}

impl Accel for Grid {
    type Params = GridParams;

    fn build(boxes: &[Aabb], params: &GridParams) -> Self {
        let prims: Vec<u32> = (0..boxes.len() as u32).filter(|&i| !boxes[i as usize].is_empty()).collect();
        let mut bounds = prims.iter().fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]));
        let n = prims.len().max(1) as f32;
        let mut res = [1u32; 3];
        if !prims.is_empty() {
            // Pad flat or tiny extents so cells have volume, and the box a little so that
            // points on its faces fall inside.
            let e = bounds.extent();
            let pad = e.max_element().max(1e-6) * 1e-4;
            bounds = Aabb::new(bounds.min - Vec3::splat(pad), bounds.max + Vec3::splat(pad));
            let e = bounds.extent();
            let cells_long = (params.lambda.max(0.01) * n.cbrt()).max(1.0);
            let per_unit = cells_long / e.max_element();
            res = [0, 1, 2].map(|a| ((e[a] * per_unit).round() as u32).clamp(1, MAX_RES));
            while res.iter().map(|&r| r as u64).product::<u64>() > MAX_CELLS {
                res = res.map(|r| (r / 2).max(1));
            }
        }
        let cell_size = bounds.extent() / Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let inv_cell = Vec3::ONE / cell_size;
        let ncells = res.iter().map(|&r| r as usize).product::<usize>();
        let mut grid = Grid {
            bounds,
            res,
            cell_size,
            inv_cell,
            cell_start: vec![0; ncells + 1],
            cell_prims: Vec::new(),
            stats: AccelStats::default(),
        };
        // Two passes over the primitives' cell ranges: count, then fill (CSR layout).
        let mut counts = vec![0u32; ncells + 1];
        for &p in &prims {
            for c in grid.cells_of(&boxes[p as usize]) {
                counts[c + 1] += 1;
            }
        }
        for c in 0..ncells {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut cell_prims = vec![0; counts[ncells] as usize];
        for &p in &prims {
            for c in grid.cells_of(&boxes[p as usize]) {
                cell_prims[fill[c] as usize] = p;
                fill[c] += 1;
            }
        }
        grid.cell_start = counts;
        grid.cell_prims = cell_prims;
        let nonempty = (0..ncells).filter(|&c| grid.cell_start[c + 1] > grid.cell_start[c]).count();
        grid.stats = AccelStats {
            nodes: ncells,
            leaves: nonempty,
            max_depth: 0,
            prim_refs: grid.cell_prims.len(),
            bytes: grid.cell_start.len() * 4 + grid.cell_prims.len() * 4,
            // Expected primitive tests of a ray through the whole grid, as a rough analogue.
            sah_cost: grid.cell_prims.len() as f32 / ncells.max(1) as f32 * (res[0] + res[1] + res[2]) as f32,
        };
        grid
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
        // Depth 0: the grid's box; deeper: its non-empty cells.
        if self.cell_prims.is_empty() {
            return Vec::new();
        }
        if depth == 0 {
            return vec![self.bounds];
        }
        let mut out = Vec::new();
        for z in 0..self.res[2] as i32 {
            for y in 0..self.res[1] as i32 {
                for x in 0..self.res[0] as i32 {
                    let c = self.cell_index([x, y, z]);
                    if self.cell_start[c + 1] > self.cell_start[c] {
                        let min = self.bounds.min + self.cell_size * Vec3::new(x as f32, y as f32, z as f32);
                        out.push(Aabb { min, max: min + self.cell_size });
                    }
                }
            }
        }
        out
    }

    fn stats(&self) -> AccelStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> GridParams {
        GridParams { base: AccelParams::default(), lambda: 3.0 }
    }

    #[test]
    fn resolution_follows_lambda_cube_root_n() {
        let boxes: Vec<Aabb> = (0..1000)
            .map(|i| {
                let p = Vec3::new((i % 10) as f32, ((i / 10) % 10) as f32, (i / 100) as f32 * 0.5);
                Aabb::new(p, p + Vec3::splat(0.1))
            })
            .collect();
        let g = Grid::build(&boxes, &params());
        // 3 · 1000^(1/3) = 30 cells on the long axes, about half on the short one.
        assert_eq!(g.res[0], 30);
        assert_eq!(g.res[1], 30);
        assert!((14..=16).contains(&g.res[2]), "{:?}", g.res);
    }

    #[test]
    fn mailboxing_tests_a_spanning_primitive_once() {
        // One long primitive across the whole grid plus small ones that make many cells.
        let mut boxes = vec![Aabb::new(Vec3::new(0.0, 0.45, 0.45), Vec3::new(10.0, 0.55, 0.55))];
        for i in 0..200 {
            let p = Vec3::new(i as f32 * 0.05, (i % 7) as f32 * 0.15, (i % 5) as f32 * 0.2);
            boxes.push(Aabb::new(p, p + Vec3::splat(0.01)));
        }
        let g = Grid::build(&boxes, &params());
        assert!(g.res[0] > 10);
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        let mut tests_of_long = 0;
        g.any(&ray, f32::INFINITY, |p, _| {
            if p == 0 {
                tests_of_long += 1;
            }
            false
        });
        assert_eq!(tests_of_long, 1);
        let mut t = f32::INFINITY;
        let mut n = 0;
        g.closest(&ray, &mut t, |p, _| {
            n += (p == 0) as i32;
            None
        });
        assert_eq!(n, 1);
    }
}
