"""The HERB packing world as Gymnasium environments, stepped in Rust.

- ``PackingEnv``: one environment (``gymnasium.Env``), for checks and evaluation.
- ``HerbVectorEnv``: N environments (``gymnasium.vector.VectorEnv``) stepped in parallel inside
  Rust by one call; episodes that end restart in the same step (``AutoresetMode.SAME_STEP``).

Observations follow the shared layout (``[2, 224, 224]`` float32 in ``[0, 1]``: box heightmap
and the next object's top-down projection); actions are ``(x, y, theta)`` in ``[-1, 1]^3``.
Rewards: ``simple``, ``c`` or ``cs<alpha>`` (HERB paper). Episodes: random multisets of catalog
objects ordered by HERB's Beam-3 (``HERB_ORDER``, ``"beam3"``: Algorithm 1 as written; the
default; ``"beam3-start"`` is an alias kept for one release), by the other reading
(``"beam3-last"``, each search rooted at the last object chosen) or randomly (``"random"``).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from ._native import (BOX_HALF_X, BOX_HALF_Y, CANDIDATE_LEN, CONTEXT_LEN, HEIGHT_SCALE_M, HERB_ORDER, INPUT_NAME,
                      MAX_CANDIDATES, MODEL_INPUT_SHAPE, MODEL_OUTPUT_SHAPE, OBS_CELL_M, OBS_CHANNELS, OBS_LEN,
                      OBS_SIZE, OUTPUT_NAME, VecEnv, half_turn_candidates, half_turn_context,
                      human_demonstrations)

# The contract constants (observation layout, model I/O, box) come from the Rust side, never
# restated in Python.
__all__ = ["PackingEnv", "HerbVectorEnv", "VecEnv", "OBS_LEN", "OBS_SIZE", "OBS_CHANNELS", "OBS_CELL_M",
           "HEIGHT_SCALE_M", "MODEL_INPUT_SHAPE", "MODEL_OUTPUT_SHAPE", "BOX_HALF_X", "BOX_HALF_Y", "INPUT_NAME",
           "OUTPUT_NAME", "CONTEXT_LEN", "CANDIDATE_LEN", "MAX_CANDIDATES", "half_turn_candidates",
           "half_turn_context", "human_demonstrations"]

OBS_SHAPE = VecEnv.observation_shape()


def _spaces():
    obs = gym.spaces.Box(0.0, 1.0, shape=OBS_SHAPE, dtype=np.float32)
    act = gym.spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
    return obs, act


class PackingEnv(gym.Env):
    """One packing episode per reset; one object placed per step.

    Keyword arguments go to ``VecEnv`` (``reward``, ``sequence``, ``min_objects``,
    ``max_objects``, ``boxed``, ``meshes``, ``sequence_model``, ``world``: ``ideal``, ``field``
    or a field model file).
    """

    metadata = {"render_modes": []}

    def __init__(self, **kwargs):
        super().__init__()
        self.observation_space, self.action_space = _spaces()
        self._env = VecEnv(1, autoreset=False, threads=1, **kwargs)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(0, 2**63 - 1))
        obs = self._env.reset(seed=seed)
        return obs[0], {}

    def step(self, action):
        a = np.asarray(action, dtype=np.float32).reshape(1, 3)
        obs, reward, terminated, info = self._env.step(a)
        out = {k: v[0].item() for k, v in info.items()}
        return obs[0], float(reward[0]), bool(terminated[0]), False, out


class HerbVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` packing environments stepped together in Rust (rayon, GIL released)."""

    def __init__(self, num_envs: int, **kwargs):
        self._env = VecEnv(num_envs, autoreset=True, **kwargs)
        self.num_envs = num_envs
        self.single_observation_space, self.single_action_space = _spaces()
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        mode = getattr(gym.vector, "AutoresetMode", None)
        self.metadata = {"autoreset_mode": mode.SAME_STEP} if mode else {}

    def reset(self, *, seed=None, options=None):
        if isinstance(seed, (list, tuple)):
            seed = seed[0]
        return self._env.reset(seed=seed), {}

    def expert_actions(self):
        """The BLBF heuristic's action for every environment's current state:
        ``(actions [N, 3] float32, valid [N] bool)``; see ``VecEnv.expert_actions``."""
        return self._env.expert_actions()

    def step(self, actions):
        a = np.ascontiguousarray(actions, dtype=np.float32).reshape(self.num_envs, 3)
        obs, reward, terminated, info = self._env.step(a)
        truncated = np.zeros(self.num_envs, dtype=bool)
        return obs, reward, terminated, truncated, info

    def candidates(self):
        """The candidate policy's inputs for every environment: ``(context [N, CONTEXT_LEN],
        candidates [N, MAX_CANDIDATES, CANDIDATE_LEN], mask [N, MAX_CANDIDATES])``."""
        return self._env.candidates()

    def teacher(self, k=8, horizon=None):
        """The lookahead teacher on every environment (rollouts of at most ``horizon``
        objects, to the episode's end by default): ``(context, candidates, mask, returns,
        packed, choice, parts)``; see ``VecEnv.teacher``."""
        return self._env.teacher(k, horizon)

    def step_candidates(self, index):
        """Steps every environment with its candidate ``index[i]`` (from the last
        ``candidates()`` or ``teacher()``): ``(rewards, terminated, info)``."""
        return self._env.step_candidates(np.ascontiguousarray(index, dtype=np.int64))

    def step_rule(self, rule, k=8, active=None, horizon=None, rollouts=None, twin="job"):
        """Steps every environment (or those where ``active`` is true) with a rule decided in
        Rust (``lattice-blbf``, ``lattice-reserve``, or ``lookahead`` or ``geo-lookahead`` with
        ``k`` candidates; ``horizon`` limits the rollouts to that many objects) or with the
        decision-time ``search`` (``k`` candidates, ``rollouts`` rollouts, default ``k``, in a
        ``twin``: the job's own twin (its decisions replayed, fitted to the heightmaps), ``"job"``,
        herbd's and the default, one built from the heightmap, ``"heightmap"``, or a clone of
        the world, ``"exact"``);
        returns as ``step``. See ``VecEnv.step_rule``."""
        if active is not None:
            active = np.ascontiguousarray(active, dtype=bool)
        obs, reward, terminated, info = self._env.step_rule(rule, k, active, horizon, rollouts, twin)
        truncated = np.zeros(self.num_envs, dtype=bool)
        return obs, reward, terminated, truncated, info
