//! The wgpu compute backend: the shaders evaluate a frame per workgroup (the default
//! [`Kernel::Cooperative`]) or per invocation ([`Kernel::PerFrame`]), in f32 or, where the
//! adapter offers `SHADER_F64` and it is asked for, in f64 ([`Precision`]).
//!
//! The model is uploaded once ([`pack`]); each batch is cut into chunks of at most `cap` frames
//! (what one storage binding holds, from the adapter's limits), each chunk is packed as
//! frame-major blocks straight into a mapped upload buffer, dispatched, and read back in place. Positions travel relative to a per-frame
//! reference point (the centroid of the observed markers, rounded to f32) so that f32 resolves
//! body-scale differences rather than lab coordinates.
//!
//! Over 600 lines: the host side of one compute pass (device, buffers, chunking, dispatch,
//! read-back) kept with its layout checks, so the buffer layouts are read against one place.

mod adapter;
mod gather;
mod host;
pub mod pack;
mod shader;
mod words;

use adapter::best_adapter;
pub use adapter::{adapters_best_first, list_adapters, searched_backends, AdapterSummary};
pub use shader::{shader_source, Kernel, Precision, COMMON, COOPERATIVE, PER_FRAME, REAL_F32, REAL_F64, WORKGROUP};

use super::assembly::{Evaluator, FrameProblem};
use super::backend::{check_shape, BackendError, BatchBackend, EnergyEval, FrameModel, GnSink};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Frames per chunk when the adapter's limits allow it. A large GPU needs many frames per
/// dispatch to be busy (an H100 keeps ~2k workgroups of 64 resident); device memory is a few tens
/// of KB per frame of capacity on the shipped model (input, scratch, output, two upload and two
/// read-back buffers; docs/KINEMATICS.md).
pub const DEFAULT_CAP: usize = 32_768;

/// Chunks a call is cut into by default ([`WgpuBackend::set_pieces`]): two, so that the device
/// evaluates one while the CPU hands out (and the lanes solve the QPs of) the other.
pub const DEFAULT_PIECES: usize = 2;

/// Smallest chunk a call is cut into for overlap (frames): below it a dispatch costs more in
/// fixed overhead than the overlap saves.
pub const MIN_PIECE: usize = 256;

/// Where the backend's wall time went, summed over the calls since the last
/// [`WgpuBackend::reset_phase_times`] (seconds). Chunks overlap (the device runs one chunk while
/// the host packs the next), so `wait_s` is the time the host had nothing else to do.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct PhaseTimes {
    /// Host: reference points and packing of the inputs into the mapped upload range (wall).
    pub pack_s: f64,
    /// CPU time of the packing, summed over threads.
    pub pack_cpu_s: f64,
    /// Host: queue writes (upload), encoding and submission.
    pub submit_s: f64,
    /// Waiting for the device and for the read-back mapping.
    pub wait_s: f64,
    /// Host: mapping the read-back range (the results are read in place, not copied).
    pub read_s: f64,
    /// Host: handing each frame's mapped results to its sink (wall; includes what the sinks do).
    pub unpack_s: f64,
    /// CPU time of the hand-out, summed over threads.
    pub unpack_cpu_s: f64,
    /// Frames evaluated.
    pub frames: u64,
}

/// Device errors raised outside an error scope, kept until the next check.
type ErrorSlot = Arc<Mutex<Option<String>>>;

/// Batched evaluation on a wgpu adapter (f32 or f64).
pub struct WgpuBackend {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: AdapterSummary,
    linearize: wgpu::ComputePipeline,
    energy: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    input: wgpu::Buffer,
    /// Two persistently mapped upload buffers: the host packs one chunk into one while the
    /// other is copied to `input`.
    upload: [wgpu::Buffer; 2],
    /// Re-mapping of an upload buffer after its copy was submitted.
    upload_wait: [Option<MapWait>; 2],
    output: wgpu::Buffer,
    /// Two read-back buffers: one chunk is read while the next one runs.
    staging: [wgpu::Buffer; 2],
    params: wgpu::Buffer,
    rows: pack::Rows,
    cap: usize,
    np: usize,
    nm: usize,
    precision: Precision,
    kernel: Kernel,
    /// Chunks a call is cut into (at least), for overlap of device and host.
    pieces: usize,
    /// Per-piece scratch of one input block while packing.
    pack_scratch: Vec<host::PackScratch>,
    /// The chunk's tracking-weight sets while packing.
    weight_sets: host::WeightSets,
    /// Reference point of each frame of the two chunks in flight (f32-representable, in f64).
    refs: [Vec<[f64; 3]>; 2],
    errors: ErrorSlot,
    phases: PhaseTimes,
}

