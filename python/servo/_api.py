"""The library's story as functions: design, simulate, identify, compare, diagnose, add.

Each function builds the command line of the ``servo`` command it stands for and runs it in
this process through the same code as ``servo ... --json`` (``servo_cli::api``): a result's
``.to_dict()`` is the CLI's JSON object, key for key, and a failure raises a :class:`servo.Error`
with the CLI's message.
"""

from __future__ import annotations

import html
import json
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple

from . import _servo
from ._errors import Error, failure, raise_failure, UsageError
from ._files import (
    Gains,
    Log,
    Model,
    as_gains,
    as_logs,
    as_model,
    log_args,
    read_text,
    tempdir,
)


def _flag_name(key: str) -> str:
    return "--" + key.replace("_", "-")


def _flags(options: Dict[str, Any], rename: Optional[Dict[str, str]] = None) -> List[str]:
    """Keyword options as flags: ``k_steps=5`` -> ``--k-steps 5``; True -> the bare flag;
    False/None -> nothing; a list -> comma-separated."""
    out: List[str] = []
    for k, v in options.items():
        if v is None or v is False:
            continue
        flag = (rename or {}).get(k) or _flag_name(k)
        if v is True:
            out.append(flag)
        elif isinstance(v, (list, tuple)):
            out += [flag, ",".join(str(x) for x in v)]
        else:
            out += [flag, str(v)]
    return out


def _run_json(command: str, args: List[str], logs: Sequence[str] = (), models: Sequence[str] = ()):
    kind, payload = _servo.run_json([command] + args + ["--json"])
    if kind != "ok":
        raise_failure(kind, payload, command, logs, models)
    return json.loads(payload)


class Result:
    """A command's result: its fields as attributes (``r.status``, ``r.ranking``), and
    ``to_dict()``, exactly the CLI's ``--json`` object (``schema`` ``servo.<command>/1``,
    documented in docs/schemas/<command>.json)."""

    _summary: Tuple[str, ...] = ()

    def __init__(self, data: Dict[str, Any]) -> None:
        self._data = data

    def to_dict(self) -> Dict[str, Any]:
        """The CLI's ``--json`` object (a copy)."""
        return json.loads(json.dumps(self._data))

    def __getattr__(self, name: str) -> Any:
        data = self.__dict__.get("_data", {})
        if name in data:
            return data[name]
        raise AttributeError(f"{type(self).__name__} has no field `{name}`")

    def __getitem__(self, name: str) -> Any:
        return self._data[name]

    def __contains__(self, name: object) -> bool:
        return name in self._data

    def __dir__(self) -> List[str]:
        return sorted(set(super().__dir__()) | set(self._data))

    def keys(self):
        return self._data.keys()

    def _fields(self) -> List[Tuple[str, Any]]:
        return [(k, self._data[k]) for k in self._summary if k in self._data]

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={_short(v)}" for k, v in self._fields())
        return f"{type(self).__name__}({inner})"

    def _repr_html_(self) -> str:
        rows = "".join(
            f"<tr><th style='text-align:left'>{html.escape(k)}</th><td style='text-align:left'>{html.escape(_short(v, 400))}</td></tr>"
            for k, v in self._fields()
        )
        return f"<b>{type(self).__name__}</b> <code>{html.escape(str(self._data.get('schema', '')))}</code><table>{rows}</table>"


def _short(v: Any, n: int = 80) -> str:
    s = v if isinstance(v, str) else json.dumps(v)
    return s if len(s) <= n else s[: n - 3] + "..."


class DesignResult(Result):
    """``servo design --json``; ``.gains`` is the controller (as ``-o gains.toml`` writes it)."""

    _summary = ("schema", "kp", "ki", "kd", "wgc_rad_s", "pm_deg", "plant_source")

    def __init__(self, data: Dict[str, Any], gains: Optional[Gains]) -> None:
        super().__init__(data)
        self.__dict__["gains"] = gains


class IdentifyResult(Result):
    """``servo identify --json``; ``.model`` is the identified model (``-o``), None when the
    estimates could not make one."""

    _summary = ("schema", "j_eq_kg_m2", "b_eq_n_m_s_rad", "tau_sf_n_m")

    def __init__(self, data: Dict[str, Any], model: Optional[Model]) -> None:
        super().__init__(data)
        self.__dict__["model"] = model

    def _fields(self):
        out = []
        for k in self._summary:
            v = self._data.get(k)
            out.append((k, v.get("value") if isinstance(v, dict) else v))
        return [(k, v) for k, v in out if v is not None]


class CompareResult(Result):
    """``servo compare --json``: fit %, RMSE and where the model fails, per log."""

    _summary = ("schema", "fit_pct", "ladder", "logs")

    @property
    def fit_pct(self) -> Optional[float]:
        """Fit [%] of the headline signal of the first log (the last rung with ``--add``)."""
        return _first_fit(self._data)


