//! `preset = "auto"`: a pilot measures, and a short rule fixes, what ERPT's config leaves out —
//! the split (which path classes get chains), the seeds, the chain budget (M and N) and the
//! mixture weights — from the norms of thesis §5.5 per path class of §5.6.
//!
//! **Candidates.** The strategies listed under `[[integrator.mutations]]`, or, when the config
//! lists none, [`CANDIDATES`]: every mutation plugin the project installs, with its default
//! parameters but the multi-chain perturbation's cone, θ₂ = 0.02 ([`candidate_params`]) (the
//! host creates this declared default list and marks it, so the integrator knows no user
//! chose it; without a list `preset` defaults to `"auto"`, with one to `"manual"`).
//!
//! **Classes.** A seed's Heckbert type (`part.rs`) puts it in the *caustic* class
//! `E.*[DG].*S.*L` (a Dirac vertex between the light and a smooth vertex: the paths path
//! tracing finds only through a lucky BSDF sample, rare and bright) or in the rest; its
//! lighting layer separates direct light (layer ≤ 1), which path tracing with next-event
//! estimation renders with low variance, from indirect light.
//!
//! **The pilot** (`pilot.rs`, in `prepare`, before any unit, counted in the time budget):
//! one entangled camera sample on a pixel grid of at most [`PILOT_SAMPLES`] pixels, pass after
//! pass until [`MIN_CAUSTIC_SEEDS`] caustic seeds are found or [`PILOT_PASSES`] passes ran,
//! gives the census — per class and layer the seeds and their energy Σ lum X, and the rays per camera
//! sample w_c. Then each candidate s runs [`PILOT_STEPS`]-step chains alone (its own
//! transition ratio, target lum f on the caustic class) from [`PILOT_CHAIN_SEEDS`] caustic
//! seeds drawn by energy, as the flow starts chains: per strategy the acceptance strength
//! a_s, the domain-miss strength (part misses included) and the rays per proposal w_s.
//!
//! **Cost in rays, not seconds.** The rule's costs are rays counted from the paths (a ray per
//! vertex traced or moved, and per seed; [`Census::work`], [`Norms::work`]), not wall-clock
//! time: the choices, and so the image, must depend on the render's seed alone, and a clock
//! differs from run to run (two pilots on the glass caustic timed the same strategies 30%
//! apart and gave weights 0.52 and 0.73 to the caustic perturbation). The seconds are
//! measured and reported beside them.
//!
//! **The rule** ([`decide`]):
//!
//! * *Split*: chains for the caustic class above direct light (`chains_for = "caustics"`,
//!   `direct = "mcpt"`) when the census found [`MIN_CAUSTIC_SEEDS`] caustic seeds; else chains
//!   for every path above direct light (`chains_for = "all"`) when path tracing is far from its
//!   mean on indirect light, R = E[X²]/E[X]² of a camera sample's indirect light ≥
//!   [`HARD_INDIRECT`] (1 for a constant; 3.6–6.6 measured on the Cornell box, the narrow gap
//!   and the glass caustic's non-caustic light, 80 on the indirect room, lit through a gap)
//!   and Amdahl's bound G_max = (V_c + V_r) / V_r from the census' relative variance per part
//!   is at least [`gain::MIN_GAIN`] (chains change only the class: veach-mis' indirect light
//!   has R = 24 but G_max = 1.000001 beside its glossy highlights; `gain.rs` says why the
//!   caustic class is not gated by it); else none (path tracing), and none when no candidate
//!   moves a chain out of its seed's pixel. Direct light is always path traced, where
//!   next-event estimation is efficient.
//! * *Seeds*: entangled (each light connection, emitter hit and escape a MIS-weighted seed),
//!   which find caustic seeds by BSDF sampling as path tracing does; with chains, terminated
//!   by the `"expo"` distribution (thesis §3.8: layer shares double with depth), which gives
//!   the chained layers (≥ 2) more of the camera paths (glass caustic, 2 s: 6.35× MCPT with
//!   it, 4.42× with `"throughput"`; every tuned caustic and indirect config uses it but the
//!   ring's, where the two tie).
//! * *Weights*: the strategies within [`WEIGHT_FLOOR`] of the best accepted moves per ray
//!   (a_s / w_s, the useful moves its work buys) are selected and weighted by the pixels their
//!   pilot chains spread a seed's energy over beyond its own, per ray: p_s ∝ (K_s − 1) / w_s
//!   (`gain.rs`; glass caustic: the multi-chain and caustic perturbations tie on accepted
//!   moves per ray, K 10.1 and 4.6, weights 0.70/0.30 as the tuned config's); 0 for the others
//!   and for every strategy that only misses the domain. A mixture's moves per ray,
//!   Σ p a / Σ p w, never exceed its best strategy's, so a clearly worse one only dilutes it;
//!   near-ties are kept, as strategies that move different vertices explore differently
//!   (the ring caustic: the multi-chain perturbation moves the eye side, the caustic
//!   perturbation the light side; at 0.61 of the caustic perturbation's accepted moves per
//!   ray the first was dropped by a floor of 2/3, and the caustic perturbation alone rendered
//!   relMSE 8.5·10⁻² at 4 s, the multi-chain one alone 2.0·10⁻², the two together
//!   1.5·10⁻²). The floor stays because a strategy alone from a seed overstates how it fares
//!   in the mixed flow, most for the large steps (glass caustic: the drill accepted 0.55 of
//!   its pilot steps and 0.19 of its steps in the render, the multi-chain perturbation 0.83
//!   and 0.53); with the film window below, no large step comes within 1/2 of the best on
//!   the caustic scenes (at most 0.41, `lens-spot`'s soft reconnection).
//!   The acceptance ratio is each strategy's own (`mixture = "selected"`: a mixture of kernels
//!   each in detailed balance is in detailed balance, and needs no 2k density calls a step).
//! * *Film window*: K = 2·r₂ ([`film_window`]), r₂ = √(0.05·W·H/π) the largest jump of the
//!   lens and multi-chain perturbations (Veach's, 5% of the image area), which the window
//!   bounds by K/2; at most [`MAX_FILM_WINDOW`]. Fixed in `create`, before the pilot, since
//!   the units' flange (2K) is (mirror chain, 8 s, seeds 1–4: 1.13× MCPT with K = 32 at 128²,
//!   1.02× with the default 8; the window the tuned config uses).
//! * *Chains per seed*: at most [`MAX_CHAINS_PER_SEED`] (16), for the reason its doc gives.
//! * *Chain length*: N = [`STEPS_PER_SEED_GAP`] / ρ, ρ the class' seeds per camera sample,
//!   rounded up to a power of two in [16, 64]: the rarer the class' seeds, the further apart
//!   they land and the further each one's energy must travel.
//! * *Budget*: M = √(c / (1 − c)) · √(w_c / w_m), w_m = Σ p_s w_s the mixture's rays per step
//!   and c the chained class' share of the census' energy, in [1/16, 16]. A class of rare
//!   seeds of similar brightness brings a variance proportional to its energy (a Poisson count
//!   of seeds), σ² ∝ c for the chains and ∝ 1 − c for the path-traced rest; Neyman's
//!   allocation of a fixed work between two independent parts, work ∝ σ·√(cost), gives the
//!   chains M·w_m rays per camera sample against the seeds' w_c in that ratio.
//! * *Quantum*: `quantum = "image"`: e_d = lum(Σ X_class) / (samples · M) once for the image,
//!   from `prepare`'s pre-pass of one camera sample per pixel with the render's termination
//!   (the census' estimate was too small: 60 spp in 4 s on the glass caustic against 99).
//!
//! Parameters the config sets are kept: the pilot fixes only the rest ([`Free`]).
//!
//! **Unbiasedness.** The pilot's samples are discarded, never deposited: its random numbers
//! are a fixed stream ([`PILOT_SEED`]) independent of every unit's, and its choices are a
//! function of them alone. Conditioned on the choices, the render is ERPT with fixed
//! parameters — unbiased for any split, weights, M, N and quantum e_d > 0 (the split's sum and
//! the flow's stationarity do not depend on them) — so it is unbiased unconditionally.
//! Depositing the pilot's seeds too would tie their weight to choices made from them (the
//! pilot chains where it saw bright caustics). The pilot's time is counted: it runs in
//! `prepare`, inside the render's time budget.
//!
//! **Report.** The choices replace the parameters' resolved values in the EXR metadata
//! (`flowlight.param.chains_for`, `….mutations_per_sample`, `….mutations` as the list to
//! freeze, …), the host logs them as a TOML snippet, and the stats JSON has them with the
//! pilot's norms (`auto.*`).

