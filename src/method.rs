//! Every rendering method implements [`Method`]: scene, transforms and camera in; direct and
//! indirect radiance, per-pass GPU times and owned GPU bytes out. The CLI and (later) the
//! evaluation harness treat all methods alike through it.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::str::FromStr;

use glam::Mat4;

use crate::gpu::GpuContext;
use crate::raster::{FrameOutput, Rasterizer, RenderError, RenderSettings};
use crate::scene::{CameraView, Scene};

pub trait Method {
    /// The method's name as given to `--method`.
    fn name(&self) -> &'static str;

    /// Renders one frame with the scene's nodes at `world_from_node`.
    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError>;

    /// Method-specific keys for the JSON report (empty by default).
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }

    /// Estimated variance of each pixel of the last frame (full or indirect image), for
    /// Monte Carlo methods; `None` for deterministic ones.
    fn variance(&self, _indirect_only: bool) -> Option<crate::image_io::Image> {
        None
    }
}

/// Methods `valgi render --method` accepts, with a one-line description.
pub const METHODS: &[(&str, &str)] = &[
    (
        "direct",
        "direct light only: shadow-mapped punctual lights and emission (indirect is black)",
    ),
    (
        "sparse",
        "direct + one-bounce diffuse and glossy light from RSM virtual area lights gathered at sparse model-space points (options: rsm, sparse-points, tile, glossy, occlusion, weights, seed)",
    ),
    (
        "brute",
        "direct + every VAL summed at every pixel: the sparse method without interpolation or occlusion (options: rsm, tile, glossy)",
    ),
    (
        "reference",
        "CPU path tracer, the ground truth (options: bounces=N|inf, spp=N, seed=N)",
    ),
    (
        "atlas",
        "direct light plus the indirect bounces of a baked light atlas (--atlas FILE)",
    ),
    (
        "lpv",
        "direct + one diffuse bounce through a light propagation volume: 2-band SH, 6-direction propagation (options: grid, steps, occlusion=on|off, rsm)",
    ),
    (
        "holpv",
        "direct + one diffuse bounce through a higher-order LPV: 3-band SH, 26-direction propagation (options: grid, steps, occlusion=on|off, rsm)",
    ),
    (
        "sparse+atlas",
        "direct + bounce 1 from the VALs (the sparse method and its options) + bounces 2.. from an atlas baked with --from-bounce 2 (--atlas FILE)",
    ),
];

/// Builds a method by name for one scene and output size.
pub fn create(
    name: &str,
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    let method: Box<dyn Method> = match name {
        "direct" => Box::new(DirectMethod {
            raster: Rasterizer::new(ctx, scene, settings)?,
        }),
        "sparse" => crate::vals::create(ctx, scene, settings, options)?,
        "brute" => Box::new(crate::peers::brute::BruteMethod::new(
            ctx, scene, settings, options,
        )?),
        "reference" => Box::new(crate::reference::ReferenceMethod::new(settings, options)?),
        "atlas" => Box::new(crate::atlas::AtlasMethod::new(
            ctx, scene, settings, options,
        )?),
        "sparse+atlas" => crate::atlas::create_sparse_atlas(ctx, scene, settings, options)?,
        "lpv" => {
            crate::peers::lpv::create(ctx, scene, settings, crate::peers::lpv::Order::Lpv, options)?
        }
        "holpv" => crate::peers::lpv::create(
            ctx,
            scene,
            settings,
            crate::peers::lpv::Order::HoLpv,
            options,
        )?,
        other => {
            return Err(RenderError::Settings(format!(
                "unknown method '{other}' (available: {})",
                METHODS
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", ")
            )))
        }
    };
    options.reject_unused(name)?;
    Ok(method)
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

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
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

/// Direct light only: the base every indirect method adds to.
pub struct DirectMethod {
    pub raster: Rasterizer,
}

impl Method for DirectMethod {
    fn name(&self) -> &'static str {
        "direct"
    }

    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        self.raster
            .render_direct(ctx, scene, world_from_node, camera)
    }
}
