"""Meshcat's Panda wears Franka's visual meshes (illustration role only); the
camera's and the contact's geometry of the Panda stay the model's own."""

import base64
import json
import re

import numpy as np
import pytest
from pydrake.geometry import Mesh, Meshcat, Role
from pydrake.math import RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_skill.station.sim.builder import add_scene_plant
from drake_skill.skills import scenario_for_skill
from drake_skill.station.models import add_package_paths, model_url, panda_illustration_table


def _geometries(plant, scene_graph, role):
    """Panda body name -> sorted [(geometry name, shape type, X_BG as a rounded tuple)] with ``role``."""
    inspector = scene_graph.model_inspector()
    out = {}
    for b in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(b))
        if not body.name().startswith("panda_"):
            continue
        frame = plant.GetBodyFrameIdOrThrow(body.index())
        out[body.name()] = sorted(
            (inspector.GetName(g), type(inspector.GetShape(g)).__name__,
             tuple(np.round(inspector.GetPoseInFrame(g).GetAsMatrix34().ravel(), 9)))
            for g in inspector.GetGeometries(frame, role))
    return out


@pytest.fixture(scope="module")
def station_plant():
    builder = DiagramBuilder()
    scene = add_scene_plant(builder, scenario_for_skill("open"))
    return scene.plant, scene.scene_graph


@pytest.fixture(scope="module")
def sdf_plant():
    """The Panda as its SDF files declare it, with nothing added."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    parser.AddModels(url=model_url("panda_arm.sdf"))
    parser.AddModels(url=model_url("panda_hand.sdf"))
    plant.Finalize()
    return plant, scene_graph


def test_illustration_of_every_panda_body_is_franka_meshes(station_plant):
    plant, scene_graph = station_plant
    table = panda_illustration_table()
    assert len(table) == 11  # links 0-7, hand, two fingers
    illustration = _geometries(plant, scene_graph, Role.kIllustration)
    inspector = scene_graph.model_inspector()
    for body, entries in table.items():
        shapes = illustration[body]
        assert len(shapes) == len(entries), body
        assert all(kind == "Mesh" for _, kind, _ in shapes), (body, shapes)
    for body, shapes in illustration.items():  # no Panda body keeps a primitive for Meshcat
        assert all(kind == "Mesh" for _, kind, _ in shapes), (body, shapes)
    meshes = [g for g in inspector.GetAllGeometryIds(Role.kIllustration)
              if isinstance(inspector.GetShape(g), Mesh) and "franka_visual" in inspector.GetName(g)]
    assert len(meshes) == 11
    for g in meshes:
        assert inspector.GetShape(g).extension() == ".gltf"
        assert inspector.GetPerceptionProperties(g) is None and inspector.GetProximityProperties(g) is None


def test_perception_and_proximity_of_the_panda_are_the_sdf_files(station_plant, sdf_plant):
    plant, scene_graph = station_plant
    ref_plant, ref_scene_graph = sdf_plant
    for role in (Role.kPerception, Role.kProximity):
        got = _geometries(plant, scene_graph, role)
        expected = _geometries(ref_plant, ref_scene_graph, role)
        assert got == expected, role
        assert sum(len(v) for v in expected.values()) > 10, role  # the comparison compares something
        assert not any(kind == "Mesh" and "franka" in name for v in got.values() for name, kind, _ in v)


def _gltf_box_in_body_frame(path, rpy):
    """Bounds of the glTF's vertex positions, read as Drake reads glTF (y-up -> the body's z-up), turned by rpy."""
    gltf = json.loads(path.read_text())
    positions = [gltf["accessors"][p["attributes"]["POSITION"]] for m in gltf["meshes"] for p in m["primitives"]]
    lo, hi = np.min([a["min"] for a in positions], axis=0), np.max([a["max"] for a in positions], axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    z_up = np.column_stack([corners[:, 0], -corners[:, 2], corners[:, 1]])
    pts = z_up @ RollPitchYaw(*rpy).ToRotationMatrix().matrix().T
    return pts.min(axis=0), pts.max(axis=0)


def test_each_mesh_sits_on_its_body(sdf_plant):
    """Every collision shape's centre lies inside its body's mesh bounds (3 cm slack): the
    meshes are on the right bodies and the right way up (read z-up, as the raw file
    coordinates, link1's and link5's meshes miss their capsules by 5-20 cm)."""
    plant, scene_graph = sdf_plant
    inspector = scene_graph.model_inspector()
    checked = 0
    for body_name, entries in panda_illustration_table().items():
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for path, rpy in entries:
            a, b = _gltf_box_in_body_frame(path, rpy)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        assert np.all(hi - lo > 0.02), (body_name, lo, hi)
        frame = plant.GetBodyFrameIdOrThrow(plant.GetBodyByName(body_name).index())
        for g in inspector.GetGeometries(frame, Role.kProximity):
            p = inspector.GetPoseInFrame(g).translation()
            # 3 cm of slack: link7's capsule centre sits 2.7 cm below Franka's mesh.
            assert np.all(p >= lo - 0.03) and np.all(p <= hi + 0.03), (body_name, inspector.GetName(g), p, lo, hi)
            checked += 1
    assert checked >= 11


def test_meshcat_receives_the_franka_meshes():
    """The station drawn in Meshcat: the page holds the glTF files' bytes."""
    from drake_skill.station.make import make_station

    meshcat = Meshcat()
    station = make_station(_no_camera(), meshcat=meshcat)
    Simulator(station).Initialize()  # MeshcatVisualizer sends the scene on initialisation
    assert meshcat.HasPath("/drake/visualizer/panda/panda_link1")
    # Every glTF the import tool writes names its source in asset.copyright;
    # the page's set_object commands carry those files' bytes.
    assert _gltf_objects(meshcat.StaticHtml()) == 11


def _no_camera():
    config = scenario_for_skill("open")
    config.enable_camera = False
    return config


def _gltf_objects(html: str) -> int:
    """How many of the static page's (base64, msgpack'd) Meshcat commands carry one of Franka's glTF files."""
    chunks = [base64.b64decode(c) for c in re.findall(r"base64,([A-Za-z0-9+/=]+)", html)]
    return sum(b"franka_description" in c and b'"asset"' in c for c in chunks)


def test_a_table_naming_a_missing_mesh_is_refused(tmp_path, monkeypatch):
    (tmp_path / "franka_panda").mkdir()
    (tmp_path / "package.xml").write_text("<package/>")
    (tmp_path / "franka_panda" / "panda_illustration.yaml").write_text("panda_link0: [{mesh: nowhere.gltf}]\n")
    monkeypatch.setenv("DRAKE_SKILL_MODELS", str(tmp_path))
    with pytest.raises(ValueError, match=r"panda_illustration.yaml: panda_link0: .*nowhere.gltf"):
        panda_illustration_table()
