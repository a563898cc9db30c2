//! Parameter declarations: each parameter of a plugin declared once — name, type, default,
//! the values accepted, a one-line doc and an optional [`ParamRole`] — and everything else
//! derived from the declaration:
//!
//! | derived | how |
//! |---|---|
//! | the plugin's `PARAMS` (what crosses the C ABI) | `DECL.spec()`, a `const fn` |
//! | the parsing in `create` | `DECL.get(params)?`: the config's value or the declared default, range-checked |
//! | the resolved value in the output's metadata | recorded by every getter ([`Params::resolved`]) |
//! | `flowlight plugins` and its `--markdown` tables, the docs tables | read from the specs |
//!
//! The default and the range are written once, as literals of the declaring macro
//! ([`int_param!`](crate::int_param), [`float_param!`](crate::float_param), [`bool_param!`](crate::bool_param), [`choice_param!`](crate::choice_param), [`string_param!`](crate::string_param));
//! the macro keeps their text for the spec (`stringify!`), so the default a table shows is
//! the default `get` returns, and a default outside its range fails to compile. A value
//! outside the range is refused with one line naming the parameter:
//! `parameter 'path_depth' must be in 1..=32, got 40`.
//!
//! ```
//! use flowlight_sdk::declare::{IntParam, ChoiceParam};
//! use flowlight_sdk::abi::{ParamRole, ParamValue, StrRef};
//! use flowlight_sdk::{choice_param, int_param, ParamKind, Params};
//!
//! const PATH_DEPTH: IntParam =
//!     int_param!("path_depth", 8, 1..=32, "deepest lighting layer N").role(ParamRole::PathDepth);
//! const VARIANT: ChoiceParam =
//!     choice_param!("variant", "entangled", ["untangled", "entangled"], "the estimator");
//! const PARAMS: &[flowlight_sdk::ParamSpec] = &[PATH_DEPTH.spec(), VARIANT.spec()];
//!
//! // The config set path_depth = 40 and left variant out.
//! let values = [ParamValue {
//!     name: StrRef::new("path_depth"),
//!     kind: ParamKind::Int,
//!     int: 40,
//!     float: 0.0,
//!     boolean: 0,
//!     string: StrRef::EMPTY,
//! }];
//! let params = Params::from_slice(&values);
//! assert_eq!(
//!     PATH_DEPTH.get(&params),
//!     Err("parameter 'path_depth' must be in 1..=32, got 40".to_string())
//! );
//! assert_eq!(VARIANT.get(&params), Ok("entangled"));
//! assert_eq!(params.resolved(), [("variant".to_string(), "\"entangled\"".to_string())]);
//! // SAFETY (of this example): the specs point to static strings.
//! assert_eq!(unsafe { PARAMS[0].default.as_str() }, "8");
//! assert_eq!(unsafe { PARAMS[0].range.as_str() }, "1..=32");
//! ```
//!
//! A default that depends on another parameter (MCPT's `branches`: 4, but 1 for untangled
//! paths) is read with `get_or(params, fallback)`, which range-checks and records the
//! fallback as well; the declaration's doc says when the fallback applies.

use crate::abi::{ParamRole, ParamSpec, StrRef};
use crate::params::{toml_float, ParamKind, Params};

/// An integer parameter accepting `min..=max`. Declared with [`int_param!`](crate::int_param).
#[derive(Clone, Copy, Debug)]
pub struct IntParam {
    name: &'static str,
    default: i64,
    min: i64,
    max: i64,
    doc: &'static str,
    role: ParamRole,
    default_text: &'static str,
    range_text: &'static str,
}

impl IntParam {
    /// Used by [`int_param!`](crate::int_param), which passes the literals' own text; call the macro instead.
    #[doc(hidden)]
    pub const fn __declare(
        name: &'static str,
        default: i64,
        min: i64,
        max: i64,
        doc: &'static str,
        default_text: &'static str,
        range_text: &'static str,
    ) -> IntParam {
        assert!(
            min <= default && default <= max,
            "the default is outside the range"
        );
        IntParam {
            name,
            default,
            min,
            max,
            doc,
            role: ParamRole::None,
            default_text,
            range_text,
        }
    }

    /// The same declaration with role `role`.
    pub const fn role(self, role: ParamRole) -> IntParam {
        IntParam { role, ..self }
    }

