#!/usr/bin/env python3
"""A ROS 2-style go-to-goal controller for a differential-drive chair, on rmw_zenoh's wire
format through rmw_node.py (the official Zenoh binding and PyPI rosbags; no ROS 2 install).

    python go_to_goal.py ENDPOINT NAME GOAL_X GOAL_Y [--tolerance 0.15]

Inputs: /map and /NAME/tf_static (transient-local, fetched once), /clock, /NAME/odom and
/NAME/scan. Output: /NAME/cmd_vel, one Twist per tick of the simulation's clock, sent once the
tick's scan (and odom) came (use_sim_time: every decision is made on message stamps, never on
wall time; wall time only notices a lost message and the end of the run).

- Where it is: map -> odom from tf_static composed with odom -> base_link, plus a slow
  correction that pulls the pose towards where the walls of /map say it is (odometry drifts:
  the wheels slip).
- What is around: the walls of /map, and an evidence grid in the map frame of what the scan
  sees. The sensors' frames (tf_static) tell which cone made each ray and so how wide its arc
  is: a narrow beam's return counts fully, a wide cone's far arc little; each ray also sees
  through the cells before its reading, and a cell is an obstacle only when hit often enough
  and as often as seen through (the readings' noise, 0.1 m, is as large as the clearances).
  Scan points the walls of /map explain are left to the map.
- Which way: hybrid A* over (x, y, heading) with the chair's true rectangle (base_link at the
  axle, the body mostly ahead of it): arcs forward, turns in place, short reverses; a hard
  clearance and a cost for low clearance and for unseen cells next to found obstacles;
  guided by a Dijkstra cost-to-go on the grid. When no clear pose lies within the tolerance
  of the goal (the goal is taken), it goes to the nearest clear place, at most 0.45 m off.
  It plans again when a newly found obstacle stands on the path, the chair strays from it,
  or it makes no progress.
- How: tracking with curvature feed-forward and lateral and heading feedback, a heading
  profile for turns in place, speed lowered in turns, near obstacles and at a segment's end;
  commands that make up for the chair's motor filter (out = 0.17 in + 0.83 previous); an
  emergency stop for a reading just ahead of the body. At the goal it answers zero twists
  until the run ends.

It prints `key value` lines at the end (reached, final pose, replans, ...).
"""

import argparse
import heapq
import math
import sys
import threading
import time

import numpy as np

import rmw_node as rmw

# ---------------------------------------------------------------------------------------------
# Geometry helpers


def wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def yaw_of(q):
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def compose(a, b):
    """Pose a (x, y, yaw) then b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2]))


class Body:
    """The footprint in base_link: x from -rear to +front, y within +-half."""

    def __init__(self, front, rear, half):
        self.front, self.rear, self.half = front, rear, half
        step = 0.05
        pts = []
        nx = max(2, int(math.ceil((front + rear) / step)) + 1)
        ny = max(2, int(math.ceil(2 * half / step)) + 1)
        for x in np.linspace(-rear, front, nx):
            pts += [(x, half), (x, -half)]
        for y in np.linspace(-half, half, ny)[1:-1]:
            pts += [(front, y), (-rear, y)]
        # A spine too, so that a thin obstacle never hides inside between samples.
        for x in np.linspace(-rear, front, nx)[1:-1:2]:
            pts.append((x, 0.0))
        self.outline = np.array(pts)  # (K, 2)

    def contains(self, local, margin):
        """Which of the points (N, 2) in the body frame lie in the footprint grown by margin."""
        return (
            (local[..., 0] >= -self.rear - margin)
            & (local[..., 0] <= self.front + margin)
            & (np.abs(local[..., 1]) <= self.half + margin)
        )


# ---------------------------------------------------------------------------------------------
# Grids


def edt(occ, res, cap_m):
    """Euclidean distance (metres) from each cell centre to the nearest occupied cell centre,
    exact up to cap_m (beyond: cap_m). Separable: column distances, then a min over rows."""
    h, w = occ.shape
    cap = int(math.ceil(cap_m / res))
    big = cap + 1
    g = np.empty((h, w), np.float32)
    prev = np.full(w, big, np.float32)
    for r in range(h):
        prev = np.where(occ[r], 0.0, np.minimum(prev + 1.0, big))
        g[r] = prev
    prev = np.full(w, big, np.float32)
    for r in range(h - 1, -1, -1):
        prev = np.where(occ[r], 0.0, np.minimum(prev + 1.0, big))
        g[r] = np.minimum(g[r], prev)
    g2 = g * g
    d2 = g2.copy()
    for dx in range(1, min(cap, w - 1) + 1):
        k = float(dx * dx)
        np.minimum(d2[:, dx:], g2[:, :-dx] + k, out=d2[:, dx:])
        np.minimum(d2[:, :-dx], g2[:, dx:] + k, out=d2[:, :-dx])
    return np.minimum(np.sqrt(d2) * res, cap_m).astype(np.float32)


class World:
    """The static map and what the scan found, on the map's grid."""

    HIT_THRESHOLD = 2.0  # evidence for a cell to be an obstacle (a reading is worth 2)...
    MISS_RATIO = 0.5  # ... and at least this share of the times a ray saw through it
    READING_WEIGHT = 2.0  # one reading's evidence, shared by the rays of its arc
    ARC_FULL_M = 0.12  # an arc longer than this (a wide cone far off) is worth less
    HIT_MAX = 20.0  # evidence is kept bounded (both counts scaled down together)
    EXPLAINED_M = 0.3  # a scan point this near a wall of /map is that wall
    CLEAR_SHORT_M = 0.05  # a ray sees through cells up to this short of its reading
    CLEAR_INF_M = 2.7  # a +inf ray sees through this far at most
    RISK_R = 0.35  # unseen cells this near a found obstacle are risky (it may go on there)

    def __init__(self, grid, hit_range=2.5, sensors=None):
        self.hit_range = hit_range
        self.sensors = np.array(sensors) if sensors else None  # (x, y, yaw) in base_link
        info = grid.info
        self.res = float(info.resolution)
        self.w, self.h = int(info.width), int(info.height)
        self.ox, self.oy = float(info.origin.position.x), float(info.origin.position.y)
        oyaw = yaw_of(info.origin.orientation)
        if abs(oyaw) > 1e-6:
            raise SystemExit("a rotated map origin is not supported")
        data = np.asarray(grid.data, dtype=np.int8).reshape(self.h, self.w)
        self.static = data >= 50
        self.static_edt = edt(self.static, self.res, 1.0)
        # Signed distance to the walls' surface (negative inside), for localizing on them.
        self.sdf = self.static_edt - edt(~self.static, self.res, 1.0)
        self.hits = np.zeros((self.h, self.w), np.float32)
        self.miss = np.zeros((self.h, self.w), np.float32)  # ticks a ray saw through the cell
        self.sensed = np.zeros((self.h, self.w), bool)
        self.seen = np.zeros((self.h, self.w), bool)  # crossed by a ray that saw through it
        self.risk_edt = None
        self.new_cells = []  # (row, col) that turned occupied since the planner last looked
        self.edt = self.static_edt
        self.dirty = False

    def cells(self, xy):
        c = np.floor((xy[..., 0] - self.ox) / self.res).astype(np.int64)
        r = np.floor((xy[..., 1] - self.oy) / self.res).astype(np.int64)
        return r, c

    def inside(self, r, c):
        return (r >= 0) & (r < self.h) & (c >= 0) & (c < self.w)

    def centre(self, r, c):
        return np.stack([self.ox + (c + 0.5) * self.res, self.oy + (r + 0.5) * self.res], axis=-1)

    def clearance(self, xy, field=None):
        """Clearance (metres) at points (..., 2): distance to the nearest occupied cell's edge
        (of field: the walls and found obstacles unless told)."""
        field = self.edt if field is None else field
        r, c = self.cells(xy)
        ok = self.inside(r, c)
        out = np.full(r.shape, -1.0, np.float32)
        out[ok] = field[r[ok], c[ok]] - self.res / 2
        return out

    def integrate(self, pose, angles, ranges, range_max):
        """One scan from base_link at pose (map frame)."""
        valid = ~np.isnan(ranges)
        if not valid.any():
            return
        finite = valid & np.isfinite(ranges) & (ranges > 0.0)
        # A reading near a cone's reach may be nothing at all plus the noise: only readings
        # within HIT_RANGE of base_link mark cells; the rest only clear.
        trusted = finite & (ranges <= self.hit_range)
        # Weight: a narrow beam places its return well; a wide cone's reading is an arc that
        # says only that something is somewhere on it, so the longer the arc the less each
        # of its rays counts. Which sensor made a ray, and how wide its cone is, comes from
        # the sensors' frames (tf_static): a cone's arc is all at one range from its apex,
        # spread round its axis.
        weight = np.zeros(len(ranges), np.float32)
        idx = np.nonzero(finite)[0]
        if len(idx) and self.sensors is not None:
            S = self.sensors
            bx, by = ranges[idx] * np.cos(angles[idx]), ranges[idx] * np.sin(angles[idx])
            beta = np.arctan2(by[:, None] - S[None, :, 1], bx[:, None] - S[None, :, 0]) - S[None, :, 2]
            beta = (beta + np.pi) % (2 * np.pi) - np.pi
            owner = np.argmin(np.abs(beta), axis=1)
            b = beta[np.arange(len(idx)), owner]
            rho = np.hypot(bx - S[owner, 0], by - S[owner, 1])
            w = np.zeros(len(idx), np.float32)
            for k in np.unique(owner):
                sel = owner == k
                n = int(sel.sum())
                width = max(float(b[sel].max() - b[sel].min()), math.radians(1.0))
                # A reading is worth READING_WEIGHT shared by its rays; an arc longer than
                # ARC_FULL_M (a wide cone far away) is worth less the longer it is.
                arc = float(np.median(rho[sel])) * width
                w[sel] = self.READING_WEIGHT / n * min(1.0, (self.ARC_FULL_M / arc) ** 2)
            w[np.abs(b) > math.radians(20)] = 0.0
            weight[idx] = w
        elif len(idx):
            # No sensor frames: a scan from one origin (a laser), every ray a point.
            weight[idx] = self.READING_WEIGHT / 2
        x, y, th = pose
        ang = th + angles
        cos, sin = np.cos(ang), np.sin(ang)
        # Clearing: from the apex of the sensor that made each ray (a cone reads the nearest
        # thing in it: everything nearer is free) up to a little short of the reading; a
        # +inf ray (nothing within the reach) up to CLEAR_INF_M.
        if self.sensors is not None:
            S = self.sensors
            fin_b = np.nonzero(finite)[0]
            inf_b = np.nonzero(valid & ~finite)[0]
            ax_list, ay_list, dx_list, dy_list, ln_list = [], [], [], [], []
            if len(fin_b):
                bx = ranges[fin_b] * np.cos(angles[fin_b])
                by = ranges[fin_b] * np.sin(angles[fin_b])
                beta = np.arctan2(by[:, None] - S[None, :, 1], bx[:, None] - S[None, :, 0]) - S[None, :, 2]
                own = np.argmin(np.abs((beta + np.pi) % (2 * np.pi) - np.pi), axis=1)
                vx, vy = bx - S[own, 0], by - S[own, 1]
                rho = np.hypot(vx, vy)
                ax_list.append(S[own, 0]); ay_list.append(S[own, 1])
                dx_list.append(vx / np.maximum(rho, 1e-9)); dy_list.append(vy / np.maximum(rho, 1e-9))
                ln_list.append(rho - self.CLEAR_SHORT_M)
            if len(inf_b):
                # A +inf bin holds a cone's arc at its reach (range_max less the farthest
                # apex): find the sensor and the point, and clear from the apex towards it.
                a_ = angles[inf_b]
                reach = range_max - float(np.hypot(S[:, 0], S[:, 1]).max())
                ux, uy = np.cos(a_), np.sin(a_)
                proj = ux[:, None] * S[None, :, 0] + uy[:, None] * S[None, :, 1]
                disc = proj ** 2 - (S[None, :, 0] ** 2 + S[None, :, 1] ** 2) + reach ** 2
                tt = proj + np.sqrt(np.maximum(disc, 0.0))
                vx = tt * ux[:, None] - S[None, :, 0]
                vy = tt * uy[:, None] - S[None, :, 1]
                diff = (np.arctan2(vy, vx) - S[None, :, 2] + np.pi) % (2 * np.pi) - np.pi
                own = np.argmin(np.abs(diff), axis=1)
                good = np.abs(diff[np.arange(len(inf_b)), own]) < math.radians(20)
                own = own[good]
                vx, vy = vx[good, own], vy[good, own]
                nv = np.maximum(np.hypot(vx, vy), 1e-9)
                ax_list.append(S[own, 0]); ay_list.append(S[own, 1])
                dx_list.append(vx / nv); dy_list.append(vy / nv)
                ln_list.append(np.full(len(own), max(0.0, min(self.CLEAR_INF_M, reach - 0.3))))
            ax_, ay_ = np.concatenate(ax_list), np.concatenate(ay_list)
            dx_, dy_ = np.concatenate(dx_list), np.concatenate(dy_list)
            ln = np.minimum(np.concatenate(ln_list), range_max)
            keep = ln > 0.08
            if keep.any():
                ax_, ay_, dx_, dy_, ln = ax_[keep], ay_[keep], dx_[keep], dy_[keep], ln[keep]
                n = int(math.ceil(float(ln.max()) / (self.res * 0.8))) + 1
                t = np.linspace(0.0, 1.0, max(n, 2))[None, :]
                d = 0.03 + (ln[:, None] - 0.03) * t
                lx = ax_[:, None] + d * dx_[:, None]
                ly = ay_[:, None] + d * dy_[:, None]
                c_, s_ = math.cos(th), math.sin(th)
                self._seen_through(x + c_ * lx - s_ * ly, y + s_ * lx + c_ * ly)
        else:
            reach = np.where(finite, ranges - self.CLEAR_SHORT_M, np.where(valid, self.CLEAR_INF_M, 0.0))
            sel = np.nonzero(np.minimum(reach, range_max) > 0.1)[0]
            if len(sel):
                n = int(math.ceil(float(reach[sel].max()) / (self.res * 0.8))) + 1
                d = np.minimum(reach[sel], range_max)[:, None] * np.linspace(0.0, 1.0, max(n, 2))[None, :]
                self._seen_through(x + d * cos[sel, None], y + d * sin[sel, None])
        # Hits.
        idx = np.nonzero(trusted)[0]
        if len(idx):
            px = x + ranges[idx] * cos[idx]
            py = y + ranges[idx] * sin[idx]
            r, c = self.cells(np.stack([px, py], -1))
            ok = self.inside(r, c)
            r, c, wgt = r[ok], c[ok], weight[idx][ok]
            explained = self.static_edt[r, c] <= self.EXPLAINED_M
            r, c, wgt = r[~explained], c[~explained], wgt[~explained]
            np.add.at(self.hits, (r, c), wgt)
            # Bounded memory: scale both counts down together once either is large.
            big = np.maximum(self.hits[r, c], self.miss[r, c] * self.MISS_RATIO) > self.HIT_MAX
            if big.any():
                rb, cb = r[big], c[big]
                f = self.HIT_MAX / np.maximum(self.hits[rb, cb], self.miss[rb, cb] * self.MISS_RATIO)
                self.hits[rb, cb] *= f
                self.miss[rb, cb] *= f
        # What changed.
        now = self.occupied()
        changed = now != self.sensed
        if changed.any():
            rr, cc = np.nonzero(changed & now)
            self.new_cells += list(zip(rr.tolist(), cc.tolist()))
            self.sensed = now
            self.dirty = True

    def _seen_through(self, px, py):
        """Counts once each cell the rays' points (px, py) pass through as seen empty."""
        r, c = self.cells(np.stack([px, py], -1))
        ok = self.inside(r, c)
        flat = np.unique(r[ok] * self.w + c[ok])
        rr, cc = flat // self.w, flat % self.w
        self.miss[rr, cc] += 1.0
        self.seen[rr, cc] = True

    def occupied(self):
        """Cells the scan found: hit often enough, and hit at least as often as seen through
        (a short reading's noise puts hits in front of a face; the readings that reach the
        face see through them)."""
        return (self.hits >= self.HIT_THRESHOLD) & (self.hits >= self.MISS_RATIO * self.miss)

    def sdf_at(self, xy):
        """The walls' signed distance at points (N, 2), interpolated."""
        u = (xy[:, 0] - self.ox) / self.res - 0.5
        v = (xy[:, 1] - self.oy) / self.res - 0.5
        i0, j0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - i0, v - j0
        i0 = np.clip(i0, 0, self.w - 2)
        j0 = np.clip(j0, 0, self.h - 2)
        f = self.sdf
        return ((1 - fu) * (1 - fv) * f[j0, i0] + fu * (1 - fv) * f[j0, i0 + 1]
                + (1 - fu) * fv * f[j0 + 1, i0] + fu * fv * f[j0 + 1, i0 + 1])

    def wall_fix(self, pose, angles, ranges):
        """How far the pose seems off the walls of /map, from this scan: (dx, dy, n). Each
        sensor's reading gives one residual: the point of its arc that touches a wall."""
        if self.sensors is None:
            return 0.0, 0.0, 0
        fin = np.nonzero(np.isfinite(ranges) & (ranges > 0.0) & (ranges <= 2.0))[0]
        if not len(fin):
            return 0.0, 0.0, 0
        S = self.sensors
        bx, by = ranges[fin] * np.cos(angles[fin]), ranges[fin] * np.sin(angles[fin])
        beta = np.arctan2(by[:, None] - S[None, :, 1], bx[:, None] - S[None, :, 0]) - S[None, :, 2]
        owner = np.argmin(np.abs((beta + np.pi) % (2 * np.pi) - np.pi), axis=1)
        x, y, th = pose
        c, s_ = math.cos(th), math.sin(th)
        p = np.stack([x + c * bx - s_ * by, y + s_ * bx + c * by], -1)
        d = self.sdf_at(p)
        # Near a wall, and nothing the scan found near it (that reading may be of that).
        r, cc = self.cells(p)
        ok = self.inside(r, cc)
        near_wall = ok & (np.abs(d) <= 0.2)
        if self.edt is not None:
            near_wall &= np.where(ok, self.edt[np.clip(r, 0, self.h - 1), np.clip(cc, 0, self.w - 1)]
                                  >= self.static_edt[np.clip(r, 0, self.h - 1), np.clip(cc, 0, self.w - 1)] - 1e-3, False)
        A = np.zeros((2, 2))
        b = np.zeros(2)
        n_used = 0
        h = self.res
        for k in np.unique(owner[near_wall]):
            sel = np.nonzero(near_wall & (owner == k))[0]
            i = sel[np.argmin(d[sel])]
            q = p[i : i + 1]
            gx = (self.sdf_at(q + [[h, 0]]) - self.sdf_at(q - [[h, 0]]))[0]
            gy = (self.sdf_at(q + [[0, h]]) - self.sdf_at(q - [[0, h]]))[0]
            g = math.hypot(gx, gy)
            if g < 1e-6:
                continue
            n = np.array([gx / g, gy / g])
            res = float(d[i])
            wgt = 1.0 / (1.0 + (res / 0.1) ** 2)
            A += wgt * np.outer(n, n)
            b += wgt * res * n
            n_used += 1
        if n_used == 0:
            return 0.0, 0.0, 0
        # The pose moves by delta so that the points land on the walls: minimise
        # sum (res + n.delta)^2 (a little damping for the direction no wall constrains).
        delta = -np.linalg.solve(A + 0.3 * np.eye(2), b)
        return float(delta[0]), float(delta[1]), n_used

    def mark(self, pose, angles, ranges):
        """Points the chair is sure of (an emergency stop's): occupied at once."""
        x, y, th = pose
        px, py = x + ranges * np.cos(th + angles), y + ranges * np.sin(th + angles)
        r, c = self.cells(np.stack([px, py], -1))
        ok = self.inside(r, c)
        self.hits[r[ok], c[ok]] = np.maximum(self.hits[r[ok], c[ok]], self.HIT_THRESHOLD)
        now = self.occupied()
        if (now != self.sensed).any():
            self.sensed = now
            self.dirty = True

    def refresh(self):
        """The distance field of walls and sensed obstacles, for the planner."""
        if self.dirty or self.edt is None:
            occ = self.static | self.sensed
            self.edt = edt(occ, self.res, 1.0)
            self.dirty = False
            # Risky: never seen through, and near something the scan found. An obstacle
            # the sensors caught a face of goes on behind it; the planner keeps away from
            # such cells when it can (a cost, not a wall).
            self.risk_edt = None
            if self.sensed.any():
                rr, cc = np.nonzero(self.sensed)
                m = int(math.ceil((self.RISK_R + 0.5) / self.res))
                r0, r1 = max(0, rr.min() - m), min(self.h, rr.max() + m + 1)
                c0, c1 = max(0, cc.min() - m), min(self.w, cc.max() + m + 1)
                near = edt(self.sensed[r0:r1, c0:c1], self.res, self.RISK_R + 0.05) <= self.RISK_R
                risky = near & ~self.seen[r0:r1, c0:c1] & ~occ[r0:r1, c0:c1]
                if risky.any():
                    self.risk_edt = np.full((self.h, self.w), 1.0, np.float32)
                    self.risk_edt[r0:r1, c0:c1] = edt(risky, self.res, 0.4)
        self.new_cells = []


