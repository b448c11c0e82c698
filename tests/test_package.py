"""The wheel is a real package: built from the checkout, installed elsewhere, it
finds its Panda models and PCAE weights through ``importlib.resources``."""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent

# Run in the installed copy: loads the package's Panda into a MultibodyPlant and
# encodes a cloud with the package's PCAE weights.
_PROBE = """
import json, sys
import numpy as np
import drake_skill, drake_skill.models
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from drake_skill.perception.pcae import default_weights, load_pcae
from drake_skill.resources import models_dir
from drake_skill.station.models import add_package_paths, model_url

plant = MultibodyPlant(0.0)
parser = Parser(plant)
add_package_paths(parser.package_map())
arm = parser.AddModels(url=model_url("panda_arm.sdf"))[0]
hand = parser.AddModels(url=model_url("panda_hand.sdf"))[0]
plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0", arm))
plant.WeldFrames(plant.GetFrameByName("panda_link8", arm), plant.GetFrameByName("panda_hand", hand))
plant.Finalize()
cloud = np.load(sys.argv[1])
code = load_pcae().encode_points(cloud)
loaded = [m.__file__ for name, m in sys.modules.items()
          if name.startswith("drake_skill") and getattr(m, "__file__", None)]
print(json.dumps({"package": drake_skill.__file__, "models": str(models_dir()), "weights": str(default_weights()),
                  "loaded": loaded, "positions": plant.num_positions(),
                  "code": code.tolist()}))
"""


def _copy_source(dest: Path) -> None:
    """The files the build reads, so the build writes nothing into the checkout."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO / name, dest / name)
    for name in ("drake_skill", "models"):
        shutil.copytree(REPO / name, dest / name, ignore=ignore)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("wheel")
    (tmp / "src").mkdir()
    _copy_source(tmp / "src")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(tmp / "dist"), str(tmp / "src")], check=True, capture_output=True, timeout=120)
    (found,) = (tmp / "dist").glob("drake_skill-*.whl")
    return found


def test_wheel_holds_every_module_the_models_and_the_licence(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in (REPO / "drake_skill").rglob("*.py")
               if "__pycache__" not in p.parts}
    assert modules and modules <= names, sorted(modules - names)
    models = {f"drake_skill/models/{p.relative_to(REPO / 'models').as_posix()}"
              for p in (REPO / "models").rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert {"drake_skill/models/pcae.safetensors", "drake_skill/models/panda_arm.sdf",
            "drake_skill/models/package.xml"} <= models
    assert models <= names, sorted(models - names)
    assert {"drake_skill/station/scenarios/box_closed.yaml", "drake_skill/station/scenarios/slider.yaml",
            "drake_skill/skills/open.yaml", "drake_skill/skills/slide.yaml"} <= names
    (metadata,) = [n for n in names if n.endswith(".dist-info/METADATA")]
    meta = zipfile.ZipFile(wheel).read(metadata)
    assert b"License-Expression: BSD-3-Clause" in meta
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)


def test_installed_wheel_loads_the_panda_and_the_encoder(wheel, tmp_path):
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q", "--target", str(site),
                    str(wheel)], check=True, capture_output=True, timeout=120)
    cloud = np.random.default_rng(0).uniform(-0.1, 0.1, size=(2048, 3)).astype(np.float32)
    np.save(tmp_path / "cloud.npy", cloud)
    # -S: no site-packages processing, so no .pth runs (an editable install's finder
    # would map drake_skill to the checkout); the dependencies come from this
    # interpreter's path, less the checkout's own folders (its .venv, where make puts the
    # dependencies, stays).
    def in_checkout(p: Path) -> bool:
        return p.is_relative_to(REPO) and not p.is_relative_to(REPO / ".venv")

    deps = [p for p in sys.path if p and Path(p).is_dir() and not in_checkout(Path(p).resolve())]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DRAKE_SKILL_MODELS")}
    env["PYTHONPATH"] = os.pathsep.join([str(site), *deps])
    result = subprocess.run([sys.executable, "-S", "-c", _PROBE, str(tmp_path / "cloud.npy")], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert Path(out["package"]).is_relative_to(site)
    assert all(Path(f).is_relative_to(site) for f in out["loaded"]), out["loaded"]
    assert Path(out["models"]) == site / "drake_skill" / "models"
    assert Path(out["weights"]) == site / "drake_skill" / "models" / "pcae.safetensors"
    assert out["positions"] == 9  # 7 arm joints + 2 fingers
    # The same code as the checkout's weights give.
    from drake_skill.perception.pcae import load_pcae

    expected = load_pcae(REPO / "models" / "pcae.safetensors").encode_points(cloud)
    code = np.array(out["code"])
    assert code.shape == (128,) and np.all(np.isfinite(code))
    np.testing.assert_allclose(code, expected, rtol=1e-5, atol=1e-6)


def test_models_folder_override_must_hold_package_xml(tmp_path, monkeypatch):
    from drake_skill.resources import models_dir

    assert (models_dir() / "package.xml").is_file()
    monkeypatch.setenv("DRAKE_SKILL_MODELS", str(tmp_path))
    with pytest.raises(FileNotFoundError, match=f"DRAKE_SKILL_MODELS={tmp_path} has no package.xml"):
        models_dir()
    (tmp_path / "package.xml").write_text("<package/>")
    assert models_dir() == tmp_path
