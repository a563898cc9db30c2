//! Distributed renders: deterministic sample ranges (`--part K/N`, `--samples A..B`), the
//! metadata a part's EXR records, and `flowlight merge` (docs/distributed.md).
//!
//! # Why parts merge to the full render bit for bit
//!
//! Sample s of pixel p draws its random numbers from a stream seeded by (seed, p, s) only
//! (MCPT and ERPT's seed paths: `flowlight_pathtrace::sampler`, a stream of
//! `Rng::hash([seed, x, y, s])` or the Sobol' points of index s scrambled by
//! `Rng::hash([seed, x, y])`; ERPT's chains: stream 1 of `Rng::hash([seed, x, y, s])`),
//! so a render of samples [A, B) computes exactly the deposits the full render computes for
//! those samples. The host's sums are fixed-point integers
//! ([`crate::accumulation`]: every deposit value v becomes ⌊v·2⁶⁴⌋, sums are `u128`
//! additions), so the per-pixel sum over [0, T) is the same integer whether it was added in
//! one render or as Σ_k (sum over part k): integer addition is associative. A part stores
//! those sums exactly (each `u128` as four `u32` EXR channels `sum.R.w0` … `sum.R.w3`, per
//! lighting layer `sum.layerK.R.w0` …, and the per-pixel sample counts in `samples`); the
//! merge adds them and resolves the image with the same code as a render
//! (`Frame::image`): sum·(1/n) in f64, rounded to f32. MCPT parts merged therefore equal the
//! full render bitwise, for any split and any thread counts.
//!
//! A part K of N (0 ≤ K < N) of a T-sample render holds samples
//!
//!   [⌊K·T/N⌋, ⌊(K+1)·T/N⌋),
//!
//! so the N parts tile [0, T) without gaps or overlaps and differ in size by at most one.
//!
//! # ERPT: the deposition quantum
//!
//! ERPT's default `quantum = "tile"` estimates e_d per work unit from the unit's own seeds,
//! traced from the fixed streams (seed, x, y, s) of the unit's tile and samples. ERPT passes
//! hold one sample each (flanged integrators keep one-sample passes), so a unit is (tile,
//! sample s) in a full render and in a part alike: its quantum, seeds and chains depend on
//! the tile layout (`render.tile_size`, part of the config hash) and s, never on the range
//! the part was given. `quantum = "image"` takes e_d from a one-sample pre-pass seeded with
//! a fixed constant, the same in every part. Either way every part deposits exactly the
//! energy the full render deposits for its samples, and the merge normalises the flanged
//! image by the total number of samples (Σ of the parts' uniform counts), as the full
//! render does: the merged image is the full render's (bitwise, with the same tiles). Its
//! expectation is that of one render with T samples, since each sample's deposit, whose
//! expectation is the pixel's value (§5.2: E[deposits of a seed] = its estimate), is
//! counted once. Parts rendered with different tile sizes would still be unbiased (each
//! sample's expected energy does not depend on the tiles) but no longer bitwise equal; the
//! config hash refuses them anyway.
//!
//! # What a part records
//!
//! Besides the render's own metadata (`flowlight.integrator`, `flowlight.seed`,
//! `flowlight.spp` = the part's samples per pixel, …): `flowlight.samples` (the ranges held,
//! `A..B[,C..D]`), `flowlight.spp_total` (T), `flowlight.part` (`K/N`, `samples` for
//! `--samples`, `merged` for a merge), `flowlight.config_hash` (FNV-1a 64 of the resolved
//! config minus outputs, seed, threads and budget: [`config_hash`]), `flowlight.layers`,
//! `flowlight.uniform_spp` (the flanged normalisation, `none` for tile-local) and, for a
//! merge, `flowlight.partial` / `flowlight.missing`.

use crate::accumulation::Frame;
use crate::output::{
    read_exr_metadata, read_exr_u32, write_atomically, write_exr_with_raw, ExrMetadata,
    OutputError, RawChannel,
};
use crate::render::{PartialPass, RenderStats};
use flowlight_scene::config::RenderConfig;
use flowlight_sdk::abi::StatSpec;
use flowlight_sdk::StatMerge;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Metadata keys a part writes.
pub const KEY_SAMPLES: &str = "flowlight.samples";
pub const KEY_SPP_TOTAL: &str = "flowlight.spp_total";
pub const KEY_PART: &str = "flowlight.part";
pub const KEY_CONFIG_HASH: &str = "flowlight.config_hash";
pub const KEY_UNIFORM_SPP: &str = "flowlight.uniform_spp";
pub const KEY_LAYERS: &str = "flowlight.layers";
pub const KEY_PARTIAL: &str = "flowlight.partial";
pub const KEY_MISSING: &str = "flowlight.missing";
/// FNV-1a 64 of a part's exact sums, sample counts and the metadata that says how they
/// resolve ([`sums_checksum`]): another tool's edit of a channel is refused by the merge.
pub const KEY_CHECKSUM: &str = "flowlight.sums_fnv1a";
/// FNV-1a 64 of the part's `.stats.json` text, so that a truncated, edited or foreign
/// statistics file is refused by the merge rather than summed.
pub const KEY_STATS_CHECKSUM: &str = "flowlight.stats_fnv1a";

