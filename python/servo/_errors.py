"""servo's exceptions: every failure of the library is a :class:`Error` carrying the message
the ``servo`` command prints after ``error:``."""

from __future__ import annotations

from typing import Iterable, Optional


class Error(Exception):
    """Base of servo's errors. ``str(e)`` is the CLI's message (the whole context chain)."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class UsageError(Error, ValueError):
    """An option's value or a missing argument (clap's message, naming the flag)."""


class LogError(Error):
    """A log could not be read (missing file, bad CSV/MCAP/MAT, wrong column map)."""


class ModelError(Error):
    """A model, plant or gains file is missing or invalid."""


class DesignError(Error):
    """``design`` failed (impossible specs, bad structure)."""


class IdentifyError(Error):
    """``identify`` failed (no usable segment, unphysical estimates)."""


class CompareError(Error):
    """``compare`` (or ``Model.add``) failed."""


class DiagnoseError(Error):
    """``diagnose`` failed."""


class SimulateError(Error):
    """``simulate`` (``servo run`` on the simulator) failed."""


_BY_COMMAND = {
    "design": DesignError,
    "identify": IdentifyError,
    "compare": CompareError,
    "diagnose": DiagnoseError,
    "run": SimulateError,
}


def raise_failure(
    kind: str,
    message: str,
    command: str,
    log_paths: Iterable[str] = (),
    model_paths: Iterable[str] = (),
) -> None:
    """Raises the exception of a failed command (``kind`` from the native module)."""
    if kind == "cancelled":
        raise KeyboardInterrupt(message)
    raise failure(kind, message, command, log_paths, model_paths)


def failure(
    kind: str,
    message: str,
    command: str,
    log_paths: Iterable[str] = (),
    model_paths: Iterable[str] = (),
) -> Error:
    """The exception for a failed command: the log or model it names, else the command's."""
    if kind == "usage":
        return UsageError(message)
    if kind == "panic":
        return Error(message)
    if _names_any(message, log_paths) or message.startswith("reading log"):
        return LogError(message)
    if _names_any(message, model_paths) or "model file" in message or "gains file" in message:
        return ModelError(message)
    return _BY_COMMAND.get(command, Error)(message)


def _names_any(message: str, paths: Iterable[Optional[str]]) -> bool:
    return any(p and p in message for p in paths)
