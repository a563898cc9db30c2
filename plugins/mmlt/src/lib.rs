//! # `mmlt` — multiplexed Metropolis light transport
//!
//! Hachisuka, Kaplanyan and Dachsbacher (2014), as pbrt-v4's `MLTIntegrator` implements it:
//! Markov chains in primary sample space whose target is one bidirectional strategy (s, t)
//! at a time, the strategy chosen by a primary sample that the chain mutates with the rest,
//! so a chain settles on the strategies that sample its paths well. Each chain has a fixed
//! depth d (interior vertices, Dirac ones included; paths of d + 2 vertices). A bootstrap of
//! `bootstrap` independent samples per depth estimates each depth's brightness b_d; a chain
//! picks its depth with probability b_d / Σ b, starts from a bootstrap sample of that depth
//! chosen ∝ its value (no start-up bias), and deposits by expected-value splatting; the
//! film's normalisation is Σ_d b_d. The chain driver is `flowlight_pathtrace::pss`
//! (shared with `pssmlt`), the strategies are `bdpt`'s (`flowlight_pathtrace::bidir`), the
//! per-depth part is `flowlight_pathtrace::pss::mmlt`. A work unit of P pixels × n samples
//! runs P·n mutations, W·H·spp in all, as pieces of its tile's chains of `chain_length`
//! mutations, which run on across the tile's units as `pssmlt`'s do; each chain draws its
//! depth once, when it starts, from numbers spread evenly over the tile's chains. Each
//! depth's chains weigh their deposits against their large steps (Kelemen's combination,
//! `combine_large_steps`) with that depth's estimate of b_d.
//!
//! Parameters (`[integrator]`; table generated in docs/mmlt.md, "Parameters"):
//!
//! * `path_depth` (default 8, 1–32): the deepest depth d, so paths of at most
//!   `path_depth` + 2 vertices; every interior vertex counts, mirrors and glass included.
//! * `large_step` (default 0.3, [0, 1]): probability of a large step (a fresh independent
//!   state) per mutation.
//! * `sigma` (default 0.01, (0, 1]): standard deviation of a small step per primary sample.
//! * `chain_length` (default 4,096; 0: one chain per sample index of a unit, a tile's
//!   pixels long): mutations per chain.
//! * `combine_large_steps` (default true): Kelemen's balance of each depth's chain against
//!   its large steps, with c_d from `bootstrap`/8 further samples of depth d.
//! * `bootstrap` (default 16384, 1–1,000,000): independent samples per depth for b_d and the
//!   chains' start states; computed once per render, in pieces by the work units that wait
//!   for it (8 bytes each).
//! * `heuristic` (`"power"` or `"balance"`): the MIS weights of a depth's strategies.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_pathtrace::bidir::params::HEURISTIC;
use flowlight_pathtrace::bidir::sample::{strategy_only_settings, FilmPlan, FilmSampler};
use flowlight_pathtrace::bidir::Heuristic;
use flowlight_pathtrace::pss::bootstrap::Piece;
use flowlight_pathtrace::pss::mmlt::{
    render_unit_in_chains, DepthBootstrap, MmltBuffers, MmltCounts,
};
use flowlight_pathtrace::pss::params::{
    mutation_from_params, COMBINE_LARGE_STEPS, LARGE_STEP, MMLT_CHAIN_LENGTH, SIGMA,
};
use flowlight_pathtrace::pss::{
    BootstrapCell, BootstrapPlan, Mutation, PssCounters, Splat, TileChains,
};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::IntParam;
use flowlight_sdk::{
    export_integrator, int_param, AccumulationStyle, Film, Integrator, IntegratorInfo, MutationSet,
    ParamRole, Params, Scene, Stats, StatsBuilder, Tracer, WorkUnit,
};
use std::cell::RefCell;

/// `path_depth`: the deepest chain depth.
const PATH_DEPTH: IntParam = int_param!(
    "path_depth",
    8,
    1..=32,
    "deepest depth d of a chain: paths of at most path_depth + 2 vertices, every interior vertex counted (mirrors and glass included)"
)
.role(ParamRole::PathDepth);

