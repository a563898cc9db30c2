//! Intersectors and the host's answer to plugins' ray queries.

use flowlight_bvh::{Bvh, HitFilter, TriangleHit};
use flowlight_core::geometry::Ray;
use flowlight_scene::config::Intersector as IntersectorChoice;
use flowlight_scene::Scene;
use flowlight_sdk::abi::{HitRecord, TracerTable};
use std::ffi::c_void;
use std::time::{Duration, Instant};

/// A ray/triangle acceleration structure. Implementations answer queries from all host
/// threads at once.
pub trait Intersector: Send + Sync {
    fn name(&self) -> &'static str;
    fn intersect(&self, ray: &Ray) -> Option<TriangleHit>;
    fn occluded(&self, ray: &Ray) -> bool;
    /// Closest hit among those `accept` keeps (alpha MASK / BLEND).
    fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit>;
    /// Whether a hit that `accept` keeps lies on the ray.
    fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool;
}

/// The pure-Rust BVH backend.
pub struct BvhIntersector {
    bvh: Bvh,
}

impl BvhIntersector {
    pub fn build(scene: &Scene) -> (BvhIntersector, Duration) {
        let start = Instant::now();
        let bvh = Bvh::build(&scene.triangle_vertices());
        (BvhIntersector { bvh }, start.elapsed())
    }
}

impl Intersector for BvhIntersector {
    fn name(&self) -> &'static str {
        "bvh"
    }
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.bvh.intersect(ray)
    }
    #[inline]
    fn occluded(&self, ray: &Ray) -> bool {
        self.bvh.occluded(ray)
    }
    #[inline]
    fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        self.bvh.intersect_filtered(ray, accept)
    }
    #[inline]
    fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        self.bvh.occluded_filtered(ray, accept)
    }
}

/// The Embree 4 backend (`flowlight-embree`): one device per process, the scene committed
/// once, robust mode on by default; `FLOWLIGHT_EMBREE_QUALITY` (`low` | `medium` | `high`)
/// sets the build quality for large scenes.
pub struct EmbreeIntersector {
    scene: flowlight_embree::EmbreeScene,
}

impl EmbreeIntersector {
    pub fn build(scene: &Scene) -> Result<(EmbreeIntersector, Duration), String> {
        let options = flowlight_embree::SceneOptions::from_env()?;
        Self::build_with(scene, options)
    }

    /// Builds with `options`; the argument-filter flag is set when the scene has
    /// alpha-tested materials.
    pub fn build_with(
        scene: &Scene,
        mut options: flowlight_embree::SceneOptions,
    ) -> Result<(EmbreeIntersector, Duration), String> {
        options.hit_filter |= scene.has_alpha();
        // Opening the library and making the device is not part of the build time.
        flowlight_embree::device()?;
        let start = Instant::now();
        let s = flowlight_embree::EmbreeScene::build(&scene.positions, &scene.triangles, options)?;
        Ok((EmbreeIntersector { scene: s }, start.elapsed()))
    }
}

impl Intersector for EmbreeIntersector {
    fn name(&self) -> &'static str {
        "embree"
    }
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        self.scene.intersect(ray)
    }
    #[inline]
    fn occluded(&self, ray: &Ray) -> bool {
        self.scene.occluded(ray)
    }
    #[inline]
    fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        self.scene.intersect_filtered(ray, accept)
    }
    #[inline]
    fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        self.scene.occluded_filtered(ray, accept)
    }
}

/// Builds the intersector the config asks for, and reports its build time. `auto` takes
/// Embree when its library can be opened and builds the scene, else the BVH (saying why in
/// the log); `embree` is an error when Embree is not there.
pub fn build_intersector(
    kind: IntersectorChoice,
    scene: &Scene,
) -> Result<(Box<dyn Intersector>, Duration), String> {
    let options = flowlight_embree::SceneOptions::from_env()?;
    build_intersector_with(kind, scene, options)
}

/// [`build_intersector`] with explicit Embree scene options (the config's `build_quality`
/// and `robust`).
pub fn build_intersector_with(
    kind: IntersectorChoice,
    scene: &Scene,
    options: flowlight_embree::SceneOptions,
) -> Result<(Box<dyn Intersector>, Duration), String> {
    match kind {
        IntersectorChoice::Bvh => {
            let (b, t) = BvhIntersector::build(scene);
            Ok((Box::new(b), t))
        }
        IntersectorChoice::Embree => {
            let (e, t) = EmbreeIntersector::build_with(scene, options)
                .map_err(|e| format!("intersector = \"embree\": {e}"))?;
            Ok((Box::new(e), t))
        }
        IntersectorChoice::Auto => match EmbreeIntersector::build_with(scene, options) {
            Ok((e, t)) => Ok((Box::new(e), t)),
            Err(e) => {
                tracing::warn!("Embree unavailable ({e}); using the BVH");
                let (b, t) = BvhIntersector::build(scene);
                Ok((Box::new(b), t))
            }
        },
    }
}