impl std::fmt::Debug for WgpuBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WgpuBackend")
            .field("adapter", &self.adapter)
            .field("cap", &self.cap)
            .field("kernel", &self.kernel)
            .finish()
    }
}

impl WgpuBackend {
    /// Uploads `eval`'s model to the best adapter found, f32 shaders.
    pub fn new(eval: &Evaluator<'_>, max_cap: usize) -> Result<WgpuBackend, BackendError> {
        WgpuBackend::with_precision(eval, max_cap, Precision::F32)
    }

    /// As [`WgpuBackend::new`], in the given precision (f64 needs an adapter offering
    /// `SHADER_F64`: an error names the adapters found otherwise).
    pub fn with_precision(
        eval: &Evaluator<'_>,
        max_cap: usize,
        precision: Precision,
    ) -> Result<WgpuBackend, BackendError> {
        WgpuBackend::with_options(eval, max_cap, precision, Kernel::default())
    }

    /// As [`WgpuBackend::with_precision`], with the given [`Kernel`].
    pub fn with_options(
        eval: &Evaluator<'_>,
        max_cap: usize,
        precision: Precision,
        kernel: Kernel,
    ) -> Result<WgpuBackend, BackendError> {
        let adapter = best_adapter(precision)?;
        WgpuBackend::on_adapter(eval, adapter, max_cap, precision, kernel)
    }

    /// Chunks a call is cut into (at least; chunks of at least [`MIN_PIECE`] frames), so that
    /// the device works on one while the host hands out another: 1 runs a call that fits one
    /// dispatch as one chunk. Results do not depend on it.
    pub fn set_pieces(&mut self, pieces: usize) {
        self.pieces = pieces.max(1);
    }

    /// See [`WgpuBackend::set_pieces`].
    pub fn pieces(&self) -> usize {
        self.pieces
    }

    /// How the shaders spread a frame's work.
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// Where the wall time of the calls since the last reset went.
    pub fn phase_times(&self) -> PhaseTimes {
        self.phases
    }

    /// Starts a new [`PhaseTimes`] account.
    pub fn reset_phase_times(&mut self) {
        self.phases = PhaseTimes::default();
    }

