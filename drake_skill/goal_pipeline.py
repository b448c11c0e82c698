"""The perception-to-reward chain of ARCHITECTURE.md, wired behind a station.

    [Station] --point_cloud--> [ObjectSegmenter] --object_points, valid--> [PcaeFeaturizer]
              --goal_data, goal_valid--> [PomrpReward] --> reward, return

``add_goal_pipeline(builder, station, skill)`` adds the three systems of a
fitted :class:`~drake_skill.skill.Skill` (its PCAE weights, PCA and POMRP) and
connects them by their named ports. Each samples at the camera rate
(``station.config.camera.fps``, 10 Hz). The reward system reads the goal data
the featurizer stored at the previous frame, so the reward lags the camera by
one frame (0.1 s); the thesis' returns are sums over whole executions, which a
short settle time at the end covers.
"""

from __future__ import annotations

import dataclasses as dc

from drake_skill.object_segmenter import ObjectSegmenter, add_object_segmenter
from drake_skill.pcae_featurizer import PcaeFeaturizer, PcaeFeaturizerConfig
from drake_skill.pomrp_reward import PomrpReward, PomrpRewardConfig


@dc.dataclass
class GoalPipeline:
    """Handles to the systems :func:`add_goal_pipeline` added."""

    segmenter: ObjectSegmenter
    featurizer: PcaeFeaturizer
    reward: PomrpReward


def add_goal_pipeline(builder, station, skill) -> GoalPipeline:
    """Adds segmenter -> featurizer -> reward for ``skill`` behind ``station``'s camera."""
    if not station.config.enable_camera:
        raise ValueError("the goal pipeline needs a station built with enable_camera = true")
    period = 1.0 / station.config.camera.fps
    segmenter = add_object_segmenter(builder, station)
    featurizer = builder.AddNamedSystem("pcae_featurizer", PcaeFeaturizer(
        skill.goal_features, PcaeFeaturizerConfig(period_s=period), model=skill.encoder()))
    reward = builder.AddNamedSystem("pomrp_reward", PomrpReward(skill.pomrp, PomrpRewardConfig(period=period)))
    builder.Connect(segmenter.get_object_points_output_port(), featurizer.get_object_points_input_port())
    builder.Connect(segmenter.get_valid_output_port(), featurizer.get_valid_input_port())
    builder.Connect(featurizer.get_goal_data_output_port(), reward.GetInputPort("goal_data"))
    builder.Connect(featurizer.get_goal_valid_output_port(), reward.GetInputPort("valid"))
    return GoalPipeline(segmenter, featurizer, reward)
