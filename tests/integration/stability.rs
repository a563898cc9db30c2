//! Numerical stability on the scenes that break renderers: scale and translation,
//! self-intersection acne, grazing angles, degenerate geometry and extreme materials and
//! lights, glass in a furnace (total internal reflection), and mirror chains against the
//! lighting depth. Every check compares with an analytic value or with an equivalent scene,
//! so each can fail; the MCMC-specific checks come with the ERPT plugin.
//!
//! Scenes are written as glTF into a scratch folder by the small builder below (one buffer,
//! embedded as base64), with the camera given by the config's `[camera]` table.

use crate::common;

use common::{mean_and_stderr, render, renderer_at, scratch};
use flowlight_core::Rgb;
use flowlight_host::metrics;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------
// A minimal glTF writer

#[derive(Clone)]
struct Mat {
    name: &'static str,
    base: [f32; 3],
    metallic: f32,
    roughness: f32,
    emission: Option<[f32; 3]>,
    transmission: Option<(f32, f32)>,
}

fn diffuse(name: &'static str, albedo: f32) -> Mat {
    Mat {
        name,
        base: [albedo; 3],
        metallic: 0.0,
        roughness: 1.0,
        emission: None,
        transmission: None,
    }
}

fn emitter(name: &'static str, radiance: f32) -> Mat {
    Mat {
        emission: Some([radiance; 3]),
        ..diffuse(name, 0.0)
    }
}

fn mirror(name: &'static str) -> Mat {
    Mat {
        metallic: 1.0,
        roughness: 0.0,
        ..diffuse(name, 1.0)
    }
}

fn glass(name: &'static str) -> Mat {
    Mat {
        roughness: 0.0,
        transmission: Some((1.0, 1.5)),
        ..diffuse(name, 1.0)
    }
}

type V = [f64; 3];

#[derive(Default)]
struct Builder {
    mats: Vec<Mat>,
    /// (material, positions, indices)
    meshes: Vec<(usize, Vec<[f32; 3]>, Vec<u32>)>,
    /// Root node transform: uniform scale, then translation.
    scale: f64,
    translation: V,
}

fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn f32s(p: V) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

impl Builder {
    fn new() -> Builder {
        Builder {
            scale: 1.0,
            ..Default::default()
        }
    }

    fn mesh(&mut self, m: &Mat) -> usize {
        let mi = match self.mats.iter().position(|x| x.name == m.name) {
            Some(i) => i,
            None => {
                self.mats.push(m.clone());
                self.mats.len() - 1
            }
        };
        if let Some(i) = self.meshes.iter().position(|x| x.0 == mi) {
            return i;
        }
        self.meshes.push((mi, Vec::new(), Vec::new()));
        self.meshes.len() - 1
    }

    /// A triangle, wound so its front face points along `facing` (when given).
    fn tri(&mut self, m: &Mat, a: V, b: V, c: V, facing: Option<V>) {
        let i = self.mesh(m);
        let n = cross(sub(b, a), sub(c, a));
        let (b, c) = match facing {
            Some(f) if dot(n, f) < 0.0 => (c, b),
            _ => (b, c),
        };
        let (_, pos, idx) = &mut self.meshes[i];
        let k = pos.len() as u32;
        pos.extend([f32s(a), f32s(b), f32s(c)]);
        idx.extend([k, k + 1, k + 2]);
    }

    /// A raw triangle from given positions and indices, as they are (for degenerate cases).
    fn raw(&mut self, m: &Mat, p: [[f32; 3]; 3], ix: [u32; 3]) {
        let i = self.mesh(m);
        let (_, pos, idx) = &mut self.meshes[i];
        let k = pos.len() as u32;
        pos.extend(p);
        idx.extend(ix.map(|j| k + j));
    }

    fn quad(&mut self, m: &Mat, p: [V; 4], facing: V) {
        self.tri(m, p[0], p[1], p[2], Some(facing));
        self.tri(m, p[0], p[2], p[3], Some(facing));
    }

