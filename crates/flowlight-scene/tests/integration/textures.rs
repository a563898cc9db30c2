//! Texture channels and vertex attributes, end to end through the glTF loader: each test
//! builds a small quad file whose correct answer is known and checks the numbers.

use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::material::{AlphaMode, Filter, Wrap};
use flowlight_scene::gltf_loader::load_gltf;
use flowlight_scene::texture::srgb_to_linear;
use flowlight_scene::{Scene, Texels};
use flowlight_testkit::gltf::{png8, temp_dir, Attribute, Quad};
use glam::{Vec2, Vec3};
use std::collections::BTreeMap;

fn load(q: &Quad, tag: &str) -> Scene {
    let dir = temp_dir(tag);
    let path = q.write(&dir, "q.gltf");
    load_gltf(&path, &BTreeMap::new()).unwrap_or_else(|e| panic!("{e}"))
}

/// Triangle and barycentrics of the quad's point (x, y, 0) (see `Quad`'s triangles).
fn bary(x: f32, y: f32) -> (u32, f32, f32) {
    if x >= y {
        (0, x - y, y)
    } else {
        (1, x, y - x)
    }
}

/// The hit of a ray arriving at (x, y, 0) from direction `from` (towards the viewer).
fn hit_from(s: &Scene, x: f32, y: f32, from: Vec3) -> SurfaceHit {
    let (prim, b1, b2) = bary(x, y);
    let from = from.normalize();
    let ray = Ray::new(Vec3::new(x, y, 0.0) + from, -from, f32::INFINITY);
    s.surface_hit(&ray, 1.0, prim, b1, b2)
}

fn hit(s: &Scene, x: f32, y: f32) -> SurfaceHit {
    hit_from(s, x, y, Vec3::Z)
}

const NEAREST: &str = r#"{"magFilter": 9728, "minFilter": 9728}"#;

/// Tangent-space unit vector tilted by `deg` from +Z towards `axis` (0 = +X, 1 = +Y),
/// encoded as an 8-bit normal-map texel, and the vector that texel decodes to.
fn normal_texel(deg: f32, axis: usize) -> ([u8; 3], Vec3) {
    let (s, c) = deg.to_radians().sin_cos();
    let mut v = [0.0, 0.0, c];
    v[axis] = s;
    let t = v.map(|x| ((x + 1.0) * 0.5 * 255.0).round() as u8);
    let d = Vec3::from_array(t.map(|x| x as f32 / 255.0 * 2.0 - 1.0)).normalize();
    (t, d)
}

