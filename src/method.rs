//! The one registry of rendering methods. Each technique exports an [`Entry`] (name, help,
//! options, constructor); [`REGISTRY`] lists them. `valgi render` generates its method flags
//! from it, `valgi methods` prints it, options are validated against it, and `valgi eval`
//! builds its methods through it. Adding a method is its folder plus one line here.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::str::FromStr;

pub use crate::frame::{Method, ViewResult};
use crate::gpu::GpuContext;
use crate::raster::{RenderError, RenderSettings};
use crate::scene::Scene;

/// Every method, in the order `valgi methods` lists them.
pub static REGISTRY: &[&Entry] = &[
    &crate::direct::ENTRY,
    &crate::vals::ENTRY,
    &crate::peers::brute::ENTRY,
    &crate::reference::ENTRY,
    &crate::atlas::ENTRY,
    &crate::peers::lpv::LPV_ENTRY,
    &crate::peers::lpv::HOLPV_ENTRY,
    &crate::composite::SPARSE_ATLAS_ENTRY,
    &crate::negative::ENTRY,
];

/// Every struct shared between Rust and WGSL: the base layer's, the light module's and each
/// technique's own list (checked against naga by `tests/shader_layout.rs`).
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    let lists: [fn() -> Vec<crate::raster::types::SharedLayout>; 9] = [
        crate::raster::types::shared_layouts,
        crate::light::shared_layouts,
        crate::vals::shared_layouts,
        crate::peers::lpv::shared_layouts,
        crate::atlas::shared_layouts,
        crate::bench::shared_layouts,
        crate::negative::shared_layouts,
        crate::mixed_reality::shared_layouts,
        crate::viewer::shared_layouts,
    ];
    lists.iter().flat_map(|list| list()).collect()
}

/// What values an option takes.
#[derive(Clone, Copy, Debug)]
pub enum OptionKind {
    /// A whole number in `min..=max`.
    Int { min: i64, max: i64 },
    /// One of these words.
    Choice(&'static [&'static str]),
    /// A file.
    Path,
    /// Free text the method parses itself (e.g. `bounces=1|B|inf`).
    Text,
}

/// One option of a method: `--NAME VALUE` on the command line, `NAME=VALUE` in a spec.
#[derive(Clone, Copy, Debug)]
pub struct OptionSpec {
    pub name: &'static str,
    pub kind: OptionKind,
    /// The default as text ("" where the method computes it, e.g. LPV steps = grid).
    pub default: &'static str,
    pub help: &'static str,
}

impl OptionSpec {
    /// Checks `value` against the option's type and range.
    pub fn check(&self, method: &str, value: &str) -> Result<(), RenderError> {
        let bad = |why: String| {
            RenderError::Settings(format!(
                "method '{method}': option {}={value}: {why}",
                self.name
            ))
        };
        match self.kind {
            OptionKind::Int { min, max } => {
                let v: i64 = value
                    .parse()
                    .map_err(|_| bad("not a whole number".into()))?;
                if !(min..=max).contains(&v) {
                    return Err(bad(format!("must be {min}..={max}")));
                }
            }
            OptionKind::Choice(allowed) => {
                if !allowed.contains(&value) {
                    return Err(bad(format!("expected one of {}", allowed.join("|"))));
                }
            }
            OptionKind::Path => {
                if value.is_empty() {
                    return Err(bad("empty path".into()));
                }
            }
            OptionKind::Text => {}
        }
        Ok(())
    }

    /// `INT a..=b`, `on|off`, `FILE` for help texts.
    pub fn value_hint(&self) -> String {
        match self.kind {
            OptionKind::Int { min, max } => format!("{min}..={max}"),
            OptionKind::Choice(c) => c.join("|"),
            OptionKind::Path => "FILE".into(),
            OptionKind::Text => "TEXT".into(),
        }
    }
}

/// A method's constructor: scene, the mono view's size and quality, and its options.
pub type Create =
    fn(&GpuContext, &Scene, RenderSettings, &MethodOptions) -> Result<Box<dyn Method>, RenderError>;

/// One registered method.
pub struct Entry {
    pub name: &'static str,
    pub help: &'static str,
    pub options: &'static [OptionSpec],
    pub create: Create,
}