    /// The config key.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The declared default.
    pub const fn default(&self) -> i64 {
        self.default
    }

    /// The smallest and largest values accepted.
    pub const fn range(&self) -> (i64, i64) {
        (self.min, self.max)
    }

    /// The entry of the plugin's `PARAMS`.
    pub const fn spec(&self) -> ParamSpec {
        spec(
            self.name,
            ParamKind::Int,
            self.default_text,
            self.range_text,
            self.doc,
            self.role,
        )
    }

    /// The config's value, else the declared default; refused outside the range.
    pub fn get(&self, params: &Params) -> Result<i64, String> {
        self.get_or(params, self.default)
    }

    /// The config's value, else `fallback` (a default that depends on other parameters);
    /// either is refused outside the range.
    pub fn get_or(&self, params: &Params, fallback: i64) -> Result<i64, String> {
        let v = params.raw_int(self.name, fallback)?;
        if (self.min..=self.max).contains(&v) {
            params.record(self.name, v.to_string());
            Ok(v)
        } else {
            Err(out_of_range(self.name, self.range_text, &v.to_string()))
        }
    }
}

/// Which ends of a [`FloatParam`]'s range are included.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bounds {
    /// `min <= x <= max`, printed `[min, max]`.
    Closed,
    /// `min < x <= max`, printed `(min, max]`.
    OpenBelow,
    /// `min < x`, finite, printed `> min` (`max` unused).
    Above,
    /// `min <= x`, finite, printed `>= min` (`max` unused).
    AtLeast,
}

/// A float parameter (an integer in the config is converted), finite and within its range.
/// Declared with [`float_param!`](crate::float_param).
#[derive(Clone, Copy, Debug)]
pub struct FloatParam {
    name: &'static str,
    default: Option<f64>,
    min: f64,
    max: f64,
    bounds: Bounds,
    doc: &'static str,
    role: ParamRole,
    default_text: &'static str,
    range_text: &'static str,
}

impl FloatParam {
    /// Used by [`float_param!`](crate::float_param), which passes the literals' own text; call the macro instead.
    #[doc(hidden)]
    #[allow(clippy::too_many_arguments)]
    pub const fn __declare(
        name: &'static str,
        default: Option<f64>,
        min: f64,
        max: f64,
        bounds: Bounds,
        doc: &'static str,
        default_text: &'static str,
        range_text: &'static str,
    ) -> FloatParam {
        if let Some(d) = default {
            assert!(
                accepts(d, min, max, bounds),
                "the default is outside the range"
            );
        }
        FloatParam {
            name,
            default,
            min,
            max,
            bounds,
            doc,
            role: ParamRole::None,
            default_text,
            range_text,
        }
    }

    /// The same declaration with role `role`.
    pub const fn role(self, role: ParamRole) -> FloatParam {
        FloatParam { role, ..self }
    }

    /// The config key.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The declared default (`None`: it depends on other parameters, see the doc).
    pub const fn default(&self) -> Option<f64> {
        self.default
    }

    /// Whether `x` is in the range.
    pub const fn accepts(&self, x: f64) -> bool {
        accepts(x, self.min, self.max, self.bounds)
    }

    /// The entry of the plugin's `PARAMS`.
    pub const fn spec(&self) -> ParamSpec {
        spec(
            self.name,
            ParamKind::Float,
            self.default_text,
            self.range_text,
            self.doc,
            self.role,
        )
    }

    /// The config's value, else the declared default; refused outside the range. A
    /// declaration without a default ([`float_param!`](crate::float_param)'s `unset` form) is read with
    /// [`FloatParam::get_or`]; `get` on one that the config left out is an error.
    pub fn get(&self, params: &Params) -> Result<f64, String> {
        match self.default {
            Some(d) => self.get_or(params, d),
            None if params.is_set(self.name) => self.get_or(params, f64::NAN),
            None => Err(format!(
                "parameter '{}' needs a value (its default is {})",
                self.name, self.default_text
            )),
        }
    }

    /// The config's value, else `fallback`; either is refused outside the range.
    pub fn get_or(&self, params: &Params, fallback: f64) -> Result<f64, String> {
        let v = params.raw_float(self.name, fallback)?;
        if self.accepts(v) {
            params.record(self.name, toml_float(v));
            Ok(v)
        } else {
            Err(out_of_range(self.name, self.range_text, &v.to_string()))
        }
    }
}

