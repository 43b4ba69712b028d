"""Stubs of the native module servo._servo (python/src/lib.rs)."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

#: Signal names of a log with their SI units.
SIGNALS: List[str]

def run_json(args: List[str]) -> Tuple[str, str]:
    """`servo ARGS...` in process: ("ok", json_text) or (kind, message); kind is one of
    "usage", "command", "cancelled", "panic". GIL released; Ctrl-C raises KeyboardInterrupt."""

def run(args: List[str]) -> Tuple[str, str]:
    """A command without --json (`servo run`): ("ok", "") or (kind, message)."""

def run_many(jobs: List[List[str]], workers: int) -> List[Tuple[str, str]]:
    """Many command lines on `workers` threads; one (kind, payload) per job, in order."""

def read_log(
    path: str, columns: Optional[str] = None
) -> Tuple[str, Any, List[str], Dict[str, str]]:
    """("ok", {signal: float64 array}, notes, metadata) or (kind, message, [], {})."""

def write_csv(path: str, signals: Sequence[Tuple[str, npt.NDArray[np.float64]]]) -> Optional[str]:
    """Writes servo's CSV exactly; None or the error message."""

def params_toml(preset: str) -> str:
    """The model file of a built-in plant: "lab" or "table2"."""

def toml_to_json(text: str) -> Tuple[str, str]:
    """A TOML document as JSON text: ("ok", json) or ("command", message)."""

def version() -> str:
    """The servo crates' version."""
