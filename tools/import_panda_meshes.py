#!/usr/bin/env python3
"""Writes ``models/franka_panda/``: Franka's visual meshes of the Panda, for Meshcat.

The meshes come from the ``example-robot-data`` wheel on PyPI, whose
``robots/panda_description`` is Franka's ``franka_description`` (franka_ros),
Apache-2.0. Drake's Meshcat draws ``.obj`` and embedded ``.gltf`` files, not
COLLADA, so every ``meshes/visual/*.dae`` is converted to an embedded
``.gltf`` (y-up, as glTF specifies): each part keeps its base colour (white,
dark grey) and its placement, and is decimated to ``--keep`` of its triangles (quadric
decimation) so that the set stays small enough for the repository and the
Meshcat replays that embed it. The licence is copied beside the meshes, with a
README stating the source, the version and the changes (Apache-2.0 section 4).

This runs once, by hand, when the meshes change; the output is committed.
Nothing is downloaded at run time. It needs the ``meshes`` extra
(``pip install -e '.[meshes]'``: trimesh, pycollada, fast-simplification)
and the example-robot-data wheel, which it reads as a zip file:

    pip download --no-deps example-robot-data==6.0.0 -d /tmp/erd
    python tools/import_panda_meshes.py /tmp/erd/example_robot_data-6.0.0-0-py3-none-any.whl
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

MESHES = ("link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand", "finger")
PREFIX = "robots/panda_description/"


def _members(wheel: zipfile.ZipFile) -> dict[str, str]:
    """Name -> archive path of the panda_description files the tool reads."""
    out = {}
    for name in wheel.namelist():
        if PREFIX not in name:
            continue
        rest = name.split(PREFIX, 1)[1]
        if rest == "LICENSE" or rest.startswith("meshes/visual/") and rest.endswith(".dae"):
            out[rest] = name
    return out


def convert(dae: bytes, keep: float) -> bytes:
    """One COLLADA file -> an embedded glTF (bytes): parts placed, base colours kept, decimated to ``keep``."""
    import trimesh
    from trimesh.exchange.gltf import export_gltf
    from trimesh.visual.material import PBRMaterial

    scene = trimesh.load(io.BytesIO(dae), file_type="dae")
    # glTF is y-up; Drake (and Meshcat, which rotates a glTF scene by +90 deg
    # about x) read a glTF's (x, y, z) as the body frame's (x, -z, y).
    z_up_to_y_up = trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0])
    out = trimesh.Scene()
    for node in sorted(scene.graph.nodes_geometry):
        transform, name = scene.graph[node]
        part = scene.geometry[name].copy()
        color = getattr(part.visual.material, "baseColorFactor", None)
        color = np.array([200, 200, 200, 255] if color is None else color, dtype=np.uint8)
        part.apply_transform(z_up_to_y_up @ transform)
        part.merge_vertices()  # COLLADA repeats vertices per face; decimation needs them shared
        if len(part.faces) > 400:
            part = part.simplify_quadric_decimation(face_count=max(int(len(part.faces) * keep), 100))
        part.visual = trimesh.visual.TextureVisuals(
            material=PBRMaterial(baseColorFactor=color, metallicFactor=0.0, roughnessFactor=0.6))
        out.add_geometry(part, geom_name=f"{node}")
    (data,) = export_gltf(out, embed_buffers=True).values()
    gltf = json.loads(data)
    gltf["asset"]["copyright"] = ("From Franka Emika's franka_description (franka_ros), Apache-2.0 (LICENSE); "
                                  "converted from COLLADA and decimated by drake-skill")
    return json.dumps(gltf, separators=(",", ":")).encode()


README = """\
# Franka Panda visual meshes (Meshcat only)

Franka Emika's visual meshes of the Panda arm and hand, from
`franka_description` (franka_ros), licensed under the Apache License 2.0
(`LICENSE` in this folder). Taken from the PyPI wheel `{wheel}` (the
`example-robot-data` package, `robots/panda_description/meshes/visual/`).

Changes (Apache-2.0 section 4(b)): each COLLADA file was converted to an
embedded glTF with its parts' placement and base colours, and decimated to
{keep_pct:.0f} % of its triangles, by `tools/import_panda_meshes.py`.

drake-skill gives these meshes the illustration role only (what Meshcat
draws); the camera renders the model's own simple shapes and contact uses
its capsules (`panda_illustration.yaml`, `drake_skill.station.models`).
"""


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("wheel", type=Path, help="the example-robot-data wheel (.whl)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: the models package's franka_panda/)")
    p.add_argument("--keep", type=float, default=0.25, help="fraction of each part's triangles kept (0, 1]")
    args = p.parse_args()
    if not 0.0 < args.keep <= 1.0:
        print(f"--keep: expected a fraction in (0, 1], got {args.keep}", file=sys.stderr)
        return 2
    if not args.wheel.is_file():
        print(f"{args.wheel}: no such wheel; get it with `pip download --no-deps example-robot-data -d DIR`",
              file=sys.stderr)
        return 2
    if args.out is None:
        from drake_skill.resources import models_dir

        args.out = models_dir() / "franka_panda"
    with zipfile.ZipFile(args.wheel) as wheel:
        members = _members(wheel)
        wanted = ["LICENSE"] + [f"meshes/visual/{m}.dae" for m in MESHES]
        missing = [w for w in wanted if w not in members]
        if missing:
            print(f"{args.wheel}: no {PREFIX}{missing[0]} (is it the example-robot-data wheel?)", file=sys.stderr)
            return 2
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "LICENSE").write_bytes(wheel.read(members["LICENSE"]))
        for mesh in MESHES:
            data = convert(wheel.read(members[f"meshes/visual/{mesh}.dae"]), args.keep)
            (args.out / f"{mesh}.gltf").write_bytes(data)
            print(f"wrote {args.out / mesh}.gltf ({len(data) // 1024} KiB)")
    (args.out / "README.md").write_text(README.format(wheel=args.wheel.name, keep_pct=100 * args.keep))
    print(f"wrote {args.out / 'LICENSE'}, {args.out / 'README.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