use crate::gain::{self, Moments};
use crate::settings::MixtureRatio;
use flowlight_sdk::stats::{Counter, Stats, StatsBuilder};
use flowlight_sdk::{Params, StatDisplay};

/// The parameters `auto`'s candidate of the multi-chain perturbation is given: a cone of
/// θ₂ = 0.02 rad, not Veach's 0.1 (a macro, so that [`CANDIDATES`] and the frozen list take
/// the same text). A direction perturbed at a smooth vertex is followed through a Dirac
/// chain to the light, and every mirror of the chain turns the cone's angle into a wider
/// miss: on the mirror chain θ₂ = 0.02 took the render from 1.13× to 1.24× MCPT (8 s, seeds
/// 1–4), and on the glass caustic, the ring, `lens-spot` and `glass-rod` it was within
/// 0.96–1.10× of θ₂ = 0.1 (docs/results.md, "`auto`'s film window").
macro_rules! multichain_candidate_params {
    () => {
        "theta2 = 0.02"
    };
}

/// The default candidate list: every mutation plugin of the project, with its default
/// parameters but the multi-chain perturbation's cone ([`candidate_params`]), as TOML (the
/// host reads it when the config lists no mutations).
pub const CANDIDATES: &str = concat!(
    "[{ plugin = \"multichain-perturbation\", ",
    multichain_candidate_params!(),
    " }, { plugin = \"caustic-perturbation\" }, { plugin = \"lens-perturbation\" }, { plugin = \"drill\" }, { plugin = \"blow\" }, { plugin = \"hard-reconnection\" }, { plugin = \"soft-reconnection\" }, { plugin = \"bxdf-extension\" }]"
);

/// The parameters [`CANDIDATES`] gives plugin `name` beyond its defaults, as TOML key-value
/// text (empty: none), for the frozen list.
pub fn candidate_params(name: &str) -> &'static str {
    match name {
        "multichain-perturbation" => multichain_candidate_params!(),
        _ => "",
    }
}