/// Ray counts of one work unit; merged into the render's totals when the unit ends, so
/// threads never share a counter.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayCounts {
    pub closest: u64,
    pub shadow: u64,
}

/// Answers one work unit's ray queries: intersects and fills in the surface data.
///
/// When the scene has alpha-tested materials (MASK or BLEND), every query goes through the
/// intersector's filtered variant with [`Scene::passes_through`] as the filter, so closest
/// hits, shadow rays and camera rays all see the same cut-outs.
pub struct UnitTracer<'a> {
    pub scene: &'a Scene,
    pub intersector: &'a dyn Intersector,
    pub counts: RayCounts,
    alpha: bool,
}

impl<'a> UnitTracer<'a> {
    pub fn new(scene: &'a Scene, intersector: &'a dyn Intersector) -> Self {
        UnitTracer {
            scene,
            intersector,
            counts: RayCounts::default(),
            alpha: scene.has_alpha(),
        }
    }

    /// The closest hit of `ray`, alpha-tested when the scene needs it.
    #[inline]
    pub fn closest(&self, ray: &Ray) -> Option<TriangleHit> {
        if self.alpha {
            let scene = self.scene;
            self.intersector.intersect_filtered(ray, &|prim, b1, b2| {
                !scene.passes_through(ray, prim, b1, b2)
            })
        } else {
            self.intersector.intersect(ray)
        }
    }

    /// Whether `ray` is blocked, alpha-tested when the scene needs it.
    #[inline]
    pub fn blocked(&self, ray: &Ray) -> bool {
        if self.alpha {
            let scene = self.scene;
            self.intersector.occluded_filtered(ray, &|prim, b1, b2| {
                !scene.passes_through(ray, prim, b1, b2)
            })
        } else {
            self.intersector.occluded(ray)
        }
    }

    /// The C-ABI table pointing at `self`, valid while `self` is borrowed.
    pub fn table(&mut self) -> TracerTable {
        TracerTable {
            ctx: self as *mut Self as *mut c_void,
            intersect: intersect_cb,
            occluded: occluded_cb,
        }
    }

    #[inline]
    pub fn intersect(&mut self, ray: &Ray) -> HitRecord {
        self.counts.closest += 1;
        match self.closest(ray) {
            Some(h) => HitRecord {
                hit: 1,
                surface: self.scene.surface_hit(ray, h.t, h.prim, h.b1, h.b2),
            },
            None => HitRecord {
                hit: 0,
                surface: EMPTY_HIT,
            },
        }
    }
}

const EMPTY_HIT: flowlight_core::geometry::SurfaceHit = flowlight_core::geometry::SurfaceHit {
    t: f32::INFINITY,
    p: glam::Vec3::ZERO,
    p_error: glam::Vec3::ZERO,
    ng: glam::Vec3::Z,
    ns: glam::Vec3::Z,
    uv: glam::Vec2::ZERO,
    uv1: glam::Vec2::ZERO,
    color: [1.0; 4],
    prim: u32::MAX,
    material: 0,
    emitter: -1,
};

unsafe extern "C" fn intersect_cb(
    ctx: *mut c_void,
    rays: *const Ray,
    hits: *mut HitRecord,
    n: usize,
) {
    let tracer = &mut *(ctx as *mut UnitTracer);
    for i in 0..n {
        *hits.add(i) = tracer.intersect(&*rays.add(i));
    }
}