def _first_fit(d: Dict[str, Any]) -> Optional[float]:
    ladder = d.get("ladder") or []
    if ladder:
        fits = ladder[-1].get("fit") or ladder[-1].get("fits") or []
        for f in fits if isinstance(fits, list) else []:
            if isinstance(f, dict) and "fit_pct" in f:
                return f["fit_pct"]
    for lg in d.get("logs") or []:
        for s in lg.get("signals") or []:
            if isinstance(s, dict) and "fit_pct" in s:
                return s["fit_pct"]
    return None


class AddResult(CompareResult):
    """``servo compare --add EFFECT --save --json``: ``.model`` the model with the effect
    (None when compare did not save it), the ladder before and after."""

    def __init__(self, data: Dict[str, Any], model: Optional[Model]) -> None:
        super().__init__(data)
        self.__dict__["model"] = model


class DiagnoseResult(Result):
    """``servo diagnose --json``: status, verdict, ranking of the candidates; with
    ``auto=True`` the ladder and ``.model`` with the accepted effects."""

    _summary = ("schema", "status", "winner", "verdict", "ladder")

    def __init__(self, data: Dict[str, Any], model: Optional[Model] = None) -> None:
        super().__init__(data)
        self.__dict__["model"] = model

    @property
    def winner(self) -> Optional[str]:
        """The missing effect named: the first significant candidate of the first diagnosis
        (with ``auto=True`` the first effect the ladder added), or None."""
        for c in self._data.get("first_ranking") or self._data.get("ranking") or []:
            if c.get("significant"):
                return c.get("effect")
        return None

    @property
    def added(self) -> List[str]:
        """With ``auto=True``: the effects the ladder added, in order."""
        return [r["added"] for r in self._data.get("ladder") or [] if r.get("added")]

    def _fields(self):
        out = super()._fields()
        out.insert(2, ("winner", self.winner))
        return [(k, v) for k, v in out if k != "winner" or v is not None]


def design(
    wc_rad_s: Optional[float] = None,
    pm_deg: Optional[float] = None,
    *,
    params: Any = None,
    **options: Any,
) -> DesignResult:
    """A PID by Bode's method (``servo design``, handout eqs. 42-53), verified on the reduced,
    full and discrete loops. ``wc_rad_s``: gain crossover w_gc [rad/s]; ``pm_deg``: phase margin
    [deg]; or time-domain specs ``overshoot`` (fraction) with ``settling_time_s`` (eq. 40),
    ``rise_time_s``... Other options as the flags: ``alpha``, ``tl_s``, ``ts_s``,
    ``u_limit_v``, ``controller="pi"``, ``meet_specs=True``, ``exact=True``. ``params``: the
    plant (Model or path; default Table 2)."""
    rename = {
        "wc_rad_s": "--wc",
        "pm_deg": "--pm",
        "settling_time_s": "--settling-time",
        "settling_time_1pct_s": "--settling-time-1pct",
        "rise_time_s": "--rise-time",
        "tl_s": "--tl",
        "ts_s": "--ts",
        "step_min_rad": "--step-min",
        "step_max_rad": "--step-max",
        "kw_per_s": "--kw",
        "u_limit_v": "--u-limit",
        "km_rad_per_v_s": "--km",
        "tm_s": "--tm",
    }
    with tempdir() as tmp:
        args = _flags(dict(wc_rad_s=wc_rad_s, pm_deg=pm_deg, **options), rename)
        models = []
        if params is not None:
            models.append(as_model(params, "params")._arg(tmp, "params.toml"))
            args += ["--params", models[-1]]
        out = os.path.join(tmp, "gains.toml")
        # the gains are returned even when time-domain specs are missed: the result says whether
        # they are met (``time_specs["met"]``), as the CLI's --force writes them
        d = _run_json("design", args + ["-o", out, "--force"], models=models)
        text = read_text(out)
        return DesignResult(d, Gains(text) if text is not None else None)


def identify(
    logs: Any,
    params: Any = None,
    *,
    method: Optional[str] = None,
    columns: Any = None,
    **options: Any,
) -> IdentifyResult:
    """Friction, inertia (and electrical constants) from logs (``servo identify``, handout
    section 4): ``method`` ``friction`` | ``inertia`` | ``combined`` | ``electrical``;
    ``params``: the known plant constants (Model or path; default Table 2). ``.model`` is the
    identified model. ``columns``: one map for every log, or a list of maps, one per log."""
    lg = as_logs(logs)
    with tempdir() as tmp:
        if isinstance(columns, (list, tuple)):
            # identify takes one map per log, in order
            paths, _ = log_args(lg, tmp, None)
            cflags = [x for c in columns for x in ("--columns", c)]
        else:
            paths, cflags = log_args(lg, tmp, columns)
        args = paths + cflags + _flags(dict(method=method, **options))
        models = []
        if params is not None:
            models.append(as_model(params, "params")._arg(tmp, "params.toml"))
            args += ["--params", models[-1]]
        out = os.path.join(tmp, "model.toml")
        d = _run_json("identify", args + ["-o", out], paths, models)
        text = read_text(out)
        return IdentifyResult(d, Model(text) if text is not None else None)