/// The registry entry of `name`.
pub fn entry(name: &str) -> Result<&'static Entry, RenderError> {
    REGISTRY
        .iter()
        .copied()
        .find(|e| e.name == name)
        .ok_or_else(|| {
            RenderError::Settings(format!(
                "unknown method '{name}' (available: {})",
                REGISTRY
                    .iter()
                    .map(|e| e.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

/// Every option name any method takes, with the methods that take it (for generated flags).
pub fn all_options() -> Vec<(OptionSpec, Vec<&'static str>)> {
    let mut out: Vec<(OptionSpec, Vec<&'static str>)> = vec![];
    for e in REGISTRY {
        for o in e.options {
            match out.iter_mut().find(|(spec, _)| spec.name == o.name) {
                Some((_, methods)) => methods.push(e.name),
                None => out.push((*o, vec![e.name])),
            }
        }
    }
    out
}

/// Validates the options against the registry entry and builds the method.
pub fn create(
    name: &str,
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    let entry = check_options(name, options)?;
    let method = (entry.create)(ctx, scene, settings, options)?;
    options.reject_unused(name)?;
    Ok(method)
}

/// [`create`], or `fallback` when `name` cannot bake its atlas in memory
/// ([`RenderError::AtlasBake`], with a warning naming `context`): how `render` and `view` build
/// their default, `sparse+atlas`, on a scene whose atlas the default bake refuses.
pub fn create_or(
    name: &str,
    fallback: Option<&str>,
    context: &str,
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    match (create(name, ctx, scene, settings, options), fallback) {
        (Err(RenderError::AtlasBake(why)), Some(fallback)) => {
            log::warn!("{why}; {context} '{fallback}' without the atlas's later bounces");
            create(fallback, ctx, scene, settings, options)
        }
        (created, _) => created,
    }
}

/// The method's registry entry, once every option given is one it takes with a valid value
/// (checked before any GPU work).
pub fn check_options(name: &str, options: &MethodOptions) -> Result<&'static Entry, RenderError> {
    let entry = entry(name)?;
    for (key, value) in options.entries() {
        let Some(spec) = entry.options.iter().find(|o| o.name == key) else {
            return Err(RenderError::Settings(format!(
                "method '{name}' has no option(s) {key} (it takes: {})",
                if entry.options.is_empty() {
                    "none".to_string()
                } else {
                    entry
                        .options
                        .iter()
                        .map(|o| o.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            )));
        };
        spec.check(name, value)?;
    }
    Ok(entry)
}

/// A method's knobs as `key=value` pairs. The CLI's method flags (`--rsm 64`) and the
/// harness's specs (`sparse:rsm=64,tile=128`) both land here, so a setting has one name
/// everywhere. Keys a method never reads are an error, so a typo cannot pass silently.
#[derive(Clone, Debug, Default)]
pub struct MethodOptions {
    entries: BTreeMap<String, String>,
    read: RefCell<BTreeSet<String>>,
}

impl PartialEq for MethodOptions {
    fn eq(&self, other: &Self) -> bool {
        self.entries == other.entries
    }
}

impl MethodOptions {
    /// Splits `name[:key=value,...]` into the method name and its options.
    pub fn parse_spec(spec: &str) -> Result<(String, MethodOptions), RenderError> {
        let (name, rest) = match spec.split_once(':') {
            Some((name, rest)) => (name, rest),
            None => (spec, ""),
        };
        let name = name.trim();
        if name.is_empty() {
            return Err(RenderError::Settings(format!(
                "method spec '{spec}' has no method name"
            )));
        }
        let mut options = MethodOptions::default();
        for pair in rest.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let Some((key, value)) = pair.split_once('=') else {
                return Err(RenderError::Settings(format!(
                    "method spec '{spec}': '{pair}' is not key=value"
                )));
            };
            options.set(key.trim(), value.trim());
        }
        Ok((name.to_string(), options))
    }

    pub fn set(&mut self, key: &str, value: impl ToString) {
        self.entries.insert(key.to_string(), value.to_string());
    }

    /// The options `key=value` of `pairs` (a method's [`crate::frame::Method::resolved_options`]).
    pub fn from_pairs(pairs: impl IntoIterator<Item = (String, String)>) -> Self {
        Self {
            entries: pairs.into_iter().collect(),
            read: RefCell::default(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Whether `key` was given (a default applies otherwise).
    pub fn given(&self, key: &str) -> bool {
        self.entries.contains_key(key)
    }

    /// The `key=value` pairs given.
    pub fn entries(&self) -> impl Iterator<Item = (&str, &str)> {
        self.entries.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// The value of `key` parsed as `T`, or `default` when absent.
    pub fn get<T: FromStr>(&self, key: &str, default: T) -> Result<T, RenderError> {
        self.read.borrow_mut().insert(key.to_string());
        match self.entries.get(key) {
            None => Ok(default),
            Some(text) => text.parse().map_err(|_| {
                RenderError::Settings(format!(
                    "option {key}={text}: not a valid {}",
                    std::any::type_name::<T>()
                ))
            }),
        }
    }

    /// The value of `key`, which must be one of `allowed` (the first is the default).
    pub fn choice(&self, key: &str, allowed: &[&'static str]) -> Result<&'static str, RenderError> {
        let text: String = self.get(key, allowed[0].to_string())?;
        allowed
            .iter()
            .find(|a| **a == text)
            .copied()
            .ok_or_else(|| {
                RenderError::Settings(format!(
                    "option {key}={text}: expected one of {}",
                    allowed.join("|")
                ))
            })
    }

    /// Errors on keys that the method did not read.
    pub fn reject_unused(&self, method: &str) -> Result<(), RenderError> {
        let read = self.read.borrow();
        let unused: Vec<&str> = self
            .entries
            .keys()
            .filter(|k| !read.contains(*k))
            .map(String::as_str)
            .collect();
        if unused.is_empty() {
            Ok(())
        } else {
            Err(RenderError::Settings(format!(
                "method '{method}' has no option(s) {}",
                unused.join(", ")
            )))
        }
    }
}

/// Canonical `key=value,...` text (sorted keys), as the harness writes it in its CSV.
impl std::fmt::Display for MethodOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pairs: Vec<String> = self
            .entries
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        f.write_str(&pairs.join(","))
    }
}
