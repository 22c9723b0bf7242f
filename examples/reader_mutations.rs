//! Mutation run over the scene readers: thousands of hostile variants of real inputs (the glTF
//! samples, the bunny PLY in ASCII and binary, the Veach room's OBJ meshes and scene file),
//! each read in a watched thread, with the outcomes counted: loaded, loaded with warnings,
//! error (by kind), panic, over the time limit, or loaded with a non-finite or negative value.
//!
//! `cargo run --example reader_mutations -- [--gltf 1200] [--ply 150] [--obj 150] [--xml 100]
//! [--seed 1]` from the repository root (the inputs are read from `../shared/data`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use valgi::scene::files::ReadPolicy;
use valgi::scene::{gltf_import, mitsuba, obj, ply, Scene, SceneError};

/// An input to mutate: its bytes, the folder its references resolve against, its file name.
type Seed = (Vec<u8>, PathBuf, String);

const TIME_LIMIT: Duration = Duration::from_secs(30);

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const HOSTILE_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1",
    "3",
    "255",
    "65536",
    "2147483647",
    "4294967295",
    "4294967296",
    "9007199254740993",
    "18446744073709551615",
    "4611686018427387904",
    "1e39",
    "-1e39",
    "-2.48",
    "1e-45",
    "0.5",
];

const HOSTILE_URIS: &[&str] = &[
    "/dev/zero",
    "/dev/urandom",
    "../../../../etc/passwd",
    "/etc/passwd",
    "file:///etc/passwd",
    "http://example.com/x.bin",
    "data:application/octet-stream;base64,AAAA",
    "data:application/octet-stream;base64,!!!!",
    "data:text/plain,abc",
    "missing.bin",
    "%2e%2e/%2e%2e/etc/passwd",
    "",
    ".",
    "..",
];

fn byte_mutation(rng: &mut Rng, bytes: &mut Vec<u8>) -> &'static str {
    if bytes.is_empty() {
        bytes.push(0);
    }
    let len = bytes.len();
    match rng.below(6) {
        0 => {
            for _ in 0..1 + rng.below(8) {
                let at = rng.below(len);
                bytes[at] ^= 1 << rng.below(8);
            }
            "bit flips"
        }
        1 => {
            bytes.truncate(rng.below(len));
            "truncation"
        }
        2 => {
            let at = rng.below(len + 1);
            let n = 1 + rng.below(16);
            let junk: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
            bytes.splice(at..at, junk);
            "insertion"
        }
        3 => {
            let at = rng.below(len);
            let end = (at + 1 + rng.below(256)).min(len);
            bytes.drain(at..end);
            "deletion"
        }
        4 => {
            let at = rng.below(len);
            let end = (at + 1 + rng.below(1024)).min(len);
            let chunk = bytes[at..end].to_vec();
            bytes.splice(at..at, chunk);
            "repeat"
        }
        _ => {
            // A run of digits replaced by a hostile number.
            let start = (0..len)
                .map(|k| (rng.below(len) + k) % len)
                .find(|&k| bytes[k].is_ascii_digit());
            if let Some(start) = start {
                let end = (start..len)
                    .find(|&k| !bytes[k].is_ascii_digit())
                    .unwrap_or(len);
                let n = HOSTILE_NUMBERS[rng.below(HOSTILE_NUMBERS.len())];
                bytes.splice(start..end, n.bytes());
            }
            "number edit"
        }
    }
}

/// Every numeric or string leaf of a JSON value, as a path of keys and indices.
fn leaves(value: &serde_json::Value, path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    match value {
        serde_json::Value::Object(map) => {
            for (k, v) in map {
                path.push(k.clone());
                leaves(v, path, out);
                path.pop();
            }
        }
        serde_json::Value::Array(items) => {
            for (i, v) in items.iter().enumerate().take(64) {
                path.push(i.to_string());
                leaves(v, path, out);
                path.pop();
            }
        }
        _ => out.push(path.clone()),
    }
}