/// The share of a render's samples one part computes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PartSpec {
    /// Samples [begin, end) of every pixel.
    pub begin: u32,
    pub end: u32,
    /// T: the samples per pixel of the whole render.
    pub total: u32,
    /// `Some((K, N))` for `--part K/N`.
    pub part: Option<(u32, u32)>,
}

impl PartSpec {
    /// `--part K/N` of a `total`-sample render: samples [⌊K·T/N⌋, ⌊(K+1)·T/N⌋).
    pub fn part(k: u32, n: u32, total: u32) -> Result<PartSpec, String> {
        if n == 0 || k >= n {
            return Err(format!(
                "--part {k}/{n}: K must be in 0..N (parts are numbered from 0, as Slurm array and Kubernetes completion indices are)"
            ));
        }
        if n > total {
            return Err(format!(
                "--part {k}/{n}: {n} parts of a {total}-sample render would leave parts empty; use at most {total} parts or raise --spp"
            ));
        }
        let at = |i: u32| (i as u64 * total as u64 / n as u64) as u32;
        Ok(PartSpec {
            begin: at(k),
            end: at(k + 1),
            total,
            part: Some((k, n)),
        })
    }

    /// `--samples A..B` (B > A) of a `total`-sample render.
    pub fn samples(begin: u32, end: u32, total: u32) -> Result<PartSpec, String> {
        if end <= begin {
            return Err(format!(
                "--samples {begin}..{end}: the range is empty (the end is exclusive and must exceed the start)"
            ));
        }
        if end > total {
            return Err(format!(
                "--samples {begin}..{end}: the render has {total} samples per pixel (render.spp or --spp), so the range must lie within 0..{total}"
            ));
        }
        Ok(PartSpec {
            begin,
            end,
            total,
            part: None,
        })
    }
}

/// Parses `K/N`.
pub fn parse_part(s: &str) -> Result<(u32, u32), String> {
    let err = || format!("--part {s}: expected K/N with whole numbers, e.g. --part 0/4");
    let (k, n) = s.split_once('/').ok_or_else(err)?;
    Ok((
        k.trim().parse().map_err(|_| err())?,
        n.trim().parse().map_err(|_| err())?,
    ))
}

/// Parses `A..B` (B exclusive).
pub fn parse_samples(s: &str) -> Result<(u32, u32), String> {
    let err = || format!("--samples {s}: expected A..B with whole numbers, e.g. --samples 0..16");
    let (a, b) = s.split_once("..").ok_or_else(err)?;
    Ok((
        a.trim().parse().map_err(|_| err())?,
        b.trim().parse().map_err(|_| err())?,
    ))
}

