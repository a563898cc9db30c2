//! ERPT parameters.

use crate::part::Part;
use flowlight_pathtrace::sampler::SamplerKind;
use flowlight_pathtrace::{PathSettings, Variant};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::{param, ParamKind, Params};

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
}

/// Which sampler draws the seeds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeedKind {
    /// One light connection per path (thesis §3.6–3.7, ch. 5).
    Untangled,
    /// Every connection, emitter hit and escape of an entangled path, MIS-weighted
    /// (`flowlight_pathtrace::seeds`).
    Entangled,
}

pub const PARAMS: [ParamSpec; 18] = [
    param("mutations", ParamKind::MutationList, "(required)", "[[integrator.mutations]] plugin = \"...\", weight = w, and that plugin's parameters"),
    param("mutations_per_sample", ParamKind::Float, "8", "expected mutations per initial MC sample (M, §5.2): e_d = lum(ΣX_f) / (count · M)"),
    param("chain_length", ParamKind::Int, "16", "mutations per chain (N); every chain of a seed has this length"),
    param("film_window", ParamKind::Int, "8", "side K of the film-plane migration window around the current position (0: fixed raster position)"),
    param("quantum", ParamKind::String, "\"tile\"", "where e_d is estimated: \"tile\" (per work unit) or \"image\" (1 spp pre-pass)"),
    param("mixture", ParamKind::String, "\"mixture\"", "acceptance ratio with several strategies: \"mixture\" density (§5.4) or \"selected\" strategy's own"),
    param("max_chains_per_seed", ParamKind::Int, "1024", "cap on chains per seed; a capped seed's chains carry a larger quantum (unbiased)"),
    param("max_consecutive", ParamKind::Int, "0", "consecutive sample filter (BIASED): at most this many consecutive deposits of a chain in one pixel, 0 = off"),
    param("termination", ParamKind::String, "\"throughput\"", "seed sampler's termination distribution: \"bxdf\", \"equi\", \"expo\" or \"throughput\""),
    param("rr_max_survival", ParamKind::Float, "0.95", "termination = \"throughput\": cap on the seeds' survival probability, in [0.01, 0.999]"),
    param("rr_depth", ParamKind::Int, "5", "termination = \"throughput\", entangled seeds: first lighting vertex where the roulette may stop a seed path (1..=1024)"),
    param("path_depth", ParamKind::Int, "8", "path-space depth N of the seeds (1..=32)"),
    param("max_ray_depth", ParamKind::Int, "32", "maximal physical ray depth of the seeds (path_depth..=32)"),
    param("layers", ParamKind::Bool, "false", "also write lighting layers layer0..layerN"),
    param("seeds", ParamKind::String, "\"untangled\"", "seed sampler: \"untangled\" (one light connection per path, the thesis') or \"entangled\" (every connection and emitter hit of an entangled path, MIS-weighted)"),
    param("direct", ParamKind::String, "\"erpt\"", "direct lighting (layers 0 and 1: ES*L, ES*[DG]L) by \"erpt\" chains or \"mcpt\" (seeds deposited as path tracing would)"),
    param("chains_for", ParamKind::String, "\"all\"", "paths the chains render, the rest by MCPT: \"all\", \"caustics\" (E.*[DG].*S.*L) or a Heckbert pattern over E D G S L with . [] ^ * + ? | ()"),
    param("sampler", ParamKind::String, "\"sobol\"", "entangled seeds only (untangled: \"independent\"): the seed paths' random numbers, \"sobol\" (a pixel's samples stratified together, as MCPT's default) or \"independent\" (PCG32); chains always draw independent numbers"),
];

impl ErptSettings {
    pub fn from_params(p: &Params) -> Result<Self, String> {
        let mut seeds = PathSettings::from_params(p)?;
        seeds.variant = Variant::Untangled;
        // Seeds are stored as paths (at most 34 vertices): a lower default and cap than MCPT.
        let max_ray_depth = p.int("max_ray_depth", 32)?;
        if max_ray_depth < seeds.path_depth as i64 || max_ray_depth > 32 {
            return Err(format!(
                "parameter 'max_ray_depth' must be in path_depth..=32 ({}..=32) for ERPT, got {max_ray_depth}",
                seeds.path_depth
            ));
        }
        seeds.max_ray_depth = max_ray_depth as u32;
        let mutations_per_sample = p.float("mutations_per_sample", 8.0)?;
        if !(mutations_per_sample > 0.0 && mutations_per_sample.is_finite()) {
            return Err(format!(
                "parameter 'mutations_per_sample' must be positive, got {mutations_per_sample}"
            ));
        }
        let chain_length = p.int("chain_length", 16)?;
        if !(1..=1_000_000).contains(&chain_length) {
            return Err(format!(
                "parameter 'chain_length' must be in 1..=1000000, got {chain_length}"
            ));
        }
        let film_window = p.int("film_window", 8)?;
        if !(0..=4096).contains(&film_window) {
            return Err(format!(
                "parameter 'film_window' must be in 0..=4096, got {film_window}"
            ));
        }
        let quantum = match p.choice("quantum", "tile", &["tile", "image"])? {
            "tile" => QuantumScope::Tile,
            _ => QuantumScope::Image,
        };
        let mixture = match p.choice("mixture", "mixture", &["mixture", "selected"])? {
            "mixture" => MixtureRatio::Mixture,
            _ => MixtureRatio::Selected,
        };
        let max_chains_per_seed = p.int("max_chains_per_seed", 1024)?;
        if !(1..=1_000_000).contains(&max_chains_per_seed) {
            return Err(format!(
                "parameter 'max_chains_per_seed' must be in 1..=1000000, got {max_chains_per_seed}"
            ));
        }
        let max_consecutive = p.int("max_consecutive", 0)?;
        if max_consecutive < 0 {
            return Err(format!(
                "parameter 'max_consecutive' must be >= 0, got {max_consecutive}"
            ));
        }
        let seed_kind = match p.choice("seeds", "untangled", &["untangled", "entangled"])? {
            "untangled" => SeedKind::Untangled,
            _ => SeedKind::Entangled,
        };
        if seed_kind == SeedKind::Entangled {
            seeds.variant = Variant::Entangled;
        }
        // Entangled seeds take the path tracer's stratified samples; untangled seeds (the
        // thesis' sampler) keep independent numbers, as MCPT's untangled variant does.
        let sampler =
            SamplerKind::from_params(p, seed_kind == SeedKind::Entangled, "seeds = \"entangled\"")?;
        let direct_by_mcpt = p.choice("direct", "erpt", &["erpt", "mcpt"])? == "mcpt";
        let part = Part::new(p.string("chains_for", "all")?, direct_by_mcpt)?;
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
        })
    }
}
