#!/usr/bin/env python3
"""Hostile-input campaign for valgi: mutated scene files and abusive command lines.

Generates, from a seed, a reproducible set of hostile inputs (mutated glTF/GLB files derived
from ../shared/data/gltf-samples, mutated PLY files from ../shared/data/bunny plus small
generated ones, mutated OBJ/MTL files, abusive command lines over the built-in scenes), runs
each one through a valgi binary at a tiny render size under a wall-clock timeout and a memory
cap, and classifies every run:

    ok           exit 0 and the expected output exists (flag `black`: the PNG is all black;
                 the summary counts it only for runs given a --light, unlit imports are black)
    non-finite   exit 0 but the render reports non-finite pixels (non_finite_pixels > 0 in its
                 JSON line, or "pixels had non-finite radiance" on stderr; warnings about
                 non-finite *inputs* that were replaced do not count)
    no-output    exit 0 but the expected output file is missing
    clean-error  nonzero exit, an `error:` message, no panic (column `names_file` says
                 whether the message names the input file, for file inputs)
    unclear-error nonzero exit, no panic, but no `error` line on stderr
    gpu-error    a wgpu validation error ("GPU error" on stderr): the input reached the GPU
                 layer in a shape valgi did not check for (an internal error, not a clean one)
    panic        "panicked" on stderr, exit code 101, or death by a signal (abort, segfault,
                 stack overflow)
    hang         ran past the timeout (killed with its process group)
    killed       memory cap (allocation failure under RLIMIT_AS, or the RSS watcher), SIGKILL
                 or the file-size cap

It prints a table of counts (input kind x outcome), then every case that is not ok/clean with
its reproduction command, and writes SCRATCH/results.csv and SCRATCH/results.json (one row per
case). Each case lives in SCRATCH/cases/<id>/ with its input files and a `cmd.sh` that
reproduces it exactly; failing cases (panic, hang, killed) are also copied to
SCRATCH/failures/<id>/ with their stderr. The exit status is 1 when any panic, hang or killed
case occurred, else 0.

Run (from the repository root, with a release build copied out of the tree so a rebuild
cannot change the binary under the campaign):

    cp target/release/valgi /tmp/valgi-campaign
    python3 scripts/hostile_inputs.py --binary /tmp/valgi-campaign            # everything
    python3 scripts/hostile_inputs.py --binary /tmp/valgi-campaign --kinds ply --jobs 1
    python3 scripts/hostile_inputs.py --binary /tmp/valgi-campaign --case gltf-0042   # one case

Options: --seed (default 1), --scratch (default /tmp/hostile; wiped and regenerated, so it must
be empty or a previous campaign's folder), --jobs (default 2), --timeout (seconds, default 60),
--mem-gib (default 8), --mem-mode as|rss (RLIMIT_AS in the child, or a watcher that samples the
resident set from /proc and kills past the cap), --gltf/--ply/--obj/--cli (case counts),
--generate-only. Python 3 standard library only.
"""

import argparse
import base64
import concurrent.futures
import csv
import json
import math
import os
import random
import shutil
import signal
import stat
import struct
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared" / "data"

OUTCOMES = ["ok", "non-finite", "no-output", "clean-error", "unclear-error", "gpu-error", "panic", "hang", "killed"]
FAILING = {"panic", "hang", "killed"}  # these make the campaign exit nonzero

NAN = float("nan")
INF = float("inf")

# Values that break readers in different ways: zero, negatives, overflows of i32/u32/u64/usize,
# f32 overflow (1e39 parses as a finite f64 but is inf as f32), subnormals, JSON's non-standard
# NaN/Infinity literals (Python's json emits them), numbers written as strings, wrong types.
NUM_POISON = [0, -1, -1e39, 1e39, 1e308, -1e308, 2**31, 2**32, 2**53 + 1, 2**63, 2**64, -(2**63),
              1.5, 4.9e-324, NAN, INF, -INF, "NaN", "inf", "1e39", None, True, [], {}]
COUNT_POISON = [0, -1, 1, 2**31 - 1, 2**31, 2**32, 2**32 + 3, 2**53, 2**62, 2**64 - 1, 2**64,
                1e308, 1.5, "3", None, NAN]
INDEX_POISON = [-1, 99, 2**31, 2**32, 2**64, 1.5, "0", None, NAN]

# URIs that try to leave the scene's folder, read devices (endless or blocking), or are not
# valid data URIs. The reader must refuse the escapes without --allow-external-paths and
# refuse device files always.
HOSTILE_URIS = [
    "../../../../etc/passwd", "../../../../../../../../etc/shadow", "/etc/passwd", "/dev/zero",
    "/dev/urandom", "/dev/random", "/proc/self/mem", "/proc/self/environ", "/proc/self/fd/0",
    "/dev/stdin", "file:///etc/passwd", "%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
    "sub/../../../../etc/passwd", "..", ".", "/", "/tmp", "", " ", "missing.bin", "C:\\Windows\\win.ini",
    "\\\\server\\share\\x.bin", "http://127.0.0.1:9/x.bin", "x" * 5000 + ".bin", "a\u0000b.bin",
    "data:application/octet-stream;base64,!!!not base64!!!", "data:application/octet-stream;base64,QUJ",
    "data:application/octet-stream;base64,", "data:;base64,AAAA", "data:application/octet-stream,raw",
    "data:image/png;base64," + "A" * 4096, "data:", "data:application/octet-stream;base64,====",
]


# ----------------------------------------------------------------------------- small helpers

def png_bytes(width, height, rgb_rows):
    """A minimal 8-bit RGB PNG (the generated textures; no Pillow in the standard library)."""
    raw = b"".join(b"\x00" + bytes(row) for row in rgb_rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def png_is_black(path):
    """True when every colour sample of an 8-bit PNG is 0, False when not, None when unsure.

    Cheap at the campaign's 32x32 size: inflate IDAT and undo the row filters by hand."""
    try:
        data = Path(path).read_bytes()
        if data[:8] != b"\x89PNG\r\n\x1a\n":
            return None
        pos, idat, ihdr = 8, b"", None
        while pos + 8 <= len(data):
            n, kind = struct.unpack(">I4s", data[pos:pos + 8])
            body = data[pos + 8:pos + 8 + n]
            if kind == b"IHDR":
                ihdr = struct.unpack(">IIBBBBB", body)
            elif kind == b"IDAT":
                idat += body
            pos += 12 + n
        w, h, depth, ctype, _, _, interlace = ihdr
        channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(ctype)
        if depth != 8 or channels is None or interlace:
            return None
        raw = zlib.decompress(idat)
        stride = w * channels
        prev = bytearray(stride)
        colour = channels - (1 if ctype in (4, 6) else 0)
        for y in range(h):
            f = raw[y * (stride + 1)]
            line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
            for i in range(stride):
                a = line[i - channels] if i >= channels else 0
                b = prev[i]
                c = prev[i - channels] if i >= channels else 0
                if f == 1:
                    line[i] = (line[i] + a) & 255
                elif f == 2:
                    line[i] = (line[i] + b) & 255
                elif f == 3:
                    line[i] = (line[i] + (a + b) // 2) & 255
                elif f == 4:
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
            for px in range(w):
                if any(line[px * channels + k] for k in range(colour)):
                    return False
            prev = line
        return True
    except Exception:
        return None


def link_or_copy(src, dst):
    """Hard-link an unchanged auxiliary file into a case folder (1000 cases of the same .bin
    would otherwise cost gigabytes); copy when the file system refuses links."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def copy_case_dir(src, dst):
    """Copy a case folder without opening FIFOs or following symlinks (a FIFO case would block
    shutil.copytree forever, a /dev/zero symlink would fill the disk)."""
    dst.mkdir(parents=True, exist_ok=True)
    for entry in os.scandir(src):
        s, d = Path(entry.path), dst / entry.name
        st = os.lstat(s)
        if stat.S_ISLNK(st.st_mode):
            os.symlink(os.readlink(s), d)
        elif stat.S_ISFIFO(st.st_mode):
            os.mkfifo(d)
        elif stat.S_ISDIR(st.st_mode):
            copy_case_dir(s, d)
        elif stat.S_ISREG(st.st_mode):
            shutil.copyfile(s, d)


def pick(rng, seq):
    return seq[rng.randrange(len(seq))]


def json_text(doc, rng=None):
    """Serialise glTF JSON; NaN/Infinity floats become JSON's non-standard literals on purpose."""
    return json.dumps(doc, indent=1 if rng is None or rng.random() < 0.5 else None)


class Case:
    """One run: its kind, what was mutated, the command line, and the file it should write."""

    def __init__(self, cid, kind, desc, argv, expect=None, input_path=None):
        self.id, self.kind, self.desc, self.argv = cid, kind, desc, argv
        self.expect = expect          # output that must exist for `ok` (None: exit 0 is enough)
        self.input_path = input_path  # the scene file, to check that errors name it


# ----------------------------------------------------------------------------- glTF bases

GLB_MAGIC, CHUNK_JSON, CHUNK_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


def pack_glb(doc_json_bytes, bin_bytes):
    """GLB 2.0 container with correctly padded chunks (the header mutations break it later)."""
    j = doc_json_bytes + b" " * (-len(doc_json_bytes) % 4)
    out = struct.pack("<II", len(j), CHUNK_JSON) + j
    if bin_bytes is not None:
        b = bytes(bin_bytes) + b"\0" * (-len(bin_bytes) % 4)
        out += struct.pack("<II", len(b), CHUNK_BIN) + b
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(out)) + out


def unpack_glb(data):
    jlen = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    binary = None
    if len(rest) >= 8:
        blen = struct.unpack("<I", rest[:4])[0]
        binary = rest[8:8 + blen]
    return doc, binary


class GltfBase:
    """A valid starting scene: its JSON, its binary buffer, and the auxiliary files it needs.

    container: 'glb' (JSON + BIN chunk in one file) or 'gltf' (JSON text; buffer 0 in bin_name
    next to it, aux files copied/linked into every case folder so the unmutated case loads)."""

    def __init__(self, name, container, doc, binary, bin_name, aux, weight):
        self.name, self.container, self.doc, self.binary = name, container, doc, binary
        self.bin_name, self.aux, self.weight = bin_name, aux, weight


def generated_gltf_doc():
    """A small scene with everything the samples lack: KHR_lights_punctual (point, spot, sun),
    a camera, an animation, an external .bin and an external PNG texture, uint16 indices."""
    buf = bytearray()
    views, accessors = [], []

    def add(data_bytes, ctype, count, typ, mn=None, mx=None, target=None):
        while len(buf) % 4:
            buf.append(0)
        view = {"buffer": 0, "byteOffset": len(buf), "byteLength": len(data_bytes)}
        if target:
            view["target"] = target
        views.append(view)
        buf.extend(data_bytes)
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": count, "type": typ}
        if mn is not None:
            acc["min"], acc["max"] = mn, mx
        accessors.append(acc)
        return len(accessors) - 1

    def mesh_accessors(pos, nrm, uv, idx):
        flat = [c for p in pos for c in p]
        p = add(struct.pack("<%df" % len(flat), *flat), 5126, len(pos), "VEC3",
                [min(v[i] for v in pos) for i in range(3)], [max(v[i] for v in pos) for i in range(3)], 34962)
        fn = [c for v in nrm for c in v]
        n = add(struct.pack("<%df" % len(fn), *fn), 5126, len(nrm), "VEC3", target=34962)
        fu = [c for v in uv for c in v]
        t = add(struct.pack("<%df" % len(fu), *fu), 5126, len(uv), "VEC2", target=34962)
        i = add(struct.pack("<%dH" % len(idx), *idx), 5123, len(idx), "SCALAR", target=34963)
        return {"POSITION": p, "NORMAL": n, "TEXCOORD_0": t}, i

    # floor quad, 4 m
    fa, fi = mesh_accessors([(-2, 0, -2), (2, 0, -2), (2, 0, 2), (-2, 0, 2)], [(0, 1, 0)] * 4,
                            [(0, 0), (1, 0), (1, 1), (0, 1)], [0, 2, 1, 0, 3, 2])
    # unit box: 6 faces x 4 vertices
    pos, nrm, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (-1, 1):
            n = [0, 0, 0]
            n[axis] = sign
            u, v = [(1, 2), (2, 0), (0, 1)][axis]
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis], p[u], p[v] = 0.5 * sign, 0.5 * a, 0.5 * b
                pos.append(tuple(p))
                nrm.append(tuple(n))
                uv.append(((a + 1) / 2, (b + 1) / 2))
            idx += [base, base + 1, base + 2, base, base + 2, base + 3] if sign > 0 else \
                   [base, base + 2, base + 1, base, base + 3, base + 2]
    ba, bi = mesh_accessors(pos, nrm, uv, idx)
    times = add(struct.pack("<2f", 0.0, 2.0), 5126, 2, "SCALAR", [0.0], [2.0])
    moves = add(struct.pack("<6f", 0, 0.5, 0, 1, 0.5, 0), 5126, 2, "VEC3")
    doc = {
        "asset": {"version": "2.0", "generator": "hostile_inputs.py"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5]}],
        "nodes": [
            {"name": "floor", "mesh": 0},
            {"name": "box", "mesh": 1, "translation": [0, 0.5, 0]},
            {"name": "camera", "camera": 0, "translation": [0, 2, 5], "rotation": [-0.1736482, 0, 0, 0.9848078]},
            {"name": "point", "translation": [1, 2, 1], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "spot", "translation": [-1, 3, 0], "rotation": [-0.7071068, 0, 0, 0.7071068],
             "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "sun", "rotation": [-0.5, 0.1, 0, 0.86], "extensions": {"KHR_lights_punctual": {"light": 2}}},
        ],
        "meshes": [{"primitives": [{"attributes": fa, "indices": fi, "material": 0, "mode": 4}]},
                   {"primitives": [{"attributes": ba, "indices": bi, "material": 1}]}],
        "materials": [
            {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0, "roughnessFactor": 0.8}},
            {"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.3, 0.2, 1], "metallicFactor": 0.1},
             "emissiveFactor": [0.2, 0.2, 0.2], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 2}}},
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "images": [{"uri": "checker.png"}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.0, "znear": 0.05, "zfar": 100}}],
        "animations": [{"channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}],
                        "samplers": [{"input": times, "output": moves, "interpolation": "LINEAR"}]}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "intensity": 5, "color": [1, 1, 1], "range": 20},
            {"type": "spot", "intensity": 20, "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}},
            {"type": "directional", "intensity": 2, "color": [1, 0.9, 0.8]},
        ]}},
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"uri": "generated.bin", "byteLength": len(buf)}],
    }
    return doc, bytes(buf)


