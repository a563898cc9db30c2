//! The tangent frame at a point of a mesh, for the BSDF lobes that are oriented in it
//! (`KHR_materials_anisotropy`): the same tangent the normal map uses
//! ([`MeshView::normal_mapped`]), at the point's barycentrics.

use super::MeshView;
use glam::Vec3;

impl MeshView<'_> {
    /// The tangent T and bitangent B at point `p` of virtual triangle `prim` with unit shading
    /// normal `n`: the interpolated vertex tangent (else the triangle's ∂p/∂u of
    /// texture-coordinate set `set`) made orthogonal to `n`, and B = w · n × T with the
    /// tangent's handedness w. `None` where the frame degenerates.
    pub fn tangent_frame(&self, prim: u32, p: Vec3, n: Vec3, set: usize) -> Option<(Vec3, Vec3)> {
        let (placed, _) = self.place(prim, u32::MAX);
        let b = barycentrics(placed.p, p)?;
        let (t, w) = match self.vertex_tangent(&placed, b) {
            Some((t, w)) if t.length_squared() > 1e-12 => (t, w),
            _ => self.face_tangent(&placed, set, n)?,
        };
        let w = if w < 0.0 { -1.0 } else { 1.0 };
        let t = (t - n * n.dot(t)).try_normalize()?;
        Some((t, n.cross(t) * w))
    }
}

/// Barycentrics of `p` (projected onto the triangle's plane) in triangle `t`.
fn barycentrics(t: [Vec3; 3], p: Vec3) -> Option<[f32; 3]> {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1p, d2p) = (e1.dot(d), e2.dot(d));
    let det = d11 * d22 - d12 * d12;
    if det.is_nan() || det == 0.0 {
        return None;
    }
    let b1 = (d22 * d1p - d12 * d2p) / det;
    let b2 = (d11 * d2p - d12 * d1p) / det;
    Some([1.0 - b1 - b2, b1, b2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frame follows the vertex tangents (and their handedness) where the mesh has them,
    /// else ∂p/∂u of the texture coordinates.
    #[test]
    fn tangent_frame_follows_vertex_tangents_else_the_uv_gradient() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let normals = [Vec3::Z; 3];
        let uvs = [
            glam::Vec2::ZERO,
            glam::Vec2::new(0.0, 1.0),
            glam::Vec2::new(1.0, 0.0),
        ];
        let tangents = [[0.0, 1.0, 0.0, -1.0]; 3];
        let view = |tangents: &'static [[f32; 4]], uvs: &'static [glam::Vec2]| MeshView {
            positions: Box::leak(Box::new(positions)),
            normals: Box::leak(Box::new(normals)),
            uvs,
            uvs1: &[],
            colors: &[],
            tangents,
            triangles: &[[0, 1, 2]],
            triangle_material: &[0],
            triangle_emitter: &[-1],
            instances: &[],
            materials: &[],
            textures: &[],
            stored_ids: false,
        };
        let p = Vec3::new(0.25, 0.25, 0.0);
        let tangents: &'static [[f32; 4]] = Box::leak(Box::new(tangents));
        let uvs: &'static [glam::Vec2] = Box::leak(Box::new(uvs));
        let (t, b) = view(tangents, uvs).tangent_frame(0, p, Vec3::Z, 0).unwrap();
        assert!(
            (t - Vec3::Y).length() < 1e-6 && (b - Vec3::X).length() < 1e-6,
            "{t} {b}"
        );
        // Without tangents: u grows along +y here, so T = +y.
        let (t, _) = view(&[], uvs).tangent_frame(0, p, Vec3::Z, 0).unwrap();
        assert!((t - Vec3::Y).length() < 1e-6, "{t}");
        assert!(view(&[], &[]).tangent_frame(0, p, Vec3::Z, 0).is_none());
    }

    #[test]
    fn barycentrics_recover_the_point() {
        let t = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 1.0),
        ];
        let b = barycentrics(t, t[0] * 0.2 + t[1] * 0.5 + t[2] * 0.3).unwrap();
        for (x, y) in b.iter().zip([0.2, 0.5, 0.3]) {
            assert!((x - y).abs() < 1e-5, "{b:?}");
        }
    }
}
