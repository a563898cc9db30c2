//! The bend of a normal-mapped shading normal that keeps the viewer's mirror reflection above
//! the surface (`flowlight_core::specular_normal`) applies to metals only: a dielectric keeps
//! its mapped normal, so that its diffuse shading is what it was.

use flowlight_core::geometry::Ray;
use flowlight_scene::gltf_loader::load_gltf;
use flowlight_testkit::gltf::{png8, temp_dir, Quad};
use glam::Vec3;
use std::collections::BTreeMap;

/// The shading normal at the quad's point (0.5, 0.3) seen from `from`, for a normal map
/// tilting the normal 60° towards +X and the given metallic factor.
fn shading_normal(metallic: f32, from: Vec3, tag: &str) -> Vec3 {
    let (s, c) = 60f32.to_radians().sin_cos();
    let t = [s, 0.0, c].map(|x: f32| ((x + 1.0) * 0.5 * 255.0).round() as u8);
    let q = Quad {
        images: vec![png8(1, 1, 3, &t)],
        textures: r#"{"source": 0}"#.into(),
        material: format!(
            r#"{{"pbrMetallicRoughness": {{"metallicFactor": {metallic}}}, "normalTexture": {{"index": 0}}}}"#
        ),
        ..Quad::default()
    };
    let dir = temp_dir(tag);
    let s = load_gltf(&q.write(&dir, "q.gltf"), &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"));
    // Point (0.5, 0.3) lies in triangle 0 (x ≥ y) at barycentrics (x − y, y).
    let from = from.normalize();
    let ray = Ray::new(Vec3::new(0.5, 0.3, 0.0) + from, -from, f32::INFINITY);
    s.surface_hit(&ray, 1.0, 0, 0.2, 0.3).ns
}

#[test]
fn only_a_metal_gets_the_bent_normal() {
    // Straight down: the mirror reflection about a 60° tilt points 120° from +Z, below.
    let wo = Vec3::Z;
    let reflect = |n: Vec3| n * (2.0 * n.dot(wo)) - wo;
    let metal = shading_normal(1.0, wo, "bend-metal");
    assert!((reflect(metal).z - 0.01).abs() < 2e-3, "{metal}");
    let dielectric = shading_normal(0.0, wo, "bend-dielectric");
    let tilt = dielectric.z.acos().to_degrees();
    assert!((tilt - 60.0).abs() < 0.5, "{dielectric}: {tilt}°");
    assert!(reflect(dielectric).z < 0.0);
}