def load_gltf_bases(samples, base_dir):
    """Every sample as a base, plus each GLB split into .gltf + .bin (more JSON-edit bases with
    external files) and the generated scene. Weights favour the small, fast scenes."""
    bases = []
    base_dir.mkdir(parents=True, exist_ok=True)
    weights = {"EmissiveStrengthTest": 6, "ClearCoatTest": 2, "SpecularTest": 2,
               "MetalRoughSpheresNoTextures": 2, "DamagedHelmet": 1, "EnvironmentTest": 4}
    for glb in sorted(samples.glob("*/*.glb")):
        name = glb.stem
        doc, binary = unpack_glb(glb.read_bytes())
        w = weights.get(name, 1)
        bases.append(GltfBase(name, "glb", doc, binary, None, {}, w))
        # the split twin: same scene, buffer 0 as an external file
        split = json.loads(json.dumps(doc))
        split["buffers"][0]["uri"] = name + ".bin"
        (base_dir / name).mkdir(exist_ok=True)
        bases.append(GltfBase(name + "-split", "gltf", split, binary, name + ".bin", {}, w))
    for gltf in sorted(samples.glob("*/*/*.gltf")) + sorted(samples.glob("*/*.gltf")):
        doc = json.loads(gltf.read_text())
        aux = {}
        bin_name = None
        for i, b in enumerate(doc.get("buffers", [])):
            if "uri" in b and not b["uri"].startswith("data:"):
                if i == 0:
                    bin_name = b["uri"]
                else:
                    aux[b["uri"]] = gltf.parent / b["uri"]
        for im in doc.get("images", []):
            if "uri" in im and not im["uri"].startswith("data:"):
                aux[im["uri"]] = gltf.parent / im["uri"]
        binary = (gltf.parent / bin_name).read_bytes() if bin_name else None
        # copy the auxiliary files once into the scratch folder: hard links need one file system
        local = {}
        for rel, src in aux.items():
            dst = base_dir / gltf.stem / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, dst)
            local[rel] = dst
        bases.append(GltfBase(gltf.stem, "gltf", doc, binary, bin_name, local, weights.get(gltf.stem, 1)))
    # the generated scene: an external checker PNG next to it
    doc, binary = generated_gltf_doc()
    gdir = base_dir / "generated"
    gdir.mkdir(exist_ok=True)
    (gdir / "checker.png").write_bytes(png_bytes(4, 4, [[(255 if (x + y) % 2 else 40) for x in range(4) for _ in range(3)] for y in range(4)]))
    bases.append(GltfBase("generated", "gltf", doc, binary, "generated.bin", {"checker.png": gdir / "checker.png"}, 8))
    # write each base's binary once so unmutated buffers can be hard-linked
    for b in bases:
        if b.container == "gltf" and b.binary is not None:
            d = base_dir / b.name
            d.mkdir(exist_ok=True)
            (d / b.bin_name).write_bytes(b.binary)
            b.bin_file = d / b.bin_name
    return bases


# ----------------------------------------------------------------------------- glTF mutations
# Each takes (doc, state, rng) and returns a description; `state` carries the binary buffer
# (state.binary, bytearray) and extra files to write into the case folder (state.extra).

class GltfState:
    def __init__(self, base):
        self.binary = bytearray(base.binary) if base.binary is not None else None
        self.bin_dirty = False
        self.extra = {}          # name -> bytes | ("symlink", target) | ("fifo",)
        self.allow_external = False
        self.time = None


def _items(doc, key):
    v = doc.get(key)
    return v if isinstance(v, list) and v else None


def m_accessor(doc, st, rng):
    accs = _items(doc, "accessors")
    if not accs:
        return m_delete_required(doc, st, rng)
    i = rng.randrange(len(accs))
    a = accs[i]
    field = pick(rng, ["count", "count", "byteOffset", "componentType", "type", "normalized",
                       "bufferView", "min", "max", "sparse", "drop-bufferView"])
    if field == "count":
        v = pick(rng, COUNT_POISON)
    elif field == "byteOffset":
        v = pick(rng, [-4, 1, 2, 3, 4096, 2**31, 2**32, 2**64 - 1, NAN, "0"])
    elif field == "componentType":
        v = pick(rng, [5120, 5121, 5122, 5123, 5125, 5126, 5124, 5130, 0, -1, 9999, "5126"])
    elif field == "type":
        v = pick(rng, ["SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4", "VEC5", "", "vec3", 3, None])
    elif field == "normalized":
        v = pick(rng, [True, "yes", 1])
    elif field == "bufferView":
        v = pick(rng, INDEX_POISON)
    elif field in ("min", "max"):
        v = pick(rng, [[NAN, NAN, NAN], [INF, -INF, 0], [1e39, 1e39, 1e39], [], [0], "NaN", None])
    elif field == "sparse":
        v = {"count": pick(rng, [1, 2**31, 0, -1]),
             "indices": {"bufferView": 0, "componentType": pick(rng, [5121, 5123, 5125, 5126]), "byteOffset": pick(rng, [0, 2**32])},
             "values": {"bufferView": pick(rng, [0, 99]), "byteOffset": 0}}
    else:
        a.pop("bufferView", None)
        return f"accessors[{i}]: bufferView removed (zero-filled accessor)"
    a[field] = v
    return f"accessors[{i}].{field}={v!r}"


def m_buffer_view(doc, st, rng):
    views = _items(doc, "bufferViews")
    if not views:
        return m_delete_required(doc, st, rng)
    i = rng.randrange(len(views))
    bv = views[i]
    field = pick(rng, ["byteOffset", "byteLength", "byteStride", "byteStride", "buffer"])
    if field == "byteOffset":
        v = pick(rng, [-1, 1, 3, 2**31, 2**32, 2**64 - 1, 10**30, NAN, bv.get("byteLength", 0) * 1000])
    elif field == "byteLength":
        v = pick(rng, [0, -1, 1, 2**31, 2**32, 2**64 - 1, 10**30, NAN, bv.get("byteLength", 0) + 1, "12"])
    elif field == "byteStride":
        v = pick(rng, [0, 1, 3, 4, 5, 252, 256, 2**31, 2**32, -4, NAN])
    else:
        v = pick(rng, INDEX_POISON)
    bv[field] = v
    return f"bufferViews[{i}].{field}={v!r}"


def m_buffer(doc, st, rng):
    bufs = _items(doc, "buffers")
    if not bufs:
        return m_delete_required(doc, st, rng)
    i = rng.randrange(len(bufs))
    v = pick(rng, [0, 1, -1, 2**31, 2**32, 2**62, 2**64 - 1, 2**64, 10**30, NAN, "1024",
                   bufs[i].get("byteLength", 0) + 1, bufs[i].get("byteLength", 0) * 4])
    bufs[i]["byteLength"] = v
    return f"buffers[{i}].byteLength={v!r}"


