"""Witness-guided starts for the ladder's PRIVILEGED agents: the certified witness drives the first part of a training
episode and the learner takes over (Jump-Start RL, Uchendu et al. 2023, arXiv 2204.02372), the part shrinking as the
learner succeeds. Used by training/ppo_heading.py with ``guide="jsrl"`` or ``guide="curriculum"``; in training only:
the policy that is evaluated sees only the env's observation and starts at the task's own starts.

The guide is a demonstration (training.protocol.save_demos: certified witness episodes of training seeds >= 100,000,
never the evaluation's pair seeds): a guided episode starts at the demonstration's start state and target (a reset
to a chosen state, ``PennyVectorEnv.reset(options={"state", "target", "reset_mask"})``: privileged) and replays its
actions (float64, as the witness played them: the replay is the witness's episode, bit for bit) for its first h
steps; then the learner acts, with its own clock and impact counter running from the episode's start and the env's
own time limit. The learner is trained on its own steps only (the guided steps are masked out of its batch).

Two schedules of the hand-over step h:

* ``jsrl`` (JSRL's curriculum with random switching): one hand-over fraction f for every demonstration, the
  hand-over step of an episode drawn uniformly in [0, f T_j] (T_j the demonstration's length), f from 1 - ``step``
  down by ``step`` each time the learner's success over at least ``min_episodes`` guided episodes (all
  demonstrations together) at the current f reaches ``threshold``; at f = 0 the demonstration only chooses the start.
* ``curriculum`` (a start-state curriculum with a success filter, DemoStart, arXiv 2409.06613, and RFCL, arXiv
  2405.03379): one hand-over step per demonstration, moved back by ``step`` T_j once the learner succeeds from it in
  at least ``threshold`` of at least ``min_episodes`` episodes of that demonstration; a demonstration solved from its
  start (h_j = 0) is done, and one never solved in ``give_up`` episodes at a stage is dropped (its start is not
  learnable yet: it stops taking samples); episodes pick among the open demonstrations uniformly.

In both, a share ``p_own`` of episodes (and every episode once every demonstration is done or dropped, the final
stage) starts at the task's own starts with no guide, so that training ends on the task's own start distribution.
"""
from __future__ import annotations

import numpy as np

SCHEDULES = ("jsrl", "curriculum")


def demo_episodes(demos: dict) -> list:
    """[(states (T+1, 6), target (2,), actions (T, n_act))] from training.protocol.save_demos' arrays."""
    out = []
    for j, T in enumerate(demos["length"]):
        rows = np.flatnonzero(demos["episode"] == j)
        rows = rows[np.argsort(demos["step"][rows])]
        first = int(np.sum(demos["length"][:j]))
        out.append((demos["states"][rows], demos["targets"][rows[0]], demos["actions"][first:first + int(T)]))
    return out


