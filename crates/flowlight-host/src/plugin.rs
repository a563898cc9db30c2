//! Finding, loading and checking plugins, and the host-side wrappers of their tables.

use crate::params::build_params;
use flowlight_sdk::abi::{
    self, ErrorBuf, FilmTable, IntegratorInfo, IntegratorTable, MutationRef, MutationTable,
    ParamRole, ParamSpec, PluginDeclaration, ResolvedList, SceneView, StatList, StatMerge,
    StatSpec, Status, StrRef, TracerTable, WorkUnit,
};
use flowlight_sdk::stats::MAX_COUNTERS;
use flowlight_sdk::{ParamKind, PluginKind, MAX_MUTATIONS};
use libloading::Library;
use std::ffi::c_void;
use std::path::{Path, PathBuf};
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    #[error("plugin '{name}' not found (looked for {file} in: {searched})")]
    NotFound {
        name: String,
        file: String,
        searched: String,
    },
    #[error("cannot load plugin {path}: {message}")]
    Load { path: PathBuf, message: String },
    #[error("plugin {path} was refused before loading: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error(
        "plugin {path} does not export `flowlight_plugin_declaration`; is it a Flowlight plugin?"
    )]
    NoDeclaration { path: PathBuf },
    #[error("plugin {path} was refused: {what} mismatch (plugin has {plugin}, host has {host}); rebuild the plugin against this host's SDK")]
    Mismatch {
        path: PathBuf,
        what: &'static str,
        plugin: String,
        host: String,
    },
    #[error("plugin {path} is {} plugin, but the config uses it as {}", kind_phrase(*found), kind_phrase(*expected))]
    WrongKind {
        path: PathBuf,
        expected: PluginKind,
        found: PluginKind,
    },
    #[error("plugin '{name}' ({path}): {message}")]
    Call {
        name: String,
        path: PathBuf,
        message: String,
    },
}

/// [`abi::DECLARATION_SYMBOL`] without its NUL, as the ELF check looks it up.
fn declaration_name() -> &'static str {
    let bytes = abi::DECLARATION_SYMBOL;
    std::str::from_utf8(&bytes[..bytes.len() - 1]).unwrap_or_default()
}

/// An error and its sources on one line: libloading's `dlopen failed` keeps the loader's
/// reason (`dlerror`) in its source.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut msg = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        msg = format!("{msg}: {c}");
        cause = c.source();
    }
    msg.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// "an integrator", "a mutation": a plugin kind with its article, for messages.
fn kind_phrase(kind: PluginKind) -> &'static str {
    match kind {
        PluginKind::Integrator => "an integrator",
        PluginKind::Mutation => "a mutation",
    }
}

/// A parameter as listed by `flowlight plugins`.
#[derive(Clone, Debug)]
pub struct ParamInfo {
    pub name: String,
    pub kind: ParamKind,
    pub default: String,
    /// The values accepted as the docs print them (`1..=32`); empty: any of the type.
    pub range: String,
    pub doc: String,
    /// What host tools may rely on the parameter for.
    pub role: ParamRole,
}

/// A loaded and checked plugin library. The declaration it points into lives as long as the
/// library, which this value keeps loaded.
pub struct PluginLibrary {
    pub path: PathBuf,
    pub name: String,
    pub kind: PluginKind,
    pub description: String,
    pub sdk_version: String,
    pub rustc_version: String,
    decl: *const PluginDeclaration,
    // Dropped last: every pointer above points into it.
    _library: Library,
}

// SAFETY: the declaration is immutable static data of the loaded library.
unsafe impl Send for PluginLibrary {}
unsafe impl Sync for PluginLibrary {}

/// File name of plugin `name` on this platform: `libflowlight_NAME.so` and the like.
pub fn plugin_file_name(name: &str) -> String {
    let stem = format!("flowlight_{}", name.replace('-', "_"));
    format!(
        "{}{stem}{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    )
}

/// Directories searched for plugins, in order: those the config names, then
/// `FLOWLIGHT_PLUGIN_PATH`, then the executable's directory (and, for test executables in
/// Cargo's `deps/`, its parent).
pub fn search_dirs(config_dirs: &[PathBuf]) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = config_dirs.to_vec();
    if let Some(paths) = std::env::var_os("FLOWLIGHT_PLUGIN_PATH") {
        dirs.extend(std::env::split_paths(&paths).filter(|p| !p.as_os_str().is_empty()));
    }
    if let Some(exe_dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(Path::to_path_buf))
    {
        if exe_dir.file_name().is_some_and(|n| n == "deps") {
            if let Some(parent) = exe_dir.parent() {
                dirs.push(parent.to_path_buf());
            }
        }
        dirs.push(exe_dir);
    }
    dirs
}

