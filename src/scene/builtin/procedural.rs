//! Built-in scenes for the evaluation: the failure cases of DESIGN §4 ("known limits to test,
//! not hide") and the animated variants `<scene>-moving` whose node TRS animations drive the
//! temporal-stability metric. All procedural, in metres, one punctual light each.
//!
//! - `corridor`: two rooms joined by a door (opening angle a parameter: `corridor-door<DEG>`);
//!   the light reaches the second room only by bouncing.
//! - `door-room`: a room lit only through a door ajar, the spot in the next room shining
//!   through the doorway (opening angle a parameter: `door-room<DEG>`, 10°..=90°).
//! - `coarse-wall`: a large wall of two triangles beside a lit object.
//! - `aligned-occluders`: two blockers in a row between a lit wall and a receiver.
//! - `thin-wall`: a 2 cm wall (thinner than any practical LPV cell) with light on one side.
//! - `glossy-row`: spheres with Phong k = 1, 10, 100, 1000 in a coloured room.
//! - `bunny-box` (seed 002's test scene): the full-resolution Stanford bunny (`bun_zipper.ply`,
//!   69,451 triangles) floating 0.8 m tall in a 3 m × 2.5 m × 3 m box (x ∈ [−1.5, 1.5],
//!   y ∈ [0, 2.5], z ∈ [−1.5, 1.5]) whose six walls are two triangles each (left red, right
//!   blue, the rest white, ρ = 0.75), lit by one spot at (0.9, 2.3, 1.1) aimed at the bunny
//!   (cones 25°/35°); the camera stands inside at (0, 1.25, 1.45) looking at (0, 0.95, 0), 50°
//!   vertical field of view. `bunny-box-empty` is the same box without the bunny,
//!   `bunny-box-res4` the same with the 948-triangle `bun_zipper_res4.ply`.
//! - `arcade`: a sunlit court and a roofed gallery behind five pillars; the sun reaches the
//!   gallery floor in stripes between the pillars' shadows (seed 001's Fig. 9 case: bounces 1
//!   and 2 land on different surfaces). In `arcade-moving` the sun turns about the vertical.
//! - `cornell-bunny`: the Stanford bunny (ASCII PLY from the shared data folder) in the Cornell
//!   box in place of the short block; a procedural stand-in, named as such, when absent.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Quat, Vec2, Vec3, Vec4};

use super::super::mesh::{compute_normals, tessellate, MeshBuilder};
use super::super::{
    Animation, Camera, Channel, FovAxis, Interpolation, LightKind, Material, Mesh, Property, Scene,
    SceneError, Trs,
};
use super::{cornell, CornellLight, SceneBuilder};

/// Seconds of one loop of every built-in animation (it returns to its start pose).
pub const LOOP_SECONDS: f32 = 4.0;

/// Default door opening of `corridor`, degrees (0 = closed, 90 = wide open).
pub const CORRIDOR_DOOR_DEGREES: f32 = 60.0;

/// Default door opening of `door-room`, degrees.
pub const DOOR_ROOM_DEGREES: f32 = 30.0;

/// Door openings `door-room<DEG>` accepts, degrees.
pub const DOOR_ROOM_RANGE: std::ops::RangeInclusive<f32> = 10.0..=90.0;

/// Names this module builds, with descriptions (the `-moving` variants follow each scene).
pub const NAMES: &[(&str, &str)] = &[
    (
        "cornell-moving",
        "cornell with the spot light sweeping and the short block sliding (4 s loop)",
    ),
    (
        "corridor",
        "two rooms joined by a door opened 60° (corridor-door<DEG> sets it); light reaches the second room only by bouncing",
    ),
    ("corridor-moving", "corridor with the door swinging 10°–90°"),
    (
        "door-room",
        "a room lit only through a door opened 30° (door-room<DEG> sets it, 10..=90), the spot in the next room shining through the doorway",
    ),
    ("door-room-moving", "door-room with the door swinging 10°–90°"),
    (
        "coarse-wall",
        "a 3 m wall of two triangles beside a spot-lit orange block",
    ),
    ("coarse-wall-moving", "coarse-wall with the block sliding along the wall"),
    (
        "aligned-occluders",
        "two blockers in a row between a spot-lit wall and a receiving wall",
    ),
    (
        "aligned-occluders-moving",
        "aligned-occluders with the blockers sliding sideways together",
    ),
    (
        "thin-wall",
        "a 2 cm wall dividing a room, the light on one side only",
    ),
    ("thin-wall-moving", "thin-wall with the light moving along the wall"),
    (
        "glossy-row",
        "spheres with Phong k = 1, 10, 100, 1000 in a red/green/blue room",
    ),
    ("glossy-row-moving", "glossy-row with the light moving along the row"),
    (
        "arcade",
        "a sunlit court and a roofed gallery behind five pillars; the sun falls in stripes on the gallery floor",
    ),
    (
        "arcade-moving",
        "arcade with the sun turning 15° either way about the vertical (the pillars' shadows sweep)",
    ),
    (
        "cornell-bunny",
        "Cornell box with the Stanford bunny (../shared/data/bunny; a procedural stand-in when absent)",
    ),
    ("cornell-bunny-moving", "cornell-bunny with the bunny turning"),
    (
        "bunny-box",
        "seed 002's scene: the full Stanford bunny floating in a box of two-triangle walls, one spot",
    ),
    ("bunny-box-moving", "bunny-box with the bunny turning"),
    ("bunny-box-empty", "bunny-box without the bunny (a convex empty box)"),
    (
        "bunny-box-res4",
        "bunny-box with the 948-triangle bunny (bun_zipper_res4.ply)",
    ),
];