def _model_args(model: Any, tmp: str) -> Tuple[List[str], List[str]]:
    m = as_model(model)
    p = m._arg(tmp, "model.toml")
    return ["--model", p], [p]


def _gains_args(gains: Any, tmp: str) -> List[str]:
    if gains is None:
        return []
    return ["--gains", as_gains(gains)._arg(tmp, "gains.toml")]


def compare(
    logs: Any,
    model: Any,
    gains: Any = None,
    *,
    columns: Optional[str] = None,
    **options: Any,
) -> CompareResult:
    """Compares ``model`` with measurements (``servo compare``): closed-loop replay when the
    controller is known (a log of ``simulate``/``servo run``, or ``gains``), else open-loop;
    fit % (MATLAB's definition), RMSE, where it fails. Options as the flags (``mode``,
    ``k_steps``, ``segment_s``, ``u_limit_v``)."""
    lg = as_logs(logs)
    with tempdir() as tmp:
        paths, cflags = log_args(lg, tmp, columns)
        margs, mpaths = _model_args(model, tmp)
        args = paths + cflags + margs + _gains_args(gains, tmp) + _flags(options)
        return CompareResult(_run_json("compare", args, paths, mpaths))


def _add(model: Model, effect: str, logs: Any, gains: Any = None, **options: Any) -> AddResult:
    lg = as_logs(logs)
    columns = options.pop("columns", None)
    with tempdir() as tmp:
        paths, cflags = log_args(lg, tmp, columns)
        margs, mpaths = _model_args(model, tmp)
        out = os.path.join(tmp, "added.toml")
        args = paths + cflags + margs + _gains_args(gains, tmp) + ["--add", effect, "--save", out]
        d = _run_json("compare", args + _flags(options), paths, mpaths)
        text = read_text(out)
        return AddResult(d, Model(text) if text is not None else None)


def _diagnose_args(
    lg: List[Log], model: Any, tmp: str, columns: Optional[str], options: Dict[str, Any]
) -> Tuple[List[str], List[str], List[str], Optional[str]]:
    paths, cflags = log_args(lg, tmp, columns)
    margs, mpaths = _model_args(model, tmp)
    save = None
    if options.get("auto"):
        save = os.path.join(tmp, f"diagnosed{len(os.listdir(tmp))}.toml")
    args = paths + cflags + margs + _flags(options) + (["--save", save] if save else [])
    return args, paths, mpaths, save


def diagnose(
    logs: Any,
    model: Any,
    *,
    columns: Optional[str] = None,
    **options: Any,
) -> DiagnoseResult:
    """Which physical effect is ``model`` missing (``servo diagnose``)? Every catalogue effect
    the model lacks is fitted and judged on held-out data. Options as the flags: ``auto=True``
    (diagnose, add, refit until nothing is left; ``.ladder`` and ``.model``), ``max_steps``,
    ``only=["backlash", ...]``, ``joint``, ``filter_hz``, ``discover``. Releases the GIL; a
    Ctrl-C (KeyboardInterrupt) stops it."""
    lg = as_logs(logs)
    with tempdir() as tmp:
        args, paths, mpaths, save = _diagnose_args(lg, model, tmp, columns, options)
        d = _run_json("diagnose", args, paths, mpaths)
        text = read_text(save) if save else None
        return DiagnoseResult(d, Model(text) if text is not None else None)


