#!/usr/bin/env python3
"""Occlusion and visibility cost against the number of mesh instances.

Writes a glTF scene of N instances of one small box (12 triangles) on a square grid over a
floor, lit by a spot light from above, renders it with `valgi render --method sparse` for each
`--occlusion` mode given, and prints the passes' times from the JSON line (`table2`).

    python3 scripts/many_instances.py [--counts 1000,3000] [--modes sum,rays] [--size 64]
        [--max-edge 0.25] [--points-per-instance 64]

Needs a release build (`cargo build --release --bin valgi`).
"""
import argparse
import base64
import json
import math
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def box_mesh():
    """A unit box centred at the origin: 24 vertices (flat normals), 36 indices."""
    positions, normals, indices = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            u, v = [(axis + 1) % 3, (axis + 2) % 3]
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = 0.5 * sign
                p[u] = 0.5 * a
                p[v] = 0.5 * b
                positions.append(p)
                normals.append(n)
            quad = [0, 1, 2, 0, 2, 3] if sign > 0 else [0, 2, 1, 0, 3, 2]
            indices += [base + i for i in quad]
    return positions, normals, indices


def scene(count, light_height=None):
    positions, normals, indices = box_mesh()
    blob = b"".join(struct.pack("<3f", *p) for p in positions)
    blob += b"".join(struct.pack("<3f", *n) for n in normals)
    blob += b"".join(struct.pack("<H", i) for i in indices)
    side = math.ceil(math.sqrt(count))
    spacing = 1.5
    extent = side * spacing
    nodes = []
    for i in range(count):
        x = (i % side - side / 2 + 0.5) * spacing
        z = (i // side - side / 2 + 0.5) * spacing
        nodes.append({"mesh": 0, "translation": [x, 0.5, z]})
    # The floor: the same box, flattened and spread under the grid.
    nodes.append({"mesh": 1, "translation": [0, -0.05, 0], "scale": [extent + 2, 0.1, extent + 2]})
    # By default the light rises with the grid, so it lights all of it.
    height = light_height or extent
    nodes.append({
        "translation": [0, height, 0],
        "rotation": [-math.sqrt(0.5), 0, 0, math.sqrt(0.5)],  # look down −y
        "extensions": {"KHR_lights_punctual": {"light": 0}},
    })
    nodes.append({
        "translation": [0, extent * 0.8, extent * 0.9],
        "rotation": [-0.38268343, 0, 0, 0.92387953],  # 45° down
        "camera": 0,
    })
    n_pos = 12 * len(positions)
    return {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{
            "type": "spot", "intensity": 40.0 * height * height,
            "spot": {"outerConeAngle": 0.9}}]}},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.9, "znear": 0.1}}],
        # The floor is a mesh of its own, so that subdividing it to --max-edge leaves the
        # boxes alone.
        # A white diffuse material: glTF's default is fully metallic, which reflects no
        # diffuse light and so makes no VALs (nothing to occlude).
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0],
                                                "metallicFactor": 0.0, "roughnessFactor": 1.0}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2,
                                    "material": 0}]}] * 2,
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": n_pos},
            {"buffer": 0, "byteOffset": n_pos, "byteLength": n_pos},
            {"buffer": 0, "byteOffset": 2 * n_pos, "byteLength": 2 * len(indices)},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
             "min": [-0.5] * 3, "max": [0.5] * 3},
            {"bufferView": 1, "componentType": 5126, "count": len(normals), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": len(indices), "type": "SCALAR"},
        ],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", default="1000,3000")
    parser.add_argument("--modes", default="sum,rays")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--max-edge", type=float, default=0.25,
                        help="valgi's --max-edge: a box face is split into (1/max-edge)² quads")
    parser.add_argument("--points-per-instance", type=int, default=64,
                        help="valgi's --sparse-points is this times the instance count")
    parser.add_argument("--light-height", type=float, default=None,
                        help="spot light height in m (default: the grid's side, lighting all of it)")
    parser.add_argument("--out", default="out/many-instances")
    parser.add_argument("--valgi", default=str(ROOT / "target/release/valgi"))
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print("| instances | occlusion | sparse points | occlusion (ms) | visibility (ms) | total (ms) | wall (s) |")
    print("|---|---|---|---|---|---|---|")
    failed = 0
    for count in [int(c) for c in args.counts.split(",")]:
        path = out / f"instances-{count}.gltf"
        path.write_text(json.dumps(scene(count, args.light_height)))
        for mode in args.modes.split(","):
            command = [args.valgi, "render", "--scene", str(path), "--method", "sparse",
                       "--occlusion", mode, "--max-edge", str(args.max_edge),
                       "--sparse-points", str(args.points_per_instance * count), "--width", str(args.size), "--height", str(args.size),
                       "--out", str(out / f"instances-{count}-{mode}.png")]
            start = time.time()
            run = subprocess.run(command, capture_output=True, text=True)
            wall = time.time() - start
            if run.returncode != 0:
                failed += 1
                print(f"| {count} | {mode} | failed: {run.stderr.strip().splitlines()[-1:]} | | | | |")
                continue
            report = json.loads(run.stdout.strip().splitlines()[-1])
            table = report.get("table2", {})
            print(f"| {count} | {mode} | {report.get('sparse_points')} | "
                  f"{table.get('occlusion', 0):.1f} | "
                  f"{table.get('visibility', 0):.1f} | {table.get('total', 0):.1f} | {wall:.1f} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
