//! The material preview as a library call: a roughness × metallic sweep on the sphere, rendered
//! by the sparse method, written as `out/glossy_preview.exr` and `.png`.
//!
//! `cargo run --release --example glossy_preview [-- SIZE]` (default 128 pixels per ball).

use valgi::method::MethodOptions;
use valgi::preview::{preview_options, render_grid, select_materials, PreviewRequest};
use valgi::raster::RenderSettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let size: u32 = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(128);
    // Five roughness values along each row, dielectric above metal.
    let (materials, columns) = select_materials(&[], Some("roughness=0..1:5,metallic=0,1"))?;
    let request = PreviewRequest {
        materials,
        columns,
        method: "sparse".into(),
        options: preview_options("sparse", &MethodOptions::default()),
        settings: RenderSettings {
            width: size,
            height: size,
            ..RenderSettings::default()
        },
        ..PreviewRequest::default()
    };
    let ctx = valgi::gpu::GpuContext::new()?;
    let grid = render_grid(&ctx, &request)?;
    let written = grid.write(
        std::path::Path::new("out/glossy_preview.png"),
        grid.auto_exposure(),
    )?;
    println!(
        "{} balls in {:.1} s: {}",
        grid.balls.len(),
        grid.total_ms / 1000.0,
        written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    // One material's scene alone, e.g. for a viewer that re-renders as a slider moves.
    let ball = valgi::preview::ball_mesh(request.ball, request.max_edge)?;
    let scene = valgi::preview::preview_scene("one ball", &request.materials[0], &ball, 0.05);
    println!("one preview scene: {} triangles", scene.triangle_count());
    Ok(())
}