def m_indices(doc, st, rng):
    """Indices out of range: rewrite index values in the binary, or point `indices` elsewhere."""
    prims = [(mi, pi, p) for mi, m in enumerate(doc.get("meshes", [])) for pi, p in enumerate(m.get("primitives", []))]
    if not prims:
        return m_delete_required(doc, st, rng)
    mi, pi, p = pick(rng, prims)
    accs = doc.get("accessors", [])
    idx = p.get("indices")
    if st.binary is not None and isinstance(idx, int) and idx < len(accs) and rng.random() < 0.7:
        a = accs[idx]
        bv = doc["bufferViews"][a["bufferView"]]
        if bv.get("buffer", 0) == 0:
            size = {5121: 1, 5123: 2, 5125: 4}.get(a.get("componentType"), 4)
            start = bv.get("byteOffset", 0) + a.get("byteOffset", 0)
            n = a.get("count", 0)
            vmax = (1 << (8 * size)) - 1
            nverts = accs[p["attributes"]["POSITION"]]["count"] if "POSITION" in p.get("attributes", {}) else 0
            value = pick(rng, [vmax, nverts, nverts + 1, vmax // 2 + 1])
            k = pick(rng, [1, 3, max(1, n // 2), n])
            where = sorted(rng.sample(range(n), min(k, n))) if n else []
            for j in where:
                off = start + j * size
                st.binary[off:off + size] = value.to_bytes(size, "little")
            st.bin_dirty = True
            return f"meshes[{mi}].primitives[{pi}]: {len(where)} of {n} indices set to {value} ({nverts} vertices)"
    v = pick(rng, INDEX_POISON + [p.get("attributes", {}).get("POSITION", 0)])
    p["indices"] = v
    return f"meshes[{mi}].primitives[{pi}].indices={v!r}"


def m_mode(doc, st, rng):
    prims = [p for m in doc.get("meshes", []) for p in m.get("primitives", [])]
    if not prims:
        return m_delete_required(doc, st, rng)
    v = pick(rng, [0, 1, 2, 3, 5, 6, 7, -1, 255, 2**32, "TRIANGLES", None])
    target = "all" if rng.random() < 0.5 else "one"
    for p in (prims if target == "all" else [pick(rng, prims)]):
        p["mode"] = v
    return f"primitive mode={v!r} ({target})"


def m_attributes(doc, st, rng):
    prims = [p for m in doc.get("meshes", []) for p in m.get("primitives", [])]
    if not prims:
        return m_delete_required(doc, st, rng)
    p = pick(rng, prims)
    attrs = p.setdefault("attributes", {})
    what = pick(rng, ["POSITION", "NORMAL", "TEXCOORD_0", "TEXCOORD_7", "COLOR_0", "JOINTS_0", "_X"])
    v = pick(rng, INDEX_POISON + [attrs.get("NORMAL", 0), attrs.get("TEXCOORD_0", 0), attrs.get("indices", 0)])
    attrs[what] = v
    return f"primitive attributes.{what}={v!r}"


def _ensure_lights(doc):
    ext = doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {})
    lights = ext.setdefault("lights", [])
    if not lights:
        lights += [{"type": "point", "intensity": 5}, {"type": "spot", "intensity": 10, "spot": {}},
                   {"type": "directional", "intensity": 2}]
        nodes = doc.setdefault("nodes", [])
        for i in range(len(lights)):
            nodes.append({"translation": [0.3 * i, 2, 1], "extensions": {"KHR_lights_punctual": {"light": i}}})
            scenes = doc.setdefault("scenes", [{"nodes": []}])
            scenes[doc.get("scene", 0) if isinstance(doc.get("scene", 0), int) and doc.get("scene", 0) < len(scenes) else 0].setdefault("nodes", []).append(len(nodes) - 1)
    used = doc.setdefault("extensionsUsed", [])
    if "KHR_lights_punctual" not in used:
        used.append("KHR_lights_punctual")
    return lights


def m_light(doc, st, rng):
    lights = _ensure_lights(doc)
    i = rng.randrange(len(lights))
    L = lights[i]
    field = pick(rng, ["intensity", "intensity", "range", "inner", "outer", "cone-order", "type", "color", "node-light"])
    bad = [1e39, -1, -1e39, 0, NAN, INF, "NaN", "nan", "-1", None, 1e308, 4.9e-324]
    if field in ("intensity", "range"):
        v = pick(rng, bad)
        L[field] = v
    elif field in ("inner", "outer"):
        L["type"] = "spot"
        v = pick(rng, bad + [math.pi, 2 * math.pi, 1.5707964, -0.1])
        L.setdefault("spot", {})["innerConeAngle" if field == "inner" else "outerConeAngle"] = v
    elif field == "cone-order":
        L["type"] = "spot"
        v = pick(rng, [(0.8, 0.2), (0.5, 0.5), (0.0, 0.0), (1.5707963, 1.5707963)])
        L["spot"] = {"innerConeAngle": v[0], "outerConeAngle": v[1]}
    elif field == "type":
        v = pick(rng, ["area", "", None, "POINT", 3])
        L["type"] = v
    elif field == "color":
        v = pick(rng, [[NAN, 1, 1], [1e39, 1e39, 1e39], [-1, -1, -1], [1, 1], [], "white", [1, 1, 1, 1]])
        L["color"] = v
    else:
        nodes = [n for n in doc.get("nodes", []) if "KHR_lights_punctual" in n.get("extensions", {})]
        v = pick(rng, INDEX_POISON)
        if nodes:
            pick(rng, nodes)["extensions"]["KHR_lights_punctual"]["light"] = v
        return f"node light index={v!r}"
    return f"lights[{i}].{field}={v!r}"


def m_material(doc, st, rng):
    mats = doc.setdefault("materials", [{}])
    if not mats:
        mats.append({})
    i = rng.randrange(len(mats))
    m = mats[i]
    pbr = m.setdefault("pbrMetallicRoughness", {})
    field = pick(rng, ["baseColorFactor", "metallicFactor", "roughnessFactor", "emissiveFactor",
                       "emissiveStrength", "texture", "texCoord", "alphaCutoff", "normalScale", "alphaMode"])
    huge = [1e39, -1, -1e39, 1e308, NAN, INF, "NaN", 2**64]
    if field == "baseColorFactor":
        v = pick(rng, [[1e39, 1, 1, 1], [-1, -1, -1, -1], [NAN, 0, 0, 1], [1, 1, 1], [], [2**64] * 4, "red"])
        pbr[field] = v
    elif field in ("metallicFactor", "roughnessFactor"):
        v = pick(rng, huge)
        pbr[field] = v
    elif field == "emissiveFactor":
        v = pick(rng, [[1e39, 1e39, 1e39], [-1, -1, -1], [NAN, NAN, NAN], [1, 1], [INF, 0, 0]])
        m[field] = v
    elif field == "emissiveStrength":
        v = pick(rng, huge + [0])
        m.setdefault("emissiveFactor", [1, 1, 1])
        m.setdefault("extensions", {})["KHR_materials_emissive_strength"] = {"emissiveStrength": v}
    elif field == "texture":
        v = pick(rng, INDEX_POISON)
        pbr["baseColorTexture"] = {"index": v}
    elif field == "texCoord":
        v = pick(rng, [1, 7, 99, -1, 2**32])
        pbr["baseColorTexture"] = {"index": 0, "texCoord": v}
    elif field == "alphaCutoff":
        v = pick(rng, huge)
        m["alphaMode"], m[field] = "MASK", v
    elif field == "normalScale":
        v = pick(rng, huge)
        m["normalTexture"] = {"index": 0, "scale": v}
    else:
        v = pick(rng, ["BLEND", "MASK", "bogus", 1])
        m[field] = v
    return f"materials[{i}].{field}={v!r}"


def m_node(doc, st, rng):
    nodes = _items(doc, "nodes")
    if not nodes:
        return m_delete_required(doc, st, rng)
    i = rng.randrange(len(nodes))
    n = nodes[i]
    what = pick(rng, ["matrix-nan", "matrix-inf", "matrix-zero", "matrix-degenerate", "matrix-short",
                      "scale", "scale", "rotation", "translation", "matrix+trs", "mesh-index",
                      "self-child", "cycle", "deep-chain", "many-instances", "child-index"])
    for k in ("matrix", "translation", "rotation", "scale"):
        if what.startswith("matrix"):
            n.pop(k, None)
    if what == "matrix-nan":
        m = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        m[rng.randrange(16)] = pick(rng, [NAN, "NaN"])
        n["matrix"] = m
    elif what == "matrix-inf":
        m = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        m[rng.randrange(16)] = pick(rng, [INF, -INF, 1e39, 1e308])
        n["matrix"] = m
    elif what == "matrix-zero":
        n["matrix"] = [0] * 16
    elif what == "matrix-degenerate":
        n["matrix"] = pick(rng, [[1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
                                 [1e-30, 0, 0, 0, 0, 1e-30, 0, 0, 0, 0, 1e-30, 0, 0, 0, 0, 1],
                                 [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0],
                                 [1, 0, 0, 1, 0, 1, 0, 1, 0, 0, 1, 1, 0, 0, 0, 1]])
    elif what == "matrix-short":
        n["matrix"] = pick(rng, [[1] * 15, [1] * 17, [], "identity"])
    elif what == "scale":
        n["scale"] = pick(rng, [[0, 0, 0], [0, 1, 1], [-1, 1, 1], [1e30, 1e30, 1e30], [1e-30, 1e-30, 1e-30],
                                [1e39, 1, 1], [NAN, 1, 1], [1, 1]])
    elif what == "rotation":
        n["rotation"] = pick(rng, [[0, 0, 0, 0], [1e39, 0, 0, 1], [NAN, 0, 0, 1], [2, 2, 2, 2], [0, 0, 1]])
    elif what == "translation":
        n["translation"] = pick(rng, [[1e39, 0, 0], [NAN, 0, 0], [1e30, 1e30, 1e30], [-INF, 0, 0]])
    elif what == "matrix+trs":
        n["matrix"] = [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]
        n["scale"] = [3, 3, 3]
    elif what == "mesh-index":
        n["mesh"] = pick(rng, INDEX_POISON)
    elif what == "self-child":
        n["children"] = [i]
    elif what == "cycle":
        j = (i + 1) % len(nodes)
        n["children"] = [j]
        nodes[j]["children"] = [i]
        return f"nodes[{i}] <-> nodes[{j}] child cycle"
    elif what == "deep-chain":
        # recursion depth: a chain of 100 000 nested children (stack overflow in a recursive walk)
        depth = pick(rng, [10000, 100000])
        start = len(nodes)
        for k in range(depth):
            nodes.append({"children": [start + k + 1]} if k < depth - 1 else {"mesh": 0})
        n["children"] = n.get("children", []) + [start]
        return f"nodes[{i}]: chain of {depth} nested children"
    elif what == "many-instances":
        count = 20000
        start = len(nodes)
        mesh = n.get("mesh", 0)
        nodes.extend({"mesh": mesh, "translation": [k * 0.001, 0, 0]} for k in range(count))
        doc.setdefault("scenes", [{"nodes": []}])[0].setdefault("nodes", []).extend(range(start, start + count))
        return f"{count} instances of mesh {mesh}"
    else:
        n["children"] = [pick(rng, INDEX_POISON)]
    return f"nodes[{i}] {what}: " + json.dumps({k: n.get(k) for k in ("matrix", "scale", "rotation", "translation", "mesh", "children") if k in n})[:160]


def m_camera(doc, st, rng):
    cams = doc.get("cameras")
    if not cams:
        doc["cameras"] = cams = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.05}}]
        nodes = doc.setdefault("nodes", [])
        nodes.append({"camera": 0, "translation": [0, 1, 5]})
        doc.setdefault("scenes", [{"nodes": []}])[0].setdefault("nodes", []).append(len(nodes) - 1)
    c = cams[0]
    field = pick(rng, ["yfov", "yfov", "aspectRatio", "znear", "zfar", "ortho", "type", "node-camera"])
    bad = [0, -1, -0.8, 1e39, NAN, INF, math.pi, 2 * math.pi, 1e-30, "0.8", None]
    if field == "ortho":
        v = {"xmag": pick(rng, [0, -1, NAN, 1e39]), "ymag": pick(rng, [0, 1, NAN]), "znear": 0, "zfar": pick(rng, [0, -1, 1e39])}
        cams[0] = {"type": "orthographic", "orthographic": v}
    elif field == "type":
        v = pick(rng, ["fisheye", "", None, "orthographic"])
        c["type"] = v
    elif field == "node-camera":
        v = pick(rng, INDEX_POISON)
        for n in doc.get("nodes", []):
            if "camera" in n:
                n["camera"] = v
                break
    else:
        v = pick(rng, bad)
        c.setdefault("perspective", {"yfov": 0.8, "znear": 0.05})[field] = v
    return f"cameras[0].{field}={v!r}"


def m_animation(doc, st, rng):
    accs = doc.get("accessors", [])
    anims = doc.get("animations")
    if not anims:
        anims = doc["animations"] = [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                                      "samplers": [{"input": 0, "output": 0}]}]
    a = anims[0]
    what = pick(rng, ["input", "output", "interp", "node", "path", "sampler", "time"])
    if what == "input":
        v = pick(rng, INDEX_POISON + list(range(min(len(accs), 4))))
        a["samplers"][0]["input"] = v
    elif what == "output":
        v = pick(rng, INDEX_POISON + list(range(min(len(accs), 4))))
        a["samplers"][0]["output"] = v
    elif what == "interp":
        v = pick(rng, ["CUBICSPLINE", "STEP", "bogus", None])
        a["samplers"][0]["interpolation"] = v
    elif what == "node":
        v = pick(rng, INDEX_POISON)
        a["channels"][0]["target"]["node"] = v
    elif what == "path":
        v = pick(rng, ["weights", "rotation", "scale", "bogus"])
        a["channels"][0]["target"]["path"] = v
    elif what == "sampler":
        v = pick(rng, INDEX_POISON)
        a["channels"][0]["sampler"] = v
    else:
        v = pick(rng, ["0.5", "1e30", "-5", "1e-300", "3.4e38", "100000"])
        st.time = v
        return f"animation evaluated at --time {v}"
    return f"animations[0].{what}={v!r}"


REQUIRED = [("asset",), ("asset", "version"), ("accessors", "*", "componentType"), ("accessors", "*", "count"),
            ("accessors", "*", "type"), ("bufferViews", "*", "buffer"), ("bufferViews", "*", "byteLength"),
            ("buffers", "*", "byteLength"), ("meshes", "*", "primitives"), ("meshes", "*", "primitives", "*", "attributes"),
            ("meshes", "*", "primitives", "*", "attributes", "POSITION"), ("scenes",), ("nodes",), ("buffers",),
            ("bufferViews",), ("accessors",), ("meshes",), ("images", "*", "uri"), ("images", "*", "bufferView"),
            ("textures", "*", "source"), ("cameras", "*", "perspective"), ("cameras", "*", "type"),
            ("animations", "*", "samplers"), ("extensions", "KHR_lights_punctual", "lights", "*", "type")]


def m_delete_required(doc, st, rng):
    path = pick(rng, REQUIRED)
    cur, trail = doc, []
    for k in path[:-1]:
        if k == "*":
            if not isinstance(cur, list) or not cur:
                return f"delete {'.'.join(path)} (absent)"
            j = rng.randrange(len(cur))
            trail.append(str(j))
            cur = cur[j]
        else:
            if not isinstance(cur, dict) or k not in cur:
                return f"delete {'.'.join(path)} (absent)"
            trail.append(k)
            cur = cur[k]
    last = path[-1]
    if last == "*" and isinstance(cur, list) and cur:
        cur.pop(rng.randrange(len(cur)))
    elif isinstance(cur, dict):
        cur.pop(last, None)
        trail.append(last)
    return "delete " + ".".join(trail)


def m_misc(doc, st, rng):
    what = pick(rng, ["version", "extensionsRequired", "scene", "deep-json", "huge-string", "random-leaf", "random-leaf"])
    if what == "version":
        v = pick(rng, ["3.0", "1.0", "2", "", "2.0.0.0", 2.0])
        doc.setdefault("asset", {})["version"] = v
        return f"asset.version={v!r}"
    if what == "extensionsRequired":
        doc["extensionsRequired"] = ["KHR_draco_mesh_compression", "EXT_bogus"]
        return "extensionsRequired: draco + unknown"
    if what == "scene":
        v = pick(rng, INDEX_POISON)
        doc["scene"] = v
        return f"scene={v!r}"
    if what == "deep-json":
        depth = pick(rng, [200, 5000])
        doc["extras"] = "__DEEP__%d" % depth   # expanded into nested arrays when serialised
        return f"extras nested {depth} arrays deep"
    if what == "huge-string":
        doc.setdefault("asset", {})["generator"] = "G" * 2_000_000
        return "asset.generator is 2 MB"
    # a random leaf anywhere in the document becomes a poison value
    leaves = []

    def walk(x, trail):
        if isinstance(x, dict):
            for k, v in x.items():
                walk(v, trail + [k]) if isinstance(v, (dict, list)) else leaves.append((x, k, trail + [k]))
        elif isinstance(x, list):
            for k, v in enumerate(x[:64]):
                walk(v, trail + [k]) if isinstance(v, (dict, list)) else leaves.append((x, k, trail + [k]))

    walk(doc, [])
    container, key, trail = pick(rng, leaves)
    v = pick(rng, NUM_POISON)
    container[key] = v
    return f"{'.'.join(map(str, trail))}={v!r}"


def m_uri(doc, st, rng):
    """Buffer or image URIs that escape, name devices, or are broken data: URIs; symlinks and
    FIFOs inside the case folder (an open() on a FIFO blocks: a reader that does not check the
    file type hangs)."""
    targets = [("buffers", i) for i in range(len(doc.get("buffers", [])))] + \
              [("images", i) for i in range(len(doc.get("images", [])))]
    if not targets:
        doc.setdefault("images", []).append({})
        targets = [("images", 0)]
    key, i = pick(rng, targets)
    how = pick(rng, ["uri"] * 6 + ["symlink", "fifo", "dir"])
    if how == "uri":
        v = pick(rng, HOSTILE_URIS)
    elif how == "symlink":
        v = "link" + (".bin" if key == "buffers" else ".png")
        st.extra[v] = ("symlink", pick(rng, ["/dev/zero", "/dev/urandom", "/etc/passwd", "/proc/self/mem", "../../../../etc/passwd", "link.bin"]))
    elif how == "fifo":
        v = "fifo" + (".bin" if key == "buffers" else ".png")
        st.extra[v] = ("fifo",)
    else:
        v = "subdir"
        st.extra["subdir/keep"] = b""
    doc[key][i]["uri"] = v
    doc[key][i].pop("bufferView", None)
    if rng.random() < 0.3:
        st.allow_external = True   # device files must stay refused even with external paths allowed
    extra = f" -> {st.extra[v][1]}" if how == "symlink" else ""
    return f"{key}[{i}].uri={v[:80]!r}{extra}" + (" (--allow-external-paths)" if st.allow_external else "")


JSON_MUTATIONS = [(m_accessor, 14), (m_buffer_view, 10), (m_buffer, 5), (m_indices, 8), (m_mode, 5),
                  (m_attributes, 4), (m_light, 10), (m_material, 8), (m_node, 10), (m_camera, 7),
                  (m_animation, 4), (m_delete_required, 8), (m_misc, 7)]


def glb_header_mutation(data, rng):
    """Edit the 12-byte header or the chunk headers of a packed GLB."""
    data = bytearray(data)
    jlen = struct.unpack("<I", data[12:16])[0]
    c1 = 20 + jlen
    what = pick(rng, ["magic", "version", "length", "len0", "len0", "type0", "len1", "len1", "type1",
                      "drop-bin", "swap", "extra-chunk", "json-nul-pad", "bom"])
    if what == "magic":
        v = pick(rng, [b"gltf", b"\0\0\0\0", b"GLTF", b"glTF"[::-1], bytes(rng.randrange(256) for _ in range(4))])
        data[0:4] = v
    elif what == "version":
        v = pick(rng, [0, 1, 3, 2**32 - 1])
        data[4:8] = struct.pack("<I", v)
    elif what == "length":
        v = pick(rng, [0, 12, 20, len(data) - 1, len(data) + 1, len(data) * 2, 2**32 - 1, len(data) // 2])
        data[8:12] = struct.pack("<I", v)
    elif what in ("len0", "len1"):
        at = 12 if what == "len0" else c1
        if at + 8 > len(data):
            return bytes(data), f"{what}: no such chunk"
        old = struct.unpack("<I", data[at:at + 4])[0]
        v = pick(rng, [0, 1, 3, old - 1, old + 1, old + 4, 2**31, 2**32 - 1, len(data), len(data) - at - 8 + 4])
        data[at:at + 4] = struct.pack("<I", v & 0xFFFFFFFF)
    elif what in ("type0", "type1"):
        at = 16 if what == "type0" else c1 + 4
        if at + 4 > len(data):
            return bytes(data), f"{what}: no such chunk"
        v = pick(rng, [CHUNK_BIN, CHUNK_JSON, 0, 0xFFFFFFFF, rng.randrange(2**32)])
        data[at:at + 4] = struct.pack("<I", v)
    elif what == "drop-bin":
        data = data[:c1]
        data[8:12] = struct.pack("<I", len(data))
        v = "BIN chunk removed, length fixed"
    elif what == "swap":
        j, b = data[12:c1], data[c1:]
        data = data[:12] + b + j
        v = "BIN chunk before JSON"
    elif what == "extra-chunk":
        data += struct.pack("<II", pick(rng, [2**32 - 1, 2**31, 16]), 0x12345678) + b"\0" * 16
        data[8:12] = struct.pack("<I", len(data))
        v = "extra unknown chunk"
    elif what == "json-nul-pad":
        body = data[20:c1].rstrip(b" ")
        data[20:c1] = body + b"\0" * (jlen - len(body))
        v = "JSON chunk padded with NUL"
    else:
        data[20:23] = b"\xef\xbb\xbf"
        v = "UTF-8 BOM over the JSON's first bytes"
    return bytes(data), f"glb {what}={v!r}"


def truncate(data, rng, boundaries=()):
    if len(data) < 2:
        return data, "truncate: too short"
    if boundaries and rng.random() < 0.5:
        b = pick(rng, list(boundaries))
        off = max(0, min(len(data) - 1, b + rng.randrange(-8, 9)))
    else:
        off = rng.randrange(len(data))
    return data[:off], f"truncated at {off} of {len(data)}"


def flip(data, rng, lo=0, hi=None):
    data = bytearray(data)
    hi = len(data) if hi is None else hi
    if hi <= lo:
        return bytes(data), "flip: empty"
    k = pick(rng, [1, 1, 2, 4, 8, 32])
    for _ in range(k):
        i = rng.randrange(lo, hi)
        data[i] ^= (1 << rng.randrange(8)) if rng.random() < 0.6 else rng.randrange(1, 256)
    return bytes(data), f"{k} byte flips in [{lo},{hi})"


def serialise_deep(doc, rng):
    text = json_text(doc, rng)
    marker = '"__DEEP__'
    at = text.find(marker)
    if at >= 0:
        end = text.index('"', at + 1)
        depth = int(text[at + len(marker):end])
        text = text[:at] + "[" * depth + "]" * depth + text[end + 1:]
    return text.encode()


def make_gltf_case(cid, rng, bases, case_dir, ctx):
    base = rng.choices(bases, weights=[b.weight for b in bases])[0]
    doc = json.loads(json.dumps(base.doc))
    st = GltfState(base)
    family = rng.choices(["json", "uri", "truncate", "flip", "glb-header", "bin"], weights=[62, 9, 8, 8, 8, 5])[0]
    if family == "glb-header" and base.container != "glb":
        family = "json"
    if family == "bin" and st.binary is None:
        family = "json"
    descs = []
    if family == "json":
        for _ in range(rng.choices([1, 2, 3], weights=[70, 20, 10])[0]):
            fn = rng.choices([f for f, _ in JSON_MUTATIONS], weights=[w for _, w in JSON_MUTATIONS])[0]
            try:
                descs.append(fn(doc, st, rng))
            except (KeyError, IndexError, TypeError, ValueError, AttributeError) as e:
                # a stacked edit can find the document already broken by the previous one
                descs.append(f"{fn.__name__} skipped ({type(e).__name__})")
    elif family == "uri":
        descs.append(m_uri(doc, st, rng))
    elif family == "bin":
        what = pick(rng, ["truncate", "flip"])
        if what == "truncate":
            st.binary, d = truncate(st.binary, rng)
        else:
            st.binary, d = flip(st.binary, rng)
        st.binary = bytearray(st.binary)
        st.bin_dirty = True
        descs.append("binary buffer " + d)
    text = serialise_deep(doc, rng)
    name = base.name
    if base.container == "glb":
        data = pack_glb(text, st.binary)
        jlen = struct.unpack("<I", data[12:16])[0]
        if family == "truncate":
            data, d = truncate(data, rng, [0, 12, 20, 20 + jlen, 28 + jlen, len(data)])
            descs.append(d)
        elif family == "flip":
            lo, hi = pick(rng, [(0, 64), (20, 20 + jlen), (0, len(data))])
            data, d = flip(data, rng, lo, min(hi, len(data)))
            descs.append(d)
        elif family == "glb-header":
            data, d = glb_header_mutation(data, rng)
            descs.append(d)
        scene = case_dir / (name + ".glb")
        scene.write_bytes(data)
    else:
        if family == "truncate":
            text, d = truncate(text, rng)
            descs.append("JSON " + d)
        elif family == "flip":
            text, d = flip(text, rng)
            descs.append("JSON " + d)
        scene = case_dir / (name + ".gltf")
        scene.write_bytes(text)
        if base.binary is not None:
            if st.bin_dirty:
                (case_dir / base.bin_name).write_bytes(bytes(st.binary))
            else:
                link_or_copy(base.bin_file, case_dir / base.bin_name)
        for rel, src in base.aux.items():
            link_or_copy(src, case_dir / rel)
    for rel, what in st.extra.items():
        p = case_dir / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(what, bytes):
            p.write_bytes(what)
        elif what[0] == "symlink":
            os.symlink(what[1], p)
        else:
            os.mkfifo(p)
    argv, mdesc = file_render_argv(ctx, scene, cid, rng)
    if st.allow_external:
        argv.append("--allow-external-paths")
    if st.time is not None:
        argv += ["--time", st.time]
    return Case(cid, "gltf", f"{base.name}/{family}: " + "; ".join(descs) + mdesc, argv, ctx.out_png(cid), scene)


def file_render_argv(ctx, scene, cid, rng):
    """The render of one mutated file: tiny, mostly `sparse` (the method with the most
    preprocessing of the scene), some `direct` and the CPU path tracer (its own BVH)."""
    method = rng.choices(["sparse", "direct", "reference"], weights=[80, 10, 10])[0]
    argv = [ctx.binary, "render", "--scene", str(scene), "--method", method,
            "--width", str(ctx.size), "--height", str(ctx.size), "--out", str(ctx.out_png(cid))]
    if method == "sparse":
        argv += ["--rsm", "16", "--sparse-points", "256"]
    elif method == "reference":
        argv += ["--spp", "1"]
    light = rng.random() < 0.8
    if light:
        argv += ["--light", "headlight:2"]
    return argv, f" [{method}{', headlight' if light else ''}]"


# ----------------------------------------------------------------------------- PLY

def generated_plys():
    """A cube as ascii, binary little-endian (with normals and uchar colours) and big-endian."""
    verts = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    head = "ply\nformat {fmt} 1.0\ncomment hostile_inputs cube\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
    ascii_ = (head.format(fmt="ascii") + "element face 6\nproperty list uchar int vertex_indices\nend_header\n"
              + "".join("%g %g %g\n" % v for v in verts) + "".join("4 %d %d %d %d\n" % f for f in faces)).encode()
    out = {"cube-ascii": ascii_}
    for fmt, e in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
        h = (head.format(fmt=fmt) + "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
             "property uchar green\nproperty uchar blue\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n")
        body = b"".join(struct.pack(e + "6f3B", *v, *[c - 0.5 for c in v], 200, 100, 50) for v in verts)
        body += b"".join(struct.pack(e + "B4i", 4, *f) for f in faces)
        out["cube-" + fmt] = h.encode() + body
    return out


def ply_split(data):
    at = data.find(b"end_header")
    if at < 0:
        return data, b""
    nl = data.find(b"\n", at)
    return data[:nl + 1], data[nl + 1:]


def make_ply_case(cid, rng, sources, case_dir, ctx):
    name = rng.choices(list(sources), weights=[sources[k][1] for k in sources])[0]
    data = sources[name][0]
    header, body = ply_split(data)
    hl = header.decode("latin-1").split("\n")
    what = pick(rng, ["count", "count", "count", "ptype", "listtype", "listtype", "format", "truncate", "truncate",
                      "face-index", "face-index", "face-count", "vertex-value", "garbage", "flip", "struct"])
    desc = what
    elems = [i for i, l in enumerate(hl) if l.startswith("element ")]
    if what == "count" and elems:
        i = pick(rng, elems)
        v = pick(rng, [0, 1, 2**31, 2**32, 2**32 + 1, 2**62, 2**63, 2**64 - 1, 2**64, -1, -(2**63), "0x10", "1e3", "",
                       "abc", "9" * 30])
        parts = hl[i].split()
        hl[i] = f"element {parts[1]} {v}"
        desc = f"{hl[i]!r}"
    elif what == "ptype":
        props = [i for i, l in enumerate(hl) if l.startswith("property ") and " list " not in l]
        i = pick(rng, props)
        t = pick(rng, ["char", "uchar", "short", "ushort", "int", "uint", "double", "int8", "uint8", "int16",
                       "uint32", "float64", "int64", "quad", "", "list uchar int"])
        hl[i] = f"property {t} {hl[i].split()[-1]}"
        desc = f"property type -> {hl[i]!r}"
    elif what == "listtype":
        lists = [i for i, l in enumerate(hl) if " list " in l]
        if lists:
            i = lists[0]
            a = pick(rng, ["uchar", "uint", "int", "float", "double", "char", "int64", "ulong", "bogus"])
            b = pick(rng, ["int", "uint", "uchar", "float", "double", "short", "bogus"])
            hl[i] = f"property list {a} {b} {pick(rng, ['vertex_indices', 'vertex_index', 'indices'])}"
            desc = f"list -> {hl[i]!r}"
    elif what == "format":
        i = next((k for k, l in enumerate(hl) if l.startswith("format")), 1)
        v = pick(rng, ["format ascii 1.0", "format binary_little_endian 1.0", "format binary_big_endian 1.0",
                       "format binary_middle_endian 1.0", "format ascii 2.0", "format", ""])
        hl[i] = v
        desc = f"format -> {v!r}"
    elif what == "truncate":
        if rng.random() < 0.8:
            body, d = truncate(body, rng)
            desc = "body " + d
        else:
            h = "\n".join(hl).encode()
            header_cut, d = truncate(h, rng)
            data = header_cut
            desc = "header " + d
            body = None
    elif what in ("face-index", "face-count") and b"ascii" in header and body:
        lines = body.split(b"\n")
        nv = int(next(l for l in hl if l.startswith("element vertex")).split()[2])
        faces = list(range(nv, len(lines) - 1))
        if faces:
            for _ in range(pick(rng, [1, 3, 50])):
                li = pick(rng, faces)
                toks = lines[li].split()
                if what == "face-index" and len(toks) > 1:
                    toks[rng.randrange(1, len(toks))] = str(pick(rng, [-1, -(2**31), 2**31, 2**32, 2**64, 10**30, nv, nv + 1, "nan", "1.5", "-0"])).encode()
                elif toks:
                    toks[0] = str(pick(rng, [0, 1, 2, 255, -1, 1000, 2**32])).encode()
                lines[li] = b" ".join(toks)
            body = b"\n".join(lines)
            desc = f"{what}: face lines edited"
    elif what in ("face-index", "face-count") and body:
        # binary: the generated cube's face block is the last 6 x 17 bytes
        e = "<" if b"little" in header else ">"
        b = bytearray(body)
        start = len(b) - 6 * 17
        f = rng.randrange(6)
        if what == "face-count":
            b[start + f * 17] = pick(rng, [0, 1, 2, 255])
        else:
            k = rng.randrange(4)
            b[start + f * 17 + 1 + 4 * k:start + f * 17 + 5 + 4 * k] = struct.pack(e + "i", pick(rng, [-1, -(2**31), 2**31 - 1, 8, 9]))
        body = bytes(b)
        desc = f"binary {what} of face {f}"
    elif what == "vertex-value" and body and b"ascii" not in header:
        # binary: the first vertex's x (the generated cubes store 27-byte vertices)
        e = "<" if b"little" in header else ">"
        v = pick(rng, [NAN, INF, -INF, 1e38 * 10, 3.4e38])
        body = struct.pack(e + "f", v) + body[4:]
        desc = f"binary vertex 0 x={v!r}"
    elif what == "vertex-value" and b"ascii" in header and body:
        lines = body.split(b"\n")
        k = rng.randrange(min(len(lines) - 1, 8) or 1)
        toks = lines[k].split() or [b"0"]
        toks[rng.randrange(len(toks))] = pick(rng, [b"nan", b"inf", b"-inf", b"1e39", b"1e308", b"abc", b"", b"0x1p3"])
        lines[k] = b" ".join(toks)
        body = b"\n".join(lines)
        desc = f"vertex line {k} -> {lines[k][:60]!r}"
    elif what == "garbage":
        g = pick(rng, ["insert-header-line", "append", "crlf", "no-end-header", "magic", "nul", "long-comment",
                       "empty-element", "second-vertex", "dup-x", "no-xyz", "element-before"])
        end = next((k for k, l in enumerate(hl) if l == "end_header"), len(hl) - 1)
        if g == "insert-header-line":
            hl.insert(rng.randrange(1, end + 1), pick(rng, ["garbage", "element", "property", "property float", "obj_info x", "\x00\xff"]))
        elif g == "append":
            body = (body or b"") + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 4096)))
        elif g == "crlf":
            hl = [l + "\r" for l in hl]
        elif g == "no-end-header":
            hl[end] = "end_headr"
        elif g == "magic":
            hl[0] = pick(rng, ["PLY", "", "ply garbage", "\ufeffply"])
        elif g == "nul":
            hl.insert(2, "comment \x00\x00\x00")
        elif g == "long-comment":
            hl.insert(2, "comment " + "x" * 1_000_000)
        elif g == "empty-element":
            hl.insert(end, "element junk %d" % pick(rng, [2**64 - 1, 2**62, 10**9]))
        elif g == "second-vertex":
            hl.insert(end, "element vertex 3")
            hl.insert(end + 1, "property float x")
        elif g == "dup-x":
            hl.insert(end, "element extra 1")
            hl.insert(end + 1, "property float x")
            hl.insert(end + 2, "property float x")
        elif g == "no-xyz":
            hl = [l.replace("property float z", "property float w") for l in hl]
        else:
            hl.insert(2, "element pre 2")
            hl.insert(3, "property list uchar int pre_list")
        desc = f"garbage: {g}"
    elif what == "flip":
        data, d = flip(data, rng)
        desc = d
        body = None
    elif what == "struct":
        # a list property before the position, in the vertex element (a known past panic)
        i = next(k for k, l in enumerate(hl) if l.startswith("element vertex"))
        hl.insert(i + 1, f"property list {pick(rng, ['uchar', 'uint'])} float junk")
        desc = "vertex element gets a list property before x"
    if body is not None:
        data = "\n".join(hl).encode("latin-1") + body
    path = case_dir / (name + ".ply")
    path.write_bytes(data)
    argv, mdesc = file_render_argv(ctx, path, cid, rng)
    if "--light" not in argv:
        argv += ["--light", "headlight:2"]
    return Case(cid, "ply", f"{name}: {desc}" + mdesc, argv, ctx.out_png(cid), path)


