"""ChannelCodeBias: the GLONASS channels' single-difference code biases learned at fixed epochs (pure)."""

from __future__ import annotations

import numpy as np

from onboard.rtk.models import ChannelCodeBias

BIAS_M = np.array([0.8, -4.1, -1.2, -1.2, 0.3, 0.5, 0.2])


def test_the_biases_between_channels_are_learned_whatever_the_common_clock() -> None:
    """Residuals = a receiver-clock part common to the channels (metres, changing every epoch) + each channel's
    bias + 1 m of noise: after 300 fixed epochs every difference of two channels' learned biases is within
    0.25 m of the true one (the datum, the median channel, is free: it cancels in the double differences)."""
    rng = np.random.default_rng(7)
    cb = ChannelCodeBias.empty(BIAS_M.size)
    use = np.ones(BIAS_M.size, bool)
    for _ in range(300):
        cb.learn(rng.normal(0.0, 50.0) + BIAS_M + rng.normal(0.0, 1.0, BIAS_M.size), use, window=300)
    got = cb.correction_m(30)
    np.testing.assert_allclose(got - got[0], BIAS_M - BIAS_M[0], atol=0.25)
    assert np.all(cb.count == 300)


def test_a_channel_joining_late_is_learned_on_the_others_datum_and_used_only_after_min_count() -> None:
    rng = np.random.default_rng(3)
    cb = ChannelCodeBias.empty(BIAS_M.size)
    first = np.array([True, True, True, True, True, True, False])
    for k in range(400):
        use = first if k < 200 else np.ones(BIAS_M.size, bool)
        cb.learn(rng.normal(0.0, 50.0) + BIAS_M + rng.normal(0.0, 0.5, BIAS_M.size), use, window=300)
    got = cb.correction_m(30)
    np.testing.assert_allclose(got - got[0], BIAS_M - BIAS_M[0], atol=0.2)
    assert cb.correction_m(250)[6] == 0.0 and cb.correction_m(250)[0] != 0.0  # 200 samples: not yet at 250


def test_fewer_than_three_channels_teach_nothing() -> None:
    """With two channels the common part and the biases cannot be told apart: nothing is learned."""
    cb = ChannelCodeBias.empty(4)
    cb.learn(np.array([3.0, -1.0, 0.0, 0.0]), np.array([True, True, False, False]), window=10)
    assert np.all(cb.count == 0) and np.all(cb.bias_m == 0.0)
