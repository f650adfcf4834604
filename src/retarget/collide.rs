//! Distances between capsules (spheres are capsules of zero length): the closest points of two
//! segments, clamped to both (Ericson, *Real-Time Collision Detection*, §5.1.9).

use nalgebra::Vector3;

/// Closest points `(c1, c2)` of segments `p1–q1` and `p2–q2`.
pub fn closest_points(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    const EPS: f64 = 1e-12;
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.dot(&d1), d2.dot(&d2), d2.dot(&r));
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > EPS { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p1 + d1 * s, p2 + d2 * t)
}

/// Signed distance between two capsules (m; negative when they overlap) and their closest axis
/// points.
pub fn capsule_distance(
    (p1, q1, r1): (&Vector3<f64>, &Vector3<f64>, f64),
    (p2, q2, r2): (&Vector3<f64>, &Vector3<f64>, f64),
) -> (f64, Vector3<f64>, Vector3<f64>) {
    let (c1, c2) = closest_points(p1, q1, p2, q2);
    ((c1 - c2).norm() - r1 - r2, c1, c2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn brute(p1: &Vector3<f64>, q1: &Vector3<f64>, p2: &Vector3<f64>, q2: &Vector3<f64>) -> f64 {
        let n = 400;
        let mut best = f64::INFINITY;
        for i in 0..=n {
            let a = p1 + (q1 - p1) * (i as f64 / n as f64);
            for j in 0..=n {
                let b = p2 + (q2 - p2) * (j as f64 / n as f64);
                best = best.min((a - b).norm());
            }
        }
        best
    }

    #[test]
    fn closest_points_match_a_dense_search_on_random_segments() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut v =
            || Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        for _ in 0..40 {
            let (p1, q1, p2, q2) = (v(), v(), v(), v());
            let (c1, c2) = closest_points(&p1, &q1, &p2, &q2);
            assert!((c1 - c2).norm() <= brute(&p1, &q1, &p2, &q2) + 1e-9);
            assert!((c1 - c2).norm() >= brute(&p1, &q1, &p2, &q2) - 0.02);
        }
    }

    #[test]
    fn parallel_and_degenerate_segments_have_their_plain_distances() {
        let z = Vector3::zeros();
        let (x, y) = (Vector3::x(), Vector3::y());
        let (d, _, _) = capsule_distance((&z, &x, 0.1), (&y, &(y + x), 0.1));
        assert!((d - 0.8).abs() < 1e-12);
        let (d, _, _) = capsule_distance((&z, &z, 0.5), (&y, &y, 0.25));
        assert!((d - 0.25).abs() < 1e-12);
    }
}
