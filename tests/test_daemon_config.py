"""The daemon's one typed config (`DaemonConfig`): the keyword construction every caller uses still
builds the same daemon, an unknown option is refused with the valid names, bad values fail before
anything starts; and the split daemon keeps every name importable from `agent.daemon`."""

from __future__ import annotations

import pytest

from sensorimotor.agent.daemon import AgentDaemon, DaemonConfig, DuplicateAgent


def test_keywords_and_a_config_build_the_same_daemon(tmp_path) -> None:
    by_kw = AgentDaemon(None, "a0", seed=3, state_dir=str(tmp_path), link_ttl=5.0, owner_id="a0.w1")  # type: ignore[arg-type]
    cfg = DaemonConfig(agent_id="a0", seed=3, state_dir=str(tmp_path), link_ttl=5.0, owner_id="a0.w1")
    by_cfg = AgentDaemon(None, config=cfg)  # type: ignore[arg-type]
    assert by_kw.settings == by_cfg.settings
    s = by_kw.settings
    assert (s.agent_id, s.owner_id, s.seed, s.link_ttl) == ("a0", "a0.w1", 3, 5.0)
    assert s.share_every == s.checkpoint_every == 30.0  # share_every defaults to checkpoint_every
    assert (by_kw.agent_id, by_kw.owner_id, by_kw.state_dir) == ("a0", "a0.w1", str(tmp_path))
    assert by_kw.config.agent_id == "a0"  # the links' AgentConfig, as before
    # a keyword replaces the config's value; the owner id defaults to the agent id
    d = AgentDaemon(None, "b", config=DaemonConfig(seed=7))  # type: ignore[arg-type]
    assert (d.agent_id, d.owner_id, d.seed) == ("b", "b", 7)


def test_unknown_options_and_bad_values_are_refused_before_anything_starts() -> None:
    with pytest.raises(TypeError, match="state_dri.*valid: agent_id, seed, state_dir"):
        AgentDaemon(None, state_dri="x")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="link_ttl must be > 0"):
        AgentDaemon(None, link_ttl=0)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        AgentDaemon(None, "bad/id")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown detector 'nope'; known: cusum"):
        AgentDaemon(None, detector="nope")  # type: ignore[arg-type]
    assert issubclass(DuplicateAgent, Exception)
