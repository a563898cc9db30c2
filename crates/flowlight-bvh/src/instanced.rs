//! Two-level BVH: a top-level hierarchy over instances, each an affine transform of one of a
//! set of per-mesh [`Bvh`]s, so that a mesh placed many times is stored once.
//!
//! * **Build**: each instance's world box is the box of the eight transformed corners of its
//!   mesh's object-space box, padded by 4ε of its largest coordinate so that rounding of the
//!   corner transform cannot make it smaller than the transformed triangles. The top level is
//!   the binary binned-SAH build of [`crate::BinaryBvh`] over those boxes (pbrt-v4 §7.3;
//!   leaves of at most [`crate::MAX_LEAF_SIZE`] instances); each mesh is an 8-wide [`Bvh`].
//! * **Traversal**: the top level is traversed like a [`crate::BinaryBvh`]; at a leaf the ray is taken to
//!   each instance's object space, `o' = M⁻¹ o`, `d' = M⁻¹ d` (the linear part only), with
//!   `d'` *not* normalised, so that the ray parameter `t` means the same point in both spaces
//!   (`M (o' + t d') = o + t d`) and one `t_max` shrinks across instances (pbrt-v4 §7.1.4,
//!   `TransformedPrimitive`). The mesh's watertight test then runs in object space.
//! * **Alpha**: the filtered queries hand every candidate (instance, triangle, barycentrics)
//!   to an [`InstanceHitFilter`] before accepting it, as [`Bvh::intersect_filtered`] does.
//! * **Hits** name the instance and the triangle of its mesh; the world-space point and
//!   normals are the caller's (`p = M p_obj`, normals by the inverse transpose of M's linear
//!   part).
//!
//! The ray transform rounds: a world-space hit at `t` is found at `t(1 + O(ε·κ(M)))`, κ the
//! condition number of M. [`TwoLevelBvh`] and a [`Bvh`] over the same triangles flattened to
//! world space therefore agree on every hit up to that tolerance (the agreement test in
//! `tests/instanced.rs`).

use crate::build::{build_parallel, Aabb, Node, PrimRef};
use crate::traverse::{SlabRay, STACK_SIZE};
use crate::Bvh;
use flowlight_core::denormals::with_denormals_flushed;
use flowlight_core::geometry::{InstanceHit, InstanceHitFilter, Ray};
use glam::{Affine3A, Mat4, Vec3};

/// One placement of a mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into the meshes given to [`TwoLevelBvh::build`].
    pub mesh: u32,
    /// Object to world; must be affine and invertible.
    pub object_to_world: Mat4,
}

/// A BVH over instances of per-mesh BVHs.
#[derive(Clone, Debug)]
pub struct TwoLevelBvh {
    meshes: Vec<Bvh>,
    instances: Vec<Instance>,
    world_to_object: Vec<Affine3A>,
    nodes: Vec<Node>,
    /// Instance index of each top-level leaf entry.
    order: Vec<u32>,
}

