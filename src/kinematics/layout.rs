//! Precomputed sparsity of one (model, proxy map) pair: which state entries and proxies can move
//! each marker. Built once per model; read-only in the hot path.

use crate::model::proxy::ProxyMap;
use crate::model::Model;

/// Per-marker dependency lists.
#[derive(Clone, Debug)]
pub struct Layout {
    /// For each marker, the indices of `y` that can move it (sorted).
    pub marker_y: Vec<Vec<usize>>,
    /// For each marker, the proxy-map terms whose `y_index` is in `marker_y` (sorted by proxy).
    pub marker_terms: Vec<Vec<usize>>,
    /// For each marker, the distinct proxies of `marker_terms` (sorted).
    pub marker_proxies: Vec<Vec<usize>>,
    /// For each marker and each entry of `marker_terms`, the position of its proxy in `marker_proxies`.
    pub marker_term_slot: Vec<Vec<usize>>,
}

impl Layout {
    pub fn new(model: &Model, proxy: &ProxyMap) -> Layout {
        let mut marker_y = Vec::new();
        let mut marker_terms = Vec::new();
        let mut marker_proxies = Vec::new();
        let mut marker_term_slot = Vec::new();
        for m in &model.markers {
            let mut ys = Vec::new();
            for &a in model.chain(m.body) {
                let body = &model.bodies[a];
                if let Some(p) = body.parent {
                    ys.extend((0..3).map(|k| model.scale_index(p, k)));
                }
                for mo in &model.motions[body.joint.motions.clone()] {
                    if let Some(c) = mo.coordinate {
                        ys.push(c);
                    }
                }
                ys.extend((0..3).map(|k| model.scale_index(a, k)));
            }
            ys.sort_unstable();
            ys.dedup();
            let mut terms: Vec<usize> = ys.iter().flat_map(|&j| proxy.y_terms[j].clone()).collect();
            terms.sort_by_key(|&t| (proxy.terms[t].proxy, t));
            let mut proxies: Vec<usize> = terms.iter().map(|&t| proxy.terms[t].proxy).collect();
            proxies.dedup();
            let slots = terms.iter().map(|&t| proxies.binary_search(&proxy.terms[t].proxy).unwrap_or(0)).collect();
            marker_y.push(ys);
            marker_terms.push(terms);
            marker_proxies.push(proxies);
            marker_term_slot.push(slots);
        }
        Layout { marker_y, marker_terms, marker_proxies, marker_term_slot }
    }
}
