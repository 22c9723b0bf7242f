//! Prints the budget-mode survey of each scene as CSV, one row per setting of the
//! `valgi eval --sweep` grid: the error terms the model combines, beside the work the setting
//! does. Joined with `sweep.csv` on (scene, points, rsm, visibility), this is the data the
//! model's constants are fitted to (`src/vals/README.md`, "Budget mode").
//!
//! ```sh
//! cargo run --release --example budget_survey -- cornell door-room \
//!     [--light sun:-0.3,-1,-0.2,5] [--camera-eye X,Y,Z --camera-target X,Y,Z --fov DEG] \
//!     [--seed S] > survey.csv
//! ```

use valgi::eval::sweep::SweepGrid;
use valgi::scene::edits::{LightSpec, SceneEdits};
use valgi::vals::budget::Survey;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes = vec![];
    let mut edits = SceneEdits::default();
    let mut seed = 1u64;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--seed" {
            seed = args.next().ok_or("--seed needs a value")?.parse()?;
        } else if arg == "--camera-eye" || arg == "--camera-target" {
            let text = args.next().ok_or("a camera option needs a value")?;
            let point = valgi::scene::edits::parse_point(&arg, &text)?;
            if arg == "--camera-eye" {
                edits.camera.eye = Some(point);
            } else {
                edits.camera.target = Some(point);
            }
        } else if arg == "--fov" {
            edits.camera.yfov_degrees = Some(args.next().ok_or("--fov needs a value")?.parse()?);
        } else if arg == "--light" {
            let spec = args.next().ok_or("--light needs a value")?;
            edits.lights.push(spec.parse::<LightSpec>()?);
        } else {
            scenes.push(arg);
        }
    }
    let grid = SweepGrid::default();
    println!(
        "scene,points,rsm,visibility,eps_points,variation,eps_vals,occluded_share,partial_share,vals,clusters,area,lit_area,survey_ms,visible_area"
    );
    for spec in &scenes {
        let mut scene = valgi::scene::load_with(spec, &valgi::scene::LoadParams::default())?;
        let camera_selector = edits.apply(&mut scene, None, 1.0)?;
        let world = scene.world_from_node_at(0.0);
        let camera = scene.camera_view(camera_selector.as_deref(), 1.0, &world)?;
        let survey = Survey::new(&scene, &world, Some(&camera), seed);
        for setting in grid.settings() {
            println!(
                "{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.0},{},{:.4},{:.4},{:.1},{:.4}",
                scene.name,
                setting.points,
                setting.rsm,
                setting.visibility.name(),
                survey.interpolation_error(survey.point_spacing(setting.points as usize)),
                survey.variation_error(survey.point_spacing(setting.points as usize)),
                survey.interpolation_error(survey.val_spacing(setting.rsm)),
                survey.occluded_share,
                survey.partial_share,
                survey.val_count(setting.rsm),
                survey.clusters,
                survey.area,
                survey.lit_area,
                survey.survey_ms,
                survey.visible_area
            );
        }
    }
    Ok(())
}