# ---------------------------------------------------------------------------------------------
# Planning


class Planner:
    NB = 72  # heading bins (5 degrees)
    STEP = 0.15  # metres per arc
    XY_KEY = 0.1
    C_MIN = 0.05  # hard clearance, metres (beyond the cells' half size)
    C_SOFT = 0.25  # clearance below this costs
    W_CLEAR = 6.0
    W_RISK = 4.0
    R_SOFT = 0.15
    TURN_COST = 0.06  # per 5 degrees turned in place
    REVERSE_FACTOR = 6.0
    SWITCH_COST = 0.15  # a change between forward, reverse and turning in place
    H_WEIGHT = 1.8
    # A search's budget, in expansions (about 1.5 s on an idle core here), never in wall time:
    # the same inputs give the same plan on a loaded machine, so a lock-step run is the same
    # run; the run's lock-step deadline must leave room for it (`iwsim run --deadline-ms`).
    MAX_EXPANSIONS = 15000
    BEST_G = 0.03
    MAX_GOAL_SHIFT = 0.45
    ESCAPE_M = 0.45  # how far from a too-near start the path may stay that near
    BACKUP_M = 0.3  # the recovery's straight reverse
    SEARCH_REVERSE = False
    HEAD_ERR = 0.015  # radians of heading error the clearance allows for

    def __init__(self, body):
        self.body = body
        nb, L = self.NB, self.STEP
        dth = 2 * math.pi / nb
        # Motions: (kind, heading bins turned, samples as (dx, dy, dtheta) in the start frame).
        motions = []
        for k in (0, 1, -1, 2, -2, 3, -3):
            samples = []
            for f in (1 / 3, 2 / 3, 1.0):
                a = k * dth * f
                s = L * f
                if k == 0:
                    samples.append((s, 0.0, 0.0))
                else:
                    R = L / (k * dth)
                    samples.append((R * math.sin(a), R * (1 - math.cos(a)), a))
            motions.append(("F", k, samples, L))
        motions.append(("R", 0, [(-L * f, 0.0, 0.0) for f in (1 / 3, 2 / 3, 1.0)], L))
        for k in (2, -2):
            motions.append(("T", k, [(0.0, 0.0, k * dth * f) for f in (1 / 3, 2 / 3, 1.0)], 0.0))
        self.motions = motions
        # The search drives forward and turns in place; reversing (one wide sonar looks back)
        # is left to the recovery's short straight back-up.
        self.searchable = np.array([mo[0] != "R" or self.SEARCH_REVERSE for mo in motions])
        # Per start heading bin: the outline of every sample pose, as offsets from the start.
        K = len(body.outline)
        S = 3
        self.offsets = np.zeros((nb, len(motions), S * K, 2), np.float32)
        self.ends = np.zeros((nb, len(motions), 3), np.float64)
        for h in range(nb):
            th = h * dth
            c, s = math.cos(th), math.sin(th)
            for m, (_, k, samples, _) in enumerate(motions):
                for j, (dx, dy, da) in enumerate(samples):
                    px, py = c * dx - s * dy, s * dx + c * dy
                    a = th + da
                    ca, sa = math.cos(a), math.sin(a)
                    o = body.outline
                    self.offsets[h, m, j * K : (j + 1) * K, 0] = px + ca * o[:, 0] - sa * o[:, 1]
                    self.offsets[h, m, j * K : (j + 1) * K, 1] = py + sa * o[:, 0] + ca * o[:, 1]
                dx, dy, _ = samples[-1]
                self.ends[h, m] = (c * dx - s * dy, s * dx + c * dy, k)
        self.outline_at = np.zeros((nb, K, 2), np.float32)
        for h in range(nb):
            th = h * dth
            c, s = math.cos(th), math.sin(th)
            o = body.outline
            self.outline_at[h, :, 0] = c * o[:, 0] - s * o[:, 1]
            self.outline_at[h, :, 1] = s * o[:, 0] + c * o[:, 1]
        # Heading error turns the body round the axle: a point r from it moves r * HEAD_ERR.
        # Clearance is counted less that, so the nose (0.9 m out) keeps a larger margin.
        self.extra = (self.HEAD_ERR * np.hypot(body.outline[:, 0], body.outline[:, 1])).astype(np.float32)
        self.extra3 = np.tile(self.extra, S)
        self.last_stats = {}

    def sample(self, x, y, h, m, f):
        """The pose a fraction f along motion m from (x, y, heading bin h), and the motion's
        curvature (heading change per metre along the heading; None for a turn in place)."""
        kind, k, _, L = self.motions[m]
        dth = 2 * math.pi / self.NB
        th = h * dth
        c, s_ = math.cos(th), math.sin(th)
        if kind == "T":
            return (x, y, wrap(th + k * dth * f)), None
        if kind == "R":
            return (x - c * L * f, y - s_ * L * f, th), 0.0
        if k == 0:
            return (x + c * L * f, y + s_ * L * f, th), 0.0
        R = L / (k * dth)
        a = k * dth * f
        dx, dy = R * math.sin(a), R * (1 - math.cos(a))
        return (x + c * dx - s_ * dy, y + s_ * dx + c * dy, wrap(th + a)), k * dth / L

    def goal_radius(self, world, goal, tolerance):
        """The smallest radius, from the tolerance up to MAX_GOAL_SHIFT, within which the
        chair can stand clear (any heading) with its axle: None if there is none."""
        step = 0.05
        n = int(math.ceil(self.MAX_GOAL_SHIFT / step))
        g = np.arange(-n, n + 1) * step
        gx, gy = np.meshgrid(g, g)
        d = np.hypot(gx, gy).ravel()
        keep = d <= self.MAX_GOAL_SHIFT + 1e-9
        px, py, d = goal[0] + gx.ravel()[keep], goal[1] + gy.ravel()[keep], d[keep]
        best = None
        for h in range(0, self.NB, 2):
            o = self.outline_at[h]
            pts = np.stack([px[:, None] + o[None, :, 0], py[:, None] + o[None, :, 1]], -1)
            cl = world.clearance(pts)
            if world.risk_edt is not None:
                # Where to stop, unseen cells next to a found obstacle count as that obstacle
                # (a goal beside a half-seen box is not a place to drive into to find out).
                cl = np.minimum(cl, world.clearance(pts, world.risk_edt))
            ok = (cl - self.extra[None, :]).min(axis=1) >= self.C_MIN
            if ok.any():
                r = float(d[ok].min())
                best = r if best is None else min(best, r)
        if best is None:
            return None
        return max(tolerance, best)

    def backup(self, world, pose):
        """Steps of a straight reverse of up to BACKUP_M from pose that never comes nearer to
        anything than the chair is now (nor nearer than C_MIN to what it is not near)."""
        m = next(i for i, mo in enumerate(self.motions) if mo[0] == "R")
        h = self.bin_of(pose[2])
        th = h * 2 * math.pi / self.NB
        now = self.pose_clearance(world, (pose[0], pose[1], th))
        steps, x, y = [], pose[0], pose[1]
        for _ in range(int(round(self.BACKUP_M / self.STEP))):
            ok = True
            for f in (1 / 3, 2 / 3, 1.0):
                q = (x - f * self.STEP * math.cos(th), y - f * self.STEP * math.sin(th), th)
                if self.pose_clearance(world, q) < min(self.C_MIN, now) - 1e-3:
                    ok = False
            if not ok:
                break
            steps.append((x, y, h, m, now))
            x, y = x - self.STEP * math.cos(th), y - self.STEP * math.sin(th)
        return steps

    def bin_of(self, th):
        return int(round(wrap(th) / (2 * math.pi / self.NB))) % self.NB

    def pose_clearance(self, world, pose):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        o = self.body.outline
        pts = np.stack([pose[0] + c * o[:, 0] - s * o[:, 1], pose[1] + s * o[:, 0] + c * o[:, 1]], -1)
        return float((world.clearance(pts) - self.extra).min())

    # The cost-to-go on a coarse grid, for the axle: a heuristic, and which goal is reachable.
    def cost_to_go(self, world, goal, start, tolerance):
        f = 2  # coarse cells per side of a fine one
        res = world.res * f
        H, W = world.h // f, world.w // f
        e = world.edt[: H * f, : W * f].reshape(H, f, W, f).max(axis=(1, 3))
        # Optimistic: the axle needs only the body's half width (a turn in place needs more,
        # which the hybrid search checks).
        free = e - world.res / 2 > self.body.half + 0.01 - res * 0.7
        gx, gy = int((goal[0] - world.ox) / res), int((goal[1] - world.oy) / res)
        sx, sy = int((start[0] - world.ox) / res), int((start[1] - world.oy) / res)
        yy, xx = np.mgrid[0:H, 0:W]
        cx, cy = world.ox + (xx + 0.5) * res, world.oy + (yy + 0.5) * res
        dgoal = np.hypot(cx - goal[0], cy - goal[1])
        # Seeds: free cells within the tolerance of the goal; if none, the free cells nearest
        # the goal (the goal itself is taken: the nearest place to it will do).
        seeds = free & (dgoal <= max(tolerance, res * 0.75))
        blocked = not seeds.any()
        if blocked:
            cand = np.where(free, dgoal, np.inf)
            near = cand.min()
            if not np.isfinite(near) or near > 1.5:
                return None, None, True
            seeds = free & (cand <= near + res * 0.75)
            subst = near
        else:
            subst = 0.0
        # Wavefront in a box round start and goal first; the whole map if that fails.
        for margin in (4.0, None):
            if margin is None:
                r0, r1, c0, c1 = 0, H, 0, W
            else:
                m = int(margin / res)
                r0, r1 = max(0, min(gy, sy) - m), min(H, max(gy, sy) + m + 1)
                c0, c1 = max(0, min(gx, sx) - m), min(W, max(gx, sx) + m + 1)
            fr = free[r0:r1, c0:c1]
            # Per-cell cost, as the search's clearance cost sees the axle's side clearance.
            cl = e[r0:r1, c0:c1] - world.res / 2 - self.body.half
            pen = 1.0 + self.W_CLEAR * np.clip((self.C_SOFT - cl) / self.C_SOFT, 0.0, 1.0) ** 2
            d = np.where(seeds[r0:r1, c0:c1], dgoal[r0:r1, c0:c1], np.inf).astype(np.float64)
            d[~fr] = np.inf
            diag = math.sqrt(2)
            moves = [(1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0),
                     (1, 1, diag), (-1, -1, diag), (1, -1, diag), (-1, 1, diag)]
            step_cost = {}
            for dr, dc, ln in moves:
                # Cost of entering cell (r, c) from (r - dr, c - dc).
                a = pen[max(0, dr) : pen.shape[0] + min(0, dr), max(0, dc) : pen.shape[1] + min(0, dc)]
                b = pen[max(0, -dr) : pen.shape[0] + min(0, -dr), max(0, -dc) : pen.shape[1] + min(0, -dc)]
                step_cost[(dr, dc)] = res * ln * (a + b) / 2
            for _ in range(8 * (r1 - r0 + c1 - c0)):
                n = d.copy()
                for dr, dc, ln in moves:
                    dst = n[max(0, dr) : n.shape[0] + min(0, dr), max(0, dc) : n.shape[1] + min(0, dc)]
                    src = d[max(0, -dr) : d.shape[0] + min(0, -dr), max(0, -dc) : d.shape[1] + min(0, -dc)]
                    np.minimum(dst, src + step_cost[(dr, dc)], out=dst)
                n[~fr] = np.inf
                if np.array_equal(n, d):
                    break
                d = n
            full = np.full((H, W), np.inf)
            full[r0:r1, c0:c1] = d
            # The start's neighbourhood must be reached (the start itself may be in an
            # inflated cell: look round it).
            rs = slice(max(0, sy - 3), sy + 4)
            cs = slice(max(0, sx - 3), sx + 4)
            if np.isfinite(full[rs, cs]).any():
                return (full, res, (world.ox, world.oy)), subst, blocked
        return None, None, blocked

    def plan(self, world, start, goal, tolerance, escape_m=None):
        """A path from start (x, y, yaw) to within tolerance of goal, and what it reaches:
        (steps, "goal" | "nearest" | "progress"), or (None, why). A step is (x, y, heading
        bin, motion, clearance), a motion from the pose given. "nearest": the goal is taken,
        the path ends at the nearest clear place (within MAX_GOAL_SHIFT); "progress": no way
        found within the budget, the path goes as far as the search got."""
        t0 = time.monotonic()
        escape_m = self.ESCAPE_M if escape_m is None else escape_m
        # Where to stop: within the tolerance of the goal, or, when no pose there is clear
        # (the goal itself is taken), as near to it as a clear pose can be.
        reach_r = self.goal_radius(world, goal, tolerance)
        if reach_r is None:
            self.last_stats = {"result": "goal taken", "within": self.MAX_GOAL_SHIFT}
            return None, "taken"
        blocked = reach_r > tolerance
        accept = min(reach_r + 0.1, self.MAX_GOAL_SHIFT) if blocked else reach_r
        self.accept = accept
        ctg, _, _ = self.cost_to_go(world, goal, start, accept)
        if ctg is None:
            self.last_stats = {"result": "no cost-to-go", "accept": round(accept, 3)}
            return None, "none"
        field, cres, (cox, coy) = ctg
        H, W = field.shape

        def heur(x, y):
            c, r = int((x - cox) / cres), int((y - coy) / cres)
            if 0 <= r < H and 0 <= c < W:
                v = field[r, c]
                if np.isfinite(v):
                    return v
                # In an inflated cell (near an obstacle): the best neighbour plus the way there.
                rs, cs = slice(max(0, r - 2), r + 3), slice(max(0, c - 2), c + 3)
                v = field[rs, cs].min()
                return v + 2 * cres if np.isfinite(v) else 1e3
            return 1e3

        nb = self.NB
        dth = 2 * math.pi / nb
        h0 = self.bin_of(start[2])
        sx, sy = start[0], start[1]
        start_clear = self.pose_clearance(world, (sx, sy, h0 * dth))
        # x, y, heading bin, parent, kind, clearance, motion, metres from the start
        nodes = [(sx, sy, h0, None, None, start_clear, None, 0.0)]
        g = {self._key(sx, sy, h0): 0.0}
        openq = [(self.H_WEIGHT * heur(sx, sy), 0.0, 0)]
        h_start = heur(sx, sy)
        best = (math.hypot(sx - goal[0], sy - goal[1]), 0)
        best_h = (h_start, 0)
        best_g = 0.0
        expansions = 0
        found = None
        edt_ = world.edt
        risk_ = world.risk_edt
        half = world.res / 2
        extra3 = self.extra3
        hh, ww = world.h, world.w
        inv = 1.0 / world.res
        while openq:
            f, gc, i = heapq.heappop(openq)
            x, y, h, parent, kind, clear, _, dist = nodes[i]
            key = self._key(x, y, h)
            if g.get(key, math.inf) < gc - 1e-9:
                continue
            dgoal = math.hypot(x - goal[0], y - goal[1])
            # The nearest the search gets, a simple way there preferred to a slightly nearer
            # one after a tangle of turns.
            if dgoal + self.BEST_G * gc < best[0] + self.BEST_G * best_g:
                best, best_g = (dgoal, i), gc
            hv = f - gc
            if hv < best_h[0] and kind != "R":
                best_h = (hv, i)
            if dgoal <= accept:
                found = i
                break
            expansions += 1
            if expansions > self.MAX_EXPANSIONS:
                break
            pts = self.offsets[h]  # (M, S*K, 2)
            cc = np.floor((pts[..., 0] + (x - world.ox)) * inv).astype(np.int64)
            rr = np.floor((pts[..., 1] + (y - world.oy)) * inv).astype(np.int64)
            ok = (rr >= 0) & (rr < hh) & (cc >= 0) & (cc < ww)
            np.clip(rr, 0, hh - 1, out=rr)
            np.clip(cc, 0, ww - 1, out=cc)
            cl = np.where(ok, edt_[rr, cc] - half - extra3, -1.0).min(axis=1)
            if risk_ is not None:
                rk = (risk_[rr, cc] - half).min(axis=1)
                rpen = self.W_RISK * np.clip((self.R_SOFT - rk) / self.R_SOFT, 0.0, 1.0) ** 2
            else:
                rpen = np.zeros(len(cl))
            # Starting too near something (noise, a late find), the first moves may stay as
            # near as the start, never nearer; then the path keeps C_MIN.
            need = min(self.C_MIN, clear - 1e-3) if dist < escape_m else self.C_MIN
            ends = self.ends[h]
            for m in np.nonzero((cl >= need) & self.searchable)[0]:
                mkind, k, _, length = self.motions[m]
                c_m = float(cl[m])
                nx, ny = x + ends[m, 0], y + ends[m, 1]
                nh = (h + k) % nb
                pen = 1.0 + self.W_CLEAR * max(0.0, (self.C_SOFT - c_m) / self.C_SOFT) ** 2 + float(rpen[m])
                if mkind == "F":
                    cost = length * pen * (1.0 + 0.3 * abs(k))
                elif mkind == "R":
                    cost = length * pen * self.REVERSE_FACTOR
                else:
                    cost = self.TURN_COST * abs(k) * pen
                if kind is not None and kind != mkind:
                    cost += self.SWITCH_COST
                ng = gc + cost
                nkey = self._key(nx, ny, nh)
                if ng < g.get(nkey, math.inf) - 1e-9:
                    g[nkey] = ng
                    nodes.append((nx, ny, nh, i, mkind, c_m, int(m), dist + max(length, 0.05)))
                    heapq.heappush(openq, (ng + self.H_WEIGHT * heur(nx, ny), ng, len(nodes) - 1))
        partial = None
        if found is None:
            # The nearest the search came, if it is near enough to be worth it.
            if best[0] <= self.MAX_GOAL_SHIFT and best[1] != 0:
                found, partial = best[1], "nearest"
            elif best[0] <= accept + 0.35 and best[1] != 0:
                found, partial = best[1], "progress"
            elif best_h[1] != 0 and best_h[0] <= self.H_WEIGHT * (h_start - 1.0):
                # No way found in the time: go as far as the search got towards the goal
                # (at least a metre nearer by the cost-to-go), and plan again from there.
                found, partial = best_h[1], "progress"
            else:
                self.last_stats = {
                    "result": "none",
                    "expansions": expansions,
                    "best": round(best[0], 3),
                    "ms": round(1000 * (time.monotonic() - t0)),
                }
                return None, "none"
        steps = []
        i = found
        while nodes[i][3] is not None:
            x, y, h, parent, kind, clear, m, _ = nodes[i]
            px, py, ph = nodes[parent][:3]
            steps.append((px, py, ph, m, clear))
            i = parent
        steps.reverse()
        path = steps
        self.last_stats = {
            "result": partial or "ok",
            "accept": round(accept, 3),
            "expansions": expansions,
            "steps": len(path),
            "kinds": "".join(self.motions[q[3]][0] for q in path),
            "ms": round(1000 * (time.monotonic() - t0)),
            "blocked": blocked,
        }
        return path, partial or ("nearest" if blocked else "goal")

    def _key(self, x, y, h):
        return (int(math.floor(x / self.XY_KEY)), int(math.floor(y / self.XY_KEY)), h)


