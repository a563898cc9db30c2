//! Parameters of the path samplers, each declared once ([`flowlight_sdk::declare`]): the
//! declarations below are MCPT's `PARAMS` entries (ERPT reuses the seed sampler's), and
//! [`PathSettings::from_params`] reads them, so a default or range is written nowhere else.

use flowlight_core::bsdf::NARROW_GLOSSY_ALPHA;
use flowlight_core::termination::{TerminationDistribution, TerminationSchedule};
use flowlight_sdk::declare::{BoolParam, ChoiceParam, FloatParam, IntParam};
use flowlight_sdk::{bool_param, choice_param, float_param, int_param, ParamRole, Params};

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

/// The largest `branches` ([`BRANCHES`]'s declared maximum).
pub const MAX_BRANCHES: u32 = BRANCHES.range().1 as u32;

/// MCPT's default `branches` for entangled paths ([`BRANCHES`]'s declared default): the
/// most efficient of 1, 2 and 4 on the benchmark suite (`scenes/experiments/suite-branches.toml`).
pub const DEFAULT_BRANCHES: u32 = BRANCHES.default() as u32;

/// `variant`: the estimator of MCPT's paths (ERPT's seeds choose theirs with `seeds`).
pub const VARIANT: ChoiceParam = choice_param!(
    "variant",
    "entangled",
    ["untangled", "entangled"],
    "\"entangled\": a light connection at every vertex and BSDF sampling, combined by MIS; \"untangled\": one light connection per path (ERPT's seed sampler)"
);

/// `termination`: the termination distribution (thesis §3.8) or the throughput roulette.
pub const TERMINATION: ChoiceParam = choice_param!(
    "termination",
    "throughput",
    ["bxdf", "equi", "expo", "throughput"],
    "termination distribution (thesis §3.8): \"bxdf\" (T = 1 - albedo, clamped to >= 0.05), \"equi\" (T_k = 1/(N-k+1)), \"expo\" (layer shares double with depth), \"throughput\" (roulette with survival min(max(beta)·eta²·albedo, rr_max_survival) from lighting vertex rr_depth on; untangled: T = 1 - min(albedo, rr_max_survival) at every vertex)"
);

/// `path_depth`: the deepest lighting layer N.
pub const PATH_DEPTH: IntParam = int_param!(
    "path_depth",
    8,
    1..=32,
    "path-space depth N: the deepest lighting layer (paths of virtual length <= N + 1); a chain of mirrors seen from the camera does not use it up"
)
.role(ParamRole::PathDepth);

/// `max_ray_depth` of MCPT: the cap on physical bounces (ERPT declares its own, capped by
/// the stored path's length).
pub const MAX_RAY_DEPTH: IntParam = int_param!(
    "max_ray_depth",
    64,
    1..=1024,
    "maximal physical ray depth, every bounce counted (mirrors and glass included); at least path_depth"
)
.role(ParamRole::MaxRayDepth);

/// `rr_depth`: where the entangled roulette may start.
pub const RR_DEPTH: IntParam = int_param!(
    "rr_depth",
    5,
    1..=1024,
    "termination = \"throughput\", entangled: first lighting vertex where the roulette may stop a path (above path_depth: no roulette)"
);

/// `rr_max_survival`: the roulette's cap on the survival probability.
pub const RR_MAX_SURVIVAL: FloatParam = float_param!(
    "rr_max_survival",
    0.95,
    0.01 <= x <= 0.999,
    "termination = \"throughput\": cap on the survival probability (below 1, so that an untangled path connects at every depth with probability >= 1 - cap)"
);

/// `narrow_glossy_alpha` (MCPT only; ERPT's mutations classify vertices with
/// [`NARROW_GLOSSY_ALPHA`], and its seeds must agree with them).
pub const NARROW_GLOSSY_ALPHA_PARAM: FloatParam = float_param!(
    "narrow_glossy_alpha",
    0.05,
    0.0 <= x <= 1.0,
    "untangled only: a glossy lobe with GGX alpha below it is treated as specular, with no light connection there (0: connect at every non-Dirac vertex)"
);

/// `layers`: write the lighting layers (MCPT and the bidirectional plugins).
pub const LAYERS: BoolParam = bool_param!(
    "layers",
    false,
    "also write lighting layers layer0..layerN as EXR layers (layer k = paths of virtual length k + 1); they sum to the image"
)
.role(ParamRole::Layers);

/// `branches` (MCPT only): splitting at the first lighting vertex.
pub const BRANCHES: IntParam = int_param!(
    "branches",
    4,
    1..=64,
    "entangled only: a camera path goes on as this many branches from its first lighting vertex, each with 1/k of the weight and its own light connection and BSDF sample (1: no split; untangled: 1, the only value allowed)"
);

/// MCPT's `branches` parameter for paths of `variant`: [`DEFAULT_BRANCHES`] for entangled
/// ones, 1 (no split) for untangled ones, which refuse any other value. Only MCPT declares
/// it: ERPT's seeds and its path-traced part stay single paths
/// ([`PathSettings::from_params`] sets 1).
pub fn branches_from_params(p: &Params, variant: Variant) -> Result<u32, String> {
    let branches = match variant {
        Variant::Entangled => BRANCHES.get(p)?,
        Variant::Untangled => BRANCHES.get_or(p, 1)?,
    };
    if branches > 1 && variant == Variant::Untangled {
        return Err(format!(
            "parameter 'branches' = {branches} needs variant = \"entangled\" (an untangled path has one light connection; it is not split)"
        ));
    }
    Ok(branches as u32)
}

