"""The reward box: goal HMM -> MRP values -> POMRP reward (docs/method.md section 4).

Drake-free math: ``goal_model`` (hmmlearn), ``mrp``, ``pomrp``, ``plots``.
Drake wrappers: ``systems`` (``PomrpReward`` and ``add_goal_pipeline``).
"""
