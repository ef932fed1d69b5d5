"""Does a coarse integration step agree with the controller rate? Random planner edges.

A planner edge holds a pair of desired wheel speeds for one period from some entry
state. :func:`random_edges` draws such edges over every terrain the way the planner meets
them: entry at rest, moving straight or turning (in the controller's steady state),
commands over the planner's whole sampled range of wheel speeds (pivots included),
grades up to the steepest sustainable grade plus a margin, both ways. :func:`compare`
rolls each edge out at a coarse step and at the controller period (the paper's 1 kHz
digital PID, the reference) and reports, per edge, whether the stall verdicts agree and
how far energy and end pose differ.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels as K
from .limits import steepest_grade
from .params import Terrain, Vehicle, load_terrain, load_vehicle, shipped_terrains
from .simulate import Model

ENTRIES = ("rest", "moving", "turning")


@dataclass(frozen=True)
class Edges:
    """A batch of edges on one model: entry states S0 (n, NS), commands (n, 2) [rad/s],
    pitch (n,) [rad], entry kind (n,) index into ENTRIES."""

    model: Model
    S0: np.ndarray
    cmds: np.ndarray
    pitch: np.ndarray
    entry: np.ndarray


def random_edges(model: Model, n: int, rng: np.random.Generator, *, margin_deg: float = 5.0,
                 speed_range=(-0.5, 1.0)) -> Edges:
    """n random edges of ``model``: commands uniform over ``speed_range`` times the no-load
    speed (the planner's default sampled range), grades uniform within +-(steepest
    sustainable grade + margin_deg), entries at rest, moving or turning in equal shares."""
    veh = model.vehicle
    w0 = veh.no_load_speed
    lo, hi = speed_range[0] * w0, speed_range[1] * w0
    steep = max(steepest_grade(veh, model.terrain), 0.0) + math.radians(margin_deg)
    cmds = rng.uniform(lo, hi, size=(n, 2))
    pitch = rng.uniform(-steep, steep, size=n)
    entry = np.arange(n) % len(ENTRIES)
    S0 = np.empty((n, K.NS))
    for b in range(n):
        if entry[b] == 0:
            wl = wr = 0.0
        elif entry[b] == 1:
            wl = wr = rng.uniform(0.1, 0.9) * w0
        else:
            wl, wr = rng.uniform(lo, hi, size=2)
        S0[b] = _feasible(model, model.state(float(wl), float(wr), pitch=float(pitch[b])))
    return Edges(model, S0, cmds, pitch, entry)


def _feasible(model: Model, S: np.ndarray) -> np.ndarray:
    """Clip a steady entry state's currents (and the integrals behind them) to what the
    drive can deliver at its speeds: a steady state the drive cannot hold still enters
    the edge with the drive at its limit."""
    v = model.vehicle
    for w, i, z in ((K.S_WL, K.S_IL, K.S_INTL), (K.S_WR, K.S_IR, K.S_INTR)):
        lo = max(-v.current_limit, (-v.v_max - v.torque_constant * S[w]) / v.armature_resistance)
        hi = min(v.current_limit, (v.v_max - v.torque_constant * S[w]) / v.armature_resistance)
        S[i] = min(max(S[i], lo), hi)
        if v.ki > 0:
            S[z] = S[i] / v.ki
    return S


def rollout(edges: Edges, dt: float, period: float) -> np.ndarray:
    """End states (n, NS) of every edge after ``period`` seconds at step dt [s]."""
    m = edges.model
    n_steps = int(round(period / dt))
    out = np.empty_like(edges.S0)
    for p in np.unique(edges.pitch):
        sel = np.flatnonzero(edges.pitch == p)
        out[sel] = K.rollout_batch(m.P, m.table, edges.S0[sel], edges.cmds[sel], n_steps, float(p), dt)
    return out


@dataclass(frozen=True)
class Agreement:
    """Per-edge comparison of a coarse rollout with the controller-rate reference."""

    stall_ref: np.ndarray     # (n,) bool: the reference stalled
    stall_agrees: np.ndarray  # (n,) bool
    energy_ref: np.ndarray    # (n,) J
    energy_err: np.ndarray    # (n,) J, coarse minus reference
    pos_err: np.ndarray       # (n,) m
    yaw_err: np.ndarray       # (n,) rad

    def energy_ok(self, rel: float = 0.02, abs_J: float = 0.05) -> np.ndarray:
        """Energy within rel of the reference (or abs_J for edges that spend almost none)."""
        return np.abs(self.energy_err) <= np.maximum(rel * np.abs(self.energy_ref), abs_J)

    def pose_ok(self, pos_m: float = 0.05, yaw_deg: float = 2.0) -> np.ndarray:
        return (self.pos_err <= pos_m) & (np.abs(self.yaw_err) <= math.radians(yaw_deg))

    def summary(self) -> dict:
        """Shares of edges that agree: the stall verdict over all edges, energy and pose
        over the edges that stall in neither solution."""
        both = ~self.stall_ref & self.stall_agrees
        n = len(self.stall_ref)
        return {
            "edges": n,
            "stalled_reference": int(self.stall_ref.sum()),
            "stall_verdict_agrees": float(self.stall_agrees.mean()),
            # disagreements by direction: a stall only at the coarse step loses an edge the
            # vehicle could drive (conservative); one only at the controller rate is an edge
            # the planner would wrongly keep (every plan's 1 kHz check catches it)
            "stall_only_coarse": int((~self.stall_agrees & ~self.stall_ref).sum()),
            "stall_only_reference": int((~self.stall_agrees & self.stall_ref).sum()),
            "compared": int(both.sum()),
            "energy_within_2pct": float(self.energy_ok()[both].mean()) if both.any() else 1.0,
            "pose_within_5cm_2deg": float(self.pose_ok()[both].mean()) if both.any() else 1.0,
            "worst_energy_err_pct": float(np.max(np.abs(self.energy_err[both])
                                                 / np.maximum(np.abs(self.energy_ref[both]), 1.0)) * 100)
            if both.any() else 0.0,
            "worst_pos_err_m": float(self.pos_err[both].max()) if both.any() else 0.0,
            "worst_yaw_err_deg": float(np.degrees(np.abs(self.yaw_err[both]).max())) if both.any() else 0.0,
        }


def compare(edges: Edges, dt: float, period: float = 1.0, dt_ref: float | None = None) -> Agreement:
    """Roll every edge out at dt and at the controller period (or dt_ref) and compare."""
    ref_dt = 1.0 / edges.model.vehicle.controller_rate if dt_ref is None else dt_ref
    ref = rollout(edges, ref_dt, period)
    out = rollout(edges, dt, period)
    e0 = edges.S0[:, K.S_E]
    stall_ref = ref[:, K.S_STALLED] > 0.5
    stall_out = out[:, K.S_STALLED] > 0.5
    dyaw = np.angle(np.exp(1j * (out[:, K.S_YAW] - ref[:, K.S_YAW])))
    return Agreement(stall_ref=stall_ref, stall_agrees=stall_ref == stall_out,
                     energy_ref=ref[:, K.S_E] - e0, energy_err=out[:, K.S_E] - ref[:, K.S_E],
                     pos_err=np.hypot(out[:, K.S_X] - ref[:, K.S_X], out[:, K.S_Y] - ref[:, K.S_Y]),
                     yaw_err=dyaw)


def shipped_models(vehicle: Vehicle | str = "p3at", dt: float | None = None) -> list[Model]:
    """The vehicle on every shipped terrain."""
    veh = load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    return [Model(veh, load_terrain(name), dt) for name in shipped_terrains()]


__all__ = ["Agreement", "ENTRIES", "Edges", "compare", "random_edges", "rollout", "shipped_models"]
_ = Terrain