# ----------------------------------------------------------------------------- OBJ

def generated_obj():
    v = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    obj = ["# hostile_inputs cube + floor quad", "mtllib cube.mtl", "o cube"]
    obj += ["v %g %g %g" % p for p in v]
    obj += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "vn 0 0 1", "usemtl red"]
    obj += ["f " + " ".join(f"{i}/{k + 1}/1" for k, i in enumerate(f)) for f in faces]
    obj += ["o floor", "v -2 -0.01 -2", "v 2 -0.01 -2", "v 2 -0.01 2", "v -2 -0.01 2", "usemtl tex", "f 9 12 11 10"]
    mtl = ["newmtl red", "Kd 0.8 0.1 0.1", "Ks 0.04 0.04 0.04", "Ns 50", "", "newmtl tex", "Kd 1 1 1", "map_Kd checker.png"]
    return "\n".join(obj) + "\n", "\n".join(mtl) + "\n"


def make_obj_case(cid, rng, case_dir, ctx, checker):
    obj, mtl = generated_obj()
    ol, ml = obj.split("\n"), mtl.split("\n")
    extra = {}
    what = pick(rng, ["face-index", "face-index", "face-index", "face-shape", "vertex", "vertex", "mtllib", "mtllib",
                      "mtl-values", "map_Kd", "garbage", "garbage", "truncate", "flip"])
    faces = [i for i, l in enumerate(ol) if l.startswith("f ")]
    verts = [i for i, l in enumerate(ol) if l.startswith("v ")]
    if what == "face-index":
        i = pick(rng, faces)
        toks = ol[i].split()
        k = rng.randrange(1, len(toks))
        v = str(pick(rng, [0, -1, -8, -9, -999, 13, 2**31, 2**31 - 1, -(2**31), 2**63, 2**64, 10**20, "x", "1.5", "+1", "1e3"]))
        slot = rng.randrange(3)
        parts = toks[k].split("/")
        parts[min(slot, len(parts) - 1)] = v
        toks[k] = "/".join(parts)
        ol[i] = " ".join(toks)
        desc = f"face index -> {ol[i]!r}"
    elif what == "face-shape":
        i = pick(rng, faces)
        ol[i] = pick(rng, ["f 1", "f 1 2", "f", "f 1/2/3/4 2 3", "f 1// 2// 3//", "f /1 /2 /3", "f 1 1 1",
                           "f " + " ".join(str(1 + k % 8) for k in range(1000)), "f a b c", "f 1 2 3 \\"])
        desc = f"face -> {ol[i][:60]!r}"
    elif what == "vertex":
        i = pick(rng, verts)
        ol[i] = pick(rng, ["v nan nan nan", "v inf 0 0", "v -inf 0 0", "v 1e39 0 0", "v 1e308 1e308 1e308", "v 0 0",
                           "v", "v 0 0 0 1 0 0 1", "v 0 0 0 0", "v abc 0 0", "v 0x10 0 0", "v 1e-320 0 0"])
        if rng.random() < 0.3:
            ol.insert(i + 1, pick(rng, ["vn 0 0 0", "vn nan 0 0", "vt nan nan", "vt 1e39 0", "vn 1e39 0 0"]))
        desc = f"vertex -> {ol[i]!r}"
    elif what == "mtllib":
        v = pick(rng, ["missing.mtl", "../../../../etc/passwd", "/etc/passwd", "/dev/zero", "/dev/urandom",
                       "/proc/self/mem", "sub/../../../../../etc/shadow", "", "cube.mtl cube.mtl", "fifo.mtl",
                       "link.mtl", "subdir", "x" * 5000])
        if v == "fifo.mtl":
            extra[v] = ("fifo",)
        elif v == "link.mtl":
            extra[v] = ("symlink", pick(rng, ["/dev/zero", "/etc/passwd", "/dev/urandom"]))
        elif v == "subdir":
            extra["subdir/keep"] = b""
        ol[1] = "mtllib " + v
        if v == "" and rng.random() < 0.5:
            del ol[1]
        desc = f"mtllib {v[:60]!r}" + (f" -> {extra[v][1]}" if v == "link.mtl" else "")
    elif what == "mtl-values":
        key = pick(rng, ["Kd", "Ks", "Ke", "Ns", "d", "Tr", "Ni", "illum"])
        val = pick(rng, ["nan nan nan", "-1 -1 -1", "1e39 1e39 1e39", "inf", "-1", "1e39", "", "abc", "1"])
        ml.insert(1, f"{key} {val}")
        if rng.random() < 0.3:
            ol[ol.index("usemtl red")] = "usemtl " + pick(rng, ["undefined", "", "x" * 1000])
        desc = f"mtl {key} {val!r}"
    elif what == "map_Kd":
        v = pick(rng, ["../../../../etc/passwd", "/dev/urandom", "/dev/zero", "missing.png", "cube.obj", "fifo.png", "/proc/self/mem", ""])
        if v == "fifo.png":
            extra[v] = ("fifo",)
        ml[-2] = "map_Kd " + v
        desc = f"map_Kd {v!r}"
    elif what == "garbage":
        g = pick(rng, ["random-bytes", "long-line", "nul", "keywords", "crlf", "continuation", "many-groups"])
        if g == "random-bytes":
            ol.insert(rng.randrange(len(ol)), bytes(rng.randrange(256) for _ in range(64)).decode("latin-1"))
        elif g == "long-line":
            ol.insert(3, "# " + "x" * 1_000_000)
        elif g == "nul":
            ol.insert(3, "v 0\x00 0 0")
        elif g == "keywords":
            ol += pick(rng, [["l 1 2", "p 1"], ["curv 0 1 1 2"], ["s off", "g", "o"], ["usemtl"], ["vp 0 0"], ["f 1 2 3 4 5 6 7 8"]])
        elif g == "crlf":
            ol = [l + "\r" for l in ol]
        elif g == "continuation":
            ol.insert(5, "v 0 0 \\")
        else:
            ol += ["g g%d" % k for k in range(20000)]
        desc = f"garbage: {g}"
    else:
        desc = None
    data = "\n".join(ol).encode("latin-1")
    if what == "truncate":
        data, d = truncate(data, rng)
        desc = d
    elif what == "flip":
        data, d = flip(data, rng)
        desc = d
    path = case_dir / "cube.obj"
    path.write_bytes(data)
    (case_dir / "cube.mtl").write_bytes("\n".join(ml).encode("latin-1"))
    link_or_copy(checker, case_dir / "checker.png")
    for rel, w in extra.items():
        p = case_dir / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(w, bytes):
            p.write_bytes(w)
        elif w[0] == "symlink":
            os.symlink(w[1], p)
        else:
            os.mkfifo(p)
    argv, mdesc = file_render_argv(ctx, path, cid, rng)
    if rng.random() < 0.2:
        argv.append("--allow-external-paths")
        mdesc += " (--allow-external-paths)"
    return Case(cid, "obj", f"cube.obj: {desc}" + mdesc, argv, ctx.out_png(cid), path)


