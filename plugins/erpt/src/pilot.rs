//! The pilot of `preset = "auto"` (the rule and its argument: `auto.rs`): a census of one
//! entangled camera sample per pixel of a grid (per class and lighting layer: seeds, Σ lum X,
//! seconds per camera sample), then each candidate strategy alone on short chains from
//! caustic seeds drawn by energy (acceptance, domain miss, seconds per proposal — thesis
//! §5.5). Nothing it traces is deposited; its random numbers come from [`auto::PILOT_SEED`].

use crate::auto::{self, Census, Norms, PILOT_CHAIN_SEEDS, PILOT_SAMPLES, PILOT_STEPS};
use crate::flow::acceptance;
use crate::gain::{self, effective_deposits};
use crate::part::Part;
use crate::settings::{MixtureRatio, QuantumScope};
use crate::{Erpt, UnitSeeds};
use flowlight_core::path::Path;
use flowlight_core::rng::Rng;
use flowlight_core::termination::{TerminationDistribution, TerminationSchedule};
use flowlight_mcmc::measurement;
use flowlight_mcmc::regenerate::within_depth;
use flowlight_sdk::{Stats, Tracer};
use std::time::Instant;

/// A seed path of the census with its energy lum X.
pub type WeightedSeed = (Box<Path>, f64);

/// The census grid's stride: the smallest with at most [`PILOT_SAMPLES`] pixels.
fn grid_stride(width: u32, height: u32) -> u32 {
    let mut stride = 1;
    while width.div_ceil(stride) * height.div_ceil(stride) > PILOT_SAMPLES {
        stride += 1;
    }
    stride
}

/// Pixels of the census grid: every `stride`-th pixel of every `stride`-th row, the stride
/// the smallest with at most [`PILOT_SAMPLES`] pixels.
fn grid(width: u32, height: u32) -> impl Iterator<Item = (u32, u32)> {
    let stride = grid_stride(width, height);
    (0..height)
        .step_by(stride as usize)
        .flat_map(move |y| (0..width).step_by(stride as usize).map(move |x| (x, y)))
}