/// Camera samples of the pilot's census (one per pixel of a grid over the image).
pub const PILOT_SAMPLES: u32 = 4096;
/// Passes of the census at most: more while fewer than [`MIN_CAUSTIC_SEEDS`] caustic seeds
/// are found (the ring caustic's seeds are one camera sample in 2,000).
pub const PILOT_PASSES: u32 = 16;
/// Caustic seeds each candidate's pilot chains start from.
pub const PILOT_CHAIN_SEEDS: usize = 64;
/// Steps of each pilot chain.
pub const PILOT_STEPS: u32 = 32;
/// Fewer caustic seeds than this in the census: no chains.
pub const MIN_CAUSTIC_SEEDS: u64 = 8;
/// A strategy whose accepted moves per ray are below this fraction of the best's gets
/// weight 0.
pub const WEIGHT_FLOOR: f64 = 0.5;
/// The film window `auto` gives the chains at most (pixels): the flange of a unit's buffer is
/// twice the window, so the buffer of a 32-pixel tile grows as (32 + 4K)².
pub const MAX_FILM_WINDOW: u32 = 32;
/// Relative second moment of a camera sample's indirect light above which path tracing
/// leaves it to chains.
pub const HARD_INDIRECT: f64 = 20.0;
/// Chains one seed may start under `auto` (the config's `max_chains_per_seed` defaults to
/// 1,024): a seed's chains all start at its path and spread over the same few pixels (K of
/// 4–12 in a pilot chain), so beyond a handful more chains add work, not spread. On the water
/// pool, whose caustic seeds are rare and bright, up to 1,024 chains per seed took `auto` to
/// 0.66× MCPT; 16 gave 1.30×, and the indirect room 10.0× against 6.7× (4 s; the other
/// caustic scenes within 4%).
pub const MAX_CHAINS_PER_SEED: u32 = 16;
/// Chain steps per camera sample between two seeds of the chained class (sets N).
pub const STEPS_PER_SEED_GAP: f64 = 2.0;
/// The random stream of the pilot, independent of the units' (hashes of their seeds).
pub const PILOT_SEED: u64 = 0xa070_9170_7e5e_ed00;

/// Which of the chains' parameters the config left to the pilot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Free {
    pub termination: bool,
    pub seeds: bool,
    pub direct: bool,
    pub chains_for: bool,
    pub mutations_per_sample: bool,
    pub chain_length: bool,
    pub mixture: bool,
    pub quantum: bool,
    pub film_window: bool,
    pub max_chains_per_seed: bool,
    /// The candidates are [`CANDIDATES`] (the config listed no mutations).
    pub mutations: bool,
}

impl Free {
    /// `Some` under `preset = "auto"`: set, or left out with the declared default mutation
    /// list (the host's mark). Records the resolved `preset`.
    pub fn from_params(p: &Params) -> Result<Option<Free>, String> {
        use crate::settings::{
            CHAINS_FOR, CHAIN_LENGTH, DIRECT, FILM_WINDOW, MAX_CHAINS_PER_SEED, MIXTURE,
            MUTATIONS_PER_SAMPLE, PRESET, QUANTUM, SEEDS,
        };
        let auto = if p.is_set(PRESET.name()) {
            PRESET.get(p)? == "auto"
        } else {
            let auto = p.mutation_list_defaulted("mutations");
            p.record(
                PRESET.name(),
                format!("{:?}", if auto { "auto" } else { "manual" }),
            );
            auto
        };
        Ok(auto.then(|| Free {
            termination: !p.is_set(flowlight_pathtrace::settings::TERMINATION.name()),
            seeds: !p.is_set(SEEDS.name()),
            direct: !p.is_set(DIRECT.name()),
            chains_for: !p.is_set(CHAINS_FOR.name()),
            mutations_per_sample: !p.is_set(MUTATIONS_PER_SAMPLE.name()),
            chain_length: !p.is_set(CHAIN_LENGTH.name()),
            mixture: !p.is_set(MIXTURE.name()),
            quantum: !p.is_set(QUANTUM.name()),
            film_window: !p.is_set(FILM_WINDOW.name()),
            max_chains_per_seed: !p.is_set(MAX_CHAINS_PER_SEED.name()),
            mutations: p.mutation_list_defaulted("mutations"),
        }))
    }
}

/// The census of the pilot's seeds: class 0 the rest, class 1 the caustic class.
#[derive(Clone, Debug, Default)]
pub struct Census {
    /// Camera samples traced.
    pub samples: u64,
    /// Seconds tracing them (reported; the rule uses `work`, which is deterministic).
    pub seconds: f64,
    /// Rays traced for them, counted from the stored seeds: a closest-hit ray per trunk
    /// vertex and a shadow ray or hit per seed.
    pub work: f64,
    /// Valid seeds with energy, per class.
    pub seeds: [u64; 2],
    /// Σ lum X per class.
    pub energy: [f64; 2],
    /// Σ lum X per lighting layer and class.
    pub layer_energy: Vec<[f64; 2]>,
    /// Indirect light outside the class (layer ≥ 2, not caustic): valid seeds with energy,
    /// Σ lum X, and Σ over camera samples of the square of the sample's sum.
    pub indirect_seeds: u64,
    pub indirect_energy: f64,
    pub indirect_sample_squares: f64,
    /// Per-camera-sample moments of the rest and of the class (`gain.rs`).
    pub moments: [Moments; 2],
    /// The same for the split of every path above direct light: layers ≤ 1 and ≥ 2.
    pub layer_moments: [Moments; 2],
    /// Whether the class is every path above direct light ([`Census::chain_indirect`]).
    pub indirect: bool,
}

impl Census {
    /// The caustic class' share of the pilot's energy.
    pub fn caustic_share(&self) -> f64 {
        let total = self.energy[0] + self.energy[1];
        if total > 0.0 {
            self.energy[1] / total
        } else {
            0.0
        }
    }