/// Finds plugin `name` in `dirs`. A name containing a path separator or ending in the
/// platform's library suffix is taken as a file path.
pub fn find_plugin(name: &str, dirs: &[PathBuf]) -> Result<PathBuf, PluginError> {
    if name.contains(std::path::MAIN_SEPARATOR) || name.ends_with(std::env::consts::DLL_SUFFIX) {
        let p = PathBuf::from(name);
        return if p.is_file() {
            Ok(p)
        } else {
            Err(PluginError::NotFound {
                name: name.into(),
                file: name.into(),
                searched: "(given as a path)".into(),
            })
        };
    }
    let file = plugin_file_name(name);
    dirs.iter()
        .map(|d| d.join(&file))
        .find(|p| p.is_file())
        .ok_or_else(|| PluginError::NotFound {
            name: name.into(),
            file,
            searched: dirs
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// Every plugin file in `dirs` (for `flowlight plugins`), deduplicated by file name.
pub fn list_plugin_files(dirs: &[PathBuf]) -> Vec<PathBuf> {
    let prefix = format!("{}flowlight_", std::env::consts::DLL_PREFIX);
    let mut seen = std::collections::BTreeSet::new();
    let mut out = Vec::new();
    for d in dirs {
        let Ok(entries) = std::fs::read_dir(d) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                    n.starts_with(&prefix) && n.ends_with(std::env::consts::DLL_SUFFIX)
                })
            })
            .collect();
        files.sort();
        for f in files {
            if seen.insert(f.file_name().map(|n| n.to_os_string())) {
                out.push(f);
            }
        }
    }
    out
}

impl PluginLibrary {
    /// Loads the library at `path` and checks its declaration before anything else is called:
    /// ABI version, layout hash, SDK version and rustc version must all equal the host's.
    pub fn load(path: &Path) -> Result<PluginLibrary, PluginError> {
        let path = path.to_path_buf();
        // Before anything is mapped: a truncated or foreign file would crash the process
        // inside dlopen (SIGBUS) instead of being refused.
        flowlight_elf::check_library(&path, declaration_name()).map_err(|e| {
            if e.0.starts_with("does not export") {
                PluginError::NoDeclaration { path: path.clone() }
            } else {
                PluginError::Invalid {
                    path: path.clone(),
                    message: e.0,
                }
            }
        })?;
        // SAFETY: loading a library runs its initialisers; plugins are trusted code the user
        // chose in the config (docs/architecture.md, "Trust boundary").
        let library = unsafe { Library::new(&path) }.map_err(|e| PluginError::Load {
            path: path.clone(),
            message: error_chain(&e),
        })?;
        // SAFETY: the symbol's type is fixed by the ABI.
        let decl = unsafe {
            let f = library
                .get::<unsafe extern "C" fn() -> *const PluginDeclaration>(abi::DECLARATION_SYMBOL)
                .map_err(|_| PluginError::NoDeclaration { path: path.clone() })?;
            f()
        };
        if decl.is_null() {
            return Err(PluginError::NoDeclaration { path });
        }
        // SAFETY: `abi_version` and `layout_hash` keep their place in every ABI version; the
        // rest is read only after both match.
        let d = unsafe { &*decl };
        let mismatch = |what, plugin: String, host: String| PluginError::Mismatch {
            path: path.clone(),
            what,
            plugin,
            host,
        };
        if d.abi_version != abi::ABI_VERSION {
            return Err(mismatch(
                "ABI version",
                d.abi_version.to_string(),
                abi::ABI_VERSION.to_string(),
            ));
        }
        if d.layout_hash != abi::layout_hash() {
            return Err(mismatch(
                "type layout",
                format!("{:016x}", d.layout_hash),
                format!("{:016x}", abi::layout_hash()),
            ));
        }
        // SAFETY: the declaration's strings are static data of the library.
        let (sdk, rustc, name, description) = unsafe {
            (
                d.sdk_version.as_str(),
                d.rustc_version.as_str(),
                d.name.as_str(),
                d.description.as_str(),
            )
        };
        if sdk != abi::SDK_VERSION {
            return Err(mismatch("SDK version", sdk.into(), abi::SDK_VERSION.into()));
        }
        if rustc != abi::RUSTC_VERSION {
            return Err(mismatch(
                "rustc version",
                rustc.into(),
                abi::RUSTC_VERSION.into(),
            ));
        }
        let kind = d.kind;
        let table_ok = match kind {
            PluginKind::Integrator => !d.integrator.is_null(),
            PluginKind::Mutation => !d.mutation.is_null(),
        };
        if !table_ok {
            return Err(PluginError::NoDeclaration { path });
        }
        Ok(PluginLibrary {
            name: name.to_string(),
            kind,
            description: description.to_string(),
            sdk_version: sdk.to_string(),
            rustc_version: rustc.to_string(),
            path,
            decl,
            _library: library,
        })
    }