impl Erpt {
    /// `preset = "auto"`: the pilot, the rule (`auto::decide`), and its choices applied to
    /// what the config left free; the report kept for the metadata and the counters.
    pub(crate) fn run_auto_pilot(&mut self, tracer: &Tracer) -> Result<(), String> {
        let (Some(free), Some((counters, _))) = (self.settings.auto, self.auto.take()) else {
            return Ok(());
        };
        let n = self.mutations.len();
        let fallback = (
            self.weights.clone(),
            self.settings.mutations_per_sample,
            self.settings.chain_length,
        );
        let by_letters = self.chains_part_empty;
        // The split is the pilot's to choose: it may chain indirect light too.
        let free_split = free.chains_for && free.direct;
        let (mut census, class_seeds, deep_seeds) = if by_letters && !free_split {
            (Census::default(), Vec::new(), Vec::new())
        } else {
            self.pilot_census(tracer, !by_letters)
        };
        // The caustic class first (its chains are the measured win); indirect light when the
        // class has too few seeds to chain.
        let indirect =
            free_split && census.seeds[1] < auto::MIN_CAUSTIC_SEEDS && census.indirect_is_hard();
        let chained = if indirect {
            // Path tracing is far from its mean on indirect light: chains for every path
            // above direct light.
            census.chain_indirect();
            self.settings.part = Part::new("all", true)?;
            self.chains_part_empty = false;
            deep_seeds
        } else {
            class_seeds
        };
        let norms = if census.seeds[1] >= auto::MIN_CAUSTIC_SEEDS {
            self.pilot_norms(tracer, &chained)?
        } else {
            vec![Norms::default(); n]
        };
        let mut plan = auto::decide(&census, &norms, (&fallback.0, fallback.1, fallback.2));
        if plan.chains {
            self.weights = plan.weights.clone();
            if free.mutations_per_sample {
                self.settings.mutations_per_sample = plan.mutations_per_sample;
            }
            if free.chain_length {
                self.settings.chain_length = plan.chain_length;
            }
            if free.max_chains_per_seed {
                self.settings.max_chains_per_seed = auto::MAX_CHAINS_PER_SEED;
            }
            if free.mixture {
                self.settings.mixture = MixtureRatio::Selected;
            }
            if free.termination {
                self.settings.seeds.termination = TerminationSchedule::new(
                    TerminationDistribution::Expo,
                    self.settings.seeds.path_depth,
                );
            }
            if free.quantum {
                // e_d of Algorithm 1 once for the image, from `prepare`'s pre-pass of one
                // camera sample per pixel with the render's termination: the census' 4,096
                // samples (with the config's termination) estimate the class' energy too
                // coarsely for it (glass caustic: 60 spp in 4 s with the census' e_d, 99
                // with the pre-pass', at the same choices).
                self.settings.quantum = QuantumScope::Image;
            }
        } else {
            self.chains_part_empty = true;
        }
        // What the render uses, the config's where it set them.
        plan.mutations_per_sample = self.settings.mutations_per_sample;
        plan.chain_length = self.settings.chain_length;
        let report = auto::Report {
            plan,
            census,
            norms,
            // Set by `prepare`'s pre-pass (`Erpt::prepare`).
            quantum: None,
            mixture: self.settings.mixture,
            film_window: self.settings.film_window,
            plugins: (0..n).map(|i| self.mutations.name(i).to_string()).collect(),
            // Indirect light the rule then left to path tracing is not frozen as chained.
            chains_for: if indirect && !self.chains_part_empty {
                "all"
            } else {
                "caustics"
            },
            by_letters,
            free,
        };
        self.auto = Some((counters, Some(report)));
        Ok(())
    }

