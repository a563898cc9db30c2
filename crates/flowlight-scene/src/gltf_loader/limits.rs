//! Limits checked before geometry is decoded (instance count, virtual triangle count, the
//! memory estimate against the memory available, [`crate::memory`]) and the warning for
//! coordinates beyond what f32 ray/triangle arithmetic takes.

use crate::error::SceneError;
use crate::scene::Scene;
use glam::Mat4;
use gltf::mesh::{Mode, Semantic};
use std::collections::HashMap;
use std::path::Path;

/// Most mesh instances a scene may have (nodes with a mesh plus `EXT_mesh_gpu_instancing`
/// placements): 2²⁴. Each costs about [`BYTES_PER_INSTANCE`] in the scene, the two-level
/// BVH and Embree's instance geometry.
pub const MAX_INSTANCES: u64 = 1 << 24;
/// Most triangles a scene may show, every instance's counted: virtual triangle ids are
/// `u32`, and `u32::MAX` means "no triangle".
pub const MAX_VIRTUAL_TRIANGLES: u64 = u32::MAX as u64 - 1;
/// Estimated resident bytes per stored triangle: its vertices' attributes and indices in the
/// scene, and the BVH's or Embree's copy and nodes. Measured on a sphere with unshared
/// vertices (three per triangle, the worst case): 133 bytes in the scene, 147 in the BVH,
/// 145 in Embree (`examples/instancing_memory.rs` of the host).
pub const BYTES_PER_STORED_TRIANGLE: u64 = 280;
/// Estimated resident bytes per instance: the scene's [`MeshInstance`](crate::scene::MeshInstance) (≈ 200), the
/// two-level BVH's entry and node (≈ 140) and Embree's instance geometry (a few hundred).
pub const BYTES_PER_INSTANCE: u64 = 512;

/// Triangles primitive `prim` will have, from its accessors' counts (nothing decoded).
fn primitive_triangles(prim: &gltf::Primitive) -> u64 {
    let Some(pos) = prim.get(&Semantic::Positions) else {
        return 0;
    };
    let n = prim.indices().map_or(pos.count(), |i| i.count()) as u64;
    match prim.mode() {
        Mode::Triangles => n / 3,
        Mode::TriangleStrip | Mode::TriangleFan => n.saturating_sub(2),
        _ => 0,
    }
}

/// Refuses, before any geometry is decoded, a scene whose instance count or instanced
/// (virtual) triangle count exceeds [`MAX_INSTANCES`] / [`MAX_VIRTUAL_TRIANGLES`], or whose
/// estimated geometry memory (stored triangles × [`BYTES_PER_STORED_TRIANGLE`] + instances ×
/// [`BYTES_PER_INSTANCE`]) exceeds the memory available ([`crate::memory`]: `MemAvailable`,
/// the memory cgroup's limit, `RLIMIT_AS`).
pub(super) fn check_instancing_limits(
    file: &Path,
    doc: &gltf::Document,
    placements: &[(usize, Vec<Mat4>)],
    uses: &HashMap<usize, usize>,
) -> Result<(), SceneError> {
    let mesh_tris: HashMap<usize, u64> = uses
        .keys()
        .filter_map(|&m| {
            let mesh = doc.meshes().nth(m)?;
            Some((m, mesh.primitives().map(|p| primitive_triangles(&p)).sum()))
        })
        .collect();
    let instances: u64 = placements.iter().map(|(_, t)| t.len() as u64).sum();
    let virtual_tris: u64 = placements
        .iter()
        .map(|(m, t)| mesh_tris.get(m).copied().unwrap_or(0) * t.len() as u64)
        .sum();
    // Every mesh is stored once: flattened when placed once, in local space otherwise.
    let stored: u64 = uses.keys().filter_map(|m| mesh_tris.get(m)).sum();
    let err = |reason: String| SceneError::Limit {
        file: file.to_path_buf(),
        reason,
    };
    if instances > MAX_INSTANCES {
        return Err(err(format!(
            "{instances} mesh instances exceed the limit of {MAX_INSTANCES}"
        )));
    }
    if virtual_tris > MAX_VIRTUAL_TRIANGLES {
        return Err(err(format!(
            "{instances} mesh instances show {virtual_tris} triangles, beyond the limit of {MAX_VIRTUAL_TRIANGLES} (32-bit triangle ids)"
        )));
    }
    let need = stored * BYTES_PER_STORED_TRIANGLE + instances * BYTES_PER_INSTANCE;
    if let Some(avail) = available_memory() {
        if need > avail {
            return Err(err(format!(
                "{stored} stored triangles and {instances} mesh instances need about {} MiB ({need} bytes) but {} MiB is available",
                need >> 20,
                avail >> 20
            )));
        }
    }
    Ok(())
}

use crate::memory::available_memory;

/// Largest coordinate magnitude the ray/triangle arithmetic takes without overflow: the
/// watertight test and the error bounds multiply three coordinates (x³ < f32::MAX ≈ 3.4e38).
pub const MAX_COORDINATE: f32 = 1e12;
/// Smallest scene extent whose triangle arithmetic stays clear of subnormal numbers (the
/// products of three edge lengths, 1e-38).
pub const MIN_EXTENT: f32 = 1e-12;

/// Logs one warning when the scene's coordinates are so large, or its extent so small, that
/// f32 ray tracing loses hits (issue: a Cornell box scaled to 1e14 rendered black with the
/// BVH and lost its lamp with Embree, silently).
pub(super) fn warn_if_beyond_f32_range(file: &Path, scene: &Scene) {
    let Some((lo, hi)) = scene.bounds() else {
        return;
    };
    let largest = lo.abs().max(hi.abs()).max_element();
    let extent = (hi - lo).max_element();
    if largest > MAX_COORDINATE {
        tracing::warn!(
            file = %file.display(),
            "coordinates reach {largest:e}, beyond {MAX_COORDINATE:e}: f32 ray/triangle arithmetic overflows there and hits are lost; scale the scene down (e.g. a root node with scale {:e})",
            MAX_COORDINATE / largest
        );
    } else if extent < MIN_EXTENT {
        tracing::warn!(
            file = %file.display(),
            "the scene is {extent:e} across, below {MIN_EXTENT:e}: f32 ray/triangle arithmetic underflows and hits are lost; scale the scene up"
        );
    }
}
