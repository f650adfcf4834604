//! The model as the shaders read it: two flat arrays (`u32` indices, real values: kept in f64 here,
//! uploaded as the shader's `real`, f32 or f64) with section
//! offsets, and the WGSL header of `const`s that names those offsets and the per-frame row
//! layouts of the input, scratch and output buffers (see `shaders/common.wgsl` and the kernels).
//!
//! The per-body chain walk of [`cpu::chain_contributions`](crate::kinematics::cpu) is flattened
//! into *items*, one per (contribution, proxy-map term), in the same order as on the CPU.

use super::gather;
use crate::kinematics::Layout;
use crate::model::proxy::ProxyMap;
use crate::model::{Function, Model, MotionKind};
use std::fmt::Write as _;

/// "No index" in the `u32` arrays (ground parent, constant motion).
const NONE: u32 = u32::MAX;

/// Item kinds (shader `switch kind`).
const ITEM_PARENT_OFFSET: u32 = 0;
const ITEM_ROTATION: u32 = 1;
const ITEM_TRANSLATION: u32 = 2;
const ITEM_TRANSLATION_WEIGHT: u32 = 3;
const ITEM_CHILD_OFFSET: u32 = 4;

/// Row counts of the per-frame structure-of-arrays buffers.
#[derive(Clone, Copy, Debug)]
pub struct Rows {
    /// Input: proxies, observations (relative to the reference point), marker weights (0 where
    /// unobserved), tracking reference, the index of the frame's tracking-weight set, the
    /// reference point. The sets (`ny` words each, shared by the frames that share a weight
    /// vector) follow the chunk's blocks at `CAP · input` words.
    pub input: usize,
    /// Entries of `y` (words of a tracking-weight set).
    pub ny: usize,
    /// Scratch of the per-frame kernel (structure of arrays): y, J_Φ, body and motion frames,
    /// one body's A/W and one marker's rows.
    pub scratch: usize,
    /// Scratch block of the cooperative kernel (frame-major): the same first sections, then
    /// every layout body's A/W, every marker's rows and `(w, r)`
    /// ([`gather`](super::gather)).
    pub scratch_coop: usize,
    /// Output: E, Σ‖r‖², markers used, g, upper H packed column by column
    /// ([`upper_index`](crate::kinematics::backend::upper_index)), model markers.
    pub output: usize,
    /// Offsets of the output sections.
    pub o_g: usize,
    pub o_h: usize,
    pub o_x: usize,
    /// Offsets of the input sections.
    pub i_p: usize,
    pub i_obs: usize,
    pub i_mw: usize,
    pub i_tref: usize,
    pub i_tw: usize,
    pub i_c: usize,
}

/// The work of one frame-evaluation of a packed model, for the cost model in
/// docs/KINEMATICS.md (`smocap bench-batch` prints it).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Cost {
    /// Words per frame: input, output (linearize) and the cooperative kernel's scratch block.
    pub in_words: usize,
    pub out_words: usize,
    pub scratch_words: usize,
    /// Bodies, tree levels, motions, markers, layout bodies, chain items.
    pub bodies: usize,
    pub levels: usize,
    pub motions: usize,
    pub markers: usize,
    pub layout_bodies: usize,
    pub chain_items: usize,
    /// Jacobian row words formed (3 per marker and slot).
    pub row_words: usize,
    /// 3-vector dot products summed into `H` (upper triangle) and `g`.
    pub h_products: usize,
    pub g_products: usize,
}

impl Cost {
    /// Floating-point operations per frame (multiply and add counted apart): bodies ≈ 200 each
    /// (two 3×3 products and the motions' axis-angle), chain items ≈ 30, row words ≈ 8 (a cross
    /// product and the offset items), products 6 (a 3-vector dot and the weight) — an estimate to
    /// hold measurements against, not a count of instructions.
    pub fn flops(&self) -> usize {
        200 * self.bodies
            + 60 * self.motions
            + 30 * self.chain_items
            + 8 * self.row_words
            + 6 * (self.h_products + self.g_products)
            + 20 * self.markers
    }
}