    /// The scalar type the shaders compute in.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// The adapter this backend runs on.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.adapter
    }

    /// Frames per dispatch.
    pub fn chunk_capacity(&self) -> usize {
        self.cap
    }

    fn on_adapter(
        eval: &Evaluator<'_>,
        adapter: wgpu::Adapter,
        max_cap: usize,
        precision: Precision,
        kernel: Kernel,
    ) -> Result<WgpuBackend, BackendError> {
        let summary = AdapterSummary::of(&adapter.get_info());
        let fail = |message: String| BackendError::Device { adapter: summary.name.clone(), message };
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("smocap"),
            required_features: match precision {
                Precision::F32 => wgpu::Features::empty(),
                Precision::F64 => wgpu::Features::SHADER_F64,
            },
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| fail(format!("requesting a device: {e}")))?;
        let errors: ErrorSlot = Arc::default();
        let slot = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut s = slot.lock().unwrap_or_else(|p| p.into_inner());
            s.get_or_insert_with(|| e.to_string());
        }));

        let packed = pack::pack(eval.model, eval.proxy, &eval.layout);
        let rows = packed.rows;
        // Chunk capacity: every per-frame buffer must fit one binding.
        let word = precision.word() as u64;
        let scratch_rows = kernel.scratch_rows(&rows);
        // Input: the frames' blocks, then up to one tracking-weight set per frame.
        let in_rows = rows.input + rows.ny;
        let widest = word * in_rows.max(scratch_rows).max(rows.output + 4) as u64;
        let bind = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let by_limits = (bind / widest) as usize;
        let by_groups = kernel.frames_per_dispatch(limits.max_compute_workgroups_per_dimension as usize);
        let cap = max_cap.min(by_limits).min(by_groups) / 64 * 64;
        if cap == 0 {
            return Err(fail(format!(
                "one frame needs {widest} bytes per binding, more than the adapter's limit of {bind} bytes"
            )));
        }
        let source = shader_source(&packed, cap, precision, kernel);

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(kernel.name()),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("batch"),
            entries: &[
                storage(0, true),
                storage(1, true),
                storage(2, true),
                storage(3, false),
                storage(4, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("batch"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let linearize = pipeline("linearize");
        let energy = pipeline("energy");

        use wgpu::util::DeviceExt as _;
        let init = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let mu = init("model u32", bytemuck::cast_slice(&packed.mu));
        let mf = init("model reals", words::Words::from_f64(precision, &packed.mf).bytes(packed.mf.len()));
        let buffer = |label: &str, words: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: word * words as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let input = buffer("input", cap * in_rows, U::STORAGE | U::COPY_DST);
        let upload = [0, 1].map(|_| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("upload"),
                size: word * (cap * in_rows) as u64,
                usage: U::MAP_WRITE | U::COPY_SRC,
                mapped_at_creation: true,
            })
        });
        let scratch = buffer("scratch", cap * scratch_rows, U::STORAGE);
        // Output: the compact energy rows (4 words per frame), then one block per frame.
        let output = buffer("output", cap * (rows.output + 4), U::STORAGE | U::COPY_SRC);
        let staging = [0, 1].map(|_| buffer("staging", cap * rows.output, U::MAP_READ | U::COPY_DST));
        // Four u32: whatever the precision, 16 bytes.
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: 16,
            usage: U::UNIFORM | U::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("batch"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: mu.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: mf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: input.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: scratch.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: output.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: params.as_entire_binding() },
            ],
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(fail(format!("creating the compute pipelines: {e}")));
        }
        Ok(WgpuBackend {
            device,
            queue,
            adapter: summary,
            linearize,
            energy,
            bind_group,
            input,
            upload,
            upload_wait: [None, None],
            output,
            staging,
            params,
            rows,
            cap,
            np: eval.proxy.np(),
            nm: eval.model.markers.len(),
            precision,
            kernel,
            pieces: DEFAULT_PIECES,
            pack_scratch: vec![host::PackScratch::default(); 2 * rayon::current_num_threads().max(1)],
            weight_sets: host::WeightSets::default(),
            refs: [vec![[0.0; 3]; cap], vec![[0.0; 3]; cap]],
            errors,
            phases: PhaseTimes::default(),
        })
    }

    fn fail(&self, message: String) -> BackendError {
        BackendError::Device { adapter: self.adapter.name.clone(), message }
    }

    /// Bytes per shader word.
    fn word(&self) -> usize {
        self.precision.word()
    }

    /// Packs `frames` straight into the mapped upload buffer `slot` (frame-major),
    /// dispatches them and starts reading back their results into staging buffer `slot`:
    /// `(E, Σ‖r‖², used)` rows for `energy`, whole output blocks for `linearize`.
    fn submit(
        &mut self,
        slot: usize,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        linearize: bool,
    ) -> Result<Pending, BackendError> {
        let (n, word, r) = (frames.len(), self.word(), self.rows);
        let t = Instant::now();
        let size = std::num::NonZeroU64::new((n * r.input * word) as u64)
            .ok_or_else(|| BackendError::Shape("an empty chunk".into()))?;
        if let Some((index, rx)) = self.upload_wait[slot].take() {
            let ready = match rx.try_recv() {
                Ok(r) => Some(r),
                Err(_) => {
                    self.device
                        .poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None })
                        .map_err(|e| self.fail(format!("waiting for the device: {e}")))?;
                    rx.recv().ok()
                }
            };
            match ready {
                Some(Ok(())) => {}
                Some(Err(e)) => return Err(self.fail(format!("mapping the upload buffer: {e}"))),
                None => return Err(self.fail("the upload buffer was never mapped".into())),
            }
        }
        let (cpu, sets) = {
            let mut view = self.upload[slot]
                .slice(..)
                .get_mapped_range_mut()
                .map_err(|e| self.fail(format!("writing the inputs: {e:?}")))?;
            let job = host::PackJob { rows: r, np: self.np, nm: self.nm, cap: self.cap, frames, proxies };
            let (refs, scratch, ws) = (&mut self.refs[slot], &mut self.pack_scratch, &mut self.weight_sets);
            match self.precision {
                Precision::F32 => host::pack::<f32>(&job, view.slice(..), refs, scratch, ws),
                Precision::F64 => host::pack::<f64>(&job, view.slice(..), refs, scratch, ws),
            }
        };
        self.upload[slot].unmap();
        self.phases.pack_s += t.elapsed().as_secs_f64();
        self.phases.pack_cpu_s += cpu;
        let t = Instant::now();
        let st = stride(n);
        self.queue.write_buffer(&self.params, 0, bytemuck::cast_slice(&[n as u32, st as u32, 0, 0]));
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("chunk") });
        enc.copy_buffer_to_buffer(&self.upload[slot], 0, &self.input, 0, size.get());
        // The frames' tracking-weight sets, at `cap · rows.input` words (`CAP * IN_ROWS`).
        let table = (self.cap * r.input * word) as u64;
        enc.copy_buffer_to_buffer(&self.upload[slot], table, &self.input, table, (sets * r.ny * word) as u64);
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(if linearize { &self.linearize } else { &self.energy });
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(self.kernel.workgroups(n) as u32, 1, 1);
        }
        let (from, bytes) = if linearize {
            ((4 * self.cap * word) as u64, (n * r.output * word) as u64)
        } else {
            (0, (4 * n * word) as u64)
        };
        enc.copy_buffer_to_buffer(&self.output, from, &self.staging[slot], 0, bytes);
        let index = self.queue.submit([enc.finish()]);
        let (utx, urx) = std::sync::mpsc::channel();
        self.upload[slot].slice(..).map_async(wgpu::MapMode::Write, move |r| {
            let _ = utx.send(r);
        });
        self.upload_wait[slot] = Some((index.clone(), urx));
        let (tx, rx) = std::sync::mpsc::channel();
        self.staging[slot].slice(..bytes).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.phases.submit_s += t.elapsed().as_secs_f64();
        Ok(Pending { slot, bytes, index, rx })
    }

    /// Waits for a submitted chunk, hands its mapped results to `unpack` (which returns the CPU
    /// time it took) and unmaps them.
    fn finish(
        &mut self,
        p: Pending,
        range: std::ops::Range<usize>,
        unpack: &mut impl FnMut(std::ops::Range<usize>, &[u8], &[[f64; 3]]) -> f64,
    ) -> Result<(), BackendError> {
        let t = Instant::now();
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(p.index), timeout: None })
            .map_err(|e| self.fail(format!("waiting for the device: {e}")))?;
        match p.rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(self.fail(format!("mapping the results: {e}"))),
            Err(_) => return Err(self.fail("the results were never mapped".into())),
        }
        self.phases.wait_s += t.elapsed().as_secs_f64();
        if let Some(e) = self.errors.lock().unwrap_or_else(|p| p.into_inner()).take() {
            self.staging[p.slot].unmap();
            return Err(self.fail(e));
        }
        let t = Instant::now();
        let cpu = {
            let view = self.staging[p.slot]
                .slice(..p.bytes)
                .get_mapped_range()
                .map_err(|e| self.fail(format!("reading the results: {e:?}")))?;
            self.phases.read_s += t.elapsed().as_secs_f64();
            unpack(range, &view, &self.refs[p.slot])
        };
        self.staging[p.slot].unmap();
        self.phases.unpack_s += t.elapsed().as_secs_f64();
        self.phases.unpack_cpu_s += cpu;
        Ok(())
    }

    /// Runs `frames` chunk by chunk, two chunks in flight: while the device works on chunk
    /// `i`, the host packs chunk `i + 1` and hands out the results of chunk `i − 1` with
    /// `unpack(range, mapped bytes, reference points)` — for `linearize_into`, the solver's QPs
    /// of chunk `i − 1` run on the CPU pool while the device evaluates chunk `i`. A call is cut
    /// into at least [`WgpuBackend::pieces`] chunks (of at least [`MIN_PIECE`] frames) so that
    /// even a call that fits one dispatch keeps both sides busy.
    fn run(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        linearize: bool,
        mut unpack: impl FnMut(std::ops::Range<usize>, &[u8], &[[f64; 3]]) -> f64,
    ) -> Result<(), BackendError> {
        let (n, np) = (frames.len(), self.np);
        let cap = piece_len(n, self.cap, self.pieces);
        let mut in_flight: Option<(Pending, std::ops::Range<usize>)> = None;
        for c in 0..n.div_ceil(cap) {
            let (a, b) = (c * cap, ((c + 1) * cap).min(n));
            let pending = self.submit(c % 2, &frames[a..b], &proxies[a * np..b * np], linearize)?;
            if let Some((p, range)) = in_flight.replace((pending, a..b)) {
                self.finish(p, range, &mut unpack)?;
            }
        }
        if let Some((p, range)) = in_flight {
            self.finish(p, range, &mut unpack)?;
        }
        self.phases.frames += n as u64;
        Ok(())
    }
}

