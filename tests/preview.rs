//! The glossy material preview: where highlights appear (from the mirror reflection of the
//! light), that a rough ball has none, sparse against brute force on the preview room's glossy
//! indirect light, and the selection of materials from a glTF file.

mod common;

use glam::{Vec3, Vec4};
use valgi::image_io::Image;
use valgi::method::MethodOptions;
use valgi::preview::scene::{BALL_CENTRE, BALL_RADIUS, CAMERA_EYE, LIGHT_POSITION};
use valgi::preview::{
    default_material, load_materials, mirror_point, render_grid, PreviewMaterial, PreviewRequest,
};
use valgi::raster::RenderSettings;

const SAMPLES: &str = "../shared/data/gltf-samples";

fn luminance(p: [f32; 4]) -> f32 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

fn grey_ball(label: &str, roughness: f32, metallic: f32, specular: f32) -> PreviewMaterial {
    PreviewMaterial::plain(
        label,
        valgi::scene::Material {
            base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
            roughness,
            metallic,
            specular_factor: specular,
            ..default_material()
        },
    )
}

fn request(materials: Vec<PreviewMaterial>, size: u32, method: &str) -> PreviewRequest {
    let (method, options) = MethodOptions::parse_spec(method).unwrap();
    PreviewRequest {
        columns: materials.len(),
        materials,
        method,
        options,
        settings: RenderSettings {
            ssaa: 1,
            ..common::small_render_settings(size)
        },
        max_edge: 0.12,
        ..PreviewRequest::default()
    }
}

/// The camera of the preview scene for a square image.
fn camera() -> valgi::scene::CameraView {
    let scene = valgi::preview::scene::builtin("preview", 0.5)
        .unwrap()
        .unwrap();
    scene
        .camera_view(None, 1.0, &scene.world_from_node())
        .unwrap()
}

/// Pixel (x right, y down) where world point `p` projects in a `size`² image.
fn project(p: Vec3, size: u32) -> (f32, f32) {
    let cam = camera();
    let clip = cam.clip_from_view() * cam.view_from_world() * p.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    (
        (ndc.x * 0.5 + 0.5) * size as f32,
        (0.5 - ndc.y * 0.5) * size as f32,
    )
}

/// Pixels whose centre's ray meets the sphere within 0.85 of its radius from the centre
/// (away from the silhouette, where pixels blend with the walls).
fn ball_interior(size: u32) -> Vec<(u32, u32)> {
    let cam = camera();
    let eye = cam.position();
    let t = (cam.yfov * 0.5).tan();
    let mut out = vec![];
    for y in 0..size {
        for x in 0..size {
            let u = ((x as f32 + 0.5) / size as f32 * 2.0 - 1.0) * t * cam.aspect;
            let v = (1.0 - (y as f32 + 0.5) / size as f32 * 2.0) * t;
            let dir = cam
                .world_from_view
                .transform_vector3(Vec3::new(u, v, -1.0))
                .normalize();
            let to_centre = BALL_CENTRE - eye;
            let closest = to_centre - dir * to_centre.dot(dir);
            if to_centre.dot(dir) > 0.0 && closest.length() < 0.85 * BALL_RADIUS {
                out.push((x, y));
            }
        }
    }
    out
}

fn brightest(image: &Image, pixels: &[(u32, u32)]) -> ((u32, u32), f32) {
    pixels
        .iter()
        .map(|&(x, y)| ((x, y), luminance(image.get(x, y))))
        .fold(((0, 0), f32::MIN), |a, b| if b.1 > a.1 { b } else { a })
}

