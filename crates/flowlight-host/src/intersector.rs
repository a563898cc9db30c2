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

    pub fn build_with(
        scene: &Scene,
        options: flowlight_embree::SceneOptions,
    ) -> Result<(EmbreeIntersector, Duration), String> {
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
            self.intersector
                .intersect_filtered(ray, &|prim, b1, b2| !scene.passes_through(ray, prim, b1, b2))
        } else {
            self.intersector.intersect(ray)
        }
    }

    /// Whether `ray` is blocked, alpha-tested when the scene needs it.
    #[inline]
    pub fn blocked(&self, ray: &Ray) -> bool {
        if self.alpha {
            let scene = self.scene;
            self.intersector
                .occluded_filtered(ray, &|prim, b1, b2| !scene.passes_through(ray, prim, b1, b2))
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