fn normal_map_quad(tangent: Option<[f32; 4]>, scale: f32) -> (Quad, Vec3, Vec3) {
    // Left texel tilts 30° towards +X (tangent), right texel 30° towards +Y (bitangent).
    let (tx, dx) = normal_texel(30.0, 0);
    let (ty, dy) = normal_texel(30.0, 1);
    let texels = [tx, ty].concat();
    let mut q = Quad {
        images: vec![png8(2, 1, 3, &texels)],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: format!(r#"{{"normalTexture": {{"index": 0, "scale": {scale}}}}}"#),
        ..Quad::default()
    };
    if let Some(t) = tangent {
        q.extra.push(Attribute::floats("TANGENT", [t; 4]));
    }
    (q, dx, dy)
}

#[test]
fn normal_map_tilts_the_shading_normal_by_the_known_angle() {
    // With the TANGENT attribute, with MikkTSpace tangents, and with a flat-shaded primitive
    // (no NORMAL: MikkTSpace over face normals), the same answer: the quad's +X is the
    // tangent (u grows with x) and +Y the bitangent (v = 1 − y, so "up" in the image).
    for (tag, tangent, flat) in [
        ("attr", Some([1.0, 0.0, 0.0, 1.0]), false),
        ("mikk", None, false),
        ("flat", None, true),
    ] {
        let (mut q, dx, dy) = normal_map_quad(tangent, 1.0);
        q.no_normals = flat;
        let s = load(&q, tag);
        assert_eq!(s.tangents.len(), s.positions.len(), "{tag}");
        let h = hit(&s, 0.25, 0.6);
        assert!((h.ns - dx).length() < 1e-5, "{tag}: {} vs {dx}", h.ns);
        let angle = h.ns.dot(Vec3::Z).acos().to_degrees();
        assert!((angle - 30.0).abs() < 0.3, "{tag}: {angle}°");
        // The 8-bit texel for 0 is 128, which decodes to 1/255, not 0.
        assert!(
            h.ns.x > 0.49 && (h.ns.y - dx.y).abs() < 1e-5 && dx.y.abs() < 0.005,
            "{tag}: {}",
            h.ns
        );
        let h = hit(&s, 0.75, 0.3);
        assert!((h.ns - dy).length() < 1e-5, "{tag}: {} vs {dy}", h.ns);
        assert!(
            h.ns.y > 0.49 && (h.ns.x - dy.x).abs() < 1e-5,
            "{tag}: {}",
            h.ns
        );
        assert_eq!(h.ng, Vec3::Z);
    }
    // A left-handed TANGENT (w = −1) flips the bitangent: the +Y texel now tilts to −Y.
    let (q, _, dy) = normal_map_quad(Some([1.0, 0.0, 0.0, -1.0]), 1.0);
    let h = hit(&load(&q, "lefthanded"), 0.75, 0.3);
    assert!(
        (h.ns - Vec3::new(dy.x, -dy.y, dy.z)).length() < 1e-5,
        "{}",
        h.ns
    );
    // normalTexture.scale multiplies X and Y: scale 0 gives back the interpolated normal.
    let (q, dx, _) = normal_map_quad(None, 0.0);
    assert!((hit(&load(&q, "scale0"), 0.25, 0.6).ns - Vec3::Z).length() < 1e-6);
    let (q, _, _) = normal_map_quad(None, 2.0);
    let want = Vec3::new(2.0 * dx.x, 2.0 * dx.y, dx.z).normalize();
    // Seen along the normal itself: from straight above, the mirror reflection about this
    // 49° tilt would fall below the surface and the normal would be bent back
    // (`flowlight_core::specular_normal`).
    let h = hit_from(&load(&q, "scale2"), 0.25, 0.6, want);
    assert!((h.ns - want).length() < 1e-5, "{} vs {want}", h.ns);
}

#[test]
fn a_normal_map_facing_away_from_the_viewer_is_bent_back() {
    // The +X texel tilts the normal 30° towards +X; a viewer grazing in from −X at 20°
    // elevation would see the surface from below the shading normal (n·wo < 0).
    let (q, dx, _) = normal_map_quad(None, 1.0);
    let s = load(&q, "bend");
    let wo = Vec3::new(-(20f32.to_radians().cos()), 0.0, 20f32.to_radians().sin());
    assert!(dx.dot(wo) < 0.0);
    let h = hit_from(&s, 0.25, 0.6, wo);
    assert!(h.ns.dot(wo) > 0.0, "{} · {wo}", h.ns);
    assert!(h.ns.dot(h.ng) > 0.0 && h.ns.y.abs() < 0.005, "{}", h.ns);
    assert!((h.ns.length() - 1.0).abs() < 1e-5);
    // Seen from above, the same point keeps the unbent normal.
    assert!((hit(&s, 0.25, 0.6).ns - dx).length() < 1e-5);
    // From below the surface (wo on −ng's side) the bend goes the other way.
    let below = Vec3::new(-wo.x, 0.0, -wo.z);
    let h = hit_from(&s, 0.25, 0.6, below);
    assert!(h.ns.dot(below) < 0.0 && h.ns.dot(h.ng) > 0.0, "{}", h.ns);
}

fn alpha_quad(mode: &str, alpha: [u8; 2]) -> Quad {
    // Base colour 2×1 RGBA: left half alpha[0], right half alpha[1].
    Quad {
        images: vec![png8(
            2,
            1,
            4,
            &[255, 255, 255, alpha[0], 255, 255, 255, alpha[1]],
        )],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: format!(
            r#"{{"alphaMode": "{mode}", "alphaCutoff": 0.5, "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}}}}}"#
        ),
        ..Quad::default()
    }
}

#[test]
fn alpha_mask_cuts_the_quad_where_alpha_is_below_the_cutoff() {
    let s = load(&alpha_quad("MASK", [255, 0]), "mask");
    assert!(s.has_alpha());
    assert_eq!(s.materials[0].alpha_mode, AlphaMode::Mask);
    for (x, y) in [
        (0.1, 0.2),
        (0.4, 0.9),
        (0.3, 0.1),
        (0.6, 0.5),
        (0.9, 0.1),
        (0.7, 0.95),
    ] {
        let (prim, b1, b2) = bary(x, y);
        let ray = Ray::new(Vec3::new(x, y, 1.0), -Vec3::Z, f32::INFINITY);
        assert_eq!(s.passes_through(&ray, prim, b1, b2), x > 0.5, "({x}, {y})");
    }
    // OPAQUE ignores alpha.
    let s = load(&alpha_quad("OPAQUE", [255, 0]), "opaque");
    assert!(!s.has_alpha());
    let ray = Ray::new(Vec3::new(0.9, 0.1, 1.0), -Vec3::Z, f32::INFINITY);
    let (prim, b1, b2) = bary(0.9, 0.1);
    assert!(!s.passes_through(&ray, prim, b1, b2));
}

#[test]
fn alpha_blend_passes_with_probability_one_minus_alpha_deterministically() {
    // α = 64/255 ≈ 0.251 everywhere: about 74.9% of rays pass.
    let s = load(&alpha_quad("BLEND", [64, 64]), "blend");
    let alpha = 64.0 / 255.0;
    let n = 20_000;
    let mut passed = 0;
    for i in 0..n {
        let x = (i as f32 + 0.5) / n as f32;
        let y = ((i * 7919) % n) as f32 / n as f32;
        let (prim, b1, b2) = bary(x, y);
        let ray = Ray::new(Vec3::new(x, y, 1.0), -Vec3::Z, f32::INFINITY);
        let p = s.passes_through(&ray, prim, b1, b2);
        assert_eq!(p, s.passes_through(&ray, prim, b1, b2), "deterministic");
        passed += p as usize;
    }
    let frac = passed as f64 / n as f64;
    // Binomial σ = sqrt(0.19 / 20000) ≈ 0.003; 5σ.
    assert!((frac - (1.0 - alpha)).abs() < 0.016, "{frac}");
}

#[test]
fn texture_transform_moves_the_lookup_to_the_expected_texel() {
    // 4×4 grey texture, texel (i, j) = 10·(4j + i); offset (0.5, 0.25) and a texCoord
    // override to set 1 (which equals set 0 here but for an offset of +0.25 in u).
    let texels: Vec<u8> = (0..16u8).map(|i| i * 10).collect();
    let uv1 = [[0.25, 1.0], [1.25, 1.0], [1.25, 0.0], [0.25, 0.0]];
    let q = Quad {
        images: vec![png8(4, 4, 1, &texels)],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        extra: vec![Attribute::floats("TEXCOORD_1", uv1)],
        material: r#"{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0,
            "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.25], "texCoord": 1}}}},
            "normalTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.125, 0], "rotation": 0.5}}}}"#
            .into(),
        extensions_used: r#""KHR_texture_transform""#.into(),
        ..Quad::default()
    };
    let s = load(&q, "transform");
    let m = &s.materials[0];
    assert_eq!(m.base_color_texture.tex_coord, 1);
    // Normal texture transform read from the JSON path.
    let t = m.normal_texture.transform;
    assert!(
        (t[4] - 0.125).abs() < 1e-7 && (t[0] - 0.5f32.cos()).abs() < 1e-6,
        "{t:?}"
    );
    // Point (0.1, 0.9): uv1 = (0.35, 0.1) → (0.85, 0.35) → texel (3, 1) = 70.
    let h = hit(&s, 0.1, 0.9);
    assert!((h.uv1 - Vec2::new(0.35, 0.1)).length() < 1e-6, "{}", h.uv1);
    let r = m.resolve(h.uvs(), h.color, &s.texture_table);
    // (glTF's default baseColorFactor is 1.)
    let want = srgb_to_linear(70.0 / 255.0);
    assert!((r.base.r - want).abs() < 1e-6, "{} vs {want}", r.base.r);
}

#[test]
fn sampler_wrap_modes_and_filters_reach_the_texture() {
    let q = Quad {
        images: vec![png8(2, 1, 1, &[0, 255])],
        textures: r#"{"source": 0, "sampler": 0}, {"source": 0, "sampler": 1}, {"source": 0}"#
            .into(),
        samplers: r#"{"magFilter": 9728, "wrapS": 33071, "wrapT": 33648},
                     {"magFilter": 9729, "minFilter": 9987, "wrapS": 33648}"#
            .into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
            "metallicRoughnessTexture": {"index": 1}}, "emissiveTexture": {"index": 2},
            "emissiveFactor": [1, 1, 1]}"#
            .into(),
        ..Quad::default()
    };
    let s = load(&q, "samplers");
    assert_eq!(s.textures.len(), 3);
    // One image decoded, shared by the three textures.
    assert_eq!(s.stats.images_decoded, 1);
    match (&s.textures[0].image.texels, &s.textures[2].image.texels) {
        (Texels::U8(a), Texels::U8(b)) => assert!(std::sync::Arc::ptr_eq(a, b)),
        other => panic!("{other:?}"),
    }
    let t0 = s.texture_table[0];
    assert_eq!(
        (t0.wrap_s, t0.wrap_t, t0.filter),
        (Wrap::ClampToEdge, Wrap::MirroredRepeat, Filter::Nearest)
    );
    let t1 = s.texture_table[1];
    // LINEAR_MIPMAP_LINEAR minification counts as linear.
    assert_eq!(
        (t1.wrap_s, t1.wrap_t, t1.filter),
        (Wrap::MirroredRepeat, Wrap::Repeat, Filter::Linear)
    );
    let t2 = s.texture_table[2];
    assert_eq!(
        (t2.wrap_s, t2.wrap_t, t2.filter),
        (Wrap::Repeat, Wrap::Repeat, Filter::Linear)
    );
    // u = 1.3: clamped → texel 1 (255); mirrored, linear: x = 2.6 − 0.5 = 2.1 between
    // texel 2 → 1 (255) and texel 3 → 0 (0): 0.9·1 + 0.1·0; repeat, linear: texels 0 and 1.
    let uv = Vec2::new(1.3, 0.5);
    assert!((t0.sample(uv, false).x - 1.0).abs() < 1e-6);
    assert!(
        (t1.sample(uv, false).x - 0.9).abs() < 1e-5,
        "{}",
        t1.sample(uv, false).x
    );
    let rep = t2.sample(uv, false).x; // x = 2.1 → texel 0 (0) and 1 (255): 0.9·0 + 0.1·1.
    assert!((rep - 0.1).abs() < 1e-5, "{rep}");
}

