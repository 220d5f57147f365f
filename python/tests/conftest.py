"""Shared paths and closed forms for the tests (../shared/reference/closed-forms.md)."""

import math
import pathlib

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
MODELS = REPO / "models"


@pytest.fixture
def ball():
    import hybc

    return hybc.Model.from_file(MODELS / "ball.hyb")


def ball_bounces(g, e, h0, t_end, max_bounces=100):
    """Bounce times of the vertical ball before t_end: t1 = sqrt(2 h0 / g), then flights of
    2 e^k v1 / g; at most `max_bounces` (before a Zeno point they never pass t_end)."""
    v1 = math.sqrt(2 * g * h0)
    times = [math.sqrt(2 * h0 / g)]
    k = 1
    while len(times) < max_bounces:
        nxt = times[-1] + 2 * e**k * v1 / g
        if nxt > t_end:
            break
        times.append(nxt)
        k += 1
    return np.array([t for t in times if t <= t_end])


def ball_energy(g, e, h0, n_bounces):
    """E = g h0 e^(2k) after k bounces, and its derivatives with respect to e and h0."""
    k = n_bounces
    return g * h0 * e ** (2 * k), 2 * k * g * h0 * e ** (2 * k - 1), g * e ** (2 * k)
