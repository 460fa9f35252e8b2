"""Learners: one algorithm per file."""

from agent.learners.lspi import LSPI, RBFBasis, TabularBasis
from agent.learners.kalman_velocity import VelocityFilter
from agent.learners.saccade import SaccadeLearner
from agent.learners.sarsa_lambda import SarsaLambda, TileCoder

__all__ = ["LSPI", "RBFBasis", "SaccadeLearner", "SarsaLambda", "TabularBasis", "TileCoder", "VelocityFilter"]