/// CPU time (s, summed over threads) of the host path alone for `frames` at `proxies`, without a
/// device: packing into plain memory laid out as the upload buffer, and handing a plain block
/// per frame, laid out as the read-back buffer, to `sinks` — the code a chunk runs, on rayon's
/// pool in as many pieces. Returns `(pack, hand-out)`. For `smocap bench-batch`: on lavapipe the
/// device's own threads share the host's cores, which inflates the in-place figures.
pub fn host_path_alone(
    eval: &Evaluator<'_>,
    precision: Precision,
    frames: &[FrameProblem<'_>],
    proxies: &[f64],
    sinks: &mut [&mut dyn GnSink],
) -> Result<(f64, f64), BackendError> {
    let (np, nm) = (eval.proxy.np(), eval.model.markers.len());
    check_shape(frames.len(), proxies.len(), sinks.len(), np)?;
    let rows = pack::pack(eval.model, eval.proxy, &eval.layout).rows;
    let job = host::PackJob { rows, np, nm, cap: frames.len(), frames, proxies };
    let pieces = 2 * rayon::current_num_threads().max(1);
    Ok(match precision {
        Precision::F32 => host::host_path_alone::<f32>(&job, sinks, pieces),
        Precision::F64 => host::host_path_alone::<f64>(&job, sinks, pieces),
    })
}

/// Frames per chunk for a call of `n` frames: at most `cap`, and at most `n / pieces` (so that
/// the call takes `pieces` chunks) unless that is under [`MIN_PIECE`].
fn piece_len(n: usize, cap: usize, pieces: usize) -> usize {
    n.div_ceil(pieces.max(1)).max(MIN_PIECE).min(cap).max(1)
}

/// Structure-of-arrays stride of a chunk of `n` frames: `n` rounded up to a workgroup.
fn stride(n: usize) -> usize {
    n.div_ceil(64) * 64
}

/// An upload buffer being mapped again: the submission that last read it, and the callback's
/// result.
type MapWait = (wgpu::SubmissionIndex, std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>);

/// A chunk submitted and being read back.
struct Pending {
    slot: usize,
    /// Bytes being read back.
    bytes: u64,
    index: wgpu::SubmissionIndex,
    rx: std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

impl BatchBackend for WgpuBackend {
    fn name(&self) -> &'static str {
        "wgpu"
    }

    fn device(&self) -> String {
        format!("wgpu: {}, {}, {} kernel", self.adapter, self.precision.name(), self.kernel.name())
    }

    fn linearize(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [FrameModel],
    ) -> Result<(), BackendError> {
        let mut sinks: Vec<&mut dyn GnSink> = out.iter_mut().map(|o| o as &mut dyn GnSink).collect();
        self.linearize_into(frames, proxies, &mut sinks)
    }

    fn linearize_into(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        sinks: &mut [&mut dyn GnSink],
    ) -> Result<(), BackendError> {
        let (np, rows, precision) = (self.np, self.rows, self.precision);
        check_shape(frames.len(), proxies.len(), sinks.len(), np)?;
        let pieces = 2 * rayon::current_num_threads().max(1);
        self.run(frames, proxies, true, |range, bytes, refs| {
            let per = range.len().div_ceil(pieces);
            let sinks = &mut sinks[range];
            match precision {
                Precision::F32 => host::hand_out::<f32>(bytemuck::cast_slice(bytes), rows, np, refs, sinks, per),
                Precision::F64 => host::hand_out::<f64>(bytemuck::cast_slice(bytes), rows, np, refs, sinks, per),
            }
        })
    }

    fn energy(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [EnergyEval],
    ) -> Result<(), BackendError> {
        check_shape(frames.len(), proxies.len(), out.len(), self.np)?;
        let precision = self.precision;
        self.run(frames, proxies, false, |range, bytes, _| {
            let t = host::thread_cpu_s();
            match precision {
                Precision::F32 => host::energies::<f32>(bytemuck::cast_slice(bytes), &mut out[range]),
                Precision::F64 => host::energies::<f64>(bytemuck::cast_slice(bytes), &mut out[range]),
            }
            host::thread_cpu_s() - t
        })
    }
}
