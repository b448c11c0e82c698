"""The package layout's rules: every box's math imports without Drake."""

import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "drake_skill"
#: Boxes whose modules are Drake-free math, except the Drake side named below.
MATH_BOXES = ("action", "perception", "reward", "learning")
#: The Drake side of a box: ``systems`` (its LeafSystems and diagram wiring);
#: in ``learning``, the rollout runner and its workers, which simulate the diagram.
DRAKE_SIDE = ("systems", "rollout", "workers")
#: Drake-free modules outside the boxes.
MATH_MODULES = ("drake_skill.common", "drake_skill.typed_yaml", "drake_skill.fileio", "drake_skill.resources")

# Makes ``import pydrake`` (and any submodule) fail, then imports the module.
_PROBE = """
import importlib, sys
class _NoDrake:
    def find_spec(self, name, path=None, target=None):
        if name == "pydrake" or name.startswith("pydrake."):
            raise ImportError(f"pydrake is made unimportable for this test ({name})")
        return None
sys.meta_path.insert(0, _NoDrake())
importlib.import_module(sys.argv[1])
assert not any(m == "pydrake" or m.startswith("pydrake.") for m in sys.modules), "pydrake got imported"
"""


def math_modules() -> list[str]:
    names = list(MATH_MODULES)
    for box in MATH_BOXES:
        names.append(f"drake_skill.{box}")
        for path in sorted((PACKAGE / box).rglob("*.py")):
            if path.stem not in ("__init__",) + DRAKE_SIDE:
                names.append(".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts))
            elif path.stem == "__init__" and path.parent != PACKAGE / box:      # a package inside the box
                names.append(".".join(path.parent.relative_to(PACKAGE.parent).parts))
    return names


def test_every_box_has_the_same_convention():
    for box in MATH_BOXES:
        assert (PACKAGE / box / "__init__.py").exists(), box
    for box in ("action", "perception", "reward"):
        assert (PACKAGE / box / "systems.py").exists(), f"{box}/systems.py holds the box's LeafSystems"


def test_the_probe_really_blocks_pydrake():
    result = subprocess.run([sys.executable, "-c", _PROBE, "drake_skill.action.systems"],
                            capture_output=True, text=True)
    assert result.returncode != 0 and "unimportable" in result.stderr


@pytest.mark.parametrize("module", math_modules())
def test_math_module_imports_without_pydrake(module):
    result = subprocess.run([sys.executable, "-c", _PROBE, module], capture_output=True, text=True)
    assert result.returncode == 0, f"{module} needs pydrake:\n{result.stderr[-2000:]}"


def _station_imports(folder: str) -> dict[str, set[str]]:
    """{module file: the drake_skill.station modules it imports} for station/FOLDER/*.py."""
    import ast

    found = {}
    for path in sorted((PACKAGE / "station" / folder).glob("*.py")):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
                names.update(f"{node.module}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        found[path.name] = {n for n in names if n.startswith("drake_skill.station")}
    return found


def test_hardware_and_simulation_stations_stand_apart():
    """station/hardware never imports station/sim: the hardware port runs without the
    simulated station; both build on the shared station modules (issue 29 item 6)."""
    hardware = _station_imports("hardware")
    assert "station.py" in hardware
    for name, imported in hardware.items():
        assert not any(m.startswith("drake_skill.station.sim") for m in imported), (name, imported)
    simulated = _station_imports("sim")
    assert {"builder.py", "simulation.py", "lcm_robot.py"} <= set(simulated)
    # Neither needs the hardware port: the driver's channels are the scenario's (station.drivers),
    # and the simulated robot builds its own station through the one factory.
    for name in ("builder.py", "simulation.py", "lcm_robot.py"):
        assert not any(m.startswith("drake_skill.station.hardware") for m in simulated[name]), name
    assert "drake_skill.station.make" in simulated["lcm_robot.py"]


def _imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at the top or inside a function (``from X import y``: X and X.y);
    not what an ``if TYPE_CHECKING:`` block imports for annotations."""
    import ast

    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING":
            node.body = []
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_nothing_outside_the_commands_imports_them():
    """The library never calls its CLI (issue 46 item 6): the workflows live in the library
    (``drake_skill.workflow``, ``drake_skill.inputs``) and the commands parse flags into them."""
    offenders = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if (PACKAGE / "cli") in path.parents:
            continue
        cli = sorted(m for m in _imported_modules(path) if m == "drake_skill.cli" or m.startswith("drake_skill.cli."))
        if cli:
            offenders[str(path.relative_to(PACKAGE))] = cli
    assert offenders == {}
    # The probe sees function-local imports (where the grid once imported drake-skill learn's code).
    assert "drake_skill.workflow.prepare" in _imported_modules(PACKAGE / "experiments" / "grid.py")



def _module_graph() -> dict[str, set[str]]:
    """drake_skill's modules and the package modules each imports (a package's ``__init__`` as the package)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        targets = set()
        for imported in _imported_modules(path):
            while imported and imported not in modules:
                imported = imported.rpartition(".")[0]
            if imported and imported != name:
                targets.add(imported)
        graph[name] = targets
    return graph


def test_no_import_cycles_counting_function_local_imports():
    """Issue 46 item 6: the modules form layers; a function-local import does not hide a cycle."""
    graph = _module_graph()
    cycles, index, low, stack, on_stack = [], {}, {}, [], set()

    def visit(v):                                     # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while not component or v not in component:
                component.add(stack.pop())
            on_stack.difference_update(component)
            if len(component) > 1:
                cycles.append({m: sorted(graph[m] & component) for m in sorted(component)})

    for module in sorted(graph):
        if module not in index:
            visit(module)
    assert cycles == []
    # The probe follows function-local imports: scenarios of skills come from skills, not the station.
    assert "drake_skill.skills" in graph["drake_skill.workflow.prepare"]
    assert "drake_skill.skills" not in graph["drake_skill.station.scenario"]


#: The package's layers, lowest first: a module imports only from its own layer or below.
LAYERS = (
    ("drake_skill", "common", "typed_yaml", "fileio", "resources"),   # Drake-free foundations
    ("action",),                  # the DMP (math | DmpSystem)
    ("perception",),              # segmenter, PCAE, features (math | systems)
    ("reward", "station"),        # goal model and POMRP; the station (sim and hardware)
    ("skills",),                  # skill files and scenarios as data
    ("inputs", "demos", "fitted_skill"),  # input checks; demonstrations; a fitted skill
    ("learning",),                # rollouts, policy search, the learning run, evaluation
    ("workflow", "bench"),        # the commands' workflows; benchmarks
    ("experiments",),             # the chapter-7 grid
    ("cli",),                     # the commands
)


def test_every_import_goes_down_the_layers():
    """Issue 46 item 6: the layer order (docs/architecture.md), function-local imports included."""
    layer = {box: i for i, boxes in enumerate(LAYERS) for box in boxes}
    graph = _module_graph()
    boxes = {m.split(".")[1] if "." in m else "drake_skill" for m in graph}
    assert boxes <= set(layer), f"a box with no layer: {sorted(boxes - set(layer))}"

    def box(module):
        return module.split(".")[1] if "." in module else "drake_skill"

    upward = sorted(f"{a} -> {b}" for a, targets in graph.items() for b in targets if layer[box(b)] > layer[box(a)])
    assert upward == []