#[test]
fn srgb_decode_applies_to_colour_textures_only() {
    // One RGB texel (128, 128, 128) as base colour (sRGB), metallic-roughness (linear) and
    // emissive (sRGB).
    let q = Quad {
        images: vec![png8(1, 1, 3, &[128, 128, 128])],
        textures: r#"{"source": 0}"#.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1],
            "baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 0},
            "metallicFactor": 1, "roughnessFactor": 1},
            "emissiveTexture": {"index": 0}, "emissiveFactor": [1, 0.5, 1]}"#
            .into(),
        ..Quad::default()
    };
    let s = load(&q, "srgb");
    assert_eq!(s.textures[0].image.texels.bytes(), 3);
    let h = hit(&s, 0.5, 0.5);
    let r = s.materials[0].resolve(h.uvs(), h.color, &s.texture_table);
    let dec = srgb_to_linear(128.0 / 255.0);
    assert!((r.base.g - dec).abs() < 1e-6 && (dec - 0.2158).abs() < 1e-3);
    assert!((r.material.roughness - 128.0 / 255.0).abs() < 1e-6);
    assert!((r.material.metallic - 128.0 / 255.0).abs() < 1e-6);
    assert!((r.material.emission.g - 0.5 * dec).abs() < 1e-6);
    let e = s.materials[0].emission_at(h.uvs(), &s.texture_table);
    assert_eq!(e, r.material.emission);
}

