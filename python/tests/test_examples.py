"""The examples: the Dask fleet example on a small directory (when dask is installed), the
plots; the notebook is executed by .ci/run (and here when SERVO_RUN_NOTEBOOK=1)."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

import servo

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_fleet_dask_collects_one_verdict_per_log(story, tmp_path, cli):
    pytest.importorskip("dask.distributed")
    fleet = tmp_path / "fleet"
    fleet.mkdir()
    for seed in (21, 22):
        rc, _, err = cli("run", "--plant", story / "plant.toml", "--voltage", "sine:amp=6,freq=0.5",
                         "--duration", "8", "--seed", str(seed), "--log", fleet / f"m{seed}.mcap",
                         "--progress", "never")
        assert rc == 0, err
    (fleet / "broken.mcap").write_bytes(b"not an mcap")
    spec = importlib.util.spec_from_file_location("fleet_dask", EXAMPLES / "fleet_dask.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["fleet_dask"] = mod
    spec.loader.exec_module(mod)
    model = servo.Model.load(story / "model.toml")
    df = mod.fleet_verdicts(str(fleet), model, only=["imbalance", "backlash"])
    assert len(df) == 3
    by = df.set_index(df["log"].map(lambda p: Path(p).name))
    assert by.loc["broken.mcap", "status"] == "error"
    for name in ("m21.mcap", "m22.mcap"):
        assert by.loc[name, "winner"] == "imbalance", by.loc[name].to_dict()


def test_plots_draw(story):
    mpl = pytest.importorskip("matplotlib")
    mpl.use("Agg")
    import servo.plot

    model = servo.Model.load(story / "model.toml")
    ax = servo.plot.compare(servo.compare(story / "ol.mcap", model))
    assert len(ax.patches) >= 1
    ax = servo.plot.friction_curve(model)
    assert len(ax.lines) == 1
    added = model.add("imbalance", story / "ol.mcap")
    ax = servo.plot.ladder(added)
    assert len(ax.lines) == 1 and len(ax.lines[0].get_xdata()) == 2


@pytest.mark.skipif(os.environ.get("SERVO_RUN_NOTEBOOK") != "1", reason="the notebook runs in .ci/run (SERVO_RUN_NOTEBOOK=1 runs it here)")
def test_story_notebook_runs():
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(EXAMPLES / "story.ipynb", as_version=4)
    nbclient.NotebookClient(nb, timeout=900, kernel_name="python3").execute()
