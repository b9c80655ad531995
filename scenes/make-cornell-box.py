#!/usr/bin/env python3
"""Writes the pbrt-v4 and glTF 2.0 versions of the measured Cornell box (cornell-box.pbrt,
cornell-box.gltf) from the OBJ meshes of the Mitsuba 3 scene in ../shared/scenes/cornell-box,
with the same camera, materials, light and integrator settings as its cbox-rgb.xml.

    python3 scenes/make-cornell-box.py ../shared/scenes/cornell-box/meshes

The tests render both and compare them with Mitsuba's reference of the XML scene. The geometry
is written inline, so the outputs need nothing else."""
import base64, json, math, os, struct, sys

MESHES = [  # (file, material, y offset, emits)
    ("cbox_luminaire.obj", "light", -0.5, True),
    ("cbox_floor.obj", "white", 0, False),
    ("cbox_ceiling.obj", "white", 0, False),
    ("cbox_back.obj", "white", 0, False),
    ("cbox_greenwall.obj", "green", 0, False),
    ("cbox_redwall.obj", "red", 0, False),
    ("cbox_smallbox.obj", "box", 0, False),
    ("cbox_largebox.obj", "box", 0, False),
]
MATERIALS = {
    "box": (0.45, 0.30, 0.90),
    "white": (0.885809, 0.698859, 0.666422),
    "red": (0.570068, 0.0430135, 0.0443706),
    "green": (0.105421, 0.37798, 0.076425),
    "light": (0.936461, 0.740433, 0.705267),
}
RADIANCE = (18.387, 10.9873, 2.75357)


def read_obj(path, dy):
    pos, tris = [], []
    for line in open(path):
        w = line.split()
        if not w:
            continue
        if w[0] == "v":
            x, y, z = map(float, w[1:4])
            pos.append((x, y + dy, z))
        elif w[0] == "f":
            idx = [int(t.split("/")[0]) - 1 for t in w[1:]]
            for k in range(1, len(idx) - 1):
                tris.append((idx[0], idx[k], idx[k + 1]))
    return pos, tris


def fmt(v):
    return " ".join(f"{x:g}" for x in v)


def main(meshes_dir, out_dir):
    meshes = [(read_obj(os.path.join(meshes_dir, f), dy), m, e, f) for f, m, dy, e in MESHES]

    # pbrt-v4. pbrt's camera space has +x to the image's right; Mitsuba's has +x to the left,
    # so the mirror in front of LookAt gives the picture Mitsuba renders.
    out = ["# The measured Cornell box (Mitsuba 3's cbox-rgb.xml), for pbrt-v4. Written by make-cornell-box.py.",
           "Scale -1 1 1",
           "LookAt 278 273 -800  278 273 -799  0 1 0",
           'Camera "perspective" "float fov" [ 39.3077 ]',
           'Film "rgb" "integer xresolution" [ 256 ] "integer yresolution" [ 256 ] "string filename" "cornell-box.exr"',
           'PixelFilter "box"',
           'Sampler "independent" "integer pixelsamples" [ 64 ]',
           'Integrator "path" "integer maxdepth" [ 5 ]',
           "WorldBegin"]
    for name, rgb in MATERIALS.items():
        out.append(f'MakeNamedMaterial "{name}" "string type" "diffuse" "rgb reflectance" [ {fmt(rgb)} ]')
    for (pos, tris), m, emits, f in meshes:
        out.append(f"# {f}")
        out.append("AttributeBegin")
        out.append(f'  NamedMaterial "{m}"')
        if emits:
            out.append(f'  AreaLightSource "diffuse" "rgb L" [ {fmt(RADIANCE)} ]')
        out.append('  Shape "trianglemesh"')
        out.append(f'    "point3 P" [ {"  ".join(fmt(p) for p in pos)} ]')
        out.append(f'    "integer indices" [ {"  ".join(fmt(t) for t in tris)} ]')
        out.append("AttributeEnd")
    open(os.path.join(out_dir, "cornell-box.pbrt"), "w").write("\n".join(out) + "\n")

    # glTF 2.0: +y up, the camera looks down its -z, so it is turned half a turn about +y (its
    # +x, the image's right, becomes the world's -x, as in Mitsuba's picture).
    blob = bytearray()
    views, accessors, gmeshes, nodes = [], [], [], []
    for (pos, tris), m, emits, f in meshes:
        off = len(blob)
        for p in pos:
            blob += struct.pack("<3f", *p)
        views.append({"buffer": 0, "byteOffset": off, "byteLength": 12 * len(pos), "target": 34962})
        lo = [min(p[i] for p in pos) for i in range(3)]
        hi = [max(p[i] for p in pos) for i in range(3)]
        accessors.append({"bufferView": len(views) - 1, "componentType": 5126, "count": len(pos), "type": "VEC3",
                          "min": lo, "max": hi})
        off = len(blob)
        for t in tris:
            blob += struct.pack("<3I", *t)
        views.append({"buffer": 0, "byteOffset": off, "byteLength": 12 * len(tris), "target": 34963})
        accessors.append({"bufferView": len(views) - 1, "componentType": 5125, "count": 3 * len(tris), "type": "SCALAR"})
        mat = list(MATERIALS).index(m) + (len(MATERIALS) if emits else 0)
        gmeshes.append({"name": f[:-4], "primitives": [{"attributes": {"POSITION": len(accessors) - 2},
                                                         "indices": len(accessors) - 1, "material": mat}]})
        nodes.append({"name": f[:-4], "mesh": len(gmeshes) - 1})
    materials = []
    for emits in (False, True):
        for name, rgb in MATERIALS.items():
            if emits and name != "light":
                materials.append({"name": name + "-unused", "pbrMetallicRoughness": {"baseColorFactor": [*rgb, 1]}})
                continue
            # Lambertian: no metal, and KHR_materials_specular turns the dielectric coat off.
            mat = {"name": name + ("-emitter" if emits else ""),
                   "pbrMetallicRoughness": {"baseColorFactor": [*rgb, 1], "metallicFactor": 0, "roughnessFactor": 1},
                   "extensions": {"KHR_materials_specular": {"specularFactor": 0}}}
            if emits:
                peak = max(RADIANCE)
                mat["emissiveFactor"] = [c / peak for c in RADIANCE]
                mat["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": peak}
            materials.append(mat)
    nodes.append({"name": "camera", "camera": 0, "translation": [278, 273, -800], "rotation": [0, 1, 0, 0]})
    doc = {
        "asset": {"version": "2.0", "generator": "snell scenes/make-cornell-box.py"},
        "extensionsUsed": ["KHR_materials_specular", "KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": gmeshes,
        "materials": materials,
        "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(39.3077), "aspectRatio": 1.0,
                                                             "znear": 1.0}}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()}],
    }
    open(os.path.join(out_dir, "cornell-box.gltf"), "w").write(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "../../shared/scenes/cornell-box/meshes"), here)
