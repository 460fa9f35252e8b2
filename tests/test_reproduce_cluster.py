"""`sme reproduce --cluster ADDRESS`: the seeded jobs as Ray tasks give the same results.json as the
local process pool. Ray is an optional extra (`cluster`): the test skips without it."""

import json
import os

import pytest

from sensorimotor.tools.cli import main


@pytest.fixture
def local_ray(monkeypatch):
    """A local Ray instance on loopback (2 CPUs, no dashboard, no usage report), stopped after."""
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'sensorimotor-embedding[cluster]')")
    ctx = ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    try:
        yield ctx.address_info["gcs_address"]
    finally:
        ray.shutdown()


def test_cluster_gives_the_same_results_as_the_process_pool(local_ray, tmp_path):
    common = ["reproduce", "gridworld", "--quick", "--runs", "1"]
    assert main([*common, "--workers", "2", "--out", str(tmp_path / "pool")]) == 0
    assert main([*common, "--cluster", local_ray, "--out", str(tmp_path / "ray")]) == 0
    with open(tmp_path / "pool" / "gridworld" / "results.json") as f:
        pool = json.load(f)
    with open(tmp_path / "ray" / "gridworld" / "results.json") as f:
        on_ray = json.load(f)
    assert pool["results"] and on_ray == pool
    assert os.path.exists(tmp_path / "ray" / "gridworld" / "gridworld_lspi.png")


def test_cluster_without_ray_says_which_extra(monkeypatch, tmp_path, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # as if ray were not installed
    assert main(["reproduce", "gridworld", "--cluster", "auto", "--out", str(tmp_path)]) == 1
    assert "sensorimotor-embedding[cluster]" in capsys.readouterr().err
