"""Reward-drop detectors behind one interface: update(x) -> drift flag."""

from agent.detectors.base import DropDetector, RunningMoments
from agent.detectors.cusum import CUSUM
from agent.detectors.moving_average_drop import MovingAverageDrop
from agent.detectors.page_hinkley import PageHinkley

DETECTORS = {"cusum": CUSUM, "moving_average": MovingAverageDrop, "page_hinkley": PageHinkley}
DEFAULT_DETECTOR = "cusum"


def make_detector(name: str = DEFAULT_DETECTOR, **params) -> DropDetector:
    try:
        return DETECTORS[name](**params)
    except KeyError:
        raise ValueError(f"unknown detector {name!r}; known: {', '.join(sorted(DETECTORS))}") from None


__all__ = ["CUSUM", "DETECTORS", "DEFAULT_DETECTOR", "DropDetector", "MovingAverageDrop", "PageHinkley",
           "RunningMoments", "make_detector"]
