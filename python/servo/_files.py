"""Models, gains and logs: the files servo's commands read, in memory or on disk.

A value loaded from a file keeps its path and is handed to the commands as that path (exactly
what ``servo ... FILE`` reads); one built in memory is written to a temporary file in servo's
own format for the call.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _servo
from ._errors import LogError, ModelError, UsageError

PathLike = Union[str, "os.PathLike[str]"]

#: Signal names of a log, with their SI units (servo's names, ``Record`` in the library).
SIGNALS: Tuple[str, ...] = tuple(_servo.SIGNALS)


def _toml_dict(text: str, what: str) -> Dict[str, Any]:
    kind, payload = _servo.toml_to_json(text)
    if kind != "ok":
        raise ModelError(f"{what}: {payload}")
    return json.loads(payload)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, np.floating, np.integer)):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    raise UsageError(f"effect parameter value {v!r}: expected a number")


class _TomlFile:
    """A TOML file of servo's (model or gains), in memory, with the path it came from."""

    _what = "file"

    def __init__(self, text: str, path: Optional[PathLike] = None) -> None:
        self.text = text
        self.path: Optional[str] = os.fspath(path) if path is not None else None
        self._dict: Optional[Dict[str, Any]] = None

    @classmethod
    def load(cls, path: PathLike):
        """Reads the file at ``path`` (kept: commands are handed this path)."""
        p = os.fspath(path)
        try:
            with open(p, encoding="utf-8") as f:
                text = f.read()
        except OSError as e:
            raise ModelError(f"reading {cls._what} {p}: {e.strerror or e}") from None
        return cls(text, p)

    @classmethod
    def from_toml(cls, text: str):
        """From the text of a file (as ``servo`` writes it)."""
        return cls(text)

    def save(self, path: PathLike) -> None:
        """Writes the file to ``path`` (the object then refers to it)."""
        p = os.fspath(path)
        with open(p, "w", encoding="utf-8") as f:
            f.write(self.text)
        self.path = p

    def to_dict(self) -> Dict[str, Any]:
        """The file's tables as a dict (``[params]``, ``[effects.NAME]``, ``[pid]`` ...)."""
        if self._dict is None:
            self._dict = _toml_dict(self.text, f"{self._what} {self.path or '(in memory)'}")
        return json.loads(json.dumps(self._dict))

    def _arg(self, tmp: str, name: str) -> str:
        """The path to hand a command: the file it came from if unchanged on disk, else a copy."""
        if self.path is not None:
            try:
                with open(self.path, encoding="utf-8") as f:
                    if f.read() == self.text:
                        return self.path
            except OSError:
                pass
        p = os.path.join(tmp, name)
        with open(p, "w", encoding="utf-8") as f:
            f.write(self.text)
        return p

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.text == self.text  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash(self.text)


