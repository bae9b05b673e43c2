"""Tests of the herb_sim bindings: spaces and layout, Gymnasium's checker, determinism,
vectorised stepping with autoreset, and bad arguments rejected with clear errors."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import herb_sim

FAST = dict(meshes=False, min_objects=3, max_objects=5)


def test_spaces_follow_the_shared_layout():
    env = herb_sim.PackingEnv(**FAST)
    assert env.observation_space.shape == (2, 224, 224)
    assert herb_sim.OBS_LEN == 2 * 224 * 224
    assert (herb_sim.INPUT_NAME, herb_sim.OUTPUT_NAME) == ("obs", "action")
    obs, info = env.reset(seed=1)
    assert obs.dtype == np.float32 and obs.shape == (2, 224, 224)
    assert 0.0 <= obs.min() and obs.max() <= 1.0
    # Channel 0: an empty box is all floor (0) inside, padding 1.0 outside; channel 1: an object.
    assert obs[0, 112, 112] == 0.0 and obs[0, 0, 0] == 1.0
    assert obs[1].sum() > 0.0


def test_gymnasium_checker_passes():
    check_env(herb_sim.PackingEnv(**FAST), skip_render_check=True)


def test_same_seed_same_episode():
    def run(seed):
        env = herb_sim.PackingEnv(**FAST)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for a in ([0.0, 0.0, 0.0], [0.5, -0.5, 0.2], [-0.6, 0.6, -0.9]):
            obs, r, term, trunc, info = env.step(np.array(a, dtype=np.float32))
            out.append(obs)
            out.append(np.array([r, info["packed"]]))
            if term:
                break
        return out

    a, b, c = run(7), run(7), run(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c))


def test_vector_env_steps_all_and_restarts_ended_episodes():
    v = herb_sim.HerbVectorEnv(4, reward="simple", sequence="random", seed=3, threads=2, **FAST)
    obs, _ = v.reset(seed=3)
    assert obs.shape == (4, 2, 224, 224)
    rng = np.random.default_rng(0)
    ended, lengths = 0, []
    for _ in range(12):
        obs, rew, term, trunc, info = v.step(rng.uniform(-1, 1, size=(4, 3)).astype(np.float32))
        assert obs.shape == (4, 2, 224, 224) and rew.shape == (4,)
        assert set(np.unique(rew)) <= {-1.0, 1.0}
        assert not trunc.any()
        ended += int(term.sum())
        lengths += list(info["episode_length"][term])
        # A restarted environment shows an empty box and its next object.
        for i in np.flatnonzero(term):
            assert obs[i, 0, 112, 112] == 0.0 and obs[i, 1].sum() > 0.0
    assert ended > 0
    assert all(1 <= n <= 5 for n in lengths)


def test_cs_rewards_are_in_range():
    v = herb_sim.HerbVectorEnv(2, reward="cs0.6", seed=5, **FAST)
    v.reset()
    for _ in range(5):
        _, rew, _, _, _ = v.step(np.zeros((2, 3), dtype=np.float32))
        assert all(r == -1.0 or 0.0 <= r <= 1.0 for r in rew)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(reward="cs1.5"), "alpha"),
        (dict(reward="fast"), "unknown reward mode"),
        (dict(sequence="sorted"), "beam3, beam3-last or random"),
        (dict(min_objects=6, max_objects=5), "objects per episode"),
        (dict(sequence_model="/nonexistent/sequence.json"), "sequence.json"),
    ],
)
def test_bad_configuration_fails_at_start(kwargs, message):
    with pytest.raises(ValueError, match=message):
        herb_sim.VecEnv(1, meshes=False, **kwargs)


def test_bad_actions_are_rejected():
    v = herb_sim.VecEnv(2, **FAST)
    v.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        v.step(np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="not finite"):
        v.step(np.array([[0, 0, np.nan], [0, 0, 0]], dtype=np.float32))
    single = herb_sim.VecEnv(1, autoreset=False, **FAST)
    with pytest.raises(RuntimeError, match="reset"):
        single.step(np.zeros((1, 3), dtype=np.float32))


def test_expert_actions_are_blbf_placements_that_stay_inside():
    v = herb_sim.HerbVectorEnv(3, reward="simple", seed=11, threads=2, **FAST)
    v.reset(seed=11)
    a, valid = v.expert_actions()
    assert a.shape == (3, 3) and a.dtype == np.float32 and valid.shape == (3,) and valid.all()
    assert np.all(np.abs(a) <= 1.0)
    # Empty box: BLBF takes the bottom-left corner (lowest top, then smallest x, then y) in
    # yaw 0 or 90 degrees (action theta 0 or 0.5).
    assert np.all(a[:, 0] < 0.0) and np.all(a[:, 1] < 0.0)
    assert set(np.round(a[:, 2], 6)) <= {0.0, 0.5}
    # Following the labels, every placement in these small episodes stays inside the box.
    ended = 0
    for _ in range(12):
        a, valid = v.expert_actions()
        assert valid.all()
        _, rew, term, _, info = v.step(a)
        assert np.all(rew == 1.0)
        ended += int(term.sum())
        assert info["success"][term].all()
    assert ended > 0


def test_expert_actions_of_an_ended_episode_are_invalid():
    single = herb_sim.VecEnv(1, autoreset=False, meshes=False, min_objects=1, max_objects=1)
    single.reset(seed=2)
    a, valid = single.expert_actions()
    assert valid.all()
    _, _, term, _ = single.step(a)
    assert term.all()
    a, valid = single.expert_actions()
    assert not valid.any() and np.all(a == 0.0)


def test_episodes_default_to_herbs_order():
    # HERB orders with Beam-3 as Algorithm 1 writes it; the bindings default to it.
    assert herb_sim.HERB_ORDER == "beam3"

    def second_objects(**kw):
        # Both readings pick the same first object (a search from <start>); they part from the
        # second on. One central placement, then channel 1 shows each environment's next object.
        v = herb_sim.VecEnv(8, seed=11, threads=1, autoreset=False, meshes=False, min_objects=8,
                            max_objects=12, **kw)
        v.reset()
        obs, _, done, _ = v.step(np.zeros((8, 3), dtype=np.float32))
        assert not done.any()
        return obs[:, 1].copy()

    default = second_objects()
    assert np.array_equal(default, second_objects(sequence=herb_sim.HERB_ORDER))
    assert not np.array_equal(default, second_objects(sequence="beam3-last"))


def test_the_field_world_is_chosen_by_name_and_a_bad_model_is_refused(tmp_path):
    """``world``: ``ideal`` (default), ``field`` (models/field.toml) or a file; zero errors
    step exactly as the ideal world, a bad file is a ValueError naming its key."""
    zero = tmp_path / "zero.toml"
    rest = ("[camera]\ndepth_sd_m = 0.0\ndropout = 0.0\nedge_dropout = 0.0\n"
            "[object]\nsize_sd = 0.0\nmass_sd = 0.0\nfriction_sd = 0.0\n")
    zero.write_text('name = "zero (fixture)"\n[release]\nxy_sd_m = 0.0\nyaw_sd_deg = 0.0\nheight_sd_m = 0.0\n' + rest)
    runs = {}
    for world in ("ideal", str(zero), "field"):
        env = herb_sim.VecEnv(2, seed=3, meshes=False, world=world, threads=1)
        env.reset(seed=3)
        rewards = []
        for _ in range(4):
            _, r, _, _ = env.step(np.zeros((2, 3), np.float32))
            rewards.append(r.copy())
        runs[world] = np.stack(rewards)
    assert np.array_equal(runs["ideal"], runs[str(zero)])
    assert not np.array_equal(runs["ideal"], runs["field"])
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\n[release]\nxy_sd_m = -0.1\nyaw_sd_deg = 0.0\nheight_sd_m = 0.0\n' + rest)
    with pytest.raises(ValueError, match="release.xy_sd_m"):
        herb_sim.VecEnv(1, meshes=False, world=str(bad))