/// Builds the scene `name` if this module knows it.
pub fn load(name: &str, max_edge: f32) -> Option<Result<Scene, SceneError>> {
    let (base, moving) = match name.strip_suffix("-moving") {
        Some(base) => (base, true),
        None => (name, false),
    };
    let scene = match base {
        "cornell" if moving => Ok(cornell_moving(name, max_edge)),
        "corridor" => Ok(corridor(name, CORRIDOR_DOOR_DEGREES, moving, max_edge)),
        "door-room" => Ok(door_room(name, DOOR_ROOM_DEGREES, moving, max_edge)),
        "coarse-wall" => Ok(coarse_wall(name, moving, max_edge)),
        "aligned-occluders" => Ok(aligned_occluders(name, moving, max_edge)),
        "thin-wall" => Ok(thin_wall(name, moving, max_edge)),
        "glossy-row" => Ok(glossy_row(name, moving, max_edge)),
        "arcade" => Ok(arcade(name, moving, max_edge)),
        "cornell-bunny" => cornell_bunny(name, moving, max_edge),
        "bunny-box" => bunny_box(name, Some("bun_zipper.ply"), moving),
        "bunny-box-res4" => bunny_box(name, Some("bun_zipper_res4.ply"), moving),
        "bunny-box-empty" => bunny_box(name, None, moving),
        other if other.starts_with("door-room") => {
            let degrees = &other["door-room".len()..];
            match degrees.parse::<f32>() {
                Ok(d) if DOOR_ROOM_RANGE.contains(&d) => Ok(door_room(name, d, moving, max_edge)),
                _ => Err(SceneError::Other {
                    path: name.into(),
                    message: format!(
                        "door angle '{degrees}' must be degrees in {}..={}",
                        DOOR_ROOM_RANGE.start(),
                        DOOR_ROOM_RANGE.end()
                    ),
                }),
            }
        }
        other => {
            let degrees = other.strip_prefix("corridor-door")?;
            match degrees.parse::<f32>() {
                Ok(d) if (0.0..=180.0).contains(&d) => Ok(corridor(name, d, moving, max_edge)),
                _ => Err(SceneError::Other {
                    path: name.into(),
                    message: format!("door angle '{degrees}' must be degrees in 0..=180"),
                }),
            }
        }
    };
    Some(scene)
}

fn grey(b: &mut SceneBuilder, name: &str, rho: f32) -> usize {
    b.material(Material::lambert(name, Vec3::splat(rho)))
}

fn camera(b: &mut SceneBuilder, eye: Vec3, target: Vec3, yfov_degrees: f32) {
    b.camera(
        Camera {
            name: "camera".into(),
            node: 0,
            yfov: yfov_degrees.to_radians(),
            fov_axis: FovAxis::Vertical,
            aspect: None,
            znear: 0.02,
            zfar: Some(20.0),
        },
        Trs::looking_at(eye, target),
    );
}

/// The four corners of the face of box [min, max] on `axis` (0..3) at the `max` side or not.
fn box_face(min: Vec3, max: Vec3, axis: usize, high: bool) -> [Vec3; 4] {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let corner = |a: f32, b: f32| {
        let mut p = Vec3::ZERO;
        p[axis] = if high { max[axis] } else { min[axis] };
        p[u] = if a > 0.0 { max[u] } else { min[u] };
        p[v] = if b > 0.0 { max[v] } else { min[v] };
        p
    };
    [
        corner(0.0, 0.0),
        corner(1.0, 0.0),
        corner(1.0, 1.0),
        corner(0.0, 1.0),
    ]
}

/// Inward-facing walls of the room [min, max], one object per face; `materials` per face in
/// the order −x, +x, floor (−y), ceiling (+y), −z, +z.
fn room(b: &mut SceneBuilder, min: Vec3, max: Vec3, materials: [usize; 6], max_edge: f32) {
    let names = [
        "wall_-x", "wall_+x", "floor", "ceiling", "wall_-z", "wall_+z",
    ];
    let centre = (min + max) * 0.5;
    for (i, name) in names.iter().enumerate() {
        let [p0, p1, p2, p3] = box_face(min, max, [0, 0, 1, 1, 2, 2][i], i % 2 == 1);
        let mut mb = MeshBuilder::new(name, materials[i]);
        mb.add_quad(p0, p1, p2, p3, centre, max_edge);
        b.object(name, mb.build(), Trs::default());
    }
}

/// A closed box [min, max] (outward normals) added to `mb`.
fn solid_box(mb: &mut MeshBuilder, min: Vec3, max: Vec3, max_edge: f32) {
    let centre = (min + max) * 0.5;
    for i in 0..6 {
        let face = box_face(min, max, i / 2, i % 2 == 1);
        let face_centre = (face[0] + face[1] + face[2] + face[3]) * 0.25;
        mb.add_quad(
            face[0],
            face[1],
            face[2],
            face[3],
            face_centre + (face_centre - centre),
            max_edge,
        );
    }
}

fn add_animation(scene: &mut Scene, name: &str, channels: Vec<Channel>) {
    scene.animations.push(Animation {
        name: name.into(),
        channels,
    });
}

/// A linear channel through `values` at evenly spaced keys over one loop.
fn channel(node: usize, property: Property, values: Vec<Vec4>) -> Channel {
    let n = values.len().max(2) - 1;
    Channel {
        node,
        property,
        interpolation: Interpolation::Linear,
        times: (0..values.len())
            .map(|i| LOOP_SECONDS * i as f32 / n as f32)
            .collect(),
        values,
    }
}

/// Animates the scene's first light to swing from `at` to `at + reach`, back, to `at − reach`
/// and back over one loop.
fn swing_first_light(scene: &mut Scene, at: Vec3, reach: Vec3) {
    let node = scene.lights[0].node;
    let offsets = [Vec3::ZERO, reach, Vec3::ZERO, -reach, Vec3::ZERO];
    add_animation(
        scene,
        "light moves",
        vec![channel(
            node,
            Property::Translation,
            translations(at, &offsets),
        )],
    );
}