    /// Seconds per camera sample.
    pub fn seconds_per_sample(&self) -> f64 {
        self.seconds / self.samples.max(1) as f64
    }

    /// R = E[X²] / E[X]² of a camera sample's indirect light outside the class: how far path
    /// tracing is from its mean there (1 for a constant; large where a few samples carry it).
    pub fn indirect_relative_second_moment(&self) -> f64 {
        if self.indirect_energy > 0.0 {
            self.samples as f64 * self.indirect_sample_squares / self.indirect_energy.powi(2)
        } else {
            0.0
        }
    }

    /// Whether path tracing is inefficient on indirect light outside the class: enough seeds
    /// and R ≥ [`HARD_INDIRECT`].
    pub fn indirect_is_hard(&self) -> bool {
        self.indirect_seeds >= MIN_CAUSTIC_SEEDS
            && self.indirect_relative_second_moment() >= HARD_INDIRECT
    }

    /// Moves indirect light outside the class into it (the chains then render every path
    /// above direct light).
    pub fn chain_indirect(&mut self) {
        self.seeds[0] -= self.indirect_seeds.min(self.seeds[0]);
        self.seeds[1] += self.indirect_seeds;
        self.energy[0] = (self.energy[0] - self.indirect_energy).max(0.0);
        self.energy[1] += self.indirect_energy;
        self.moments = self.layer_moments;
        self.indirect = true;
    }

    /// G_max of `gain.rs`: the most chains on the class can gain over path tracing.
    pub fn noise_bound(&self) -> f64 {
        gain::amdahl_bound(self.moments[1].variance(), self.moments[0].variance())
    }

    /// w_s: rays per camera sample.
    pub fn work_per_sample(&self) -> f64 {
        self.work / self.samples.max(1) as f64
    }
}

/// The §5.5 norms of one strategy's pilot chains, and their cost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Norms {
    pub proposals: u64,
    pub accepted: u64,
    /// Domain misses, part misses (proposals outside the caustic class) included.
    pub misses: u64,
    /// Seconds of the pilot chains (reported only: wall-clock time varies from run to run).
    pub seconds: f64,
    /// Rays the proposals traced, counted from the paths: per proposal one for its fixed
    /// costs (the choice, the target function) and one per vertex it moved (a miss: every
    /// vertex after the eye, as if it traced the whole path).
    pub work: f64,
    /// Pilot chains run, and the sum of their effective deposits K (`gain.rs`).
    pub chains: u64,
    pub spread_sum: f64,
}

impl Norms {
    fn ratio(n: u64, d: u64) -> f64 {
        Self::per(n as f64, d as f64)
    }
    /// n / d, or 0 where nothing was measured (d ≤ 0).
    fn per(n: f64, d: f64) -> f64 {
        if d > 0.0 {
            n / d
        } else {
            0.0
        }
    }
    pub fn acceptance(&self) -> f64 {
        Self::ratio(self.accepted, self.proposals)
    }
    pub fn domain_miss(&self) -> f64 {
        Self::ratio(self.misses, self.proposals)
    }
    pub fn seconds_per_proposal(&self) -> f64 {
        Self::per(self.seconds, self.proposals as f64)
    }
    /// Accepted moves per second of the strategy's steps (reported).
    pub fn accepted_per_second(&self) -> f64 {
        Self::per(self.accepted as f64, self.seconds)
    }
    /// w_s: rays per proposal.
    pub fn work_per_proposal(&self) -> f64 {
        Self::per(self.work, self.proposals as f64)
    }
    /// Accepted moves per ray of the strategy's steps (reported).
    pub fn accepted_per_work(&self) -> f64 {
        Self::per(self.accepted as f64, self.work)
    }
    /// K: a pilot chain's effective deposits (pixels its deposits spread over).
    pub fn spread(&self) -> f64 {
        Self::per(self.spread_sum, self.chains as f64)
    }
    /// Pixels a pilot chain's deposits spread over beyond its seed's, per ray of its steps,
    /// Σ (K − 1) / Σ rays: what the rule weights by (a strategy that never leaves the seed's
    /// pixel gets 0).
    pub fn spread_per_work(&self) -> f64 {
        Self::per((self.spread_sum - self.chains as f64).max(0.0), self.work)
    }
}

/// What the rule fixed.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Chains for the caustic class; false: the render is path tracing.
    pub chains: bool,
    /// Selection probability per candidate (sums to 1 when `chains`).
    pub weights: Vec<f64>,
    pub mutations_per_sample: f64,
    pub chain_length: u32,
    /// Amdahl's bound G_max from the census (`gain.rs`; 0 when the class has no seeds).
    pub noise_bound: f64,
}

/// K of `auto`: the film window in which the lens jump (of the lens and multi-chain
/// perturbations, bounded by K/2) reaches Veach's r₂ = √(0.05·W·H/π), the radius of 5% of the
/// image area — 2·r₂ rounded to an even pixel count, in [8, [`MAX_FILM_WINDOW`]] (32 at
/// 128², 16 at 64²).
pub fn film_window(width: u32, height: u32) -> u32 {
    let r2 = (0.05 * width as f64 * height as f64 / std::f64::consts::PI).sqrt();
    (2 * r2.round() as u32).clamp(8, MAX_FILM_WINDOW)
}

/// The smallest power of two ≥ x, in [lo, hi].
fn power_of_two_in(x: f64, lo: u32, hi: u32) -> u32 {
    let mut n = lo;
    while (n as f64) < x && n < hi {
        n *= 2;
    }
    n
}