/// Roughness 0.2 (Phong k = 2/α² − 2 ≈ 1248) shows the light's mirror image where the
/// reflection law puts it; roughness 1 (k = 1) has no highlight: its brightest pixel is no
/// brighter than the same ball without a specular lobe allows for. With ρ_d = 0.8 and
/// ρ_s = 0.04 the k = 1 lobe adds at most ρ_s·(k+2)/(2π) = 0.019 per unit irradiance to the
/// diffuse ρ_d/π = 0.255, a factor 1.075 at the brightest point (its glossy indirect light
/// less still); the k ≈ 1248 lobe's peak is ρ_s·1250/(2π) ≈ 8.0, 31× the diffuse.
#[test]
fn highlight_at_the_mirror_point_and_none_when_rough() {
    let Some(ctx) = common::gpu() else { return };
    let size = 48;
    let mut req = request(
        vec![
            grey_ball("no specular", 0.2, 0.0, 0.0),
            grey_ball("r=0.2", 0.2, 0.0, 1.0),
            grey_ball("r=1", 1.0, 0.0, 1.0),
        ],
        size,
        "sparse:sparse-points=512,rsm=32",
    );
    // 4×4 samples per pixel: the k ≈ 1248 highlight is narrower than a pixel at 48².
    req.settings.ssaa = 4;
    let grid = render_grid(&ctx, &req).unwrap();
    assert_eq!(grid.balls.len(), 3);
    let interior = ball_interior(size);
    assert!(interior.len() > 300, "{} ball pixels", interior.len());
    let (_, diffuse_max) = brightest(&grid.balls[0], &interior);
    let (at, glossy_max) = brightest(&grid.balls[1], &interior);
    let (_, rough_max) = brightest(&grid.balls[2], &interior);
    let predicted = project(
        mirror_point(BALL_CENTRE, BALL_RADIUS, LIGHT_POSITION, CAMERA_EYE),
        size,
    );
    let offset = ((at.0 as f32 + 0.5 - predicted.0).powi(2)
        + (at.1 as f32 + 0.5 - predicted.1).powi(2))
    .sqrt();
    eprintln!(
        "max luminance: no specular {diffuse_max:.4}, r=0.2 {glossy_max:.4} ({:.2}×), \
         r=1 {rough_max:.4} ({:.3}×); highlight at {at:?}, predicted {predicted:?}, \
         {offset:.2} px off",
        glossy_max / diffuse_max,
        rough_max / diffuse_max
    );
    assert!(diffuse_max > 0.0);
    assert!(
        rough_max / diffuse_max < 1.15,
        "roughness 1 has a highlight: {rough_max} vs {diffuse_max} without specular"
    );
    assert!(
        glossy_max / diffuse_max > 2.0,
        "roughness 0.2 shows no highlight: {glossy_max} vs {diffuse_max} without specular"
    );
    assert!(
        offset <= 1.5,
        "highlight at {at:?}, the mirror reflection predicts {predicted:?}"
    );
}

/// The square of pixels around the ball's interior (where its glossy light is).
fn ball_crop(image: &Image, interior: &[(u32, u32)]) -> Image {
    let x0 = interior.iter().map(|p| p.0).min().unwrap();
    let x1 = interior.iter().map(|p| p.0).max().unwrap();
    let y0 = interior.iter().map(|p| p.1).min().unwrap();
    let y1 = interior.iter().map(|p| p.1).max().unwrap();
    let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
    let pixels = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x0 + x, y0 + y)))
        .map(|(x, y)| image.get(x, y))
        .collect();
    Image::from_rgba(w, h, pixels)
}

/// Glossy indirect light of balls in the preview room: sparse against brute force (every VAL
/// at every pixel), indirect only, FLIP over the ball's square. Measured figures in the
/// preview README; the threshold is the measurement with a margin, and sparse without its
/// glossy lobe must miss it.
#[test]
fn sparse_glossy_indirect_matches_brute_force() {
    let Some(ctx) = common::gpu() else { return };
    let size = 48;
    let balls = || {
        vec![
            grey_ball("r=0.3 m=1", 0.3, 1.0, 1.0),
            grey_ball("r=0.6 m=1", 0.6, 1.0, 1.0),
        ]
    };
    let render = |method: &str| {
        render_grid(&ctx, &request(balls(), size, method))
            .unwrap()
            .indirect
    };
    let points = std::env::var("PREVIEW_POINTS").unwrap_or("2048".into());
    let brute = render("brute:rsm=32");
    let sparse = render(&format!("sparse:sparse-points={points},rsm=32"));
    let sparse_no_glossy = render(&format!("sparse:sparse-points={points},rsm=32,glossy=off"));
    let interior = ball_interior(size);
    let mut worst: f64 = 0.0;
    let mut broken_best = f64::MAX;
    for i in 0..brute.len() {
        let exposure = valgi::eval::metrics::auto_exposure(&brute[i]);
        let flip = |image: &Image| {
            valgi::eval::metrics::flip(
                &ball_crop(image, &interior),
                &ball_crop(&brute[i], &interior),
                exposure,
            )
        };
        let whole = valgi::eval::metrics::flip(&sparse[i], &brute[i], exposure);
        let (ball_flip, broken) = (flip(&sparse[i]), flip(&sparse_no_glossy[i]));
        let ball_sum = |image: &Image| -> f32 {
            interior
                .iter()
                .map(|&(x, y)| luminance(image.get(x, y)))
                .sum()
        };
        eprintln!(
            "ball {i}: indirect FLIP on the ball sparse {ball_flip:.4}, sparse glossy=off \
             {broken:.4} (whole image sparse {whole:.4}); ball indirect sum brute {:.3} \
             sparse {:.3} glossy=off {:.3}",
            ball_sum(&brute[i]),
            ball_sum(&sparse[i]),
            ball_sum(&sparse_no_glossy[i])
        );
        worst = worst.max(ball_flip);
        broken_best = broken_best.min(broken);
    }
    assert!(
        worst < MAX_SPARSE_BRUTE_FLIP,
        "sparse vs brute FLIP {worst}"
    );
    assert!(
        broken_best > MAX_SPARSE_BRUTE_FLIP,
        "the threshold does not catch sparse without glossy ({broken_best})"
    );
}