fn translations(base: Vec3, offsets: &[Vec3]) -> Vec<Vec4> {
    offsets.iter().map(|o| (base + *o).extend(0.0)).collect()
}

fn rotations(quats: &[Quat]) -> Vec<Vec4> {
    quats.iter().map(|q| Vec4::from(*q)).collect()
}

fn node_named(scene: &Scene, name: &str) -> usize {
    scene
        .nodes
        .iter()
        .position(|n| n.name == name)
        .unwrap_or_else(|| panic!("built-in scene has no node {name}"))
}

/// `cornell` with the spot sweeping ±20° about z and the short block sliding 8 cm and back.
fn cornell_moving(name: &str, max_edge: f32) -> Scene {
    let mut scene = cornell(name, CornellLight::Spot, max_edge);
    let light = scene.lights[0].node;
    let rest = scene.nodes[light].local.rotation;
    let tilt = |deg: f32| Quat::from_rotation_z(deg.to_radians()) * rest;
    let block = node_named(&scene, "short_box");
    let origin = scene.nodes[block].local.translation;
    add_animation(
        &mut scene,
        "sweep and slide",
        vec![
            channel(
                light,
                Property::Rotation,
                rotations(&[tilt(-20.0), tilt(0.0), tilt(20.0), tilt(0.0), tilt(-20.0)]),
            ),
            channel(
                block,
                Property::Translation,
                translations(
                    origin,
                    &[Vec3::ZERO, Vec3::new(0.08, 0.0, 0.04), Vec3::ZERO],
                ),
            ),
        ],
    );
    scene
}

/// Two 2.1 × 2.4 × 2 m rooms side by side (x < 2.1 and x > 2.1) sharing a zero-thickness wall
/// with a 0.8 × 1.9 m doorway; a door panel hinged at the doorway's edge, opened `door_degrees`
/// into the second room. A spot in the first room points down with a 30° cone that cannot
/// reach the doorway, so the second room is lit by bounced light only. The camera stands in
/// the second room looking back at the door.
/// A partition across a room at `x` (height, depth) with a doorway over `z`, up to
/// `door_height`, and its door: a panel hinged at (x, 0, z.0) that turns about y into +x.
struct Doorway {
    x: f32,
    height: f32,
    depth: f32,
    z: (f32, f32),
    door_height: f32,
}

impl Doorway {
    /// The door's turn about its hinge when open by `degrees`.
    fn opening(degrees: f32) -> Quat {
        Quat::from_rotation_y(degrees.to_radians())
    }

    /// The `-moving` variants: the door swings 10° → 90° → 10°.
    fn swing(scene: &mut Scene) {
        let door_node = node_named(scene, "door");
        add_animation(
            scene,
            "door swing",
            vec![channel(
                door_node,
                Property::Rotation,
                rotations(&[
                    Self::opening(10.0),
                    Self::opening(90.0),
                    Self::opening(10.0),
                ]),
            )],
        );
    }

    /// Adds the objects `partition` and `door` (the door open by `door_degrees`).
    fn build(
        &self,
        b: &mut SceneBuilder,
        wall_material: usize,
        door_material: usize,
        door_degrees: f32,
        max_edge: f32,
    ) {
        let (x, h, d, (z0, z1), door_h) =
            (self.x, self.height, self.depth, self.z, self.door_height);
        // Partition and door are zero-thickness sheets seen from both rooms: two-sided.
        let two_sided = |b: &mut SceneBuilder, m: usize| {
            let mut material = b.scene.materials[m].clone();
            material.name = format!("{} (two-sided)", material.name);
            material.double_sided = true;
            b.material(material)
        };
        let wall_material = two_sided(b, wall_material);
        let door_material = two_sided(b, door_material);
        let mut wall = MeshBuilder::new("partition", wall_material);
        let facing = Vec3::new(0.0, 1.0, 1.0);
        let q = |y0: f32, y1: f32, za: f32, zb: f32| {
            [
                Vec3::new(x, y0, za),
                Vec3::new(x, y0, zb),
                Vec3::new(x, y1, zb),
                Vec3::new(x, y1, za),
            ]
        };
        for [p0, p1, p2, p3] in [q(0.0, h, 0.0, z0), q(0.0, h, z1, d), q(door_h, h, z0, z1)] {
            wall.add_quad(p0, p1, p2, p3, facing, max_edge);
        }
        b.object("partition", wall.build(), Trs::default());
        // The door panel in model space spans z ∈ [0, width] at x = 0; its node sits on the
        // hinge.
        let mut door = MeshBuilder::new("door", door_material);
        let w = z1 - z0;
        door.add_quad(
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, w),
            Vec3::new(0.0, door_h, w),
            Vec3::new(0.0, door_h, 0.0),
            Vec3::new(-1.0, 0.0, w * 0.5),
            max_edge,
        );
        b.object(
            "door",
            door.build(),
            Trs {
                translation: Vec3::new(x, 0.0, z0),
                rotation: Self::opening(door_degrees),
                ..Trs::default()
            },
        );
    }
}