#[test]
fn color_0_multiplies_the_base_colour_as_floats_and_normalized_bytes() {
    // Float RGB vertex colours: red at x = 0, blue at x = 1 (vertices 1, 2 at x = 1).
    let rgb = [
        [1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
    ];
    let q = Quad {
        extra: vec![Attribute::floats("COLOR_0", rgb)],
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1]}}"#.into(),
        ..Quad::default()
    };
    let s = load(&q, "color-f32");
    let h = hit(&s, 0.25, 0.5);
    assert!((h.color[0] - 0.75).abs() < 1e-6 && (h.color[2] - 0.25).abs() < 1e-6);
    assert_eq!(h.color[3], 1.0);
    let r = s.materials[0].resolve(h.uvs(), h.color, &s.texture_table);
    assert!((r.base.r - 0.375).abs() < 1e-6 && (r.base.b - 0.25).abs() < 1e-6);
    // Normalized unsigned-byte RGBA, alpha 51/255 = 0.2 on every vertex.
    let q = Quad {
        extra: vec![Attribute {
            semantic: "COLOR_0".into(),
            ty: "VEC4",
            component_type: 5121,
            normalized: true,
            bytes: [
                [255u8, 0, 0, 51],
                [0, 0, 255, 51],
                [0, 0, 255, 51],
                [255, 0, 0, 51],
            ]
            .concat(),
        }],
        material: r#"{"alphaMode": "MASK", "alphaCutoff": 0.3}"#.into(),
        ..Quad::default()
    };
    let s = load(&q, "color-u8");
    let h = hit(&s, 0.25, 0.5);
    assert!((h.color[0] - 0.75).abs() < 1e-6 && (h.color[3] - 0.2).abs() < 1e-6);
    // Vertex alpha 0.2 < cutoff 0.3: the whole quad is cut away.
    let (prim, b1, b2) = bary(0.25, 0.5);
    let ray = Ray::new(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z, f32::INFINITY);
    assert!(s.passes_through(&ray, prim, b1, b2));
    // Without COLOR_0 the colour is white and takes no memory.
    let s = load(&Quad::default(), "color-none");
    assert!(s.colors.is_empty() && s.uvs1.is_empty() && s.tangents.is_empty());
    assert_eq!(hit(&s, 0.3, 0.3).color, [1.0; 4]);
}

#[test]
fn the_second_uv_set_feeds_the_textures_that_ask_for_it() {
    // Emissive 2×1 texture (black | white) read through TEXCOORD_1 = (1 − x, y), so the
    // white texel lies at small x; the base colour reads TEXCOORD_0 (white | black).
    let uv1 = [[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
    let q = Quad {
        images: vec![png8(2, 1, 1, &[0, 255]), png8(2, 1, 1, &[255, 0])],
        textures: r#"{"source": 0, "sampler": 0}, {"source": 1, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        extra: vec![Attribute::floats("TEXCOORD_1", uv1)],
        material: r#"{"emissiveTexture": {"index": 0, "texCoord": 1}, "emissiveFactor": [1, 1, 1],
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}}"#
            .into(),
        ..Quad::default()
    };
    let s = load(&q, "uv1");
    let m = &s.materials[0];
    let left = hit(&s, 0.2, 0.5);
    let right = hit(&s, 0.8, 0.5);
    assert!((left.uv1 - Vec2::new(0.8, 0.5)).length() < 1e-6);
    assert_eq!(m.emission_at(left.uvs(), &s.texture_table).r, 1.0);
    assert_eq!(m.emission_at(right.uvs(), &s.texture_table).r, 0.0);
    let rl = m.resolve(left.uvs(), left.color, &s.texture_table);
    let rr = m.resolve(right.uvs(), right.color, &s.texture_table);
    assert!((rl.base.r - 1.0).abs() < 1e-6 && rr.base.r == 0.0);
}

#[test]
fn bad_texture_fields_are_clear_errors() {
    let mut q = alpha_quad("MASK", [255, 0]);
    q.material = r#"{"alphaMode": "MASK", "alphaCutoff": -1}"#.into();
    let dir = temp_dir("bad");
    let e = load_gltf(&q.write(&dir, "bad.gltf"), &BTreeMap::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("alphaCutoff") && e.contains("bad.gltf"), "{e}");
    let mut q = normal_map_quad(None, 1.0).0;
    q.material = r#"{"normalTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [1]}}}}"#.into();
    let e = load_gltf(&q.write(&dir, "bad2.gltf"), &BTreeMap::new())
        .unwrap_err()
        .to_string();
    assert!(e.contains("normalTexture") && e.contains("offset"), "{e}");
}

