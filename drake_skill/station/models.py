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
           "instance_directives", "model_url", "models_dir", "panda_illustration_table", "process_directives"]

PACKAGE_NAME = "drake_skill_models"
"""The Drake (package.xml) package name of the models folder."""


def model_url(filename: str) -> str:
    return f"package://{PACKAGE_NAME}/{filename}"


def url_path(url: str) -> Path | None:
    """The local file a ``package://drake_skill_models/...`` or ``file://...`` URL names; None for
    another scheme."""
    prefix = model_url("")
    if url.startswith(prefix):
        return models_dir() / url[len(prefix):]
    if url.startswith("file://"):
        return Path(url[len("file://"):])
    return None


def add_package_paths(package_map) -> None:
    """Registers ``drake_skill_models`` in a Drake PackageMap (idempotent)."""
    if not package_map.Contains(PACKAGE_NAME):
        package_map.Add(PACKAGE_NAME, str(models_dir()))


def _directive_text(directive) -> str:
    """``add_weld {parent: A, child: B}``: the directive as a user wrote it, short."""
    for kind in ("add_model", "add_weld", "add_frame", "add_model_instance", "add_directives",
                 "add_collision_filter_group"):
        body = getattr(directive, kind, None)
        if body is not None:
            fields = [f"{name}: {getattr(body, name)}" for name in ("name", "parent", "child", "file")
                      if isinstance(getattr(body, name, None), str)]
            return f"{kind} {{{', '.join(fields)}}}"
    return "a directive"


def _short_reason(message: str, directive) -> str:
    """Drake's reason in one line; for a frame no model has, only the valid frames of the model named."""
    import re

    message = " ".join(message.split())
    missing = re.search(r"There is no Frame named '([^']*)'", message)
    if missing is None:
        return message[:300]
    scoped = [getattr(getattr(directive, "add_weld", None), name, "") or "" for name in ("parent", "child")] \
        if directive is not None else []
    model = next((n.split("::")[0] for n in scoped if n.endswith("::" + missing[1])), None)
    frames = re.search(rf"valid names in model instance '{re.escape(model)}' are: ([^;)]*)", message) if model else None
    return (f"no frame '{missing[1]}' in model '{model}'" + (f" (its frames: {frames[1]})" if frames else "")
            if model else message[:300])


def _culprit(directives, message: str):
    """(index, directive) that Drake's ``message`` is about: the weld or frame naming the frame it
    could not find, or the model whose file it names; (None, None) when it does not say."""
    import re

    missing = re.search(r"There is no Frame named '([^']*)'", message)
    no_model = re.search(r"There is no model instance named '([^']*)'", message)
    for i, directive in enumerate(directives):
        for kind in ("add_weld", "add_frame"):
            body = getattr(directive, kind, None)
            names = [getattr(body, n, None) for n in ("parent", "child", "name")] if body is not None else []
            names += [getattr(getattr(body, "X_PF", None), "base_frame", None)] if kind == "add_frame" else []
            names = [n for n in names if isinstance(n, str)]
            if missing and any(n.split("::")[-1] == missing[1] for n in names):
                return i, directive
            if no_model and any(n.split("::")[0] == no_model[1] for n in names if "::" in n):
                return i, directive
        model = getattr(directive, "add_model", None)
        if model is not None and model.file and model.file.split("/")[-1] in message:
            return i, directive
    return None, None


def process_directives(directives, plant, parser) -> None:
    """Drake's ``ProcessModelDirectives``; a failure (a frame no model has, a model file that does
    not parse) is a one-line ValueError naming the directive: ``scenario directives[i] (add_weld
    {...}): <Drake's reason, short>; fix that directive`` instead of Drake's RuntimeError.
    (Processed as one list: directive by directive, Drake 1.51 aborts on a missing weld frame.)"""
    from pydrake.multibody.parsing import ModelDirectives, ProcessModelDirectives

    try:
        ProcessModelDirectives(ModelDirectives(directives=list(directives)), plant, parser)
    except RuntimeError as e:
        i, directive = _culprit(directives, " ".join(str(e).split()))
        where = f"scenario directives[{i}] ({_directive_text(directive)})" if directive is not None \
            else "scenario directives"
        raise ValueError(f"{where}: {_short_reason(str(e), directive)}; fix that directive") from None


ROBOT_FILE = "panda_robot.dmd.yaml"
"""The robot's model directives (the arm and its hand; models folder): the one definition."""
WORKCELL_FILE = "workcell.dmd.yaml"
"""The workcell's model directives (models folder): ``ROBOT_FILE`` and the table welded on the
world origin, the one definition of both; every shipped scenario includes it, then adds its object."""


def instance_directives(directives, instances) -> list:
    """The directives of ``directives`` (a scenario's, ``add_directives`` included: flattened with
    Drake's ``FlattenModelDirectives``) that add or weld the model instances ``instances``, as the
    ``manipulation`` repository's ``MakeMultibodyPlant(scenario, model_instance_names)`` keeps a
    scenario's: a controller's plant of the arm alone takes ``("panda",)``. A weld is kept when its
    child is one of them."""
    from pydrake.multibody.parsing import FlattenModelDirectives, ModelDirectives, PackageMap

    package_map = PackageMap()
    add_package_paths(package_map)
    flat = FlattenModelDirectives(ModelDirectives(directives=list(directives)), package_map).directives
    kept = []
    for d in flat:
        name = (d.add_model.name if d.add_model is not None else
                d.add_weld.child.split("::")[0] if d.add_weld is not None else None)
        if name in instances:
            kept.append(d)
    missing = set(instances) - {d.add_model.name for d in kept if d.add_model is not None}
    if missing:
        raise ValueError(f"the directives add no model instance named {', '.join(sorted(missing))}")
    return kept


def robot_directives(instances=("panda", "panda_hand")) -> list:
    """``ROBOT_FILE``'s directives that add or weld the model instances ``instances``
    (:func:`instance_directives` of the robot's own file)."""
    from pydrake.multibody.parsing import LoadModelDirectives

    return instance_directives(LoadModelDirectives(str(model_path(ROBOT_FILE))).directives, instances)


def hand_mount(directives=None):
    """X_FH, the hand's pose on the flange (``panda_link8``): the weld of ``panda_hand::panda_hand``
    in ``directives`` (a scenario's; default ``ROBOT_FILE``'s), the one place it is written."""
    kept = robot_directives() if directives is None else instance_directives(directives, ("panda_hand",))
    (weld,) = [d.add_weld for d in kept if d.add_weld is not None and d.add_weld.child == "panda_hand::panda_hand"]
    return weld.X_PC.GetDeterministicValue()


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