/// 64-bit FNV-1a, continuing from `h` (start with [`FNV_OFFSET`]): a stable hash, the same
/// on every machine and Rust version.
pub fn fnv1a(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// The part of the config hash that needs no file reads: everything in the resolved config
/// that can change a sample's value, as text. Excluded: the output paths, the part, the
/// seed (compared on its own), threads (sums do not depend on them), the sample budget
/// (`flowlight.spp_total` is compared on its own), the plugin search path and the file
/// paths (the scene and the environment map enter by their bytes: [`config_hash`]).
/// `params` are the integrator's parameters after `--set`, mutations included.
pub fn config_text(
    config: &RenderConfig,
    camera: &flowlight_core::camera::Camera,
    params: &[(String, toml::Value)],
) -> String {
    let mut params: Vec<String> = params.iter().map(|(k, v)| format!("{k}={v}")).collect();
    params.sort();
    let env = config
        .environment
        .as_ref()
        .map(|e| {
            format!(
                "color={:?} strength={:?} rotation={:?} map={}",
                e.color,
                e.strength,
                e.rotation_degrees,
                e.map.is_some()
            )
        })
        .unwrap_or_default();
    format!(
        "size={}x{}\ntile={}\nintersector={:?}\nquality={}\nrobust={}\ncamera={camera:?}\nintegrator={}\nparams={}\nmaterials={:?}\nenvironment={env}\n",
        config.width,
        config.height,
        config.tile_size,
        config.intersector,
        config.build_quality,
        config.robust,
        config.integrator_plugin,
        params.join(" "),
        config.material_overrides,
    ) + &load_options_text(config)
}

/// The loading options that change the image, as lines of [`config_text`]; empty at their
/// defaults, so the hash of every config without them stays what it was.
fn load_options_text(config: &RenderConfig) -> String {
    let mut t = String::new();
    if config.multiscatter {
        t += "multiscatter=true\n";
    }
    if config.missing_textures != flowlight_scene::MissingTextures::Error {
        t += &format!("missing_textures={:?}\n", config.missing_textures);
    }
    t
}

/// FNV-1a of [`config_text`] followed by the bytes of the scene file and of the
/// environment map (the glTF's external buffers and textures are not read: parts of one
/// job share them).
pub fn config_hash(text: &str, config: &RenderConfig) -> Result<u64, String> {
    let mut h = fnv1a(FNV_OFFSET, text.as_bytes());
    let mut files = vec![config.scene.clone()];
    if let Some(m) = config.environment.as_ref().and_then(|e| e.map.clone()) {
        files.push(m);
    }
    for f in files {
        let bytes = std::fs::read(&f).map_err(|e| {
            format!(
                "{}: cannot read {} for the config hash: {e}",
                config.path.display(),
                f.display()
            )
        })?;
        h = fnv1a(h, &bytes);
    }
    Ok(h)
}

/// `A..B,C..D`.
pub fn format_ranges(ranges: &[(u32, u32)]) -> String {
    ranges
        .iter()
        .map(|(a, b)| format!("{a}..{b}"))
        .collect::<Vec<_>>()
        .join(",")
}

fn parse_ranges(s: &str) -> Option<Vec<(u32, u32)>> {
    s.split(',')
        .map(|r| {
            let (a, b) = r.split_once("..")?;
            let (a, b) = (a.parse().ok()?, b.parse().ok()?);
            (b > a).then_some((a, b))
        })
        .collect()
}

/// The metadata entries of a part (added to the render's own).
pub fn part_entries(spec: &PartSpec, hash: u64, frame: &Frame) -> Vec<(String, String)> {
    vec![
        (KEY_SAMPLES.into(), format_ranges(&[(spec.begin, spec.end)])),
        (KEY_SPP_TOTAL.into(), spec.total.to_string()),
        (
            KEY_PART.into(),
            spec.part
                .map_or("samples".to_string(), |(k, n)| format!("{k}/{n}")),
        ),
        (KEY_CONFIG_HASH.into(), format!("{hash:016x}")),
        (KEY_LAYERS.into(), frame.layer_count.to_string()),
        (KEY_UNIFORM_SPP.into(), uniform_text(frame.uniform_spp())),
    ]
}

fn uniform_text(u: Option<f64>) -> String {
    // `{}` of an f64 prints the shortest text that parses back to the same bits.
    u.map_or("none".to_string(), |v| format!("{v}"))
}

fn sum_channel_names(layer: Option<usize>) -> [[String; 4]; 3] {
    let prefix = layer.map_or("sum".to_string(), |k| format!("sum.layer{k}"));
    ["R", "G", "B"].map(|c| std::array::from_fn(|w| format!("{prefix}.{c}.w{w}")))
}

fn large_channel_names(k: usize) -> [[String; 2]; 3] {
    let prefix = if k == 0 {
        "large".to_string()
    } else {
        format!("large.layer{}", k - 1)
    };
    ["R", "G", "B"].map(|c| std::array::from_fn(|w| format!("{prefix}.{c}.w{w}")))
}

/// The frame's exact sums and sample counts as `u32` channels (module documentation).
pub fn sum_channels(frame: &Frame) -> Vec<RawChannel> {
    let mut out = Vec::new();
    let mut push = |sums: &[[u128; 3]], layer: Option<usize>| {
        let names = sum_channel_names(layer);
        for (c, words) in names.into_iter().enumerate() {
            for (w, name) in words.into_iter().enumerate() {
                out.push(RawChannel {
                    name,
                    samples: sums.iter().map(|s| (s[c] >> (32 * w)) as u32).collect(),
                });
            }
        }
    };
    push(frame.main_sums(), None);
    for k in 0..frame.layer_count as usize {
        push(frame.layer_sums(k), Some(k));
    }
    // Large values' f64 sums (accumulation docs), as the two halves of their bits; only
    // where there are any.
    let n = frame.width as usize * frame.height as usize;
    for k in 0..=frame.layer_count as usize {
        let large = frame.large_sums(k);
        if large.is_empty() {
            continue;
        }
        for (c, words) in large_channel_names(k).into_iter().enumerate() {
            for (w, name) in words.into_iter().enumerate() {
                let mut samples = vec![0u32; n];
                for (&i, v) in large {
                    samples[i] = (v[c].to_bits() >> (32 * w)) as u32;
                }
                out.push(RawChannel { name, samples });
            }
        }
    }
    out.push(RawChannel {
        name: "samples".into(),
        samples: frame.samples().to_vec(),
    });
    out
}

/// FNV-1a 64 over the `u32` channels (by name, then their little-endian words) and the
/// metadata values that say what the sums are (`flowlight.samples`, `.spp_total`, `.layers`,
/// `.uniform_spp`), as 16 hex digits.
pub fn sums_checksum<'c>(
    channels: impl IntoIterator<Item = (&'c str, &'c [u32])>,
    meta: &BTreeMap<String, String>,
) -> String {
    let mut sorted: Vec<(&str, &[u32])> = channels.into_iter().collect();
    sorted.sort_by_key(|c| c.0);
    let mut h = FNV_OFFSET;
    for (name, words) in sorted {
        h = fnv1a(h, name.as_bytes());
        h = fnv1a(h, &[0]);
        for w in words {
            h = fnv1a(h, &w.to_le_bytes());
        }
    }
    for key in [KEY_SAMPLES, KEY_SPP_TOTAL, KEY_LAYERS, KEY_UNIFORM_SPP] {
        h = fnv1a(h, key.as_bytes());
        h = fnv1a(h, meta.get(key).map_or("", |v| v.as_str()).as_bytes());
        h = fnv1a(h, &[0]);
    }
    format!("{h:016x}")
}