fn corridor(name: &str, door_degrees: f32, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.75);
    let floor = grey(&mut b, "floor", 0.6);
    let door_mat = b.material(Material::lambert("door", Vec3::new(0.6, 0.45, 0.3)));
    let (len, h, d) = (4.2, 2.4, 2.0);
    room(
        &mut b,
        Vec3::ZERO,
        Vec3::new(len, h, d),
        [white, white, floor, white, white, white],
        max_edge,
    );
    let x = 2.1;
    let (z0, z1, door_h) = (0.6, 1.4, 1.9);
    let door = Doorway {
        x,
        height: h,
        depth: d,
        z: (z0, z1),
        door_height: door_h,
    };
    door.build(&mut b, white, door_mat, door_degrees, max_edge);
    b.light(
        "spot",
        Vec3::new(0.5, 2.3, 1.0),
        LightKind::Spot {
            inner_cone_angle: 20f32.to_radians(),
            outer_cone_angle: 30f32.to_radians(),
        },
        2.0,
    );
    camera(
        &mut b,
        Vec3::new(4.0, 1.5, 1.7),
        Vec3::new(2.1, 0.8, 0.9),
        65.0,
    );
    let mut scene = b.scene;
    if moving {
        Doorway::swing(&mut scene);
    }
    scene
}

/// Dimensions of `door-room` (metres): room A, x ∈ [0, 2.5], holds the light; room B, x ∈
/// [2.5, 6.5], is lit only through the doorway; both y ∈ [0, 2.5] (floor to ceiling), z ∈ [0, 3].
/// The partition at x = 2.5 has zero thickness and a doorway z ∈ [1.0, 1.9], y ∈ [0, 2.0].
pub const DOOR_ROOM: DoorRoom = DoorRoom {
    length_a: 2.5,
    length_b: 4.0,
    height: 2.5,
    depth: 3.0,
    doorway_z: (1.0, 1.9),
    doorway_height: 2.0,
    spot: Vec3::new(0.4, 2.0, 1.45),
    spot_target: Vec3::new(3.7, 0.4, 1.45),
};

/// The measurements of [`DOOR_ROOM`].
#[derive(Clone, Copy, Debug)]
pub struct DoorRoom {
    /// Room A (the light's) along x, from x = 0 to the partition.
    pub length_a: f32,
    /// Room B (lit through the door) along x, from the partition on.
    pub length_b: f32,
    pub height: f32,
    pub depth: f32,
    /// The doorway's extent along z in the partition.
    pub doorway_z: (f32, f32),
    pub doorway_height: f32,
    pub spot: Vec3,
    /// Where the spot's axis meets room B's floor.
    pub spot_target: Vec3,
}

/// Two rooms side by side sharing a zero-thickness partition with a doorway (see [`DOOR_ROOM`]
/// for the measurements). A door panel hinged at the doorway's z = 1.0 edge opens
/// `door_degrees` into room B (90° = flat against nothing, perpendicular to the partition).
/// A spot (inner 15°, outer 22°, 8 W/sr) in room A stands 0.4 m from its far wall, 2 m up,
/// and points through the doorway at room B's floor 1.2 m behind the partition: room B gets
/// direct light only through the opening the door leaves, and its bounces. The camera stands
/// in room B's far corner looking back at the door.
fn door_room(name: &str, door_degrees: f32, moving: bool, max_edge: f32) -> Scene {
    let dims = DOOR_ROOM;
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.75);
    let floor = grey(&mut b, "floor", 0.6);
    let door_mat = b.material(Material::lambert("door", Vec3::new(0.6, 0.45, 0.3)));
    let (x, h, d) = (dims.length_a, dims.height, dims.depth);
    room(
        &mut b,
        Vec3::ZERO,
        Vec3::new(x + dims.length_b, h, d),
        [white, white, floor, white, white, white],
        max_edge,
    );
    let z0 = dims.doorway_z.0;
    let door = Doorway {
        x,
        height: h,
        depth: d,
        z: dims.doorway_z,
        door_height: dims.doorway_height,
    };
    door.build(&mut b, white, door_mat, door_degrees, max_edge);
    b.light_along(
        "spot",
        dims.spot,
        dims.spot_target - dims.spot,
        LightKind::Spot {
            inner_cone_angle: 15f32.to_radians(),
            outer_cone_angle: 22f32.to_radians(),
        },
        8.0,
    );
    camera(
        &mut b,
        Vec3::new(x + dims.length_b - 0.3, 1.6, d - 0.3),
        Vec3::new(x, 0.9, z0),
        70.0,
    );
    let mut scene = b.scene;
    if moving {
        Doorway::swing(&mut scene);
    }
    scene
}

/// A 3 × 2 m wall made of exactly two triangles (whatever `max_edge` says: the point of the
/// scene), a tessellated floor, and an orange block 0.3 m in front of the wall under a spot
/// light. The wall's bounce light from the block is a small bright patch that per-vertex
/// methods cannot resolve on two triangles (the sparse methods refine the wall to their
/// points' spacing when loaded without `--max-edge`: `scene::load_choosing_max_edge`).
fn coarse_wall(name: &str, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.8);
    let orange = b.material(Material::lambert("orange", Vec3::new(0.85, 0.4, 0.1)));
    let mut wall = MeshBuilder::new(COARSE_WALL_MESH, white);
    wall.add_quad(
        Vec3::new(-1.5, 0.0, 0.0),
        Vec3::new(1.5, 0.0, 0.0),
        Vec3::new(1.5, 2.0, 0.0),
        Vec3::new(-1.5, 2.0, 0.0),
        Vec3::new(0.0, 1.0, 1.0),
        f32::INFINITY,
    );
    b.object(COARSE_WALL_MESH, wall.build(), Trs::default());
    let mut floor = MeshBuilder::new("floor", white);
    floor.add_quad(
        Vec3::new(-1.5, 0.0, 0.0),
        Vec3::new(1.5, 0.0, 0.0),
        Vec3::new(1.5, 0.0, 3.0),
        Vec3::new(-1.5, 0.0, 3.0),
        Vec3::Y,
        max_edge,
    );
    b.object("floor", floor.build(), Trs::default());
    let mut block = MeshBuilder::new("block", orange);
    solid_box(
        &mut block,
        Vec3::new(-0.2, 0.0, -0.2),
        Vec3::new(0.2, 0.4, 0.2),
        max_edge,
    );
    let block_at = Vec3::new(0.0, 0.0, 0.5);
    b.object(
        "block",
        block.build(),
        Trs {
            translation: block_at,
            ..Trs::default()
        },
    );
    b.light_along(
        "spot",
        Vec3::new(0.0, 1.6, 1.4),
        Vec3::new(0.0, 0.2, 0.5) - Vec3::new(0.0, 1.6, 1.4),
        LightKind::Spot {
            inner_cone_angle: 15f32.to_radians(),
            outer_cone_angle: 25f32.to_radians(),
        },
        2.0,
    );
    camera(
        &mut b,
        Vec3::new(0.0, 1.2, 3.2),
        Vec3::new(0.0, 0.6, 0.2),
        55.0,
    );
    let mut scene = b.scene;
    if moving {
        let node = node_named(&scene, "block");
        add_animation(
            &mut scene,
            "slide",
            vec![channel(
                node,
                Property::Translation,
                translations(
                    block_at,
                    &[
                        Vec3::ZERO,
                        Vec3::new(0.7, 0.0, 0.0),
                        Vec3::ZERO,
                        Vec3::new(-0.7, 0.0, 0.0),
                        Vec3::ZERO,
                    ],
                ),
            )],
        );
    }
    scene
}