# ----------------------------------------------------------------------------- command lines

def cli_cases(ctx, case_root):
    """Abusive command lines over the built-in scenes: every numeric option gets zero,
    negatives, NaN, inf, overflows and huge values; unknown names; unwritable outputs."""
    out = []
    B = ctx.binary
    S = str(ctx.size)

    def render(opts=None, drop=(), extra=(), expect=True, scene="cornell", method="sparse"):
        base = {"--scene": scene, "--method": method, "--width": S, "--height": S}
        if method == "sparse":
            base.update({"--rsm": "16", "--sparse-points": "256"})
        if method == "reference":
            base["--spp"] = "1"
        base.update(opts or {})
        for d in drop:
            base.pop(d, None)
        return base, list(extra), expect

    bad_num = ["0", "-1", "NaN", "inf", "-inf", "1e39", "4294967296", "18446744073709551616", "abc", "", "1.5"]
    specs = []  # (desc, subcommand, opts dict, extra args, expect-output)
    for opt, values in [
        ("--width", bad_num + ["100000", "16385"]), ("--height", ["0", "-1", "NaN", "100000", "4294967297"]),
        ("--rsm", ["0", "-1", "NaN", "2049", "2048", "4294967296"]),
        ("--sparse-points", ["0", "-1", "NaN", "1048577", "1", "1048576"]),
        ("--shadow-res", ["0", "15", "16", "16385", "65536", "-1", "NaN", "4294967296"]),
        ("--shadow-memory", ["0", "65537", "-1", "NaN", "1", "65536"]),
        ("--max-vals", ["0", "1", "2147483648", "2147483649", "-1", "NaN"]),
        ("--max-edge", ["0", "-1", "NaN", "inf", "1e-9", "1e39", "1e-45", "0.001"]),
        ("--exposure", ["NaN", "inf", "65", "-65", "1e39", "abc", "64"]),
        ("--time", ["NaN", "inf", "-1", "1e39", "1e300", "-0", "1e30"]),
        ("--ssaa", ["0", "-1", "1000", "65536", "NaN"]),
        ("--emitter-lights", ["65", "-1", "NaN"]),
        ("--fov", ["0", "-1", "180", "360", "NaN", "1e39", "1e-30"]),
        ("--camera", ["99", "-1", "nope", ""]),
        ("--camera-eye", ["NaN,0,0", "1,2", "1,2,3,4", "inf,inf,inf", "0.278,0.273,-0.8", "1e39,0,0", ",,"]),
        ("--camera-target", ["NaN,0,0", "0.278,0.273,-0.8", "1e30,1e30,1e30"]),
        ("--views", ["stereo:NaN", "stereo:-1", "stereo:1e39", "grid:0", "grid:-1", "grid:100000", "cave:/etc/passwd",
                     "cave:missing.json", "cave:/dev/zero", "bogus", "grid:NaN"]),
        ("--tile", ["0", "257", "-1"]), ("--visibility-history", ["91", "-1", "NaN"]),
        ("--occlusion", ["bogus", ""]), ("--glossy", ["maybe"]), ("--weights", ["bogus"]),
        ("--seed", ["-1", "9223372036854775808", "NaN"]),
        ("--opt", ["bogus=1", "rsm=abc", "=", "noequals", "rsm=", "rsm=0"]),
        ("--light", ["point:NaN,0,0,1", "point:0,0,0,-1", "point:0.3,0.3,0.3,1e39", "spot:0,0.5,0,0,-1,0,40,20,5",
                     "spot:0,0.5,0,0,-1,0,10,180,5", "spot:0,0.5,0,0,0,0,10,20,5", "sun:0,0,0,2", "sun:0,-1,0,NaN",
                     "headlight:1e39", "headlight:-1", "laser:1", "point:", "point:0,0,0,1,-1,-1,-1", "headlight:2,NaN,0,0"]),
        ("--memory-every", ["-1", "NaN"]),
    ]:
        for v in values:
            specs.append((f"render {opt} {v!r}", "render", render({opt: v})))
    # the same light a hundred times and 2000 lights: the shadow and VAL budgets
    specs.append(("render 2000 --light point", "render", render(extra=sum((["--light", f"point:0.{k % 5 + 1},0.4,0.{k % 7 + 1},0.001"] for k in range(2000)), []))))
    for m, opts in [("reference", {"--spp": "0"}), ("reference", {"--spp": "-1"}), ("reference", {"--spp": "1048577"}),
                    ("reference", {"--spp": "NaN"}), ("reference", {"--bounces": "abc"}), ("reference", {"--bounces": "-1"}),
                    ("reference", {"--bounces": "NaN"}), ("reference", {"--bounces": "1e9", "--width": "4", "--height": "4"}),
                    ("reference", {"--bounces": "inf", "--width": "4", "--height": "4"}),
                    ("reference", {"--bounces": "18446744073709551616"}), ("reference", {"--seed": "-5"}),
                    ("lpv", {"--grid": "2"}), ("lpv", {"--grid": "257"}), ("lpv", {"--steps": "1025"}), ("lpv", {"--grid": "NaN"}),
                    ("holpv", {"--grid": "0"}), ("holpv", {"--steps": "-1"}), ("holpv", {"--rsm": "0"}),
                    ("negative", {"--positive": "0"}), ("negative", {"--negative": "1025"}), ("negative", {"--threshold-pos": "NaN"}),
                    ("negative", {"--threshold-normal": "2"}), ("negative", {"--dmin": "-1"}), ("negative", {"--dmin": "NaN"}),
                    ("negative", {"--weight": "bogus"}), ("negative", {"--falloff": "bogus"}), ("negative", {"--lowres": "NaN"}),
                    ("negative", {"--threshold-pos": "inf"}), ("brute", {"--rsm": "0"}), ("brute", {"--tile": "0"}),
                    ("atlas", {}), ("atlas", {"--atlas": "missing.exr"}), ("atlas", {"--atlas": "/dev/zero"}),
                    ("atlas", {"--atlas": "/etc/passwd"}), ("atlas", {"--atlas": "junk.exr"}),
                    ("sparse+atlas", {"--atlas": "/dev/urandom"}), ("bogus", {}), ("", {}), ("SPARSE", {}),
                    ("sparse:rsm=16", {}), ("direct", {"--rsm": "0"})]:
        specs.append((f"render --method {m!r} " + " ".join(f"{k} {v}" for k, v in opts.items()), "render", render(opts, method=m)))
    for sc in ["bogus", "", "sponza", "/tmp", "/dev/zero", "/dev/urandom", "/etc/passwd", "/proc/self/mem", "missing.glb",
               "missing.gltf", "fifo.gltf", "corridor-door999", "corridor-door-1", "door-room5", "door-room91", "door-roomNaN",
               "door-room90", "corridor-door0", "cornell ", "CORNELL", "../../../../etc/passwd.gltf"]:
        specs.append((f"render --scene {sc!r}", "render", render({"--scene": sc})))
    for o in ["/proc/x.png", "/tmp", "/nonexistent/dir/x.png", "x.bmp", "", "/dev/full", "noext", "/proc/self/mem",
              "/dev/null", "sub/dir/x.png", "x.png.exr", "/etc/passwd"]:
        specs.append((f"render --out {o!r}", "render", render({"--out": o}, expect=False)))
    for f in ["0", "-1", "4294967296", "NaN", "3"]:
        specs.append((f"render --frames {f} --out a file", "render", render({"--frames": f, "--scene": "cornell-moving"}, expect=False)))
    specs.append(("render --frames 2 --fps 0 --out DIR", "render", render({"--frames": "2", "--fps": "0", "--scene": "cornell-moving", "--out": "frames"}, expect=False)))
    specs.append(("render --frames 2 --fps NaN --out DIR", "render", render({"--frames": "2", "--fps": "NaN", "--scene": "cornell-moving", "--out": "frames"}, expect=False)))
    specs.append(("render --frames 2 --fps -1 --out DIR", "render", render({"--frames": "2", "--fps": "-1", "--scene": "cornell-moving", "--out": "frames"}, expect=False)))
    specs.append(("render --frames 2 --time 1e39 --out DIR", "render", render({"--frames": "2", "--time": "1e39", "--scene": "cornell-moving", "--out": "frames"}, expect=False)))
    specs.append(("render --frames 2 --out /proc/x", "render", render({"--frames": "2", "--scene": "cornell-moving", "--out": "/proc/x"}, expect=False)))
    specs.append(("render --frames 3 --no-write", "render", render({"--frames": "3", "--scene": "cornell-moving"}, extra=["--no-write"], expect=False)))
    specs.append(("render --no-write --memory-every 0", "render", render({"--memory-every": "0"}, extra=["--no-write"], expect=False)))
    specs.append(("render --max-edge 1e-5 on an imported glb", "render", render({"--scene": str(SHARED / "gltf-samples/EmissiveStrengthTest/EmissiveStrengthTest.glb"), "--max-edge": "1e-5"})))
    specs.append(("render --max-edge 0.0001 on the bunny ply", "render", render({"--scene": str(SHARED / "bunny/bun_zipper_res4.ply"), "--max-edge": "0.0001"}, extra=["--light", "headlight:2"])))
    specs.append(("render missing option value", "render", ({"--width": None}, [], False)))
    specs.append(("render unknown flag", "render", render(extra=["--bogus-flag"])))
    specs.append(("render repeated --width", "render", render(extra=["--width", "7"])))

    # bake
    bake_base = {"--scene": "cornell", "--vpls": "4", "--atlas-res": "32", "--near-rays": "0", "--cube-res": "8", "--bounces": "1"}
    for opt, values in [("--vpls", ["0", "-1", "16385", "NaN", "18446744073709551616"]), ("--bounces", ["0", "65", "-1", "NaN"]),
                        ("--atlas-res", ["0", "1", "-1", "65536", "4294967296", "NaN"]), ("--near-rays", ["2", "-1", "2147483648", "NaN"]),
                        ("--cube-res", ["0", "1", "65536", "-1"]), ("--from-bounce", ["0", "5", "-1"]),
                        ("--near-radius", ["NaN", "-1", "0", "inf"]), ("--max-edge", ["0", "NaN", "-1", "1e-9"]),
                        ("--lights", ["bogus", "polygons"]), ("--cluster-size", ["0", "-1"]), ("--polygon-cube-res", ["0", "65536"]),
                        ("--scene", ["bogus", "/dev/zero", "sponza"]), ("--light", ["point:NaN,0,0,1", "headlight:2"]),
                        ("--out", ["/proc/x.exr", "/tmp", "x.png", "/dev/full"])]:
        for v in values:
            o = dict(bake_base)
            if opt == "--lights" and v == "polygons":
                o["--vpls"] = "8"
            if opt == "--from-bounce":
                o["--bounces"] = "2"
            o[opt] = v
            specs.append((f"bake {opt} {v!r}", "bake", (o, [], opt != "--out")))
    # eval
    ev = {"--scenes": "cornell", "--methods": "direct", "--width": "16", "--height": "16", "--ref-spp": "1"}
    for opt, v in [("--scenes", "bogus"), ("--scenes", ""), ("--scenes", ",,,"), ("--methods", "bogus"), ("--methods", "sparse:rsm=0"),
                   ("--methods", "sparse:="), ("--methods", "direct:foo=bar"), ("--methods", ""), ("--methods", "sparse:rsm=16,bogus=1"),
                   ("--ref-spp", "0"), ("--ref-spp", "-1"), ("--frames", "0"), ("--frames", "-1"), ("--frames", "4294967296"),
                   ("--width", "0"), ("--height", "NaN"), ("--exposure", "NaN"), ("--exposure", "inf"), ("--ref-bounces", "-1"),
                   ("--ref-bounces", "abc"), ("--max-edge", "0"), ("--emitter-lights", "65"), ("--scenes", "/dev/zero"),
                   ("--fov", "0"), ("--camera", "99")]:
        o = dict(ev)
        o[opt] = v
        specs.append((f"eval {opt} {v!r}", "eval", (o, [], True)))
    specs.append(("eval --out /proc/x", "eval", ({**ev, "--out": "/proc/x"}, [], False)))
    # mr
    R = SHARED / "rgbd" / "RGBD"
    mr = {"--rgbd": str(R), "--object": str(SHARED / "bunny/bun_zipper_res4.ply"), "--frames": "0", "--sparse-points": "16",
          "--rsm": "8", "--differential-rays": "0", "--real-vals": "64"}
    for opt, v in [("--frames", "5..2"), ("--frames", "0..0"), ("--frames", "99999"), ("--frames", "-1"), ("--frames", "a..b"),
                   ("--frames", "0..18446744073709551615"), ("--rgbd", "/nonexistent"), ("--rgbd", "/tmp"), ("--rgbd", "/dev/zero"),
                   ("--format", "bogus"), ("--format", "nyu"), ("--intrinsics", "/etc/passwd"), ("--intrinsics", "zero-focal.json"),
                   ("--scale", "0"), ("--scale", "-1"), ("--scale", "NaN"), ("--scale", "1e39"), ("--yaw", "NaN"), ("--yaw", "1e39"),
                   ("--place", "NaN,0,0"), ("--place", "1,2"), ("--place", "1e39,0,0"), ("--voxel", "0"), ("--voxel", "-1"),
                   ("--accumulate", "0"), ("--accumulate", "4294967296"), ("--real-vals", "0"), ("--bilateral-radius", "2147483647"),
                   ("--sigma-spatial", "0"), ("--sigma-range", "NaN"), ("--differential-rays", "2147483647"), ("--sparse-points", "0"),
                   ("--rsm", "0"), ("--object", "/dev/zero"), ("--object", "missing.glb"), ("--object", "/etc/passwd"),
                   ("--trajectory", "/etc/passwd"), ("--trajectory", "/dev/zero"), ("--light", "bogus"),
                   ("--light", "point:0,0,0:NaN"), ("--real-scale", "NaN"), ("--real-scale", "-1"), ("--out", "/proc/x")]:
        o = dict(mr)
        o[opt] = v
        specs.append((f"mr {opt} {v!r}", "mr", (o, [], opt not in ("--out",))))
    specs.append(("mr --color /dev/zero --depth /dev/zero", "mr", ({k: v for k, v in mr.items() if k != "--rgbd"} | {"--color": "/dev/zero", "--depth": "/dev/zero"}, [], True)))
    specs.append(("mr --color depth-as-colour", "mr", ({k: v for k, v in mr.items() if k != "--rgbd"} | {"--color": str(R / "depth/00000.png"), "--depth": str(R / "color/00000.jpg")}, [], True)))

    for n, (desc, sub, (opts, extra, expect)) in enumerate(specs):
        cid = f"cli-{n:04d}"
        d = case_root / cid
        d.mkdir(parents=True, exist_ok=True)
        (d / "junk.exr").write_bytes(b"v/1\x01" + bytes(range(256)) * 4)
        (d / "zero-focal.json").write_text('{"width": 640, "height": 480, "intrinsic_matrix": [0,0,0,0,0,0,319.5,239.5,1]}')
        os.mkfifo(d / "fifo.gltf")
        argv = [B, sub]
        opts = dict(opts)
        if sub == "render" and "--out" not in opts:
            opts["--out"] = str(ctx.out_png(cid))
        if sub in ("bake",) and "--out" not in opts:
            opts["--out"] = str(ctx.out_dir / f"{cid}.exr")
        if sub in ("eval", "mr") and "--out" not in opts:
            opts["--out"] = str(ctx.out_dir / cid)
        for k, v in opts.items():
            argv += [k] if v is None else [k, v]
        argv += extra
        target = None
        if expect:
            target = {"render": opts.get("--out"), "bake": opts.get("--out"),
                      "eval": str(Path(opts.get("--out", "")) / "results.csv"),
                      "mr": str(Path(opts.get("--out", "")) / "composite_00000.png")}[sub]
            if sub == "render" and "--frames" in opts:
                target = None
            if sub == "mr" and opts.get("--frames") not in ("0",):
                target = None
        out.append(Case(cid, "cli", desc, argv, Path(target) if target else None))
    return out