# ---------------------------------------------------------------------------------------------
# Following


class Follower:
    """Tracks a planned path: segments of one kind of motion each (arcs forward, straight
    back, turns in place), sampled densely with their curvature."""

    K_Y = 6.0  # lateral error gain, 1/m^2
    K_TH = 3.5  # heading error gain, 1/m
    DECEL = 0.5  # m/s^2, for stopping at a segment's end
    ALPHA = 1.5  # rad/s^2, for stopping a turn in place
    W_MAX = 1.0

    def __init__(self, steps, planner, v_max):
        self.v_max = v_max
        segs = []
        for (x, y, h, m, clear) in steps:
            kind = planner.motions[m][0]
            n = 1 if kind == "T" else 5
            poses, curv = [], []
            for j in range(n + 1):
                p, c = planner.sample(x, y, h, m, j / n)
                poses.append(p)
                curv.append(c if c is not None else 0.0)
            if kind == "T":
                kind = "T+" if planner.motions[m][1] > 0 else "T-"
            if segs and segs[-1]["kind"] == kind:
                seg = segs[-1]
                seg["poses"] += poses[1:]
                seg["curv"] += curv[1:]
                seg["clear"] += [clear] * n
            else:
                segs.append({"kind": kind, "poses": poses, "curv": curv, "clear": [clear] * (n + 1)})
        for seg in segs:
            P = np.array(seg["poses"])
            seg["P"] = P
            seg["K"] = np.array(seg["curv"])
            seg["s"] = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(P[:, 0]), np.diff(P[:, 1])))])
        self.segs = segs
        self.k = 0
        self.j = 0
        self.err = (0.0, 0.0)

    def done(self):
        return self.k >= len(self.segs)

    def remaining_poses(self):
        if self.done():
            return np.zeros((0, 3))
        parts = [self.segs[self.k]["P"][self.j :]] + [seg["P"] for seg in self.segs[self.k + 1 :]]
        return np.concatenate(parts)

    def _next(self):
        self.k += 1
        self.j = 0

    def command(self, pose, v_meas, w_meas, clearance_here):
        """The wanted (v, w) this tick and a word for the log."""
        while not self.done():
            seg = self.segs[self.k]
            kind, P = seg["kind"], seg["P"]
            if kind[0] == "T":
                # Through each planned heading in turn, the way the plan turns (the short way
                # to the last one could swing the body the other way, into what the plan
                # went round).
                turn = 1.0 if kind == "T+" else -1.0
                n = len(P) - 1
                while self.j < n:
                    e = wrap(P[self.j + 1, 2] - pose[2])
                    if turn * e < math.radians(1.5):
                        self.j += 1
                    else:
                        break
                if self.j >= n:
                    if abs(w_meas) < 0.12:
                        self._next()
                        continue
                    return 0.0, 0.0, "T-stop"
                e = wrap(P[self.j + 1, 2] - pose[2])
                left = abs(e) + (n - self.j - 1) * abs(wrap(P[1, 2] - P[0, 2]))
                w = turn * min(self.W_MAX, math.sqrt(2 * self.ALPHA * left))
                return 0.0, w, kind
            sign = 1.0 if kind == "F" else -1.0
            # The nearest reference pose, never going back.
            lo, hi = self.j, min(len(P), self.j + 12)
            d = np.hypot(P[lo:hi, 0] - pose[0], P[lo:hi, 1] - pose[1])
            j = lo + int(np.argmin(d))
            self.j = j
            rx, ry, rth = P[j]
            c, s_ = math.cos(rth), math.sin(rth)
            ex = c * (pose[0] - rx) + s_ * (pose[1] - ry)
            ey = -s_ * (pose[0] - rx) + c * (pose[1] - ry)
            eth = wrap(pose[2] - rth)
            # Distance left, along the direction of motion.
            rem = seg["s"][-1] - seg["s"][j] - sign * ex
            if rem < 0.015:
                if abs(v_meas) < 0.05:
                    self._next()
                    continue
                return 0.0, 0.0, "stop"
            kappa = float(seg["K"][j])
            v = self.v_max
            v = min(v, 0.45 / (1.0 + 1.2 * abs(kappa)))
            v = min(v, 0.1 + 1.5 * max(0.0, clearance_here - 0.03))
            if kind == "R":
                v = min(v, 0.2)
            v = min(v, max(0.04, math.sqrt(2 * self.DECEL * max(rem - 0.01, 0.0))))
            v *= sign
            w = v * kappa - self.K_Y * v * ey - self.K_TH * abs(v) * eth
            w = max(-self.W_MAX, min(self.W_MAX, w))
            self.err = (ey, eth)
            return v, w, kind
        return 0.0, 0.0, "done"


