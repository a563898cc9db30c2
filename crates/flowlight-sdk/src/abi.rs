//! The C-ABI surface between the host and a plugin. Everything here is `#[repr(C)]`, borrowed
//! (never freed on the other side) and versioned by [`ABI_VERSION`] plus a layout hash.
//!
//! Ownership rules: a pointer passed in a call is valid for that call only, unless the type's
//! doc says otherwise (the scene view lives as long as the plugin instance). Strings are
//! [`StrRef`]s: pointer + length, never freed by the receiver. Errors come back by copying a
//! message into a host-provided [`ErrorBuf`]. Panics are caught on the side that raised them.

use crate::params::ParamKind;
use flowlight_core::camera::Camera;
use flowlight_core::geometry::{Ray, SurfaceHit};
use flowlight_core::light::{Emitter, Environment, PunctualLight};
use flowlight_core::material::{Material, Texture, TextureRef};
use flowlight_core::mesh::{CompactHit, MeshInstance};
use flowlight_core::path::{Path, PathVertex};
use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use glam::Vec3;
use std::ffi::c_void;

/// Bumped whenever any type or function table in this module changes incompatibly; every
/// version and what changed is listed in the repository's `CHANGELOG.md`.
pub const ABI_VERSION: u32 = 9;
/// Version of the SDK crate compiled into this binary.
pub const SDK_VERSION: &str = env!("CARGO_PKG_VERSION");
/// `rustc --version` of the compiler that built this binary.
pub const RUSTC_VERSION: &str = env!("FLOWLIGHT_RUSTC_VERSION");
/// Name of the one symbol a plugin exports.
pub const DECLARATION_SYMBOL: &[u8] = b"flowlight_plugin_declaration\0";

/// A borrowed UTF-8 string.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StrRef {
    /// Start of the bytes (null or dangling when `len` is 0).
    pub ptr: *const u8,
    /// Length in bytes.
    pub len: usize,
}

// SAFETY: a StrRef only ever borrows immutable data (static strings or host-owned config text).
unsafe impl Sync for StrRef {}
unsafe impl Send for StrRef {}

impl StrRef {
    /// The empty string.
    pub const EMPTY: StrRef = StrRef {
        ptr: std::ptr::null(),
        len: 0,
    };

    /// Borrows `s` (the caller keeps it alive while the reference is read).
    pub const fn new(s: &str) -> StrRef {
        StrRef {
            ptr: s.as_ptr(),
            len: s.len(),
        }
    }

    /// # Safety
    /// The pointer must be valid for `len` bytes of UTF-8 for the chosen lifetime.
    pub unsafe fn as_str<'a>(&self) -> &'a str {
        // SAFETY: the caller upholds this function's contract (its `# Safety` section, or the
        // ABI rules in `abi.rs` for the C entry points).
        unsafe {
            if self.ptr.is_null() || self.len == 0 {
                return "";
            }
            let bytes = std::slice::from_raw_parts(self.ptr, self.len);
            std::str::from_utf8(bytes).unwrap_or("<invalid utf-8>")
        }
    }
}

/// Outcome of a call across the boundary.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The call succeeded.
    Ok = 0,
    /// The callee returned an error; its message is in the [`ErrorBuf`].
    Error = 1,
    /// The callee panicked; the panic message is in the [`ErrorBuf`].
    Panic = 2,
}

/// Host-owned buffer a callee copies an error message into (truncated to fit).
#[repr(C)]
pub struct ErrorBuf {
    /// Bytes of the message written (at most 1024).
    pub len: usize,
    /// The message, UTF-8, its first `len` bytes valid.
    pub bytes: [u8; 1024],
}

impl Default for ErrorBuf {
    fn default() -> Self {
        ErrorBuf {
            len: 0,
            bytes: [0; 1024],
        }
    }
}

impl ErrorBuf {
    /// Copies `msg` in, truncated at a character boundary to the buffer's 1024 bytes.
    pub fn set(&mut self, msg: &str) {
        let mut n = msg.len().min(self.bytes.len());
        while !msg.is_char_boundary(n) {
            n -= 1;
        }
        self.bytes[..n].copy_from_slice(&msg.as_bytes()[..n]);
        self.len = n;
    }