const fn accepts(x: f64, min: f64, max: f64, bounds: Bounds) -> bool {
    x.is_finite()
        && match bounds {
            Bounds::Closed => min <= x && x <= max,
            Bounds::OpenBelow => min < x && x <= max,
            Bounds::Above => min < x,
            Bounds::AtLeast => min <= x,
        }
}

/// A boolean parameter. Declared with [`bool_param!`](crate::bool_param).
#[derive(Clone, Copy, Debug)]
pub struct BoolParam {
    name: &'static str,
    default: bool,
    doc: &'static str,
    role: ParamRole,
    default_text: &'static str,
}

impl BoolParam {
    /// Used by [`bool_param!`](crate::bool_param); call the macro instead.
    #[doc(hidden)]
    pub const fn __declare(
        name: &'static str,
        default: bool,
        doc: &'static str,
        default_text: &'static str,
    ) -> BoolParam {
        BoolParam {
            name,
            default,
            doc,
            role: ParamRole::None,
            default_text,
        }
    }

    /// The same declaration with role `role`.
    pub const fn role(self, role: ParamRole) -> BoolParam {
        BoolParam { role, ..self }
    }

    /// The config key.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The declared default.
    pub const fn default(&self) -> bool {
        self.default
    }

    /// The entry of the plugin's `PARAMS`.
    pub const fn spec(&self) -> ParamSpec {
        spec(
            self.name,
            ParamKind::Bool,
            self.default_text,
            "",
            self.doc,
            self.role,
        )
    }

    /// The config's value, else the declared default.
    pub fn get(&self, params: &Params) -> Result<bool, String> {
        params.boolean(self.name, self.default)
    }
}

/// A string parameter that must be one of a fixed list. Declared with [`choice_param!`](crate::choice_param).
#[derive(Clone, Copy, Debug)]
pub struct ChoiceParam {
    name: &'static str,
    default: &'static str,
    choices: &'static [&'static str],
    doc: &'static str,
    role: ParamRole,
    default_text: &'static str,
    range_text: &'static str,
}

impl ChoiceParam {
    /// Used by [`choice_param!`](crate::choice_param); call the macro instead.
    #[doc(hidden)]
    pub const fn __declare(
        name: &'static str,
        default: &'static str,
        choices: &'static [&'static str],
        doc: &'static str,
        default_text: &'static str,
        range_text: &'static str,
    ) -> ChoiceParam {
        assert!(
            contains(choices, default),
            "the default is not one of the choices"
        );
        ChoiceParam {
            name,
            default,
            choices,
            doc,
            role: ParamRole::None,
            default_text,
            range_text,
        }
    }

    /// The same declaration with role `role`.
    pub const fn role(self, role: ParamRole) -> ChoiceParam {
        ChoiceParam { role, ..self }
    }

    /// The config key.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The declared default.
    pub const fn default(&self) -> &'static str {
        self.default
    }

    /// The values accepted.
    pub const fn choices(&self) -> &'static [&'static str] {
        self.choices
    }

    /// The entry of the plugin's `PARAMS`.
    pub const fn spec(&self) -> ParamSpec {
        spec(
            self.name,
            ParamKind::String,
            self.default_text,
            self.range_text,
            self.doc,
            self.role,
        )
    }

    /// The config's choice, else the declared default, as the declaration's own `'static`
    /// string (so a `match` on it sees exactly the declared spellings).
    pub fn get(&self, params: &Params) -> Result<&'static str, String> {
        self.get_or(params, self.default)
    }

    /// The config's choice, else `fallback` (a default that depends on other parameters);
    /// either must be one of the choices.
    pub fn get_or(&self, params: &Params, fallback: &'static str) -> Result<&'static str, String> {
        let given = params.choice(self.name, fallback, self.choices)?;
        Ok(self
            .choices
            .iter()
            .find(|c| **c == given)
            .copied()
            .unwrap_or(fallback))
    }
}

const fn contains(choices: &[&str], s: &str) -> bool {
    let mut i = 0;
    while i < choices.len() {
        let c = choices[i].as_bytes();
        let b = s.as_bytes();
        if c.len() == b.len() {
            let mut j = 0;
            while j < c.len() && c[j] == b[j] {
                j += 1;
            }
            if j == c.len() {
                return true;
            }
        }
        i += 1;
    }
    false
}

