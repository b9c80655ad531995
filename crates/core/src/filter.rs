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
    pub fn eval_1d(&self, x: f32) -> f32 {
        let x = x.abs();
        match self {
            Filter::Box { radius } => (x <= *radius) as u8 as f32,
            Filter::Tent { radius } => (1.0 - x / radius).max(0.0),
            Filter::Gaussian { radius, sigma, floor, .. } => {
                // The floor is made once (a sample splatted through Mitsuba's default Gaussian
                // weighs about eight columns and rows, each an `exp`).
                if x >= *radius {
                    0.0
                } else {
                    (gaussian(x, *sigma) - floor).max(0.0)
                }
            }
        }
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

/// The unnormalised Gaussian of standard deviation `sigma` at `x`.
#[inline]
fn gaussian(x: f32, sigma: f32) -> f32 {
    crate::sampling::exp(-(x * x) / (2.0 * sigma * sigma))
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