    /// The message written so far.
    pub fn message(&self) -> String {
        String::from_utf8_lossy(&self.bytes[..self.len.min(self.bytes.len())]).into_owned()
    }
}

/// What a plugin provides.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PluginKind {
    /// Implements [`crate::Integrator`]; the declaration's `integrator` table is set.
    Integrator = 0,
    /// Implements [`crate::Mutation`]; the declaration's `mutation` table is set.
    Mutation = 1,
}

/// One parameter a plugin accepts, for validation, for `flowlight plugins` (and its
/// `--markdown` tables) and for the host tools that look for a parameter by its
/// [`ParamRole`]. Built from a declaration ([`crate::declare`]) by its `spec()`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    /// The config key.
    pub name: StrRef,
    /// The value's type; the host refuses a config value of another type.
    pub kind: ParamKind,
    /// Default value as the user would write it in TOML, or a phrase (`by width`) when the
    /// default depends on other parameters.
    pub default: StrRef,
    /// Values accepted, as the docs print them (`1..=32`, `[0.01, 0.999]`,
    /// `"bxdf" | "equi"`); empty when every value of the type is (ABI 6).
    pub range: StrRef,
    /// One line: what the parameter means.
    pub doc: StrRef,
    /// What host tools may rely on the parameter for (ABI 6).
    pub role: ParamRole,
}

/// What a parameter means to host tools: the bench renders every method of a suite at the
/// scene's [`ParamRole::PathDepth`] and asks the reference for [`ParamRole::Layers`], whatever
/// the integrator names them.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamRole {
    /// No role: only the plugin reads it.
    None = 0,
    /// An integer: the deepest lighting layer N rendered (paths of virtual length ≤ N + 1).
    PathDepth = 1,
    /// An integer: the cap on physical scattering events of a path.
    MaxRayDepth = 2,
    /// A boolean: write the lighting layers `layer0..=layerN` beside the image.
    Layers = 3,
}

/// One parameter value an instance resolved (after defaults), which the host writes into the
/// output's metadata (ABI 6). Owned by the instance, valid until `destroy`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ResolvedParam {
    /// The config key.
    pub name: StrRef,
    /// The value as TOML would write it (`8`, `0.95`, `"sobol"`, `true`).
    pub value: StrRef,
}

/// The values an instance resolved, written by the SDK's glue after `create` (ABI 6).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ResolvedList {
    /// `count` entries owned by the instance (null when `count` is 0).
    pub entries: *const ResolvedParam,
    /// Number of entries.
    pub count: usize,
}

impl ResolvedList {
    /// No values.
    pub const EMPTY: ResolvedList = ResolvedList {
        entries: std::ptr::null(),
        count: 0,
    };
}

/// One parameter value from the config, already checked against the plugin's [`ParamSpec`]s.
///
/// A value of kind [`ParamKind::MutationList`] (ABI 7) is never the config's: the host adds
/// it, under the list's name, when the config gave no list and the host created the list
/// the integrator's spec declares as its default (`int`: the number of entries), so that the
/// integrator can tell the declared defaults from a list a user wrote.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct ParamValue {
    /// The config key.
    pub name: StrRef,
    /// Which of the value fields holds the value (`Int` also for an integer given to a
    /// float parameter).
    pub kind: ParamKind,
    /// The value of an `Int`.
    pub int: i64,
    /// The value of a `Float`.
    pub float: f64,
    /// The value of a `Bool`: 1 for true, 0 for false.
    pub boolean: u32,
    /// The value of a `String` (host-owned, valid for the `create` call).
    pub string: StrRef,
}

