"""Demonstrations: the file format (``format``), the scripted demonstrator
(``demonstrator``) and Meshcat teleoperation (``teleop``)."""
