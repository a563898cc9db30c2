//! The end of a load: attributes no primitive had are dropped, the emissive triangles become
//! [`Emitter`]s (each stored triangle once, then placed once per instance of its mesh, in
//! world space), the emitter power CDF is built and the load statistics are logged.

use super::limits::warn_if_beyond_f32_range;
use super::Loader;
use crate::error::SceneError;
use crate::lights::{emission_strata, mean_emission};
use crate::scene::{triangle_area, triangle_normal, Scene};
use flowlight_core::light::Emitter;
use flowlight_core::sampling::build_cdf;
use flowlight_core::Rgb;
use glam::{Vec2, Vec3};

impl Loader<'_> {
    pub(super) fn finish(mut self) -> Result<Scene, SceneError> {
        let file = self.file();
        let scene = &mut self.scene;
        // Attributes no primitive had take no memory, and a hit reads none of them (a scan
        // without normals or texture coordinates: three cache lines fewer each, per hit).
        if !self.any_normal {
            scene.normals = Vec::new();
        }
        if !self.any_uv0 {
            scene.uvs = Vec::new();
        }
        if !self.any_uv1 {
            scene.uvs1 = Vec::new();
        }
        if !self.any_color {
            scene.colors = Vec::new();
        }
        if !self.any_tangent {
            scene.tangents = Vec::new();
        }
        scene.sync_texture_views();
        if scene.triangles.is_empty() {
            return Err(SceneError::NoTriangles { file });
        }
        warn_if_beyond_f32_range(&file, scene);
        for name in self.overrides.keys() {
            if !scene.material_names.contains(name) {
                tracing::warn!(file = %file.display(), "material override '{name}' matches no loaded material");
            }
        }
        place_emitters(scene);
        if !scene.emitters.is_empty() {
            let powers: Vec<f32> = scene.emitters.iter().map(Emitter::power).collect();
            scene.emitter_power_cdf = build_cdf(&powers).ok_or_else(|| SceneError::Primitive {
                file: file.clone(),
                reason: "the emitters' total power is not finite".into(),
            })?;
        }
        log_stats(&file, scene);
        self.scene.files = self.src.referenced_files();
        Ok(self.scene)
    }
}

/// Makes the emissive triangles [`Emitter`]s: each stored emissive triangle once (its
/// radiance, texture included, does not depend on where it is placed), ranked within its
/// mesh, then placed once per instance of its mesh, in world space, naming its virtual
/// triangle. Triangles whose mean emission is black are counted and left out.
fn place_emitters(scene: &mut Scene) {
    scene.triangle_emitter = vec![-1; scene.triangles.len()];
    // Each stored emissive triangle once (its radiance does not depend on where it is
    // placed), ranked within its mesh ...
    let views = scene.texture_views();
    let mut mesh_emitters: Vec<Vec<(usize, Emitter)>> = vec![Vec::new(); scene.meshes.len()];
    for (mi, range) in scene.meshes.iter().enumerate() {
        let first = range.first_triangle as usize;
        for prim in first..first + range.triangle_count as usize {
            let tri = scene.triangles[prim];
            let material = scene.triangle_material[prim];
            let m = &scene.materials[material as usize];
            if !m.is_emissive() {
                continue;
            }
            let [p0, p1, p2] = tri.map(|i| scene.positions[i as usize]);
            let uv = tri.map(|i| scene.uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO));
            // TEXCOORD_1 takes memory only when some primitive has it.
            let uv1 = if scene.uvs1.is_empty() {
                uv
            } else {
                tri.map(|i| scene.uvs1[i as usize])
            };
            let mut e = Emitter {
                p0,
                p1,
                p2,
                n: triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z),
                area: triangle_area(p0, p1, p2) as f32,
                radiance: m.emission,
                double_sided: m.two_sided_emission,
                prim: prim as u32,
                material,
                uv0: uv,
                uv1,
                color: [Rgb::ONE; 3],
                vertex_colored: 0,
            };
            // An unlit material's colour is base colour × COLOR_0 (`crate::unlit`).
            let unlit = scene.unlit_materials.get(material as usize) == Some(&true);
            if unlit && !scene.colors.is_empty() {
                e.color = tri.map(|i| {
                    let [r, g, b, _] = scene.colors[i as usize];
                    Rgb::new(r, g, b)
                });
                e.vertex_colored = 1;
            }
            let strata = emission_strata(&e, &m.emissive_texture, &views);
            e.radiance = mean_emission(strata, |b| e.emission_at(b, &scene.materials, &views));
            if e.radiance.is_black() || e.power() <= 0.0 {
                scene.stats.black_emitters += 1;
                continue;
            }
            scene.triangle_emitter[prim] = mesh_emitters[mi].len() as i32;
            mesh_emitters[mi].push((prim, e));
        }
    }
    // ... then placed once per instance: each instance of an emissive mesh is its own
    // light, in world space, naming its virtual triangle.
    for inst in scene.instances.iter_mut() {
        inst.first_emitter = scene.emitters.len() as u32;
        for &(prim, e) in &mesh_emitters[inst.mesh as usize] {
            let local = (prim - inst.first_triangle as usize) as u32;
            let mut e = e;
            e.prim = inst.first_virtual + local;
            if !inst.identity {
                let m = inst.object_to_world;
                let (mut p, mut uv0, mut uv1) = ([e.p0, e.p1, e.p2], e.uv0, e.uv1);
                if inst.mirror {
                    p.swap(1, 2);
                    uv0.swap(1, 2);
                    uv1.swap(1, 2);
                    e.color.swap(1, 2);
                }
                let [p0, p1, p2] = p.map(|q| m.transform_point3(q));
                e.p0 = p0;
                e.p1 = p1;
                e.p2 = p2;
                e.uv0 = uv0;
                e.uv1 = uv1;
                e.n = triangle_normal(p0, p1, p2).unwrap_or(Vec3::Z);
                e.area = triangle_area(p0, p1, p2) as f32;
            }
            scene.emitters.push(e);
        }
    }
}

/// Fills the triangle and vertex counts of the load statistics and logs them (the dropped
/// triangles as a warning).
fn log_stats(file: &std::path::Path, scene: &mut Scene) {
    let virtual_triangles = scene.virtual_triangle_count();
    let s = &mut scene.stats;
    s.triangles = scene.triangles.len();
    s.vertices = scene.positions.len();
    s.virtual_triangles = virtual_triangles;
    if s.degenerate_dropped > 0 {
        tracing::warn!(
            file = %file.display(),
            "dropped {} degenerate triangles ({} zero-area, {} non-finite, {} repeated-index; {} of them emissive)",
            s.degenerate_dropped, s.dropped_zero_area, s.dropped_non_finite, s.dropped_repeated_index, s.dropped_emitters
        );
    }
    tracing::info!(
        file = %file.display(),
        "loaded {} triangles, {} vertices, {} materials, {} textures, {} emitters, {} punctual lights",
        s.triangles, s.vertices, scene.materials.len(), scene.textures.len(), scene.emitters.len(), scene.punctual_lights.len()
    );
    if s.instanced_placements > 0 {
        tracing::info!(
            file = %file.display(),
            "instancing: {} placements of {} meshes stored once show {} triangles",
            s.instanced_placements, scene.meshes.len() - usize::from(scene.instances[0].identity), s.virtual_triangles
        );
    }
}