/// Writes a part's (or a merge's) EXR: the resolved image and layers, the exact sums, and
/// `meta` plus the sums' checksum ([`KEY_CHECKSUM`]).
pub fn write_part_exr(path: &Path, frame: &Frame, meta: &ExrMetadata) -> Result<(), String> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let image = frame.image();
    let layers: Vec<Vec<flowlight_core::Rgb>> = (0..frame.layer_count as usize)
        .map(|k| frame.layer(k))
        .collect();
    let exr_layers = crate::output::frame_layers(&image, &layers);
    let raw = sum_channels(frame);
    let mut meta = meta.clone();
    meta.entries.retain(|(k, _)| k != KEY_CHECKSUM);
    let values: BTreeMap<String, String> = meta.entries.iter().cloned().collect();
    let checksum = sums_checksum(
        raw.iter().map(|c| (c.name.as_str(), c.samples.as_slice())),
        &values,
    );
    meta.entries.push((KEY_CHECKSUM.into(), checksum));
    write_exr_with_raw(path, w, h, &exr_layers, &raw, &meta).map_err(|e| e.to_string())
}

/// A part read back.
pub struct PartFile {
    pub path: PathBuf,
    pub meta: BTreeMap<String, String>,
    pub ranges: Vec<(u32, u32)>,
    pub total: u32,
    pub frame: Frame,
}

impl PartFile {
    fn get(&self, key: &str) -> &str {
        self.meta.get(key).map_or("", |s| s.as_str())
    }
}

/// Reads a part written by `flowlight render --part/--samples` or `flowlight merge`.
pub fn read_part(path: &Path) -> Result<PartFile, String> {
    let p = path.display();
    let meta: BTreeMap<String, String> = read_exr_metadata(path)
        .map_err(|e| e.to_string())?
        .entries
        .into_iter()
        .collect();
    let field = |key: &str| {
        meta.get(key).ok_or_else(|| {
            format!("{p}: not a part of a distributed render (no {key} in its metadata): render it with --part K/N or --samples A..B")
        })
    };
    let ranges = parse_ranges(field(KEY_SAMPLES)?).ok_or_else(|| {
        format!(
            "{p}: {KEY_SAMPLES} = {:?} is not a list of ranges A..B",
            meta[KEY_SAMPLES]
        )
    })?;
    let total: u32 = field(KEY_SPP_TOTAL)?
        .parse()
        .map_err(|_| format!("{p}: {KEY_SPP_TOTAL} is not a whole number"))?;
    let layers: usize = field(KEY_LAYERS)?
        .parse()
        .map_err(|_| format!("{p}: {KEY_LAYERS} is not a whole number"))?;
    let uniform = match field(KEY_UNIFORM_SPP)?.as_str() {
        "none" => None,
        u => Some(
            u.parse::<f64>()
                .map_err(|_| format!("{p}: {KEY_UNIFORM_SPP} = {u:?} is not a number"))?,
        ),
    };
    if meta.get("flowlight.interrupted").map(|s| s.as_str()) == Some("true") {
        return Err(format!(
            "{p}: this part was interrupted (flowlight.interrupted = true) and holds fewer samples than its range; render it again"
        ));
    }
    if ranges.iter().any(|&(_, b)| b > total) {
        return Err(format!(
            "{p}: {KEY_SAMPLES} = {} reaches beyond the render's {total} samples per pixel ({KEY_SPP_TOTAL})",
            meta[KEY_SAMPLES]
        ));
    }
    let (w, h, mut channels) = read_exr_u32(path).map_err(|e: OutputError| e.to_string())?;
    let stored = meta.get(KEY_CHECKSUM).ok_or_else(|| {
        format!("{p}: no {KEY_CHECKSUM} checksum of its sums in its metadata (written by an older Flowlight, or rewritten by another tool): render this part again")
    })?;
    let computed = sums_checksum(
        channels.iter().map(|(n, v)| (n.as_str(), v.as_slice())),
        &meta,
    );
    if *stored != computed {
        return Err(format!(
            "{p}: its exact sums or sample counts do not match the checksum it was written with ({KEY_CHECKSUM} = {stored}, the channels give {computed}): another tool changed them; render this part again"
        ));
    }
    let mut take_sums = |layer: Option<usize>| -> Result<Vec<[u128; 3]>, String> {
        let mut sums = vec![[0u128; 3]; w * h];
        for (c, words) in sum_channel_names(layer).into_iter().enumerate() {
            for (wi, name) in words.into_iter().enumerate() {
                let v = channels
                    .remove(&name)
                    .ok_or_else(|| format!("{p}: the exact-sum channel {name} is missing"))?;
                for (s, x) in sums.iter_mut().zip(v) {
                    s[c] |= (x as u128) << (32 * wi);
                }
            }
        }
        Ok(sums)
    };
    let main = take_sums(None)?;
    let layer_sums = (0..layers)
        .map(|k| take_sums(Some(k)))
        .collect::<Result<Vec<_>, _>>()?;
    let samples = channels
        .remove("samples")
        .ok_or_else(|| format!("{p}: the sample-count channel `samples` is missing"))?;
    let mut large = vec![crate::accumulation::LargeSums::new(); layers + 1];
    for (k, map) in large.iter_mut().enumerate() {
        for (c, [lo, hi]) in large_channel_names(k).into_iter().enumerate() {
            let (Some(lo), Some(hi)) = (channels.remove(&lo), channels.remove(&hi)) else {
                continue;
            };
            for (i, (l, h)) in lo.into_iter().zip(hi).enumerate() {
                let v = f64::from_bits(l as u64 | (h as u64) << 32);
                if v != 0.0 {
                    map.entry(i).or_insert([0.0; 3])[c] = v;
                }
            }
        }
    }
    let frame = Frame::from_sums(
        w as u32, h as u32, main, layer_sums, samples, uniform, large,
    );
    Ok(PartFile {
        path: path.to_path_buf(),
        meta,
        ranges,
        total,
        frame,
    })
}

