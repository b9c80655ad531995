//! Pixel reconstruction filters, applied by filter importance sampling (pbrt-v4 §8.8): each
//! camera sample is placed at an offset from the pixel centre distributed like the filter, and
//! the pixel value is the plain average of its samples. For these positive filters this equals
//! the weighted average of the classic splatting approach in expectation, while each pixel stays
//! independent of its neighbours (so tiles need no shared borders and threads never contend).

use glam::Vec2;

/// A separable reconstruction filter.
#[derive(Clone, Debug, PartialEq)]
pub enum Filter {
    /// Constant over `[-radius, radius]²`; radius 0.5 is one pixel.
    Box { radius: f32 },
    /// Linear falloff to zero at `radius`.
    Tent { radius: f32 },
    /// Gaussian of standard deviation `sigma` truncated at `radius`: its value there, `floor`,
    /// is taken off, so that the weight falls to zero at the radius.
    Gaussian { radius: f32, sigma: f32, floor: f32, cdf: Vec<f32> },
}

impl Default for Filter {
    fn default() -> Self {
        Filter::gaussian(1.5, 0.5)
    }
}

impl Filter {
    pub fn gaussian(radius: f32, sigma: f32) -> Filter {
        const N: usize = 256;
        let floor = gaussian(radius, sigma);
        let cdf = crate::sampling::build_cdf(
            (0..N).map(|i| gaussian(-radius + (i as f32 + 0.5) * 2.0 * radius / N as f32, sigma) - floor),
        );
        Filter::Gaussian { radius, sigma, floor, cdf }
    }

    pub fn radius(&self) -> f32 {
        match self {
            Filter::Box { radius } | Filter::Tent { radius } | Filter::Gaussian { radius, .. } => *radius,
        }
    }

    /// The filter's weight at `offset` from a pixel centre (separable, not normalised).
    pub fn eval(&self, offset: Vec2) -> f32 {
        self.eval_1d(offset.x) * self.eval_1d(offset.y)
    }

    /// The weight of one axis: [`Filter::eval`] is the product of two.
    #[inline]
    pub fn eval_1d(&self, x: f32) -> f32 {
        match self {
            Filter::Box { radius } => box_weight(x, *radius),
            Filter::Tent { radius } => tent_weight(x, *radius),
            Filter::Gaussian { radius, sigma, floor, .. } => gaussian_weight(x, *radius, *sigma, *floor),
        }
    }

    /// [`Filter::eval_1d`] of eight offsets at once, the same bits: the filter is matched once
    /// and its weights worked out in vector lanes (a sample splatted through Mitsuba's default
    /// Gaussian weighs four columns and four rows, each an exponential).
    #[inline]
    pub fn eval_1d_8(&self, x: &[f32; 8]) -> [f32; 8] {
        let mut w = [0.0; 8];
        match self {
            Filter::Box { radius } => (0..8).for_each(|j| w[j] = box_weight(x[j], *radius)),
            Filter::Tent { radius } => (0..8).for_each(|j| w[j] = tent_weight(x[j], *radius)),
            Filter::Gaussian { radius, sigma, floor, .. } => {
                (0..8).for_each(|j| w[j] = gaussian_weight(x[j], *radius, *sigma, *floor))
            }
        }
        w
    }

    /// Offset from the pixel centre for uniform `u ∈ [0,1)²`.
    pub fn sample(&self, u: Vec2) -> Vec2 {
        Vec2::new(self.sample_1d(u.x), self.sample_1d(u.y))
    }

    fn sample_1d(&self, u: f32) -> f32 {
        match self {
            Filter::Box { radius } => (2.0 * u - 1.0) * radius,
            Filter::Tent { radius } => {
                if u < 0.5 {
                    radius * ((2.0 * u).sqrt() - 1.0)
                } else {
                    radius * (1.0 - (2.0 - 2.0 * u).sqrt())
                }
            }
            Filter::Gaussian { radius, cdf, .. } => {
                let (i, frac) = crate::sampling::sample_cdf(cdf, u);
                -radius + (i as f32 + frac) * 2.0 * radius / cdf.len() as f32
            }
        }
    }
}

#[inline(always)]
fn box_weight(x: f32, radius: f32) -> f32 {
    (x.abs() <= radius) as u8 as f32
}

#[inline(always)]
fn tent_weight(x: f32, radius: f32) -> f32 {
    (1.0 - x.abs() / radius).max(0.0)
}

