"""The station box: the simulated Panda, objects and camera behind one set of ports.

- ``config``: the scenario (``StationConfig``), loaded from the YAML files in
  ``scenarios/`` or a user's own;
- ``builder``: ``build_station(config)``, the station Diagram;
- ``controller``: the end-effector controller (differential IK);
- ``models``: where the SDFormat models live;
- ``success``: the simulator's ground-truth success judges;
- ``scripted``, ``pose_source``: scripted keyframe motions and the source that plays them;
- ``simulation``: ``StationSimulation``, build once / reset / run, and the one
  recording loop.

Every module here builds on Drake: the station *is* the plant.
"""
