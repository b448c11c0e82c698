"""A demonstration played back in Meshcat and saved as a standalone HTML page.

The recorded joint positions ``q_100hz`` pose the Panda of the skill's
scenario plant (:func:`drake_skill.station.sim.builder.add_scene_plant`, what the
station simulates), the finger opening ``gripper_100hz`` its fingers (each at
half the opening), the object sits at ``X_WO_true`` with its joint at
``object_state_100hz``. Nothing is simulated: each sample is drawn by a
``ForcedPublish`` of the MeshcatVisualizer at the sample's time while Meshcat
records; ``Meshcat.StaticHtml()`` gives the page (as the learning loop's
``replay_first.html``). The object cloud is not drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drake_skill.demos.format import Demonstration

__all__ = ["joints_replay_html", "replay_html", "write_replay"]

#: Meshcat's recording rate (frames per second); the 100 Hz samples are thinned to about it.
FPS = 32.0


def replay_html(demo: Demonstration, station_config=None, meshcat=None) -> str:
    """The standalone Meshcat HTML of ``demo`` played back in its skill's scenario.

    station_config: the scenario (default: the skill's shipped one); meshcat:
    a Meshcat to record in (default: a new one, closed when this returns).
    """
    from drake_skill.skills import scenario_for_skill

    config = station_config if station_config is not None else scenario_for_skill(demo.skill)
    return joints_replay_html(config, demo.X_WO_true, demo.times_100hz - demo.times_100hz[0], demo.q_100hz,
                              demo.gripper_100hz, demo.object_state_100hz, meshcat)


def joints_replay_html(config, X_WO_true, times, q, gripper, object_state, meshcat=None) -> str:
    """The standalone Meshcat HTML of recorded joints on ``config``'s scenario plant (module docstring).

    X_WO_true: (7,) the object's pose (xyz m + wxyz); times (N,) [s]; q (N, 7) arm joint
    positions [rad]; gripper (N,) or a number: the finger opening [m]; object_state (N,)
    the object joint [rad or m]. meshcat: as :func:`replay_html`'s.
    """
    from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
    from pydrake.systems.framework import DiagramBuilder

    from drake_skill.common import frame_meshcat_camera, recorded_html
    from drake_skill.station.recording import vector_to_pose
    from drake_skill.station.sim.builder import add_scene_plant

    times = np.asarray(times, dtype=float)
    gripper = np.broadcast_to(np.asarray(gripper, dtype=float), times.shape)
    meshcat = meshcat if meshcat is not None else Meshcat()
    builder = DiagramBuilder()
    scene = add_scene_plant(builder, config)
    MeshcatVisualizer.AddToBuilder(builder, scene.scene_graph, meshcat,
                                   MeshcatVisualizerParams(role=Role.kIllustration))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant, plant_context = scene.plant, scene.plant.GetMyMutableContextFromRoot(context)
    X_WO = vector_to_pose(X_WO_true)
    plant.SetFreeBodyPose(plant_context, scene.object_base, X_WO)
    joint_index = scene.object_joint.position_start()     # the lid's hinge or the drawer's slide
    frame_meshcat_camera(meshcat, X_WO.translation())
    step = max(1, int(round(1.0 / (FPS * float(np.median(np.diff(times))))))) if times.size > 1 else 1
    samples = np.unique(np.append(np.arange(0, times.size, step), times.size - 1))
    def draw():
        for k in samples:
            context.SetTime(float(times[k]))
            plant.SetPositions(plant_context, scene.panda, q[k])
            plant.SetPositions(plant_context, scene.hand, np.full(2, 0.5 * gripper[k]))
            positions = plant.GetPositions(plant_context)
            positions[joint_index] = object_state[k]
            plant.SetPositions(plant_context, positions)
            diagram.ForcedPublish(context)

    return recorded_html(meshcat, draw, fps=FPS)[1]


def write_replay(demo: Demonstration, path, station_config=None, meshcat=None) -> Path:
    """Writes :func:`replay_html` of ``demo`` to ``path`` atomically."""
    from drake_skill.fileio import atomic_write_text

    return atomic_write_text(path, replay_html(demo, station_config, meshcat))
