//! Parameters of the path samplers.

use flowlight_core::bsdf::NARROW_GLOSSY_ALPHA;
use flowlight_core::termination::{
    TerminationDistribution, TerminationSchedule, DEFAULT_MAX_SURVIVAL, DEFAULT_RR_DEPTH,
};
use flowlight_sdk::{param, ParamKind, Params};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    Untangled,
    Entangled,
}

/// Depth limits and the termination distribution.
#[derive(Clone, Debug)]
pub struct PathSettings {
    pub variant: Variant,
    /// Path-space depth N: deepest lighting layer (paths of virtual length ≤ N + 1).
    pub path_depth: u32,
    /// Maximal ray-trace depth: cap on physical scattering events, mirrors included.
    pub max_ray_depth: u32,
    pub termination: TerminationSchedule,
    /// GGX α below which the untangled sampler treats a glossy lobe as Λα (no light
    /// connection there; light is found only by hitting it). MCPT's `narrow_glossy_alpha`.
    pub narrow_glossy_alpha: f32,
    /// Entangled only: a camera path goes on as this many branches from its first lighting
    /// vertex (MCPT's `branches`, [`branches_from_params`]; 1 = no split, what
    /// [`PathSettings::from_params`] sets). See [`crate::entangled::trace_wavefront`].
    pub branches: u32,
}

/// The largest `branches`.
pub const MAX_BRANCHES: u32 = 64;

/// MCPT's default `branches` for entangled paths: the most efficient of 1, 2 and 4 on the
/// benchmark suite (`scenes/suite-branches.toml`; docs/performance.md, "Sixteenth session").
pub const DEFAULT_BRANCHES: u32 = 4;

/// MCPT's `branches` parameter for paths of `variant`: [`DEFAULT_BRANCHES`] for entangled
/// ones, 1 (no split) for untangled ones, which refuse any other value. Only MCPT declares
/// it: ERPT's seeds and its path-traced part stay single paths
/// ([`PathSettings::from_params`] sets 1).
pub fn branches_from_params(p: &Params, variant: Variant) -> Result<u32, String> {
    let default = match variant {
        Variant::Entangled => DEFAULT_BRANCHES,
        Variant::Untangled => 1,
    };
    let branches = p.int("branches", default as i64)?;
    if !(1..=MAX_BRANCHES as i64).contains(&branches) {
        return Err(format!(
            "parameter 'branches' must be in 1..={MAX_BRANCHES}, got {branches}"
        ));
    }
    if branches > 1 && variant == Variant::Untangled {
        return Err(format!(
            "parameter 'branches' = {branches} needs variant = \"entangled\" (an untangled path has one light connection; it is not split)"
        ));
    }
    Ok(branches as u32)
}

/// Parameters every path-sampling plugin accepts (user documentation in each plugin header).
pub const PATH_PARAMS: [flowlight_sdk::abi::ParamSpec; 6] = [
    param("variant", ParamKind::String, "\"entangled\"", "\"untangled\" (one light connection per path) or \"entangled\" (NEE + MIS at every vertex)"),
    param("termination", ParamKind::String, "\"throughput\"", "termination distribution: \"bxdf\", \"equi\", \"expo\" (thesis §3.8) or \"throughput\" (roulette on the path throughput)"),
    param("path_depth", ParamKind::Int, "8", "path-space depth N: deepest lighting layer rendered (1..=32)"),
    param("max_ray_depth", ParamKind::Int, "64", "maximal physical ray depth, mirror and glass bounces included (>= path_depth)"),
    param("rr_depth", ParamKind::Int, "5", "termination = \"throughput\", entangled: first lighting vertex where the roulette may stop a path (1..=1024)"),
    param("rr_max_survival", ParamKind::Float, "0.95", "termination = \"throughput\": cap on the survival probability min(max(beta)*albedo, cap) (untangled: min(albedo, cap)), in [0.01, 0.999]"),
];

impl PathSettings {
    pub fn from_params(p: &Params) -> Result<Self, String> {
        let variant = match p.choice("variant", "entangled", &["untangled", "entangled"])? {
            "untangled" => Variant::Untangled,
            _ => Variant::Entangled,
        };
        let termination = TerminationDistribution::parse(p.choice(
            "termination",
            "throughput",
            &["bxdf", "equi", "expo", "throughput"],
        )?)
        .expect("validated choice");
        let rr_depth = p.int("rr_depth", DEFAULT_RR_DEPTH as i64)?;
        if !(1..=1024).contains(&rr_depth) {
            return Err(format!(
                "parameter 'rr_depth' must be in 1..=1024, got {rr_depth}"
            ));
        }
        let rr_max_survival = p.float("rr_max_survival", DEFAULT_MAX_SURVIVAL as f64)?;
        if !(0.01..=0.999).contains(&rr_max_survival) {
            return Err(format!(
                "parameter 'rr_max_survival' must be in [0.01, 0.999], got {rr_max_survival}"
            ));
        }
        let path_depth = p.int("path_depth", 8)?;
        if !(1..=32).contains(&path_depth) {
            return Err(format!(
                "parameter 'path_depth' must be in 1..=32, got {path_depth}"
            ));
        }
        let max_ray_depth = p.int("max_ray_depth", 64)?;
        if max_ray_depth < path_depth || max_ray_depth > 1024 {
            return Err(format!(
                "parameter 'max_ray_depth' must be in path_depth..=1024 ({path_depth}..=1024), got {max_ray_depth}"
            ));
        }
        // Only MCPT declares this parameter: ERPT's mutations classify vertices with the
        // default, and its seeds must agree with them.
        let narrow_glossy_alpha = p.float("narrow_glossy_alpha", NARROW_GLOSSY_ALPHA as f64)?;
        if !(0.0..=1.0).contains(&narrow_glossy_alpha) {
            return Err(format!(
                "parameter 'narrow_glossy_alpha' must be in [0, 1], got {narrow_glossy_alpha}"
            ));
        }
        Ok(PathSettings {
            variant,
            branches: 1,
            narrow_glossy_alpha: narrow_glossy_alpha as f32,
            path_depth: path_depth as u32,
            max_ray_depth: max_ray_depth as u32,
            termination: TerminationSchedule::new(termination, path_depth as u32)
                .with_roulette(rr_depth as u32, rr_max_survival as f32),
        })
    }
}
