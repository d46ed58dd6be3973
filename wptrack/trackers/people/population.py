"""S2: who is there (ours: the paper tracks a known set of people). The population logic of
:class:`wptrack.trackers.people.tracker.PeopleTracker`, host code on the small evidence map after each frame:

* births: where the motion that no tracked person's rectangle explains covers a person's rectangle better than an
  empty one would, in every camera that sees the ground cell (two at least), for ``BirthConfig.add_seconds``: the
  evidence map of the Probabilistic Occupancy Map's generative model (Fleuret, Berclaz, Lengagne and Fua, PAMI 2008,
  section 4), one birth per frame;
* removal: a person the masks have not shown for ``remove_seconds`` (``hold_seconds`` when it stood still when
  lost), who left the ground the cameras see, or who duplicates another;
* identity: each person's appearance (HSV histograms of its legs and torso) kept over time; a person added near
  where another was lost within ``reid_seconds`` and similar enough takes its id again.

Times are in seconds (sums of the frame intervals).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from wptrack.core.errors import ConfigError, FrameError
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import coverage as kcov
from wptrack.trackers.people.person import WALK_SPEED, PeopleEstimate

log = logging.getLogger("wptrack.trackers.people.tracker")

STILL_SPEED = 0.3
"""A person walking slower than this (metres per second) when the masks lose it is taken to stand still."""
STILL_WINDOW = 1.0
"""Seconds over which a person's ground speed is measured."""
MIN_APPEARANCE_PX = 100
"""Pixels of its own a body part needs in a frame to update a person's appearance (all cameras together)."""
MAX_SPEED = 2.0
"""A brisk walk, metres per second: how far evidence may move between frames and stay the same candidate."""

HOST_ARRAYS = (
    "slot_id",
    "slot_age",
    "slot_miss",
    "slot_close",
    "pending",
    "slot_track",
    "slot_speed",
    "slot_still",
    "slot_app",
    "slot_app_seen",
    "slot_new",
)
"""The population bookkeeping kept on the host, per pool slot (person id, age, seconds unseen and close to another,
the walk's reference point and speed, held while standing, appearance, added last frame) and the pending births."""