impl PathSettings {
    /// MCPT's settings: [`VARIANT`], [`NARROW_GLOSSY_ALPHA_PARAM`] and those of
    /// [`PathSettings::shared_from_params`] with [`MAX_RAY_DEPTH`]; 1 branch
    /// ([`branches_from_params`] reads MCPT's `branches`). With no values: the defaults.
    pub fn from_params(p: &Params) -> Result<Self, String> {
        let variant = variant_from_params(p)?;
        let mut settings = PathSettings::shared_from_params(p, variant, &MAX_RAY_DEPTH)?;
        settings.narrow_glossy_alpha = NARROW_GLOSSY_ALPHA_PARAM.get(p)? as f32;
        Ok(settings)
    }

    /// The settings every path-sampling plugin shares: `termination`, `rr_depth`,
    /// `rr_max_survival`, `path_depth` and `max_ray_depth` (the plugin's own declaration of
    /// it, e.g. [`MAX_RAY_DEPTH`]; at least `path_depth`), for paths of `variant`, with
    /// [`NARROW_GLOSSY_ALPHA`] and 1 branch. Reads only those five parameters, so a plugin
    /// reports only what it declares.
    pub fn shared_from_params(
        p: &Params,
        variant: Variant,
        max_ray_depth: &IntParam,
    ) -> Result<Self, String> {
        let termination =
            TerminationDistribution::parse(TERMINATION.get(p)?).expect("declared choice");
        let rr_depth = RR_DEPTH.get(p)?;
        let rr_max_survival = RR_MAX_SURVIVAL.get(p)?;
        let path_depth = PATH_DEPTH.get(p)?;
        let depth_cap = max_ray_depth.get(p)?;
        if depth_cap < path_depth {
            return Err(format!(
                "parameter '{}' must be at least path_depth ({path_depth}), got {depth_cap}",
                max_ray_depth.name()
            ));
        }
        Ok(PathSettings {
            variant,
            branches: 1,
            narrow_glossy_alpha: NARROW_GLOSSY_ALPHA,
            path_depth: path_depth as u32,
            max_ray_depth: depth_cap as u32,
            termination: TerminationSchedule::new(termination, path_depth as u32)
                .with_roulette(rr_depth as u32, rr_max_survival as f32),
        })
    }
}

/// [`VARIANT`] as a [`Variant`].
pub fn variant_from_params(p: &Params) -> Result<Variant, String> {
    Ok(match VARIANT.get(p)? {
        "untangled" => Variant::Untangled,
        _ => Variant::Entangled,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use flowlight_core::termination::{DEFAULT_MAX_SURVIVAL, DEFAULT_RR_DEPTH};
    use flowlight_sdk::abi::{ParamValue, StrRef};
    use flowlight_sdk::ParamKind;

    fn int(name: &'static str, v: i64) -> ParamValue {
        ParamValue {
            name: StrRef::new(name),
            kind: ParamKind::Int,
            int: v,
            float: 0.0,
            boolean: 0,
            string: StrRef::EMPTY,
        }
    }

    #[test]
    fn declared_defaults_are_the_renderers_constants() {
        assert_eq!(RR_DEPTH.default(), DEFAULT_RR_DEPTH as i64);
        assert_eq!(
            RR_MAX_SURVIVAL.default().map(|x| x as f32),
            Some(DEFAULT_MAX_SURVIVAL)
        );
        assert_eq!(
            NARROW_GLOSSY_ALPHA_PARAM.default().map(|x| x as f32),
            Some(NARROW_GLOSSY_ALPHA)
        );
        let s = PathSettings::from_params(&Params::from_slice(&[])).unwrap();
        assert_eq!((s.path_depth, s.max_ray_depth, s.branches), (8, 64, 1));
        assert_eq!(s.variant, Variant::Entangled);
        assert_eq!(s.narrow_glossy_alpha, NARROW_GLOSSY_ALPHA);
    }

    #[test]
    fn out_of_range_and_inconsistent_values_are_refused() {
        let v = [int("path_depth", 40)];
        let e = PathSettings::from_params(&Params::from_slice(&v));
        assert_eq!(
            e.unwrap_err(),
            "parameter 'path_depth' must be in 1..=32, got 40"
        );
        let v = [int("path_depth", 10), int("max_ray_depth", 9)];
        let e = PathSettings::from_params(&Params::from_slice(&v));
        assert_eq!(
            e.unwrap_err(),
            "parameter 'max_ray_depth' must be at least path_depth (10), got 9"
        );
        let v = [int("branches", 2)];
        assert!(branches_from_params(&Params::from_slice(&v), Variant::Untangled).is_err());
        assert_eq!(
            branches_from_params(&Params::from_slice(&[]), Variant::Untangled),
            Ok(1)
        );
        assert_eq!(
            branches_from_params(&Params::from_slice(&[]), Variant::Entangled),
            Ok(4)
        );
        let v = [int("branches", 65)];
        assert_eq!(
            branches_from_params(&Params::from_slice(&v), Variant::Entangled),
            Err("parameter 'branches' must be in 1..=64, got 65".into())
        );
    }
}