/// Read-only view of the scene a plugin may use for shading and light sampling. Valid for
/// the lifetime of the plugin instance it was given to.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct SceneView {
    /// The camera, with the image size it renders.
    pub camera: Camera,
    /// The materials, `material_count` of them (a hit's `material` indexes them).
    pub materials: *const Material,
    /// Number of materials.
    pub material_count: usize,
    /// The textures the materials sample, `texture_count` of them.
    pub textures: *const Texture,
    /// Number of textures.
    pub texture_count: usize,
    /// The emissive triangles' emitters, `emitter_count` of them.
    pub emitters: *const Emitter,
    /// Number of emitters.
    pub emitter_count: usize,
    /// `KHR_lights_punctual` lights.
    pub punctual_lights: *const PunctualLight,
    /// Number of punctual lights.
    pub punctual_count: usize,
    /// The environment (kind `None` when the config has none).
    pub environment: Environment,
    /// CDF over the power of all lights: emitters, punctual lights, then the environment when
    /// present (`emitter_count + punctual_count + 0 or 1` entries).
    pub light_power_cdf: *const f32,
    /// Lower corner of the scene's bounding box (world space).
    pub bounds_min: Vec3,
    /// Upper corner of the scene's bounding box (world space).
    pub bounds_max: Vec3,
    /// The vertex and triangle buffers (ABI 4), for surface data built plugin-side from
    /// [`CompactHit`]s.
    pub mesh: MeshTables,
}

/// The scene's vertex and triangle buffers as the host stores them
/// (`flowlight_core::mesh::MeshView` is the plugin's safe view). `positions` has
/// `vertex_count` entries; each optional per-vertex array (`normals`, `uvs`, `uvs1`,
/// `colors`, `tangents`) has its own count, `vertex_count` or 0 when no primitive has the
/// attribute (its pointer may then be dangling or null); the three per-triangle arrays have
/// `triangle_count` entries each.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct MeshTables {
    /// Vertex positions, `vertex_count` entries.
    pub positions: *const Vec3,
    /// Number of vertices.
    pub vertex_count: usize,
    /// Per-vertex shading normals, `normals_count` entries.
    pub normals: *const Vec3,
    /// `vertex_count` or 0.
    pub normals_count: usize,
    /// Per-vertex TEXCOORD_0, `uvs_count` entries.
    pub uvs: *const glam::Vec2,
    /// `vertex_count` or 0.
    pub uvs_count: usize,
    /// Per-vertex TEXCOORD_1, `uvs1_count` entries.
    pub uvs1: *const glam::Vec2,
    /// `vertex_count` or 0.
    pub uvs1_count: usize,
    /// Per-vertex COLOR_0 (RGBA), `colors_count` entries.
    pub colors: *const [f32; 4],
    /// `vertex_count` or 0.
    pub colors_count: usize,
    /// Per-vertex tangents (xyz and handedness w), `tangents_count` entries.
    pub tangents: *const [f32; 4],
    /// `vertex_count` or 0.
    pub tangents_count: usize,
    /// Vertex indices of each triangle.
    pub triangles: *const [u32; 3],
    /// Material index of each triangle.
    pub triangle_material: *const u32,
    /// Emitter rank of each triangle (read only where its material is emissive).
    pub triangle_emitter: *const i32,
    /// Number of triangles.
    pub triangle_count: usize,
    /// Sorted by `first_virtual`; 0 entries: one identity instance of all triangles.
    pub instances: *const MeshInstance,
    /// Number of instances.
    pub instance_count: usize,
}

impl MeshTables {
    /// No geometry (a scene view built by hand for tests of the shading code).
    pub const EMPTY: MeshTables = MeshTables {
        positions: std::ptr::null(),
        vertex_count: 0,
        normals: std::ptr::null(),
        normals_count: 0,
        uvs: std::ptr::null(),
        uvs_count: 0,
        uvs1: std::ptr::null(),
        uvs1_count: 0,
        colors: std::ptr::null(),
        colors_count: 0,
        tangents: std::ptr::null(),
        tangents_count: 0,
        triangles: std::ptr::null(),
        triangle_material: std::ptr::null(),
        triangle_emitter: std::ptr::null(),
        triangle_count: 0,
        instances: std::ptr::null(),
        instance_count: 0,
    };
}

/// Flags of a batched closest-hit query.
pub mod batch {
    /// The rays are coherent (camera rays of a tile, in raster order): the host may answer
    /// them with packet traversal (Embree's `rtcIntersect4/8/16`).
    pub const COHERENT: u32 = 1;
}