impl TwoLevelBvh {
    /// Builds the top level over `instances` of `meshes`. Errors name the instance: a mesh
    /// index out of range, a transform that is not affine, not finite or not invertible.
    /// Instances of empty meshes are kept (and never hit).
    pub fn build(meshes: Vec<Bvh>, instances: Vec<Instance>) -> Result<TwoLevelBvh, String> {
        if instances.len() > u32::MAX as usize {
            return Err("too many instances".into());
        }
        let mut world_to_object = Vec::with_capacity(instances.len());
        let mut refs = Vec::new();
        for (i, inst) in instances.iter().enumerate() {
            let m = inst.object_to_world;
            let mesh = meshes.get(inst.mesh as usize).ok_or_else(|| {
                format!(
                    "instance {i}: mesh {} does not exist ({} meshes)",
                    inst.mesh,
                    meshes.len()
                )
            })?;
            if m.row(3) != glam::Vec4::W || !m.is_finite() {
                return Err(format!(
                    "instance {i}: transform is not a finite affine matrix"
                ));
            }
            let a = Affine3A::from_mat4(m);
            let det = a.matrix3.determinant();
            if !(det.is_finite() && det != 0.0) {
                return Err(format!("instance {i}: transform is not invertible"));
            }
            let inv = a.inverse();
            if !inv.is_finite() {
                return Err(format!("instance {i}: transform is not invertible"));
            }
            world_to_object.push(inv);
            let (lo, hi) = mesh.bounds();
            if mesh.node_count() == 0 {
                continue;
            }
            let mut b = Aabb::EMPTY;
            for c in 0..8 {
                let corner = Vec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                );
                b.grow(a.transform_point3(corner).into());
            }
            let pad = b.min.abs().max(b.max.abs()).max_element() * 4.0 * f32::EPSILON;
            b.min -= pad;
            b.max += pad;
            refs.push(PrimRef::from_bounds(b, i as u32));
        }
        let nodes = if refs.is_empty() {
            Vec::new()
        } else {
            build_parallel(&mut refs, 0, 0)
        };
        let order = refs.iter().map(|r| r.index()).collect();
        Ok(TwoLevelBvh {
            meshes,
            instances,
            world_to_object,
            nodes,
            order,
        })
    }

    /// Closest hit with `t ∈ (0, ray.t_max)`, or `None`.
    pub fn intersect(&self, ray: &Ray) -> Option<InstanceHit> {
        self.traverse::<false, false>(ray, &|_, _, _, _| true)
    }

    /// Whether any instance's triangle is hit with `t ∈ (0, ray.t_max)`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse::<true, false>(ray, &|_, _, _, _| true)
            .is_some()
    }

    /// [`TwoLevelBvh::intersect`] counting only the hits `accept(instance, prim, b1, b2)`
    /// keeps (alpha testing through instances): a rejected candidate does not shorten the
    /// ray.
    pub fn intersect_filtered(&self, ray: &Ray, accept: InstanceHitFilter) -> Option<InstanceHit> {
        self.traverse::<false, true>(ray, accept)
    }

    /// [`TwoLevelBvh::occluded`] counting only the hits `accept` keeps.
    pub fn occluded_filtered(&self, ray: &Ray, accept: InstanceHitFilter) -> bool {
        self.traverse::<true, true>(ray, accept).is_some()
    }

    #[inline(always)]
    fn traverse<const ANY_HIT: bool, const FILTER: bool>(
        &self,
        ray: &Ray,
        accept: &dyn Fn(u32, u32, f32, f32) -> bool,
    ) -> Option<InstanceHit> {
        if self.nodes.is_empty() || ray.t_max.is_nan() || ray.t_max <= 0.0 {
            return None;
        }
        // The whole query, the rays' transforms included, in the queries' floating-point
        // mode (`Bvh::traverse`); the meshes' traversals then only read it.
        with_denormals_flushed(|| self.traverse_in_mode::<ANY_HIT, FILTER>(ray, accept))
    }

    #[inline(always)]
    fn traverse_in_mode<const ANY_HIT: bool, const FILTER: bool>(
        &self,
        ray: &Ray,
        accept: &dyn Fn(u32, u32, f32, f32) -> bool,
    ) -> Option<InstanceHit> {
        let slab = SlabRay::new(ray);
        let mut t_max = ray.t_max;
        let mut hit = None;
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0usize;
        let mut idx = 0usize;
        loop {
            let node = &self.nodes[idx];
            if slab.hits(node, t_max) {
                if node.count > 0 {
                    let first = node.offset as usize;
                    for &inst in &self.order[first..first + node.count as usize] {
                        let w2o = &self.world_to_object[inst as usize];
                        let local = Ray {
                            origin: w2o.transform_point3(ray.origin),
                            dir: w2o.transform_vector3(ray.dir),
                            t_max,
                        };
                        let mesh = &self.meshes[self.instances[inst as usize].mesh as usize];
                        if FILTER {
                            let keep = |prim, b1, b2| accept(inst, prim, b1, b2);
                            if ANY_HIT {
                                if mesh.occluded_filtered(&local, &keep) {
                                    return Some(InstanceHit {
                                        t: t_max,
                                        instance: inst,
                                        prim: u32::MAX,
                                        b1: 0.0,
                                        b2: 0.0,
                                    });
                                }
                            } else if let Some(h) = mesh.intersect_filtered(&local, &keep) {
                                t_max = h.t;
                                hit = Some(InstanceHit {
                                    t: h.t,
                                    instance: inst,
                                    prim: h.prim,
                                    b1: h.b1,
                                    b2: h.b2,
                                });
                            }
                        } else if ANY_HIT {
                            if mesh.occluded(&local) {
                                return Some(InstanceHit {
                                    t: t_max,
                                    instance: inst,
                                    prim: u32::MAX,
                                    b1: 0.0,
                                    b2: 0.0,
                                });
                            }
                        } else if let Some(h) = mesh.intersect(&local) {
                            t_max = h.t;
                            hit = Some(InstanceHit {
                                t: h.t,
                                instance: inst,
                                prim: h.prim,
                                b1: h.b1,
                                b2: h.b2,
                            });
                        }
                    }
                } else {
                    let (near, far) = if slab.neg[node.axis as usize] {
                        (node.offset as usize, idx + 1)
                    } else {
                        (idx + 1, node.offset as usize)
                    };
                    stack[sp] = far as u32;
                    sp += 1;
                    idx = near;
                    continue;
                }
            }
            if sp == 0 {
                return hit;
            }
            sp -= 1;
            idx = stack[sp] as usize;
        }
    }

    pub fn instances(&self) -> &[Instance] {
        &self.instances
    }

    pub fn meshes(&self) -> &[Bvh] {
        &self.meshes
    }

    /// Triangles stored: each mesh's once.
    pub fn stored_triangle_count(&self) -> usize {
        self.meshes.iter().map(Bvh::stored_triangle_count).sum()
    }

    /// Triangles the scene shows: each instance's mesh, counted per instance (what a flattened
    /// BVH would store).
    pub fn instanced_triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].stored_triangle_count())
            .sum()
    }
}
