//! Solved frames put back in frame order, with what the markers did not observe bridged.
//!
//! A frame with too few markers is not solved: every pose proxy is interpolated between the
//! neighbouring frames that observed it. A frame where only some bodies lost all their markers (a
//! foot whose markers drop out for a frame at an impact) is solved, but the proxies that move only
//! those bodies are not observed: the solver keeps them where the previous frame left them, a step
//! in the output when the markers come back. They are interpolated too, per proxy, between the
//! last frame before that observed it and the next one after (held at the last observed value when
//! no later frame observes it, as OpenSim's IK holds an unobserved coordinate). A gap longer than
//! [`MAX_HELD`] frames is held at the last observed value instead, so that what is held in memory
//! stays bounded (a limb with no markers in a whole trial). A proxy is
//! observed in a frame when a weighted marker on a body it moves (through its coordinates, a
//! coupling, or the root) is seen.

use crate::model::math::wrap_angle;
use crate::model::proxy::ProxyKind;
use crate::pipeline::context::Context;
use crate::pipeline::running::lanes::{FrameObservations, FrameResult};
use crate::pipeline::running::sink::{FrameSink, SolvedFrame, Stop};
use crate::solve::FrameStatus;
use std::collections::{BTreeMap, VecDeque};

/// Frames held at most while waiting for a proxy to be observed again.
pub const MAX_HELD: usize = 100;

/// A frame handed to the [`Orderer`] and not yet passed on.
struct Pending {
    frame: SolvedFrame,
    /// Pose proxies not observed in this frame and not yet bridged.
    open: Vec<usize>,
}

/// Puts frames in order and bridges what they did not observe before handing them on.
pub(crate) struct Orderer<'a> {
    ctx: &'a Context,
    calibrated: &'a [f64],
    pub(crate) next: usize,
    /// Finished ahead of `next` (several lanes), with their observations.
    pub(crate) early: BTreeMap<usize, (FrameResult, Vec<f64>)>,
    /// In frame order, waiting for a later frame to observe what they did not.
    pending: VecDeque<Pending>,
    /// Per proxy: the markers whose position it moves (empty for scale proxies).
    moves: Vec<Vec<usize>>,
    /// Per proxy: the last frame that observed it, and its value there.
    last_seen: Vec<Option<(usize, f64)>>,
    pub(crate) bridged: usize,
    /// Proxies unwrapped toward the previous solved frame ([`crate::pipeline::running::continuity`]).
    periodic: Vec<usize>,
    /// The last solved frame's proxies, as solved (unwrapped).
    last: Option<Vec<f64>>,
}

