//! Tests against the Embree library: the 4.4 layouts, hits, batches and packets.

use super::*;
use embree4_sys::RTCRay;
use flowlight_core::geometry::Ray;
use flowlight_core::mesh::CompactHit;
use glam::Vec3;

fn quad() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    (
        vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

#[test]
fn device_is_embree_4_4() {
    let d = device().unwrap();
    assert!(
        d.version >= 40400,
        "{} from {}",
        d.version_string(),
        d.library
    );
}

#[test]
fn hits_and_barycentrics_and_t_range() {
    let (p, t) = quad();
    let s = EmbreeScene::build(&p, &t, SceneOptions::default()).unwrap();
    let ray = Ray {
        origin: Vec3::new(0.5, -0.25, -2.0),
        dir: Vec3::Z,
        t_max: f32::INFINITY,
    };
    let h = s.intersect(&ray).unwrap();
    assert_eq!(h.prim, 0);
    assert!((h.t - 2.0).abs() < 1e-6);
    let q = p[0] * (1.0 - h.b1 - h.b2) + p[1] * h.b1 + p[2] * h.b2;
    assert!((q - Vec3::new(0.5, -0.25, 0.0)).length() < 1e-6, "{q}");
    assert!(s.occluded(&ray));
    // A hit beyond t_max is not one. Whether a hit exactly at t_max counts differs
    // between Embree's ISA kernels (AVX2 and AVX-512 builds disagree), so nothing in the
    // renderer relies on it: shadow rays stop short of their target by the spawn offset.
    let short = Ray {
        t_max: 1.9999,
        ..ray
    };
    assert!(s.intersect(&short).is_none());
    assert!(!s.occluded(&short));
    let longer = Ray {
        t_max: 2.0001,
        ..ray
    };
    assert!(s.intersect(&longer).is_some());
    // Behind the origin: no hit.
    let away = Ray {
        dir: -Vec3::Z,
        ..ray
    };
    assert!(s.intersect(&away).is_none());
}

#[test]
fn the_library_writes_the_4_4_hit_layout() {
    // The library writes instPrimID right after instID: byte 80..84 of RTCRayHit, past
    // the end of embree4-sys's 80-byte (4.2) struct.
    let (p, t) = quad();
    let s = EmbreeScene::build(&p, &t, SceneOptions::default()).unwrap();
    #[repr(C, align(16))]
    struct Buf([u8; 128]);
    let mut buf = Buf([0xAB; 128]);
    let ray = EmbreeScene::embree_ray(&Ray {
        origin: Vec3::new(0.5, -0.25, -2.0),
        dir: Vec3::Z,
        t_max: f32::INFINITY,
    });
    unsafe {
        std::ptr::write(buf.0.as_mut_ptr() as *mut RTCRay, ray);
        s.intersect_raw(buf.0.as_mut_ptr());
    }
    let geom = u32::from_ne_bytes(buf.0[72..76].try_into().unwrap());
    assert_eq!(geom, 0, "geomID at the 4.2 offset");
    let written: Vec<usize> = (80..128).filter(|&i| buf.0[i] != 0xAB).collect();
    assert_eq!(
        written,
        vec![80, 81, 82, 83],
        "bytes written past the 4.2 RTCRayHit"
    );
}

/// A bumpy sphere of 2·n·(n−1) triangles.
fn bumpy_sphere(n: usize) -> Vec<[Vec3; 3]> {
    let at = |i: usize, j: usize| {
        let (th, ph) = (
            std::f32::consts::PI * i as f32 / n as f32,
            std::f32::consts::TAU * j as f32 / n as f32,
        );
        let r = 1.0 + 0.1 * (5.0 * th).sin() * (3.0 * ph).cos();
        Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r
    };
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            if i > 0 {
                tris.push([a, b, d]);
            }
            if i + 1 < n {
                tris.push([b, c, d]);
            }
        }
    }
    tris
}

/// Camera rays through a 61 × 61 grid (not a multiple of 16: partial packets), then
/// incoherent rays with random `t_max`, some of them 0, negative or NaN.
fn batch_rays() -> Vec<Ray> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut u = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut rays: Vec<Ray> = (0..61 * 61)
        .map(|i| {
            let (x, y) = ((i % 61) as f32 / 60.0 - 0.5, (i / 61) as f32 / 60.0 - 0.5);
            Ray::new(
                Vec3::new(0.0, 0.0, 4.0),
                Vec3::new(x, y, -1.5).normalize(),
                f32::INFINITY,
            )
        })
        .collect();
    for i in 0..3001 {
        let o = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * 6.0;
        let d = (Vec3::new(u(), u(), u()) - 0.5 - o * 0.1).normalize();
        let t_max = match i % 97 {
            0 => 0.0,
            1 => -1.0,
            2 => f32::NAN,
            _ if u() < 0.5 => f32::INFINITY,
            _ => 4.0 * u(),
        };
        rays.push(Ray::new(o, d, t_max));
    }
    rays
}

#[test]
fn batches_return_exactly_the_single_ray_answers() {
    let tris = bumpy_sphere(40);
    let rays = batch_rays();
    let bits = |h: CompactHit| (h.t.to_bits(), h.prim, h.b1.to_bits(), h.b2.to_bits());
    for packets in [Packets::Always, Packets::Never] {
        let options = SceneOptions {
            packets,
            ..SceneOptions::default()
        };
        let s = EmbreeScene::build_soup(&tris, options).unwrap();
        assert_eq!(s.uses_packets(), packets == Packets::Always);
        let mut hits = vec![CompactHit::MISS; rays.len()];
        s.intersect_batch(&rays, &mut hits);
        let mut blocked = vec![7u8; rays.len()];
        s.occluded_batch(&rays, &mut blocked);
        let (mut n_hit, mut n_blocked) = (0, 0);
        for (i, ray) in rays.iter().enumerate() {
            let want = s.intersect(ray).map_or(CompactHit::MISS, CompactHit::from);
            assert_eq!(bits(hits[i]), bits(want), "{packets:?}, ray {i}: {ray:?}");
            assert_eq!(
                blocked[i],
                u8::from(s.occluded(ray)),
                "{packets:?}, ray {i}"
            );
            n_hit += want.is_hit() as usize;
            n_blocked += blocked[i] as usize;
        }
        assert!(
            n_hit > 1500 && n_blocked >= n_hit,
            "{n_hit} hits, {n_blocked} blocked"
        );
    }
}

#[test]
fn packets_follow_the_scene_size() {
    assert!(Packets::Auto.resolve(38));
    assert!(Packets::Auto.resolve(PACKET_MAX_TRIANGLES));
    assert!(!Packets::Auto.resolve(PACKET_MAX_TRIANGLES + 1));
    assert!(Packets::Always.resolve(10_000_000));
    assert!(!Packets::Never.resolve(1));
    assert_eq!(Packets::parse("auto"), Ok(Packets::Auto));
    assert_eq!(Packets::parse("always"), Ok(Packets::Always));
    assert!(Packets::parse("1").is_err(), "no undocumented aliases");
    assert_eq!(Packets::parse("never"), Ok(Packets::Never));
    assert!(Packets::parse("sometimes")
        .unwrap_err()
        .contains("auto, always or never"));
    let big = bumpy_sphere(40);
    let s = EmbreeScene::build_soup(&big[..8], SceneOptions::default()).unwrap();
    assert!(s.uses_packets(), "a small scene takes packets by default");
}
