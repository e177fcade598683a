//! Self-collision's candidates found on the device (`shaders/collide.wgsl`), the twin of the
//! CPU's searches (`find_faces` in `src/collide/search.rs`, `find_crossings` in
//! `src/collide/edges.rs`): the items (triangles, or edges) put in hashed cells by a counting
//! sort with integer atomics, each bucket then in item order, and each query's (a member's, or
//! an edge's) items within its reach counted, placed by a scan and written, so every run gives
//! the same lists. One submit and one read-back a find. The host tests each candidate again in
//! f64 and orders them as the CPU does (`src/collide/device.rs`).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::GpuContext;
use crate::error::GpuError;

/// The WGSL source of the find's passes: the prelude ([`super::PRELUDE`]), the triangle
/// queries (`shaders/triangle.wgsl`), then `shaders/collide.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("../../shaders/prelude.wgsl"),
    include_str!("../../shaders/triangle.wgsl"),
    include_str!("../../shaders/collide.wgsl")
);

/// `Find` in shaders/collide.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Find {
    pub cell: f32,
    pub reach_max: f32,
    pub slack: f32,
    pub margin: f32,
    pub members: u32,
    pub triangles: u32,
    pub buckets: u32,
    pub capacity: u32,
    pub tris_at: u32,
    pub excluded_at: u32,
    pub thickness_at: u32,
    pub flags_at: u32,
    pub queries: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// `Centre` in shaders/collide.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Centre {
    pub m: [f32; 4],
    pub cell: [i32; 4],
}

/// Member flags (the shader's `HELD` and `OUT`): inverse mass 0; position not finite.
pub const HELD: u32 = 1;
pub const OUT: u32 = 2;

/// What the find searches: members against triangles, or edges against edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Search {
    Faces,
    Edges,
}

/// The third corner of an edge (the shader's `NONE`).
pub const NONE: u32 = u32::MAX;

/// What the find needs of a gather, by member slot.
#[derive(Debug)]
pub struct FindSetup {
    pub search: Search,
    /// Each member's layer.
    pub layers: Vec<u32>,
    /// Each item's corners (member slots; an edge's third [`NONE`]) and layer.
    pub tris: Vec<[u32; 4]>,
    /// Query `s`'s (a member's, or an edge's) neighbours at rest are
    /// `excluded[excluded_at[s]..excluded_at[s + 1]]`, ascending.
    pub excluded_at: Vec<u32>,
    pub excluded: Vec<u32>,
    /// Each layer's thickness.
    pub thickness: Vec<f32>,
}

/// One find's figures (the uniform's other fields come from the setup).
#[derive(Clone, Copy, Debug)]
pub struct FindShape {
    pub cell: f32,
    pub reach_max: f32,
    pub slack: f32,
    pub margin: f32,
}

/// The device find of one gather.
pub struct DeviceFind {
    ctx: Arc<GpuContext>,
    layout: wgpu::BindGroupLayout,
    passes: [wgpu::ComputePipeline; 7],
    bind_group: wgpu::BindGroup,
    params: wgpu::Buffer,
    points: wgpu::Buffer,
    topo: wgpu::Buffer,
    centres: wgpu::Buffer,
    counts: wgpu::Buffer,
    starts: wgpu::Buffer,
    sorted: wgpu::Buffer,
    list: wgpu::Buffer,
    staging: wgpu::Buffer,
    uniform: Find,
}

impl std::fmt::Debug for DeviceFind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceFind")
            .field("members", &self.uniform.members)
            .field("triangles", &self.uniform.triangles)
            .field("capacity", &self.uniform.capacity)
            .finish()
    }
}

/// The pass entry points, in the order a find runs them.
fn passes(search: Search) -> [&'static str; 7] {
    let (count, write) = match search {
        Search::Faces => ("count_pass", "write_pass"),
        Search::Edges => ("count_edges", "write_edges"),
    };
    [
        "centres_pass",
        "scan_buckets",
        "scatter_pass",
        "order_pass",
        count,
        "scan_queries",
        write,
    ]
}

