//! The film-wide bidirectional samples (`flowlight_pathtrace::bidir::sample`) on the Cornell
//! box (Lambertian, so a path's depth d = s + t − 2 is its lighting layer):
//!
//! - **One strategy per sample equals BDPT per depth.** The mean of
//!   [`FilmSampler::strategy_sample`] at depth d (strategy chosen uniformly, value × (d + 2))
//!   equals the mean of the full BDPT sample's deposits in lighting layer d, over the film and
//!   per quadrant: a z-test of the two independent means with both sides' noise.
//! - **The weights of a depth's strategies sum to one.** Per strategy (s, t), the mean of its
//!   weighted contribution F_{s,t} = E[w_{s,t} f / p_{s,t}] is measured under the balance
//!   and the power heuristic. Σ_s F_{s,t} is the depth's image whatever the weights are only
//!   if they sum to one on every path; the per-strategy parts themselves differ between the
//!   heuristics (checked, so that the test compares different weights). A weight off by a
//!   factor on some strategy moves one of the sums, and the z-test against BDPT's layer
//!   catches it.

mod loaded;

use flowlight_core::rng::Rng;
use flowlight_core::Rgb;
use flowlight_host::intersector::UnitTracer;
use flowlight_pathtrace::bidir::params::settings_from_params;
use flowlight_pathtrace::bidir::sample::{FilmPlan, FilmSampler, SampleScratch};
use flowlight_pathtrace::bidir::{BidirSettings, Techniques};
use flowlight_sdk::abi::{ParamValue, StrRef};
use flowlight_sdk::{ParamKind, Params, Scene, Tracer};
use glam::Vec2;
use loaded::{load, LoadedScene};

const CORNELL: &str = "scenes/cornell-box/cornell-box.toml";
/// Deepest depth checked.
const DEPTH: u32 = 3;
/// Samples per estimate.
const SAMPLES: u64 = 60_000;
/// |z| bound: 5 σ, about 6e-7 per check for a correct sampler (a few dozen checks here).
const Z_MAX: f64 = 5.0;

/// The bdpt settings with `path_depth` = [`DEPTH`], lighting layers and `heuristic`.
fn settings(heuristic: &'static str) -> BidirSettings {
    let int = |name: &'static str, v: i64| ParamValue {
        name: StrRef::new(name),
        kind: ParamKind::Int,
        int: v,
        float: 0.0,
        boolean: 0,
        string: StrRef::EMPTY,
    };
    let params = [
        int("path_depth", i64::from(DEPTH)),
        ParamValue {
            kind: ParamKind::Bool,
            boolean: 1,
            ..int("layers", 0)
        },
        ParamValue {
            kind: ParamKind::String,
            string: StrRef::new(heuristic),
            ..int("heuristic", 0)
        },
    ];
    settings_from_params(&Params::from_slice(&params), Techniques::BDPT, false).unwrap()
}

/// Regions an estimate is measured over: the whole film, then its four quadrants.
const REGIONS: usize = 5;

/// Running sums of per-sample region luminances: Σx and Σx² per region.
#[derive(Clone, Default)]
struct Moments {
    sum: [f64; REGIONS],
    sum2: [f64; REGIONS],
    n: u64,
}

impl Moments {
    fn add(&mut self, x: &[f64; REGIONS]) {
        for ((sum, sum2), x) in self.sum.iter_mut().zip(&mut self.sum2).zip(x) {
            *sum += x;
            *sum2 += x * x;
        }
        self.n += 1;
    }

    fn mean(&self, r: usize) -> f64 {
        self.sum[r] / self.n as f64
    }

    /// The variance of the mean of region `r`.
    fn variance_of_mean(&self, r: usize) -> f64 {
        let n = self.n as f64;
        let m = self.mean(r);
        (self.sum2[r] / n - m * m).max(0.0) / (n - 1.0)
    }
}

/// Adds `value`'s luminance landing at `raster` to the regions of a film of size `film`.
fn add_to_regions(x: &mut [f64; REGIONS], film: Vec2, raster: Vec2, value: Rgb) {
    let l = f64::from(value.luminance());
    x[0] += l;
    let q = usize::from(raster.x >= film.x * 0.5) + 2 * usize::from(raster.y >= film.y * 0.5);
    x[1 + q] += l;
}

/// z of the difference of two independent means in region `r`.
fn z(a: &Moments, b: &Moments, r: usize) -> f64 {
    let var = a.variance_of_mean(r) + b.variance_of_mean(r);
    (a.mean(r) - b.mean(r)) / var.sqrt().max(1e-12)
}

/// Runs `f` with a sampler of the Cornell box under `heuristic`.
fn with_sampler<R>(
    loaded: &LoadedScene,
    heuristic: &'static str,
    f: impl FnOnce(&FilmSampler, Vec2) -> R,
) -> R {
    // SAFETY: `loaded` owns what the view points into and outlives `scene`.
    let scene = unsafe { Scene::from_view(&loaded.view) };
    let mut unit_tracer = UnitTracer::new(&loaded.scene, loaded.intersector.as_ref());
    let table = unit_tracer.table();
    let tracer = Tracer::new(&table);
    let settings = settings(heuristic);
    let film = Vec2::new(scene.camera.width as f32, scene.camera.height as f32);
    let plan = FilmPlan::new(&scene, settings, DEPTH);
    let sampler = FilmSampler::new(&scene, &tracer, &plan);
    f(&sampler, film)
}

