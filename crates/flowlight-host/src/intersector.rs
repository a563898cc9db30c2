//! Intersectors and the host's answer to plugins' ray queries.

use flowlight_bvh::{Bvh, Instance, TwoLevelBvh};
use flowlight_core::geometry::{HitFilter, InstanceHit, Ray, TriangleHit};
use flowlight_core::mesh::CompactHit;
use flowlight_scene::config::Intersector as IntersectorChoice;
use flowlight_scene::Scene;
use flowlight_sdk::abi::{batch, HitRecord, TracerTable};
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
    /// Closest hits of a batch of rays (no alpha test): `hits[i]` is exactly
    /// [`Intersector::intersect`] of `rays[i]`. By default a loop over the rays inside
    /// [`Intersector::batch`], compiled for each backend, so no ray pays an indirect call;
    /// Embree answers small scenes with packets.
    fn intersect_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.batch(&mut || {
            for (ray, out) in rays.iter().zip(hits.iter_mut()) {
                *out = self
                    .intersect(ray)
                    .map_or(CompactHit::MISS, CompactHit::from);
            }
        });
    }
    /// [`Intersector::intersect_batch`] for rays the caller says are coherent (camera rays
    /// of a tile in raster order), by whatever traversal suits such rays: the same
    /// distances, but a tie between two triangles at one distance may go the other way. By
    /// default the batch call itself; Embree takes its coherent packet traversal.
    fn intersect_coherent_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.intersect_batch(rays, hits)
    }
    /// Shadow rays of a batch (no alpha test): `blocked[i]` is 1 where
    /// [`Intersector::occluded`] of `rays[i]` holds, else 0.
    fn occluded_batch(&self, rays: &[Ray], blocked: &mut [u8]) {
        self.batch(&mut || {
            for (ray, out) in rays.iter().zip(blocked.iter_mut()) {
                *out = u8::from(self.occluded(ray));
            }
        });
    }
    /// Runs `queries`, a loop over a batch's rays that calls this intersector and only moves
    /// the results, in the ray queries' floating-point mode: flush-to-zero and
    /// denormals-are-zero, set once for the batch (`flowlight_core::denormals`). Both
    /// backends' single queries set it themselves; around every single ray the two MXCSR
    /// writes cost about a tenth of the dragon's render, so inside a batch they only read it.
    fn batch(&self, queries: &mut dyn FnMut()) {
        flowlight_core::denormals::with_denormals_flushed(queries)
    }
}

/// The meshes and instances of an instanced scene, as the two-level builds take them: per
/// stored mesh its triangles' vertices (indices into the mesh's range), per instance its mesh
/// and object-to-world matrix, and the first virtual id of each instance.
struct Levels {
    meshes: Vec<Vec<[glam::Vec3; 3]>>,
    instances: Vec<(u32, glam::Mat4)>,
    first_virtual: Vec<u32>,
}

fn levels(scene: &Scene) -> Levels {
    let meshes = scene
        .meshes
        .iter()
        .map(|r| {
            scene.triangles[r.first_triangle as usize..][..r.triangle_count as usize]
                .iter()
                .map(|t| t.map(|i| scene.positions[i as usize]))
                .collect()
        })
        .collect();
    Levels {
        meshes,
        instances: scene
            .instances
            .iter()
            .map(|i| (i.mesh, i.object_to_world))
            .collect(),
        first_virtual: scene.instances.iter().map(|i| i.first_virtual).collect(),
    }
}

/// An instance hit as the virtual triangle it shows.
#[inline]
fn virtual_hit(first_virtual: &[u32], h: InstanceHit) -> TriangleHit {
    TriangleHit {
        t: h.t,
        prim: first_virtual[h.instance as usize] + h.prim,
        b1: h.b1,
        b2: h.b2,
    }
}

/// The pure-Rust BVH backend: one BVH over the world-space triangles for a scene without
/// instancing, else a [`TwoLevelBvh`] over the scene's mesh instances (each mesh stored
/// once). Hits name virtual triangle ids either way.
pub enum BvhIntersector {
    Flat(Bvh),
    Instanced {
        bvh: TwoLevelBvh,
        first_virtual: Vec<u32>,
    },
}

