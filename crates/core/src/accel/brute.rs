use super::{Accel, AccelParams, AccelStats, Counter};
use crate::geometry::{Aabb, Ray};

/// The brute-force list: every non-empty primitive is tested for every ray. It is the oracle
/// the other accelerators are checked against, so it is deliberately free of cleverness (not
/// even a box test before the primitive test).
pub struct Brute {
    prims: Vec<u32>,
    bounds: Aabb,
}

impl Brute {
    pub fn new(boxes: &[Aabb]) -> Brute {
        let prims: Vec<u32> = (0..boxes.len() as u32).filter(|&i| !boxes[i as usize].is_empty()).collect();
        let bounds = prims.iter().fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]));
        Brute { prims, bounds }
    }
}

impl Accel for Brute {
    type Params = AccelParams;

    fn build(boxes: &[Aabb], _params: &AccelParams) -> Self {
        Brute::new(boxes)
    }

    fn closest_counted(
        &self,
        _ray: &Ray,
        t_max: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<f32>,
        counter: &impl Counter,
    ) -> bool {
        counter.node();
        let mut hit = false;
        for &p in &self.prims {
            if let Some(t) = test(p, *t_max) {
                *t_max = t;
                hit = true;
            }
        }
        hit
    }

    fn any_counted(
        &self,
        _ray: &Ray,
        t_max: f32,
        mut test: impl FnMut(u32, f32) -> bool,
        counter: &impl Counter,
    ) -> bool {
        counter.node();
        self.prims.iter().any(|&p| test(p, t_max))
    }

    fn boxes_at_depth(&self, depth: usize) -> Vec<Aabb> {
        if depth == 0 && !self.bounds.is_empty() {
            vec![self.bounds]
        } else {
            Vec::new()
        }
    }

    fn stats(&self) -> AccelStats {
        AccelStats {
            nodes: 1,
            leaves: 1,
            max_depth: 0,
            prim_refs: self.prims.len(),
            bytes: self.prims.len() * 4,
            sah_cost: self.prims.len() as f32,
        }
    }
}