# ----------------------------------------------------------------------------- running

class Ctx:
    def __init__(self, args):
        self.binary = str(Path(args.binary).resolve())
        self.scratch = Path(args.scratch).resolve()
        self.out_dir = self.scratch / "out"
        self.size = args.size

    def out_png(self, cid):
        return self.out_dir / f"{cid}.png"


def limit_prefix(args):
    """The child's limits, as a `prlimit` prefix (util-linux; it execs the command, so the pid
    is valgi's). prlimit rather than preexec_fn: preexec_fn is unsafe in a threaded parent.
    RLIMIT_AS is the memory cap (lavapipe starts under 8 GiB; the sanity check proves it);
    no core files; a hostile --width or --frames must not fill the disk: 2 GiB per file."""
    mem = int(args.mem_gib * (1 << 30))
    pre = ["prlimit", "--core=0", f"--fsize={2 << 30}"]
    if args.mem_mode == "as":
        pre.append(f"--as={mem}")
    return pre + ["--"]


def rss_bytes(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def run_case(case, args, case_dir):
    env = dict(os.environ, RUST_BACKTRACE="1")
    mem = int(args.mem_gib * (1 << 30))
    t0 = time.monotonic()
    hung = mem_killed = False
    peak = 0
    cpu = None
    with open(case_dir / "stdout.txt", "wb") as out, open(case_dir / "stderr.txt", "wb") as err:
        p = subprocess.Popen(limit_prefix(args) + case.argv, cwd=case_dir, stdout=out, stderr=err,
                             stdin=subprocess.DEVNULL, env=env, start_new_session=True)
        # Poll instead of wait(timeout): the RSS watcher (mem-mode rss) needs to sample.
        while True:
            try:
                p.wait(timeout=0.2)
                break
            except subprocess.TimeoutExpired:
                pass
            r = rss_bytes(p.pid)
            peak = max(peak, r)
            if args.mem_mode == "rss" and r > mem:
                mem_killed = True
            if time.monotonic() - t0 > args.timeout:
                hung = True
            if hung or mem_killed:
                cpu = cpu_seconds(p.pid)
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                p.wait()
                break
    secs = time.monotonic() - t0
    stderr = (case_dir / "stderr.txt").read_bytes().decode("utf-8", "replace")
    stdout = (case_dir / "stdout.txt").read_bytes().decode("utf-8", "replace")
    row = classify(case, p.returncode, secs, stdout, stderr, hung, mem_killed, peak)
    row["cpu_s_at_kill"] = "" if cpu is None else round(cpu, 1)
    return row


def cpu_seconds(pid):
    """User + system CPU seconds of a process (all its threads): tells a hang that waits
    (a FIFO, a lock: ~0 s) from one that computes (~timeout x threads)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def first_error_line(stderr):
    lines = [l for l in stderr.splitlines() if l.strip()]
    for l in lines:
        if l.startswith("error") or "] ERROR" in l:
            return l
    for l in lines:
        if "panicked" in l or "memory allocation" in l or "overflowed" in l:
            return l
    # skip progress lines ("loading X: 1/1 in 0.0 s") and log warnings
    rest = [l for l in lines if not (" in " in l and "/" in l and l.rstrip().endswith(" s")) and " WARN " not in l]
    return (rest or lines or [""])[0]


def classify(case, rc, secs, stdout, stderr, hung, mem_killed, peak):
    row = {"id": case.id, "kind": case.kind, "mutation": case.desc, "exit": rc, "seconds": round(secs, 2),
           "outcome": None, "first_stderr": first_error_line(stderr)[:400], "names_file": "", "black": "",
           "non_finite_pixels": "", "warnings": stderr.count(" WARN "), "peak_rss_mb": round(peak / 2**20),
           "command": " ".join(sh_quote(a) for a in case.argv)}
    report = None
    for line in reversed(stdout.splitlines()):
        if line.startswith("{"):
            try:
                report = json.loads(line)
            except ValueError:
                pass
            break
    nf = 0
    if isinstance(report, dict):
        v = report.get("non_finite_pixels", 0)
        nf = sum(v) if isinstance(v, list) else (v or 0)
        row["non_finite_pixels"] = nf
    if hung:
        row["outcome"] = "hang"
    elif mem_killed or rc == -signal.SIGKILL or rc == -signal.SIGXFSZ or "memory allocation of" in stderr:
        row["outcome"] = "killed"   # the cap (RLIMIT_AS makes Rust abort with "memory allocation of N bytes failed")
    elif "panicked" in stderr or rc == 101 or (rc is not None and rc < 0) or rc in (134, 139):
        row["outcome"] = "panic"
    elif "GPU error" in stderr:
        row["outcome"] = "gpu-error"
    elif rc == 0:
        if case.expect is not None and not Path(case.expect).exists():
            row["outcome"] = "no-output"
        elif nf or "non-finite radiance" in stderr:   # app.rs: "N pixels had non-finite radiance"
            row["outcome"] = "non-finite"
        else:
            row["outcome"] = "ok"
            if case.expect is not None and str(case.expect).endswith(".png"):
                b = png_is_black(case.expect)
                row["black"] = "" if b is None else ("yes" if b else "no")
    else:
        has_error = any(l.startswith("error") for l in stderr.splitlines())
        row["outcome"] = "clean-error" if has_error else "unclear-error"
    if case.input_path is not None and row["outcome"] in ("clean-error", "unclear-error"):
        row["names_file"] = "yes" if (str(case.input_path) in stderr or Path(case.input_path).name in row["first_stderr"]) else "no"
    return row


def sh_quote(s):
    s = str(s)
    if s and all(c.isalnum() or c in "-_./=:,+@%" for c in s):
        return s
    return "'" + s.replace("'", "'\\''") + "'"


def write_cmd(case, case_dir, args):
    """A script that reproduces the case exactly (same folder, same limits, a backtrace)."""
    cmd = " ".join(sh_quote(a) for a in limit_prefix(args) + case.argv)
    (case_dir / "cmd.sh").write_text(
        "#!/bin/sh\n# %s: %s\ncd %s && RUST_BACKTRACE=1 exec %s\n" % (case.id, case.desc.replace("\n", " ")[:300], sh_quote(case_dir), cmd))


def prepare_scratch(scratch, keep_failures=False):
    """Wipe what a previous campaign left, but never a folder that is not ours."""
    marker = scratch / ".hostile-scratch"
    if scratch.exists() and any(scratch.iterdir()) and not marker.exists():
        sys.exit(f"{scratch} is not empty and not a hostile-input scratch folder; pick another --scratch")
    if scratch.exists():
        for sub in ("cases", "out", "base") + (() if keep_failures else ("failures",)):
            if (scratch / sub).exists():
                shutil.rmtree(scratch / sub)
    for sub in ("cases", "out", "base"):
        (scratch / sub).mkdir(parents=True, exist_ok=True)
    marker.write_text("made by scripts/hostile_inputs.py\n")


def generate(args, ctx):
    samples = Path(args.samples)
    bunny = Path(args.bunny)
    cases_root = ctx.scratch / "cases"
    cases = []
    kinds = set(args.kinds.split(","))
    if "gltf" in kinds:
        bases = load_gltf_bases(samples, ctx.scratch / "base")
        for i in range(args.gltf):
            cid = f"gltf-{i:04d}"
            d = cases_root / cid
            d.mkdir(parents=True)
            cases.append(make_gltf_case(cid, random.Random(f"{args.seed}/gltf/{i}"), bases, d, ctx))
    if "ply" in kinds:
        sources = {k: (v, 4) for k, v in generated_plys().items()}
        for p, w in (("bun_zipper_res4.ply", 6), ("bun_zipper_res2.ply", 2), ("bun_zipper.ply", 1)):
            if (bunny / p).exists():
                sources[p[:-4]] = ((bunny / p).read_bytes(), w)
        for i in range(args.ply):
            cid = f"ply-{i:04d}"
            d = cases_root / cid
            d.mkdir(parents=True)
            cases.append(make_ply_case(cid, random.Random(f"{args.seed}/ply/{i}"), sources, d, ctx))
    if "obj" in kinds:
        checker = ctx.scratch / "base" / "checker.png"
        checker.write_bytes(png_bytes(2, 2, [[255, 255, 255, 0, 0, 0], [0, 0, 0, 255, 255, 255]]))
        for i in range(args.obj):
            cid = f"obj-{i:04d}"
            d = cases_root / cid
            d.mkdir(parents=True)
            cases.append(make_obj_case(cid, random.Random(f"{args.seed}/obj/{i}"), d, ctx, checker))
    if "cli" in kinds:
        cli = cli_cases(ctx, cases_root)
        if args.cli < len(cli):
            # keep a deterministic, evenly spread subset when fewer are asked for
            step = len(cli) / args.cli
            cli = [cli[int(k * step)] for k in range(args.cli)]
        cases += cli
    for c in cases:
        write_cmd(c, cases_root / c.id, args)
    return cases


def sanity_check(args, ctx):
    """The memory cap must not break lavapipe itself: a valid tiny render under the cap."""
    case = Case("sanity", "sanity", "valid cornell under the cap",
                [ctx.binary, "render", "--scene", "cornell", "--method", "sparse", "--width", "16", "--height", "16",
                 "--rsm", "8", "--sparse-points", "64", "--out", str(ctx.out_dir / "sanity.png")], ctx.out_dir / "sanity.png")
    d = ctx.scratch / "cases" / "sanity"
    d.mkdir(parents=True, exist_ok=True)
    row = run_case(case, args, d)
    if row["outcome"] != "ok":
        sys.exit(f"sanity render failed under the cap ({row['outcome']}: {row['first_stderr']}); "
                 f"try --mem-mode rss or a larger --mem-gib")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=str(REPO / "target" / "release" / "valgi"))
    ap.add_argument("--scratch", default="/tmp/hostile")
    ap.add_argument("--seed", default="1")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=60)
    ap.add_argument("--mem-gib", type=float, default=8)
    ap.add_argument("--mem-mode", choices=["as", "rss"], default="as")
    ap.add_argument("--size", type=int, default=32, help="render width and height of the file cases")
    ap.add_argument("--gltf", type=int, default=1100)
    ap.add_argument("--ply", type=int, default=150)
    ap.add_argument("--obj", type=int, default=150)
    ap.add_argument("--cli", type=int, default=10**6, help="at most this many command-line cases (default: all)")
    ap.add_argument("--kinds", default="gltf,ply,obj,cli")
    ap.add_argument("--samples", default=str(SHARED / "gltf-samples"))
    ap.add_argument("--bunny", default=str(SHARED / "bunny"))
    ap.add_argument("--case", help="run only this case id (after generating all, so ids are stable)")
    ap.add_argument("--generate-only", action="store_true")
    args = ap.parse_args()

    ctx = Ctx(args)
    if not Path(ctx.binary).exists():
        sys.exit(f"no binary at {ctx.binary}")
    prepare_scratch(ctx.scratch, keep_failures=bool(args.case))
    t_start = time.monotonic()
    cases = generate(args, ctx)
    print(f"generated {len(cases)} cases in {time.monotonic() - t_start:.1f} s under {ctx.scratch}/cases", flush=True)
    if args.case:
        cases = [c for c in cases if c.id == args.case]
        if not cases:
            sys.exit(f"no case {args.case}")
    if args.generate_only:
        return 0
    sanity_check(args, ctx)

    rows, lock, done = [], threading.Lock(), [0]

    def one(case):
        row = run_case(case, args, ctx.scratch / "cases" / case.id)
        with lock:
            done[0] += 1
            rows.append(row)
            if row["outcome"] in FAILING or done[0] % 50 == 0 or len(cases) < 50:
                print(f"[{done[0]}/{len(cases)} {time.monotonic() - t_start:.0f}s] {row['id']} {row['outcome']} "
                      f"{row['seconds']}s {row['first_stderr'][:120]}", flush=True)
        return row

    t_run = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        list(pool.map(one, cases))
    wall = time.monotonic() - t_run
    rows.sort(key=lambda r: r["id"])

    # keep the failing inputs (and their stderr, command) together
    def kept(r):
        return r["outcome"] in FAILING or r["outcome"] == "gpu-error"

    for r in rows:
        if kept(r):
            src, dst = ctx.scratch / "cases" / r["id"], ctx.scratch / "failures" / r["id"]
            copy_case_dir(src, dst)
            cmd = dst / "cmd.sh"   # reproduce from the kept copy, not the folder the next run wipes
            cmd.write_text(cmd.read_text().replace(str(src), str(dst)))

    if args.case:
        print(json.dumps(rows, indent=1))
        print(f"stderr: {ctx.scratch}/cases/{args.case}/stderr.txt")
        return 1 if any(r["outcome"] in FAILING for r in rows) else 0
    fields = list(rows[0].keys()) if rows else []
    with open(ctx.scratch / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    (ctx.scratch / "results.json").write_text(json.dumps(rows, indent=1))

    kinds = [k for k in ("gltf", "ply", "obj", "cli") if any(r["kind"] == k for r in rows)]
    print(f"\n{len(rows)} cases, seed {args.seed}, {args.jobs} jobs, run wall time {wall:.0f} s "
          f"({sum(r['seconds'] for r in rows):.0f} s of case time)\n")
    header = "| kind | " + " | ".join(OUTCOMES) + " | total | ok black (lit) | errors not naming the file |"
    print(header)
    print("|" + "---|" * (len(OUTCOMES) + 4))
    for k in kinds + ["all"]:
        rs = [r for r in rows if k == "all" or r["kind"] == k]
        counts = [sum(r["outcome"] == o for r in rs) for o in OUTCOMES]
        print(f"| {k} | " + " | ".join(map(str, counts)) + f" | {len(rs)} | {sum(r['black'] == 'yes' and '--light' in r['command'] for r in rs)} | "
              f"{sum(r['names_file'] == 'no' for r in rs)} |")
    bad = [r for r in rows if r["outcome"] not in ("ok", "clean-error")]
    if bad:
        print("\nnot ok / clean-error:")
        for r in bad:
            cpu = f", {r['cpu_s_at_kill']} CPU s" if r["cpu_s_at_kill"] != "" else ""
            print(f"\n{r['id']} [{r['outcome']}] exit {r['exit']} {r['seconds']} s{cpu}: {r['mutation']}\n"
                  f"  reproduce: sh {ctx.scratch}/{'failures' if kept(r) else 'cases'}/{r['id']}/cmd.sh\n"
                  f"  stderr: {r['first_stderr'][:300]}")
    print(f"\nresults: {ctx.scratch}/results.csv, {ctx.scratch}/results.json")
    return 1 if any(r["outcome"] in FAILING for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
