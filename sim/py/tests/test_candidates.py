"""Tests of the candidate interface of the bindings: the shared feature layout, the teacher's
simulated outcomes, stepping by candidate index, the half-turn symmetry, and bad indices."""

import numpy as np
import pytest

import herb_sim

FAST = dict(meshes=False, min_objects=3, max_objects=6)


def test_candidate_inputs_follow_the_shared_layout():
    v = herb_sim.HerbVectorEnv(4, reward="cs0.6", seed=3, threads=2, **FAST)
    v.reset(seed=3)
    ctx, cand, mask = v.candidates()
    n, c, f = 4, herb_sim.MAX_CANDIDATES, herb_sim.CANDIDATE_LEN
    assert ctx.shape == (n, herb_sim.CONTEXT_LEN) and cand.shape == (n, c, f) and mask.shape == (n, c)
    assert ctx.dtype == cand.dtype == mask.dtype == np.float32
    # Empty box: the pooled heightmap is all floor, and every environment has candidates.
    assert np.all(ctx[:, :28 * 19] == 0.0)
    k = mask.sum(axis=1)
    assert np.all(k >= 8)
    # Real rows: positions inside [-1, 1], exactly one yaw, resting on the floor with full
    # support; padding rows are zero.
    for i in range(n):
        real, pad = cand[i, : int(k[i])], cand[i, int(k[i]):]
        assert np.all(np.abs(real[:, :2]) <= 1.0)
        assert np.all(real[:, 2:6].sum(axis=1) == 1.0)
        assert np.all(real[:, 9] == 1.0)
        assert np.all(pad == 0.0) and np.all(mask[i, int(k[i]):] == 0.0)


def test_teacher_outcomes_and_stepping_by_index():
    v = herb_sim.HerbVectorEnv(3, reward="simple", seed=5, threads=2, **FAST)
    v.reset(seed=5)
    ctx, cand, mask, rets, packed, choice, parts = v.teacher(k=4)
    assert rets.shape == packed.shape == mask.shape and choice.shape == (3,)
    for i in range(3):
        sim = ~np.isnan(rets[i])
        assert sim.sum() == min(4, int(mask[i].sum()))
        assert np.all(packed[i][sim] >= 0) and np.all(packed[i][~sim] == -1)
        # The choice is the best simulated return (first of equals).
        assert choice[i] == int(np.argmax(np.where(sim, rets[i], -np.inf)))
        # Under the simple reward the return is the objects packed minus a failure.
        assert np.allclose(rets[i][sim], packed[i][sim] - parts[i][sim][:, 2])
    rew, term, info = v.step_candidates(choice)
    assert rew.shape == (3,) and term.dtype == bool
    # Stepping again without new candidates is an error naming what to call.
    with pytest.raises(RuntimeError, match="candidates"):
        v.step_candidates(choice)
    v.candidates()
    with pytest.raises(ValueError, match="not one of"):
        v.step_candidates(np.full(3, herb_sim.MAX_CANDIDATES + 5))


def test_teacher_rollout_of_candidate_0_is_the_lattice_blbf_episode():
    # One environment, one episode: the return simulated for candidate 0 at the first step is
    # the return the lattice BLBF rule then actually gets.
    a = herb_sim.VecEnv(1, reward="cs0.6", seed=9, autoreset=False, threads=1, **FAST)
    a.reset(seed=9)
    *_, rets, _, _, _ = a.teacher(k=2)
    predicted = rets[0, 0]
    b = herb_sim.VecEnv(1, reward="cs0.6", seed=9, autoreset=False, threads=1, **FAST)
    b.reset(seed=9)
    total = 0.0
    while True:
        _, rew, term, _ = b.step_rule("lattice-blbf")
        total += float(rew[0])
        if term[0]:
            break
    assert np.float32(total) == pytest.approx(predicted, abs=1e-5)


def test_half_turn_of_the_features_matches_the_turned_box():
    # On the empty box the pooled heightmap is symmetric; a candidate's half turn has the
    # negated position, the yaw two steps on, and swapped wall gaps.
    v = herb_sim.HerbVectorEnv(1, seed=1, threads=1, **FAST)
    v.reset(seed=1)
    _, cand, mask = v.candidates()
    row = cand[0, 0]
    turned = herb_sim.half_turn_candidates(row[None, None, :])[0, 0]
    assert np.allclose(turned[:2], -row[:2])
    assert np.argmax(turned[2:6]) == (np.argmax(row[2:6]) + 2) % 4
    assert turned[11] == row[12] and turned[12] == row[11]
    assert turned[13] == row[14] and turned[14] == row[13]
    assert np.array_equal(herb_sim.half_turn_candidates(turned[None, None, :])[0, 0], row)
    ctx = np.arange(herb_sim.CONTEXT_LEN, dtype=np.float32)[None]
    t = herb_sim.half_turn_context(ctx)
    assert t[0, 0] == 28 * 19 - 1 and t[0, -1] == ctx[0, -1]
    with pytest.raises(ValueError, match="last axis"):
        herb_sim.half_turn_candidates(np.zeros((2, 3), np.float32))


def test_step_rule_steps_only_the_active_environments():
    v = herb_sim.HerbVectorEnv(3, reward="simple", seed=4, threads=2, **FAST)
    v.reset(seed=4)
    _, rew, term, _, info = v.step_rule("lattice-blbf", active=np.array([True, False, True]))
    assert rew[1] == 0.0 and not term[1] and info["packed"][1] == 0
    assert rew[0] == 1.0 and rew[2] == 1.0
    with pytest.raises(ValueError, match="active"):
        v.step_rule("lattice-blbf", active=np.array([True]))


def test_step_rule_search_places_through_the_twin_and_the_exact_clone():
    # The decision-time search through the bindings: each twin places the first object of
    # every environment, and a bad twin name is a clear error.
    for twin in ("heightmap", "job", "exact"):
        v = herb_sim.HerbVectorEnv(2, reward="simple", seed=5, threads=2, **FAST)
        v.reset(seed=5)
        _, rew, term, _, info = v.step_rule("search", k=2, rollouts=2, horizon=2, twin=twin)
        assert (info["packed"] == 1).all(), (twin, info["packed"])
        assert (rew == 1.0).all() and not term.any()
    with pytest.raises(ValueError, match="twin"):
        v.step_rule("search", k=2, twin="camera")
    with pytest.raises(ValueError, match="search"):
        v.step_rule("blbff")
