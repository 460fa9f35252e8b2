"""Learners: one algorithm per file."""

from agent.learners.lspi import LSPI, RBFBasis, TabularBasis
from agent.learners.saccade import SaccadeLearner

__all__ = ["LSPI", "RBFBasis", "SaccadeLearner", "TabularBasis"]