unsafe extern "C" fn occluded_cb(ctx: *mut c_void, rays: *const Ray, blocked: *mut u8, n: usize) {
    let tracer = &mut *(ctx as *mut UnitTracer);
    tracer.counts.shadow += n as u64;
    for i in 0..n {
        *blocked.add(i) = tracer.blocked(&*rays.add(i)) as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::geometry::Ray;
    use flowlight_scene::gltf_loader::load_gltf;
    use flowlight_testkit::gltf::{png8, temp_dir, Quad};
    use glam::Vec3;
    use std::collections::BTreeMap;

    /// The unit quad at z = 0 whose right half (x > 0.5) is cut away by its base colour
    /// alpha (`mode` MASK or BLEND), and a copy at z = −1 shifted by +0.5 in x.
    fn cut_scene(mode: &str, alpha_right: u8) -> Scene {
        let q = Quad {
            images: vec![png8(
                2,
                1,
                4,
                &[255, 255, 255, 255, 255, 255, 255, alpha_right],
            )],
            textures: r#"{"source": 0, "sampler": 0}"#.into(),
            samplers: r#"{"magFilter": 9728}"#.into(),
            material: format!(
                r#"{{"alphaMode": "{mode}", "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}}}}}"#
            ),
            second_node: Some([0.5, 0.0, -1.0]),
            ..Quad::default()
        };
        let dir = temp_dir("alpha-host");
        load_gltf(&q.write(&dir, "cut.gltf"), &BTreeMap::new()).unwrap()
    }

    fn intersectors(scene: &Scene) -> Vec<Box<dyn Intersector>> {
        let (bvh, _) = BvhIntersector::build(scene);
        let (embree, _) =
            EmbreeIntersector::build_with(scene, flowlight_embree::SceneOptions::default())
                .expect("Embree is provisioned by the build");
        vec![Box::new(bvh), Box::new(embree)]
    }

    fn down(x: f32, y: f32) -> Ray {
        Ray::new(Vec3::new(x, y, 1.0), -Vec3::Z, f32::INFINITY)
    }

    #[test]
    fn alpha_mask_cuts_half_a_quad_in_both_intersectors() {
        let scene = cut_scene("MASK", 0);
        for isect in intersectors(&scene) {
            let tracer = UnitTracer::new(&scene, isect.as_ref());
            for i in 0..16 {
                for j in 0..16 {
                    let (x, y) = ((i as f32 + 0.5) / 16.0 * 1.5, (j as f32 + 0.5) / 16.0);
                    let ray = down(x, y);
                    // Upper quad opaque on x < 0.5; lower copy opaque on 0.5 < x < 1.
                    let want = if x < 0.5 {
                        Some(1.0)
                    } else if x < 1.0 {
                        Some(2.0)
                    } else {
                        None
                    };
                    let got = tracer.closest(&ray).map(|h| h.t);
                    match (want, got) {
                        (Some(w), Some(g)) => {
                            assert!((w - g).abs() < 1e-5, "{} ({x}, {y}): t {g}", isect.name())
                        }
                        (None, None) => {}
                        _ => panic!("{} ({x}, {y}): want {want:?}, got {got:?}", isect.name()),
                    }
                    assert_eq!(
                        tracer.blocked(&ray),
                        want.is_some(),
                        "{} ({x}, {y})",
                        isect.name()
                    );
                    // A shadow ray that stops above the lower copy sees only the upper quad.
                    let short = Ray::new(ray.origin, ray.dir, 1.5);
                    assert_eq!(
                        tracer.blocked(&short),
                        x < 0.5,
                        "{} ({x}, {y}) short",
                        isect.name()
                    );
                    // Unfiltered queries still see the whole quads.
                    assert_eq!(isect.occluded(&ray), x < 1.5);
                }
            }
        }
    }

    #[test]
    fn alpha_blend_decisions_agree_between_intersectors() {
        let scene = cut_scene("BLEND", 128);
        let all = intersectors(&scene);
        let (bvh, embree) = (
            UnitTracer::new(&scene, all[0].as_ref()),
            UnitTracer::new(&scene, all[1].as_ref()),
        );
        let mut passed_upper = 0;
        let n = 2000;
        for i in 0..n {
            let x = 0.5 + (i as f32 + 0.5) / n as f32 * 0.5;
            let y = ((i * 37) % n) as f32 / n as f32;
            let ray = down(x, y);
            let (a, b) = (bvh.closest(&ray), embree.closest(&ray));
            assert_eq!(
                a.map(|h| (h.prim, (h.t * 1e4).round())),
                b.map(|h| (h.prim, (h.t * 1e4).round())),
                "({x}, {y})"
            );
            assert_eq!(bvh.blocked(&ray), embree.blocked(&ray));
            passed_upper += a.is_none_or(|h| h.t > 1.5) as usize;
        }
        // α = 128/255 on the right half of the upper quad: about half the rays pass it.
        let f = passed_upper as f64 / n as f64;
        assert!((f - (1.0 - 128.0 / 255.0)).abs() < 0.06, "{f}");
    }
}
