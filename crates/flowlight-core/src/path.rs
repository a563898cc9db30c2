//! Node and path types (thesis §3.3): Heckbert notation and the node-type classes.

use crate::geometry::SurfaceHit;
use crate::Rgb;
use glam::{Vec2, Vec3};

/// Node type of the third kind, Λ₃ = {D_r, G_r, S_r, D_t, G_t, S_t}, plus the path's end
/// points. It records the scattering mode a sampler actually chose (the strong type).
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NodeType {
    Eye = 0,
    Light = 1,
    DiffuseReflection = 2,
    GlossyReflection = 3,
    SpecularReflection = 4,
    DiffuseTransmission = 5,
    GlossyTransmission = 6,
    SpecularTransmission = 7,
}

/// Whether direct and indirect lighting may be estimated separately at a node (thesis §3.3):
/// Λβ (diffuse, wide glossy) may be connected to a light explicitly; Λα (specular, narrow
/// glossy) may not, so light reaching it is only found by hitting an emitter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeClass {
    Alpha,
    Beta,
}

impl NodeType {
    /// Heckbert letter (node type of the second kind, with T for any transmission).
    pub fn heckbert(self) -> char {
        match self {
            NodeType::Eye => 'E',
            NodeType::Light => 'L',
            NodeType::DiffuseReflection => 'D',
            NodeType::GlossyReflection => 'G',
            NodeType::SpecularReflection => 'S',
            NodeType::DiffuseTransmission
            | NodeType::GlossyTransmission
            | NodeType::SpecularTransmission => 'T',
        }
    }

    /// Node type of the first kind: reflection or transmission.
    pub fn is_transmission(self) -> bool {
        matches!(
            self,
            NodeType::DiffuseTransmission
                | NodeType::GlossyTransmission
                | NodeType::SpecularTransmission
        )
    }

    pub fn is_specular(self) -> bool {
        matches!(
            self,
            NodeType::SpecularReflection | NodeType::SpecularTransmission
        )
    }
}

/// Writes a path type in Heckbert notation, e.g. `EDSL`.
pub fn heckbert_string(types: &[NodeType]) -> String {
    types.iter().map(|t| t.heckbert()).collect()
}

/// Most vertices a [`Path`] can hold (eye and light included).
pub const MAX_PATH_VERTICES: usize = 34;

/// One vertex of a stored path. Directions are recomputed from positions.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathVertex {
    pub p: Vec3,
    pub p_error: Vec3,
    pub ng: Vec3,
    pub ns: Vec3,
    pub uv: Vec2,
    /// TEXCOORD_1 and COLOR_0 at the vertex, so that a path's BSDFs can be re-evaluated
    /// with their textures.
    pub uv1: Vec2,
    pub color: [f32; 4],
    pub prim: u32,
    pub material: u32,
    pub emitter: i32,
    pub node: NodeType,
    /// BSDF component chosen at this vertex (the strong type's scattering mode).
    pub component: u8,
}

impl PathVertex {
    /// Both texture-coordinate sets, for [`crate::material::Material::resolve`].
    #[inline]
    pub fn uvs(&self) -> [Vec2; 2] {
        [self.uv, self.uv1]
    }

    /// The vertex at a ray hit, scattered with `node` by BSDF `component`.
    pub fn from_hit(hit: &SurfaceHit, node: NodeType, component: u8) -> PathVertex {
        PathVertex {
            p: hit.p,
            p_error: hit.p_error,
            ng: hit.ng,
            ns: hit.ns,
            uv: hit.uv,
            uv1: hit.uv1,
            color: hit.color,
            prim: hit.prim,
            material: hit.material,
            emitter: hit.emitter,
            node,
            component,
        }
    }

    /// The eye vertex at `position` (the camera ray's origin: the pinhole, or a point of an
    /// orthographic film, `Camera::eye_point`) looking along `forward`.
    pub fn eye(position: Vec3, forward: Vec3) -> PathVertex {
        PathVertex {
            p: position,
            p_error: Vec3::ZERO,
            ng: forward,
            ns: forward,
            uv: Vec2::ZERO,
            uv1: Vec2::ZERO,
            color: [1.0; 4],
            prim: u32::MAX,
            material: u32::MAX,
            emitter: -1,
            node: NodeType::Eye,
            component: 0,
        }
    }

    /// The vertex as a surface to spawn rays from.
    pub fn surface(&self) -> SurfaceHit {
        SurfaceHit {
            t: 0.0,
            p: self.p,
            p_error: self.p_error,
            ng: self.ng,
            ns: self.ns,
            uv: self.uv,
            uv1: self.uv1,
            color: self.color,
            prim: self.prim,
            material: self.material,
            emitter: self.emitter,
        }
    }
}

/// A complete eye-to-light path with its sampled contribution: the state of a Markov chain.
/// Fixed capacity so it can cross the plugin boundary by pointer without allocation.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Path {
    /// Raster position of the eye ray.
    pub raster: Vec2,
    /// Side K of the film-plane migration window of a Markov chain (0: the raster position
    /// is fixed). Part of the state so that every mutation strategy moves alike.
    pub film_window: u32,
    /// Number of vertices in use; path length n = vertex_count - 1.
    pub vertex_count: u32,
    /// Lighting layer (virtual length - 1, §2) this path contributes to.
    pub layer: u32,
    /// Monte Carlo estimate f(x)/p(x) carried by this path.
    pub contribution: Rgb,
    pub vertices: [PathVertex; MAX_PATH_VERTICES],
}

impl Path {
    /// An empty path (no vertices).
    pub fn empty() -> Path {
        let v = PathVertex::eye(Vec3::ZERO, Vec3::Z);
        Path {
            raster: Vec2::ZERO,
            film_window: 0,
            vertex_count: 0,
            layer: 0,
            contribution: Rgb::ZERO,
            vertices: [v; MAX_PATH_VERTICES],
        }
    }

    pub fn vertices(&self) -> &[PathVertex] {
        &self.vertices[..self.vertex_count as usize]
    }

    /// Path type in Heckbert notation.
    pub fn heckbert(&self) -> String {
        self.vertices().iter().map(|v| v.node.heckbert()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heckbert_notation() {
        use NodeType::*;
        let t = [
            Eye,
            DiffuseReflection,
            SpecularTransmission,
            SpecularTransmission,
            Light,
        ];
        assert_eq!(heckbert_string(&t), "EDTTL");
        assert!(SpecularReflection.is_specular() && !GlossyReflection.is_specular());
        assert!(GlossyTransmission.is_transmission());
    }
}
