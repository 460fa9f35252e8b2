"""Success as the world defines it: whether an observation ends a trace at the goal, by the rule
the world declares (`WorldSpec.goal`), and whether it ends it in failure.

The dissertation's worlds pay a positive reward at the goal (rule ``reward``). Gymnasium's meaning
of reaching a goal is a terminal state (``terminated``: done, not by a time limit), whatever the
reward (MountainCar pays -1 on every step, the goal step included); panda-gym and
Gymnasium-Robotics set a success flag (``success``). A termination that is not a goal under the
rule (a hole of FrozenLake, MiniGrid's lava) is a failure; a truncation (a time limit) is neither.
"""

from __future__ import annotations

from sensorimotor.protocol.messages import GoalRule, Observation


def reached(rule: str, obs: Observation) -> bool:
    """Whether `obs` is the goal under `rule` (a `GoalRule` token)."""
    if rule == GoalRule.TERMINATED:
        return obs.done and not obs.truncated
    if rule == GoalRule.SUCCESS:
        return obs.success
    if rule == GoalRule.NONE:
        return False
    return obs.reward > 0


def failed(rule: str, obs: Observation) -> bool:
    """Whether `obs` ends the episode on a terminal state that is not the goal (a failure)."""
    return obs.done and not obs.truncated and not reached(rule, obs)
