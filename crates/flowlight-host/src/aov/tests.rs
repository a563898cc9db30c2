//! The AOV pass on scenes whose AOVs are known in closed form.

use super::*;
use crate::intersector::BvhIntersector;
use flowlight_core::material::Material;

const W: u32 = 8;
const H: u32 = 6;

/// A scene of quads 100 wide in the planes z = const (two triangles each), one object per
/// quad: (z, material).
fn quads(quads: &[(f32, Material)]) -> Scene {
    let mut s = Scene::default();
    for (k, (z, m)) in quads.iter().enumerate() {
        let base = s.positions.len() as u32;
        let size = 50.0;
        // Counter-clockwise seen from +z (the pass turns normals to the ray anyway).
        let corners = [(-size, -size), (size, -size), (size, size), (-size, size)];
        for (x, y) in corners {
            s.positions.push(Vec3::new(x, y, *z));
        }
        s.triangles.push([base, base + 1, base + 2]);
        s.triangles.push([base, base + 2, base + 3]);
        s.triangle_material.extend([k as u32, k as u32]);
        s.triangle_emitter.extend([-1, -1]);
        s.materials.push(*m);
        s.material_names.push(format!("m{k}"));
        s.object_first_virtual.push(2 * k as u32);
    }
    s
}

fn camera() -> Camera {
    Camera::look_along(Vec3::ZERO, -Vec3::Z, Vec3::Y, 60.0, W, H)
}

fn run(scene: &Scene, spp: u32) -> AovImages {
    run_with(scene, &camera(), spp)
}

fn run_with(scene: &Scene, camera: &Camera, spp: u32) -> AovImages {
    let (bvh, _) = BvhIntersector::build(scene);
    let req = AovRequest {
        aovs: Aov::ALL.to_vec(),
        spp,
        seed: 1,
        threads: 2,
    };
    render_aovs(scene, &bvh, camera, &req, &AtomicBool::new(false)).unwrap()
}

fn diffuse(c: Rgb) -> Material {
    Material {
        base_color: c,
        specular: 0.0,
        ..Material::default()
    }
}

/// The mean over a pixel's samples of `f` of the camera ray's direction (the pass's
/// positions, computed here independently of it).
fn pixel_mean(x: u32, y: u32, spp: u32, f: impl Fn(Vec3) -> Vec3) -> Vec3 {
    let cam = camera();
    let mut sum = Vec3::ZERO;
    for i in 0..spp {
        let r = cam.generate_ray(Vec2::new(x as f32, y as f32) + sample_offset(i));
        sum += f(r.dir);
    }
    sum / spp as f32
}

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).abs().max_element() <= tol * b.abs().max_element().max(1.0)
}

/// A diffuse plane z = −2 in front of a pinhole at the origin: depth is 2/cos θ along each
/// ray, position the ray's point at that distance, normal +z, albedo the base colour, ids
/// the plane's, all averaged over the pixel's samples (ids from the centre sample).
#[test]
fn a_plane_has_its_analytic_depth_position_normal_and_albedo() {
    let base = Rgb::new(0.7, 0.4, 0.2);
    let scene = quads(&[(-2.0, diffuse(base))]);
    let spp = 5;
    let img = run(&scene, spp);
    let at = |aov: Aov, i: usize| {
        let c = img.layer(aov).unwrap();
        Vec3::new(c[0][i], c[1][i], c[2][i])
    };
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            let depth = pixel_mean(x, y, spp, |d| Vec3::splat(2.0 / -d.z));
            let position = pixel_mean(x, y, spp, |d| d * (2.0 / -d.z));
            assert!(
                close(at(Aov::Depth, i), depth, 1e-5),
                "{x},{y}: depth {:?} vs {depth:?}",
                at(Aov::Depth, i)
            );
            assert!(
                close(at(Aov::Position, i), position, 1e-5),
                "{x},{y}: {:?} vs {position:?}",
                at(Aov::Position, i)
            );
            assert!(
                close(at(Aov::Normal, i), Vec3::Z, 1e-6),
                "{:?}",
                at(Aov::Normal, i)
            );
            let a = at(Aov::Albedo, i);
            assert!(
                close(a, Vec3::new(base.r, base.g, base.b), 1e-6),
                "albedo {a:?}"
            );
            assert_eq!(at(Aov::MaterialId, i), Vec3::ZERO);
            assert_eq!(at(Aov::ObjectId, i), Vec3::ZERO);
        }
    }
    // Depth differs between the centre and the corner pixels, as 1/cos θ does.
    assert!(at(Aov::Depth, 0).x > at(Aov::Depth, (H / 2 * W + W / 2) as usize).x + 0.05);
}