    fn decl(&self) -> &PluginDeclaration {
        // SAFETY: checked non-null at load; valid while the library is loaded.
        unsafe { &*self.decl }
    }

    pub fn param_specs(&self) -> &[ParamSpec] {
        let d = self.decl();
        if d.params.is_null() || d.param_count == 0 {
            return &[];
        }
        // SAFETY: the plugin declares `param_count` static specs.
        unsafe { std::slice::from_raw_parts(d.params, d.param_count) }
    }

    pub fn params(&self) -> Vec<ParamInfo> {
        self.param_specs()
            .iter()
            .map(|s| unsafe {
                // SAFETY: static strings of the loaded library.
                ParamInfo {
                    name: s.name.as_str().into(),
                    kind: s.kind,
                    default: s.default.as_str().into(),
                    range: s.range.as_str().into(),
                    doc: s.doc.as_str().into(),
                    role: s.role,
                }
            })
            .collect()
    }

    /// The default of the integrator's mutation list, when its spec declares one: the TOML
    /// text of an array of inline tables, the list the host creates when the config gives
    /// none (ABI 7; `flowlight_sdk::declare::mutation_list_or`).
    pub fn mutation_list_default(&self) -> Option<String> {
        self.params()
            .into_iter()
            .find(|p| p.kind == ParamKind::MutationList)
            .map(|p| p.default)
            .filter(|d| d.trim_start().starts_with('['))
    }

    /// The name of the integrator's [`ParamKind::MutationList`] parameter, the one config key
    /// the host reads a mutation list from (`None`: the integrator takes no mutations). An
    /// integrator declaring two is refused: the host would not know which list is meant.
    pub fn mutation_list_param(&self) -> Result<Option<String>, PluginError> {
        let lists: Vec<String> = self
            .params()
            .into_iter()
            .filter(|p| p.kind == ParamKind::MutationList)
            .map(|p| p.name)
            .collect();
        match lists.as_slice() {
            [] => Ok(None),
            [one] => Ok(Some(one.clone())),
            many => Err(PluginError::Call {
                name: self.name.clone(),
                path: self.path.clone(),
                message: format!(
                    "declares {} mutation-list parameters ({}); an integrator takes at most one",
                    many.len(),
                    many.join(", ")
                ),
            }),
        }
    }

    fn integrator_table(&self) -> Result<IntegratorTable, PluginError> {
        match self.kind {
            // SAFETY: non-null checked at load.
            PluginKind::Integrator => Ok(unsafe { *self.decl().integrator }),
            found => Err(PluginError::WrongKind {
                path: self.path.clone(),
                expected: PluginKind::Integrator,
                found,
            }),
        }
    }

    /// The mutation table, for mutation plugins.
    pub fn mutation_table(&self) -> Result<MutationTable, PluginError> {
        match self.kind {
            // SAFETY: non-null checked at load.
            PluginKind::Mutation => Ok(unsafe { *self.decl().mutation }),
            found => Err(PluginError::WrongKind {
                path: self.path.clone(),
                expected: PluginKind::Mutation,
                found,
            }),
        }
    }