def diagnose_many(
    log_sets: Sequence[Any],
    model: Any,
    workers: int = 2,
    *,
    errors: str = "raise",
    columns: Optional[str] = None,
    **options: Any,
) -> List[Any]:
    """:func:`diagnose` on each log set (a log or a list of logs, each one diagnosis), on
    ``workers`` threads inside the library (one diagnosis per worker in memory at a time),
    the GIL released. Results in order; ``errors="return"`` puts each failure's
    :class:`servo.Error` in its place instead of raising the first."""
    if errors not in ("raise", "return"):
        raise UsageError(f"errors must be 'raise' or 'return', got {errors!r}")
    if workers < 1:
        raise UsageError(f"workers must be at least 1, got {workers}")
    with tempdir() as tmp:
        jobs, meta = [], []
        for i, s in enumerate(log_sets):
            sub = os.path.join(tmp, str(i))
            os.mkdir(sub)
            args, paths, mpaths, save = _diagnose_args(as_logs(s), model, sub, columns, dict(options))
            jobs.append(["diagnose"] + args + ["--json"])
            meta.append((paths, mpaths, save))
        got = _servo.run_many(jobs, workers)
        out: List[Any] = []
        for (kind, payload), (paths, mpaths, save) in zip(got, meta):
            if kind == "ok":
                text = read_text(save) if save else None
                out.append(DiagnoseResult(json.loads(payload), Model(text) if text else None))
                continue
            if kind == "cancelled":
                raise KeyboardInterrupt(payload)
            e = failure(kind, payload, "diagnose", paths, mpaths)
            if errors == "raise":
                raise e
            out.append(e)
        return out


class TrendResult(Result):
    """``servo trend --json`` (schema ``servo.trend/1``): per actuator its logs and estimates,
    each parameter's trend, and ``changes`` (only the significant ones)."""

    _summary = ("schema", "logs_found", "cache", "changes")


def trend(
    logs: Any,
    model: Any,
    *,
    cache: Optional[str] = None,
    jobs: Optional[int] = None,
    limits: Optional[Dict[str, float]] = None,
    **options: Any,
) -> TrendResult:
    """Each actuator's parameters over many logs (``servo trend``): ``logs`` are paths of logs
    or of directories of logs; ``model`` the model fitted to each (Model or path); ``cache`` the
    cache directory shared by the runs (a re-run fits only new logs); ``limits``
    ``{"tau_sf": 0.02}``. Options as the flags (``group_by``, ``time_from="name:%Y%m%d"``,
    ``min_change_pct``, ``report``). Releases the GIL."""
    paths = [str(p) for p in (logs if isinstance(logs, (list, tuple)) else [logs])]
    with tempdir() as tmp:
        margs, mpaths = _model_args(model, tmp)
        args = paths + margs + ["--quiet"]
        if cache is not None:
            args += ["--cache", str(cache)]
        if jobs is not None:
            args += ["--jobs", str(int(jobs))]
        for k, v in (limits or {}).items():
            args += ["--limit", f"{k}={v}"]
        args += _flags(options)
        return TrendResult(_run_json("trend", args, paths, mpaths))


def simulate(
    plant: Any = None,
    gains: Any = None,
    reference: Optional[str] = None,
    duration_s: float = 5.0,
    seed: Optional[int] = None,
    *,
    voltage: Optional[str] = None,
    command: Optional[str] = None,
    **options: Any,
) -> Log:
    """Runs the loop on the simulator (``servo run``) and returns its log (MCAP kept with the
    Log, with the plant, controller and reference in its metadata). ``plant``: Model or path
    (default the lab plant); ``gains``: controller (DesignResult, Gains or path) with
    ``reference`` (``"step:1.5"``, ``"sine:amp=0.5,freq=1"`` [rad]); or open loop ``voltage``
    (``"prbs:amp=3,bit=0.02"`` [V]), or on a plant with a current or duty ``[drive]`` its open-loop
    ``command`` in the drive's unit (``"step:0.5"``: A or duty; the log then holds ``i_ref_a`` or
    ``duty``). ``seed``: the sensor noise. Options as the flags
    (``plant_effect="backlash:gap=0.04"``, ``current_noise_a``, ``ts``)."""
    keep = tempdir()
    tmp = keep.name
    args: List[str] = []
    models: List[str] = []
    if plant is not None:
        models.append(as_model(plant, "plant")._arg(tmp, "plant.toml"))
        args += ["--plant", models[-1]]
    args += _gains_args(gains, tmp)
    if reference is not None:
        args += ["--ref", reference]
    if voltage is not None:
        args += ["--voltage", voltage]
    if command is not None:
        args += ["--command", command]
    args += ["--duration", repr(float(duration_s))]
    if seed is not None:
        args += ["--seed", str(int(seed))]
    log = os.path.join(tmp, "run.mcap")
    args += _flags(options) + ["--log", log, "--progress", "never"]
    kind, payload = _servo.run(["run"] + args)
    if kind != "ok":
        keep.cleanup()
        raise_failure(kind, payload, "run", (), models)
    got = Log.read(log)
    got._keep = keep
    return got


def version() -> str:
    """The servo crates' version this package was built from."""
    return _servo.version()


__all__ = [
    "AddResult",
    "CompareResult",
    "DesignResult",
    "DiagnoseResult",
    "Error",
    "IdentifyResult",
    "Result",
    "compare",
    "design",
    "diagnose",
    "diagnose_many",
    "identify",
    "simulate",
]
