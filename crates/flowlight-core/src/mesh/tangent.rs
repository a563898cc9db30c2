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
    if !(det.abs() > 0.0) {
        return None;
    }
    let b1 = (d22 * d1p - d12 * d2p) / det;
    let b2 = (d11 * d2p - d12 * d1p) / det;
    Some([1.0 - b1 - b2, b1, b2])
}

#[cfg(test)]
mod tests {
    use super::*;

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
