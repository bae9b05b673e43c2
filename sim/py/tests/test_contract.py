"""The contract constants the training scripts read come from the Rust side and agree."""

import math

import herb_sim


def test_model_shapes_are_the_observation_layout():
    assert list(herb_sim.MODEL_INPUT_SHAPE) == [1, herb_sim.OBS_CHANNELS, herb_sim.OBS_SIZE, herb_sim.OBS_SIZE]
    assert math.prod(herb_sim.MODEL_INPUT_SHAPE) == herb_sim.OBS_LEN
    assert tuple(herb_sim.MODEL_INPUT_SHAPE[1:]) == tuple(herb_sim.OBS_SHAPE)
    assert list(herb_sim.MODEL_OUTPUT_SHAPE) == [1, 3]
    assert abs(herb_sim.OBS_CELL_M * herb_sim.OBS_SIZE - 0.35) < 1e-6
    assert 0 < herb_sim.HEIGHT_SCALE_M < 1