/// An uninitialised buffer of `size` bytes (at least 16).
pub(super) fn buffer(
    ctx: &GpuContext,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

/// The list of `capacity` candidates and its read-back (the queries' starts, then the list).
fn lists(ctx: &GpuContext, queries: u32, capacity: u32) -> (wgpu::Buffer, wgpu::Buffer) {
    use wgpu::BufferUsages as U;
    let bytes = u64::from(capacity) * 4;
    let list = buffer(ctx, "find list", bytes, U::STORAGE | U::COPY_SRC);
    let out = u64::from(queries + 1) * 4 + bytes;
    let staging = buffer(ctx, "find staging", out, U::MAP_READ | U::COPY_DST);
    (list, staging)
}

impl DeviceFind {
    pub fn new(ctx: Arc<GpuContext>, setup: &FindSetup) -> Result<Self, GpuError> {
        let members = setup.layers.len() as u32;
        let triangles = setup.tris.len() as u32;
        let queries = setup.excluded_at.len().saturating_sub(1) as u32;
        let buckets = (2 * triangles).next_power_of_two().max(256);
        // The topology in one buffer: layers, triangles, excluded lists, thicknesses, flags.
        let mut topo = setup.layers.clone();
        let tris_at = topo.len() as u32;
        topo.extend(setup.tris.iter().flatten());
        let excluded_at = topo.len() as u32;
        topo.extend(&setup.excluded_at);
        topo.extend(&setup.excluded);
        let thickness_at = topo.len() as u32;
        topo.extend(setup.thickness.iter().map(|t| t.to_bits()));
        let flags_at = topo.len() as u32;
        topo.resize(topo.len() + members as usize, 0);
        let capacity = (4 * queries).max(1024);
        let uniform = Find {
            members,
            queries,
            triangles,
            buckets,
            capacity,
            tris_at,
            excluded_at,
            thickness_at,
            flags_at,
            ..Default::default()
        };
        let scans = u64::from(buckets + queries + 2) * 4;
        let ctx2 = ctx.clone();
        ctx.scoped("self-collision find", move || {
            use super::Slot::{Storage, Uniform};
            use wgpu::BufferUsages as U;
            let write = Storage { read_only: false };
            let read = Storage { read_only: true };
            let (layout, passes) = super::stage_pipelines(
                &ctx2.device,
                "self-collision find",
                SHADER,
                passes(setup.search),
                &[
                    Uniform { dynamic: false },
                    read,
                    read,
                    write,
                    write,
                    write,
                    write,
                    write,
                ],
            );
            let params = buffer(&ctx2, "find params", 64, U::UNIFORM | U::COPY_DST);
            let points = buffer(
                &ctx2,
                "find points",
                u64::from(members) * 16,
                U::STORAGE | U::COPY_DST,
            );
            let topo = super::init_buffer(
                &ctx2.device,
                "find topology",
                bytemuck::cast_slice(&topo),
                U::STORAGE | U::COPY_DST,
            );
            let centres = buffer(&ctx2, "find centres", u64::from(triangles) * 32, U::STORAGE);
            let counts = buffer(&ctx2, "find counts", scans, U::STORAGE | U::COPY_DST);
            let starts = buffer(&ctx2, "find starts", scans, U::STORAGE | U::COPY_SRC);
            let sorted = buffer(&ctx2, "find sorted", u64::from(triangles) * 4, U::STORAGE);
            let (list, staging) = lists(&ctx2, queries, capacity);
            let bind_group = Self::bind(
                &ctx2,
                &layout,
                [
                    &params, &points, &topo, &centres, &counts, &starts, &sorted, &list,
                ],
            );
            Self {
                ctx: ctx2.clone(),
                layout,
                passes,
                bind_group,
                params,
                points,
                topo,
                centres,
                counts,
                starts,
                sorted,
                list,
                staging,
                uniform,
            }
        })
    }

    fn bind(
        ctx: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        buffers: [&wgpu::Buffer; 8],
    ) -> wgpu::BindGroup {
        let entries: Vec<_> = (0u32..)
            .zip(buffers)
            .map(|(i, b)| super::entry(i, b))
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("self-collision find"),
            layout,
            entries: &entries,
        })
    }

    /// Room for `capacity` candidates in the list (and its read-back).
    fn grow(&mut self, capacity: u32) -> Result<(), GpuError> {
        let ctx = self.ctx.clone();
        let queries = self.uniform.queries;
        let (list, staging) =
            ctx.scoped("self-collision find", || lists(&ctx, queries, capacity))?;
        self.bind_group = Self::bind(
            &ctx,
            &self.layout,
            [
                &self.params,
                &self.points,
                &self.topo,
                &self.centres,
                &self.counts,
                &self.starts,
                &self.sorted,
                &list,
            ],
        );
        (self.list, self.staging, self.uniform.capacity) = (list, staging, capacity);
        Ok(())
    }

    /// The candidates, the members at `points` (position, `swept`) with `flags`: query `s`'s
    /// items are `list[at[s]..at[s + 1]]`, in the device's order.
    pub fn find(
        &mut self,
        shape: FindShape,
        points: &[[f32; 4]],
        flags: &[u32],
        at: &mut Vec<u32>,
        list: &mut Vec<u32>,
    ) -> Result<(), GpuError> {
        let members = self.uniform.members as usize;
        if points.len() != members || flags.len() != members {
            return Err(GpuError::Device {
                adapter: self.ctx.describe(),
                what: format!(
                    "self-collision find over {members} members given {} points and {} flags",
                    points.len(),
                    flags.len()
                ),
            });
        }
        self.uniform.cell = shape.cell;
        self.uniform.reach_max = shape.reach_max;
        self.uniform.slack = shape.slack;
        self.uniform.margin = shape.margin;
        let q = &self.ctx.queue;
        q.write_buffer(&self.points, 0, bytemuck::cast_slice(points));
        let flags_at = u64::from(self.uniform.flags_at) * 4;
        q.write_buffer(&self.topo, flags_at, bytemuck::cast_slice(flags));
        loop {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(&self.uniform));
            let total = self.run(at, list)?;
            if total <= self.uniform.capacity {
                return Ok(());
            }
            self.grow(total.next_power_of_two())?;
        }
    }

    /// One find's submit and read-back; the candidates' count.
    fn run(&self, at: &mut Vec<u32>, list: &mut Vec<u32>) -> Result<u32, GpuError> {
        let u = self.uniform;
        let base = u64::from(u.buckets + 1) * 4;
        let at_bytes = u64::from(u.queries + 1) * 4;
        let list_bytes = u64::from(u.capacity) * 4;
        let mut total = 0;
        super::read_staging(
            &self.ctx,
            "self-collision find",
            &self.staging,
            at_bytes + list_bytes,
            |encoder| {
                encoder.clear_buffer(&self.counts, 0, None);
                {
                    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("self-collision find"),
                        timestamp_writes: None,
                    });
                    pass.set_bind_group(0, &self.bind_group, &[]);
                    // One invocation per element, or (the scans) one workgroup.
                    let (t, m) = (Some(u.triangles), Some(u.queries));
                    let sizes = [t, None, t, Some(u.buckets), m, None, m];
                    for (p, n) in self.passes.iter().zip(sizes) {
                        pass.set_pipeline(p);
                        match n {
                            Some(n) => super::dispatch(&mut pass, n),
                            None => pass.dispatch_workgroups(1, 1, 1),
                        }
                    }
                }
                encoder.copy_buffer_to_buffer(&self.starts, base, &self.staging, 0, at_bytes);
                encoder.copy_buffer_to_buffer(&self.list, 0, &self.staging, at_bytes, list_bytes);
            },
            |bytes| {
                let words: &[u32] = bytemuck::cast_slice(bytes);
                let (starts, found) = words.split_at(u.queries as usize + 1);
                total = starts[u.queries as usize];
                at.clear();
                at.extend_from_slice(starts);
                list.clear();
                list.extend_from_slice(&found[..(total.min(u.capacity)) as usize]);
            },
        )?;
        Ok(total)
    }
}
