"""ORCA (controllers.orca): known answers on small cases, simulated with exact kinematics."""

import numpy as np

from stafpipe.controllers.orca import orca_velocities
from stafpipe.sensing import Observation

R = 0.2


def _obs(p, v, wall_x=None, movers=None):
    n = len(p)
    rel = p[None, :, :] - p[:, None, :]
    if wall_x is None:
        obstacle, dist = np.tile([1e3, 0.0], (n, 1)), np.full(n, 1e3)
    else:
        obstacle = np.stack([wall_x - p[:, 0], np.zeros(n)], axis=1)
        dist = wall_x - p[:, 0] - R
    return Observation(
        position=p,
        velocity=v,
        heading=np.zeros(n),
        goal=p,
        obstacle=obstacle,
        obstacle_distance=dist,
        neighbours=~np.eye(n, dtype=bool),
        rel_position=rel,
        rel_velocity=v[None] - v[:, None],
        time=np.zeros(()),
        movers=np.zeros((0, 4)) if movers is None else movers,
        heard=~np.eye(n, dtype=bool),
    )


def _run(p, goals, steps=200, dt=0.05, **kw):
    p, v = np.array(p, float), np.zeros((len(p), 2))
    closest = np.inf
    for _ in range(steps):
        pref = goals - p
        pref *= np.minimum(1.0, 1.0 / np.maximum(np.linalg.norm(pref, axis=1, keepdims=True), 1e-9))
        v = orca_velocities(pref, _obs(p, v, **kw), R, 1.0, 1.0, dt, 0.05)
        p = p + dt * v
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p)) * 1e9
        closest = min(closest, d.min())
    return p, closest


def test_free_robots_keep_their_preferred_velocity() -> None:
    p = np.array([[0.0, 0.0], [5.0, 5.0]])
    pref = np.array([[0.5, 0.0], [0.0, -0.3]])
    assert np.allclose(orca_velocities(pref, _obs(p, pref.copy()), R, 1.0, 1.0, 0.1, 0.05), pref)


def test_head_on_robots_pass_each_other_without_contact() -> None:
    start = np.array([[0.0, 0.0], [4.0, 0.01]])
    p, closest = _run(start, start[::-1].copy())
    assert closest >= 2 * R  # never touching
    assert np.linalg.norm(p - start[::-1], axis=1).max() < 0.1  # and both arrive


def test_a_crowd_swapping_sides_of_a_circle_stays_contact_free() -> None:
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    start = 2.0 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    start += np.random.default_rng(0).normal(0, 0.02, start.shape)  # a perfectly symmetric crowd deadlocks
    _, closest = _run(start, -start, steps=200)
    assert closest >= 2 * R - 1e-6  # ORCA keeps them apart (a symmetric crowd may stall: ORCA's known deadlock)


def test_robots_crossing_at_right_angles_both_arrive_without_contact() -> None:
    start = np.array([[-2.0, 0.0], [0.0, -2.1]])
    goals = np.array([[2.0, 0.0], [0.0, 2.1]])
    p, closest = _run(start, goals)
    assert closest >= 2 * R
    assert np.linalg.norm(p - goals, axis=1).max() < 0.1


def test_approach_to_a_wall_is_limited_to_closing_the_gap_in_the_horizon() -> None:
    p = np.array([[0.0, 0.0]])
    v = orca_velocities(np.array([[1.0, 0.3]]), _obs(p, np.zeros((1, 2)), wall_x=0.8), R, 1.0, 1.0, 0.1, 0.05)
    gap = 0.8 - R - 0.05
    assert v[0, 0] <= gap / 1.0 + 1e-9 and v[0, 1] > 0.29  # slides along the wall
