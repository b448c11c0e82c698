"""The commands' input checks: :mod:`drake_skill.inputs` (the library's, which the CLI shares)."""

from drake_skill.inputs import input_file, input_folder, load_yaml, output_folder, scenario, skill

__all__ = ["input_file", "input_folder", "load_yaml", "output_folder", "scenario", "skill"]