/// A model packed for the shaders.
#[derive(Clone, Debug)]
pub struct Packed {
    pub mu: Vec<u32>,
    /// Real values in f64; [`super::Precision`] converts them at upload.
    pub mf: Vec<f64>,
    pub rows: Rows,
    /// What one frame-evaluation costs (docs/KINEMATICS.md, the cost model).
    pub cost: Cost,
    /// `const` declarations except `CAP`, which [`Packed::header`] adds.
    consts: String,
}

impl Packed {
    /// The WGSL header for chunks of `cap` frames.
    pub fn header(&self, cap: usize) -> String {
        format!("const CAP: u32 = {cap}u;\n{}", self.consts)
    }
}

/// Appends `f` (times `scale`) to the function table; returns its index.
fn push_function(fu: &mut Vec<u32>, fp: &mut Vec<f64>, f: &Function, scale: f64) -> u32 {
    if let Function::Multiplier { scale: s, inner } = f {
        return push_function(fu, fp, inner, scale * s);
    }
    let start = fp.len() as u32;
    fp.push(scale);
    let (kind, n) = match f {
        Function::Constant { value } => {
            fp.push(*value);
            (0, 1)
        }
        Function::Linear { slope, intercept } => {
            fp.extend([*slope, *intercept]);
            (1, 2)
        }
        Function::Polynomial { coefficients } => {
            fp.extend(coefficients.iter().copied());
            (2, coefficients.len())
        }
        Function::Spline(s) => {
            for v in [&s.x, &s.a, &s.b, &s.c, &s.d] {
                fp.extend(v.iter().copied());
            }
            (3, s.x.len())
        }
        Function::PiecewiseLinear { x, y } => {
            fp.extend(x.iter().copied());
            fp.extend(y.iter().copied());
            (4, x.len())
        }
        Function::Multiplier { .. } => unreachable!("unwrapped above"),
    };
    let i = fu.len() as u32 / 3;
    fu.extend([kind, start, n as u32]);
    i
}