/// The truncated Gaussian's weight: zero from the radius out, the floor taken off inside.
#[inline(always)]
fn gaussian_weight(x: f32, radius: f32, sigma: f32, floor: f32) -> f32 {
    let x = x.abs();
    let g = (gaussian(x, sigma) - floor).max(0.0);
    if x >= radius {
        0.0
    } else {
        g
    }
}

/// The unnormalised Gaussian of standard deviation `sigma` at `x`. Below e⁻⁸⁷ (beyond 13.2
/// standard deviations, where a weight is nothing) it stays at e⁻⁸⁷, so that it needs no
/// branch.
#[inline(always)]
fn gaussian(x: f32, sigma: f32) -> f32 {
    crate::sampling::exp_in_range((-(x * x) / (2.0 * sigma * sigma)).max(-87.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_stay_within_radius_and_are_centred() {
        for f in [Filter::Box { radius: 0.5 }, Filter::Tent { radius: 1.0 }, Filter::gaussian(1.5, 0.5)] {
            let r = f.radius();
            let n = 1000;
            let mut mean = Vec2::ZERO;
            for i in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, ((i * 7919 % n) as f32 + 0.5) / n as f32);
                let o = f.sample(u);
                assert!(o.x.abs() <= r && o.y.abs() <= r, "{f:?} {o}");
                mean += o / n as f32;
            }
            assert!(mean.length() < 1e-2, "{f:?} mean {mean}");
        }
    }

    #[test]
    fn weights_fall_off_to_zero_at_the_radius() {
        for f in [Filter::Box { radius: 0.5 }, Filter::Tent { radius: 1.0 }, Filter::gaussian(2.0, 0.5)] {
            let r = f.radius();
            assert!(f.eval(Vec2::ZERO) > 0.0);
            assert_eq!(f.eval(Vec2::new(r * 1.01, 0.0)), 0.0);
            assert!(f.eval(Vec2::new(0.3 * r, 0.0)) <= f.eval(Vec2::ZERO));
        }
    }

    /// Eight weights at once are the single weights' bits, for every filter, at random offsets
    /// and at the radius and its neighbours (where the tent's and the Gaussian's weights must be
    /// exactly 0; the box's is 1 there).
    #[test]
    fn eight_weights_are_the_single_weights() {
        let mut rng = crate::sampling::Pcg32::new(3, 4);
        for f in [
            Filter::Box { radius: 0.5 },
            Filter::Tent { radius: 1.0 },
            Filter::gaussian(2.0, 0.5),
            Filter::gaussian(16.5, 1.0),
        ] {
            let r = f.radius();
            let edges = [r, -r, r.next_up(), r.next_down(), 0.0, -0.0, 3.0 * r, f32::NAN];
            for round in 0..2000 {
                let x: [f32; 8] =
                    if round == 0 { edges } else { std::array::from_fn(|_| (rng.next_f32() * 2.0 - 1.0) * 1.2 * r) };
                let w = f.eval_1d_8(&x);
                for j in 0..8 {
                    let one = f.eval_1d(x[j]);
                    assert!(w[j].to_bits() == one.to_bits(), "{f:?} at {}: {} in lanes, {one} alone", x[j], w[j]);
                }
            }
            if !matches!(f, Filter::Box { .. }) {
                assert_eq!(f.eval_1d(r), 0.0, "{f:?}");
            }
        }
    }

    /// The Gaussian's weight is the curve less its value at the radius (so continuous there).
    #[test]
    fn gaussian_weight_is_the_curve_less_its_value_at_the_radius() {
        let (radius, sigma) = (2.0f64, 0.5f64);
        let f = Filter::gaussian(radius as f32, sigma as f32);
        let g = |x: f64| (-x * x / (2.0 * sigma * sigma)).exp();
        for x in [0.0, 0.3, -0.7, 1.2, 1.9, 1.999] {
            let want = g(x) - g(radius);
            assert!((f.eval_1d(x as f32) as f64 - want).abs() < 1e-6, "{x}: {} against {want}", f.eval_1d(x as f32));
        }
    }

    #[test]
    fn gaussian_concentrates_near_centre() {
        let f = Filter::gaussian(1.5, 0.5);
        // About 68 % of a (barely truncated) normal lies within one sigma.
        let inside = (0..1000).filter(|i| f.sample(Vec2::splat((*i as f32 + 0.5) / 1000.0)).x.abs() < 0.5).count();
        assert!((600..760).contains(&inside), "{inside}");
    }
}