impl BvhIntersector {
    pub fn build(scene: &Scene) -> (BvhIntersector, Duration) {
        let start = Instant::now();
        let b = if scene.is_instanced() {
            let l = levels(scene);
            let meshes = l.meshes.iter().map(|m| Bvh::build(m)).collect();
            let instances = l
                .instances
                .iter()
                .map(|&(mesh, object_to_world)| Instance {
                    mesh,
                    object_to_world,
                })
                .collect();
            // The loader only makes invertible affine instances of existing meshes.
            let bvh = TwoLevelBvh::build(meshes, instances)
                .expect("the scene's instances are valid by construction");
            BvhIntersector::Instanced {
                bvh,
                first_virtual: l.first_virtual,
            }
        } else {
            BvhIntersector::Flat(Bvh::build_indexed(&scene.positions, &scene.triangles))
        };
        (b, start.elapsed())
    }

    /// Triangles stored in the acceleration structure (each instanced mesh once).
    pub fn stored_triangle_count(&self) -> usize {
        match self {
            BvhIntersector::Flat(b) => b.stored_triangle_count(),
            BvhIntersector::Instanced { bvh, .. } => bvh.stored_triangle_count(),
        }
    }
}

impl Intersector for BvhIntersector {
    fn name(&self) -> &'static str {
        "bvh"
    }
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        match self {
            BvhIntersector::Flat(b) => b.intersect(ray),
            BvhIntersector::Instanced { bvh, first_virtual } => {
                bvh.intersect(ray).map(|h| virtual_hit(first_virtual, h))
            }
        }
    }
    #[inline]
    fn occluded(&self, ray: &Ray) -> bool {
        match self {
            BvhIntersector::Flat(b) => b.occluded(ray),
            BvhIntersector::Instanced { bvh, .. } => bvh.occluded(ray),
        }
    }
    #[inline]
    fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        match self {
            BvhIntersector::Flat(b) => b.intersect_filtered(ray, accept),
            BvhIntersector::Instanced { bvh, first_virtual } => bvh
                .intersect_filtered(ray, &|inst, prim, b1, b2| {
                    accept(first_virtual[inst as usize] + prim, b1, b2)
                })
                .map(|h| virtual_hit(first_virtual, h)),
        }
    }
    #[inline]
    fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        match self {
            BvhIntersector::Flat(b) => b.occluded_filtered(ray, accept),
            BvhIntersector::Instanced { bvh, first_virtual } => bvh
                .occluded_filtered(ray, &|inst, prim, b1, b2| {
                    accept(first_virtual[inst as usize] + prim, b1, b2)
                }),
        }
    }
}