/// A free-text string parameter (checked by the plugin, e.g. a pattern). Declared with
/// [`string_param!`](crate::string_param).
#[derive(Clone, Copy, Debug)]
pub struct StringParam {
    name: &'static str,
    default: &'static str,
    doc: &'static str,
    role: ParamRole,
    default_text: &'static str,
}

impl StringParam {
    /// Used by [`string_param!`](crate::string_param); call the macro instead.
    #[doc(hidden)]
    pub const fn __declare(
        name: &'static str,
        default: &'static str,
        doc: &'static str,
        default_text: &'static str,
    ) -> StringParam {
        StringParam {
            name,
            default,
            doc,
            role: ParamRole::None,
            default_text,
        }
    }

    /// The config key.
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// The declared default.
    pub const fn default(&self) -> &'static str {
        self.default
    }

    /// The entry of the plugin's `PARAMS`.
    pub const fn spec(&self) -> ParamSpec {
        spec(
            self.name,
            ParamKind::String,
            self.default_text,
            "",
            self.doc,
            self.role,
        )
    }

    /// The config's value, else the declared default.
    pub fn get<'a>(&self, params: &Params<'a>) -> Result<&'a str, String> {
        params.string(self.name, self.default)
    }
}

/// The spec of a [`ParamKind::MutationList`] parameter (the host reads the list and hands
/// the strategies to `create`): required, no default.
pub const fn mutation_list(name: &'static str, doc: &'static str) -> ParamSpec {
    spec(
        name,
        ParamKind::MutationList,
        "(required)",
        "1 to 8 entries",
        doc,
        ParamRole::None,
    )
}

/// The spec of a [`ParamKind::MutationList`] parameter with a default: `default` is the list
/// the host creates when the config gives none, as TOML writes it, an array of inline tables
/// (`[{ plugin = "blow" }, { plugin = "drill", width = "narrow" }]`; ABI 7). The host marks
/// such a list ([`Params::mutation_list_defaulted`](crate::Params::mutation_list_defaulted)).
pub const fn mutation_list_or(
    name: &'static str,
    default: &'static str,
    doc: &'static str,
) -> ParamSpec {
    spec(
        name,
        ParamKind::MutationList,
        default,
        "1 to 8 entries",
        doc,
        ParamRole::None,
    )
}

const fn spec(
    name: &'static str,
    kind: ParamKind,
    default: &'static str,
    range: &'static str,
    doc: &'static str,
    role: ParamRole,
) -> ParamSpec {
    ParamSpec {
        name: StrRef::new(name),
        kind,
        default: StrRef::new(default),
        range: StrRef::new(range),
        doc: StrRef::new(doc),
        role,
    }
}

/// The standard one-line refusal of a value outside its declared range.
fn out_of_range(name: &str, range: &str, got: &str) -> String {
    if let Some(min) = range.strip_prefix("> ") {
        format!("parameter '{name}' must be greater than {min}, got {got}")
    } else if let Some(min) = range.strip_prefix(">= ") {
        format!("parameter '{name}' must be at least {min}, got {got}")
    } else {
        format!("parameter '{name}' must be in {range}, got {got}")
    }
}

/// Declares an [`IntParam`]: `int_param!(name, default, min..=max, doc)`, literals only.
/// A default outside the range fails to compile.
#[macro_export]
macro_rules! int_param {
    ($name:literal, $default:literal, $min:literal ..= $max:literal, $doc:literal) => {
        $crate::declare::IntParam::__declare(
            $name,
            $default,
            $min,
            $max,
            $doc,
            stringify!($default),
            concat!(stringify!($min), "..=", stringify!($max)),
        )
    };
}

