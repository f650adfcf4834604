//! Searching the body's shape space: a phenotype's stature from the few vertices that can be
//! the highest or the lowest, the `height` that gives a stature, and each shape coefficient's
//! spread over adults (the fit's prior, [`super::fit`]).

use super::asset::{BodyAsset, BodyError, Phenotype};

impl BodyAsset {
    /// The spread (standard deviation) of each shape coefficient over adult phenotypes: every
    /// parameter uniform in [0, 1], sampled on 512 points of a fixed low-discrepancy sequence
    /// (additive recurrences of the six-dimensional golden ratio), so the same every call.
    pub fn coefficient_spread(&self) -> Vec<f64> {
        const N: usize = 512;
        // the plastic-number generalisation of the golden ratio in six dimensions (Roberts)
        let g = (0..30).fold(1.5f64, |x, _| (1.0 + x).powf(1.0 / 7.0));
        let alpha: Vec<f64> = (1..=6).map(|k| 1.0 / g.powi(k)).collect();
        let mut sum = vec![0.0; self.rank];
        let mut sq = vec![0.0; self.rank];
        for i in 0..N {
            let u: Vec<f64> = alpha.iter().map(|a| (0.5 + a * (i + 1) as f64).fract()).collect();
            let p = Phenotype { gender: u[0], age: u[1], muscle: u[2], weight: u[3], height: u[4], proportions: u[5] };
            for (k, c) in self.coeffs(&p).into_iter().enumerate() {
                sum[k] += c;
                sq[k] += c * c;
            }
        }
        sum.iter().zip(&sq).map(|(s, q)| (q / N as f64 - (s / N as f64).powi(2)).max(0.0).sqrt()).collect()
    }

    /// The 100 highest and 100 lowest vertices of the reference shape and of each shape with one
    /// parameter at 0 or 1: where the top of the head and the soles are for any adult.
    pub(super) fn extreme_candidates(&self) -> Vec<usize> {
        let mut shapes = vec![self.rest.clone()];
        for name in ["gender", "age", "muscle", "weight", "height", "proportions"] {
            for v in [0.0, 1.0] {
                let mut p = Phenotype::default();
                p.set(name, v);
                shapes.push(self.shape_from(&p));
            }
        }
        let mut out = Vec::new();
        for s in &shapes {
            let mut order: Vec<usize> = (0..s.vertices.len()).collect();
            order.sort_by(|&a, &b| s.vertices[a].z.total_cmp(&s.vertices[b].z).then(a.cmp(&b)));
            out.extend(&order[..100]);
            out.extend(&order[order.len() - 100..]);
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The stature (m) of phenotype `p`'s shape, from the z of [`Self::extreme_candidates`] only.
    pub fn stature_of(&self, p: &Phenotype) -> f64 {
        let c = self.coeffs(p);
        let n = self.mean.len();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &v in &self.extremes {
            let i = 3 * v + 2;
            let z =
                self.mean[i] + c.iter().enumerate().map(|(k, ck)| ck * self.components[k * n + i] as f64).sum::<f64>();
            (lo, hi) = (lo.min(z), hi.max(z));
        }
        hi - lo
    }

    /// The phenotype `p` with `height` set so that the shape's stature is `stature` (m), found
    /// by bisection (stature grows with `height`); an error if `height` in [0, 1] cannot reach it.
    pub fn height_for_stature(&self, p: &Phenotype, stature: f64) -> Result<Phenotype, BodyError> {
        let at = |h: f64| self.stature_of(&Phenotype { height: h, ..*p });
        let (min, max) = (at(0.0), at(1.0));
        if !(min..=max).contains(&stature) {
            return Err(BodyError::StatureOutOfRange { target: stature, min, max });
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if at(mid) < stature {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(Phenotype { height: 0.5 * (lo + hi), ..*p })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asset() -> BodyAsset {
        BodyAsset::shipped().unwrap()
    }

    #[test]
    fn the_stature_from_the_extreme_vertices_is_the_shapes() {
        let a = asset();
        for (i, h) in [0.0, 0.3, 0.7, 1.0].into_iter().enumerate() {
            let p =
                Phenotype { height: h, weight: 0.25 * i as f64, gender: 1.0 - 0.3 * i as f64, ..Default::default() };
            assert!((a.stature_of(&p) - a.shape_from(&p).stature()).abs() < 1e-9, "{h}");
        }
    }

    #[test]
    fn height_for_stature_reaches_the_target() {
        let a = asset();
        let p = Phenotype { gender: 1.0, ..Default::default() };
        let q = a.height_for_stature(&p, 1.65).unwrap();
        assert!((a.shape_from(&q).stature() - 1.65).abs() < 1e-6, "{q:?}");
        assert_eq!(q.gender, 1.0);
        assert!(matches!(a.height_for_stature(&p, 3.0), Err(BodyError::StatureOutOfRange { .. })));
    }
}