    fn call_error(&self, status: Status, err: &ErrorBuf) -> PluginError {
        let what = if status == Status::Panic {
            "panicked"
        } else {
            "failed"
        };
        let msg = err.message();
        PluginError::Call {
            name: self.name.clone(),
            path: self.path.clone(),
            message: if msg.starts_with("panicked") || status != Status::Panic {
                msg
            } else {
                format!("{what}: {msg}")
            },
        }
    }
}

/// The values of `after` that `before` lacks or holds otherwise, as TOML lines
/// (`name = value`): what an integrator decided in `prepare`.
pub fn decided_snippet(before: &[(String, String)], after: &[(String, String)]) -> String {
    after
        .iter()
        .filter(|(n, v)| !before.iter().any(|(bn, bv)| bn == n && bv == v))
        .map(|(n, v)| format!("{n} = {v}\n"))
        .collect()
}

/// A mutation plugin instance created from a `[[integrator.mutations]]` entry.
pub struct MutationInstance {
    plugin: Arc<PluginLibrary>,
    table: Box<MutationTable>,
    instance: *mut c_void,
    /// Name as the integrator sees it (the plugin name).
    name: String,
    /// Selection probability p(sᵢ): the config's weight normalised with the list's others by
    /// [`normalised_weights`] (the caller's one call of it).
    weight: f64,
    /// The parameter values the instance resolved (owned by the instance, valid until
    /// `destroy`).
    resolved: ResolvedList,
    /// The counters the instance declared (owned by the instance, valid until `destroy`).
    stats: StatList,
}

// SAFETY: the SDK requires mutations to be Send + Sync.
unsafe impl Send for MutationInstance {}
unsafe impl Sync for MutationInstance {}

impl MutationInstance {
    /// Creates an instance of a mutation plugin with `params` from the config; `weight` is
    /// its selection probability, from [`normalised_weights`] over the whole list.
    ///
    /// # Safety
    /// The data `view` points to must outlive the instance.
    pub unsafe fn create(
        plugin: Arc<PluginLibrary>,
        params: &[(String, toml::Value)],
        weight: f64,
        view: &SceneView,
    ) -> Result<MutationInstance, PluginError> {
        let table = Box::new(plugin.mutation_table()?);
        let list = build_params(&plugin.name, plugin.param_specs(), params).map_err(|message| {
            PluginError::Call {
                name: plugin.name.clone(),
                path: plugin.path.clone(),
                message,
            }
        })?;
        let mut instance = std::ptr::null_mut();
        let mut resolved = ResolvedList::EMPTY;
        let mut stats = StatList::EMPTY;
        let mut err = ErrorBuf::default();
        // SAFETY: the table is a checked mutation plugin's; the parameter list and `view` are
        // valid for the call, and the caller keeps `view`'s data alive for the instance.
        let status = unsafe {
            (table.create)(
                list.as_slice().as_ptr(),
                list.as_slice().len(),
                view,
                &mut instance,
                &mut stats,
                &mut resolved,
                &mut err,
            )
        };
        if status != Status::Ok {
            return Err(plugin.call_error(status, &err));
        }
        let name = plugin.name.clone();
        let inst = MutationInstance {
            plugin,
            table,
            instance,
            name,
            weight,
            resolved,
            stats,
        };
        // The SDK's builder refuses more; a plugin that wrote its own glue might not.
        if stats.count > MAX_COUNTERS || (stats.count > 0 && stats.specs.is_null()) {
            return Err(PluginError::Call {
                name: inst.plugin.name.clone(),
                path: inst.plugin.path.clone(),
                message: format!(
                    "declares {} statistics counters, at most {MAX_COUNTERS} are supported",
                    stats.count
                ),
            });
        }
        Ok(inst)
    }

    /// The statistics counters the mutation declared.
    pub fn stat_specs(&self) -> &[StatSpec] {
        if self.stats.specs.is_null() || self.stats.count == 0 {
            return &[];
        }
        // SAFETY: owned by the instance until `destroy` (in our Drop), `count` entries.
        unsafe { std::slice::from_raw_parts(self.stats.specs, self.stats.count) }
    }

    pub fn plugin(&self) -> &PluginLibrary {
        &self.plugin
    }

