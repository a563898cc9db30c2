//! A hand-built scene for the unit tests of the target function and the transition densities
//! (no tracer: both are functions of the stored paths alone).
//!
//! A Lambert floor material (albedo ½, no specular layer) and a mirror, an emissive triangle
//! (index 0) at height 2 facing down, a directional light (index 1) and a constant
//! environment (index 2).

use crate::measure::distant_vertex;
use flowlight_core::camera::Camera;
use flowlight_core::light::{light_powers, Emitter, Environment, Lights, PunctualLight};
use flowlight_core::material::Material;
use flowlight_core::path::{NodeType, Path, PathVertex};
use flowlight_core::sampling::build_cdf;
use flowlight_core::Rgb;
use flowlight_sdk::Scene;
use glam::{Vec2, Vec3};

pub const ALBEDO: f32 = 0.5;
pub const LAMP: f32 = 3.0;
pub const SUN: f32 = 2.0;
pub const SKY: f32 = 0.7;
pub const AREA: usize = 0;
pub const SUN_INDEX: usize = 1;
pub const SKY_INDEX: usize = 2;
pub const MIRROR: u32 = 1;

/// The direction the sun's light travels along.
pub fn sun_travel() -> Vec3 {
    Vec3::new(0.3, -1.0, 0.2).normalize()
}

pub fn scene() -> Scene<'static> {
    let materials: &'static [Material] = Box::leak(Box::new([
        Material {
            base_color: Rgb::splat(ALBEDO),
            specular: 0.0,
            ..Default::default()
        },
        Material {
            base_color: Rgb::ONE,
            metallic: 1.0,
            roughness: 0.0,
            ..Default::default()
        },
    ]));
    let (p0, p1, p2) = (
        Vec3::new(-1.0, 2.0, -1.0),
        Vec3::new(1.0, 2.0, -1.0),
        Vec3::new(0.0, 2.0, 1.0),
    );
    let emitters: &'static [Emitter] = Box::leak(Box::new([Emitter {
        p0,
        p1,
        p2,
        n: -Vec3::Y,
        area: 2.0,
        radiance: Rgb::splat(LAMP),
        double_sided: 0,
        prim: 7,
        material: u32::MAX,
        uv0: [Vec2::ZERO; 3],
        uv1: [Vec2::ZERO; 3],
        color: [Rgb::ONE; 3],
        vertex_colored: 0,
    }]));
    let punctual: &'static [PunctualLight] = Box::leak(Box::new([PunctualLight::directional(
        sun_travel(),
        Rgb::splat(SUN),
    )]));
    let environment = Environment::constant(Rgb::splat(SKY));
    let cdf = build_cdf(&light_powers(emitters, punctual, &environment, 3.0)).unwrap();
    let cdf: &'static [f32] = Box::leak(cdf.into_boxed_slice());
    Scene {
        camera: Camera::look_along(Vec3::new(0.0, 1.0, 2.0), -Vec3::Z, Vec3::Y, 60.0, 16, 16),
        materials,
        textures: &[],
        lights: Lights {
            emitters,
            punctual,
            environment,
            power_cdf: cdf,
            // Emission falls back to the emitter's stored radiance (no material table entry).
            materials: &[],
            textures: &[],
        },
        bounds_min: Vec3::splat(-3.0),
        bounds_max: Vec3::splat(3.0),
        mesh: Default::default(),
        material_bsdfs: &[],
        light_bound: None,
    }
    .with_light_bound()
}

/// A floor vertex at `p` (normal +Y) scattered diffusely.
pub fn floor(p: Vec3) -> PathVertex {
    let mut v = PathVertex::eye(p, Vec3::Y);
    v.node = NodeType::DiffuseReflection;
    v.material = 0;
    v.prim = 0;
    v
}

/// A mirror vertex at `p` with normal `n`.
pub fn mirror(p: Vec3, n: Vec3) -> PathVertex {
    let mut v = PathVertex::eye(p, n);
    v.node = NodeType::SpecularReflection;
    v.material = MIRROR;
    v.prim = 1;
    v
}

/// A point of the emitting triangle.
pub fn lamp(p: Vec3) -> PathVertex {
    let mut v = PathVertex::eye(p, -Vec3::Y);
    v.node = NodeType::Light;
    v.material = u32::MAX;
    v.emitter = AREA as i32;
    v.prim = 7;
    v
}

/// The sun's vertex seen from `from`.
pub fn sun(from: Vec3) -> PathVertex {
    distant_vertex(from, -sun_travel(), SUN_INDEX)
}

/// The sky's vertex in direction `dir` seen from `from`.
pub fn sky(from: Vec3, dir: Vec3) -> PathVertex {
    distant_vertex(from, dir.normalize(), SKY_INDEX)
}

/// A path of these vertices, the eye first, on film window `k` at raster (8, 8).
pub fn path(vertices: &[PathVertex], k: u32) -> Path {
    let mut p = Path::empty();
    p.raster = Vec2::new(8.0, 8.0);
    p.film_window = k;
    p.vertex_count = vertices.len() as u32;
    p.vertices[..vertices.len()].copy_from_slice(vertices);
    p
}

/// The eye vertex of the scene's camera.
pub fn eye() -> PathVertex {
    PathVertex::eye(Vec3::new(0.0, 1.0, 2.0), -Vec3::Z)
}