/// Through a white mirror (metallic, roughness 0) the AOVs are those of the wall it
/// reflects: its albedo, its normal turned to the ray, its material and object, and the
/// depth the whole path (2 to the mirror, 4 back to the wall at z = +2).
#[test]
fn a_mirror_shows_the_aovs_of_what_it_reflects() {
    let wall = Rgb::new(0.2, 0.5, 0.7);
    let mirror = Material {
        base_color: Rgb::ONE,
        metallic: 1.0,
        roughness: 0.0,
        ..Material::default()
    };
    let scene = quads(&[(-2.0, mirror), (2.0, diffuse(wall))]);
    let spp = 3;
    let img = run(&scene, spp);
    let albedo = img.pixels(Aov::Albedo).unwrap();
    let normal = img.layer(Aov::Normal).unwrap();
    let depth = img.layer(Aov::Depth).unwrap();
    let material = img.layer(Aov::MaterialId).unwrap();
    let object = img.layer(Aov::ObjectId).unwrap();
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            let a = albedo[i];
            for (got, want) in [(a.r, wall.r), (a.g, wall.g), (a.b, wall.b)] {
                assert!(
                    (got - want).abs() < 1e-5,
                    "{x},{y}: albedo {a:?} vs the wall's {wall:?}"
                );
            }
            let n = Vec3::new(normal[0][i], normal[1][i], normal[2][i]);
            assert!(close(n, -Vec3::Z, 1e-6), "{n:?}");
            let d = pixel_mean(x, y, spp, |d| Vec3::splat(6.0 / -d.z)).x;
            assert!((depth[0][i] - d).abs() < 1e-4 * d, "{} vs {d}", depth[0][i]);
            assert_eq!((material[0][i], object[0][i]), (1.0, 1.0));
        }
    }
}

/// A ray that leaves the scene gives zeros and ids −1; the mirror itself with nothing to
/// reflect is such a ray.
#[test]
fn misses_are_zero_with_no_id() {
    let mirror = Material {
        base_color: Rgb::ONE,
        metallic: 1.0,
        roughness: 0.0,
        ..Material::default()
    };
    let img = run(&quads(&[(-2.0, mirror)]), 2);
    for (aov, channels) in &img.layers {
        let want = match aov {
            Aov::MaterialId | Aov::ObjectId => -1.0,
            _ => 0.0,
        };
        assert!(channels.iter().flatten().all(|&v| v == want), "{aov:?}");
    }
}

/// The sample positions cover the pixel evenly (the box filter): their mean is near the
/// centre and they fill each quarter of it.
#[test]
fn sample_positions_fill_the_pixel() {
    let n = 16;
    let pts: Vec<Vec2> = (0..n).map(sample_offset).collect();
    assert_eq!(pts[0], Vec2::splat(0.5));
    let mean = pts.iter().sum::<Vec2>() / n as f32;
    assert!(
        (mean - Vec2::splat(0.5)).abs().max_element() < 0.1,
        "{mean:?}"
    );
    for qx in 0..2 {
        for qy in 0..2 {
            let inside = pts
                .iter()
                .filter(|p| (p.x >= 0.5) == (qx == 1) && (p.y >= 0.5) == (qy == 1))
                .count();
            assert!((3..=5).contains(&inside), "quarter {qx},{qy}: {inside}");
        }
    }
    assert!(pts
        .iter()
        .all(|p| p.x >= 0.0 && p.x < 1.0 && p.y >= 0.0 && p.y < 1.0));
}

/// Under a thin lens the AOV rays start on the lens: a plane at z = −2 seen through a lens of
/// radius 0.5 focused at 0.5 is hit at 4q − 3p (q on the focus plane, p on the lens), whose
/// mean over the symmetric lens is the pinhole's point (within the noise of 256 lens samples,
/// σ ≈ 0.05 per axis) but whose mean distance is longer. A
/// pass that ignored the lens would give the pinhole's depth; a vanishing lens gives it.
#[test]
fn the_aov_rays_sample_the_thin_lens() {
    let scene = quads(&[(-2.0, diffuse(Rgb::splat(0.5)))]);
    let spp = 256;
    let pinhole = run(&scene, spp);
    let blurred = run_with(&scene, &camera().with_thin_lens(0.5, 0.5), spp);
    let tiny = run_with(&scene, &camera().with_thin_lens(1e-6, 0.5), spp);
    let depth = |img: &AovImages| img.layer(Aov::Depth).unwrap()[0].clone();
    let position = |img: &AovImages| img.pixels(Aov::Position).unwrap();
    let (d0, d1, d2) = (depth(&pinhole), depth(&blurred), depth(&tiny));
    let (p0, p1) = (position(&pinhole), position(&blurred));
    for i in 0..(W * H) as usize {
        assert!(
            d1[i] > 1.05 * d0[i],
            "pixel {i}: depth {} vs pinhole {}",
            d1[i],
            d0[i]
        );
        assert!(
            (d2[i] - d0[i]).abs() < 1e-4 * d0[i],
            "pixel {i}: {} vs {}",
            d2[i],
            d0[i]
        );
        let (a, b) = (
            Vec3::new(p1[i].r, p1[i].g, p1[i].b),
            Vec3::new(p0[i].r, p0[i].g, p0[i].b),
        );
        assert!(
            close(a, b, 0.125),
            "pixel {i}: position {a:?} vs pinhole {b:?}"
        );
    }
}
