//! Render-level instancing: nine placements of one emissive octahedron (rotated, scaled
//! non-uniformly, every third mirrored) render the image of the same scene flattened (a mesh
//! entry per node), with both intersectors. Each instance is its own light and they light
//! each other (white diffuse base, path depth 3).

use crate::common;

use common::{mean_and_stderr, render, renderer_from};
use flowlight_testkit::gltf::{octahedra_gltf, octahedra_placements};

const BODY_BVH: &str = r#"
[render]
width = 48
height = 16
spp = 8
seed = 5
intersector = "bvh"
[camera]
position = [12.0, 1.0, 10.0]
look_at = [12.0, 1.0, -2.0]
fov_y = 40.0
[integrator]
plugin = "mcpt"
path_depth = 3
"#;

#[test]
fn instanced_emissive_octahedra_render_like_their_flattened_copy() {
    let placements = octahedra_placements(9);
    let material =
        r#"{"emissiveFactor": [1.0, 0.8, 0.6], "pbrMetallicRoughness": {"metallicFactor": 0.0}}"#;
    for isect in ["bvh", "embree"] {
        let body = BODY_BVH.replace("\"bvh\"", &format!("\"{isect}\""));
        let shared = renderer_from(
            &format!("inst-shared-{isect}"),
            &octahedra_gltf(&placements, false, material),
            &body,
            8,
        );
        let flat = renderer_from(
            &format!("inst-flat-{isect}"),
            &octahedra_gltf(&placements, true, material),
            &body,
            8,
        );
        assert_eq!(shared.scene.triangles.len(), 8);
        assert_eq!(flat.scene.triangles.len(), 72);
        // One light per instance's triangle, as flattened.
        assert_eq!(shared.scene.emitters.len(), 72);
        assert_eq!(shared.intersector.name(), isect);
        let (a, b) = (render(&shared), render(&flat));
        let (ia, ib) = (a.frame.image(), b.frame.image());
        let lum = |c: flowlight_core::Rgb| c.r + c.g + c.b;
        let (ma, sa) = mean_and_stderr(&ia, lum);
        let (mb, sb) = mean_and_stderr(&ib, lum);
        assert!(ma > 0.03, "{isect}: the octahedra are lit: {ma}");
        assert!(
            (ma - mb).abs() < 3.0 * (sa * sa + sb * sb).sqrt() + 1e-6,
            "{isect}: instanced {ma} ± {sa} vs flattened {mb} ± {sb}"
        );
        // Same seeds, same hits: nearly every pixel is the same up to float noise.
        let differing = ia
            .iter()
            .zip(&ib)
            .filter(|(x, y)| (lum(**x) - lum(**y)).abs() > 1e-3 * (1.0 + lum(**y)))
            .count();
        assert!(
            differing * 20 <= ia.len(),
            "{isect}: {differing} of {} pixels differ",
            ia.len()
        );
    }
}
