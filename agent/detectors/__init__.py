"""Reward-drop detectors behind one interface: update(x) -> drift flag."""

import inspect

from sensorimotor.agent.detectors.base import DropDetector, RunningMoments
from sensorimotor.agent.detectors.bernoulli_cusum import BernoulliCUSUM
from sensorimotor.agent.detectors.cusum import CUSUM
from sensorimotor.agent.detectors.moving_average_drop import MovingAverageDrop
from sensorimotor.agent.detectors.page_hinkley import PageHinkley

DETECTORS: dict[str, type[DropDetector]] = {
    "cusum": CUSUM,
    "moving_average": MovingAverageDrop,
    "page_hinkley": PageHinkley,
}
DEFAULT_DETECTOR = "cusum"


def make_detector(name: str = DEFAULT_DETECTOR, **params) -> DropDetector:
    """A detector by name, with the settings it takes.

    Parameters it does not take are ignored: programs suggest settings for their performance
    stream (e.g. `warmup`, `rate`) without knowing which detector the user chose.

    Parameters
    ----------
    name : str, default DEFAULT_DETECTOR
        A key of `DETECTORS` ("cusum", "moving_average", "page_hinkley").
    **params
        Constructor settings; those the detector does not accept are dropped. With "cusum", a
        `failure` value (a stream of episodes that succeed or fail, such as the mountain car's
        -1 for a given-up episode) gives the CUSUM of its failures, `BernoulliCUSUM`.

    Returns
    -------
    DropDetector
        A fresh detector.

    Raises
    ------
    ValueError
        If `name` is unknown (or a setting is out of range).

    Examples
    --------
    ::

        det = make_detector("page_hinkley", warmup=20, rate=0.05)  # `rate` is dropped
    """
    try:
        cls = DETECTORS[name]
    except KeyError:
        raise ValueError(f"unknown detector {name!r}; known: {', '.join(sorted(DETECTORS))}") from None
    if cls is CUSUM and params.get("failure") is not None:
        cls = BernoulliCUSUM  # a stream with a failure value: the CUSUM of its failures
    accepted = inspect.signature(cls).parameters
    return cls(**{k: v for k, v in params.items() if k in accepted})


__all__ = [
    "BernoulliCUSUM",
    "CUSUM",
    "DETECTORS",
    "DEFAULT_DETECTOR",
    "DropDetector",
    "MovingAverageDrop",
    "PageHinkley",
    "RunningMoments",
    "make_detector",
]