/// Result of one closest-hit query.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct HitRecord {
    /// 1 when `surface` is valid.
    pub hit: u32,
    /// The hit's surface data when `hit` is 1.
    pub surface: SurfaceHit,
}

/// Ray queries the host answers. `ctx` is the host's per-work-unit context.
///
/// Single-ray calls return the full [`SurfaceHit`] (what ERPT and the mutations use); the
/// batch calls (ABI 4) take `n` rays and return one [`CompactHit`] or flag per ray, so one
/// indirect call is paid per batch and the plugin builds only the surface data it shades
/// (`flowlight_core::mesh::MeshView::surface_hit` over [`SceneView::mesh`]). A batch's
/// answers are exactly the single-ray answers of its rays.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct TracerTable {
    /// The host's context for the calls below.
    pub ctx: *mut c_void,
    /// Writes the closest hit of `ray` into `hit` (`hit.hit = 0` when it escapes).
    pub intersect: unsafe extern "C" fn(ctx: *mut c_void, ray: *const Ray, hit: *mut HitRecord),
    /// 1 when `ray` is blocked before its `t_max`, else 0.
    pub occluded: unsafe extern "C" fn(ctx: *mut c_void, ray: *const Ray) -> u8,
    /// Closest hits of `rays[0..n]` into `hits[0..n]` ([`CompactHit::MISS`] for an escape);
    /// `flags` is a set of [`batch`] bits.
    pub intersect_batch: unsafe extern "C" fn(
        ctx: *mut c_void,
        rays: *const Ray,
        n: usize,
        flags: u32,
        hits: *mut CompactHit,
    ),
    /// `blocked[i]` = 1 when `rays[i]` is blocked before its `t_max`, else 0.
    pub occluded_batch:
        unsafe extern "C" fn(ctx: *mut c_void, rays: *const Ray, n: usize, blocked: *mut u8),
    /// 1 when the render's time budget has run out or Ctrl-C was pressed and this unit may
    /// be abandoned (ABI 6): the host then discards everything the unit deposited, so the
    /// plugin may return at once. 0 otherwise, always 0 where the host could not discard the
    /// unit's deposits.
    pub should_stop: unsafe extern "C" fn(ctx: *mut c_void) -> u8,
}

/// One contribution to the image: radiance `value` (already divided by its sample density)
/// at raster position (`x`, `y`), recorded in lighting `layer` as well as the main image.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Deposit {
    /// Raster x of the deposit (pixels, 0 at the left edge).
    pub x: f32,
    /// Raster y of the deposit (pixels, 0 at the top edge).
    pub y: f32,
    /// Lighting layer (its path depth), besides the main image.
    pub layer: u32,
    /// The radiance deposited.
    pub value: Rgb,
}

/// An accumulator the host owns: a plugin hands it deposits in batches.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct FilmTable {
    /// The accumulator's context for `deposit`.
    pub ctx: *mut c_void,
    /// Accumulates `deposits[0..n]`.
    pub deposit: unsafe extern "C" fn(ctx: *mut c_void, deposits: *const Deposit, n: usize),
}

/// How an integrator's deposits must be accumulated (thesis §5.9).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccumulationStyle {
    /// Every deposit of a work unit lands inside its tile: the host gives each unit a private
    /// tile buffer and merges it when the unit ends (path tracing).
    Tile = 0,
    /// Deposits may land within `flange` pixels around the tile (flanged tiles, ERPT); the
    /// host keeps deposits beyond the flange too, so any deposit on the film counts.
    FlangedTile = 1,
}

/// How the host merges a statistics counter over work units.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StatMerge {
    /// Values and units are added.
    Sum = 0,
    /// The largest value is kept.
    Max = 1,
    /// Not accumulated: the host reports `counter[numerator] / counter[denominator]`.
    Ratio = 2,
}