/// The Embree 4 backend (`flowlight-embree`): one device per process, the scene committed
/// once, robust mode on by default; `FLOWLIGHT_EMBREE_QUALITY` (`low` | `medium` | `high`)
/// sets the build quality for large scenes. A scene with instancing becomes an
/// [`flowlight_embree::EmbreeInstancedScene`] (one Embree scene per stored mesh, one
/// instance geometry per placement).
pub enum EmbreeIntersector {
    Flat(flowlight_embree::EmbreeScene),
    Instanced {
        scene: flowlight_embree::EmbreeInstancedScene,
        first_virtual: Vec<u32>,
    },
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
        let e = if scene.is_instanced() {
            let instances: Vec<(u32, glam::Mat4)> = scene
                .instances
                .iter()
                .map(|i| (i.mesh, i.object_to_world))
                .collect();
            let first_virtual = scene.instances.iter().map(|i| i.first_virtual).collect();
            // Each mesh's own vertex buffer: the span of scene vertices its triangles use
            // (a mesh's vertices are contiguous), re-indexed from 0.
            let meshes: Vec<(Vec<glam::Vec3>, Vec<[u32; 3]>)> = scene
                .meshes
                .iter()
                .map(|r| {
                    let tris =
                        &scene.triangles[r.first_triangle as usize..][..r.triangle_count as usize];
                    let lo = tris.iter().flatten().copied().min().unwrap_or(0);
                    let hi = tris.iter().flatten().copied().max().map_or(0, |h| h + 1);
                    let positions = scene.positions[lo as usize..hi as usize].to_vec();
                    (positions, tris.iter().map(|t| t.map(|i| i - lo)).collect())
                })
                .collect();
            let s = flowlight_embree::EmbreeInstancedScene::build(&meshes, &instances, options)?;
            EmbreeIntersector::Instanced {
                scene: s,
                first_virtual,
            }
        } else {
            EmbreeIntersector::Flat(flowlight_embree::EmbreeScene::build(
                &scene.positions,
                &scene.triangles,
                options,
            )?)
        };
        Ok((e, start.elapsed()))
    }

    fn closest_batch(&self, coherent: bool, rays: &[Ray], hits: &mut [CompactHit]) {
        match self {
            EmbreeIntersector::Flat(s) if coherent => s.intersect_coherent_batch(rays, hits),
            EmbreeIntersector::Flat(s) => s.intersect_batch(rays, hits),
            EmbreeIntersector::Instanced {
                scene,
                first_virtual,
            } => {
                assert_eq!(rays.len(), hits.len(), "one hit per ray");
                let emit = |i: usize, h: Option<InstanceHit>| {
                    hits[i] = h.map_or(CompactHit::MISS, |h| {
                        CompactHit::from(virtual_hit(first_virtual, h))
                    });
                };
                if coherent {
                    scene.intersect_coherent_batch(rays, emit)
                } else {
                    scene.intersect_batch(rays, emit)
                }
            }
        }
    }

    /// Triangles stored in Embree (each instanced mesh once).
    pub fn stored_triangle_count(&self) -> usize {
        match self {
            EmbreeIntersector::Flat(s) => s.triangle_count(),
            EmbreeIntersector::Instanced { scene, .. } => scene.stored_triangle_count(),
        }
    }
}

impl Intersector for EmbreeIntersector {
    fn name(&self) -> &'static str {
        "embree"
    }
    /// The scene's own batch call: packets for small scenes (flat or instanced), else single
    /// rays, with the FP mode set once ([`flowlight_embree::EmbreeScene::intersect_batch`]).
    fn intersect_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.closest_batch(false, rays, hits)
    }
    /// Packets through Embree's coherent traversal, at any scene size
    /// ([`flowlight_embree::EmbreeScene::intersect_coherent_batch`]).
    fn intersect_coherent_batch(&self, rays: &[Ray], hits: &mut [CompactHit]) {
        self.closest_batch(true, rays, hits)
    }
    fn occluded_batch(&self, rays: &[Ray], blocked: &mut [u8]) {
        match self {
            EmbreeIntersector::Flat(s) => s.occluded_batch(rays, blocked),
            EmbreeIntersector::Instanced { scene, .. } => scene.occluded_batch(rays, blocked),
        }
    }
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<TriangleHit> {
        match self {
            EmbreeIntersector::Flat(s) => s.intersect(ray),
            EmbreeIntersector::Instanced {
                scene,
                first_virtual,
            } => scene.intersect(ray).map(|h| virtual_hit(first_virtual, h)),
        }
    }
    #[inline]
    fn occluded(&self, ray: &Ray) -> bool {
        match self {
            EmbreeIntersector::Flat(s) => s.occluded(ray),
            EmbreeIntersector::Instanced { scene, .. } => scene.occluded(ray),
        }
    }
    #[inline]
    fn intersect_filtered(&self, ray: &Ray, accept: HitFilter) -> Option<TriangleHit> {
        match self {
            EmbreeIntersector::Flat(s) => s.intersect_filtered(ray, accept),
            EmbreeIntersector::Instanced {
                scene,
                first_virtual,
            } => scene
                .intersect_filtered(ray, &|inst, prim, b1, b2| {
                    accept(first_virtual[inst as usize] + prim, b1, b2)
                })
                .map(|h| virtual_hit(first_virtual, h)),
        }
    }
    #[inline]
    fn occluded_filtered(&self, ray: &Ray, accept: HitFilter) -> bool {
        match self {
            EmbreeIntersector::Flat(s) => s.occluded_filtered(ray, accept),
            EmbreeIntersector::Instanced {
                scene,
                first_virtual,
            } => scene.occluded_filtered(ray, &|inst, prim, b1, b2| {
                accept(first_virtual[inst as usize] + prim, b1, b2)
            }),
        }
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
    /// What `should_stop` answers from: set only for units whose deposits the host can
    /// discard ([`UnitTracer::with_stop`]).
    stop: Option<StopSignal<'a>>,
    /// Whether `should_stop` has answered true: the unit's deposits must then be discarded.
    pub stop_answered: bool,
}