class Guide:
    """Per env: which demonstration guides its episode (-1: none) and for how many more steps; the schedule's state.

    ``start(rows)`` picks the next start of the envs ``rows`` (their episode just began) and returns (states,
    targets, guided mask) for a privileged reset of the guided ones; ``actions(act)`` writes the guide's float64
    actions into ``act`` for the envs still guided and returns their mask (before ``advance()``, once per step);
    ``record(rows, won)`` takes the outcomes of finished guided episodes."""

    def __init__(self, demos: dict, num_envs: int, rng, schedule: str = "jsrl", step: float = 0.1,
                 threshold: float = 0.5, min_episodes: int = 256, p_own: float = 0.1, give_up: int = 4096):
        if schedule not in SCHEDULES:
            raise ValueError(f"guide schedule must be one of {SCHEDULES}, got {schedule!r}")
        self.episodes = demo_episodes(demos)
        self.schedule, self.step, self.threshold = schedule, float(step), float(threshold)
        self.min_episodes, self.p_own, self.give_up = int(min_episodes), float(p_own), int(give_up)
        self.rng = rng
        D = len(self.episodes)
        self.T = np.array([len(a) for _, _, a in self.episodes], np.int64)
        self.frac = np.full(D, 1.0 - self.step)  # hand-over fraction per demonstration (jsrl: all equal)
        self.done = np.zeros(D, bool)      # solved from its start (curriculum) / the schedule reached 0 (jsrl)
        self.dropped = np.zeros(D, bool)   # never solved in give_up episodes at one stage (curriculum)
        self.wins = np.zeros(D, np.int64)  # outcomes at the current stage
        self.tries = np.zeros(D, np.int64)
        self.stage = np.zeros(D, np.int64)
        self.demo = np.full(num_envs, -1)
        self.demo_stage = np.zeros(num_envs, np.int64)
        self.left = np.zeros(num_envs, np.int64)   # guided steps left in the env's episode
        self.t = np.zeros(num_envs, np.int64)      # the guided episode's step
        self.n_act = self.episodes[0][2].shape[1] if D else 1

    # -- state ------------------------------------------------------------------------------------------------------
    def open(self) -> np.ndarray:
        return np.flatnonzero(~(self.done | self.dropped))

    def finished(self) -> bool:
        """Every demonstration done or dropped: the final stage, on the task's own starts only."""
        return len(self.open()) == 0

    def state_dict(self) -> dict:
        return {k: getattr(self, k).copy() for k in ("frac", "done", "dropped", "wins", "tries", "stage")}

    def load_state_dict(self, d: dict) -> None:
        for k, v in d.items():
            getattr(self, k)[...] = v

    def summary(self) -> dict:
        D = max(len(self.T), 1)
        n = int(self.tries.sum())
        return {"guide_frac": float(np.mean(np.where(self.done, 0.0, self.frac))) if len(self.T) else 0.0,
                "guide_done": float(self.done.sum() / D), "guide_dropped": float(self.dropped.sum() / D),
                "guide_success": float(self.wins.sum() / n) if n else float("nan")}

    # -- per step ---------------------------------------------------------------------------------------------------
    def start(self, rows: np.ndarray):
        """(states (len(rows), 6), targets (len(rows), 2), guided (len(rows),) bool) of the next episode of ``rows``."""
        rows = np.asarray(rows)
        self.demo[rows], self.left[rows], self.t[rows] = -1, 0, 0
        states, targets = np.zeros((len(rows), 6)), np.zeros((len(rows), 2))
        opened = self.open()
        guided = np.zeros(len(rows), bool)
        if len(opened):
            guided = self.rng.random(len(rows)) >= self.p_own
        g = np.flatnonzero(guided)
        if len(g):
            j = opened[self.rng.integers(0, len(opened), len(g))]
            # JSRL's random switching: the hand-over anywhere up to the stage's step (so the learner also sees
            # earlier hand-overs, down to the start, while a stage lasts), the curriculum's at the stage's step
            f = self.frac[j] * (self.rng.random(len(g)) if self.schedule == "jsrl" else 1.0)
            h = np.round(f * self.T[j]).astype(np.int64)
            h = np.where(self.done[j], 0, np.minimum(h, self.T[j] - 1))
            for r, d in zip(g, j):
                states[r], targets[r] = self.episodes[d][0][0], self.episodes[d][1]
            self.demo[rows[g]], self.demo_stage[rows[g]], self.left[rows[g]] = j, self.stage[j], h
        return states, targets, guided

    def actions(self, act: np.ndarray) -> np.ndarray:
        """Write the guide's actions into ``act`` (N, n_act) where an env is still guided; that mask."""
        on = self.left > 0
        for i in np.flatnonzero(on):
            act[i] = self.episodes[self.demo[i]][2][self.t[i]]
        return on

    def advance(self) -> None:
        """One step of every env taken."""
        self.t += 1
        self.left = np.maximum(self.left - 1, 0)

    def record(self, rows: np.ndarray, won: np.ndarray) -> None:
        """Outcomes of guided episodes that ended (rows: their envs; outcomes of an older stage are ignored)."""
        rows = np.asarray(rows)
        g = self.demo[rows] >= 0
        j, won = self.demo[rows][g], np.asarray(won, bool)[g]
        cur = self.demo_stage[rows][g] == self.stage[j]
        j, won = j[cur], won[cur]
        np.add.at(self.tries, j, 1)
        np.add.at(self.wins, j, won.astype(np.int64))
        self.demo[rows] = -1
        if self.schedule == "jsrl":
            self._record_jsrl()
        else:
            self._record_curriculum(np.unique(j))

    def _record_jsrl(self):
        opened = self.open()
        n, w = int(self.tries[opened].sum()), int(self.wins[opened].sum())
        if n < self.min_episodes or w < self.threshold * n:
            return
        if self.frac[0] <= 0.0:
            self.done[:] = True
        else:
            self.frac[:] = max(0.0, self.frac[0] - self.step)
            self.stage += 1
        self.wins[:] = self.tries[:] = 0

    def _record_curriculum(self, touched):
        for d in touched:
            if self.done[d] or self.dropped[d]:
                continue
            if self.tries[d] >= self.min_episodes and self.wins[d] >= self.threshold * self.tries[d]:
                if self.frac[d] <= 0.0:
                    self.done[d] = True
                else:
                    self.frac[d] = max(0.0, self.frac[d] - self.step)
                    self.stage[d] += 1
                    self.wins[d] = self.tries[d] = 0
            elif self.tries[d] >= self.give_up and self.wins[d] == 0:
                self.dropped[d] = True