    /// An axis-aligned box with faces towards `outwards ? outside : inside`.
    fn boxed(&mut self, m: &Mat, lo: V, hi: V, outwards: bool) {
        let c = [
            (lo[0] + hi[0]) / 2.0,
            (lo[1] + hi[1]) / 2.0,
            (lo[2] + hi[2]) / 2.0,
        ];
        for axis in 0..3 {
            for side in [lo[axis], hi[axis]] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let corner = |a: f64, b: f64| {
                    let mut p = [0.0; 3];
                    p[axis] = side;
                    p[u] = a;
                    p[v] = b;
                    p
                };
                let p = [
                    corner(lo[u], lo[v]),
                    corner(hi[u], lo[v]),
                    corner(hi[u], hi[v]),
                    corner(lo[u], hi[v]),
                ];
                let mut out = [0.0; 3];
                out[axis] = side - c[axis];
                if !outwards {
                    out = [-out[0], -out[1], -out[2]];
                }
                self.quad(m, p, out);
            }
        }
    }

    /// A flat-faceted UV sphere; faces point outwards or inwards.
    fn sphere(&mut self, m: &Mat, centre: V, r: f64, rings: usize, outwards: bool) {
        let segs = 2 * rings;
        let pt = |i: usize, j: usize| {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            let ph = 2.0 * std::f64::consts::PI * j as f64 / segs as f64;
            [
                centre[0] + r * th.sin() * ph.cos(),
                centre[1] + r * th.cos(),
                centre[2] + r * th.sin() * ph.sin(),
            ]
        };
        for i in 0..rings {
            for j in 0..segs {
                let (a, b, c, d) = (pt(i, j), pt(i + 1, j), pt(i + 1, j + 1), pt(i, j + 1));
                let mid = [
                    (a[0] + c[0]) / 2.0 - centre[0],
                    (a[1] + c[1]) / 2.0 - centre[1],
                    (a[2] + c[2]) / 2.0 - centre[2],
                ];
                let f = if outwards {
                    mid
                } else {
                    [-mid[0], -mid[1], -mid[2]]
                };
                if i != 0 {
                    self.tri(m, a, b, d, Some(f));
                }
                if i != rings - 1 {
                    self.tri(m, b, c, d, Some(f));
                }
            }
        }
    }

    fn gltf(&self) -> String {
        let mut blob: Vec<u8> = Vec::new();
        let (mut views, mut accessors, mut meshes, mut nodes) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (mi, pos, idx) in &self.meshes {
            let off = blob.len();
            for p in pos {
                for c in p {
                    blob.extend(c.to_le_bytes());
                }
            }
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{off},"byteLength":{}}}"#,
                pos.len() * 12
            ));
            let finite = pos.iter().filter(|p| p.iter().all(|c| c.is_finite()));
            let mut lo = [f32::MAX; 3];
            let mut hi = [f32::MIN; 3];
            for p in finite {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}"#,
                views.len() - 1,
                pos.len(),
                lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
            ));
            let off = blob.len();
            for i in idx {
                blob.extend(i.to_le_bytes());
            }
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{off},"byteLength":{}}}"#,
                idx.len() * 4
            ));
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5125,"count":{},"type":"SCALAR"}}"#,
                views.len() - 1,
                idx.len()
            ));
            meshes.push(format!(
                r#"{{"primitives":[{{"attributes":{{"POSITION":{}}},"indices":{},"material":{mi}}}]}}"#,
                accessors.len() - 2,
                accessors.len() - 1
            ));
            nodes.push(format!(r#"{{"mesh":{}}}"#, meshes.len() - 1));
        }
        let children: Vec<String> = (0..nodes.len()).map(|i| i.to_string()).collect();
        let t = self.translation;
        let s = self.scale;
        nodes.push(format!(
            r#"{{"name":"root","children":[{}],"scale":[{s:e},{s:e},{s:e}],"translation":[{:e},{:e},{:e}]}}"#,
            children.join(","),
            t[0],
            t[1],
            t[2]
        ));
        let mats: Vec<String> = self
            .mats
            .iter()
            .map(|m| {
                let mut ext = Vec::new();
                let mut extra = String::new();
                if let Some(e) = m.emission {
                    let k = e[0].max(e[1]).max(e[2]).max(1e-30);
                    let _ = write!(
                        extra,
                        r#","emissiveFactor":[{:e},{:e},{:e}]"#,
                        e[0] / k,
                        e[1] / k,
                        e[2] / k
                    );
                    ext.push(format!(
                        r#""KHR_materials_emissive_strength":{{"emissiveStrength":{k:e}}}"#
                    ));
                }
                if let Some((t, ior)) = m.transmission {
                    ext.push(format!(
                        r#""KHR_materials_transmission":{{"transmissionFactor":{t}}}"#
                    ));
                    ext.push(format!(r#""KHR_materials_ior":{{"ior":{ior}}}"#));
                    // Solid glass: a closed volume that refracts (glTF is thin-walled without).
                    ext.push(r#""KHR_materials_volume":{"thicknessFactor":1}"#.to_string());
                } else if m.metallic == 0.0 {
                    // The analytic checks assume a Lambertian: no dielectric specular layer.
                    ext.push(r#""KHR_materials_specular":{"specularFactor":0}"#.to_string());
                }
                let ext = if ext.is_empty() {
                    String::new()
                } else {
                    format!(r#","extensions":{{{}}}"#, ext.join(","))
                };
                format!(
                    r#"{{"name":"{}","pbrMetallicRoughness":{{"baseColorFactor":[{},{},{},1],"metallicFactor":{},"roughnessFactor":{}}},"doubleSided":true{extra}{ext}}}"#,
                    m.name, m.base[0], m.base[1], m.base[2], m.metallic, m.roughness
                )
            })
            .collect();
        format!(
            r#"{{"asset":{{"version":"2.0","generator":"flowlight tests/integration/stability.rs"}},
"extensionsUsed":["KHR_materials_emissive_strength","KHR_materials_transmission","KHR_materials_ior","KHR_materials_volume","KHR_materials_specular"],
"scene":0,"scenes":[{{"nodes":[{}]}}],"nodes":[{}],"meshes":[{}],"materials":[{}],
"accessors":[{}],"bufferViews":[{}],
"buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}]}}"#,
            nodes.len() - 1,
            nodes.join(","),
            meshes.join(","),
            mats.join(","),
            accessors.join(","),
            views.join(","),
            blob.len(),
            base64(&blob)
        )
    }

    /// Writes `<name>.gltf` and `<name>.toml` (camera from `cam`) into `dir`.
    fn write(&self, dir: &Path, name: &str, cam: &Cam, extra_toml: &str) -> PathBuf {
        std::fs::write(dir.join(format!("{name}.gltf")), self.gltf()).unwrap();
        let cfg = dir.join(format!("{name}.toml"));
        let v = |p: V| format!("[{:e}, {:e}, {:e}]", p[0], p[1], p[2]);
        std::fs::write(
            &cfg,
            format!(
                "scene = \"{name}.gltf\"\n[render]\nseed = 1\n[camera]\nposition = {}\nlook_at = {}\nup = {}\nfov_y = {:e}\n[integrator]\nplugin = \"mcpt\"\n{extra_toml}",
                v(cam.position),
                v(cam.look_at),
                v(cam.up),
                cam.fov_y
            ),
        )
        .unwrap();
        cfg
    }
}

struct Cam {
    position: V,
    look_at: V,
    up: V,
    fov_y: f64,
}

fn base64(data: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn params(pairs: &[(&'static str, toml::Value)]) -> Vec<(&'static str, toml::Value)> {
    pairs.to_vec()
}

/// Renders `cfg` and checks what every render here must satisfy: all pixels of the image and
/// the layers finite and non-negative, every pixel got all its samples, no stray deposit.
fn render_checked(
    cfg: &Path,
    size: u32,
    spp: u32,
    pairs: &[(&'static str, toml::Value)],
) -> (Vec<Rgb>, flowlight_host::RenderStats) {
    let s = renderer_at(cfg.to_str().unwrap(), size, size, spp, pairs);
    let out = render(&s);
    let img = out.frame.image();
    let all_valid = |v: &[Rgb]| v.iter().all(|c| c.is_valid_radiance());
    assert!(all_valid(&img), "{}: non-finite pixel", cfg.display());
    for k in 0..out.frame.layer_count as usize {
        assert!(
            all_valid(&out.frame.layer(k)),
            "{}: non-finite pixel in layer {k}",
            cfg.display()
        );
    }
    assert!(
        out.frame.samples().iter().all(|&n| n == spp),
        "{}: a pixel lost samples",
        cfg.display()
    );
    assert_eq!(out.stats.pixel_samples, spp as u64 * (size * size) as u64);
    assert_eq!(out.stats.stray_deposits, 0);
    (img, out.stats)
}

fn mean_rgb(img: &[Rgb]) -> [(f64, f64); 3] {
    [
        mean_and_stderr(img, |c| c.r),
        mean_and_stderr(img, |c| c.g),
        mean_and_stderr(img, |c| c.b),
    ]
}

// ---------------------------------------------------------------------------------------
// Scale and translation

/// The Cornell box wrapped in a root node with `scale` and `translation` (the camera node
/// moves with it).
fn transformed_cornell(dir: &Path, name: &str, scale: f64, t: f64) -> PathBuf {
    let src = common::repo().join("scenes/cornell-box");
    let text = std::fs::read_to_string(src.join("cornell-box.gltf")).unwrap();
    std::fs::copy(src.join("cornell-box.bin"), dir.join("cornell-box.bin")).unwrap();
    // The scene lists nodes 0..=8; add node 9 as their parent and make it the only root.
    let scenes = text.find("\"scenes\"").unwrap();
    let nodes = scenes + text[scenes..].find("\"nodes\": [\n  {").unwrap();
    let meshes = text.find("\n ],\n \"meshes\"").unwrap();
    assert!(nodes < meshes);
    let wrapper = format!(
        ",\n  {{\"name\": \"wrapper\", \"children\": [0, 1, 2, 3, 4, 5, 6, 7, 8], \"scale\": [{scale:e}, {scale:e}, {scale:e}], \"translation\": [{t:e}, {t:e}, {t:e}]}}"
    );
    let out = format!(
        "{}\"scenes\": [{{\"nodes\": [9]}}],\n {}{}{}",
        &text[..scenes],
        &text[nodes..meshes],
        wrapper,
        &text[meshes..]
    );
    std::fs::write(dir.join(format!("{name}.gltf")), out).unwrap();
    let cfg = dir.join(format!("{name}.toml"));
    std::fs::write(
        &cfg,
        format!(
            "scene = \"{name}.gltf\"\n[render]\nseed = 1\n[integrator]\nplugin = \"mcpt\"\npath_depth = 8\n"
        ),
    )
    .unwrap();
    cfg
}

#[test]
fn cornell_box_scaled_and_translated_gives_the_same_image() {
    let dir = scratch("stability-scale");
    let (size, spp) = (48, 48);
    let unit = transformed_cornell(&dir, "unit", 1.0, 0.0);
    let (a, _) = render_checked(&unit, size, spp, &[]);
    // The noise baseline: the unit scene with another seed.
    let mut s = renderer_at(unit.to_str().unwrap(), size, size, spp, &[]);
    s.options.seed = 2;
    let noise = render(&s).frame.image();
    let baseline = metrics::compare(&noise, &a, None).unwrap().relmse;
    // World-space vertices are f32. The luminaire hangs 0.5 mm below the ceiling, so a
    // translation must leave a few ulps between them: at 1e5 the ulp is 7.8 mm, and the box
    // translated there unscaled has its lamp *in* the ceiling plane (half the light is lost,
    // whatever the renderer does). Far translations are therefore combined with a scale that
    // keeps the gap at ≥ 6 ulps.
    for (name, scale, t) in [
        ("small", 1e-4, 0.0),
        ("large", 1e4, 0.0),
        ("far", 100.0, 1e5),
        ("far-unit", 1.0, 1e3),
        ("small-far", 1e-4, 0.1),
    ] {
        let cfg = transformed_cornell(&dir, name, scale, t);
        let mut s = renderer_at(cfg.to_str().unwrap(), size, size, spp, &[]);
        s.options.seed = 2;
        let out = render(&s);
        assert_eq!(out.stats.invalid_deposits, 0, "{name}");
        let img = out.frame.image();
        let e = metrics::compare(&img, &a, None).unwrap();
        eprintln!(
            "{name}: relMSE {:.4e} (noise {baseline:.4e}), luminance ratio {:.4}",
            e.relmse, e.luminance_ratio
        );
        // Another seed: the error must look like noise (translated, f32 vertices snap to a
        // grid of up to 0.14% of the box, which moves edges by a small fraction of a pixel).
        let bound = 1.25;
        assert!(
            e.relmse < bound * baseline,
            "{name} (scale {scale}, translation {t}): relMSE {:.4e} against the unit scene, noise alone gives {baseline:.4e}",
            e.relmse
        );
        assert!(
            (e.luminance_ratio - 1.0).abs() < 0.02,
            "{name}: mean luminance ratio {:.4}",
            e.luminance_ratio
        );
    }
}

// ---------------------------------------------------------------------------------------
// Acne and grazing angles

/// Form factor from a point to a parallel rectangle at height h whose corner is above it:
/// sides a, b.
fn corner_form_factor(a: f64, b: f64, h: f64) -> f64 {
    let (x, y) = (a / h, b / h);
    let sx = (1.0 + x * x).sqrt();
    let sy = (1.0 + y * y).sqrt();
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

/// Form factor from the centre point below a square emitter of half-size `a` at height `h`.
fn square_form_factor(a: f64, h: f64) -> f64 {
    4.0 * corner_form_factor(a, a, h)
}

/// A diffuse plane (albedo `rho`, y = 0, half-size `half`) under a black square emitter of
/// radiance `le` at height 1 facing down, in a root node translated by `t` and scaled by `s`.
fn plane_under_emitter(rho: f32, le: f32, half: f64, s: f64, t: V) -> Builder {
    let mut b = Builder::new();
    b.scale = s;
    b.translation = t;
    let (pl, em) = (diffuse("plane", rho), emitter("sky", le));
    let q = |y: f64| {
        [
            [-half, y, -half],
            [half, y, -half],
            [half, y, half],
            [-half, y, half],
        ]
    };
    b.quad(&pl, q(0.0), [0.0, 1.0, 0.0]);
    b.quad(&em, q(1.0), [0.0, -1.0, 0.0]);
    b
}

fn check_mean(img: &[Rgb], expected: f64, tol: f64, what: &str) {
    for (k, (mean, se)) in mean_rgb(img).into_iter().enumerate() {
        let rel = mean / expected - 1.0;
        eprintln!(
            "{what}[{k}]: mean {mean:.5}, expected {expected:.5} ({rel:+.4}), stderr {se:.2e}"
        );
        assert!(
            rel.abs() < tol,
            "{what}: channel {k} mean {mean:.5}, expected {expected:.5} (relative error {rel:+.4}, stderr {se:.2e})"
        );
        assert!(
            se / expected < tol / 3.0,
            "{what}: too noisy to judge ({se})"
        );
    }
}

#[test]
fn diffuse_plane_lit_head_on_has_no_acne_at_any_position_or_scale() {
    let dir = scratch("stability-acne");
    let (rho, le, half) = (0.5f32, 1.0f32, 10.0);
    let expected = rho as f64 * le as f64 * square_form_factor(half, 1.0);
    // The camera sees a disc of radius 0.044 around the centre: the form factor is flat there.
    assert!(
        (corner_form_factor(half - 0.05, half - 0.05, 1.0) * 4.0 / square_form_factor(half, 1.0)
            - 1.0)
            .abs()
            < 1e-3
    );
    for (name, s, t) in [
        ("unit", 1.0, [0.0; 3]),
        ("far", 1.0, [1e4, 1e4, -1e4]),
        ("tiny", 1e-4, [0.0; 3]),
        ("huge", 1e4, [0.0; 3]),
    ] {
        let b = plane_under_emitter(rho, le, half, s, t);
        let at = |p: V| [p[0] * s + t[0], p[1] * s + t[1], p[2] * s + t[2]];
        let cam = Cam {
            position: at([0.0, 0.5, 0.0]),
            look_at: at([0.0, 0.0, 0.0]),
            up: [0.0, 0.0, 1.0],
            fov_y: 10.0,
        };
        let cfg = b.write(&dir, name, &cam, "path_depth = 4\n");
        // Entangled (MIS) only: the untangled estimator's one area-sampled connection to a
        // 20 × 20 emitter at distance 1 is too noisy for a 1% check at this budget.
        let (img, stats) = render_checked(&cfg, 32, 128, &[]);
        assert_eq!(stats.invalid_deposits, 0);
        check_mean(&img, expected, 0.01, name);
    }
}

#[test]
fn plane_seen_at_grazing_angles_up_to_89_9_degrees() {
    let dir = scratch("stability-grazing-view");
    let (rho, le, half) = (0.5f32, 1.0f32, 100.0);
    let expected = rho as f64 * le as f64 * square_form_factor(half, 1.0);
    // Hits land within 2 of the centre, where the form factor is flat to 1e-3.
    assert!(
        (4.0 * corner_form_factor(half - 2.0, half - 2.0, 1.0) / square_form_factor(half, 1.0)
            - 1.0)
            .abs()
            < 1e-3
    );
    let b = plane_under_emitter(rho, le, half, 1.0, [0.0; 3]);
    for theta in [60.0f64, 85.0, 89.0, 89.9] {
        // Look down by δ = 90° − θ with a field of view of δ: every ray is depressed by δ/2 to
        // 3δ/2 and hits the plane at h / tan(depression) in front of the camera.
        let delta = 90.0 - theta;
        let h = 1e-3;
        let far = h / (delta / 2.0).to_radians().tan();
        assert!(far < 2.0);
        let (sd, cd) = (delta.to_radians().sin(), delta.to_radians().cos());
        let cam = Cam {
            position: [0.0, h, -far / 2.0],
            look_at: [0.0, h - sd, -far / 2.0 + cd],
            up: [0.0, 1.0, 0.0],
            fov_y: delta,
        };
        let name = format!("view{theta}");
        let cfg = b.write(&dir, &name, &cam, "path_depth = 4\n");
        let (img, stats) = render_checked(&cfg, 32, 128, &[]);
        assert_eq!(stats.invalid_deposits, 0);
        check_mean(&img, expected, 0.01, &format!("seen at {theta}°"));
    }
}

#[test]
fn plane_lit_at_grazing_angles_up_to_89_9_degrees() {
    let dir = scratch("stability-grazing-light");
    let rho = 0.5f64;
    for theta in [60.0f64, 89.0, 89.9] {
        // A small square emitter at distance 10, elevation e = 90° − θ, facing the origin.
        let e = (90.0 - theta).to_radians();
        let r = 10.0;
        let c = [0.0, r * e.sin(), r * e.cos()];
        let n = [0.0, -e.sin(), -e.cos()];
        let t1 = [1.0, 0.0, 0.0];
        let t2 = cross(n, t1);
        let hs = 0.01;
        let corner = |a: f64, b: f64| {
            [
                c[0] + a * t1[0] + b * t2[0],
                c[1] + a * t1[1] + b * t2[1],
                c[2] + a * t1[2] + b * t2[2],
            ]
        };
        assert!(corner(-hs, -hs)[1].min(corner(hs, hs)[1]) > 0.0);
        // Irradiance at the origin by quadrature: ∫ Le cos θ_i cos θ_e / r² dA.
        let steps = 200;
        let mut g = 0.0;
        for i in 0..steps {
            for j in 0..steps {
                let a = -hs + (i as f64 + 0.5) / steps as f64 * 2.0 * hs;
                let b = -hs + (j as f64 + 0.5) / steps as f64 * 2.0 * hs;
                let q = corner(a, b);
                let d2 = dot(q, q);
                let d = d2.sqrt();
                let (ci, ce) = (q[1] / d, -dot(q, n) / d);
                g += ci * ce / d2;
            }
        }
        g *= (2.0 * hs).powi(2) / (steps * steps) as f64;
        // Radiance 1 / (ρ/π · G) makes the expected pixel value 1.
        let le = 1.0 / (rho / std::f64::consts::PI * g);
        let mut b = Builder::new();
        let (pl, em) = (diffuse("plane", rho as f32), emitter("sun", le as f32));
        b.quad(
            &pl,
            [
                [-20.0, 0.0, -20.0],
                [20.0, 0.0, -20.0],
                [20.0, 0.0, 20.0],
                [-20.0, 0.0, 20.0],
            ],
            [0.0, 1.0, 0.0],
        );
        b.quad(
            &em,
            [
                corner(-hs, -hs),
                corner(hs, -hs),
                corner(hs, hs),
                corner(-hs, hs),
            ],
            n,
        );
        let cam = Cam {
            position: [0.0, 0.05, 0.0],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            fov_y: 2.0,
        };
        let cfg = b.write(&dir, &format!("light{theta}"), &cam, "path_depth = 2\n");
        let (img, stats) = render_checked(&cfg, 32, 32, &[]);
        assert_eq!(stats.invalid_deposits, 0);
        check_mean(&img, 1.0, 0.01, &format!("lit at {theta}°"));
    }
}

// ---------------------------------------------------------------------------------------
// Degenerate geometry, extreme materials and lights

#[test]
fn degenerate_geometry_extreme_albedo_and_lights_give_finite_counted_output() {
    let dir = scratch("stability-degenerate");
    let mut b = Builder::new();
    let (white, black, one) = (
        diffuse("white", 0.7),
        diffuse("black", 0.0),
        diffuse("one", 1.0),
    );
    // A closed room: albedo 1 walls, a zero-albedo floor, a white ceiling.
    b.quad(
        &black,
        [
            [-1.0, 0.0, -1.0],
            [1.0, 0.0, -1.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, 1.0],
        ],
        [0.0, 1.0, 0.0],
    );
    b.quad(
        &white,
        [
            [-1.0, 2.0, -1.0],
            [1.0, 2.0, -1.0],
            [1.0, 2.0, 1.0],
            [-1.0, 2.0, 1.0],
        ],
        [0.0, -1.0, 0.0],
    );
    for (x, f) in [(-1.0, 1.0), (1.0, -1.0)] {
        b.quad(
            &one,
            [[x, 0.0, -1.0], [x, 2.0, -1.0], [x, 2.0, 1.0], [x, 0.0, 1.0]],
            [f, 0.0, 0.0],
        );
    }
    for (z, f) in [(-1.0, 1.0), (1.0, -1.0)] {
        b.quad(
            &one,
            [[-1.0, 0.0, z], [1.0, 0.0, z], [1.0, 2.0, z], [-1.0, 2.0, z]],
            [0.0, 0.0, f],
        );
    }
    // A normal lamp.
    b.quad(
        &emitter("lamp", 5.0),
        [
            [-0.2, 1.99, -0.2],
            [0.2, 1.99, -0.2],
            [0.2, 1.99, 0.2],
            [-0.2, 1.99, 0.2],
        ],
        [0.0, -1.0, 0.0],
    );
    // Degenerate triangles: collinear, repeated vertex, repeated index, NaN and Inf vertices.
    let nan = f32::NAN;
    b.raw(
        &white,
        [[0.0, 0.5, 0.5], [0.5, 0.5, 0.5], [1.0, 0.5, 0.5]],
        [0, 1, 2],
    );
    b.raw(
        &white,
        [[0.0, 0.5, 0.5], [0.0, 0.5, 0.5], [0.3, 0.9, 0.5]],
        [0, 1, 2],
    );
    b.raw(
        &white,
        [[0.0, 0.5, 0.5], [0.4, 0.5, 0.5], [0.3, 0.9, 0.5]],
        [0, 0, 2],
    );
    b.raw(
        &white,
        [[nan, 0.5, 0.5], [0.4, 0.5, 0.5], [0.3, 0.9, 0.5]],
        [0, 1, 2],
    );
    b.raw(
        &white,
        [[f32::INFINITY, 0.5, 0.5], [0.4, 0.5, 0.5], [0.3, 0.9, 0.5]],
        [0, 1, 2],
    );
    // Sliver triangles in view: 1 long, 1e-6 and 1e-7 wide; and a needle 1e-7 long.
    b.tri(
        &white,
        [-0.8, 0.3, 0.0],
        [0.8, 0.3, 0.0],
        [0.0, 0.300001, 0.0],
        None,
    );
    b.tri(
        &white,
        [-0.8, 0.6, 0.2],
        [0.8, 0.6, 0.2],
        [0.0, 0.6000001, 0.2],
        None,
    );
    b.tri(
        &one,
        [0.1, 1.0, 0.0],
        [0.1, 1.0000001, 0.0],
        [0.1000001, 1.0, 0.0],
        None,
    );
    // Zero-area lights: a collinear emissive triangle, and one of area 1e-14.
    b.raw(
        &emitter("flat-lamp", 100.0),
        [[0.0, 1.5, 0.0], [0.1, 1.5, 0.0], [0.2, 1.5, 0.0]],
        [0, 1, 2],
    );
    b.tri(
        &emitter("speck", 100.0),
        [0.3, 1.5, 0.0],
        [0.3000001, 1.5, 0.0],
        [0.3, 1.5, 0.0000001],
        Some([0.0, -1.0, 0.0]),
    );
    // A light of radiance 1e6 covering 1e-6 of the view: the camera's 60° frustum covers
    // 2.3 × 2.3 at distance 2, so a square of side 2.3e-3 facing the camera.
    let s = 2.3e-3 / 2.0;
    b.quad(
        &emitter("spark", 1e6),
        [
            [-s, 1.0 - s, 0.0],
            [s, 1.0 - s, 0.0],
            [s, 1.0 + s, 0.0],
            [-s, 1.0 + s, 0.0],
        ],
        [0.0, 0.0, -1.0],
    );
    let cam = Cam {
        position: [0.0, 1.0, -0.95],
        look_at: [0.0, 1.0, 1.0],
        up: [0.0, 1.0, 0.0],
        fov_y: 60.0,
    };
    let cfg = b.write(&dir, "degenerate", &cam, "path_depth = 12\n");
    let loaded =
        flowlight_scene::load_gltf(&dir.join("degenerate.gltf"), &Default::default()).unwrap();
    assert!(
        loaded.stats.degenerate_dropped >= 6 && loaded.stats.dropped_emitters >= 1,
        "degenerate triangles must be dropped and counted: {:?}",
        loaded.stats
    );
    for variant in ["entangled", "untangled"] {
        for termination in ["bxdf", "equi", "expo", "throughput"] {
            let what = format!("{variant}/{termination}");
            let pairs = params(&[
                ("variant", variant.into()),
                ("termination", termination.into()),
                ("layers", true.into()),
            ]);
            let s = renderer_at(cfg.to_str().unwrap(), 48, 48, 16, &pairs);
            let out = render(&s);
            let img = out.frame.image();
            assert!(img.iter().all(|c| c.is_valid_radiance()), "{what}");
            for k in 0..out.frame.layer_count as usize {
                assert!(
                    out.frame.layer(k).iter().all(|c| c.is_valid_radiance()),
                    "{what}"
                );
            }
            // Every sample is accounted for: written to its pixel, or discarded and counted.
            assert!(out.frame.samples().iter().all(|&n| n == 16), "{what}");
            assert_eq!(out.stats.stray_deposits, 0, "{what}");
            assert_eq!(
                out.stats.invalid_deposits, 0,
                "{what}: the scene is legitimate, no sample should be invalid"
            );
            // The outputs can be written (the EXR writer refuses non-finite pixels).
            let mut s = s;
            s.exr_path = Some(dir.join(format!("{variant}-{termination}.exr")));
            s.write_outputs(out.frame, &out.stats).unwrap();
            let mean = img.iter().map(|c| c.luminance() as f64).sum::<f64>() / img.len() as f64;
            assert!(mean.is_finite() && mean > 0.0, "{what}: mean {mean}");
        }
    }
}

#[test]
fn scene_whose_only_light_has_zero_area_renders_black() {
    let dir = scratch("stability-zero-light");
    let mut b = Builder::new();
    b.quad(
        &diffuse("floor", 0.5),
        [
            [-1.0, 0.0, -1.0],
            [1.0, 0.0, -1.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, 1.0],
        ],
        [0.0, 1.0, 0.0],
    );
    b.raw(
        &emitter("flat-lamp", 100.0),
        [[0.0, 1.0, 0.0], [0.1, 1.0, 0.0], [0.2, 1.0, 0.0]],
        [0, 1, 2],
    );
    let cam = Cam {
        position: [0.0, 1.0, -1.0],
        look_at: [0.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y: 60.0,
    };
    let cfg = b.write(&dir, "dark", &cam, "");
    for variant in ["entangled", "untangled"] {
        let (img, stats) = render_checked(&cfg, 16, 4, &params(&[("variant", variant.into())]));
        assert_eq!(stats.invalid_deposits, 0);
        assert!(
            img.iter().all(|c| *c == Rgb::ZERO),
            "{variant}: light from nowhere"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Glass in the white furnace

/// The white furnace (closed sphere, albedo 0.5, emission 1, radius 1, camera at the centre)
/// with glass inside: a dielectric neither absorbs nor emits, so every pixel stays at
/// Le / (1 − a) = 2. The camera looks at a glass slab (total internal reflection at its
/// sides) and a flat-faceted glass sphere.
#[test]
fn glass_slab_and_sphere_in_the_white_furnace_conserve_energy() {
    let dir = scratch("stability-glass-furnace");
    let wall = Mat {
        emission: Some([1.0; 3]),
        ..diffuse("furnace", 0.5)
    };
    let g = glass("glass");
    let mut b = Builder::new();
    b.sphere(&wall, [0.0; 3], 1.0, 12, false);
    b.sphere(&g, [-0.12, 0.0, 0.55], 0.25, 10, true);
    b.boxed(&g, [0.0, -0.3, 0.35], [0.3, 0.3, 0.5], true);
    let cam = Cam {
        position: [0.0; 3],
        look_at: [0.0, 0.0, 1.0],
        up: [0.0, 1.0, 0.0],
        fov_y: 75.0,
    };
    // Glass events after the first diffuse vertex count as lighting depth, and rays caught
    // by total internal reflection bounce many times: at N = 24 the truncation alone costs
    // 0.5%. N = 32 (the maximum) and a generous physical cap keep it below 0.2%.
    let depth = 32;
    let cfg = b.write(
        &dir,
        "glass-furnace",
        &cam,
        &format!("path_depth = {depth}\nmax_ray_depth = 1024\n"),
    );
    let expected = (1.0 - 0.5f64.powi(depth + 1)) / 0.5;
    for variant in ["entangled", "untangled"] {
        let (img, stats) = render_checked(&cfg, 32, 256, &params(&[("variant", variant.into())]));
        assert_eq!(stats.invalid_deposits, 0);
        check_mean(&img, expected, 0.01, &format!("glass furnace/{variant}"));
        // The glass covers the middle of the view: check it alone too.
        let centre: Vec<Rgb> = (8..24)
            .flat_map(|y| (8..24).map(move |x| (x, y)))
            .map(|(x, y)| img[y * 32 + x])
            .collect();
        check_mean(
            &centre,
            expected,
            0.02,
            &format!("glass furnace centre/{variant}"),
        );
    }
}

// ---------------------------------------------------------------------------------------
// Mirror chains and the lighting depth

/// A diffuse wall at the end of a corridor between two parallel mirrors (x = 0 and x = 1),
/// seen after exactly 10 mirror reflections, is lit by direct light with `path_depth = 1`:
/// mirrors seen from the camera do not use up lighting depth. Unfolding the 10 reflections
/// gives an equivalent scene without mirrors, seen from a camera moved by −10 in x: the two
/// images must agree pixel by pixel. `max_ray_depth` still caps the physical depth.
#[test]
fn virtual_depth_keeps_direct_light_through_ten_mirrors() {
    let dir = scratch("stability-mirrors");
    let build = |mirrors: bool| {
        let mut b = Builder::new();
        if mirrors {
            let m = mirror("mirror");
            for x in [0.0, 1.0] {
                b.quad(
                    &m,
                    [
                        [x, -1.0, -1.0],
                        [x, 1.0, -1.0],
                        [x, 1.0, 21.0],
                        [x, -1.0, 21.0],
                    ],
                    [0.5 - x, 0.0, 0.0],
                );
            }
        }
        b.quad(
            &diffuse("wall", 0.5),
            [
                [-0.2, -1.0, 20.5],
                [1.2, -1.0, 20.5],
                [1.2, 1.0, 20.5],
                [-0.2, 1.0, 20.5],
            ],
            [0.0, 0.0, -1.0],
        );
        b.quad(
            &emitter("lamp", 10.0),
            [
                [0.1, 0.9, 19.6],
                [0.9, 0.9, 19.6],
                [0.9, 0.9, 20.4],
                [0.1, 0.9, 20.4],
            ],
            [0.0, -1.0, 0.0],
        );
        b
    };
    // tan α = 1/2: the centre ray meets the mirrors at z = 1, 3, …, 19 (10 reflections) and
    // the wall at x = 0.75. With a 1° field of view every ray reflects exactly 10 times.
    let dir_v = [0.5, 0.0, 1.0];
    let cam = |x: f64| Cam {
        position: [x, 0.0, 0.0],
        look_at: [x + dir_v[0], 0.0, dir_v[2]],
        up: [0.0, 1.0, 0.0],
        fov_y: 1.0,
    };
    let chain = build(true).write(&dir, "chain", &cam(0.5), "path_depth = 1\n");
    let unfolded = build(false).write(&dir, "unfolded", &cam(0.5 - 10.0), "path_depth = 1\n");
    let (size, spp) = (24, 256);
    let (a, _) = render_checked(&chain, size, spp, &[]);
    let mut s = renderer_at(unfolded.to_str().unwrap(), size, size, spp, &[]);
    s.options.seed = 2;
    let b = render(&s).frame.image();
    let mut s = renderer_at(unfolded.to_str().unwrap(), size, size, spp, &[]);
    s.options.seed = 3;
    let c = render(&s).frame.image();
    let noise = metrics::compare(&c, &b, None).unwrap();
    let e = metrics::compare(&a, &b, None).unwrap();
    eprintln!(
        "mirror chain: relMSE {:.4e} (noise {:.4e}), luminance ratio {:.4}, mean {:.4}",
        e.relmse, noise.relmse, e.luminance_ratio, e.mean_luminance_b
    );
    assert!(e.mean_luminance_b > 0.05, "the unfolded wall must be lit");
    assert!(
        (e.luminance_ratio - 1.0).abs() < 0.03,
        "through 10 mirrors the wall has {:.4} of its direct light",
        e.luminance_ratio
    );
    assert!(e.relmse < 1.5 * noise.relmse, "{e:?} vs noise {noise:?}");
    // The physical cap still applies: 10 reflections need a ray depth above 10.
    let (capped, _) = render_checked(&chain, size, 16, &params(&[("max_ray_depth", 8.into())]));
    let m = capped.iter().map(|c| c.luminance() as f64).sum::<f64>() / capped.len() as f64;
    assert!(
        m < 1e-3 * e.mean_luminance_b,
        "max_ray_depth = 8 must stop the path before the wall (mean {m})"
    );
}