/// What a merge wrote.
#[derive(Debug)]
pub struct MergeReport {
    pub written: Vec<PathBuf>,
    /// Ranges of [0, T) no part held (only with `allow_missing`).
    pub missing: Vec<(u32, u32)>,
    pub ranges: Vec<(u32, u32)>,
    pub total: u32,
    /// Parts without a statistics file, or whose statistics could not be merged.
    pub stats_warning: Option<String>,
}

/// Ranges of [0, total) none of `sorted` (sorted, disjoint) covers.
fn gaps(sorted: &[(u32, u32)], total: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut at = 0;
    for &(a, b) in sorted {
        if a > at && at < total {
            out.push((at, a.min(total)));
        }
        at = at.max(b);
    }
    if at < total {
        out.push((at, total));
    }
    out
}

/// Joins adjacent ranges of a sorted, disjoint list.
fn coalesce(sorted: &[(u32, u32)]) -> Vec<(u32, u32)> {
    let mut out: Vec<(u32, u32)> = Vec::new();
    for &(a, b) in sorted {
        match out.last_mut() {
            Some(last) if last.1 == a => last.1 = b,
            _ => out.push((a, b)),
        }
    }
    out
}

/// Merges `inputs` into `out` (docs/distributed.md): refuses parts of different configs,
/// seeds, sizes, integrators or sample totals, and overlapping ranges, naming the files;
/// refuses missing ranges unless `allow_missing` (then the output says
/// `flowlight.partial = true` and lists them). Adds the exact sums (so each sample is
/// weighted once: a part's weight is its sample count), merges every lighting layer and
/// the `.stats.json` statistics, and writes atomically; never overwrites an input.
pub fn merge(out: &Path, inputs: &[PathBuf], allow_missing: bool) -> Result<MergeReport, String> {
    if inputs.is_empty() {
        return Err("flowlight merge: no parts given".into());
    }
    let same = |a: &Path, b: &Path| {
        let c = |p: &Path| {
            p.canonicalize()
                .unwrap_or_else(|_| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()))
        };
        c(a) == c(b)
    };
    let out_stats = out.with_extension("stats.json");
    for i in inputs {
        if same(out, i) || same(&out_stats, i) || same(&out_stats, &i.with_extension("stats.json"))
        {
            return Err(format!(
                "{}: the merge output (or its statistics file) is the input {}; refusing to overwrite an input",
                out.display(),
                i.display()
            ));
        }
    }
    for (i, a) in inputs.iter().enumerate() {
        if let Some(b) = inputs[..i].iter().find(|b| same(a, b)) {
            return Err(format!(
                "{} is given twice (also as {})",
                a.display(),
                b.display()
            ));
        }
    }
    let parts = inputs
        .iter()
        .map(|p| read_part(p))
        .collect::<Result<Vec<_>, _>>()?;
    // Nor the config or the scene the parts were rendered from.
    for p in &parts {
        for (key, what) in [
            ("flowlight.config", "the config"),
            ("flowlight.scene", "the scene"),
        ] {
            if let Some(input) = p.meta.get(key).filter(|i| same(out, Path::new(i))) {
                return Err(format!(
                    "{}: the merge output is {what} {input} that {} was rendered from; refusing to overwrite an input",
                    out.display(),
                    p.path.display()
                ));
            }
        }
    }
    let first = &parts[0];
    for p in &parts[1..] {
        let (a, b) = (first.path.display(), p.path.display());
        let differ = |what: &str, x: &str, y: &str| {
            format!("{a} and {b}: different {what} ({x} vs {y}); parts of one image must come from the same config, seed and options")
        };
        if (first.frame.width, first.frame.height) != (p.frame.width, p.frame.height) {
            return Err(differ(
                "image sizes",
                &format!("{}x{}", first.frame.width, first.frame.height),
                &format!("{}x{}", p.frame.width, p.frame.height),
            ));
        }
        for (key, what) in [
            ("flowlight.integrator", "integrators"),
            (KEY_CONFIG_HASH, "configs (config hash)"),
            ("flowlight.seed", "seeds"),
            (KEY_SPP_TOTAL, "sample totals (--spp)"),
            (KEY_LAYERS, "lighting layer counts"),
        ] {
            if first.get(key) != p.get(key) {
                return Err(differ(what, first.get(key), p.get(key)));
            }
        }
        if first.frame.uniform_spp().is_some() != p.frame.uniform_spp().is_some() {
            return Err(differ("normalisations", "uniform", "per pixel"));
        }
    }
    let total = first.total;
    let mut held: Vec<(u32, u32, usize)> = parts
        .iter()
        .enumerate()
        .flat_map(|(i, p)| p.ranges.iter().map(move |&(a, b)| (a, b, i)))
        .collect();
    held.sort();
    for w in held.windows(2) {
        let ((a0, b0, i), (a1, b1, j)) = (w[0], w[1]);
        if a1 < b0 {
            return Err(format!(
                "{} (samples {a0}..{b0}) and {} (samples {a1}..{b1}) overlap: each sample may be merged once",
                parts[i].path.display(),
                parts[j].path.display()
            ));
        }
    }
    let sorted: Vec<(u32, u32)> = held.iter().map(|&(a, b, _)| (a, b)).collect();
    let missing = gaps(&sorted, total);
    if !missing.is_empty() && !allow_missing {
        return Err(format!(
            "samples {} of 0..{total} are in none of the parts (held: {}); render the missing parts, or pass --allow-missing to write a partial image",
            format_ranges(&missing),
            format_ranges(&coalesce(&sorted))
        ));
    }

    let mut frame = Frame::from_sums(
        first.frame.width,
        first.frame.height,
        first.frame.main_sums().to_vec(),
        (0..first.frame.layer_count as usize)
            .map(|k| first.frame.layer_sums(k).to_vec())
            .collect(),
        first.frame.samples().to_vec(),
        first.frame.uniform_spp(),
        (0..=first.frame.layer_count as usize)
            .map(|k| first.frame.large_sums(k).clone())
            .collect(),
    );
    let mut uniform = first.frame.uniform_spp();
    for p in &parts[1..] {
        frame.add_frame(&p.frame);
        uniform = uniform.zip(p.frame.uniform_spp()).map(|(a, b)| a + b);
    }
    if let Some(u) = uniform {
        frame.set_uniform_spp(u);
    }
    let ranges = coalesce(&sorted);
    let spp: u64 = sorted.iter().map(|&(a, b)| (b - a) as u64).sum();
    let mut meta = first.meta.clone();
    meta.remove(KEY_STATS_CHECKSUM);
    meta.insert(KEY_SAMPLES.into(), format_ranges(&ranges));
    meta.insert(KEY_PART.into(), "merged".into());
    meta.insert(KEY_UNIFORM_SPP.into(), uniform_text(uniform));
    meta.insert("flowlight.spp".into(), spp.to_string());
    meta.insert(KEY_PARTIAL.into(), (!missing.is_empty()).to_string());
    meta.insert(KEY_MISSING.into(), format_ranges(&missing));
    let meta = ExrMetadata {
        entries: meta.into_iter().collect(),
    };

    // Statistics first (nothing is written if they fail to parse), then the image, which
    // records the statistics' checksum.
    let (stats, stats_warning) = merge_stats_files(&parts)?;
    let mut meta = meta;
    if let Some(json) = &stats {
        meta.entries.push((
            KEY_STATS_CHECKSUM.into(),
            format!("{:016x}", fnv1a(FNV_OFFSET, json.as_bytes())),
        ));
    }
    write_part_exr(out, &frame, &meta)?;
    let mut written = vec![out.to_path_buf()];
    if let Some(json) = stats {
        write_atomically(&out_stats, |tmp| {
            std::fs::write(tmp, &json).map_err(|e| OutputError::Io {
                path: out_stats.clone(),
                source: e,
            })
        })
        .map_err(|e| e.to_string())?;
        written.push(out_stats);
    }
    Ok(MergeReport {
        written,
        missing,
        ranges,
        total,
        stats_warning,
    })
}

