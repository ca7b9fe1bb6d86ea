//! The GPU renderer through wgpu (DESIGN §10), the CPU renderer's twin: per frame, a compute
//! pass builds the appearance `ā + P_a b_a` (components resident in GPU memory) straight into
//! the padded reference image, and one draw of the mesh — a quad per triangle, its bounding box
//! grown by the dilation, every fragment testing its barycentric coordinates as the CPU's span
//! walker does — samples it bilinearly onto the canvas, replacing the pixels (hard edge) or
//! blending by the warped feathered alpha. Whole batches are recorded into one submission, each
//! frame with its own buffers, so the GPU works through a batch without waiting on the CPU and
//! the render pipeline's worker overlaps it with encoding. Frames agree with the CPU renderer to
//! within one grey level on ≥ 99.9 % of pixels (tests/gpu.rs).
//!
//! Runs on any adapter wgpu finds: a real GPU, Vulkan on lavapipe, or GL on Mesa's llvmpipe (a
//! fresh machine has the last with no install). No adapter → [`GpuError::NoAdapter`], the cue for
//! the CPU path.

use std::sync::{Arc, Mutex};

use bytemuck::{Pod, Zeroable};
use image::RgbImage;
use thiserror::Error;
use wgpu::util::DeviceExt;

use super::{Edge, RenderError, Renderer};
use crate::facespace::{FaceParams, Frames};
use crate::model::FaceModel;
use crate::warp;

/// What can go wrong with the GPU.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter on the backends asked for.
    #[error("no GPU adapter ({0})")]
    NoAdapter(String),
    /// An adapter that lacks what the renderer needs.
    #[error("GPU adapter {adapter}: {reason}")]
    Unsupported {
        /// The adapter.
        adapter: String,
        /// What it lacks.
        reason: String,
    },
    /// The device could not be created, or reported an error while rendering.
    #[error("GPU: {0}")]
    Device(String),
}

/// Which backends to look for an adapter on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backends {
    /// Any (Vulkan first, then GL), narrowed by the `WGPU_BACKEND` environment variable
    /// (`vulkan`, `gl`) as other wgpu programs are.
    Any,
    /// Vulkan only (a real driver or lavapipe).
    Vulkan,
    /// GL only (e.g. Mesa's llvmpipe).
    Gl,
}

impl Backends {
    fn wgpu(self) -> wgpu::Backends {
        match self {
            Backends::Any => {
                let ours = wgpu::Backends::VULKAN | wgpu::Backends::GL;
                wgpu::Backends::from_env().map_or(ours, |env| env & ours)
            }
            Backends::Vulkan => wgpu::Backends::VULKAN,
            Backends::Gl => wgpu::Backends::GL,
        }
    }
}

/// A GPU device and queue, shared by the renderers made on it.
#[derive(Clone, Debug)]
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    /// The first error the device reported outside an error scope.
    failure: Arc<Mutex<Option<String>>>,
}

impl Gpu {
    /// The best adapter on `backends` and a device on it.
    pub fn new(backends: Backends) -> Result<Gpu, GpuError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
        descriptor.backends = backends.wgpu();
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let name = format!("{} ({:?})", info.name, info.backend);
        let unsupported = |reason: &str| GpuError::Unsupported {
            adapter: name.clone(),
            reason: reason.into(),
        };
        let downlevel = adapter.get_downlevel_capabilities();
        if !downlevel
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(unsupported("no compute shaders"));
        }
        let limits = adapter.limits();
        if limits.max_storage_buffers_per_shader_stage < 5 {
            return Err(unsupported("fewer than 5 storage buffers per shader stage"));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("facespace"),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        let failure = Arc::new(Mutex::new(None));
        let sink = Arc::clone(&failure);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut slot = sink.lock().unwrap_or_else(|p| p.into_inner());
            slot.get_or_insert_with(|| e.to_string());
        }));
        Ok(Gpu {
            device,
            queue,
            info,
            failure,
        })
    }

    /// The adapter and backend, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) via Gl".
    pub fn describe(&self) -> String {
        format!("{} via {:?}", self.info.name, self.info.backend)
    }

    /// Whether the adapter is a CPU implementation (llvmpipe, lavapipe).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    fn check(&self) -> Result<(), GpuError> {
        let slot = self.failure.lock().unwrap_or_else(|p| p.into_inner());
        match slot.as_ref() {
            Some(e) => Err(GpuError::Device(e.clone())),
            None => Ok(()),
        }
    }
}

