use super::{Accel, AccelParams, AccelStats};
use crate::geometry::{Aabb, Ray};

/// The brute-force list: every non-empty primitive is tested for every ray. It is the oracle
/// the other accelerators are checked against, so it is deliberately free of cleverness (not
/// even a box test before the primitive test).
pub struct Brute {
    prims: Vec<u32>,
}

impl Brute {
    pub fn new(boxes: &[Aabb]) -> Brute {
        Brute { prims: (0..boxes.len() as u32).filter(|&i| !boxes[i as usize].is_empty()).collect() }
    }
}

impl Accel for Brute {
    type Params = AccelParams;

    fn build(boxes: &[Aabb], _params: &AccelParams) -> Self {
        Brute::new(boxes)
    }

    fn closest(&self, _ray: &Ray, t_max: &mut f32, mut test: impl FnMut(u32, f32) -> Option<f32>) -> bool {
        let mut hit = false;
        for &p in &self.prims {
            if let Some(t) = test(p, *t_max) {
                *t_max = t;
                hit = true;
            }
        }
        hit
    }

    fn any(&self, _ray: &Ray, t_max: f32, mut test: impl FnMut(u32, f32) -> bool) -> bool {
        self.prims.iter().any(|&p| test(p, t_max))
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