/// How a counter merges over parts, as the `counter_kinds` of a part's `.stats.json` says:
/// `sum`, `max`, or `ratio NUMERATOR DENOMINATOR` (names of two other counters).
pub fn counter_kinds(specs: &[StatSpec]) -> Vec<(String, String)> {
    // SAFETY: static strings of the loaded plugin, alive as long as its instance.
    let name = |i: usize| unsafe { specs[i].name.as_str() }.to_string();
    (0..specs.len())
        .map(|i| {
            let s = &specs[i];
            let kind = match s.merge {
                StatMerge::Sum => "sum".to_string(),
                StatMerge::Max => "max".to_string(),
                StatMerge::Ratio => {
                    let (n, d) = (s.numerator as usize, s.denominator as usize);
                    if n < specs.len() && d < specs.len() {
                        format!("ratio {} {}", name(n), name(d))
                    } else {
                        "ratio".to_string()
                    }
                }
            };
            (name(i), kind)
        })
        .collect()
}

fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        if c == '"' || c == '\\' {
            out.push('\\');
        }
        out.push(c);
    }
    out.push('"');
    out
}

/// The renderer's statistics JSON with a `counter_kinds` object appended, for a part.
pub fn stats_json_with_kinds(json: &str, kinds: &[(String, String)]) -> String {
    let body = json.trim_end().strip_suffix('}').unwrap_or(json).trim_end();
    let mut out = format!("{body},\n  \"counter_kinds\": {{");
    for (i, (k, v)) in kinds.iter().enumerate() {
        out += &format!(
            "{}\n    {}: {}",
            if i == 0 { "" } else { "," },
            json_string(k),
            json_string(v)
        );
    }
    out += "\n  }\n}\n";
    out
}

/// The flat JSON `stats_json` writes, read back: top-level values and those of each nested
/// object (`counters`, `counter_kinds`), in file order.
type FlatJson = Vec<(Option<String>, String, String)>;