/// `Dims` of the shaders.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Dims {
    width: u32,
    height: u32,
    stride: u32,
    n_params: u32,
    dim: u32,
    pad: [u32; 3],
}

/// `Instance` of the shaders: one triangle's quad and maps, relative to its first vertex.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Instance {
    quad: [f32; 4],
    origin_src0: [f32; 4],
    src12: [f32; 4],
    la: [f32; 4],
    lx: [f32; 4],
    ly: [f32; 4],
    floor: [f32; 4],
}

impl Instance {
    fn of(t: &warp::Tri) -> Instance {
        let o = t.origin;
        let la: [f64; 3] = std::array::from_fn(|i| t.l0[i] + t.lx[i] * o[0] + t.ly[i] * o[1]);
        let v3 = |v: [f64; 3]| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0];
        Instance {
            quad: [
                t.x_lo.ceil() as f32,
                t.y0 as f32,
                (t.x_hi.floor() + 1.0) as f32,
                (t.y1 + 1) as f32,
            ],
            origin_src0: [o[0], o[1], t.src[0][0], t.src[0][1]].map(|v| v as f32),
            src12: [t.src[1][0], t.src[1][1], t.src[2][0], t.src[2][1]].map(|v| v as f32),
            la: v3(la),
            lx: v3(t.lx),
            ly: v3(t.ly),
            floor: v3(t.floor),
        }
    }
}

/// Bytes per row of a readback, padded to wgpu's copy alignment.
fn padded_row(width: u32, bytes_per_pixel: u32) -> u32 {
    let row = width * bytes_per_pixel;
    row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// One frame's GPU resources, reused from batch to batch while the canvas size holds.
struct Slot {
    size: (u32, u32),
    params: wgpu::Buffer,
    instances: wgpu::Buffer,
    canvas: wgpu::Texture,
    readback: wgpu::Buffer,
    appearance_group: wgpu::BindGroup,
    draw_group: wgpu::BindGroup,
    reference_buffer: wgpu::Buffer,
    reference: wgpu::Texture,
}

/// The GPU renderer (see the module docs).
pub struct GpuRenderer<'m> {
    model: &'m FaceModel,
    gpu: Gpu,
    feathered: bool,
    appearance: wgpu::ComputePipeline,
    draw: wgpu::RenderPipeline,
    dims: wgpu::Buffer,
    basis: wgpu::Buffer,
    source_pixel: wgpu::Buffer,
    alpha: wgpu::Buffer,
    /// Texels per row of the reference image in `reference_buffer`.
    stride: u32,
    slots: Mutex<Vec<Slot>>,
}

impl std::fmt::Debug for GpuRenderer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRenderer")
            .field("adapter", &self.gpu.describe())
            .field("feathered", &self.feathered)
            .finish()
    }
}

const SHADER: &str = include_str!("gpu.wgsl");

