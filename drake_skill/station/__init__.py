"""The station box: the Panda, the object and the camera behind one set of ports.

Two stations satisfy one contract (``interface.StationInterface``), and one
factory builds both from one scenario: ``make.make_station(scenario,
hardware=False, meshcat=None)``, the arm driven as the scenario's ``driver``
says (``drivers``). The rest of the system sees only the ports:

- ``sim/``: the simulated station.
  - ``sim.builder``: ``Station``, the MultibodyPlant diagram;
  - ``sim.simulation``: ``StationSimulation``, build once / reset / run;
  - ``sim.lcm_robot``: a simulated Panda behind the Panda driver's LCM
    protocol, the stand-in robot the hardware port is tested against.
- ``hardware/``: the real robot.
  - ``hardware.station``: ``HardwareStation``, the same ports backed by the
    Panda driver over LCM and a camera; ``hardware.systems``: its LeafSystems.

Shared by both:

- ``interface``: the contract (ports and their types);
- ``config``: the scenario (``Scenario``), loaded from ``scenarios/`` or a
  user's own file; ``drivers``: its ``driver`` field's types (the robot's LCM
  channels, URL, timeouts and workspace among them); ``make``: the factory;
- ``recording``: ``advance_station``, how every run advances a station, and
  the errors that end a run early;
- ``controller``, ``limits``, ``reflex``: the end-effector controller, the
  Panda's limits and the collision reflex;
- ``camera``: the object camera's crop; ``models``: where the model files live;
- ``success``: the ground-truth success judges;
- ``scripted``, ``pose_source``: keyframed hand motions and the source that plays them;
- ``loggers``: ``StationLoggers``, the one recording path: Drake loggers (and a
  frame log of the segmenter's outputs) of what a run records, in the Context.
"""
