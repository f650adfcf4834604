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
    /// For every proxy, its slot in `proxies` (entries not in `proxies` are never read).
    pub slot_of_proxy: Vec<usize>,
}

/// Per-body dependency lists, for bodies that carry markers.
#[derive(Clone, Debug)]
pub struct Layout {
    pub bodies: Vec<BodyDeps>,
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
            let mut proxies: Vec<usize> =
                ys.iter().flat_map(|&j| proxy.y_terms[j].clone()).map(|t| proxy.terms[t].proxy).collect();
            proxies.sort_unstable();
            proxies.dedup();
            let mut slot_of_proxy = vec![usize::MAX; proxy.np()];
            for (slot, &k) in proxies.iter().enumerate() {
                slot_of_proxy[k] = slot;
            }
            bodies.push(BodyDeps { markers, ys, proxies, slot_of_proxy });
        }
        Layout { bodies }
    }
}