/// The rule of the module docs: from the census and each candidate's norms, the split, the
/// weights, N and M. `fallback` holds the weights, M and N a plan without chains keeps.
pub fn decide(census: &Census, norms: &[Norms], fallback: (&[f64], f64, u32)) -> Plan {
    let noise_bound = if census.seeds[1] > 0 {
        census.noise_bound()
    } else {
        0.0
    };
    let no_chains = || Plan {
        chains: false,
        weights: fallback.0.to_vec(),
        mutations_per_sample: fallback.1,
        chain_length: fallback.2,
        noise_bound,
    };
    if census.seeds[1] < MIN_CAUSTIC_SEEDS || census.energy[1] <= 0.0 {
        // Too few caustic seeds to measure: path tracing.
        return no_chains();
    }
    if census.indirect && noise_bound < gain::MIN_GAIN {
        // Indirect light is a small share of path tracing's noise: chains on it cannot pay.
        return no_chains();
    }
    // Selected: the strategies within the floor of the best accepted moves per ray; weighted
    // by the pixels their chains spread over per ray.
    let rates: Vec<f64> = norms.iter().map(Norms::accepted_per_work).collect();
    let best = rates.iter().cloned().fold(0.0, f64::max);
    let kept: Vec<f64> = rates
        .iter()
        .zip(norms)
        .map(|(&r, n)| {
            if best > 0.0 && r >= WEIGHT_FLOOR * best {
                n.spread_per_work()
            } else {
                0.0
            }
        })
        .collect();
    let sum: f64 = kept.iter().sum();
    if sum <= 0.0 {
        // No strategy moves a chain out of its seed's pixel: path tracing.
        return no_chains();
    }
    let weights: Vec<f64> = kept.iter().map(|r| r / sum).collect();
    let step_work: f64 = weights
        .iter()
        .zip(norms)
        .map(|(w, n)| w * n.work_per_proposal())
        .sum();
    // Caustic seeds per camera sample: the rarer, the further a seed's energy must travel.
    let density = census.seeds[1] as f64 / census.samples.max(1) as f64;
    let chain_length = power_of_two_in(STEPS_PER_SEED_GAP / density, 16, 64);
    // Neyman: work ∝ σ·√(cost) per part, σ² ∝ energy: M·w_m / w_c = √(c/(1−c)) · √(w_m/w_c).
    let c = census.caustic_share().min(0.999);
    let m = if step_work > 0.0 {
        (c / (1.0 - c)).sqrt() * (census.work_per_sample() / step_work).sqrt()
    } else {
        1.0
    };
    Plan {
        chains: true,
        weights,
        mutations_per_sample: m.clamp(1.0 / 16.0, 16.0),
        chain_length,
        noise_bound,
    }
}

/// The pilot's choices and norms, for the metadata, the log and the stats.
#[derive(Clone, Debug)]
pub struct Report {
    pub plan: Plan,
    pub census: Census,
    pub norms: Vec<Norms>,
    /// The quantum fixed for the image (`None`: per tile, or no chains).
    pub quantum: Option<f64>,
    pub mixture: MixtureRatio,
    /// The chains' film window K ([`film_window`] where the config left it out).
    pub film_window: u32,
    /// The candidates' plugin names.
    pub plugins: Vec<String>,
    /// The chained part: `"caustics"`, or `"all"` when indirect light is chained too.
    pub chains_for: &'static str,
    /// No chains because the scene's surfaces give no path of the chained class (no pilot
    /// ran): the resolved split already renders without chains.
    pub by_letters: bool,
    /// What the config left to `auto`.
    pub free: Free,
}

impl Report {
    /// The decided parameters, `(name, TOML text)`: what a config freezes to render the same
    /// way without the pilot (`preset = "manual"` and these).
    pub fn decided_params(&self) -> Vec<(String, String)> {
        let (p, free) = (&self.plan, &self.free);
        let mut out = vec![("preset".to_string(), "\"manual\"".to_string())];
        let mut fix = |free: bool, name: &str, value: &str| {
            if free {
                out.push((name.to_string(), value.to_string()));
            }
        };
        fix(free.seeds, "seeds", "\"entangled\"");
        fix(free.direct, "direct", "\"mcpt\"");
        if !p.chains && !self.by_letters {
            // `E`, the eye alone, is the type of no path: every seed is path traced.
            fix(true, "chains_for", "\"E\"");
            return out;
        }
        fix(
            free.chains_for,
            "chains_for",
            &format!("{:?}", self.chains_for),
        );
        if !p.chains {
            return out;
        }
        fix(free.termination, "termination", "\"expo\"");
        out.push((
            "mutations_per_sample".into(),
            format!("{}", p.mutations_per_sample),
        ));
        out.push(("chain_length".into(), p.chain_length.to_string()));
        if free.film_window {
            out.push(("film_window".into(), self.film_window.to_string()));
        }
        if free.max_chains_per_seed {
            out.push((
                "max_chains_per_seed".into(),
                MAX_CHAINS_PER_SEED.to_string(),
            ));
        }
        out.push((
            "mixture".into(),
            match self.mixture {
                MixtureRatio::Mixture => "\"mixture\"",
                MixtureRatio::Selected => "\"selected\"",
            }
            .into(),
        ));
        if self.quantum.is_some() {
            out.push(("quantum".into(), "\"image\"".into()));
        }
        let list: Vec<String> = self
            .plugins
            .iter()
            .zip(&p.weights)
            .filter(|(_, &w)| w > 0.0)
            .map(|(name, w)| {
                // The default candidates' own parameters go with them; a listed candidate's
                // are the config's, which the plugin does not see (docs/erpt.md).
                let own = match candidate_params(name) {
                    own if free.mutations && !own.is_empty() => format!(", {own}"),
                    _ => String::new(),
                };
                format!("{{ plugin = \"{name}\", weight = {w:.4}{own} }}")
            })
            .collect();
        out.push(("mutations".into(), format!("[{}]", list.join(", "))));
        out
    }
}

