//! The node walk: transforms composed down the hierarchy (cycles and nodes with two
//! parents refused), the cameras and punctual lights the nodes place, and the placements of
//! every mesh, from which the geometry is loaded flattened (placed once) or instanced (placed
//! several times, see [`crate::scene`]).

use super::limits::check_instancing_limits;
use super::Loader;
use crate::error::SceneError;
use crate::instancing::instance_transforms;
use crate::lights::punctual_light;
use crate::scene::{MeshInstance, MeshRange, NamedNode};
use glam::Mat4;
use std::collections::HashMap;

impl Loader<'_> {
    pub(super) fn walk(&mut self) -> Result<(), SceneError> {
        let doc = self.src.document.clone();
        let gscene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| SceneError::NoScene { file: self.file() })?;
        enum Step<'d> {
            Enter(gltf::Node<'d>, Mat4),
            Exit(usize),
        }
        // (glTF mesh, its world placements) in traversal order; geometry is loaded after the
        // walk, once the number of placements of each mesh is known.
        let mut placements: Vec<(usize, Vec<Mat4>)> = Vec::new();
        let mut on_path = vec![false; doc.nodes().len()];
        let mut entered = vec![false; doc.nodes().len()];
        let mut stack: Vec<Step> = gscene
            .nodes()
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .map(|n| Step::Enter(n, Mat4::IDENTITY))
            .collect();
        while let Some(step) = stack.pop() {
            let (node, parent) = match step {
                Step::Enter(node, parent) => (node, parent),
                Step::Exit(i) => {
                    on_path[i] = false;
                    continue;
                }
            };
            let idx = node.index();
            if on_path[idx] {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "the node hierarchy has a cycle".into(),
                });
            }
            // glTF requires the nodes to form disjoint trees: a node reached twice has several
            // parents (or is listed twice by one), and a chain of such nodes expands
            // exponentially (30 of them: 2^30 instances). Sharing is what meshes are for.
            if entered[idx] {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "it is reached twice in the node hierarchy (a second parent, or a \
                             parent listing it twice); glTF nodes must form trees — share the \
                             mesh between two nodes instead"
                        .into(),
                });
            }
            entered[idx] = true;
            let local = Mat4::from_cols_array_2d(&node.transform().matrix());
            let world = parent * local;
            if !world.is_finite() {
                return Err(SceneError::Node {
                    file: self.file(),
                    node: idx,
                    reason: "its world transform is not finite".into(),
                });
            }
            if let Some(name) = node.name() {
                self.scene.named_nodes.push(NamedNode {
                    name: name.to_string(),
                    node: idx,
                    position: world.transform_point3(glam::Vec3::ZERO),
                });
            }
            if let Some(cam) = node.camera() {
                self.camera(&cam, &node, world)?;
            }
            if let Some(light) = node.light() {
                let l = punctual_light(&self.src.file, &light, world)?;
                if light.range().is_some() {
                    tracing::info!(file = %self.src.file.display(), "light {}: range is ignored (inverse-square fall-off)", light.index());
                }
                self.scene.punctual_lights.push(l);
            }
            if let Some(mesh) = node.mesh() {
                // One placement, or one per EXT_mesh_gpu_instancing instance.
                let transforms = instance_transforms(&mut self.src, &node, world)?;
                self.scene.stats.mesh_instances += transforms.len();
                placements.push((mesh.index(), transforms));
            }
            on_path[idx] = true;
            stack.push(Step::Exit(idx));
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push(Step::Enter(child, world));
            }
        }
        self.geometry(&doc, &placements)
    }

    /// Loads the meshes of `placements`: a mesh placed once is flattened into world space
    /// (all of them form mesh 0, one identity instance); a mesh placed several times is
    /// stored once in its local space and gets one [`MeshInstance`] per placement. The
    /// limits ([`check_instancing_limits`]) are checked before any geometry is decoded.
    fn geometry(
        &mut self,
        doc: &gltf::Document,
        placements: &[(usize, Vec<Mat4>)],
    ) -> Result<(), SceneError> {
        let mesh_of = |i: usize| doc.meshes().nth(i);
        let mut uses: HashMap<usize, usize> = HashMap::new();
        for (m, ts) in placements {
            *uses.entry(*m).or_default() += ts.len();
        }
        check_instancing_limits(&self.src.file, doc, placements, &uses)?;
        let mut virtual_count: u32 = 0;
        // Meshes placed once, flattened in traversal order.
        let flat_start = self.scene.triangles.len() as u32;
        for (m, ts) in placements {
            if uses[m] != 1 {
                continue;
            }
            let Some(mesh) = mesh_of(*m) else { continue };
            // One object per placement (the AOVs' object id): its first virtual triangle.
            let first = self.scene.triangles.len() as u32 - flat_start;
            self.scene.object_first_virtual.push(first);
            for prim in mesh.primitives() {
                self.primitive(&mesh, &prim, ts[0])?;
            }
        }
        let flat = MeshRange {
            first_triangle: flat_start,
            triangle_count: self.scene.triangles.len() as u32 - flat_start,
        };
        if flat.triangle_count > 0 {
            self.scene.meshes.push(flat);
            self.scene
                .instances
                .push(MeshInstance::identity(0, flat, 0, 0));
            virtual_count = flat.triangle_count;
        }
        // Meshes placed several times: stored once, in local space.
        let mut stored: HashMap<usize, u32> = HashMap::new();
        for (m, ts) in placements {
            if uses[m] < 2 {
                continue;
            }
            let Some(mesh) = mesh_of(*m) else { continue };
            let index = match stored.get(m) {
                Some(&i) => i,
                None => {
                    let first = self.scene.triangles.len() as u32;
                    for prim in mesh.primitives() {
                        self.primitive(&mesh, &prim, Mat4::IDENTITY)?;
                    }
                    self.scene.meshes.push(MeshRange {
                        first_triangle: first,
                        triangle_count: self.scene.triangles.len() as u32 - first,
                    });
                    let i = (self.scene.meshes.len() - 1) as u32;
                    stored.insert(*m, i);
                    i
                }
            };
            let range = self.scene.meshes[index as usize];
            if range.triangle_count == 0 {
                continue;
            }
            for &t in ts {
                match MeshInstance::placed(index, range, t, virtual_count, 0) {
                    Some(inst) => {
                        self.scene.instances.push(inst);
                        self.scene.object_first_virtual.push(virtual_count);
                        self.scene.stats.instanced_placements += 1;
                        // Bounded by check_instancing_limits.
                        virtual_count += range.triangle_count;
                    }
                    None => self.scene.stats.singular_placements += 1,
                }
            }
        }
        if self.scene.stats.singular_placements > 0 {
            tracing::warn!(file = %self.src.file.display(), "{} placements of instanced meshes have a transform that cannot be inverted (zero scale); they are not rendered", self.scene.stats.singular_placements);
        }
        self.scene.stats.virtual_triangles = virtual_count as usize;
        Ok(())
    }
}