class Population:
    """The population half of :class:`~wptrack.trackers.people.tracker.PeopleTracker` and its clock (a mixin: it
    reads the tracker's configuration, pool and evidence-map host copies)."""

    # --- the clock ---------------------------------------------------------------------------------------
    def _set_time(self, timestamp: float | None) -> None:
        """Take dt from ``timestamp`` (seconds) and the previous one; update the device copies when it changes."""
        if timestamp is None:
            return
        t = float(timestamp)
        if not math.isfinite(t):
            raise FrameError(f"frame {self.frames_done}: timestamp {timestamp!r} is not a finite number of seconds")
        last, self._last_timestamp = self._last_timestamp, t
        if last is None:
            return
        if t <= last:
            raise FrameError(
                f"frame {self.frames_done}: timestamp {t:.6f} s is not after the previous one {last:.6f} s"
            )
        self.set_frame_interval(t - last)

    def set_frame_interval(self, dt: float) -> None:
        """Use the frame interval ``dt`` (seconds) from the next frame on: the dynamics' per-frame noise and eq. 6's
        factor (``DynamicsConfig.per_frame``) and the birth and removal clocks. A device fill per changed value, no
        host copy (CUDA graphs read the arrays)."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"frame interval: expected seconds > 0, got {dt!r}")
        if dt == self.frame_dt:
            return
        self.frame_dt = dt
        self.frame_dynamics = sp, sv, al = self.config.dynamics.per_frame(dt)
        self.dt.fill_(dt)
        self.sigma_vel[0:1].fill_(sv[0])
        self.sigma_vel[1:2].fill_(sv[1])
        self.alpha.fill_(al)
        self.decay.fill_(self._decay(dt))
        for p in self.pool:
            p.set_sigma(sp)

    def _decay(self, dt: float) -> float:
        """Factor of an unseen person's velocity over one frame interval ``dt``: exp(-dt / stop_seconds)."""
        return math.exp(-dt / self.config.person.stop_seconds)

    def _elapsed(self, seconds: float, limit: float) -> bool:
        """Whether ``seconds`` (a sum of frame intervals) has reached ``limit``, to half a frame: a time rounds to
        whole frames, and any limit is reached after one frame at a low frame rate."""
        return seconds >= limit - 0.5 * self.frame_dt

    # --- who is there (ours) ---------------------------------------------------------------------------------
    def _cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of the evidence map's cell centres, metres, (ny, nx) each (computed once)."""
        if self._centres is None:
            c = self.config.birth.cell
            xs = self.grid_origin[0] + c * (np.arange(self.nx) + 0.5)
            ys = self.grid_origin[1] + c * (np.arange(self.ny) + 0.5)
            self._centres = tuple(np.meshgrid(xs, ys))
        return self._centres

    def _update_appearance(self, active: list[int]) -> None:
        """Fold this frame's appearance histograms (``kernels.people.coverage.person_histogram_kernel``, the cameras'
        counts added) into each tracked person's exponential average (``BirthConfig.appearance_seconds``); a part needs
        ``MIN_APPEARANCE_PX`` pixels of its own. A person added last frame is first compared with the people lost
        recently (:meth:`_reidentify`)."""
        b = self.config.birth
        counts = self._hist_host.numpy().sum(axis=1)  # (people, parts, bins + 1)
        rate = 1.0 - math.exp(-self.frame_dt / b.appearance_seconds)
        nh, ns = int(kcov.HIST_H), int(kcov.HIST_S)
        for k in active:
            for part in range(counts.shape[1]):
                c = counts[k, part]
                if c[-1] < MIN_APPEARANCE_PX:
                    continue
                h = c[:-1].copy()
                for lo, hi in ((0, nh), (nh, nh + ns), (nh + ns, len(h))):
                    total = h[lo:hi].sum()
                    h[lo:hi] = h[lo:hi] / total if total > 0 else 1.0 / (hi - lo)
                if self.slot_app_seen[k, part]:
                    self.slot_app[k, part] += rate * (h - self.slot_app[k, part])
                else:
                    self.slot_app[k, part] = h
                    self.slot_app_seen[k, part] = True
            if self.slot_new[k]:
                self.slot_new[k] = False
                self._reidentify(k)

    def _similarity(self, a: np.ndarray, seen_a: np.ndarray, b: np.ndarray, seen_b: np.ndarray) -> float:
        """Appearance similarity of two people: the mean Bhattacharyya coefficient of their hue, saturation and value
        histograms over the body parts both have seen (0 when none)."""
        nh, ns = int(kcov.HIST_H), int(kcov.HIST_S)
        values = [
            float(np.sum(np.sqrt(a[p, lo:hi] * b[p, lo:hi])))
            for p in range(a.shape[0])
            if seen_a[p] and seen_b[p]
            for lo, hi in ((0, nh), (nh, nh + ns), (nh + ns, a.shape[1]))
        ]
        return float(np.mean(values)) if values else 0.0

    def _reidentify(self, k: int) -> None:
        """Give the person just added in slot ``k`` the id of a person lost within ``reid_seconds`` and within reach
        (1 m + ``WALK_SPEED`` x the time since) whose appearance is the most similar, if at least
        ``reid_similarity``."""
        b = self.config.birth
        self.lost = [p for p in self.lost if self.clock - p["time"] <= b.reid_seconds]
        if not self.lost or not self.slot_app_seen[k].any():
            return
        xy = self.pool[k].est_host.numpy()[kreduce.EST_MEAN : kreduce.EST_MEAN + 2]
        best, score = None, b.reid_similarity
        for p in self.lost:
            if np.hypot(*(xy - p["xy"])) > 1.0 + WALK_SPEED * (self.clock - p["time"]):
                continue
            sim = self._similarity(self.slot_app[k], self.slot_app_seen[k], p["app"], p["seen"])
            if sim >= score:
                best, score = p, sim
        if best is None:
            return
        self.lost.remove(best)
        log.info("person %d is person %d again (appearance similarity %.2f)", self.slot_id[k], best["id"], score)
        self.slot_id[k] = best["id"]

    def _update_speed(self, k: int, xy: np.ndarray) -> None:
        """The ground speed of slot ``k`` over about the last ``STILL_WINDOW`` seconds (from its estimates)."""
        x0, y0, t0 = self.slot_track[k]
        span = self.clock - t0
        if span > 0:
            self.slot_speed[k] = float(np.hypot(xy[0] - x0, xy[1] - y0)) / span
        if span >= STILL_WINDOW or not np.all(np.isfinite(self.slot_track[k])):
            self.slot_track[k] = (xy[0], xy[1], self.clock)

    def _evidence_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """From this frame's coverage maps (host copies): ``(evidence, free_evidence, births)``, (ny, nx) each.
        ``evidence``: the sum over the cameras that see each cell's person rectangle of the rectangle term of
        :class:`~wptrack.trackers.people.config.PersonConfig` (``(slope f - offset) area``, nats: > 0 where a
        person explains the masks better than nobody); ``free_evidence`` the same for the motion the tracked people
        leave unexplained;
        ``births``: cells of the working area seen by ``min_cameras`` cameras where every camera that sees them
        finds more unexplained motion than an empty rectangle would have (its term > 0); with
        ``BirthConfig.explained == "neutral"`` the terms count only the part of the rectangle the tracked people's
        rectangles leave, and only cameras where that part is at least ``PersonConfig.gate_left`` judge (and count
        towards ``min_cameras``)."""
        slope, offset = self.config.person.slope_offset
        shape = (len(self.rig), self.ny, self.nx)
        cover = self._cover_host.numpy().reshape(shape)
        free = self._free_cover_host.numpy().reshape(shape)
        seen = cover >= 0
        evidence = np.where(seen, (slope * cover - offset) * self.cell_area, 0.0).sum(axis=0)
        if self.config.birth.explained == "empty":
            terms = np.where(seen, (slope * free - offset) * self.cell_area, 0.0)
            judged = seen
        else:  # POM's gain: what the tracked people's rectangles leave of the candidate's
            left = self._free_left_host.numpy().reshape(shape)
            terms = np.where(seen, (slope * free - offset) * self.cell_area * np.maximum(left, 0.0), 0.0)
            judged = seen & (left >= self.config.person.gate_left)
        free_evidence = terms.sum(axis=0)
        births = (judged.sum(axis=0) >= self.min_votes) & np.all(~judged | (terms > 0), axis=0) & self.area_map
        return evidence, free_evidence, births

    def _update_population(self, est: PeopleEstimate, active: list[int], column: np.ndarray) -> None:
        """Remove people without multi-view support, duplicates and people who left; add people where the
        evidence is unexplained for a while. Host code on the small evidence map.

        A person is supported while this frame's masks show it (``PersonEstimate.support`` above
        ``PersonConfig.gate``: the rectangle term of what the other people's rectangles leave, at its position or
        near it)."""
        b = self.config.birth
        dt = self.frame_dt
        _evidence, free_evidence, births = self._evidence_maps()
        gate = self.config.person.gate
        gx, gy = self._cell_centres()
        by_slot = {k: e for k, e in zip(active, est.people, strict=True)}
        for k, e in by_slot.items():
            self._update_speed(k, e.mean[:2])
            if e.support > gate:
                self.slot_miss[k] = 0.0
                self.slot_still[k] = False
            else:
                if self.slot_miss[k] == 0.0:  # lost from sight now: standing (the background model took it)?
                    self.slot_still[k] = self.slot_speed[k] < STILL_SPEED
                self.slot_miss[k] += dt
            limit = b.hold_seconds if self.slot_still[k] else b.remove_seconds
            outside = not self.keep_area.contains(e.mean[:2])
            if self._elapsed(self.slot_miss[k], limit) or outside or not np.all(np.isfinite(e.mean)):
                self._remove(k, est, remember=e.mean[:2] if np.all(np.isfinite(e.mean)) else None)
        # duplicates: two filters on one person
        alive = [k for k in active if self.slot_id[k] >= 0]
        for k in alive:
            close = any(
                np.hypot(*(by_slot[k].mean[:2] - by_slot[j].mean[:2])) < b.merge_distance
                for j in alive
                if j != k and self.slot_id[j] >= 0
            )
            self.slot_close[k] = self.slot_close[k] + dt if close else 0.0
        for k in sorted(alive, key=lambda s: self.slot_age[s]):  # the younger of a pair goes
            if self.slot_id[k] >= 0 and self._elapsed(self.slot_close[k], b.remove_seconds):
                self._remove(k, est)
                for j in alive:
                    self.slot_close[j] = 0.0
        # unexplained evidence -> candidates; at most one person added per frame, the strongest (see BirthConfig)
        free = births.copy()
        for k in range(len(self.pool)):  # people added or kept this frame explain their surroundings
            if self.slot_id[k] >= 0 and k in by_slot:
                e = by_slot[k]
                free &= (gx - e.mean[0]) ** 2 + (gy - e.mean[1]) ** 2 > b.exclusion**2
        candidates = self._blobs(free, free_evidence, gx, gy)
        pending, added = [], False
        reach = max(0.5, MAX_SPEED * dt)  # the same evidence one frame later: within a walk of one frame interval
        for cx, cy, _strength in sorted(candidates, key=lambda c: -c[2]):
            seen = dt
            if len(self.pending):
                dist = np.hypot(self.pending[:, 0] - cx, self.pending[:, 1] - cy)
                j = int(np.argmin(dist))
                if dist[j] < reach:
                    seen = self.pending[j, 2] + dt
            if self._elapsed(seen, b.add_seconds) and not added:
                self._add(np.array([cx, cy]), est)
                added = True
            else:
                pending.append((cx, cy, min(seen, b.add_seconds)))
        self.pending = np.asarray(pending, dtype=np.float64).reshape(-1, 3)

    def _blobs(
        self, free: np.ndarray, votes: np.ndarray, gx: np.ndarray, gy: np.ndarray
    ) -> list[tuple[float, float, float]]:
        """Vote-weighted centroids and total votes of the connected regions of ``free`` cells with at least
        ``min_area`` cells."""
        if not free.any():
            return []
        import cv2

        count, labels, stats, _ = cv2.connectedComponentsWithStats(free.astype(np.uint8), connectivity=8)
        out = []
        for lab in range(1, count):
            if stats[lab, cv2.CC_STAT_AREA] < self.config.birth.min_area:
                continue
            sel = labels == lab
            w = np.maximum(votes[sel].astype(np.float64), 1e-9)
            out.append((float(np.sum(gx[sel] * w) / w.sum()), float(np.sum(gy[sel] * w) / w.sum()), float(w.sum())))
        return out

    def _add(self, xy: np.ndarray, est: PeopleEstimate) -> None:
        free = np.nonzero(self.slot_id < 0)[0]
        if not free.size:
            self.births_refused += 1
            # once a run (a crowd would repeat it every frame); the count goes to run.json (births_refused)
            level = logging.WARNING if self.births_refused == 1 else logging.DEBUG
            log.log(
                level,
                "frame %d: no free slot for a new person at %s: %d people (max_people) are tracked; raise --max-people "
                "(later refusals are counted in run.json, births_refused)",
                est.frame,
                xy.round(2),
                len(self.pool),
            )
            return
        k = int(free[0])
        self.pool[k].spawn(xy, self.frames_done)
        self.slot_xy[k : k + 1].fill_(wp.vec2(float(xy[0]), float(xy[1])))
        self.slot_app_seen[k] = False
        self.slot_new[k] = True
        self.slot_id[k] = self.next_id
        self.slot_alive.assign((self.slot_id >= 0).astype(np.int32))
        self.slot_age[k] = 0
        self.slot_miss[k] = 0
        self.slot_close[k] = 0
        self.slot_track[k] = (xy[0], xy[1], self.clock)
        self.slot_speed[k] = 0.0
        self.slot_still[k] = False
        est.added.append(self.next_id)
        log.info("frame %d: person %d added at (%.2f, %.2f)", est.frame, self.next_id, xy[0], xy[1])
        self.next_id += 1

    def _remove(self, k: int, est: PeopleEstimate, remember: np.ndarray | None = None) -> None:
        """Stop tracking slot ``k``; with ``remember`` (its last ground position) the person may be re-identified
        (:meth:`_reidentify`)."""
        est.removed.append(int(self.slot_id[k]))
        log.info("frame %d: person %d removed", est.frame, self.slot_id[k])
        if remember is not None and self.config.birth.reid_seconds > 0 and self.slot_app_seen[k].any():
            self.lost.append(
                dict(
                    id=int(self.slot_id[k]),
                    time=self.clock,
                    xy=np.array(remember, dtype=np.float64),
                    app=self.slot_app[k].copy(),
                    seen=self.slot_app_seen[k].copy(),
                )
            )
        self.slot_id[k] = -1
        self.slot_alive.assign((self.slot_id >= 0).astype(np.int32))

    def add_person(self, xy: Sequence[float]) -> int:
        """Start tracking a person standing at ``xy`` (ground x, y, metres) now, as if added by the evidence (e.g.
        known initial positions). Returns its id.

        Raises:
            ConfigError: every slot of the pool is taken (``BirthConfig.max_people``).
        """
        if not np.any(self.slot_id < 0):
            raise ConfigError(f"max_people ({len(self.pool)}) people are tracked already")
        est = PeopleEstimate(frame=self.frames_done, people=[], sigma_n=0.0)
        self._add(np.asarray(xy, dtype=np.float64)[:2], est)
        return est.added[0]

    @property
    def tracked_ids(self) -> list[int]:
        """Ids of the people tracked now."""
        return [int(i) for i in self.slot_id if i >= 0]

    # --- checkpoints of the population ------------------------------------------------------------------------
    def population_state(self) -> dict[str, np.ndarray]:
        """:data:`HOST_ARRAYS`, the next id, the births refused, the clock and the people remembered for
        re-identification."""
        state = {f"__{name}__": getattr(self, name).copy() for name in HOST_ARRAYS}
        state["__next_id__"] = np.int64(self.next_id)
        state["__births_refused__"] = np.int64(self.births_refused)
        state["__clock__"] = np.float64(self.clock)
        nparts, nb = self.slot_app.shape[1:]
        state["__lost_id__"] = np.array([p["id"] for p in self.lost], dtype=np.int64)
        state["__lost_time__"] = np.array([p["time"] for p in self.lost], dtype=np.float64)
        state["__lost_xy__"] = np.array([p["xy"] for p in self.lost], dtype=np.float64).reshape(-1, 2)
        state["__lost_app__"] = np.array([p["app"] for p in self.lost], dtype=np.float64).reshape(-1, nparts, nb)
        state["__lost_seen__"] = np.array([p["seen"] for p in self.lost], dtype=bool).reshape(-1, nparts)
        return state

    def load_population_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`population_state`."""
        for name in HOST_ARRAYS:
            setattr(self, name, np.array(state[f"__{name}__"]))
        self.next_id = int(state["__next_id__"])
        # checkpoints written before the count existed have none: 0
        self.births_refused = int(state["__births_refused__"]) if "__births_refused__" in state else 0
        self.clock = float(state["__clock__"])
        self.lost = [
            dict(id=int(i), time=float(t), xy=np.array(xy), app=np.array(app), seen=np.array(seen))
            for i, t, xy, app, seen in zip(
                state["__lost_id__"],
                state["__lost_time__"],
                state["__lost_xy__"],
                state["__lost_app__"],
                state["__lost_seen__"],
                strict=True,
            )
        ]
