"""The workflows the commands run, as library functions with typed inputs.

Record -> fit -> save (:mod:`drake_skill.workflow.prepare`). The commands in
``drake_skill.cli`` parse flags into these inputs; nothing outside ``cli``
imports ``cli`` (``tests/test_layout.py``).
"""