    /// The selection probability p(sᵢ) (normalised over the list).
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The parameter values the instance resolved (after defaults), `(name, TOML text)`.
    pub fn resolved_params(&self) -> Vec<(String, String)> {
        // SAFETY: owned by the instance until `destroy` (in our Drop).
        unsafe { resolved_pairs(&self.resolved) }
    }
}

/// The entries of a [`ResolvedList`] as owned pairs.
///
/// # Safety
/// `list` must come from a live instance's `create` (entries valid, `count` of them).
unsafe fn resolved_pairs(list: &ResolvedList) -> Vec<(String, String)> {
    if list.entries.is_null() || list.count == 0 {
        return Vec::new();
    }
    // SAFETY: the caller upholds this function's contract.
    unsafe {
        std::slice::from_raw_parts(list.entries, list.count)
            .iter()
            .map(|e| (e.name.as_str().to_string(), e.value.as_str().to_string()))
            .collect()
    }
}

/// Validates the weights of a mutation list and normalises them to sum to 1: the one place
/// where weights are checked. Each weight must be finite and ≥ 0 (0 keeps a strategy in the
/// list, e.g. in the mixture density, without ever choosing it), their sum positive and
/// finite, and the list at most [`MAX_MUTATIONS`] long. `list` is the parameter's name
/// (`mutations`), `entries` the plugin name and weight of each entry; errors name the entry
/// as `integrator.LIST[i] (plugin "NAME")`.
pub fn normalised_weights(list: &str, entries: &[(&str, f64)]) -> Result<Vec<f64>, String> {
    if entries.len() > MAX_MUTATIONS {
        return Err(format!(
            "integrator.{list}: {} entries, at most {MAX_MUTATIONS} mutation strategies are supported (flowlight_sdk::MAX_MUTATIONS)",
            entries.len()
        ));
    }
    let mut total = 0.0;
    for (i, &(name, w)) in entries.iter().enumerate() {
        let at = format!("integrator.{list}[{i}] (plugin \"{name}\")");
        if !w.is_finite() {
            return Err(format!("{at}: `weight` must be finite, got {w}"));
        }
        if w < 0.0 {
            return Err(format!("{at}: `weight` must not be negative, got {w}"));
        }
        total += w;
    }
    if entries.is_empty() {
        return Ok(Vec::new());
    }
    if total <= 0.0 {
        return Err(format!(
            "integrator.{list}: the weights sum to 0; give at least one entry a positive `weight`"
        ));
    }
    if !total.is_finite() {
        return Err(format!(
            "integrator.{list}: the weights sum to more than the largest f64; use smaller weights (only their ratios matter)"
        ));
    }
    Ok(entries.iter().map(|&(_, w)| w / total).collect())
}

impl Drop for MutationInstance {
    fn drop(&mut self) {
        // SAFETY: created by this table's `create`, destroyed once.
        unsafe { (self.table.destroy)(self.instance) };
    }
}

/// An integrator plugin instance. Keeps its library, its mutation instances and the scene
/// view it was given alive.
pub struct IntegratorInstance {
    plugin: Arc<PluginLibrary>,
    table: IntegratorTable,
    instance: *mut c_void,
    pub info: IntegratorInfo,
    /// The counters the instance declared (owned by the instance, valid until `destroy`).
    stats: StatList,
    /// The parameter values the instance resolved (owned likewise), written again by its
    /// `prepare` (ABI 7).
    resolved: std::sync::Mutex<ResolvedList>,
    /// The integrator's counters, then each mutation's as `NAME.counter` (names owned by
    /// `_stat_names`): what a unit's slots hold and what is reported.
    all_stats: Vec<StatSpec>,
    _stat_names: Vec<Box<str>>,
    // The plugin may keep pointers into these for its whole life; dropped after `destroy`.
    _view: Box<SceneView>,
    _mutation_refs: Vec<MutationRef>,
    mutations: Vec<MutationInstance>,
    prepared: std::sync::Mutex<bool>,
    /// What `prepare` decided, as TOML lines ([`decided_snippet`]).
    decided: std::sync::Mutex<String>,
}

// SAFETY: the SDK requires integrators to be Send + Sync; the host calls `render` concurrently.
unsafe impl Send for IntegratorInstance {}
unsafe impl Sync for IntegratorInstance {}