fn leaf_mut<'a>(
    value: &'a mut serde_json::Value,
    path: &[String],
) -> Option<&'a mut serde_json::Value> {
    let mut v = value;
    for key in path {
        v = match v {
            serde_json::Value::Object(map) => map.get_mut(key)?,
            serde_json::Value::Array(items) => items.get_mut(key.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(v)
}

/// Targeted edits of the glTF JSON: counts, offsets, indices, factors, light values, URIs.
fn json_mutation(rng: &mut Rng, json: &[u8]) -> Option<(Vec<u8>, &'static str)> {
    let mut doc: serde_json::Value = serde_json::from_slice(json).ok()?;
    let mut all = Vec::new();
    leaves(&doc, &mut vec![], &mut all);
    if all.is_empty() {
        return None;
    }
    let kind = match rng.below(4) {
        0 => {
            let uris: Vec<&Vec<String>> = all
                .iter()
                .filter(|p| p.last().is_some_and(|k| k == "uri"))
                .collect();
            let path = if uris.is_empty() {
                vec!["buffers".into(), "0".into(), "uri".into()]
            } else {
                uris[rng.below(uris.len())].clone()
            };
            let uri = HOSTILE_URIS[rng.below(HOSTILE_URIS.len())];
            *leaf_mut(&mut doc, &path)? = serde_json::Value::String(uri.into());
            "JSON uri edit"
        }
        1 => {
            // Lights: add a light with hostile values when the file has none.
            let value = HOSTILE_NUMBERS[rng.below(HOSTILE_NUMBERS.len())];
            let number: serde_json::Value = serde_json::from_str(value).ok()?;
            let kind = ["point", "spot", "directional", "area"][rng.below(4)];
            let light = serde_json::json!({
                "type": kind,
                "intensity": number,
                "color": [1.0, number, 0.5],
                "range": number,
                "spot": {"innerConeAngle": number, "outerConeAngle": 1.0}
            });
            doc["extensionsUsed"] = serde_json::json!(["KHR_lights_punctual"]);
            doc["extensions"] = serde_json::json!({"KHR_lights_punctual": {"lights": [light]}});
            if let Some(nodes) = doc["nodes"].as_array_mut() {
                if let Some(node) = nodes.first_mut() {
                    node["extensions"] =
                        serde_json::json!({"KHR_lights_punctual": {"light": rng.below(2)}});
                }
            }
            "JSON light edit"
        }
        _ => {
            let path = &all[rng.below(all.len())];
            let value = HOSTILE_NUMBERS[rng.below(HOSTILE_NUMBERS.len())];
            let leaf = leaf_mut(&mut doc, path)?;
            *leaf = serde_json::from_str(value)
                .unwrap_or_else(|_| serde_json::Value::String(value.into()));
            "JSON value edit"
        }
    };
    let text = serde_json::to_string(&doc).ok()?;
    Some((text.into_bytes(), kind))
}

fn split_glb(bytes: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let json_len = u32::from_le_bytes(bytes.get(12..16)?.try_into().ok()?) as usize;
    let json = bytes.get(20..20 + json_len)?.to_vec();
    let rest = bytes.get(20 + json_len..).unwrap_or(&[]);
    let bin = if rest.len() >= 8 {
        let n = u32::from_le_bytes(rest[0..4].try_into().ok()?) as usize;
        rest.get(8..8 + n)?.to_vec()
    } else {
        vec![]
    };
    Some((json, bin))
}

fn build_glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json = json.to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut body = Vec::new();
    body.extend((json.len() as u32).to_le_bytes());
    body.extend(b"JSON");
    body.extend(&json);
    if !bin.is_empty() {
        body.extend((bin.len() as u32).to_le_bytes());
        body.extend(b"BIN\0");
        body.extend(bin);
    }
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((12 + body.len() as u32).to_le_bytes());
    out.extend(body);
    out
}

fn gltf_mutation(rng: &mut Rng, seed: &[u8]) -> (Vec<u8>, &'static str) {
    let glb = seed.starts_with(b"glTF");
    match rng.below(10) {
        0..=3 => {
            let mut bytes = seed.to_vec();
            let kind = byte_mutation(rng, &mut bytes);
            (bytes, kind)
        }
        4 if glb => {
            // GLB header and chunk fields.
            let mut bytes = seed.to_vec();
            let fields = [4usize, 8, 12, 16];
            let at = fields[rng.below(fields.len())];
            let value = [0u32, 1, 3, 12, 0x7fff_ffff, u32::MAX][rng.below(6)];
            if bytes.len() >= at + 4 {
                bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
            }
            (bytes, "GLB header edit")
        }
        _ => {
            let (json, bin) = if glb {
                split_glb(seed).unwrap_or_default()
            } else {
                (seed.to_vec(), vec![])
            };
            match json_mutation(rng, &json) {
                Some((json, kind)) => {
                    let bytes = if glb { build_glb(&json, &bin) } else { json };
                    (bytes, kind)
                }
                None => {
                    let mut bytes = seed.to_vec();
                    let kind = byte_mutation(rng, &mut bytes);
                    (bytes, kind)
                }
            }
        }
    }
}

fn ply_mutation(rng: &mut Rng, seed: &[u8]) -> (Vec<u8>, &'static str) {
    if rng.below(3) == 0 {
        // Header counts and list types.
        let text_end = seed
            .windows(10)
            .position(|w| w == b"end_header")
            .unwrap_or(0);
        let header = String::from_utf8_lossy(&seed[..text_end]).into_owned();
        let n = HOSTILE_NUMBERS[rng.below(HOSTILE_NUMBERS.len())];
        let edited = match rng.below(3) {
            0 => regex_replace_count(&header, "element vertex ", n),
            1 => regex_replace_count(&header, "element face ", n),
            _ => header.replace(
                "list uchar",
                ["list uint", "list int", "list char", "list float"][rng.below(4)],
            ),
        };
        let mut out = edited.into_bytes();
        out.extend(&seed[text_end..]);
        return (out, "PLY header edit");
    }
    let mut bytes = seed.to_vec();
    let kind = byte_mutation(rng, &mut bytes);
    (bytes, kind)
}

fn regex_replace_count(header: &str, prefix: &str, n: &str) -> String {
    header
        .lines()
        .map(|l| {
            if l.starts_with(prefix) {
                format!("{prefix}{n}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

#[derive(Default)]
struct Tally {
    outcomes: BTreeMap<String, usize>,
    examples: BTreeMap<String, Vec<String>>,
    mutations: BTreeMap<&'static str, usize>,
    slowest: (Duration, String),
}

impl Tally {
    fn add(&mut self, outcome: String, example: String, mutation: &'static str, took: Duration) {
        *self.outcomes.entry(outcome.clone()).or_default() += 1;
        *self.mutations.entry(mutation).or_default() += 1;
        let e = self.examples.entry(outcome).or_default();
        if e.len() < 2 {
            e.push(example.chars().take(200).collect());
        }
        if took > self.slowest.0 {
            self.slowest = (took, mutation.to_string());
        }
    }

    fn print(&self, reader: &str, total: usize) {
        println!("== {reader}: {total} mutated inputs");
        for (outcome, n) in &self.outcomes {
            println!("  {n:6}  {outcome}");
            for e in &self.examples[outcome] {
                println!("          e.g. {e}");
            }
        }
        let kinds: Vec<String> = self
            .mutations
            .iter()
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        println!("  mutations: {}", kinds.join(", "));
        println!(
            "  slowest input: {:.2} s ({})",
            self.slowest.0.as_secs_f64(),
            self.slowest.1
        );
    }
}

fn classify(result: &Result<Scene, SceneError>, display: &str) -> (String, String) {
    match result {
        Ok(scene) => {
            let finite = scene.meshes.iter().all(|m| {
                m.positions.iter().all(|p| p.is_finite())
                    && m.normals.iter().all(|n| n.is_finite())
                    && m.uv0.iter().all(|u| u.is_finite())
                    && m.indices.iter().all(|&i| (i as usize) < m.positions.len())
            }) && scene.materials.iter().all(|m| {
                m.base_color.is_finite()
                    && m.base_color.min_element() >= 0.0
                    && m.emissive.is_finite()
                    && m.emissive.min_element() >= 0.0
            }) && scene.lights.iter().all(|l| {
                let p = l.radiometric();
                p.is_finite() && p.min_element() >= 0.0
            });
            if !finite {
                ("LOADED WITH A BAD VALUE".into(), scene.name.clone())
            } else if scene.warnings.is_empty() {
                ("loaded".into(), scene.name.clone())
            } else {
                (
                    "loaded with warnings".into(),
                    scene.warnings.first().cloned().unwrap_or_default(),
                )
            }
        }
        Err(e) => {
            let message = e.to_string();
            if !message.starts_with(&format!("{display}: ")) {
                return ("ERROR NOT NAMING THE FILE".into(), message);
            }
            let lower = message.to_lowercase();
            let kind = [
                ("outside the scene", "error: reference outside the folder"),
                ("absolute", "error: absolute reference"),
                ("not a regular file", "error: not a regular file"),
                ("not a local file", "error: not a local file"),
                ("missing", "error: missing file or value"),
                ("json", "error: malformed or mistyped JSON"),
                ("glb", "error: malformed GLB container"),
                ("base64", "error: bad data URI"),
                ("out of range", "error: index, count or range out of bounds"),
                ("exceed", "error: count above a limit"),
                ("file ends", "error: file shorter than declared"),
                ("declares", "error: file shorter than declared"),
                ("invalid glTF", "error: glTF validation"),
                ("invalid gltf", "error: glTF validation"),
                ("not a number", "error: not a number"),
                ("not an integer", "error: not a number"),
                ("not numbers", "error: not a number"),
                ("xml", "error: malformed XML"),
                ("header", "error: bad header"),
            ]
            .iter()
            .find(|(needle, _)| lower.contains(needle))
            .map_or("error: other", |(_, kind)| kind);
            (kind.to_string(), message)
        }
    }
}

fn run_case(
    reader: &'static str,
    bytes: Vec<u8>,
    dir: Option<PathBuf>,
    policy: ReadPolicy,
) -> (Result<(String, String), String>, Duration) {
    let (tx, rx) = mpsc::channel();
    let start = Instant::now();
    std::thread::spawn(move || {
        let display = format!("mutated.{reader}");
        let result = std::panic::catch_unwind(|| {
            let result = match reader {
                "gltf" => {
                    gltf_import::load_from_slice_with(&bytes, dir.as_deref(), &display, policy)
                }
                "ply" => ply::parse(&bytes, &display).map(|mesh| Scene {
                    meshes: vec![mesh],
                    ..Scene::default()
                }),
                "obj" => obj::parse(&bytes, &display, dir.as_deref(), policy),
                _ => mitsuba::parse(&bytes, &display, dir.as_deref(), policy),
            };
            classify(&result, &display)
        });
        let _ = tx.send(result.map_err(|p| {
            p.downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default()
        }));
    });
    match rx.recv_timeout(TIME_LIMIT) {
        Ok(r) => (r, start.elapsed()),
        Err(_) => (Err("TIMEOUT".into()), start.elapsed()),
    }
}

fn find_files(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            find_files(&p, exts, out);
        } else if p
            .extension()
            .and_then(|x| x.to_str())
            .is_some_and(|x| exts.contains(&x))
        {
            out.push(p);
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str, default: usize| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let mut rng = Rng((arg("--seed", 1) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    std::panic::set_hook(Box::new(|_| {}));
    let data = Path::new("../shared/data");
    let corpus = Path::new("tests/corpus");

    let mut gltf_seeds = Vec::new();
    find_files(
        &data.join("gltf-samples"),
        &["gltf", "glb"],
        &mut gltf_seeds,
    );
    find_files(&corpus.join("gltf"), &["gltf", "glb"], &mut gltf_seeds);
    gltf_seeds.sort();
    let mut ply_seeds = vec![data.join("bunny/bun_zipper_res4.ply")];
    find_files(&corpus.join("ply"), &["ply"], &mut ply_seeds);
    let mut obj_seeds = Vec::new();
    find_files(&data.join("veach-ajar/models"), &["obj"], &mut obj_seeds);
    find_files(&corpus.join("obj"), &["obj"], &mut obj_seeds);
    obj_seeds.sort();
    let mut xml_seeds = vec![data.join("veach-ajar/scene.xml")];
    find_files(&corpus.join("xml"), &["xml"], &mut xml_seeds);

    let read = |paths: &[PathBuf]| -> Vec<Seed> {
        paths
            .iter()
            .filter_map(|p| {
                Some((
                    std::fs::read(p).ok()?,
                    p.parent()?.to_path_buf(),
                    p.file_name()?.to_string_lossy().into_owned(),
                ))
            })
            .collect()
    };
    let mut plys = read(&ply_seeds);
    // The bunny again as binary little- and big-endian.
    if let Ok(bunny) = ply::load_mesh(&ply_seeds[0]) {
        for big in [false, true] {
            let order = if big { "big" } else { "little" };
            let b = ply::to_binary(&bunny, big);
            plys.push((b, PathBuf::from("."), format!("bunny-{order}.ply")));
        }
    }
    let sets: Vec<(&'static str, Vec<Seed>, usize)> = vec![
        ("gltf", read(&gltf_seeds), arg("--gltf", 1200)),
        ("ply", plys, arg("--ply", 150)),
        ("obj", read(&obj_seeds), arg("--obj", 150)),
        ("xml", read(&xml_seeds), arg("--xml", 100)),
    ];
    let started = Instant::now();
    for (reader, seeds, count) in sets {
        if seeds.is_empty() {
            println!("== {reader}: no seed inputs found");
            continue;
        }
        let names: Vec<&str> = seeds.iter().map(|s| s.2.as_str()).collect();
        println!("seeds for {reader}: {}", names.join(", "));
        let mut tally = Tally::default();
        for _ in 0..count {
            // The 3.7 MB DamagedHelmet decodes five 2048² textures: one case in twenty.
            let mut pick = rng.below(seeds.len());
            if seeds[pick].2.contains("DamagedHelmet") && rng.below(20) != 0 {
                pick = (pick + 1) % seeds.len();
            }
            let (seed, dir, name) = &seeds[pick];
            let (bytes, mutation) = match reader {
                "gltf" => gltf_mutation(&mut rng, seed),
                "ply" => ply_mutation(&mut rng, seed),
                _ => {
                    let mut b = seed.clone();
                    let kind = byte_mutation(&mut rng, &mut b);
                    (b, kind)
                }
            };
            // One case in four admits external paths: device files must still be refused.
            let policy = ReadPolicy {
                allow_external_paths: rng.below(4) == 0,
            };
            let (result, took) = run_case(reader, bytes, Some(dir.clone()), policy);
            match result {
                Ok((outcome, example)) => tally.add(outcome, example, mutation, took),
                Err(message) if message == "TIMEOUT" => tally.add(
                    "TIMEOUT".into(),
                    format!("{name}: {mutation}"),
                    mutation,
                    took,
                ),
                Err(message) => tally.add(
                    "PANIC".into(),
                    format!("{name}: {mutation}: {message}"),
                    mutation,
                    took,
                ),
            }
        }
        tally.print(reader, count);
    }
    let peak = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM"))
                .map(|l| l.split_whitespace().nth(1).unwrap_or("?").to_string())
        })
        .unwrap_or_else(|| "?".into());
    println!(
        "total {:.1} s, peak resident memory {peak} kB",
        started.elapsed().as_secs_f64()
    );
}
