"""Hyperparameters of the mountain-car program (ch. 8): the vergence stage (LSPI), the driver
(Sarsa(lambda) over tile coding, the velocity estimate) and how its episodes are watched."""

from __future__ import annotations

from dataclasses import dataclass

from sensorimotor.protocol.params import option


@dataclass(frozen=True)
class MountainCarProgramParams:
    """Hyperparameters of the mountain-car program (ch. 8)."""

    samples_per_iteration: int = option(400, "vergence samples between LSPI iterations", min=1)
    epsilon: float = option(0.2, "vergence exploration: probability of a random action", min=0.0, max=1.0)
    vergence_gamma: float = option(0.95, "LSPI discount of the vergence stage", min=0.0, max=1.0)
    ridge: float = option(1e-3, "LSPI ridge regulariser", min=0.0)
    max_trace: int = option(80, "longest vergence trace", min=2)
    alpha: float = option(0.3, "Sarsa(lambda) step size", min=0.0)
    gamma: float = option(
        1.0,
        "Sarsa(lambda) discount (1: undiscounted, as the task is episodic and every step costs the same; "
        "the dissertation's 0.99 caps what never arriving costs at about 100 steps)",
        min=0.0,
        max=1.0,
    )
    lam: float = option(0.9, "Sarsa(lambda) trace decay", min=0.0, max=1.0)
    tiles: int = option(10, "tiles per dimension and tiling", min=1)
    n_tilings: int = option(8, "tilings", min=1)
    drive_epsilon: float = option(0.0, "driving exploration: probability of a random action", min=0.0, max=1.0)
    eval_every: int = option(10_000, "training car steps between evaluations", min=1)
    n_eval: int | None = option(None, "evaluation states used (none: all the world offers)", min=0)
    watch_after: int = option(50_000, "training car steps before episodes report performance", min=0)
    report_after: int = option(400, "car steps after which a trained driver gives up an episode", min=1)
    process_var: float = option(
        2e-4,
        "process variance of the velocity Kalman filter, in squared vergence steps per car step (1e-5 "
        "with substep=false reproduces the whole-step reading as it was)",
        min=0.0,
    )
    velocity_range: float = option(
        0.04,
        "velocity the driver's tiles span either side of rest, in embedding spans per car step (0.04: the "
        "car crosses its track in no fewer than ~25 steps)",
        min=1e-6,
    )
    velocity: str = option(
        "kalman",
        "velocity estimate: kalman (a constant-velocity Kalman filter on the position) or window "
        "(the least-squares slope of the last velocity_window + 1 positions)",
        choices=("kalman", "window"),
    )
    velocity_window: int = option(8, "car steps the window velocity estimate spans", min=1)
    policy_map: int = option(
        0, "clusters of a policy map of the drive traces emitted after each evaluation (0: none; ch. 9.6)", min=0
    )
    substep: bool = option(
        True,
        "read the position below one vergence step: at the goal the eyes look one step either side, "
        "and the foveal differences there place the minimum between steps (equiangular fit)",
    )
    recall_check: int = option(
        64,
        "a car step whose parallel-eye view was read before reuses that reading; every Nth reuse is "
        "verged again, and a differing reading forgets them all (0: verge at every car step)",
        min=0,
    )
