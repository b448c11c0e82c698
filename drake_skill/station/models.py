"""The Drake package map for drake-skill's model files.

The models folder is the installed package ``drake_skill.models``
(``drake_skill.resources.models_dir``, found with ``importlib.resources``).
For Drake it is the package ``drake_skill_models``, so SDF files are
addressed as ``package://drake_skill_models/<file>``. ``DRAKE_SKILL_MODELS``
overrides the folder.

Meshcat draws the Panda with Franka's visual meshes (``franka_panda/``,
Apache-2.0, from the ``example-robot-data`` wheel on PyPI, converted by
``tools/import_panda_meshes.py``): ``add_panda_illustration`` gives them the
illustration role only, so the camera (perception role) and contact
(proximity role) see the model's own simple geometry, unchanged.
"""

from __future__ import annotations

from pathlib import Path

from drake_skill.resources import model_path, models_dir

__all__ = ["PACKAGE_NAME", "PANDA_ILLUSTRATION", "add_package_paths", "add_panda_illustration", "model_path",
           "model_url", "models_dir", "panda_illustration_table"]

PACKAGE_NAME = "drake_skill_models"
"""The Drake (package.xml) package name of the models folder."""


def model_url(filename: str) -> str:
    return f"package://{PACKAGE_NAME}/{filename}"


def add_package_paths(package_map) -> None:
    """Registers ``drake_skill_models`` in a Drake PackageMap (idempotent)."""
    if not package_map.Contains(PACKAGE_NAME):
        package_map.Add(PACKAGE_NAME, str(models_dir()))


PANDA_ILLUSTRATION = "franka_panda/panda_illustration.yaml"
"""The table of Franka's visual meshes per Panda body (in the models folder)."""


def panda_illustration_table() -> dict[str, list[tuple[Path, tuple[float, float, float]]]]:
    """Body name -> [(mesh file, rpy [rad] of the mesh in the body frame)], from ``PANDA_ILLUSTRATION``.

    Raises ValueError naming the file and the entry when the table is malformed
    or names a mesh that is not there.
    """
    import yaml

    path = model_path(PANDA_ILLUSTRATION)
    table = yaml.safe_load(path.read_text())
    if not isinstance(table, dict) or not table:
        raise ValueError(f"{path}: expected a mapping of Panda body name -> list of {{mesh, rpy}}")
    out = {}
    for body, entries in table.items():
        if not isinstance(entries, list) or not entries:
            raise ValueError(f"{path}: {body}: expected a list of {{mesh: FILE, rpy: [r, p, y]}}")
        out[body] = []
        for entry in entries:
            mesh = path.parent / str(entry.get("mesh", "")) if isinstance(entry, dict) else None
            if mesh is None or not mesh.is_file() or set(entry) - {"mesh", "rpy"}:
                raise ValueError(f"{path}: {body}: {entry!r} is not {{mesh: FILE, rpy: [r, p, y]}} "
                                 "with FILE beside the table")
            rpy = entry.get("rpy", [0.0, 0.0, 0.0])
            if not (isinstance(rpy, list) and len(rpy) == 3):
                raise ValueError(f"{path}: {body}: rpy {rpy!r}: expected three angles [rad]")
            out[body].append((mesh, tuple(float(a) for a in rpy)))
    return out


def add_panda_illustration(plant, scene_graph, model_instances) -> list:
    """Meshcat's Panda: Franka's visual meshes on the bodies of ``model_instances``.

    For every body of the instances (the arm and the hand) that
    ``PANDA_ILLUSTRATION`` names, the SDF's visual geometries lose their
    illustration role and keep their perception role (the camera still renders
    the model's simple shapes, and contact its capsules), and the table's
    meshes are registered with the illustration role only. Call before
    ``plant.Finalize()``. Returns the new geometries' ids.
    """
    from pydrake.geometry import GeometryInstance, IllustrationProperties, Mesh, Role
    from pydrake.math import RigidTransform, RollPitchYaw

    table = panda_illustration_table()
    inspector = scene_graph.model_inspector()
    source = plant.get_source_id()
    added = []
    for instance in model_instances:
        for body_index in plant.GetBodyIndices(instance):
            body = plant.get_body(body_index)
            if body.name() not in table:
                continue
            frame = plant.GetBodyFrameIdOrThrow(body_index)
            for gid in inspector.GetGeometries(frame, Role.kIllustration):
                scene_graph.RemoveRole(source, gid, Role.kIllustration)
            for i, (mesh, rpy) in enumerate(table[body.name()]):
                geometry = GeometryInstance(RigidTransform(RollPitchYaw(*rpy), [0.0, 0.0, 0.0]), Mesh(str(mesh)),
                                            f"{body.name()}_franka_visual_{i}")
                geometry.set_illustration_properties(IllustrationProperties())
                added.append(plant.RegisterVisualGeometry(body, geometry))
    return added
