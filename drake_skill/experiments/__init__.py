"""The thesis's simulation study (chapter 7) as a grid of learning runs.

- :mod:`~drake_skill.experiments.grid`: the grid (skills x methods x rewards
  x runs), each run one call of :func:`~drake_skill.learning.loop.learn`,
  stored atomically the moment it ends and skipped when there.
- :mod:`~drake_skill.experiments.pool`: where the runs execute: worker
  processes (a dead worker's run is retried) or Ray.
- :mod:`~drake_skill.experiments.table`: the tidy table of the stored runs (CSV).
- :mod:`~drake_skill.experiments.report`: figures and ``results.md`` from
  the table alone.

``drake-skill experiment run`` / ``drake-skill experiment report`` are the
command line. Nothing here imports Drake at import time; the workers do.
"""