/// Declares a [`FloatParam`]: `float_param!(name, default, RANGE, doc)` with RANGE one of
/// `min <= x <= max`, `min < x <= max`, `min < x`, `min <= x` (literals; every value must
/// also be finite). `float_param!(name, unset "text", RANGE, doc)` declares one without a
/// default (it depends on other parameters; `text` says how, e.g. `"by width"`), read with
/// [`FloatParam::get_or`].
#[macro_export]
macro_rules! float_param {
    (@range $name:literal, $d:expr, $dt:expr, $min:literal <= x <= $max:literal, $doc:literal) => {
        $crate::declare::FloatParam::__declare($name, $d, $min, $max, $crate::declare::Bounds::Closed, $doc, $dt,
            concat!("[", stringify!($min), ", ", stringify!($max), "]"))
    };
    (@range $name:literal, $d:expr, $dt:expr, $min:literal < x <= $max:literal, $doc:literal) => {
        $crate::declare::FloatParam::__declare($name, $d, $min, $max, $crate::declare::Bounds::OpenBelow, $doc, $dt,
            concat!("(", stringify!($min), ", ", stringify!($max), "]"))
    };
    (@range $name:literal, $d:expr, $dt:expr, $min:literal < x, $doc:literal) => {
        $crate::declare::FloatParam::__declare($name, $d, $min, f64::INFINITY, $crate::declare::Bounds::Above, $doc, $dt,
            concat!("> ", stringify!($min)))
    };
    (@range $name:literal, $d:expr, $dt:expr, $min:literal <= x, $doc:literal) => {
        $crate::declare::FloatParam::__declare($name, $d, $min, f64::INFINITY, $crate::declare::Bounds::AtLeast, $doc, $dt,
            concat!(">= ", stringify!($min)))
    };
    ($name:literal, unset $text:literal, $($range:tt)+) => {
        $crate::float_param!(@range $name, None, $text, $($range)+)
    };
    ($name:literal, $default:literal, $($range:tt)+) => {
        $crate::float_param!(@range $name, Some($default), stringify!($default), $($range)+)
    };
}

/// Declares a [`BoolParam`]: `bool_param!(name, default, doc)`.
#[macro_export]
macro_rules! bool_param {
    ($name:literal, $default:literal, $doc:literal) => {
        $crate::declare::BoolParam::__declare($name, $default, $doc, stringify!($default))
    };
}

/// Declares a [`ChoiceParam`]: `choice_param!(name, default, [choice, …], doc)`. A default
/// that is not one of the choices fails to compile.
#[macro_export]
macro_rules! choice_param {
    ($name:literal, $default:literal, [$first:literal $(, $rest:literal)* $(,)?], $doc:literal) => {
        $crate::declare::ChoiceParam::__declare(
            $name,
            $default,
            &[$first $(, $rest)*],
            $doc,
            stringify!($default),
            concat!(stringify!($first) $(, " | ", stringify!($rest))*),
        )
    };
}