fn parse_stats_json(text: &str) -> Option<FlatJson> {
    let unquote = |s: &str| -> Option<String> {
        let s = s.trim().strip_prefix('"')?.strip_suffix('"')?;
        let mut out = String::new();
        let mut esc = false;
        for c in s.chars() {
            if esc || c != '\\' {
                out.push(c);
                esc = false;
            } else {
                esc = true;
            }
        }
        Some(out)
    };
    let mut section: Option<String> = None;
    let mut out = Vec::new();
    for line in text.lines().map(str::trim) {
        let line = line.strip_suffix(',').unwrap_or(line);
        if line == "{" || line.is_empty() {
            continue;
        }
        if line == "}" {
            section = None;
            continue;
        }
        let (k, v) = split_key(line)?;
        let key = unquote(k)?;
        let v = v.trim();
        if v == "{" {
            section = Some(key);
        } else if v == "{}" {
            continue;
        } else {
            let value = if v.starts_with('"') {
                unquote(v)?
            } else {
                v.to_string()
            };
            out.push((section.clone(), key, value));
        }
    }
    Some(out)
}

/// Splits `"key": value` at the colon after the quoted key.
fn split_key(line: &str) -> Option<(&str, &str)> {
    let bytes = line.as_bytes();
    if bytes.first() != Some(&b'"') {
        return None;
    }
    let mut i = 1;
    while i < bytes.len() {
        match bytes[i] {
            b'\\' => i += 2,
            b'"' => break,
            _ => i += 1,
        }
    }
    let rest = line.get(i + 1..)?.trim_start().strip_prefix(':')?;
    Some((&line[..=i], rest))
}

/// Merges the parts' `.stats.json` files: host counters and `sum` counters add, `max`
/// ones take the maximum, ratios are recomputed from the merged numerator and denominator;
/// `wall_seconds` is the sum over the parts (machine time, not the elapsed time). `None`
/// with a warning when a part has no statistics file, or one without `counter_kinds`; an
/// error when a statistics file is not the one its part was written with (its checksum,
/// [`KEY_STATS_CHECKSUM`], differs: truncated, edited or another render's).
type MergedStats = (Option<String>, Option<String>);