/// The `auto.*` counters: the choices and the pilot's norms, the same in every unit (`max`).
#[derive(Clone, Debug)]
pub struct Counters {
    chains: Counter,
    mutations_per_sample: Counter,
    chain_length: Counter,
    quantum: Counter,
    samples: Counter,
    seconds_per_sample: Counter,
    rays_per_sample: Counter,
    caustic_seeds: Counter,
    caustic_share: Counter,
    indirect_r: Counter,
    /// The census' relative variance per camera sample of the class and of the rest, and
    /// Amdahl's bound G_max from them (`gain.rs`).
    class_variance: Counter,
    rest_variance: Counter,
    noise_bound: Counter,
    /// Per lighting layer: Σ lum X per camera sample outside and inside the census' class
    /// (the caustic class, or the config's `chains_for`).
    per_layer: Vec<[Counter; 2]>,
    /// Per candidate: weight, acceptance, domain miss, seconds and rays per proposal,
    /// accepted moves per second and per ray, effective deposits of a pilot chain.
    per_strategy: Vec<[Counter; 8]>,
}

impl Counters {
    /// `layers`: the census' lighting layers (path depth + 2, the last holding every deeper
    /// one).
    pub fn declare(b: &mut StatsBuilder, names: &[String], layers: usize) -> Counters {
        let n = |b: &mut StatsBuilder, name: String| b.max_as(name, StatDisplay::Number);
        let hidden = |b: &mut StatsBuilder, name: String| b.max_as(name, StatDisplay::Hidden);
        Counters {
            chains: n(b, "auto.chains".into()),
            mutations_per_sample: n(b, "auto.mutations_per_sample".into()),
            chain_length: n(b, "auto.chain_length".into()),
            quantum: hidden(b, "auto.quantum".into()),
            samples: hidden(b, "auto.pilot.samples".into()),
            seconds_per_sample: hidden(b, "auto.pilot.seconds_per_sample".into()),
            rays_per_sample: hidden(b, "auto.pilot.rays_per_sample".into()),
            caustic_seeds: hidden(b, "auto.pilot.chained_seeds".into()),
            caustic_share: n(b, "auto.pilot.chained_energy_share".into()),
            indirect_r: n(b, "auto.pilot.indirect_relative_second_moment".into()),
            class_variance: hidden(b, "auto.pilot.class_variance".into()),
            rest_variance: hidden(b, "auto.pilot.rest_variance".into()),
            noise_bound: n(b, "auto.pilot.noise_bound".into()),
            per_layer: (0..layers)
                .map(|k| {
                    [
                        hidden(b, format!("auto.pilot.layer{k}.other_energy_per_sample")),
                        hidden(b, format!("auto.pilot.layer{k}.class_energy_per_sample")),
                    ]
                })
                .collect(),
            per_strategy: names
                .iter()
                .map(|s| {
                    [
                        n(b, format!("auto.weight.{s}")),
                        hidden(b, format!("auto.pilot.{s}.acceptance_strength")),
                        hidden(b, format!("auto.pilot.{s}.domain_miss_strength")),
                        hidden(b, format!("auto.pilot.{s}.seconds_per_proposal")),
                        hidden(b, format!("auto.pilot.{s}.rays_per_proposal")),
                        hidden(b, format!("auto.pilot.{s}.accepted_per_second")),
                        hidden(b, format!("auto.pilot.{s}.accepted_per_ray")),
                        hidden(b, format!("auto.pilot.{s}.effective_deposits")),
                    ]
                })
                .collect(),
        }
    }

