//! Render-level alpha MASK: a camera looks at an emissive quad (radiance 1, nothing else in
//! the scene) whose right half is cut away by its base colour texture's alpha. Pixels on the
//! left see the lamp (exactly 1: nothing else reflects), pixels on the right see through the
//! cut into the empty background (exactly 0), with both intersectors.

use crate::common;

use common::{render, scratch};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_testkit::gltf::{png8, Quad};

fn render_cut(intersector: &str, mode: &str) -> Vec<Vec<f32>> {
    let dir = scratch(&format!("alpha-{intersector}-{mode}"));
    let q = Quad {
        images: vec![png8(2, 1, 4, &[255, 255, 255, 255, 255, 255, 255, 0])],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: r#"{"magFilter": 9728}"#.into(),
        material: format!(
            r#"{{"alphaMode": "{mode}", "emissiveFactor": [1, 1, 1],
                "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}}}}}"#
        ),
        ..Quad::default()
    };
    q.write(&dir, "cut.gltf");
    let toml = format!(
        r#"scene = "cut.gltf"
[render]
width = 16
height = 16
spp = 4
seed = 3
intersector = "{intersector}"
[camera]
position = [0.5, 0.5, 3.0]
look_at = [0.5, 0.5, 0.0]
fov_y = 10.0
[integrator]
plugin = "mcpt"
path_depth = 2
"#
    );
    let cfg = dir.join("cut.toml");
    std::fs::write(&cfg, toml).unwrap();
    let ov = Overrides {
        threads: Some(2),
        ..Default::default()
    };
    let mut s = Renderer::prepare(&cfg, &ov).unwrap_or_else(|e| panic!("{e}"));
    s.exr_path = None;
    s.png_path = None;
    let out = render(&s);
    let img = out.frame.image();
    (0..16)
        .map(|y| (0..16).map(|x| img[y * 16 + x].g).collect())
        .collect()
}

#[test]
fn a_masked_half_is_seen_through_with_both_intersectors() {
    for isect in ["bvh", "embree"] {
        let rows = render_cut(isect, "MASK");
        for (y, row) in rows.iter().enumerate() {
            for (x, &v) in row.iter().enumerate() {
                // Columns 7 and 8 straddle the cut at x = 0.5.
                if x < 7 {
                    assert!(
                        (v - 1.0).abs() < 1e-4,
                        "{isect}: pixel ({x}, {y}) = {v}, lamp expected"
                    );
                } else if x > 8 {
                    assert!(
                        v.abs() < 1e-6,
                        "{isect}: pixel ({x}, {y}) = {v}, the cut expected"
                    );
                }
            }
        }
        // Without the mask the whole quad is seen.
        let opaque = render_cut(isect, "OPAQUE");
        assert!(
            opaque.iter().flatten().all(|&v| (v - 1.0).abs() < 1e-4),
            "{isect}"
        );
    }
}