/// Name of the two-triangle wall of `coarse-wall` (exempt from the tessellation bound).
pub const COARSE_WALL_MESH: &str = "coarse_wall";

/// A wall at x = 0 lit by a spot, a receiving wall at x = 3 facing it, a floor, and two 0.5 m
/// square blockers in a row on the line between the walls' centres (at x = 1 and x = 2).
fn aligned_occluders(name: &str, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.8);
    let dark = grey(&mut b, "blocker", 0.4);
    let floor_mat = grey(&mut b, "floor", 0.5);
    let wall = |b: &mut SceneBuilder, name: &str, x: f32, facing_x: f32| {
        let mut mb = MeshBuilder::new(name, white);
        mb.add_quad(
            Vec3::new(x, 0.0, -1.0),
            Vec3::new(x, 0.0, 1.0),
            Vec3::new(x, 2.0, 1.0),
            Vec3::new(x, 2.0, -1.0),
            Vec3::new(facing_x, 1.0, 0.0),
            max_edge,
        );
        b.object(name, mb.build(), Trs::default());
    };
    wall(&mut b, "lit_wall", 0.0, 1.0);
    wall(&mut b, "receiver", 3.0, 2.0);
    let mut floor = MeshBuilder::new("floor", floor_mat);
    floor.add_quad(
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(3.0, 0.0, -1.0),
        Vec3::new(3.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::Y,
        max_edge,
    );
    b.object("floor", floor.build(), Trs::default());
    let mut blocker_nodes = vec![];
    for (i, x) in [1.0f32, 2.0].into_iter().enumerate() {
        let mut mb = MeshBuilder::new(&format!("blocker_{i}"), dark);
        solid_box(
            &mut mb,
            Vec3::new(-0.05, 0.75, -0.25),
            Vec3::new(0.05, 1.25, 0.25),
            max_edge,
        );
        let name = format!("blocker_{i}");
        b.object(
            &name,
            mb.build(),
            Trs {
                translation: Vec3::new(x, 0.0, 0.0),
                ..Trs::default()
            },
        );
        blocker_nodes.push((name, x));
    }
    b.light_along(
        "spot",
        Vec3::new(1.5, 1.9, 0.8),
        Vec3::new(0.0, 1.0, 0.0) - Vec3::new(1.5, 1.9, 0.8),
        LightKind::Spot {
            inner_cone_angle: 20f32.to_radians(),
            outer_cone_angle: 30f32.to_radians(),
        },
        3.0,
    );
    camera(
        &mut b,
        Vec3::new(1.5, 1.3, 3.2),
        Vec3::new(1.5, 0.9, 0.0),
        65.0,
    );
    let mut scene = b.scene;
    if moving {
        let channels = blocker_nodes
            .iter()
            .map(|(name, x)| {
                channel(
                    node_named(&scene, name),
                    Property::Translation,
                    translations(
                        Vec3::new(*x, 0.0, 0.0),
                        &[
                            Vec3::ZERO,
                            Vec3::new(0.0, 0.0, 0.4),
                            Vec3::ZERO,
                            Vec3::new(0.0, 0.0, -0.4),
                            Vec3::ZERO,
                        ],
                    ),
                )
            })
            .collect();
        add_animation(&mut scene, "blockers slide", channels);
    }
    scene
}

/// A 4 × 2.4 × 3 m room divided at x = 2 by a 2 cm thick, 1.8 m high wall; a downward spot in
/// the left half whose cone clears the wall's top, so the right half (where the camera looks
/// at the wall) receives bounced light only, over the wall.
fn thin_wall(name: &str, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.75);
    let wall_mat = b.material(Material::lambert("wall", Vec3::new(0.7, 0.7, 0.5)));
    room(
        &mut b,
        Vec3::ZERO,
        Vec3::new(4.0, 2.4, 3.0),
        [white; 6],
        max_edge,
    );
    let mut wall = MeshBuilder::new("thin_wall", wall_mat);
    solid_box(
        &mut wall,
        Vec3::new(1.99, 0.0, 0.0),
        Vec3::new(2.01, 1.8, 3.0),
        max_edge,
    );
    b.object("thin_wall", wall.build(), Trs::default());
    let light_at = Vec3::new(1.0, 2.2, 1.5);
    b.light(
        "spot",
        light_at,
        LightKind::Spot {
            inner_cone_angle: 35f32.to_radians(),
            outer_cone_angle: 45f32.to_radians(),
        },
        2.0,
    );
    camera(
        &mut b,
        Vec3::new(3.85, 1.5, 1.5),
        Vec3::new(2.0, 0.8, 1.5),
        70.0,
    );
    let mut scene = b.scene;
    if moving {
        swing_first_light(&mut scene, light_at, Vec3::new(0.0, 0.0, 0.7));
    }
    scene
}