    /// Adds the report into a unit's counters (each a maximum: every unit adds the same).
    pub fn add(&self, stats: &mut Stats, r: &Report) {
        let p = &r.plan;
        // 0: path tracing, 1: chains for the caustic class, 2: for every indirect path.
        let chains = match (p.chains, r.chains_for) {
            (false, _) => 0.0,
            (true, "all") => 2.0,
            (true, _) => 1.0,
        };
        stats.add(self.chains, chains);
        stats.add(self.mutations_per_sample, p.mutations_per_sample);
        stats.add(self.chain_length, p.chain_length as f64);
        stats.add(self.quantum, r.quantum.unwrap_or(0.0));
        stats.add(self.samples, r.census.samples as f64);
        stats.add(self.seconds_per_sample, r.census.seconds_per_sample());
        stats.add(self.rays_per_sample, r.census.work_per_sample());
        stats.add(self.caustic_seeds, r.census.seeds[1] as f64);
        stats.add(self.caustic_share, r.census.caustic_share());
        stats.add(self.indirect_r, r.census.indirect_relative_second_moment());
        stats.add(self.class_variance, r.census.moments[1].variance());
        stats.add(self.rest_variance, r.census.moments[0].variance());
        // A maximum over units: infinity (no noise left outside the class) as a large number.
        stats.add(self.noise_bound, p.noise_bound.min(1e12));
        let samples = r.census.samples.max(1) as f64;
        for (c, e) in self.per_layer.iter().zip(&r.census.layer_energy) {
            stats.add(c[0], e[0] / samples);
            stats.add(c[1], e[1] / samples);
        }
        for (i, c) in self.per_strategy.iter().enumerate() {
            let n = r.norms.get(i).copied().unwrap_or_default();
            let values = [
                p.weights.get(i).copied().unwrap_or(0.0),
                n.acceptance(),
                n.domain_miss(),
                n.seconds_per_proposal(),
                n.work_per_proposal(),
                n.accepted_per_second(),
                n.accepted_per_work(),
                n.spread(),
            ];
            for (&counter, v) in c.iter().zip(values) {
                stats.add(counter, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Moments of 1000 camera samples whose per-pixel variance is `v`.
    fn moments(v: f64) -> Moments {
        Moments {
            samples: 1000,
            squares: 1000.0 * v,
            neighbour_products: 0.0,
            pairs: 900,
        }
    }

    /// 1000 camera samples of 4 rays; the class' share of the energy `share`, its variance
    /// 10× the rest's (the glass caustic's kind).
    fn census(caustic_seeds: u64, share: f64) -> Census {
        Census {
            samples: 1000,
            seconds: 1000.0 * 4e-6,
            work: 4000.0,
            seeds: [5000, caustic_seeds],
            energy: [1.0 - share, share],
            moments: [moments(1.0), moments(10.0)],
            ..Census::default()
        }
    }

    #[test]
    fn indirect_light_is_hard_when_a_few_samples_carry_it() {
        // 1000 samples, indirect energy 0.5 of the rest's 1: spread evenly R = 1, in one
        // sample R = 1000.
        let mut c = census(0, 0.0);
        c.indirect_seeds = 1000;
        c.indirect_energy = 0.5;
        c.indirect_sample_squares = 1000.0 * 0.0005f64.powi(2);
        c.layer_moments = [moments(2.0), moments(3.0)];
        assert!((c.indirect_relative_second_moment() - 1.0).abs() < 1e-9);
        assert!(!c.indirect_is_hard());
        c.indirect_sample_squares = 0.25;
        assert!((c.indirect_relative_second_moment() - 1000.0).abs() < 1e-9);
        assert!(c.indirect_is_hard());
        c.chain_indirect();
        assert_eq!((c.seeds, c.energy), ([4000, 1000], [0.5, 0.5]));
        // The class is now every path above direct light, with its variance.
        assert_eq!(c.moments, c.layer_moments);
    }

    /// Norms of 100 pilot chains with `work` rays in all (and as many microseconds), each
    /// spreading its deposits over `spread` pixels.
    fn norms(proposals: u64, accepted: u64, misses: u64, work: f64, spread: f64) -> Norms {
        Norms {
            proposals,
            accepted,
            misses,
            seconds: work * 1e-6,
            work,
            chains: 100,
            spread_sum: 100.0 * spread,
        }
    }

    #[test]
    fn without_caustic_seeds_or_moves_the_render_is_path_tracing() {
        let fallback = (&[0.5, 0.5][..], 8.0, 16);
        let good = [
            norms(1000, 500, 0, 1000.0, 11.0),
            norms(1000, 100, 0, 1000.0, 3.0),
        ];
        let p = decide(&census(2, 0.2), &good, fallback);
        assert!(!p.chains && p.weights == [0.5, 0.5] && p.chain_length == 16);
        // Chains that never leave their seed's pixel (K = 1) spread nothing.
        let stuck = [
            norms(1000, 0, 1000, 1000.0, 1.0),
            norms(1000, 0, 10, 1000.0, 1.0),
        ];
        assert!(!decide(&census(100, 0.2), &stuck, fallback).chains);
        assert!(decide(&census(100, 0.2), &good, fallback).chains);
    }

    #[test]
    fn indirect_light_with_a_small_share_of_the_noise_is_path_traced() {
        let fallback = (&[1.0][..], 8.0, 16);
        let good = [norms(1000, 500, 0, 1000.0, 11.0)];
        // Indirect light chained (the census' R was high) that carries most of the noise:
        // chains (the indirect room's kind).
        let mut noisy = census(100, 0.2);
        noisy.indirect = true;
        let p = decide(&noisy, &good, fallback);
        assert!(p.chains && (p.noise_bound - 11.0).abs() < 1e-9, "{p:?}");
        // veach-mis' kind: its indirect light is 0.003 of relative variance beside 2,652 of
        // glossy highlights. Path tracing, whatever the seeds and strategies.
        let mut quiet = noisy.clone();
        quiet.moments = [moments(2652.0), moments(0.003)];
        let p = decide(&quiet, &good, fallback);
        assert!(!p.chains && p.noise_bound < gain::MIN_GAIN, "{p:?}");
        assert_eq!((p.mutations_per_sample, p.chain_length), (8.0, 16));
        // The caustic class is not gated: the census does not see its tail of rare seeds.
        quiet.indirect = false;
        assert!(decide(&quiet, &good, fallback).chains);
    }

    #[test]
    fn acceptance_per_ray_selects_and_spread_per_ray_weights() {
        let fallback = (&[0.25; 4][..], 8.0, 16);
        // Accepted moves per ray 0.5, 0.4, 0.24 (under the floor of 1/2 · 0.5) and 0.5; pixels
        // spread beyond the seed's per ray (100 chains): 1.0, 0.4, 1.9 and 0 (the fourth's
        // moves never leave the pixel).
        let n = [
            norms(1000, 500, 0, 1000.0, 11.0),
            norms(1000, 500, 100, 1250.0, 6.0),
            norms(1000, 240, 600, 1000.0, 20.0),
            norms(1000, 500, 0, 1000.0, 1.0),
        ];
        let p = decide(&census(100, 0.25), &n, fallback);
        assert!(p.chains);
        assert!((p.weights[0] - 1.0 / 1.4).abs() < 1e-12, "{:?}", p.weights);
        assert!((p.weights[1] - 0.4 / 1.4).abs() < 1e-12);
        assert_eq!((p.weights[2], p.weights[3]), (0.0, 0.0));
        // w_m = (1·1 + 0.4·1.25) / 1.4 rays a step; M = √(1/3) · √(4 / w_m).
        let m = (1.0f64 / 3.0).sqrt() * (4.0 * 1.4 / 1.5f64).sqrt();
        assert!((p.mutations_per_sample - m).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn rare_seeds_get_long_chains_and_the_budget_stays_within_bounds() {
        let fallback = (&[1.0][..], 8.0, 16);
        let good = [norms(1000, 500, 0, 1000.0, 11.0)];
        let at = |seeds: u64| decide(&census(seeds, 0.5), &good, fallback);
        // 2 / (seeds per camera sample), as a power of two in [16, 64].
        assert_eq!(at(200).chain_length, 16);
        assert_eq!(at(100).chain_length, 32);
        assert_eq!(at(10).chain_length, 64);
        // M = √(0.5 / 0.5) · √(4 / 1) = 2, and within [1/16, 16].
        assert!((at(100).mutations_per_sample - 2.0).abs() < 1e-9);
        let cheap = decide(
            &census(100, 1.0),
            &[norms(1000, 900, 0, 1e-3, 11.0)],
            fallback,
        );
        assert_eq!(cheap.mutations_per_sample, 16.0);
        let dim = decide(&census(100, 1e-6), &good, fallback);
        assert_eq!(dim.mutations_per_sample, 1.0 / 16.0);
    }

    /// The report's frozen parameters as the TOML table a config would hold.
    fn frozen(r: &Report) -> toml::Table {
        let text: String = r
            .decided_params()
            .iter()
            .map(|(k, v)| format!("{k} = {v}\n"))
            .collect();
        text.parse().expect("TOML")
    }

    #[test]
    fn the_report_freezes_into_a_manual_config() {
        let plan = decide(
            &census(100, 0.5),
            &[
                norms(1000, 500, 0, 1000.0, 11.0),
                norms(1000, 0, 1000, 1000.0, 1.0),
            ],
            (&[0.5, 0.5], 8.0, 16),
        );
        let r = Report {
            plan,
            census: census(100, 0.5),
            norms: vec![],
            quantum: Some(0.01),
            mixture: MixtureRatio::Selected,
            film_window: 32,
            plugins: vec!["drill".into(), "blow".into()],
            chains_for: "caustics",
            by_letters: false,
            free: Free {
                termination: true,
                seeds: true,
                direct: true,
                chains_for: true,
                mutations_per_sample: true,
                chain_length: true,
                mixture: true,
                quantum: true,
                film_window: true,
                max_chains_per_seed: true,
                mutations: true,
            },
        };
        let table = frozen(&r);
        assert_eq!(table["preset"].as_str(), Some("manual"));
        assert_eq!(table["chains_for"].as_str(), Some("caustics"));
        assert_eq!(table["seeds"].as_str(), Some("entangled"));
        assert_eq!(table["direct"].as_str(), Some("mcpt"));
        assert_eq!(table["termination"].as_str(), Some("expo"));
        let list = table["mutations"].as_array().unwrap();
        assert_eq!(list.len(), 1, "blow moved nothing: {table:?}");
        assert_eq!(list[0]["plugin"].as_str(), Some("drill"));
        assert_eq!(table["mixture"].as_str(), Some("selected"));
        assert_eq!(table["film_window"].as_integer(), Some(32));
        assert_eq!(
            table["max_chains_per_seed"].as_integer(),
            Some(MAX_CHAINS_PER_SEED as i64)
        );

        // The default candidates' own parameters are frozen with them; a listed candidate's
        // are not the plugin's to repeat.
        let frozen_list = |free_list: bool| {
            let mut r = r.clone();
            r.plugins = vec!["multichain-perturbation".into(), "blow".into()];
            r.free.mutations = free_list;
            frozen(&r)["mutations"].as_array().unwrap()[0].clone()
        };
        let defaulted = frozen_list(true);
        assert_eq!(
            defaulted["plugin"].as_str(),
            Some("multichain-perturbation")
        );
        assert_eq!(defaulted["theta2"].as_float(), Some(0.02));
        assert!(frozen_list(false).get("theta2").is_none());
        assert!(CANDIDATES.contains(&format!(
            "{{ plugin = \"multichain-perturbation\", {} }}",
            candidate_params("multichain-perturbation")
        )));
    }

    #[test]
    fn the_film_window_lets_the_lens_jump_reach_veachs_radius() {
        // r₂ = √(0.05·W·H/π): 16.2 px at 128², 8.1 at 64², 4.0 at 32²; K = 2·r₂ in [8, 32].
        assert_eq!(film_window(128, 128), 32);
        assert_eq!(film_window(64, 64), 16);
        assert_eq!(film_window(96, 64), 20);
        assert_eq!(film_window(32, 32), 8);
        assert_eq!(film_window(1920, 1080), MAX_FILM_WINDOW);
        assert_eq!(film_window(1, 1), 8);
    }
}
