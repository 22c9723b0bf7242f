//! Sizes beyond what the device allows are errors that name the size and a remedy, never a
//! panic from wgpu's default error handler.

mod common;

use valgi::frame::{FrameTargets, View};
use valgi::gpu::{GpuContext, GpuError};
use valgi::raster::{Rasterizer, RenderSettings};
use valgi::scene::{builtin::BuiltinParams, CameraView, Scene};

fn scene() -> Scene {
    valgi::scene::load("plane-point", &BuiltinParams { max_edge: 0.5 }).expect("built-in scene")
}

fn camera(scene: &Scene) -> CameraView {
    scene
        .camera_view(None, 1.0, &scene.world_from_node())
        .expect("camera")
}

fn texture_of_width(ctx: &GpuContext, width: u32) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("too wide"),
        size: wgpu::Extent3d {
            width,
            height: 1,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::R8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    })
}

#[test]
fn a_view_beyond_the_texture_limit_is_an_error_naming_its_size() {
    let Some(ctx) = common::gpu() else { return };
    let limit = ctx.device.limits().max_texture_dimension_2d;
    let scene = scene();
    let too_wide = View::new(&ctx, "main", camera(&scene), (limit + 1, 1), 1)
        .err()
        .expect("a view wider than the device allows must be refused");
    let message = too_wide.to_string();
    assert!(message.contains(&(limit + 1).to_string()), "{message}");
    assert!(message.contains("--width"), "{message}");
    // Within the limit per output pixel, beyond it after supersampling.
    let half = limit / 2 + 1;
    let message = View::new(&ctx, "main", camera(&scene), (half, 1), 2)
        .err()
        .expect("SSAA beyond the limit must be refused")
        .to_string();
    assert!(message.contains(&(2 * half).to_string()), "{message}");
    assert!(message.contains("--ssaa"), "{message}");
}

#[test]
fn shadow_maps_out_of_range_are_an_error_naming_the_resolution() {
    let Some(ctx) = common::gpu() else { return };
    let limit = ctx.device.limits().max_texture_dimension_2d;
    let scene = scene();
    for resolution in [0, 8, limit + 1] {
        let settings = RenderSettings {
            shadow_resolution: resolution,
            ..common::small_render_settings(8)
        };
        let message = Rasterizer::new(&ctx, &scene, settings)
            .err()
            .unwrap_or_else(|| panic!("--shadow-res {resolution} was accepted"))
            .to_string();
        assert!(message.contains("--shadow-res"), "{message}");
        assert!(message.contains(&resolution.to_string()), "{message}");
        assert!(message.contains(&limit.to_string()), "{message}");
    }
    let settings = RenderSettings {
        shadow_resolution: 16,
        ..common::small_render_settings(8)
    };
    assert!(Rasterizer::new(&ctx, &scene, settings).is_ok());
}

#[test]
fn a_refused_allocation_in_a_scope_is_an_error_naming_what_and_how_big() {
    let Some(ctx) = common::gpu() else { return };
    let limit = ctx.device.limits().max_texture_dimension_2d;
    let refused = ctx.scoped("the test texture", Some(3 << 20), "make it smaller", || {
        texture_of_width(&ctx, limit + 1)
    });
    match refused {
        Err(GpuError::Allocation {
            what,
            size,
            message,
            remedy,
        }) => {
            assert_eq!(what, "the test texture");
            assert_eq!(size, "3.0 MiB");
            assert!(!message.is_empty());
            assert_eq!(remedy, "make it smaller");
        }
        Err(other) => panic!("wrong error: {other}"),
        Ok(_) => panic!("a texture beyond the device's limit was made"),
    }
    // The scopes were popped: a valid allocation afterwards succeeds, and nothing leaked out
    // to the uncaptured handler.
    assert!(ctx
        .scoped("a small texture", None, "", || texture_of_width(&ctx, 4))
        .is_ok());
    assert!(ctx.check_uncaptured().is_ok());
}

#[test]
fn an_error_outside_any_scope_is_reported_once_not_a_panic() {
    let Some(ctx) = common::gpu() else { return };
    assert!(ctx.check_uncaptured().is_ok());
    let limit = ctx.device.limits().max_texture_dimension_2d;
    // wgpu's default handler would panic here.
    let _invalid = texture_of_width(&ctx, limit + 1);
    match ctx.check_uncaptured() {
        Err(GpuError::Uncaptured(message)) => assert!(!message.is_empty()),
        other => panic!("expected the uncaptured error, got {other:?}"),
    }
    assert!(ctx.check_uncaptured().is_ok(), "reported twice");
}

#[test]
fn storage_buffers_beyond_the_binding_limit_are_refused_up_front() {
    let Some(ctx) = common::gpu() else { return };
    let limits = ctx.device.limits();
    let limit = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    assert!(ctx.check_storage_buffer("points", limit, "fewer").is_ok());
    let message = ctx
        .check_storage_buffer("the sparse points", limit + 1, "Lower --sparse-points")
        .expect_err("one byte beyond the limit")
        .to_string();
    assert!(message.contains("the sparse points"), "{message}");
    assert!(message.contains("--sparse-points"), "{message}");
    assert!(
        message.contains(&valgi::gpu::format_bytes(limit + 1)),
        "{message}"
    );
}

#[test]
fn the_view_target_size_in_messages_is_what_the_view_allocates() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene();
    let view = View::new(&ctx, "main", camera(&scene), (8, 4), 2).expect("small view");
    assert_eq!(view.targets.bytes.0, FrameTargets::bytes(8, 4, 2));
}

#[test]
fn byte_sizes_read_as_units() {
    assert_eq!(valgi::gpu::format_bytes(12), "12 B");
    assert_eq!(valgi::gpu::format_bytes(1536), "1.5 KiB");
    assert_eq!(valgi::gpu::format_bytes(6 << 30), "6.0 GiB");
}