impl<'a> Orderer<'a> {
    pub(crate) fn new(ctx: &'a Context, calibrated: &'a [f64]) -> Orderer<'a> {
        Orderer {
            ctx,
            calibrated,
            next: 0,
            early: BTreeMap::new(),
            pending: VecDeque::new(),
            moves: markers_moved(ctx),
            last_seen: vec![None; ctx.proxy.np()],
            bridged: 0,
            periodic: crate::pipeline::running::continuity::periodic_proxies(&ctx.proxy),
            last: None,
        }
    }

    /// Takes frame `f`'s result; `obs` is the window it lies in, frame `f` at `f - first`.
    pub(crate) fn push(
        &mut self,
        f: usize,
        r: FrameResult,
        obs: (&FrameObservations<'_>, usize),
        sink: &mut FrameSink<'_>,
    ) -> Result<(), Stop> {
        let mut observed = vec![0.0; 3 * obs.0.map.len()];
        obs.0.fill(f - obs.1, &mut observed);
        self.early.insert(f, (r, observed));
        while let Some(((mut proxies, stats, seconds), observed)) = self.early.remove(&self.next) {
            let index = self.next;
            self.next += 1;
            let bridged = stats.status == FrameStatus::TooFewMarkers;
            // Continuous angles: every output follows the frames handed on from here.
            if !bridged {
                if let Some(prev) = &self.last {
                    crate::pipeline::running::continuity::unwrap_towards(&mut proxies, prev, &self.periodic);
                }
                self.last = Some(proxies.clone());
            }
            let markers = &self.ctx.model.markers;
            let seen = |m: &usize| markers[*m].weight > 0.0 && observed[3 * *m].is_finite();
            let open: Vec<usize> = (0..self.moves.len())
                .filter(|&k| !self.moves[k].is_empty() && (bridged || !self.moves[k].iter().any(seen)))
                .collect();
            // What this frame observes closes the gaps of the frames waiting for it.
            for k in (0..self.moves.len()).filter(|k| !self.moves[*k].is_empty() && !open.contains(k)) {
                let to = (index, proxies[k]);
                for p in self.pending.iter_mut().filter(|p| p.open.contains(&k)) {
                    let g = p.frame.index;
                    p.frame.proxies[k] = interpolate(self.ctx, k, g, self.last_seen[k], Some(to), proxies[k]);
                    p.open.retain(|&j| j != k);
                }
                self.last_seen[k] = Some(to);
            }
            self.bridged += usize::from(bridged);
            let frame = SolvedFrame { index, proxies, stats, seconds, bridged, observed };
            self.pending.push_back(Pending { frame, open });
            if self.pending.len() > MAX_HELD {
                let p = self.pending.front_mut().expect("held");
                for &k in &p.open {
                    p.frame.proxies[k] =
                        interpolate(self.ctx, k, p.frame.index, self.last_seen[k], None, p.frame.proxies[k]);
                }
                p.open.clear();
            }
            self.release(sink)?;
        }
        Ok(())
    }

    /// Hands on the frames at the front whose gaps are all bridged.
    fn release(&mut self, sink: &mut FrameSink<'_>) -> Result<(), Stop> {
        while self.pending.front().is_some_and(|p| p.open.is_empty()) {
            let p = self.pending.pop_front().expect("front");
            let f = p.frame.index;
            sink(p.frame).map_err(|e| Stop::Sink(f, e))?;
        }
        Ok(())
    }

    /// At the end of the trial: what no later frame observed is held at its last observed value
    /// (the calibration's pose where no frame observed it and the frame was not solved).
    pub(crate) fn finish(&mut self, sink: &mut FrameSink<'_>) -> Result<(), Stop> {
        for p in &mut self.pending {
            for &k in &p.open {
                let own = if p.frame.bridged { self.calibrated[k] } else { p.frame.proxies[k] };
                p.frame.proxies[k] = interpolate(self.ctx, k, p.frame.index, self.last_seen[k], None, own);
            }
            p.open.clear();
        }
        self.release(sink)
    }
}

/// Proxy `k` at frame `f` between the frames `before` and `after` that observed it (the nearer
/// one's value when only one exists; `own` when neither does). Unbounded angles (a root heading)
/// go the short way round.
fn interpolate(
    ctx: &Context,
    k: usize,
    f: usize,
    before: Option<(usize, f64)>,
    after: Option<(usize, f64)>,
    own: f64,
) -> f64 {
    match (before, after) {
        (Some((g0, a)), Some((g1, b))) => {
            let w = (f - g0) as f64 / (g1 - g0) as f64;
            let px = &ctx.proxy.proxies[k];
            let unbounded = px.range.0 == f64::NEG_INFINITY && px.range.1 == f64::INFINITY;
            let d = if px.kind == ProxyKind::Rotation && unbounded { wrap_angle(b - a) } else { b - a };
            a + w * d
        }
        (Some((_, v)), None) | (None, Some((_, v))) => v,
        (None, None) => own,
    }
}

/// Per proxy, the weighted markers whose position it moves: those on a body whose chain to the
/// root has a joint driven by one of its coordinates (or by a coordinate coupled to one). Scale
/// proxies move markers too but are fixed per subject: they get none.
fn markers_moved(ctx: &Context) -> Vec<Vec<usize>> {
    let (model, proxy) = (&ctx.model, &ctx.proxy);
    let nq = model.nq();
    // Coordinates each body's joint depends on.
    let joint_coords = |b: usize| -> Vec<usize> {
        let mut c: Vec<usize> =
            model.bodies[b].joint.motions.clone().filter_map(|m| model.motions[m].coordinate).collect();
        // A coupled coordinate moves the joint through its independent one.
        for cp in &model.couplings {
            if c.contains(&cp.dependent) && !c.contains(&cp.independent) {
                c.push(cp.independent);
            }
        }
        c
    };
    let coords: Vec<Vec<usize>> = (0..model.nb()).map(joint_coords).collect();
    (0..proxy.np())
        .map(|k| {
            if proxy.proxies[k].kind == ProxyKind::Scale {
                return Vec::new();
            }
            let ys: Vec<usize> =
                proxy.terms.iter().filter(|t| t.proxy == k && t.y_index < nq).map(|t| t.y_index).collect();
            (0..model.markers.len())
                .filter(|&m| {
                    model.markers[m].weight > 0.0
                        && model.chain(model.markers[m].body).iter().any(|&b| coords[b].iter().any(|c| ys.contains(c)))
                })
                .collect()
        })
        .collect()
}
