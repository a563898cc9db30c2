//! Tangent frames per triangle corner for normal mapping: the file's TANGENT attribute, or
//! MikkTSpace tangents computed from positions, normals and texture coordinates.

use crate::scene::triangle_normal;
use flowlight_core::material::Material;
use glam::{Mat3, Vec3};
use std::path::Path;

/// Tangents per triangle corner (3 per entry of `tris`, world space, w = ±1): the TANGENT
/// attribute transformed by the node's linear part (w flipped under a mirroring transform,
/// since then n × t flips), or, when the material has a normal map and the file no tangents,
/// MikkTSpace tangents (the glTF 2.0 spec's choice, §3.7.2.1) from the world-space positions,
/// normals and the normal map's texture-coordinate set. MikkTSpace is given (u, 1 − v) so
/// that its bitangent points along −∂p/∂v, the normal map's +Y ("up" in the image).
/// `None` when neither applies.
#[allow(clippy::too_many_arguments)]
pub(super) fn corner_tangents(
    file: &Path,
    what: &str,
    mat: &Material,
    tris: &[[u32; 3]],
    wp: &[Vec3],
    normals: Option<&[Vec3]>,
    uvs: [Option<&[[f32; 2]]>; 2],
    file_tangents: Option<&[[f32; 4]]>,
    linear: Mat3,
) -> Option<Vec<[f32; 4]>> {
    if let Some(ft) = file_tangents {
        let mirror = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let tv: Vec<[f32; 4]> = ft
            .iter()
            .map(|t| {
                let x = (linear * Vec3::new(t[0], t[1], t[2])).normalize_or_zero();
                let w = if t[3] < 0.0 { -1.0 } else { 1.0 } * mirror;
                if x.is_finite() {
                    [x.x, x.y, x.z, w]
                } else {
                    [0.0; 4]
                }
            })
            .collect();
        return Some(
            tris.iter()
                .flat_map(|t| t.map(|i| tv[i as usize]))
                .collect(),
        );
    }
    if !mat.normal_texture.is_some() {
        return None;
    }
    let set = (mat.normal_texture.tex_coord as usize).min(1);
    let Some(uv) = uvs[set] else {
        tracing::warn!(file = %file.display(), "{what}: the normal map reads TEXCOORD_{set}, which the primitive lacks; normal map ignored");
        return None;
    };
    struct Mikk<'a> {
        tris: &'a [[u32; 3]],
        wp: &'a [Vec3],
        normals: Option<&'a [Vec3]>,
        uv: &'a [[f32; 2]],
        out: Vec<[f32; 4]>,
    }
    impl Mikk<'_> {
        fn vertex(&self, face: usize, vert: usize) -> usize {
            self.tris[face][vert] as usize
        }
    }
    impl bevy_mikktspace::Geometry for Mikk<'_> {
        fn num_faces(&self) -> usize {
            self.tris.len()
        }
        fn num_vertices_of_face(&self, _face: usize) -> usize {
            3
        }
        fn position(&self, face: usize, vert: usize) -> [f32; 3] {
            self.wp[self.vertex(face, vert)].to_array()
        }
        fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
            match self.normals {
                Some(n) => n[self.vertex(face, vert)].to_array(),
                None => {
                    let [a, b, c] = self.tris[face].map(|i| self.wp[i as usize]);
                    triangle_normal(a, b, c).unwrap_or(Vec3::Z).to_array()
                }
            }
        }
        fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
            let t = self.uv[self.vertex(face, vert)];
            [t[0], 1.0 - t[1]]
        }
        fn set_tangent(
            &mut self,
            tangent: Option<bevy_mikktspace::TangentSpace>,
            face: usize,
            vert: usize,
        ) {
            if let Some(t) = tangent {
                self.out[3 * face + vert] = t.tangent_encoded();
            }
        }
    }
    let mut m = Mikk {
        tris,
        wp,
        normals,
        uv,
        out: vec![[0.0; 4]; tris.len() * 3],
    };
    if let Err(e) = bevy_mikktspace::generate_tangents(&mut m) {
        tracing::warn!(file = %file.display(), "{what}: MikkTSpace could not compute tangents ({e:?}); per-face tangents are used");
        return None;
    }
    Some(m.out)
}
