"""DGNN's adapter (Blumenkamp et al., ICRA 2022): each robot drives to its own goal slot, seen through the
robot-frame features of `learning/features.py`; navigation and contact rewards only. Training (`train_ppo.method=dgnn`)
and evaluation (`method=dgnn`) both drive the method through this class."""

from __future__ import annotations

import numpy as np

from stafpipe.controllers.base import TeamInfo
from stafpipe.geometry import path_length
from stafpipe.learning.adapters import Adapter, Step
from stafpipe.learning.features import Features, features, guide_targets
from stafpipe.methods.dgnn.network import DGNNPolicy
from stafpipe.sensing import Observation


class DGNNAdapter(Adapter):
    """DGNN (Blumenkamp et al., ICRA 2022): each robot drives to its own goal slot, guided along the path through the
    middle of the passages (`policy.guide=path`; the path STAF's plan centres its subteams on); navigation and contact
    rewards only."""

    name = "dgnn"
    network = DGNNPolicy

    def begin(self, teams: list[TeamInfo], privileged: bool = False) -> None:
        super().begin(teams)
        # the centred path, not TeamInfo.path (the shortest, one radius from the walls): guided along a shortest path
        # that hugs a wall, robots slid on it (docs/learning.md, "The guide path")
        self.paths = [self.centred(t) for t in teams] if self.policy.guide == "path" else []
        self.arcs = np.zeros((len(teams), len(teams[0].start)))  # each robot's arc length along its path, from 0
        self.lengths = [path_length(p) for p in self.paths]

    def step(self, obs: Observation, dt: float) -> Step:
        pc = self.policy
        goal = obs.goal
        if pc.guide == "path":  # worlds that share a path are guided in one call (each robot independently)
            target = np.empty_like(goal)
            groups: dict[int, list[int]] = {}
            for w, path in enumerate(self.paths):
                groups.setdefault(id(path), []).append(w)
            for ws in groups.values():
                pos, own_goal = obs.position[ws].reshape(-1, 2), goal[ws].reshape(-1, 2)
                path, near = self.paths[ws[0]], self.arcs[ws].reshape(-1)
                guided, left = guide_targets(pos, own_goal, path, pc.lookahead, pc.release, near)
                target[ws] = guided.reshape(len(ws), -1, 2)
                self.arcs[ws] = (self.lengths[ws[0]] - left).reshape(len(ws), -1)
        else:
            target = goal
        self._aim = self._target = target  # a teacher steers where the network is guided
        return Step(features(obs, pc.goal_clip, self.sensing_radius, target), goal, target)

    def features(self, obs: Observation) -> Features:
        return features(obs, self.policy.goal_clip, self.sensing_radius, self._target)
