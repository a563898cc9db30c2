//! The bidirectional plugins' parameters, each declared once ([`flowlight_sdk::declare`]):
//! `lighttrace`, `bdpt` and `vcm` list the ones they take in their `PARAMS`, and
//! [`settings_from_params`] reads them. The depth and roulette parameters are MCPT's
//! ([`crate::settings`]).

use super::{BidirSettings, Heuristic, Techniques};
use crate::settings::{self, Variant};
use crate::PathSettings;
use flowlight_sdk::abi::ParamSpec;
use flowlight_sdk::declare::{BoolParam, ChoiceParam, FloatParam};
use flowlight_sdk::{bool_param, choice_param, float_param, Params};

/// `heuristic`: how the strategies' densities become weights.
pub const HEURISTIC: ChoiceParam = choice_param!(
    "heuristic",
    "power",
    ["power", "balance"],
    "multiple importance sampling of the strategies: \"power\" (Veach's power heuristic, exponent 2) or \"balance\""
);

/// `strategies` (bdpt): one layer per (s, t) strategy.
pub const STRATEGIES: BoolParam = bool_param!(
    "strategies",
    false,
    "write one EXR layer per strategy (s light vertices, t camera vertices; layer index (n-1)n/2 - 1 + s for n = s + t vertices, paths of up to path_depth + 2 vertices), weighted, as in Veach's figure 10.3; they sum to the image. Not with layers"
);

/// `radius` (vcm): the first iteration's merging radius. The default gives a merge about the
/// photon density per query that LuxCore's BIDIRVMCPU gets from its defaults (radius 0.003 of
/// the scene's radius, 16,384 light paths per pass): a work unit here merges with its own
/// 1,024 light paths (32² tiles), 16 times fewer, so the radius is 4 times larger (0.012,
/// rounded to 0.01).
pub const RADIUS: FloatParam = float_param!(
    "radius",
    0.01,
    0.0 < x <= 1.0,
    "merging radius of the first iteration, as a fraction of the radius of the scene's bounding sphere"
);

/// `radius_alpha` (vcm): how fast the radius shrinks.
pub const RADIUS_ALPHA: FloatParam = float_param!(
    "radius_alpha",
    0.75,
    0.0 < x <= 1.0,
    "radius schedule r_i = radius * (i + 1)^((alpha - 1)/2) over sample indices i (Knaus and Zwicker 2011); 1 keeps the radius constant (biased, not consistent)"
);

/// `mode` (vcm): vertex connection and merging, or merging alone.
pub const MODE: ChoiceParam = choice_param!(
    "mode",
    "vcm",
    ["vcm", "ppm"],
    "\"vcm\": every connection strategy and merging, by MIS; \"ppm\": progressive photon mapping, merging alone at the first non-Dirac camera vertex"
);

/// What every bidirectional plugin takes: depths, roulette and lighting layers (`bdpt` and
/// `vcm` add [`HEURISTIC`]: light tracing alone has one strategy per path).
pub const SHARED: [ParamSpec; 6] = [
    settings::TERMINATION.spec(),
    settings::PATH_DEPTH.spec(),
    settings::MAX_RAY_DEPTH.spec(),
    settings::RR_DEPTH.spec(),
    settings::RR_MAX_SURVIVAL.spec(),
    settings::LAYERS.spec(),
];

/// The settings of a plugin that combines `techniques` (for `vcm`, [`MODE`] may replace
/// them by photon mapping). Reads only the parameters the plugin declares: the heuristic
/// where `techniques` weigh strategies, `strategies` where `strategies` is true, the radius
/// and mode where `techniques` merge.
pub fn settings_from_params(
    p: &Params,
    techniques: Techniques,
    strategies: bool,
) -> Result<BidirSettings, String> {
    let path = PathSettings::shared_from_params(p, Variant::Entangled, &settings::MAX_RAY_DEPTH)?;
    let heuristic = if techniques.weighs() {
        Heuristic::parse(HEURISTIC.get(p)?).expect("declared choice")
    } else {
        Heuristic::Power
    };
    let lighting_layers = settings::LAYERS.get(p)?;
    let strategy_layers = strategies && STRATEGIES.get(p)?;
    if lighting_layers && strategy_layers {
        return Err(
            "parameters 'layers' and 'strategies' exclude each other: a deposit has one layer"
                .into(),
        );
    }
    let (techniques, radius, radius_alpha) = if techniques.merge {
        let techniques = match MODE.get(p)? {
            "ppm" => Techniques::PPM,
            _ => techniques,
        };
        (
            techniques,
            RADIUS.get(p)? as f32,
            RADIUS_ALPHA.get(p)? as f32,
        )
    } else {
        (techniques, 0.0, 1.0)
    };
    Ok(BidirSettings {
        path,
        heuristic,
        techniques,
        lighting_layers,
        strategy_layers,
        radius,
        radius_alpha,
        only_strategy: None,
    })
}
