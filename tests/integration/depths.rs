//! One definition of `max_ray_depth` for every sampler: at most k scattering vertices
//! between the eye and the light, the light found by the k-th vertex's light sample or BSDF
//! sample (docs/mcpt.md, "Depths"). A mirror floor under a white sky, seen from above, at
//! `path_depth = 1` and `max_ray_depth = 1`: every pixel sees the sky once reflected (one
//! scattering vertex), so the image is the sky's radiance, for both MCPT variants. Before
//! both counted the same, the untangled variant stopped at the mirror and rendered black.

use crate::common;

use common::{quads_gltf, render, renderer_from, FLOOR};

const MIRROR: &str = r#"{"name": "mirror", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.0}}"#;

fn config(variant: &str, max_ray_depth: u32) -> String {
    format!(
        r#"[render]
width = 16
height = 16
seed = 5
intersector = "bvh"
[camera]
position = [0.0, 2.0, 2.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0
[environment]
color = [1.0, 1.0, 1.0]
strength = 2.0
[integrator]
plugin = "mcpt"
variant = "{variant}"
path_depth = 1
max_ray_depth = {max_ray_depth}
"#
    )
}

#[test]
fn max_ray_depth_counts_scattering_vertices_in_both_mcpt_variants() {
    let gltf = quads_gltf(&[FLOOR], MIRROR, &[], "");
    for variant in ["entangled", "untangled"] {
        let s = renderer_from(&format!("depth-{variant}"), &gltf, &config(variant, 1), 4);
        let img = render(&s).frame.image();
        for (i, c) in img.iter().enumerate() {
            assert!(
                (c.luminance() - 2.0).abs() < 1e-3,
                "{variant}: pixel {i} is {c:?}, want the sky's 2.0 seen in the mirror"
            );
        }
    }
}