/// Per lighting layer 0 ..= DEPTH, the moments of the full BDPT sample's deposits.
fn bdpt_layers(sampler: &FilmSampler, film: Vec2, seed: u64) -> Vec<Moments> {
    let mut scratch = SampleScratch::default();
    let mut layers = vec![Moments::default(); DEPTH as usize + 1];
    for i in 0..SAMPLES {
        let mut x = [[0.0; REGIONS]; DEPTH as usize + 1];
        let (camera, light) = (Rng::new(seed ^ i, 0), Rng::new(seed ^ i, 2));
        sampler.bdpt_sample(
            camera,
            light,
            &mut scratch,
            &mut |r: Vec2, l: u32, v: Rgb| {
                add_to_regions(&mut x[l as usize], film, r, v);
            },
        );
        for (m, x) in layers.iter_mut().zip(&x) {
            m.add(x);
        }
    }
    layers
}

/// The moments of strategy samples at `depth`, the strategy chosen by `choose` from a
/// uniform number; values divided by `divide`.
fn strategy_moments(
    sampler: &FilmSampler,
    film: Vec2,
    depth: u32,
    seed: u64,
    choose: impl Fn(f32) -> f32,
    divide: f32,
) -> Moments {
    let mut scratch = SampleScratch::default();
    let mut m = Moments::default();
    for i in 0..SAMPLES {
        let mut x = [0.0; REGIONS];
        let mut choice = Rng::new(seed ^ i, 4);
        let u = choose(choice.uniform());
        let (camera, light) = (Rng::new(seed ^ i, 0), Rng::new(seed ^ i, 2));
        if let Some(s) = sampler.strategy_sample(depth, u, camera, light, &mut scratch) {
            add_to_regions(&mut x, film, s.raster, s.value * (1.0 / divide));
        }
        m.add(&x);
    }
    m
}

#[test]
fn one_strategy_per_sample_averages_to_bdpt_per_depth() {
    let loaded = load(CORNELL);
    with_sampler(&loaded, "power", |sampler, film| {
        let bdpt = bdpt_layers(sampler, film, 0x5eed);
        for depth in 0..=DEPTH {
            let mmlt =
                strategy_moments(sampler, film, depth, 0xbeef + u64::from(depth), |u| u, 1.0);
            let b = &bdpt[depth as usize];
            assert!(b.mean(0) > 0.0, "depth {depth}: BDPT's layer is black");
            for r in 0..REGIONS {
                let z = z(&mmlt, b, r);
                println!(
                    "depth {depth} region {r}: strategies {:.5e}, bdpt {:.5e}, z {z:.2}",
                    mmlt.mean(r),
                    b.mean(r)
                );
                assert!(z.abs() < Z_MAX, "depth {depth}, region {r}: z = {z:.2}");
            }
        }
    });
}

#[test]
fn the_weights_of_a_depths_strategies_sum_to_one() {
    let loaded = load(CORNELL);
    let bdpt = with_sampler(&loaded, "power", |sampler, film| {
        bdpt_layers(sampler, film, 0xfeed)
    });
    for depth in 1..=DEPTH {
        let n = depth + 2;
        let mut parts = Vec::new();
        for heuristic in ["balance", "power"] {
            let per_strategy: Vec<Moments> = with_sampler(&loaded, heuristic, |sampler, film| {
                (0..n)
                    .map(|s| {
                        let u = (s as f32 + 0.5) / n as f32;
                        let seed = 0xa11 + u64::from(depth) * 100 + u64::from(s);
                        strategy_moments(sampler, film, depth, seed, |_| u, n as f32)
                    })
                    .collect()
            });
            // The sum of independent per-strategy means: its mean and the variance of it.
            let mut total = Moments::default();
            let mut variance = 0.0;
            for m in &per_strategy {
                total.sum[0] += m.mean(0);
                variance += m.variance_of_mean(0);
            }
            total.n = 1;
            let b = &bdpt[depth as usize];
            let z = (total.sum[0] - b.mean(0)) / (variance + b.variance_of_mean(0)).sqrt();
            let means: Vec<f64> = per_strategy.iter().map(|m| m.mean(0)).collect();
            println!(
                "depth {depth} {heuristic}: Σ_s F = {:.5e} (parts {means:?}), bdpt {:.5e}, z {z:.2}",
                total.sum[0],
                b.mean(0)
            );
            assert!(z.abs() < Z_MAX, "depth {depth} {heuristic}: z = {z:.2}");
            parts.push(per_strategy);
        }
        // The two heuristics weigh some strategy differently by many standard errors.
        let differs = (0..n as usize).any(|s| {
            let (a, b) = (&parts[0][s], &parts[1][s]);
            z(a, b, 0).abs() > Z_MAX
        });
        assert!(
            differs,
            "depth {depth}: balance and power weigh every strategy alike"
        );
    }
}
