import numpy as np
import pytest

from dlo_course.noise import OUNoise


def test_one_step_by_hand():
    noise = OUNoise(2, theta=0.15, sigma=0.0, mu=1.0, dt=0.5, seed=0)
    noise.state = np.array([3.0, -1.0])
    # x + theta * (mu - x) * dt, without the random kick
    np.testing.assert_allclose(noise.sample(), [3 - 0.15 * 2 * 0.5, -1 + 0.15 * 2 * 0.5])


def test_reset_and_output():
    noise = OUNoise(3, mu=0.2, seed=0)
    x = noise.sample()
    assert x.shape == (3,) and x.dtype == np.float32
    noise.reset()
    np.testing.assert_array_equal(noise.state, [0.2, 0.2, 0.2])


def test_seeded_and_resumable():
    a, b = OUNoise(3, seed=5), OUNoise(3, seed=5)
    np.testing.assert_array_equal(a.sample(), b.sample())
    assert not np.array_equal(OUNoise(3, seed=6).sample(), OUNoise(3, seed=5).sample())
    c = OUNoise(3, seed=0)
    c.load_state_dict(a.state_dict())
    for _ in range(5):
        np.testing.assert_array_equal(a.sample(), c.sample())


def test_statistics_of_a_long_run():
    theta, sigma = 0.15, 0.3
    noise = OUNoise(1, theta=theta, sigma=sigma, seed=0)
    x = np.array([noise.sample()[0] for _ in range(40_000)], dtype=np.float64)
    assert abs(x.mean()) < 0.05
    assert x.std() == pytest.approx(sigma / np.sqrt(theta * (2 - theta)), rel=0.1)
    # consecutive values are correlated: lag-1 autocorrelation 1 - theta
    assert np.corrcoef(x[:-1], x[1:])[0, 1] == pytest.approx(1 - theta, abs=0.02)
