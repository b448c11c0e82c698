"""A hand-written two-state goal model (no fit) shared by the goal-model and POMRP tests."""

import numpy as np


def two_state_model_arrays():
    """Arrays and metadata as :meth:`GoalHMM.to_arrays` gives them: a 0 -> 1 chain in 2-D goal data,
    state 1 terminal and absorbing, two demonstrations of 20 and 30 frames."""
    arrays = {"startprob": np.array([1.0, 0.0]), "transmat": np.array([[0.9, 0.1], [0.0, 1.0]]),
              "means": np.array([[0.0, 0.0], [1.0, 0.5]]),
              "covars": np.array([[[0.04, 0.01], [0.01, 0.09]], [[0.01, 0.0], [0.0, 0.01]]]),
              "terminal_states": np.array([1]), "lengths": np.array([20, 30]),
              "loglik_per_step": np.array([-1.5, -1.2])}
    return arrays, {"n_states": 2, "n_features": 2, "covariance_type": "full"}