/// An 8 × 8 m court (floor y = 0) closed by walls 4 m high and 0.25 m thick on three sides
/// (x = 0, x = 8, z = 0), with a gallery along the back wall: a roof slab y ∈ [3, 3.3] over z ∈ [0, 2.5]
/// standing on five 0.4 m pillars at its front edge. The sun (3 W/m², travelling along
/// (0.25, −1, −0.6)) lights the court and, between the pillars' shadows, the gallery floor
/// from z ≈ 0.7 to 2.5; the back wall and the roof's underside get bounced light only. So the
/// first bounce's light on the gallery floor comes in stripes whose gaps the second bounce
/// fills: what clustering bounces jointly smears (seed 001, Fig. 9).
fn arcade(name: &str, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let stone = b.material(Material::lambert("stone", Vec3::new(0.7, 0.65, 0.55)));
    let floor_mat = b.material(Material::lambert("floor", Vec3::new(0.6, 0.55, 0.5)));
    let (size, wall_h) = (8.0, 4.0);
    let court = Vec3::new(size, wall_h, size);
    let centre = court * 0.5;
    let [p0, p1, p2, p3] = box_face(Vec3::ZERO, court, 1, false);
    let mut floor = MeshBuilder::new("floor", floor_mat);
    floor.add_quad(p0, p1, p2, p3, centre, max_edge);
    b.object("floor", floor.build(), Trs::default());
    // The walls are solid, 0.25 m thick outside the court: a sheet lit from behind would
    // leave nothing beyond its foot in the sun's shadow map, and the filter taps there would
    // let a line of light in along it.
    let t = 0.25;
    let walls = [
        (
            "wall_-x",
            Vec3::new(-t, 0.0, 0.0),
            Vec3::new(0.0, wall_h, size),
        ),
        (
            "wall_+x",
            Vec3::new(size, 0.0, 0.0),
            Vec3::new(size + t, wall_h, size),
        ),
        (
            "back_wall",
            Vec3::new(-t, 0.0, -t),
            Vec3::new(size + t, wall_h, 0.0),
        ),
    ];
    for (object, min, max) in walls {
        let mut mb = MeshBuilder::new(object, stone);
        solid_box(&mut mb, min, max, max_edge);
        b.object(object, mb.build(), Trs::default());
    }
    let (roof_y, depth, pillar) = (3.0, 2.5, 0.4);
    let mut gallery = MeshBuilder::new("gallery", stone);
    solid_box(
        &mut gallery,
        Vec3::new(0.0, roof_y, 0.0),
        Vec3::new(size, roof_y + 0.3, depth),
        max_edge,
    );
    for i in 0..5 {
        let x = 0.2 + 1.9 * i as f32;
        solid_box(
            &mut gallery,
            Vec3::new(x - 0.5 * pillar, 0.0, depth - pillar),
            Vec3::new(x + 0.5 * pillar, roof_y, depth),
            max_edge,
        );
    }
    b.object("gallery", gallery.build(), Trs::default());
    let sun_direction = Vec3::new(0.25, -1.0, -0.6);
    b.light_along(
        "sun",
        Vec3::new(4.0, 6.0, 6.0),
        sun_direction,
        LightKind::Directional,
        3.0,
    );
    // From the court's far corner into the gallery: its floor, back wall and roof underside.
    camera(
        &mut b,
        Vec3::new(6.2, 2.2, 6.5),
        Vec3::new(2.5, 0.8, 1.0),
        60.0,
    );
    let mut scene = b.scene;
    if moving {
        // The sun's azimuth sweeps ±15° (a time-of-day change), its elevation kept.
        let node = scene.lights[0].node;
        let at = |degrees: f32| {
            let turned = Quat::from_rotation_y(degrees.to_radians()) * sun_direction;
            Quat::from_rotation_arc(Vec3::NEG_Z, turned.normalize())
        };
        add_animation(
            &mut scene,
            "sun turns",
            vec![channel(
                node,
                Property::Rotation,
                rotations(&[at(0.0), at(15.0), at(0.0), at(-15.0), at(0.0)]),
            )],
        );
    }
    scene
}

/// Roughness giving the Phong exponent `k` under DESIGN §3's mapping
/// (k = 2/α² − 2, α = roughness²).
pub fn roughness_for_exponent(k: f32) -> f32 {
    (2.0 / (k + 2.0)).sqrt().sqrt()
}

/// Exponents of the `glossy-row` spheres, left to right.
pub const GLOSSY_ROW_EXPONENTS: [f32; 4] = [1.0, 10.0, 100.0, 1000.0];

