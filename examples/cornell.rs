//! Renders the built-in Cornell box with direct light and writes `out/example-cornell.exr`
//! and a PNG: the smallest complete use of the library.
//!
//! cargo run --example cornell

use valgi::gpu::GpuContext;
use valgi::method;
use valgi::raster::RenderSettings;
use valgi::scene::builtin::{self, BuiltinParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scene = builtin::load("cornell", &BuiltinParams::default())?;
    let ctx = GpuContext::new()?;
    let settings = RenderSettings {
        width: 256,
        height: 256,
        ..RenderSettings::default()
    };
    let world_from_node = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world_from_node)?;
    let mut direct = method::create("direct", &ctx, &scene, settings, &Default::default())?;
    let frame = direct.render(&ctx, &scene, &world_from_node, &camera)?;
    let image = frame.radiance(false);
    image.write_exr("out/example-cornell.exr".as_ref())?;
    image.write_png("out/example-cornell.png".as_ref(), 0.0)?;
    println!(
        "rendered on {} in {:.2} ms of GPU passes: {:?}",
        ctx.adapter_label(),
        frame.timings.total_ms(),
        frame.timings.passes
    );
    Ok(())
}