/// How the host shows a counter in the render summary (the `.stats.json` has every counter,
/// unformatted). Declared with the counter ([`crate::stats::StatsBuilder::sum_as`]), so the
/// CLI need not guess from its name (ABI 6).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StatDisplay {
    /// A number: an integer as is, else with 4 decimals.
    Number = 0,
    /// Seconds (summed over threads): 3 decimals and `s`.
    Seconds = 1,
    /// A share in [0, 1], printed as a percentage with 2 decimals.
    Percent = 2,
    /// Only in the `.stats.json`, not in the summary (details such as streak totals).
    Hidden = 3,
}

/// A statistics counter an integrator declared through [`crate::stats::StatsBuilder`]. The
/// host gives each work unit a zeroed array of `f64`, one per counter, merges the arrays with
/// [`StatMerge::combine`] and reports them (summary and JSON).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StatSpec {
    /// The counter's name as reported.
    pub name: StrRef,
    /// How it is merged.
    pub merge: StatMerge,
    /// For [`StatMerge::Ratio`]: indices of the counters divided.
    pub numerator: u32,
    /// See `numerator`.
    pub denominator: u32,
    /// How the summary shows it (ABI 6).
    pub display: StatDisplay,
}

/// What an integrator instance tells the host after creation.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct IntegratorInfo {
    /// Number of extra per-depth lighting layers (0 = main image only).
    pub layer_count: u32,
    /// How the deposits are accumulated.
    pub accumulation: AccumulationStyle,
    /// Flange width in pixels for [`AccumulationStyle::FlangedTile`].
    pub flange: u32,
    /// 1 when the estimator is biased (e.g. ERPT's consecutive sample filter); written to the
    /// output metadata.
    pub biased: u32,
}

/// The counters an integrator instance declared, written by the SDK's glue after `create`:
/// `count` specs owned by the instance (valid until `destroy`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct StatList {
    /// The specs, `count` of them (null for none).
    pub specs: *const StatSpec,
    /// Number of specs.
    pub count: usize,
}

impl StatList {
    /// No counters.
    pub const EMPTY: StatList = StatList {
        specs: std::ptr::null(),
        count: 0,
    };
}

impl IntegratorInfo {
    /// Info for an integrator with no layers, tile accumulation and no statistics.
    pub const fn simple() -> IntegratorInfo {
        IntegratorInfo {
            layer_count: 0,
            accumulation: AccumulationStyle::Tile,
            flange: 0,
            biased: 0,
        }
    }
}

/// A mutation plugin instance handed to an integrator: the host created it from a
/// `[[integrator.mutations]]` entry and keeps it alive longer than the integrator.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct MutationRef {
    /// The plugin's name.
    pub name: StrRef,
    /// Selection weight: the config's, validated and normalised by the host so that the
    /// weights of a list are finite, ≥ 0 and sum to 1.
    pub weight: f64,
    /// The plugin's function table.
    pub table: *const MutationTable,
    /// The instance `table.create` made.
    pub instance: *const c_void,
    /// Where the mutation's counters start among the counters the host appends after the
    /// integrator's own (ABI 6): its slots in a unit are `integrator count + stat_offset ..
    /// + stat_count` of the array `render` receives.
    pub stat_offset: u32,
    /// Number of counters the mutation declared.
    pub stat_count: u32,
}

/// A coarse piece of work: `sample_count` samples per pixel for the pixels of a tile.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorkUnit {
    /// Left edge of the tile (first pixel column).
    pub x0: u32,
    /// Top edge of the tile (first pixel row).
    pub y0: u32,
    /// Right edge of the tile (one past its last column).
    pub x1: u32,
    /// Bottom edge of the tile (one past its last row).
    pub y1: u32,
    /// Index of the first sample of each pixel in this unit (samples of a pixel are numbered
    /// 0, 1, … across the whole render).
    pub sample_begin: u32,
    /// Samples per pixel in this unit.
    pub sample_count: u32,
    /// Render seed; combine with pixel and sample indices for per-sample generators.
    pub seed: u64,
}