#[test]
fn a_normal_map_below_the_surface_is_lifted_to_the_horizon_not_mirrored() {
    // A texel pointing 100° away from +Z towards +X: below the geometric surface.
    let (s, c) = 100f32.to_radians().sin_cos();
    let t = [s, 0.0, c].map(|x: f32| ((x + 1.0) * 0.5 * 255.0).round() as u8);
    let q = Quad {
        images: vec![png8(1, 1, 3, &t)],
        textures: r#"{"source": 0}"#.into(),
        material: r#"{"normalTexture": {"index": 0}}"#.into(),
        ..Quad::default()
    };
    let sc = load(&q, "below");
    // Seen from +X (so the bend towards the viewer leaves it alone), it stays tilted to +X,
    // lifted above the horizon; the mirror reflection of the viewer about a normal at the
    // horizon would fall below the surface, so it is then turned up just enough to keep that
    // reflection at the height min(0.9 cos θ_o, 0.01) (`flowlight_core::specular_normal`).
    let wo = Vec3::new(1.0, 0.0, 1.0).normalize();
    let h = hit_from(&sc, 0.5, 0.3, wo);
    assert!(
        h.ns.x > 0.7 && h.ns.z > 0.0 && h.ns.y.abs() < 0.01,
        "{}",
        h.ns
    );
    let reflected = h.ns * (2.0 * h.ns.dot(wo)) - wo;
    assert!((reflected.z - 0.01).abs() < 1e-3, "{reflected}");
}

/// An emissive texture that is black over the quad's upper-left triangle (u + v < 1) and white
/// over most of the other: the black triangle emits nothing and is no light; the other is the
/// only emitter, and its radiance follows the texture (the factor where white, 0 where black).
#[test]
fn emissive_texture_black_half_is_not_a_light() {
    const N: usize = 8;
    let mut texels = Vec::new();
    for j in 0..N {
        for i in 0..N {
            let v = if i + j >= N { 255 } else { 0 };
            texels.extend_from_slice(&[v, v, v]);
        }
    }
    let q = Quad {
        images: vec![png8(N as u32, N as u32, 3, &texels)],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: r#"{"emissiveFactor": [1.0, 0.5, 0.25], "emissiveTexture": {"index": 0}}"#.into(),
        ..Quad::default()
    };
    let s = load(&q, "emissive-half");
    assert_eq!(s.emitters.len(), 1, "only the lit triangle is a light");
    assert_eq!(s.stats.black_emitters, 1);
    assert_eq!(s.triangle_emitter, vec![0, -1]);
    let e = &s.emitters[0];
    assert_eq!(e.prim, 0);
    // Deep in the white part (x = 0.9, y = 0.2: u = 0.9, v = 0.8) and in a black texel of the
    // lit triangle (x = 0.55, y = 0.51: u = 0.55, v = 0.49 → texel (4, 3), 4 + 3 < 8).
    let at = |x: f32, y: f32| {
        let (prim, b1, b2) = bary(x, y);
        assert_eq!(prim, 0);
        e.emission_at([1.0 - b1 - b2, b1, b2], &s.materials, &s.texture_table)
    };
    assert_eq!(at(0.9, 0.2), flowlight_core::Rgb::new(1.0, 0.5, 0.25));
    assert_eq!(at(0.55, 0.51), flowlight_core::Rgb::ZERO);
}

/// One lit texel of a 64² emissive texture inside a triangle that covers 2048 texels: the
/// triangle is still a light (a fixed 4×4 set of points would miss it and drop its light), and
/// its mean radiance is the texel's share of the triangle.
#[test]
fn a_small_lit_feature_keeps_its_triangle_a_light() {
    const N: usize = 64;
    let (li, lj) = (20, 30); // u = 0.32, v = 0.48: u + v < 1, the quad's triangle 1
    let mut texels = vec![0u8; N * N * 3];
    for c in 0..3 {
        texels[(lj * N + li) * 3 + c] = 255;
    }
    let q = Quad {
        images: vec![png8(N as u32, N as u32, 3, &texels)],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: r#"{"emissiveFactor": [1.0, 1.0, 1.0], "emissiveTexture": {"index": 0}}"#.into(),
        ..Quad::default()
    };
    let s = load(&q, "emissive-texel");
    assert_eq!(
        s.triangle_emitter,
        vec![-1, 0],
        "the lit texel's triangle is the light"
    );
    let share = 1.0 / (0.5 * (N * N) as f32);
    let mean = s.emitters[0].radiance.g;
    assert!(
        (mean / share - 1.0).abs() < 0.5,
        "mean radiance {mean}, the texel's share {share}"
    );
}

// ---- Textures of the BRDF extensions: each a 2×1 texture (left half | right half), nearest
// filtering, so the quad's x < 0.5 reads the left texel and x > 0.5 the right one.

use flowlight_core::bsdf::Bsdf;
use flowlight_core::material::{Material, ResolvedMaterial};
use flowlight_core::Rgb;

