"""Writes spot_lambert_plane.gltf with pygltflib (an independent glTF writer), so valgi's tests
render a file that valgi did not author: a 2 m x 2 m Lambertian plane (KHR_materials_specular
specularFactor 0) under a coloured KHR_lights_punctual spot light, seen by a camera without an
aspect ratio. Run: pip install pygltflib==1.16.5 && python3 make_spot_lambert_plane.py
"""
import base64
import math
import struct

import pygltflib as g

N = 16  # grid cells per side
SIZE = 2.0
positions, normals, indices = [], [], []
for j in range(N + 1):
    for i in range(N + 1):
        positions.append((-SIZE / 2 + SIZE * i / N, 0.0, -SIZE / 2 + SIZE * j / N))
        normals.append((0.0, 1.0, 0.0))
for j in range(N):
    for i in range(N):
        a = j * (N + 1) + i
        b, c, d = a + 1, a + N + 1, a + N + 2
        # Counter-clockwise seen from +y.
        indices += [a, c, b, b, c, d]

pos_bytes = b"".join(struct.pack("<3f", *p) for p in positions)
nrm_bytes = b"".join(struct.pack("<3f", *n) for n in normals)
idx_bytes = b"".join(struct.pack("<I", i) for i in indices)
blob = pos_bytes + nrm_bytes + idx_bytes

half = math.sqrt(0.5)
gltf = g.GLTF2(
    asset=g.Asset(version="2.0", generator="pygltflib"),
    extensionsUsed=["KHR_lights_punctual", "KHR_materials_specular"],
    scene=0,
    scenes=[g.Scene(nodes=[0, 1, 2])],
    nodes=[
        g.Node(name="plane", mesh=0),
        # -90 degrees about x: the light's -z axis points down.
        g.Node(name="spot", translation=[0.0, 1.5, 0.0], rotation=[-half, 0.0, 0.0, half],
               extensions={"KHR_lights_punctual": {"light": 0}}),
        g.Node(name="camera", camera=0, translation=[0.0, 3.0, 0.0],
               rotation=[-half, 0.0, 0.0, half]),
    ],
    cameras=[g.Camera(type="perspective",
                      perspective=g.Perspective(yfov=0.9, znear=0.1, zfar=10.0))],
    extensions={"KHR_lights_punctual": {"lights": [{
        "type": "spot", "name": "spot", "color": [1.0, 0.5, 0.25], "intensity": 2.0,
        "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}}]}},
    materials=[g.Material(
        name="lambert",
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.5, 0.5, 0.5, 1.0], metallicFactor=0.0, roughnessFactor=1.0),
        extensions={"KHR_materials_specular": {"specularFactor": 0.0}})],
    meshes=[g.Mesh(name="plane", primitives=[g.Primitive(
        attributes=g.Attributes(POSITION=0, NORMAL=1), indices=2, material=0)])],
    accessors=[
        g.Accessor(bufferView=0, componentType=g.FLOAT, count=len(positions), type=g.VEC3,
                   min=[-SIZE / 2, 0.0, -SIZE / 2], max=[SIZE / 2, 0.0, SIZE / 2]),
        g.Accessor(bufferView=1, componentType=g.FLOAT, count=len(normals), type=g.VEC3),
        g.Accessor(bufferView=2, componentType=g.UNSIGNED_INT, count=len(indices), type=g.SCALAR),
    ],
    bufferViews=[
        g.BufferView(buffer=0, byteOffset=0, byteLength=len(pos_bytes), target=g.ARRAY_BUFFER),
        g.BufferView(buffer=0, byteOffset=len(pos_bytes), byteLength=len(nrm_bytes),
                     target=g.ARRAY_BUFFER),
        g.BufferView(buffer=0, byteOffset=len(pos_bytes) + len(nrm_bytes),
                     byteLength=len(idx_bytes), target=g.ELEMENT_ARRAY_BUFFER),
    ],
    buffers=[g.Buffer(byteLength=len(blob),
                      uri="data:application/octet-stream;base64," + base64.b64encode(blob).decode())],
)
gltf.save("spot_lambert_plane.gltf")
