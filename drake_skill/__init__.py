"""drake-skill: robot skill learning from very few demonstrations, as a Drake diagram."""
__version__ = "0.1.0"