/// Function table of an integrator plugin.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct IntegratorTable {
    /// Creates an instance from the checked parameters, the mutation strategies, and the scene
    /// view (valid for the instance's life); writes the instance, its info and its counter
    /// list.
    pub create: unsafe extern "C" fn(
        params: *const ParamValue,
        param_count: usize,
        mutations: *const MutationRef,
        mutation_count: usize,
        scene: *const SceneView,
        instance: *mut *mut c_void,
        info: *mut IntegratorInfo,
        stats: *mut StatList,
        resolved: *mut ResolvedList,
        err: *mut ErrorBuf,
    ) -> Status,
    /// Frees an instance made by `create` (null is ignored).
    pub destroy: unsafe extern "C" fn(instance: *mut c_void),
    /// Called once before the first unit, on one thread, with ray queries available
    /// (e.g. ERPT's whole-image deposition quantum pre-pass, or its `auto` pilot). Writes the
    /// instance's resolved parameters again into `resolved` (ABI 7): `create`'s, with the
    /// values the instance decided while preparing; the list `create` wrote is then stale.
    pub prepare: unsafe extern "C" fn(
        instance: *mut c_void,
        tracer: *const TracerTable,
        resolved: *mut ResolvedList,
        err: *mut ErrorBuf,
    ) -> Status,
    /// Renders one unit. Called concurrently from the host's threads with the same instance.
    /// `stats` points to `stat_count` zeroed counters for this unit, one per spec of the
    /// instance's [`StatList`] (null when it declared none).
    pub render: unsafe extern "C" fn(
        instance: *const c_void,
        unit: *const WorkUnit,
        tracer: *const TracerTable,
        film: *const FilmTable,
        stats: *mut f64,
        stat_count: usize,
        err: *mut ErrorBuf,
    ) -> Status,
}

/// What a mutation proposed, as it crosses the boundary ([`crate::Proposal`] is the Rust
/// side: [`ProposalRecord::from`] and [`crate::Proposal::from`] convert).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProposalRecord {
    /// 1 when a proposal of the same path length and weak type was built; 0 for a domain
    /// miss (the chain stays where it is and deposits there).
    pub valid: u32,
    /// Tentative transition density ratio T(y→x) / T(x→y) (thesis §5.4); 0 for a miss.
    pub transition_ratio: f32,
}

/// Function table of a mutation plugin.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct MutationTable {
    /// Creates an instance from the checked parameters and the scene view (valid for the
    /// instance's life); writes the instance and its counter list.
    pub create: unsafe extern "C" fn(
        params: *const ParamValue,
        param_count: usize,
        scene: *const SceneView,
        instance: *mut *mut c_void,
        stats: *mut StatList,
        resolved: *mut ResolvedList,
        err: *mut ErrorBuf,
    ) -> Status,
    /// Frees an instance made by `create` (null is ignored).
    pub destroy: unsafe extern "C" fn(instance: *mut c_void),
    /// Proposes `proposal` from `current`. Called concurrently with the same instance.
    /// `stats` points to `stat_count` counters of the current work unit, one per spec of the
    /// instance's [`StatList`] (ABI 6; null when it declared none).
    pub propose: unsafe extern "C" fn(
        instance: *const c_void,
        tracer: *const TracerTable,
        rng: *mut Rng,
        current: *const Path,
        proposal: *mut Path,
        out: *mut ProposalRecord,
        stats: *mut f64,
        stat_count: usize,
        err: *mut ErrorBuf,
    ) -> Status,
    /// Transition density T(from → to) of this strategy (0 when it cannot propose `to`).
    /// Mixtures of strategies need it for the mixture density Σ p(sᵢ)·T^{sᵢ} (thesis §5.4).
    pub density: unsafe extern "C" fn(
        instance: *const c_void,
        from: *const Path,
        to: *const Path,
        out: *mut f64,
        err: *mut ErrorBuf,
    ) -> Status,
}

