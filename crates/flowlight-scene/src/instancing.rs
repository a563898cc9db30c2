//! `EXT_mesh_gpu_instancing`: one node, many placements of its mesh.
//!
//! The node's `extensions.EXT_mesh_gpu_instancing.attributes` names up to three accessors
//! with one element per instance: `TRANSLATION` (VEC3 float), `ROTATION` (VEC4 float or
//! normalized byte/short, a unit quaternion x, y, z, w) and `SCALE` (VEC3 float); all have the
//! same count. Instance i is placed by `world · T(tᵢ) · R(qᵢ) · S(sᵢ)`: the instance transform
//! is applied in the node's local space, before the node's world transform (extension spec,
//! "Overview"). A missing attribute is the identity. The instance count is the accessors'
//! common count.

use crate::accessor::read_floats;
use crate::error::SceneError;
use crate::source::GltfSource;
use glam::{Mat4, Quat, Vec3};

/// The world transforms of the instances of `node`'s mesh: `[world]` for a node without the
/// extension.
pub fn instance_transforms(
    src: &mut GltfSource,
    node: &gltf::Node,
    world: Mat4,
) -> Result<Vec<Mat4>, SceneError> {
    let Some(ext) = node.extension_value("EXT_mesh_gpu_instancing") else {
        return Ok(vec![world]);
    };
    let node_err = |src: &GltfSource, reason: String| SceneError::Node {
        file: src.file.clone(),
        node: node.index(),
        reason: format!("EXT_mesh_gpu_instancing: {reason}"),
    };
    let Some(attrs) = ext.get("attributes").and_then(|a| a.as_object()) else {
        return Err(node_err(src, "missing `attributes` object".into()));
    };
    let doc = src.document.clone();
    let accessor = |name: &str| -> Result<Option<gltf::Accessor>, String> {
        match attrs.get(name) {
            None => Ok(None),
            Some(v) => {
                let i = v
                    .as_u64()
                    .ok_or_else(|| format!("attributes.{name} is not an accessor index"))?;
                doc.accessors()
                    .nth(i as usize)
                    .map(Some)
                    .ok_or_else(|| format!("attributes.{name}: accessor {i} does not exist"))
            }
        }
    };
    let get = |name| accessor(name).map_err(|r| node_err(src, r));
    let (t, r, s) = (get("TRANSLATION")?, get("ROTATION")?, get("SCALE")?);
    let translations = t.map(|a| read_floats::<3>(src, &a)).transpose()?;
    let rotations = r.map(|a| read_floats::<4>(src, &a)).transpose()?;
    let scales = s.map(|a| read_floats::<3>(src, &a)).transpose()?;
    let counts: Vec<usize> = [
        translations.as_ref().map(Vec::len),
        rotations.as_ref().map(Vec::len),
        scales.as_ref().map(Vec::len),
    ]
    .into_iter()
    .flatten()
    .collect();
    let Some(&n) = counts.first() else {
        return Err(node_err(
            src,
            "none of TRANSLATION, ROTATION, SCALE is given".into(),
        ));
    };
    if counts.iter().any(|&c| c != n) {
        return Err(node_err(
            src,
            format!("the attributes' counts differ ({counts:?})"),
        ));
    }
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let t = translations
            .as_ref()
            .map_or(Vec3::ZERO, |v| Vec3::from_array(v[i]));
        let q = rotations.as_ref().map_or(Quat::IDENTITY, |v| {
            let [x, y, z, w] = v[i];
            Quat::from_xyzw(x, y, z, w)
        });
        let s = scales
            .as_ref()
            .map_or(Vec3::ONE, |v| Vec3::from_array(v[i]));
        let len = q.length();
        if !(t.is_finite() && s.is_finite() && len.is_finite() && len > 0.0) {
            return Err(node_err(
                src,
                format!("instance {i} has a non-finite or zero transform"),
            ));
        }
        let m = world * Mat4::from_scale_rotation_translation(s, q / len, t);
        if !m.is_finite() {
            return Err(node_err(
                src,
                format!("instance {i}: its world transform is not finite"),
            ));
        }
        out.push(m);
    }
    Ok(out)
}