/// Packs `model` with `proxy` (sparsity from `layout`).
pub fn pack(model: &Model, proxy: &ProxyMap, layout: &Layout) -> Packed {
    let (nb, nmot, nm, np, ny, nq, nt) =
        (model.nb(), model.motions.len(), model.markers.len(), proxy.np(), model.ny(), model.nq(), proxy.terms.len());
    let nh = np * (np + 1) / 2;
    // Function table first: its parameters go into their own real section.
    let (mut fu, mut fp) = (Vec::new(), Vec::new());
    let motion_func: Vec<u32> = model.motions.iter().map(|m| push_function(&mut fu, &mut fp, &m.func, 1.0)).collect();
    let term_func: Vec<u32> = proxy.terms.iter().map(|t| push_function(&mut fu, &mut fp, &t.func, 1.0)).collect();

    let mut mu: Vec<u32> = Vec::new();
    let mut mf: Vec<f64> = Vec::new();
    let mut consts = String::new();
    let mut c = |name: &str, v: usize| {
        let _ = writeln!(consts, "const {name}: u32 = {v}u;");
    };
    for (name, v) in [("NB", nb), ("NMOT", nmot), ("NM", nm), ("NP", np), ("NY", ny), ("NQ", nq), ("NT", nt)] {
        c(name, v);
    }
    c("NLB", layout.bodies.len());
    c("NH", nh);

    // Real sections.
    c("F_FUNC", mf.len());
    let f_func = mf.len() as u32;
    mf.extend(&fp);
    for s in fu.chunks_exact_mut(3) {
        s[1] += f_func;
    }
    c("F_BODY", mf.len());
    for b in &model.bodies {
        for iso in [&b.joint.parent_offset, &b.joint.child_offset] {
            let r = iso.rotation.to_rotation_matrix();
            mf.extend(r.matrix().as_slice().iter().copied()); // column-major
            mf.extend(iso.translation.vector.iter().copied());
        }
    }
    c("F_MOT", mf.len());
    for m in &model.motions {
        mf.extend(m.axis.iter().copied());
        mf.extend(m.parent_scale_weights.unwrap_or_default().iter().copied());
    }
    c("F_MARK", mf.len());
    for m in &model.markers {
        mf.extend(m.offset.iter().copied());
    }
    c("F_YOFF", mf.len());
    mf.extend(proxy.offsets.iter().copied());

    // u32 sections.
    c("U_FUNC", mu.len());
    mu.extend(&fu);
    c("U_BODY", mu.len());
    for b in &model.bodies {
        mu.extend([b.parent.map_or(NONE, |p| p as u32), b.joint.motions.start as u32, b.joint.motions.end as u32]);
    }
    c("U_MOT", mu.len());
    for (m, mo) in model.motions.iter().enumerate() {
        let kind = match mo.kind {
            MotionKind::Rotation => 0,
            MotionKind::Translation => 1,
        };
        mu.extend([
            kind,
            mo.coordinate.map_or(NONE, |c| c as u32),
            motion_func[m],
            mo.parent_scale_weights.is_some() as u32,
        ]);
    }
    c("U_MARK", mu.len());
    mu.extend(model.markers.iter().map(|m| m.body as u32));
    c("U_TERM", mu.len());
    for (t, term) in proxy.terms.iter().enumerate() {
        mu.extend([term.y_index as u32, term.proxy as u32, term_func[t]]);
    }
    c("U_YT", mu.len());
    for r in &proxy.y_terms {
        mu.extend([r.start as u32, r.end as u32]);
    }

    // Layout bodies: chain items, slot lists, markers with their offset items.
    let (mut lbs, mut slots, mut items, mut coefs, mut lbm, mut oitems) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut ns_max = 0;
    for deps in &layout.bodies {
        let body = model.markers[deps.markers[0]].body;
        let slot = |t: usize| deps.slot_of_proxy[proxy.terms[t].proxy] as u32;
        let items_start = items.len() / 5;
        let mut emit = |kind: u32, idx: usize, k: usize, coef: f64, j: usize| {
            for t in proxy.y_terms[j].clone() {
                items.extend([kind, idx as u32, k as u32, t as u32, slot(t)]);
                coefs.push(coef);
            }
        };
        for &a in model.chain(body) {
            let b = &model.bodies[a];
            if let Some(p) = b.parent {
                let t_p = b.joint.parent_offset.translation.vector;
                for k in 0..3 {
                    emit(ITEM_PARENT_OFFSET, p, k, t_p[k], model.scale_index(p, k));
                }
            }
            for m in b.joint.motions.clone() {
                let mo = &model.motions[m];
                if let Some(c) = mo.coordinate {
                    let kind = match mo.kind {
                        MotionKind::Rotation => ITEM_ROTATION,
                        MotionKind::Translation => ITEM_TRANSLATION,
                    };
                    emit(kind, m, 0, 0.0, c);
                }
                if let (MotionKind::Translation, Some(w), Some(p)) = (mo.kind, mo.parent_scale_weights, b.parent) {
                    for k in 0..3 {
                        emit(ITEM_TRANSLATION_WEIGHT, m, k, w[k], model.scale_index(p, k));
                    }
                }
            }
            let t_c = b.joint.child_offset.translation.vector;
            for k in 0..3 {
                emit(ITEM_CHILD_OFFSET, a, k, t_c[k], model.scale_index(a, k));
            }
        }
        let items_end = items.len() / 5;
        let markers_start = lbm.len() / 3;
        for &m in &deps.markers {
            let o0 = oitems.len() / 3;
            for k in 0..3 {
                for t in proxy.y_terms[model.scale_index(body, k)].clone() {
                    oitems.extend([k as u32, t as u32, slot(t)]);
                }
            }
            lbm.extend([m as u32, o0 as u32, (oitems.len() / 3) as u32]);
        }
        let markers_end = lbm.len() / 3;
        ns_max = ns_max.max(deps.proxies.len());
        lbs.push([body, deps.proxies.len(), slots.len(), items_start, items_end, markers_start, markers_end]);
        slots.extend(deps.proxies.iter().map(|&k| k as u32));
    }
    let layout_bodies: Vec<gather::LayoutBody> = lbs
        .iter()
        .map(|lb| gather::LayoutBody {
            slots: slots[lb[2]..lb[2] + lb[1]].iter().map(|&k| k as usize).collect(),
            markers: lb[5]..lb[6],
        })
        .collect();
    c("U_SLOT", mu.len());
    let u_slot = mu.len();
    mu.extend(&slots);
    c("U_LB", mu.len());
    for lb in &mut lbs {
        lb[2] += u_slot;
        mu.extend(lb.iter().map(|&v| v as u32));
    }
    c("U_LBM", mu.len());
    mu.extend(&lbm);
    c("U_ITEM", mu.len());
    mu.extend(&items);
    c("U_OITEM", mu.len());
    mu.extend(&oitems);
    c("F_ITEM", mf.len());
    mf.extend(&coefs);
    // Per-frame scratch rows shared by both kernels: y, J_Φ, body and motion frames.
    let s_dphi = ny;
    let s_rot = s_dphi + nt;
    let s_pos = s_rot + 9 * nb;
    let s_max = s_pos + 3 * nb;
    let s_mor = s_max + 3 * nmot;
    let s_mval = s_mor + 3 * nmot;
    let s_mder = s_mval + nmot;
    let s_msig = s_mder + nmot;
    let s_aw = s_msig + nmot;
    // The cooperative kernel's tables; its scratch block shares the sections before S_AW.
    let coop = gather::gather(model, proxy, &layout_bodies, s_aw);
    for (name, section) in &coop.sections {
        c(name, mu.len());
        mu.extend(section);
    }
    c("NLEV", coop.levels);
    c("NQE", lbm.len() / 3);
    for (name, v) in [("C_AW", coop.c_aw), ("C_ROW", coop.c_row), ("C_WR", coop.c_wr), ("C_ROWS", coop.c_rows)] {
        c(name, v);
    }
    // Never bind an empty buffer.
    mu.resize(mu.len().max(4), 0);
    mf.resize(mf.len().max(4), 0.0);

    // The per-frame kernel's rows after them: one body's A/W and one marker's rows.
    let s_row = s_aw + 6 * ns_max;
    let scratch = s_row + 3 * ns_max;
    for (name, v) in [
        ("S_Y", 0),
        ("S_DPHI", s_dphi),
        ("S_ROT", s_rot),
        ("S_POS", s_pos),
        ("S_MAX", s_max),
        ("S_MOR", s_mor),
        ("S_MVAL", s_mval),
        ("S_MDER", s_mder),
        ("S_MSIG", s_msig),
        ("S_AW", s_aw),
        ("S_ROW", s_row),
    ] {
        c(name, v);
    }
    let (i_p, i_obs) = (0, np);
    let i_mw = i_obs + 3 * nm;
    let i_tref = i_mw + nm;
    let i_tw = i_tref + ny;
    let i_c = i_tw + 1;
    for (name, v) in [("I_P", i_p), ("I_OBS", i_obs), ("I_MW", i_mw), ("I_TREF", i_tref), ("I_TW", i_tw), ("I_C", i_c)]
    {
        c(name, v);
    }
    let (o_g, o_h) = (3, 3 + np);
    let o_x = o_h + nh;
    for (name, v) in [("O_E", 0), ("O_SQ", 1), ("O_USED", 2), ("O_G", o_g), ("O_H", o_h), ("O_X", o_x)] {
        c(name, v);
    }
    c("IN_ROWS", i_c + 3);
    c("OUT_ROWS", o_x + 3 * nm);
    let rows = Rows {
        input: i_c + 3,
        ny,
        scratch: scratch.max(1),
        scratch_coop: coop.c_rows.max(1),
        output: o_x + 3 * nm,
        o_g,
        o_h,
        o_x,
        i_p,
        i_obs,
        i_mw,
        i_tref,
        i_tw,
        i_c,
    };
    let cost = Cost {
        in_words: rows.input,
        out_words: rows.output,
        scratch_words: rows.scratch_coop,
        bodies: nb,
        levels: coop.levels,
        motions: nmot,
        markers: nm,
        layout_bodies: layout.bodies.len(),
        chain_items: items.len() / 5,
        row_words: coop.c_wr - coop.c_row,
        h_products: coop.h_products,
        g_products: coop.g_products,
    };
    Packed { mu, mf, rows, cost, consts }
}