/// The one declaration a plugin exports. `abi_version` and `layout_hash` come first and keep
/// their place in every ABI version, so a host can read them from any plugin.
#[repr(C)]
pub struct PluginDeclaration {
    /// [`ABI_VERSION`] of the SDK the plugin was built with (first field in every version).
    pub abi_version: u32,
    /// What the plugin implements.
    pub kind: PluginKind,
    /// [`layout_hash`] of the SDK the plugin was built with (second field in every version).
    pub layout_hash: u64,
    /// [`SDK_VERSION`] of the SDK the plugin was built with.
    pub sdk_version: StrRef,
    /// [`RUSTC_VERSION`] of the compiler that built the plugin.
    pub rustc_version: StrRef,
    /// The plugin's name (what configs write).
    pub name: StrRef,
    /// One line for `flowlight plugins`.
    pub description: StrRef,
    /// The parameters it accepts, `param_count` of them.
    pub params: *const ParamSpec,
    /// Number of parameters.
    pub param_count: usize,
    /// Non-null for [`PluginKind::Integrator`].
    pub integrator: *const IntegratorTable,
    /// Non-null for [`PluginKind::Mutation`].
    pub mutation: *const MutationTable,
}

// SAFETY: a declaration is immutable static data.
unsafe impl Sync for PluginDeclaration {}

/// Fingerprint of the size and alignment of every type that crosses the boundary. Host and
/// plugin compute it from their own copy of the SDK; any difference refuses the plugin.
pub const fn layout_hash() -> u64 {
    use std::mem::{align_of, size_of};
    let sizes = [
        size_of::<StrRef>(),
        size_of::<ErrorBuf>(),
        size_of::<ParamSpec>(),
        size_of::<ParamValue>(),
        size_of::<SceneView>(),
        size_of::<Camera>(),
        size_of::<Material>(),
        size_of::<Texture>(),
        size_of::<TextureRef>(),
        size_of::<Emitter>(),
        size_of::<PunctualLight>(),
        size_of::<Environment>(),
        size_of::<Ray>(),
        size_of::<SurfaceHit>(),
        size_of::<HitRecord>(),
        size_of::<CompactHit>(),
        size_of::<MeshTables>(),
        size_of::<MeshInstance>(),
        size_of::<TracerTable>(),
        size_of::<Deposit>(),
        size_of::<FilmTable>(),
        size_of::<IntegratorInfo>(),
        size_of::<StatSpec>(),
        size_of::<StatList>(),
        size_of::<ResolvedParam>(),
        size_of::<ResolvedList>(),
        size_of::<MutationRef>(),
        size_of::<WorkUnit>(),
        size_of::<IntegratorTable>(),
        size_of::<ProposalRecord>(),
        size_of::<MutationTable>(),
        size_of::<PathVertex>(),
        size_of::<Path>(),
        size_of::<Rng>(),
        size_of::<PluginDeclaration>(),
        align_of::<SceneView>(),
        align_of::<Environment>(),
        align_of::<Path>(),
        align_of::<ErrorBuf>(),
        align_of::<MeshInstance>(),
        align_of::<WorkUnit>(),
    ];
    // FNV-1a over the sizes, seeded with the ABI version.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325 ^ ABI_VERSION as u64;
    let mut i = 0;
    while i < sizes.len() {
        h ^= sizes[i] as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn str_ref_round_trips_and_tolerates_empty_null_and_bad_utf8() {
        let s = String::from("drill#2 ✓");
        let r = StrRef::new(&s);
        assert_eq!(r.len, s.len());
        // SAFETY: `s` outlives the read.
        assert_eq!(unsafe { r.as_str() }, "drill#2 ✓");
        // SAFETY: null and empty references read as "".
        assert_eq!(unsafe { StrRef::EMPTY.as_str() }, "");
        assert_eq!(unsafe { StrRef::new("").as_str() }, "");
        let bad = [0x66, 0xff, 0x6f];
        let r = StrRef {
            ptr: bad.as_ptr(),
            len: bad.len(),
        };
        // SAFETY: `bad` outlives the read; invalid UTF-8 is reported, not trusted.
        assert_eq!(unsafe { r.as_str() }, "<invalid utf-8>");
    }

    #[test]
    fn error_buf_truncates_at_a_char_boundary() {
        let mut e = ErrorBuf::default();
        e.set("short");
        assert_eq!(e.message(), "short");
        // 1023 ASCII bytes then a 3-byte character: it does not fit whole and is dropped.
        let long = format!("{}✓tail", "a".repeat(1023));
        e.set(&long);
        assert_eq!(e.len, 1023);
        assert_eq!(e.message(), "a".repeat(1023));
    }
}