# ---------------------------------------------------------------------------------------------
# The node


class Inbox:
    """What the Zenoh threads hand the control loop: each scan with the odom of its tick."""

    def __init__(self):
        self.cv = threading.Condition()
        self.odom = {}  # stamp (ns) -> Odometry
        self.scans = []  # (stamp ns, LaserScan)
        self.clock_ns = None
        self.clock_count = 0
        self.last_clock_wall = None
        self.driver_gone = False

    @staticmethod
    def stamp(h):
        return int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec)

    def on_clock(self, msg, ok):
        with self.cv:
            self.clock_ns = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)
            self.clock_count += 1
            self.last_clock_wall = time.monotonic()
            self.cv.notify_all()

    def on_driver_gone(self):
        with self.cv:
            self.driver_gone = True
            self.cv.notify_all()

    def on_odom(self, msg, ok):
        with self.cv:
            self.odom[self.stamp(msg.header)] = msg
            if len(self.odom) > 50:
                for k in sorted(self.odom)[:-20]:
                    del self.odom[k]
            self.cv.notify_all()

    def on_scan(self, msg, ok):
        with self.cv:
            self.scans.append((self.stamp(msg.header), msg))
            self.cv.notify_all()


def path_clear(planner, world, follower):
    """Whether the rest of the path keeps its clearance in the current grid (the first few
    centimetres may be as tight as where the chair stands)."""
    rest = follower.remaining_poses()
    if len(rest) <= 3:
        return True
    rest = rest[3::2]
    o = planner.body.outline
    c, s = np.cos(rest[:, 2])[:, None], np.sin(rest[:, 2])[:, None]
    px = rest[:, 0:1] + c * o[None, :, 0] - s * o[None, :, 1]
    py = rest[:, 1:2] + s * o[None, :, 0] + c * o[None, :, 1]
    cl = (world.clearance(np.stack([px, py], -1)) - planner.extra[None, :]).min(axis=1)
    return bool((cl >= planner.C_MIN - 0.035).all())