impl IntegratorInstance {
    /// Creates an instance with `params` from the config and the given mutation strategies
    /// (created with their selection probabilities, from one call of [`normalised_weights`]
    /// over the list; `params` no longer holds the mutation list).
    ///
    /// # Safety
    /// The data `view` points to must outlive the instance.
    /// `defaulted`: the mutations are the default list the integrator's spec declares (the
    /// config gave none); the instance is told so by a [`ParamKind::MutationList`] value.
    pub unsafe fn create(
        plugin: Arc<PluginLibrary>,
        params: &[(String, toml::Value)],
        mutations: Vec<MutationInstance>,
        defaulted: bool,
        view: SceneView,
    ) -> Result<IntegratorInstance, PluginError> {
        let table = plugin.integrator_table()?;
        let call_error = |message| PluginError::Call {
            name: plugin.name.clone(),
            path: plugin.path.clone(),
            message,
        };
        let mut list =
            build_params(&plugin.name, plugin.param_specs(), params).map_err(call_error)?;
        let list_name = plugin.mutation_list_param()?;
        if let (true, Some(name)) = (defaulted, &list_name) {
            list.mark_defaulted_list(name, mutations.len());
        }
        if let (None, Some(m)) = (&list_name, mutations.first()) {
            return Err(call_error(format!(
                "takes no mutation list, but was given mutation '{}'",
                m.name
            )));
        }
        let mut stat_offset = 0u32;
        let refs: Vec<MutationRef> = mutations
            .iter()
            .map(|m| {
                let stat_count = m.stats.count as u32;
                stat_offset += stat_count;
                MutationRef {
                    name: StrRef::new(&m.name),
                    weight: m.weight,
                    table: &*m.table,
                    instance: m.instance,
                    stat_offset: stat_offset - stat_count,
                    stat_count,
                }
            })
            .collect();
        let view = Box::new(view);
        let mut instance = std::ptr::null_mut();
        let mut info = IntegratorInfo::simple();
        let mut stats = StatList::EMPTY;
        let mut resolved = ResolvedList::EMPTY;
        let mut err = ErrorBuf::default();
        // SAFETY: the table is a checked integrator plugin's; every pointer is valid for the
        // call, and `refs`, the mutation instances and the boxed view live in the returned
        // instance (the caller keeps the view's data alive for it).
        let status = unsafe {
            (table.create)(
                list.as_slice().as_ptr(),
                list.as_slice().len(),
                refs.as_ptr(),
                refs.len(),
                &*view,
                &mut instance,
                &mut info,
                &mut stats,
                &mut resolved,
                &mut err,
            )
        };
        if status != Status::Ok {
            return Err(plugin.call_error(status, &err));
        }
        let mut inst = IntegratorInstance {
            plugin,
            table,
            instance,
            info,
            stats,
            resolved: std::sync::Mutex::new(resolved),
            all_stats: Vec::new(),
            _stat_names: Vec::new(),
            _view: view,
            _mutation_refs: refs,
            mutations,
            prepared: std::sync::Mutex::new(false),
            decided: std::sync::Mutex::new(String::new()),
        };
        // The SDK's builder refuses more; a plugin that wrote its own glue might not.
        if inst.stats.count > MAX_COUNTERS || (inst.stats.count > 0 && inst.stats.specs.is_null()) {
            return Err(PluginError::Call {
                name: inst.plugin.name.clone(),
                path: inst.plugin.path.clone(),
                message: format!(
                    "declares {} statistics counters, at most {MAX_COUNTERS} are supported",
                    inst.stats.count
                ),
            });
        }
        inst.append_mutation_stats()
            .map_err(|message| PluginError::Call {
                name: inst.plugin.name.clone(),
                path: inst.plugin.path.clone(),
                message,
            })?;
        Ok(inst)
    }

