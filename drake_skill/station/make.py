"""``make_station``: the one factory of a station, simulated or on the robot.

The pattern of the ``manipulation`` repository's ``MakeHardwareStation(scenario,
meshcat, hardware=False)``: one scenario (``Scenario``) describes the
models, the object, the cameras and the arm's ``driver``; ``hardware``
chooses between the simulated station and the interface to the robot, and
the driver's type chooses what drives the arm (``drake_skill.station.drivers``).
Both stations export the ports of ``drake_skill.station.interface``.
"""

from __future__ import annotations

from drake_skill.station.scenario import Scenario

__all__ = ["make_station"]


def make_station(scenario: Scenario | None = None, hardware: bool = False, meshcat=None, *,
                 lcm=None, commanding: bool = True):
    """The station of ``scenario`` (default: the Open scene).

    hardware=False: the simulated station (``drake_skill.station.sim.builder.Station``),
    its arm driven as ``scenario.driver`` says. hardware=True: the interface to the
    robot (``drake_skill.station.hardware.station.HardwareStation``); the driver must
    be a ``!PandaLcmDriver`` (else a ValueError that names the field). ``lcm`` (a DrakeLcm to use instead of one on the
    driver's URL) and ``commanding`` (False: only listen, e.g. while a person guides
    the arm) apply to the robot only. ``meshcat`` draws the station in Meshcat.
    """
    scenario = scenario if scenario is not None else Scenario()     # each station validates it
    if not hardware:
        from drake_skill.station.sim.builder import Station

        return Station(scenario, meshcat=meshcat)
    from drake_skill.station.hardware.station import HardwareStation

    return HardwareStation(scenario, lcm=lcm, meshcat=meshcat, commanding=commanding)
