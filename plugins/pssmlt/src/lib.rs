//! # `pssmlt` — primary-sample-space Metropolis light transport
//!
//! Kelemen, Szirmay-Kalos, Antal and Csonka 2002: Markov chains over the uniform numbers a
//! sampler turns into a path, with large steps (a fresh independent sample) and small steps
//! (every number moved by a normal offset of size `sigma`, pbrt-v4's kernel), the scalar
//! target being the luminance of the sample's estimate. A bootstrap of independent samples
//! gives the normalisation b = ∫ f; chains start from bootstrap samples resampled ∝ f (no
//! start-up bias) and splat the expected value of every mutation (proposal with weight
//! a·b/f(y), current state with (1 − a)·b/f(x)). The library is
//! `flowlight_pathtrace::pss`; docs/pssmlt.md has the formulas.
//!
//! Each mutation also counts its large-step proposal as an independent sample, weighed
//! against the chain by the balance heuristic (Kelemen's combination, `combine_large_steps`;
//! `flowlight_pathtrace::pss::large_steps`), with an estimate of b drawn apart from the
//! bootstrap so that the weights do not bias the image.
//!
//! `spp` keeps MCPT's meaning: a work unit of P pixels × n samples runs P·n mutations, W·H·spp
//! in all, as pieces of its tile's chains of `chain_length` mutations, which run on across the
//! tile's units (parked between them); each chain's numbers depend only on (render seed,
//! tile, its first mutation), so the image does not depend on the thread count. The work
//! units of a render that find no bootstrap for its seed build it together, in pieces
//! (`pss::bootstrap`), and the image is the same bits whatever the thread count.
//!
//! Parameters (`[integrator]` table): `sampler` (the sampler the chains run over: `"mcpt"`,
//! entangled path tracing, or `"bdpt"`, one bidirectional sample with every (s, t) strategy
//! weighed by `heuristic`, each splatted at its own raster position), `large_step`
//! (probability of a large step), `sigma` (the small step's standard deviation per number),
//! `chain_length` (mutations per chain; 0: one chain per unit), `combine_large_steps`,
//! `bootstrap` (independent samples of the normalisation), and the path tracer's `path_depth`, `max_ray_depth`, `termination`,
//! `rr_depth`, `rr_max_survival` and `layers`. The generated table is in docs/pssmlt.md
//! ("Parameters"); `flowlight plugins --markdown` prints it.
//!
//! A sample whose contributions are not all finite and non-negative counts as f = 0: never a
//! chain state, never deposited, counted (`invalid samples`).

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_pathtrace::bidir::params::HEURISTIC;
use flowlight_pathtrace::bidir::sample::{strategy_only_settings, FilmPlan, FilmSampler};
use flowlight_pathtrace::bidir::Heuristic;
use flowlight_pathtrace::pss::bdpt::BdptTarget;
use flowlight_pathtrace::pss::bootstrap::{assemble_part, evaluate, Piece};
use flowlight_pathtrace::pss::params::{
    mutation_from_params, CHAIN_LENGTH, COMBINE_LARGE_STEPS, LARGE_STEP, SIGMA,
};
use flowlight_pathtrace::pss::{
    render_unit_in_chains, BootstrapCell, BootstrapPlan, ChainBuffers, ChainCounts, McptTarget,
    Mutation, PssCounters, PssTarget, Splat, TileChains,
};
use flowlight_pathtrace::{settings, PathSettings, Variant};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::{ChoiceParam, IntParam};
use flowlight_sdk::{
    choice_param, export_integrator, int_param, AccumulationStyle, Film, Integrator,
    IntegratorInfo, MutationSet, Params, Scene, Stats, StatsBuilder, Tracer, WorkUnit,
};
use std::cell::RefCell;

/// `sampler`: what the chains' primary samples are turned into.
const SAMPLER: ChoiceParam = choice_param!(
    "sampler",
    "mcpt",
    ["mcpt", "bdpt"],
    "the sampler the chains run over: \"mcpt\", one entangled path-tracing camera sample (next-event estimation and BSDF sampling by MIS) whose first pair of numbers is its position on the film; \"bdpt\", one light and one camera subpath (two streams) with every (s, t) strategy weighed by heuristic, each splatted at its own raster position"
);

/// `bootstrap`: independent samples of the normalisation (pbrt-v4's default).
const BOOTSTRAP: IntParam = int_param!(
    "bootstrap",
    100000,
    1..=10_000_000,
    "independent samples that estimate the normalisation b (the image's mean luminance integral) and that the chains start from, resampled by luminance; run once per render, shared out over the work units that wait for it (8 bytes each)"
);

const PARAMS: [ParamSpec; 13] = [
    SAMPLER.spec(),
    LARGE_STEP.spec(),
    SIGMA.spec(),
    CHAIN_LENGTH.spec(),
    COMBINE_LARGE_STEPS.spec(),
    BOOTSTRAP.spec(),
    settings::TERMINATION.spec(),
    settings::PATH_DEPTH.spec(),
    settings::MAX_RAY_DEPTH.spec(),
    settings::RR_DEPTH.spec(),
    settings::RR_MAX_SURVIVAL.spec(),
    settings::LAYERS.spec(),
    HEURISTIC.spec(),
];