    /// Builds [`IntegratorInstance::stat_specs`]: the integrator's counters, then each
    /// mutation's renamed `NAME.counter` (`NAME#k` for the k-th entry of a plugin listed
    /// more than once), ratios pointing at the shifted indices.
    fn append_mutation_stats(&mut self) -> Result<(), String> {
        let own: Vec<StatSpec> = self.own_stat_specs().to_vec();
        let mut names: Vec<Box<str>> = Vec::new();
        let mut specs = own.clone();
        let mut seen: Vec<&str> = Vec::new();
        for m in &self.mutations {
            let entry = seen.iter().filter(|n| **n == m.name).count();
            seen.push(&m.name);
            let group = if entry == 0 {
                m.name.clone()
            } else {
                format!("{}#{}", m.name, entry + 1)
            };
            let base = specs.len() as u32;
            for s in m.stat_specs() {
                // SAFETY: the mutation instance owns its names until `destroy`.
                let name = format!("{group}.{}", unsafe { s.name.as_str() });
                if own.iter().any(|o| unsafe { o.name.as_str() } == name) {
                    return Err(format!(
                        "counter '{name}' of mutation '{}' has the name of one of the integrator's own",
                        m.name
                    ));
                }
                names.push(name.into_boxed_str());
                let shifted = |i: u32| {
                    if s.merge == StatMerge::Ratio {
                        i + base
                    } else {
                        i
                    }
                };
                specs.push(StatSpec {
                    name: StrRef::new(names.last().expect("just pushed")),
                    merge: s.merge,
                    numerator: shifted(s.numerator),
                    denominator: shifted(s.denominator),
                    display: s.display,
                });
            }
        }
        self.all_stats = specs;
        self._stat_names = names;
        Ok(())
    }

    pub fn plugin(&self) -> &PluginLibrary {
        &self.plugin
    }

    pub fn mutations(&self) -> &[MutationInstance] {
        &self.mutations
    }

    /// The parameter values the integrator resolved (after defaults), `(name, TOML text)`.
    pub fn resolved_params(&self) -> Vec<(String, String)> {
        let list = *self.resolved.lock().unwrap();
        // SAFETY: owned by the instance until `destroy` (in our Drop), and rewritten only by
        // `prepare` under the lock.
        unsafe { resolved_pairs(&list) }
    }

    /// The mutation strategies as the integrator sees them (normalised weights), e.g. for
    /// tests that drive strategies directly.
    pub fn mutation_set(&self) -> flowlight_sdk::MutationSet<'_> {
        // SAFETY: the refs and the instances they point to live as long as `self`.
        unsafe {
            flowlight_sdk::MutationSet::from_raw(
                self._mutation_refs.as_ptr(),
                self._mutation_refs.len(),
            )
        }
    }

    /// The scene view the integrator was created with.
    pub fn view(&self) -> &SceneView {
        &self._view
    }

    /// The statistics counters a unit's slots hold: the integrator's own, then its mutation
    /// strategies' (named `NAME.counter`).
    pub fn stat_specs(&self) -> &[StatSpec] {
        &self.all_stats
    }

    /// The statistics counters the integrator itself declared.
    fn own_stat_specs(&self) -> &[StatSpec] {
        if self.stats.specs.is_null() || self.stats.count == 0 {
            return &[];
        }
        // SAFETY: owned by the instance until `destroy` (in our Drop), `count` entries.
        unsafe { std::slice::from_raw_parts(self.stats.specs, self.stats.count) }
    }

    /// The parameter values the integrator decided in `prepare` (changed or added to what
    /// `create` resolved), as TOML lines `name = value`; empty before `prepare` or when it
    /// decided nothing.
    pub fn decided(&self) -> String {
        self.decided.lock().unwrap().clone()
    }

    /// Runs the plugin's one-time preparation, the first time it is called. The scheduler
    /// calls it before any unit, from one thread.
    pub fn prepare_once(&self, tracer: &TracerTable) -> Result<(), PluginError> {
        let mut prepared = self.prepared.lock().unwrap();
        if *prepared {
            return Ok(());
        }
        *prepared = true;
        let mut err = ErrorBuf::default();
        // SAFETY: the lock is held and no unit runs before preparation, so this is the only
        // access to the instance (the plugin's `prepare` takes it mutably).
        let before = self.resolved_params();
        let mut resolved = *self.resolved.lock().unwrap();
        let status =
            unsafe { (self.table.prepare)(self.instance, tracer, &mut resolved, &mut err) };
        if status != Status::Ok {
            return Err(self.plugin.call_error(status, &err));
        }
        // The list `create` wrote may have been freed: only the new one is read from now on.
        *self.resolved.lock().unwrap() = resolved;
        let decided = decided_snippet(&before, &self.resolved_params());
        if !decided.is_empty() {
            tracing::info!(
                "{} decided while preparing (to freeze into the config):\n[integrator]\n{decided}",
                self.plugin.name
            );
        }
        *self.decided.lock().unwrap() = decided;
        Ok(())
    }

    /// Renders one work unit through the plugin; `stats` holds one zeroed slot per counter
    /// of [`IntegratorInstance::stat_specs`].
    pub fn render(
        &self,
        unit: &WorkUnit,
        tracer: &TracerTable,
        film: &FilmTable,
        stats: &mut [f64],
    ) -> Result<(), PluginError> {
        if stats.len() < self.all_stats.len() {
            return Err(PluginError::Call {
                name: self.plugin.name.clone(),
                path: self.plugin.path.clone(),
                message: format!(
                    "render was given {} statistics slots for {} counters",
                    stats.len(),
                    self.all_stats.len()
                ),
            });
        }
        let mut err = ErrorBuf::default();
        // SAFETY: all pointers are valid for the call; the instance is alive.
        let status = unsafe {
            (self.table.render)(
                self.instance,
                unit,
                tracer,
                film,
                stats.as_mut_ptr(),
                stats.len(),
                &mut err,
            )
        };
        if status != Status::Ok {
            return Err(self.plugin.call_error(status, &err));
        }
        Ok(())
    }
}

