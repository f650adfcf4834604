//! The tables of the cooperative kernel (`shaders/cooperative.wgsl`): one workgroup evaluates
//! one frame, each invocation owning whole outputs, so that nothing is accumulated by two
//! invocations (no atomics, a fixed summation order, results identical run to run).
//!
//! - **Levels**: bodies grouped by depth in the tree; the bodies of one level are evaluated in
//!   parallel, one level after the other.
//! - **Marker rows**: every marker of a layout body ("q", in [`Layout`] order) has its own rows
//!   of `J_m` in the frame's scratch block, so that all markers' rows are formed at once.
//! - **Gathers**: for every entry of `g` and of the upper triangle of `H`, the list of the
//!   products that sum to it — `(q, slot)` for `g_k = Σ w_q (J_q,slot)ᵀ r_q`, `(q, slot_i,
//!   slot_j)` for `H_ij = Σ w_q (J_q,i)ᵀ J_q,j`, and tracking terms `(t)`, `(t, u)` — in the order
//!   in which the one-invocation-per-frame kernel and the CPU add them.
//!
//! The lists' total length is the work of the sequential assembly; the workgroup spreads it
//! over its invocations by output entry.

use crate::kinematics::backend::upper_index;
use crate::model::proxy::ProxyMap;
use crate::model::Model;
use std::ops::Range;

/// One layout body as [`super::pack`] emitted it.
pub(super) struct LayoutBody {
    /// Proxy index of each slot (ascending).
    pub slots: Vec<usize>,
    /// Its markers' entries `q` (consecutive).
    pub markers: Range<usize>,
}

/// What the cooperative kernel needs beyond the per-frame kernel's tables.
pub(super) struct Gather {
    /// `u32` sections, in order, with their names (offsets relative to the start of `mu`
    /// are assigned by the caller).
    pub sections: Vec<(&'static str, Vec<u32>)>,
    /// Number of levels.
    pub levels: usize,
    /// Scratch block per frame: offset of the A/W area, of the marker rows, of the `(w, r)`
    /// quadruples, and the block's length (words).
    pub c_aw: usize,
    pub c_row: usize,
    pub c_wr: usize,
    pub c_rows: usize,
    /// Products summed into `H` and `g` (marker and tracking), for the cost model.
    pub h_products: usize,
    pub g_products: usize,
}

/// Offsets into `items` of consecutive ranges given by their lengths: `[0, n0, n0 + n1, …]`.
fn offsets(lists: &[Vec<u32>], width: usize) -> (Vec<u32>, Vec<u32>) {
    let mut off = Vec::with_capacity(lists.len() + 1);
    let mut flat = Vec::new();
    off.push(0);
    for l in lists {
        flat.extend_from_slice(l);
        off.push((flat.len() / width) as u32);
    }
    (off, flat)
}

/// Builds the cooperative tables; `scratch_start` is where the per-frame kernel's A/W area
/// begins (the sections before it are shared by both kernels).
pub(super) fn gather(model: &Model, proxy: &ProxyMap, lbs: &[LayoutBody], scratch_start: usize) -> Gather {
    let (np, nb) = (proxy.np(), model.nb());
    let nh = np * (np + 1) / 2;

    // Bodies by depth (parents precede children in the model's order).
    let mut depth = vec![0usize; nb];
    for b in 0..nb {
        depth[b] = model.bodies[b].parent.map_or(0, |p| depth[p] + 1);
    }
    let levels = depth.iter().max().map_or(0, |d| d + 1);
    let mut by_level: Vec<u32> = (0..nb as u32).collect();
    by_level.sort_by_key(|&b| (depth[b as usize], b));
    let mut lev = vec![0u32; levels + 1];
    for &d in &depth {
        lev[d + 1] += 1;
    }
    for l in 0..levels {
        lev[l + 1] += lev[l];
    }

    // Scratch: A/W per layout body, rows per marker entry, (w, r) per marker entry.
    let (mut lb_aw, mut q_info) = (Vec::new(), Vec::new());
    let mut aw = 0;
    for lb in lbs {
        lb_aw.push(aw as u32);
        aw += 6 * lb.slots.len();
    }
    let nq = lbs.iter().map(|l| l.markers.end).max().unwrap_or(0);
    let mut row = 0;
    let mut q_lb = vec![0usize; nq];
    for (i, lb) in lbs.iter().enumerate() {
        for q in lb.markers.clone() {
            q_lb[q] = i;
        }
    }
    for &lb in &q_lb {
        q_info.extend([lb as u32, row as u32]);
        row += 3 * lbs[lb].slots.len();
    }
    let c_aw = scratch_start;
    let c_row = c_aw + aw;
    let c_wr = c_row + row;
    let c_rows = c_wr + 4 * nq;

    // Gathers of g and H from the marker rows, in the sequential kernel's order (q ascending,
    // then slots).
    let mut g_m: Vec<Vec<u32>> = vec![Vec::new(); np];
    let mut h_m: Vec<Vec<u32>> = vec![Vec::new(); nh];
    for (q, &lb) in q_lb.iter().enumerate() {
        let slots = &lbs[lb].slots;
        for (i, &ki) in slots.iter().enumerate() {
            g_m[ki].extend([q as u32, i as u32]);
            for (j, &kj) in slots.iter().enumerate().skip(i) {
                h_m[upper_index(ki.min(kj), ki.max(kj))].extend([q as u32, i as u32, j as u32]);
            }
        }
    }
    // Tracking terms: j ascending, then t, then u, as the sequential kernel adds them.
    let mut g_t: Vec<Vec<u32>> = vec![Vec::new(); np];
    let mut h_t: Vec<Vec<u32>> = vec![Vec::new(); nh];
    for r in &proxy.y_terms {
        for t in r.clone() {
            let kt = proxy.terms[t].proxy;
            g_t[kt].push(t as u32);
            for u in r.clone() {
                let ku = proxy.terms[u].proxy;
                if kt <= ku {
                    h_t[upper_index(kt, ku)].extend([t as u32, u as u32]);
                }
            }
        }
    }
    let h_products = h_m.iter().map(|l| l.len() / 3).sum::<usize>() + h_t.iter().map(|l| l.len() / 2).sum::<usize>();
    let g_products = g_m.iter().map(|l| l.len() / 2).sum::<usize>() + g_t.iter().map(Vec::len).sum::<usize>();
    let (g_m_off, g_m_flat) = offsets(&g_m, 2);
    let (g_t_off, g_t_flat) = offsets(&g_t, 1);
    let (h_m_off, h_m_flat) = offsets(&h_m, 3);
    let (h_t_off, h_t_flat) = offsets(&h_t, 2);
    let sections = vec![
        ("U_LEV", lev),
        ("U_LEVB", by_level),
        ("U_LBAW", lb_aw),
        ("U_Q", q_info),
        ("U_GMO", g_m_off),
        ("U_GM", g_m_flat),
        ("U_GTO", g_t_off),
        ("U_GT", g_t_flat),
        ("U_HMO", h_m_off),
        ("U_HM", h_m_flat),
        ("U_HTO", h_t_off),
        ("U_HT", h_t_flat),
    ];
    Gather { sections, levels, c_aw, c_row, c_wr, c_rows, h_products, g_products }
}
