//! Meshes and primitives: a triangle primitive's attributes are read and checked against
//! POSITION, strips and fans become lists, the vertices go to world space (normals by the
//! inverse transpose, the winding flipped under a mirroring transform), degenerate triangles
//! are dropped and counted, and the kept triangles join the scene with their vertices shared
//! (or unwelded per corner for a flat, normal-mapped primitive).

use super::tangents::corner_tangents;
use super::Loader;
use crate::accessor::{read_floats, read_indices};
use crate::error::SceneError;
use crate::scene::{triangle_area, triangle_normal, LoadStats};
use crate::source::GltfSource;
use glam::{Mat3, Mat4, Vec2, Vec3};
use gltf::mesh::{Mode, Semantic};

/// A primitive's vertex attributes as read from the file (every one `positions.len()` long).
struct Attributes {
    positions: Vec<[f32; 3]>,
    normals: Option<Vec<[f32; 3]>>,
    uvs: Option<Vec<[f32; 2]>>,
    uvs1: Option<Vec<[f32; 2]>>,
    colors: Option<Vec<[f32; 4]>>,
    tangents: Option<Vec<[f32; 4]>>,
}

/// A primitive's vertices in world space, ready to be copied into the scene.
struct WorldVertices {
    positions: Vec<Vec3>,
    /// `None` for a flat-shaded primitive.
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<[f32; 2]>>,
    uvs1: Option<Vec<[f32; 2]>>,
    colors: Option<Vec<[f32; 4]>>,
    /// Three per triangle (see [`corner_tangents`]).
    corner_tangents: Option<Vec<[f32; 4]>>,
}

impl WorldVertices {
    fn uv(set: &Option<Vec<[f32; 2]>>, v: usize) -> Vec2 {
        set.as_ref().map_or(Vec2::ZERO, |u| Vec2::from_array(u[v]))
    }

    fn color(&self, v: usize) -> [f32; 4] {
        self.colors.as_ref().map_or([1.0; 4], |c| c[v])
    }
}

