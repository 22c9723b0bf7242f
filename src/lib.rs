//! valgi: dynamic global illumination with virtual area lights gathered at sparse model-space
//! points, on top of a baked multi-bounce light atlas. See README.md and DESIGN notes.

pub mod app;
pub mod atlas;
pub mod bench;
pub mod composite;
pub mod direct;
pub mod eval;
pub mod frame;
pub mod gpu;
pub mod image_io;
pub mod light;
pub mod method;
pub mod mixed_reality;
pub mod negative;
pub mod peers;
pub mod preview;
pub mod progress;
pub mod raster;
pub mod reference;
pub mod sampling;
pub mod scene;
pub mod shaders;
pub mod shading;
pub mod trace;
pub mod vals;
pub mod viewer;
pub mod views_bench;