impl<'m> GpuRenderer<'m> {
    /// A renderer of `model`'s faces on `gpu`, meeting the canvas as `edge` says (the same
    /// alpha as [`super::CpuRenderer::with_edge`]).
    pub fn new(gpu: &Gpu, model: &'m FaceModel, edge: impl Into<Edge>) -> Result<Self, GpuError> {
        let alpha_values = edge.into().alpha(model);
        let feather = alpha_values.is_some().then_some(());
        let device = &gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let frame = &model.frame;
        let (w, h) = (frame.width as u32, frame.height as u32);
        let pca = &model.appearance.pca;
        let dim = pca.dim();
        let n_params = pca.n_components();
        let stride = padded_row(w, 16) / 16;
        let limits = device.limits();
        let basis_bytes = ((n_params + 1) * dim * 4) as u64;
        if basis_bytes > limits.max_storage_buffer_binding_size
            || w > limits.max_texture_dimension_2d
            || h > limits.max_texture_dimension_2d
        {
            return Err(GpuError::Unsupported {
                adapter: gpu.describe(),
                reason: format!(
                    "the model ({} MB of components, {w}×{h} reference frame) exceeds its limits",
                    basis_bytes >> 20
                ),
            });
        }
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage,
            })
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let dims = init(
            "dims",
            bytemuck::bytes_of(&Dims {
                width: w,
                height: h,
                stride,
                n_params: n_params as u32,
                dim: dim as u32,
                pad: [0; 3],
            }),
            wgpu::BufferUsages::UNIFORM,
        );
        let mut basis_values = Vec::with_capacity((n_params + 1) * dim);
        basis_values.extend_from_slice(&pca.mean);
        basis_values.extend_from_slice(&pca.components);
        let basis = init("basis", bytemuck::cast_slice(&basis_values), storage);
        // Which mask pixel fills each reference-image pixel: the mask, then the padding rings.
        let mut source = vec![-1i32; frame.width * frame.height];
        for (i, p) in frame.pixels.iter().enumerate() {
            source[p.y as usize * frame.width + p.x as usize] = i as i32;
        }
        for &(dst, src) in &frame.padding {
            source[dst as usize] = src as i32;
        }
        let source_pixel = init("source pixel", bytemuck::cast_slice(&source), storage);
        let alpha_values = alpha_values.unwrap_or_else(|| vec![1.0; frame.n_pixels()]);
        let alpha = init("alpha", bytemuck::cast_slice(&alpha_values), storage);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("facespace gpu.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let appearance = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("appearance"),
            layout: None,
            module: &module,
            entry_point: Some("appearance"),
            compilation_options: Default::default(),
            cache: None,
        });
        let attributes = wgpu::vertex_attr_array![
            0 => Float32x4, 1 => Float32x4, 2 => Float32x4, 3 => Float32x4,
            4 => Float32x4, 5 => Float32x4, 6 => Float32x4
        ];
        let blend = feather.map(|_| wgpu::BlendState {
            color: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::SrcAlpha,
                dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
                operation: wgpu::BlendOperation::Add,
            },
            alpha: wgpu::BlendComponent::REPLACE,
        });
        let draw = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("warp"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("quad"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Instance>() as u64,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some(if feather.is_some() {
                    "feathered"
                } else {
                    "hard"
                }),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: wgpu::TextureFormat::Rgba8Unorm,
                    blend,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Unsupported {
                adapter: gpu.describe(),
                reason: e.to_string(),
            });
        }
        Ok(GpuRenderer {
            model,
            gpu: gpu.clone(),
            feathered: feather.is_some(),
            appearance,
            draw,
            dims,
            basis,
            source_pixel,
            alpha,
            stride,
            slots: Mutex::new(Vec::new()),
        })
    }

    /// The device this renderer draws with.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    fn slot(&self, size: (u32, u32)) -> Slot {
        let device = &self.gpu.device;
        let frame = &self.model.frame;
        let (rw, rh) = (frame.width as u32, frame.height as u32);
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: (self.model.appearance.n_params().max(1) * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let instances = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("instances"),
            size: (frame.triangles.len().max(1) * std::mem::size_of::<Instance>()) as u64,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let reference_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("reference image"),
            size: u64::from(self.stride) * u64::from(rh) * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let reference = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("reference image"),
            size: wgpu::Extent3d {
                width: rw,
                height: rh,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let canvas = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("canvas"),
            size: wgpu::Extent3d {
                width: size.0,
                height: size.1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded_row(size.0, 4)) * u64::from(size.1),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let canvas_uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("canvas"),
            contents: bytemuck::cast_slice(&[size.0 as f32, size.1 as f32, rw as f32, rh as f32]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry { binding, resource }
        }
        let appearance_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("appearance"),
            layout: &self.appearance.get_bind_group_layout(0),
            entries: &[
                entry(0, self.dims.as_entire_binding()),
                entry(1, self.basis.as_entire_binding()),
                entry(2, self.source_pixel.as_entire_binding()),
                entry(3, self.alpha.as_entire_binding()),
                entry(4, params.as_entire_binding()),
                entry(5, reference_buffer.as_entire_binding()),
            ],
        });
        let view = reference.create_view(&Default::default());
        let draw_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("warp"),
            layout: &self.draw.get_bind_group_layout(0),
            entries: &[
                entry(0, canvas_uniform.as_entire_binding()),
                entry(1, wgpu::BindingResource::TextureView(&view)),
            ],
        });
        Slot {
            size,
            params,
            instances,
            canvas,
            readback,
            appearance_group,
            draw_group,
            reference_buffer,
            reference,
        }
    }

    /// Renders frames `start..start + canvases.len()` as [`Renderer::render_batch`] does but
    /// leaves them on the GPU (the canvases are uploaded as backgrounds, not written back): for
    /// measuring the readback's share, or for a consumer on the GPU.
    pub fn render_batch_on_gpu(
        &self,
        frames: &Frames,
        start: usize,
        canvases: &[RgbImage],
    ) -> Result<(), RenderError> {
        let params = batch_params(frames, start, canvases.len());
        let mut copies = canvases.to_vec();
        self.render_all(&params, &mut copies, false)
    }

    /// Renders frames onto canvases of one size, all in one submission; with `readback`, the
    /// frames are copied back into the canvases.
    fn render_all(
        &self,
        params: &[FaceParams<'_>],
        canvases: &mut [RgbImage],
        readback: bool,
    ) -> Result<(), RenderError> {
        let n = canvases.len();
        if n == 0 {
            return Ok(());
        }
        let size = canvases[0].dimensions();
        if let Some(c) = canvases.iter().find(|c| c.dimensions() != size) {
            return Err(RenderError::Size {
                what: "a canvas of the batch".into(),
                found: c.dimensions(),
                expected: size,
            });
        }
        // The CPU's share: landmarks and triangle setup, exactly as the CPU renderer.
        let frame = &self.model.frame;
        let mut instances = Vec::with_capacity(n);
        for p in params {
            let landmarks = self.model.landmarks(*p)?;
            warp::check_landmarks(frame, &landmarks.points)?;
            let tris = warp::triangles(frame, &landmarks.points, size.0 as usize, size.1 as usize);
            instances.push(tris.iter().map(Instance::of).collect::<Vec<_>>());
        }
        let (device, queue) = (&self.gpu.device, &self.gpu.queue);
        let mut slots = self.slots.lock().unwrap_or_else(|p| p.into_inner());
        if slots.first().is_some_and(|s| s.size != size) {
            slots.clear();
        }
        while slots.len() < n {
            let slot = self.slot(size);
            slots.push(slot);
        }
        let (rw, rh) = (frame.width as u32, frame.height as u32);
        let extent = |w: u32, h: u32| wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let row = padded_row(size.0, 4);
        let mut encoder = device.create_command_encoder(&Default::default());
        let mut rgba = Vec::with_capacity((size.0 * size.1 * 4) as usize);
        for k in 0..n {
            let slot = &slots[k];
            queue.write_buffer(&slot.params, 0, bytemuck::cast_slice(params[k].appearance));
            if !instances[k].is_empty() {
                queue.write_buffer(&slot.instances, 0, bytemuck::cast_slice(&instances[k]));
            }
            rgba.clear();
            rgba.extend(
                canvases[k]
                    .as_raw()
                    .chunks_exact(3)
                    .flat_map(|p| [p[0], p[1], p[2], 255]),
            );
            queue.write_texture(
                slot.canvas.as_image_copy(),
                &rgba,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size.0 * 4),
                    rows_per_image: Some(size.1),
                },
                extent(size.0, size.1),
            );
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.appearance);
                pass.set_bind_group(0, &slot.appearance_group, &[]);
                pass.dispatch_workgroups((rw * rh).div_ceil(64), 1, 1);
            }
            encoder.copy_buffer_to_texture(
                wgpu::TexelCopyBufferInfo {
                    buffer: &slot.reference_buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(self.stride * 16),
                        rows_per_image: Some(rh),
                    },
                },
                slot.reference.as_image_copy(),
                extent(rw, rh),
            );
            {
                let view = slot.canvas.create_view(&Default::default());
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("warp"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                if !instances[k].is_empty() {
                    pass.set_pipeline(&self.draw);
                    pass.set_bind_group(0, &slot.draw_group, &[]);
                    pass.set_vertex_buffer(0, slot.instances.slice(..));
                    pass.draw(0..6, 0..instances[k].len() as u32);
                }
            }
            if !readback {
                continue;
            }
            encoder.copy_texture_to_buffer(
                slot.canvas.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &slot.readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(size.1),
                    },
                },
                extent(size.0, size.1),
            );
        }
        queue.submit([encoder.finish()]);
        if !readback {
            device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| gpu_failure(e.to_string()))?;
            return self.gpu.check().map_err(gpu_error);
        }
        let (tx, rx) = std::sync::mpsc::channel();
        for (k, slot) in slots.iter().take(n).enumerate() {
            let tx = tx.clone();
            slot.readback
                .map_async(wgpu::MapMode::Read, .., move |r| drop(tx.send((k, r))));
        }
        drop(tx);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| gpu_failure(e.to_string()))?;
        self.gpu.check().map_err(gpu_error)?;
        for (k, mapped) in rx {
            mapped.map_err(|e| gpu_failure(e.to_string()))?;
            let slot = &slots[k];
            {
                let data = slot
                    .readback
                    .get_mapped_range(..)
                    .map_err(|e| gpu_failure(e.to_string()))?;
                let out = canvases[k].as_mut();
                let width = size.0 as usize;
                for (y, dst) in out.chunks_exact_mut(width * 3).enumerate() {
                    let src = &data[y * row as usize..y * row as usize + width * 4];
                    for (d, s) in dst.chunks_exact_mut(3).zip(src.chunks_exact(4)) {
                        d.copy_from_slice(&s[..3]);
                    }
                }
            }
            slot.readback.unmap();
        }
        Ok(())
    }
}

fn batch_params(frames: &Frames, start: usize, n: usize) -> Vec<FaceParams<'_>> {
    (0..n).map(|k| frames.params(start + k)).collect()
}

fn gpu_failure(message: String) -> RenderError {
    gpu_error(GpuError::Device(message))
}

fn gpu_error(e: GpuError) -> RenderError {
    RenderError::Gpu(e)
}

impl Renderer for GpuRenderer<'_> {
    fn model(&self) -> &FaceModel {
        self.model
    }

    fn render_into(
        &self,
        params: FaceParams<'_>,
        canvas: &mut RgbImage,
    ) -> Result<(), RenderError> {
        self.render_all(&[params], std::slice::from_mut(canvas), true)
    }

    fn render_batch(
        &self,
        frames: &Frames,
        start: usize,
        canvases: &mut [RgbImage],
    ) -> Result<(), RenderError> {
        let params = batch_params(frames, start, canvases.len());
        self.render_all(&params, canvases, true)
    }

    fn describe(&self) -> String {
        format!("GPU: {}", self.gpu.describe())
    }
}
