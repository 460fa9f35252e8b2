"""Learners: one algorithm per file."""

from sensorimotor.agent.learners.kalman_velocity import VelocityFilter
from sensorimotor.agent.learners.lspi import LSPI, RBFBasis, TabularBasis
from sensorimotor.agent.learners.saccade import SaccadeLearner
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder

__all__ = ["LSPI", "RBFBasis", "SaccadeLearner", "SarsaLambda", "TabularBasis", "TileCoder", "VelocityFilter"]
