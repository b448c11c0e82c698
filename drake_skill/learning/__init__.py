"""The outer loop: policy search (docs/method.md section 5).

Drake-free math: ``policy_search`` (the ask/tell methods), ``loop`` (the
learning run, :class:`~drake_skill.learning.loop.LearningRun` and ``learn``),
``evaluation`` (greedy and held-out success), ``runlog`` (progress.csv,
TensorBoard, versions), ``plots`` (figures).
Drake side: ``rollout`` (the rollout runner that resets and simulates the
diagram), ``workers`` (pools of runners).
"""
