"""The simulated station: MultibodyPlant with contact, RgbdSensor cameras, and the
simulation that resets and re-runs it (see ``drake_skill.station``)."""