/// Highest indirect FLIP of sparse against brute force on the preview balls above: measured
/// 0.590 (r = 0.3) and 0.455 (r = 0.6) at 48², 2048 points, plus 15 %; sparse with
/// `glossy=off` measures 0.799 and 0.816. The sparse points' density on the ball limits the
/// sharper lobe (at 4096 points and 64²: 0.444 and 0.308).
const MAX_SPARSE_BRUTE_FLIP: f64 = 0.68;

#[test]
fn materials_from_a_gltf_file_by_name_and_index() {
    let file = format!("{SAMPLES}/MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb");
    if !std::path::Path::new(&file).is_file() {
        eprintln!("SKIPPED: {file} not present");
        return;
    }
    let all = load_materials(&file).unwrap();
    assert_eq!(all.len(), 98);
    assert_eq!(all[5].label, "5: mat_5");
    let by_name = load_materials(&format!("{file}#mat_97")).unwrap();
    assert_eq!(by_name.len(), 1);
    assert_eq!(by_name[0].label, "mat_97");
    assert_eq!(
        (by_name[0].material.metallic, by_name[0].material.roughness),
        (1.0, 1.0)
    );
    let by_index = load_materials(&format!("{file}#97")).unwrap();
    assert_eq!(by_index[0].material.name, "mat_97");
    assert_eq!(
        by_index[0].material.base_color,
        by_name[0].material.base_color
    );
    let e = load_materials(&format!("{file}#98"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("index 98 is out of range") && e.contains("98 material(s)"),
        "{e}"
    );
    let e = load_materials(&format!("{file}#chrome"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no material named 'chrome'") && e.contains("mat_0"),
        "{e}"
    );

    // A textured material brings its textures along, renumbered.
    let specular = format!("{SAMPLES}/SpecularTest/SpecularTest.glb");
    if std::path::Path::new(&specular).is_file() {
        let label = load_materials(&format!("{specular}#LabelMat")).unwrap();
        assert_eq!(label[0].material.base_color_texture, Some(0));
        assert_eq!(label[0].textures.len(), 1);
    }
}

/// Bad input on the command line: a clear error naming the problem, no panic, no output file.
#[test]
fn cli_rejects_bad_specs_clearly() {
    let dir = common::temp_dir("preview-cli");
    let out = dir.join("grid.png");
    let run = |args: &[&str]| {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_valgi"))
            .arg("preview")
            .args(args)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("run valgi");
        assert!(!output.status.success(), "{args:?} succeeded");
        let stderr = String::from_utf8_lossy(&output.stderr).to_string();
        assert!(!stderr.contains("panicked"), "{stderr}");
        stderr
    };
    let e = run(&["--sweep", "roughness=0..1:5,shininess=3"]);
    assert!(e.contains("unknown parameter 'shininess'"), "{e}");
    let e = run(&["--sweep", "roughness=0..1"]);
    assert!(e.contains("a range needs a count"), "{e}");
    let e = run(&[]);
    assert!(e.contains("nothing to preview"), "{e}");
    let e = run(&["--material", "no/such/file.glb#0"]);
    assert!(e.contains("no/such/file.glb: file not found"), "{e}");
    let e = run(&["--sweep", "roughness=0.5", "--method", "sparse:points=3"]);
    assert!(e.contains("has no option(s) points"), "{e}");
    let e = run(&["--sweep", "roughness=0.5", "--ball", "cube"]);
    assert!(e.contains("unknown ball 'cube'"), "{e}");
    assert!(!out.exists() && !out.with_extension("exr").exists());
}
