//! # `mcpt` — Monte Carlo path tracing
//!
//! Unidirectional path tracing in the two variants of the thesis (§3.7):
//!
//! * `variant = "entangled"` (default): next-event estimation at every vertex, combined with
//!   BSDF sampling by multiple importance sampling (power heuristic). The better stand-alone
//!   estimator.
//! * `variant = "untangled"`: exactly one light connection per path, chosen by the
//!   termination distribution at a Λβ vertex; emitters are found by hitting them only after a
//!   specular (Λα) vertex. This is ERPT's seed sampler.
//!
//! Parameters (`[integrator]` table of the render config): each is declared once, in
//! `flowlight_pathtrace::settings` and below; the table generated from the declarations is in
//! docs/mcpt.md ("Parameters"), and `flowlight plugins --markdown` prints it.
//!
//! Each pixel sample's numbers depend only on (seed, pixel, sample index) — a PCG32 stream
//! seeded from them, or the sample's Sobol' points — so an image does not depend on the
//! number of threads or on how the samples are split into work units. A sample whose contributions are not all
//! finite and non-negative is handed to the host as one invalid deposit, which the host counts
//! and discards.

// A plugin writes no `unsafe`: the SDK's glue holds the raw side of the boundary.
#![forbid(unsafe_code)]

use flowlight_core::rng::Rng;
use flowlight_core::sobol::SobolSampler;
use flowlight_pathtrace::sampler::{sample_start, PixelSampler, SamplerKind, SAMPLER};
use flowlight_pathtrace::walk::units;
use flowlight_pathtrace::{
    entangled, settings, untangled, PathSettings, SampleContributions, Variant,
};
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::IntParam;
use flowlight_sdk::{
    export_integrator, int_param, Film, Integrator, IntegratorInfo, MutationSet, Params, Scene,
    Stats, StatsBuilder, Tracer, WorkUnit,
};

pub struct Mcpt {
    scene: Scene<'static>,
    settings: PathSettings,
    /// Paths per wavefront; 0 = path at a time.
    wavefront: usize,
    sampler: SamplerKind,
    /// Lighting layers are written: each contribution keeps its layer.
    layers: bool,
}

/// `wavefront`: paths traced together as ray batches. The default is large enough that a
/// batch amortises the host call, small enough that the batch's rays and states stay in cache.
const WAVEFRONT: IntParam = int_param!(
    "wavefront",
    256,
    0..=65536,
    "entangled only: paths traced together, as batches of camera, extension and shadow rays handed to the host in one call each; 0 traces one path at a time. The image is the same bit for bit either way"
);

const PARAMS: [ParamSpec; 11] = [
    settings::VARIANT.spec(),
    settings::TERMINATION.spec(),
    settings::PATH_DEPTH.spec(),
    settings::MAX_RAY_DEPTH.spec(),
    settings::RR_DEPTH.spec(),
    settings::RR_MAX_SURVIVAL.spec(),
    settings::LAYERS.spec(),
    settings::NARROW_GLOSSY_ALPHA_PARAM.spec(),
    WAVEFRONT.spec(),
    settings::BRANCHES.spec(),
    SAMPLER.spec(),
];

impl Integrator for Mcpt {
    const NAME: &'static str = "mcpt";
    const DESCRIPTION: &'static str = "Monte Carlo path tracing, untangled or entangled (NEE + MIS), with depth-based termination";
    const PARAMS: &'static [ParamSpec] = &PARAMS;

    fn create(
        params: &Params,
        _mutations: MutationSet<'static>,
        scene: Scene<'static>,
        _stats: &mut StatsBuilder,
    ) -> Result<(Self, IntegratorInfo), String> {
        let mut settings = PathSettings::from_params(params)?;
        settings.branches = settings::branches_from_params(params, settings.variant)?;
        let layers = settings::LAYERS.get(params)?;
        let sampler = SamplerKind::from_params(
            params,
            settings.variant == Variant::Entangled,
            "variant = \"entangled\"",
        )?;
        let wavefront = WAVEFRONT.get(params)?;
        let info = IntegratorInfo {
            layer_count: if layers { settings.path_depth + 1 } else { 0 },
            ..IntegratorInfo::simple()
        };
        Ok((
            Mcpt {
                scene,
                settings,
                wavefront: wavefront as usize,
                sampler,
                layers,
            },
            info,
        ))
    }

    fn render(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
        _stats: &mut Stats,
    ) -> Result<(), String> {
        match self.sampler {
            SamplerKind::Independent => self.render_with::<Rng>(unit, tracer, film),
            SamplerKind::Sobol => self.render_with::<SobolSampler>(unit, tracer, film),
        }
    }
}

impl Mcpt {
    fn render_with<S: PixelSampler>(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
    ) -> Result<(), String> {
        if self.settings.variant == Variant::Entangled && self.wavefront > 0 {
            return self.render_wavefront::<S>(unit, tracer, film);
        }
        let mut contributions = SampleContributions::default();
        for y in unit.y0..unit.y1 {
            for x in unit.x0..unit.x1 {
                for s in unit.sample_begin..unit.sample_begin + unit.sample_count {
                    let (mut rng, raster) = sample_start::<S>(unit.seed, x, y, s);
                    contributions.clear();
                    match self.settings.variant {
                        Variant::Entangled => entangled::trace(
                            &self.scene,
                            tracer,
                            &self.settings,
                            &rng,
                            raster,
                            &mut contributions,
                        ),
                        Variant::Untangled => {
                            let sample = untangled::trace(
                                &self.scene,
                                tracer,
                                &self.settings,
                                &mut rng,
                                raster,
                                None,
                            );
                            contributions.add(sample.layer, sample.value);
                        }
                    }
                    contributions.deposit(film, x, y, self.layers);
                }
            }
        }
        Ok(())
    }

    /// Entangled MCPT over a unit as wavefronts of `wavefront` paths, in the unit's
    /// (row, pixel, sample) order; each wave's contributions are deposited in that order
    /// afterwards, so the film sees exactly the deposits of a path-at-a-time loop.
    fn render_wavefront<S: PixelSampler>(
        &self,
        unit: &WorkUnit,
        tracer: &Tracer,
        film: &mut Film,
    ) -> Result<(), String> {
        let mut wf = entangled::Wavefront::<S>::default();
        let mut out = vec![SampleContributions::default(); self.wavefront];
        let samples = unit.sample_begin..unit.sample_begin + unit.sample_count;
        let pixels = units::unit_pixels(unit);
        units::for_each_wave::<S>(
            unit.seed,
            pixels,
            samples,
            self.wavefront,
            |starts, keys| {
                let out = &mut out[..starts.len()];
                entangled::trace_wavefront(
                    &self.scene,
                    tracer,
                    &self.settings,
                    starts,
                    &mut wf,
                    out,
                );
                for (key, c) in keys.iter().zip(out.iter()) {
                    c.deposit(film, key.x, key.y, self.layers);
                }
            },
        );
        Ok(())
    }
}

export_integrator!(Mcpt);