    /// The census, the seeds of the chains' part and those of every path above direct light
    /// (layer ≥ 2), with their energies (at most [`PILOT_SAMPLES`] of each): one camera sample
    /// per pixel of the grid per pass, passes until [`auto::MIN_CAUSTIC_SEEDS`] seeds of the
    /// chains' part are found (at most [`auto::PILOT_PASSES`]; one when `want_class` is false:
    /// the scene has no path of the part). Every seed is stored (no split while tracing): the
    /// settings' part is set to everything for the call.
    pub(crate) fn pilot_census(
        &mut self,
        tracer: &Tracer,
        want_class: bool,
    ) -> (Census, Vec<WeightedSeed>, Vec<WeightedSeed>) {
        let saved = std::mem::replace(&mut self.settings.part, Part::new("all", false).unwrap());
        let (w, h) = (self.scene.camera.width, self.scene.camera.height);
        let depth = self.settings.seeds.path_depth as usize;
        let mut census = Census {
            layer_energy: vec![[0.0; 2]; depth + 2],
            ..Census::default()
        };
        let mut seeds = UnitSeeds::default();
        let mut path = Box::new(Path::empty());
        let (mut class_seeds, mut deep_seeds) = (Vec::new(), Vec::new());
        // Pass after pass over the grid (sample index `pass`), until the class has enough
        // seeds to measure or the passes run out: rare caustics are the ones chains are for.
        for pass in 0..auto::PILOT_PASSES {
            if census.seeds[1] >= auto::MIN_CAUSTIC_SEEDS || (pass > 0 && !want_class) {
                break;
            }
            seeds.store.clear();
            seeds.keys.clear();
            let start = Instant::now();
            self.trace_unit(
                tracer,
                auto::PILOT_SEED,
                grid(w, h),
                pass..pass + 1,
                &mut seeds,
                &mut path,
                &mut |_, _, _, _| {},
            );
            census.seconds += start.elapsed().as_secs_f64();
            census.samples += seeds.store.samples;
            census.work += (seeds.store.vertices.len() + seeds.store.seeds.len()) as f64;
            let count = seeds.store.seeds.len();
            // Per grid pixel its camera sample's light per part: the rest and the class,
            // layers ≤ 1 and ≥ 2 (for the variance per part, `gain.rs`).
            let stride = grid_stride(w, h);
            let cols = w.div_ceil(stride) as usize;
            let mut cells = vec![[0.0; 4]; cols * h.div_ceil(stride) as usize];
            for (k, key) in seeds.keys.iter().enumerate() {
                let end = seeds.keys.get(k + 1).map_or(count, |n| n.first);
                let mut indirect = 0.0;
                let mut parts = [0.0; 4];
                for i in key.first..end {
                    let estimate = seeds.store.seeds[i].estimate;
                    let lum = estimate.luminance() as f64;
                    if !(estimate.is_valid_radiance() && lum.is_finite() && lum > 0.0) {
                        continue;
                    }
                    seeds.store.path(i, &mut path);
                    let c = saved.contains(&path) as usize;
                    census.seeds[c] += 1;
                    census.energy[c] += lum;
                    let layer = (path.layer as usize).min(depth + 1);
                    census.layer_energy[layer][c] += lum;
                    let deep = layer >= 2;
                    parts[c] += lum;
                    parts[2 + deep as usize] += lum;
                    if c == 0 && deep {
                        census.indirect_seeds += 1;
                        census.indirect_energy += lum;
                        indirect += lum;
                    }
                    if c == 1 && class_seeds.len() < PILOT_SAMPLES as usize {
                        class_seeds.push((path.clone(), lum));
                    }
                    if deep && deep_seeds.len() < PILOT_SAMPLES as usize {
                        deep_seeds.push((path.clone(), lum));
                    }
                }
                census.indirect_sample_squares += indirect * indirect;
                let cell = (key.y / stride) as usize * cols + (key.x / stride) as usize;
                if let Some(c) = cells.get_mut(cell) {
                    *c = parts;
                }
            }
            let [a, b] = census.moments;
            let [c, d] = census.layer_moments;
            let mut moments = [a, b, c, d];
            gain::add_pass(&mut moments, cols, &cells);
            census.moments = [moments[0], moments[1]];
            census.layer_moments = [moments[2], moments[3]];
        }
        self.settings.part = saved;
        (census, class_seeds, deep_seeds)
    }

    /// The §5.5 norms of each candidate alone on [`PILOT_STEPS`]-step chains from
    /// [`PILOT_CHAIN_SEEDS`] of `caustic` drawn by energy (systematic resampling), with the
    /// candidate's own transition ratio and the caustic class as the domain.
    pub(crate) fn pilot_norms(
        &self,
        tracer: &Tracer,
        caustic: &[WeightedSeed],
    ) -> Result<Vec<Norms>, String> {
        let starts = draw_by_energy(caustic, PILOT_CHAIN_SEEDS);
        let class = &self.settings.part;
        let s = &self.settings.seeds;
        let mut scratch: Vec<f64> = Vec::new();
        let mut stats = Stats::new(&mut scratch);
        let (mut state, mut proposal) = (Box::new(Path::empty()), Box::new(Path::empty()));
        let mut all = Vec::with_capacity(self.mutations.len());
        for m in 0..self.mutations.len() {
            let mut rng = Rng::new(Rng::hash(&[auto::PILOT_SEED, m as u64]), 2);
            let mut n = Norms::default();
            let start = Instant::now();
            let mut pixels = Vec::with_capacity(PILOT_STEPS as usize);
            for &k in &starts {
                *state = *caustic[k].0;
                state.film_window = self.settings.film_window;
                let mut f_y = measurement(&self.scene, &state);
                if !(f_y.is_valid_radiance() && f_y.luminance() > 0.0) {
                    continue;
                }
                pixels.clear();
                for _ in 0..PILOT_STEPS {
                    let p = self.mutations.propose(
                        m,
                        tracer,
                        &mut rng,
                        &state,
                        &mut proposal,
                        &mut stats,
                    )?;
                    n.proposals += 1;
                    n.work += 1.0 + moved_vertices(&state, &proposal, p.is_move()) as f64;
                    let inside = within_depth(
                        proposal.vertex_count,
                        proposal.layer,
                        s.path_depth,
                        s.max_ray_depth,
                    ) && class.contains(&proposal);
                    let ratio = p.transition_ratio().filter(|_| inside);
                    if ratio.is_none() {
                        n.misses += 1;
                    }
                    if let Some(ratio) = ratio {
                        let f_z = measurement(&self.scene, &proposal);
                        let a = acceptance(f_y, f_z, ratio as f64).unwrap_or(0.0);
                        if (rng.uniform() as f64) < a {
                            n.accepted += 1;
                            std::mem::swap(&mut state, &mut proposal);
                            f_y = f_z;
                        }
                    }
                    // The flow deposits once a step, into the pixel of the state.
                    pixels.push((state.raster.x.floor() as i64, state.raster.y.floor() as i64));
                }
                n.chains += 1;
                n.spread_sum += effective_deposits(&mut pixels);
            }
            n.seconds = start.elapsed().as_secs_f64();
            all.push(n);
        }
        Ok(all)
    }
}

