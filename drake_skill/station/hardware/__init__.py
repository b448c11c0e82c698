"""The hardware station: the simulated station's ports, backed by a Panda over the
driver's LCM protocol and a camera (see ``drake_skill.station``)."""