def fetch_latched(node, topic, typename, deadline):
    while time.monotonic() < deadline:
        got = node.latched(topic, typename, timeout=5.0)
        if got:
            return got[0]
        time.sleep(0.2)
    return None


def sensor_frames(tf_msg, base="base_link"):
    """The frames fixed on base_link (the proximity sensors): x, y, yaw each."""
    out = []
    for t in tf_msg.transforms:
        if t.header.frame_id.lstrip("/") == base:
            tr = t.transform.translation
            out.append((tr.x, tr.y, yaw_of(t.transform.rotation)))
    return out


def map_to_odom(tf_msg, log):
    """map -> odom from tf_static (composed through any chain of static frames)."""
    edges = {}
    for t in tf_msg.transforms:
        tr, q = t.transform.translation, t.transform.rotation
        edges[t.child_frame_id.lstrip("/")] = (t.header.frame_id.lstrip("/"), (tr.x, tr.y, yaw_of(q)))
    pose, frame = (0.0, 0.0, 0.0), "odom"
    chain = []
    while frame != "map":
        if frame not in edges or len(chain) > 10:
            log("no map -> odom in tf_static: taking odom as the map frame")
            return (0.0, 0.0, 0.0)
        parent, tfm = edges[frame]
        chain.append(tfm)
        frame = parent
    for tfm in chain:  # odom's parent first ... : compose outward
        pose = compose(tfm, pose)
    return pose


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("endpoint", help="Zenoh router, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("name", help="the chair's namespace")
    ap.add_argument("goal_x", type=float)
    ap.add_argument("goal_y", type=float)
    ap.add_argument("--tolerance", type=float, default=0.15, help="metres, on the axle (base_link)")
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--max-speed", type=float, default=0.45, help="m/s")
    ap.add_argument(
        "--footprint", default="0.88,0.22,0.325", help="front,rear,half-width of the body round base_link, metres"
    )
    ap.add_argument("--hit-range", type=float, default=2.5,
                    help="scan readings farther than this (m) only clear: near a cone's reach a noisy 'nothing' reads as a return")
    ap.add_argument("--wall-fix", type=float, default=0.05,
                    help="share of the offset to /map's walls the pose takes each tick (0: odometry alone)")
    ap.add_argument("--debug-dir", help="write each plan's grid, the scans and a per-tick log there (development)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    args = ap.parse_args()
    goal = (args.goal_x, args.goal_y)
    debug_dir = args.debug_dir
    front, rear, half = (float(v) for v in args.footprint.split(","))
    body = Body(front, rear, half)

    def log(*a):
        if not args.quiet:
            print("#", *a, file=sys.stderr, flush=True)

    session = rmw.open_session(args.endpoint)
    node = rmw.Node(session, args.domain, "/", "go_to_goal")
    ns = f"/{args.name}"
    deadline = time.monotonic() + 60
    grid = fetch_latched(node, "/map", "nav_msgs/msg/OccupancyGrid", deadline)
    statics = fetch_latched(node, f"{ns}/tf_static", "tf2_msgs/msg/TFMessage", deadline)
    if grid is None or statics is None:
        sys.exit(f"no /map or {ns}/tf_static from their transient-local publishers")
    if grid.header.frame_id.lstrip("/") != "map":
        log(f"/map is in frame {grid.header.frame_id!r}: taken as map")
    t0 = time.monotonic()
    world = World(grid, args.hit_range, sensor_frames(statics))
    planner = Planner(body)
    m_o = map_to_odom(statics, log)
    log(f"sensor frames on base_link: {len(world.sensors) if world.sensors is not None else 0}")
    log(f"map {world.w}x{world.h} at {world.res:.3f} m; map->odom {m_o[0]:.3f} {m_o[1]:.3f} {m_o[2]:.3f}; "
        f"ready in {time.monotonic() - t0:.2f} s")

    inbox = Inbox()
    node.subscribe("/clock", "rosgraph_msgs/msg/Clock", inbox.on_clock, rmw.QOS_SENSOR)
    node.subscribe(f"{ns}/odom", "nav_msgs/msg/Odometry", inbox.on_odom, rmw.QOS_DEFAULT)
    node.subscribe(f"{ns}/scan", "sensor_msgs/msg/LaserScan", inbox.on_scan, rmw.QOS_SENSOR)
    # The run is over when the chair's driver leaves the graph.
    node.on_publisher_gone(f"{ns}/odom", inbox.on_driver_gone)
    # Last: the publisher's token tells the bridge this chair has a controller, which starts a
    # lock-step run, so every subscription must be in place before it (and have reached the
    # router: declarations travel asynchronously, so give them a moment, or tick 0 is lost).
    time.sleep(0.5)
    cmd = node.publisher(f"{ns}/cmd_vel", "geometry_msgs/msg/Twist")
    last_answer = [time.monotonic()]

    def answer(v, w):
        cmd.put(rmw.twist(v, w))
        last_answer[0] = time.monotonic()

    # No cmd_vel before the first scan: in lock-step any cmd_vel answers the tick the bridge
    # is at, so an early one could answer tick 0 before its scan was read.

    st = {
        "ticks": 0, "replans": 0, "plan_failures": 0, "estops": 0, "plan_ms_max": 0, "plan_ms_total": 0,
        "reached": 0, "reached_nearest": 0, "t_reached": None, "first_t": None, "last_t": None,
        "ticks_without_scan": 0, "recoveries": 0,
    }
    follower = None
    plan_partial = None
    last_plan_t = -1e9
    fail_until = -1e9
    progress_ref = (None, None)  # (t, distance to goal)
    done = False
    angles = None
    pose = None
    reason = "start"
    # Wall-clock bounds, only for what went missing: they never decide anything in a run whose
    # messages all come (a loaded machine slows every tick; these are far above a tick's gap
    # between a clock and its scan, sent back to back).
    QUIET_S = 10.0
    LOST_S = 2.0
    K_LAG = 3.0  # how much of the motor filter's lag the command makes up
    estop_prev = False
    scan_log = []
    answered_ns = -1
    fix = [0.0, 0.0]

    while True:
        with inbox.cv:
            while not inbox.scans:
                now = time.monotonic()
                # The run is over when the chair's driver left, or (a driver that died
                # unseen) no clock came for a while after the last answer (counted from the
                # answer: a long plan is no silence of the simulation's).
                quiet = inbox.last_clock_wall is not None and \
                    now - max(inbox.last_clock_wall, last_answer[0]) > QUIET_S
                never = inbox.last_clock_wall is None and now - t0 > 600
                if quiet or never or inbox.driver_gone:
                    break
                # A tick whose scan never came (lost): answer it anyway, standing still, so
                # that a lock-step run goes on.
                if (inbox.clock_ns is not None and inbox.clock_ns > answered_ns
                        and now - inbox.last_clock_wall > LOST_S):
                    answered_ns = inbox.clock_ns
                    st["ticks_without_scan"] += 1
                    answer(0.0, 0.0)
                inbox.cv.wait(0.1)
            if not inbox.scans:
                break
            stamp, scan = inbox.scans.pop(0)
            if inbox.scans:
                # Behind (should not happen in lock-step): act on the newest only.
                stamp, scan = inbox.scans[-1]
                inbox.scans.clear()
            odom = inbox.odom.get(stamp)
            if odom is None:
                w_end = time.monotonic() + LOST_S
                while odom is None and time.monotonic() < w_end:
                    inbox.cv.wait(0.02)
                    odom = inbox.odom.get(stamp)
            if odom is None and inbox.odom:
                odom = inbox.odom[max(inbox.odom)]
        if odom is None:
            answer(0.0, 0.0)
            continue
        t = stamp * 1e-9
        answered_ns = max(answered_ns, stamp)
        st["ticks"] += 1
        st["first_t"] = t if st["first_t"] is None else st["first_t"]
        st["last_t"] = t
        p = odom.pose.pose
        pose = compose(m_o, (p.position.x, p.position.y, yaw_of(p.orientation)))
        pose = (pose[0] + fix[0], pose[1] + fix[1], pose[2])
        v_meas, w_meas = odom.twist.twist.linear.x, odom.twist.twist.angular.z
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        if angles is None or len(angles) != len(ranges):
            angles = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
        if args.wall_fix > 0:
            # Odometry drifts (its wheels slip): pull the estimate towards where the walls of
            # /map say it is, a little each tick.
            dx, dy, n_fix = world.wall_fix(pose, angles, ranges)
            if n_fix:
                step = np.clip(np.array([dx, dy]) * args.wall_fix, -0.005, 0.005)
                fix[0] += float(step[0])
                fix[1] += float(step[1])
                pose = (pose[0] + float(step[0]), pose[1] + float(step[1]), pose[2])
        if debug_dir:
            scan_log.append((t, pose, ranges.astype(np.float32)))
        world.integrate(pose, angles, ranges, float(scan.range_max))

        if done:
            answer(0.0, 0.0)
            continue
        dgoal = math.hypot(pose[0] - goal[0], pose[1] - goal[1])
        if dgoal <= args.tolerance:
            done = True
            st["reached"] = 1
            st["t_reached"] = t
            log(f"t={t:.1f} reached the goal: {dgoal:.3f} m")
            answer(0.0, 0.0)
            continue

        # Should the path be planned (again)?
        if follower is None and t >= fail_until:
            reason = reason or "no path"
        if follower is not None and world.new_cells:
            rc = np.array(world.new_cells)
            pts = world.centre(rc[:, 0], rc[:, 1])
            rest = follower.remaining_poses()
            if len(rest):
                c, s = np.cos(rest[:, 2])[:, None], np.sin(rest[:, 2])[:, None]
                dx, dy = pts[None, :, 0] - rest[:, 0:1], pts[None, :, 1] - rest[:, 1:2]
                local = np.stack([c * dx + s * dy, -s * dx + c * dy], -1)
                if body.contains(local, Planner.C_MIN + world.res).any():
                    # Something new near the path: is the path still clear of it?
                    world.refresh()
                    if not path_clear(planner, world, follower):
                        reason = "blocked"
            # Something new next to the goal: where to stop may have changed (the goal may
            # now be taken), so plan again (at most once a second).
            if reason is None and t - last_plan_t >= 1.0 and len(rest) \
                    and (np.hypot(pts[:, 0] - goal[0], pts[:, 1] - goal[1]) < 1.0).any():
                reason = "goal area"
            world.new_cells = []
        if follower is not None and reason is None:
            rest = follower.remaining_poses()
            if len(rest):
                dev = np.hypot(rest[:, 0] - pose[0], rest[:, 1] - pose[1]).min()
                if dev > 0.25:
                    reason = f"strayed {dev:.2f}"
            if follower.done():
                if plan_partial == "nearest" and dgoal <= planner.MAX_GOAL_SHIFT + 0.05:
                    done = True
                    st["reached_nearest"] = 1
                    st["t_reached"] = t
                    log(f"t={t:.1f} at the nearest free place to the goal: {dgoal:.3f} m")
                    answer(0.0, 0.0)
                    continue
                reason = "path ended"
        if progress_ref[0] is None or dgoal < progress_ref[1] - 0.1:
            progress_ref = (t, dgoal)
        elif t - progress_ref[0] > 10.0 and reason is None:
            reason = "no progress"
            progress_ref = (t, dgoal)
        if reason is not None and t >= fail_until and (reason != "no progress" or t - last_plan_t >= 0.5):
            world.refresh()
            w0 = time.monotonic()
            path, partial = planner.plan(world, pose, goal, args.tolerance)
            if path is None and partial == "none":
                # Recovery (as a navigation stack's "back up"): no way from here, often because
                # the chair stands too near something (a noisy find): back off straight, if
                # that keeps clear, and plan again from there.
                back = planner.backup(world, pose)
                if back:
                    log(f"t={t:.1f} no way from here ({planner.last_stats}): backing up {0.15 * len(back):.2f} m")
                    path, partial = back, "progress"
                    st["recoveries"] += 1
            ms = 1000 * (time.monotonic() - w0)
            st["plan_ms_max"] = max(st["plan_ms_max"], round(ms))
            st["plan_ms_total"] += ms
            st["replans"] += 1
            last_plan_t = t
            log(f"t={t:.1f} plan ({reason}) at {pose[0]:.2f},{pose[1]:.2f},{math.degrees(pose[2]):.0f}: "
                f"{planner.last_stats}")
            if debug_dir:
                np.savez_compressed(
                    f"{debug_dir}/plan{st['replans']:03d}.npz", hits=world.hits, sensed=world.sensed,
                    seen=world.seen, pose=np.array(pose), t=t, ok=path is not None,
                    path=Follower(path, planner, 0.4).remaining_poses() if path else np.zeros((0, 3)))
            if path is None:
                st["plan_failures"] += 1
                follower = None
                fail_until = t + 1.0
                reason = "no path"
            else:
                follower = Follower(path, planner, args.max_speed)
                plan_partial = partial
                reason = None
        if follower is None:
            # No path (yet): stand still, and try again in a second.
            answer(0.0, 0.0)
            continue

        clear_here = planner.pose_clearance(world, pose)
        v, w, mode = follower.command(pose, v_meas, w_meas, clear_here)
        # Emergency stop: a reading just ahead of (behind) the body in the way it moves, two
        # ticks running (one when very near: the noise is 0.1 m).
        fin = np.isfinite(ranges)
        near_hit = False
        if fin.any() and abs(v) > 1e-3:
            a, r = angles[fin], ranges[fin]
            lx, ly = r * np.cos(a), r * np.sin(a)
            reach = 0.05 + 0.5 * abs(v_meas)
            if v > 0:
                ahead = lx - body.front
            else:
                ahead = -body.rear - lx
            hit = (ahead > 0.02) & (ahead < reach) & (np.abs(ly) < body.half)
            if hit.any():
                very = bool((ahead[hit] < 0.06).any())
                if very or estop_prev:
                    st["estops"] += 1
                    log(f"t={t:.1f} emergency stop ({mode}): rays "
                        + " ".join(f"{math.degrees(aa):.0f}:{rr:.2f}" for aa, rr in zip(a[hit], r[hit])))
                    v, w = 0.0, 0.0
                    reason = "blocked"
                    world.mark(pose, a[hit], r[hit])
                near_hit = True
        estop_prev = near_hit
        # Make up for the motor filter's lag: the chair's wheels output 0.17 of the command
        # plus 0.83 of what they did last tick; ask for more than wanted by K_LAG times the
        # shortfall (4.9 would be dead-beat; less keeps the noise of the measured twist down).
        vc = v + K_LAG * (v - v_meas)
        wc = w + K_LAG * (w - w_meas)
        if v == 0.0 and abs(v_meas) < 0.02:
            vc = 0.0
        if w == 0.0 and abs(w_meas) < 0.03:
            wc = 0.0
        answer(vc, wc)
        if debug_dir:
            log(f"t={t:.1f} {pose[0]:.3f},{pose[1]:.3f},{math.degrees(pose[2]):.1f} vm={v_meas:.2f} wm={w_meas:.2f} "
                f"{mode} seg={follower.k}/{len(follower.segs)} v={v:.2f} w={w:.2f} vc={vc:.2f} wc={wc:.2f} clr={clear_here:.2f} "
                f"ey={follower.err[0]:+.3f} eth={math.degrees(follower.err[1]):+.1f} fix={fix[0]:+.3f},{fix[1]:+.3f}")

    # The end.
    if debug_dir and scan_log:
        np.savez_compressed(f"{debug_dir}/scans.npz", t=np.array([q[0] for q in scan_log]),
                            pose=np.array([q[1] for q in scan_log]), ranges=np.stack([q[2] for q in scan_log]),
                            angles=angles, range_max=float(scan.range_max),
                            sensors=world.sensors if world.sensors is not None else np.zeros((0, 3)))
    if debug_dir:
        np.savez_compressed(f"{debug_dir}/final.npz", hits=world.hits, sensed=world.sensed, seen=world.seen,
                            pose=np.array(pose if pose is not None else (0, 0, 0)), t=st["last_t"] or 0.0, ok=True,
                            path=np.zeros((0, 3)))
    if pose is not None:
        print("reached", st["reached"])
        print("reached_nearest", st["reached_nearest"])
        print("final_pose", f"{pose[0]:.3f}", f"{pose[1]:.3f}", f"{math.degrees(pose[2]):.1f}")
        print("goal_dist", f"{math.hypot(pose[0] - goal[0], pose[1] - goal[1]):.3f}")
        print("t_reached", f"{st['t_reached']:.1f}" if st["t_reached"] is not None else "none")
    print("ticks", st["ticks"])
    print("replans", st["replans"])
    print("plan_failures", st["plan_failures"])
    print("plan_ms_max", st["plan_ms_max"])
    print("plan_ms_total", round(st["plan_ms_total"]))
    print("estops", st["estops"])
    print("recoveries", st["recoveries"])
    print("wall_fix", f"{fix[0]:+.3f}", f"{fix[1]:+.3f}")
    print("ticks_without_scan", st["ticks_without_scan"])
    sys.stdout.flush()
    session.close()


if __name__ == "__main__":
    main()