/// The sampler the chains run over.
enum Sampler {
    Mcpt,
    /// BDPT with the plugin's path settings and layers.
    Bdpt(Box<FilmPlan>),
}

pub struct Pssmlt {
    scene: Scene<'static>,
    sampler: Sampler,
    settings: PathSettings,
    layers: bool,
    mutation: Mutation,
    chain_length: u64,
    chains: TileChains,
    /// The pieces of the bootstrap's vectors (and, with `combine_large_steps`, of the scale
    /// estimate's), the same for every render seed.
    bootstrap_pieces: Vec<Piece>,
    bootstrap: BootstrapCell,
    counters: PssCounters,
}

thread_local! {
    /// A thread's chain buffers, reused by its units.
    static BUFFERS: RefCell<ChainBuffers> = RefCell::new(ChainBuffers::default());
}

impl Integrator for Pssmlt {
    const NAME: &'static str = "pssmlt";
    const DESCRIPTION: &'static str = "Primary-sample-space Metropolis light transport (Kelemen et al. 2002) over path tracing, with expected-value splatting";
    const PARAMS: &'static [ParamSpec] = &PARAMS;

    /// Deposits land anywhere on the film (flanged tiles without a flange: every deposit
    /// kept, the film normalised by the samples per pixel).
    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let sampler = SAMPLER.get(params)?;
        let settings =
            PathSettings::shared_from_params(params, Variant::Entangled, &settings::MAX_RAY_DEPTH)?;
        let layers = settings::LAYERS.get(params)?;
        let sampler = match sampler {
            "bdpt" => {
                let heuristic = Heuristic::parse(HEURISTIC.get(params)?).expect("declared choice");
                let mut bidir = strategy_only_settings(heuristic);
                bidir.path = settings.clone();
                bidir.lighting_layers = layers;
                Sampler::Bdpt(Box::new(FilmPlan::new(&scene, bidir, 0)))
            }
            _ => Sampler::Mcpt,
        };
        let mutation = mutation_from_params(params)?;
        let bootstrap_count = BOOTSTRAP.get(params)? as u32;
        let combine_large_steps = COMBINE_LARGE_STEPS.get(params)?;
        // With `combine_large_steps`, c from vectors apart from the bootstrap's
        // (pss::large_steps: unbiased).
        let bootstrap_pieces = BootstrapPlan::new(1, bootstrap_count, combine_large_steps).pieces();
        let chain_length = CHAIN_LENGTH.get(params)? as u64;
        let info = IntegratorInfo {
            layer_count: if layers { settings.path_depth + 1 } else { 0 },
            accumulation: AccumulationStyle::FlangedTile,
            flange: 0,
            biased: 0,
        };
        let counters = PssCounters::declare(stats);
        let integrator = Pssmlt {
            scene,
            sampler,
            settings,
            layers,
            mutation,
            chain_length,
            chains: TileChains::default(),
            bootstrap_pieces,
            bootstrap: BootstrapCell::default(),
            counters,
        };
        Ok((integrator, info))
    }

    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        stats: &mut Stats,
    ) -> Result<(), String> {
        match &self.sampler {
            Sampler::Mcpt => {
                let mut target = McptTarget::new(&self.scene, tracer, &self.settings, self.layers);
                self.render_target(&mut target, unit, film, stats);
            }
            Sampler::Bdpt(plan) => {
                let sampler = FilmSampler::new(&self.scene, tracer, plan);
                self.render_target(&mut BdptTarget::new(&sampler), unit, film, stats);
            }
        }
        Ok(())
    }
}

impl Pssmlt {
    /// Runs `unit`'s chains over `target`, the bootstrap first if this render has none yet.
    fn render_target<T: PssTarget>(
        &self,
        target: &mut T,
        unit: &WorkUnit,
        film: &mut Film,
        stats: &mut Stats,
    ) {
        // Every unit that finds no bootstrap for this seed evaluates pieces of it.
        let pieces = &self.bootstrap_pieces;
        let streams = target.streams();
        let (bootstrap, assembled) = self.bootstrap.get_or_build(
            unit.seed,
            pieces.len(),
            |k| {
                let p = &pieces[k];
                evaluate(target, unit.seed, p.scale, p.vectors.clone(), self.mutation)
            },
            |evaluated| assemble_part(pieces, &evaluated, 0, unit.seed, self.mutation, streams),
        );
        let mut counts = ChainCounts::default();
        let mut deposit = |s: Splat| film.deposit(s.raster.x, s.raster.y, s.layer, s.value);
        BUFFERS.with_borrow_mut(|buffers| {
            render_unit_in_chains(
                target,
                &bootstrap,
                unit,
                self.chain_length,
                &self.chains,
                buffers,
                &mut counts,
                &mut deposit,
            )
        });
        self.counters.report(stats, &counts, &*bootstrap, assembled);
    }
}

export_integrator!(Pssmlt);