fn merge_stats_files(parts: &[PartFile]) -> Result<MergedStats, String> {
    let mut files = Vec::new();
    for p in parts {
        let path = p.path.with_extension("stats.json");
        let Ok(text) = std::fs::read_to_string(&path) else {
            return Ok((
                None,
                Some(format!(
                    "{} is missing: statistics not merged",
                    path.display()
                )),
            ));
        };
        let checksum = format!("{:016x}", fnv1a(FNV_OFFSET, text.as_bytes()));
        match p.meta.get(KEY_STATS_CHECKSUM) {
            Some(expected) if *expected != checksum => {
                return Err(format!(
                    "{}: not the statistics {} was written with ({KEY_STATS_CHECKSUM} = {expected}, the file gives {checksum}): it was truncated, edited or comes from another render; restore it, or delete it to merge without statistics",
                    path.display(),
                    p.path.display()
                ))
            }
            Some(_) => {}
            None => {
                return Ok((
                    None,
                    Some(format!(
                        "{} has no {KEY_STATS_CHECKSUM} for {}: statistics not merged",
                        p.path.display(),
                        path.display()
                    )),
                ))
            }
        }
        match parse_stats_json(&text) {
            Some(v) => files.push((path, v)),
            None => {
                return Ok((
                    None,
                    Some(format!(
                        "{}: cannot parse it: statistics not merged",
                        path.display()
                    )),
                ))
            }
        }
    }
    let get = |f: &FlatJson, sec: Option<&str>, key: &str| -> Option<String> {
        f.iter()
            .find(|(s, k, _)| s.as_deref() == sec && k == key)
            .map(|(_, _, v)| v.clone())
    };
    let num = |f: &FlatJson, sec: Option<&str>, key: &str| -> f64 {
        get(f, sec, key).and_then(|v| v.parse().ok()).unwrap_or(0.0)
    };
    let (first_path, first) = &files[0];
    let integrator = get(first, None, "integrator").unwrap_or_default();
    let names: Vec<String> = first
        .iter()
        .filter(|(s, ..)| s.as_deref() == Some("counters"))
        .map(|(_, k, _)| k.clone())
        .collect();
    let kinds: Vec<(String, String)> = names
        .iter()
        .filter_map(|n| Some((n.clone(), get(first, Some("counter_kinds"), n)?)))
        .collect();
    if kinds.len() != names.len() {
        return Ok((
            None,
            Some(format!(
                "{} has no counter_kinds for every counter (not written by a part render): statistics not merged",
                first_path.display()
            )),
        ));
    }
    let sum = |key: &str| files.iter().map(|(_, f)| num(f, None, key)).sum::<f64>();
    let mut counters: Vec<(String, f64)> = Vec::new();
    for (name, kind) in &kinds {
        let values = files.iter().map(|(_, f)| num(f, Some("counters"), name));
        let v = match kind.as_str() {
            "max" => values.fold(f64::NEG_INFINITY, f64::max),
            k if k.starts_with("ratio") => f64::NAN,
            _ => values.sum(),
        };
        counters.push((name.clone(), v));
    }
    for (i, (_, kind)) in kinds.iter().enumerate() {
        let mut words = kind.split_whitespace();
        if words.next() == Some("ratio") {
            let find = |n: Option<&str>| {
                n.and_then(|n| counters.iter().find(|(k, _)| k == n).map(|c| c.1))
            };
            let (n, d) = (find(words.next()), find(words.next()));
            counters[i].1 = match (n, d) {
                (Some(n), Some(d)) if d != 0.0 => n / d,
                _ => 0.0,
            };
        }
    }
    let stats = RenderStats {
        wall: std::time::Duration::from_secs_f64(sum("wall_seconds").max(0.0)),
        pixel_samples: sum("pixel_samples") as u64,
        closest_rays: sum("closest_rays") as u64,
        shadow_rays: sum("shadow_rays") as u64,
        invalid_deposits: sum("invalid_deposits") as u64,
        full_passes: sum("full_passes") as u32,
        partial_pass: None::<PartialPass>,
        integrator: counters,
        ..Default::default()
    };
    let json = crate::renderer::stats_json(&integrator, &stats);
    Ok((Some(stats_json_with_kinds(&json, &kinds)), None))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_tile_the_samples_without_gaps_or_overlaps() {
        for (n, t) in [(4u32, 64u32), (3, 10), (7, 7), (5, 1000)] {
            let mut at = 0;
            for k in 0..n {
                let p = PartSpec::part(k, n, t).unwrap();
                assert_eq!(p.begin, at);
                assert!(p.end > p.begin && p.end - p.begin <= t / n + 1);
                at = p.end;
            }
            assert_eq!(at, t);
        }
        assert_eq!(PartSpec::part(1, 3, 10).unwrap().begin, 3);
        assert!(PartSpec::part(4, 4, 64).unwrap_err().contains("0..N"));
        assert!(PartSpec::part(0, 9, 8).unwrap_err().contains("empty"));
        assert!(PartSpec::samples(5, 5, 8).is_err());
        assert_eq!(parse_part("3/8"), Ok((3, 8)));
        assert_eq!(parse_samples("16..32"), Ok((16, 32)));
        assert!(parse_part("3").is_err() && parse_samples("3-4").is_err());
    }

    #[test]
    fn gaps_and_coalesced_ranges() {
        assert_eq!(gaps(&[(0, 4), (8, 12)], 16), vec![(4, 8), (12, 16)]);
        assert_eq!(gaps(&[(0, 16)], 16), vec![]);
        assert_eq!(gaps(&[(2, 20)], 16), vec![(0, 2)]);
        assert_eq!(coalesce(&[(0, 4), (4, 8), (9, 10)]), vec![(0, 8), (9, 10)]);
        assert_eq!(parse_ranges("0..8,9..10"), Some(vec![(0, 8), (9, 10)]));
        assert_eq!(parse_ranges("4..4"), None);
    }

    #[test]
    fn fnv1a_matches_the_reference_vectors() {
        // From the FNV reference: FNV-1a 64 of "" and "a".
        assert_eq!(fnv1a(FNV_OFFSET, b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(FNV_OFFSET, b"a"), 0xaf63_dc4c_8601_ec8c);
    }

    #[test]
    fn stats_merge_sums_maxes_and_recomputes_ratios() {
        let stats = |seeds: f64, chains: f64, longest: f64| RenderStats {
            pixel_samples: 10,
            integrator: vec![
                ("seeds".into(), seeds),
                ("chains".into(), chains),
                ("longest".into(), longest),
                ("chains_per_seed".into(), chains / seeds),
            ],
            ..Default::default()
        };
        let kinds: Vec<(String, String)> = [
            ("seeds", "sum"),
            ("chains", "sum"),
            ("longest", "max"),
            ("chains_per_seed", "ratio chains seeds"),
        ]
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
        let dir = std::env::temp_dir().join(format!("flowlight-parts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut parts = Vec::new();
        for (i, s) in [stats(2.0, 10.0, 3.0), stats(6.0, 6.0, 5.0)]
            .iter()
            .enumerate()
        {
            let path = dir.join(format!("p{i}.exr"));
            let json = stats_json_with_kinds(&crate::renderer::stats_json("erpt", s), &kinds);
            std::fs::write(path.with_extension("stats.json"), &json).unwrap();
            // The part's record of its statistics file (written with it).
            let checksum = format!("{:016x}", fnv1a(FNV_OFFSET, json.as_bytes()));
            parts.push(PartFile {
                path,
                meta: BTreeMap::from([(KEY_STATS_CHECKSUM.to_string(), checksum)]),
                ranges: vec![],
                total: 0,
                frame: Frame::new(1, 1, 0),
            });
        }
        let (json, warn) = merge_stats_files(&parts).unwrap();
        assert!(warn.is_none(), "{warn:?}");
        let flat = parse_stats_json(&json.unwrap()).unwrap();
        let c = |k: &str| {
            flat.iter()
                .find(|(s, n, _)| s.as_deref() == Some("counters") && n == k)
                .map(|(_, _, v)| v.parse::<f64>().unwrap())
                .unwrap()
        };
        assert_eq!(c("seeds"), 8.0);
        assert_eq!(c("longest"), 5.0);
        assert_eq!(c("chains_per_seed"), 2.0);
        assert!(flat
            .iter()
            .any(|(s, k, v)| s.is_none() && k == "pixel_samples" && v == "20"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