/// A quad whose `material` reads a 2×1 texture of `channels` channels, `left` | `right`.
fn halves(channels: u32, left: &[u8], right: &[u8], material: &str, used: &str) -> Quad {
    Quad {
        images: vec![png8(2, 1, channels, &[left, right].concat())],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: material.into(),
        extensions_used: format!(r#""{used}""#),
        ..Quad::default()
    }
}

/// The resolved material at the quad's left (x = 0.25) and right (x = 0.75) halves.
fn left_right(s: &Scene) -> (ResolvedMaterial, ResolvedMaterial) {
    let at = |x: f32| {
        let h = hit(s, x, 0.5);
        s.materials[0].resolve(h.uvs(), h.color, &s.texture_table)
    };
    (at(0.25), at(0.75))
}

fn bsdf(r: &ResolvedMaterial) -> Bsdf {
    Bsdf::from_material(&r.material, r.base)
}

/// Energy that light arriving along the normal (ω_o = +z) leaves with, above and below the
/// surface: E[f |cos θ_i| / pdf] over stratified samples of the mixture (component choice
/// and direction × a lobe's own discrete choice × the direction's second number). Exact for
/// Dirac lobes, which is all these tests use where they compare.
fn scattered(b: &Bsdf) -> (Rgb, Rgb) {
    // The pair's first number, which chooses the component, in 4096 strata: a lobe of
    // weight w is chosen w ± 1/4096 of the time. The lobe's own number (a dielectric's
    // reflect/refract choice) goes through all 4096 strata too for each `i`, in an order
    // (c · 1597 mod 4096, 1597 odd) that pairs it with every part of the first number.
    const N: usize = 4096;
    const M: usize = 4;
    // Summed in f64: 2¹⁶ f32 additions would drift by ~10⁻⁴ relative.
    let (mut up, mut down) = ([0f64; 3], [0f64; 3]);
    for c in 0..N {
        for i in 0..M {
            for j in 0..M {
                let uc = ((c * 1597 + i * (N / M)) % N) as f32 / N as f32 + 0.5 / N as f32;
                let u = Vec2::new((c as f32 + 0.5) / N as f32, (j as f32 + 0.5) / M as f32);
                if let Some(s) = b.sample(Vec3::Z, uc, u) {
                    let w = (s.f * (s.wi.z.abs() / s.pdf)).to_array();
                    let sum = if s.wi.z > 0.0 { &mut up } else { &mut down };
                    for k in 0..3 {
                        sum[k] += w[k] as f64;
                    }
                }
            }
        }
    }
    let n = (N * M * M) as f64;
    let mean = |a: [f64; 3]| Rgb::new((a[0] / n) as f32, (a[1] / n) as f32, (a[2] / n) as f32);
    (mean(up), mean(down))
}

fn near(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn transmission_texture_red_channel_switches_what_passes_through() {
    // White smooth dielectric, transmissionFactor 0.8; texture R = 0 | 255 (G, B = 255 | 0
    // so a wrong channel would swap the halves).
    let q = halves(
        3,
        &[0, 255, 255],
        &[255, 0, 0],
        r#"{"pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0},
            "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.8,
            "transmissionTexture": {"index": 0}}}}"#,
        "KHR_materials_transmission",
    );
    let s = load(&q, "ext-transmission");
    assert!(s.materials[0].transmission_texture.is_some());
    let (l, r) = left_right(&s);
    assert_eq!(
        (l.material.transmission, r.material.transmission),
        (0.0, 0.8)
    );
    let (_, down_l) = scattered(&bsdf(&l));
    let (up_r, down_r) = scattered(&bsdf(&r));
    // Left: opaque, nothing below. Right: the thin dielectric at normal incidence passes
    // t (1 − F0) = 0.8 · 0.96 of white light and reflects F0 = 0.04 specularly, the rest
    // (1 − t)(1 − F0) = 0.192 diffusely.
    assert_eq!(down_l, Rgb::ZERO);
    assert!(near(down_r.g, 0.8 * 0.96, 2e-3), "{down_r:?}");
    assert!(near(up_r.g, 0.04 + 0.2 * 0.96, 2e-2), "{up_r:?}");
}

#[test]
fn specular_texture_alpha_zero_removes_the_dielectric_specular() {
    // Black smooth dielectric: all it reflects is the specular layer, F0 = 0.04 at ior 1.5.
    // specularTexture RGBA: A = 0 | 255 (RGB 255 | 0, the wrong channels).
    let q = halves(
        4,
        &[255, 255, 255, 0],
        &[0, 0, 0, 255],
        r#"{"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0,
            "roughnessFactor": 0},
            "extensions": {"KHR_materials_specular": {"specularFactor": 1,
            "specularTexture": {"index": 0}}}}"#,
        "KHR_materials_specular",
    );
    let s = load(&q, "ext-specular");
    let (l, r) = left_right(&s);
    assert_eq!((l.material.specular, r.material.specular), (0.0, 1.0));
    let (up_l, down_l) = scattered(&bsdf(&l));
    let (up_r, _) = scattered(&bsdf(&r));
    assert_eq!((up_l, down_l), (Rgb::ZERO, Rgb::ZERO));
    for v in up_r.to_array() {
        assert!(near(v, 0.04, 1e-5), "{up_r:?}");
    }
}

#[test]
fn specular_color_texture_tints_f0_after_the_srgb_decode() {
    // specularColorTexture (sRGB): (255, 128, 0) | white, × specularColorFactor (1, 2, 1).
    let q = halves(
        3,
        &[255, 128, 0],
        &[255, 255, 255],
        r#"{"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0,
            "roughnessFactor": 0},
            "extensions": {"KHR_materials_specular": {"specularColorFactor": [1, 2, 1],
            "specularColorTexture": {"index": 0}}}}"#,
        "KHR_materials_specular",
    );
    let s = load(&q, "ext-specular-color");
    let (l, r) = left_right(&s);
    let dec = srgb_to_linear(128.0 / 255.0);
    assert!(near(l.material.specular_color.g, 2.0 * dec, 1e-6));
    assert_eq!(l.material.specular_color.b, 0.0);
    assert_eq!(r.material.specular_color, Rgb::new(1.0, 2.0, 1.0));
    // F0 = min(0.04 C, 1) per channel: (0.04, 0.08 · 0.2158, 0) on the left.
    let (up_l, _) = scattered(&bsdf(&l));
    let (up_r, _) = scattered(&bsdf(&r));
    assert!(near(up_l.r, 0.04, 1e-5), "{up_l:?}");
    assert!(near(up_l.g, 0.08 * dec, 1e-5), "{up_l:?}");
    assert!(near(up_l.b, 0.0, 1e-6), "{up_l:?}");
    assert!(near(up_r.g, 0.08, 1e-5), "{up_r:?}");
}