/// Vertices a proposal traced: those after the eye whose position differs from the current
/// state's (every one of a longer proposal's extra vertices); for a miss, every vertex of the
/// state after the eye (the proposal's contents are meaningless; a miss is charged a whole
/// path).
fn moved_vertices(state: &Path, proposal: &Path, valid: bool) -> usize {
    let (v, w) = (state.vertices(), proposal.vertices());
    if !valid {
        return v.len().saturating_sub(1);
    }
    (1..w.len())
        .filter(|&i| v.get(i).is_none_or(|x| x.p != w[i].p))
        .count()
}

/// `count` indices of `items` drawn with probability ∝ their energy by systematic
/// resampling (one fixed offset: deterministic, and every item of more than 1/count of the
/// energy is drawn).
fn draw_by_energy(items: &[WeightedSeed], count: usize) -> Vec<usize> {
    let total: f64 = items.iter().map(|(_, e)| e).sum();
    if items.is_empty() || total.is_nan() || total <= 0.0 {
        return Vec::new();
    }
    let step = total / count as f64;
    let (mut acc, mut i, mut out) = (0.0, 0, Vec::with_capacity(count));
    for k in 0..count {
        let target = (k as f64 + 0.5) * step;
        while i + 1 < items.len() && acc + items[i].1 <= target {
            acc += items[i].1;
            i += 1;
        }
        out.push(i);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_holds_at_most_the_pilot_samples_and_covers_the_image() {
        for (w, h) in [(16, 16), (64, 64), (128, 128), (256, 256), (1000, 3)] {
            let pixels: Vec<_> = grid(w, h).collect();
            assert!(pixels.len() as u32 <= PILOT_SAMPLES, "{w}x{h}");
            assert!(pixels.iter().all(|&(x, y)| x < w && y < h));
            if w * h <= PILOT_SAMPLES {
                assert_eq!(pixels.len() as u32, w * h);
            } else {
                assert!(pixels.len() as u32 > PILOT_SAMPLES / 4, "{w}x{h}");
            }
        }
    }

    #[test]
    fn resampling_draws_in_proportion_to_energy() {
        let items: Vec<(Box<Path>, f64)> = [1.0, 3.0, 0.0, 4.0]
            .iter()
            .map(|&e| (Box::new(Path::empty()), e))
            .collect();
        let drawn = draw_by_energy(&items, 8);
        let count = |i| drawn.iter().filter(|&&d| d == i).count();
        assert_eq!([count(0), count(1), count(2), count(3)], [1, 3, 0, 4]);
        assert!(draw_by_energy(&items[2..3], 8).is_empty());
    }
}
