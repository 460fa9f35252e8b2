"""The worlds. Importing this package registers every sme world as a Gymnasium environment
(``sme/Gridworld-v0``...; see `worlds.gym_env.GYM_ENVS`)."""

from sensorimotor.worlds.gym_env import register_envs

register_envs()