#[test]
fn clearcoat_textures_scale_the_coat_and_its_roughness() {
    // A black base with no dielectric specular (specularFactor 0), so all that reflects is
    // the coat: F0 = 0.04 at normal incidence where clearcoat = 1, nothing where it is 0.
    // clearcoatTexture reads R (0 | 255); clearcoatRoughnessTexture, the same image through
    // a second texture, reads G (255 | 0): the left half's coat would be rough.
    let q = Quad {
        images: vec![png8(2, 1, 3, &[0, 255, 0, 255, 0, 255])],
        textures: r#"{"source": 0, "sampler": 0}, {"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1],
            "metallicFactor": 0, "roughnessFactor": 0},
            "extensions": {"KHR_materials_specular": {"specularFactor": 0},
            "KHR_materials_clearcoat": {"clearcoatFactor": 1, "clearcoatRoughnessFactor": 0.5,
            "clearcoatTexture": {"index": 0}, "clearcoatRoughnessTexture": {"index": 1}}}}"#
            .into(),
        extensions_used: r#""KHR_materials_specular", "KHR_materials_clearcoat""#.into(),
        ..Quad::default()
    };
    let s = load(&q, "ext-clearcoat");
    let m = &s.materials[0];
    assert_eq!(
        (
            m.clearcoat_texture.index,
            m.clearcoat_roughness_texture.index
        ),
        (0, 1)
    );
    let (l, r) = left_right(&s);
    assert_eq!((l.material.clearcoat, r.material.clearcoat), (0.0, 1.0));
    assert_eq!(
        (
            l.material.clearcoat_roughness,
            r.material.clearcoat_roughness
        ),
        (0.5, 0.0)
    );
    let (up_l, _) = scattered(&bsdf(&l));
    let (up_r, _) = scattered(&bsdf(&r));
    assert_eq!(up_l, Rgb::ZERO);
    for v in up_r.to_array() {
        assert!(near(v, 0.04, 1e-5), "{up_r:?}");
    }
    assert!(bsdf(&r).is_delta());
    // The same coat at full factor and the texture's roughness 0.5 (left half) is a rough
    // lobe, no longer a mirror.
    let rough = Material {
        clearcoat: 1.0,
        ..l.material
    };
    assert!(!Bsdf::from_material(&rough, l.base).is_delta());
}

#[test]
fn extension_textures_follow_their_texcoord_and_transform() {
    // clearcoatTexture through KHR_texture_transform offset (0.5, 0) swaps the halves (with
    // REPEAT); transmissionTexture reads TEXCOORD_1 = (1 − u, v), which swaps them too.
    let uv1 = [[1.0, 1.0], [0.0, 1.0], [0.0, 0.0], [1.0, 0.0]];
    let mut q = halves(
        1,
        &[0],
        &[255],
        r#"{"extensions": {
            "KHR_materials_clearcoat": {"clearcoatFactor": 1, "clearcoatTexture": {"index": 0,
              "extensions": {"KHR_texture_transform": {"offset": [0.5, 0]}}}},
            "KHR_materials_transmission": {"transmissionFactor": 1,
              "transmissionTexture": {"index": 0, "texCoord": 1}}}}"#,
        "KHR_materials_clearcoat",
    );
    q.extra.push(Attribute::floats("TEXCOORD_1", uv1));
    let s = load(&q, "ext-transform");
    assert_eq!(s.materials[0].transmission_texture.tex_coord, 1);
    let (l, r) = left_right(&s);
    assert_eq!((l.material.clearcoat, r.material.clearcoat), (1.0, 0.0));
    assert_eq!(
        (l.material.transmission, r.material.transmission),
        (1.0, 0.0)
    );
}

#[test]
fn thickness_texture_is_read_but_does_not_change_the_material() {
    // thicknessTexture G = 0 | 255: loaded, but the volume model traces the distance inside
    // the mesh, so the resolved thickness stays the factor on both halves.
    let q = halves(
        3,
        &[255, 0, 255],
        &[0, 255, 0],
        r#"{"extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
            "KHR_materials_volume": {"thicknessFactor": 0.5, "thicknessTexture": {"index": 0}}}}"#,
        "KHR_materials_volume",
    );
    let s = load(&q, "ext-thickness");
    assert!(s.materials[0].thickness_texture.is_some());
    let (l, r) = left_right(&s);
    assert_eq!((l.material.thickness, r.material.thickness), (0.5, 0.5));
    assert_eq!(l.material, r.material);
}

