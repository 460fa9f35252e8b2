"""Learners: one algorithm per file."""

from agent.learners.lspi import LSPI, TabularBasis

__all__ = ["LSPI", "TabularBasis"]