/// Declares a [`StringParam`]: `string_param!(name, default, doc)`.
#[macro_export]
macro_rules! string_param {
    ($name:literal, $default:literal, $doc:literal) => {
        $crate::declare::StringParam::__declare($name, $default, $doc, stringify!($default))
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::ParamValue;

    const DEPTH: IntParam = int_param!("depth", 8, 1..=32, "depth").role(ParamRole::PathDepth);
    const SURVIVAL: FloatParam = float_param!("survival", 0.95, 0.01 <= x <= 0.999, "cap");
    const CAP: FloatParam = float_param!("cap", 10.0, 0.0 < x <= 90.0, "degrees");
    const M: FloatParam = float_param!("m", 8.0, 0.0 < x, "positive");
    const BY: FloatParam = float_param!("by", unset "by width", 0.0 < x <= 90.0, "degrees");
    const LAYERS: BoolParam = bool_param!("layers", false, "layers").role(ParamRole::Layers);
    const WIDTH: ChoiceParam = choice_param!("width", "narrow", ["narrow", "wide"], "width");
    const PATTERN: StringParam = string_param!("pattern", "all", "a pattern");

    fn int(name: &'static str, v: i64) -> ParamValue {
        ParamValue {
            name: StrRef::new(name),
            kind: ParamKind::Int,
            int: v,
            float: 0.0,
            boolean: 0,
            string: StrRef::EMPTY,
        }
    }

    fn float(name: &'static str, v: f64) -> ParamValue {
        ParamValue {
            kind: ParamKind::Float,
            float: v,
            ..int(name, 0)
        }
    }

    fn string(name: &'static str, v: &'static str) -> ParamValue {
        ParamValue {
            kind: ParamKind::String,
            string: StrRef::new(v),
            ..int(name, 0)
        }
    }

    fn text(s: StrRef) -> &'static str {
        // SAFETY: the specs of this module point to static strings.
        unsafe { s.as_str() }
    }

    #[test]
    fn specs_carry_the_declared_default_range_and_role() {
        let s = DEPTH.spec();
        assert_eq!(
            (text(s.name), s.kind, text(s.default), text(s.range), s.role),
            ("depth", ParamKind::Int, "8", "1..=32", ParamRole::PathDepth)
        );
        assert_eq!(text(SURVIVAL.spec().range), "[0.01, 0.999]");
        assert_eq!(text(SURVIVAL.spec().default), "0.95");
        assert_eq!(text(CAP.spec().range), "(0.0, 90.0]");
        assert_eq!(text(M.spec().range), "> 0.0");
        assert_eq!(text(BY.spec().default), "by width");
        assert_eq!(text(WIDTH.spec().default), "\"narrow\"");
        assert_eq!(text(WIDTH.spec().range), "\"narrow\" | \"wide\"");
        assert_eq!(text(LAYERS.spec().default), "false");
        assert_eq!(LAYERS.spec().role, ParamRole::Layers);
        assert_eq!(text(PATTERN.spec().default), "\"all\"");
        assert_eq!(text(PATTERN.spec().range), "");
    }

    #[test]
    fn absent_values_are_the_declared_defaults_and_are_recorded() {
        let p = Params::from_slice(&[]);
        assert_eq!(DEPTH.get(&p), Ok(8));
        assert_eq!(SURVIVAL.get(&p), Ok(0.95));
        assert_eq!(LAYERS.get(&p), Ok(false));
        assert_eq!(WIDTH.get(&p), Ok("narrow"));
        assert_eq!(PATTERN.get(&p), Ok("all"));
        assert_eq!(BY.get_or(&p, 2.0), Ok(2.0));
        assert_eq!(
            BY.get(&p),
            Err("parameter 'by' needs a value (its default is by width)".into())
        );
        let r = p.resolved();
        let r: Vec<(&str, &str)> = r.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
        assert_eq!(
            r,
            [
                ("depth", "8"),
                ("survival", "0.95"),
                ("layers", "false"),
                ("width", "\"narrow\""),
                ("pattern", "\"all\""),
                ("by", "2.0"),
            ]
        );
    }

    #[test]
    fn values_outside_the_range_are_refused_in_one_line() {
        let v = [
            int("depth", 40),
            float("survival", 1.5),
            float("cap", 0.0),
            float("m", -1.0),
            string("width", "medium"),
        ];
        let p = Params::from_slice(&v);
        assert_eq!(
            DEPTH.get(&p),
            Err("parameter 'depth' must be in 1..=32, got 40".into())
        );
        assert_eq!(
            SURVIVAL.get(&p),
            Err("parameter 'survival' must be in [0.01, 0.999], got 1.5".into())
        );
        assert_eq!(
            CAP.get(&p),
            Err("parameter 'cap' must be in (0.0, 90.0], got 0".into())
        );
        assert_eq!(
            M.get(&p),
            Err("parameter 'm' must be greater than 0.0, got -1".into())
        );
        assert_eq!(
            WIDTH.get(&p),
            Err("parameter 'width' must be one of [\"narrow\", \"wide\"], got \"medium\"".into())
        );
        // Refused values are not recorded as resolved.
        assert_eq!(p.resolved(), []);
        // A fallback outside the range is refused as well.
        assert!(DEPTH.get_or(&Params::from_slice(&[]), 0).is_err());
        // Non-finite floats are never in a range.
        let nan = [float("m", f64::NAN)];
        assert!(M.get(&Params::from_slice(&nan)).is_err());
    }

    #[test]
    fn set_values_are_read_and_recorded() {
        let v = [int("depth", 32), int("cap", 90), string("width", "wide")];
        let p = Params::from_slice(&v);
        assert_eq!(DEPTH.get(&p), Ok(32));
        assert_eq!(CAP.get(&p), Ok(90.0));
        assert_eq!(WIDTH.get_or(&p, "narrow"), Ok("wide"));
        assert_eq!(
            p.resolved(),
            [
                ("depth".to_string(), "32".to_string()),
                ("cap".to_string(), "90.0".to_string()),
                ("width".to_string(), "\"wide\"".to_string()),
            ]
        );
    }
}
