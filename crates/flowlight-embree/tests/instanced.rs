//! Embree's two-level scene (RTC_GEOMETRY_TYPE_INSTANCE) against flowlight-bvh's TwoLevelBvh
//! on random instanced scenes: same hits up to rounding, same instance and triangle ids.

use flowlight_bvh::{Bvh, Instance, TwoLevelBvh};
use flowlight_core::geometry::InstanceHit;
use flowlight_core::geometry::Ray;
use flowlight_core::rng::Rng;
use flowlight_embree::{EmbreeInstancedScene, Packets, SceneOptions};
use glam::{Mat4, Quat, Vec3};

fn v(rng: &mut Rng) -> Vec3 {
    Vec3::new(rng.uniform(), rng.uniform(), rng.uniform())
}

fn dir(rng: &mut Rng) -> Vec3 {
    loop {
        let d = v(rng) * 2.0 - 1.0;
        if d.length_squared() > 1e-4 && d.length_squared() <= 1.0 {
            return d.normalize();
        }
    }
}

/// A unit cube (12 triangles) and a soup of 100 random triangles in the unit box.
fn meshes(rng: &mut Rng) -> Vec<(Vec<Vec3>, Vec<[u32; 3]>)> {
    let cube_v: Vec<Vec3> = (0..8)
        .map(|c| Vec3::new((c & 1) as f32, (c >> 1 & 1) as f32, (c >> 2 & 1) as f32))
        .collect();
    let cube_f = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    let mut soup_v = Vec::new();
    for _ in 0..100 {
        let c = v(rng);
        for _ in 0..3 {
            soup_v.push(c + (v(rng) - 0.5) * 0.4);
        }
    }
    let soup_f = (0..100u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    vec![(cube_v, cube_f), (soup_v, soup_f)]
}

/// 50 placements of the two meshes, a tenth of them mirrored.
fn placements(rng: &mut Rng) -> Vec<(u32, Mat4)> {
    (0..50)
        .map(|i| {
            let mut s = Vec3::new(0.3, 0.3, 0.3) + v(rng) * 2.5;
            if i % 5 == 0 {
                s.y = -s.y;
            }
            let m = Mat4::from_scale_rotation_translation(
                s,
                Quat::from_axis_angle(dir(rng), rng.uniform() * std::f32::consts::TAU),
                (v(rng) - 0.5) * 30.0,
            );
            ((i % 2) as u32, m)
        })
        .collect()
}

/// Batches through instances, by 8-lane packets and by single rays, give exactly the
/// single-ray answers: the same t, instance, triangle and barycentrics bit for bit.
#[test]
fn instanced_batches_return_exactly_the_single_ray_answers() {
    let mut rng = Rng::new(7, 1);
    let meshes = meshes(&mut rng);
    let instances = placements(&mut rng);
    let rays: Vec<Ray> = (0..4001)
        .map(|k| {
            let o = (v(&mut rng) - 0.5) * 50.0;
            let (m, x) = instances[rng.next_u32() as usize % instances.len()];
            let c = x.transform_point3(meshes[m as usize].0[0] + Vec3::splat(0.3));
            let d = if k % 2 == 0 {
                dir(&mut rng)
            } else {
                (c - o).normalize()
            };
            Ray::new(o, d, if k % 3 == 0 { 25.0 } else { f32::INFINITY })
        })
        .collect();
    let bits = |h: Option<InstanceHit>| {
        h.map(|h| {
            (
                h.t.to_bits(),
                h.instance,
                h.prim,
                h.b1.to_bits(),
                h.b2.to_bits(),
            )
        })
    };
    for packets in [Packets::Always, Packets::Never] {
        let options = SceneOptions {
            packets,
            ..SceneOptions::default()
        };
        let s = EmbreeInstancedScene::build(&meshes, &instances, options).unwrap();
        assert_eq!(s.uses_packets(), packets == Packets::Always);
        let mut got = vec![
            Some(InstanceHit {
                t: -1.0,
                instance: 0,
                prim: 0,
                b1: 0.0,
                b2: 0.0,
            });
            rays.len()
        ];
        let mut order = Vec::new();
        s.intersect_batch(&rays, |i, h| {
            order.push(i);
            got[i] = h;
        });
        assert!(
            order.iter().copied().eq(0..rays.len()),
            "{packets:?}: every ray once, in order"
        );
        let mut blocked = vec![7u8; rays.len()];
        s.occluded_batch(&rays, &mut blocked);
        let mut hits = 0;
        for (i, ray) in rays.iter().enumerate() {
            let want = s.intersect(ray);
            assert_eq!(bits(got[i]), bits(want), "{packets:?}, ray {i}");
            assert_eq!(
                blocked[i],
                u8::from(s.occluded(ray)),
                "{packets:?}, ray {i}"
            );
            hits += want.is_some() as usize;
        }
        assert!(hits > 1000, "{packets:?}: only {hits} hits");
    }
}

#[test]
fn embree_instances_agree_with_the_two_level_bvh() {
    if let Err(e) = flowlight_embree::device() {
        panic!("Embree is provisioned by the build and must open: {e}");
    }
    let mut rng = Rng::new(42, 1);
    let meshes = meshes(&mut rng);
    let instances = placements(&mut rng);
    let embree = EmbreeInstancedScene::build(&meshes, &instances, SceneOptions::default()).unwrap();
    assert_eq!(embree.stored_triangle_count(), 112);
    assert_eq!(embree.instance_count(), 50);
    let bvhs = meshes
        .iter()
        .map(|(p, f)| {
            Bvh::build(
                &f.iter()
                    .map(|t| t.map(|i| p[i as usize]))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let two = TwoLevelBvh::build(
        bvhs,
        instances
            .iter()
            .map(|&(mesh, object_to_world)| Instance {
                mesh,
                object_to_world,
            })
            .collect(),
    )
    .unwrap();
    let n = 20_000;
    let (mut hits, mut mismatches) = (0, 0);
    for k in 0..n {
        let o = (v(&mut rng) - 0.5) * 50.0;
        let d = if k % 2 == 0 {
            dir(&mut rng)
        } else {
            let (m, x) = instances[rng.next_u32() as usize % instances.len()];
            let c = x.transform_point3(meshes[m as usize].0[0] + Vec3::splat(0.3));
            (c - o).normalize()
        };
        let ray = Ray::new(o, d, if k % 3 == 0 { 25.0 } else { f32::INFINITY });
        let a = embree.intersect(&ray);
        let b = two.intersect(&ray);
        assert_eq!(
            embree.occluded(&ray),
            a.is_some(),
            "ray {k}: occluded vs closest"
        );
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                hits += 1;
                let rel = (a.t - b.t).abs() / b.t.max(1e-3);
                if (a.instance, a.prim) == (b.instance, b.prim) {
                    assert!(rel < 1e-3, "ray {k}: t {} vs {}", a.t, b.t);
                } else if rel >= 1e-4 {
                    mismatches += 1;
                }
            }
            _ => mismatches += 1,
        }
    }
    assert!(hits > n / 4, "only {hits} hits");
    assert!(mismatches * 500 < n, "{mismatches} of {n} rays disagree");
}
