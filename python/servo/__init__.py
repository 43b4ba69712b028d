"""servo in Python: DC servomotors from datasheet to an understood position loop.

Model a gearmotor, design a PID by Bode's method, simulate, identify friction and inertia,
compare the model with measurements, diagnose the missing physical effect, add it and watch
the error fall: the servo Rust library, in process. Every result's ``.to_dict()`` is the JSON
of the matching ``servo ... --json`` command (docs/schemas/); every failure is a
:class:`servo.Error` with the CLI's message. SI units everywhere, in every name (``_s``,
``_rad``, ``_v``, ``_a``, ``_n_m``).

>>> import servo
>>> plant = servo.Plant.lab().with_effect("imbalance", amplitude=0.01)
>>> log = servo.simulate(plant, voltage="sine:amp=6,freq=0.5", duration_s=20, seed=3)
>>> model = servo.identify(log, method="combined").model
>>> servo.diagnose(log, model, auto=True).winner
'imbalance'
"""

from ._api import (
    AddResult,
    CompareResult,
    DesignResult,
    DiagnoseResult,
    IdentifyResult,
    Result,
    TrendResult,
    compare,
    design,
    diagnose,
    diagnose_many,
    identify,
    simulate,
    trend,
    version,
)
from ._errors import (
    CompareError,
    DesignError,
    DiagnoseError,
    Error,
    IdentifyError,
    LogError,
    ModelError,
    SimulateError,
    UsageError,
)
from ._files import SIGNALS, Gains, Log, Model, Plant, read_log
from . import plot  # matplotlib is imported when a plot is drawn

__version__: str = version()

__all__ = [
    "AddResult",
    "CompareError",
    "CompareResult",
    "DesignError",
    "DesignResult",
    "DiagnoseError",
    "DiagnoseResult",
    "Error",
    "Gains",
    "IdentifyError",
    "IdentifyResult",
    "Log",
    "LogError",
    "Model",
    "ModelError",
    "Plant",
    "Result",
    "SIGNALS",
    "SimulateError",
    "TrendResult",
    "UsageError",
    "compare",
    "design",
    "diagnose",
    "diagnose_many",
    "identify",
    "plot",
    "read_log",
    "simulate",
    "trend",
    "version",
]