/// A 4 × 2.5 × 3 m room with a red left wall, green right wall and blue back wall; four
/// spheres (r = 0.28 m, ρ_d = 0.45, ρ_s ≈ 0.47) with Phong k = 1, 10, 100, 1000 in a row on
/// the floor, lit by a point light in front of them.
fn glossy_row(name: &str, moving: bool, max_edge: f32) -> Scene {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.75);
    let red = b.material(Material::lambert("red", Vec3::new(0.7, 0.1, 0.1)));
    let green = b.material(Material::lambert("green", Vec3::new(0.1, 0.6, 0.1)));
    let blue = b.material(Material::lambert("blue", Vec3::new(0.1, 0.15, 0.7)));
    room(
        &mut b,
        Vec3::ZERO,
        Vec3::new(4.0, 2.5, 3.0),
        [red, green, white, white, blue, white],
        max_edge,
    );
    let radius = 0.28;
    for (i, k) in GLOSSY_ROW_EXPONENTS.into_iter().enumerate() {
        let material = b.material(Material {
            name: format!("phong k={k}"),
            base_color: Vec4::new(0.9, 0.9, 0.9, 1.0),
            metallic: 0.5,
            roughness: roughness_for_exponent(k),
            ..Material::default()
        });
        let mesh = icosphere(&format!("sphere_k{k}"), material, radius, max_edge, false);
        b.object(
            &format!("sphere_k{k}"),
            mesh,
            Trs {
                translation: Vec3::new(0.8 + 0.8 * i as f32, radius, 1.0),
                ..Trs::default()
            },
        );
    }
    let light_at = Vec3::new(2.0, 1.9, 2.0);
    b.light("point", light_at, LightKind::Point, 1.0);
    camera(
        &mut b,
        Vec3::new(2.0, 1.2, 2.9),
        Vec3::new(2.0, 0.45, 0.9),
        60.0,
    );
    let mut scene = b.scene;
    if moving {
        swing_first_light(&mut scene, light_at, Vec3::new(1.2, 0.0, 0.0));
    }
    scene
}

