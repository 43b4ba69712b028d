"""Plots of servo's results with matplotlib (an optional dependency: ``pip install
matplotlib``). Each function returns the matplotlib Axes it drew on (``ax=`` to draw on yours).
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ._errors import UsageError


def _plt():
    try:
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("servo.plot needs matplotlib: pip install matplotlib") from e
    return plt


def _axes(ax):
    if ax is not None:
        return ax
    _, ax = _plt().subplots(figsize=(7, 3.5))
    return ax


def ladder(result: Any, ax: Any = None, log: bool = True):
    """The error ladder of ``servo.diagnose(..., auto=True)`` (held-out simulation error
    [rad] per rung, effect added at each step), or of ``Model.add`` (``compare --add``: fit %
    per rung). ``result``: a DiagnoseResult, AddResult or their ``to_dict()``."""
    d = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    rungs = d.get("ladder") or []
    if not rungs:
        raise UsageError("no ladder in this result: use diagnose(..., auto=True) or Model.add")
    ax = _axes(ax)
    labels = [r.get("added") or "base" for r in rungs]
    if "oe_cost_rad" in rungs[0]:
        y = [r.get("oe_cost_rad") for r in rungs]
        y = [np.nan if v is None else v for v in y]
        ax.plot(range(len(y)), y, "o-")
        ax.set_ylabel("held-out simulation error [rad]")
        if log and all(v > 0 for v in y if v == v):
            ax.set_yscale("log")
    else:
        y = [_rung_fit(r) for r in rungs]
        ax.plot(range(len(y)), y, "o-")
        ax.set_ylabel("fit [%]")
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(["+ " + s if i else s for i, s in enumerate(labels)])
    ax.set_title("the error ladder: each effect added")
    ax.grid(True, alpha=0.3)
    return ax


def _rung_fit(r: Dict[str, Any]) -> float:
    for key in ("fit", "fits"):
        for f in r.get(key) or []:
            if isinstance(f, dict) and "fit_pct" in f:
                return float(f["fit_pct"])
    return float(r.get("fit_pct", np.nan))


def compare(result: Any, ax: Any = None):
    """Fit % per signal and log of a CompareResult (its ``to_dict()`` works too)."""
    d = result.to_dict() if hasattr(result, "to_dict") else dict(result)
    ax = _axes(ax)
    names: List[str] = []
    fits: List[float] = []
    for i, lg in enumerate(d.get("logs") or []):
        for s in lg.get("signals") or []:
            if isinstance(s, dict) and "fit_pct" in s:
                names.append(f"{s.get('signal', '?')} (log {i + 1})")
                fits.append(float(s["fit_pct"]))
    if not fits:
        raise UsageError("no fit figures in this result")
    ax.barh(range(len(fits)), fits)
    ax.set_yticks(range(len(fits)))
    ax.set_yticklabels(names)
    ax.set_xlabel("fit [%] (100 = perfect)")
    ax.set_xlim(min(0.0, min(fits)), 100)
    ax.set_title("model vs measurements")
    ax.grid(True, axis="x", alpha=0.3)
    return ax


def friction_curve(
    model: Any,
    omega_l_rad_s: Optional[Sequence[float]] = None,
    ax: Any = None,
):
    """The friction torque at the load [N m] against the load speed [rad/s] of a model:
    viscous B_eq (motor side, times N^2 at the load), Coulomb tau_sf, and a Stribeck breakaway
    or an asymmetry when the model has them (handout eqs. 8-9)."""
    m = model.model if hasattr(model, "model") and model.model is not None else model
    p = m.params
    eff = m.effects
    n = float(p.get("n", 14.0))
    b_eq = float(eff.get("viscous", {}).get("b_eq", p.get("b_eq", 0.0)))
    tau_sf = float(eff.get("coulomb", {}).get("tau_sf", p.get("tau_sf", 0.0)))
    w = np.linspace(-10, 10, 801) if omega_l_rad_s is None else np.asarray(omega_l_rad_s, float)
    tau = b_eq * n * n * w
    if "asymmetry" in eff:
        a = eff["asymmetry"]
        tau = tau + np.where(w > 0, a.get("tau_sf_pos", tau_sf), -a.get("tau_sf_neg", tau_sf))
    else:
        tau = tau + tau_sf * np.sign(w)
    if "stribeck" in eff:
        s = eff["stribeck"]
        tau = tau + (s.get("tau_s", tau_sf) - tau_sf) * np.exp(
            -((w / s.get("omega_s", 0.5)) ** 2)
        ) * np.sign(w)
    ax = _axes(ax)
    ax.plot(w, tau)
    ax.set_xlabel("load speed omega_l [rad/s]")
    ax.set_ylabel("friction torque at the load [N m]")
    ax.set_title("friction curve of the model")
    ax.grid(True, alpha=0.3)
    return ax