/// `bootstrap`: independent samples per depth.
const BOOTSTRAP: IntParam = int_param!(
    "bootstrap",
    16384,
    1..=1_000_000,
    "independent samples per depth that estimate its brightness b_d (chains per depth are proportional to it; the film is normalised by the sum) and from which chains start; run once per render, shared out over the work units that wait for it (8 bytes each)"
);

const PARAMS: [ParamSpec; 7] = [
    PATH_DEPTH.spec(),
    LARGE_STEP.spec(),
    SIGMA.spec(),
    MMLT_CHAIN_LENGTH.spec(),
    COMBINE_LARGE_STEPS.spec(),
    BOOTSTRAP.spec(),
    HEURISTIC.spec(),
];

pub struct Mmlt {
    scene: Scene<'static>,
    /// The strategies' settings up to `depth`, made once.
    plan: FilmPlan,
    mutation: Mutation,
    /// Mutations per chain (0: one chain per sample index of a unit).
    chain_length: u64,
    /// The tiles' chains between their units, with their depths.
    chains: TileChains<u32>,
    /// The per-depth bootstraps' plan and its pieces, the same for every render seed.
    bootstrap_plan: BootstrapPlan,
    bootstrap_pieces: Vec<Piece>,
    /// The per-depth bootstrap of the render seed, built by the work units that need it (it
    /// needs a tracer, which `create` has not).
    bootstrap: BootstrapCell<DepthBootstrap>,
    counters: PssCounters,
}

thread_local! {
    static BUFFERS: RefCell<MmltBuffers> = RefCell::new(MmltBuffers::default());
}

impl Integrator for Mmlt {
    const NAME: &'static str = "mmlt";
    const DESCRIPTION: &'static str = "Multiplexed Metropolis light transport: primary-sample-space chains over the BDPT strategies, one depth per chain (Hachisuka et al. 2014)";
    const PARAMS: &'static [ParamSpec] = &PARAMS;

    /// Deposits land anywhere on the film (flanged tiles without a flange, as `bdpt`).
    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        scene: Scene<'static>,
        stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let depth = PATH_DEPTH.get(params)? as u32;
        let mutation = mutation_from_params(params)?;
        let bootstrap_plan = DepthBootstrap::plan(
            depth,
            BOOTSTRAP.get(params)? as u32,
            COMBINE_LARGE_STEPS.get(params)?,
        );
        let chain_length = MMLT_CHAIN_LENGTH.get(params)? as u64;
        let heuristic = Heuristic::parse(HEURISTIC.get(params)?).expect("declared choice");
        let counters = PssCounters::declare(stats);
        let info = IntegratorInfo {
            layer_count: 0,
            accumulation: AccumulationStyle::FlangedTile,
            flange: 0,
            biased: 0,
        };
        let integrator = Mmlt {
            scene,
            plan: FilmPlan::new(&scene, strategy_only_settings(heuristic), depth),
            mutation,
            chain_length,
            chains: TileChains::default(),
            bootstrap_plan,
            bootstrap_pieces: bootstrap_plan.pieces(),
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
        let sampler = FilmSampler::new(&self.scene, tracer, &self.plan);
        // Every unit that finds no bootstrap for this seed evaluates pieces of it.
        let (plan, pieces) = (self.bootstrap_plan, &self.bootstrap_pieces);
        let (bootstrap, assembled) = self.bootstrap.get_or_build(
            unit.seed,
            pieces.len(),
            |k| DepthBootstrap::evaluate_piece(&sampler, &pieces[k], unit.seed, self.mutation),
            |evaluated| {
                DepthBootstrap::assemble(pieces, &evaluated, plan, unit.seed, self.mutation)
            },
        );
        let bootstrap = &*bootstrap;
        let mut counts = MmltCounts::default();
        BUFFERS.with(|buffers| {
            let buffers = &mut *buffers.borrow_mut();
            let mut deposit = |s: Splat| film.deposit(s.raster.x, s.raster.y, 0, s.value);
            render_unit_in_chains(
                &sampler,
                bootstrap,
                unit,
                self.chain_length,
                &self.chains,
                buffers,
                &mut counts,
                &mut deposit,
            );
        });
        self.counters
            .report(stats, &counts.chains, bootstrap, assembled);
        Ok(())
    }
}

export_integrator!(Mmlt);
