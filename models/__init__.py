"""drake-skill's model files, installed as the package ``drake_skill.models``.

This folder is the repository's ``models/``; pyproject.toml maps it onto
``drake_skill.models`` so the wheel (and an editable install) carries the
Panda, table, box and drawer SDFormat files, their meshes and the trained
PCAE weights. Code reaches them with ``importlib.resources``
(``drake_skill.station.models.models_dir``), never by a path relative to a
source file.
"""
