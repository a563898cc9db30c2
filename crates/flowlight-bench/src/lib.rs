//! References and the error-against-time benchmark (`flowlight reference`, `flowlight bench`),
//! a crate of its own so the host does not carry the suite format or the plotting library.
//!
//! Everything here goes through the ordinary host API ([`flowlight_host::renderer::Renderer`]): a method of the suite is
//! any integrator plugin plus parameters, so a new integrator (ERPT and its mutation mixes)
//! is benchmarked by adding a `[[method]]` entry, without code changes. The suite format is
//! documented in `docs/bench.md`.
//!
//! # References
//!
//! A reference is the mean of **two independent renders** with seeds `s` and `s + 1` (the
//! plugin ABI has no per-pixel second moment, so the variance comes from the host side): with
//! per-pixel means A, B of n_A, n_B samples, the reference is (n_A A + n_B B)/(n_A + n_B) and
//! (A − B)² / ((1/n_A + 1/n_B)(n_A + n_B)) is an unbiased (one degree of freedom, so noisy per
//! pixel, but fine on average) estimate of the variance of that mean. It is stored as the EXR
//! layer `variance`, beside the lighting layers `layer0..layerN` when the integrator wrote them.
//!
//! # Modules
//!
//! - [`reference`](mod@reference): two-half references, their variance layer, reading and writing them;
//! - [`suite`]: the suite TOML (`docs/bench.md`), parsed and validated;
//! - [`run`]: one render through the host API, and a whole suite's runs;
//! - [`report`]: means over seeds, efficiencies, the CSV and Markdown tables;
//! - [`plot`]: the SVG plots (the only user of `plotters`);
//! - [`seams`]: the seam metric of tile-edge artefacts (`flowlight seams`, thesis §5.9).

pub mod plot;
pub mod reference;
pub mod report;
pub mod run;
pub mod seams;
pub mod suite;

pub use plot::{plot_layers, plot_scene};
pub use reference::{
    combine_halves, read_reference, reference_from_exrs, render_reference, write_reference,
    Reference,
};
pub use report::{summarise, BenchReport, SummaryRow};
pub use run::{
    check_floor, check_reference_matches, ensure_reference, render_request, run_suite,
    BenchOverrides, Budget, RenderRequest, RenderResult, Run,
};
pub use seams::{seam_metric, SeamMetric};
pub use suite::{load_suite, parse_suite, Method, Suite, SuiteScene};
