//! ERPT parameters, each declared once ([`flowlight_sdk::declare`]): [`PARAMS`] and
//! [`ErptSettings::from_params`] are built from the declarations, and so are the table in
//! docs/erpt.md ("Parameters") and `flowlight plugins --markdown`.

use crate::part::Part;
use flowlight_pathtrace::sampler::{SamplerKind, SAMPLER};
use flowlight_pathtrace::settings as path;
use flowlight_pathtrace::{PathSettings, Variant};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::{
    mutation_list_or, BoolParam, ChoiceParam, FloatParam, IntParam, StringParam,
};
use flowlight_sdk::{
    bool_param, choice_param, float_param, int_param, string_param, ParamRole, Params,
};

/// Where the deposition quantum e_d is estimated (thesis Algorithm 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QuantumScope {
    /// From a one-sample-per-pixel pre-pass over the whole image.
    Image,
    /// From each work unit's own seeds: brighter tiles get a larger quantum, so dark tiles keep
    /// their share of chains (§5.9).
    Tile,
}

/// How the acceptance ratio treats several strategies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MixtureRatio {
    /// T = Σ p(sᵢ)·T^{sᵢ}: the mixture density of §5.4 (asks every strategy for its density).
    Mixture,
    /// Only the chosen strategy's own ratio (each kernel is reversible on its own).
    Selected,
}

#[derive(Clone, Debug)]
pub struct ErptSettings {
    pub seeds: PathSettings,
    pub mutations_per_sample: f64,
    pub chain_length: u32,
    pub film_window: u32,
    pub quantum: QuantumScope,
    pub mixture: MixtureRatio,
    pub max_chains_per_seed: u32,
    /// Consecutive-sample filter: 0 = off; else at most this many consecutive deposits of a
    /// chain into one pixel (biased).
    pub max_consecutive: u32,
    /// Seed sampler: untangled (thesis) or entangled paths split into their techniques.
    pub seed_kind: SeedKind,
    /// The part of path space the chains render (the rest by MCPT).
    pub part: Part,
    /// Random numbers of the seed paths (entangled seeds only; chains draw independent ones).
    pub sampler: SamplerKind,
    /// Lighting layers are written.
    pub layers: bool,
    /// `preset = "auto"`: the pilot (`auto.rs`) fixes what the config left out.
    pub auto: Option<crate::auto::Free>,
}

/// Which sampler draws the seeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeedKind {
    /// One light connection per path (thesis §3.6–3.7, ch. 5).
    Untangled,
    /// Every connection, emitter hit and escape of an entangled path, MIS-weighted
    /// (`flowlight_pathtrace::seeds`).
    Entangled,
    /// Every connection strategy (s, t) of a BDPT sample, MIS-weighted
    /// (`flowlight_pathtrace::bidir::strategy_seeds`).
    Bdpt,
}

/// `mutations_per_sample`: M of §5.2.
pub const MUTATIONS_PER_SAMPLE: FloatParam = float_param!(
    "mutations_per_sample",
    8.0,
    0.0 < x,
    "M: expected mutations per camera sample (one untangled path, or one entangled tree and all its seeds), §5.2: e_d = lum(sum of X) / (samples · M)"
);

/// `chain_length`: N, the steps of every chain.
pub const CHAIN_LENGTH: IntParam = int_param!(
    "chain_length",
    16,
    1..=1000000,
    "N: mutations per chain; every chain of a seed has this length"
);

/// `film_window`: K, the side of the film-plane migration window.
pub const FILM_WINDOW: IntParam = int_param!(
    "film_window",
    8,
    0..=4096,
    "K: side of the film-plane migration window around the current position (0: the raster position never moves)"
);

/// `quantum`: where e_d is estimated.
pub const QUANTUM: ChoiceParam = choice_param!(
    "quantum",
    "tile",
    ["tile", "image"],
    "where e_d is estimated: \"tile\" (from each work unit's seeds) or \"image\" (from a one-sample-per-pixel pre-pass)"
);

/// `mixture`: the acceptance ratio with several strategies.
pub const MIXTURE: ChoiceParam = choice_param!(
    "mixture",
    "mixture",
    ["mixture", "selected"],
    "acceptance ratio with several strategies: the \"mixture\" density sum p(s_i)·T^{s_i} (§5.4) or the \"selected\" strategy's own"
);

/// `max_chains_per_seed`: the cap on chains per seed.
pub const MAX_CHAINS_PER_SEED: IntParam = int_param!(
    "max_chains_per_seed",
    1024,
    1..=1000000,
    "cap on chains per seed; a capped seed's chains carry a larger quantum (still unbiased)"
);

/// `max_consecutive`: the consecutive sample filter.
pub const MAX_CONSECUTIVE: IntParam = int_param!(
    "max_consecutive",
    0,
    0..=1000000,
    "consecutive sample filter (BIASED): at most this many consecutive deposits of a chain in one pixel; 0 = off"
);

/// `max_ray_depth` of ERPT: seeds are stored as paths (at most 34 vertices), so a lower
/// default and cap than MCPT's.
pub const MAX_RAY_DEPTH: IntParam = int_param!(
    "max_ray_depth",
    32,
    1..=32,
    "maximal physical ray depth of the seeds, every bounce counted; at least path_depth (seeds are stored as paths of at most 34 vertices)"
)
.role(ParamRole::MaxRayDepth);

/// `layers`: write the lighting layers.
pub const LAYERS: BoolParam = bool_param!(
    "layers",
    false,
    "also write lighting layers layer0..layerN as EXR layers; they sum to the image"
)
.role(ParamRole::Layers);