/// A sphere of `radius` about the model origin: an icosahedron subdivided (and projected onto
/// the sphere) until no edge exceeds `max_edge`; normals radial (inward when `inward`, with the
/// winding flipped to match).
pub fn icosphere(name: &str, material: usize, radius: f32, max_edge: f32, inward: bool) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let longest = |positions: &[Vec3], tris: &[[u32; 3]]| {
        tris.iter()
            .flat_map(|t| {
                [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
                    .map(|(a, b)| positions[a as usize].distance(positions[b as usize]))
            })
            .fold(0.0f32, f32::max)
            * radius
    };
    let max_edge = if max_edge.is_finite() && max_edge > 0.0 {
        max_edge
    } else {
        f32::INFINITY
    };
    // Level 7 is 327 680 triangles: enough for any sensible max_edge.
    for _ in 0..7 {
        if longest(&positions, &tris) <= max_edge {
            break;
        }
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *midpoints.entry(key).or_insert_with(|| {
                positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    let sign = if inward { -1.0 } else { 1.0 };
    let normals = positions.iter().map(|p| *p * sign).collect();
    let uv0 = positions
        .iter()
        .map(|p| {
            Vec2::new(
                0.5 + p.z.atan2(p.x) / std::f32::consts::TAU,
                0.5 - p.y.asin() / std::f32::consts::PI,
            )
        })
        .collect();
    let indices = tris
        .into_iter()
        .flat_map(|[a, b, c]| if inward { [a, c, b] } else { [a, b, c] })
        .collect();
    Mesh {
        name: name.into(),
        positions: positions.iter().map(|p| *p * radius).collect(),
        normals,
        tangents: vec![],
        uv0,
        uv1: None,
        indices,
        material,
    }
}

/// Where the Stanford bunny is looked for: `$VALGI_BUNNY` alone when set, else the shared
/// data folder beside the working directory and beside the crate.
pub fn bunny_candidates() -> Vec<PathBuf> {
    let mut paths = vec![];
    if let Some(p) = std::env::var_os("VALGI_BUNNY") {
        paths.push(PathBuf::from(p));
        return paths;
    }
    let rel = Path::new("../shared/data/bunny/bun_zipper_res2.ply");
    paths.push(rel.to_path_buf());
    paths.push(Path::new(env!("CARGO_MANIFEST_DIR")).join(rel));
    paths
}

/// Seed 002's scene (dimensions in the module documentation) with the bunny PLY `bunny` of
/// the shared data folder (none: the empty box); a missing file gives the procedural
/// stand-in and a warning.
fn bunny_box(name: &str, bunny: Option<&str>, moving: bool) -> Result<Scene, SceneError> {
    let mut b = SceneBuilder::new(name);
    let white = grey(&mut b, "white", 0.75);
    let red = b.material(Material::lambert("red", Vec3::new(0.75, 0.15, 0.12)));
    let blue = b.material(Material::lambert("blue", Vec3::new(0.12, 0.2, 0.75)));
    let bunny_material = grey(&mut b, "bunny", 0.75);
    let (lo, hi) = (Vec3::new(-1.5, 0.0, -1.5), Vec3::new(1.5, 2.5, 1.5));
    let corner = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { hi.x } else { lo.x },
            if y { hi.y } else { lo.y },
            if z { hi.z } else { lo.z },
        )
    };
    let walls = [
        (
            "floor",
            white,
            [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)],
            Vec3::Y,
        ),
        (
            "ceiling",
            white,
            [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)],
            Vec3::NEG_Y,
        ),
        (
            "left wall",
            red,
            [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)],
            Vec3::X,
        ),
        (
            "right wall",
            blue,
            [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)],
            Vec3::NEG_X,
        ),
        (
            "back wall",
            white,
            [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)],
            Vec3::Z,
        ),
        (
            "front wall",
            white,
            [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
            Vec3::NEG_Z,
        ),
    ];
    for (wall_name, material, c, facing) in walls {
        let mut mesh = MeshBuilder::new(wall_name, material);
        let p = c.map(|(x, y, z)| corner(x == 1, y == 1, z == 1));
        mesh.add_quad(p[0], p[1], p[2], p[3], facing, f32::INFINITY);
        b.object(wall_name, mesh.build(), Trs::default());
    }
    let bunny_at = Vec3::new(0.0, 0.55, 0.0);
    if let Some(file) = bunny {
        let rel = Path::new("../shared/data/bunny").join(file);
        let candidates = vec![
            rel.clone(),
            Path::new(env!("CARGO_MANIFEST_DIR")).join(&rel),
        ];
        let (mut mesh, warning) = bunny_mesh(&candidates)?;
        if let Some(warning) = warning {
            b.scene.warnings.push(format!("{name}: {warning}"));
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in &mesh.positions {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let scale = 0.8 / (hi.y - lo.y).max(1e-6);
        let centre = Vec3::new((lo.x + hi.x) * 0.5, lo.y, (lo.z + hi.z) * 0.5);
        for p in &mut mesh.positions {
            *p = (*p - centre) * scale;
        }
        mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
        if mesh.uv0.len() != mesh.positions.len() {
            mesh.uv0 = vec![Vec2::ZERO; mesh.positions.len()];
        }
        mesh.material = bunny_material;
        b.object(
            "bunny",
            mesh,
            Trs {
                translation: bunny_at,
                ..Trs::default()
            },
        );
    }
    b.light_along(
        "spot",
        Vec3::new(0.9, 2.3, 1.1),
        bunny_at + Vec3::new(0.0, 0.4, 0.0) - Vec3::new(0.9, 2.3, 1.1),
        LightKind::Spot {
            inner_cone_angle: 25f32.to_radians(),
            outer_cone_angle: 35f32.to_radians(),
        },
        8.0,
    );
    camera(
        &mut b,
        Vec3::new(0.0, 1.25, 1.45),
        Vec3::new(0.0, 0.95, 0.0),
        50.0,
    );
    let mut scene = b.scene;
    if moving && bunny.is_some() {
        let node = node_named(&scene, "bunny");
        let turns: Vec<Quat> = (0..=4)
            .map(|i| Quat::from_rotation_y(i as f32 * std::f32::consts::FRAC_PI_2))
            .collect();
        add_animation(
            &mut scene,
            "bunny turns",
            vec![channel(node, Property::Rotation, rotations(&turns))],
        );
    }
    Ok(scene)
}

/// Cornell box with the bunny (0.25 m tall, turned to face the camera) in place of the short
/// block. A missing PLY gives a procedural stand-in (mesh `bunny (procedural stand-in)`) and a
/// warning; a malformed one is an error.
fn cornell_bunny(name: &str, moving: bool, max_edge: f32) -> Result<Scene, SceneError> {
    let mut scene = cornell(name, CornellLight::Spot, max_edge);
    let block = node_named(&scene, "short_box");
    let instance = scene
        .instances
        .iter()
        .position(|i| i.node == block)
        .expect("short box instance");
    let mesh_index = scene.instances[instance].mesh;
    let material = scene.meshes[mesh_index].material;
    let (mut mesh, warning) = bunny_mesh(&bunny_candidates())?;
    if let Some(warning) = warning {
        scene.warnings.push(format!("{name}: {warning}"));
    }
    // Fit: 0.25 m tall, centred on the node's origin, resting on y = 0, facing −z (the camera).
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in &mesh.positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let scale = 0.25 / (hi.y - lo.y).max(1e-6);
    let centre = Vec3::new((lo.x + hi.x) * 0.5, lo.y, (lo.z + hi.z) * 0.5);
    let turn = Quat::from_rotation_y(std::f32::consts::PI);
    for p in &mut mesh.positions {
        *p = turn * ((*p - centre) * scale);
    }
    mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
    if mesh.uv0.len() != mesh.positions.len() {
        mesh.uv0 = vec![Vec2::ZERO; mesh.positions.len()];
    }
    mesh.material = material;
    tessellate(&mut mesh, max_edge);
    scene.meshes[mesh_index] = mesh;
    scene.nodes[block].name = "bunny".into();
    if moving {
        let rest = scene.nodes[block].local.rotation;
        let turns: Vec<Quat> = (0..=4)
            .map(|i| Quat::from_rotation_y(i as f32 * std::f32::consts::FRAC_PI_2) * rest)
            .collect();
        add_animation(
            &mut scene,
            "bunny turns",
            vec![channel(block, Property::Rotation, rotations(&turns))],
        );
    }
    Ok(scene)
}

/// The bunny from the first existing file of `candidates` (`name` "bunny"), or the procedural
/// stand-in and a warning saying so when none exists. A malformed file is an error.
pub fn bunny_mesh(candidates: &[PathBuf]) -> Result<(Mesh, Option<String>), SceneError> {
    match candidates.iter().find(|p| p.is_file()) {
        Some(path) => {
            let mut mesh = load_ply(path)?;
            mesh.name = "bunny".into();
            Ok((mesh, None))
        }
        None => Ok((
            bunny_standin(),
            Some(format!(
                "Stanford bunny not found (looked for {}); using a procedural stand-in",
                candidates
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        )),
    }
}

/// A bunny-sized blob (body, head, two ears) standing in for the Stanford bunny.
fn bunny_standin() -> Mesh {
    let mut mesh = Mesh {
        name: "bunny (procedural stand-in)".into(),
        ..Mesh::default()
    };
    let parts = [
        (Vec3::new(0.0, 0.06, 0.0), Vec3::new(0.08, 0.06, 0.06)),
        (Vec3::new(0.0, 0.12, 0.05), Vec3::new(0.04, 0.04, 0.04)),
        (Vec3::new(-0.015, 0.17, 0.04), Vec3::new(0.012, 0.04, 0.01)),
        (Vec3::new(0.015, 0.17, 0.04), Vec3::new(0.012, 0.04, 0.01)),
    ];
    for (centre, radii) in parts {
        let part = icosphere("part", 0, 1.0, 0.5, false);
        let base = mesh.positions.len() as u32;
        mesh.positions
            .extend(part.positions.iter().map(|p| centre + *p * radii));
        mesh.indices.extend(part.indices.iter().map(|i| i + base));
    }
    mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
    mesh
}

/// Reads a PLY triangle mesh (ASCII or binary; see [`crate::scene::ply`]). Errors name the
/// file and the problem.
pub fn load_ply(path: &Path) -> Result<Mesh, SceneError> {
    crate::scene::ply::load_mesh(path)
}
