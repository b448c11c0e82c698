"""The end-effector controller: hand pose in, joint position commands out.

Drake's ``DifferentialInverseKinematicsIntegrator`` solves, every period, the
QP of differential IK (min ||J v - V_WE_desired||, subject to joint position
and velocity limits) and integrates the joint velocities; a discrete
derivative then turns the joint positions into the desired state [q, v] that
the Panda's joint impedance controller tracks.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsIntegrator,
    DifferentialInverseKinematicsParameters,
)
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import StateInterpolatorWithDiscreteDerivative

from drake_skill.station.models import add_package_paths, model_url
from drake_skill.station.config import ControllerConfig

# Hand frame H is the flange turned -45 degrees about z (Franka Hand mounting);
# the tool centre point E (the "hand pose" everywhere in drake-skill) is
# 0.1034 m along z_H, between the fingertips.
X_FLANGE_HAND = RigidTransform(RotationMatrix.MakeZRotation(-np.pi / 4))
X_HAND_TCP = RigidTransform([0.0, 0.0, 0.1034])

# Franka's published joint velocity limits [rad/s].
PANDA_QD_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])


def make_control_plant() -> MultibodyPlant:
    """A 7-DoF kinematic model of the arm with the TCP frame named ``ee``."""
    plant = MultibodyPlant(time_step=0.0)
    parser = Parser(plant)
    add_package_paths(parser.package_map())
    parser.AddModels(url=model_url("panda_arm.sdf"))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    plant.AddFrame(FixedOffsetFrame("ee", plant.GetFrameByName("panda_link8"),
                                    X_FLANGE_HAND @ X_HAND_TCP))
    plant.Finalize()
    return plant


class EndEffectorController(Diagram):
    """Input ``X_WE_desired`` (RigidTransform), output ``panda_state_desired`` (14).

    Joint limits are Franka's, shrunk by a 0.05 rad margin; velocity limits are
    Franka's scaled by ``config.velocity_scale``; the hand's translational
    speed is limited to ``config.ee_speed_max`` m/s.
    """

    def __init__(self, config: ControllerConfig, q_home):
        super().__init__()
        builder = DiagramBuilder()
        self.control_plant = make_control_plant()
        plant = self.control_plant
        q_home = np.asarray(q_home, dtype=float)
        # The integrator's default state is the positions in this context.
        plant.SetDefaultPositions(q_home)
        context = plant.CreateDefaultContext()

        params = DifferentialInverseKinematicsParameters(plant.num_positions(), plant.num_velocities())
        params.set_time_step(config.diff_ik_period)
        margin = 0.05
        params.set_joint_position_limits((plant.GetPositionLowerLimits() + margin,
                                          plant.GetPositionUpperLimits() - margin))
        qd = PANDA_QD_MAX * config.velocity_scale
        params.set_joint_velocity_limits((-qd, qd))
        v = config.ee_speed_max
        params.set_end_effector_translational_velocity_limits([-v] * 3, [v] * 3)
        params.set_end_effector_angular_speed_limit(2.0)
        params.set_nominal_joint_position(q_home)
        params.set_joint_centering_gain(config.joint_centering_gain * np.eye(7))

        self._diff_ik = builder.AddNamedSystem("diff_ik", DifferentialInverseKinematicsIntegrator(
            plant, plant.world_frame(), plant.GetFrameByName("ee"), config.diff_ik_period, params, context, True))
        interp = builder.AddNamedSystem("desired_state", StateInterpolatorWithDiscreteDerivative(
            7, config.diff_ik_period, suppress_initial_transient=True))
        builder.Connect(self._diff_ik.GetOutputPort("joint_positions"), interp.get_input_port())
        builder.ExportInput(self._diff_ik.GetInputPort("X_AE_desired"), "X_WE_desired")
        builder.ExportOutput(interp.get_output_port(), "panda_state_desired")
        builder.BuildInto(self)
        self._interp = interp
        self._q_home = q_home

    def set_joint_positions(self, context, q) -> None:
        """Resets the integrator (and the derivative filter) to joint positions q."""
        q = np.asarray(q, dtype=float)
        self._diff_ik.SetPositions(self._diff_ik.GetMyMutableContextFromRoot(context), q)
        self._interp.set_initial_position(self._interp.GetMyMutableContextFromRoot(context), q)