/// `seeds`: the seed sampler.
pub const SEEDS: ChoiceParam = choice_param!(
    "seeds",
    "untangled",
    ["untangled", "entangled", "bdpt"],
    "seed sampler: \"untangled\" (one light connection per path, the thesis'), \"entangled\" (every connection, emitter hit and escape of an entangled path, MIS-weighted) or \"bdpt\" (every connection strategy (s, t) of a bidirectional sample, MIS-weighted by the power heuristic)"
);

/// `direct`: who renders direct light.
pub const DIRECT: ChoiceParam = choice_param!(
    "direct",
    "erpt",
    ["erpt", "mcpt"],
    "direct lighting (layers 0 and 1: ES*L, ES*[DG]L) by \"erpt\" chains or by \"mcpt\" (seeds deposited as path tracing would)"
);

/// `chains_for`: the part of path space the chains render.
pub const CHAINS_FOR: StringParam = string_param!(
    "chains_for",
    "all",
    "paths the chains render, the rest by MCPT: \"all\", \"caustics\" (E.*[DG].*S.*L) or a Heckbert pattern over E D G S L with . [] [^] * + ? | ()"
);

/// `preset`: who fixes the chains' parameters.
pub const PRESET: ChoiceParam = choice_param!(
    "preset",
    "auto",
    ["auto", "manual"],
    "\"auto\" (the default when the config lists no mutations): a pilot picks the split, seeds, chain budget and mixture weights among the listed (or all installed) strategies for what the config leaves out; \"manual\" (the default with a list): everything as given"
);

/// ERPT's parameters: its own, and the seed sampler's from `flowlight_pathtrace::settings`
/// (with ERPT's [`MAX_RAY_DEPTH`]).
pub const PARAMS: [ParamSpec; 19] = [
    mutation_list_or(
        "mutations",
        crate::auto::CANDIDATES,
        "[[integrator.mutations]]: plugin = \"...\", weight = w (default 1; finite, >= 0, normalised to sum to 1), and that plugin's parameters; without a list every installed strategy is a candidate of preset = \"auto\"",
    ),
    PRESET.spec(),
    MUTATIONS_PER_SAMPLE.spec(),
    CHAIN_LENGTH.spec(),
    FILM_WINDOW.spec(),
    QUANTUM.spec(),
    MIXTURE.spec(),
    MAX_CHAINS_PER_SEED.spec(),
    MAX_CONSECUTIVE.spec(),
    path::TERMINATION.spec(),
    path::RR_MAX_SURVIVAL.spec(),
    path::RR_DEPTH.spec(),
    path::PATH_DEPTH.spec(),
    MAX_RAY_DEPTH.spec(),
    LAYERS.spec(),
    SEEDS.spec(),
    DIRECT.spec(),
    CHAINS_FOR.spec(),
    SAMPLER.spec(),
];

impl ErptSettings {
    /// Reads ERPT's parameters (all but `mutations`, which the host hands over as strategies).
    pub fn from_params(p: &Params) -> Result<Self, String> {
        let auto = crate::auto::Free::from_params(p)?;
        // Under `auto` the split and the seeds default to the pilot's candidates; they are
        // resolved (recorded) by the pilot, which may change the split.
        let auto_default =
            |name: &str, value: &'static str| (auto.is_some() && !p.is_set(name)).then_some(value);
        let seeds_choice = match auto_default(SEEDS.name(), "entangled") {
            Some(v) => v,
            None => SEEDS.get(p)?,
        };
        let seed_kind = match seeds_choice {
            "untangled" => SeedKind::Untangled,
            "bdpt" => SeedKind::Bdpt,
            _ => SeedKind::Entangled,
        };
        // BDPT's subpaths roll the roulette as the `bdpt` plugin's do (the entangled variant).
        let variant = match seed_kind {
            SeedKind::Untangled => Variant::Untangled,
            SeedKind::Entangled | SeedKind::Bdpt => Variant::Entangled,
        };
        let seeds = PathSettings::shared_from_params(p, variant, &MAX_RAY_DEPTH)?;
        let mutations_per_sample = MUTATIONS_PER_SAMPLE.get(p)?;
        let chain_length = CHAIN_LENGTH.get(p)?;
        let film_window = FILM_WINDOW.get(p)?;
        let quantum = match QUANTUM.get(p)? {
            "tile" => QuantumScope::Tile,
            _ => QuantumScope::Image,
        };
        let mixture = match MIXTURE.get(p)? {
            "mixture" => MixtureRatio::Mixture,
            _ => MixtureRatio::Selected,
        };
        let max_chains_per_seed = MAX_CHAINS_PER_SEED.get(p)?;
        let max_consecutive = MAX_CONSECUTIVE.get(p)?;
        // Entangled seeds take the path tracer's stratified samples; untangled seeds (the
        // thesis' sampler) keep independent numbers, as MCPT's untangled variant does.
        let sampler =
            SamplerKind::from_params(p, seed_kind == SeedKind::Entangled, "seeds = \"entangled\"")?;
        let direct_by_mcpt = match auto_default(DIRECT.name(), "mcpt") {
            Some(v) => v,
            None => DIRECT.get(p)?,
        } == "mcpt";
        let chains_for = match auto_default(CHAINS_FOR.name(), "caustics") {
            Some(v) => v,
            None => CHAINS_FOR.get(p)?,
        };
        let part = Part::new(chains_for, direct_by_mcpt)?;
        let layers = LAYERS.get(p)?;
        Ok(ErptSettings {
            sampler,
            seed_kind,
            part,
            seeds,
            mutations_per_sample,
            chain_length: chain_length as u32,
            film_window: film_window as u32,
            quantum,
            mixture,
            max_chains_per_seed: max_chains_per_seed as u32,
            max_consecutive: max_consecutive as u32,
            layers,
            auto,
        })
    }
}