impl Loader<'_> {
    pub(super) fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        world: Mat4,
    ) -> Result<(), SceneError> {
        let what = format!("mesh {} primitive {}", mesh.index(), prim.index());
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            tracing::warn!(file = %self.src.file.display(), "{what}: mode {mode:?} is not triangles; skipped");
            self.scene.stats.skipped_primitives += 1;
            return Ok(());
        }
        let Some(attributes) = self.attributes(&what, prim)? else {
            return Ok(());
        };
        let n = attributes.positions.len();
        let indices = match prim.indices() {
            Some(acc) => {
                let idx = read_indices(&mut self.src, &acc)?;
                if let Some(&bad) = idx.iter().find(|&&i| i as usize >= n) {
                    return Err(SceneError::Accessor {
                        file: self.file(),
                        accessor: acc.index(),
                        reason: format!("{what}: index {bad} is out of range ({n} vertices)"),
                    });
                }
                idx
            }
            None => (0..n as u32).collect(),
        };
        let mut tris = self.triangle_list(&what, mode, &indices);
        let linear = Mat3::from_mat4(world);
        if linear.determinant() < 0.0 {
            for t in &mut tris {
                t.swap(1, 2);
            }
        }
        let mat_index = self.material(&prim.material())?;
        let mat = self.scene.materials[mat_index as usize];
        let vertices = self.world_vertices(&what, &mat, attributes, &tris, world);
        self.any_uv0 |= vertices.uvs.is_some();
        self.any_uv1 |= vertices.uvs1.is_some();
        self.any_color |= vertices.colors.is_some();
        self.any_tangent |= vertices.corner_tangents.is_some();

        let flat = vertices.normals.is_none();
        // A flat primitive keeps its vertices shared with zero normals: the interpolated
        // normal vanishes and `MeshView::surface_hit` takes the geometric normal, the face
        // normal the spec asks for. For a scan of shared vertices that is a sixth of the
        // vertex memory of duplicating them (the Stanford dragon: 437k vertices instead of
        // 2.6M, no normals to read at a hit). Normal mapping needs a tangent frame per corner
        // of a triangle, so a flat, normal-mapped primitive is unwelded, as before.
        let unweld = flat && vertices.corner_tangents.is_some();
        self.any_normal |= !flat || unweld;
        if flat {
            self.scene.stats.flat_shaded_primitives += 1;
        }
        let kept = kept_triangles(
            &mut self.scene.stats,
            &tris,
            &vertices.positions,
            mat.is_emissive(),
        );
        if unweld {
            self.push_unwelded(&tris, &kept, &vertices, mat_index);
        } else {
            self.push_shared(&tris, &kept, &vertices, mat_index);
        }
        Ok(())
    }

    /// Reads the vertex attributes of `prim`, each checked to have as many elements as
    /// POSITION; `None` (counted, with a warning) when the primitive has no POSITION.
    fn attributes(
        &mut self,
        what: &str,
        prim: &gltf::Primitive,
    ) -> Result<Option<Attributes>, SceneError> {
        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            tracing::warn!(file = %self.src.file.display(), "{what}: no POSITION attribute; skipped");
            self.scene.stats.skipped_no_position += 1;
            return Ok(None);
        };
        let positions = read_floats::<3>(&mut self.src, &pos_acc)?;
        let n = positions.len();
        let count_err = |src: &GltfSource, acc: &gltf::Accessor, got: usize| SceneError::Accessor {
            file: src.file.clone(),
            accessor: acc.index(),
            reason: format!("{what}: has {got} elements but POSITION has {n}"),
        };
        let normals = match prim.get(&Semantic::Normals) {
            Some(acc) => {
                let v = read_floats::<3>(&mut self.src, &acc)?;
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        let read2 =
            |src: &mut GltfSource, sem: Semantic| -> Result<Option<Vec<[f32; 2]>>, SceneError> {
                match prim.get(&sem) {
                    Some(acc) => {
                        let v = read_floats::<2>(src, &acc)?;
                        if v.len() != n {
                            return Err(count_err(src, &acc, v.len()));
                        }
                        Ok(Some(v))
                    }
                    None => Ok(None),
                }
            };
        let uvs = read2(&mut self.src, Semantic::TexCoords(0))?;
        let uvs1 = read2(&mut self.src, Semantic::TexCoords(1))?;
        let colors: Option<Vec<[f32; 4]>> = match prim.get(&Semantic::Colors(0)) {
            Some(acc) => {
                let v: Vec<[f32; 4]> = match acc.dimensions() {
                    gltf::accessor::Dimensions::Vec3 => read_floats::<3>(&mut self.src, &acc)?
                        .into_iter()
                        .map(|[r, g, b]| [r, g, b, 1.0])
                        .collect(),
                    _ => read_floats::<4>(&mut self.src, &acc)?,
                };
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        if prim.get(&Semantic::Colors(1)).is_some() {
            tracing::warn!(file = %self.src.file.display(), "{what}: COLOR_1 and beyond are ignored (glTF materials only use COLOR_0)");
        }
        let tangents = match prim.get(&Semantic::Tangents) {
            Some(acc) => {
                let v = read_floats::<4>(&mut self.src, &acc)?;
                if v.len() != n {
                    return Err(count_err(&self.src, &acc, v.len()));
                }
                Some(v)
            }
            None => None,
        };
        Ok(Some(Attributes {
            positions,
            normals,
            uvs,
            uvs1,
            colors,
            tangents,
        }))
    }

    /// The triangles of `indices` under `mode`: TRIANGLES as they are (a trailing partial
    /// triangle ignored with a warning), TRIANGLE_STRIP and TRIANGLE_FAN converted to a list
    /// (and counted), keeping the strip's alternating winding.
    fn triangle_list(&mut self, what: &str, mode: Mode, indices: &[u32]) -> Vec<[u32; 3]> {
        match mode {
            Mode::Triangles => {
                if !indices.len().is_multiple_of(3) {
                    tracing::warn!(file = %self.src.file.display(), "{what}: {} indices is not a multiple of 3; the rest is ignored", indices.len());
                }
                indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect()
            }
            Mode::TriangleStrip => {
                self.scene.stats.converted_strips_fans += 1;
                (0..indices.len().saturating_sub(2))
                    .map(|i| {
                        if i % 2 == 0 {
                            [indices[i], indices[i + 1], indices[i + 2]]
                        } else {
                            [indices[i], indices[i + 2], indices[i + 1]]
                        }
                    })
                    .collect()
            }
            _ => {
                self.scene.stats.converted_strips_fans += 1;
                (0..indices.len().saturating_sub(2))
                    .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
                    .collect()
            }
        }
    }

    /// The primitive's vertices placed by `world`: positions transformed, normals by the
    /// inverse transpose (zero where that matrix is not finite), and the corner tangents the
    /// material needs ([`corner_tangents`]).
    fn world_vertices(
        &self,
        what: &str,
        mat: &flowlight_core::material::Material,
        attributes: Attributes,
        tris: &[[u32; 3]],
        world: Mat4,
    ) -> WorldVertices {
        let linear = Mat3::from_mat4(world);
        let normal_matrix = linear.inverse().transpose();
        let positions: Vec<Vec3> = attributes
            .positions
            .iter()
            .map(|&p| world.transform_point3(Vec3::from_array(p)))
            .collect();
        let nm_ok = normal_matrix.is_finite();
        let normals: Option<Vec<Vec3>> = attributes.normals.as_ref().map(|ns| {
            ns.iter()
                .map(|&v| {
                    if nm_ok {
                        (normal_matrix * Vec3::from_array(v)).normalize_or_zero()
                    } else {
                        Vec3::ZERO
                    }
                })
                .collect()
        });
        let corner_tangents = corner_tangents(
            &self.src.file,
            what,
            mat,
            tris,
            &positions,
            normals.as_deref(),
            [attributes.uvs.as_deref(), attributes.uvs1.as_deref()],
            attributes.tangents.as_deref(),
            linear,
        );
        WorldVertices {
            positions,
            normals,
            uvs: attributes.uvs,
            uvs1: attributes.uvs1,
            colors: attributes.colors,
            corner_tangents,
        }
    }

    /// Adds the kept triangles with three vertices of their own each, the face normal at
    /// every corner (a flat, normal-mapped primitive).
    fn push_unwelded(
        &mut self,
        tris: &[[u32; 3]],
        kept: &[bool],
        vertices: &WorldVertices,
        mat_index: u32,
    ) {
        let wp = &vertices.positions;
        for (k, t) in tris.iter().enumerate().filter(|&(k, _)| kept[k]) {
            let [a, b, c] = t.map(|i| i as usize);
            let face_n = triangle_normal(wp[a], wp[b], wp[c]).unwrap_or(Vec3::Z);
            let sc = &mut self.scene;
            let first = sc.positions.len() as u32;
            for (j, v) in [a, b, c].into_iter().enumerate() {
                sc.positions.push(wp[v]);
                sc.normals.push(face_n);
                sc.uvs.push(WorldVertices::uv(&vertices.uvs, v));
                sc.uvs1.push(WorldVertices::uv(&vertices.uvs1, v));
                sc.colors.push(vertices.color(v));
                sc.tangents.push(
                    vertices
                        .corner_tangents
                        .as_ref()
                        .map_or([0.0; 4], |ct| ct[3 * k + j]),
                );
            }
            sc.triangles.push([first, first + 1, first + 2]);
            sc.triangle_material.push(mat_index);
        }
    }

    /// Adds the kept triangles over shared vertices: those of kept triangles, in the file's
    /// order (a vertex that only dropped triangles use may be non-finite, and takes no
    /// memory).
    fn push_shared(
        &mut self,
        tris: &[[u32; 3]],
        kept: &[bool],
        vertices: &WorldVertices,
        mat_index: u32,
    ) {
        let n = vertices.positions.len();
        let kept_triangles = || {
            tris.iter()
                .enumerate()
                .filter(|&(k, _)| kept[k])
                .map(|(_, &t)| t)
        };
        let mut tv = vec![[0.0f32; 4]; n];
        if let Some(ct) = &vertices.corner_tangents {
            for (k, t) in tris.iter().enumerate() {
                for j in 0..3 {
                    tv[t[j] as usize] = ct[3 * k + j];
                }
            }
        }
        let mut used = vec![false; n];
        for t in kept_triangles() {
            for i in t {
                used[i as usize] = true;
            }
        }
        let sc = &mut self.scene;
        let mut remap = vec![u32::MAX; n];
        for v in (0..n).filter(|&v| used[v]) {
            remap[v] = sc.positions.len() as u32;
            sc.positions.push(vertices.positions[v]);
            sc.normals
                .push(vertices.normals.as_ref().map_or(Vec3::ZERO, |ns| ns[v]));
            sc.uvs.push(WorldVertices::uv(&vertices.uvs, v));
            sc.uvs1.push(WorldVertices::uv(&vertices.uvs1, v));
            sc.colors.push(vertices.color(v));
            sc.tangents.push(tv[v]);
        }
        for t in kept_triangles() {
            sc.triangles.push(t.map(|i| remap[i as usize]));
            sc.triangle_material.push(mat_index);
        }
    }
}

/// Which of `tris` are kept: a triangle with a repeated index, a non-finite vertex or zero
/// area is dropped and counted in `stats` (as an emitter lost too when `emissive`).
fn kept_triangles(
    stats: &mut LoadStats,
    tris: &[[u32; 3]],
    wp: &[Vec3],
    emissive: bool,
) -> Vec<bool> {
    tris.iter()
        .map(|&t| {
            let [a, b, c] = t.map(|i| i as usize);
            let dropped = if a == b || b == c || a == c {
                stats.dropped_repeated_index += 1;
                true
            } else if !(wp[a].is_finite() && wp[b].is_finite() && wp[c].is_finite()) {
                stats.dropped_non_finite += 1;
                true
            } else if triangle_normal(wp[a], wp[b], wp[c]).is_none()
                || (triangle_area(wp[a], wp[b], wp[c]) as f32) <= 0.0
            {
                stats.dropped_zero_area += 1;
                true
            } else {
                false
            };
            if dropped {
                stats.degenerate_dropped += 1;
                stats.dropped_emitters += emissive as usize;
            }
            !dropped
        })
        .collect()
}