/// Ctrl-C and the time budget, as a unit sees them.
#[derive(Clone, Copy)]
pub struct StopSignal<'a> {
    pub interrupt: &'a std::sync::atomic::AtomicBool,
    pub deadline: Option<Instant>,
}

impl StopSignal<'_> {
    /// Whether Ctrl-C was pressed or the deadline has passed.
    pub fn is_set(&self) -> bool {
        self.interrupt.load(std::sync::atomic::Ordering::Relaxed)
            || self.deadline.is_some_and(|d| Instant::now() >= d)
    }
}

impl<'a> UnitTracer<'a> {
    pub fn new(scene: &'a Scene, intersector: &'a dyn Intersector) -> Self {
        UnitTracer {
            scene,
            intersector,
            counts: RayCounts::default(),
            alpha: scene.has_alpha(),
            stop: None,
            stop_answered: false,
        }
    }

    /// A tracer whose `should_stop` answers from `stop`: for units whose deposits the host
    /// holds apart until the unit ends, and discards when the answer was true.
    pub fn with_stop(mut self, stop: StopSignal<'a>) -> Self {
        self.stop = Some(stop);
        self
    }

    /// The `should_stop` answer (ABI 6): true once the budget or Ctrl-C stops the render,
    /// and only for a tracer made [`UnitTracer::with_stop`]; remembered in
    /// [`UnitTracer::stop_answered`].
    pub fn should_stop(&mut self) -> bool {
        let stop = self.stop.is_some_and(|s| s.is_set());
        self.stop_answered |= stop;
        stop
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
            intersect_batch: intersect_batch_cb,
            occluded_batch: occluded_batch_cb,
            should_stop: should_stop_cb,
        }
    }

    /// Closest hits of a batch of rays as compact hits (ABI 4): `hits[i]` is `rays[i]`'s hit
    /// exactly as [`UnitTracer::closest`] finds it, from the intersector's own batch call
    /// ([`Intersector::intersect_batch`]: for Embree, packets in small scenes) unless the
    /// scene needs alpha tests. Batches the plugin calls `coherent` (camera rays of a tile in
    /// raster order) go to [`Intersector::intersect_coherent_batch`]: Embree's coherent
    /// packet traversal, several times faster on such rays, which finds the same distance
    /// but may settle a tie between two triangles at it the other way.
    pub fn intersect_batch(&mut self, rays: &[Ray], coherent: bool, hits: &mut [CompactHit]) {
        self.counts.closest += rays.len() as u64;
        if !self.alpha {
            return if coherent {
                self.intersector.intersect_coherent_batch(rays, hits)
            } else {
                self.intersector.intersect_batch(rays, hits)
            };
        }
        let this = &*self;
        this.intersector.batch(&mut || {
            for (ray, out) in rays.iter().zip(hits.iter_mut()) {
                *out = this.closest(ray).map_or(CompactHit::MISS, CompactHit::from);
            }
        });
    }

    /// Shadow rays of a batch: `blocked[i]` = [`UnitTracer::blocked`] of `rays[i]`.
    pub fn occluded_batch(&mut self, rays: &[Ray], blocked: &mut [u8]) {
        self.counts.shadow += rays.len() as u64;
        if !self.alpha {
            return self.intersector.occluded_batch(rays, blocked);
        }
        let this = &*self;
        this.intersector.batch(&mut || {
            for (ray, out) in rays.iter().zip(blocked.iter_mut()) {
                *out = this.blocked(ray) as u8;
            }
        });
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

unsafe extern "C" fn intersect_cb(ctx: *mut c_void, ray: *const Ray, hit: *mut HitRecord) {
    // SAFETY: `ctx` is the UnitTracer whose table this is, and the SDK passes one valid ray
    // and one writable result per call (`TracerTable`).
    unsafe {
        let tracer = &mut *(ctx as *mut UnitTracer);
        hit.write(tracer.intersect(&*ray));
    }
}

unsafe extern "C" fn intersect_batch_cb(
    ctx: *mut c_void,
    rays: *const Ray,
    n: usize,
    flags: u32,
    hits: *mut CompactHit,
) {
    // SAFETY: `ctx` is the UnitTracer whose table this is, and the SDK passes `n` valid rays
    // and `n` writable results (`TracerTable::intersect_batch`).
    unsafe {
        let tracer = &mut *(ctx as *mut UnitTracer);
        let rays = std::slice::from_raw_parts(rays, n);
        let hits = std::slice::from_raw_parts_mut(hits, n);
        tracer.intersect_batch(rays, flags & batch::COHERENT != 0, hits);
    }
}

unsafe extern "C" fn occluded_batch_cb(ctx: *mut c_void, rays: *const Ray, n: usize, out: *mut u8) {
    // SAFETY: as for `intersect_batch_cb`.
    unsafe {
        let tracer = &mut *(ctx as *mut UnitTracer);
        let rays = std::slice::from_raw_parts(rays, n);
        let out = std::slice::from_raw_parts_mut(out, n);
        tracer.occluded_batch(rays, out);
    }
}

unsafe extern "C" fn should_stop_cb(ctx: *mut c_void) -> u8 {
    // SAFETY: as for `intersect_cb`.
    unsafe {
        let tracer = &mut *(ctx as *mut UnitTracer);
        tracer.should_stop() as u8
    }
}

unsafe extern "C" fn occluded_cb(ctx: *mut c_void, ray: *const Ray) -> u8 {
    // SAFETY: as for `intersect_cb`.
    unsafe {
        let tracer = &mut *(ctx as *mut UnitTracer);
        tracer.counts.shadow += 1;
        tracer.blocked(&*ray) as u8
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

    fn load_json(tag: &str, json: &str) -> Scene {
        let dir = temp_dir(tag);
        let p = dir.join(format!("{tag}.gltf"));
        std::fs::write(&p, json).unwrap();
        load_gltf(&p, &BTreeMap::new()).unwrap()
    }

    /// Rays from a sphere around the octahedra towards random points near them.
    fn probe_rays(scene: &Scene, n: usize) -> Vec<Ray> {
        let (lo, hi) = scene.bounds().unwrap();
        let (c, r) = ((lo + hi) * 0.5, (hi - lo).length());
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut u = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let o = c + (Vec3::new(u(), u(), u()) - 0.5).normalize_or_zero() * r;
                let t = lo + (hi - lo) * Vec3::new(u(), u(), u());
                Ray::new(o, (t - o).normalize(), f32::INFINITY)
            })
            .collect()
    }

    #[test]
    fn instanced_scene_hits_what_its_flattened_copy_hits_in_both_intersectors() {
        use flowlight_testkit::gltf::{octahedra_gltf, octahedra_placements};
        let placements = octahedra_placements(9);
        let shared = load_json("inst-shared", &octahedra_gltf(&placements, false, "{}"));
        let flat = load_json("inst-flat", &octahedra_gltf(&placements, true, "{}"));
        assert!(shared.is_instanced() && !flat.is_instanced());
        let (flat_bvh, _) = BvhIntersector::build(&flat);
        let reference = UnitTracer::new(&flat, &flat_bvh);
        assert_eq!(shared.triangles.len(), 8);
        for isect in intersectors(&shared) {
            let mut hits = 0;
            let mut tracer = UnitTracer::new(&shared, isect.as_ref());
            let mut mismatched = 0;
            let rays = probe_rays(&shared, 4000);
            for ray in &rays {
                let want = reference.closest(ray);
                let got = tracer.closest(ray);
                assert_eq!(isect.occluded(ray), got.is_some(), "{}", isect.name());
                match (want, got) {
                    (Some(w), Some(g)) => {
                        assert!(
                            (w.t - g.t).abs() <= 1e-4 * w.t,
                            "{}: t {} vs {}",
                            isect.name(),
                            g.t,
                            w.t
                        );
                        if w.prim != g.prim {
                            // Only on an edge shared by two triangles of one octahedron.
                            assert_eq!(w.prim / 8, g.prim / 8, "{}", isect.name());
                            mismatched += 1;
                            continue;
                        }
                        hits += 1;
                        let a = tracer.intersect(ray).surface;
                        let mut r = UnitTracer::new(&flat, &flat_bvh);
                        let b = r.intersect(ray).surface;
                        assert!(
                            (a.p - b.p).length() <= 1e-4 * (1.0 + b.p.length()),
                            "{} vs {}",
                            a.p,
                            b.p
                        );
                        assert!((a.ng - b.ng).length() < 1e-5, "{} vs {}", a.ng, b.ng);
                        assert!((a.ns - b.ns).length() < 1e-3, "{} vs {}", a.ns, b.ns);
                        assert_eq!(a.prim, b.prim);
                    }
                    (None, None) => {}
                    // Grazing an outline, within float noise of an edge.
                    _ => mismatched += 1,
                }
            }
            assert!(
                mismatched * 200 <= rays.len(),
                "{}: {mismatched} mismatches",
                isect.name()
            );
            assert!(hits > 300, "{}: {hits} hits", isect.name());
        }
    }

    #[test]
    fn all_27_gpu_instances_are_hit_and_stored_once() {
        use flowlight_testkit::gltf::octahedra_ext_gltf;
        let t: Vec<[f32; 3]> = (0..27)
            .map(|i| {
                [
                    3.0 * (i % 3) as f32,
                    3.0 * (i / 3 % 3) as f32,
                    3.0 * (i / 9) as f32,
                ]
            })
            .collect();
        let s: Vec<[f32; 3]> = (0..27).map(|_| [1.0, 1.0, 1.0]).collect();
        let scene = load_json("ext27-host", &octahedra_ext_gltf(&t, &s, "{}"));
        assert_eq!(scene.triangles.len(), 8);
        let (bvh, _) = BvhIntersector::build(&scene);
        assert_eq!(bvh.stored_triangle_count(), 8);
        let (embree, _) =
            EmbreeIntersector::build_with(&scene, flowlight_embree::SceneOptions::default())
                .unwrap();
        assert_eq!(embree.stored_triangle_count(), 8);
        for isect in [&bvh as &dyn Intersector, &embree] {
            for (i, ti) in t.iter().enumerate() {
                // Straight down onto the top vertex's face 0 (local +x, +y, +z corner).
                let target = Vec3::from_array(*ti) + Vec3::new(0.3, 0.3, 0.4);
                let ray = Ray::new(
                    target + Vec3::new(0.3, 0.3, 0.4) * 0.5,
                    -Vec3::new(0.3, 0.3, 0.4).normalize(),
                    f32::INFINITY,
                );
                let h = isect
                    .intersect(&ray)
                    .unwrap_or_else(|| panic!("{} instance {i} missed", isect.name()));
                assert_eq!(h.prim, 8 * i as u32, "{} instance {i}", isect.name());
                let want = (Vec3::new(0.3, 0.3, 0.4) * 0.5).length();
                assert!(
                    (h.t - want).abs() < 1e-5,
                    "{} instance {i}: t {}",
                    isect.name(),
                    h.t
                );
            }
        }
    }

    #[test]
    fn alpha_mask_cuts_through_an_instance() {
        // cut_scene's two nodes share the quad mesh: the second is an instance.
        let scene = cut_scene("MASK", 0);
        assert!(scene.is_instanced());
        assert_eq!(scene.triangles.len(), 2);
        assert_eq!(scene.virtual_triangle_count(), 4);
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
