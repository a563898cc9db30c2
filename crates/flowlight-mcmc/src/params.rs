//! Parameters several mutation plugins share, each declared once
//! ([`flowlight_sdk::declare`]): the lens jump's radii (lens and multi-chain perturbations),
//! the exponential cone's angles (caustic and multi-chain perturbations) and `free_chains`
//! (drill, lens and multi-chain). A plugin lists their `spec()`s in its `PARAMS` and reads
//! them through [`crate::perturbation::LensJump::from_params`], [`exp_cone`] and
//! `FREE_CHAINS.get(params)`; their tables in docs/erpt.md are generated from the plugins.

use crate::perturbation::ExpCone;
use flowlight_sdk::declare::{BoolParam, FloatParam};
use flowlight_sdk::{bool_param, float_param, Params};

/// `r1`: the lens jump's smallest radius in pixels (Veach's r₁).
pub const R1: FloatParam = float_param!(
    "r1",
    0.1,
    0.0 < x,
    "smallest raster jump, pixels (Veach's r1)"
);

/// `r2`: the lens jump's largest radius in pixels; 0 selects Veach's √(0.05·W·H/π).
pub const R2: FloatParam = float_param!(
    "r2",
    0.0,
    0.0 <= x,
    "largest raster jump, pixels; 0: Veach's sqrt(0.05·W·H/pi) (5 % of the image area); else greater than r1; bounded by film_window/2"
);

/// `theta1`: the exponential cone's smallest angle in radians. The bound is π/2 written out:
/// a declaration's bounds are literals, whose text the docs table shows.
#[allow(clippy::approx_constant)]
pub const THETA1: FloatParam = float_param!(
    "theta1",
    0.0001,
    0.0 < x <= 1.5707963267948966,
    "smallest direction perturbation, radians (less than theta2)"
);

/// `theta2`: the exponential cone's largest angle in radians (bound π/2, as [`THETA1`]'s).
#[allow(clippy::approx_constant)]
pub const THETA2: FloatParam = float_param!(
    "theta2",
    0.1,
    0.0 < x <= 1.5707963267948966,
    "largest direction perturbation, radians"
);

/// `free_chains`: follow mirror chains to any length (`crate::regenerate`, "Dirac chains of
/// any length").
pub const FREE_CHAINS: BoolParam = bool_param!(
    "free_chains",
    true,
    "follow a chain of mirrors to whatever length it has; false: Veach's rule, every chain keeps the path's number of bounces"
);

/// The exponential cone of [`THETA1`] and [`THETA2`] (checked together: θ₁ < θ₂).
pub fn exp_cone(params: &Params) -> Result<ExpCone, String> {
    ExpCone::new(THETA1.get(params)?, THETA2.get(params)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_declared_defaults_are_veachs() {
        let p = Params::from_slice(&[]);
        let cone = exp_cone(&p).unwrap();
        assert_eq!(cone, ExpCone::VEACH);
        assert_eq!(FREE_CHAINS.get(&p), Ok(true));
        assert_eq!(
            p.resolved(),
            [
                ("theta1".to_string(), "0.0001".to_string()),
                ("theta2".to_string(), "0.1".to_string()),
                ("free_chains".to_string(), "true".to_string()),
            ]
        );
    }
}