#[test]
fn a_bad_clearcoat_texture_reference_is_a_clear_error() {
    let dir = temp_dir("ext-bad");
    for (material, want) in [
        (
            r#"{"extensions": {"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 7}}}}"#,
            "clearcoatTexture.index = 7 is out of range",
        ),
        (
            r#"{"extensions": {"KHR_materials_clearcoat": {"clearcoatRoughnessTexture": {"texCoord": 0}}}}"#,
            "clearcoatRoughnessTexture.index is missing",
        ),
        (
            r#"{"extensions": {"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 0,
                "extensions": {"KHR_texture_transform": {"scale": 2}}}}}}"#,
            "KHR_texture_transform.scale",
        ),
    ] {
        let q = halves(1, &[0], &[255], material, "KHR_materials_clearcoat");
        let e = load_gltf(&q.write(&dir, "bad.gltf"), &BTreeMap::new())
            .unwrap_err()
            .to_string();
        assert!(e.contains(want) && e.contains("bad.gltf"), "{e}");
    }
}

#[test]
fn a_clearcoat_normal_texture_is_ignored_and_the_coat_still_applies() {
    let q = halves(
        3,
        &[128, 128, 255],
        &[128, 128, 255],
        r#"{"extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.5,
            "clearcoatNormalTexture": {"index": 0}}}}"#,
        "KHR_materials_clearcoat",
    );
    let s = load(&q, "ext-coat-normal");
    let m = &s.materials[0];
    assert_eq!(m.clearcoat, 0.5);
    assert!(!m.clearcoat_texture.is_some() && !m.normal_texture.is_some());
    // No texture reads it, so it is not even decoded.
    assert!(s.textures.is_empty() && s.stats.images_decoded == 0);
}

#[test]
fn d10_an_image_in_a_buffer_view_without_mime_type_is_a_clear_error() {
    let q = Quad {
        images: vec![png8(1, 1, 3, &[200, 100, 50])],
        textures: r#"{"source": 0}"#.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}"#.into(),
        ..Default::default()
    };
    let mut text = q.json();
    // The images array becomes one image read from buffer view 0, with no mimeType.
    let key = "\"images\":[";
    let start = text.find(key).unwrap() + key.len() - 1;
    let end = start + text[start..].find(']').unwrap() + 1;
    text.replace_range(start..end, r#"[{"bufferView": 0}]"#);
    let dir = temp_dir("d10-mime");
    let path = dir.join("nomime.gltf");
    std::fs::write(&path, text).unwrap();
    let e = load_gltf(&path, &BTreeMap::new()).unwrap_err().to_string();
    assert!(
        e.contains("nomime.gltf") && e.contains("image 0") && e.contains("mimeType"),
        "{e}"
    );
}

/// The layer extensions' textures reach their factors: a 2×1 RGBA image (left texel
/// (0, 255, 0, 0), right (255, 0, 255, 255)) as sheen colour (sRGB RGB) and roughness (A),
/// diffuse transmission (A), iridescence (R) and thickness (G), anisotropy (RG direction,
/// B strength).
#[test]
fn layer_textures_scale_their_factors() {
    let q = Quad {
        images: vec![png8(2, 1, 4, &[0, 255, 0, 0, 255, 0, 255, 255])],
        textures: r#"{"source": 0, "sampler": 0}"#.into(),
        samplers: NEAREST.into(),
        material: r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]},
            "extensions": {
            "KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1], "sheenRoughnessFactor": 0.5,
                "sheenColorTexture": {"index": 0}, "sheenRoughnessTexture": {"index": 0}},
            "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.8,
                "diffuseTransmissionTexture": {"index": 0}},
            "KHR_materials_iridescence": {"iridescenceFactor": 1,
                "iridescenceThicknessMinimum": 100, "iridescenceThicknessMaximum": 500,
                "iridescenceTexture": {"index": 0}, "iridescenceThicknessTexture": {"index": 0}},
            "KHR_materials_anisotropy": {"anisotropyStrength": 0.5,
                "anisotropyTexture": {"index": 0}}}}"#
            .into(),
        extensions_used: r#""KHR_materials_sheen", "KHR_materials_diffuse_transmission",
            "KHR_materials_iridescence", "KHR_materials_anisotropy""#
            .into(),
        ..Quad::default()
    };
    let s = load(&q, "ext-layers");
    let (l, r) = left_right(&s);
    let (l, r) = (l.material.layers, r.material.layers);
    assert_eq!(l.sheen_color.to_array(), [0.0, 1.0, 0.0]);
    assert_eq!(r.sheen_color.to_array(), [1.0, 0.0, 1.0]);
    assert_eq!((l.sheen_roughness, r.sheen_roughness), (0.0, 0.5));
    assert_eq!((l.diffuse_transmission, r.diffuse_transmission), (0.0, 0.8));
    assert_eq!((l.iridescence, r.iridescence), (0.0, 1.0));
    assert_eq!(
        (l.iridescence_thickness_max, r.iridescence_thickness_max),
        (500.0, 100.0)
    );
    // Left: direction (−1, 1)/√2, strength 0; right: (1, −1)/√2, strength 0.5.
    assert_eq!((l.anisotropy_strength, r.anisotropy_strength), (0.0, 0.5));
    let h = std::f32::consts::FRAC_1_SQRT_2;
    for (got, want) in [
        (l.anisotropy_direction, [-h, h]),
        (r.anisotropy_direction, [h, -h]),
    ] {
        assert!(
            near(got[0], want[0], 1e-6) && near(got[1], want[1], 1e-6),
            "{got:?}"
        );
    }
}
