//! Precomputed sparsity of one (model, proxy map) pair: which state entries and proxies can move
//! the markers of each body. Built once per model; read-only in the hot path.

use crate::model::proxy::ProxyMap;
use crate::model::Model;

/// Dependencies of the markers of one body (all markers of a body share them).
#[derive(Clone, Debug, Default)]
pub struct BodyDeps {
    /// Markers on this body.
    pub markers: Vec<usize>,
    /// Indices of `y` that can move them (sorted).
    pub ys: Vec<usize>,
    /// Distinct proxies that can move them (sorted): the index set `S` of their rows of `J_m`.
    pub proxies: Vec<usize>,
    /// Proxy-map terms acting on `ys`, as `(term, position in ys, slot in proxies)`.
    pub terms: Vec<(usize, usize, usize)>,
    /// For every index of `y`, its position in `ys` (entries not in `ys` are never read).
    pub y_slot: Vec<usize>,
}

/// Per-body dependency lists, for bodies that carry markers.
#[derive(Clone, Debug)]
pub struct Layout {
    pub bodies: Vec<BodyDeps>,
    /// Largest `proxies.len()` and `ys.len()` over bodies (scratch sizes).
    pub max_proxies: usize,
    pub max_ys: usize,
}

impl Layout {
    pub fn new(model: &Model, proxy: &ProxyMap) -> Layout {
        let mut bodies = Vec::new();
        for b in 0..model.nb() {
            let markers: Vec<usize> = (0..model.markers.len()).filter(|&m| model.markers[m].body == b).collect();
            if markers.is_empty() {
                continue;
            }
            let mut ys = Vec::new();
            for &a in model.chain(b) {
                let body = &model.bodies[a];
                if let Some(p) = body.parent {
                    ys.extend((0..3).map(|k| model.scale_index(p, k)));
                }
                ys.extend(model.motions[body.joint.motions.clone()].iter().filter_map(|mo| mo.coordinate));
                ys.extend((0..3).map(|k| model.scale_index(a, k)));
            }
            ys.sort_unstable();
            ys.dedup();
            let term_ids: Vec<usize> = ys.iter().flat_map(|&j| proxy.y_terms[j].clone()).collect();
            let mut proxies: Vec<usize> = term_ids.iter().map(|&t| proxy.terms[t].proxy).collect();
            proxies.sort_unstable();
            proxies.dedup();
            let mut y_slot = vec![usize::MAX; model.ny()];
            for (i, &j) in ys.iter().enumerate() {
                y_slot[j] = i;
            }
            let terms = term_ids
                .iter()
                .map(|&t| (t, y_slot[proxy.terms[t].y_index], proxies.partition_point(|&k| k < proxy.terms[t].proxy)))
                .collect();
            bodies.push(BodyDeps { markers, ys, proxies, terms, y_slot });
        }
        let max_proxies = bodies.iter().map(|b| b.proxies.len()).max().unwrap_or(0);
        let max_ys = bodies.iter().map(|b| b.ys.len()).max().unwrap_or(0);
        Layout { bodies, max_proxies, max_ys }
    }
}
