//! The CPU side of a frame's geometry: vertex layouts, body meshes, growing buffers.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rapier3d::prelude::ColliderHandle;

use super::bounds;
use crate::gpu::GpuContext;
use crate::Simulation;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(super) struct Vertex {
    pub(super) position: [f32; 3],
    pub(super) normal: [f32; 3],
    pub(super) colour: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(super) struct ViewUniform {
    pub(super) view_proj: [[f32; 4]; 4],
    pub(super) eye: [f32; 4],
    pub(super) floor: [f32; 4],
    pub(super) grid: [f32; 4],
}

/// A body's surface in its own frame, from parry's tessellation.
pub(super) struct BodyMesh {
    pub(super) collider: ColliderHandle,
    pub(super) vertices: Vec<Vec3>,
    pub(super) triangles: Vec<[u32; 3]>,
}

pub(super) fn body_mesh(
    shape: &dyn rapier3d::parry::shape::Shape,
) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
    if let Some(s) = shape.as_ball() {
        return Some(s.to_trimesh(20, 40));
    }
    if let Some(s) = shape.as_cuboid() {
        return Some(s.to_trimesh());
    }
    if let Some(s) = shape.as_capsule() {
        return Some(s.to_trimesh(20, 12));
    }
    if let Some(s) = shape.as_cylinder() {
        return Some(s.to_trimesh(40));
    }
    if let Some(s) = shape.as_cone() {
        return Some(s.to_trimesh(40));
    }
    if let Some(s) = shape.as_convex_polyhedron() {
        return Some(s.to_trimesh());
    }
    if let Some(s) = shape.as_trimesh() {
        return Some((s.vertices().to_vec(), s.indices().to_vec()));
    }
    if let Some(s) = shape.as_heightfield() {
        return Some(s.to_trimesh());
    }
    None
}

/// A vertex or index buffer that grows as needed.
pub(super) struct Growing {
    pub(super) buffer: Option<wgpu::Buffer>,
    pub(super) usage: wgpu::BufferUsages,
    pub(super) label: &'static str,
}

impl Growing {
    pub(super) fn new(usage: wgpu::BufferUsages, label: &'static str) -> Self {
        Self {
            buffer: None,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            label,
        }
    }

    pub(super) fn write(&mut self, ctx: &GpuContext, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let size = bytes.len() as u64;
        if self.buffer.as_ref().is_none_or(|b| b.size() < size) {
            self.buffer = Some(ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: size.next_power_of_two().max(256),
                usage: self.usage,
                mapped_at_creation: false,
            }));
        }
        if let Some(b) = &self.buffer {
            ctx.queue.write_buffer(b, 0, bytes);
        }
    }
}

pub(super) struct Attachments {
    pub(super) size: (u32, u32),
    pub(super) colour: wgpu::TextureView,
    pub(super) depth: wgpu::TextureView,
}

/// One flat-shaded triangle (its face normal at each corner), on vertices of its own.
pub(super) fn push_flat(
    indices: &mut Vec<u32>,
    vertices: &mut Vec<Vertex>,
    tri: [Vec3; 3],
    colour: [f32; 3],
) {
    let [a, b, c] = tri;
    let normal = (b - a).cross(c - a).normalize_or_zero().to_array();
    for q in tri {
        indices.push(vertices.len() as u32);
        vertices.push(Vertex {
            position: q.to_array(),
            normal,
            colour,
        });
    }
}

/// The half-size of the marker drawn at each particle of a scene without triangles: a quarter
/// of the mean spring length (a tenth of the box's size without springs). None when the
/// scene has too many particles to mark.
pub(super) fn rope_marker(sim: &Simulation) -> Option<f32> {
    let packed = sim.packed();
    if packed.x.is_empty() || packed.x.len() > 20_000 {
        return None;
    }
    let n = packed.spring_count();
    if n > 0 {
        let mean = packed.all_springs().map(|s| s.rest).sum::<f64>() / n as f64;
        if mean > 0.0 {
            return Some((0.25 * mean) as f32);
        }
    }
    let (lo, hi) = bounds(sim);
    Some((0.02 * (hi - lo).length()).max(0.01))
}