class Model(_TomlFile):
    """A plant model: servo's model file (``[params]`` of Table 2 and identified ``j_eq``,
    ``b_eq`` [N m s/rad], ``tau_sf`` [N m]; ``[effects.NAME]`` of the catalogue). The same file
    serves as the simulator's plant (``servo.Plant`` is this class) and as the model judged."""

    _what = "model file"

    @classmethod
    def lab(cls) -> "Model":
        """The default simulated plant (``servo params``): Table 2 with J_eq = 7.0e-7 kg m^2,
        B_eq = 1.0e-6 N m s/rad and Coulomb tau_sf = 9.0e-3 N m, as measured on SRV-02s."""
        return cls(_servo.params_toml("lab"))

    @classmethod
    def table2(cls) -> "Model":
        """The handout's Table 2 as printed (no friction)."""
        return cls(_servo.params_toml("table2"))

    @property
    def params(self) -> Dict[str, float]:
        """``[params]``: Table 2 keys in SI units (``r_a`` ohm, ``k_t`` N m/A, ``n`` -, ...)."""
        return dict(self.to_dict().get("params", {}))

    @property
    def effects(self) -> Dict[str, Dict[str, float]]:
        """``[effects.NAME]``: the catalogue effects in the model with their parameters."""
        return dict(self.to_dict().get("effects", {}))

    def with_effect(self, name: str, **params: float) -> "Model":
        """A copy with the catalogue effect ``name`` and its parameters (SI units, e.g.
        ``with_effect("imbalance", amplitude=0.01)`` [N m]): a simulator plant with a hidden
        effect. Unknown names or keys are reported by the command that reads the file."""
        if name in self.effects:
            raise UsageError(f"the model already has the effect `{name}`")
        lines = [f"\n[effects.{name}]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in params.items()]
        return type(self)(self.text.rstrip("\n") + "\n" + "\n".join(lines) + "\n")

    def add(self, effect: str, logs: Any, gains: Optional["Gains"] = None, **options: Any):
        """Adds the catalogue ``effect`` with a refit on ``logs`` (``servo compare --add``):
        returns an :class:`~servo.AddResult` whose ``.model`` is the new model and whose
        ``.to_dict()`` is the CLI's ``--json`` (the error ladder before and after)."""
        from ._api import _add

        return _add(self, effect, logs, gains=gains, **options)

    def __repr__(self) -> str:
        p = self.params
        eff = ", ".join(self.effects) or "none"
        src = f" from {self.path}" if self.path else ""
        return (
            f"Model(j_eq={p.get('j_eq')!r} kg m^2, b_eq={p.get('b_eq')!r} N m s/rad, "
            f"tau_sf={p.get('tau_sf')!r} N m, effects: {eff}{src})"
        )


#: The simulator's plant is a model file too.
Plant = Model


class Gains(_TomlFile):
    """A controller (gains file of ``servo design -o``: ``[pid] kp, ki, kd, tl_s, ts_s``)."""

    _what = "gains file"

    @property
    def pid(self) -> Dict[str, Any]:
        """``[pid]``: ``kp`` [V/rad], ``ki`` [V/(rad s)], ``kd`` [V s/rad], ``tl_s``, ``ts_s``..."""
        return dict(self.to_dict().get("pid", {}))

    def __repr__(self) -> str:
        p = self.pid
        return "Gains(" + ", ".join(f"{k}={p[k]!r}" for k in ("kp", "ki", "kd") if k in p) + ")"


def _digest(arrays: Mapping[str, np.ndarray]) -> str:
    h = hashlib.sha1()
    for k in sorted(arrays):
        h.update(k.encode())
        h.update(np.ascontiguousarray(arrays[k], dtype=np.float64).tobytes())
    return h.hexdigest()


class Log:
    """A log: signals as numpy arrays with SI units in their names (``time_s``, ``u_v``,
    ``theta_l_rad``, ``theta_m_rad``, ``omega_l_rad_s``, ``omega_m_rad_s``, ``i_a_a``,
    ``ref_rad``; a current drive's command ``i_ref_a``, a PWM bridge's ``duty`` and its supply
    ``v_supply_v``). A log read from a file keeps its path (and its metadata: the controller and
    reference a closed-loop run was made with) and the commands read that file."""

    def __init__(
        self,
        signals: Optional[Dict[str, np.ndarray]] = None,
        path: Optional[PathLike] = None,
        columns: Optional[str] = None,
        metadata: Optional[Dict[str, str]] = None,
        notes: Sequence[str] = (),
        _keep: Any = None,
    ) -> None:
        if signals is None and path is None:
            raise UsageError("a Log needs signals or a path")
        self._signals = signals
        self.path: Optional[str] = os.fspath(path) if path is not None else None
        self.columns = columns
        self._metadata = metadata
        self.notes: List[str] = list(notes)
        self._keep = _keep  # a temporary directory the file lives in, removed with the Log

    @classmethod
    def read(cls, path: PathLike, columns: Optional[str] = None) -> "Log":
        """Reads a log (MCAP, CSV or MATLAB .mat, by extension) as ``servo`` does. ``columns``:
        the ``--columns`` map for foreign CSVs and MAT-files."""
        p = os.fspath(path)
        kind, payload, notes, meta = _servo.read_log(p, columns)
        if kind != "ok":
            raise LogError(payload)
        return cls(dict(payload), p, columns, dict(meta), notes)

    @classmethod
    def from_arrays(
        cls,
        time_s: Any,
        u_v: Any = None,
        theta_l_rad: Any = None,
        i_a_a: Any = None,
        theta_m_rad: Any = None,
        omega_l_rad_s: Any = None,
        omega_m_rad_s: Any = None,
        ref_rad: Any = None,
        i_ref_a: Any = None,
        duty: Any = None,
        v_supply_v: Any = None,
    ) -> "Log":
        """A log from arrays in SI units: sample times [s], driver input u [V] applied from
        each row to the next (or a current drive's reference ``i_ref_a`` [A], a PWM bridge's
        ``duty`` in [-1, 1] with its supply ``v_supply_v`` [V]), load angle [rad], armature
        current [A], ... (same lengths)."""
        given = dict(
            time_s=time_s,
            u_v=u_v,
            theta_l_rad=theta_l_rad,
            i_a_a=i_a_a,
            theta_m_rad=theta_m_rad,
            omega_l_rad_s=omega_l_rad_s,
            omega_m_rad_s=omega_m_rad_s,
            ref_rad=ref_rad,
            i_ref_a=i_ref_a,
            duty=duty,
            v_supply_v=v_supply_v,
        )
        sig = {}
        for k, v in given.items():
            if v is None:
                continue
            a = np.ascontiguousarray(np.asarray(v, dtype=np.float64).reshape(-1))
            sig[k] = a
        n = len(sig["time_s"])
        for k, a in sig.items():
            if len(a) != n:
                raise UsageError(f"signal `{k}` has {len(a)} samples but time_s has {n}")
        return cls(sig)

    @property
    def signals(self) -> Dict[str, np.ndarray]:
        """The signals present, by name."""
        if self._signals is None:
            assert self.path is not None
            got = Log.read(self.path, self.columns)
            self._signals, self._metadata, self.notes = got._signals, got._metadata, got.notes
        return dict(self._signals or {})

    @property
    def metadata(self) -> Dict[str, str]:
        """An MCAP run's metadata (``plant_toml``, ``gains_toml``, ``controller_toml``, ...)."""
        if self._metadata is None:
            self.signals
        return dict(self._metadata or {})

    def __getitem__(self, name: str) -> np.ndarray:
        return self.signals[name]

    def __contains__(self, name: object) -> bool:
        return name in self.signals

    def __len__(self) -> int:
        return len(self.signals["time_s"])

    @property
    def duration_s(self) -> float:
        """Time span [s]."""
        t = self.signals["time_s"]
        return float(t[-1] - t[0]) if len(t) > 1 else 0.0

    def to_pandas(self):
        """A pandas DataFrame, one column per signal (``.attrs['servo_path']`` and a digest of
        the data: passed back to servo unchanged, it is read from its file)."""
        import pandas as pd

        sig = self.signals
        df = pd.DataFrame(sig)
        if self.path is not None:
            df.attrs["servo_path"] = self.path
            df.attrs["servo_columns"] = self.columns
            df.attrs["servo_digest"] = _digest(sig)
            df.attrs["servo_log"] = self
        return df

    def _arg(self, tmp: str, i: int) -> str:
        if self.path is not None:
            return self.path
        p = os.path.join(tmp, f"log{i}.csv")
        sig = self.signals
        err = _servo.write_csv(p, list(sig.items()))
        if err is not None:
            raise LogError(err)
        return p

    def __repr__(self) -> str:
        names = ", ".join(self.signals)
        src = f", {self.path}" if self.path else ""
        return f"Log({len(self)} samples, {self.duration_s:.3f} s: {names}{src})"


class _LogDict(dict):
    """What :func:`read_log` returns without pandas: a dict of arrays, with its source."""

    servo_log: Optional[Log] = None
    servo_digest: Optional[str] = None


def read_log(path: PathLike, columns: Optional[str] = None):
    """Reads a log (MCAP, CSV or MAT) into a pandas DataFrame (a dict of numpy arrays when
    pandas is absent) with SI units in the column names: ``time_s``, ``u_v``, ``theta_l_rad``,
    ``i_a_a``, ... Passed back to servo unchanged, the file itself is read (with its metadata);
    edited, the edited arrays are."""
    log = Log.read(path, columns)
    try:
        return log.to_pandas()
    except ImportError:
        d = _LogDict(log.signals)
        d.servo_log = log
        d.servo_digest = _digest(log.signals)
        return d


def as_log(x: Any) -> Log:
    """A Log from what the functions accept: a Log, a path, what ``read_log`` returns (a
    DataFrame or dict of arrays, edited or not)."""
    if isinstance(x, Log):
        return x
    if isinstance(x, (str, os.PathLike)):
        return Log(path=x)
    attrs = getattr(x, "attrs", None)
    if isinstance(attrs, dict) and hasattr(x, "columns"):
        cols = {str(c): x[c].to_numpy(dtype=np.float64) for c in x.columns}
        src = attrs.get("servo_log")
        if isinstance(src, Log) and attrs.get("servo_digest") == _digest(cols):
            return src
        return _from_mapping(cols)
    if isinstance(x, Mapping):
        cols = {str(k): np.asarray(v, dtype=np.float64) for k, v in x.items()}
        src = getattr(x, "servo_log", None)
        if isinstance(src, Log) and getattr(x, "servo_digest", None) == _digest(cols):
            return src
        return _from_mapping(cols)
    raise UsageError(
        f"expected a log: a servo.Log, a path, a DataFrame or a dict of arrays, got {type(x).__name__}"
    )


def _from_mapping(cols: Dict[str, np.ndarray]) -> Log:
    unknown = [k for k in cols if k not in SIGNALS]
    if unknown:
        raise UsageError(
            f"unknown log column(s) {', '.join(unknown)}; expected names from {', '.join(SIGNALS)}"
        )
    if "time_s" not in cols:
        raise UsageError("a log needs a `time_s` column [s]")
    return Log.from_arrays(**cols)


def as_logs(x: Any) -> List[Log]:
    """One log or a list of them."""
    if isinstance(x, (list, tuple)):
        if not x:
            raise UsageError("no logs given")
        return [as_log(v) for v in x]
    return [as_log(x)]


def as_model(x: Any, what: str = "model") -> Model:
    if isinstance(x, Model):
        return x
    if isinstance(x, (str, os.PathLike)):
        return Model.load(x)
    raise UsageError(f"{what}: expected a servo.Model or a path, got {type(x).__name__}")


def as_gains(x: Any) -> Gains:
    if isinstance(x, Gains):
        return x
    if isinstance(x, (str, os.PathLike)):
        return Gains.load(x)
    from ._api import DesignResult

    if isinstance(x, DesignResult) and x.gains is not None:
        return x.gains
    raise UsageError(f"gains: expected a servo.Gains or a path, got {type(x).__name__}")


def log_args(logs: Iterable[Log], tmp: str, columns: Optional[str]) -> Tuple[List[str], List[str]]:
    """Paths for the logs and the ``--columns`` flag (one map for every log of a call)."""
    logs = list(logs)
    paths = [lg._arg(tmp, i) for i, lg in enumerate(logs)]
    maps = {lg.columns for lg in logs if lg.path is not None and lg.columns is not None}
    if columns is None and len(maps) > 1:
        raise UsageError(
            "logs read with different column maps cannot go in one call (servo applies one --columns map to every log)"
        )
    cols = columns if columns is not None else (maps.pop() if maps else None)
    flags = ["--columns", cols] if cols is not None else []
    return paths, flags


def tempdir() -> "tempfile.TemporaryDirectory[str]":
    return tempfile.TemporaryDirectory(prefix="servo-")


def read_text(path: str) -> Optional[str]:
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError:
        return None