impl Drop for IntegratorInstance {
    fn drop(&mut self) {
        // SAFETY: created by this table's `create`, destroyed once, before the mutation
        // instances and the view it may point into (fields drop after this body).
        unsafe { (self.table.destroy)(self.instance) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_decided_snippet_holds_what_prepare_changed_or_added() {
        let pair = |n: &str, v: &str| (n.to_string(), v.to_string());
        let before = [pair("a", "1"), pair("b", "\"x\"")];
        let after = [pair("a", "1"), pair("b", "\"y\""), pair("c", "[1, 2]")];
        assert_eq!(decided_snippet(&before, &after), "b = \"y\"\nc = [1, 2]\n");
        assert_eq!(decided_snippet(&before, &before), "");
    }

    #[test]
    fn weights_are_normalised_to_sum_to_one() {
        let w =
            normalised_weights("mutations", &[("drill", 1.0), ("blow", 3.0), ("x", 0.0)]).unwrap();
        assert_eq!(w, [0.25, 0.75, 0.0]);
        assert_eq!(
            normalised_weights("mutations", &[]).unwrap(),
            Vec::<f64>::new()
        );
        // Only ratios matter: huge finite weights are fine as long as their sum is.
        let w = normalised_weights("m", &[("a", 1e300), ("b", 1e300)]).unwrap();
        assert_eq!(w, [0.5, 0.5]);
    }

    #[test]
    fn bad_weights_are_one_line_errors_naming_the_entry() {
        let e = normalised_weights("mutations", &[("drill", 1.0), ("blow", -2.0)]).unwrap_err();
        assert_eq!(
            e,
            "integrator.mutations[1] (plugin \"blow\"): `weight` must not be negative, got -2"
        );
        let e = normalised_weights("strategies", &[("drill", f64::NAN)]).unwrap_err();
        assert_eq!(
            e,
            "integrator.strategies[0] (plugin \"drill\"): `weight` must be finite, got NaN"
        );
        let e = normalised_weights("m", &[("a", f64::INFINITY)]).unwrap_err();
        assert!(e.contains("[0]") && e.contains("inf"), "{e}");
        let e = normalised_weights("m", &[("a", 0.0), ("b", 0.0)]).unwrap_err();
        assert!(e.starts_with("integrator.m: the weights sum to 0"), "{e}");
        let e = normalised_weights("m", &[("a", f64::MAX), ("b", f64::MAX)]).unwrap_err();
        assert!(e.contains("largest f64"), "{e}");
        let nine: Vec<(&str, f64)> = (0..MAX_MUTATIONS + 1).map(|_| ("a", 1.0)).collect();
        let e = normalised_weights("m", &nine).unwrap_err();
        assert!(e.contains("9 entries") && e.contains("at most 8"), "{e}");
    }
}
